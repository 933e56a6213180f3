"""A patch that grows between the steps of a static run (issue 25, item 1, in statics).

:class:`PatchGrowth` asks its criteria (:mod:`~dolfinx_meshfree.geometry.patch_criteria`) which
FE cells must be particles, and when any must, builds the larger patch
(:meth:`~dolfinx_meshfree.ParticlePatch.grown`: the cells' particles placed as at build time),
moves the cracks into it (:meth:`~dolfinx_meshfree.Crack.release` from the old patch and its MLS,
:meth:`~dolfinx_meshfree.ParticlePatch.add_crack` into the new one) and rebuilds the user's model
on it (:meth:`~dolfinx_meshfree.CoupledLinearProblem.with_patch`): interface, multipliers, ramp
cells or bridging band move with the patch because they are built from it.

The rebuild is full (every table, the operators and the assembly), and each event says so in
its record: this is what issue 25 allows "while a constraint cannot be rebuilt locally". A static
linear (LEFM) growth step re-solves from the unloaded state, so no state or velocity has to be
carried to the new particles; a model with state (cohesive faces, damage) is refused by the
drivers that take ``adapt``.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..geometry.crack import CrackPlacementWarning
from ..geometry.patch import ParticlePatch
from ..geometry.patch_criteria import GrowthContext, PatchCriterion, as_criteria, named_cells
from ..parallel import raise_on_all_ranks
from .growth_update import disable_local_update, enable_local_update
from .problem import CoupledLinearProblem

__all__ = ["PatchEvent", "PatchGrowth"]


@dataclass
class PatchEvent:
    """One growth of the patch.

    Attributes:
        step: The driver's step after whose solve the patch grew (-1: before the first solve).
        cells_added: FE cells that became particle cells (global count).
        by: The criteria that named them (their ``repr``).
        particles_before, particles_after: The particle counts.
        cells_after: Patch cells after (global count).
        time_rebuild: Seconds of the new patch and the model's construction (its tables and
            operators are built by the next solve, as at the first).
        rebuild: ``"full"``: every table and operator rebuilt (the only kind in statics).
        energy_change: :func:`~dolfinx_meshfree.follow_path` only: the new model's stored energy
            after it is brought back to equilibrium, less the old model's and the work of the
            load on the way: what the rebuild changed (0 for a rebuild that reproduced the
            old field exactly).
        carried: :func:`~dolfinx_meshfree.follow_path` with a law with state: the bulk's
            dissipated energy before and after its states were carried to the new points, the
            points that took a state from another position, and those that took it across a
            crack (as :attr:`~dolfinx_meshfree.statics.path_following.PathResult.carried`).
    """

    step: int
    cells_added: int
    by: list[str]
    particles_before: int
    particles_after: int
    cells_after: int
    time_rebuild: float
    rebuild: str = "full"
    energy_change: float = 0.0
    carried: tuple[float, float, int, int] | None = None

    def as_dict(self) -> dict:
        """Plain values (for JSON)."""
        return asdict(self)


class PatchGrowth:
    """Grows the patch of a :class:`~dolfinx_meshfree.CoupledLinearProblem` between steps.

    Args:
        problem: The user's ``CoupledLinearProblem`` (it keeps its forms and conditions, so it
            can be rebuilt on a larger patch).
        adapt: One criterion or a list (a cell joins when any names it).
        driver: The driver's name, for the messages.

    Attributes:
        problem: The current problem (a new object after each event).
        events: The :class:`PatchEvent` records.
        selected: Whether any criterion ever named a cell (patch cells included).
    """

    def __init__(self, problem: Any, adapt: Any, driver: str) -> None:
        comm = getattr(getattr(problem, "patch", None), "comm", None)

        def check() -> list[PatchCriterion]:
            if not isinstance(problem, CoupledLinearProblem):
                kind = type(problem).__name__
                why = (
                    "pure EFG has particles everywhere: there is no FE cell to convert"
                    if kind == "EFGElasticity"
                    else "it rebuilds the model from the user's forms and conditions on the "
                    "larger patch; a model whose loads were added by its methods cannot be "
                    "carried over"
                )
                raise TypeError(
                    f"{driver}(adapt=...) grows the patch of a CoupledLinearProblem, got a "
                    f"{kind}: {why}"
                )
            return as_criteria(adapt)

        if comm is None:
            self.criteria = check()
        else:
            self.criteria = raise_on_all_ranks(comm, check)
        self.problem, self.driver = problem, driver
        self.events: list[PatchEvent] = []
        self.selected = False

    @property
    def patch(self) -> ParticlePatch:
        return self.problem.patch

    def grow(self, context: GrowthContext, local: Any = None) -> PatchEvent | None:
        """Ask the criteria; when FE cells must be particles, grow the patch and rebuild the
        model (collective). ``local``: the old model's local update, released with it. Returns
        the event, or ``None``."""
        patch = self.patch
        comm = patch.comm
        want, by, named, _ = named_cells(self.criteria, patch, context, self.driver)
        self.selected |= named
        added = comm.allreduce(int(want.sum()))
        if added == 0:
            return None
        t0 = time.perf_counter()
        before = patch.particles.num_particles
        grown = patch.grown(np.flatnonzero(want))
        with warnings.catch_warnings():  # the path is the physics' (as Crack.extend's)
            warnings.simplefilter("ignore", CrackPlacementWarning)
            for crack in patch.cracks:
                grown.add_crack(crack)
        old = self.problem.problem  # the CoupledElasticity
        mls = getattr(old, "mls", None)
        if mls is not None:
            disable_local_update(mls)
        for crack in grown.cracks:
            crack.release(patch, mls, local)
        self.problem = self.problem.with_patch(grown)
        event = PatchEvent(
            step=context.step, cells_added=added, by=by, particles_before=before,
            particles_after=grown.particles.num_particles,
            cells_after=comm.allreduce(grown.cells.size),
            time_rebuild=time.perf_counter() - t0,
        )  # fmt: skip
        self.events.append(event)
        return event

    def local_update(self, cracks: Sequence) -> Any:
        """Enable the growth's local update on the current model's MLS (after an event)."""
        mls = getattr(self.problem.problem, "mls", None)
        return None if mls is None else enable_local_update(mls, cracks)
