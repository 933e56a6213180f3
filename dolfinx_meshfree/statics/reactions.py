"""Reaction forces of a coupled static solution on one of the user's ``DirichletBC``s.

The reaction of a held dof is its row of the residual at the solution: ``r_a = (K u - f)_a``
for :class:`~dolfinx_meshfree.CoupledLinearProblem`, ``r_a = F(u; N_a)`` for
:class:`~dolfinx_meshfree.CoupledNonlinearProblem`, the force the support exerts on the body
(the FEniCSx way: assemble the residual and read it at the condition's dofs). For a held FE
node whose cells are FE cells that do not touch the patch, that row is the user's own form
(``action(a, u) - L``, or ``F``) assembled by DOLFINx at the coupled solution's FE field: the
coupled system's row there is exactly that. Nearer the patch the row also holds what the
coupling adds and a form on the FE space does not see (multipliers on the interface nodes, the
ramps' blended interface cells, a bridging band's weights, master-slave's links): a condition
with such a node is refused, named by the node's coordinates. A pin (a node only patch cells
carry, held at a point: :mod:`~dolfinx_meshfree.couplings.point_conditions`) is the exception:
its force is its multiplier's, ``-E h (sum_J phi_J(x)) lambda``, which the linear lagrange,
edge-to-edge, ramp and bridging solves keep (``CoupledSolution.point_forces``).

A body load (``L``'s ``dx`` terms) and tractions on the held facets are in the row, as in
DOLFINx. With a law with state (``J2Plasticity``, ``RankineDamage``) the FE cells follow the law,
not ``a``: the row is the law's internal force at the converged state minus the load, kept by
the Newton solve (``CoupledSolution.fe_residual``): a force-displacement curve of a plastic or
softening specimen.

The summed reaction balances the applied load to round-off when the particle side conserves
momentum (plain Gauss points); VCI's corrected test gradients do not sum to zero exactly, so
there the balance holds to the consistency error (``tests/test_reactions.py``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import dolfinx
import numpy as np
import ufl
from petsc4py import PETSc

from .. import _compat
from ..parallel import raise_on_all_ranks
from ..physics.state import is_stateful

if TYPE_CHECKING:  # annotations only
    from ..couplings.base import CoupledSolution
    from .nonlinear import CoupledNonlinearProblem
    from .problem import CoupledLinearProblem

__all__ = ["reaction"]


def _node_flags(V: dolfinx.fem.FunctionSpace, cells: np.ndarray) -> np.ndarray:
    """Flags of the local nodes (owned and ghost) of the given local cells, summed over the
    ranks that hold each node (collective)."""
    bs = V.dofmap.index_map_bs
    f = dolfinx.fem.Function(V)
    f.x.array[:] = 0.0
    nodes = np.unique(_compat.dofmap_array(V)[cells].ravel())
    f.x.array.reshape(-1, bs)[nodes, 0] = 1.0
    _compat.scatter_reverse_add(f)
    f.x.scatter_forward()
    return f.x.array.reshape(-1, bs)[:, 0] > 0.0


def near_patch_nodes(problem: CoupledLinearProblem | CoupledNonlinearProblem) -> np.ndarray:
    """Local nodes of a patch cell, or of a cell that has one (collective): where the coupled
    system's FE rows hold more than the user's form."""
    V, patch = problem.V, problem.patch
    dofmap = _compat.dofmap_array(V)
    local = dofmap.shape[0]
    on_patch = _node_flags(V, np.flatnonzero(patch.in_patch[:local]))
    touching = np.flatnonzero(on_patch[dofmap].any(axis=1))
    return _node_flags(V, touching)


def _pin_forces(
    problem: CoupledLinearProblem | CoupledNonlinearProblem,
    dofs: np.ndarray,
    solution: CoupledSolution | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Which of the owned ``dofs`` are pins of the model (its ``point_dirichlet``) at nodes no
    FE cell carries, and the sum of their forces (gdim,) on this rank (collective: the FE
    cells' nodes are flagged over the ranks). A pin where the solve kept no forces, or at a
    node an FE cell carries too (a ramp's interface node: its FE row carries force as well),
    is refused by its coordinates."""
    V = problem.V
    bs = V.dofmap.index_map_bs
    model = problem.model
    fe_nodes = _node_flags(V, np.asarray(model.patch.fe_cells, dtype=np.int32))
    pinned, total = np.zeros(len(dofs), dtype=bool), np.zeros(bs)
    forces = None if solution is None else solution.point_forces
    node, comp = np.asarray(dofs) // bs, np.asarray(dofs) % bs
    bad: list[np.ndarray] = []
    for k, pc in enumerate(model.point_dirichlet):
        point = np.full(fe_nodes.size, -1)  # the node's point in pc, or -1
        point[pc.nodes] = np.arange(len(pc.nodes))
        j = point[node]
        hit = (j >= 0) & np.isin(comp, pc.components)
        pinned |= hit
        refused = hit & (fe_nodes[node] | (forces is None))
        bad += list(pc.points[j[refused]])
        if forces is not None:
            ok = hit & ~refused
            np.add.at(total, comp[ok], forces[k][j[ok], comp[ok]])

    def check() -> None:
        if bad:
            raise ValueError(
                f"bc holds {len(bad)} pinned dof(s) whose force this solve did not keep, first "
                f"the pin at {tuple(np.round(bad[0], 12))}: a pin's force is its multiplier, "
                "kept by the linear lagrange, edge-to-edge, ramp and bridging solves at nodes "
                "that only patch cells carry (not by master-slave, Newton, or a ramp's "
                "interface node, whose FE row carries force too)"
            )

    raise_on_all_ranks(V.mesh.comm, check)
    return pinned, total


def reaction(
    problem: CoupledLinearProblem | CoupledNonlinearProblem,
    bc: object,
    solution: CoupledSolution | None = None,
) -> np.ndarray:
    """The total reaction force ``sum_a r_a`` (gdim,) over the dofs that ``bc`` holds, on every
    rank (collective; module docstring): of a component condition (``V.sub(i)``), that
    component only, the others 0.

    Args:
        problem: A :class:`~dolfinx_meshfree.CoupledLinearProblem` (a ``LinearElastic`` law
            or a law with state), or a solved :class:`~dolfinx_meshfree.CoupledNonlinearProblem`.
        bc: One of the problem's ``bcs`` (the same object).
        solution: ``CoupledLinearProblem``: the solution its :meth:`solve` returned.

    Raises:
        ValueError: on every rank, for a ``bc`` that is not the problem's, a missing solution
            a held node on or beside the patch (by its coordinates) that is not a pin, or a pin
            whose force the solve did not keep.
    """
    comm = problem.patch.comm
    V = problem.V
    linear = hasattr(problem, "a")

    def check_input() -> None:
        if not any(bc is b for b in problem.bcs):
            raise ValueError(
                "bc must be one of the problem's bcs (the same DirichletBC object), got another"
            )
        if linear and solution is None:
            raise ValueError(
                "solution=None: pass the CoupledSolution that problem.solve() returned"
            )
        if linear and solution.u.function_space is not V:
            raise ValueError("solution is not a solution of this problem (another space)")
        if linear and is_stateful(problem.material) and solution.fe_residual is None:
            raise ValueError(
                "solution holds no FE residual: pass the solution of this problem's solve()"
            )
        if not linear and problem.solution is None:
            raise ValueError("the problem has not been solved: call problem.solve() first")

    raise_on_all_ranks(comm, check_input)
    bs = V.dofmap.index_map_bs
    owned = bs * V.dofmap.index_map.size_local
    dofs = _compat.dirichlet_values(bc)[0]
    dofs = dofs[dofs < owned]
    near = near_patch_nodes(problem)  # collective
    # pins (nodes only particles carry, held at points): their forces are their multipliers'
    pinned, pin_total = _pin_forces(problem, dofs, solution if linear else problem.solution)
    dofs = dofs[~pinned]

    def check_nodes() -> None:
        bad = dofs[near[dofs // bs]]
        if bad.size:
            x = V.tabulate_dof_coordinates()[bad[0] // bs]
            raise ValueError(
                f"bc holds {bad.size} dof(s) on a node on or beside the particle patch, first "
                f"the node at {tuple(np.round(x[: V.mesh.geometry.dim], 12))}: there the "
                "reaction holds the coupling's interface forces, which the form on V does not "
                "see; keep the patch at least one FE cell away from the held boundary"
            )

    raise_on_all_ranks(comm, check_nodes)
    total = pin_total
    if linear and is_stateful(problem.material):  # the law's internal force of the FE rows
        np.add.at(total, dofs % bs, solution.fe_residual[dofs])
        return comm.allreduce(total)
    if linear:
        residual = ufl.action(problem.a, solution.u) - problem.L
    else:
        residual = problem.F
    b = _compat.assemble_vector(_compat.create_form(residual))
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    np.add.at(total, dofs % bs, b.array_r[dofs])
    b.destroy()
    return comm.allreduce(total)
