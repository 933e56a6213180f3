"""Exact solutions of longitudinal waves in rods, for the explicit-dynamics demos and tests.

The rod of Rabczuk et al. 2006, sec. 6.2.1: ``[x0, x0 + L] x [y0, y0 + H]`` in plane strain with
``nu = 0``, free everywhere, and an initial velocity along the rod that depends on ``x`` only.
With ``nu = 0`` the plane-strain law has ``lambda = 0``, so a uniaxial field
``u = (u(x, t), 0)`` gives ``sigma_yy = lambda eps_xx = 0`` and ``sigma_xy = 0``: the lateral
faces stay traction-free and the 1D wave equation ``u_tt = c^2 u_xx`` with ``c = sqrt(E/rho)``
is the exact 2D solution. Free ends (``sigma = E u_x = 0``) reflect velocity waves with the same
sign, so d'Alembert's solution holds for all times with the even, ``2L``-periodic extension ``W``
of the initial velocity (method of images):

.. math::
    v(x, t) = \\tfrac12 [W(x - ct) + W(x + ct)], \\qquad
    u(x, t) = \\tfrac{1}{2c} [U(x + ct) - U(x - ct)], \\quad U' = W.

The wave returns to its initial position after ``L / c`` (the two halves meet again after one
reflection each, Rabczuk's ``t = 0.011563`` ms) and every ``L / c`` after that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.special import erf

__all__ = ["GaussianPulseRod"]


@dataclass(frozen=True)
class GaussianPulseRod:
    """Free–free rod with the Gaussian initial velocity ``v0(x) = A exp(-alpha (x - center)^2)``.

    Rabczuk et al. 2006, sec. 6.2.1 (defaults: a 60 mm rod, ``E = 210000`` MPa,
    ``rho = 0.0078`` g/mm^3, ``alpha = 0.025``, centre 30 mm, so ``c = 5189`` mm/ms). Units are
    g, mm, ms (force N, stress MPa), the paper's: its times 0.011563 / 0.023126 are in ms. (In
    t, mm, s the density is 7.8e-9 t/mm^3 and the times are 1.1563e-5 / 2.3126e-5 s.) The initial
    velocity is the image sum of the Gaussian (its even ``2L``-periodic extension restricted to
    the rod), which differs from the bare Gaussian by ``exp(-alpha (L/2)^2) = 2e-10`` at the ends
    for the defaults and makes the exact solution exact for the initial condition used.

    Args:
        E, rho: Young's modulus and density (``c = sqrt(E/rho)``, ``nu = 0``).
        length: ``L``; the rod spans ``x0 <= x <= x0 + L``.
        center, alpha, amplitude: The Gaussian.
        x0: The left end.
    """

    E: float = 210000.0
    rho: float = 0.0078
    length: float = 60.0
    center: float = 30.0
    alpha: float = 0.025
    amplitude: float = 1.0
    x0: float = 0.0

    def __post_init__(self):
        for name in ("E", "rho", "length", "alpha"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v} must be a positive number")
        if not (self.x0 <= self.center <= self.x0 + self.length):
            raise ValueError(
                f"center={self.center} must lie on the rod [{self.x0}, {self.x0 + self.length}]"
            )

    @property
    def wave_speed(self) -> float:
        """``c = sqrt(E / rho)`` (the bar and the nu = 0 dilatational speed coincide)."""
        return float(np.sqrt(self.E / self.rho))

    @property
    def transit_time(self) -> float:
        """``L / c``: the pulse is back at its initial position (Rabczuk's t1 = 0.011563 ms)."""
        return self.length / self.wave_speed

    def _images(self, y: np.ndarray, antiderivative: bool) -> np.ndarray:
        """``W(y)`` or ``U(y)`` (``U(0) = 0``) at rod coordinates ``y = x - x0`` (any real)."""
        L, a, A = self.length, self.alpha, self.amplitude
        yc = self.center - self.x0
        period = 2.0 * L
        n = np.floor(y / period)
        r = y - n * period  # in [0, 2L)
        ks = np.arange(-2, 3)[:, None]
        if not antiderivative:
            g = np.exp(-a * (r - 2 * ks * L - yc) ** 2) + np.exp(-a * (-r - 2 * ks * L - yc) ** 2)
            return A * g.sum(axis=0)

        s = np.sqrt(a)
        scale = 0.5 * A * np.sqrt(np.pi / a)

        def prim(z):  # an antiderivative of W on the reduced coordinate
            return scale * (erf(s * (z - 2 * ks * L - yc)) - erf(s * (-z - 2 * ks * L - yc))).sum(
                axis=0
            )

        zero = prim(np.zeros(1))
        per_period = prim(np.full(1, period)) - zero
        return n * per_period + prim(r) - zero

    def initial_velocity(self, points: npt.ArrayLike) -> np.ndarray:
        """``v(x, 0)``, shape (m, 2) for points (m, 2) (or (m, 3))."""
        return self.velocity(points, 0.0)

    def velocity(self, points: npt.ArrayLike, t: float) -> np.ndarray:
        """Exact velocity ``(v(x, t), 0)`` at points (m, 2)."""
        x = np.asarray(points, dtype=float).reshape(-1, np.shape(points)[-1])[:, 0] - self.x0
        ct = self.wave_speed * float(t)
        v = 0.5 * (self._images(x - ct, False) + self._images(x + ct, False))
        return np.stack([v, np.zeros_like(v)], axis=1)

    def displacement(self, points: npt.ArrayLike, t: float) -> np.ndarray:
        """Exact displacement ``(u(x, t), 0)`` with ``u(x, 0) = 0``, at points (m, 2)."""
        x = np.asarray(points, dtype=float).reshape(-1, np.shape(points)[-1])[:, 0] - self.x0
        c = self.wave_speed
        ct = c * float(t)
        u = (self._images(x + ct, True) - self._images(x - ct, True)) / (2.0 * c)
        return np.stack([u, np.zeros_like(u)], axis=1)
