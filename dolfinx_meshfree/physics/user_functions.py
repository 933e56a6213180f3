"""Values of the functions a user passes (displacements, tractions, body forces) at points,
checked: the one place that evaluates a user's vector function and names what is wrong."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["vector_values"]


def vector_values(
    fn: Callable[..., np.ndarray], args: tuple, m: int, name: str, gdim: int = 2
) -> np.ndarray:
    """``fn(*args)`` as a float array of shape ``(m, gdim)``; a ``ValueError`` naming ``name``,
    the expected and the returned shape otherwise."""
    v = np.asarray(fn(*args), dtype=float)
    if v.shape != (m, gdim):
        raise ValueError(f"{name} must return an array of shape ({m}, {gdim}), got {v.shape}")
    return v
