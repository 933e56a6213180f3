"""Weight functions of EFG (Belytschko et al. 1995, eq. 3.10a–c) and the SPH cubic-spline kernel.

All weights are written in the normalised distance ``r = |x - x_I| / d_I`` with compact support
``r <= 1`` and return the value and the derivative ``dw/dr``, vectorised over ``r``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

__all__ = [
    "WEIGHTS",
    "cubic_spline",
    "gaussian",
    "get_weight",
    "quartic",
    "sph_cubic_spline",
]

WeightFunction = Callable[[npt.NDArray[np.floating]], tuple[np.ndarray, np.ndarray]]


def gaussian(r: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Truncated Gaussian, Belytschko et al. 1995, eq. (3.10a): ``w = exp(-(r/0.4)^2)``, r <= 1.

    Returns:
        ``(w, dw/dr)``, each shaped like ``r``; zero outside the support.
    """
    r = np.asarray(r, dtype=float)
    inside = r <= 1.0
    w = np.where(inside, np.exp(-((r / 0.4) ** 2)), 0.0)
    dw = np.where(inside, -2.0 * r / 0.16 * w, 0.0)
    return w, dw


def cubic_spline(r: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Cubic spline, Belytschko et al. 1995, eq. (3.10b).

    ``w = 2/3 - 4r^2 + 4r^3`` for r <= 1/2, ``4/3 - 4r + 4r^2 - 4r^3/3`` for 1/2 < r <= 1.
    """
    r = np.asarray(r, dtype=float)
    inner = r <= 0.5
    outer = (r > 0.5) & (r <= 1.0)
    w = np.where(inner, 2.0 / 3.0 - 4.0 * r**2 + 4.0 * r**3, 0.0)
    w = np.where(outer, 4.0 / 3.0 - 4.0 * r + 4.0 * r**2 - 4.0 / 3.0 * r**3, w)
    dw = np.where(inner, -8.0 * r + 12.0 * r**2, 0.0)
    dw = np.where(outer, -4.0 + 8.0 * r - 4.0 * r**2, dw)
    return w, dw


def quartic(r: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Quartic polynomial, Belytschko et al. 1995, eq. (3.10c): ``1 - 6r^2 + 8r^3 - 3r^4``."""
    r = np.asarray(r, dtype=float)
    inside = r <= 1.0
    w = np.where(inside, 1.0 - 6.0 * r**2 + 8.0 * r**3 - 3.0 * r**4, 0.0)
    dw = np.where(inside, -12.0 * r + 24.0 * r**2 - 12.0 * r**3, 0.0)
    return w, dw


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
