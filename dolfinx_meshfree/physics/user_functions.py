"""What a user passes to the ``add_*`` calls, checked: the values of the functions
(displacements, tractions, body forces) at points, and the facets they act on. The one place
that evaluates a user's vector function or takes a user's facets and names what is wrong."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..parallel import owned_indices, raise_on_all_ranks

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
    """``facets`` as this rank's owned facet indices (int32), refused on every rank
    (collective), naming ``name``, when they are not owned facets of ``msh`` here, or when no
    rank holds one: a condition or a load on no facet acts nowhere, silently (a marker that
    selects nothing, e.g. ``np.isclose(r, R)`` tested at the midpoints of a curved boundary's
    straight facets)."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    n_own = msh.topology.index_map(tdim - 1).size_local
    fix = "pass owned exterior facets of the model's mesh, as mf.boundary_facets returns them"

    def check() -> np.ndarray:
        return owned_indices(facets, name, "facet", n_own, fix).astype(np.int32)

    out = raise_on_all_ranks(msh.comm, check)
    if msh.comm.allreduce(int(out.size)) == 0:
        raise ValueError(
            f"{name} holds no facet on any rank, so it would act nowhere: the marker selected "
            "no boundary facet. mf.boundary_facets(msh, marker) keeps a facet when the marker "
            "accepts all its vertices or its midpoint; on a curved boundary give the marker a "
            "tolerance of the mesh's sagitta (np.isclose(r, R, atol=...)); pass the facets of "
            "the boundary you mean"
        )
    return out
