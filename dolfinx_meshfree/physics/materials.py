"""Constitutive laws for the particle side (and the reference FE solver)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import dolfinx.fem
import numpy as np
import ufl

if TYPE_CHECKING:  # annotations only
    from .constitutive import Material

#: ``LinearElastic(plane=AXISYMMETRIC)``: the (r, z) section of a solid of revolution.
AXISYMMETRIC = "axisymmetric"


def is_axisymmetric(law: object) -> bool:
    """Whether a law (linear, rate-form, zoned, bound) is axisymmetric (``plane=AXISYMMETRIC``):
    the one test of every path that revolves its integrals or takes the hoop stretch."""
    return getattr(law, "plane", None) == AXISYMMETRIC


__all__ = [
    "AXISYMMETRIC",
    "DEFAULT_DENSITY",
    "LinearElastic",
    "check_ufl_dimension",
    "is_axisymmetric",
    "linear_twin",
    "resolve_density",
    "ufl_constants",
]

#: The density of a law built without ``rho``: enough for statics, which does not use it; explicit
#: dynamics warns when it runs on it (issue 23, item 4: a steel model in SI units got a time
#: scale sqrt(7850) too fast without a word).
DEFAULT_DENSITY = 1.0


def resolve_density(law: object) -> None:
    """Set ``law.density_given`` (whether ``rho`` was given) and ``law.rho`` to
    :data:`DEFAULT_DENSITY` when it was not: the ``__post_init__`` step that every law (frozen
    dataclasses: linear and finite-strain) shares."""
    object.__setattr__(law, "density_given", law.rho is not None)
    if law.rho is None:
        object.__setattr__(law, "rho", DEFAULT_DENSITY)


def check_ufl_dimension(law: object, size: int, what: str) -> None:
    """Refuse a UFL operand of ``size`` components per direction for a law of another
    dimension (a 2D ``plane`` law on a 3D mesh: UFL said only "Can't add expressions with
    different shapes")."""
    gdim = law.gdim
    if size != gdim:
        fix = "plane=None (3D)" if size == 3 else "plane='strain' or 'stress' (2D)"
        raise ValueError(
            f"{type(law).__name__}(plane={law.plane!r}) is a {gdim}D law but {what} is {size}D: "
            f"pass {fix}"
        )


def ufl_constants(expr: ufl.core.expr.Expr, *values: float) -> tuple:
    """The ``values`` as DOLFINx ``Constant``s on the mesh of the UFL expression ``expr`` (plain
    floats when ``expr`` has no mesh): the material parameters of a law's UFL form.

    A float in a UFL form is a literal of the C code FFCx generates, so every new value (a
    material's E, nu, rho) compiles a new form; a ``Constant`` is an argument of the kernel,
    whose code is then the same for every value: a parameter sweep compiles once. Measured on
    the test suite (lane A serial, an empty FFCx cache): 534 forms compiled before, 389 after,
    and the run 335 s before, 304 s after (274 s with a warm cache).
    """
    domain = ufl.domain.extract_unique_domain(expr)
    if domain is None:
        return tuple(float(v) for v in values)
    return tuple(dolfinx.fem.Constant(domain, float(v)) for v in values)


@dataclass(frozen=True)
class LinearElastic:
    """Isotropic linear elasticity: 2D plane stress or plane strain, axisymmetric (r, z), or 3D
    (``plane=None``).

    Args:
        E: Young's modulus (> 0). nu: Poisson's ratio (-1 < nu < 0.5). plane: ``"stress"`` or
            ``"strain"`` for a 2D mesh, ``"axisymmetric"`` for a 2D mesh in the (r, z)
            half-plane ``x[0] = r >= 0`` (a solid of revolution: the hoop strain ``u_r / r`` and
            ``2 pi r`` weights, :mod:`~dolfinx_meshfree.physics.axisymmetry`; the paths that
            take it say so, every other one refuses it by name), ``None`` for a 3D mesh (the
            solvers check it against the mesh with :meth:`check_gdim`). rho: Mass density
            (used by dynamics; > 0); ``None`` (not given): :data:`DEFAULT_DENSITY`, and
            explicit dynamics warns that the density was not given (it sets the time scale).

    Attributes:
        density_given: Whether ``rho`` was given (``False``: the default was taken).
    """

    E: float
    nu: float
    plane: str | None = "stress"
    rho: float | None = None

    def __post_init__(self) -> None:
        resolve_density(self)
        if not (np.isfinite(self.E) and self.E > 0):
            raise ValueError(f"E={self.E} must be a positive number")
        if not (np.isfinite(self.nu) and -1.0 < self.nu < 0.5):
            raise ValueError(f"nu={self.nu} must lie in (-1, 0.5)")
        if self.plane not in ("stress", "strain", AXISYMMETRIC, None):
            raise ValueError(
                f"plane={self.plane!r} must be 'stress', 'strain' or 'axisymmetric' (2D), or "
                "None (3D)"
            )
        if not (np.isfinite(self.rho) and self.rho > 0):
            raise ValueError(f"rho={self.rho} must be positive (a zero or negative density)")

    @property
    def gdim(self) -> int:
        """Dimension of the law's mesh: 2 with ``plane="stress"|"strain"|"axisymmetric"``, 3
        with ``plane=None``."""
        return 3 if self.plane is None else 2

    @property
    def axisymmetric(self) -> bool:
        """Whether the law is the (r, z) section of a solid of revolution."""
        return is_axisymmetric(self)

    def refuse_axisymmetric(self, what: str) -> None:
        """Raise a ValueError naming ``what`` if the law is axisymmetric: the plane operators
        (:meth:`voigt`, :meth:`stress`, :meth:`ufl_stress` and the finite-strain protocol) have
        no hoop strain and no ``2 pi r`` weight, so a path built on them would silently solve
        plane strain."""
        if self.axisymmetric:
            raise ValueError(
                f"material plane='axisymmetric': {what} has no hoop strain u_r / r and no "
                "2 pi r weights (it would solve plane strain). Axisymmetric models run in "
                "EFGElasticity, ExplicitDynamics.fe and ExplicitDynamics.efg (linear), and FE "
                "forms written with dolfinx_meshfree.physics.axisymmetry (ufl_stress, "
                "ufl_strain, radius); elsewhere use plane='strain' or a 3D model"
            )

    def axisymmetric_voigt(self) -> np.ndarray:
        """The (4 x 4) material matrix of an axisymmetric law: ``[s_rr, s_zz, s_rz, s_tt] = D
        [e_rr, e_zz, gamma_rz, e_tt]`` (the plane Voigt order, then the hoop component; 3D
        Lamé constants)."""
        if not self.axisymmetric:
            raise ValueError(
                f"axisymmetric_voigt needs plane='axisymmetric', got plane={self.plane!r}"
            )
        lam, mu = self.lmbda, self.mu
        D = np.zeros((4, 4))
        D[np.ix_([0, 1, 3], [0, 1, 3])] = lam
        D[[0, 1, 3], [0, 1, 3]] = lam + 2.0 * mu
        D[2, 2] = mu
        return D

    def check_gdim(self, gdim: int, where: str = "the mesh", law: str | None = None) -> None:
        """Raise a ValueError unless the law fits a geometric dimension ``gdim`` (local);
        ``law``: the class the user gave, when this is its :func:`linear_twin`."""
        if gdim == self.gdim:
            return
        fix = (
            "plane=None (3D elasticity)"
            if gdim == 3
            else "plane='stress' or plane='strain' (2D elasticity)"
        )
        args = "E, nu" if law is None else "..."
        raise ValueError(
            f"material plane={self.plane!r} is a {self.gdim}D law but {where} has gdim={gdim}; "
            f"use {law or 'LinearElastic'}({args}, {fix})"
        )

    @property
    def mu(self) -> float:
        """Shear modulus."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lmbda(self) -> float:
        """First Lamé parameter (plane-stress effective value for ``plane="stress"``)."""
        lam = self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))
        if self.plane == "stress":
            return 2.0 * lam * self.mu / (lam + 2.0 * self.mu)
        return lam

    def voigt(self) -> np.ndarray:
        """Material matrix D in Voigt notation with engineering shears.

        2D (3 x 3): ``[s_xx, s_yy, s_xy] = D [e_xx, e_yy, gamma_xy]``. 3D (6 x 6):
        ``[s_xx, s_yy, s_zz, s_yz, s_xz, s_xy] = D [e_xx, e_yy, e_zz, gamma_yz, gamma_xz,
        gamma_xy]`` with ``gamma_ij = 2 e_ij`` (the order of
        :func:`~dolfinx_meshfree.approx.tables.voigt_pairs` and of the strain operator).
        """
        self.refuse_axisymmetric("voigt() (the plane 3 x 3 matrix)")
        lam, mu = self.lmbda, self.mu
        d = self.gdim
        nv = d * (d + 1) // 2
        D = np.zeros((nv, nv))
        D[:d, :d] = lam
        D[np.arange(d), np.arange(d)] = lam + 2 * mu
        D[np.arange(d, nv), np.arange(d, nv)] = mu
        return D

    def stress(self, grad_u: np.ndarray) -> np.ndarray:
        """Cauchy stress (..., d, d) from displacement gradients (..., d, d), d = ``gdim``."""
        self.refuse_axisymmetric("stress(grad_u)")
        d = self.gdim
        if grad_u.shape[-2:] != (d, d):
            raise ValueError(
                f"grad_u should have shape (..., {d}, {d}) for plane={self.plane!r}, "
                f"got {grad_u.shape}"
            )
        eps = 0.5 * (grad_u + np.swapaxes(grad_u, -1, -2))
        tr = np.trace(eps, axis1=-2, axis2=-1)[..., None, None]
        return 2.0 * self.mu * eps + self.lmbda * tr * np.eye(d)

    def ufl_stress(self, u: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """The same law as a UFL expression, for DOLFINx forms (``u`` of ``gdim`` components)."""
        self.refuse_axisymmetric("ufl_stress(u)")
        check_ufl_dimension(self, u.ufl_shape[0], "ufl_stress's u")
        eps = ufl.sym(ufl.grad(u))
        mu, lmbda = ufl_constants(u, self.mu, self.lmbda)
        return 2.0 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(self.gdim)

    def wave_speed(self, F: np.ndarray | None = None) -> float:
        """Dilatational wave speed ``sqrt((lambda + 2 mu) / rho)`` (the tangent is constant: any
        ``F`` gives the same)."""
        return float(np.sqrt((self.lmbda + 2.0 * self.mu) / self.rho))

    # --- the Material protocol (dolfinx_meshfree.physics.constitutive): the small-strain member
    # ---------

    def _grad_u(self, F: np.ndarray) -> np.ndarray:
        self.refuse_axisymmetric("the finite-strain protocol (first_piola, tangent)")
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

    def ufl_first_piola(self, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """:meth:`ufl_stress` of the displacement gradient ``F - I`` in UFL."""
        self.refuse_axisymmetric("ufl_first_piola(F)")
        check_ufl_dimension(self, F.ufl_shape[0], "ufl_first_piola's F")
        eps = ufl.sym(F - ufl.Identity(self.gdim))
        mu, lmbda = ufl_constants(F, self.mu, self.lmbda)
        return 2.0 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(self.gdim)


def linear_twin(material: Material) -> LinearElastic:
    """The small-strain law a material reduces to at ``F = I``: the same ``E``, ``nu``,
    ``plane`` and ``rho`` (``material`` itself when it is a :class:`LinearElastic`). The linear
    stiffness of a finite-strain model at ``u = 0``, and its checks, use it."""
    if isinstance(material, LinearElastic):
        return material
    rho = material.rho if getattr(material, "density_given", True) else None
    return LinearElastic(material.E, material.nu, plane=material.plane, rho=rho)
