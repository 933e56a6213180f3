"""Weight functions of EFG (Belytschko et al. 1995, eq. 3.10a–c) and the SPH cubic-spline kernel.

All weights are written in the normalised distance ``r = |x - x_I| / d_I`` with compact support
``r <= 1`` and return the value and the derivative ``dw/dr``, vectorised over ``r``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TypeVar

import numpy as np
import numpy.typing as npt

__all__ = [
    "WEIGHTS",
    "cubic_inner_piece",
    "cubic_outer_piece",
    "cubic_spline",
    "gaussian",
    "gaussian_piece",
    "get_weight",
    "quartic",
    "quartic_piece",
    "sph_cubic_spline",
]

#: A float or an array of floats: the pieces below work on both.
Piece = TypeVar("Piece", float, np.ndarray)

WeightFunction = Callable[[npt.NDArray[np.floating]], tuple[np.ndarray, np.ndarray]]


# The polynomial (or exponential) piece of each weight as a plain formula in ``r``, for arrays and
# scalars alike: the vectorised weights below mask them to their intervals, and the compiled MLS
# path (:mod:`.compiled`) compiles the same formulas, so each weight is written once.
def gaussian_piece(r: Piece) -> tuple[Piece, Piece]:
    """``(w, dw/dr)`` of eq. (3.10a) without the cut-off at ``r = 1``."""
    w = np.exp(-((r / 0.4) ** 2))
    return w, -2.0 * r / 0.16 * w


def cubic_inner_piece(r: Piece) -> tuple[Piece, Piece]:
    """``(w, dw/dr)`` of eq. (3.10b) for ``r <= 1/2``."""
    return 2.0 / 3.0 - 4.0 * r**2 + 4.0 * r**3, -8.0 * r + 12.0 * r**2


def cubic_outer_piece(r: Piece) -> tuple[Piece, Piece]:
    """``(w, dw/dr)`` of eq. (3.10b) for ``1/2 < r <= 1``."""
    return 4.0 / 3.0 - 4.0 * r + 4.0 * r**2 - 4.0 / 3.0 * r**3, -4.0 + 8.0 * r - 4.0 * r**2


def quartic_piece(r: Piece) -> tuple[Piece, Piece]:
    """``(w, dw/dr)`` of eq. (3.10c) for ``r <= 1``."""
    return 1.0 - 6.0 * r**2 + 8.0 * r**3 - 3.0 * r**4, -12.0 * r + 24.0 * r**2 - 12.0 * r**3


def gaussian(r: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Truncated Gaussian, Belytschko et al. 1995, eq. (3.10a): ``w = exp(-(r/0.4)^2)``, r <= 1.

    Returns:
        ``(w, dw/dr)``, each shaped like ``r``; zero outside the support.
    """
    r = np.asarray(r, dtype=float)
    inside = r <= 1.0
    w, dw = gaussian_piece(r)
    return np.where(inside, w, 0.0), np.where(inside, dw, 0.0)


def cubic_spline(r: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Cubic spline, Belytschko et al. 1995, eq. (3.10b).

    ``w = 2/3 - 4r^2 + 4r^3`` for r <= 1/2, ``4/3 - 4r + 4r^2 - 4r^3/3`` for 1/2 < r <= 1.
    """
    r = np.asarray(r, dtype=float)
    inner = r <= 0.5
    outer = (r > 0.5) & (r <= 1.0)
    w_in, dw_in = cubic_inner_piece(r)
    w_out, dw_out = cubic_outer_piece(r)
    w = np.where(outer, w_out, np.where(inner, w_in, 0.0))
    dw = np.where(outer, dw_out, np.where(inner, dw_in, 0.0))
    return w, dw


def quartic(r: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Quartic polynomial, Belytschko et al. 1995, eq. (3.10c): ``1 - 6r^2 + 8r^3 - 3r^4``."""
    r = np.asarray(r, dtype=float)
    inside = r <= 1.0
    w, dw = quartic_piece(r)
    return np.where(inside, w, 0.0), np.where(inside, dw, 0.0)


WEIGHTS: dict[str, WeightFunction] = {
    "gaussian": gaussian,
    "cubic": cubic_spline,
    "quartic": quartic,
}


def get_weight(name: str) -> WeightFunction:
    """Look a weight function up by name, with an error that lists the valid names."""
    try:
        return WEIGHTS[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"weight={name!r} is not a known weight function; use one of {sorted(WEIGHTS)}"
        ) from None


def sph_cubic_spline(q: npt.ArrayLike, h: float, dim: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Normalised SPH cubic-spline kernel (Monaghan), support ``2h``; ``q = |x - x_I| / h``.

    ``W = sigma_d / h^d * (1 - 3/2 q^2 + 3/4 q^3)`` for q < 1 and ``sigma_d / h^d * (2 - q)^3 / 4``
    for 1 <= q < 2, with ``sigma_1 = 2/3``, ``sigma_2 = 10/(7 pi)``, ``sigma_3 = 1/pi``. It is the
    EFG cubic spline (3.10b) of ``r = q/2`` rescaled: ``W = 3/2 sigma_d / h^d * w(q/2)``, which is
    how it is computed, so both share one implementation. Used in Rabczuk et al. 2006, eq. (10).

    Returns:
        ``(W, dW/dq)``; divide the derivative by ``h`` for the derivative in space.
    """
    sigma = {1: 2.0 / 3.0, 2: 10.0 / (7.0 * math.pi), 3: 1.0 / math.pi}
    if dim not in sigma:
        raise ValueError(f"dim={dim} is not supported by the SPH kernel; use 1, 2 or 3")
    if not h > 0.0:
        raise ValueError(f"smoothing length h={h} must be positive")
    scale = 1.5 * sigma[dim] / h**dim
    w, dw = cubic_spline(np.asarray(q, dtype=float) / 2.0)
    return scale * w, 0.5 * scale * dw
