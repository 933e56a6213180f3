"""Exact fields and reference values for the stress intensity factor demos (issue 10)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fracture.frame import TipFrame
from ..fracture.kolosov import PotentialField, kolosov_fields
from ..physics.materials import LinearElastic

__all__ = ["InclinedCentreCrack", "edge_crack_factor"]

#: Tada's fit for the single edge crack in a plate under remote tension, valid (±0.5 %) for
#: ``a/W <= 0.6`` (Tada, Paris & Irwin, The Stress Analysis of Cracks Handbook).
EDGE_CRACK_RANGE = (0.0, 0.6)


def edge_crack_factor(a_over_w: float | np.ndarray) -> np.ndarray:
    """``F(a/W) = K_I / (sigma sqrt(pi a))`` of a single edge crack of depth ``a`` in a plate of
    width ``W`` under remote tension ``sigma`` (plate long enough, ``H/W >= 2``):
    ``F = 1.12 - 0.231 (a/W) + 10.55 (a/W)^2 - 21.72 (a/W)^3 + 30.39 (a/W)^4`` (Tada)."""
    r = np.asarray(a_over_w, dtype=float)
    lo, hi = EDGE_CRACK_RANGE
    if not np.all(np.isfinite(r) & (r > lo) & (r <= hi)):
        raise ValueError(
            f"a_over_w={a_over_w!r}: Tada's formula holds (to 0.5 %) for 0 < a/W <= {hi}"
        )
    return 1.12 - 0.231 * r + 10.55 * r**2 - 21.72 * r**3 + 30.39 * r**4


@dataclass(frozen=True)
class InclinedCentreCrack(PotentialField):
    """Infinite plate with a straight crack of half-length ``a`` centred at ``center``, at angle
    ``alpha`` (radians) to the x axis, under remote uniaxial tension ``sigma`` along y.

    Muskhelishvili's solution in crack coordinates (``x'`` along the crack, ``|x'| < a``): with
    ``g(z) = sqrt(z^2 - a^2)`` (``~ z`` at infinity, cut along the crack) and the remote stresses
    ``S = sigma cos^2 alpha`` (normal to the crack), ``T = sigma sin alpha cos alpha`` (shear),
    ``P = sigma sin^2 alpha`` (along it),

    .. math::
        \\phi = \\frac{S - iT}{2} g + \\frac{P - S}{4} z,\\qquad
        \\psi = -\\frac{S - iT}{2}\\frac{z^2}{g} + \\frac{S + iT}{2} g - \\frac{P - S}{2} z,

    the Westergaard functions ``Z_I = S z/g``, ``Z_II = T z/g`` in Kolosov–Muskhelishvili form
    plus the uniform ``sigma_x'x' = P - S``. Both tips have ``K_I = S sqrt(pi a)``,
    ``K_II = T sqrt(pi a)`` in their tip frames, i.e.
    ``K_I / (sigma sqrt(pi a)) = cos^2 alpha``, ``K_II / (sigma sqrt(pi a)) = sin alpha cos alpha``.
    Displacements are exact up to the rigid motion fixed by these potentials (none at the centre).
    Points on the crack line take the face the principal branch gives them; stay off it.
    """

    material: LinearElastic
    a: float = 1.0
    alpha: float = 0.0
    sigma: float = 1.0
    center: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.a) and self.a > 0):
            raise ValueError(f"a={self.a} must be a positive crack half-length")
        if not (np.isfinite(self.alpha) and np.isfinite(self.sigma)):
            raise ValueError(f"alpha={self.alpha}, sigma={self.sigma} must be finite")

    @property
    def frame(self) -> TipFrame:
        """The crack's frame (origin at the centre, ``e1`` along the crack)."""
        return TipFrame(np.asarray(self.center), np.array([np.cos(self.alpha), np.sin(self.alpha)]))

    @property
    def tips(self) -> np.ndarray:
        """(2, 2): the tip at ``center + a t`` and the one at ``center - a t``."""
        t = self.frame.direction
        return self.frame.tip + np.array([self.a, -self.a])[:, None] * t

    @property
    def tip_directions(self) -> np.ndarray:
        """(2, 2): the crack's direction ahead of each tip (``t``, ``-t``)."""
        t = self.frame.direction
        return np.array([t, -t])

    @property
    def remote(self) -> tuple[float, float, float]:
        """``(S, T, P)``: remote normal, shear and parallel stress on the crack plane."""
        c, s = np.cos(self.alpha), np.sin(self.alpha)
        return self.sigma * c * c, self.sigma * s * c, self.sigma * s * s

    @property
    def K_I(self) -> float:
        return self.remote[0] * np.sqrt(np.pi * self.a)

    @property
    def K_II(self) -> float:
        return self.remote[1] * np.sqrt(np.pi * self.a)

    @property
    def normalized(self) -> tuple[float, float]:
        """``K_I, K_II`` over ``sigma sqrt(pi a)``, i.e. ``cos^2 alpha`` and
        ``sin alpha cos alpha``."""
        c, s = np.cos(self.alpha), np.sin(self.alpha)
        return c * c, s * c

    def fields(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Displacement (m, 2), gradient (m, 2, 2) (``[:, i, j] = du_i/dx_j``) and stress
        (m, 2, 2) at global points (m, 2), in global components."""
        frame = self.frame
        x = frame.to_local(np.asarray(points, dtype=float).reshape(-1, 2))
        z = x[:, 0] + 1j * x[:, 1]
        if np.any(np.abs(z**2 - self.a**2) == 0):
            raise ValueError(f"the field is singular at the tips {self.tips.tolist()}")
        S, T, P = self.remote
        a2 = self.a**2
        g = np.sqrt(z - self.a) * np.sqrt(z + self.a)  # cut on [-a, a] only
        c, u0 = 0.5 * (S - 1j * T), 0.25 * (P - S)
        phi = c * g + u0 * z
        dphi = c * z / g + u0
        d2phi = -c * a2 / g**3
        psi = -c * z * z / g + np.conj(c) * g - 2.0 * u0 * z
        # d/dz (z^2/g) = z (z^2 - 2 a^2) / g^3
        dpsi = -c * z * (z * z - 2.0 * a2) / g**3 + np.conj(c) * z / g - 2.0 * u0
        u, grad, sigma = kolosov_fields(z, phi, dphi, d2phi, psi, dpsi, self.material)
        return (
            frame.vectors_to_global(u),
            frame.tensors_to_global(grad),
            frame.tensors_to_global(sigma),
        )
