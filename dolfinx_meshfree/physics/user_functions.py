"""What a user passes to the ``add_*`` calls, checked: the values of the functions
(displacements, tractions, body forces) at points, and the facets they act on. The one place
that evaluates a user's vector function or takes a user's facets and names what is wrong."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..parallel import raise_on_all_ranks

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = ["check_arguments", "check_facets", "vector_values"]

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


def check_facets(msh: dolfinx.mesh.Mesh, facets: npt.ArrayLike, name: str) -> np.ndarray:
    """``facets`` as local facet indices (int32), refused on every rank (collective) when they
    are not indices of this rank's facets, or when no rank holds one: a condition or a load
    on no facet acts nowhere, silently (a marker that selects nothing, e.g. ``np.isclose(r,
    R)`` tested at the midpoints of a curved boundary's straight facets). ``name`` names the
    call in the message."""
    arr = np.asarray(facets)
    n_local = msh.topology.index_map(msh.topology.dim - 1)
    n_local = n_local.size_local + n_local.num_ghosts

    def check() -> np.ndarray:
        if arr.size and (arr.ndim != 1 or not np.issubdtype(arr.dtype, np.integer)):
            raise TypeError(
                f"{name}: facets must be a 1D array of facet indices (as mf.boundary_facets or "
                f"dolfinx.mesh.locate_entities_boundary return them), got an array of dtype "
                f"{arr.dtype} and shape {arr.shape}"
            )
        out = arr.astype(np.int32).ravel()
        bad = out[(out < 0) | (out >= n_local)]
        if bad.size:
            raise ValueError(
                f"{name}: facets holds {bad.size} index(es) that are not facets of this rank's "
                f"mesh (e.g. {bad[:3].tolist()}; valid: 0..{n_local - 1}): pass facet indices "
                "of the model's mesh, as mf.boundary_facets(msh, marker) returns them"
            )
        return out

    out = raise_on_all_ranks(msh.comm, check)
    if msh.comm.allreduce(int(out.size)) == 0:
        raise ValueError(
            f"{name}: facets holds no facet on any rank, so it would act nowhere: the marker "
            "selected no boundary facet. mf.boundary_facets(msh, marker) keeps a facet when "
            "the marker accepts all its vertices or its midpoint; on a curved boundary give "
            "the marker a "
            "tolerance of the mesh's sagitta (np.isclose(r, R, atol=...)); pass the facets "
            "of the boundary you mean"
        )
    return out
