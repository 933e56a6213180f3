"""Constitutive laws for the particle side (and the reference FE solver)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LinearElastic"]


@dataclass(frozen=True)
class LinearElastic:
    """Isotropic linear elasticity in 2D, plane stress or plane strain.

    Args:
        E: Young's modulus (> 0). nu: Poisson's ratio (-1 < nu < 0.5). plane: ``"stress"`` or
            ``"strain"``. rho: Mass density (used by dynamics; > 0).
    """

    E: float
    nu: float
    plane: str = "stress"
    rho: float = 1.0

    def __post_init__(self):
        if not (np.isfinite(self.E) and self.E > 0):
            raise ValueError(f"E={self.E} must be a positive number")
        if not (np.isfinite(self.nu) and -1.0 < self.nu < 0.5):
            raise ValueError(f"nu={self.nu} must lie in (-1, 0.5)")
        if self.plane not in ("stress", "strain"):
            raise ValueError(f"plane={self.plane!r} must be 'stress' or 'strain'")
        if not (np.isfinite(self.rho) and self.rho > 0):
            raise ValueError(f"rho={self.rho} must be positive (a zero or negative density)")

    @property
    def mu(self) -> float:
        """Shear modulus."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lmbda(self) -> float:
        """First Lamé parameter of the 2D law (plane-stress effective value for ``stress``)."""
        lam = self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))
        if self.plane == "stress":
            return 2.0 * lam * self.mu / (lam + 2.0 * self.mu)
        return lam

    def voigt(self) -> np.ndarray:
        """3 x 3 matrix D with ``[s_xx, s_yy, s_xy] = D [e_xx, e_yy, gamma_xy]``."""
        lam, mu = self.lmbda, self.mu
        return np.array([[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]])

    def stress(self, grad_u: np.ndarray) -> np.ndarray:
        """Cauchy stress (..., 2, 2) from displacement gradients (..., 2, 2)."""
        eps = 0.5 * (grad_u + np.swapaxes(grad_u, -1, -2))
        tr = np.trace(eps, axis1=-2, axis2=-1)[..., None, None]
        return 2.0 * self.mu * eps + self.lmbda * tr * np.eye(2)

    def ufl_stress(self, u):
        """The same law as a UFL expression, for DOLFINx forms."""
        import ufl

        eps = ufl.sym(ufl.grad(u))
        return 2.0 * self.mu * eps + self.lmbda * ufl.tr(eps) * ufl.Identity(2)

    def wave_speed(self) -> float:
        """Dilatational wave speed ``sqrt((lambda + 2 mu) / rho)``."""
        return float(np.sqrt((self.lmbda + 2.0 * self.mu) / self.rho))
