"""Newton on a coupled model's block system at finite strain (total Lagrangian).

The step shared by :class:`~dolfinx_meshfree.CoupledNonlinearProblem` (the user's UFL residual)
and :class:`~dolfinx_meshfree.CoupledElasticity` with a finite-strain material (the model's own
law, loads and Dirichlet callables): the coupling family assembles its linear block system once
(``family.system``: constraint blocks, the external load split between FE and particles, the
held FE dofs), then the stiffness blocks are replaced by state-dependent sides (Rabczuk et al.
2006, eq. 34: ``f_int(u) = sum_q B0^T P(F_q) w_q`` on the particles; the FE cells' UFL internal
force) and Newton runs over the load steps
(:func:`~dolfinx_meshfree.statics.sides.solve_load_steps`). See
:mod:`~dolfinx_meshfree.statics.nonlinear` for the blocks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import dolfinx
import numpy as np
import ufl

from ..couplings import REGISTRY
from ..couplings.assembly import component_conditions
from ..couplings.base import CoupledSolution
from ..geometry.crack import particle_spacing
from ..parallel import raise_on_all_ranks
from ..physics.constitutive import Material
from ..physics.state import StatefulLaw, is_stateful
from .cohesive import CohesiveSide
from .fe_state import check_bands
from .history import SolveHistory
from .newton import NewtonOptions
from .petsc import SolverOptions, create_vector
from .sides import (
    BlockProblem,
    FESide,
    NonlinearSolveResult,
    ParticleSide,
    particle_band_factor,
    solve_load_steps,
)

if TYPE_CHECKING:  # annotations only
    from .coupled import CoupledElasticity

__all__ = [
    "FE_LAW_DEGREE",
    "FINITE_STRAIN_COUPLINGS",
    "BlockModel",
    "FiniteStrainSolve",
    "build_block_problem",
    "check_load_steps",
    "law_internal_force",
    "solve_finite_strain",
]

#: Couplings available at finite strain, those whose family assembles its block system apart
#: from solving it (``system``); the others refuse with a clear error.
FINITE_STRAIN_COUPLINGS = tuple(name for name, cls in REGISTRY.items() if hasattr(cls, "system"))

#: Quadrature degree of a law's UFL internal force on P1/Q1 cells (the estimated degree of a
#: plane-stress neo-Hookean's thickness stretch would ask for millions of points per cell).
FE_LAW_DEGREE = 4


def law_internal_force(law: Material | StatefulLaw, u: dolfinx.fem.Function) -> ufl.Form | None:
    """The FE cells' internal force ``int P(I + grad u) : grad v dX`` of a finite-strain law's
    UFL twin (degree :data:`FE_LAW_DEGREE`); ``None`` for a law with state, whose FE cells use
    :class:`~dolfinx_meshfree.statics.fe_state.FEStateLaw` instead."""
    if is_stateful(law):
        return None
    V = u.function_space
    dx = ufl.Measure("dx", domain=V.mesh, metadata={"quadrature_degree": FE_LAW_DEGREE})
    F = ufl.Identity(V.mesh.geometry.dim) + ufl.grad(u)
    return ufl.inner(law.ufl_first_piola(F), ufl.grad(ufl.TestFunction(V))) * dx


def check_load_steps(load_steps: int) -> None:
    """Raise a ValueError unless ``load_steps`` is an integer >= 1."""
    if not (isinstance(load_steps, int | np.integer) and load_steps >= 1):
        raise ValueError(f"load_steps={load_steps!r} must be an integer >= 1")


@dataclass
class FiniteStrainSolve:
    """What :func:`solve_finite_strain` returns: Newton's record, the coupled solution and the
    state of every block field (the start of a later solve)."""

    result: NonlinearSolveResult
    solution: CoupledSolution
    state: list[np.ndarray]


@dataclass
class BlockModel:
    """A coupled model's block problem at finite strain (or with a law with state), ready for
    Newton: what :func:`build_block_problem` returns. :meth:`finish` turns a state into the
    coupled solution and frees the PETSc objects."""

    model: CoupledElasticity
    problem: BlockProblem
    x: list
    fe: FESide
    particles: ParticleSide
    extra: dict
    objects: list
    setup: float

    def solution(self, timings: dict | None = None) -> CoupledSolution:
        """The coupled solution at the current ``x`` (collective)."""
        P = self.model.patch.particles
        self.fe.set_state(self.x[0])
        coeffs = self.particles.coefficients(self.x[1]).reshape(-1, P.gdim)
        solution = CoupledSolution(
            u=self.fe.u,
            coefficients=coeffs,
            mls=self.model.mls,
            patch=self.model.patch,
            timings=timings or {"setup": self.setup},
            interface=self.extra.get("interface"),
        )
        if "links" in self.extra:  # master-slave: the slaves' links, as the linear solution has
            solution.links = self.extra["links"]
        return solution

    def state(self) -> list[np.ndarray]:
        """Copies of every block field (the start of a later solve)."""
        return [v.getArray(readonly=True).copy() for v in self.x]

    def destroy(self) -> None:
        self.problem.destroy()
        for obj in [*self.objects, *self.x]:
            obj.destroy()


def build_block_problem(
    model: CoupledElasticity,
    F_int: ufl.Form | None,
    u: dolfinx.fem.Function,
    material: Material | StatefulLaw,
    state: list[np.ndarray] | None = None,
) -> BlockModel:
    """The block problem of ``model`` (collective): the family's linear system, its stiffness
    blocks replaced by the FE and particle sides (and the shared sides of the ramps and
    master-slave), the start ``x`` (``state``, or ``u`` and zeros).

    Args:
        model: The coupled model.
        F_int: The FE internal force (``None`` with a law with state: the FE cells then use
            :class:`~dolfinx_meshfree.statics.fe_state.FEStateLaw`).
        u: The FE unknown.
        material: The particle side's law (finite-strain, or with state).
        state: The block fields of a previous solve, or ``None``.
    """
    P = model.patch.particles
    t0 = time.perf_counter()
    factor = None  # the particle points' crack band in cell sizes (a law that softens)
    if is_stateful(material) and material.needs_band:  # on every rank, before the assembly
        factor = particle_band_factor(model.mls, getattr(model, "particle_band", None))

        def check() -> None:
            check_bands(model.V.mesh, material, model.patch.in_patch, factor)

        raise_on_all_ranks(model.patch.comm, check)
    tables: dict = {}
    blocks, rhs, mats, extra = model.family.system(model, tables)
    b_fe, f_p = extra["loads"]  # the external load, not lifted
    comm = model.patch.comm
    f_p = create_vector(comm, P.dof_layout(P.gdim), P.petsc_dofs(P.gdim).ravel(), f_p)
    loads = [b_fe, f_p, *rhs[2:]]
    stateful = is_stateful(material)
    fe = FESide(
        F_int, u, extra["fe_cells"], extra["fixed"], extra["fe_weight"],
        law=material if stateful else None, dilatation=getattr(model, "fe_dilatation", None),
    )  # fmt: skip
    particles = ParticleSide(P, tables, material, factor)
    # held FE dofs (before the shared sides, which leave their rows out): the strong values on
    # Dirichlet nodes, 0 on nodes no FE cell carries
    fe.fixed_values = extra["fixed_values"][fe.fixed_local]
    # and the dofs held by component (DirichletBCs on V.sub(i)) on nodes not held whole
    flags, values = component_conditions(model)
    flags = flags[: fe.n_owned // fe.bs].ravel()
    flags[fe.fixed_local] = False
    if flags.any():
        held = np.flatnonzero(flags)
        fe.hold(
            np.concatenate([fe.fixed_local, held]),
            np.concatenate([fe.fixed_values, values.ravel()[held]]),
            fe.l2g,
        )
    constant = [list(row) for row in blocks]
    constant[0][0], constant[1][1] = extra["constant_diagonal"]
    names = ["fe", "particles"] + [f"multiplier{i}" for i in range(len(blocks) - 2)]
    # sides over several fields (the ramps' blended cells, master-slave's rotating links)
    # and the linear blocks they replace
    shared = extra["shared_sides"](fe, particles, material) if "shared_sides" in extra else []
    for i, j in extra.get("state_blocks", ()):
        constant[i][j] = None
    if model.cohesive:  # the cohesive faces of the patch's cracks
        h = particle_spacing(model.patch)
        shared += [
            CohesiveSide(c, particles, model.mls, 1, model.material.E, h) for c in model.cohesive
        ]
    problem = BlockProblem(names, 2, [fe, particles], constant, loads, shared=shared)
    x = []
    for i, load in enumerate(loads):  # the previous solve's state, or u and zeros
        v = load.duplicate()
        v.set(0.0)
        if state is not None and state[i].size == load.getLocalSize():
            v.array[:] = state[i]
        x.append(v)
    if state is None:
        x[0].array[:] = u.x.array[: fe.n_owned]
    objects = [*mats, extra["x_bc"], *rhs, f_p]
    return BlockModel(model, problem, x, fe, particles, extra, objects, time.perf_counter() - t0)


def solve_finite_strain(
    model: CoupledElasticity,
    F_int: ufl.Form | None,
    u: dolfinx.fem.Function,
    material: Material | StatefulLaw,
    load_steps: int,
    newton: NewtonOptions,
    solver: SolverOptions,
    state: list[np.ndarray] | None = None,
    history: SolveHistory | None = None,
) -> FiniteStrainSolve:
    """Newton over ``load_steps`` on ``model``'s block system (collective).

    Args:
        model: The coupled model (space, patch, MLS, loads, essential conditions); its
            ``material`` is the linear twin of ``material`` (the constant blocks).
        F_int: The FE internal force ``F(u; v) - F(0; v)`` (cell integrals; weighted by the FE
            cells' indicator here); ``None`` with a law with state.
        u: The FE unknown (updated in place).
        material: The particle side's finite-strain law, or a law with state (small strain,
            its state committed at every converged load step,
            :mod:`~dolfinx_meshfree.physics.state`).
        load_steps, newton, solver: Load steps, Newton options, the linear solver.
        state: The block fields of a previous solve (the start), or ``None`` (``u`` and zeros).
        history: A model with state: where its last solve ended (the start, and the loads the
            steps start from), updated at the end (:mod:`~dolfinx_meshfree.statics.history`).

    Raises:
        NewtonError: when a step does not converge (with the residual history).
    """
    t0 = time.perf_counter()
    built = build_block_problem(model, F_int, u, material, state)
    try:
        result = solve_load_steps(built.problem, built.x, load_steps, newton, solver, history)
        new_state = built.state()
        solution = built.solution(
            {"setup": built.setup, "newton": time.perf_counter() - t0 - built.setup}
        )
        solution.states = built.problem.states
        solution.take_loads(model.body_forces)
        # the FE rows' residual at the solution, held rows included: the reactions
        f = built.fe.internal_force(built.x[0])
        solution.fe_residual = f.getArray(readonly=True) - built.problem.loads[0].getArray(
            readonly=True
        )
        f.destroy()
    finally:
        built.destroy()
    return FiniteStrainSolve(result, solution, new_state)
