"""Small PETSc helpers of explicit dynamics: a private MUMPS factorisation, entrywise absolute
values, the row layout of a matrix, block (BAIJ) copies of node-interleaved matrices."""

from __future__ import annotations

import itertools

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..parallel import Layout

__all__ = ["BLOCK_FORMATS", "absolute", "add_weighted_gram", "blocked", "mumps_lu", "row_layout"]

#: Storage of the stiffness blocks of explicit dynamics (:func:`blocked`).
BLOCK_FORMATS = ("baij", "aij")

_prefix_counter = itertools.count()


def absolute(A: PETSc.Mat) -> PETSc.Mat:
    """``|A|`` (entrywise absolute values), a new AIJ matrix with the layout of ``A``."""
    ai, aj, av = A.getValuesCSR()
    B = PETSc.Mat().createAIJ(A.getSizes(), csr=(ai, aj, np.abs(av)), comm=A.getComm())
    B.assemble()
    return B


def add_weighted_gram(K: PETSc.Mat, B: PETSc.Mat, weights: np.ndarray) -> None:
    """``K += B^T diag(weights) B`` (collective; ``weights`` >= 0 per owned row of ``B``): a
    penalty's stiffness on the rows of ``B`` (crack contact, cohesive faces)."""
    scaled = B.copy()
    root = B.createVecLeft()
    root.array[:] = np.sqrt(weights)
    scaled.diagonalScale(L=root)
    gram = scaled.transposeMatMult(scaled)
    K.axpy(1.0, gram, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    for obj in (scaled, root, gram):
        obj.destroy()


def mumps_lu(A: PETSc.Mat) -> PETSc.KSP:
    """A private KSP (own options prefix) holding the MUMPS LU factorisation of ``A``; the
    caller destroys it."""
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(f"dolfinx_meshfree_dyn_{next(_prefix_counter)}_")
    ksp.setOperators(A)
    ksp.setType(PETSc.KSP.Type.PREONLY)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.LU)
    pc.setFactorSolverType("mumps")
    ksp.setUp()
    pc.destroy()  # our handle only (the KSP keeps its PC): see petsc.solve_lu
    return ksp


def row_layout(A: PETSc.Mat) -> Layout:
    """The :class:`~dolfinx_meshfree.parallel.Layout` of the rows of ``A``."""
    lo, hi = A.getOwnershipRange()
    return Layout(hi - lo, A.getSize()[0], lo)


def blocked(A: PETSc.Mat, bs: int, fmt: str = "baij") -> PETSc.Mat | None:
    """A copy of ``A`` stored in ``bs x bs`` blocks, or ``None`` where that is not possible.

    Explicit dynamics spends most of a step in ``K u`` (Belytschko et al. 1995, eq. 4.4); with
    node-interleaved dofs (``bs * node + component``) every ``bs x bs`` block of ``K`` is dense,
    and PETSc's BAIJ format multiplies it with one column index per block instead of per entry.
    The entries are copied unchanged (zeros inside a stored block are stored); only the
    summation order of a product may differ (round-off).

    Args:
        A: An assembled AIJ (or BAIJ) matrix, rows and columns numbered ``bs * node + c``.
        bs: The block size (the geometric dimension).
        fmt: ``"baij"`` (MPIBAIJ/SeqBAIJ) or ``"aij"`` (AIJ with the block size set).

    Returns ``None`` (collectively) when ``bs == 1``, the row or column ranges of some rank
    do not start and end on whole blocks, or ``A`` is stored so already (BAIJ of block size
    ``bs`` for ``"baij"``, AIJ for ``"aij"``: e.g. the ramps' blocks, assembled as BAIJ); the
    caller then keeps ``A``.
    """
    if fmt not in BLOCK_FORMATS:
        raise ValueError(f"fmt={fmt!r} is not known; use one of {list(BLOCK_FORMATS)}")
    is_baij = A.getType() in (PETSc.Mat.Type.SEQBAIJ, PETSc.Mat.Type.MPIBAIJ)
    if is_baij == (fmt == "baij") and (not is_baij or A.getBlockSize() == bs):
        return None
    comm = A.getComm()
    (rl, _), (cl, _) = A.getSizes()
    r0, c0 = A.getOwnershipRange()[0], A.getOwnershipRangeColumn()[0]
    whole = bs > 1 and all(v % bs == 0 for v in (rl, cl, r0, c0))
    if not comm.tompi4py().allreduce(whole, op=MPI.LAND):
        return None
    ai, aj, av = A.getValuesCSR()  # owned rows, global columns
    nb = rl // bs
    # blocks per block row, inside and outside this rank's column range
    brow = np.repeat(np.arange(rl) // bs, np.diff(ai))
    bcol = aj // bs
    key = np.unique(brow.astype(np.int64) * (A.getSize()[1] // bs + 1) + bcol)
    kb_row = key // (A.getSize()[1] // bs + 1)
    kb_col = key % (A.getSize()[1] // bs + 1)
    diag = (kb_col >= c0 // bs) & (kb_col < (c0 + cl) // bs)
    d_nnz = np.bincount(kb_row[diag], minlength=nb).astype(PETSc.IntType)
    o_nnz = np.bincount(kb_row[~diag], minlength=nb).astype(PETSc.IntType)
    B = PETSc.Mat().create(comm=comm)
    B.setSizes(A.getSizes(), bsize=bs)
    B.setType(PETSc.Mat.Type.BAIJ if fmt == "baij" else PETSc.Mat.Type.AIJ)
    if fmt == "aij":  # counts per row, not per block row
        d_nnz, o_nnz = np.repeat(d_nnz, bs) * bs, np.repeat(o_nnz, bs) * bs
    # a rank without rows gives scalar counts: petsc4py 3.18 mishandles empty arrays for BAIJ
    # (the assembly then hangs)
    B.setPreallocationNNZ((d_nnz, o_nnz) if rl else (0, 0))
    if rl:
        B.setValuesCSR(ai, aj, av)
    B.assemble()
    return B
