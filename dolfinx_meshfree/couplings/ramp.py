"""FE–EFG coupling by interface elements with a ramp function (Belytschko et al. 1995, sec. 3.2).

The patch cells are the EFG domain Omega_E. Gamma_E is the set of FE nodes on the patch
interface; the interface elements Omega_I are the FE cells (outside the patch) with at least one
node on Gamma_E. In an interface cell the displacement blends the two approximations (eq. 3.12)

.. math::
    u^h = (1 - R) \\sum_a N_a u_a + R \\sum_J \\phi_J u_J, \\qquad
    R = \\sum_{a \\in \\Gamma_E} N_a \\quad (3.13),

with gradients by the product rule (eq. 3.16). ``coupling="ramp-cubic"`` replaces ``R`` by the
smoothed ramp ``3R^2 - 2R^3`` (Rabczuk, Xiao & Sauer 2006, eq. 38–42). The nodes on Gamma_E are
particles: the shape function ``(1 - R) N_a`` of a Gamma_E node belongs to the dof of the
particle at the node's position (a :class:`~dolfinx_meshfree.ParticlePatch` puts particles on
the patch border's nodes whatever its spacing; see :func:`ramp_mls` for the supports), so
the FE dofs of Gamma_E are inactive like those inside the patch. The blended shape functions
are a partition of unity and reproduce linear fields (eq. 3.17), so the coupling needs no
interface multipliers.

Assembly, in a PETSc nest ``[[K_FE, K_FP], [K_PF, K_P]]`` (plus patch-side Dirichlet
multipliers):

* pure FE cells: DOLFINx's assembly of the FE form (the material's, or the user's form of a
  :class:`~dolfinx_meshfree.CoupledLinearProblem`) weighted by the DG0 indicator of these cells;
* interface cells: Gauss points, the blended table with columns ``[local FE nodes | particles]``
  and ``K = B^T D B``; its FE–FE part is a PETSc AIJ matrix added to DOLFINx's matrix with
  ``MatAXPY`` (``DIFFERENT_NONZERO_PATTERN``: DOLFINx's sparsity has no room for interface
  cells), the particle–particle part joins the EFG stiffness, the FE–particle parts are the
  off-diagonal blocks;
* patch cells: EFG as in :func:`~dolfinx_meshfree.statics.efg.particle_stiffness`.

Loads use the same functions: tractions on facets of interface cells and body forces on the
interface cells are integrated against the blended functions (the FE part ``(1 - R) N_a`` on the
FE nodes, ``R phi_J`` and the Gamma_E nodes' ``(1 - R) N_a`` on the particles), body forces on
pure FE cells against ``N_a`` and on patch cells against ``phi_J``
(:mod:`~dolfinx_meshfree.physics.body_loads`).

Essential conditions act strongly on FE nodes. Where the particle part of an interface cell
reaches a Dirichlet facet (an exterior facet of an interface cell), it is constrained like the
patch facets, by piecewise-constant multipliers on ``u^h - ubar`` with the known FE part moved
to the right-hand side.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, ClassVar

import dolfinx
import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from .. import _compat
from ..approx.fe_points import tabulate_in_cells
from ..approx.mls import MLS
from ..approx.tables import ShapeTable
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import (
    QuadraturePoints,
    boundary_facets,
    cell_quadrature,
    facet_quadrature,
)
from ..parallel import Layout, raise_on_all_ranks
from ..physics.axisymmetry import (
    approximation_hoop,
    axisymmetric_stiffness,
    hoop_table,
    revolved_if,
)
from ..physics.body_loads import StressRule
from ..physics.operators import consistent_gradients, load_vector, stiffness_matrix
from ..physics.user_functions import vector_values
from ..statics.baij import create_baij
from ..statics.efg import crack_rules, particle_stiffness
from ..statics.kept_factor import KeptFactorisation
from ..statics.petsc import SolverOptions, create_aij, create_vector
from ..statics.sides import BlendedSide
from .assembly import (
    append_patch_conditions,
    body_loads,
    essential_conditions,
    fe_active,
    fe_stiffness,
    fix_fe_rows,
    pin_forces,
    sizes,
    solve_and_gather,
    split_facets,
    strong_values,
)
from .base import (
    CoupledSolution,
    CouplingOperators,
    facet_nodes,
    fe_dof_layout,
    interface_node_flags,
)

if TYPE_CHECKING:  # annotations only: the model imports this module
    from ..statics.coupled import CoupledElasticity

__all__ = ["RAMPS", "RampInterface", "ramp_mls", "ramp_operators", "ramp_system", "solve_ramp"]


#: The ramp couplings and whether each smooths the ramp (3R^2 - 2R^3).
RAMPS = {"ramp": False, "ramp-cubic": True}


def _interface_element_size(patch: ParticlePatch) -> float:
    """The longest interface facet of the patch on any rank (collective; 0 without interface)."""
    msh = patch.mesh
    fdim = msh.topology.dim - 1
    h = 0.0
    if patch.interface_facets.size:
        ends = msh.geometry.x[_compat.entities_to_geometry(msh, fdim, patch.interface_facets), :2]
        h = float(np.linalg.norm(ends[:, -1] - ends[:, 0], axis=1).max())
    return patch.comm.allreduce(h, op=MPI.MAX)


def _interface_reach(patch: ParticlePatch) -> tuple[np.ndarray, np.ndarray]:
    """The reach of the interface elements (FE cells with a vertex on Gamma_E) at each Gamma_E
    node: the largest distance from a vertex of an interface element that has the node to the
    nearest Gamma_E node (collective; identical on every rank). One element size beside a
    straight interface, the cell's diagonal where a staircase interface touches a cell at one
    corner.

    Returns:
        ``(gamma, rho)``: the Gamma_E nodes (k, 2), sorted, and their reach (k,).
    """
    msh, comm = patch.mesh, patch.comm
    fdim = msh.topology.dim - 1
    geo = _compat.entities_to_geometry(msh, fdim, patch.interface_facets)
    gamma = np.concatenate(comm.allgather(msh.geometry.x[geo.ravel(), :2]))
    if gamma.shape[0] == 0:
        return gamma, np.zeros(0)
    tol = 1e-10 * max(np.ptp(gamma, axis=0).max(), 1.0)
    _, first = np.unique(np.round(gamma / tol).astype(np.int64), axis=0, return_index=True)
    gamma = gamma[np.sort(first)]
    order = np.lexsort(gamma.T[::-1])
    gamma = gamma[order]
    tree = cKDTree(gamma)
    fe = patch.fe_cells
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[fe], :2]  # (cells, vertices, 2)
    dist, nearest = tree.query(nodes.reshape(-1, 2))
    dist, nearest = dist.reshape(nodes.shape[:2]), nearest.reshape(nodes.shape[:2])
    on = dist <= tol
    touching = on.any(axis=1)
    reach = dist.max(axis=1)
    rho = np.zeros(gamma.shape[0])
    cell, vertex = np.nonzero(on & touching[:, None])
    np.maximum.at(rho, nearest[cell, vertex], reach[cell])
    comm.Allreduce(MPI.IN_PLACE, rho, op=MPI.MAX)
    return gamma, rho


def ramp_mls(mls: MLS, patch: ParticlePatch) -> MLS:
    """The MLS of a ramp coupling: support radii ``d_max max(c_I, rho_I)``, where ``rho_I`` is
    the largest reach ``rho_g`` of the Gamma_E nodes ``g`` within ``d_max rho_g`` of particle
    ``I`` (0 for the others, whose radii stay eq. 3.11's ``d_max c_I``; collective).

    ``c_I`` is eq. 3.11's nodal spacing and ``rho_g`` the reach of the interface elements at
    ``g``: the largest distance from a vertex of an interface element that has the node ``g`` to
    Gamma_E (:func:`_interface_reach`; the element size ``h`` beside a straight interface, the
    diagonal at a staircase's corners). The particle functions must span the interface elements
    up to their FE side (eq. 3.12): a point of an interface element lies within ``rho_g`` of one
    of its Gamma_E nodes ``g``, and every particle within ``(d_max - 1) rho_g`` of ``g`` reaches
    it. ``d_max c_I`` does that when the particles are as far apart as the nodes (``c_I = h``,
    the paper's set-up, whose radii these are): finer particles would reach no further than the
    interface row there, whose particles are collinear. Where ``c_I >= rho_I`` the radii are
    eq. 3.11's. (A reach of ``(d_max - 1) c_I + rho`` is enough to be non-singular, but at
    0.5 h it left the FE-side corners to the tails of the weights: 2.25x the FE error on the
    robustness matrix's square, against 1.0x with these radii.) The reach is the local one: with
    the largest reach of the whole interface (before), elements of very different sizes along
    Gamma_E (a ring around a hole in a mapped mesh, particles at the hole's element size) gave
    every particle the widest supports: 20x lagrange's time on the Kirsch plate at 32 cells per
    sector side, against 13x with the local reach (the rest is the price of particles 2-3x finer
    than the interface elements; at their size, 2.7x). Particles on the vertices
    (``placement="vertices"``, the paper's set-up) have ``c_I`` about ``rho`` beside a straight
    interface, so their radii are eq. 3.11's there; at a staircase interface's corners the
    diagonal reach widens them too (before, they kept eq. 3.11's and the ramp refused the
    Kirsch plate's ring: the corners of interface cells outside every support).
    """
    gamma, rho = _interface_reach(patch)
    if gamma.shape[0] == 0:
        return mls
    c = mls.radii / mls.dilation
    rho_p = np.zeros(mls.points.shape[0])
    tree = cKDTree(mls.points)
    for g, near in enumerate(tree.query_ball_point(gamma, mls.dilation * rho)):
        if near:
            idx = np.asarray(near, dtype=np.int64)
            rho_p[idx] = np.maximum(rho_p[idx], rho[g])
    radii = mls.dilation * np.maximum(c, rho_p)
    if np.all(radii <= mls.radii):
        return mls
    return MLS(mls.points, mls.weight_name, mls.dilation, mls.basis, radii=radii, rcond=mls.rcond)


class RampInterface:
    """Interface elements of a :class:`~dolfinx_meshfree.CoupledElasticity` with a ramp coupling.

    Collective to construct. Raises ``ValueError`` (on every rank) when an FE node on the patch
    interface has no particle at its position.

    Attributes:
        on_gamma: bool per local node of ``V``: the node lies on Gamma_E (the patch interface).
        particle_of_node: per local node, the particle at its position (-1 off Gamma_E).
        in_interface: bool per local cell (owned and ghost): an interface element.
        cells: Owned interface cells (local indices).
        cubic: Whether the smoothed ramp ``3R^2 - 2R^3`` is used.
    """

    def __init__(self, problem: CoupledElasticity, cubic: bool = False) -> None:
        V, patch = problem.V, problem.patch
        msh = V.mesh
        comm = patch.comm
        self.V, self.mls, self.cubic = V, problem.mls, bool(cubic)
        # The same MLS functions, accepting ill-conditioned moment matrices: towards the FE side
        # of an interface cell the particles in support approach a line (with the default
        # dilation 2 they are the interface particles alone on the far edge, where R = 0 and the
        # particle part vanishes); there phi is multiplied by a vanishing ramp.
        m = problem.mls
        self._mls = MLS(m.points, m.weight_name, m.dilation, m.basis, radii=m.radii, rcond=0.0)
        self._mls.pair_cuts = list(m.pair_cuts)  # the bodies' cut (ramps refuse cracks)
        self.num_particles = patch.particles.num_particles
        self.on_gamma = interface_node_flags(V, patch)
        self.coordinates = V.tabulate_dof_coordinates()[:, :2]
        dofs = _compat.dofmap_array(V)
        self.in_interface = ~patch.in_patch & self.on_gamma[dofs[: patch.in_patch.size]].any(axis=1)
        n_owned = msh.topology.index_map(msh.topology.dim).size_local
        self.cells = np.flatnonzero(self.in_interface[:n_owned]).astype(np.int32)

        # the element size: the longest interface facet (on any rank)
        h = _interface_element_size(patch)
        self.tolerance = 1e-10 * h
        positions = patch.particles.positions

        def match() -> np.ndarray:
            g = np.flatnonzero(self.on_gamma)
            owner = np.full(self.on_gamma.size, -1, dtype=np.int64)
            if g.size == 0:
                return owner
            dist, idx = cKDTree(positions).query(self.coordinates[g])
            bad = np.flatnonzero(dist > self.tolerance)
            if bad.size:
                k = g[bad[0]]
                raise ValueError(
                    f"{bad.size} FE node(s) on the patch interface have no particle at their "
                    f"position (within {self.tolerance:.1e}); first: the node at "
                    f"{np.array2string(self.coordinates[k], precision=6)}, nearest particle "
                    f"{dist[bad[0]]:.3e} away. The ramp couplings need particles on the "
                    f"interface nodes (Belytschko et al. 1995, sec. 3.2), which "
                    f"ParticlePatch(placement={patch.placement!r}) did not put there: use "
                    "ParticlePatch(..., placement='conforming') (the default, any spacing) or "
                    "placement='vertices'"
                )
            owner[g] = idx
            return owner

        self.particle_of_node = raise_on_all_ranks(comm, match)

        # the particle supports must cover the interface cells up to their FE side: check the
        # MLS (strictly conditioned) near every vertex of every interface cell
        nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[self.cells], :2]
        near = nodes + 1e-3 * (nodes.mean(axis=1, keepdims=True) - nodes)
        raise_on_all_ranks(comm, lambda: self._check_supports(near.reshape(-1, 2)))
        n_loc = self.on_gamma.size
        # columns of the FE part: a node off Gamma_E keeps its own column, a node on Gamma_E goes
        # to its particle's column (after the n_loc FE columns)
        col = np.where(self.on_gamma, n_loc + self.particle_of_node, np.arange(n_loc))
        self._route = sp.csr_matrix(
            (np.ones(n_loc), (np.arange(n_loc), col)), shape=(n_loc, n_loc + self.num_particles)
        )

    def blended_facets(self, facets: np.ndarray) -> np.ndarray:
        """The given exterior facets on which the particle part of the blended functions lives:
        facets of interface cells with a node on Gamma_E (elsewhere ``R = 0`` on the facet, and
        a constraint on the particle part there would be an empty row)."""
        msh = self.V.mesh
        facets = np.asarray(facets, dtype=np.int32)
        if facets.size == 0:
            return facets

        keep = self.in_interface[_first_cells(msh, facets)]
        keep &= self.on_gamma[facet_nodes(self.V, facets)].any(axis=1)
        return facets[keep]

    def _check_supports(self, points: np.ndarray) -> None:
        try:
            self.mls.tabulate(points, 0)
        except ValueError as e:
            raise type(e)(
                "the particle supports do not cover the ramp's interface cells (the FE cells "
                f"beside the patch; the points checked lie just inside their corners): {e}. "
                f"The supports have radii d_max max(c_I, rho_I) (see ramp_mls) with "
                f"dilation d_max = {self.mls.dilation}: increase dilation, or choose a particle "
                "spacing closer to the interface elements' size"
            ) from e

    @property
    def num_fe_columns(self) -> int:
        """Number of FE columns of :meth:`table` (local nodes of ``V``); particles follow."""
        return self.on_gamma.size

    def column_positions(self) -> np.ndarray:
        """Positions (n_loc + n, 2) of the columns of :meth:`table`: FE nodes, then particles."""
        return np.vstack([self.coordinates, self.mls.points])

    def ramp(self, points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ramp ``R`` (m,) and its gradient (m, 2) at points of the given local cells (the
        smoothed ramp with ``cubic``)."""
        t = tabulate_in_cells(self.V, points, cells)
        return self._ramp(t)

    def _ramp(self, t: ShapeTable) -> tuple[np.ndarray, np.ndarray]:
        return self._ramps(t)[:2]

    def _ramps(self, t: ShapeTable) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(R, dR, linear ramp): the (smoothed) ramp, its gradient and eq. 3.13's ramp."""
        g = self.on_gamma.astype(float)
        r = t.values @ g
        dr = np.stack([d @ g for d in t.gradients], axis=1) if t.gradients else None
        if not self.cubic:
            return r, dr, r
        if dr is not None:
            dr = (6.0 * r - 6.0 * r**2)[:, None] * dr
        return 3.0 * r**2 - 2.0 * r**3, dr, r

    def table(self, points: np.ndarray, cells: np.ndarray, derivatives: int = 1) -> ShapeTable:
        """Blended shape functions (eq. 3.15–3.16) at points of local interface cells.

        Columns: the ``n_loc`` local FE nodes of ``V`` (nodes on Gamma_E have empty columns),
        then the particles. Local (MLS is evaluated on this rank).
        """
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        n_loc = self.num_fe_columns
        if points.shape[0] == 0:
            empty = sp.csr_matrix((0, n_loc + self.num_particles))
            return ShapeTable(points, empty, [empty.copy() for _ in range(2 * derivatives)])
        t_fe = tabulate_in_cells(self.V, points, cells, derivatives=1)
        r, dr, linear = self._ramps(t_fe)
        # particles only where the ramp is positive: on the FE side (R = 0) the particles in
        # support may be collinear, and the particle part vanishes (its gradient dR phi is
        # dropped on that edge only, a set of measure zero)
        where = np.flatnonzero(linear > 1e-12)
        pick = sp.csr_matrix(
            (np.ones(where.size), (where, np.arange(where.size))), shape=(len(points), where.size)
        )
        t_p = self._mls.tabulate(points[where], derivatives)
        t_p = ShapeTable(points, pick @ t_p.values, [pick @ d for d in t_p.gradients])
        pad = sp.csr_matrix((len(points), n_loc))

        def blend(fe: sp.csr_matrix, p: sp.csr_matrix) -> sp.csr_matrix:
            return (fe @ self._route + sp.hstack([pad, p])).tocsr()

        values = blend(sp.diags(1.0 - r) @ t_fe.values, sp.diags(r) @ t_p.values)
        grads = []
        if derivatives:
            for k in range(2):
                d = sp.diags(dr[:, k])
                fe = sp.diags(1.0 - r) @ t_fe.gradients[k] - d @ t_fe.values
                grads.append(blend(fe, d @ t_p.values + sp.diags(r) @ t_p.gradients[k]))
        return ShapeTable(points=points, values=values, gradients=grads)

    def evaluate(
        self, points: np.ndarray, cells: np.ndarray, fe_values: np.ndarray, coefficients: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Displacement (m, 2) and gradient (m, 2, 2) of the blended field in interface cells."""
        c = np.vstack([fe_values, coefficients])
        t = self.table(points, cells)
        return t.values @ c, t.gradient(c)


def _interface_rule(problem: CoupledElasticity, blend: RampInterface) -> tuple:
    """The interface cells' Gauss rule, the blended table there (columns: local FE nodes, then
    particles) and, for an axisymmetric law, its hoop table ``N / r`` (the rule then revolved,
    ``2 pi r w``). Returns ``(q, table, hoop)`` (collective).

    The hoop is the plain ``N / r`` in interface cells that touch the axis too. Taking the axis
    offset off, as the patch cells do (:func:`~dolfinx_meshfree.physics.axisymmetry.
    approximation_hoop`), was tried with the blended functions evaluated at the points'
    projections on the axis in the same cells. It missed the axisymmetric patch test by 5.5e-3
    (triangles), where the plain hoop passes it to round-off (5.2e-15). The blended table keeps
    the particle part only where the ramp is positive, which such a projection need not be."""
    msh, comm = problem.V.mesh, problem.patch.comm
    q = cell_quadrature(msh, problem.quadrature_degree, blend.cells)
    if problem.material.axisymmetric:
        q = raise_on_all_ranks(comm, lambda: revolved_if(q, problem.material))
    tab = raise_on_all_ranks(comm, lambda: blend.table(q.points, q.cells))
    hoop = None
    if problem.material.axisymmetric:
        hoop = raise_on_all_ranks(comm, lambda: hoop_table(tab.values, q.points))
    return q, tab, hoop


def _blended_stiffness(
    problem: CoupledElasticity, test: list, q: QuadraturePoints, tab: ShapeTable, hoop
) -> sp.csr_matrix:
    """The interface cells' ``sum_q B_test^T D B w_q`` on the blended table (axisymmetric: with
    the ``hoop`` rows, ``q`` revolved)."""
    if hoop is not None:
        return axisymmetric_stiffness(test, hoop, q.weights, problem.material, tab.gradients)
    return stiffness_matrix(test, q.weights, problem.material, tab.gradients)


def _fe_stiffness(problem: CoupledElasticity, interface: RampInterface) -> PETSc.Mat:
    """DOLFINx assembly of the FE form on the pure FE cells (not interface, not patch)."""
    pure = ~problem.patch.in_patch & ~interface.in_interface
    return fe_stiffness(problem, problem.cell_indicator(pure))


def ramp_system(problem: CoupledElasticity, tables: dict | None = None) -> tuple:
    """The ramp-coupled block system, assembled, not solved (collective); see
    :func:`~dolfinx_meshfree.couplings.lagrange.interface_system` for ``tables`` (the patch
    cells' quadrature, MLS table and test gradients) and the returned ``(blocks, rhs, mats,
    extra)``. ``extra`` also holds what a finite-strain solve needs: the external loads before
    lifting (``loads``), the pure FE cells (``fe_cells``), ``shared_sides(fe, particles,
    material)``: the interface cells' :class:`~dolfinx_meshfree.statics.sides.BlendedSide` on
    the blended table of eq. 3.15-3.16 (columns ``[local FE nodes | particles]``, particle
    columns' test gradients VCI corrected when consistent), whose FE-particle blocks replace
    the linear ones (``state_blocks``), and the :class:`RampInterface` (``interface``)."""

    V, patch, P = problem.V, problem.patch, problem.patch.particles
    comm = patch.comm
    msh = V.mesh
    deg = problem.quadrature_degree
    n = P.num_particles
    pdofs = P.petsc_dofs(2)
    fe_layout, l2g = fe_dof_layout(problem.V)
    pl = P.dof_layout()
    t0 = time.perf_counter()

    blend = RampInterface(problem, cubic=RAMPS[problem.coupling])
    n_loc = blend.num_fe_columns
    tables = {} if tables is None else tables  # the stiffness's rule: the loads' stresses too
    # interface cells: the blended table (columns: local FE nodes, then particles)
    qi, ti, hoop = _interface_rule(problem, blend)
    test = ti.gradients
    if problem.consistent:
        Kp_loc, kt, test = _consistent_stiffness(problem, blend, qi, ti, tables, hoop)
    else:
        Kp_loc, _, _, kt = particle_stiffness(
            P, problem.mls, problem.material, deg, quadrature=_patch_rule(problem), tables=tables
        )

    # essential conditions: FE nodes strongly; patch facets and the particle part of interface
    # cells' facets by multipliers
    fe_bc, patch_bc, dq, dtabs, ubc, is_bc = essential_conditions(problem)
    held_dofs, known = strong_values(problem, is_bc, ubc)  # whole nodes and components
    # whole nodes, then components: the particle part of the interface cells' facets
    held = [(f, fn) for f, fn in fe_bc] + [(f, fn, c) for f, fn, c in problem.component_dirichlet]
    for f, fn, *components in held:
        f_i = blend.blended_facets(f)  # interface cells' facets only (none of the patch's)
        if not comm.allreduce(f_i.size):
            continue
        iq = revolved_if(facet_quadrature(msh, f_i, deg), problem.material, True)
        tab = raise_on_all_ranks(comm, lambda iq=iq: blend.table(iq.points, iq.cells, 0))
        ubar = raise_on_all_ranks(
            comm,
            lambda fn=fn, iq=iq: vector_values(fn, (iq.points,), len(iq), "the Dirichlet value"),
        )
        # the FE part is known (strong values, by node or by the held components): constrain
        # the particle part to the rest
        rest = ubar - tab.values[:, :n_loc] @ known
        patch_bc.append((f_i, lambda x, rest=rest: rest, *components))
        dq.append(iq)
        dtabs.append(ShapeTable(iq.points, tab.values[:, n_loc:].tocsr(), []))
    # active FE nodes: nodes of FE cells (interface cells included) that are not on Gamma_E
    active = fe_active(problem) & ~blend.on_gamma
    fixed_local = is_bc | ~active

    setup = problem.setup_time + time.perf_counter() - t0 - kt["assemble"]

    # interface cells: blended stiffness split into FE/particle blocks
    t1 = time.perf_counter()
    Ki = _blended_stiffness(problem, test, qi, ti, hoop).tocoo()
    # dof map of the blended columns: FE (2 a + i) -> 2 l2g[a] + i; particles -> PETSc dofs
    nf = 2 * n_loc
    fe_dof = (2 * l2g[:, None] + np.arange(2)).ravel()
    is_fe_r, is_fe_c = Ki.row < nf, Ki.col < nf
    pr = Ki.row[~is_fe_r] - nf
    pc = Ki.col[~is_fe_c] - nf
    prow = np.zeros(Ki.row.size, dtype=np.int64)
    pcol = np.zeros(Ki.col.size, dtype=np.int64)
    prow[~is_fe_r] = pdofs[pr // 2, pr % 2]
    pcol[~is_fe_c] = pdofs[pc // 2, pc % 2]
    # every dof held strongly, whole nodes and components, with its value (the FE rows of a
    # held component must go too, and its column be lifted)
    fixed_dof = (held_dofs | fixed_local[:, None]).ravel()
    x_fix = np.where(np.repeat(is_bc, 2), ubc.x.array, 0.0)
    x_held = known.ravel()
    ff = is_fe_r & is_fe_c
    K_ff = sp.csr_matrix(
        (Ki.data[ff], (fe_dof[Ki.row[ff]], fe_dof[Ki.col[ff]])), shape=(fe_layout.size_global,) * 2
    )
    pp = ~is_fe_r & ~is_fe_c
    Kp_loc = Kp_loc + sp.csr_matrix((Ki.data[pp], (prow[pp], pcol[pp])), shape=(2 * n, 2 * n))
    # FE rows of fixed dofs vanish; FE columns of fixed dofs move their known values to b_p
    fp = is_fe_r & ~is_fe_c & ~fixed_dof[np.minimum(Ki.row, nf - 1)]
    K_fp = sp.csr_matrix(
        (Ki.data[fp], (fe_dof[Ki.row[fp]], pcol[fp])), shape=(fe_layout.size_global, 2 * n)
    )
    pf = ~is_fe_r & is_fe_c
    col_fixed = fixed_dof[np.minimum(Ki.col, nf - 1)]
    keep = pf & ~col_fixed
    K_pf = sp.csr_matrix(
        (Ki.data[keep], (prow[keep], fe_dof[Ki.col[keep]])), shape=(2 * n, fe_layout.size_global)
    )
    lift = pf & col_fixed
    f_lift = np.zeros(2 * n)
    # particle loads in interleaved particle order (2 J + i), like the EFG loads
    inv = np.empty(2 * n, dtype=np.int64)
    inv[pdofs.ravel()] = np.arange(2 * n)
    np.add.at(f_lift, inv[prow[lift]], -Ki.data[lift] * x_held[Ki.col[lift]])
    f_p = np.zeros(2 * n)

    # loads: FE facets of pure FE cells with the FE basis, of interface cells blended
    f_fe_rows, f_fe_vals = [], []
    for facets, fn in problem.tractions:
        f_fe_facets, f_p_facets = split_facets(problem, facets)
        inter = blend.in_interface[_first_cells(msh, f_fe_facets)]
        for part, use_blend in ((f_fe_facets[~inter], False), (f_fe_facets[inter], True)):
            fq = revolved_if(facet_quadrature(msh, part, deg), problem.material)
            t = raise_on_all_ranks(
                comm,
                lambda fn=fn, fq=fq: vector_values(
                    fn, (fq.points, fq.normals), len(fq), "traction"
                ),
            )
            if use_blend:
                bt = raise_on_all_ranks(comm, lambda fq=fq: blend.table(fq.points, fq.cells, 0))
                fl = load_vector(bt.values, fq.weights, t)
                f_p += fl[nf:]
                fl = fl[:nf].reshape(-1, 2)
            else:
                bt = tabulate_in_cells(V, fq.points, fq.cells, derivatives=0)
                fl = load_vector(bt.values, fq.weights, t).reshape(-1, 2)
            for comp in range(2):
                f_fe_rows.append(2 * l2g[: fl.shape[0]] + comp)
                f_fe_vals.append(fl[:, comp])
        fq = revolved_if(facet_quadrature(msh, f_p_facets, deg), problem.material)
        t = raise_on_all_ranks(
            comm,
            lambda fn=fn, fq=fq: vector_values(fn, (fq.points, fq.normals), len(fq), "traction"),
        )
        bt = raise_on_all_ranks(comm, lambda fq=fq: problem.mls.tabulate(fq.points, 0))
        f_p += load_vector(bt.values, fq.weights, t)
    cat = np.concatenate
    b_fe = create_vector(
        comm, fe_layout, cat([*f_fe_rows, np.zeros(0, np.int64)]), cat([*f_fe_vals, []])
    )
    if problem.body_forces:  # pure FE cells with N_a, interface cells blended, patch phi_J
        fe_body, p_body = _body_loads(problem, blend, qi, ti, tables, test)
        b_fe.array[:] += fe_body
        f_p += p_body

    loads = (b_fe.copy(), f_p.copy())
    # K_FE = DOLFINx (pure FE cells) + interface FE-FE block, then strong conditions
    K_fe = _fe_stiffness(problem, blend)
    K_int = create_aij(comm, K_ff, fe_layout, fe_layout)
    K_fe.axpy(1.0, K_int, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    x_bc = fix_fe_rows(problem, K_fe, b_fe, fixed_local, x_fix)
    Kp = create_aij(comm, Kp_loc, pl, pl)
    b_p = create_vector(comm, pl, pdofs.ravel(), f_lift + f_p)
    Kfp = create_aij(comm, K_fp, fe_layout, pl)
    Kpf = create_aij(comm, K_pf, pl, fe_layout)
    blocks = [[K_fe, Kfp], [Kpf, Kp]]
    rhs = [b_fe, b_p]
    mats = [K_fe, K_int, Kp, Kfp, Kpf, loads[0]]
    dl, *pins = append_patch_conditions(problem, blocks, rhs, mats, patch_bc, dq, dtabs)
    extra = {
        "pins": tuple(pins),
        "x_bc": x_bc,
        "active": active,
        "is_bc": is_bc,
        "fixed": fixed_local,
        "fixed_values": x_fix,
        "multipliers": dl.size_global,
        "setup": setup,
        "assemble": time.perf_counter() - t1 + kt["assemble"],
        "loads": loads,
        "fe_cells": ~patch.in_patch & ~blend.in_interface,
        "fe_weight": None,
        "constant_diagonal": [None, None],
        "shared_sides": lambda fe, particles, material: [
            BlendedSide(fe, particles, ti, qi.weights, material, test, quadrature=qi)
        ],
        "state_blocks": [(0, 1), (1, 0)],
        "interface": blend,
    }
    return blocks, rhs, mats, extra


def solve_ramp(
    problem: CoupledElasticity,
    solver: str | SolverOptions = "mumps",
    kept: KeptFactorisation | None = None,
) -> CoupledSolution:
    """Assemble and solve the ramp-coupled system of ``problem`` (collective; ``kept``: see
    :func:`~dolfinx_meshfree.statics.petsc.solve_lu`)."""
    blocks, rhs, mats, extra = ramp_system(problem)
    uh, coeffs, solve, lam = solve_and_gather(
        problem, blocks, rhs, [*mats, extra["x_bc"]], solver, kept
    )
    return CoupledSolution(
        u=uh,
        coefficients=coeffs,
        mls=problem.mls,
        patch=problem.patch,
        timings={"setup": extra["setup"], "assemble": extra["assemble"], "solve": solve},
        sizes=sizes(problem, extra["active"], extra["multipliers"]),
        point_forces=pin_forces(extra, lam),
        interface=extra["interface"],
    )


def _body_loads(
    problem,
    blend: RampInterface,
    q,
    tab: ShapeTable,
    tables: dict | None = None,
    test: list[sp.csr_matrix] | None = None,
):
    """The ramp coupling's shares of ``problem``'s body forces (collective): ``N_a`` on the pure
    FE cells, the blended functions ``(1 - R) N_a`` and ``R phi_J`` of eq. 3.15 on the interface
    cells (rule ``q``, table ``tab``; Rabczuk et al. 2006, eq. 38-42 for the cubic ramp), and
    ``phi_J`` on the patch cells. Returns the FE loads per owned dof and the particle loads
    (original interleaved order). A stress part: with the test gradients of the stiffness,
    the patch cells' in ``tables`` and the interface cells' ``test`` (eq. 3.16, particle columns
    VCI-corrected when consistent)."""
    pure = ~problem.patch.in_patch & ~blend.in_interface
    return body_loads(
        problem, problem.cell_indicator(pure), interface_rule=(q, tab.values), tables=tables,
        interface_stress=None if test is None else StressRule(q, q.weights, test),
    )  # fmt: skip


def _patch_rule(problem: CoupledElasticity) -> QuadraturePoints:
    """The patch cells' rule: Gauss on each cell, cut cells side by side when the patch has
    cracks (:func:`~dolfinx_meshfree.statics.efg.crack_rules`). Collective."""
    patch, msh, deg = problem.patch, problem.V.mesh, problem.quadrature_degree
    cells = patch.particles.cells
    q = crack_rules(msh, cells, patch.cracks, deg, None)[0]  # None without cracks
    return cell_quadrature(msh, deg, cells) if q is None else q


def _consistent_stiffness(
    problem,
    blend: RampInterface,
    q,
    tab: ShapeTable,
    tables: dict | None = None,
    hoop: sp.csr_matrix | None = None,
):
    """Variationally consistent integration (VCI) of the particle test functions of a ramp
    coupling (Chen, Hillman & Rüter 2013; see :func:`~dolfinx_meshfree.physics.operators.
    consistent_gradients`). Collective.

    A particle's test function is ``phi_J`` on the patch cells and ``R phi_J`` on the interface
    cells (eq. 3.15), so its integration domain is the patch with the interface cells, whose
    boundary is the exterior boundary of both: on the interface cells' facets towards the pure
    FE cells ``R = 0``. One correction vector per particle, from the quadrature of both kinds of
    cells and of that boundary, makes ``sum_q grad psi_J w_q = sum_b psi_J n w_b`` exact. The FE
    test functions ``(1 - R) N_a`` are polynomials, integrated exactly by the Gauss rule.
    Axisymmetric (``hoop``: the interface table's hoop, ``q`` revolved): every rule revolved and
    the test functions' hoop ``N / r`` in the radial identity (``consistent_gradients(...,
    hoop=)``); the patch cells' trial strain with the axis offset taken off
    (:func:`~dolfinx_meshfree.physics.axisymmetry.approximation_hoop`).

    Returns:
        ``(K_P, timings, test)``: the patch cells' particle stiffness (PETSc numbering) with the
        corrected test gradients, and the interface table's test gradients (FE columns as they
        are, particle columns corrected). ``tables``, if given, receives the patch cells'
        quadrature, MLS table and corrected test gradients.
    """
    patch, P, comm = problem.patch, problem.patch.particles, problem.patch.comm
    msh, deg, mls = problem.V.mesh, problem.quadrature_degree, problem.mls
    n_loc = blend.num_fe_columns
    t0 = time.perf_counter()
    qp = raise_on_all_ranks(comm, lambda: revolved_if(_patch_rule(problem), problem.material))
    tp = raise_on_all_ranks(comm, lambda: mls.tabulate(qp.points))
    hoop_p = test_p = None  # the patch cells' trial and test hoops (as particle_stiffness's)
    if hoop is not None:
        hoop_p = raise_on_all_ranks(comm, lambda: approximation_hoop(mls, msh, qp, tp.values))
        test_p = raise_on_all_ranks(comm, lambda: hoop_table(tp.values, qp.points))
    # the boundary: exterior facets of patch cells (phi), with the faces of the patch's cracks
    # (one-sided values), and of interface cells (R phi)
    ext = boundary_facets(msh)
    ext_i = ext[blend.in_interface[_first_cells(msh, ext)]]
    exterior = (patch.exterior_facets, patch.exterior_cells)
    bp = crack_rules(msh, P.cells, patch.cracks, deg, exterior, cell_rule=False)[1]
    if bp is None:  # no crack
        bp = facet_quadrature(msh, patch.exterior_facets, deg, patch.exterior_cells)
    bi = facet_quadrature(msh, ext_i, deg)
    bp, bi = (
        raise_on_all_ranks(comm, lambda b=b: revolved_if(b, problem.material)) for b in (bp, bi)
    )
    sides = getattr(bp, "sides", None)
    vp = raise_on_all_ranks(comm, lambda: mls.tabulate(bp.points, 0, sides=sides)).values
    vi = raise_on_all_ranks(comm, lambda: blend.table(bi.points, bi.cells, 0)).values[:, n_loc:]
    particle = slice(n_loc, None)
    values = sp.vstack([tp.values, tab.values[:, particle]]).tocsr()
    grads = [
        sp.vstack([g, gi[:, particle]]).tocsr()
        for g, gi in zip(tp.gradients, tab.gradients, strict=True)
    ]
    corrected = raise_on_all_ranks(
        comm,
        lambda: consistent_gradients(
            values,
            grads,
            np.concatenate([qp.weights, q.weights]),
            sp.vstack([vp, vi]).tocsr(),
            np.concatenate([bp.weights, bi.weights]),
            np.concatenate([bp.normals, bi.normals]),
            comm,
            mls.points,
            hoop=None if hoop is None else sp.vstack([test_p, hoop[:, particle]]).tocsr(),
        ),
    )
    m = len(qp)
    if tables is not None:  # the patch cells' rule, table and test gradients
        tables.update(quadrature=qp, table=tp, test_gradients=[c[:m] for c in corrected])
        if hoop_p is not None:
            tables["hoop"], tables["test_hoop"] = hoop_p, test_p
    t1 = time.perf_counter()
    patch_test = [c[:m] for c in corrected]
    if hoop_p is not None:
        K = axisymmetric_stiffness(
            patch_test, test_p, qp.weights, problem.material, tp.gradients, trial_hoop=hoop_p
        )
    else:
        K = stiffness_matrix(patch_test, qp.weights, problem.material, tp.gradients)
    K = K.tocoo()
    dof_map = P.petsc_dofs(2).ravel()
    n = P.num_particles
    Kp = sp.csr_matrix((K.data, (dof_map[K.row], dof_map[K.col])), shape=(2 * n, 2 * n))
    test = [
        sp.hstack([gi[:, :n_loc], c[m:]]).tocsr()
        for gi, c in zip(tab.gradients, corrected, strict=True)
    ]
    return Kp, {"setup": t1 - t0, "assemble": time.perf_counter() - t1}, test


def _owned_csr(A: PETSc.Mat, rows: Layout) -> sp.csr_matrix:
    """The owned rows of an assembled PETSc matrix as a (global rows x global columns) CSR
    (other ranks' rows empty)."""
    ai, aj, av = A.getValuesCSR()
    indptr = np.concatenate(
        [np.zeros(rows.start, ai.dtype), ai, np.full(rows.size_global - rows.end, ai[-1])]
    )
    return sp.csr_matrix((av, aj, indptr), shape=A.getSize())


def _first_cells(msh: dolfinx.mesh.Mesh, facets: np.ndarray) -> np.ndarray:
    """The first local cell of each facet (the only one on exterior facets)."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    return np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]


def ramp_operators(problem: CoupledElasticity) -> CouplingOperators:
    """The ramp couplings' operators without essential conditions (collective).

    ``K_FE``: DOLFINx's assembly on the pure FE cells plus the interface cells' FE–FE block;
    ``K_P``: EFG on the patch cells plus the interface cells' particle–particle block;
    ``K_FP``/``K_PF``: the interface cells' mixed blocks, all from the blended shape functions
    of eq. 3.15–3.16 (Belytschko et al. 1995). The interface quadrature and its blended table
    give the interface cells' share of the row-sum masses with the same shape functions
    (eq. 4.5). See :class:`~dolfinx_meshfree.couplings.base.CouplingOperators`.

    The four stiffness blocks are assembled as PETSc BAIJ (2 x 2 blocks,
    :func:`~dolfinx_meshfree.statics.baij.create_baij`), the format explicit dynamics multiplies
    (no AIJ copy), and ``K_FE`` leaves out the patch cells' zeros that DOLFINx's sparsity
    stores (about half its entries on the rod): the products are those of the AIJ blocks copied
    to BAIJ (:func:`~dolfinx_meshfree.dynamics.linalg.blocked`) to the last bit, at less cost.
    """

    if problem.consistent:
        raise ValueError(
            "consistent=True is not available for the ramp couplings' dynamic operators (the "
            "statics support it); use consistent=False for ExplicitDynamics"
        )
    t0 = time.perf_counter()
    patch, P = problem.patch, problem.patch.particles
    comm = patch.comm
    n = P.num_particles
    pdofs = P.petsc_dofs(2)
    fe_layout, l2g = fe_dof_layout(problem.V)
    pl = P.dof_layout()
    blend = RampInterface(problem, cubic=RAMPS[problem.coupling])
    n_loc = blend.num_fe_columns
    tables: dict = {}  # the patch cells' rule, table and test gradients (finite strain)
    Kp_loc, pq, ptab, _ = particle_stiffness(  # cut cells side by side (as in statics)
        P, problem.mls, problem.material, problem.quadrature_degree,
        quadrature=_patch_rule(problem), tables=tables,
    )  # fmt: skip
    active = fe_active(problem) & ~blend.on_gamma
    q, tab, hoop = _interface_rule(problem, blend)
    Ki = _blended_stiffness(problem, tab.gradients, q, tab, hoop).tocoo()
    # blended columns: FE (2 a + i) -> 2 l2g[a] + i; particles (2 J + i) -> PETSc dofs
    nf = 2 * n_loc
    dof = np.concatenate([(2 * l2g[:, None] + np.arange(2)).ravel(), pdofs.ravel()])
    r, c = dof[Ki.row], dof[Ki.col]
    fr, fc = Ki.row < nf, Ki.col < nf
    nfe = fe_layout.size_global

    def block(sel: np.ndarray, shape: tuple[int, int]) -> sp.csr_matrix:
        return sp.csr_matrix((Ki.data[sel], (r[sel], c[sel])), shape=shape)

    def baij(
        local: sp.spmatrix, rows: Layout, cols: Layout, assembled: sp.spmatrix | None = None
    ) -> PETSc.Mat:
        return create_baij(comm, local, rows, cols, 2, assembled)

    # the stiffness blocks in 2 x 2 blocks, as explicit dynamics multiplies them (no AIJ copy);
    # K_FE without the patch cells' stored zeros of DOLFINx's sparsity (same products)
    K_dolfinx = _fe_stiffness(problem, blend)
    K_fe = baij(block(fr & fc, (nfe, nfe)), fe_layout, fe_layout, _owned_csr(K_dolfinx, fe_layout))
    K_dolfinx.destroy()
    Kp_loc = Kp_loc + block(~fr & ~fc, (2 * n, 2 * n))
    pure = ~patch.in_patch & ~blend.in_interface
    return CouplingOperators(
        coupling=problem.coupling,
        K_fe=K_fe,
        K_p=baij(Kp_loc, pl, pl),
        fe_weight=problem.cell_indicator(pure),
        fe_active=active,
        particle_quadrature=pq,
        particle_table=ptab.values.tocsr(),
        fe_layout=fe_layout,
        particle_layout=pl,
        K_fp=baij(block(fr & ~fc, (nfe, 2 * n)), fe_layout, pl),
        K_pf=baij(block(~fr & fc, (2 * n, nfe)), pl, fe_layout),
        interface_quadrature=q,
        interface_table=tab.values.tocsr(),
        interface=blend,
        particle_tables=tables,
        timings={"operators": time.perf_counter() - t0},
    )


class _RampCoupling:
    """Interface elements with a ramp function (Belytschko et al. 1995, sec. 3.2)."""

    default_dilation: ClassVar[float] = 2.5
    consistent_default: ClassVar[bool] = True
    integrations: ClassVar[tuple[str, ...]] = ("cells",)
    blended: ClassVar[bool] = True
    dimensions: ClassVar[tuple[int, ...]] = (2,)
    missing_3d: ClassVar[str] = (
        "its interface elements, ramp function and the widened particle supports over them "
        "(Belytschko et al. 1995, eq. 3.13-3.15) are built from 2D interface cells and edges"
    )

    def prepare_mls(self, mls: MLS, patch: ParticlePatch) -> MLS:
        """Supports spanning the interface elements (:func:`ramp_mls`)."""
        return ramp_mls(mls, patch)

    def solve(
        self,
        problem: CoupledElasticity,
        solver: str | SolverOptions,
        kept: KeptFactorisation | None = None,
    ) -> CoupledSolution:
        return solve_ramp(problem, solver, kept)

    def system(self, problem: CoupledElasticity, tables: dict | None = None) -> tuple:
        return ramp_system(problem, tables)

    def operators(
        self, problem: CoupledElasticity, integration: str, slaves: str
    ) -> CouplingOperators:
        return ramp_operators(problem)


class RampCoupling(_RampCoupling):
    """The linear ramp ``R = sum_{a in Gamma_E} N_a`` (Belytschko et al. 1995, eq. 3.13)."""

    name: ClassVar[str] = "ramp"


class CubicRampCoupling(_RampCoupling):
    """The smoothed ramp ``3R^2 - 2R^3`` (Rabczuk et al. 2006, eq. 38–42)."""

    name: ClassVar[str] = "ramp-cubic"
