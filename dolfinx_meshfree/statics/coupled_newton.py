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
from ..physics.constitutive import Material
from .newton import NewtonOptions
from .petsc import SolverOptions, create_vector
from .sides import BlockProblem, FESide, NonlinearSolveResult, ParticleSide, solve_load_steps

if TYPE_CHECKING:  # annotations only
    from .coupled import CoupledElasticity

__all__ = [
    "FE_LAW_DEGREE",
    "FINITE_STRAIN_COUPLINGS",
    "FiniteStrainSolve",
    "check_load_steps",
    "solve_finite_strain",
]

#: Couplings available at finite strain, those whose family assembles its block system apart
#: from solving it (``system``); the others refuse with a clear error.
FINITE_STRAIN_COUPLINGS = tuple(name for name, cls in REGISTRY.items() if hasattr(cls, "system"))

#: Quadrature degree of a law's UFL internal force on P1/Q1 cells (the estimated degree of a
#: plane-stress neo-Hookean's thickness stretch would ask for millions of points per cell).
FE_LAW_DEGREE = 4


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


def solve_finite_strain(
    model: CoupledElasticity,
    F_int: ufl.Form,
    u: dolfinx.fem.Function,
    material: Material,
    load_steps: int,
    newton: NewtonOptions,
    solver: SolverOptions,
    state: list[np.ndarray] | None = None,
) -> FiniteStrainSolve:
    """Newton over ``load_steps`` on ``model``'s block system (collective).

    Args:
        model: The coupled model (space, patch, MLS, loads, essential conditions); its
            ``material`` is the linear twin of ``material`` (the constant blocks).
        F_int: The FE internal force ``F(u; v) - F(0; v)`` (cell integrals; weighted by the FE
            cells' indicator here).
        u: The FE unknown (updated in place).
        material: The particle side's finite-strain law.
        load_steps, newton, solver: Load steps, Newton options, the linear solver.
        state: The block fields of a previous solve (the start), or ``None`` (``u`` and zeros).

    Raises:
        NewtonError: when a step does not converge (with the residual history).
    """
    P = model.patch.particles
    t0 = time.perf_counter()
    tables: dict = {}
    blocks, rhs, mats, extra = model.family.system(model, tables)
    b_fe, f_p = extra["loads"]  # the external load, not lifted
    comm = model.patch.comm
    f_p = create_vector(comm, P.dof_layout(P.gdim), P.petsc_dofs(P.gdim).ravel(), f_p)
    loads = [b_fe, f_p, *rhs[2:]]
    fe = FESide(F_int, u, extra["fe_cells"], extra["fixed"], extra["fe_weight"])
    particles = ParticleSide(P, tables, material)
    constant = [list(row) for row in blocks]
    constant[0][0], constant[1][1] = extra["constant_diagonal"]
    names = ["fe", "particles"] + [f"multiplier{i}" for i in range(len(blocks) - 2)]
    # sides over several fields (the ramps' blended cells, master-slave's rotating links)
    # and the linear blocks they replace
    shared = extra["shared_sides"](fe, particles, material) if "shared_sides" in extra else []
    for i, j in extra.get("state_blocks", ()):
        constant[i][j] = None
    problem = BlockProblem(names, 2, [fe, particles], constant, loads, shared=shared)
    x = []
    for i, load in enumerate(loads):  # the previous solve's state, or u and zeros
        v = load.duplicate()
        v.set(0.0)
        if state is not None and state[i].size == load.getLocalSize():
            v.array[:] = state[i]
        x.append(v)
    # held FE dofs: the strong values on Dirichlet nodes, 0 on nodes no FE cell carries
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
    x[0].array[:] = u.x.array[: fe.n_owned]
    setup = time.perf_counter() - t0
    try:
        result = solve_load_steps(problem, x, load_steps, newton, solver)
    finally:
        problem.destroy()
    fe.set_state(x[0])
    new_state = [v.getArray(readonly=True).copy() for v in x]
    coeffs = particles.coefficients(x[1]).reshape(-1, P.gdim)
    solution = CoupledSolution(
        u=u,
        coefficients=coeffs,
        mls=model.mls,
        patch=model.patch,
        timings={"setup": setup, "newton": time.perf_counter() - t0 - setup},
        interface=extra.get("interface"),
    )
    if "links" in extra:  # master-slave: the slaves' links, as the linear solution has
        solution.links = extra["links"]
    for obj in [*mats, extra["x_bc"], *rhs, f_p, *x]:
        obj.destroy()
    return FiniteStrainSolve(result, solution, new_state)
