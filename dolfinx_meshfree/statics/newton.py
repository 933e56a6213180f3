"""Newton's method with a backtracking line search on a PETSc block (nest) system.

The nonlinear static problems (:mod:`~dolfinx_meshfree.statics.nonlinear`) are block systems with
the
fields of the linear ones (FE displacements, particle coefficients, Lagrange multipliers). At a
state ``x`` (one PETSc vector per field) they give the residual ``R(x)`` and the Jacobian blocks
``J(x)``; Newton solves ``J(x) dx = -R(x)`` with the same block solvers as the linear problems
(:class:`~dolfinx_meshfree.statics.petsc.BlockSystem`, MUMPS by default or any ``petsc_options``)
and
updates ``x <- x + alpha dx``. By default (``line_search="guard"``) the full Newton step is
taken unless it would invert the material at a point (``det F <= 0``), take a law with state
past what its return map solves (an ``ArithmeticError``: J2's plane-stress return at a strain
far beyond a limit load), or make the residual non-finite or grow by more than ``growth`` times,
in which case ``alpha`` halves: the residual norm is a poor merit function for finite
elasticity (a good full step often raises it for an iteration: on a bent beam, an Armijo test
on ``|R|`` took 13-14 damped iterations per load step where full steps took 4-5).
``line_search="armijo"`` halves until ``|R|`` falls by ``1 - 1e-4 alpha``; ``"none"`` always
takes the full step.

Convergence: ``|R(x)| <= max(atol, rtol |R(x_0)|)`` with ``x_0`` the state at the start of the
load step, or (PETSc SNES's step test) a step ``|alpha dx| <= stol |x|`` once ``|R|`` has fallen
below ``sqrt(rtol) |R(x_0)|``: a stiff body under a small load reaches the round-off floor of its
internal forces (``|f_int| ~ E``) above ``rtol |R(x_0)|`` (a slender cantilever: 1.6e-10 against
a tolerance of 1.0e-10, after a quadratic 5e-5 -> 1.6e-10). A problem that does not converge in
``max_it`` iterations raises
:class:`NewtonError` with the residual history: the last iterate is never returned as a solution.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from petsc4py import PETSc

from ..physics.constitutive import DeformationError
from .kept_factor import KeptFactorisation
from .petsc import BlockSystem, SolverOptions

__all__ = [
    "LINE_SEARCHES",
    "NewtonError",
    "NewtonOptions",
    "NewtonResult",
    "NonlinearBlockProblem",
    "newton",
]


#: The step-length rules of :class:`NewtonOptions`.
LINE_SEARCHES = ("guard", "armijo", "none")


class NewtonError(RuntimeError):
    """Newton did not converge; :attr:`history` holds the residual norms per iteration."""

    def __init__(self, message: str, history: Sequence[float]):
        super().__init__(message)
        self.history = list(history)


@dataclass(frozen=True)
class NewtonOptions:
    """Options of :func:`newton`.

    Attributes:
        max_it: Iterations per load step (>= 1).
        rtol, atol: Convergence when ``|R| <= max(atol, rtol |R_0|)``.
        stol: ... or when a step is below ``stol |x|`` (and ``|R| <= sqrt(rtol) |R_0|``).
        line_search: ``"guard"`` (default), ``"armijo"`` or ``"none"``; see the module notes.
        growth: The residual growth that ``"guard"`` rejects.
        max_halvings: Most halvings of the step length per iteration.
        report: Print the residual norm of every iteration on rank 0.
    """

    max_it: int = 25
    rtol: float = 1e-9
    atol: float = 1e-12
    stol: float = 1e-10
    line_search: str = "guard"
    growth: float = 1e3
    max_halvings: int = 10
    report: bool = False

    def __post_init__(self) -> None:
        if not (isinstance(self.max_it, int) and self.max_it >= 1):
            raise ValueError(f"max_it={self.max_it!r} must be an integer >= 1")
        if not (0.0 <= self.rtol < 1.0):
            raise ValueError(f"rtol={self.rtol!r} must lie in [0, 1)")
        if not self.atol >= 0.0:
            raise ValueError(f"atol={self.atol!r} must be >= 0")
        if self.line_search not in LINE_SEARCHES:
            raise ValueError(
                f"line_search={self.line_search!r} is not known; use one of {list(LINE_SEARCHES)}"
            )
        if self.rtol == 0.0 and self.atol == 0.0:
            raise ValueError("rtol and atol are both 0: Newton could never converge")


@dataclass
class NewtonResult:
    """What one Newton solve did.

    Attributes:
        iterations: Newton iterations (linear solves) taken.
        converged: Always ``True`` (a solve that does not converge raises :class:`NewtonError`).
        residual_norms: ``|R|`` before the first iteration and after each one.
        step_lengths: The line search's ``alpha`` of each iteration.
        seconds: Wall time.
    """

    iterations: int
    converged: bool
    residual_norms: list[float] = field(default_factory=list)
    step_lengths: list[float] = field(default_factory=list)
    seconds: float = 0.0


class NonlinearBlockProblem(Protocol):
    """A nonlinear block system at a state: one PETSc vector per field."""

    names: list[str]
    num_primal: int

    def residual(self, x: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        """``R(x)`` per field (new vectors; the caller destroys them). Collective."""
        ...

    def jacobian(self, x: Sequence[PETSc.Vec]) -> list[list[PETSc.Mat | None]]:
        """The Jacobian blocks at ``x`` (new or reused matrices, owned by the problem)."""
        ...


def _kept(problem: NonlinearBlockProblem) -> KeptFactorisation | None:
    """The problem's kept direct-solver analysis (``kept_factorisation``, owned and freed by the
    problem), or ``None``: each Newton iteration analyses its tangent afresh."""
    return getattr(problem, "kept_factorisation", None)


def _norm(vecs: Sequence[PETSc.Vec]) -> float:
    return float(np.sqrt(sum(v.norm() ** 2 for v in vecs)))


def _destroy(objects: Sequence) -> None:
    for obj in objects:
        obj.destroy()


def _axpy(x: Sequence[PETSc.Vec], alpha: float, dx: Sequence[np.ndarray]) -> list[PETSc.Vec]:
    out = []
    for xi, di in zip(x, dx, strict=True):
        y = xi.copy()
        y.array[:] += alpha * di
        out.append(y)
    return out


def newton(
    problem: NonlinearBlockProblem,
    x: list[PETSc.Vec],
    options: NewtonOptions | None = None,
    solver: str | SolverOptions = "mumps",
    on_iteration: Callable[[int, float], None] | None = None,
) -> NewtonResult:
    """Solve ``R(x) = 0`` from ``x`` (updated in place). Collective.

    Raises:
        NewtonError: no convergence in ``options.max_it`` iterations, or no step length that
            keeps every ``det F > 0`` (the history of residual norms is attached).
    """
    opts = options or NewtonOptions()
    t0 = time.perf_counter()
    comm = x[0].getComm().tompi4py()
    r = problem.residual(x)
    norm0 = _norm(r)
    history, alphas = [norm0], []
    tol = max(opts.atol, opts.rtol * norm0)
    it = 0
    small_step = False
    while history[-1] > tol and not small_step:
        if it == opts.max_it:
            _destroy(r)
            raise NewtonError(
                f"Newton did not converge in max_it={opts.max_it} iterations: residual norms "
                f"{', '.join(f'{h:.3e}' for h in history)} (tolerance {tol:.3e}); take smaller "
                "load steps (load_steps=) or raise max_it",
                history,
            )
        blocks = problem.jacobian(x)
        rhs = []
        for v in r:
            v.scale(-1.0)
            rhs.append(v)
        system = BlockSystem(blocks, rhs, num_primal=problem.num_primal, names=problem.names)
        dx = system.solve(solver, kept=_kept(problem))
        system.destroy()
        alpha, accepted, best = 1.0, None, None
        for _ in range(opts.max_halvings + 1):
            trial = _axpy(x, alpha, dx)
            try:
                r_try = problem.residual(trial)
            except (DeformationError, ArithmeticError):  # inverts a point, or past a return map
                _destroy(trial)
                alpha *= 0.5
                continue
            n_try = _norm(r_try)
            if not np.isfinite(n_try):  # never carried on: shorten the step
                _destroy([*trial, *r_try])
                alpha *= 0.5
                continue
            if opts.line_search == "armijo":
                good = n_try <= (1.0 - 1e-4 * alpha) * history[-1]
            elif opts.line_search == "guard":
                good = n_try <= opts.growth * history[-1]
            else:
                good = True
            if good:
                accepted = (trial, r_try, n_try, alpha)
                break
            if best is None or n_try < best[2]:  # keep the best step in case none decreases
                if best is not None:
                    _destroy([*best[0], *best[1]])
                best = (trial, r_try, n_try, alpha)
            else:
                _destroy([*trial, *r_try])
            alpha *= 0.5
        if accepted is None:
            if best is None:
                _destroy(r)
                raise NewtonError(
                    f"iteration {it + 1}: every step length down to 2^-{opts.max_halvings} "
                    "inverts the material at a point (det F <= 0), fails a law's return map or "
                    "gives a non-finite residual; take smaller load steps (load_steps=)",
                    history,
                )
            accepted = best  # no sufficient decrease: the best step, and carry on
        elif best is not None:
            _destroy([*best[0], *best[1]])
        trial, r_new, n_new, alpha = accepted
        step = alpha * float(np.sqrt(sum(comm.allreduce(float(d @ d)) for d in dx)))
        size = float(np.sqrt(sum(t.norm() ** 2 for t in trial)))
        small_step = step <= opts.stol * size and n_new <= np.sqrt(opts.rtol) * norm0
        for xi, ti in zip(x, trial, strict=True):
            ti.copy(xi)
        _destroy([*trial, *r])
        r = r_new
        it += 1
        history.append(n_new)
        alphas.append(alpha)
        if opts.report and comm.rank == 0:
            print(f"  Newton iteration {it}: |R| = {n_new:.3e} (alpha {alpha:g})", flush=True)
        if on_iteration is not None:
            on_iteration(it, n_new)
    _destroy(r)
    return NewtonResult(it, True, history, alphas, time.perf_counter() - t0)
