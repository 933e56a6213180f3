"""Hybrid SPH–FE coupling for linear elasticity (Rabczuk et al. 2006, sec. 5.5; Sauer 2000).

The patch is discretised by SPH particles, the rest by finite elements; no interface element and
no multiplier joins them. Instead the FE integration points of the cells near the patch join the
particle sums (eq. 125–130, :mod:`~dolfinx_meshfree.couplings.hybrid_sph`): at a stress point
``x_q`` of the
patch the displacement gradient is

.. math::
    \\nabla u^h(x_q) = \\sum_J u_J \\otimes G_J(x_q) + \\sum_g u^{FE}(X_g) \\otimes G_g(x_q),
    \\qquad u^{FE}(X_g) = \\sum_a N_a(X_g) u_a,

with the corrected kernel gradients ``G`` (exact for linear fields) of
:class:`~dolfinx_meshfree.couplings.hybrid_sph.CorrectedSPH`. For linear elasticity the particle
forces of
eq. 127 are then the derivatives of the particle strain energy
``sum_q w_q 1/2 eps(x_q) : C : eps(x_q)`` (the pair form ``(P_J + P_I) . grad N`` of eq. 127 is
that derivative for nodal integration), a linear operator assembled once:

.. math::
    f^{int} = K u, \\qquad K = K_{FE} + \\sum_q w_q B_q^T D B_q ,

``B_q`` spanning particle and FE dofs. The forces reach the FE nodes in one of two ways (Sauer
2000; ``variant``):

* ``"HA-F"`` (eq. 135, Fig. 10): the integration points are particles of the sums, so the
  reaction on each point ``X_g`` goes to the FE nodes by interpolation, ``N_a(X_g)``: the FE
  rows of ``sum_q w_q B_q^T D B_q``. With ``"smoothed"`` strains, or ``"cells"`` and
  ``consistent=False``, ``K`` is symmetric (central differences conserve its energy to
  round-off); the pair term of
  the point's own FE stress, ``P(X_GP)`` in eq. 135, belongs to the FE energy, which ``K_FE``
  already holds, and is not added twice.
* ``"HA-S"`` (eq. 131–134, Fig. 8–9): the particles' stresses load the FE interface as
  tractions. At the end node ``k`` of an interface edge the stress is the kernel average of the
  stresses of the particles it can see (eq. 131), ``P_k = sum_J P_J N_J / sum_J N_J``; the
  visibility criterion keeps the particles on the patch side of that edge,
  ``(X_J - X_k) . n >= 0`` with ``n`` the FE side's outward normal (so at a corner each edge sees
  its own side only). The edge's traction ``t = n . P_k`` (eq. 132–133) gives the node the force
  ``l/2 t`` per edge (eq. 134). The particles' rows stay those of their strain energy, so ``K``
  is not symmetric: the traction is not the work conjugate of the kinematic coupling through the
  sums.

Integration of the particle energy (``integration``):

* ``"smoothed"`` (default for HA-F): the strains smoothed over sub-cells of the patch cells by
  the divergence theorem (:mod:`~dolfinx_meshfree.couplings.hybrid_smoothing`), the hybrid sums on
  the
  sub-cells' inner edges, the FE trace on the interface and the particles' interpolant on the
  exterior boundary: ``K`` is symmetric *and* integration-consistent (the linear patch test
  holds to round-off; ``consistent`` has no effect), so central differences conserve energy and
  a wave crosses the interface without the reflection that the inconsistent Gauss integration
  leaves there;
* ``"cells"`` (default for HA-S): Gauss points of the patch cells as stress points (a
  background-cell quadrature, which keeps ``K`` free of the zero-energy modes of nodal
  integration and gives a regular static problem);
* ``"particles"``: the particles themselves with their volumes, eq. 127–128 as written (nodal
  integration; its sawtooth modes carry no energy, so the static problem is singular: dynamics
  only).

Integration consistency of ``"cells"`` (``consistent``, default ``True``): the corrected kernel
gradients are not derivatives of a function, so on background cells they do not satisfy the
divergence theorem near the exterior boundary and the interface, and a linear field leaves forces
of the order of the stress times the spacing there: the static cantilever then does not converge,
and in dynamics part of every wave that crosses the interface is reflected. The test gradients
get the variationally consistent correction of Chen, Hillman & Rüter 2013
(:meth:`HybridElasticity._consistent_test_gradients`): the linear patch test holds to round-off,
and ``K`` is no longer symmetric (central differences then do not conserve energy).

The SPH particles of HA-F (``particles``, default ``"centred"`` with HA-F) sit at the centres of
a lattice of squares with the squares' areas as volumes
(:func:`~dolfinx_meshfree.couplings.hybrid_sph.centred_particles`), not on the patch's own grid
through
the interface nodes (see :mod:`~dolfinx_meshfree.couplings.hybrid_sph` for why: with that grid the
rod's
error depended on the particle:node ratio).

Essential conditions in statics: strongly on FE facets; on patch facets by Nitsche's method with
the smoothed strains (``"smoothed"``, the default; :meth:`HybridElasticity._nitsche`), otherwise
by piecewise-constant multipliers on pieces of the boundary at least ``multiplier_length``
particle spacings long (:mod:`~dolfinx_meshfree.geometry.facet_groups`). One multiplier per facet,
as
:class:`~dolfinx_meshfree.CoupledElasticity` has, outnumbers the centred particles near the
boundary once the spacing reaches the element size: the constraint block loses rank and the
solve returned garbage (on the gmsh square with particles at 1.5 h, 1.1e6 x the plain FE error);
dependent multipliers are now refused with a ``ValueError`` before the solve. The displacement
in the patch cells is the particles' own
:class:`~dolfinx_meshfree.couplings.hybrid_sph.CorrectedSPH`
interpolant; body loads on the patch cells go to the dofs through the hybrid sums' functions
(eq. 125), the displacement whose strains the particle energy holds.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable

import dolfinx
import numpy as np
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from .. import _compat
from ..approx.fe_points import tabulate_in_cells
from ..approx.kernels import sph_cubic_spline
from ..approx.neighbours import pairs_within_support
from ..approx.tables import strain_operator
from ..geometry.facet_groups import FacetGroups, constraint_rank_check, grouped_facet_quadrature
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import QuadraturePoints, cell_quadrature, facet_quadrature
from ..parallel import Layout, raise_on_all_ranks
from ..physics.body_loads import CallableBodyForce, body_load_vectors
from ..physics.materials import LinearElastic
from ..physics.operators import load_vector
from ..statics.efg import _vector_values, facet_multipliers
from ..statics.petsc import BlockSystem, create_aij, create_vector
from .base import (
    CoupledSolution,
    CouplingOperators,
    cell_indicator,
    check_dimension,
    fe_dof_layout,
    node_flags,
)
from .hybrid_smoothing import EXTERIOR, INTERIOR, smoothing_cells
from .hybrid_sph import (
    CorrectedSPH,
    centred_particles,
    hybrid_points,
    particle_spacing_median,
)

__all__ = ["HYBRID_INTEGRATIONS", "HYBRID_PARTICLES", "HYBRID_VARIANTS", "HybridElasticity"]

#: How the particle forces reach the FE nodes (Rabczuk et al. 2006, sec. 5.5).
HYBRID_VARIANTS = ("HA-S", "HA-F")
#: Stress points of the particle energy.
HYBRID_INTEGRATIONS = ("cells", "particles", "smoothed")
#: Where the SPH particles sit: centres of a lattice of squares, or the patch's own particles.
HYBRID_PARTICLES = ("centred", "patch")

VectorFunction = Callable[[np.ndarray], np.ndarray]


class HybridElasticity:
    """Linear elasticity with FE cells and an SPH particle patch, hybrid coupling.

    Args:
        V: Vector P1/Q1 space on the whole mesh (FE on the cells outside the patch).
        patch: :class:`~dolfinx_meshfree.ParticlePatch` on the same mesh.
        material: :class:`~dolfinx_meshfree.LinearElastic`, on both sides.
        variant: ``"HA-F"`` (default: forces on the FE nodes by interpolation from the
            integration points, eq. 135, with centred particles and smoothed strains) or
            ``"HA-S"`` (by interface tractions, eq. 131–134, with the visibility criterion). Over
            the 135 cases of ``demos/robustness.py`` HA-F's median L2 error is 2.1 x plain FE's
            and HA-S's 42 x (HA-S above 5 % relative error in 67 cases, HA-F in 28).
        smoothing: Smoothing length over the particle spacing (median nearest-neighbour
            distance); the kernel support is twice the smoothing length. The default 1.0 (support
            two spacings, as EFG's d_max = 2) was the most accurate of 1.0, 1.3, 1.6 on the
            cantilever.
        quadrature_degree: Gauss degree of the stress points on the patch cells (``"cells"``);
            default: two points per particle spacing and direction. With ``"smoothed"`` the
            patch cells get as many sub-cells per direction as this rule has points (one sub-cell
            per particle spacing lets the sub-cells' centres coincide with the particles when the
            spacing divides the cells, and the rod's error then grows 2.8x from t1 to t2 at
            ratio 4, 2,000 nodes).
        hybrid_degree: Gauss degree of the FE integration points that join the sums (eq.
            129–130); default: about one point per particle spacing and direction (Sauer 2000:
            the particles' density).
        integration: ``"smoothed"``, ``"cells"`` or ``"particles"`` (see the module
            docstring). Default: ``"smoothed"`` for HA-F (symmetric and consistent; cantilever
            L2 errors 1.8e-2, 4.3e-3, 1.9e-3 at h = 3, 1.5, 1, against 0.20, 5.7e-2, 3.0e-2
            with ``"cells"``), ``"cells"`` for HA-S (whose traction rows go with the Gauss
            points: 0.14, 3.2e-2, 1.3e-2, against 0.38, 0.16, 9.7e-2 smoothed).
        particles: ``"centred"`` (default for HA-F): the SPH particles sit at the centres of a
            lattice of squares of the patch's particle spacing, none on the interface, each with
            the area of its square in the patch as its volume
            (:func:`~dolfinx_meshfree.couplings.hybrid_sph.centred_particles`); :attr:`patch` is
            then a
            copy of the given patch holding these particles. ``"patch"`` (default for HA-S): the
            patch's own particles and Voronoi volumes. Those put a particle on every interface
            FE node (a compliant double layer that reflects waves) and their sampled volumes
            scatter when the spacing does not divide the cells: the rod's error then depended on
            the particle:node ratio (see :mod:`~dolfinx_meshfree.couplings.hybrid_sph`). HA-S keeps
            them:
            its node stresses (eq. 131) average the particles that an interface node sees, which
            are then at the node; with centred particles its static L2 rate fell below 1 in 14
            of the 90 cases of ``demos/robustness.py`` (1 with the patch's particles).
        consistent: Integration-consistent test gradients (Chen, Hillman & Rüter 2013; see
            :meth:`_consistent_test_gradients`): the linear patch test holds to round-off, at
            the price of a ``K`` that is not symmetric. ``False``: the symmetric
            ``sum_q w_q B_q^T D B_q``, whose background-cell integration of the corrected kernel
            gradients leaves forces of the order of the stress times the spacing at the
            particles near exterior boundaries (the patch test is missed).
        multiplier_length: Statics without Nitsche: the length, in particle spacings, of the
            pieces of a patch Dirichlet boundary that carry one multiplier per component
            (:func:`~dolfinx_meshfree.geometry.facet_groups.grouped_facet_quadrature`; 0: one per
            facet). The default 2.0 was the most accurate of 1, 1.5, 2, 3 on the robustness
            cases that have Dirichlet facets on the patch (1: 20-120 x FE at spacing 1.5 h;
            3: up to 35 x); dependent multipliers are refused.
        nitsche: Statics with ``"smoothed"``: Nitsche's parameter ``gamma`` of the patch's
            essential conditions, ``beta = gamma max(D) / h_k`` (``h_k`` the size of the
            smoothing cell at the boundary); 0 uses the multipliers instead. The errors of the
            robustness cases change by less than 2 % for gamma from 4 to 30 (100: up to 60 %).

    Raises:
        ValueError: on every rank, for an unknown ``variant`` or ``integration``, a smoothing
            that is not positive, a mesh mismatch, or particles too sparse for the kernel.
    """

    coupling = "hybrid"

    def __init__(
        self,
        V,
        patch: ParticlePatch,
        material: LinearElastic,
        variant: str = "HA-F",
        smoothing: float = 1.0,
        quadrature_degree: int | None = None,
        hybrid_degree: int | None = None,
        integration: str | None = None,
        consistent: bool = True,
        particles: str | None = None,
        multiplier_length: float = 2.0,
        nitsche: float = 10.0,
    ):
        comm = patch.comm

        def check() -> None:
            check_dimension(
                V.mesh,
                "hybrid",
                (2,),
                "its SPH particles (a 2D lattice of squares), kernel normalisation and "
                "interface tractions (Rabczuk et al. 2006, eq. 131-135) are written for 2D",
            )
            if variant not in HYBRID_VARIANTS:
                raise ValueError(
                    f"variant={variant!r} is not known; use 'HA-S' (forces by interface "
                    "tractions, Rabczuk et al. 2006, eq. 131-134) or 'HA-F' (by interpolation, "
                    "eq. 135)"
                )
            if integration is not None and integration not in HYBRID_INTEGRATIONS:
                raise ValueError(
                    f"integration={integration!r} is not known; use 'cells' (Gauss points of "
                    "the patch cells), 'smoothed' (strains smoothed over sub-cells: symmetric "
                    "and consistent) or 'particles' (nodal integration, dynamics only)"
                )
            if particles is not None and particles not in HYBRID_PARTICLES:
                raise ValueError(
                    f"particles={particles!r} is not known; use 'centred' (SPH particles at the "
                    "centres of a lattice of squares, the default) or 'patch' (the patch's own "
                    "particles)"
                )
            if not isinstance(material, LinearElastic):
                raise TypeError(f"material must be a LinearElastic, got {type(material).__name__}")
            if V.mesh is not patch.mesh:
                raise ValueError("V and patch must live on the same mesh object")
            if isinstance(smoothing, bool) or not (
                isinstance(smoothing, int | float) and math.isfinite(smoothing) and smoothing > 0
            ):
                raise ValueError(
                    f"smoothing={smoothing!r} must be a positive number (the smoothing length "
                    "over the particle spacing; 1.3 is usual)"
                )
            for name, deg in (
                ("quadrature_degree", quadrature_degree),
                ("hybrid_degree", hybrid_degree),
            ):
                if deg is not None and (
                    isinstance(deg, bool) or not isinstance(deg, int) or deg < 1
                ):
                    raise ValueError(f"{name}={deg!r} must be a positive integer or None")

            if not isinstance(consistent, bool | np.bool_):
                raise ValueError(f"consistent={consistent!r} must be True or False")
            if isinstance(nitsche, bool) or not (
                isinstance(nitsche, int | float) and math.isfinite(nitsche) and nitsche >= 0
            ):
                raise ValueError(
                    f"nitsche={nitsche!r} must be a number >= 0 (Nitsche's parameter of the "
                    "patch's essential conditions, 10.0 by default; 0 for multipliers)"
                )
            if isinstance(multiplier_length, bool) or not (
                isinstance(multiplier_length, int | float)
                and math.isfinite(multiplier_length)
                and multiplier_length >= 0
            ):
                raise ValueError(
                    f"multiplier_length={multiplier_length!r} must be a number >= 0 (the "
                    "length of the pieces of a patch Dirichlet boundary that carry one "
                    "multiplier, in particle spacings; 2.0 is the default, 0 one per facet)"
                )

        raise_on_all_ranks(comm, check)
        if integration is None:
            integration = "smoothed" if variant == "HA-F" else "cells"
        if particles is None:
            particles = "centred" if variant == "HA-F" else "patch"
        t0 = time.perf_counter()
        self.consistent = bool(consistent)
        self.multiplier_length = float(multiplier_length)
        self.nitsche = float(nitsche)
        self.variant, self.integration = variant, integration
        # the median nearest-neighbour distance, but not below the spacing the patch was asked
        # for: the conforming placement's border particles (at the FE nodes) are closer than the
        # grid, and a kernel sized on them leaves the interior particles of a coarse grid with
        # too few neighbours (singular corrections at spacing 1.5 h)
        self.spacing = max(particle_spacing_median(patch.particles.positions), patch.spacing or 0.0)
        if particles == "centred":
            patch = copy.copy(patch)
            patch.particles = centred_particles(patch, self.spacing)
        #: The patch whose particles carry the particle field (a copy with the SPH particles of
        #: ``particles="centred"``).
        self.V, self.patch, self.material = V, patch, material
        P = patch.particles
        self.smoothing_length = float(smoothing) * self.spacing
        msh = V.mesh
        q0 = cell_quadrature(msh, 1)
        area = np.bincount(np.searchsorted(np.unique(q0.cells), q0.cells), weights=q0.weights)
        s = comm.allreduce(np.array([np.sqrt(area).sum(), area.size], dtype=float), op=MPI.SUM)
        self.cell_size = float(s[0] / s[1])
        ratio = self.cell_size / self.spacing
        if quadrature_degree is None:
            quadrature_degree = 2 * max(2, math.ceil(2.0 * ratio - 1e-9)) - 1
        if hybrid_degree is None:
            hybrid_degree = 2 * max(1, math.ceil(ratio - 1e-9)) - 1
        self.quadrature_degree, self.hybrid_degree = int(quadrature_degree), int(hybrid_degree)
        radius = 2.0 * self.smoothing_length
        self.hybrid = hybrid_points(V, patch.fe_cells, P.positions, radius, self.hybrid_degree)
        hp = self.hybrid
        #: The hybrid sums: particles first, then the FE integration points (eq. 125-126).
        self.sph = raise_on_all_ranks(
            comm,
            lambda: CorrectedSPH(
                np.vstack([P.positions, hp.points]),
                np.concatenate([P.volumes, hp.weights]),
                self.smoothing_length,
            ),
        )
        #: The particles' own interpolant: displacement in the patch, loads, masses.
        self.evaluator = raise_on_all_ranks(
            comm, lambda: CorrectedSPH(P.positions, P.volumes, self.smoothing_length)
        )
        self._smoothing = None
        self._smoothed: tuple[list[sp.csr_matrix], np.ndarray] | None = None
        self._dirichlet: list[tuple[np.ndarray, VectorFunction]] = []
        self._tractions: list[tuple[np.ndarray, Callable]] = []
        self._body_forces: list[CallableBodyForce] = []
        self._setup = time.perf_counter() - t0

    # -- user data ------------------------------------------------------------------------------

    @property
    def comm(self):
        return self.patch.comm

    def add_dirichlet(self, facets: np.ndarray, value: VectorFunction) -> None:
        """``u = value(x)`` on owned exterior facets (FE side strongly, patch side by facet
        multipliers); ``value`` maps points (m, 2) to (m, 2)."""
        self._dirichlet.append((np.asarray(facets, dtype=np.int32), value))

    def add_traction(self, facets: np.ndarray, traction: Callable) -> None:
        """Traction ``traction(x, n)`` (m, 2) on owned exterior facets, on either side."""
        self._tractions.append((np.asarray(facets, dtype=np.int32), traction))

    def set_body_force(self, force: VectorFunction) -> None:
        """Body force per unit volume ``b(x)`` (m, 2) on the whole body (replaces a previous
        one), as :meth:`CoupledElasticity.set_body_force
        <dolfinx_meshfree.CoupledElasticity.set_body_force>`: ``int N_a b`` over the FE cells and
        ``int phi_c b`` over the patch cells, ``phi_c`` the functions of the hybrid sums over
        particles and FE nodes (eq. 125-126: the displacement whose strains the particle energy
        holds, so the load is its work conjugate), on the patch cells' Gauss rule of degree
        :attr:`quadrature_degree`. (With the particles' own interpolant instead, as before, the
        FE nodes near the interface got no share of the patch's load: up to 42 x the plain FE
        error in the robustness matrix, against at most 3.9 x.)"""
        self._body_forces = [CallableBodyForce(force)]

    # -- numbering ------------------------------------------------------------------------------

    def _node_map(self) -> sp.csr_matrix:
        """``Z = diag(I, E)``: values of the hybrid sums' points from [particles | FE nodes]."""
        n = self.patch.particles.num_particles
        return sp.bmat([[sp.identity(n, format="csr"), None], [None, self.hybrid.interpolation]])

    def _dof_map(self) -> np.ndarray:
        """Combined dof of each interleaved column ``2 c + i`` of [particles | FE nodes]:
        particle PETSc dofs ``0 .. 2n-1``, then ``2n +`` the FE global dofs."""
        P = self.patch.particles
        n = P.num_particles
        N = self.hybrid.interpolation.shape[1]
        return np.concatenate([P.petsc_dofs(2).ravel(), 2 * n + np.arange(2 * N)])

    def _split(self, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exterior facets beside FE cells and beside patch cells."""
        msh = self.V.mesh
        msh.topology.create_connectivity(msh.topology.dim - 1, msh.topology.dim)
        f2c = msh.topology.connectivity(msh.topology.dim - 1, msh.topology.dim)
        first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
        on_p = self.patch.in_patch[first]
        return facets[~on_p], facets[on_p]

    # -- operators ------------------------------------------------------------------------------

    def stress_points(self) -> QuadraturePoints:
        """This rank's stress points of the particle energy: Gauss points of its patch cells
        (``"cells"``), the centroids of the smoothing cells with their areas (``"smoothed"``)
        or its owned particles with their volumes (``"particles"``)."""
        if self.integration == "cells":
            return cell_quadrature(self.V.mesh, self.quadrature_degree, self.patch.cells)
        if self.integration == "smoothed":
            sc = self._smoothing_cells()
            return QuadraturePoints(sc.centroids, sc.areas, sc.cells)
        P = self.patch.particles
        own = P.owned
        return QuadraturePoints(
            P.positions[own], P.volumes[own], np.full(own.size, -1, dtype=np.int64)
        )

    def _strain_rows(self, points: np.ndarray) -> sp.csr_matrix:
        """Strain operator (3m x 2(n + N)) of the hybrid sums at ``points`` over [particles |
        FE nodes] (eq. 126/128 with the correction; collective for the error)."""
        t = raise_on_all_ranks(self.comm, lambda: self.sph.tabulate(points))
        Z = self._node_map()
        return strain_operator([(g @ Z).tocsr() for g in t.gradients])

    def _consistent_test_gradients(
        self, values: sp.csr_matrix, grads: list[sp.csr_matrix], weights: np.ndarray
    ) -> list[sp.csr_matrix]:
        """Integration-consistent test gradients (Chen, Hillman & Rüter 2013) of the hybrid
        sums over [particles | FE nodes] (collective).

        ``Ghat_c = G_c + xi_c Nhat_c`` with one vector per column so that
        ``sum_q Ghat_c(x_q) w_q = b_c``, the boundary term of the divergence theorem of the
        patch: for a particle ``b_J = int N_J n`` over the patch's exterior facets (``N_J`` the
        particles' interpolant, the functions of the traction loads); for an FE node
        ``b_a = int N_a n_P`` over the interface (the FE trace, ``n_P`` out of the patch), which
        cancels the FE cells' own boundary term ``int N_a n_FE``. With these, a linear field
        leaves no force at any dof but the loaded boundary's (patch test), for either variant.
        """
        V, patch, comm, msh = self.V, self.patch, self.comm, self.V.mesh
        P = patch.particles
        n = P.num_particles
        N = self.hybrid.interpolation.shape[1]
        deg = max(self.quadrature_degree, 4)
        target = np.zeros((n + N, 2))
        eq = facet_quadrature(msh, patch.exterior_facets, deg, patch.exterior_cells)
        et = raise_on_all_ranks(comm, lambda: self.evaluator.tabulate(eq.points, 0)).values
        target[:n] = et.T @ (eq.weights[:, None] * eq.normals)
        iq = facet_quadrature(msh, patch.interface_facets, deg, patch.interface_patch_cells)
        it = tabulate_in_cells(V, iq.points, patch.interface_fe_cells[_facet_index(iq)], 0)
        _, l2g = fe_dof_layout(self.V)
        fl = it.values.T @ (iq.weights[:, None] * iq.normals)  # (local FE nodes, 2)
        np.add.at(target, n + l2g[: fl.shape[0]], fl)
        integral = np.stack([g.T @ weights for g in grads], axis=1)
        volume = values.T @ weights
        sums = comm.allreduce(np.hstack([target, integral, volume[:, None]]), op=MPI.SUM)
        target, integral, volume = sums[:, :2], sums[:, 2:4], sums[:, 4]
        used = np.abs(volume) > 1e-12 * np.abs(volume).max()
        xi = np.where(used[:, None], (target - integral) / np.where(used, volume, 1.0)[:, None], 0)
        return [(g + values @ sp.diags(xi[:, k])).tocsr() for k, g in enumerate(grads)]

    def _smoothing_cells(self):
        """This rank's smoothing cells (``"smoothed"``): ``(quadrature_degree + 1) // 2``
        sub-cells per patch cell and direction, as many as the Gauss points of ``"cells"``."""
        if self._smoothing is None:
            n = max(1, (self.quadrature_degree + 1) // 2)
            self._smoothing = smoothing_cells(self.V.mesh, self.patch.cells, self.patch.in_patch, n)
        return self._smoothing

    def _smoothed_gradients(self) -> tuple[list[sp.csr_matrix], np.ndarray]:
        """Smoothed gradients (ns x (n + N)) of this rank's smoothing cells over [particles |
        FE nodes] and the cells' areas (collective;
        :mod:`~dolfinx_meshfree.couplings.hybrid_smoothing`):
        ``(1 / |Omega_k|) sum_p w_p n_p N_c(x_p)`` over the Gauss points of the cell's edges,
        ``N_c`` the hybrid sums' functions inside the patch, the particles' own interpolant on
        the exterior boundary (the functions of the traction loads) and the FE basis on the
        interface.
        """
        if self._smoothed is not None:
            return self._smoothed
        sc = self._smoothing_cells()
        n = self.patch.particles.num_particles
        N = self.hybrid.interpolation.shape[1]
        inner = np.flatnonzero(sc.fe_cell == INTERIOR)
        # an edge inside the patch belongs to two sub-cells: tabulate its points once
        key = np.round(sc.points[inner] / (1e-9 * self.spacing)).astype(np.int64)
        _, first, back = np.unique(key, axis=0, return_index=True, return_inverse=True)
        pts = sc.points[inner[first]]
        t = raise_on_all_ranks(self.comm, lambda: self.sph.tabulate(pts, 0))
        T = (t.values @ self._node_map()).tocsr()[back.ravel()].tocoo()
        rows, cols, vals = [inner[T.row]], [T.col], [T.data]
        outer = np.flatnonzero(sc.fe_cell == EXTERIOR)
        t = raise_on_all_ranks(self.comm, lambda: self.evaluator.tabulate(sc.points[outer], 0))
        T = t.values.tocoo()
        rows, cols, vals = [*rows, outer[T.row]], [*cols, T.col], [*vals, T.data]
        iface = np.flatnonzero(sc.fe_cell >= 0)
        if iface.size:
            _, l2g = fe_dof_layout(self.V)
            tf = tabulate_in_cells(self.V, sc.points[iface], sc.fe_cell[iface], 0).values.tocoo()
            rows.append(iface[tf.row])
            cols.append(n + l2g[tf.col])
            vals.append(tf.data)
        m = sc.points.shape[0]
        T = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, n + N)
        )
        ns = sc.areas.size
        grads = []
        for d in range(2):
            R = sp.csr_matrix(
                (sc.normals[:, d] / sc.areas[sc.owner], (sc.owner, np.arange(m))), shape=(ns, m)
            )
            grads.append((R @ T).tocsr())
        self._smoothed = (grads, sc.areas)
        return self._smoothed

    def particle_energy_matrix(self) -> sp.coo_matrix:
        """``sum_q w_q Bhat_q^T D B_q`` of this rank's stress points in the combined numbering
        of :meth:`_dof_map` (collective); ``Bhat = B`` unless ``consistent``. With
        ``"smoothed"``: ``sum_k |Omega_k| B_k^T D B_k`` of the smoothed strains (symmetric and
        consistent; ``consistent`` has no effect)."""
        D = sp.csr_matrix(self.material.voigt())
        dof = self._dof_map()
        if self.integration == "smoothed":
            grads, areas = self._smoothed_gradients()
            B = strain_operator(grads)
            K = (B.T @ sp.kron(sp.diags(areas), D, format="csr") @ B).tocoo()
            return sp.coo_matrix((K.data, (dof[K.row], dof[K.col])), shape=K.shape)
        q = self.stress_points()
        t = raise_on_all_ranks(self.comm, lambda: self.sph.tabulate(q.points))
        Z = self._node_map()
        grads = [(g @ Z).tocsr() for g in t.gradients]
        B = strain_operator(grads)
        Bt = B
        if self.consistent:
            shepard = (t.values @ Z).tocsr()
            Bt = strain_operator(self._consistent_test_gradients(shepard, grads, q.weights))
        K = (Bt.T @ sp.kron(sp.diags(q.weights), D, format="csr") @ B).tocoo()
        return sp.coo_matrix((K.data, (dof[K.row], dof[K.col])), shape=K.shape)

    def traction_matrix(self) -> sp.coo_matrix:
        """HA-S: ``-F`` of eq. 131–134 as a matrix (FE rows, combined numbering), this rank's
        owned interface edges (collective).

        For each end node ``k`` of an interface edge (length ``l``, normal ``n`` out of the FE
        cell), the visible particles ``(X_J - X_k) . n >= 0`` within the kernel support give the
        stress ``P_k = sum_J N_J P_J / sum_J N_J`` (eq. 131, ``N_J = V_J W``), the traction
        ``n . P_k`` (eq. 132–133) and the node force ``l/2 n . P_k`` (eq. 134); the internal
        force is its negative.
        """
        V, patch, comm = self.V, self.patch, self.comm
        msh = V.mesh
        P = patch.particles
        facets = patch.interface_facets
        fe_cells = patch.interface_fe_cells
        ends = msh.geometry.x[_compat.entities_to_geometry(msh, 1, facets), :2].reshape(-1, 2, 2)
        tvec = ends[:, 1] - ends[:, 0]
        length = np.linalg.norm(tvec, axis=1)
        normal = np.stack([tvec[:, 1], -tvec[:, 0]], axis=1) / np.maximum(length, 1e-300)[:, None]
        centroid = msh.geometry.x[_compat.geometry_dofmap(msh)[fe_cells], :2].mean(axis=1)
        mid = ends.mean(axis=1)
        flip = np.einsum("fi,fi->f", mid - centroid, normal) < 0.0
        normal[flip] *= -1.0
        xe = ends.reshape(-1, 2)  # the two end nodes of each edge
        ne = np.repeat(normal, 2, axis=0)
        half = np.repeat(0.5 * length, 2)
        _, l2g = fe_dof_layout(self.V)
        tab = tabulate_in_cells(V, xe, np.repeat(fe_cells, 2), derivatives=0).values.tocoo()
        at_node = tab.data > 0.5  # N_a(X_k) = 1 at the edge's own nodes
        node = np.full(xe.shape[0], -1, dtype=np.int64)
        node[tab.row[at_node]] = l2g[tab.col[at_node]]
        radius = 2.0 * self.smoothing_length
        i, j, dx = pairs_within_support(xe, P.positions, np.full(P.num_particles, radius))
        tol = 1e-10 * self.spacing
        visible = np.einsum("pi,pi->p", -dx, ne[i]) >= -tol  # visibility criterion
        i, j, dx = i[visible], j[visible], dx[visible]
        W, _ = sph_cubic_spline(
            np.linalg.norm(dx, axis=1) / self.smoothing_length, self.smoothing_length, 2
        )
        w = P.volumes[j] * W
        total = np.bincount(i, weights=w, minlength=xe.shape[0])

        def check() -> None:
            blind = np.flatnonzero(total <= 0.0)
            if blind.size:
                k = int(blind[0])
                raise ValueError(
                    f"HA-S: {blind.size} interface node(s) see no particle within the kernel "
                    f"support {radius:.3g}; first at {xe[k]}: increase smoothing or the particle "
                    "density near the interface"
                )
            if np.any(node < 0):
                raise ValueError("HA-S: an interface edge end is not an FE node of its cell")

        raise_on_all_ranks(comm, check)
        w = w / np.where(total > 0, total, 1.0)[i]
        # stresses of the particles in use, D B_J (eq. 131's P(X_J))
        used, jj = np.unique(j, return_inverse=True)
        B = self._strain_rows(P.positions[used])  # (3 nu x 2(n+N))
        S = sp.kron(sp.identity(used.size), sp.csr_matrix(self.material.voigt()), format="csr") @ B
        # A: Voigt stresses of the used particles -> node forces l/2 w (n . P)
        coef = half[i] * w
        nx, ny = ne[i, 0], ne[i, 1]
        n = P.num_particles
        r0 = 2 * n + 2 * node[i]
        rows = np.concatenate([r0, r0, r0 + 1, r0 + 1])
        cols = np.concatenate([3 * jj, 3 * jj + 2, 3 * jj + 2, 3 * jj + 1])
        vals = np.concatenate([coef * nx, coef * ny, coef * nx, coef * ny])
        N = self.hybrid.interpolation.shape[1]
        A = sp.csr_matrix((vals, (rows, cols)), shape=(2 * (n + N), 3 * used.size))
        K = (-(A @ S)).tocoo()
        dof = self._dof_map()
        return sp.coo_matrix((K.data, (K.row, dof[K.col])), shape=K.shape)

    def operators(self, extra: sp.coo_matrix | None = None) -> CouplingOperators:
        """The assembled operators without essential conditions (collective): ``K_fe`` (FE
        cells, plus the FE-FE hybrid block), ``K_p``, ``K_fp``, ``K_pf``; the FE weight (the FE
        cells' indicator), the active FE nodes, the stress points and the particles' values
        there (row-sum masses). See :class:`~dolfinx_meshfree.CouplingOperators`."""
        t0 = time.perf_counter()
        comm, P = self.comm, self.patch.particles
        n = P.num_particles
        fe_layout, _ = fe_dof_layout(self.V)
        pl = self.patch.particles.dof_layout()
        K = self.particle_energy_matrix()
        if self.variant == "HA-S":  # particle rows from the energy, FE rows from tractions
            keep = K.row < 2 * n
            K = sp.coo_matrix((K.data[keep], (K.row[keep], K.col[keep])), shape=K.shape)
            T = self.traction_matrix()
            K = sp.coo_matrix(
                (np.r_[K.data, T.data], (np.r_[K.row, T.row], np.r_[K.col, T.col])), shape=K.shape
            )
        if extra is not None:  # statics: Nitsche's terms of the patch's essential conditions
            K = (K.tocsr() + extra.tocsr()).tocoo()
        K = K.tocsr()
        N2 = K.shape[0] - 2 * n

        def block(rows: slice, cols: slice, shape) -> sp.csr_matrix:
            return K[rows, cols].tocsr() if K.nnz else sp.csr_matrix(shape)

        p, f = slice(0, 2 * n), slice(2 * n, K.shape[0])
        K_pp = create_aij(comm, block(p, p, (2 * n, 2 * n)), pl, pl)
        K_pf = create_aij(comm, block(p, f, (2 * n, N2)), pl, fe_layout)
        K_fp = create_aij(comm, block(f, p, (N2, 2 * n)), fe_layout, pl)
        K_ff = create_aij(comm, block(f, f, (N2, N2)), fe_layout, fe_layout)
        chi = cell_indicator(self.V.mesh, ~self.patch.in_patch)
        u, v = ufl.TrialFunction(self.V), ufl.TestFunction(self.V)
        a = chi * ufl.inner(self.material.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
        K_fe = _compat.assemble_matrix(_compat.create_form(a))
        K_fe.axpy(1.0, K_ff, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        K_ff.destroy()
        q = self.stress_points()
        table = raise_on_all_ranks(comm, lambda: self.evaluator.tabulate(q.points, 0))
        return CouplingOperators(
            coupling="hybrid",
            K_fe=K_fe,
            K_p=K_pp,
            K_fp=K_fp,
            K_pf=K_pf,
            fe_weight=chi,
            fe_active=node_flags(self.V, _compat.dofmap_array(self.V)[self.patch.fe_cells].ravel()),
            particle_quadrature=q,
            particle_table=table.values.tocsr(),
            fe_layout=fe_layout,
            particle_layout=pl,
            timings={"operators": time.perf_counter() - t0},
        )

    # -- statics --------------------------------------------------------------------------------

    def _loads(self, extra: np.ndarray | None = None) -> tuple[PETSc.Vec, PETSc.Vec]:
        """Traction and body loads: FE basis on FE facets and cells, the particles' interpolant
        on patch facets and cells (collective; patch facets with ``"smoothed"`` by the smoothing
        cells' edge rule, so that the loads of a constant stress are the boundary terms of the
        particle energy)."""
        V, comm, msh = self.V, self.comm, self.V.mesh
        P = self.patch.particles
        fe_layout, l2g = fe_dof_layout(self.V)
        pl = self.patch.particles.dof_layout()
        deg = max(self.quadrature_degree, 4)
        rows, vals = [np.zeros(0, np.int64)], [np.zeros(0)]
        f_p = np.zeros(2 * P.num_particles)
        for facets, fn in self._tractions:
            f_fe, f_pf = self._split(facets)
            for sel, side in ((f_fe, "fe"), (f_pf, "p")):
                if side == "p" and self.integration == "smoothed":
                    q = self._smoothing_cells().exterior_quadrature(msh, _global_facets(msh, sel))
                else:
                    q = facet_quadrature(msh, sel, deg)
                t = raise_on_all_ranks(
                    comm, lambda fn=fn, q=q: _vector_values(fn, (q.points, q.normals), len(q), "t")
                )
                if side == "fe":
                    tab = tabulate_in_cells(V, q.points, q.cells, derivatives=0).values
                    fl = load_vector(tab, q.weights, t).reshape(-1, 2)
                    rows.append((2 * l2g[: fl.shape[0], None] + np.arange(2)).ravel())
                    vals.append(fl.ravel())
                else:
                    tab = raise_on_all_ranks(
                        comm, lambda q=q: self.evaluator.tabulate(q.points, 0)
                    ).values
                    f_p += load_vector(tab, q.weights, t)
        fe = None
        if extra is not None:  # interleaved [particles | FE nodes] (Nitsche's terms)
            n2 = 2 * P.num_particles
            f_p += extra[:n2]
            hit = np.flatnonzero(extra[n2:])
            rows.append(hit)
            vals.append(extra[n2:][hit])
        if self._body_forces:
            q = cell_quadrature(msh, self.quadrature_degree, self.patch.cells)
            chi = cell_indicator(msh, ~self.patch.in_patch)
            # the hybrid sums' functions over [particles | FE nodes] (eq. 125): the displacement
            # whose strains the particle energy holds, so the load is its work conjugate
            t = raise_on_all_ranks(comm, lambda: self.sph.tabulate(q.points, 0))
            table = (t.values @ self._node_map()).tocsr()
            fe, fp = body_load_vectors(self._body_forces, V, chi, deg, (q, table), comm=comm)
            n2 = 2 * P.num_particles
            f_p += fp[:n2]
            hit = np.flatnonzero(fp[n2:])
            rows.append(hit)
            vals.append(fp[n2:][hit])
        b_fe = create_vector(comm, fe_layout, np.concatenate(rows), np.concatenate(vals))
        if fe is not None:
            b_fe.array[:] += fe
        b_p = create_vector(comm, pl, P.petsc_dofs(2).ravel(), f_p)
        return b_fe, b_p

    def _nitsche(self, conditions: list) -> tuple[sp.coo_matrix, np.ndarray]:
        """Nitsche's terms (Nitsche 1971, symmetric) of ``u = ubar`` on patch facets with
        smoothed strains (collective):
        ``-int (t(u).v + t(v).u) + beta int u.v`` and ``-int t(v).ubar + beta int v.ubar`` over
        the exterior edge points of the smoothing cells on those facets, ``t = D B_k n`` the
        traction of the smoothed strain of the edge's sub-cell, ``u`` the particles' interpolant
        (the functions of the traction loads), ``beta = nitsche * max(D) / h_k`` with ``h_k``
        the sub-cell's size. Returns ``K`` (combined numbering) and ``f`` (interleaved
        [particles | FE nodes], this rank's share)."""
        msh, comm = self.V.mesh, self.comm
        sc = self._smoothing_cells()
        n = self.patch.particles.num_particles
        N = self.hybrid.interpolation.shape[1]
        grads, areas = self._smoothed_gradients()
        B = strain_operator(grads).tocsr()  # (3 ns x 2(n + N))
        Dm = self.material.voigt()
        dof = self._dof_map()
        Ks, f = [], np.zeros(2 * (n + N))
        for facets, fn in conditions:
            on = np.flatnonzero(
                (sc.fe_cell == EXTERIOR) & np.isin(sc.facet, _global_facets(msh, facets))
            )
            w = np.linalg.norm(sc.normals[on], axis=1)
            nrm = sc.normals[on] / np.maximum(w, 1e-300)[:, None]
            x = sc.points[on]
            k = sc.owner[on]
            g = raise_on_all_ranks(
                comm, lambda fn=fn, x=x: _vector_values(fn, (x,), len(x), "dirichlet")
            )
            t = raise_on_all_ranks(comm, lambda x=x: self.evaluator.tabulate(x, 0)).values.tocoo()
            m = on.size
            # U: (2m x 2(n + N)) values of the particles' interpolant, interleaved
            U = sp.csr_matrix(
                (
                    np.r_[t.data, t.data],
                    (np.r_[2 * t.row, 2 * t.row + 1], np.r_[2 * t.col, 2 * t.col + 1]),
                ),
                shape=(2 * m, 2 * (n + N)),
            )
            # T: (2m x 2(n + N)) tractions N_n D B_k
            Nn = np.zeros((m, 2, 3))
            Nn[:, 0, 0], Nn[:, 0, 2] = nrm[:, 0], nrm[:, 1]
            Nn[:, 1, 1], Nn[:, 1, 2] = nrm[:, 1], nrm[:, 0]
            ND = Nn @ Dm  # (m, 2, 3)
            rows3 = (3 * k[:, None] + np.arange(3)).ravel()
            Bk = B[rows3]  # (3m x ...)
            NDm = sp.block_diag(list(ND), format="csr") if m else sp.csr_matrix((0, 0))
            T = (NDm @ Bk).tocsr() if m else sp.csr_matrix((0, 2 * (n + N)))
            beta = self.nitsche * np.max(np.diag(Dm)) / np.sqrt(areas[k])
            W = sp.diags(np.repeat(w, 2))
            Wb = sp.diags(np.repeat(w * beta, 2))
            K = -(U.T @ W @ T) - (T.T @ W @ U) + U.T @ Wb @ U
            Ks.append(K.tocoo())
            gv = g.ravel()
            f += -(T.T @ (np.repeat(w, 2) * gv)) + U.T @ (np.repeat(w * beta, 2) * gv)
        K = sum(Ks[1:], Ks[0]).tocoo() if Ks else sp.coo_matrix((2 * (n + N),) * 2)
        return sp.coo_matrix((K.data, (dof[K.row], dof[K.col])), shape=K.shape), f

    def _check_multipliers(self, pieces: list[FacetGroups]) -> None:
        """Refuse linearly dependent multipliers of the patch's essential conditions, on every
        rank before the solve (collective): the rows ``int_g phi_J`` of all pieces ``g`` (the
        same on every rank: the particles are replicated) must have full rank, or the saddle
        point is singular and its solution garbage
        (:func:`~dolfinx_meshfree.geometry.facet_groups.constraint_rank_check`)."""
        rows, where = [], []
        deg = max(self.quadrature_degree, 4)
        for groups in pieces:
            q = groups.quadrature(deg)
            m = np.arange(len(q))
            S = sp.csr_matrix((q.weights, (q.entities, m)), shape=(groups.num_groups, len(q)))
            t = raise_on_all_ranks(self.comm, lambda q=q: self.evaluator.tabulate(q.points, 0))
            rows.append(S @ t.values)
            where.append(np.stack([S @ q.points[:, k] for k in range(2)], axis=1))
            where[-1] /= (S @ np.ones(len(q)))[:, None]
        raise_on_all_ranks(
            self.comm,
            lambda: constraint_rank_check(
                sp.vstack(rows).tocsr(), np.vstack(where), "HybridElasticity"
            ),
        )

    def solve(self, solver: str = "mumps") -> CoupledSolution:
        """Assemble ``K u = f`` with the essential conditions and solve it (collective).

        FE facets' conditions are strong (rows and columns of the FE dofs removed, values lifted
        into the right-hand side, also through ``K_pf``); patch facets' conditions are
        Nitsche's terms (``"smoothed"`` with ``nitsche > 0``) or multipliers on pieces of the
        boundary (a third field of the nest). FE nodes that no FE cell holds are fixed at 0.

        Raises:
            ValueError: on every rank, before the solve, if the patch's multipliers are linearly
                dependent (the saddle point would be singular).

        Args:
            solver: ``"mumps"`` (LU of the nest as AIJ; ``K`` is not symmetric with ``HA-S``).

        Returns:
            A :class:`~dolfinx_meshfree.CoupledSolution` (FE function, particle values, the
            particles' interpolant for the patch cells).
        """
        if solver not in ("mumps", "fieldsplit"):
            raise ValueError(f"solver={solver!r} is not known; use 'mumps' or 'fieldsplit'")
        V, comm, msh = self.V, self.comm, self.V.mesh
        P = self.patch.particles
        t0 = time.perf_counter()
        nitsche = self.integration == "smoothed" and self.nitsche > 0 and bool(self._dirichlet)
        conditions = [(self._split(f)[1], fn) for f, fn in self._dirichlet]
        K_n, f_n = self._nitsche(conditions) if nitsche else (None, None)
        ops = self.operators(K_n)
        b_fe, b_p = self._loads(f_n)
        assemble = time.perf_counter() - t0
        fe_layout, l2g = fe_dof_layout(self.V)
        n_owned = V.dofmap.index_map.size_local
        # strong conditions on FE facets, zero on inactive FE nodes
        fixed = ~ops.fe_active.copy()
        values = np.zeros((fixed.size, 2))
        coords = V.tabulate_dof_coordinates()[:, :2]
        patch_bc, dq, pieces = [], [], []
        for facets, fn in self._dirichlet:
            f_fe, f_pf = self._split(facets)
            flags = node_flags(
                self.V, dolfinx.fem.locate_dofs_topological(V, msh.topology.dim - 1, f_fe)
            )
            xn = coords[flags]
            vals = raise_on_all_ranks(
                comm, lambda fn=fn, xn=xn: _vector_values(fn, (xn,), len(xn), "dirichlet")
            )
            values[flags] = vals
            fixed |= flags
            if nitsche:
                continue
            patch_bc.append((f_pf, fn))
            pieces.append(
                grouped_facet_quadrature(msh, f_pf, self.multiplier_length * self.spacing)
            )
            dq.append(pieces[-1].quadrature(max(self.quadrature_degree, 4), comm.rank))
        if pieces:
            self._check_multipliers(pieces)
        own = np.flatnonzero(fixed[:n_owned])
        rows = (2 * l2g[own][:, None] + np.arange(2)).ravel().astype(PETSc.IntType)
        x_bc = create_vector(comm, fe_layout, rows, values[own].ravel())
        mask = create_vector(comm, fe_layout, np.zeros(0, np.int64), np.zeros(0))
        mask.set(1.0)
        mask.setValues(rows, np.zeros(rows.size), addv=PETSc.InsertMode.INSERT_VALUES)
        mask.assemble()
        t1 = time.perf_counter()
        K_fe, K_p, K_fp, K_pf = ops.K_fe, ops.K_p, ops.K_fp, ops.K_pf
        _lift(K_pf, x_bc, b_p)  # b_p -= K_pf x_bc
        K_pf.diagonalScale(R=mask)
        K_fp.diagonalScale(L=mask)
        K_fe.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        zero = K_fe.createVecLeft()
        zero.set(0.0)
        K_fe.setDiagonal(zero, addv=PETSc.InsertMode.ADD_VALUES)
        zero.destroy()
        K_fe.zeroRowsColumns(rows, diag=1.0, x=x_bc, b=b_fe)
        blocks = [[K_fe, K_fp], [K_pf, K_p]]
        rhs = [b_fe, b_p]
        mats = [K_fe, K_p, K_fp, K_pf]
        dtabs = [
            raise_on_all_ranks(comm, lambda d=d: self.evaluator.tabulate(d.points, 0)) for d in dq
        ]
        ml = Layout(0, 0, 0)
        if patch_bc:
            Gd, d_rows, d_vals, ml = facet_multipliers(P, patch_bc, dq, dtabs, self.material.E)
            if ml.size_global:
                pl = self.patch.particles.dof_layout()
                D = create_aij(comm, Gd, ml, pl)
                DT = create_aij(comm, Gd.T.tocsr(), pl, ml)
                blocks = [[K_fe, K_fp, None], [K_pf, K_p, DT], [None, D, None]]
                rhs.append(create_vector(comm, ml, d_rows, d_vals))
                mats += [D, DT]
        assemble += time.perf_counter() - t1
        system = BlockSystem(blocks, rhs, num_primal=2)
        t2 = time.perf_counter()
        parts = system.solve(solver)
        solve = time.perf_counter() - t2
        system.destroy()
        for obj in [*mats, *rhs, x_bc, mask]:
            obj.destroy()
        uh = dolfinx.fem.Function(V)
        uh.x.array[: 2 * n_owned] = parts[0]
        uh.x.scatter_forward()
        coeffs = np.concatenate(comm.allgather(parts[1])).reshape(-1, 2)[P.petsc_index]
        return CoupledSolution(
            u=uh,
            coefficients=coeffs,
            mls=self.evaluator,
            patch=self.patch,
            timings={"setup": self._setup, "assemble": assemble, "solve": solve},
            sizes={
                "fe_dofs": 2 * comm.allreduce(int(np.sum(ops.fe_active[:n_owned]))),
                "particle_dofs": 2 * P.num_particles,
                "multiplier_dofs": ml.size_global,
                "hybrid_points": self.hybrid.num_points,
            },
        )


def _global_facets(msh, facets: np.ndarray) -> np.ndarray:
    """The given owned facets of every rank, as local facet indices of this rank where it
    holds them (collective): an exterior facet that one rank owns may bound a cell that another
    rank owns."""
    fmap = msh.topology.index_map(msh.topology.dim - 1)
    n_local = fmap.size_local + fmap.num_ghosts
    to_global = np.asarray(fmap.local_to_global(np.arange(n_local, dtype=np.int32)))
    wanted = np.concatenate(msh.comm.allgather(to_global[np.asarray(facets, dtype=np.int64)]))
    return np.flatnonzero(np.isin(to_global, wanted))


def _facet_index(q: QuadraturePoints) -> np.ndarray:
    """Position of each facet quadrature point's facet in the facet list it was made from."""
    _, index = np.unique(q.entities, return_inverse=True)
    return index


def _lift(A: PETSc.Mat, x: PETSc.Vec, b: PETSc.Vec) -> None:
    """``b -= A x``."""
    y = A.createVecLeft()
    A.mult(x, y)
    b.axpy(-1.0, y)
    y.destroy()
