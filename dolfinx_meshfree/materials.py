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

    def wave_speed(self, F: np.ndarray | None = None) -> float:
        """Dilatational wave speed ``sqrt((lambda + 2 mu) / rho)`` (the tangent is constant: any
        ``F`` gives the same)."""
        return float(np.sqrt((self.lmbda + 2.0 * self.mu) / self.rho))

    # --- the Material protocol (dolfinx_meshfree.constitutive): the small-strain member ---------

    @property
    def gdim(self) -> int:
        """2 in plane strain/stress, 3 for ``plane=None``."""
        return 3 if self.plane is None else 2

    def _grad_u(self, F: np.ndarray) -> np.ndarray:
        F = np.asarray(F, dtype=float)
        d = self.gdim
        if F.ndim != 3 or F.shape[1:] != (d, d):
            raise ValueError(f"F should have shape (num_points, {d}, {d}), got {F.shape}")
        return F - np.eye(d)

    def first_piola(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """Linearised nominal stress ``P = sigma(sym(F - I))`` (n, d, d): :meth:`stress` of the
        displacement gradient ``F - I`` (no finite-strain check: the law is linear in ``F``)."""
        return self.stress(self._grad_u(F))

    def tangent(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """Constant ``C_iJkL = lambda d_iJ d_kL + mu (d_ik d_JL + d_iL d_Jk)``, (n, d, d, d, d)."""
        n = self._grad_u(F).shape[0]
        eye = np.eye(self.gdim)
        C = self.lmbda * np.einsum("ij,kl->ijkl", eye, eye) + self.mu * (
            np.einsum("ik,jl->ijkl", eye, eye) + np.einsum("il,jk->ijkl", eye, eye)
        )
        return np.broadcast_to(C, (n, *C.shape)).copy()

    def strain_energy_density(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """``W = 1/2 eps : C : eps`` (n,) with ``eps = sym(F - I)``."""
        H = self._grad_u(F)
        return 0.5 * np.einsum("qij,qij->q", self.stress(H), H)

    def ufl_first_piola(self, F):
        """:meth:`ufl_stress` of the displacement gradient ``F - I`` in UFL."""
        import ufl

        eps = ufl.sym(F - ufl.Identity(self.gdim))
        return 2.0 * self.mu * eps + self.lmbda * ufl.tr(eps) * ufl.Identity(self.gdim)
