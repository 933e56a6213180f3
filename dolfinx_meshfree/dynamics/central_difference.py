"""Central differences with half-step velocities and the multiplier correction.

Belytschko et al. 1995, sec. 5.2; Rabczuk et al. 2006, Table I. With ``f^int`` the internal
force of the system (``K d`` for a linear one) and ``M`` lumped:

* trial velocities (eq. 93): ``vbar = v_{n-1/2} + dt M^{-1} (f^ext_n - f^int(d_n))``;
* the multiplier correction (eq. 94–96, :mod:`~dolfinx_meshfree.dynamics.constraint`):
  ``v_{n+1/2} = vbar - M^{-1} G^T lambda`` with ``G v_{n+1/2} = 0``;
* ``d_{n+1} = d_n + dt v_{n+1/2}``; ``v_{1/2} = v_0 + dt/2 M^{-1} f_0``; a run continued with
  another step size uses ``(dt_{n-1/2} + dt_{n+1/2}) / 2`` for its first velocity update.

Dofs fixed strongly (FE Dirichlet nodes) have ``M^{-1} = 0``: zero velocity and acceleration,
or a prescribed velocity (:mod:`~dolfinx_meshfree.dynamics.prescribed`).
The velocity at an output time is ``v_n = (v_{n-1/2} + v_{n+1/2}) / 2``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..io import ProgressBar
from ..physics.constitutive import DeformationError
from .constraint import VelocityProjection
from .energy import (
    EnergyRecord,
    constraint_work,
    discrete_energy,
    external_work,
    kinetic_energy,
)
from .loads import ExternalLoads
from .system import SemiDiscreteSystem
from .time_step import Rebound, TimeStepBound

__all__ = ["CentralDifference", "Stepped", "advance_to", "schedule"]

OnOutput = Callable[[int, float], None]


def schedule(
    n0: int, t0: float, nsteps: int, dt: float, outputs: Sequence[float], energy_records: int
) -> tuple[dict[int, float], set[int]]:
    """The output steps ``{step: requested time}`` (the nearest step of each output time) and
    the energy steps (about ``energy_records`` of them, the outputs and the last step added)
    of a run of ``nsteps`` steps of ``dt`` from step ``n0`` at time ``t0``."""
    out_steps = {n0 + min(nsteps, max(0, round((t - t0) / dt))): t for t in outputs}
    every = max(1, nsteps // max(1, energy_records))
    energy_steps = set(range(n0, n0 + nsteps + 1, every)) | set(out_steps) | {n0 + nsteps}
    return out_steps, energy_steps


@dataclass
class Stepped:
    """What :meth:`CentralDifference.advance` did.

    Attributes:
        steps: The number of steps. records: This run's energy records.
        outputs: ``(step, time)`` of each output.
        t_loop: Seconds in the loop, outputs excluded. t_out: Seconds in the outputs.
        dt: The (last) step.
    """

    steps: int
    records: list[EnergyRecord]
    outputs: list[tuple[int, float]]
    t_loop: float
    t_out: float
    dt: float = 0.0

    @property
    def timings(self) -> dict[str, float]:
        """Seconds in ``steps`` (the loop, outputs excluded), ``per_step``, ``outputs``."""
        return {"steps": self.t_loop, "per_step": self.t_loop / self.steps, "outputs": self.t_out}


class CentralDifference:
    """The state ``(d_n, v_{n-1/2})`` of a semi-discrete system and its time stepping.

    Args:
        system: The semi-discrete system (masses, internal force, constraints).
        minv: ``M^{-1}`` per field (0 on dofs held at rest).
        loads: The external loads.
        projection: The velocity correction onto ``G v = 0``, or ``None``: no constraint.

    Attributes:
        u, v: ``d_n`` and ``v_{n-1/2}`` (``v_0`` before the first step) per field.
        step, time: The current step and time.
        records: The energy records of every run since :meth:`reset`.
        w_ext, w_c: This rank's part of the work of the loads and (per field) of the constraint
            forces since :meth:`reset` (the records hold their sums over the ranks).
    """

    def __init__(
        self,
        system: SemiDiscreteSystem,
        minv: Sequence[PETSc.Vec],
        loads: ExternalLoads,
        projection: VelocityProjection | None = None,
    ) -> None:
        self.system, self.minv = system, list(minv)
        self.loads, self.projection = loads, projection
        masses = system.mass()
        self.u = [m.duplicate() for m in masses]
        self.v = [m.duplicate() for m in masses]
        for x in (*self.u, *self.v):
            x.set(0.0)
        self._work = [m.duplicate() for m in masses]
        self._tmp = [m.duplicate() for m in masses]
        self._final: list[PETSc.Vec] = []
        self.reset()

    def reset(self) -> None:
        """Time, step and the energy account back to zero (the state vectors are kept)."""
        self.step, self.time = 0, 0.0
        self.dt_prev = 0.0
        self.v_now: list[PETSc.Vec] | None = None  # v_n at the current output time
        #: ``f^int(d_n)`` per field during an output callback of :meth:`advance` (the step's own
        #: force, which :func:`~dolfinx_meshfree.dynamics.sifs.current_acceleration` then need
        #: not recompute), ``None`` outside one: never kept past the callback. Read it through
        #: :meth:`force_now`, which drops it once the callback has changed the displacement.
        self.f_now: list[PETSc.Vec] | None = None
        self._f_state: list[int] = []  # the displacement's PETSc states when f_now was set
        self.records: list[EnergyRecord] = []
        self.w_ext, self.w_c = 0.0, np.zeros(len(self.u))

    def force_now(self) -> list[PETSc.Vec] | None:
        """:attr:`f_now` while it is the force of the current displacement: ``None`` outside
        an output callback, and inside one once the callback has changed ``u`` (PETSc counts
        every change of a vector's values: its state), so a callback that moves the state and
        then asks for the acceleration gets the new state's force, not the step's."""
        if self.f_now is None or [x.stateGet() for x in self.u] != self._f_state:
            return None
        return self.f_now

    def current_velocity(self) -> list[PETSc.Vec]:
        """``v_n`` at an output time or after a run, else ``v_{n-1/2}``."""
        return self.v_now if self.v_now is not None else self.v

    def residual(
        self, vel: Sequence[PETSc.Vec] | None = None, target: np.ndarray | None = None
    ) -> float:
        """The relative constraint residual of ``vel`` (default: the current velocities; from
        ``G v = target`` with prescribed values); 0 without a constraint (collective)."""
        if self.projection is None:
            return 0.0
        vel = vel if vel is not None else self.current_velocity()
        return self.projection.residual(vel, target)

    def advance(
        self,
        nsteps: int,
        dt: float,
        span: float,
        out_steps: Mapping[int, float],
        energy_steps: Collection[int],
        on_output: OnOutput | None,
        progress: ProgressBar,
        stop: Callable[[int], bool] | None = None,
    ) -> Stepped:
        """Take ``nsteps`` steps of ``dt`` (``nsteps dt = span``), recording the energies at
        ``energy_steps`` and calling ``on_output(step, time)`` at ``out_steps`` with ``v_n``
        current; closes ``progress``. Collective.

        The state stays ``(d_N, v_{N-1/2})`` for a next run; ``v_N`` is kept for evaluation.
        ``stop(n)``, if given, is asked before each step ``n0 < n < n0 + nsteps`` (collective, the
        same answer on every rank; not at ``N = n0 + nsteps``, where no step is taken and
        ``v_N`` and its outputs are recorded): ``True`` ends the run there, in the state
        ``(d_n, v_{n-1/2})`` (:attr:`Stepped.steps` tells how many steps were taken), e.g. to
        continue with a smaller step (:class:`~dolfinx_meshfree.dynamics.time_step.Rebound`).
        """
        system, loads, G = self.system, self.loads, self.system.constraints()
        masses = system.mass()
        F = len(masses)
        n0, t0 = self.step, self.time
        ku, vnew, vnow, imp = ([m.duplicate() for m in masses] for _ in range(4))
        for x in imp:
            x.set(0.0)
        records = self.records
        first = len(records)
        comm = masses[0].getComm().tompi4py()
        # the works are summed on each rank over its dofs, and over the ranks at the energy
        # records only (one Allreduce there instead of collective dot products every step);
        # the held dofs' reaction work, the same on every rank, counts on rank 0
        held_share = 1.0 if comm.rank == 0 else 0.0
        w_ext, w_c = self.w_ext, self.w_c
        pk = [k for k, f in enumerate(system.fields) if f.name == "particles"]
        t_out = 0.0
        outs: list[tuple[int, float]] = []
        set_time = getattr(system, "set_time", None)
        clock = time.perf_counter()
        n = n0
        stopped = False
        try:
            for n in range(n0, n0 + nsteps + 1):
                # asked before each step taken: not at N, where the run only records v_N and
                # its outputs (a stop there lost the last output, issue 23, item 3)
                if stop is not None and n0 < n < n0 + nsteps and stop(n):
                    stopped = True
                    break  # the state is (d_n, v_{n-1/2})
                tn = t0 + (n - n0) * dt
                # v_{n+1/2} = v_{n-1/2} + (dt_{n-1/2} + dt_{n+1/2}) / 2 a_n (a new run may
                # change dt)
                gamma = 0.5 if n == 0 else (0.5 * (1.0 + self.dt_prev / dt) if n == n0 else 1.0)
                amps = loads.at(tn)
                # trial velocities (eq. 93): vbar = v_{n-1/2} + gamma dt M^{-1} (f_ext - f_int)
                if set_time is not None:  # a rate-form law advances its state to t_n
                    set_time(tn)
                try:
                    system.internal_force(self.u, ku)
                except DeformationError as e:  # finite strain: name the step and stop
                    at = f"(explicit dynamics: step {n}, t = {tn:.6g})"
                    raise DeformationError(f"{e} {at}") from e
                for k in range(F):
                    loaded = [(vecs[k], an) for vecs, an in amps if vecs[k] is not None and an]
                    residual = ku[k]  # f_int - f_ext (a copy only when loaded or driven)
                    if loaded or (k == 0 and loads.motion is not None):
                        residual = self._work[k]
                        ku[k].copy(residual)
                        for b, an in loaded:
                            residual.axpy(-an, b)
                    vnew[k].pointwiseMult(self.minv[k], residual)
                    vnew[k].aypx(-gamma * dt, self.v[k])
                d_held = 0.0  # held FE dofs driven at prescribed velocities, their reaction's work
                if loads.motion is not None:
                    d_held = loads.motion.impose(masses[0], self._work[0], self.v[0], vnew[0],
                                                 tn, dt, gamma)  # fmt: skip
                # multiplier correction (eq. 94-96): G v_{n+1/2} = 0
                g = None
                if self.projection is not None:
                    g = None if loads.motion is None else loads.motion.target(tn + 0.5 * dt)
                    self.projection.correct(vnew, imp, g)
                # work of the step (see energy.external_work)
                d_ext, d_c = 0.0, np.zeros(F)
                if n > 0:
                    d_ext = external_work(amps, self.v, vnew, dt) + held_share * d_held
                    if G is not None:  # constraint force -G^T lambda / dt
                        d_c = constraint_work(G, imp, self.v, vnew)
                if n in energy_steps:
                    tic = time.perf_counter()
                    for k in range(F):  # v_n
                        if n == 0:
                            self.v[k].copy(vnow[k])
                        else:
                            vnow[k].waxpy(1.0, self.v[k], vnew[k])
                            vnow[k].scale(0.5)
                    internal = system.strain_energy(self.u, ku)
                    half = kinetic_energy(masses, vnew, self._tmp)
                    works = np.array([w_ext + d_ext, *(w_c + d_c)])
                    if comm.size > 1:
                        comm.Allreduce(MPI.IN_PLACE, works, op=MPI.SUM)
                    rec = EnergyRecord(
                        step=n,
                        time=tn,
                        kinetic=float(kinetic_energy(masses, vnow, self._tmp)),
                        internal=float(internal),
                        external=float(works[0]),
                        constraint=float(works[1:].sum()),
                        transfer=float(works[1 + pk[0]]) if pk and G is not None else 0.0,
                        discrete=float(discrete_energy(half, internal, ku, vnew, dt)),
                        residual=self.residual(vnew, g),
                    )
                    records.append(rec)
                    if n in out_steps:
                        self.v_now, self.f_now = vnow, ku
                        self._f_state = [x.stateGet() for x in self.u]
                        self.time, self.step = tn, n
                        outs.append((n, tn))
                        try:
                            if on_output is not None:
                                on_output(n, tn)
                        finally:
                            self.v_now = self.f_now = None
                    t_out += time.perf_counter() - tic
                if n == n0 + nsteps:
                    break  # v_N is known; the state stays (d_N, v_{N-1/2}) for a next run
                w_ext += d_ext
                w_c = w_c + d_c
                for k in range(F):
                    self.u[k].axpy(dt, vnew[k])
                    vnew[k].copy(self.v[k])
                progress.update(n + 1 - n0, t0 + (n + 1 - n0) * dt)
        finally:
            progress.close(nsteps if n == n0 + nsteps else None, t0 + (n - n0) * dt)
        t_loop = time.perf_counter() - clock - t_out
        self.dt_prev = dt
        if stopped:
            self.step, self.time, self.v_now = n, t0 + (n - n0) * dt, None
            self.records, self.w_ext, self.w_c = records, w_ext, w_c
            for obj in (*ku, *vnew, *vnow, *imp):
                obj.destroy()
            return Stepped(n - n0, records[first:], outs, t_loop, t_out, dt)
        self.step, self.time = n0 + nsteps, t0 + span
        # keep v_N for evaluation after the run
        for x in self._final:
            x.destroy()
        self._final = [x.copy() for x in vnow]
        self.v_now = self._final
        self.records, self.w_ext, self.w_c = records, w_ext, w_c
        for obj in (*ku, *vnew, *vnow, *imp):
            obj.destroy()
        return Stepped(nsteps, records[first:], outs, t_loop, t_out, dt)

    def destroy(self) -> None:
        """Destroy the state and work vectors (collective)."""
        for obj in (*self.u, *self.v, *self._work, *self._tmp, *self._final):
            obj.destroy()


def advance_to(
    stepper: CentralDifference,
    bound: TimeStepBound,
    t_end: float,
    nsteps: int,
    dt: float,
    outputs: Sequence[float],
    energy_records: int,
    on_output: OnOutput | None,
    progress: Callable[[int], ProgressBar],
    rebound: int | None = None,
    force: bool = False,
) -> Stepped:
    """Advance ``stepper`` to ``t_end`` in ``nsteps`` steps of ``dt``, or, with ``rebound`` (steps
    between two checks of the wave speed, :class:`~dolfinx_meshfree.dynamics.time_step.Rebound`),
    in segments whose step is lowered each time the re-bounded stable step falls below it
    (collective). Outputs not reached in a segment carry over; energy records stay about one
    per ``nsteps / energy_records`` steps.

    Args:
        progress: ``progress(n)``: a progress bar of ``n`` steps (one per segment).
    """
    every = max(1, nsteps // max(1, energy_records))
    pending = [float(t) for t in outputs]
    parts: list[Stepped] = []
    count = energy_records
    while True:
        n0, t0 = stepper.step, stepper.time
        stop = Rebound(bound, dt, n0, rebound) if rebound is not None else None
        out_steps, energy_steps = schedule(n0, t0, nsteps, dt, pending, count)
        done = stepper.advance(
            nsteps, dt, t_end - t0, out_steps, energy_steps, on_output, progress(nsteps), stop
        )
        parts.append(done)
        if done.steps == nsteps:
            break
        reached = stepper.step - n0  # outputs not reached before the stop stay pending
        pending = [t for t in pending if round((t - t0) / dt) >= reached]
        nsteps, dt = bound.steps_to(t_end - stepper.time, min(dt, bound.stable()), force)
        count = max(1, nsteps // every)
    return Stepped(
        steps=sum(p.steps for p in parts),
        records=[r for p in parts for r in p.records],
        outputs=[o for p in parts for o in p.outputs],
        t_loop=sum(p.t_loop for p in parts),
        t_out=sum(p.t_out for p in parts),
        dt=dt,
    )
