"""An explicit run whose particle patch grows where the material needs it (issue 25, item 2:
criteria on the running state; the base of issue 27's conversion of failing elements).

:class:`AdaptiveRun` advances a coupled model ``check_every`` steps at a time; between chunks it
asks its criteria (:mod:`~dolfinx_meshfree.geometry.patch_criteria`: ``FieldAbove`` on the
current displacement, e.g. the largest principal stress; ``CellsWhere``; ``NearTips`` about the
model's crack tips) which FE cells must be particles. The model is then rebuilt by the user's
``build(cells=...)`` on the larger patch and the state carried over
(:func:`~dolfinx_meshfree.dynamics.patch_conversion.convert`: the new particles take the L2
projection of the old field, stabilised for the ramps; mass and momentum conserved, the energy
change recorded).
:class:`~dolfinx_meshfree.dynamics.DynamicCrackGrowth` does the same about a running crack.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..parallel import raise_on_all_ranks
from .explicit import ExplicitDynamics
from .patch_conversion import Conversion, ConvertingPatch

__all__ = ["AdaptiveRun"]


class AdaptiveRun:
    """An explicit run of a coupled model whose patch grows (module docstring).

    Args:
        build: ``build(cells=None) -> ExplicitDynamics``: the model with its loads and
            conditions, its patch on ``cells`` (this rank's local cells; ``None``: the first
            patch). Any coupling (master-slave at finite strain only with links of length
            zero).
        adapt: A criterion or a list (a cell joins when any names it).
        check_every: Steps between two checks (>= 1).
        dt: The time step; ``None``: the stable step of each (re)built model.
        release_after: Shrinking back: a particle cell that no criterion has named in this
            many checks in a row returns to FE, unless it belongs to the first patch (the state
            is carried over as for growth; the nodes it gives back take the field's values).
            ``None`` (default): the patch only grows.

    Attributes:
        model: The current :class:`~dolfinx_meshfree.ExplicitDynamics` (a new object after
            each conversion; the old one is destroyed).
        conversions: One :class:`~dolfinx_meshfree.dynamics.patch_conversion.Conversion` per
            growth of the patch.
        timings: Seconds in ``steps`` and ``conversions``.

    Example::

        run = mf.dynamics.AdaptiveRun(build, mf.FieldAbove("max_principal_stress", 0.8 * ft))
        run.run(t_end)
        run.model.velocity_at(points), run.conversions
    """

    def __init__(
        self,
        build: Any,
        adapt: Any,
        check_every: int = 10,
        dt: float | None = None,
        release_after: int | None = None,
    ) -> None:
        if not callable(build):
            raise ValueError(f"build={build!r:.80} must be a callable build(cells=None) -> model")
        if isinstance(check_every, bool) or not isinstance(check_every, int) or check_every < 1:
            raise ValueError(f"check_every={check_every!r} must be an integer >= 1 (steps)")
        if dt is not None and not (isinstance(dt, int | float) and np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt={dt!r} must be a positive time step or None (the stable one)")
        self.model = build()
        if not isinstance(self.model, ExplicitDynamics):
            raise ValueError(f"build() returned {self.model!r:.80}, not ExplicitDynamics")
        self.adaptive = ConvertingPatch(adapt, self.model, build, release_after=release_after)
        self.build, self.check_every, self.dt = build, check_every, dt
        self.timings = {"steps": 0.0, "conversions": 0.0}

    @property
    def conversions(self) -> list[Conversion]:
        return self.adaptive.conversions

    def _check(self) -> None:
        """Ask the criteria; on a growth, the rebuilt model with the state carried over."""
        tic = time.perf_counter()
        new = self.adaptive.grow(
            self.model, lambda cells: self.build(cells=cells), driver="AdaptiveRun"
        )
        if new is not None:
            self.model.destroy()
            self.model = new
        self.timings["conversions"] += time.perf_counter() - tic

    def run(self, t_end: float, energy_records: int = 100, last: bool = True) -> ExplicitDynamics:
        """Run to ``t_end`` (collective), checking before the first step and every
        ``check_every`` steps. Returns the final model. A
        :class:`~dolfinx_meshfree.PatchCriterionWarning` (once) if the criteria have named no
        cell by then.

        Args:
            energy_records: About how many energy records this call adds to
                ``model.stepper.records`` (at least one per check: the end of each stretch of
                steps).
            last: ``False`` when later calls continue the run (a run in pieces): the warning
                waits for a last call.

        Raises:
            ValueError: on every rank: ``t_end`` not after the current time; ``dt`` above the
                stable step of a (rebuilt) model.
        """
        dyn = self.model

        def check() -> float:
            if not (isinstance(t_end, int | float) and np.isfinite(t_end) and t_end > dyn.time):
                raise ValueError(
                    f"t_end={t_end!r} must be a time after the current one ({dyn.time:.6g})"
                )
            if (
                isinstance(energy_records, bool)
                or not isinstance(energy_records, int)
                or energy_records < 1
            ):
                raise ValueError(f"energy_records={energy_records!r} must be an integer >= 1")
            return float(t_end)

        t_end = raise_on_all_ranks(dyn.comm, check)
        t_start = dyn.time
        self._check()
        while self.model.time < t_end * (1.0 - 1e-12):
            dyn = self.model
            stable = dyn.stable_time_step()
            dt = stable if self.dt is None else self.dt
            t_next = min(t_end, dyn.time + self.check_every * dt)
            share = max(1, round(energy_records * (t_next - dyn.time) / (t_end - t_start)))
            tic = time.perf_counter()
            # a dt above the stable step: refused there
            dyn.run(t_next, dt=dt, energy_records=share, progress=False)
            self.timings["steps"] += time.perf_counter() - tic
            if self.model.time < t_end * (1.0 - 1e-12):
                self._check()
        if last:
            self.adaptive.finish("AdaptiveRun", f"the run to t = {self.model.time:.6g}")
        return self.model
