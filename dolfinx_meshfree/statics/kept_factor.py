"""A direct solver kept between solves of systems with one sparsity pattern (Newton's tangents).

A MUMPS factorisation has two phases: the analysis (an ordering of the unknowns that keeps the
factors sparse and the symbolic factorisation that sizes them), which depends only on where the
matrix's nonzeros are, and the numerical factorisation, which depends on their values. Newton's
tangents keep their pattern from one iteration to the next (and from one load step to the next,
until a crack grows or a patch changes), so the analysis of the first serves them all. On
Petersson's notched beam (``demos/concrete_beam.py``, h = 10 mm, 115 factorisations) the
analyses were 53 % of MUMPS's time with the lagrange coupling (2.45 s of 4.62 s) and 31 % with
pure EFG (4.29 s of 13.86 s).

:class:`KeptFactorisation` holds the private KSP of the last solve and its operator. The next
system is compared with it entry by entry of the sparsity pattern (stored zeros included, on
every rank: a collective decision); where it matches, its values are copied into the kept
operator (``MatCopy`` with ``SAME_NONZERO_PATTERN``, which leaves PETSc's nonzero state alone),
so that PETSc's ``PCSetUp`` calls only MUMPS's numerical factorisation (job 2) on the kept
analysis. Anything else (another pattern, another factorisation or solver, the determinant asked
for or not) starts afresh.

The kept analysis is the one of the first tangent: its ordering is exactly as good for the next
ones (it depends only on the pattern), but the matching and scaling MUMPS computes from the
values at analysis (ICNTL(6), ICNTL(8)) are the first tangent's, and the pivots are chosen at
the numerical factorisation (threshold partial pivoting, delayed pivots in the workspace of
ICNTL(14)). A numerical factorisation that fails on the kept analysis is redone afresh before any
failure is reported (:func:`~dolfinx_meshfree.statics.petsc.solve_lu`).

A system whose values are also the kept operator's, bit for bit on every rank, is not factorised
at all: the kept factors solve it (a load sweep of a linear model: the stiffness is assembled
again, the same, and only the loads change); only the triangular solves are done. The solution
is a fresh factorisation's: to the bit serially, to round-off on several ranks, where two runs
of one model differ at round-off already (2.2e-16 measured: a bridging model on 2 ranks).
"""

from __future__ import annotations

from collections.abc import Hashable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

__all__ = ["KeptFactorisation", "check_kept"]


def check_kept(kept: object) -> None:
    """Raise a ``TypeError`` unless ``kept`` is a :class:`KeptFactorisation` or ``None`` (the
    ``kept=`` of the problems' ``solve``; local, the same on every rank)."""
    if kept is not None and not isinstance(kept, KeptFactorisation):
        raise TypeError(
            f"kept={kept!r:.60} must be an mf.KeptFactorisation or None: kept = "
            "mf.KeptFactorisation(), then problem.solve(kept=kept) at each load and "
            "kept.destroy() after the last"
        )


class KeptFactorisation:
    """The last direct solve's KSP, kept for the next system of the same sparsity pattern.

    Owned by whoever solves a sequence of systems (a nonlinear problem: one per model, freed
    with it by :meth:`destroy`; a user's load sweep of a linear model:
    ``problem.solve(kept=kept)`` at each load, then ``kept.destroy()``) and passed to
    :func:`~dolfinx_meshfree.statics.petsc.solve_lu` as ``kept=``. :attr:`reused` and
    :attr:`analysed` count the factorisations done on a kept analysis and afresh, and
    :attr:`repeated` the systems solved by the kept factors (the kept operator's values: no
    factorisation). It holds the last system's factors until :meth:`destroy`.

    Example::

        kept = mf.KeptFactorisation()
        for value in (1.0, 2.0, 3.0):  # a load sweep: one factorisation
            load.value = value
            u = problem.solve(kept=kept).displacement(points)
        kept.destroy()
    """

    def __init__(self) -> None:
        self._ksp: PETSc.KSP | None = None
        self._operator: PETSc.Mat | None = None
        self._key: Hashable = None
        #: Factorisations on a kept analysis.
        self.reused = 0
        #: Factorisations with their own analysis.
        self.analysed = 0
        #: Systems solved by the kept factors, without a factorisation (the same values).
        self.repeated = 0
        #: What the last :meth:`take` kept: ``"factors"`` (the same values: no factorisation),
        #: ``"analysis"`` (the same pattern: a numerical factorisation) or ``None`` (nothing).
        self.last: str | None = None

    def take(self, A: PETSc.Mat, key: Hashable) -> PETSc.KSP | None:
        """The kept KSP, its operator now holding ``A``'s values, where ``A`` has the kept
        operator's sparsity pattern on every rank and ``key`` (the solver, factorisation and
        options) is the kept one's; else ``None`` (and nothing is kept any more). Where the
        values are the kept operator's too (every rank), the KSP keeps its factors: its
        ``setUp`` does nothing and only the solves are done (:attr:`last` says which).
        Collective."""
        match = same = self._ksp is not None and key == self._key
        if match:
            ai, aj, av = A.getValuesCSR()
            kept_i, kept_j, kept_v = self._operator.getValuesCSR()
            match = (
                A.getType() == self._operator.getType()
                and A.getSizes() == self._operator.getSizes()
                and np.array_equal(ai, kept_i)
                and np.array_equal(aj, kept_j)
            )
            same = match and np.array_equal(av, kept_v)
        flags = np.array([match, same], dtype=np.int32)
        A.getComm().tompi4py().Allreduce(MPI.IN_PLACE, flags, op=MPI.MIN)
        if not flags[0]:
            self.clear()
            return None
        if flags[1]:  # the kept factors are this system's: no setOperators, no factorisation
            self.repeated += 1
            self.last = "factors"
            return self._ksp
        A.copy(self._operator, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self._ksp.setOperators(self._operator)  # a new matrix stage: PCSetUp refactorises
        self.reused += 1
        self.last = "analysis"
        return self._ksp

    def keep(self, ksp: PETSc.KSP, key: Hashable) -> None:
        """Keep ``ksp`` (set up on its operator: a new analysis) for the next :meth:`take`."""
        if ksp is not self._ksp:
            self.clear()
            self._ksp, self._key = ksp, key
            self._operator = ksp.getOperators()[0]  # a handle of its own: the caller's may go
            self.analysed += 1

    def clear(self) -> None:
        """Free the kept KSP (its factorisation) and operator (nothing is kept: :attr:`last`
        ``None``); the counts stay."""
        if self._ksp is not None:
            pc = self._ksp.getPC()
            pc.getFactorMatrix().destroy()
            pc.destroy()
            self._ksp.destroy()
            self._operator.destroy()
        self._ksp = self._operator = self._key = self.last = None

    def destroy(self) -> None:
        """:meth:`clear`: the end of the sequence of solves."""
        self.clear()
