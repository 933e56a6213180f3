"""Values of the functions a user passes (displacements, tractions, body forces) at points,
checked: the one place that evaluates a user's vector function and names what is wrong."""

from __future__ import annotations

import inspect
from collections.abc import Callable

import numpy as np

__all__ = ["check_arguments", "vector_values"]

#: How each arity is called and what its arguments are (the messages of :func:`check_arguments`).
_CALLS = {
    1: ("x", "x: points (m, gdim)"),
    2: ("x, n", "x: points (m, gdim), n: outward unit normals (m, gdim)"),
}


def check_arguments(fn: object, nargs: int, name: str) -> None:
    """Refuse ``fn`` unless it is a callable that takes ``nargs`` positional arguments (1: the
    points ``x``; 2: the points and the outward normals ``n``), naming ``name``, the signature
    it has and the one it needs. Not collective: the same answer on every rank. A callable
    whose signature Python cannot read (a builtin) passes."""
    call, doc = _CALLS.get(nargs, (", ".join(f"a{k}" for k in range(nargs)), ""))
    if not callable(fn):
        raise TypeError(
            f"{name} must be a callable of ({call}) returning an (m, gdim) array ({doc}), got "
            f"{fn!r:.80}"
        )
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):  # a builtin or an extension type: called as it is
        return
    try:
        sig.bind(*range(nargs))
    except TypeError as e:
        label = getattr(fn, "__qualname__", type(fn).__name__)
        raise TypeError(
            f"{name} is called with ({call}) ({doc}), but {label}{sig} cannot take that "
            f"({e}): give a function of ({call}), e.g. lambda {call}: ..."
        ) from None


def vector_values(
    fn: Callable[..., np.ndarray], args: tuple, m: int, name: str, gdim: int = 2
) -> np.ndarray:
    """``fn(*args)`` as a float array of shape ``(m, gdim)``; a ``TypeError`` naming ``name``
    when ``fn`` cannot take ``args`` (:func:`check_arguments`), a ``ValueError`` naming the
    expected and the returned shape otherwise."""
    check_arguments(fn, len(args), name)
    v = np.asarray(fn(*args), dtype=float)
    if v.shape != (m, gdim):
        raise ValueError(f"{name} must return an array of shape ({m}, {gdim}), got {v.shape}")
    return v
