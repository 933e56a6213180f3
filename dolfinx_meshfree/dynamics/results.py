"""What a run of explicit dynamics returns: the step, the energy records, the output times."""

from __future__ import annotations

from dataclasses import dataclass, field

from .energy import EnergyRecord

__all__ = ["DynamicsResult"]


@dataclass
class DynamicsResult:
    """What :meth:`ExplicitDynamics.run <dolfinx_meshfree.ExplicitDynamics.run>` did.

    Attributes:
        dt: The time step (the last one, if a finite-strain run lowered it).
        steps: Number of steps taken.
        time: The final time.
        energies: :class:`~dolfinx_meshfree.dynamics.energy.EnergyRecord` at this run's energy
            steps (outputs included; a run continued with another step size starts a new level
            of the discrete energy).
        outputs: ``(step, time)`` of each requested output time (nearest step).
        critical: :meth:`ExplicitDynamics.critical_time_step
            <dolfinx_meshfree.ExplicitDynamics.critical_time_step>` (``critical = spectral =
            2 / omega_bound``, the guard; ``courant = h_min / c`` reported only; ``bounds``: how
            many times it was computed) and ``stable`` (times ``safety``).
        timings: Seconds in ``steps`` (the loop, outputs excluded), ``per_step``, ``outputs``.
    """

    dt: float
    steps: int
    time: float
    energies: list[EnergyRecord]
    outputs: list[tuple[int, float]]
    critical: dict
    timings: dict = field(default_factory=dict)

    def _relative_change(self, key: str) -> float:
        if not self.energies:
            return 0.0
        e0 = getattr(self.energies[0], key)
        scale = max(abs(e0), *(r.kinetic + r.internal for r in self.energies))
        if scale == 0.0:
            return 0.0
        return max(abs(getattr(r, key) - e0) for r in self.energies) / scale

    @property
    def energy_drift(self) -> float:
        """Relative drift of :attr:`EnergyRecord.balance` (the conserved discrete energy minus
        the work done on the system): ``max_n |B_n - B_0| / max(|B_0|, max_n (kin + int))``."""
        return self._relative_change("balance")

    @property
    def energy_oscillation(self) -> float:
        """The same for :attr:`EnergyRecord.total` (kinetic energy at integer steps), an O(dt^2)
        oscillation of the averaged velocities, not a drift."""
        return self._relative_change("total")

    @property
    def max_residual(self) -> float:
        """Largest relative constraint residual over the records."""
        return max((r.residual for r in self.energies), default=0.0)
