"""The sides of a finite-strain block system, and the block problem Newton solves.

* :class:`FESide`: the FE field, residual and Jacobian of a user's UFL residual (its cell
  integrals, weighted by a cell indicator), assembled by DOLFINx;
* :class:`ParticleSide`: the particle field, ``f_int`` and ``K_T`` of a
  :class:`~dolfinx_meshfree.InternalForces` (Rabczuk et al. 2006, eq. 34) in PETSc numbering;
* :class:`BlendedSide`: cells where the displacement blends both fields (the ramps' interface
  elements, Belytschko et al. 1995, eq. 3.12-3.16): ``f_int`` and ``K_T`` on a table with
  columns ``[local FE nodes | particles]``, split into the FE and particle rows and the four
  blocks FE-FE, FE-P, P-FE, P-P;
* :class:`BlockProblem`: ``R(x) = f_int(x) - t f_ext + C x - t c`` on a nest whose primal
  diagonal blocks are the sides' tangents (plus the blended sides' blocks) and whose other
  blocks ``C`` (constraints) are constant; what :func:`~dolfinx_meshfree.statics.newton.newton`
  solves.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import dolfinx
import numpy as np
import scipy.sparse as sp
import ufl
from petsc4py import PETSc
from ufl.algorithms import expand_derivatives, extract_coefficients
from ufl.classes import Sum

from .. import _compat
from ..approx.fe_dofs import cell_indicator, fe_dof_layout
from ..approx.tables import ShapeTable
from ..geometry.particles import ParticleSet
from ..geometry.quadrature import QuadraturePoints, cell_sizes
from ..parallel import Layout
from ..physics.constitutive import Material
from ..physics.forces import InternalForces
from ..physics.state import BoundLaw, PointState, StatefulLaw, is_stateful
from .fe_state import FEStateLaw
from .kept_factor import KeptFactorisation
from .newton import NewtonError, NewtonOptions, NewtonResult, newton
from .petsc import SolverOptions, create_aij, create_vector

if TYPE_CHECKING:  # annotations only
    from mpi4py import MPI

    from .history import SolveHistory

__all__ = [
    "BlendedSide",
    "BlockProblem",
    "FESide",
    "NonlinearSolveResult",
    "ParticleSide",
    "cell_part",
    "check_particle_band",
    "on_cells",
    "particle_band_factor",
    "particle_coefficients",
    "restore_step",
    "solve_built",
    "solve_load_steps",
    "split_residual",
    "zeros",
]


class NonlinearSolveResult(NamedTuple):
    """``(iterations, converged)`` as DOLFINx's ``NewtonSolver.solve`` returns, over all load
    steps; the per-step :class:`~dolfinx_meshfree.statics.newton.NewtonResult` records in
    ``steps``."""

    iterations: int
    converged: bool
    steps: list


def zeros(comm: MPI.Comm, layout: Layout) -> PETSc.Vec:
    """A distributed zero vector of ``layout``."""
    return create_vector(comm, layout, np.zeros(0, np.int64), np.zeros(0))


# -- the two sides ------------------------------------------------------------------------------


def _terms(expr) -> list:
    """The operands of a top-level sum (the terms a user adds in a residual)."""
    if isinstance(expr, Sum):
        return [t for op in expr.ufl_operands for t in _terms(op)]
    return [expr]


def split_residual(F: ufl.Form, u: dolfinx.fem.Function) -> tuple[ufl.Form, ufl.Form | None]:
    """``F(u; v) = F_int(u; v) - L(v)``: the terms that depend on ``u`` and the dead load ``L``
    (minus the terms that do not), integral by integral and term by term of each integrand.

    A cell term of ``u`` that does not vanish at ``u = 0`` holds a dead part: an initial or
    thermal stress written inside the law's term, ``inner(P(F(u)) - P_0, grad(v))``. Its value
    at ``u = 0`` goes to ``L`` and ``F_int`` keeps ``T(u) - T(0)``, which is zero in the
    reference state, as the particles' law is (``F`` is unchanged; collective: the values at
    ``u = 0`` are assembled to find out).

    Returns ``(F_int, L)``; ``L`` is ``None`` without load terms.
    """
    internal, load = [], []
    zero = ufl.as_vector([0.0] * u.ufl_shape[0])
    for itg in expand_derivatives(F).integrals():
        for term in _terms(itg.integrand()):
            part = itg.reconstruct(integrand=term)
            if u not in extract_coefficients(term):
                load.append(part)
                continue
            internal.append(part)
            if itg.integral_type() != "cell":
                continue
            value = expand_derivatives(ufl.replace(term, {u: zero}))
            if isinstance(value, ufl.classes.Zero):
                continue
            at_rest = itg.reconstruct(integrand=value)
            b = _compat.assemble_vector(_compat.create_form(ufl.Form([at_rest])))
            b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            dead = b.norm() > 0.0
            b.destroy()
            if dead:
                internal.append(at_rest.reconstruct(integrand=-at_rest.integrand()))
                load.append(at_rest)
    L = ufl.Form([i.reconstruct(integrand=-i.integrand()) for i in load]) if load else None
    return ufl.Form(internal), L


#: The tag of the cells a restricted FE residual integrates over.
ON = 1


def on_cells(
    F: ufl.Form, msh: dolfinx.mesh.Mesh, flags: np.ndarray, weight: ufl.core.expr.Expr | None = None
) -> ufl.Form:
    """The cell integrals of ``F`` on the owned cells flagged in ``flags`` only, and its
    exterior-facet integrals, each integrand multiplied by ``weight`` if given.

    Integrals with subdomain data of the user's own are weighted by the indicator of the cells
    instead of restricted to them (the same where the integrand is finite everywhere). The
    exterior-facet integrals (elastic supports, follower loads) are kept as they are: the caller
    has checked that they run over facets of flagged cells only
    (:class:`~dolfinx_meshfree.statics.facet_terms.FacetTermCheck`)."""
    tdim = msh.topology.dim
    n_owned = msh.topology.index_map(tdim).size_local
    cells = np.flatnonzero(flags[:n_owned]).astype(np.int32)
    tags = dolfinx.mesh.meshtags(msh, tdim, cells, np.full(cells.size, ON, dtype=np.int32))
    out = []
    for itg in F.integrals():
        integrand = itg.integrand() if weight is None else weight * itg.integrand()
        if itg.integral_type() == "exterior_facet":
            out.append(itg.reconstruct(integrand=integrand))
            continue
        if itg.integral_type() != "cell":
            continue
        if itg.subdomain_data() is None and itg.subdomain_id() in ("everywhere", "otherwise"):
            out.append(itg.reconstruct(integrand=integrand, subdomain_id=ON, subdomain_data=tags))
        else:
            chi = cell_indicator(msh, flags)
            out.append(itg.reconstruct(integrand=chi * integrand))
    return ufl.Form(out)


def cell_part(
    F: ufl.Form, weight: ufl.core.expr.Expr | None = None, facets: bool = False
) -> ufl.Form:
    """The cell integrals of ``F`` (and with ``facets`` its other integrals too), each
    multiplied by ``weight`` if given."""
    itgs = [i for i in F.integrals() if facets or i.integral_type() == "cell"]
    if weight is not None:
        itgs = [i.reconstruct(integrand=weight * i.integrand()) for i in itgs]
    return ufl.Form(itgs)


class FESide:
    """The FE field: internal force and tangent of the user's residual on the FE cells.

    ``fixed`` (bool per local node) are the dofs held: strong Dirichlet nodes and nodes no FE
    cell carries. Their tangent rows are the identity (columns kept, so that the first Newton
    step of a load step carries the prescribed increment into the body, as DOLFINx's lifting
    does) and their residual is ``x - t x_bar``, with :attr:`fixed_values` ``x_bar`` (0 on the
    nodes no FE cell carries) and ``t`` the load factor.

    With a ``law`` with state, ``F_int`` is not read: the FE cells run the law through
    :class:`~dolfinx_meshfree.statics.fe_state.FEStateLaw` (``dilatation``: its volumetric
    strain, :mod:`~dolfinx_meshfree.statics.mean_dilatation`).
    """

    def __init__(
        self,
        F_int: ufl.Form,
        u: dolfinx.fem.Function,
        cells: np.ndarray | None,
        fixed: np.ndarray,
        weight: ufl.core.expr.Expr | None = None,
        law: StatefulLaw | None = None,
        dilatation: str | None = None,
    ) -> None:
        V = u.function_space
        self.u, self.V = u, V
        #: The law with state on the FE cells (:class:`~dolfinx_meshfree.statics.fe_state.
        #: FEStateLaw`), whose stress and tangent are updated before every assembly; ``None``:
        #: ``F_int`` is the whole FE internal force.
        self.state_law: FEStateLaw | None = None
        if law is not None:
            n = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
            owned = np.ones(n, bool) if cells is None else np.asarray(cells[:n], bool)
            cells_on = np.flatnonzero(owned)
            self.state_law = FEStateLaw(u, law, cells_on, weight, dilatation=dilatation)
            forms = (self.state_law.residual_form, self.state_law.jacobian_form)
            R, J = (f if cells is None else on_cells(f, V.mesh, cells) for f in forms)
        else:
            # on the FE cells only (``cells``: flags of the owned cells): a weight 0 on the patch
            # cells would still evaluate the law there, on an FE field that means nothing (NaN
            # at finite strain)
            R = (
                cell_part(F_int, weight, facets=True)  # every cell FE: facet terms whole
                if cells is None
                else on_cells(F_int, V.mesh, cells, weight)
            )
            J = ufl.derivative(R, u, ufl.TrialFunction(V))
        self._R = _compat.create_form(R)
        self._J = _compat.create_form(J)
        self._J_kept: PETSc.Mat | None = None  # the tangent's matrix, its pattern kept
        self.layout, l2g = fe_dof_layout(V)
        self.l2g = l2g
        n_owned = V.dofmap.index_map.size_local
        self.bs = bs = V.mesh.geometry.dim  # dofs per node: the vector space's block size
        nodes = np.flatnonzero(fixed[:n_owned])
        self.fixed_rows = (bs * l2g[nodes][:, None] + np.arange(bs)).ravel().astype(PETSc.IntType)
        self.fixed_local = (bs * nodes[:, None] + np.arange(bs)).ravel()
        #: Prescribed values of the fixed dofs (full load), set by the problem.
        self.fixed_values = np.zeros(self.fixed_local.size)
        self.n_owned = bs * n_owned

    def held_everywhere(self) -> np.ndarray:
        """The held rows (global FE dofs) of every rank (collective)."""
        comm = self.V.mesh.comm
        return np.concatenate(comm.allgather(np.asarray(self.fixed_rows, np.int64)))

    def hold(self, dofs: np.ndarray, values: np.ndarray, l2g: np.ndarray) -> None:
        """Fix owned local dofs (not nodes) to ``values`` (at full load)."""
        d = np.asarray(dofs, dtype=np.int64)
        self.fixed_rows = (self.bs * l2g[d // self.bs] + d % self.bs).astype(PETSc.IntType)
        self.fixed_local = d
        self.fixed_values = np.asarray(values, dtype=float)

    def destroy(self) -> None:
        """Free the kept tangent matrix."""
        if self._J_kept is not None:
            self._J_kept.destroy()
            self._J_kept = None

    def set_state(self, x: PETSc.Vec) -> None:
        self.u.x.array[: self.n_owned] = x.getArray(readonly=True)
        self.u.x.scatter_forward()
        if self.state_law is not None:
            self.state_law.update()

    @property
    def states(self) -> list[PointState]:
        """The state stores of this side (committed when a load step converges)."""
        return [] if self.state_law is None else [self.state_law.state]

    def internal_force(self, x: PETSc.Vec) -> PETSc.Vec:
        self.set_state(x)
        b = _compat.assemble_vector(self._R)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        r = zeros(x.getComm(), self.layout)
        r.array[:] = b.array_r[: self.n_owned]
        b.destroy()
        return r

    def tangent(self, x: PETSc.Vec) -> PETSc.Mat:
        """``K_T`` (a new matrix the caller owns): assembled into a kept matrix whose pattern
        has the whole diagonal (room for the identity rows of held dofs on nodes no FE cell
        carries), then copied: inserting the diagonal into a freshly assembled matrix at every
        iteration reallocated it (68 ms of the 117 ms tangent at 3,640 cells)."""
        self.set_state(x)
        if self._J_kept is None:
            J = _compat.assemble_matrix(self._J)
            J.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
            diag = J.createVecLeft()
            diag.set(0.0)
            J.setDiagonal(diag, addv=PETSc.InsertMode.ADD_VALUES)  # room on empty rows
            diag.destroy()
            self._J_kept = J
        else:
            _compat.assemble_matrix_into(self._J_kept, self._J)
        if self.state_law is not None:  # mean dilatation's cell terms
            self.state_law.complete_tangent(self._J_kept)
        J = self._J_kept.copy()
        J.zeroRows(self.fixed_rows, diag=1.0)
        return J


def particle_coefficients(particles: ParticleSet, x: PETSc.Vec) -> np.ndarray:
    """All particle coefficients of ``x`` (PETSc numbering), interleaved in original order, on
    every rank (collective)."""
    owned = np.concatenate(particles.comm.allgather(x.getArray(readonly=True)))
    return owned.reshape(-1, particles.gdim)[particles.petsc_index].ravel()


def check_particle_band(particle_band: object) -> None:
    """Refuse a ``particle_band`` that is not a positive number; ``None`` (the MLS dilation)
    passes (local, the same on every rank)."""
    if particle_band is not None and not (
        isinstance(particle_band, int | float)
        and not isinstance(particle_band, bool)
        and np.isfinite(particle_band)
        and particle_band > 0
    ):
        raise ValueError(
            f"particle_band={particle_band!r} must be a positive number (the crack band of a "
            "particle point in its integration cell's sizes), or None (the MLS dilation)"
        )


def particle_band_factor(approximation: object, band_factor: float | None) -> float:
    """The crack band of a particle point in integration-cell sizes: ``band_factor`` if
    given, else the dilation of the MLS ``approximation`` (the model's, whatever tabulated the
    particle rule: the ramps' tables do not carry it)."""
    if band_factor is not None:
        return float(band_factor)
    dilation = getattr(approximation, "dilation", None)
    if dilation is None:
        raise ValueError(
            f"the crack band of the particle points needs the MLS dilation, and "
            f"{type(approximation).__name__} has none: pass the band in cell sizes "
            "(particle_band=...)"
        )
    return float(dilation)


class ParticleSide:
    """The particle field: ``f_int`` and ``K_T`` on the patch quadrature, in PETSc numbering."""

    def __init__(
        self,
        particles: ParticleSet,
        tables: dict,
        material: Material | StatefulLaw,
        band_factor: float | None = None,
    ) -> None:
        if is_stateful(material) and material.needs_band and band_factor is None:
            raise ValueError(
                f"ParticleSide: {type(material).__name__} softens and needs the crack band of "
                "the particle points: pass band_factor (particle_band_factor(model.mls, ...))"
            )
        q, tq = tables["quadrature"], tables["table"]
        self.P, self.comm = particles, particles.comm
        #: The patch quadrature (points, weights, cells).
        self.rule = q
        weights = tables.get("weights", q.weights)  # the bridging band's alpha w_q
        #: The state store of a law with state at the patch quadrature, else ``None``. The
        #: crack band of a particle point is ``band_factor`` times its integration cell's size;
        #: the models pass :func:`particle_band_factor`, by default the MLS dilation: a smooth
        #: MLS field does not localise in a band narrower than about one support radius.
        self.state: PointState | None = None
        if is_stateful(material):
            band = None
            if material.needs_band:
                band = float(band_factor) * cell_sizes(particles.mesh, q.cells)
            self.state = PointState(material, q.points, band, q.cells)
            material = BoundLaw(self.state)
        self.forces = InternalForces(
            tq,
            weights,
            material,
            test_gradients=tables["test_gradients"],
            comm=particles.comm,
            approximation=tables.get("approximation"),
            hoop=tables.get("hoop"),
            test_hoop=tables.get("test_hoop"),
        )
        self.gdim = particles.gdim
        self.dof_map = particles.petsc_dofs(self.gdim).ravel()
        self.layout = particles.dof_layout(self.gdim)

    @property
    def states(self) -> list[PointState]:
        """The state stores of this side (committed when a load step converges)."""
        return [] if self.state is None else [self.state]

    def coefficients(self, x: PETSc.Vec) -> np.ndarray:
        """All particle coefficients, interleaved in original order, on every rank."""
        return particle_coefficients(self.P, x)

    def internal_force(self, x: PETSc.Vec) -> PETSc.Vec:
        f = self.forces.internal_force(self.coefficients(x))
        return create_vector(self.comm, self.layout, self.dof_map, f)

    def tangent(self, x: PETSc.Vec) -> PETSc.Mat:
        K = self.forces.tangent(self.coefficients(x)).tocoo()
        n = self.dof_map.size
        Kg = sp.csr_matrix((K.data, (self.dof_map[K.row], self.dof_map[K.col])), shape=(n, n))
        return create_aij(self.comm, Kg, self.layout, self.layout)


class BlendedSide:
    """Cells where the displacement blends the FE and particle fields: the ramps' interface
    elements, ``u = (1 - R) sum_a N_a u_a + R sum_J phi_J u_J`` (Belytschko et al. 1995, eq.
    3.12; Rabczuk et al. 2006, eq. 38-42 for the cubic ramp).

    ``F = I + grad_0 u`` with the blended gradients (eq. 3.16), ``f_int = sum_q B0^T P(F) w_q``
    and ``K_T`` by :class:`~dolfinx_meshfree.InternalForces` on the blended table (columns
    ``[local FE nodes | particles]``), then split by field: FE rows to the FE layout (ghost
    nodes' rows are sent to their owners), particle rows to the PETSc particle numbering.
    Rows of the FE side's held dofs are dropped (the block problem holds them).

    Args:
        fe, particles: The two sides (their state and numbering).
        table: The blended shape functions at this rank's interface quadrature points.
        weights: Their quadrature weights.
        material: The law of the interface cells (a law with state keeps it at these points).
        test_gradients: Test gradients (default: the table's), e.g. VCI-corrected particle
            columns.
        quadrature: The points (their cells: the crack band of a law with state).
    """

    #: The fields (block indices) this side couples.
    fields = (0, 1)

    def __init__(
        self,
        fe: FESide,
        particles: ParticleSide,
        table: ShapeTable,
        weights: np.ndarray,
        material: Material | StatefulLaw,
        test_gradients: Sequence[sp.spmatrix] | None = None,
        quadrature: QuadraturePoints | None = None,
    ) -> None:
        self.fe, self.particles, self.comm = fe, particles, particles.comm
        #: The state store of a law with state at the blended points (band: their cells' size,
        #: as on the FE cells), else ``None``.
        self.state: PointState | None = None
        if is_stateful(material):
            if quadrature is None:
                raise ValueError(
                    "a law with state on blended cells needs their quadrature (its cells give the "
                    "crack band)"
                )
            band = None
            if material.needs_band:
                band = cell_sizes(fe.V.mesh, quadrature.cells)
            self.state = PointState(material, quadrature.points, band, quadrature.cells)
            material = BoundLaw(self.state)
        self.forces = InternalForces(
            table, weights, material, test_gradients=test_gradients, comm=particles.comm
        )
        gdim = particles.gdim
        self.nf = fe.u.x.array.size  # FE columns: gdim per local node, owned and ghost
        fe_dofs = (gdim * fe.l2g[:, None] + np.arange(gdim)).ravel()
        self.dofs = np.concatenate([fe_dofs, particles.dof_map]).astype(np.int64)
        # rows of held FE dofs, ghosts' included (held by their owner's FE side)
        self._held = np.isin(fe_dofs, fe.held_everywhere())

    @property
    def states(self) -> list[PointState]:
        """The state stores of this side (committed when a load step converges)."""
        return [] if self.state is None else [self.state]

    def _coefficients(self, xs: Sequence[PETSc.Vec]) -> np.ndarray:
        self.fe.set_state(xs[0])
        return np.concatenate([self.fe.u.x.array, self.particles.coefficients(xs[1])])

    def strain_energy(self, xs: Sequence[PETSc.Vec]) -> float:
        """``sum_q W(F_q) w_q`` over this rank's blended points (not summed over ranks)."""
        return self.forces.strain_energy(self._coefficients(xs))

    def deformation_gradient(self, xs: Sequence[PETSc.Vec]) -> np.ndarray:
        """``F`` (m, d, d) at this rank's blended points."""
        return self.forces.deformation_gradient(self._coefficients(xs))

    def internal_force(self, xs: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        """``f_int`` of the blended cells: ``[FE rows, particle rows]``. Collective."""
        f = self.forces.internal_force(self._coefficients(xs))
        keep = np.concatenate([~self._held, np.ones(f.size - self.nf, dtype=bool)])
        nf = self.nf
        fe = create_vector(self.comm, self.fe.layout, self.dofs[:nf][keep[:nf]], f[:nf][keep[:nf]])
        p = create_vector(self.comm, self.particles.layout, self.dofs[nf:], f[nf:])
        return [fe, p]

    def tangent(self, xs: Sequence[PETSc.Vec]) -> dict[tuple[int, int], PETSc.Mat]:
        """``K_T`` of the blended cells by blocks ``{(i, j): Mat}`` of :attr:`fields`."""
        K = self.forces.tangent(self._coefficients(xs)).tocoo()
        nf = self.nf
        row_fe, col_fe = K.row < nf, K.col < nf
        keep = ~(row_fe & self._held[np.minimum(K.row, nf - 1)])
        r, c = self.dofs[K.row], self.dofs[K.col]
        layouts = [self.fe.layout, self.particles.layout]
        out = {}
        for i, rows in enumerate((row_fe, ~row_fe)):
            for j, cols in enumerate((col_fe, ~col_fe)):
                sel = keep & rows & cols
                shape = (layouts[i].size_global, layouts[j].size_global)
                local = sp.csr_matrix((K.data[sel], (r[sel], c[sel])), shape=shape)
                out[i, j] = create_aij(self.comm, local, layouts[i], layouts[j])
        return out


# -- the block problem --------------------------------------------------------------------------


@dataclass
class BlockProblem:
    """``R(x) = f_int(x) - t f_ext + C x - t c`` on a nest whose first fields have nonlinear
    diagonal blocks (``sides``), whose other blocks ``C`` are constant (constraints), and whose
    ``shared`` sides (e.g. :class:`BlendedSide`: ``fields``, ``internal_force(xs)`` per field,
    ``tangent(xs)`` by blocks) add internal forces and tangent blocks over several fields.

    With :attr:`start` (a solve that continues from a previous one,
    :mod:`~dolfinx_meshfree.statics.history`) the loads at ``t`` are ``(1 - t) start + t f_ext``
    and the held values ``(1 - t) x_start + t x_bar``: the load steps run from the last solve's
    loads to the current ones."""

    names: list[str]
    num_primal: int
    sides: list  # one FESide / ParticleSide per primal field
    constant: list[list[PETSc.Mat | None]]  # the C blocks (primal diagonal blocks: None)
    loads: list[PETSc.Vec]  # f_ext per primal field, c per constraint field
    t: float = 1.0
    shared: list = field(default_factory=list)  # sides over several fields (BlendedSide...)
    _owned: list = field(default_factory=list)
    #: The loads at ``t = 0`` per field (owned entries), or ``None``: zero.
    start: list[np.ndarray] | None = None
    #: The held values at ``t = 0`` per side (``None`` entries: not an FE side), or ``None``.
    start_held: list[np.ndarray | None] | None = None
    #: The next :meth:`jacobian` takes the laws' tangents of unloading (then it is reset): the
    #: predictor of a step that unloads a body on its loading surface.
    predictor: bool = False
    #: MUMPS's analysis of the last tangent, kept for the next ones of the same sparsity
    #: pattern (Newton's iterations and load steps, a path's steps); freed by :meth:`destroy`.
    kept_factorisation: KeptFactorisation = field(default_factory=KeptFactorisation)

    def residual(self, x: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        out = []
        for i, row in enumerate(self.constant):
            r = self.sides[i].internal_force(x[i]) if i < self.num_primal else self.loads[i].copy()
            if i < self.num_primal:
                r.axpy(-self.t, self.loads[i])
            else:
                r.scale(-self.t)
            if self.start is not None:
                r.array[:] -= (1.0 - self.t) * self.start[i]
            for j, C in enumerate(row):
                if C is not None:
                    C.multAdd(x[j], r, r)
            out.append(r)
        for side in self.shared:
            for i, f in zip(
                side.fields, side.internal_force([x[i] for i in side.fields]), strict=True
            ):
                out[i].axpy(1.0, f)
                f.destroy()
        for i, side in enumerate(self.sides):
            if isinstance(side, FESide):  # held dofs: x - t x_bar
                held = side.fixed_local
                value = self.t * side.fixed_values
                if self.start_held is not None:
                    value = value + (1.0 - self.t) * self.start_held[i]
                out[i].array[held] = x[i].getArray(readonly=True)[held] - value
        return out

    def jacobian(self, x: Sequence[PETSc.Vec]) -> list[list[PETSc.Mat | None]]:
        """The tangent blocks at ``x`` (the laws' tangents of unloading once after
        :attr:`predictor` was set)."""
        stores = self.states if self.predictor else []
        self.predictor = False
        for st in stores:
            st.predictor = True
        try:
            return self._jacobian(x)
        finally:
            for st in stores:
                st.predictor = False

    def _jacobian(self, x: Sequence[PETSc.Vec]) -> list[list[PETSc.Mat | None]]:
        for M in self._owned:
            M.destroy()
        self._owned = [self.sides[i].tangent(x[i]) for i in range(self.num_primal)]
        blocks = [list(row) for row in self.constant]
        for i, K in enumerate(self._owned):
            if blocks[i][i] is not None:  # a constant part (a penalty): K_T + C_ii
                K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
                K.axpy(1.0, blocks[i][i], structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                if isinstance(self.sides[i], FESide):  # held rows stay the identity
                    K.zeroRows(self.sides[i].fixed_rows, diag=1.0)
            blocks[i][i] = K
        different = PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN
        for side in self.shared:  # held rows are not in its blocks
            for (a, b), K in side.tangent([x[k] for k in side.fields]).items():
                i, j = side.fields[a], side.fields[b]
                if i == j:  # onto the owned diagonal block
                    blocks[i][i].setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
                    blocks[i][i].axpy(1.0, K, structure=different)
                    K.destroy()
                    continue
                if blocks[i][j] is not None:  # a constant block stays as it is: K + C
                    K.axpy(1.0, blocks[i][j], structure=different)
                self._owned.append(K)
                blocks[i][j] = K
        return blocks

    @property
    def states(self) -> list[PointState]:
        """The state stores of the sides' laws with state (empty for hyperelastic laws)."""
        return [st for side in [*self.sides, *self.shared] for st in getattr(side, "states", [])]

    def commit(self, x: Sequence[PETSc.Vec]) -> None:
        """Commit the state at the converged ``x``: one more evaluation there (the last one of
        Newton may have been a rejected line-search trial), then every store's trial state
        becomes its committed one. Nothing happens without a law with state."""
        states = self.states
        if not states:
            return
        for r in self.residual(x):
            r.destroy()
        for st in states:
            st.commit()

    def restore(self) -> None:
        """Drop the trial states (a cut step)."""
        for st in self.states:
            st.restore()

    def destroy(self) -> None:
        for M in self._owned:
            M.destroy()
        self._owned = []
        self.kept_factorisation.destroy()
        for side in self.sides:
            if hasattr(side, "destroy"):
                side.destroy()


def restore_step(problem: BlockProblem, x: Sequence[PETSc.Vec], saved: Sequence[PETSc.Vec]) -> None:
    """Undo a step that is not kept: ``x`` back to ``saved`` (then freed), the laws' trial
    states back to the committed ones."""
    for v, w in zip(x, saved, strict=True):
        w.copy(v)
        w.destroy()
    problem.restore()


def solve_built(
    built: object,
    load_steps: int,
    options: NewtonOptions,
    solver: SolverOptions,
    history: SolveHistory | None = None,
) -> object:
    """:func:`solve_load_steps` on a built model (``problem``, ``x``, ``solution()``,
    ``destroy()``: a pure EFG or pure FE block model), freed after; its solution with the solve's
    time in ``timings["solve"]`` and Newton's record in ``newton`` (collective). With a
    ``history`` (a model with state), the solve starts where the last one ended and records
    where it ends (:mod:`~dolfinx_meshfree.statics.history`)."""
    t0 = time.perf_counter()
    try:
        result = solve_load_steps(built.problem, built.x, load_steps, options, solver, history)
        solution = built.solution()
    finally:
        built.destroy()
    solution.timings["solve"] = time.perf_counter() - t0
    solution.newton = result
    return solution


def solve_load_steps(
    problem: BlockProblem,
    x: list[PETSc.Vec],
    load_steps: int,
    options: NewtonOptions,
    solver: SolverOptions,
    history: SolveHistory | None = None,
    max_cuts: int = 6,
) -> NonlinearSolveResult:
    """Newton over the load factor ``t`` from 0 to 1 in ``load_steps`` equal steps (collective).
    With a ``history``, ``t = 0`` is where the last solve ended (its fields, states, loads and
    held values: :meth:`~dolfinx_meshfree.statics.history.SolveHistory.resume`), and the end
    is recorded in it.

    A converged step commits the state of the laws with state (:meth:`BlockProblem.commit`).
    A step whose Newton iterations do not converge is cut in half, from the last converged
    state (laws' state included), up to ``max_cuts`` times below the nominal step (a slender
    body under a large load step can fall into a cycle of full Newton steps); after a converged
    cut step the increment grows back towards the nominal one. Raises
    :class:`~dolfinx_meshfree.statics.newton.NewtonError` when even the smallest step does not
    converge: no unconverged state is returned.
    """
    if history is not None:
        history.resume(problem, x)
    steps: list[NewtonResult] = []
    nominal = 1.0 / load_steps
    t, dt, cuts = 0.0, nominal, 0
    while t < 1.0 - 1e-12:
        t_new = min(1.0, t + dt)
        saved = [v.copy() for v in x]
        problem.t = t_new
        try:
            steps.append(newton(problem, x, options, solver))
        except NewtonError as err:
            restore_step(problem, x, saved)
            if cuts == max_cuts:
                if not problem.states:
                    raise
                raise NewtonError(  # a body that yields or softens: maybe past its limit load
                    f"{err}. No equilibrium was found from load factor {t:.6g} (the last "
                    f"converged, of 1) even in steps of {dt:.3g}: a load above the limit load of "
                    "a body that yields or softens has none, and load control cannot pass a "
                    "peak; mf.follow_path(model, control, options) follows the path through it",
                    err.history,
                ) from None
            cuts, dt = cuts + 1, 0.5 * dt
            continue
        for w in saved:
            w.destroy()
        problem.commit(x)
        t = t_new
        if cuts:  # grow back after a cut step converged
            cuts, dt = cuts - 1, 2.0 * dt
    if history is not None:
        history.record(problem, x)
    return NonlinearSolveResult(sum(s.iterations for s in steps), True, steps)
