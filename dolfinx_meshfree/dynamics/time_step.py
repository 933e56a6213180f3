"""The stable time step of central differences: an upper bound of the largest frequency.

Central differences are stable for ``dt <= 2 / omega_max`` (Belytschko et al. 1995, sec. 5.2),
``omega_max^2`` the largest eigenvalue of the constrained operator ``P M^{-1} K`` on the free dofs
(``P`` the velocity projection of eq. 94–96, which is ``M``-orthogonal, and dofs with
``M^{-1} = 0`` held at rest), ``K`` the tangent of the system. A too large estimate of the step is
unstable, so the guard is a bound that cannot be too small in ``omega``: the Schur test with
``B = M^{-1/2} K M^{-1/2}`` (free dofs) and any positive ``y``,

.. math::
    \\omega_{max}^2 \\le |P M^{-1} K|_M \\le |B|_2 \\le \\sqrt{
    \\max_i \\frac{(|K| y)_i}{m_i y_i} \\, \\max_j \\frac{(|K|^T y)_j}{m_j y_j}},

since ``|P|_M = 1``; measured 1.00-1.14x the true ``omega_max`` on FE, EFG and every coupling.
The Courant condition ``h_min / c`` is reported only: it is exact for square Q1 elements at
``nu = 0`` but exceeds the critical step on triangles (1.44x on right triangles), for
``nu -> 1/2`` and for small weighted masses (bridging); for EFG it is conservative.

:class:`TimeStepBound` holds the bound of a system: computed once for a linear system, and
re-bounded when the system says its tangent changed (:meth:`TimeStepBound.invalidate`, the hook
of a stiffening material or a rebuilt approximation).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..physics.materials import LinearElastic
from .linalg import absolute
from .system import SemiDiscreteSystem

__all__ = [
    "DefaultDensityWarning",
    "Rebound",
    "TimeStepBound",
    "check_safety",
    "frequency_bound",
    "same_time",
    "warn_default_density",
]


class DefaultDensityWarning(UserWarning):
    """Explicit dynamics runs on a law built without ``rho`` (the default density 1.0)."""


def warn_default_density(material: object) -> None:
    """Warn (on every rank, no collective call) when ``material`` was built without ``rho``:
    the density sets the time scale of explicit dynamics and its stable step (``dt ~ h
    sqrt(rho / E)``), so a steel model in SI units with the default 1.0 runs sqrt(7850) = 89
    times too fast without a word (issue 23, item 4). Statics does not use the density."""
    if not getattr(material, "density_given", True):
        warnings.warn(
            f"material={material!r} was built without a density: explicit dynamics uses "
            f"rho={material.rho} (the default), which sets the time scale and the stable step; "
            f"pass rho= to the law (e.g. {type(material).__name__}(..., rho=7850.0) for steel in "
            "SI units)",
            DefaultDensityWarning,
            stacklevel=3,
        )


def check_safety(safety: float) -> float:
    """Return ``safety`` as a float if it lies in (0, 1], else raise a ``ValueError``."""
    if isinstance(safety, bool) or not (isinstance(safety, int | float) and 0.0 < safety <= 1.0):
        raise ValueError(
            f"safety={safety!r} must lie in (0, 1] (a fraction of the critical time step)"
        )
    return float(safety)


def frequency_bound(
    system: SemiDiscreteSystem,
    minv: Sequence[PETSc.Vec],
    free: Sequence[np.ndarray],
    comm: MPI.Comm,
    iterations: int = 30,
    u: Sequence[PETSc.Vec] | None = None,
) -> tuple[float, float]:
    """Upper bounds of ``omega_max^2`` by the Schur test (collective).

    With ``y = 1`` it is Gershgorin's row-sum bound ``max_i sum_j |K_ij| / m_i`` (for a
    symmetric ``K`` both factors agree); ``y`` is then improved by ``iterations`` power steps
    with ``M^{-1} (|K| + |K|^T) / 2`` and the smallest bound is kept (every iterate gives a valid
    bound; it tends to the spectral radius of ``|M^{-1} K|``). The bound holds for a
    non-symmetric ``K`` too (consistent integration), for ``|lambda|``.

    Args:
        system: Its masses and its tangent at ``u``.
        minv: ``M^{-1}`` per field (0 on dofs held at rest).
        free: bool per owned dof of each field: not held at rest.
        u: The state of the tangent (``None``: the reference state).

    Returns:
        ``(best, first)``: the smallest bound of ``omega_max^2`` and the Gershgorin one.
    """
    masses = system.mass()
    F = len(masses)
    tangent = {kl: absolute(A) for kl, A in system.tangent(u).items()}
    on_free = [fr.astype(float) for fr in free]
    y = [m.duplicate() for m in masses]
    r = [m.duplicate() for m in masses]
    col = [m.duplicate() for m in masses]
    for yk, fk in zip(y, on_free, strict=True):
        yk.array[:] = fk

    def ratio(vecs: list[PETSc.Vec]) -> float:
        """``max_i v_i / (m_i y_i)`` over the free dofs (every rank)."""
        loc = 0.0
        for v, yk, m, fk in zip(vecs, y, masses, on_free, strict=True):
            on = fk > 0.0
            if on.any():
                loc = max(loc, float(np.max(v.array_r[on] / (m.array_r[on] * yk.array_r[on]))))
        return float(comm.allreduce(loc, op=MPI.MAX))

    best, first = np.inf, np.inf
    for it in range(iterations + 1):
        for k in range(F):
            r[k].set(0.0)
            col[k].set(0.0)
        for (k, j), A in tangent.items():
            A.multAdd(y[j], r[k], r[k])
            A.multTransposeAdd(y[k], col[j], col[j])
        lam = np.sqrt(ratio(r) * ratio(col))
        best = min(best, lam)
        if it == 0:
            first = lam
        if it == iterations or lam == 0.0:
            break
        top = 0.0
        for k in range(F):  # y <- M^{-1} (|K| + |K|^T) y / 2 on the free dofs
            yk = 0.5 * (r[k].array_r + col[k].array_r) * minv[k].array_r * on_free[k]
            y[k].array[:] = yk
            top = max(top, float(yk.max(initial=0.0)))
        top = comm.allreduce(top, op=MPI.MAX)
        if top <= 0.0:
            break
        for yk, fk in zip(y, on_free, strict=True):  # positive on the free dofs
            yk.array[:] = np.maximum(yk.array_r / top, 1e-3) * fk
    for obj in (*tangent.values(), *y, *r, *col):
        obj.destroy()
    return float(best), float(first)


class TimeStepBound:
    """The critical and stable time steps of a system (cached until :meth:`invalidate`).

    A system with a state-dependent tangent (finite strain) is bounded at its current state
    (``state``) and its current wave speed (``system.wave_speed``, reported and the reference of
    :class:`Rebound`); the guard ``critical`` is the smallest bound met so far: a re-bound may
    lower the step, never raise it (a softening material keeps the step of its stiffest state).

    Args:
        system: The semi-discrete system.
        material: Its material (the wave speed of the Courant estimate).
        minv, free: ``M^{-1}`` and the free dofs of each field.
        comm: The communicator.
        safety: Fraction of the critical step used by default (0 < safety <= 1).
        state: ``state()`` -> the current displacement per field, or ``None``: the tangent at
            the reference state (a linear system's, the same at any state).
    """

    def __init__(
        self,
        system: SemiDiscreteSystem,
        material: LinearElastic,
        minv: Sequence[PETSc.Vec],
        free: Sequence[np.ndarray],
        comm: MPI.Comm,
        safety: float = 0.9,
        state: Callable[[], Sequence[PETSc.Vec]] | None = None,
    ) -> None:
        self.system, self.material = system, material
        self.minv, self.free, self.comm = list(minv), list(free), comm
        self.safety = check_safety(safety)
        self.state = state
        self._critical: dict | None = None
        #: The step of the last wave-speed check (:class:`Rebound`), across runs.
        self.checked_at = 0
        self._lowest = np.inf
        #: How many times the bound was computed.
        self.count = 0

    def critical(self, iterations: int = 30) -> dict:
        """Critical time step from an upper bound of ``omega_max`` (collective, cached).

        Returns:
            ``{"courant": h_min / c, "spectral": 2 / omega_bound, "critical": the smallest
            spectral bound so far (the guard), "omega_bound": ..., "gershgorin": 2 / (the row-sum
            bound with y = 1), "h_min": ..., "wave_speed": c (current), "bounds": count}``.
        """
        if self._critical is not None:
            return self._critical
        u = self.state() if self.state is not None else None
        speed = getattr(self.system, "wave_speed", None)
        c = speed(u) if (u is not None and speed is not None) else self.material.wave_speed()
        h = min(f.spacing for f in self.system.fields)
        best, first = frequency_bound(self.system, self.minv, self.free, self.comm, iterations, u)
        spectral = 2.0 / np.sqrt(best) if best > 0 else np.inf
        self._lowest = min(self._lowest, float(spectral))
        self.count += 1
        self._critical = {
            "courant": float(h / c),
            "spectral": float(spectral),
            "critical": float(self._lowest),
            "omega_bound": float(np.sqrt(best)),
            "gershgorin": float(2.0 / np.sqrt(first)) if first > 0 else np.inf,
            "h_min": float(h),
            "wave_speed": float(c),
            "bounds": self.count,
        }
        return self._critical

    def damper(self) -> float:
        """The factor by which a bulk viscosity lowers the step now (collective; 1 without):
        the largest over the points of ``(b + sqrt(b^2 + c^2)) / c``
        (:mod:`~dolfinx_meshfree.physics.bulk_viscosity`). Each point's damper scales its
        frequencies by at most it, so the bound divided by it is a bound (as Wilkins' step,
        the smallest over the cells)."""
        factor = getattr(self.system, "viscous_factor", None)
        return float(factor()) if factor is not None else 1.0

    def stable(self) -> float:
        """``safety`` times the critical time step, over :meth:`damper` (collective)."""
        return self.safety * self.critical()["critical"] / self.damper()

    def steps_to(self, span: float, dt: float | None, force: bool) -> tuple[int, float]:
        """The number of steps and the step that cover ``span`` exactly: ``dt`` (default the
        stable step) rounded down to ``span / ceil(span / dt)``.

        Raises:
            ValueError: ``span`` not positive and finite, ``dt`` not positive, or above the
                stable step without ``force``.
        """
        crit = self.critical()
        damper = self.damper()
        stable = self.safety * crit["critical"] / damper
        if not (np.isfinite(span) and span > 0.0):
            raise ValueError(f"span={span!r} must be positive")
        if dt is None:
            dt = stable
        elif not (isinstance(dt, int | float) and np.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt={dt!r} must be a positive number")
        elif dt > stable * (1.0 + 1e-12) and not force:
            raise ValueError(
                f"dt={dt:.6g} is above the stable time step {stable:.6g} (safety {self.safety} x "
                f"critical 2/omega_bound = {crit['critical']:.6g}, omega_bound >= omega_max, "
                f"over the bulk viscosity's factor {damper:.4g}; "
                f"Courant h_min/c = {crit['courant']:.6g} with h_min = {crit['h_min']:.4g}); "
                f"pass dt <= {stable:.6g}, dt=None for the stable step, or force=True"
            )
        nsteps = max(1, int(np.ceil(span / dt - 1e-9)))
        return nsteps, span / nsteps

    def invalidate(self) -> None:
        """Forget the bound: the next :meth:`critical` re-bounds the system's current tangent
        (the hook for a system whose tangent changed)."""
        self._critical = None


def same_time(a: float, b: float) -> bool:
    """Whether two times of a run are one up to round-off: a next run's first ``t_n``, ``t0 +
    span``, against the last run's ``t0 + N dt`` (a run continued in pieces)."""
    return abs(a - b) <= 1e-13 * max(abs(a), abs(b))


class Rebound:
    """Re-bounds the stable step of a stiffening system during a run (a ``stop`` hook of
    :meth:`~dolfinx_meshfree.dynamics.central_difference.CentralDifference.advance`).

    Every ``every`` steps (counted across runs) the largest current wave speed
    (``system.wave_speed(u)``, cheap: ``F`` at the quadrature points) is compared with the one
    of the last bound; when it grew by more than ``growth``, the bound is recomputed at the
    current tangent
    (:meth:`TimeStepBound.invalidate`). The run stops (``True``) when the new stable step lies
    below the step in use, so that the caller continues with a smaller one; a system with a bulk
    viscosity (``system.viscous``) is held to its current damper at every step
    (:meth:`TimeStepBound.stable`; no new bound). Between two checks
    the step has a margin ``1 / safety`` on the last bound, which a growth of the frequencies by
    less than ``growth`` (5 %) cannot use up at ``safety <= 0.95``.

    Args:
        bound: The bound (its ``state`` gives the current displacement).
        dt: The step in use.
        start: The first step of the run.
        every: Steps between two checks of the wave speed.
        growth: Relative growth of the wave speed that triggers a re-bound.
    """

    def __init__(
        self, bound: TimeStepBound, dt: float, start: int, every: int = 10, growth: float = 0.05
    ) -> None:
        if not (isinstance(every, int) and every >= 1):
            raise ValueError(f"every={every!r} must be an integer >= 1 (steps between checks)")
        self.bound, self.dt, self.start = bound, float(dt), int(start)
        self.every, self.growth = every, float(growth)

    def __call__(self, n: int) -> bool:
        # a bulk viscosity's damper at every step (cheap: the points' factors of their last
        # update; no new bound)
        if getattr(self.bound.system, "viscous", False):
            if self.bound.stable() < self.dt * (1.0 - 1e-12):
                return True
        # every ``every`` steps since the last check, whichever run it was in (a model run in
        # short pieces, ``run(t)`` in a loop, was never checked when its pieces were shorter)
        if n - self.bound.checked_at < self.every:
            return False
        self.bound.checked_at = n
        speed = self.bound.system.wave_speed(self.bound.state())
        if speed <= (1.0 + self.growth) * self.bound.critical()["wave_speed"]:
            return False
        self.bound.invalidate()
        return self.bound.stable() < self.dt * (1.0 - 1e-12)
