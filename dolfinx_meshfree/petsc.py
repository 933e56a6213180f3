"""PETSc-facing code: distributed matrices from local triplets, block (nest) systems, solves.

Mirrors ``dolfinx.fem.petsc``. Off-rank contributions go through PETSc's stash (``MatSetValues``
with ``ADD_VALUES`` on rows another rank owns), never through hand-written messaging. The same
code runs on PETSc 3.18 (no COO assembly in its petsc4py) and current PETSc.

Solvers never touch PETSc's global options database: MUMPS is selected through the API on a KSP
with its own prefix.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from .parallel import Layout

__all__ = ["BlockSystem", "create_aij", "create_vector", "solve_lu", "to_local_csr"]

_prefix_counter = itertools.count()


def to_local_csr(
    rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, shape: tuple[int, int]
) -> sp.csr_matrix:
    """Sum duplicate global triplets into a CSR matrix of global shape (local, no messaging)."""
    return sp.csr_matrix((vals, (rows, cols)), shape=shape)


def create_aij(comm, local: sp.spmatrix, row_layout: Layout, col_layout: Layout) -> PETSc.Mat:
    """Distributed AIJ matrix from this rank's contributions in global numbering (collective).

    Args:
        local: (global rows x global cols) sparse matrix of this rank's contributions; rows that
            other ranks own are sent through PETSc's stash and added there.
    """
    A = local.tocsr()
    A.sum_duplicates()
    A.eliminate_zeros()
    rs, re = row_layout.start, row_layout.end
    cs, ce = col_layout.start, col_layout.end
    own = A[rs:re]
    indptr = own.indptr.astype(PETSc.IntType)
    indices = own.indices.astype(PETSc.IntType)
    in_diag = (own.indices >= cs) & (own.indices < ce)
    row_of = np.repeat(np.arange(re - rs), np.diff(own.indptr))
    d_nnz = np.bincount(row_of[in_diag], minlength=re - rs).astype(PETSc.IntType)
    o_nnz = np.bincount(row_of[~in_diag], minlength=re - rs).astype(PETSc.IntType)
    M = PETSc.Mat().createAIJ(size=(row_layout.petsc_sizes(), col_layout.petsc_sizes()), comm=comm)
    # extra room for entries other ranks add to our rows (interface rows only); PETSc rejects
    # counts above the number of diagonal-block / off-diagonal-block columns
    nd = col_layout.size_local
    no = col_layout.size_global - nd
    M.setPreallocationNNZ((np.minimum(d_nnz + 8, nd), np.minimum(o_nnz + 8, no)))
    M.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    if re > rs:
        M.setValuesCSR(indptr, indices, own.data, addv=PETSc.InsertMode.ADD_VALUES)
    off = A.getnnz(axis=1)
    off[rs:re] = 0
    for r in np.flatnonzero(off):
        lo, hi = A.indptr[r], A.indptr[r + 1]
        M.setValues(
            [r],
            A.indices[lo:hi].astype(PETSc.IntType),
            A.data[lo:hi],
            addv=PETSc.InsertMode.ADD_VALUES,
        )
    M.assemble()
    return M


def create_vector(comm, layout: Layout, rows: np.ndarray, vals: np.ndarray) -> PETSc.Vec:
    """Distributed vector with ``vals`` added at global ``rows`` (any rank may add any row)."""
    v = PETSc.Vec().createMPI(layout.petsc_sizes(), comm=comm)
    v.set(0.0)
    rows = np.asarray(rows, dtype=PETSc.IntType)
    if rows.size:
        v.setValues(rows, np.asarray(vals, dtype=float), addv=PETSc.InsertMode.ADD_VALUES)
    v.assemblyBegin()
    v.assemblyEnd()
    return v


def solve_lu(A: PETSc.Mat, b: PETSc.Vec, solver: str = "mumps") -> PETSc.Vec:
    """Solve ``A x = b`` with a parallel LU (MUMPS by default) on a private KSP.

    The factorisation is chosen through the API; nothing is written to PETSc's options database.
    """
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(f"dolfinx_meshfree_lu_{next(_prefix_counter)}_")
    ksp.setOperators(A)
    ksp.setType(PETSc.KSP.Type.PREONLY)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.LU)
    pc.setFactorSolverType(solver)
    if solver == "mumps":
        # Saddle points (Lagrange multipliers) pivot off the diagonal. Through the API, not the
        # options database: 100 % extra workspace (ICNTL(14)), else INFOG(1) = -9; a pivot
        # threshold of 0.1 instead of 0.01 (CNTL(1)) and up to 3 steps of iterative refinement
        # (ICNTL(10), CNTL(2)): with MUMPS's defaults the EFG patch-test saddle point loses 3-4
        # digits against a dense LU (7e-11 instead of 2e-14); with these it gives 5e-15.
        pc.setFactorSetUpSolverType()
        F = pc.getFactorMatrix()
        F.setMumpsIcntl(14, 100)
        F.setMumpsCntl(1, 0.1)
        F.setMumpsIcntl(10, -3)
        F.setMumpsCntl(2, 1e-15)
    x = A.createVecRight()
    ksp.solve(b, x)
    reason = ksp.getConvergedReason()
    info = pc.getFactorMatrix().getMumpsInfog(1) if solver == "mumps" else 0
    ksp.destroy()
    if reason < 0:
        raise RuntimeError(
            f"the {solver} LU solve failed (KSP reason {reason}, MUMPS INFOG(1)={info}); the "
            "system is singular: check that the boundary conditions remove rigid-body motions"
        )
    return x


class BlockSystem:
    """A square block system as a PETSc MatNest, solved by MUMPS on its AIJ conversion.

    Args:
        blocks: 2D list of PETSc matrices or ``None`` (a zero block), e.g. the Lagrange-multiplier
            saddle point ``[[K, G^T], [G, None]]``.
        rhs: One PETSc vector per block row.
    """

    def __init__(self, blocks: Sequence[Sequence[PETSc.Mat | None]], rhs: Sequence[PETSc.Vec]):
        self.blocks = [list(r) for r in blocks]
        self.rhs = list(rhs)
        n = len(self.blocks)
        if any(len(r) != n for r in self.blocks) or len(self.rhs) != n:
            raise ValueError(f"blocks must be square with one rhs per row; got {n} rows")
        self.nest = PETSc.Mat().createNest(self.blocks, comm=self.rhs[0].getComm())

    def solve(self, solver: str = "mumps") -> list[np.ndarray]:
        """Solve and return the owned part of each block of the solution (collective)."""
        aij = PETSc.Mat()
        self.nest.convert("aij", aij)
        b = aij.createVecLeft()
        b.setArray(np.concatenate([v.getArray(readonly=True) for v in self.rhs]))
        x = solve_lu(aij, b, solver)
        arr = x.getArray(readonly=True).copy()
        sizes = np.cumsum([v.getLocalSize() for v in self.rhs])[:-1]
        aij.destroy()
        b.destroy()
        x.destroy()
        return np.split(arr, sizes)

    def destroy(self) -> None:
        self.nest.destroy()
