"""Compiled assembly of ``K = sum_q w_q G_test(x_q)^T A_q G_trial(x_q)`` from shape tables.

The stiffness of Belytschko et al. 1995, eq. (4.3) (``A`` the material law, constant) and the
consistent tangent of Rabczuk, Xiao & Sauer 2006, eq. 34 (``A = dP/dF`` per point) have one
form: with gradient tables ``g_a(I, q) = dN_I/dx_a (x_q)``,

.. math::
    K_{dI+i,\\,dJ+k} = \\sum_q w_q \\sum_{a,b} \\hat g_a(I, q)\\, A_q[d i + a,\\, d k + b]\\,
    g_b(J, q),

``A_q`` a (d^2 x d^2) matrix in the row-major order of the displacement gradient
``du_i/dx_a -> d i + a``. The scipy path (:func:`~dolfinx_meshfree.physics.operators
.stiffness_matrix`) forms it as a product of sparse matrices, whose temporaries (the expanded
strain operators, the unsorted products) dominate memory; here it is one pass from the tables
to the CSR, block row by block row:

1. the node-to-point transpose of the table pattern, by a counting sort (no comparison sort);
2. per block row ``I`` (in the output numbering ``node_map``), the union of the supports of the
   points in ``I``'s support, marked in a stamp array and sorted (one small sort per row): the
   sparsity pattern, computed once;
3. per block row, the sums over its points straight into the row's (d x d) blocks, written
   as a scalar CSR with interleaved dofs ``d I + i``.

The only temporaries are the transpose (two integers per table entry) and one row's pattern,
so peak memory is the tables plus the output (a few times the assembled matrix), and each
entry of the output is written by one row's loop (no duplicates, no scatter-add conflicts).
"""

from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp

from ..approx import jit as _jit
from ..approx.jit import jit

__all__ = [
    "BACKENDS",
    "DEFAULT_BACKEND",
    "assemble_blocks",
    "gradient_form",
    "resolve_backend",
    "transpose_pattern",
]

BACKENDS = ("numba", "scipy")
#: ``"numba"`` when numba is importable, else ``"scipy"`` (the sparse products, the reference the
#: tests compare with); ``DOLFINX_MESHFREE_ASSEMBLY_BACKEND`` (``numba`` or ``scipy``) overrides it.
DEFAULT_BACKEND = os.environ.get("DOLFINX_MESHFREE_ASSEMBLY_BACKEND") or (
    "numba" if _jit.AVAILABLE else "scipy"
)


def resolve_backend(backend: str | None) -> str:
    """The backend to use: ``backend`` or :data:`DEFAULT_BACKEND`, checked (local)."""
    backend = DEFAULT_BACKEND if backend is None else backend
    if backend not in BACKENDS:
        raise ValueError(
            f"backend={backend!r} (argument or DOLFINX_MESHFREE_ASSEMBLY_BACKEND) is not known; "
            f"use one of {BACKENDS}"
        )
    if backend == "numba" and not _jit.AVAILABLE:
        raise ValueError(
            "backend='numba' needs numba, which is not importable: install numba "
            "(python3-numba or pip install numba) or use backend='scipy'"
        )
    return backend


@jit
def transpose_pattern(indptr, indices, n):  # pragma: no cover - compiled
    """Points of each node's support: CSR ``(tptr, tpoint, tpos)`` over the ``n`` nodes, with
    the point ``q`` and the table position ``p`` of every entry, points in increasing order
    (a counting sort of the table's column indices)."""
    nnz = indices.shape[0]
    tptr = np.zeros(n + 1, np.int64)
    for p in range(nnz):
        tptr[indices[p] + 1] += 1
    for i in range(n):
        tptr[i + 1] += tptr[i]
    fill = tptr[:-1].copy()
    tpoint = np.empty(nnz, np.int64)
    tpos = np.empty(nnz, np.int64)
    for q in range(indptr.shape[0] - 1):
        for p in range(indptr[q], indptr[q + 1]):
            c = indices[p]
            k = fill[c]
            tpoint[k] = q
            tpos[k] = p
            fill[c] = k + 1
    return tptr, tpoint, tpos


@jit
def _block_pattern(indptr, indices, tptr, tpoint, node_map, inverse):  # pragma: no cover
    """Block rows in the output numbering: ``bptr`` and the sorted output node numbers of the
    columns, the union over the points of each row node's support."""
    n = tptr.shape[0] - 1
    n_out = inverse.shape[0]
    stamp = np.full(n, -1, np.int64)
    bptr = np.zeros(n_out + 1, np.int64)
    cap = max(16, 4 * indices.shape[0])
    bcols = np.empty(cap, np.int64)
    row = np.empty(n, np.int64)
    for r in range(n_out):
        node = inverse[r]
        c = 0
        if node >= 0:
            for t in range(tptr[node], tptr[node + 1]):
                q = tpoint[t]
                for p in range(indptr[q], indptr[q + 1]):
                    j = indices[p]
                    if stamp[j] != r:
                        stamp[j] = r
                        row[c] = node_map[j]
                        c += 1
        start = bptr[r]
        if start + c > cap:
            cap = max(2 * cap, start + c)
            grown = np.empty(cap, np.int64)
            grown[:start] = bcols[:start]
            bcols = grown
        bcols[start : start + c] = np.sort(row[:c])
        bptr[r + 1] = start + c
    return bptr, bcols[: bptr[n_out]].copy()


@jit
def _fill_blocks(
    indptr,
    indices,
    test,
    trial,
    weights,
    tangents,
    tptr,
    tpoint,
    tpos,
    node_map,
    inverse,
    bptr,
    bcols,
    out_indptr,
    out_indices,
    out_data,
):  # pragma: no cover - compiled
    """The sums of the module docstring, block row by block row, into the scalar CSR arrays."""
    d = test.shape[0]
    n = tptr.shape[0] - 1
    n_out = inverse.shape[0]
    per_point = tangents.shape[0] > 1
    where = np.full(n_out, -1, np.int64)
    W = np.empty((d, d, d))
    for r in range(n_out):
        nb = bptr[r + 1] - bptr[r]
        base = d * d * bptr[r]
        for i in range(d):
            out_indptr[d * r + i] = base + i * nb * d
            for kb in range(nb):
                for k in range(d):
                    out_indices[base + i * nb * d + kb * d + k] = d * bcols[bptr[r] + kb] + k
        node = inverse[r]
        if node < 0:
            continue
        for kb in range(nb):
            where[bcols[bptr[r] + kb]] = kb
        for t in range(tptr[node], tptr[node + 1]):
            q = tpoint[t]
            p0 = tpos[t]
            A = tangents[q if per_point else 0]
            w = weights[q]
            # W[i, k, b] = w sum_a g^_a(I) A[d i + a, d k + b]: once per (row, point)
            for i in range(d):
                for k in range(d):
                    for b in range(d):
                        s = 0.0
                        for a in range(d):
                            s += test[a, p0] * A[d * i + a, d * k + b]
                        W[i, k, b] = w * s
            for p in range(indptr[q], indptr[q + 1]):
                kb = where[node_map[indices[p]]]
                for i in range(d):
                    at = base + i * nb * d + kb * d
                    for k in range(d):
                        s = 0.0
                        for b in range(d):
                            s += W[i, k, b] * trial[b, p]
                        out_data[at + k] += s
    out_indptr[d * n_out] = d * d * bptr[n_out]
    return n


def assemble_blocks(
    indptr: np.ndarray,
    indices: np.ndarray,
    test: np.ndarray,
    trial: np.ndarray,
    weights: np.ndarray,
    tangents: np.ndarray,
    num_nodes: int,
    node_map: np.ndarray | None = None,
    num_out: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR arrays of ``K`` (module docstring) from tables sharing one pattern.

    Args:
        indptr, indices: the tables' CSR pattern (m + 1,), (nnz,) over ``num_nodes`` columns.
        test, trial: (d, nnz) test and trial gradient values on that pattern.
        weights: (m,) quadrature weights.
        tangents: (1, d^2, d^2) (the same at every point) or (m, d^2, d^2), index ``d i + a``.
        node_map: output node number of each node (injective into ``range(num_out)``; default
            the identity): rows and columns ``d node_map[I] + i``.
        num_out: number of output nodes (default ``num_nodes``).

    Returns:
        ``(indptr, indices, data)`` of the (d num_out x d num_out) CSR, sorted indices, no
        duplicates (structural zeros of the pattern kept).
    """
    d = test.shape[0]
    n_out = num_nodes if num_out is None else num_out
    if node_map is None:
        node_map = np.arange(num_nodes, dtype=np.int64)
    node_map = np.ascontiguousarray(node_map, dtype=np.int64)
    inverse = np.full(n_out, -1, np.int64)
    inverse[node_map] = np.arange(num_nodes)
    indptr = np.ascontiguousarray(indptr, dtype=np.int64)
    indices = np.ascontiguousarray(indices, dtype=np.int64)
    tptr, tpoint, tpos = transpose_pattern(indptr, indices, num_nodes)
    bptr, bcols = _block_pattern(indptr, indices, tptr, tpoint, node_map, inverse)
    nnz = d * d * int(bptr[-1])
    itype = np.int32 if max(nnz, d * n_out) < np.iinfo(np.int32).max else np.int64
    out_indptr = np.empty(d * n_out + 1, itype)
    out_indices = np.empty(nnz, itype)
    out_data = np.zeros(nnz)
    _fill_blocks(
        indptr, indices, np.ascontiguousarray(test, dtype=float),
        np.ascontiguousarray(trial, dtype=float), np.ascontiguousarray(weights, dtype=float),
        np.ascontiguousarray(tangents, dtype=float), tptr, tpoint, tpos, node_map, inverse,
        bptr, bcols, out_indptr, out_indices, out_data,
    )  # fmt: skip
    return out_indptr, out_indices, out_data


@jit
def _gather(uptr, uidx, tptr, tidx, tdata, n, out):  # pragma: no cover - compiled
    """Values of a CSR table (tptr, tidx, tdata) on the wider pattern (uptr, uidx), in place."""
    where = np.full(n, -1, np.int64)
    for q in range(uptr.shape[0] - 1):
        for p in range(uptr[q], uptr[q + 1]):
            where[uidx[p]] = p
        for p in range(tptr[q], tptr[q + 1]):
            out[where[tidx[p]]] += tdata[p]


def _common_pattern(
    tables: list[sp.csr_matrix],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One CSR pattern for all ``tables`` and their values on it (len(tables), nnz): theirs
    when they share one (the MLS tables), else the union (e.g. VCI sums that dropped zeros)."""
    first = tables[0]
    same = all(
        t is first
        or (np.array_equal(t.indptr, first.indptr) and np.array_equal(t.indices, first.indices))
        for t in tables
    )
    if same:
        return first.indptr, first.indices, np.stack([t.data for t in tables])
    union = sp.csr_matrix(first.shape)
    for t in tables:
        union = union + sp.csr_matrix((np.ones(t.nnz), t.indices, t.indptr), shape=t.shape)
    union.sort_indices()
    uptr = union.indptr.astype(np.int64)
    uidx = union.indices.astype(np.int64)
    values = np.zeros((len(tables), union.nnz))
    for k, t in enumerate(tables):
        _gather(uptr, uidx, t.indptr.astype(np.int64), t.indices.astype(np.int64),
                np.asarray(t.data, dtype=float), first.shape[1], values[k])  # fmt: skip
    return uptr, uidx, values


def gradient_form(
    test_gradients: list[sp.spmatrix],
    trial_gradients: list[sp.spmatrix],
    weights: np.ndarray,
    tangents: np.ndarray,
    node_map: np.ndarray | None = None,
    num_out: int | None = None,
) -> sp.csr_matrix:
    """``K = sum_q w_q G_test^T A_q G_trial`` (module docstring) as a scipy CSR, compiled.

    Args:
        test_gradients, trial_gradients: ``d`` tables (m x n) each.
        weights: (m,). tangents: (d^2, d^2), or (m, d^2, d^2) per point.
        node_map, num_out: output node numbering (see :func:`assemble_blocks`).

    Returns:
        (d num_out x d num_out) CSR with sorted indices and no duplicates.
    """
    d = len(trial_gradients)
    n = trial_gradients[0].shape[1]
    tables = [sp.csr_matrix(t) for t in (*test_gradients, *trial_gradients)]
    indptr, indices, values = _common_pattern(tables)
    A = np.asarray(tangents, dtype=float).reshape(-1, d * d, d * d)
    n_out = n if num_out is None else num_out
    indptr, indices, data = assemble_blocks(
        indptr, indices, values[:d], values[d:], weights, A, n, node_map, n_out
    )
    K = sp.csr_matrix((data, indices, indptr), shape=(d * n_out, d * n_out))
    K.has_sorted_indices = True
    return K
