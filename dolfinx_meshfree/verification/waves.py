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

The step-loaded rod of Belytschko et al. 1995, sec. 5.2.1 (:class:`StepLoadedRod`): a traction
``sigma0 H(t)`` on one end, the other end fixed, a step wave reflected alternately by the fixed
end (velocity reversed) and the loaded end.

The wave returns to its initial position after ``L / c`` (the two halves meet again after one
reflection each, Rabczuk's ``t = 0.011563`` ms) and every ``L / c`` after that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.special import erf

__all__ = ["GaussianPulseRod", "StepLoadedRod"]


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

    def __post_init__(self) -> None:
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
        """``L / c``, when the pulse is back at its initial position (Rabczuk's t1 = 0.011563
        ms)."""
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

        def prim(z: np.ndarray) -> np.ndarray:  # an antiderivative of W on the reduced coordinate
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


@dataclass(frozen=True)
class StepLoadedRod:
    """Rod ``x0 <= x <= x0 + L``, at rest, under a step traction ``sigma0 H(t)`` pushing on the end
    ``x0`` (traction ``(sigma0, 0)``), fixed at ``x0 + L`` (Belytschko et al. 1995, sec. 5.2.1,
    Fig. 9: ``E = rho = L = sigma0 = 1``).

    The wave front carries the velocity ``v0 = sigma0 / (rho c)``; the fixed end reflects it
    with the velocity reversed, the loaded end (constant traction) too, so with ``xi = x - x0``

    .. math::
        v(x, t) = v_0 \\sum_{k \\ge 0} (-1)^k \\left[ H\\left(t - \\frac{2kL + \\xi}{c}\\right)
                  - H\\left(t - \\frac{2(k+1)L - \\xi}{c}\\right) \\right],

    periodic with period ``4 L / c`` (d'Alembert, method of characteristics). With ``nu = 0``
    in plane strain it is also the exact 2D solution of a strip (no lateral stress).

    Args:
        E, rho: Young's modulus and density (``c = sqrt(E/rho)``).
        length: ``L``. sigma0: The traction. x0: The loaded end.
    """

    E: float = 1.0
    rho: float = 1.0
    length: float = 1.0
    sigma0: float = 1.0
    x0: float = 0.0

    def __post_init__(self) -> None:
        for name in ("E", "rho", "length"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v} must be a positive number")
        if not np.isfinite(self.sigma0):
            raise ValueError(f"sigma0={self.sigma0} must be finite")

    @property
    def wave_speed(self) -> float:
        """``c = sqrt(E / rho)``."""
        return float(np.sqrt(self.E / self.rho))

    @property
    def front_velocity(self) -> float:
        """``v0 = sigma0 / (rho c)``, the particle velocity behind the front."""
        return self.sigma0 / (self.rho * self.wave_speed)

    def arrivals(self, x: float, t_end: float) -> np.ndarray:
        """Times ``<= t_end`` at which a front passes ``x`` (the jumps of the velocity)."""
        c, L, xi = self.wave_speed, self.length, float(x) - self.x0
        k = np.arange(int(np.ceil(c * t_end / (2 * L))) + 1)
        t = np.sort(np.concatenate([(2 * k * L + xi) / c, (2 * (k + 1) * L - xi) / c]))
        return t[t <= t_end]

    def velocity(self, points: npt.ArrayLike, t: float) -> np.ndarray:
        """Exact velocity ``(v(x, t), 0)`` at points (m, 2)."""
        x = np.asarray(points, dtype=float).reshape(-1, np.shape(points)[-1])[:, 0] - self.x0
        c, L = self.wave_speed, self.length
        k = np.arange(int(np.ceil(c * float(t) / (2 * L))) + 1)[:, None]
        sign = np.where(k % 2 == 0, 1.0, -1.0)
        on = (float(t) > (2 * k * L + x) / c).astype(float)
        off = (float(t) > (2 * (k + 1) * L - x) / c).astype(float)
        v = self.front_velocity * np.sum(sign * (on - off), axis=0)
        return np.stack([v, np.zeros_like(v)], axis=1)
