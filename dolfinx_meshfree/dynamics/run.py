"""A run of explicit dynamics from the current time to ``t_end``: the step count and size, the
progress bar, the XDMF writer of a run and the output callbacks around
:func:`~dolfinx_meshfree.dynamics.central_difference.advance_to` (Belytschko et al. 1995, sec.
5.2; Rabczuk et al. 2006, Table I); what :meth:`ExplicitDynamics.run
<dolfinx_meshfree.dynamics.explicit.ExplicitDynamics.run>` does.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..io import DynamicsWriter, ProgressBar
from .central_difference import advance_to
from .results import DynamicsResult

if TYPE_CHECKING:  # annotations only: the facade imports this module
    from .explicit import ExplicitDynamics

__all__ = ["integrate"]


def integrate(
    dyn: ExplicitDynamics,
    t_end: float,
    dt: float | None,
    force: bool,
    outputs: Sequence[float],
    energy_records: int,
    on_output: Callable | None,
    xdmf: str | os.PathLike | None,
    progress: bool | None,
) -> DynamicsResult:
    """Integrate ``dyn`` to ``t_end`` (collective); see :meth:`ExplicitDynamics.run
    <dolfinx_meshfree.dynamics.explicit.ExplicitDynamics.run>` for the arguments."""
    crit = dyn.critical_time_step()
    span = float(t_end) - dyn.time
    if not (np.isfinite(span) and span > 0.0):
        raise ValueError(f"t_end={t_end!r} must lie after the current time {dyn.time}")
    nsteps, dt = dyn.bound.steps_to(span, dt, force)
    t0 = dyn.time
    label = "explicit dynamics "
    bars = [ProgressBar(nsteps, dyn.comm, progress, label=label)]  # checks `progress`
    writer = DynamicsWriter(xdmf, dyn) if xdmf is not None else None
    if writer is not None and not len(outputs):
        outputs = (t0, float(t_end))

    def notify(n: int, t: float) -> None:
        if writer is not None:
            writer(dyn, n, t)
        if on_output is not None:
            on_output(dyn, n, t)

    # a finite-strain system re-bounds its step as it stiffens (not with a forced dt; a bulk
    # viscosity's damper is checked at every step, time_step.Rebound)
    rebound = dyn.rebound_every if hasattr(dyn.system, "wave_speed") and not force else None
    try:
        done = advance_to(
            dyn.stepper, dyn.bound, float(t_end), nsteps, dt, outputs, energy_records,
            notify, lambda n: bars.pop() if bars else ProgressBar(n, dyn.comm, progress,
                                                                   label=label),
            rebound, force,
        )  # fmt: skip
    finally:
        if writer is not None:
            writer.close()
    return DynamicsResult(
        dt=done.dt,
        steps=done.steps,
        time=dyn.time,
        energies=done.records,
        outputs=done.outputs,
        critical={**crit, **dyn.critical_time_step(), "stable": dyn.stable_time_step()},
        timings=done.timings,
    )
