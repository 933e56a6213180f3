"""What a model with a law with state carries from one ``solve()`` to the next.

A body that yields, softens or opens a cohesive crack remembers its path: its plastic strain,
its damage or its faces' largest opening. DOLFINx users load such a model in a loop, setting a
load or a prescribed displacement and solving again (the FEniCSx plasticity demos); each solve
must then start from the last converged one. Before, every ``solve()`` of
:class:`~dolfinx_meshfree.FEElasticity`, :class:`~dolfinx_meshfree.EFGElasticity`,
:class:`~dolfinx_meshfree.CoupledElasticity` (and :class:`~dolfinx_meshfree.CoupledLinearProblem`)
started from the unloaded, virgin state: a J2 strip loaded to 1.2 sigma_y and unloaded to zero
came back to zero strain instead of keeping its plastic strain (2.5e-3 in
``tests/test_solve_history.py``), silently.

:class:`SolveHistory` keeps, after each converged solve, the block fields (displacements,
coefficients, multipliers), the committed state of every store (FE cells, particles, cohesive
faces, in the order of :attr:`~dolfinx_meshfree.statics.sides.BlockProblem.states`) and the
loads and held values the solve ended at. The next solve starts there, and its load steps run
from those loads to the current ones (:attr:`~dolfinx_meshfree.statics.sides.BlockProblem.start`):
a load step is an increment of the path, as a return map needs; a solve that takes the loads
back towards zero starts Newton from the laws' tangents of unloading
(:attr:`~dolfinx_meshfree.statics.sides.BlockProblem.predictor`), so that a softened body
unloads along its secant instead of softening further. ``model.reset()`` forgets the
history (the next solve starts unloaded). The history belongs to the model's discretisation: a
model whose fields or stores changed size since (a new condition, a crack) is refused by name.
``model.solve()`` of a hyperelastic model keeps none (its answer does not depend on the path;
it solves from the unloaded state); :class:`~dolfinx_meshfree.CoupledNonlinearProblem` and
:class:`~dolfinx_meshfree.FENonlinearProblem` keep one, so that their load steps run from the
last solve's loads (a sweep by ``Constant`` objects), and start from the last solution.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .sides import BlockProblem, FESide

__all__ = ["SolveHistory"]


@dataclass
class SolveHistory:
    """The state a model with state ended its last converged solve in (empty before the first
    solve and after :meth:`clear`).

    Args:
        owner: The class that keeps it, named in its errors (``"FEElasticity"``, ...).
        fields: Whether a resumed solve starts from the recorded fields; ``False`` keeps the
            caller's (a user's ``u``, the initial guess of DOLFINx's Newton), the loads and held
            values still starting from the history's.
    """

    owner: str = "the model"
    fields: bool = True
    #: The block fields (owned entries), one array per field.
    x: list[np.ndarray] = field(default_factory=list)
    #: The committed state of every store, as copies of its fields.
    states: list[dict[str, np.ndarray]] = field(default_factory=list)
    #: The loads the solve ended at (owned entries per field).
    loads: list[np.ndarray] = field(default_factory=list)
    #: The held values the solve ended at, per side (``None``: not an FE side).
    held: list[np.ndarray | None] = field(default_factory=list)
    #: Some store's state left its initial one (the same on every rank): the body yielded,
    #: softened or opened, so a path that starts unloaded would not continue it.
    inelastic: bool = False
    #: The path this model started went on on another model (``follow_path`` grew the patch:
    #: ``path.model``): a solve of this one is refused until :meth:`clear`.
    moved: bool = False

    @property
    def empty(self) -> bool:
        """No solve converged since the model was built or reset."""
        return not self.x

    def clear(self) -> None:
        """Forget the history: the next solve starts from the unloaded, virgin state."""
        self.x, self.states, self.loads, self.held = [], [], [], []
        self.inelastic = self.moved = False  # owner and fields stay

    def record(self, problem: BlockProblem, x: Sequence[PETSc.Vec]) -> None:
        """Keep the converged state ``x`` of ``problem`` at its load factor ``problem.t``: the
        loads and held values there, ``(1 - t) start + t f_ext`` (collective)."""
        t = problem.t
        start = problem.start or [0.0] * len(problem.loads)
        start_held = problem.start_held or [0.0] * len(problem.sides)
        self.x = [v.getArray(readonly=True).copy() for v in x]
        stores = problem.states
        self.states = [{k: v.copy() for k, v in st.committed.items()} for st in stores]
        self.loads = [
            t * v.getArray(readonly=True) + (1.0 - t) * s0
            for v, s0 in zip(problem.loads, start, strict=True)
        ]
        self.held = [
            t * np.asarray(side.fixed_values, dtype=float) + (1.0 - t) * h0
            if isinstance(side, FESide)
            else None
            for side, h0 in zip(problem.sides, start_held, strict=True)
        ]
        changed = any(
            not np.array_equal(v, st.law.initial_state(len(st))[k])
            for st in stores
            for k, v in st.committed.items()
        )
        comm = problem.loads[0].getComm().tompi4py()
        self.inelastic = bool(comm.allreduce(int(changed), op=MPI.MAX))

    def resume(self, problem: BlockProblem, x: Sequence[PETSc.Vec]) -> None:
        """Start ``problem`` and its fields ``x`` (unless not :attr:`fields`) where the last solve
        ended (collective: the check is reduced over the ranks, so every rank raises alike).
        Nothing happens when the history is empty.

        Raises:
            ValueError: when the model's fields or state stores changed size since the last
                solve, or its path went on on another model (both named for :attr:`owner`).
        """
        stores = problem.states
        comm = problem.loads[0].getComm().tompi4py()
        if self.moved:  # the same on every rank (set by follow_path on every rank)
            raise ValueError(
                f"{self.owner}.solve(): follow_path grew this model's patch, so its path went "
                "on on the rebuilt model (path.model): solve that one to continue, or call "
                "model.reset() to start this one again from the unloaded state"
            )
        why = "" if self.empty else self._misfit(problem, x)
        if comm.allreduce(int(bool(why)), op=MPI.MAX):
            raise ValueError(
                f"{self.owner}.solve(): the model changed {why or 'on another rank'} since its "
                "last solve (a condition, a load on new facets or a crack added?), so the state "
                "its law carries from that solve does not fit it any more; call model.reset() to "
                "start again from the unloaded state, or build the model with every condition "
                "first"
            )
        if self.empty:
            return
        for v, a in zip(x, self.x if self.fields else (), strict=False):
            v.array[:] = a
        for st, old in zip(stores, self.states, strict=True):
            st.committed = {k: v.copy() for k, v in old.items()}
            st.restore()  # the trial state too, and the evaluations keyed on the version
        problem.start = [a.copy() for a in self.loads]
        problem.start_held = [None if h is None else h.copy() for h in self.held]
        problem.predictor = self._unloads(problem, comm)

    def _unloads(self, problem: BlockProblem, comm: MPI.Comm) -> bool:
        """Whether the solve takes the loads (primal fields) or the prescribed values (held
        dofs, constraint fields) back towards zero: ``(f - f_0) . f_0 < 0``, of either kind
        (collective). Then its first iteration takes the laws' tangents of unloading: on the
        loading surface of a softened point the consistent tangent is the loading one, and from
        there Newton found the equilibrium further down the softening branch (a cohesive bar
        unloaded to half its stress went to 1.28 times its displacement instead of half of
        it; a damaged bar unloaded to 0.4 of its stress, to 2.1 times instead of 0.4)."""
        dots = np.zeros(4)
        for i, (v, f0) in enumerate(zip(problem.loads, self.loads, strict=True)):
            kind = 0 if i < problem.num_primal else 2
            d = v.getArray(readonly=True) - f0
            dots[kind : kind + 2] += (float(d @ f0), float(f0 @ f0))
        for side, h0 in zip(problem.sides, self.held, strict=True):
            if h0 is not None:
                dots[2:] += (float((side.fixed_values - h0) @ h0), float(h0 @ h0))
        comm.Allreduce(MPI.IN_PLACE, dots, op=MPI.SUM)
        eps = 1e-12
        return bool(dots[0] < -eps * dots[1] or dots[2] < -eps * dots[3])

    def _misfit(self, problem: BlockProblem, x: Sequence[PETSc.Vec]) -> str:
        """What of ``problem`` no longer fits the history (``""``: nothing; local)."""
        stores = problem.states
        if [v.getLocalSize() for v in x] != [a.size for a in self.x] or [
            v.getLocalSize() for v in problem.loads
        ] != [a.size for a in self.loads]:
            return "its fields"
        held = [s.fixed_values.size if isinstance(s, FESide) else -1 for s in problem.sides]
        if held != [-1 if h is None else h.size for h in self.held]:
            return "its held dofs"
        if len(stores) != len(self.states) or any(
            len(st) != len(next(iter(old.values()), ()))
            for st, old in zip(stores, self.states, strict=True)
        ):
            return "its quadrature points"
        return ""
