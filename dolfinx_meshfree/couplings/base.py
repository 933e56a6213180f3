"""What every FE–particle coupling shares: the coupling protocol and registry, the solution
and operator records, and the constraint-block helpers.

A coupling family is one class registered by name (:func:`register`): it builds its static
block system (:meth:`Coupling.solve`) and its unconstrained operators for explicit dynamics
(:meth:`Coupling.operators`) from a :class:`~dolfinx_meshfree.CoupledElasticity`, which holds
the model (space, patch, material, MLS, loads, essential conditions) and dispatches to the class
of its ``coupling`` name. Adding a coupling touches its own module and the registry,
:data:`dolfinx_meshfree.couplings.REGISTRY`, nowhere else.

The constraint helpers write the multiplier rows of Rabczuk et al. 2006, eq. 103–110 (FE and
particle columns of ``G``) in PETSc's global numbering.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Protocol, runtime_checkable

import dolfinx
import numpy as np
import scipy.sparse as sp
import ufl
from petsc4py import PETSc

from .. import _compat
from ..approx.fe_dofs import cell_indicator, fe_dof_layout, node_flags
from ..approx.fe_points import point_value_nodes, route_to_owners, tabulate_in_cells
from ..approx.mls import MLS
from ..approx.neighbours import check_points
from ..fracture.interaction import StressIntensityFactors
from ..geometry.crack import Crack
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import QuadraturePoints
from ..parallel import Layout, raise_on_all_ranks
from ..physics import axisymmetry
from ..physics.materials import LinearElastic
from ..statics.kept_factor import KeptFactorisation
from ..statics.sifs import solution_sifs

if TYPE_CHECKING:  # annotations only: the model imports this module, not the reverse
    from ..statics.coupled import CoupledElasticity
    from ..statics.sides import NonlinearSolveResult
    from .bridging import BridgingBand
    from .master_slave import MasterSlaveLinks
    from .ramp import RampInterface

__all__ = [
    "ROUND_OFF",
    "CoupledSolution",
    "Coupling",
    "CouplingDefaults",
    "CouplingOperators",
    "cell_indicator",
    "check_dimension",
    "facet_nodes",
    "facet_table",
    "fe_constraint_block",
    "fe_dof_layout",
    "interface_node_flags",
    "material_stiffness_form",
    "node_flags",
    "particle_constraint_block",
]

VectorFunction = Callable[[np.ndarray], np.ndarray]


def material_stiffness_form(
    law: LinearElastic, V: dolfinx.fem.FunctionSpace, weight: ufl.core.expr.Expr
) -> ufl.Form:
    """``weight inner(sigma(u), eps(v)) dx`` of ``law`` on ``V`` (axisymmetric: the hoop strain
    and ``2 pi r``): the FE form of :meth:`~dolfinx_meshfree.CoupledElasticity.fe_form`, of the
    hybrid's FE cells and of ``ExplicitDynamics.fe``, and what
    :class:`~dolfinx_meshfree.CoupledLinearProblem` compares the user's form with."""
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    dx = ufl.Measure("dx", domain=V.mesh)
    if law.axisymmetric:
        stress, strain = axisymmetry.ufl_stress(u, law), axisymmetry.ufl_strain(v)
        return weight * axisymmetry.measure(V.mesh) * ufl.inner(stress, strain) * dx
    return weight * ufl.inner(law.ufl_stress(u), ufl.sym(ufl.grad(v))) * dx


@dataclass
class CoupledSolution:
    """FE displacement, particle coefficients, and the means to evaluate the coupled field."""

    u: dolfinx.fem.Function
    coefficients: np.ndarray
    mls: MLS
    patch: ParticlePatch
    timings: dict[str, float] = field(default_factory=dict)
    sizes: dict[str, int] = field(default_factory=dict)
    #: For the ramp couplings, the :class:`~dolfinx_meshfree.couplings.ramp.RampInterface`
    #: (blended interface cells).
    interface: RampInterface | None = None
    #: At finite strain, Newton's record (:class:`~dolfinx_meshfree.NonlinearSolveResult`).
    newton: NonlinearSolveResult | None = None
    #: The small-strain law of the solve (for :meth:`stress_intensity_factors`).
    material: LinearElastic | None = None
    #: Whether the loads held a stress ``S : grad(v)`` (a thermal or initial stress of ``L``):
    #: the stress is then ``C : eps(u) - S``, which :meth:`stress_intensity_factors` refuses.
    initial_stress: bool = False
    #: The model's body forces: their term in the interaction integral
    #: (:func:`~dolfinx_meshfree.statics.sifs.body_force_acceleration`).
    body_forces: list = field(default_factory=list)
    #: A Newton solve: ``f_int - f_ext`` of the FE rows (owned dofs), held rows included
    #: (:func:`~dolfinx_meshfree.statics.reactions.reaction` with a law with state).
    fe_residual: np.ndarray | None = None
    #: Per entry of the model's ``point_dirichlet`` (pins), (m, gdim) forces the pins exert on
    #: the body at this rank's points (:class:`~dolfinx_meshfree.couplings.point_conditions.
    #: PinRows`); ``None`` where the solve does not keep them.
    point_forces: list[np.ndarray] | None = None

    def take_loads(self, body_forces: list) -> None:
        """Record the model's body forces (:attr:`body_forces`, :attr:`initial_stress`)."""
        self.body_forces = list(body_forces)
        self.initial_stress = any(f.has_stress for f in body_forces)

    def stress_intensity_factors(
        self,
        crack: Crack,
        tip: int | np.ndarray = 0,
        radius: float | np.ndarray | None = None,
        material: LinearElastic | None = None,
        **options,
    ) -> StressIntensityFactors:
        """K_I, K_II and J at a tip of a crack of the patch by the domain interaction integral
        on the crack-aware MLS field (collective; the domains must stay inside the patch, away
        from the FE interface; see :func:`~dolfinx_meshfree.statics.sifs.solution_sifs`).

        Args:
            crack: one of ``patch.cracks``. tip: an index of ``crack.tips`` or its coordinates.
            radius: outer domain radii (default 8, 10, 12, 14, 16 particle spacings,
                ``r1 = r2 / 2``, shrunk together to fit the patch:
                ``statics.sifs.DOMAIN_RADII``).
            material: the law (default: the solve's).
            options: ``inner``, ``weight``, ``points`` of
                :func:`~dolfinx_meshfree.interaction_integral`.
        """

        if self.initial_stress:  # an attribute of the solve: the same on every rank
            raise ValueError(
                "this solution carries a thermal or initial stress S (an inner(S, grad(v)) dx "
                "term of L): the interaction integral takes the stress as C : eps(u) and has no "
                "term for S or its gradient, so K_I and K_II would be wrong; stress intensity "
                "factors are not available with an initial stress"
            )

        def grad(x: np.ndarray) -> np.ndarray:
            return self.mls.tabulate(x).gradient(self.coefficients)

        return solution_sifs(
            grad, material or self.material, self.patch.cracks, self.patch, crack, tip, radius,
            body=(self.body_forces, self.u.function_space), **options,
        )  # fmt: skip

    def evaluate_at_quadrature(self, q: QuadraturePoints) -> tuple[np.ndarray, np.ndarray]:
        """Displacement (m, gdim) and gradient (m, gdim, gdim) at quadrature points of local
        cells: FE in FE cells, particles in patch cells, blended in a ramp coupling's interface
        cells (local)."""
        V = self.u.function_space
        gdim = V.mesh.geometry.dim
        local = self.u.x.array.reshape(-1, gdim)
        inside = self.patch.in_patch[q.cells]
        u = np.empty((len(q), gdim))
        g = np.empty((len(q), gdim, gdim))
        fe = ~inside
        if self.interface is not None:
            blended = self.interface.in_interface[q.cells]
            fe &= ~blended
            if np.any(blended):
                u[blended], g[blended] = self.interface.evaluate(
                    q.points[blended], q.cells[blended], local, self.coefficients
                )
        if np.any(fe):
            t = tabulate_in_cells(V, q.points[fe], q.cells[fe])
            u[fe], g[fe] = t.values @ local, t.gradient(local)
        if np.any(inside):
            t = self.mls.tabulate(q.points[inside])
            u[inside], g[inside] = t.values @ self.coefficients, t.gradient(self.coefficients)
        return u, g

    def displacement(self, points: np.ndarray) -> np.ndarray:
        """Displacement (m, gdim) at any points of the mesh, on every rank (collective). Points
        on the interface are evaluated on the FE side, the same on any partition."""
        msh = self.patch.mesh
        gdim = msh.geometry.dim
        x = raise_on_all_ranks(msh.comm, lambda: check_points(points, gdim, "points"))

        def compute(pts: np.ndarray, cells: np.ndarray) -> list:
            q = QuadraturePoints(pts, np.zeros(len(pts)), cells)
            return list(self.evaluate_at_quadrature(q)[0])

        # points on the interface belong to both sides, which a weak coupling makes differ
        # slightly: take the FE side, whatever the partition
        fe_side = ~self.patch.in_patch
        return np.array(route_to_owners(msh, x, compute, fe_side), dtype=float).reshape(-1, gdim)

    def as_function(self, V: dolfinx.fem.FunctionSpace | None = None) -> dolfinx.fem.Function:
        """The coupled displacement field as a DOLFINx Function on ``V`` (collective), for
        ``XDMFFile``, UFL post-processing and plotting: ``u`` itself is zero inside the patch.

        The value at each node (dof coordinate) of ``V``:

        * a node of an FE cell (a cell not in the patch), interface nodes included: the FE side,
          as :meth:`displacement` takes it: ``u`` itself on its own space (for another ``V``,
          ``u`` interpolated); in a ramp coupling's interface cells the blended field
          ``(1 - R) u_FE + R u_P`` (on the interface, where ``R = 1``, the particle field);
        * a node whose cells all lie in the patch: the particle field there,
          ``mls.tabulate(x).values @ coefficients`` (the MLS field is not interpolating: these
          are not the coefficients). Bridging: so also in the band's interior nodes, where the
          solution is the energy-weighted ``(1 - alpha) u_FE + alpha u_P`` that the two fields
          make up to the coupling error; the band's FE field is ``u`` itself.

        The nodes of ``V`` take the values of the field, so a ``V`` of a higher degree than the
        FE space interpolates its piecewise-linear FE part exactly (a P2 space holds the P1 field
        and the particle field at its nodes). The choice is made per node from the whole mesh,
        so every partition gives the same values to round-off (a node on cells owned by several
        ranks takes the mean of their evaluations of the same continuous field); ghost values
        are up to date.

        Args:
            V: A vector space of ``gdim`` components on the solution's mesh whose dofs are point
                values (Lagrange, continuous or discontinuous, any degree); ``None``: the
                solution's own FE space (``u.function_space``).

        Returns:
            A new Function on ``V`` named ``"displacement"``.
        """
        U = self.u.function_space
        V = U if V is None else V
        msh = U.mesh
        gdim, tdim = msh.geometry.dim, msh.topology.dim
        coordinates = raise_on_all_ranks(msh.comm, lambda: point_value_nodes(V, gdim, msh))
        n_nodes = coordinates.shape[0]
        n_cells = msh.topology.index_map(tdim).size_local
        cell_nodes = _compat.dofmap_array(V)[:n_cells]
        fe_cells = np.flatnonzero(~self.patch.in_patch[:n_cells])
        blended = np.zeros(n_cells, dtype=bool)
        if self.interface is not None:  # the ramps' interface cells
            blended = self.interface.in_interface[:n_cells]
        # one owned FE cell per node of this rank's FE cells, a pure FE cell where there is one
        cell_of = np.full(n_nodes, -1, dtype=np.int64)
        for group in (fe_cells[blended[fe_cells]], fe_cells[~blended[fe_cells]]):
            cell_of[cell_nodes[group].ravel()] = np.repeat(group, cell_nodes.shape[1])
        nodes = np.flatnonzero(cell_of >= 0)
        values = np.zeros((n_nodes, gdim))
        exact = np.zeros(nodes.size, dtype=bool)
        if V is U:  # the FE function itself at its own nodes of pure FE cells
            exact = ~blended[cell_of[nodes]]
            values[nodes[exact]] = self.u.x.array.reshape(-1, gdim)[nodes[exact]]
        rest = nodes[~exact]

        def fe_side() -> np.ndarray:
            if rest.size == 0:
                return np.zeros((0, gdim))
            q = QuadraturePoints(coordinates[rest], np.zeros(rest.size), cell_of[rest])
            return self.evaluate_at_quadrature(q)[0]

        values[rest] = raise_on_all_ranks(msh.comm, fe_side)
        # sum the evaluations of every rank that owns FE cells at a node, count them
        acc = dolfinx.fem.Function(V)
        count = dolfinx.fem.Function(V)
        acc.x.array[:] = 0.0
        count.x.array[:] = 0.0
        acc.x.array.reshape(-1, gdim)[nodes] = values[nodes]
        count.x.array.reshape(-1, gdim)[nodes] = 1.0
        _compat.scatter_reverse_add(acc)
        _compat.scatter_reverse_add(count)
        n_owned = V.dofmap.index_map.size_local
        c = count.x.array.reshape(-1, gdim)[:n_owned, 0]
        fe_node = c > 0.5
        out = acc  # reused: its owned entries hold the sums
        owned = out.x.array.reshape(-1, gdim)[:n_owned]
        owned[fe_node] /= c[fe_node, None]
        inner = np.flatnonzero(~fe_node)

        def particle_side() -> np.ndarray:
            if inner.size == 0:
                return np.zeros((0, gdim))
            return self.mls.tabulate(coordinates[inner], 0).values @ self.coefficients

        owned[inner] = raise_on_all_ranks(msh.comm, particle_side)
        out.x.scatter_forward()
        out.name = "displacement"
        return out


@dataclass
class CouplingOperators:
    """The assembled operators of a coupling, without essential conditions and unscaled.

    What :meth:`CoupledElasticity.operators` returns, for explicit dynamics (Rabczuk et al.
    2006, Table I) and for users who assemble their own systems. Two fields: the FE dofs of
    ``V`` (two per node, PETSc global numbering, layout :attr:`fe_layout`) and the particle dofs
    (:meth:`~dolfinx_meshfree.ParticleSet.petsc_dofs`, layout :attr:`particle_layout`). The
    caller owns the PETSc objects (:meth:`destroy`).

    Attributes:
        coupling: The coupling's name.
        K_fe: FE stiffness: the FE form weighted by :attr:`fe_weight`, plus the coupling's FE-FE
            terms (ramp interface cells, bridging penalty). Rows of inactive dofs are empty.
        K_p: Particle stiffness (EFG on the patch cells, bridging: weighted by ``alpha``, ramp:
            plus the interface cells' particle-particle block).
        K_fp, K_pf: Off-diagonal stiffness blocks (FE rows x particle columns and back; ramp
            interface cells, bridging penalty), or ``None``.
        G_fe, G_p: Constraint blocks (multipliers x FE dofs, multipliers x particle dofs) of the
            multiplier couplings, ``G_FE u_FE + G_P u_P = 0`` with unit scaling (the static
            system scales them by ``E``) and no column removed for essential conditions; ``None``
            for the couplings without multipliers.
        fe_weight: Scalar UFL expression, the weight of the FE energy on each cell (the DG0
            indicator of the FE cells; bridging: ``beta_FE``, eq. 47–48). The FE masses are
            ``rho fe_weight`` integrated against the FE basis (eq. 88).
        fe_active: bool per local FE node (owned and ghost): the node carries FE dofs.
        particle_quadrature: This rank's quadrature of the particle cells (bridging: weights
            times ``alpha``, eq. 89); ``particle_table``: (nq x n) CSR of the MLS values there
            (columns in original particle order). The row-sum particle masses are
            ``rho particle_table^T w``.
        interface_quadrature, interface_table: Ramp couplings: the interface cells' quadrature
            and the blended shape functions there, (nq x (n_loc + n)) CSR with columns ``[local
            FE nodes | particles]`` (Belytschko et al. 1995, eq. 3.15); ``None`` otherwise.
        reduction: Master–slave: ``(T_PF, S)``, PETSc matrices with ``u_P = T_PF u_FE + S u_M``
            (slaves follow the FE interface, eq. 27; ``S`` selects the free particles, whose
            master layout is :attr:`master_layout`); ``None`` otherwise.
        interface: The coupling's interface object for evaluation (``RampInterface``,
            ``BridgingBand``, ``MasterSlaveLinks``) or ``None``.
        fe_layout, particle_layout, multiplier_layout, master_layout: Layouts (dofs).
        penalty_blocks: The bridging penalty's diagonal blocks ``(FE, particles)`` (eq. 72–75;
            already added to ``K_fe`` and ``K_p``, its off-diagonal blocks are ``K_fp``,
            ``K_pf``): the part of the stiffness that stays linear at finite strain; ``None``
            without a penalty.
        particle_tables: What a finite-strain internal force needs on the particle rule
            (``"quadrature"``, ``"table"``, ``"test_gradients"`` of ``K_P``, and ``"weights"``
            if they differ from the quadrature's), or ``None`` (couplings without it yet).
        timings: Seconds spent.
    """

    coupling: str
    K_fe: PETSc.Mat
    K_p: PETSc.Mat
    fe_weight: object
    fe_active: np.ndarray
    particle_quadrature: QuadraturePoints
    particle_table: sp.csr_matrix
    fe_layout: Layout
    particle_layout: Layout
    K_fp: PETSc.Mat | None = None
    K_pf: PETSc.Mat | None = None
    G_fe: PETSc.Mat | None = None
    G_p: PETSc.Mat | None = None
    multiplier_layout: Layout | None = None
    interface_quadrature: QuadraturePoints | None = None
    interface_table: sp.csr_matrix | None = None
    reduction: tuple[PETSc.Mat, PETSc.Mat] | None = None
    master_layout: Layout | None = None
    interface: RampInterface | MasterSlaveLinks | BridgingBand | None = None
    particle_tables: dict | None = None
    penalty_blocks: tuple[PETSc.Mat, PETSc.Mat] | None = None
    timings: dict[str, float] = field(default_factory=dict)

    def matrices(self) -> list[PETSc.Mat]:
        """The PETSc matrices held (for destruction or transfer of ownership)."""
        mats = [self.K_fe, self.K_p, self.K_fp, self.K_pf, self.G_fe, self.G_p]
        mats += list(self.reduction or ()) + list(self.penalty_blocks or ())
        return [m for m in mats if m is not None]

    def destroy(self) -> None:
        """Destroy the PETSc matrices (collective)."""
        for m in self.matrices():
            m.destroy()


@runtime_checkable
class Coupling(Protocol):
    """One coupling family: its static system and its operators for explicit dynamics.

    Implementations are stateless classes, listed by :attr:`name` in
    :data:`~dolfinx_meshfree.couplings.REGISTRY`; the model
    (:class:`~dolfinx_meshfree.CoupledElasticity`) holds the options and passes itself.

    Attributes:
        name: The ``coupling=`` name.
        default_dilation: The MLS dilation ``d_max`` the coupling needs by default.
        consistent_default: Whether variationally consistent integration is the default.
        integrations: The particle integrations its dynamic operators offer.
        blended: Whether its particle functions are blended or weighted on cells (ramp,
            bridging): then no volume masses in dynamics.
        dimensions: The geometric dimensions it works in (2, or 2 and 3).
        missing_3d: For a 2D-only coupling, what it lacks in 3D (the refusal's message).
    """

    name: ClassVar[str]
    default_dilation: ClassVar[float]
    consistent_default: ClassVar[bool]
    integrations: ClassVar[tuple[str, ...]]
    blended: ClassVar[bool]
    dimensions: ClassVar[tuple[int, ...]]
    missing_3d: ClassVar[str]

    def prepare_mls(self, mls: MLS, patch: ParticlePatch) -> MLS:
        """The MLS the coupling works with (e.g. supports widened over interface cells)."""
        ...

    def solve(
        self, problem: CoupledElasticity, solver: str, kept: KeptFactorisation | None = None
    ) -> CoupledSolution:
        """Assemble and solve the static block system (collective); ``kept``: the direct
        solve's factorisation shared with earlier solves
        (:func:`~dolfinx_meshfree.statics.petsc.solve_lu`)."""
        ...

    def operators(
        self, problem: CoupledElasticity, integration: str, slaves: str
    ) -> CouplingOperators:
        """The assembled operators without essential conditions (collective)."""
        ...


class CouplingDefaults:
    """What most coupling families share: the particle side's MLS used as given (the ramps
    widen its supports over their interface cells instead)."""

    def prepare_mls(self, mls: MLS, patch: ParticlePatch) -> MLS:
        """``mls`` itself."""
        return mls


def check_dimension(
    msh: dolfinx.mesh.Mesh, name: str, dimensions: tuple[int, ...], missing: str
) -> None:
    """Refuse a mesh whose geometric dimension the coupling ``name`` does not work in: a
    ValueError on every rank (the dimension is the same on every rank), saying what is
    ``missing`` and which couplings work in that dimension."""
    gdim = msh.geometry.dim
    if gdim not in dimensions:
        raise ValueError(
            f"coupling={name!r} works on {' and '.join(f'{d}D' for d in dimensions)} meshes "
            f"only, this mesh has gdim={gdim}: {missing}. In 3D use coupling='lagrange', "
            "'edge-to-edge' or 'bridging'"
        )


def fe_constraint_block(
    rows: np.ndarray,
    nodes: np.ndarray,
    values: np.ndarray,
    global_nodes: bool,
    s: float,
    is_bc: np.ndarray,
    ubc: dolfinx.fem.Function,
    l2g: np.ndarray,
    shape: tuple[int, int],
) -> tuple[sp.csr_matrix, list, list]:
    """FE columns ``s G_FE`` of multiplier rows, with strong Dirichlet dofs moved to the rhs.

    Entry ``k`` contributes ``s values[k]`` at ``(d rows[k] + i, d node + i)`` for each component
    ``i < d`` (``d``: the block size of ``ubc``'s space, the mesh's ``gdim``); a column that is
    a strong Dirichlet dof (``is_bc``, value in ``ubc``) is dropped and ``-s values[k] ubc`` is
    added to the constraint's right-hand side instead.

    Args:
        rows: (k,) global multiplier block (node) numbers.
        nodes: (k,) FE node columns: local nodes of ``V`` or, with ``global_nodes``, global nodes
            (which must be local, owned or ghost, on this rank).
        values: (k,) unscaled entries; ``s``: the scaling of the constraint rows.
        is_bc, ubc: Strong-condition flags (per local node, or (node, component) for dofs
            held by component) and values; ``l2g``: local to global
            node numbers.

    Returns:
        ``(G_FE, rhs rows, rhs values)``; the rhs as lists of arrays per component.
    """
    c = nodes
    if global_nodes:
        order = np.argsort(l2g, kind="stable")
        pos = np.searchsorted(l2g[order], nodes)
        c = order[np.minimum(pos, order.size - 1)] if order.size else pos
        if c.size and not np.array_equal(l2g[c], nodes):
            raise RuntimeError("FE constraint columns name nodes that are not local to this rank")
    r, v = rows, values
    bs = ubc.function_space.dofmap.index_map_bs
    g_rows, g_vals = [], []
    gfe: tuple[list, list, list] = ([], [], [])
    for comp in range(bs):
        bc_col = is_bc[c, comp] if is_bc.ndim == 2 else is_bc[c]
        rr = bs * r + comp
        cols = bs * l2g[c] + comp
        # known FE values move to the right-hand side
        g_rows.append(rr[bc_col])
        g_vals.append(-s * v[bc_col] * ubc.x.array[bs * c[bc_col] + comp])
        gfe[0].append(rr[~bc_col])
        gfe[1].append(cols[~bc_col])
        gfe[2].append(s * v[~bc_col])
    G = sp.csr_matrix(
        (np.concatenate(gfe[2]), (np.concatenate(gfe[0]), np.concatenate(gfe[1]))), shape=shape
    )
    return G, g_rows, g_vals


def particle_constraint_block(
    rows: np.ndarray,
    particles: np.ndarray,
    values: np.ndarray,
    s: float,
    pdofs: np.ndarray,
    shape: tuple[int, int],
) -> sp.csr_matrix:
    """Particle columns ``s G_P``: ``-s values[k]`` at ``(d rows[k] + i, pdofs[particle, i])``
    for each component ``i < d = pdofs.shape[1]``."""
    d = pdofs.shape[1]
    return sp.csr_matrix(
        (
            np.concatenate([-s * values] * d),
            (
                np.concatenate([d * rows + i for i in range(d)]),
                np.concatenate([pdofs[particles, i] for i in range(d)]),
            ),
        ),
        shape=shape,
    )


#: FE basis values at points on a facet below this are round-off of the nodes off the facet
#: (the inverse map of a non-affine quadrilateral leaves up to 1.5e-13 on the gmsh meshes).
ROUND_OFF = 1e-11


def facet_table(
    V: dolfinx.fem.FunctionSpace, points: np.ndarray, cells: np.ndarray
) -> sp.csr_matrix:
    """FE basis values (points x local nodes) at points on facets of the given cells, without
    the round-off entries of the nodes off the facet."""
    t = tabulate_in_cells(V, points, cells, derivatives=0).values.tocsr()
    t.data[np.abs(t.data) <= ROUND_OFF] = 0.0
    t.eliminate_zeros()
    return t


def interface_node_flags(V: dolfinx.fem.FunctionSpace, patch: ParticlePatch) -> np.ndarray:
    """Flag of every local node (owned and ghost) of ``V`` on the patch interface Gamma, on
    every rank that holds it (collective)."""
    fdim = V.mesh.topology.dim - 1
    return node_flags(V, dolfinx.fem.locate_dofs_topological(V, fdim, patch.interface_facets))


def facet_nodes(V: dolfinx.fem.FunctionSpace, facets: np.ndarray) -> np.ndarray:
    """Local P1/Q1 nodes (block indices) of each facet, shape (num_facets, vertices per facet):
    2 in 2D, 3 (triangles) or 4 (quadrilaterals, DOLFINx's vertex order) in 3D."""
    msh = V.mesh
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim, 0)
    msh.topology.create_connectivity(tdim - 1, 0)
    c2v = msh.topology.connectivity(tdim, 0)
    f2v = msh.topology.connectivity(tdim - 1, 0)
    vmap = msh.topology.index_map(0)
    node_of_vertex = np.empty(vmap.size_local + vmap.num_ghosts, dtype=np.int64)
    node_of_vertex[np.asarray(c2v.array)] = _compat.dofmap_array(V).ravel()
    per_facet = int(np.asarray(f2v.offsets)[1]) if len(f2v.offsets) > 1 else tdim
    fv = np.asarray(f2v.array).reshape(-1, per_facet)[np.asarray(facets, dtype=np.int64)]
    return node_of_vertex[fv]
