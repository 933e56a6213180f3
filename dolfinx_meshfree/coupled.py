"""FE–EFG elastostatics on a mesh with a particle patch, coupled by Lagrange multipliers.

Compatibility coupling (Rabczuk et al. 2006, sec. 5.4, eq. 98–110; Hegen 1996): the FE cells and
the patch cells do not overlap and meet on the interface Gamma_I. Displacement continuity is
imposed weakly by a multiplier field discretised with the FE trace functions of the interface
nodes, Lambda_k = N_k on Gamma_I:

.. math::
    G_{FE} = \\int_{\\Gamma_I} \\Lambda^T N_{FE}, \\qquad G_P = -\\int_{\\Gamma_I} \\Lambda^T \\phi,

and the block system (a PETSc MatNest, fields FE, particles, interface multipliers, and patch
Dirichlet multipliers when essential conditions act on patch facets)

.. math::
    \\begin{bmatrix} K_{FE} & 0 & s G_{FE}^T \\\\ 0 & K_P & s G_P^T \\\\
    s G_{FE} & s G_P & 0 \\end{bmatrix}.

``K_FE`` is DOLFINx's assembly of the elasticity form restricted to the FE cells (``dx`` with the
patch's cell tags); FE dofs that no FE cell supports become identity rows. Essential conditions on
FE facets are applied to ``K_FE`` by ``MatZeroRowsColumns`` (which lifts them into the
right-hand side) and removed from the coupling columns; on patch facets they are multiplier
constraints as in :mod:`~dolfinx_meshfree.efg`. ``s = E`` scales the constraint rows.

Edge-to-edge variant (``coupling="edge-to-edge"``, Rabczuk et al. 2006, sec. 5.4): the multipliers
are collocated at the particles ``x_I`` on the interface, one per particle and component, so that
``G_FE[I, a] = N_a(x_I)`` and ``G_P[I, J] = -phi_J(x_I)``: continuity holds exactly at the
interface particles. It does not integrate the interface traction consistently (the particle
forces become the integral of the linear interpolant of ``phi_J``), so the linear patch test is
passed only to first order in h, not exactly.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import dolfinx
import numpy as np
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from . import _compat
from .efg import _vector_values, facet_multipliers, particle_stiffness
from .fe_points import _route, tabulate_fe_basis, tabulate_in_cells
from .materials import LinearElastic
from .mls import MLS
from .operators import load_vector
from .parallel import Layout, raise_on_all_ranks
from .patch import ParticlePatch
from .petsc import BlockSystem, create_aij, create_vector
from .quadrature import QuadraturePoints, cell_quadrature, facet_quadrature

__all__ = [
    "COUPLINGS",
    "DEFAULT_DILATION",
    "CoupledElasticity",
    "CoupledSolution",
    "CouplingOperators",
]

#: Default MLS dilation ``d_max`` of each coupling (see :class:`CoupledElasticity`).
DEFAULT_DILATION = {
    "lagrange": 2.0,
    "edge-to-edge": 2.0,
    "ramp": 2.5,
    "ramp-cubic": 2.5,
    "bridging": 2.0,
    "master-slave": 2.0,
}

#: The ``corner_angle`` of the earlier default (degrees): one Lagrange multiplier per side at
#: interface nodes where the interface turns by more than this (see
#: :meth:`CoupledElasticity._interface_multipliers`). No longer the default: on staircase
#: interfaces it over-constrains the particles (measured: 2.2x the FE error instead of 1.1x).
CORNER_ANGLE = 30.0

#: Couplings available in this release.
COUPLINGS = ("lagrange", "edge-to-edge", "ramp", "ramp-cubic", "bridging", "master-slave")

VectorFunction = Callable[[np.ndarray], np.ndarray]


@dataclass
class CoupledSolution:
    """FE displacement, particle coefficients, and the means to evaluate the coupled field."""

    u: dolfinx.fem.Function
    coefficients: np.ndarray
    mls: MLS
    patch: ParticlePatch
    timings: dict = field(default_factory=dict)
    sizes: dict = field(default_factory=dict)
    #: Ramp couplings: the :class:`~dolfinx_meshfree.ramp.RampInterface` (blended interface cells).
    interface: object | None = None

    def evaluate_at_quadrature(self, q: QuadraturePoints) -> tuple[np.ndarray, np.ndarray]:
        """Displacement (m, 2) and gradient (m, 2, 2) at quadrature points of local cells: FE in
        FE cells, particles in patch cells, blended in a ramp coupling's interface cells (local)."""
        V = self.u.function_space
        local = self.u.x.array.reshape(-1, 2)
        inside = self.patch.in_patch[q.cells]
        u = np.empty((len(q), 2))
        g = np.empty((len(q), 2, 2))
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
        """Displacement (m, 2) at any points of the mesh, on every rank (collective). Points on
        the interface are evaluated on the FE side, the same on any partition."""
        from .neighbours import check_points

        msh = self.patch.mesh
        x = raise_on_all_ranks(msh.comm, lambda: check_points(points, 2, "points"))

        def compute(pts: np.ndarray, cells: np.ndarray) -> list:
            q = QuadraturePoints(pts, np.zeros(len(pts)), cells)
            return list(self.evaluate_at_quadrature(q)[0])

        # points on the interface belong to both sides, which a weak coupling makes differ
        # slightly: take the FE side, whatever the partition
        fe_side = ~self.patch.in_patch
        return np.array(_route(msh, x, compute, fe_side), dtype=float).reshape(-1, 2)


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
    interface: object | None = None
    timings: dict = field(default_factory=dict)

    def matrices(self) -> list[PETSc.Mat]:
        """The PETSc matrices held (for destruction or transfer of ownership)."""
        mats = [self.K_fe, self.K_p, self.K_fp, self.K_pf, self.G_fe, self.G_p]
        mats += list(self.reduction or ())
        return [m for m in mats if m is not None]

    def destroy(self) -> None:
        """Destroy the PETSc matrices (collective)."""
        for m in self.matrices():
            m.destroy()


class CoupledElasticity:
    """Linear elastostatics with FE cells and a particle patch, coupled by Lagrange multipliers.

    Args:
        V: Vector P1/Q1 space on the whole mesh (the FE side lives on its non-patch cells).
        patch: :class:`~dolfinx_meshfree.ParticlePatch` on the same mesh.
        material: :class:`~dolfinx_meshfree.LinearElastic`, used on both sides.
        coupling: ``"lagrange"`` (compatibility coupling with FE trace multipliers, Rabczuk et
            al. 2006, sec. 5.4) or ``"edge-to-edge"`` (multipliers collocated at the interface
            particles, see :meth:`interface_particles`), ``"ramp"`` or ``"ramp-cubic"``
            (interface elements blending FE and particles with a ramp function, Belytschko et al.
            1995, sec. 3.2; see :mod:`~dolfinx_meshfree.ramp`), ``"bridging"`` (overlap band
            with energy weights and multipliers on the band's FE nodes, Rabczuk et al. 2006,
            sec. 5.3; see :mod:`~dolfinx_meshfree.bridging`) or ``"master-slave"`` (particles
            rigidly linked to the FE boundary, Rabczuk et al. 2006, sec. 5.1.2; see
            :mod:`~dolfinx_meshfree.master_slave`).
        weight, dilation, basis: MLS options of the particle side. The default dilation is
            ``DEFAULT_DILATION[coupling]``: 2.0 (Belytschko et al. 1995), but 2.5 for the ramp
            couplings, whose particle functions must also cover the interface cells up to their
            FE-side edge, which d_max = 2 leaves to collinear particles only.
        quadrature_degree: Gauss degree on cells and facets.
        consistent: Variationally consistent integration on the patch (VCI, Chen, Hillman &
            Rüter 2013, over the patch boundary, interface included): the linear patch test
            passes to round-off. Default (``None``): on for every variational coupling, off for
            ``master-slave``, which is first order by construction (its rigid links drop the
            strain across the slave layer) and whose slaves, not multipliers, carry the interface
            traction that VCI's identity assumes: with VCI it loses the exact rigid-body motion
            (2e-5 to 4e-4 instead of 3e-14, tests/test_master_slave.py). ``False``: the papers'
            plain Gauss quadrature.
        overlap, penalty, constraint: ``coupling="bridging"`` (bridging domain, Rabczuk et al.
            2006, sec. 5.3, see :mod:`~dolfinx_meshfree.bridging`): band width in cell layers
            (>= 1), the augmented-Lagrangian penalty ``p >= 0``, and where the band is tied:
            ``"integral"`` (the default: Gauss quadrature over the band cells, eq. 52) or
            ``"points"`` (at the band particles, eq. 79-81, which needs enough band particles to
            determine the multipliers on the band nodes: grid particles on a gmsh mesh are not).
        band_width: ``coupling="bridging"``: a band of this physical width instead of
            ``overlap`` cell layers, with ``alpha = min(d / band_width, 1)`` and ``d`` the
            distance to the interface (see :class:`~dolfinx_meshfree.bridging.BridgingBand`).
        corner_angle: ``coupling="lagrange"``: ``None`` (the default): the multipliers are the
            FE traces of the interface nodes, continuous along the whole interface (Rabczuk et
            al. 2006, eq. 109), also where it turns; the patch test still passes to round-off
            with consistent integration (:meth:`_projected_normals`). A number in (0, 90)
            (degrees, e.g. :data:`CORNER_ANGLE`, the earlier default): nodes where the interface
            turns by more than this carry one multiplier per side. On a staircase of mesh facets
            (a patch chosen by a slanted or curved criterion) that doubles the multipliers and
            over-constrains the particles: 1.7-3.9x the FE error at particle spacings >= 0.75 h
            (tests/test_staircase_couplings.py), against 0.9-1.1x with ``None``.
    """

    def __init__(
        self,
        V,
        patch: ParticlePatch,
        material: LinearElastic,
        coupling: str = "lagrange",
        weight: str = "quartic",
        dilation: float | None = None,
        basis: str = "linear",
        quadrature_degree: int = 7,
        consistent: bool | None = None,
        overlap: int = 2,
        penalty: float = 0.0,
        constraint: str = "integral",
        band_width: float | None = None,
        corner_angle: float | None = None,
    ):
        if coupling not in COUPLINGS:
            raise ValueError(
                f"coupling={coupling!r} is not available; choose one of {list(COUPLINGS)}"
            )
        if corner_angle is not None and not (
            isinstance(corner_angle, (int, float)) and 0.0 < corner_angle < 90.0
        ):
            raise ValueError(
                f"corner_angle={corner_angle!r} must be None (multipliers continuous along the "
                "interface, the default) or an angle in degrees between 0 and 90"
            )
        if not isinstance(material, LinearElastic):
            raise TypeError(f"material must be a LinearElastic, got {type(material).__name__}")
        if V.mesh is not patch.mesh:
            raise ValueError("V and patch must live on the same mesh object")
        if patch.comm.allreduce(patch.fe_cells.size) == 0:
            raise ValueError(
                "the patch covers the whole mesh: no FE cells are left to couple to; solve with "
                "EFGElasticity, or leave some cells out of the patch"
            )
        t0 = time.perf_counter()
        self.V, self.patch, self.material, self.coupling = V, patch, material, coupling
        self.quadrature_degree = quadrature_degree
        self.corner_angle = None if corner_angle is None else float(corner_angle)
        self.consistent = coupling != "master-slave" if consistent is None else bool(consistent)
        from .bridging import check_options

        self.overlap, self.penalty, self.constraint, self.band_width = check_options(
            overlap, penalty, constraint, band_width
        )
        self.mls = raise_on_all_ranks(
            patch.comm,
            lambda: MLS(
                patch.particles,
                weight=weight,
                dilation=DEFAULT_DILATION[coupling] if dilation is None else dilation,
                basis=basis,
            ),
        )
        if coupling in ("ramp", "ramp-cubic"):  # supports spanning the interface elements
            from .ramp import ramp_mls

            self.mls = ramp_mls(self.mls, patch)
        self._dirichlet: list[tuple[np.ndarray, VectorFunction]] = []
        self._tractions: list[tuple[np.ndarray, Callable]] = []
        #: The user's bilinear form (set by :class:`~dolfinx_meshfree.CoupledLinearProblem`);
        #: ``None``: the elasticity form of :attr:`material`.
        self.form: ufl.Form | None = None
        # set by CoupledLinearProblem: strong conditions by node (flags, values)
        self._strong: list[tuple[np.ndarray, np.ndarray]] = []
        #: Body forces (:mod:`~dolfinx_meshfree.body_loads`): :meth:`set_body_force`, or the
        #: cell integrals of a CoupledLinearProblem's ``L``.
        self._body_forces: list = []
        self._setup = time.perf_counter() - t0

    def add_dirichlet(self, facets: np.ndarray, value: VectorFunction) -> None:
        """``u = value(x)`` on owned exterior facets (FE side: strongly; patch side: multipliers).
        ``value`` maps points (m, 2) to (m, 2)."""
        self._dirichlet.append((np.asarray(facets, dtype=np.int32), value))

    def add_traction(self, facets: np.ndarray, traction: Callable) -> None:
        """Traction ``traction(x, n)`` (m, 2) on owned exterior facets, on either side."""
        self._tractions.append((np.asarray(facets, dtype=np.int32), traction))

    def set_body_force(self, force: VectorFunction) -> None:
        """Body force per unit volume ``b(x)`` (m, 2) on the whole body (replaces a previous one),
        as :meth:`EFGElasticity.set_body_force <dolfinx_meshfree.EFGElasticity.set_body_force>`.

        Every coupling integrates it with the functions and weights of its stiffness (see
        :mod:`~dolfinx_meshfree.body_loads`): FE cells with ``N_a``, patch cells with
        ``phi_J``, ramp interface cells with the blended functions (Belytschko et al. 1995,
        eq. 3.15), a bridging band with ``1 - alpha`` and ``alpha`` (Rabczuk et al. 2006,
        eq. 49)."""
        from .body_loads import CallableBodyForce

        self._body_forces = [CallableBodyForce(force)]

    def _body_loads(self, fe_weight, particle_weights=None, interface_rule=None):
        """This coupling's shares of its body forces (collective): the FE loads per owned dof
        (``fe_weight``: the FE energy's weight) and the particle loads (original interleaved
        order) on the patch cells' Gauss rule, its weights multiplied by ``particle_weights(q)``
        if given (the bridging band's ``alpha``); see
        :func:`~dolfinx_meshfree.body_loads.body_load_vectors`."""
        from .body_loads import body_load_vectors

        msh, comm, deg = self.V.mesh, self.patch.comm, self.quadrature_degree
        q = cell_quadrature(msh, deg, self.patch.particles.cells)
        if particle_weights is not None:
            q = QuadraturePoints(q.points, q.weights * particle_weights(q), q.cells)
        table = raise_on_all_ranks(comm, lambda: self.mls.tabulate(q.points, 0)).values
        return body_load_vectors(
            self._body_forces, self.V, fe_weight, deg, (q, table), interface_rule, comm
        )

    # -- pieces ---------------------------------------------------------------------------------

    def _split(self, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exterior facets beside FE cells and beside patch cells."""
        msh = self.patch.mesh
        f2c = msh.topology.connectivity(msh.topology.dim - 1, msh.topology.dim)
        first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
        in_patch = self.patch.in_patch[first]
        return facets[~in_patch], facets[in_patch]

    def _fe_layout(self) -> tuple[Layout, np.ndarray]:
        return fe_dof_layout(self.V)

    def cell_indicator(self, owned_flags: np.ndarray) -> dolfinx.fem.Function:
        """DG0 Function equal to 1 on the owned cells flagged in ``owned_flags`` (and on their
        ghost copies), 0 elsewhere (collective)."""
        return cell_indicator(self.V.mesh, owned_flags)

    def fe_form(self, weight) -> ufl.Form:
        """The FE bilinear form weighted by ``weight`` (a scalar UFL expression: a cell indicator,
        or the bridging energy weight ``1 - alpha``).

        Without a user form (:class:`~dolfinx_meshfree.CoupledLinearProblem` sets
        :attr:`form`), it is ``weight inner(sigma(u), eps(v)) dx`` of :attr:`material`;
        with one, every cell integral of the user's form is multiplied by ``weight``, so that the
        user's own measures, subdomain data and metadata are kept.
        """
        if self.form is None:
            V = self.V
            u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
            dx = ufl.Measure("dx", domain=V.mesh)
            return weight * ufl.inner(self.material.ufl_stress(u), ufl.sym(ufl.grad(v))) * dx
        return ufl.Form(
            [itg.reconstruct(integrand=weight * itg.integrand()) for itg in self.form.integrals()]
        )

    def _fe_stiffness(self, weight=None) -> PETSc.Mat:
        """DOLFINx assembly of :meth:`fe_form` with ``weight`` (default: 1 on the FE cells, 0 on
        the patch)."""
        if weight is None:
            weight = self.cell_indicator(~self.patch.in_patch)
        return _compat.assemble_matrix(_compat.create_form(self.fe_form(weight)))

    def _node_flags(self, local_nodes: np.ndarray) -> np.ndarray:
        """Flag nodes (local block indices) on every rank that has them (collective)."""
        return node_flags(self.V, local_nodes)

    def _interface_multipliers(self, iq: QuadraturePoints, t_fe: sp.csr_matrix):
        """The multiplier basis of the compatibility coupling at the interface quadrature points
        (collective): ``Lambda_k = N_a``, the FE trace of interface node ``a`` (Rabczuk eq. 109).

        By default (``corner_angle=None``) one multiplier per interface node and component,
        continuous along the whole interface: the multiplier space is the FE trace space, so
        the constraint makes the FE trace the L2 projection of the particle trace (a stable
        mortar pairing whatever the particle spacing). With ``corner_angle`` a node where the
        interface turns by more than that angle carries one multiplier per side, so that
        ``sigma n`` may jump there; on a staircase interface (every node a 90 degree turn)
        that is one discontinuous linear function per facet side, twice the FE trace's
        dimension, and the constraint also asks the particle trace's projection to be
        continuous at every step: with particles at spacing >= 0.75 h this over-constrains
        them (1.7-3.9x the FE error, tests/test_staircase_couplings.py). Consistent
        integration does not need the split: :meth:`_projected_normals` carries the jump of
        ``n`` (the linear patch test passes to round-off either way). The interface is small,
        so its facets are gathered on every rank and every rank numbers the multipliers the
        same way, owner by owner (the owner of the node).

        Args:
            iq: Quadrature points on ``patch.interface_facets`` (``entities``: the facet).
            t_fe: FE basis there, (points x local nodes).

        Returns:
            ``(Lambda, layout)``: (points x global multipliers) CSR with the pattern of ``t_fe``
            and the multipliers' layout (two components per multiplier).
        """
        V, patch, comm = self.V, self.patch, self.patch.comm
        imap = V.dofmap.index_map
        l2g = np.asarray(
            imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
        )
        facets = patch.interface_facets
        nodes = facet_nodes(V, facets)
        xy = V.tabulate_dof_coordinates()[:, :2]
        tangent = xy[nodes[:, 1]] - xy[nodes[:, 0]] if facets.size else np.zeros((0, 2))
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
        parts = comm.allgather((l2g[nodes].reshape(-1, 2), tangent))
        offset = int(sum(len(p[0]) for p in parts[: comm.rank]))
        ends = np.concatenate([p[0] for p in parts]).reshape(-1, 2)
        lines = np.concatenate([p[1] for p in parts]).reshape(-1, 2)
        # group the facets at each node: joined when their lines differ by < corner_angle
        group: dict[tuple[int, int], int] = {}
        at_node: dict[int, list[int]] = {}
        for f, (a, b) in enumerate(ends.tolist()):
            at_node.setdefault(a, []).append(f)
            at_node.setdefault(b, []).append(f)
        # |sin| of the turn between two facet lines is at most 1: 2 joins every pair
        sine = 2.0 if self.corner_angle is None else np.sin(np.radians(self.corner_angle))
        for g, fs in at_node.items():
            for f in fs:
                joined = [
                    group[(g, e)]
                    for e in fs
                    if (g, e) in group
                    and abs(lines[f, 0] * lines[e, 1] - lines[f, 1] * lines[e, 0]) < sine
                ]
                group[(g, f)] = min(joined) if joined else f
        ranges = np.asarray([*comm.allgather(imap.local_range[0]), imap.size_global])
        keys = sorted(
            set(
                (int(np.searchsorted(ranges, g, side="right") - 1), g, k)
                for (g, _), k in group.items()
            )
        )
        number = {(g, k): i for i, (_, g, k) in enumerate(keys)}
        owners = np.array([r for r, _, _ in keys], dtype=np.int64)
        start = int(np.sum(owners < comm.rank))
        count = int(np.sum(owners == comm.rank))
        # Lambda: the pattern of t_fe, columns renumbered to the multiplier of (node, piece)
        coo = t_fe.tocoo()
        position = {int(f): offset + i for i, f in enumerate(facets)}
        cols = np.array(
            [
                number[(int(l2g[a]), group[(int(l2g[a]), position[int(iq.entities[q])])])]
                for q, a in zip(coo.row, coo.col, strict=True)
            ],
            dtype=np.int64,
        )
        lam = sp.csr_matrix((coo.data, (coo.row, cols)), shape=(len(iq), len(keys)))
        return lam, Layout(2 * count, 2 * len(keys), 2 * start)

    def _lagrange_rows(self, scale: float = 1.0) -> tuple[tuple, tuple, Layout]:
        """Constraint entries of the compatibility coupling (Rabczuk eq. 109): ``G_FE = int
        Lambda^T N`` and ``G_P = int Lambda^T phi`` on the interface (collective).

        Returns:
            ``(fe_rows, p_rows, layout)`` for :func:`_fe_constraint_block` (local node columns)
            and :func:`_particle_constraint_block`, and the multipliers' layout.
        """
        V, patch, comm = self.V, self.patch, self.patch.comm
        iq = facet_quadrature(
            V.mesh, patch.interface_facets, self.quadrature_degree, patch.interface_fe_cells
        )
        t_fe = facet_table(V, iq.points, iq.cells)
        t_p = raise_on_all_ranks(comm, lambda: self.mls.tabulate(iq.points, 0)).values
        lam, ml = self._interface_multipliers(iq, t_fe)
        W = sp.diags(iq.weights)
        M_fe = (lam.T @ W @ t_fe).tocoo()  # (multipliers x local nodes)
        M_p = (lam.T @ W @ t_p).tocoo()  # (multipliers x particles)
        tiny = 1e-14 * (np.abs(M_fe.data).max() if M_fe.nnz else 1.0)
        keep = np.abs(M_fe.data) > tiny
        fe_rows = (M_fe.row[keep], M_fe.col[keep], M_fe.data[keep], False)
        keep = np.abs(M_p.data) > tiny
        p_rows = (M_p.row[keep], M_p.col[keep], M_p.data[keep])
        return fe_rows, p_rows, ml

    def _facet_particles(self, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray, list]:
        """The particles on each of ``facets`` (local), with their place along it (local).

        A particle is on a facet when its distance to it is below ``1e-10`` times the facet's
        length.

        Returns:
            ``(a, t, on)``: each facet's first vertex and its vector ``t`` to the second (k, 2),
            and per facet ``(particles, xi)`` sorted by ``xi`` in [0, 1], the particle's place
            ``a + xi t``.
        """
        msh, x = self.patch.mesh, self.patch.particles.positions
        if facets.size == 0:
            return np.zeros((0, 2)), np.zeros((0, 2)), []
        fdim = msh.topology.dim - 1
        ends = msh.geometry.x[_compat.entities_to_geometry(msh, fdim, facets), :2]
        a, t = ends[:, 0], ends[:, 1] - ends[:, 0]
        length = np.linalg.norm(t, axis=1)
        tol = 1e-10 * length
        on = []
        near = cKDTree(x).query_ball_point(a + 0.5 * t, 0.5 * length + 2.0 * tol)
        for f, cand in enumerate(near):
            cand = np.asarray(cand, dtype=np.int64)
            # distance to the segment a + [0, 1] t
            r = x[cand] - a[f]
            xi = np.clip(r @ t[f] / length[f] ** 2, 0.0, 1.0)
            d = np.linalg.norm(r - xi[:, None] * t[f], axis=1)
            hit = d <= tol[f]
            order = np.argsort(xi[hit], kind="stable")
            on.append((cand[hit][order], xi[hit][order]))
        return a, t, on

    def interface_particles(self) -> np.ndarray:
        """Indices of the particles on the interface facets, the same on every rank (collective).

        A particle is on the interface when its distance to one of the interface facets is below
        ``1e-10`` times that facet's length. Each rank tests its owned interface facets; the flags
        are combined by an MPI MAX reduction.
        """
        from mpi4py import MPI

        patch = self.patch
        flags = np.zeros(patch.particles.num_particles, dtype=np.int8)
        for found, _ in self._facet_particles(patch.interface_facets)[2]:
            flags[found] = 1
        patch.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
        found = np.flatnonzero(flags)
        if found.size == 0 and patch.comm.allreduce(len(patch.interface_facets)) > 0:
            raise ValueError(
                "edge-to-edge coupling found no particle on the interface, so the FE and particle "
                "sides would not be coupled; use a particle spacing that puts particles on the "
                "interface (e.g. spacing = h) or coupling='lagrange'"
            )
        return found

    def _projected_normals(self, bq: QuadraturePoints) -> np.ndarray:
        """VCI boundary normals of the Lagrange coupling: on the interface facets the normal
        ``n`` is replaced by its L2 projection ``Pi n`` on the multiplier space (collective).

        The FE side of a linear field receives ``int N_a sigma n`` at the interface, which the
        multipliers carry as ``lambda = sigma Pi n`` (every trace ``N_a`` lies in their space);
        the particles then receive ``int phi_J sigma Pi n``, which is what the divergence
        identity of consistent integration must hold with. Where the interface turns inside one
        multiplier's support (every node by default, see :meth:`_interface_multipliers`) ``n``
        jumps there and ``Pi n != n``; with ``n`` itself the linear patch test missed by 3.8e-5
        (a slanted staircase of gmsh cells).
        The interface's multiplier mass matrix is gathered and solved on every rank.
        """
        V, comm = self.V, self.patch.comm
        on = np.flatnonzero(np.isin(bq.entities, self.patch.interface_facets))
        iq = QuadraturePoints(
            bq.points[on], bq.weights[on], bq.cells[on], bq.normals[on], bq.entities[on]
        )
        lam, _ = self._interface_multipliers(iq, facet_table(V, iq.points, iq.cells))
        M = (lam.T @ sp.diags(iq.weights) @ lam).tocoo()
        parts = comm.allgather((M.row, M.col, M.data))
        cat = np.concatenate
        M = sp.csc_matrix(
            (cat([p[2] for p in parts]), (cat([p[0] for p in parts]), cat([p[1] for p in parts]))),
            shape=M.shape,
        )
        rhs = comm.allreduce(np.asarray(lam.T @ (iq.weights[:, None] * iq.normals)), op=MPI.SUM)
        coef = np.column_stack([spsolve(M, rhs[:, k]) for k in range(rhs.shape[1])])
        normals = bq.normals.copy()
        normals[on] = lam @ coef
        return normals

    def _interface_interpolant(self, bq: QuadraturePoints, values: sp.csr_matrix) -> sp.csr_matrix:
        """VCI boundary values of the edge-to-edge coupling: on the interface facets the particle
        functions are replaced by their interpolant on the interface particles,
        ``I_P phi_J = sum_I psi_I phi_J(x_I)`` with ``psi_I`` the piecewise-linear hats of the
        interface particles along each facet (collective).

        The collocated multipliers pass the interface force to particle ``J`` as
        ``sum_I phi_J(x_I) lambda_I``. For a linear field ``lambda_I = int psi_I sigma n``
        balances the FE side (``sum_I N_a(x_I) psi_I = N_a`` on a facet whose ends are
        particles, as the conforming and vertex placements make them) and gives the particles
        ``int sigma n I_P phi_J``; with the consistent integration's divergence identity written
        with the same ``I_P phi_J`` on the interface the linear patch test passes to round-off
        (with ``int sigma n phi_J`` it missed by about 4e-2). With particles only at the facets'
        ends ``I_P`` is the FE interpolant ``I_h phi_J = sum_a N_a phi_J(x_a)``. Particles
        between the ends (spacing < h) need ``I_P``: with ``I_h`` a particle between two nodes
        has ``I_h phi_J`` near 0 where ``phi_J`` is near 1, the correction spoils the particle
        gradients near the interface and the error fell at rate 1.1 only (4.3x the FE error,
        quadrilateral staircase, spacing 0.5 h, traction). A facet whose ends are not particles
        (``placement="grid"``) keeps ``I_h``.
        """
        V, comm, patch = self.V, self.patch.comm, self.patch
        on = np.flatnonzero(np.isin(bq.entities, patch.interface_facets))
        a, t, found = self._facet_particles(patch.interface_facets)
        index = {int(f): i for i, f in enumerate(patch.interface_facets)}
        fe = facet_table(V, bq.points[on], bq.cells[on])
        xn = V.tabulate_dof_coordinates()[:, :2]
        xp = patch.particles.positions
        rows, sites, weights = [], [], []
        for r, q in enumerate(on):
            i = index[int(bq.entities[q])]
            ids, xi = found[i]
            if ids.size >= 2 and xi[0] < 1e-9 and xi[-1] > 1.0 - 1e-9:
                s = float((bq.points[q] - a[i]) @ t[i] / (t[i] @ t[i]))
                k = int(np.clip(np.searchsorted(xi, s, side="right") - 1, 0, ids.size - 2))
                w = (s - xi[k]) / (xi[k + 1] - xi[k])
                pts, ws = xp[ids[k : k + 2]], [1.0 - w, w]
            else:
                row = fe.getrow(r)
                pts, ws = xn[row.indices], list(row.data)
            rows += [r] * len(ws)
            sites.append(pts)
            weights += ws
        sites = np.vstack(sites) if sites else np.zeros((0, 2))
        phi = raise_on_all_ranks(comm, lambda: self.mls.tabulate(sites, 0)).values
        B = sp.csr_matrix(
            (
                np.asarray(weights, dtype=float),
                (np.asarray(rows, dtype=np.int64), np.arange(len(sites))),
            ),
            shape=(on.size, len(sites)),
        )
        interpolant = (B @ phi).tocsr()
        place = sp.csr_matrix(
            (np.ones(on.size), (on, np.arange(on.size))), shape=(len(bq), on.size)
        )
        mask = np.ones(len(bq))
        mask[on] = 0.0
        return (sp.diags(mask) @ values + place @ interpolant).tocsr()

    def _collocation_rows(self) -> tuple[tuple, Layout]:
        """Edge-to-edge coupling: one multiplier per interface particle and component, owned by
        the particle's owner, rows ``u_FE(x_I) - u_P(x_I)`` (collective).

        Returns:
            ``((block rows, global FE nodes, N values, True), (block rows, particles, phi
            values))`` of this rank's owned interface particles, and the multipliers' layout.
        """
        P, comm = self.patch.particles, self.patch.comm
        iface = self.interface_particles()
        # multiplier blocks in PETSc particle order, hence owner by owner and contiguous per rank
        iface = iface[np.argsort(P.petsc_index[iface], kind="stable")]
        layout = Layout.from_local(comm, int(np.sum(P.owner[iface] == comm.rank)))
        mine = iface[P.owner[iface] == comm.rank]
        block = layout.start + np.arange(mine.size, dtype=np.int64)
        xs = P.positions[mine]
        n_fe = tabulate_fe_basis(self.V, xs, derivatives=0).values.tocoo()
        keep = np.abs(n_fe.data) > 1e-13  # nodes off the particle's facet: round-off
        phi = raise_on_all_ranks(comm, lambda: self.mls.tabulate(xs, 0)).values.tocoo()
        phi_keep = phi.data != 0.0
        fe_rows = (block[n_fe.row[keep]], n_fe.col[keep], n_fe.data[keep], True)
        p_rows = (block[phi.row[phi_keep]], phi.col[phi_keep], phi.data[phi_keep])
        ml = Layout(2 * layout.size_local, 2 * layout.size_global, 2 * layout.start)
        return (fe_rows, p_rows), ml

    def _essential_conditions(self, also_strong=None) -> tuple:
        """Split the essential conditions: strong on FE facets, multipliers on patch facets.

        Args:
            also_strong: Optional ``also_strong(patch_facets) -> facets`` naming patch facets whose
                FE nodes are fixed strongly as well (the bridging band, where FE also lives).

        Returns:
            ``(fe_bc, patch_bc, quadratures, tables, ubc, is_bc)``: the ``(facets, value)`` pairs
            on FE facets (strong) and on patch facets, the patch facets' quadratures and particle
            tables (for :func:`~dolfinx_meshfree.efg.facet_multipliers`), the FE values as a
            Function and the flag of every local FE node fixed strongly (collective).
        """
        V, comm = self.V, self.patch.comm
        msh = V.mesh
        deg = self.quadrature_degree
        fe_bc, patch_bc = [], []
        for facets, fn in self._dirichlet:
            f_fe, f_p = self._split(facets)
            if also_strong is not None:
                f_fe = np.concatenate([f_fe, also_strong(f_p)])
            fe_bc.append((f_fe, fn))
            patch_bc.append((f_p, fn))
        dq = [facet_quadrature(msh, f, deg) for f, _ in patch_bc]
        dtabs = [raise_on_all_ranks(comm, lambda d=d: self.mls.tabulate(d.points, 0)) for d in dq]
        ubc = dolfinx.fem.Function(V)
        ubc.x.array[:] = 0.0
        is_bc = np.zeros(ubc.x.array.size // 2, dtype=bool)
        coords = V.tabulate_dof_coordinates()[:, :2]
        for f, fn in fe_bc:
            flags = self._node_flags(
                dolfinx.fem.locate_dofs_topological(V, msh.topology.dim - 1, f)
            )
            xn = coords[flags]
            vals = raise_on_all_ranks(
                comm, lambda fn=fn, xn=xn: _vector_values(fn, (xn,), len(xn), "dirichlet")
            )
            ubc.x.array.reshape(-1, 2)[flags] = vals
            is_bc |= flags
        for flags, vals in self._strong:  # by node (CoupledLinearProblem's DirichletBCs)
            ubc.x.array.reshape(-1, 2)[flags] = vals[flags]
            is_bc |= flags
        return fe_bc, patch_bc, dq, dtabs, ubc, is_bc

    def _fix_fe_rows(self, K_fe, b_fe, fixed_local: np.ndarray, values: np.ndarray):
        """Fix FE dofs: zero their rows and columns of ``K_fe`` with 1 on the diagonal and lift the
        values into ``b_fe`` (``MatZeroRowsColumns``). Collective.

        Args:
            fixed_local: bool per local node (owned and ghost) to fix.
            values: (num local nodes, 2) values of the fixed nodes (others ignored).

        Returns:
            The PETSc vector of fixed values (the caller destroys it).
        """
        fe_layout, l2g = self._fe_layout()
        n_owned = self.V.dofmap.index_map.size_local
        fixed = np.flatnonzero(fixed_local[:n_owned])
        rows = (2 * l2g[fixed][:, None] + np.arange(2)).ravel().astype(PETSc.IntType)
        x_bc = create_vector(
            self.patch.comm, fe_layout, rows, np.asarray(values).reshape(-1, 2)[fixed].ravel()
        )
        # rows of dofs that no FE cell supports are empty, diagonal included: add it
        K_fe.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        zero = K_fe.createVecLeft()
        zero.set(0.0)
        K_fe.setDiagonal(zero, addv=PETSc.InsertMode.ADD_VALUES)
        zero.destroy()
        K_fe.zeroRowsColumns(rows, diag=1.0, x=x_bc, b=b_fe)
        return x_bc

    def _traction_loads(self) -> tuple[PETSc.Vec, np.ndarray]:
        """Tractions on FE facets (FE load vector, PETSc) and on patch facets (particle loads in
        original particle order, local contributions), plus the body forces (FE cells with
        ``N_a``, patch cells with ``phi_J``). Collective."""
        V, comm = self.V, self.patch.comm
        msh, deg = V.mesh, self.quadrature_degree
        fe_layout, l2g = self._fe_layout()
        f_fe_rows, f_fe_vals = [np.zeros(0, np.int64)], [np.zeros(0)]
        f_p = np.zeros(2 * self.patch.particles.num_particles)
        for facets, fn in self._tractions:
            f_fe_facets, f_p_facets = self._split(facets)
            q = facet_quadrature(msh, f_fe_facets, deg)
            t = raise_on_all_ranks(
                comm, lambda fn=fn, q=q: _vector_values(fn, (q.points, q.normals), len(q), "t")
            )
            tab = tabulate_in_cells(V, q.points, q.cells, derivatives=0).values
            fl = load_vector(tab, q.weights, t).reshape(-1, 2)
            for comp in range(2):
                f_fe_rows.append(2 * l2g[: fl.shape[0]] + comp)
                f_fe_vals.append(fl[:, comp])
            q = facet_quadrature(msh, f_p_facets, deg)
            t = raise_on_all_ranks(
                comm, lambda fn=fn, q=q: _vector_values(fn, (q.points, q.normals), len(q), "t")
            )
            tab = raise_on_all_ranks(comm, lambda q=q: self.mls.tabulate(q.points, 0)).values
            f_p += load_vector(tab, q.weights, t)
        b_fe = create_vector(comm, fe_layout, np.concatenate(f_fe_rows), np.concatenate(f_fe_vals))
        if self._body_forces:  # FE cells with N_a, patch cells with phi_J
            fe, fp = self._body_loads(self.cell_indicator(~self.patch.in_patch))
            b_fe.array[:] += fe
            f_p += fp
        return b_fe, f_p

    def _append_patch_conditions(self, blocks, rhs, mats, patch_bc, dq, dtabs) -> Layout:
        """Append the multiplier field of essential conditions on patch facets (it couples to
        field 1, the particles) to ``blocks``/``rhs``; new PETSc objects go to ``mats``."""
        P, comm = self.patch.particles, self.patch.comm
        pl = P.dof_layout()
        Gd, d_rows, d_vals, dl = facet_multipliers(P, patch_bc, dq, dtabs, self.material.E)
        if dl.size_global:
            D = create_aij(comm, Gd, dl, pl)
            DT = create_aij(comm, Gd.T.tocsr(), pl, dl)
            for row in blocks:
                row.append(None)
            blocks[1][-1] = DT
            blocks.append([None, D] + [None] * (len(blocks) - 1))
            rhs.append(create_vector(comm, dl, d_rows, d_vals))
            mats += [D, DT]
        return dl

    def _solve_and_gather(self, blocks, rhs, objects, solver: str):
        """Solve the nest (fields FE, particles, multipliers...), destroy ``objects`` and ``rhs``,
        and return the FE Function, the particle coefficients (n, 2) in original order and the
        solve time. Collective."""
        V, P, comm = self.V, self.patch.particles, self.patch.comm
        system = BlockSystem(blocks, rhs, num_primal=2)
        t0 = time.perf_counter()
        parts = system.solve(solver)
        seconds = time.perf_counter() - t0
        system.destroy()
        for obj in [*objects, *rhs]:
            obj.destroy()
        uh = dolfinx.fem.Function(V)
        uh.x.array[: 2 * V.dofmap.index_map.size_local] = parts[0]
        uh.x.scatter_forward()
        owned = np.concatenate(comm.allgather(parts[1]))
        return uh, owned.reshape(-1, 2)[P.petsc_index], seconds

    # -- operators (explicit dynamics) ----------------------------------------------------------

    def operators(
        self, integration: str = "cells", slaves: str = "layer", consistent: bool = False
    ) -> CouplingOperators:
        """The coupling's assembled operators without essential conditions (collective).

        Stiffness blocks, constraint blocks with unit scaling, the weights of the FE energy and
        the particle quadrature with its MLS table (for lumped masses), and the coupling's
        interface object; see :class:`CouplingOperators`. Tractions and Dirichlet conditions
        given to this object are not used. Every coupling of :data:`COUPLINGS` is available.

        Args:
            integration: ``"cells"`` (default): the particle stiffness on the patch cells' Gauss
                rule; ``"stress-points"``: at the particles and stress points with their
                volumes (Rabczuk, Belytschko & Xiao 2004; see
                :mod:`~dolfinx_meshfree.stress_points`), for ``lagrange``, ``edge-to-edge``
                and ``master-slave``; :attr:`CouplingOperators.particle_quadrature` is then that
                rule. The ramp and bridging couplings integrate blended or weighted functions
                on cells and refuse it.
            slaves: ``master-slave`` only: ``"layer"`` (default, the first particle layer
                rigidly linked to the interface, eq. 17–28) or ``"coincident"`` (Johnson's
                particles fixed to the interface FE nodes, eq. 15–16); see
                :class:`~dolfinx_meshfree.master_slave.MasterSlaveLinks`.
            consistent: Variationally consistent integration in the particle stiffness. Default
                ``False`` whatever :attr:`consistent` says: explicit dynamics needs a symmetric
                ``K`` for its discrete energy identity; the VCI stiffness is Petrov-Galerkin, not
                symmetric (rod of tests/test_dynamic_couplings.py, two transits: energy drift
                1.4e-3 to 3.1e-3 instead of 1e-14, velocity error unchanged to 3 %, master-slave
                +47 %). ``True``: VCI for lagrange, edge-to-edge, bridging and master-slave.

        Raises:
            ValueError: on every rank, for an unknown or unsupported option.
        """
        from .master_slave import SLAVES
        from .stress_points import check_integration

        check_integration(integration)
        if slaves not in SLAVES:
            raise ValueError(f"slaves={slaves!r} is not known; use one of {list(SLAVES)}")
        if slaves != "layer" and self.coupling != "master-slave":
            raise ValueError(
                f"slaves={slaves!r} is an option of coupling='master-slave', not of "
                f"coupling={self.coupling!r}"
            )
        if integration != "cells" and self.coupling in ("bridging", "ramp", "ramp-cubic"):
            raise ValueError(
                f"integration={integration!r} is not available with coupling={self.coupling!r} "
                "(its particle functions are blended or weighted on cells); use 'cells', or "
                "lagrange, edge-to-edge or master-slave"
            )
        # the builders read the option from the problem: a shallow copy carries this call's
        problem = copy.copy(self)
        problem.consistent = bool(consistent)
        if self.coupling == "master-slave":
            from .master_slave import master_slave_operators

            return master_slave_operators(problem, integration, slaves)
        if self.coupling == "bridging":
            from .bridging import bridging_operators

            return bridging_operators(problem)
        if self.coupling in ("ramp", "ramp-cubic"):
            from .ramp import ramp_operators

            return ramp_operators(problem)
        return problem._interface_operators(integration)

    def _sizes(self, active: np.ndarray, multiplier_dofs: int) -> dict:
        """The system's sizes for :attr:`CoupledSolution.sizes`: active FE dofs (from the flags
        of the local nodes), particle dofs and multiplier dofs (collective)."""
        n_owned = self.V.dofmap.index_map.size_local
        return {
            "fe_dofs": 2 * self.patch.comm.allreduce(int(np.sum(active[:n_owned]))),
            "particle_dofs": 2 * self.patch.particles.num_particles,
            "multiplier_dofs": multiplier_dofs,
        }

    def _fe_active(self, cells: np.ndarray | None = None) -> np.ndarray:
        """Flag of every local FE node of the given owned cells (default: the FE cells)."""
        cells = self.patch.fe_cells if cells is None else cells
        return self._node_flags(_compat.dofmap_array(self.V)[cells].ravel())

    def _particle_rule(self, integration: str) -> QuadraturePoints | None:
        """The stress-point rule of the patch, or ``None`` for the cells' Gauss rule."""
        if integration == "cells":
            return None
        from .stress_points import stress_point_quadrature

        return stress_point_quadrature(self.patch.particles)

    def _interface_operators(self, integration: str = "cells") -> CouplingOperators:
        """Lagrange (FE trace multipliers, eq. 109) and edge-to-edge (collocation) operators."""
        t0 = time.perf_counter()
        V, patch, P = self.V, self.patch, self.patch.particles
        comm, n = patch.comm, patch.particles.num_particles
        fe_layout, l2g = self._fe_layout()
        pl = self.patch.particles.dof_layout()
        boundary = patch.boundary() if self.consistent else None
        Kp_loc, q, tq, _ = particle_stiffness(
            P,
            self.mls,
            self.material,
            self.quadrature_degree,
            boundary,
            quadrature=self._particle_rule(integration),
            boundary_normals=self._projected_normals if self.coupling == "lagrange" else None,
        )
        if self.coupling == "lagrange":
            fe_rows, p_rows, ml = self._lagrange_rows()
        else:
            (fe_rows, p_rows), ml = self._collocation_rows()
        no_bc = np.zeros(l2g.size, dtype=bool)
        zero = dolfinx.fem.Function(V)
        zero.x.array[:] = 0.0
        G_fe, _, _ = _fe_constraint_block(
            *fe_rows[:3], fe_rows[3], 1.0, no_bc, zero, l2g, (ml.size_global, fe_layout.size_global)
        )
        G_p = _particle_constraint_block(*p_rows, 1.0, P.petsc_dofs(2), (ml.size_global, 2 * n))
        return CouplingOperators(
            coupling=self.coupling,
            K_fe=self._fe_stiffness(),
            K_p=create_aij(comm, Kp_loc, pl, pl),
            fe_weight=self.cell_indicator(~patch.in_patch),
            fe_active=self._fe_active(),
            particle_quadrature=q,
            particle_table=tq.values.tocsr(),
            fe_layout=fe_layout,
            particle_layout=pl,
            G_fe=create_aij(comm, G_fe, ml, fe_layout),
            G_p=create_aij(comm, G_p, ml, pl),
            multiplier_layout=ml,
            timings={"operators": time.perf_counter() - t0},
        )

    # -- solve ----------------------------------------------------------------------------------

    def solve(self, solver: str = "mumps") -> CoupledSolution:
        """Assemble the nest block system and solve it (collective).

        Args:
            solver: ``"mumps"`` (direct) or ``"fieldsplit"`` (Schur complement, displacements
                against multipliers, on the augmented Lagrangian; see
                :class:`~dolfinx_meshfree.petsc.BlockSystem`).
        """
        if solver not in ("mumps", "fieldsplit"):
            raise ValueError(f"solver={solver!r} is not known; use 'mumps' or 'fieldsplit'")
        if self.coupling == "bridging":
            from .bridging import solve_bridging

            return solve_bridging(self, solver)
        if self.coupling == "master-slave":
            from .master_slave import solve_master_slave

            return solve_master_slave(self, solver)
        if self.coupling in ("ramp", "ramp-cubic"):
            from .ramp import solve_ramp

            return solve_ramp(self, solver)
        patch, P = self.patch, self.patch.particles
        comm = patch.comm
        deg = self.quadrature_degree
        n = P.num_particles
        s = self.material.E
        pdofs = P.petsc_dofs(2)
        fe_layout, l2g = self._fe_layout()
        pl = P.dof_layout()
        t0 = time.perf_counter()

        # particle side
        boundary = patch.boundary() if self.consistent else None
        hook = self._interface_interpolant if self.coupling == "edge-to-edge" else None
        normals = self._projected_normals if self.coupling == "lagrange" else None
        Kp_loc, _, _, kt = particle_stiffness(
            P, self.mls, self.material, deg, boundary, hook, boundary_normals=normals
        )

        # essential conditions: FE side strongly, patch side by multipliers
        _, patch_bc, dq, dtabs, ubc, is_bc = self._essential_conditions()
        # FE nodes that no FE cell supports
        active = self._fe_active()

        # interface multipliers
        if self.coupling == "lagrange":
            fe_rows, p_rows, ml = self._lagrange_rows()
        else:
            (fe_rows, p_rows), ml = self._collocation_rows()
        setup = self._setup + time.perf_counter() - t0 - kt["assemble"]

        t1 = time.perf_counter()
        K_fe = self._fe_stiffness()
        G_fe, g_rows, g_vals = _fe_constraint_block(
            *fe_rows[:3], fe_rows[3], s, is_bc, ubc, l2g, (ml.size_global, fe_layout.size_global)
        )
        G_p = _particle_constraint_block(*p_rows, s, pdofs, (ml.size_global, 2 * n))

        b_fe, f_p = self._traction_loads()
        cat = np.concatenate
        # strong conditions and inactive dofs on K_FE: zero rows and columns, lift into b_fe
        x_bc = self._fix_fe_rows(
            K_fe, b_fe, is_bc | ~active, np.where(is_bc[:, None], ubc.x.array.reshape(-1, 2), 0.0)
        )
        Kp = create_aij(comm, Kp_loc, pl, pl)
        b_p = create_vector(comm, pl, pdofs.ravel(), f_p)
        Gfe = create_aij(comm, G_fe, ml, fe_layout)
        GfeT = create_aij(comm, G_fe.T.tocsr(), fe_layout, ml)
        Gp = create_aij(comm, G_p, ml, pl)
        GpT = create_aij(comm, G_p.T.tocsr(), pl, ml)
        g = create_vector(comm, ml, cat([*g_rows, np.zeros(0, np.int64)]), cat([*g_vals, []]))
        blocks = [[K_fe, None, GfeT], [None, Kp, GpT], [Gfe, Gp, None]]
        rhs = [b_fe, b_p, g]
        mats = [K_fe, Kp, Gfe, GfeT, Gp, GpT]
        dl = self._append_patch_conditions(blocks, rhs, mats, patch_bc, dq, dtabs)
        assemble = time.perf_counter() - t1 + kt["assemble"]
        uh, coeffs, solve = self._solve_and_gather(blocks, rhs, [*mats, x_bc], solver)
        return CoupledSolution(
            u=uh,
            coefficients=coeffs,
            mls=self.mls,
            patch=patch,
            timings={"setup": setup, "assemble": assemble, "solve": solve},
            sizes=self._sizes(active, ml.size_global + dl.size_global),
        )


def _fe_constraint_block(
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

    Entry ``k`` contributes ``s values[k]`` at ``(2 rows[k] + i, 2 node + i)`` for each component
    ``i``; a column that is a strong Dirichlet dof (``is_bc``, value in ``ubc``) is dropped and
    ``-s values[k] ubc`` is added to the constraint's right-hand side instead.

    Args:
        rows: (k,) global multiplier block (node) numbers.
        nodes: (k,) FE node columns: local nodes of ``V`` or, with ``global_nodes``, global nodes
            (which must be local, owned or ghost, on this rank).
        values: (k,) unscaled entries; ``s``: the scaling of the constraint rows.
        is_bc, ubc: Strong-condition flags (per local node) and values; ``l2g``: local to global
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
    bc_col = is_bc[c]
    g_rows, g_vals = [], []
    gfe: tuple[list, list, list] = ([], [], [])
    for comp in range(2):
        rr = 2 * r + comp
        cols = 2 * l2g[c] + comp
        # known FE values move to the right-hand side
        g_rows.append(rr[bc_col])
        g_vals.append(-s * v[bc_col] * ubc.x.array[2 * c[bc_col] + comp])
        gfe[0].append(rr[~bc_col])
        gfe[1].append(cols[~bc_col])
        gfe[2].append(s * v[~bc_col])
    G = sp.csr_matrix(
        (np.concatenate(gfe[2]), (np.concatenate(gfe[0]), np.concatenate(gfe[1]))), shape=shape
    )
    return G, g_rows, g_vals


def _particle_constraint_block(
    rows: np.ndarray,
    particles: np.ndarray,
    values: np.ndarray,
    s: float,
    pdofs: np.ndarray,
    shape: tuple[int, int],
) -> sp.csr_matrix:
    """Particle columns ``s G_P``: ``-s values[k]`` at ``(2 rows[k] + i, pdofs[particle, i])``."""
    return sp.csr_matrix(
        (
            np.concatenate([-s * values, -s * values]),
            (
                np.concatenate([2 * rows, 2 * rows + 1]),
                np.concatenate([pdofs[particles, 0], pdofs[particles, 1]]),
            ),
        ),
        shape=shape,
    )


#: FE basis values at points on a facet below this are round-off of the nodes off the facet
#: (the inverse map of a non-affine quadrilateral leaves up to 1.5e-13 on the gmsh meshes).
ROUND_OFF = 1e-11


def facet_table(V, points: np.ndarray, cells: np.ndarray) -> sp.csr_matrix:
    """FE basis values (points x local nodes) at points on facets of the given cells, without
    the round-off entries of the nodes off the facet."""
    t = tabulate_in_cells(V, points, cells, derivatives=0).values.tocsr()
    t.data[np.abs(t.data) <= ROUND_OFF] = 0.0
    t.eliminate_zeros()
    return t


def facet_nodes(V, facets: np.ndarray) -> np.ndarray:
    """Local P1/Q1 nodes (block indices) of each facet of a 2D mesh, shape (num_facets, 2)."""
    msh = V.mesh
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim, 0)
    msh.topology.create_connectivity(tdim - 1, 0)
    c2v = msh.topology.connectivity(tdim, 0)
    f2v = msh.topology.connectivity(tdim - 1, 0)
    vmap = msh.topology.index_map(0)
    node_of_vertex = np.empty(vmap.size_local + vmap.num_ghosts, dtype=np.int64)
    node_of_vertex[np.asarray(c2v.array)] = _compat.dofmap_array(V).ravel()
    fv = np.asarray(f2v.array).reshape(-1, 2)[np.asarray(facets, dtype=np.int64)]
    return node_of_vertex[fv]


def fe_dof_layout(V) -> tuple[Layout, np.ndarray]:
    """PETSc layout of the interleaved dofs of a vector P1/Q1 space (DOLFINx's numbering), and
    the global node number of every local node."""
    imap = V.dofmap.index_map
    l2g = np.asarray(
        imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    )
    return Layout(2 * imap.size_local, 2 * imap.size_global, 2 * imap.local_range[0]), l2g


def node_flags(V, local_nodes: np.ndarray) -> np.ndarray:
    """Flag nodes (local block indices) of ``V`` on every rank that has them, owned or ghost
    (collective)."""
    f = dolfinx.fem.Function(V)
    f.x.array[:] = 0.0
    f.x.array[2 * np.asarray(local_nodes, dtype=np.int64)] = 1.0
    _compat.scatter_reverse_add(f)
    f.x.scatter_forward()
    return f.x.array[0::2] > 0.5


def cell_indicator(msh, owned_flags: np.ndarray) -> dolfinx.fem.Function:
    """DG0 Function equal to 1 on the owned cells flagged in ``owned_flags`` (and on their ghost
    copies), 0 elsewhere (collective)."""
    Q = _compat.scalar_function_space(msh, "DG", 0)
    chi = dolfinx.fem.Function(Q)
    dof_of_cell = _compat.dofmap_array(Q)[:, 0]
    n_owned = msh.topology.index_map(msh.topology.dim).size_local
    chi.x.array[:] = 0.0
    chi.x.array[dof_of_cell[:n_owned]] = np.asarray(owned_flags[:n_owned], dtype=float)
    chi.x.scatter_forward()
    return chi
