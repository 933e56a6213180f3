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
(:func:`~dolfinx_meshfree.couplings.hybrid_strains.consistent_test_gradients`): the linear patch
test holds to round-off, and ``K`` is no longer symmetric (central differences then do not conserve
energy).

The SPH particles of HA-F (``particles``, default ``"centred"`` with HA-F) sit at the centres of a
lattice of squares with the squares' areas as volumes
(:func:`~dolfinx_meshfree.couplings.hybrid_sph.centred_particles`), not on the patch's own grid
through the interface nodes (see :mod:`~dolfinx_meshfree.couplings.hybrid_sph` for why: with that
grid the rod's error depended on the particle:node ratio).

Essential conditions in statics: strongly on FE facets; on patch facets by Nitsche's method with the
smoothed strains (``"smoothed"``, the default;
:func:`~dolfinx_meshfree.couplings.hybrid_boundary.nitsche_terms`), otherwise by piecewise-constant
multipliers on pieces of the boundary at least ``multiplier_length`` particle spacings long
(:mod:`~dolfinx_meshfree.geometry.facet_groups`). One multiplier per facet, as
:class:`~dolfinx_meshfree.CoupledElasticity` has, outnumbers the centred particles near the boundary
once the spacing reaches the element size: the constraint block loses rank and the solve returned
garbage (on the gmsh square with particles at 1.5 h, 1.1e6 x the plain FE error); dependent
multipliers are now refused with a ``ValueError`` before the solve. The displacement in the patch
cells is the particles' own :class:`~dolfinx_meshfree.couplings.hybrid_sph.CorrectedSPH`
interpolant; body loads on the patch cells go to the dofs through the hybrid sums' functions (eq.
125), the displacement whose strains the particle energy holds.

Conditions by component (``add_dirichlet(..., components=)``: a roller, a symmetry plane, the
axis): the FE nodes' held components strongly; on the patch facets Nitsche's terms of those
components or multipliers per piece and component.

Axisymmetric models (``LinearElastic(..., plane="axisymmetric")``, HA-F): the strains smoothed
over revolved sub-cells (:func:`~dolfinx_meshfree.couplings.hybrid_strains.smoothed_gradients`:
the edges carry ``r u``, the hoop is the hybrid sums at the centroid over ``r``), or Gauss points
with VCI and the hoop term; the FE form, the loads, the masses and Nitsche's terms revolved
(``docs/guide/axisymmetry.md``). HA-S and nodal integration are refused there.

Module map: :mod:`~dolfinx_meshfree.couplings.hybrid_discretisation` (options, particles, hybrid
sums, numbering, stress points), :mod:`~dolfinx_meshfree.couplings.hybrid_strains` (particle
energy, consistent and smoothed strains), :mod:`~dolfinx_meshfree.couplings.hybrid_traction`
(HA-S), :mod:`~dolfinx_meshfree.couplings.hybrid_loads`,
:mod:`~dolfinx_meshfree.couplings.hybrid_boundary` (essential conditions); this module assembles
the operators and solves.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import dolfinx
import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from .. import _compat
from ..geometry.patch import ParticlePatch
from ..parallel import raise_on_all_ranks
from ..physics.body_loads import CallableBodyForce
from ..physics.materials import LinearElastic
from ..physics.user_functions import check_arguments, check_facets
from ..statics.kept_factor import KeptFactorisation, check_kept
from ..statics.petsc import BlockSystem, create_aij
from .base import (
    CoupledSolution,
    CouplingOperators,
    cell_indicator,
    fe_dof_layout,
    material_stiffness_form,
    node_flags,
)
from .hybrid_boundary import (
    apply_strong_conditions,
    multiplier_blocks,
    nitsche_terms,
    strong_conditions,
)
from .hybrid_discretisation import (
    HYBRID_INTEGRATIONS,
    HYBRID_PARTICLES,
    HYBRID_VARIANTS,
    HybridDiscretisation,
)
from .hybrid_loads import hybrid_loads
from .hybrid_strains import particle_energy_matrix, smoothed_gradients
from .hybrid_traction import traction_matrix

__all__ = ["HYBRID_INTEGRATIONS", "HYBRID_PARTICLES", "HYBRID_VARIANTS", "HybridElasticity"]

VectorFunction = Callable[[np.ndarray], np.ndarray]


class HybridElasticity(HybridDiscretisation):
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
            lattice of squares of the patch's particle spacing, none on the interface, each with the
            area of its square in the patch as its volume
            (:func:`~dolfinx_meshfree.couplings.hybrid_sph.centred_particles`); :attr:`patch` is
            then a copy of the given patch holding these particles. ``"patch"`` (default for HA-S):
            the patch's own particles and Voronoi volumes. Those put a particle on every interface
            FE node (a compliant double layer that reflects waves) and their sampled volumes scatter
            when the spacing does not divide the cells: the rod's error then depended on the
            particle:node ratio (see :mod:`~dolfinx_meshfree.couplings.hybrid_sph`). HA-S keeps
            them: its node stresses (eq. 131) average the particles that an interface node sees,
            which are then at the node; with centred particles its static L2 rate fell below 1 in 14
            of the 90 cases of ``demos/robustness.py`` (1 with the patch's particles).
        consistent: Integration-consistent test gradients (Chen, Hillman & Rüter 2013; see
            :func:`~dolfinx_meshfree.couplings.hybrid_strains.consistent_test_gradients`): the
            linear patch test holds to round-off, at the price of a ``K`` that is not symmetric.
            ``False``: the symmetric ``sum_q w_q B_q^T D B_q``, whose background-cell integration of
            the corrected kernel gradients leaves forces of the order of the stress times the
            spacing at the particles near exterior boundaries (the patch test is missed).
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
        V: dolfinx.fem.FunctionSpace,
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
    ) -> None:
        super().__init__(
            V,
            patch,
            material,
            variant=variant,
            smoothing=smoothing,
            quadrature_degree=quadrature_degree,
            hybrid_degree=hybrid_degree,
            integration=integration,
            consistent=consistent,
            particles=particles,
            multiplier_length=multiplier_length,
            nitsche=nitsche,
        )
        self._smoothed: tuple[list[sp.csr_matrix], np.ndarray] | None = None
        self._dirichlet: list[tuple[np.ndarray, VectorFunction, tuple[int, ...]]] = []
        self._tractions: list[tuple[np.ndarray, Callable]] = []
        self._body_forces: list[CallableBodyForce] = []

    # -- user data ------------------------------------------------------------------------------

    def add_dirichlet(
        self, facets: np.ndarray, value: VectorFunction, components: tuple[int, ...] | None = None
    ) -> None:
        """``u = value(x)`` on owned exterior facets (FE side strongly, patch side by facet
        multipliers); ``value`` maps points (m, 2) to (m, 2). ``components`` holds only those
        (a roller, a symmetry plane, the axis of an axisymmetric model: ``(0,)``): the FE
        nodes' components strongly, the patch facets' by one multiplier per piece and
        component (or Nitsche's terms of those components, ``"smoothed"``)."""
        check_arguments(value, 1, "the Dirichlet value")
        c = (0, 1) if components is None else tuple(components)

        def check() -> None:
            if not c or len(set(c)) != len(c) or any(k not in (0, 1) for k in c):
                raise ValueError(f"components={components!r} must be distinct indices in 0..1")

        raise_on_all_ranks(self.comm, check)
        facets = check_facets(self.V.mesh, facets, "add_dirichlet: facets")
        self._dirichlet.append((facets, value, c))

    def add_traction(self, facets: np.ndarray, traction: Callable) -> None:
        """Traction ``traction(x, n)`` (m, 2) on owned exterior facets, on either side."""
        check_arguments(traction, 2, "traction")
        facets = check_facets(self.V.mesh, facets, "add_traction: facets")
        self._tractions.append((facets, traction))

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

    def _nitsche(self) -> bool:
        """Whether the patch's essential conditions are Nitsche's terms (``"smoothed"`` with
        ``nitsche > 0``), by component too, axisymmetric too
        (:func:`~dolfinx_meshfree.couplings.hybrid_boundary.nitsche_terms`)."""
        return self.integration == "smoothed" and self.nitsche > 0

    # -- operators ------------------------------------------------------------------------------

    def _smoothed_gradients(self) -> tuple[list[sp.csr_matrix], np.ndarray]:
        """The smoothed gradients and areas of this rank's smoothing cells, computed once
        (:func:`~dolfinx_meshfree.couplings.hybrid_strains.smoothed_gradients`; collective)."""
        if self._smoothed is None:
            self._smoothed = smoothed_gradients(self)
        return self._smoothed

    def particle_energy_matrix(self) -> sp.coo_matrix:
        """``sum_q w_q Bhat_q^T D B_q`` of this rank's stress points in the combined numbering
        (collective; :func:`~dolfinx_meshfree.couplings.hybrid_strains.particle_energy_matrix`):
        eq. 127 as the derivative of the particle strain energy."""
        smoothed = self._smoothed_gradients() if self.integration == "smoothed" else None
        return particle_energy_matrix(self, smoothed)

    def traction_matrix(self) -> sp.coo_matrix:
        """HA-S: ``-F`` of eq. 131–134 as a matrix (FE rows, combined numbering; collective;
        :func:`~dolfinx_meshfree.couplings.hybrid_traction.traction_matrix`)."""
        return traction_matrix(self)

    def operators(self, extra: sp.coo_matrix | None = None) -> CouplingOperators:
        """The assembled operators without essential conditions (collective): ``K_fe`` (FE
        cells, plus the FE-FE hybrid block), ``K_p``, ``K_fp``, ``K_pf``; the FE weight (the FE
        cells' indicator), the active FE nodes, the stress points and the particles' values
        there (row-sum masses). See :class:`~dolfinx_meshfree.CouplingOperators`.

        Args:
            extra: Statics: Nitsche's terms of the patch's essential conditions (combined
                numbering), added to ``K``.
        """
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

        def block(rows: slice, cols: slice, shape: tuple[int, int]) -> sp.csr_matrix:
            return K[rows, cols].tocsr() if K.nnz else sp.csr_matrix(shape)

        p, f = slice(0, 2 * n), slice(2 * n, K.shape[0])
        K_pp = create_aij(comm, block(p, p, (2 * n, 2 * n)), pl, pl)
        K_pf = create_aij(comm, block(p, f, (2 * n, N2)), pl, fe_layout)
        K_fp = create_aij(comm, block(f, p, (N2, 2 * n)), fe_layout, pl)
        K_ff = create_aij(comm, block(f, f, (N2, N2)), fe_layout, fe_layout)
        chi = cell_indicator(self.V.mesh, ~self.patch.in_patch)
        a = material_stiffness_form(self.material, self.V, chi)  # axisymmetric: hoop, 2 pi r
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
        """Traction and body loads (collective;
        :func:`~dolfinx_meshfree.couplings.hybrid_loads.hybrid_loads`), ``extra`` Nitsche's
        terms (interleaved [particles | FE nodes])."""
        return hybrid_loads(self, self._tractions, self._body_forces, extra)

    def solve(
        self, solver: str = "mumps", kept: KeptFactorisation | None = None
    ) -> CoupledSolution:
        """Assemble ``K u = f`` with the essential conditions and solve it (collective).

        FE facets' conditions are strong (rows and columns of the FE dofs removed, values lifted
        into the right-hand side, also through ``K_pf``); patch facets' conditions are
        Nitsche's terms (``"smoothed"`` with ``nitsche > 0``) or multipliers on pieces of the
        boundary (a third field of the nest). FE nodes that no FE cell holds are fixed at 0
        (:mod:`~dolfinx_meshfree.couplings.hybrid_boundary`).

        Raises:
            ValueError: on every rank, before the solve, if the patch's multipliers are linearly
                dependent (the saddle point would be singular).

        Args:
            solver: ``"mumps"`` (LU of the nest as AIJ; ``K`` is not symmetric with ``HA-S``).
            kept: The direct solve's factorisation shared with earlier solves (a load sweep:
                :meth:`~dolfinx_meshfree.CoupledElasticity.solve`).

        Returns:
            A :class:`~dolfinx_meshfree.CoupledSolution` (FE function, particle values, the
            particles' interpolant for the patch cells).
        """
        if solver not in ("mumps", "fieldsplit"):
            raise ValueError(f"solver={solver!r} is not known; use 'mumps' or 'fieldsplit'")
        check_kept(kept)
        V, comm = self.V, self.comm
        P = self.patch.particles
        t0 = time.perf_counter()
        nitsche = self._nitsche() and bool(self._dirichlet)
        conditions = [(self.split(f)[1], fn, c) for f, fn, c in self._dirichlet]
        if nitsche:
            K_n, f_n = nitsche_terms(self, conditions, self._smoothed_gradients())
        else:
            K_n, f_n = None, None
        ops = self.operators(K_n)
        b_fe, b_p = self._loads(f_n)
        assemble = time.perf_counter() - t0
        n_owned = V.dofmap.index_map.size_local
        bc = strong_conditions(self, self._dirichlet, ops.fe_active, nitsche)
        t1 = time.perf_counter()
        apply_strong_conditions(ops, bc, b_fe, b_p)
        K_fe, K_p, K_fp, K_pf = ops.K_fe, ops.K_p, ops.K_fp, ops.K_pf
        blocks = [[K_fe, K_fp], [K_pf, K_p]]
        rhs = [b_fe, b_p]
        mats = [K_fe, K_p, K_fp, K_pf]
        mult, ml = multiplier_blocks(self, bc)
        if mult is not None:
            blocks = [[K_fe, K_fp, None], [K_pf, K_p, mult.DT], [None, mult.D, None]]
            rhs.append(mult.rhs)
            mats += [mult.D, mult.DT]
        assemble += time.perf_counter() - t1
        system = BlockSystem(blocks, rhs, num_primal=2)
        t2 = time.perf_counter()
        parts = system.solve(solver, kept=kept)
        solve = time.perf_counter() - t2
        system.destroy()
        for obj in [*mats, *rhs, bc.x_bc, bc.mask]:
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
