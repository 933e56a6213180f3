"""Pure FE with a law with state: the finite-element reference of the softening and plasticity
models, with the calls of the coupled ones.

A user who compares a particle patch with plain finite elements (a crack-band FE model of a
notched beam, an FE ring that yields) needs the same law on FE cells alone. The package's laws
with state (:class:`~dolfinx_meshfree.RankineDamage`, :class:`~dolfinx_meshfree.J2Plasticity`)
have no UFL expression, so a plain DOLFINx form cannot carry them. :class:`FEElasticity` puts
them on every cell of a vector P1/Q1 space through
:class:`~dolfinx_meshfree.statics.fe_state.FEStateLaw` (stress and consistent tangent as
quadrature-point functions, the crack band of each point its cell's size, Bazant & Oh 1983),
and solves with the block Newton and the path following of the coupled models
(:func:`~dolfinx_meshfree.follow_path`) on a block problem of one field:

.. math::
    R(u, t) = \\int \\sigma_q(\\varepsilon(u)) \\cdot \\varepsilon(v)\\, dx - t\\, f_{ext}(v),
    \\qquad u = t\\, \\bar u \\text{ on the held dofs,}

with ``t`` the load factor (Rabczuk et al. 2006, sec. 6.1.2 compare a pure FE model with the
couplings; the FE side of their eq. 53 is this residual). The calls are those of
:class:`~dolfinx_meshfree.CoupledElasticity` without the patch: ``add_dirichlet`` (whole nodes,
or ``components``), ``add_traction``, ``set_body_force``, ``solve(load_steps=)``, and
``follow_path(model, control, options)``, so that a model switches between FE, a coupling and
pure EFG by its constructor.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import dolfinx
import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from ..approx.fe_dofs import fe_dof_layout, node_flags
from ..approx.fe_points import check_p1_space, tabulate_fe_basis
from ..couplings.assembly import fe_facet_loads
from ..parallel import raise_on_all_ranks
from ..physics.body_loads import CallableBodyForce
from ..physics.materials import LinearElastic, is_axisymmetric, linear_twin
from ..physics.state import check_not_rate_law, is_stateful
from ..physics.user_functions import check_arguments, check_facets, vector_values
from .coupled_newton import check_load_steps
from .fe import FESolution
from .fe_state import check_bands
from .history import SolveHistory
from .mean_dilatation import resolve_dilatation
from .newton import NewtonOptions
from .petsc import SolverOptions, create_vector, solver_options
from .sides import BlockProblem, FESide, solve_built

__all__ = ["FE_LOAD_DEGREE", "FEBlockModel", "FEElasticity", "fe_point_functional"]

#: Quadrature degree of the tractions on facets and of a callable body force on the cells.
FE_LOAD_DEGREE = 4

VectorFunction = Callable[[np.ndarray], np.ndarray]


def _check_model(V: dolfinx.fem.FunctionSpace, law: object, dilatation: str | None) -> None:
    """Refuse what the model does not carry (local; call on every rank)."""
    check_p1_space(V)  # vector P1/Q1, affine cells
    gdim = V.mesh.geometry.dim
    if V.dofmap.index_map_bs != gdim:
        raise ValueError(
            f"V must be a vector space with {gdim} components (the displacement), got block "
            f"size {V.dofmap.index_map_bs}"
        )
    check_not_rate_law(law, "FEElasticity")
    if not (is_stateful(law) or isinstance(law, LinearElastic)):
        raise TypeError(
            f"FEElasticity carries a small-strain law (a law with state: RankineDamage, "
            f"J2Plasticity; or LinearElastic), got {type(law).__name__}: a finite-strain FE "
            "model is a UFL residual; solve it with mf.FENonlinearProblem(F, u, bcs)"
        )
    if is_axisymmetric(law):
        raise ValueError(
            "FEElasticity is plane or 3D: an axisymmetric model needs the 2 pi r weights; "
            "write its forms with dolfinx_meshfree.physics.axisymmetry (radius, ufl_stress, "
            "ufl_strain) and solve them with mf.solve_forms"
        )
    if law.gdim != V.mesh.geometry.dim:
        raise ValueError(
            f"the law is {law.gdim}D (plane={law.plane!r}) and the mesh {V.mesh.geometry.dim}D: "
            "give plane='stress' or 'strain' on a 2D mesh, plane=None on a 3D one"
        )
    cell = V.mesh.topology.cell_type.name
    resolve_dilatation(dilatation, law if is_stateful(law) else None, cell, "FEElasticity")


class FEElasticity:
    """A pure FE model of a law with state on every cell (module docstring).

    Args:
        V: The displacement space, vector P1/Q1 on affine cells (2D or 3D).
        law: A law with state (:class:`~dolfinx_meshfree.RankineDamage`,
            :class:`~dolfinx_meshfree.J2Plasticity`), committed at every converged step; or
            :class:`~dolfinx_meshfree.LinearElastic` (its ``solve()`` is the linear solve, in
            one Newton iteration: a model's elastic twin).
        dilatation: ``None`` (automatic), ``"mean"`` or ``"pointwise"``: a law with state runs
            at the strain whose trace is its cell's mean (B-bar, Hughes 1980;
            :mod:`~dolfinx_meshfree.statics.mean_dilatation`), or at the plain strain of each
            point. Automatic: mean on quadrilaterals and hexahedra in plane strain and 3D,
            where the full rule locks under plastic flow (the thick ring's load past its limit
            pressure); pointwise elsewhere. ``"mean"`` where it does not apply (plane stress,
            simplices, ``LinearElastic``) is refused.

    Attributes:
        V, law, comm, dilatation: As given; ``material``: the law's elastic twin.
        dirichlet: ``(facets, value, components)`` of :meth:`add_dirichlet`.
        tractions: ``(facets, traction)`` of :meth:`add_traction`.
        body_forces: Of :meth:`set_body_force`.
        cohesive, cracks: Empty: FE cells carry no crack (what
            :func:`~dolfinx_meshfree.follow_path` reads of every model).

    Raises:
        TypeError: a finite-strain or rate-form law (naming what solves it).
        ValueError: a space that is not vector P1/Q1 on affine cells, an axisymmetric law, a
            law of another dimension than the mesh, a ``dilatation`` that does not apply.
    """

    def __init__(
        self, V: dolfinx.fem.FunctionSpace, law: object, dilatation: str | None = None
    ) -> None:
        self.comm: MPI.Comm = V.mesh.comm
        raise_on_all_ranks(self.comm, lambda: _check_model(V, law, dilatation))
        self.V, self.law, self.dilatation = V, law, dilatation
        #: The law's small-strain elastic twin (its E and nu).
        self.material = linear_twin(law)
        self.dirichlet: list[tuple[np.ndarray, VectorFunction, tuple[int, ...] | None]] = []
        self.tractions: list[tuple[np.ndarray, Callable]] = []
        self.body_forces: list = []
        self.cohesive: list = []
        self.cracks: list = []
        #: Where the last solve of a law with state ended: the next starts there
        #: (:mod:`~dolfinx_meshfree.statics.history`; :meth:`reset` forgets it).
        self.history = SolveHistory("FEElasticity")

    def reset(self) -> None:
        """Forget the path: the next :meth:`solve` starts from the unloaded, virgin state."""
        self.history.clear()

    def add_dirichlet(
        self, facets: np.ndarray, value: VectorFunction, components: tuple[int, ...] | None = None
    ) -> None:
        """``u = value(x)`` on the nodes of owned exterior ``facets``, held strongly, reached in
        proportion to the load factor; ``components``: only those (a roller, a symmetry plane).
        ``value`` maps points (m, gdim) to (m, gdim). Collective."""
        check_arguments(value, 1, "the Dirichlet value")
        facets = check_facets(self.V.mesh, facets, "add_dirichlet: facets")
        gdim = self.V.mesh.geometry.dim

        def check() -> tuple[int, ...] | None:
            if components is None:
                return None
            c = tuple(components)
            if not c or len(set(c)) != len(c) or any(k not in range(gdim) for k in c):
                raise ValueError(
                    f"components={components!r} must be distinct indices in 0..{gdim - 1}"
                )
            return c

        self.dirichlet.append((facets, value, raise_on_all_ranks(self.comm, check)))

    def add_traction(self, facets: np.ndarray, traction: Callable) -> None:
        """Traction ``traction(x, n)`` (m, gdim) on owned exterior facets: the reference load,
        scaled by the load factor. Collective."""
        check_arguments(traction, 2, "traction")
        self.tractions.append((check_facets(self.V.mesh, facets, "add_traction: facets"), traction))

    def set_body_force(self, force: VectorFunction) -> None:
        """Body force per unit volume ``b(x)`` (m, gdim) on every cell (replaces a previous
        one)."""
        check_arguments(force, 1, "the body force")
        self.body_forces = [CallableBodyForce(force)]

    def _held(self) -> tuple[np.ndarray, np.ndarray]:
        """The owned dofs held (local indices) and their values at full load (collective)."""
        V, comm = self.V, self.comm
        gdim = V.mesh.geometry.dim
        n_local = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
        flags, values = np.zeros((n_local, gdim), bool), np.zeros((n_local, gdim))
        coords = V.tabulate_dof_coordinates()[:, :gdim]
        fdim = V.mesh.topology.dim - 1
        for facets, fn, components in self.dirichlet:
            nodes = node_flags(V, dolfinx.fem.locate_dofs_topological(V, fdim, facets))
            xn = coords[nodes]
            vals = raise_on_all_ranks(
                comm,
                lambda fn=fn, xn=xn: vector_values(fn, (xn,), len(xn), "the Dirichlet value", gdim),
            )
            comps = list(range(gdim)) if components is None else list(components)
            block = np.zeros((int(nodes.sum()), gdim), bool)
            block[:, comps] = True
            flags[nodes] |= block
            values[np.ix_(np.flatnonzero(nodes), comps)] = vals[:, comps]
        n_owned = gdim * V.dofmap.index_map.size_local
        held = np.flatnonzero(flags.ravel()[:n_owned])
        return held, values.ravel()[held]

    def _loads(self) -> PETSc.Vec:
        """The reference load: tractions on facets and the body force (collective)."""
        V, comm = self.V, self.comm
        rows, vals = [np.zeros(0, np.int64)], [np.zeros(0)]
        for facets, fn in self.tractions:
            r, v = fe_facet_loads(V, facets, fn, FE_LOAD_DEGREE, self.material, comm)
            rows += r
            vals += v
        b = create_vector(comm, fe_dof_layout(V)[0], np.concatenate(rows), np.concatenate(vals))
        for force in self.body_forces:  # per owned dof
            b.array[:] += force.fe_load(V, None, FE_LOAD_DEGREE)
        return b

    def block_model(self) -> FEBlockModel:
        """The block problem of Newton and of path following (one field, the FE
        displacement), from ``u = 0``. Collective."""
        t0 = time.perf_counter()
        V, law = self.V, self.law
        msh = V.mesh
        if getattr(law, "needs_band", False):  # before the assembly: no cell may snap back
            n = msh.topology.index_map(msh.topology.dim).size_local
            raise_on_all_ranks(
                self.comm, lambda: check_bands(msh, law, np.zeros(n, dtype=bool), 1.0)
            )
        u = dolfinx.fem.Function(V)
        u.x.array[:] = 0.0
        n_local = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
        free = np.zeros(n_local, dtype=bool)
        if is_stateful(law):
            fe = FESide(None, u, None, free, law=law, dilatation=self.dilatation)
        else:  # LinearElastic: its UFL stress
            v = ufl.TestFunction(V)
            fe = FESide(ufl.inner(law.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx, u, None, free)
        held, values = self._held()
        fe.hold(held, values, fe.l2g)
        b = self._loads()
        problem = BlockProblem(["fe"], 1, [fe], [[None]], [b])
        x = b.duplicate()
        x.set(0.0)
        return FEBlockModel(self, problem, [x], fe, [b], time.perf_counter() - t0)

    def solve(
        self,
        load_steps: int = 1,
        newton: NewtonOptions | None = None,
        solver: str | SolverOptions = "mumps",
    ) -> FESolution:
        """Newton over ``load_steps`` equal steps of the load factor to 1, committing the
        states at every converged step (a step that does not converge is cut; load control
        cannot pass a peak: :func:`~dolfinx_meshfree.follow_path` can). A law with state
        continues from the last solve: the steps run from its loads and prescribed values to the
        current ones, from its state (a load sweep; :meth:`reset` starts again). Collective.

        Returns:
            The :class:`~dolfinx_meshfree.FESolution`, with the committed ``states`` and
            Newton's record in ``newton``.
        """
        options = raise_on_all_ranks(self.comm, lambda: solver_options(solver))
        raise_on_all_ranks(self.comm, lambda: check_load_steps(load_steps))
        history = self.history if is_stateful(self.law) else None
        return solve_built(
            self.block_model(), int(load_steps), newton or NewtonOptions(), options, history
        )


@dataclass
class FEBlockModel:
    """:meth:`FEElasticity.block_model`: the problem, its state ``x`` (the FE field's owned
    dofs), the FE side, the PETSc objects to free and the setup time."""

    model: FEElasticity
    problem: BlockProblem
    x: list
    fe: FESide
    objects: list
    setup: float

    def solution(self) -> FESolution:
        """The solution at the current ``x`` (a copy of the displacement), with the laws'
        committed states (collective)."""
        self.fe.set_state(self.x[0])
        u = dolfinx.fem.Function(self.model.V)
        u.x.array[:] = self.fe.u.x.array
        return FESolution(u, {"setup": self.setup}, states=self.problem.states)

    def destroy(self) -> None:
        self.problem.destroy()
        for obj in [*self.objects, *self.x]:
            obj.destroy()


def fe_point_functional(
    V: dolfinx.fem.FunctionSpace, points: npt.ArrayLike, directions: npt.ArrayLike
) -> np.ndarray:
    """The weights ``w`` over this rank's owned dofs of ``V`` (local order) such that
    ``sum_k directions_k . u(points_k) = sum_ranks w . u_owned``: the functional a path's control
    quantity is (collective; ``points`` and ``directions``, (k, gdim), the same on every rank).
    Evaluated once: a control is read at every Newton iteration."""
    comm = V.mesh.comm
    gdim = V.mesh.geometry.dim
    pts = np.asarray(points, dtype=float).reshape(-1, gdim)
    dirs = np.asarray(directions, dtype=float).reshape(-1, gdim)
    mine = pts if comm.rank == 0 else pts[:0]  # each point tabulated once
    values = tabulate_fe_basis(V, mine, derivatives=0).values.tocsc()  # global node columns
    nodes = np.flatnonzero(np.diff(values.indptr))
    weights = (values[:, nodes].T @ dirs[: values.shape[0]]) if nodes.size else np.zeros((0, gdim))
    nodes, weights = comm.bcast((nodes, np.asarray(weights)), root=0)
    imap = V.dofmap.index_map
    lo, hi = imap.local_range
    w = np.zeros((imap.size_local, gdim))
    own = (nodes >= lo) & (nodes < hi)
    w[nodes[own] - lo] = weights[own]
    return w.ravel()
