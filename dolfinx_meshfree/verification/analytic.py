"""Exact solutions used by the demos and the tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics.materials import LinearElastic

__all__ = ["HeatedBushing", "KirschPlate", "LinearField", "PressurizedBushing", "TimoshenkoBeam"]


@dataclass(frozen=True)
class TimoshenkoBeam:
    """Cantilever under a parabolic end shear (Timoshenko & Goodier), Belytschko et al. 1995,
    eq. (5.2)–(5.3); Rabczuk et al. 2006, sec. 6.1.1.

    The beam occupies ``[0, L] x [-D/2, D/2]``; the exact displacement is prescribed at ``x = 0``
    and the shear traction ``t_y = P/(2I) (D^2/4 - y^2)`` acts on ``x = L``. Rabczuk's typeset
    ``u_y`` has a misprint (``D x^2/4``); eq. (5.2b) of Belytschko et al. is used. Plane strain
    uses ``E' = E/(1 - nu^2)``, ``nu' = nu/(1 - nu)`` in the plane-stress formulas.
    """

    material: LinearElastic
    L: float = 48.0
    D: float = 12.0
    P: float = 1000.0

    def __post_init__(self) -> None:
        for name in ("L", "D"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v} must be a positive length")
        if not np.isfinite(self.P):
            raise ValueError(f"P={self.P} must be finite")

    @property
    def inertia(self) -> float:
        return self.D**3 / 12.0

    def _moduli(self) -> tuple[float, float]:
        E, nu = self.material.E, self.material.nu
        if self.material.plane == "strain":
            return E / (1.0 - nu**2), nu / (1.0 - nu)
        return E, nu

    def displacement(self, x: np.ndarray) -> np.ndarray:
        """Exact displacement (m, 2) at points (m, 2)."""
        E, nu = self._moduli()
        P, L, D, inertia = self.P, self.L, self.D, self.inertia
        X, Y = x[:, 0], x[:, 1]
        ux = -P * Y / (6 * E * inertia) * ((6 * L - 3 * X) * X + (2 + nu) * (Y**2 - D**2 / 4))
        uy = (
            P
            / (6 * E * inertia)
            * (3 * nu * Y**2 * (L - X) + (4 + 5 * nu) * D**2 * X / 4 + (3 * L - X) * X**2)
        )
        return np.stack([ux, uy], axis=1)

    def displacement_gradient(self, x: np.ndarray) -> np.ndarray:
        """Exact gradient ``du_i/dx_j`` (m, 2, 2)."""
        E, nu = self._moduli()
        P, L, D, inertia = self.P, self.L, self.D, self.inertia
        X, Y = x[:, 0], x[:, 1]
        c = P / (6 * E * inertia)
        g = np.empty((x.shape[0], 2, 2))
        g[:, 0, 0] = -c * Y * (6 * L - 6 * X)
        g[:, 0, 1] = -c * ((6 * L - 3 * X) * X + (2 + nu) * (3 * Y**2 - D**2 / 4))
        g[:, 1, 0] = c * (-3 * nu * Y**2 + (4 + 5 * nu) * D**2 / 4 + 6 * L * X - 3 * X**2)
        g[:, 1, 1] = c * 6 * nu * Y * (L - X)
        return g

    def stress(self, x: np.ndarray) -> np.ndarray:
        """Exact stress (m, 2, 2), eq. (5.3a–c)."""
        P, L, D, inertia = self.P, self.L, self.D, self.inertia
        X, Y = x[:, 0], x[:, 1]
        s = np.zeros((x.shape[0], 2, 2))
        s[:, 0, 0] = -P * (L - X) * Y / inertia
        s[:, 0, 1] = s[:, 1, 0] = P / (2 * inertia) * (D**2 / 4 - Y**2)
        return s

    def traction(self, x: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Traction ``sigma n`` (m, 2) at boundary points with outward normals (m, 2)."""
        return np.einsum("mij,mj->mi", self.stress(x), normals)


@dataclass(frozen=True)
class LinearField:
    """Affine displacement ``u = c + G x``: the patch-test solution (Belytschko et al. 1995,
    eq. 5.1, is ``c = 0``, ``G = I``)."""

    G: tuple = ((1.0, 0.0), (0.0, 1.0))
    c: tuple = (0.0, 0.0)

    def displacement(self, x: np.ndarray) -> np.ndarray:
        return x @ np.asarray(self.G).T + np.asarray(self.c)

    def displacement_gradient(self, x: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.G, dtype=float), (x.shape[0], 2, 2)).copy()


class _RadialField:
    """``u = u_r(r) x / r`` in the plane, from a subclass's ``radial(r)`` and
    ``radial_derivative(r)``: its value and gradient ``u_r / r I + (u_r' - u_r / r) e_r e_r``."""

    def displacement(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)[:, :2]
        r = np.linalg.norm(x, axis=1)
        return (self.radial(r) / r)[:, None] * x

    def displacement_gradient(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)[:, :2]
        r = np.linalg.norm(x, axis=1)
        ur, dur = self.radial(r), self.radial_derivative(r)
        e = x / r[:, None]
        return (ur / r)[:, None, None] * np.eye(2) + (dur - ur / r)[:, None, None] * np.einsum(
            "qi,qj->qij", e, e
        )


@dataclass(frozen=True)
class PressurizedBushing(_RadialField):
    """Lamé's thick-walled cylinder: the annulus ``a <= r <= b`` under an internal pressure ``p``
    with its outer surface held fixed (a bushing in a rigid housing); 2D linear elasticity with the
    material's (plane stress or plane strain) Lamé constants.

    ``u = u_r(r) x / r`` with ``u_r = C1 r + C2 / r``, ``u_r(b) = 0`` and ``sigma_rr(a) = -p``:
    ``C2 = p / (2 (lambda + mu) / b^2 + 2 mu / a^2)``, ``C1 = -C2 / b^2``. The hoop stress
    ``sigma_tt = 2 (lambda + mu) C1 + 2 mu C2 / r^2`` peaks at the inner surface.
    """

    material: LinearElastic
    a: float = 1.0
    b: float = 2.0
    p: float = 1.0

    def __post_init__(self) -> None:
        if not (0 < self.a < self.b):
            raise ValueError(f"radii a={self.a}, b={self.b} must satisfy 0 < a < b")

    @property
    def constants(self) -> tuple[float, float]:
        lam, mu = self.material.lmbda, self.material.mu
        c2 = self.p / (2 * (lam + mu) / self.b**2 + 2 * mu / self.a**2)
        return -c2 / self.b**2, c2

    def radial(self, r: np.ndarray) -> np.ndarray:
        c1, c2 = self.constants
        return c1 * r + c2 / r

    def radial_derivative(self, r: np.ndarray) -> np.ndarray:
        c1, c2 = self.constants
        return c1 - c2 / np.asarray(r, dtype=float) ** 2

    def hoop_stress(self, r: np.ndarray) -> np.ndarray:
        c1, c2 = self.constants
        lam, mu = self.material.lmbda, self.material.mu
        return 2 * (lam + mu) * c1 + 2 * mu * c2 / np.asarray(r, dtype=float) ** 2


@dataclass(frozen=True)
class HeatedBushing(_RadialField):
    """The bushing of :class:`PressurizedBushing` heated from inside: the annulus
    ``a <= r <= b`` at the steady temperature rise of radial conduction,
    ``T(r) = T_a ln(b / r) / ln(b / a)`` (``T_a`` at the inner surface, 0 at the outer), its
    outer surface held fixed (a rigid housing) and its inner surface free; 2D linear
    thermoelasticity ``sigma = lambda tr(eps) I + 2 mu eps - beta T I`` with the material's
    (plane stress or plane strain) Lamé constants and the thermal modulus ``beta``: ``(3 lambda
    + 2 mu) alpha`` in plane strain, ``E alpha / (1 - nu)`` in plane stress (:meth:`beta_of`).

    Radial equilibrium gives ``d/dr (d(r u_r)/dr / r) = k dT/dr``, ``k = beta / (lambda + 2
    mu)`` (Timoshenko & Goodier, *Theory of Elasticity*, 3rd ed., sec. 151), so ``u_r = k I(r)
    / r + C1 r + C2 / r`` with ``I(r) = int_a^r T s ds = T_a / ln(b / a) [r^2 / 2 ln(b / r) + r^2
    / 4 - a^2 / 2 ln(b / a) - a^2 / 4]``. Then ``sigma_rr = -2 mu k I / r^2 + 2 (lambda + mu) C1 -
    2 mu C2 / r^2`` and ``sigma_tt = -2 mu k T + 2 mu k I / r^2 + 2 (lambda + mu) C1 + 2 mu C2 /
    r^2``; ``sigma_rr(a) = 0`` and ``u_r(b) = 0`` fix ``C1`` and ``C2``. The hoop stress is
    compressive at the hot inner surface.
    """

    material: LinearElastic
    beta: float
    Ta: float = 1.0
    a: float = 1.0
    b: float = 2.0

    def __post_init__(self) -> None:
        if not (0 < self.a < self.b):
            raise ValueError(f"radii a={self.a}, b={self.b} must satisfy 0 < a < b")
        if not (np.isfinite(self.beta) and np.isfinite(self.Ta)):
            raise ValueError(f"beta={self.beta} and Ta={self.Ta} must be finite")

    @staticmethod
    def beta_of(material: LinearElastic, alpha: float) -> float:
        """The thermal modulus of a 2D law for the expansion coefficient ``alpha``: the stress
        ``beta T`` that free expansion would relieve in the plane."""
        return (
            2.0 * (material.lmbda + material.mu) * (1.0 + material.nu) * alpha
            if (material.plane == "strain")
            else 2.0 * (material.lmbda + material.mu) * alpha
        )

    def temperature(self, r: np.ndarray) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        return self.Ta * np.log(self.b / r) / np.log(self.b / self.a)

    def _integral(self, r: np.ndarray) -> np.ndarray:
        a, b = self.a, self.b
        f = r**2 / 2 * np.log(b / r) + r**2 / 4 - a**2 / 2 * np.log(b / a) - a**2 / 4
        return self.Ta / np.log(b / a) * f

    @property
    def k(self) -> float:
        return self.beta / (self.material.lmbda + 2.0 * self.material.mu)

    @property
    def constants(self) -> tuple[float, float]:
        lam, mu, a, b = self.material.lmbda, self.material.mu, self.a, self.b
        c2 = -self.k * float(self._integral(np.asarray(b))) / (mu * b**2 / ((lam + mu) * a**2) + 1)
        return mu * c2 / ((lam + mu) * a**2), c2

    def radial(self, r: np.ndarray) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        c1, c2 = self.constants
        return self.k * self._integral(r) / r + c1 * r + c2 / r

    def radial_derivative(self, r: np.ndarray) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        c1, c2 = self.constants
        return self.k * (self.temperature(r) - self._integral(r) / r**2) + c1 - c2 / r**2

    def radial_stress(self, r: np.ndarray) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        lam, mu = self.material.lmbda, self.material.mu
        c1, c2 = self.constants
        return (
            -2 * mu * self.k * self._integral(r) / r**2 + 2 * (lam + mu) * c1 - 2 * mu * c2 / r**2
        )

    def hoop_stress(self, r: np.ndarray) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        lam, mu, k = self.material.lmbda, self.material.mu, self.k
        c1, c2 = self.constants
        return (
            -2 * mu * k * self.temperature(r)
            + 2 * mu * k * self._integral(r) / r**2
            + 2 * (lam + mu) * c1
            + 2 * mu * c2 / r**2
        )


@dataclass(frozen=True)
class KirschPlate:
    """Kirsch's infinite plate with a circular hole of radius ``a`` at the origin under a remote
    uniaxial stress ``sigma`` along x; 2D linear elasticity, plane stress or plane strain by the
    material's ``kappa`` (``3 - 4 nu`` in plane strain, ``(3 - nu) / (1 + nu)`` in plane
    stress). In polar coordinates (Barber, Elasticity, sec. 8.4.1), with ``mu`` the shear
    modulus:

    ``u_r = sigma / (8 mu) [r (kappa - 1 + 2 cos 2t) + 2 a^2 / r (1 + (1 + kappa) cos 2t)
    - 2 a^4 / r^3 cos 2t]``,
    ``u_t = -sigma / (8 mu) [2 r + 2 (kappa - 1) a^2 / r + 2 a^4 / r^3] sin 2t``.

    The hoop stress at the top of the hole, ``sigma_xx(0, a)``, is ``3 sigma``
    (:meth:`stress`). The field is symmetric about both axes (``u_y = 0`` on ``y = 0``,
    ``u_x = 0`` on ``x = 0``), so a quarter plate with those conditions models it.
    """

    material: LinearElastic
    a: float = 1.0
    sigma: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.a) and self.a > 0):
            raise ValueError(f"a={self.a} must be a positive hole radius")
        if not np.isfinite(self.sigma):
            raise ValueError(f"sigma={self.sigma} must be finite")

    @property
    def kappa(self) -> float:
        nu = self.material.nu
        return 3.0 - 4.0 * nu if self.material.plane == "strain" else (3.0 - nu) / (1.0 + nu)

    def _polar(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """``r, t`` and ``u_r, u_t`` with their derivatives in ``r`` and ``t``."""
        x = np.asarray(x, dtype=float)[:, :2]
        r, t = np.hypot(x[:, 0], x[:, 1]), np.arctan2(x[:, 1], x[:, 0])
        k, a, c = self.kappa, self.a, self.sigma / (8.0 * self.material.mu)
        c2, s2 = np.cos(2 * t), np.sin(2 * t)
        ur = c * (r * (k - 1 + 2 * c2) + 2 * a**2 / r * (1 + (1 + k) * c2) - 2 * a**4 / r**3 * c2)
        dur_dr = c * (
            (k - 1 + 2 * c2) - 2 * a**2 / r**2 * (1 + (1 + k) * c2) + 6 * a**4 / r**4 * c2
        )
        dur_dt = c * (-4 * r * s2 - 4 * a**2 / r * (1 + k) * s2 + 4 * a**4 / r**3 * s2)
        g = 2 * r + 2 * (k - 1) * a**2 / r + 2 * a**4 / r**3
        dg = 2 - 2 * (k - 1) * a**2 / r**2 - 6 * a**4 / r**4
        ut, dut_dr, dut_dt = -c * g * s2, -c * dg * s2, -2 * c * g * c2
        return r, t, ur, ut, dur_dr, dur_dt, dut_dr, dut_dt

    def displacement(self, x: np.ndarray) -> np.ndarray:
        """Exact displacement (m, 2) at points (m, 2) (outside the hole)."""
        _, t, ur, ut, *_ = self._polar(x)
        cos, sin = np.cos(t), np.sin(t)
        return np.stack([ur * cos - ut * sin, ur * sin + ut * cos], axis=1)

    def displacement_gradient(self, x: np.ndarray) -> np.ndarray:
        """Exact gradient ``du_i/dx_j`` (m, 2, 2): the polar gradient
        ``[[u_r,r, (u_r,t - u_t) / r], [u_t,r, (u_t,t + u_r) / r]]`` rotated to x, y."""
        r, t, ur, ut, dur_dr, dur_dt, dut_dr, dut_dt = self._polar(x)
        polar = np.empty((r.size, 2, 2))
        polar[:, 0, 0], polar[:, 0, 1] = dur_dr, (dur_dt - ut) / r
        polar[:, 1, 0], polar[:, 1, 1] = dut_dr, (dut_dt + ur) / r
        cos, sin = np.cos(t), np.sin(t)
        rot = np.empty((r.size, 2, 2))
        rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = cos, -sin, sin, cos
        return np.einsum("mik,mkl,mjl->mij", rot, polar, rot)

    def stress(self, x: np.ndarray) -> np.ndarray:
        """Exact stress (m, 2, 2) (Kirsch 1898; Barber, eq. 8.68-8.70 rotated to x, y)."""
        return self.material.stress(self.displacement_gradient(x))
