"""Distributed PETSc BAIJ matrices assembled directly from scipy contributions.

:func:`~dolfinx_meshfree.statics.petsc.create_aij` builds a scalar AIJ matrix, and explicit
dynamics then copies it into ``gdim x gdim`` blocks
(:func:`~dolfinx_meshfree.dynamics.linalg.blocked`): for the ramp rod's particle stiffness
(4.5 M entries) the copy took 3x as long as the assembly. :func:`create_baij` stores the same
entries in blocks at once: the matrix equals ``blocked(create_aij(...), bs)`` entry for entry
(the same blocks, zeros inside a stored block kept, blocks of exact zeros left out), so its
products are the same to the last bit.
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from ..parallel import Layout

__all__ = ["create_baij"]


def _owned_rows(comm: MPI.Comm, A: sp.csr_matrix, row_layout: Layout) -> sp.csr_matrix:
    """The owned rows ``[start, end)`` of the sum over the ranks of ``A`` (collective): each rank
    sends its entries in rows owned elsewhere to their owner (global columns)."""
    rs, re = row_layout.start, row_layout.end
    if comm.size == 1:
        return A
    ends = np.array(comm.allgather(re), dtype=np.int64)
    coo = A.tocoo()
    owner = np.searchsorted(ends, coo.row, side="right")
    order = np.argsort(owner, kind="stable")
    cuts = np.searchsorted(owner[order], np.arange(comm.size + 1))
    send = [
        (coo.row[order[a:b]], coo.col[order[a:b]], coo.data[order[a:b]])
        for a, b in itertools.pairwise(cuts)
    ]
    got = comm.alltoall(send)
    rows = np.concatenate([g[0] for g in got]).astype(np.int64) - rs
    cols = np.concatenate([g[1] for g in got]).astype(np.int64)
    vals = np.concatenate([g[2] for g in got])
    return sp.csr_matrix((vals, (rows, cols)), shape=(re - rs, A.shape[1]))


def create_baij(
    comm: MPI.Comm | PETSc.Comm,
    local: sp.spmatrix,
    row_layout: Layout,
    col_layout: Layout,
    bs: int,
    assembled: sp.spmatrix | None = None,
) -> PETSc.Mat:
    """Distributed BAIJ matrix (``bs x bs`` blocks) from this rank's contributions in global
    numbering (collective): the entries of
    :func:`~dolfinx_meshfree.statics.petsc.create_aij` with the same arguments, stored in blocks
    as :func:`~dolfinx_meshfree.dynamics.linalg.blocked` stores them.

    Args:
        local: (global rows x global cols) sparse matrix of this rank's contributions, rows and
            columns numbered ``bs * node + component``; rows that other ranks own are sent to
            them and added there.
        bs: The block size (the geometric dimension); the layouts' ranges must start and end on
            whole blocks on every rank.
        assembled: An already assembled matrix's owned rows (global shape, other rows empty),
            added after the ranks' contributions are summed: ``A + create_aij(local)`` as
            PETSc's ``A.axpy`` sums it (e.g. DOLFINx's FE stiffness plus the ramps' interface
            cells).

    Raises:
        ValueError: (on every rank) a layout's range of some rank is not made of whole blocks.
    """
    mpi = comm.tompi4py() if isinstance(comm, PETSc.Comm) else comm
    ranges = (row_layout.start, row_layout.size_local, col_layout.start, col_layout.size_local)
    whole = all(v % bs == 0 for v in (*ranges, row_layout.size_global, col_layout.size_global))
    if not mpi.allreduce(whole, op=MPI.LAND):
        raise ValueError(
            f"create_baij: block size bs={bs} does not divide the row or column ranges of every "
            f"rank (this rank: rows from {row_layout.start}, {row_layout.size_local} of them; "
            f"columns from {col_layout.start}, {col_layout.size_local}); use create_aij"
        )
    A = local.tocsr()
    A.sum_duplicates()
    own = _owned_rows(mpi, A, row_layout)
    own.sum_duplicates()
    if assembled is not None:  # (serial: own is every row, the owned ones)
        own = assembled.tocsr()[row_layout.start : row_layout.end] + own
    own.eliminate_zeros()
    blocks = own.tobsr(blocksize=(bs, bs))
    blocks.sum_duplicates()  # sorted block columns, one entry per block
    nb = row_layout.size_local // bs
    c0, c1 = col_layout.start // bs, col_layout.end // bs
    brow = np.repeat(np.arange(nb), np.diff(blocks.indptr))
    diag = (blocks.indices >= c0) & (blocks.indices < c1)
    d_nnz = np.bincount(brow[diag], minlength=nb).astype(PETSc.IntType)
    o_nnz = np.bincount(brow[~diag], minlength=nb).astype(PETSc.IntType)
    M = PETSc.Mat().create(comm=comm)
    M.setSizes((row_layout.petsc_sizes(), col_layout.petsc_sizes()), bsize=bs)
    M.setType(PETSc.Mat.Type.BAIJ)
    # a rank without rows gives scalar counts: petsc4py 3.18 mishandles empty arrays for BAIJ
    M.setPreallocationNNZ((d_nnz, o_nnz) if nb else (0, 0))
    if nb:
        M.setValuesBlockedCSR(
            blocks.indptr.astype(PETSc.IntType),
            blocks.indices.astype(PETSc.IntType),
            blocks.data.ravel(),
        )
    M.assemble()
    return M
