"""MPI helpers: agree on errors before collective calls, lay out distributed index ranges."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

import numpy as np

if TYPE_CHECKING:  # annotations only
    from mpi4py import MPI

__all__ = ["Layout", "owned_indices", "raise_on_all_ranks"]

T = TypeVar("T")


class _RemoteError(ValueError):
    """Raised on the ranks where a check passed because it failed on another rank."""


def owned_indices(value: object, name: str, kind: str, n_owned: int, fix: str) -> np.ndarray:
    """``value`` as a 1D integer array of this rank's owned ``kind`` indices (``0..n_owned -
    1``), else a ``ValueError`` naming ``name``, what it holds and ``fix`` (local: call it
    inside :func:`raise_on_all_ranks`)."""
    a = np.asarray(value)
    if a.ndim != 1 or (a.size and not np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"{name} must be a 1D array of {kind} indices, got {a!r:.80}: {fix}")
    if a.size and (a.min() < 0 or a.max() >= n_owned):
        raise ValueError(
            f"{name} names {kind}s that are not owned here (valid 0..{n_owned - 1}): {fix}"
        )
    return a


def raise_on_all_ranks(comm: MPI.Comm, fn: Callable[[], T]) -> T:
    """Run ``fn`` on every rank; if it raises on any rank, raise on every rank (collective).

    The rank that failed re-raises its own exception; the others raise one of the same class
    (when it takes a single message, else a ``ValueError``) with the failing rank's message, so
    that no rank goes on into a collective call that would hang and every rank can catch the
    same class (e.g. Newton's line search catches a ``DeformationError`` everywhere).
    """
    if comm.size == 1:  # nothing to tell another rank
        return fn()
    err: BaseException | None = None
    result = None
    try:
        result = fn()
    except (ValueError, TypeError, ArithmeticError) as e:  # user-input errors only
        err = e
    reports = comm.allgather(None if err is None else (type(err), f"{type(err).__name__}: {err}"))
    if err is not None:
        raise err
    failed = [(r, rep) for r, rep in enumerate(reports) if rep is not None]
    if failed:
        r, (cls, msg) = failed[0]
        try:
            remote = cls(f"on rank {r}: {msg}")
        except Exception:  # a class that needs more than a message
            remote = _RemoteError(f"on rank {r}: {msg}")
        raise remote
    return result  # type: ignore[return-value]


@dataclass(frozen=True)
class Layout:
    """A contiguous distributed index range: this rank owns ``[start, start + size_local)``."""

    size_local: int
    size_global: int
    start: int

    @classmethod
    def from_local(cls, comm: MPI.Comm, size_local: int) -> Layout:
        """Layout with ``size_local`` entries on this rank, ranks in order (collective)."""
        sizes = np.array(comm.allgather(int(size_local)), dtype=np.int64)
        start = int(sizes[: comm.rank].sum())
        return cls(int(size_local), int(sizes.sum()), start)

    @property
    def end(self) -> int:
        return self.start + self.size_local

    def petsc_sizes(self) -> tuple[int, int]:
        return (self.size_local, self.size_global)
