"""Hyperelastic materials behind one protocol: nominal stress P(F), its tangent, W(F), a UFL twin.

Rabczuk, Xiao & Sauer 2006 write every method of the package in a total-Lagrangian frame: the
momentum balance ``rho_0 u'' = div_0 P + rho_0 b`` (eq. 2) with the nominal (first
Piola–Kirchhoff) stress ``P`` of the deformation gradient ``F = I + grad_X u``, angular momentum
``F P = P^T F^T`` (eq. 3, which every law derived from a frame-indifferent energy satisfies), the
reference boundary conditions (eqs. 4–5, traction ``n^0 . P``) and the internal virtual work
``delta W_int = int_Omega0 (grad_0 delta u)^T : P`` (eq. 34). A :class:`Material` provides what
that weak form and its linearisation need, vectorised over quadrature points ``F`` (n, d, d):

* ``first_piola(F)`` -> ``P`` (n, d, d), ``P_iJ = dW/dF_iJ``;
* ``tangent(F)`` -> ``A`` (n, d, d, d, d), ``A_iJkL = dP_iJ/dF_kL`` (material and geometric parts
  together; major symmetry ``A_iJkL = A_kLiJ`` for these hyperelastic laws);
* ``strain_energy_density(F)`` -> ``W`` (n,) per unit reference volume;
* ``ufl_first_piola(F)``: the same law as a UFL expression for the FE side (``F = I + grad(u)``);
* ``wave_speed(F=None)``: the largest reference-frame (Lagrangian) wave speed
  ``sqrt(max_{|N|=|m|=1} m.Q(N).m / rho)`` of the acoustic tensor ``Q_ik(N) = A_iJkL N_J N_L``
  at the worst point, in closed form for each law (exact, never an underestimate); at ``F=None``
  the reference dilatational speed.

``d = gdim`` is 2 (``plane="strain"`` or ``"stress"``) or 3 (``plane=None``). The small-strain
member is :class:`~dolfinx_meshfree.LinearElastic` (``P = sigma(sym(F - I))``, constant tangent).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
import ufl

from ..approx import batched
from .materials import check_ufl_dimension, resolve_density, ufl_constants

__all__ = [
    "PLANES",
    "DeformationError",
    "Material",
    "NeoHookean",
    "SaintVenantKirchhoff",
    "check_deformation_gradients",
    "lame_parameters",
]

#: Accepted values of ``plane``: 2D plane strain, 2D plane stress, or ``None`` for 3D.
PLANES = ("strain", "stress", None)


@runtime_checkable
class Material(Protocol):
    """What the force, tangent, energy and time-step code needs from a constitutive law.

    ``F`` is a stack of deformation gradients (n, d, d) with ``d = gdim``; ``points`` (n, gdim),
    if given, are the reference coordinates of the ``F`` (used only to name a bad point).
    """

    rho: float
    plane: str | None

    @property
    def gdim(self) -> int:
        """2 for ``plane="strain"|"stress"``, 3 for ``plane=None``."""
        ...

    def first_piola(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """Nominal stress ``P`` (n, d, d) (Rabczuk et al. 2006, eqs. 2, 5, 34)."""
        ...

    def tangent(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """``A_iJkL = dP_iJ / dF_kL``, shape (n, d, d, d, d)."""
        ...

    def strain_energy_density(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """Stored energy per unit reference volume ``W`` (n,)."""
        ...

    def ufl_first_piola(self, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """The same ``P`` as a UFL expression of a UFL (d x d) tensor ``F``."""
        ...

    def wave_speed(self, F: np.ndarray | None = None) -> float:
        """Largest Lagrangian wave speed over the points (reference value at ``F=None``)."""
        ...


def lame_parameters(E: float, nu: float, rho: float, plane: str | None) -> tuple[float, float]:
    """Check ``(E, nu, rho, plane)`` and return the 3D Lamé parameters ``(lambda, mu)``.

    Raises:
        ValueError: naming the bad argument, its value and the admissible range.
    """
    if not (isinstance(E, int | float) and np.isfinite(E) and E > 0):
        raise ValueError(f"E={E!r} must be a positive number (Young's modulus)")
    if not (isinstance(nu, int | float) and np.isfinite(nu) and -1.0 < nu < 0.5):
        raise ValueError(
            f"nu={nu!r} must lie in (-1, 0.5): nu >= 0.5 is incompressible, which these "
            "compressible laws cannot represent"
        )
    if not (isinstance(rho, int | float) and np.isfinite(rho) and rho > 0):
        raise ValueError(f"rho={rho!r} must be a positive number (mass density)")
    if plane not in PLANES:
        raise ValueError(f"plane={plane!r} must be 'strain' or 'stress' (2D) or None (3D)")
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return float(lam), float(mu)


def _where(points: np.ndarray | None, q: int) -> str:
    if points is None:
        return f"quadrature point {q}"
    return f"quadrature point {q} at X = {np.asarray(points)[q].tolist()}"


class DeformationError(ValueError):
    """A deformation gradient with ``det F <= 0`` or a non-finite entry: the material is
    inverted (or the state is garbage) at a point. A ``ValueError``, so callers that expect one
    still catch it; Newton's line search catches this one to shorten its step."""


def check_deformation_gradients(
    F: npt.ArrayLike, gdim: int, points: np.ndarray | None = None, positive_jacobian: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a stack of deformation gradients and return ``(F, det F)``.

    Raises ``ValueError`` for a wrong shape, a non-finite entry, or (``positive_jacobian``)
    ``det F <= 0``, naming the first bad point (by its coordinates when ``points`` is given): the
    material is inverted there and the computation stops, so that no NaN is carried on.
    """
    F = np.asarray(F, dtype=float)
    if F.ndim != 3 or F.shape[1:] != (gdim, gdim):
        raise ValueError(
            f"F should have shape (num_points, {gdim}, {gdim}) for this {gdim}D material, "
            f"got {F.shape}"
        )
    bad = np.flatnonzero(~np.all(np.isfinite(F), axis=(1, 2)))
    if bad.size:
        raise DeformationError(
            f"F is not finite at {bad.size} point(s), first {_where(points, int(bad[0]))}: "
            f"{F[bad[0]].tolist()}; stop: no NaNs carried on"
        )
    J = np.linalg.det(F) if F.shape[0] else np.zeros(0)
    if positive_jacobian:
        bad = np.flatnonzero(J <= 0.0)
        if bad.size:
            q = int(bad[0])
            raise DeformationError(
                f"det F = {J[q]:.3e} <= 0 at {bad.size} point(s), first {_where(points, q)}: "
                "the deformation inverts the material there; stop: no NaNs carried on "
                "(reduce the load step or the time step)"
            )
    return F, J


@dataclass(frozen=True)
class _Hyperelastic:
    """Parameters and checks shared by the finite-strain laws (isotropic, from E and nu)."""

    E: float
    nu: float
    plane: str | None = "stress"  # the default of LinearElastic, so that swapping laws keeps it
    rho: float | None = None  # None: DEFAULT_DENSITY, dynamics warns (resolve_density)

    def __post_init__(self) -> None:
        resolve_density(self)
        lame_parameters(self.E, self.nu, self.rho, self.plane)

    @property
    def gdim(self) -> int:
        """2 in plane strain/stress, 3 for ``plane=None``."""
        return 3 if self.plane is None else 2

    @property
    def mu(self) -> float:
        """Shear modulus ``E / (2 (1 + nu))``."""
        return lame_parameters(self.E, self.nu, self.rho, self.plane)[1]

    @property
    def lmbda(self) -> float:
        """First Lamé parameter of the 3D law."""
        return lame_parameters(self.E, self.nu, self.rho, self.plane)[0]

    def _check(self, F: npt.ArrayLike, points: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        return check_deformation_gradients(F, self.gdim, points)


@dataclass(frozen=True)
class SaintVenantKirchhoff(_Hyperelastic):
    """Saint Venant–Kirchhoff: ``S = lambda tr(E) I + 2 mu E``, ``P = F S`` (the nominal stress of
    Rabczuk et al. 2006, eq. 2), ``E = (F^T F - I) / 2``, ``W = lambda/2 tr(E)^2 + mu E:E``.

    Args:
        E: Young's modulus (> 0). nu: Poisson's ratio in (-1, 0.5). rho: reference density (> 0).
        plane: ``"strain"`` (``F_33 = 1``: the 3D law with ``E_33 = 0``), ``"stress"`` (the
            default, as for :class:`~dolfinx_meshfree.LinearElastic`) or ``None`` (3D).

    Plane stress: the 2D law with the effective ``lambda* = 2 lambda mu / (lambda + 2 mu)``. For
    this law that is not only the small-strain limit: with ``F = diag(F_2D, lambda_3)``,
    ``S_33 = 0`` gives ``E_33 = -lambda tr(E_2D) / (lambda + 2 mu)`` and then exactly
    ``S_2D = lambda* tr(E_2D) I + 2 mu E_2D`` and ``W_2D = W_3D`` at any strain (a membrane whose
    thickness stretch ``lambda_3 = sqrt(1 + 2 E_33)`` is uniform through the thickness). It stops
    with a ``ValueError`` where ``1 + 2 E_33 <= 0`` (the thickness would vanish: no real
    ``lambda_3``).
    """

    @property
    def lmbda_2d(self) -> float:
        """``lambda`` of the law as used in ``d = gdim`` (``lambda*`` in plane stress)."""
        lam, mu = self.lmbda, self.mu
        return 2.0 * lam * mu / (lam + 2.0 * mu) if self.plane == "stress" else lam

    def _green(self, F: np.ndarray, points: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        d = self.gdim
        E = 0.5 * (np.einsum("qki,qkj->qij", F, F) - np.eye(d))
        trE = np.trace(E, axis1=1, axis2=2)
        if self.plane == "stress":
            e33 = -self.lmbda / (self.lmbda + 2.0 * self.mu) * trE
            bad = np.flatnonzero(1.0 + 2.0 * e33 <= 0.0)
            if bad.size:
                q = int(bad[0])
                raise ValueError(
                    f"plane stress: the thickness stretch squared 1 + 2 E_33 = "
                    f"{1.0 + 2.0 * e33[q]:.3e} <= 0 at {_where(points, q)} (in-plane tr E = "
                    f"{trE[q]:.3e}): the sheet's thickness vanishes; stop: no NaNs carried on"
                )
        return E, trE

    def _pk2(self, F: np.ndarray, points: np.ndarray | None) -> np.ndarray:
        E, trE = self._green(F, points)
        return self.lmbda_2d * trE[:, None, None] * np.eye(self.gdim) + 2.0 * self.mu * E

    def first_piola(self, F: npt.ArrayLike, points: np.ndarray | None = None) -> np.ndarray:
        """``P = F S`` (n, d, d)."""
        F, _ = self._check(F, points)
        return np.einsum("qik,qkj->qij", F, self._pk2(F, points))

    def tangent(self, F: npt.ArrayLike, points: np.ndarray | None = None) -> np.ndarray:
        """``A_iJkL = delta_ik S_JL + lambda F_iJ F_kL + mu F_iL F_kJ + mu (F F^T)_ik delta_JL``."""
        F, _ = self._check(F, points)
        S = self._pk2(F, points)
        eye = np.eye(self.gdim)
        FFt = np.einsum("qiM,qkM->qik", F, F)
        return (
            np.einsum("ik,qJL->qiJkL", eye, S)
            + self.lmbda_2d * np.einsum("qiJ,qkL->qiJkL", F, F)
            + self.mu * np.einsum("qiL,qkJ->qiJkL", F, F)
            + self.mu * np.einsum("qik,JL->qiJkL", FFt, eye)
        )

    def strain_energy_density(
        self, F: npt.ArrayLike, points: np.ndarray | None = None
    ) -> np.ndarray:
        """``W = lambda/2 tr(E)^2 + mu E:E`` (n,)."""
        F, _ = self._check(F, points)
        E, trE = self._green(F, points)
        return 0.5 * self.lmbda_2d * trE**2 + self.mu * np.einsum("qij,qij->q", E, E)

    def ufl_first_piola(self, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """``F (lambda tr(E) I + 2 mu E)`` in UFL (``lambda*`` in plane stress)."""
        check_ufl_dimension(self, F.ufl_shape[0], "ufl_first_piola's F")
        E = 0.5 * (F.T * F - ufl.Identity(self.gdim))
        lmbda, mu = ufl_constants(F, self.lmbda_2d, self.mu)
        return F * (lmbda * ufl.tr(E) * ufl.Identity(self.gdim) + 2.0 * mu * E)

    def wave_speed(self, F: npt.ArrayLike | None = None) -> float:
        """Exact largest Lagrangian wave speed.

        ``Q(N) = (N.S N) I + (lambda + mu) (F N)(F N)^T + mu F F^T``; with ``S`` coaxial with
        ``C = F^T F`` its largest eigenvalue over unit ``N`` is
        ``lambda tr E - mu + (lambda + 3 mu) s_max(F)^2`` (at the top principal direction), which
        is ``lambda + 2 mu`` at ``F = I``; a negative value (loss of ellipticity) gives 0.
        """
        lam, mu = self.lmbda_2d, self.mu
        if F is None:
            return float(np.sqrt((lam + 2.0 * mu) / self.rho))
        F, _ = self._check(F, None)
        if F.shape[0] == 0:
            return 0.0
        _, trE = self._green(F, None)
        smax2 = np.linalg.norm(F, ord=2, axis=(1, 2)) ** 2
        q = lam * trE - mu + (lam + 3.0 * mu) * smax2
        return float(np.sqrt(max(float(q.max()), 0.0) / self.rho))


@dataclass(frozen=True)
class NeoHookean(_Hyperelastic):
    """Compressible neo-Hookean (the Ciarlet/Simo–Pister form used by FEniCS demos):

    .. math::
        W = \\frac{\\mu}{2} (I_1 - 3) - \\mu \\ln J + \\frac{\\lambda}{2} (\\ln J)^2, \\quad
        P = \\mu (F - F^{-T}) + \\lambda \\ln J \\, F^{-T},

    with ``I_1 = tr(F^T F)`` of the 3D deformation gradient and ``J = det F``; ``W`` and ``P``
    reduce to linear elasticity (``lambda``, ``mu``) for small strains.

    Args:
        E: Young's modulus (> 0). nu: Poisson's ratio in (-1, 0.5). rho: reference density (> 0).
        plane: ``"strain"`` (the 3D law with ``F_33 = 1``), ``"stress"`` (the default, as for
            :class:`~dolfinx_meshfree.LinearElastic`) or ``None`` (3D).

    Plane stress is the exact condition ``P_33 = 0`` on ``F = diag(F_2D, lambda_3)``:
    ``g(lambda_3) = mu (lambda_3^2 - 1) + lambda ln(J_2D lambda_3) = 0``, solved per point by
    Newton's method in ``s = ln lambda_3`` (``g`` is increasing and convex in ``s``: one root,
    global convergence), with the consistent condensed tangent
    ``A - lambda^2 / (2 mu lambda_3^2 + lambda) F^{-T} (x) F^{-T}``. Its UFL twin unrolls the same
    Newton iteration (see :meth:`ufl_first_piola`).

    ``det F <= 0`` at a point stops with a ``ValueError`` naming the point.
    """

    #: Newton steps unrolled in the UFL plane-stress thickness solve (numpy iterates to round-off);
    #: 8 reach round-off for 0.05 <= J_2D <= 20 at any nu <= 0.49 (measured: at most 7 needed).
    plane_stress_iterations: int = 8

    def __post_init__(self) -> None:
        super().__post_init__()
        k = self.plane_stress_iterations
        if not (isinstance(k, int) and k >= 1):
            raise ValueError(f"plane_stress_iterations={k!r} must be an integer >= 1 (e.g. 8)")

    def thickness_stretch(self, F: npt.ArrayLike, points: np.ndarray | None = None) -> np.ndarray:
        """``lambda_3 = F_33`` (n,): 1 in plane strain; in plane stress the root of ``P_33 = 0``."""
        F, J = self._check(F, points)
        return np.exp(self._log_stretch(J, points))

    def _log_stretch(self, J2: np.ndarray, points: np.ndarray | None) -> np.ndarray:
        if self.plane != "stress":
            return np.zeros_like(J2)
        lam, mu = self.lmbda, self.mu
        lnJ2 = np.log(J2)
        s = -lam * lnJ2 / (2.0 * mu + lam)  # small-strain root: the first Newton step from 0
        converged = False
        for _ in range(50):
            e2 = np.exp(2.0 * s)
            ds = (mu * (e2 - 1.0) + lam * (lnJ2 + s)) / (2.0 * mu * e2 + lam)
            s = s - ds
            if converged:  # one more step after the test: quadratic convergence to round-off
                return s
            converged = bool(np.all(np.abs(ds) <= 1e-10 * (1.0 + np.abs(s))))
        q = int(np.argmax(np.abs(ds)))
        raise ValueError(
            f"plane stress: the thickness stretch did not converge at {_where(points, q)} "
            f"(J_2D = {J2[q]:.3e}, last step {ds[q]:.2e}); stop: no NaNs carried on"
        )

    def _kinematics(
        self, F: npt.ArrayLike, points: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(F, F^{-T}, ln J (3D), s = ln lambda_3)``."""
        F, J2 = self._check(F, points)
        s = self._log_stretch(J2, points)
        FinvT = np.swapaxes(batched.inv(F), 1, 2)
        return F, FinvT, np.log(J2) + s, s

    def first_piola(self, F: npt.ArrayLike, points: np.ndarray | None = None) -> np.ndarray:
        """``P = mu (F - F^{-T}) + lambda ln J F^{-T}`` (n, d, d)."""
        F, FinvT, lnJ, _ = self._kinematics(F, points)
        return self.mu * (F - FinvT) + self.lmbda * lnJ[:, None, None] * FinvT

    def tangent(self, F: npt.ArrayLike, points: np.ndarray | None = None) -> np.ndarray:
        """``A_iJkL = mu d_ik d_JL + (mu - lambda ln J) F^-T_iL F^-T_kJ + lambda F^-T_iJ F^-T_kL``
        (minus the plane-stress condensation term)."""
        F, FinvT, lnJ, s = self._kinematics(F, points)
        lam, mu = self.lmbda, self.mu
        eye = np.eye(self.gdim)
        c3 = np.full_like(lnJ, lam)
        if self.plane == "stress":
            c3 = c3 - lam**2 / (2.0 * mu * np.exp(2.0 * s) + lam)
        return (
            mu * np.einsum("ik,JL->iJkL", eye, eye)[None]
            + np.einsum("q,qiL,qkJ->qiJkL", mu - lam * lnJ, FinvT, FinvT)
            + np.einsum("q,qiJ,qkL->qiJkL", c3, FinvT, FinvT)
        )

    def strain_energy_density(
        self, F: npt.ArrayLike, points: np.ndarray | None = None
    ) -> np.ndarray:
        """``W = mu/2 (I_1 - 3) - mu ln J + lambda/2 (ln J)^2`` (n,), 3D invariants."""
        F, _, lnJ, s = self._kinematics(F, points)
        I1 = np.einsum("qij,qij->q", F, F) + (np.exp(2.0 * s) if self.gdim == 2 else 0.0)
        return 0.5 * self.mu * (I1 - 3.0) - self.mu * lnJ + 0.5 * self.lmbda * lnJ**2

    def ufl_first_piola(self, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """The same ``P`` in UFL. In plane stress ``ln lambda_3`` is
        :attr:`plane_stress_iterations` Newton steps from the small-strain root, unrolled."""
        check_ufl_dimension(self, F.ufl_shape[0], "ufl_first_piola's F")
        lam, mu = ufl_constants(F, self.lmbda, self.mu)
        FinvT = ufl.inv(F).T
        lnJ = ufl.ln(ufl.det(F))
        if self.plane == "stress":
            lnJ2 = lnJ
            s = -lam * lnJ2 / (2.0 * mu + lam)
            for _ in range(self.plane_stress_iterations):
                e2 = ufl.exp(2.0 * s)
                s = s - (mu * (e2 - 1.0) + lam * (lnJ2 + s)) / (2.0 * mu * e2 + lam)
            lnJ = lnJ2 + s
        return mu * (F - FinvT) + lam * lnJ * FinvT

    def wave_speed(self, F: npt.ArrayLike | None = None) -> float:
        """Exact largest Lagrangian wave speed.

        ``Q(N) = mu I + c a a^T`` with ``a = F^{-T} N`` and ``c = mu + lambda (1 - ln J)`` (minus
        the plane-stress term), so the largest eigenvalue over unit ``N`` is
        ``mu + max(c, 0) / s_min(F)^2``: ``lambda + 2 mu`` at ``F = I`` (``lambda* + 2 mu`` in
        plane stress).
        """
        lam, mu = self.lmbda, self.mu
        if F is None:
            lam_eff = 2.0 * lam * mu / (lam + 2.0 * mu) if self.plane == "stress" else lam
            return float(np.sqrt((lam_eff + 2.0 * mu) / self.rho))
        F, _, lnJ, s = self._kinematics(F, None)
        if F.shape[0] == 0:
            return 0.0
        c = mu + lam * (1.0 - lnJ)
        if self.plane == "stress":
            c = c - lam**2 / (2.0 * mu * np.exp(2.0 * s) + lam)
        smin2 = np.linalg.norm(F, ord=-2, axis=(1, 2)) ** 2
        return float(np.sqrt(float(np.max(mu + np.maximum(c, 0.0) / smin2)) / self.rho))
