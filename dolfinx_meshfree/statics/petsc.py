"""PETSc-facing code: distributed matrices from local triplets, block (nest) systems, solves.

Mirrors ``dolfinx.fem.petsc``. Off-rank contributions go through PETSc's stash (``MatSetValues``
with ``ADD_VALUES`` on rows another rank owns), never through hand-written messaging. The same
code runs on PETSc 3.18 (no COO assembly in its petsc4py) and current PETSc.

Solvers never leave anything in PETSc's global options database: the shorthands (``"mumps"``,
``"fieldsplit"``, ``"iterative"``) configure a private KSP through the API or under its prefix;
user ``petsc_options`` (as DOLFINx's ``LinearProblem`` takes them) are written under the KSP's
prefix, read by ``setFromOptions`` and removed again.
"""

from __future__ import annotations

import contextlib
import itertools
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from ..parallel import Layout
from .kept_factor import KeptFactorisation

__all__ = [
    "DECOUPLED_SHARE",
    "FACTORISATIONS",
    "ITERATIVE_DEFAULTS",
    "MUMPS_FAILURES",
    "NON_PIVOTING",
    "PREONLY_RESIDUAL",
    "SADDLE_HINT",
    "SAMPLED_SYMMETRY_ROWS",
    "SHORTHANDS",
    "SYMMETRY_TOL",
    "BlockSystem",
    "SolverOptions",
    "asymmetry",
    "asymmetry_above",
    "check_factor_package",
    "check_preonly",
    "create_aij",
    "create_vector",
    "decoupled_rows",
    "mumps_failure",
    "rigid_body_modes",
    "scoped_options",
    "solve_lu",
    "solver_options",
    "to_local_csr",
]

#: The solver shorthands of every ``solve(solver=...)``: ``"mumps"`` is the best direct solve
#: (MUMPS's symmetric LDL^T where the assembled system is symmetric, else LU), ``"mumps-lu"``
#: MUMPS's LU whatever the symmetry (for comparison), ``"fieldsplit"`` and ``"iterative"`` see
#: :class:`BlockSystem`.
SHORTHANDS = ("mumps", "mumps-lu", "fieldsplit", "iterative")

#: The options of ``solver="iterative"`` (:meth:`BlockSystem.solve`), under the KSP's prefix;
#: a :class:`SolverOptions`' ``petsc_options`` override them one by one. FGMRES on the
#: augmented system to ``rtol`` 1e-12 of the unpreconditioned residual, as
#: :func:`~dolfinx_meshfree.solve_large` (difference to MUMPS: 2e-14 to 4e-13 on the cantilevers
#: of tests/test_coupled_iterative.py, 2.5e-12 at h = 0.125; 1e-10 gave 5e-12 with 20 % fewer
#: iterations); block upper-triangular Schur preconditioner: one GAMG V-cycle on the augmented
#: primal block (threshold 0.05: as many iterations as 0.0, a 2x cheaper hierarchy), the Schur
#: complement by a multiple of the identity (see :data:`SCHUR_SCALE`). The primal split is
#: named ``u``, the multipliers ``lambda`` (e.g. ``fieldsplit_u_pc_gamg_threshold``).
ITERATIVE_DEFAULTS: dict[str, Any] = {
    "ksp_type": "fgmres",
    "ksp_gmres_restart": 200,
    "ksp_rtol": 1e-12,
    "ksp_atol": 0.0,
    "ksp_max_it": 1000,
    "ksp_norm_type": "unpreconditioned",
    "pc_type": "fieldsplit",
    "pc_fieldsplit_type": "schur",
    "pc_fieldsplit_schur_fact_type": "upper",
    "fieldsplit_u_ksp_type": "preonly",
    "fieldsplit_u_pc_type": "gamg",
    "fieldsplit_u_pc_gamg_threshold": 0.05,
    "fieldsplit_lambda_ksp_type": "preonly",
    "fieldsplit_lambda_pc_type": "jacobi",
}

#: The Schur complement of the augmented system ``S = -G A_gamma^-1 G^T`` is approximated by
#: ``-(SCHUR_SCALE / gamma) I`` (for the augmented Lagrangian ``S^-1 = S_0^-1 - gamma I``, so
#: ``-gamma I`` is the classical choice). With one V-cycle on the primal block, a smaller
#: inverse works better: lagrange cantilever, h = 0.125, 50 % patch: 223 FGMRES iterations
#: with 1, 90 with 10, 126 with 100 (with an exact primal solve 11-13 whatever the scale).
SCHUR_SCALE = 10.0

#: Factorisations of :func:`solve_lu`: ``"auto"`` (LDL^T when symmetric, else LU) or ``"lu"``.
FACTORISATIONS = ("auto", "lu")

#: Largest relative asymmetry ``|A - A^T|_F / |A|_F`` factorised as symmetric: the Galerkin
#: systems are symmetric to round-off (measured 0 to 3e-16), the Petrov-Galerkin ones (VCI,
#: hybrid HA-S) by far more (1e-3 and above).
SYMMETRY_TOL = 1e-12

_prefix_counter = itertools.count()


@dataclass(frozen=True)
class SolverOptions:
    """A linear solver for a block system: a shorthand, or PETSc options under a prefix.

    Attributes:
        solver: ``"mumps"``, ``"mumps-lu"``, ``"fieldsplit"`` or ``"iterative"`` (see
            :class:`BlockSystem`); ignored when :attr:`petsc_options` is given, except
            ``"iterative"``, whose :data:`ITERATIVE_DEFAULTS` they override one by one.
        petsc_options: PETSc options (without the prefix, e.g. ``{"ksp_type": "preonly",
            "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}``) for a KSP on the
            assembled block system, as ``dolfinx.fem.petsc.LinearProblem`` takes them. The
            fields of the nest are available to ``pc_type: fieldsplit`` by name
            (:attr:`BlockSystem.names`, e.g. ``fieldsplit_particles_pc_type``). With
            ``solver="iterative"``: changes of its options (e.g. ``{"ksp_rtol": 1e-12}``).
        prefix: The KSP's options prefix (default: a unique ``dolfinx_meshfree_<n>_``).
    """

    solver: str = "mumps"
    petsc_options: Mapping[str, Any] | None = field(default=None)
    prefix: str | None = None


def solver_options(
    solver: str | SolverOptions = "mumps",
    petsc_options: Mapping[str, Any] | None = None,
    prefix: str | None = None,
) -> SolverOptions:
    """Check and bundle a ``solve`` call's solver arguments (raises ``ValueError`` on every rank
    of a collective call alike: the check is local and the same everywhere)."""
    if isinstance(solver, SolverOptions):
        if petsc_options is not None or prefix is not None:
            raise ValueError("give petsc_options and prefix inside the SolverOptions, not beside")
        return solver
    if solver not in SHORTHANDS:
        raise ValueError(f"solver={solver!r} is not known; use one of {list(SHORTHANDS)}")
    if petsc_options is not None and not isinstance(petsc_options, Mapping):
        raise ValueError(
            f"petsc_options must be a dict of PETSc options, got {type(petsc_options).__name__}"
        )
    if prefix is not None and (not isinstance(prefix, str) or not prefix or " " in prefix):
        raise ValueError(f"prefix={prefix!r} must be a non-empty PETSc options prefix")
    return SolverOptions(solver, None if petsc_options is None else dict(petsc_options), prefix)


def to_local_csr(
    rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, shape: tuple[int, int]
) -> sp.csr_matrix:
    """Sum duplicate global triplets into a CSR matrix of global shape (local, no messaging)."""
    return sp.csr_matrix((vals, (rows, cols)), shape=shape)


def create_aij(
    comm: MPI.Comm | PETSc.Comm,
    local: sp.spmatrix,
    row_layout: Layout,
    col_layout: Layout,
    block_size: int = 1,
) -> PETSc.Mat:
    """Distributed AIJ matrix from this rank's contributions in global numbering (collective).

    Args:
        local: (global rows x global cols) sparse matrix of this rank's contributions; rows that
            other ranks own are sent through PETSc's stash and added there. A CSR ``local`` with
            sorted indices and no duplicates is used in place (no copy of its arrays, so that
            large matrices are held twice at most: here and in PETSc).
        block_size: the matrix's block size (e.g. ``gdim`` for interleaved displacement dofs:
            what GAMG aggregates by); the layouts' local sizes must be multiples of it.
    """
    A = local.tocsr()
    A.sum_duplicates()
    A.eliminate_zeros()
    rs, re = row_layout.start, row_layout.end
    cs, ce = col_layout.start, col_layout.end
    if (rs, re) == (0, A.shape[0]):
        own = A
    else:  # the owned rows as views of A's arrays (A[rs:re] would copy them: a third matrix)
        p0, p1 = A.indptr[rs], A.indptr[re]
        own = sp.csr_matrix(
            (A.data[p0:p1], A.indices[p0:p1], A.indptr[rs : re + 1] - p0),
            shape=(re - rs, A.shape[1]),
        )
    indptr = own.indptr.astype(PETSc.IntType, copy=False)
    indices = own.indices.astype(PETSc.IntType, copy=False)
    d_nnz = np.empty(re - rs, PETSc.IntType)
    step = 1 << 16  # rows at a time: no (nnz,) integer temporaries
    for lo in range(0, re - rs, step):
        hi = min(lo + step, re - rs)
        p0, p1 = own.indptr[lo], own.indptr[hi]
        cols = own.indices[p0:p1]
        in_diag = np.concatenate(([0], np.cumsum((cols >= cs) & (cols < ce))))
        d_nnz[lo:hi] = np.diff(in_diag[own.indptr[lo : hi + 1] - p0])
    o_nnz = (np.diff(own.indptr) - d_nnz).astype(PETSc.IntType)
    off = A.getnnz(axis=1)
    off[rs:re] = 0
    off_rows = np.flatnonzero(off)
    mpi = comm.tompi4py() if isinstance(comm, PETSc.Comm) else comm
    if mpi.size > 1:  # room for what other ranks add to our rows: their counts, sent here
        received = _off_rank_counts(mpi, A[off_rows], off_rows, row_layout, col_layout)
        d_nnz += received[0]
        o_nnz += received[1]
    sizes = (row_layout.petsc_sizes(), col_layout.petsc_sizes())
    M = PETSc.Mat().createAIJ(size=sizes, bsize=block_size, comm=comm)
    # extra room for entries other ranks add to our rows (interface rows only); PETSc rejects
    # counts above the number of diagonal-block / off-diagonal-block columns
    nd = col_layout.size_local
    no = col_layout.size_global - nd
    M.setPreallocationNNZ((np.minimum(d_nnz + 8, nd), np.minimum(o_nnz + 8, no)))
    M.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    if re > rs:
        M.setValuesCSR(indptr, indices, own.data, addv=PETSc.InsertMode.ADD_VALUES)
    del own, indptr, indices
    for r in off_rows:
        lo, hi = A.indptr[r], A.indptr[r + 1]
        M.setValues(
            [r],
            A.indices[lo:hi].astype(PETSc.IntType),
            A.data[lo:hi],
            addv=PETSc.InsertMode.ADD_VALUES,
        )
    M.assemble()
    return M


def _off_rank_counts(
    comm: MPI.Comm, rows: sp.csr_matrix, row_ids: np.ndarray, row_layout: Layout, col_layout: Layout
) -> tuple[np.ndarray, np.ndarray]:
    """Entries per owned row (diagonal-block, off-diagonal-block columns) that the other ranks
    add (collective): each rank sends the counts of its ``rows`` (global ``row_ids``, owned
    elsewhere) to their owners. An upper bound of the new entries, for the preallocation."""
    ends = np.array(comm.allgather(row_layout.end), dtype=np.int64)
    col_ranges = np.array(comm.allgather((col_layout.start, col_layout.end)), dtype=np.int64)
    owner = np.searchsorted(ends, row_ids, side="right")
    per_row = np.diff(rows.indptr)
    entry_owner = np.repeat(owner, per_row)
    lo, hi = col_ranges[entry_owner, 0], col_ranges[entry_owner, 1]
    diag = np.bincount(
        np.repeat(np.arange(row_ids.size), per_row),
        weights=(rows.indices >= lo) & (rows.indices < hi),
        minlength=row_ids.size,
    ).astype(np.int64)
    send = [
        (row_ids[owner == r], diag[owner == r], per_row[owner == r] - diag[owner == r])
        for r in range(comm.size)
    ]
    d = np.zeros(row_layout.size_local, PETSc.IntType)
    o = np.zeros(row_layout.size_local, PETSc.IntType)
    for ids, dc, oc in comm.alltoall(send):
        np.add.at(d, ids - row_layout.start, dc)
        np.add.at(o, ids - row_layout.start, oc)
    return d, o


def create_vector(
    comm: MPI.Comm | PETSc.Comm, layout: Layout, rows: np.ndarray, vals: np.ndarray
) -> PETSc.Vec:
    """Distributed vector with ``vals`` added at global ``rows`` (any rank may add any row)."""
    v = PETSc.Vec().createMPI(layout.petsc_sizes(), comm=comm)
    v.set(0.0)
    rows = np.asarray(rows, dtype=PETSc.IntType)
    if rows.size:
        v.setValues(rows, np.asarray(vals, dtype=float), addv=PETSc.InsertMode.ADD_VALUES)
    v.assemblyBegin()
    v.assemblyEnd()
    return v


def asymmetry(A: PETSc.Mat, norm: float | None = None) -> float:
    """``|A - A^T|_F / |A|_F`` of a square assembled matrix, 0 for a zero matrix (collective);
    ``norm``: ``|A|_F`` where the caller has it."""
    T = A.transpose(PETSc.Mat())  # (without an argument petsc4py transposes in place)
    norm = A.norm(PETSc.NormType.FROBENIUS) if norm is None else norm
    T.axpy(-1.0, A, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    diff = T.norm(PETSc.NormType.FROBENIUS)
    T.destroy()
    return diff / norm if norm > 0.0 else 0.0


#: Systems of at least this many rows are first tested for asymmetry on a sample
#: (:func:`asymmetry_above`); smaller ones are always measured whole.
SAMPLED_SYMMETRY_ROWS = 10_000


def asymmetry_above(A: PETSc.Mat, tol: float) -> tuple[float, bool]:
    """Whether ``A`` is symmetric to ``tol``, measured, at a fraction of :func:`asymmetry`'s cost
    where it is not (collective).

    ``|A_SS - A_SS^T|_F`` of a principal submatrix (rows and columns ``S``) sums a subset of the
    squared entries of ``A - A^T``, so ``|A_SS - A_SS^T|_F / |A|_F`` is a lower bound of
    ``A``'s asymmetry: where the bound exceeds ``tol``, ``A`` is proven unsymmetric without
    measuring the rest. ``S`` is 8 evenly spaced runs of 1/64 of each rank's rows (an eighth
    of the rows; a run holds the near-diagonal couplings of a spatially ordered field). Where the
    bound does not decide (a symmetric matrix, or asymmetry outside ``S``), or below
    :data:`SAMPLED_SYMMETRY_ROWS` rows, the whole of ``A`` is measured. On the cantilever at
    75k dofs (lane A) the whole measure took 0.16 s for pure EFG with VCI and 0.065 s for the
    lagrange 25 % patch system, the sample 0.010 s and 0.009 s (the bounds 4.2e-6 and 3.1e-7
    against the whole 1.1e-5 and 2.1e-6); ``solve_lu``'s ``stats["check"]`` times it.

    Returns:
        ``(value, sampled)``: ``value`` is the asymmetry of :func:`asymmetry` or, where
        ``sampled``, the lower bound that exceeded ``tol``.
    """
    if A.getSize()[0] < SAMPLED_SYMMETRY_ROWS:
        return asymmetry(A), False
    lo, hi = A.getOwnershipRange()
    n = hi - lo
    run = max(n // 64, 1)
    starts = lo + (np.arange(8) * n) // 8
    rows = np.unique(np.concatenate([np.arange(s, min(s + run, hi)) for s in starts]))
    index = PETSc.IS().createGeneral(rows.astype(PETSc.IntType), comm=A.getComm())
    sub = A.createSubMatrix(index, index)
    part = sub.norm(PETSc.NormType.FROBENIUS) * asymmetry(sub)
    sub.destroy()
    index.destroy()
    norm = A.norm(PETSc.NormType.FROBENIUS)
    if norm > 0.0 and part / norm > tol:
        return part / norm, True
    return asymmetry(A, norm), False


#: :func:`solve_lu` solves the decoupled rows (:func:`decoupled_rows`) apart and factorises the
#: rest when they are at least this share of the rows. A coupled model's FE dofs inside the
#: particle patch are such rows (18,818 of 93,702 for the cantilever's 25 % patch at h = 0.125):
#: without them MUMPS's factorisation took 1.2x less time with 9 % fewer factor entries. Below
#: the share (a model's few Dirichlet rows) the copy of the matrix would cost more than it saves.
DECOUPLED_SHARE = 0.01


def decoupled_rows(A: PETSc.Mat) -> tuple[np.ndarray, np.ndarray]:
    """This rank's rows of the square ``A`` whose only nonzero, in the row and in the column, is
    the diagonal (the identity rows of fixed or inactive dofs), as global row numbers, with
    their diagonal values (collective).

    Stored zeros do not count. The columns are checked over every rank (each rank's
    off-diagonal nonzeros counted into a PETSc vector). Empty where the row and column layouts
    differ.
    """
    lo, hi = A.getOwnershipRange()
    square = A.getSize()[0] == A.getSize()[1] and (lo, hi) == A.getOwnershipRangeColumn()
    if not A.getComm().tompi4py().allreduce(square, op=MPI.LAND):
        return np.zeros(0, PETSc.IntType), np.zeros(0)
    ai, aj, av = A.getValuesCSR()
    rows = np.repeat(np.arange(lo, hi, dtype=PETSc.IntType), np.diff(ai))
    on_diagonal = aj == rows
    off = (av != 0.0) & ~on_diagonal
    columns = np.unique(aj[off])
    layout = Layout(hi - lo, A.getSize()[1], lo)
    hits = create_vector(A.getComm(), layout, columns, np.ones(columns.size))
    in_column = hits.getArray(readonly=True) > 0.0
    hits.destroy()
    in_row = np.bincount(rows[off] - lo, minlength=hi - lo) > 0
    diagonal = np.zeros(hi - lo)
    diagonal[rows[on_diagonal] - lo] = av[on_diagonal]
    keep = ~in_row & ~in_column & (diagonal != 0.0)
    return (np.flatnonzero(keep) + lo).astype(PETSc.IntType), diagonal[keep]


def solve_lu(
    A: PETSc.Mat,
    b: PETSc.Vec,
    solver: str = "mumps",
    factorisation: str = "auto",
    stats: dict | None = None,
    more: Sequence[PETSc.Vec] = (),
    sign: bool = False,
    kept: KeptFactorisation | None = None,
) -> PETSc.Vec:
    """Solve ``A x = b`` by a parallel direct factorisation (MUMPS by default) on a private KSP.

    With MUMPS and ``factorisation="auto"``, a system that is symmetric to :data:`SYMMETRY_TOL`
    (measured by :func:`asymmetry_above`, never assumed) is marked symmetric and factorised as
    ``L D L^T`` (PETSc's Cholesky PC, MUMPS ``SYM = 2``: symmetric indefinite with pivoting,
    as a saddle point needs); at 75k dofs that took 1.6x less time and half the memory of the
    LU. Any other system, or ``factorisation="lu"``, is factorised as LU. The factorisation
    is chosen through the API; nothing is written to PETSc's options database.

    Rows decoupled from the rest (:func:`decoupled_rows`: ``x_i = b_i / a_ii``) are solved
    apart and the rest is factorised alone when they are at least :data:`DECOUPLED_SHARE` of
    the rows; the solution is the same to round-off.

    Args:
        solver: PETSc's factor package (``"mumps"``, ``"petsc"``, ...).
        factorisation: ``"auto"`` or ``"lu"`` (:data:`FACTORISATIONS`).
        more: Further right-hand sides solved with the same factorisation (path following
            needs two per iteration); their solutions are in ``stats["more"]`` when ``stats``
            is given, else returned as ``(x, [x_1, ...])``.
        stats: Filled (if given) with ``factorisation`` (``"ldlt"`` or ``"lu"``),
            ``determinant_sign`` (with ``sign``: the sign of ``det A``, from MUMPS's
            determinant, ICNTL(33); not given by another factor package),
            ``asymmetry`` (a lower bound where ``asymmetry_sampled``: :func:`asymmetry_above`),
            the seconds of its ``check``, of ``factor`` (and its CPU seconds on this rank,
            ``factor_cpu``) and ``solve`` and, with MUMPS, its ``memory_mb``
            (INFOG(22): the memory the factorisation used, summed over ranks), the number of
            ``decoupled`` rows solved apart (0 where none were) and the seconds to find them
            and take the rest (``reduce``), ``analysis``: ``"kept"`` where the
            factorisation reused ``kept``'s analysis, else ``"new"``, and ``factors``:
            ``"kept"`` where ``kept``'s factors solved the system (its values were the kept
            operator's: no factorisation, ``factor`` is then the time of an empty set-up),
            else ``"new"``.
        kept: A :class:`~dolfinx_meshfree.statics.kept_factor.KeptFactorisation` that a
            sequence of systems of one sparsity pattern shares (Newton's tangents): MUMPS's
            analysis of the first serves the next ones, whose factorisation is then numerical
            only, and a system with the kept values (a load sweep) is not factorised at all;
            it is kept there after the solve (the caller frees it). ``None``: a KSP of this
            solve alone, freed after it.
    """
    if factorisation not in FACTORISATIONS:
        raise ValueError(
            f"factorisation={factorisation!r} is not known; use one of {list(FACTORISATIONS)}"
        )
    tr = time.perf_counter()
    rows, diagonal = decoupled_rows(A)
    count = A.getComm().tompi4py().allreduce(rows.size, op=MPI.SUM)

    def result(xs: list[PETSc.Vec]) -> PETSc.Vec | tuple:
        if not more:
            return xs[0]
        if stats is not None:
            stats["more"] = xs[1:]
            return xs[0]
        return xs[0], xs[1:]

    if count == 0 or count < DECOUPLED_SHARE * A.getSize()[0]:
        reduce = time.perf_counter() - tr
        xs = _factorise_and_solve(A, [b, *more], solver, factorisation, stats, sign, kept)
        if stats is not None:
            stats.update(decoupled=0, reduce=reduce)
        return result(xs)
    want_sign = sign and stats is not None
    if want_sign:  # det A = det(the rest) x the decoupled diagonal's product
        negative = A.getComm().tompi4py().allreduce(int(np.count_nonzero(diagonal < 0)))
    lo, hi = A.getOwnershipRange()
    locals_ = [v.getArray(readonly=True) for v in (b, *more)]
    values = [np.empty(hi - lo) for _ in locals_]
    for val, loc in zip(values, locals_, strict=True):
        val[rows - lo] = loc[rows - lo] / diagonal
    diagonal_only = count == A.getSize()[0]
    if not diagonal_only:  # else A is diagonal: nothing left to factorise
        rest = np.setdiff1d(np.arange(lo, hi, dtype=PETSc.IntType), rows, assume_unique=True)
        index = PETSc.IS().createGeneral(rest, comm=A.getComm())
        A_rest = A.createSubMatrix(index, index)
        b_rest = []
        for loc in locals_:
            v = A_rest.createVecLeft()
            v.setArray(loc[rest - lo])
            b_rest.append(v)
        reduce = time.perf_counter() - tr
        try:
            x_rest = _factorise_and_solve(A_rest, b_rest, solver, factorisation, stats, sign, kept)
        finally:
            for obj in (A_rest, *b_rest, index):
                obj.destroy()
        for val, xr in zip(values, x_rest, strict=True):
            val[rest - lo] = xr.getArray(readonly=True)
            xr.destroy()
    else:
        reduce = time.perf_counter() - tr
    xs = []
    for val in values:
        x = A.createVecRight()
        x.setArray(val)
        xs.append(x)
    if stats is not None:
        stats.update(decoupled=count, reduce=reduce)
    if want_sign:
        rest_sign = 1.0 if diagonal_only else stats.get("determinant_sign")
        stats["determinant_sign"] = (
            None if rest_sign is None else (-1.0 if negative % 2 else 1.0) * rest_sign
        )
    return result(xs)


def _factorise_and_solve(
    A: PETSc.Mat,
    bs: Sequence[PETSc.Vec],
    solver: str,
    factorisation: str,
    stats: dict | None,
    sign: bool = False,
    kept: KeptFactorisation | None = None,
) -> list[PETSc.Vec]:
    """:func:`solve_lu` on the (reduced) system: the symmetry check, the factorisation (on
    ``kept``'s analysis where it fits) and the triangular solves, one per right-hand side in
    ``bs``; with ``sign`` (and ``stats``) the determinant's sign in
    ``stats["determinant_sign"]``."""
    mumps = solver == "mumps"
    want_sign = sign and stats is not None
    tc = time.perf_counter()
    asym, sampled = (None, False)
    if mumps and factorisation == "auto":
        asym, sampled = asymmetry_above(A, SYMMETRY_TOL)
    check = time.perf_counter() - tc
    symmetric = asym is not None and asym <= SYMMETRY_TOL
    if symmetric:
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    key = (solver, symmetric, want_sign)
    ksp = None if kept is None else kept.take(A, key)
    reused = ksp is not None
    if not reused:
        ksp = _direct_ksp(A, solver, symmetric, want_sign)
    t0, c0 = time.perf_counter(), time.process_time()
    ksp.setUp()
    t1, c1 = time.perf_counter(), time.process_time()
    pc = ksp.getPC()
    if want_sign and mumps:
        stats["determinant_sign"] = float(np.sign(pc.getFactorMatrix().getMumpsRinfog(12)))
    xs, reason = [], 0
    for b in bs:
        x = A.createVecRight()
        ksp.solve(b, x)
        xs.append(x)
        reason = min(reason, ksp.getConvergedReason())
    t2 = time.perf_counter()
    F = pc.getFactorMatrix()
    info = F.getMumpsInfog(1) if mumps else 0
    if stats is not None:
        stats.update(
            factorisation="ldlt" if symmetric else "lu",
            asymmetry=asym,
            asymmetry_sampled=sampled,
            check=check,
            factor=t1 - t0,
            factor_cpu=c1 - c0,
            solve=t2 - t1,
            memory_mb=F.getMumpsInfog(22) if mumps else None,
            analysis="kept" if reused else "new",
            factors="kept" if reused and kept.last == "factors" else "new",
        )
    if reason < 0 and reused:
        # the kept analysis did not serve these values (its matching and scaling are an
        # earlier system's): afresh, with this system's own analysis
        for x in xs:
            x.destroy()
        kept.clear()
        return _factorise_and_solve(A, bs, solver, factorisation, stats, sign, kept)
    if kept is not None and reason >= 0:
        kept.keep(ksp, key)  # its handles stay open until the kept one is freed
    else:
        # every handle is destroyed: petsc4py 3.18 otherwise keeps the factorisation alive
        # (1.3 MB per solve at 1,250 dofs, which added up to gigabytes over a test session)
        F.destroy()
        pc.destroy()
        ksp.destroy()
    if reason < 0 and symmetric:
        # MUMPS's symmetric analysis can fail where its LU does not: lane B's MUMPS called a
        # Lagrange saddle point with multipliers split at the interface's corners (triangles)
        # structurally singular (INFOG(1) = -6) that LU solves to 3e-13 of the patch test. LU
        # then, and the failure kept in the stats.
        xs = _factorise_and_solve(A, bs, solver, "lu", stats, sign, kept)
        if stats is not None:
            stats["ldlt_failed"] = info
        return xs
    if reason < 0:
        raise RuntimeError(
            f"the {solver} {'LDL^T' if symmetric else 'LU'} solve failed (KSP reason {reason}, "
            f"MUMPS INFOG(1)={info}): {mumps_failure(info if mumps else None)}"
        )
    return xs


def _direct_ksp(A: PETSc.Mat, solver: str, symmetric: bool, want_sign: bool) -> PETSc.KSP:
    """A private KSP (PREONLY) on ``A`` that factorises it with ``solver``: Cholesky (LDL^T)
    where ``symmetric``, else LU; MUMPS's settings for saddle points, and its determinant
    (ICNTL(33)) with ``want_sign``. Not set up yet."""
    mumps = solver == "mumps"
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(f"dolfinx_meshfree_lu_{next(_prefix_counter)}_")
    ksp.setOperators(A)
    ksp.setType(PETSc.KSP.Type.PREONLY)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.CHOLESKY if symmetric else PETSc.PC.Type.LU)
    pc.setFactorSolverType(solver)
    if mumps:
        # Saddle points (Lagrange multipliers) pivot off the diagonal. Through the API, not the
        # options database: 100 % extra workspace (ICNTL(14)), else INFOG(1) = -9; a pivot
        # threshold of 0.1 instead of 0.01 (CNTL(1)) and up to 3 steps of iterative refinement
        # (ICNTL(10), CNTL(2)): with MUMPS's defaults the EFG patch-test saddle point loses 3-4
        # digits against a dense LU (7e-11 instead of 2e-14); with these it gives 5e-15. The
        # same settings serve the symmetric indefinite LDL^T (2x2 pivots, threshold CNTL(1)).
        # ICNTL(10) = +3: MUMPS stops refining when the backward error no longer falls. A fixed
        # 3 steps (-3, before) gave the same residuals on the 75k-dof cantilever (3.1e-12 pure
        # EFG, 1.3e-12 lagrange; the solutions within 7e-13) in 1.7x the solve phase's time.
        # The ordering (ICNTL(7)) is left to MUMPS: of what Debian's MUMPS has (AMD, AMF, PORD,
        # QAMD) its automatic PORD gives the fewest flops on these systems, and PETSc 3.18
        # resets an ICNTL(7) set here anyway (README, "What the factorisation ... was tried with").
        pc.setFactorSetUpSolverType()
        F = pc.getFactorMatrix()
        F.setMumpsIcntl(14, 100)
        F.setMumpsCntl(1, 0.1)
        F.setMumpsIcntl(10, 3)
        F.setMumpsCntl(2, 1e-15)
        if want_sign:
            F.setMumpsIcntl(33, 1)  # the determinant (RINFOG(12), INFOG(34)): its sign only
    return ksp


#: MUMPS's failures (INFOG(1) < 0, MUMPS users' guide, sec. "Error diagnostics") and what
#: they usually mean for the systems built here.
MUMPS_FAILURES = {
    -6: "the system is structurally singular: check that the boundary conditions remove "
    "rigid-body motions",
    -10: "the system is numerically singular: check that the boundary conditions remove "
    "rigid-body motions, and that no multiplier is left without a constraint",
    -13: "MUMPS could not allocate its memory: the system is too large for this machine",
}


def mumps_failure(info: int | None) -> str:
    """What MUMPS's error ``INFOG(1) = info`` means here (no longer every failure called a
    singular system: ``-9`` is a workspace too small, which a nearly singular saddle point
    with many delayed pivots also causes); ``None``: another solver failed."""
    if info is None or info == 0:
        return (
            "the system may be singular: check that the boundary conditions remove rigid-body "
            "motions"
        )
    if info in MUMPS_FAILURES:
        return MUMPS_FAILURES[info]
    if info in (-8, -9, -11, -12, -14, -15, -17, -20):
        return (
            "MUMPS's workspace was too small (100 % extra requested, ICNTL(14)): the "
            "factorisation needed far more pivoting than planned, as a singular or nearly "
            "singular system (e.g. a saddle point with dependent multipliers) does"
        )
    return "see the MUMPS users' guide for this INFOG(1); the system may be singular"


#: What a coupled system with multipliers needs from a solver given by ``petsc_options``.
SADDLE_HINT = (
    ". The coupled system is a saddle point: its multipliers' diagonal block is zero, so a "
    "factorisation must pivot (pc_factor_mat_solver_type 'mumps'), and an iterative method needs a "
    "preconditioner that knows the blocks (pc_type 'fieldsplit' on the fields named fe, "
    "particles, multiplier0, ...); or leave petsc_options out for solver='mumps' (the default), "
    "'fieldsplit' or 'iterative'"
)

#: Factor packages that stop at the multipliers' zero diagonal (SuperLU_DIST aborts the
#: process there, so they are refused before the solve).
NON_PIVOTING = ("petsc", "superlu", "superlu_dist")

#: The largest normwise backward error ``|b - A x| / (|A| |x| + |b|)`` (max norms) a
#: ``ksp_type='preonly'`` solve may leave: a direct factorisation leaves round-off (MUMPS's LU
#: 7e-17 to 7e-14 on coupled systems in 2D and 3D), whatever the conditioning; a Cholesky
#: factorisation of the unsymmetric VCI system left 1e-5, a Jacobi step 0.09.
PREONLY_RESIDUAL = 1e-8

_REASONS = {
    getattr(PETSc.KSP.ConvergedReason, k): k
    for k in dir(PETSc.KSP.ConvergedReason)
    if k.startswith(("DIVERGED", "CONVERGED"))
}


def check_factor_package(options: Mapping[str, Any], saddle: bool) -> None:
    """Refuse, before the solve, a factorisation of a saddle point by a package that does not
    pivot (:data:`NON_PIVOTING`; the default package of ``pc_type`` 'lu' or 'cholesky' is
    PETSc's own). Local, the same on every rank."""
    pc = str(options.get("pc_type", ""))
    if not saddle or pc not in ("lu", "cholesky"):
        return
    package = str(options.get("pc_factor_mat_solver_type", "petsc"))
    if package in NON_PIVOTING:
        raise ValueError(
            f"petsc_options={dict(options)!r}: pc_type={pc!r} with the factor package "
            f"{package!r} cannot factor this system (PETSc's own LU and SuperLU stop at a zero "
            f"pivot, SuperLU_DIST aborts the process){SADDLE_HINT}"
        )


def check_preonly(aij: PETSc.Mat, b: PETSc.Vec, x: PETSc.Vec, options: Mapping[str, Any]) -> None:
    """``ksp_type='preonly'`` applies the preconditioner once and always reports success: refuse
    a solution whose normwise backward error is above :data:`PREONLY_RESIDUAL` (a
    preconditioner that is not a direct solve, or a symmetric factorisation of a matrix that is
    not symmetric). Collective (the norms are global)."""
    if str(options.get("ksp_type", "")) != "preonly":
        return
    r = b.duplicate()
    aij.mult(x, r)
    r.aypx(-1.0, b)
    inf = PETSc.NormType.INFINITY
    scale = aij.norm(inf) * x.norm(inf) + b.norm(inf)
    rel = r.norm(inf) / max(scale, 1e-300)
    r.destroy()
    if rel <= PREONLY_RESIDUAL:
        return
    pc = str(options.get("pc_type", ""))
    why = (
        f"pc_type={pc!r} factors a symmetric matrix, and this one is not (consistent "
        "integration is Petrov-Galerkin: integration='smoothed' gives a symmetric system)"
        if pc in ("cholesky", "icc")
        else f"ksp_type 'preonly' applies pc_type={pc!r} once, which solves the system only if it "
        "is a direct factorisation"
    )
    raise RuntimeError(
        f"the solve with petsc_options={dict(options)!r} left a backward error |b - A x| / "
        f"(|A| |x| + |b|) = {rel:.3g} (> {PREONLY_RESIDUAL:g}): {why}; use pc_type 'lu' with "
        "pc_factor_mat_solver_type 'mumps', or leave petsc_options out (solver='mumps')"
    )


@contextlib.contextmanager
def scoped_options(prefix: str, options: Mapping[str, Any] | None) -> Iterator[None]:
    """Put ``options`` (name -> value) into PETSc's options database under ``prefix`` for the
    ``with`` block, then restore what the database held under those names (nothing leaks into
    the global database, also when the block raises)."""
    db = PETSc.Options()
    previous = {}
    for key, value in (options or {}).items():
        name = f"{prefix}{key}"
        previous[name] = db.getString(name) if db.hasName(name) else None
        db.setValue(name, value)
    try:
        yield
    finally:
        for name, value in previous.items():
            if value is None:
                db.delValue(name)
            else:
                db.setValue(name, value)


def rigid_body_modes(
    coordinates: np.ndarray, template: PETSc.Vec
) -> tuple[PETSc.NullSpace, list[PETSc.Vec]]:
    """The rigid-body modes of displacement dofs interleaved by node (2D: two translations and
    a rotation; 3D: three and three), orthonormalised: GAMG's near-nullspace.

    Args:
        coordinates: (owned nodes, gdim) positions of this rank's nodes, in the order of the
            owned dofs of ``template`` (``gdim`` dofs per node).
        template: A vector of the layout of the dofs (duplicated, not changed).

    Returns:
        The near-nullspace and its vectors (destroy both after use).
    """
    x = np.asarray(coordinates, dtype=float)
    n, gdim = x.shape
    modes = []
    for k in range(gdim):
        m = np.zeros((n, gdim))
        m[:, k] = 1.0
        modes.append(m)
    for a, b in [(0, 1)] if gdim == 2 else [(0, 1), (1, 2), (2, 0)]:
        m = np.zeros((n, gdim))
        m[:, a], m[:, b] = -x[:, b], x[:, a]
        modes.append(m)
    vecs = []
    for m in modes:
        v = template.duplicate()
        v.setArray(m.ravel())
        for u in vecs:  # Gram-Schmidt
            v.axpy(-v.dot(u), u)
        v.normalize()
        vecs.append(v)
    return PETSc.NullSpace().create(vectors=vecs, comm=template.getComm()), vecs


class BlockSystem:
    """A square block system as a PETSc MatNest.

    Args:
        blocks: 2D list of PETSc matrices or ``None`` (a zero block), e.g. the Lagrange-multiplier
            saddle point ``[[K, G^T], [G, None]]``.
        rhs: One PETSc vector per block row.
        num_primal: How many leading fields are primal (displacements); the rest are Lagrange
            multipliers with zero diagonal blocks. Default: every field but the last when the
            last diagonal block is ``None``, else all.
        names: One name per field, for ``fieldsplit`` options (default ``field0``, ...).
        coordinates: For ``solver="iterative"``: per primal field, the (owned nodes, gdim)
            positions of this rank's nodes in the order of its owned dofs (``gdim`` dofs per
            node), which give GAMG the rigid-body modes and the block size. Default: none
            (GAMG then sees scalar dofs and no rotations: correct, but many more iterations).

    Three shorthand solvers (:meth:`solve`), or any KSP from PETSc options
    (:class:`SolverOptions`):

    * ``"mumps"``: the nest converted to AIJ and factorised by MUMPS (:func:`solve_lu`): LDL^T
      where the assembled system is symmetric (measured), else LU; ``"mumps-lu"``: always LU;
    * ``"fieldsplit"``: a Schur-complement fieldsplit on the same AIJ, primal fields against
      multipliers (FGMRES outside; primal block by MUMPS LU or, with ``inner="gamg"``, CG +
      GAMG; Schur complement by GMRES preconditioned with Jacobi on ``A11 - A10 diag(A00)^-1
      A01``). The primal block alone is singular when the multipliers hold the rigid modes (a
      floating particle patch, pure EFG), so the system is first augmented (augmented
      Lagrangian): ``A_ij += gamma G_ki^T G_kj`` and ``f_i += gamma G_ki^T g_k``, which leaves
      the solution unchanged because ``G u = g`` holds at it. ``gamma`` balances the norms of
      the primal blocks and of ``G^T G``.
    * ``"iterative"``: the same augmented system, solved without any factorisation, so that
      it scales over ranks: FGMRES preconditioned by the block upper-triangular
      ``[[A_gamma, G^T], [0, S]]^-1`` (Benzi & Olshanskii 2006) with one GAMG V-cycle on the
      primal block ``A_gamma`` (FE and particle fields together, block size gdim, the
      rigid-body modes of :attr:`coordinates` as near-nullspace) and ``S = -(SCHUR_SCALE /
      gamma) I`` (:data:`SCHUR_SCALE`); options :data:`ITERATIVE_DEFAULTS`. Without
      multipliers: FGMRES + GAMG on the whole system. Iterations in :attr:`iterations`.
    """

    def __init__(
        self,
        blocks: Sequence[Sequence[PETSc.Mat | None]],
        rhs: Sequence[PETSc.Vec],
        num_primal: int | None = None,
        names: Sequence[str] | None = None,
        coordinates: Sequence[np.ndarray] | None = None,
    ):
        self.blocks = [list(r) for r in blocks]
        self.rhs = list(rhs)
        n = len(self.blocks)
        if any(len(r) != n for r in self.blocks) or len(self.rhs) != n:
            raise ValueError(f"blocks must be square with one rhs per row; got {n} rows")
        if num_primal is None:
            num_primal = n - 1 if n > 1 and self.blocks[-1][-1] is None else n
        if not 1 <= num_primal <= n:
            raise ValueError(f"num_primal={num_primal} must lie in [1, {n}]")
        self.num_primal = num_primal
        self.names = [f"field{i}" for i in range(n)] if names is None else list(names)
        if len(self.names) != n:
            raise ValueError(f"names={names!r} must name each of the {n} fields")
        if coordinates is not None and len(coordinates) != num_primal:
            raise ValueError(
                f"coordinates must give the nodes of each of the {num_primal} primal fields, "
                f"got {len(coordinates)} arrays"
            )
        self.coordinates = None if coordinates is None else [np.asarray(c) for c in coordinates]
        self.comm = self.rhs[0].getComm()
        self.nest = PETSc.Mat().createNest(self.blocks, comm=self.comm)
        self.iterations: dict[str, int] = {}
        #: What the last direct solve did (:func:`solve_lu`'s ``stats``), or the iterative one
        #: (its ``seconds``, GAMG set-up included, ``iterations``, the final ``residual``).
        self.stats: dict = {}
        #: The sign of the system's determinant (:meth:`solve_many` with ``sign``), or ``None``.
        self.determinant_sign: float | None = None

    def solve_many(
        self,
        more: Sequence[Sequence[PETSc.Vec]],
        solver: str | SolverOptions = "mumps",
        sign: bool = False,
        kept: KeptFactorisation | None = None,
    ) -> list[list[np.ndarray]]:
        """Solve for :attr:`rhs` and for every right-hand side in ``more`` (one vector per block
        row each), sharing one factorisation with the direct solvers (``"mumps"``,
        ``"mumps-lu"``); other solvers solve them one by one. Returns the owned blocks of each
        solution, :attr:`rhs`'s first (collective). With ``sign``, :attr:`determinant_sign` is
        the sign of the system's determinant where MUMPS factorised it (else ``None``).
        ``kept``: the direct solve's analysis shared with earlier systems (:func:`solve_lu`)."""
        self.determinant_sign = None
        options = solver_options(solver)
        direct = options.solver in ("mumps", "mumps-lu") and options.petsc_options is None
        if not direct or not more:
            out = [self.solve(options, kept=kept)]
            for rhs in more:
                other = BlockSystem(self.blocks, rhs, self.num_primal, self.names, self.coordinates)
                out.append(other.solve(options))
                other.destroy()
            return out
        aij = PETSc.Mat()
        self.nest.convert("aij", aij)
        vecs = []
        for rhs in (self.rhs, *more):
            b = aij.createVecLeft()
            b.setArray(np.concatenate([v.getArray(readonly=True) for v in rhs]))
            vecs.append(b)
        self.stats = {}
        factorisation = "lu" if options.solver == "mumps-lu" else "auto"
        x = solve_lu(
            aij,
            vecs[0],
            factorisation=factorisation,
            stats=self.stats,
            more=vecs[1:],
            sign=sign,
            kept=kept,
        )
        self.determinant_sign = self.stats.get("determinant_sign")
        sizes = np.cumsum([v.getLocalSize() for v in self.rhs])[:-1]
        out = []
        for xi in (x, *self.stats.pop("more")):
            out.append(np.split(xi.getArray(readonly=True).copy(), sizes))
            xi.destroy()
        for obj in (aij, *vecs):
            obj.destroy()
        return out

    def solve(
        self,
        solver: str | SolverOptions = "mumps",
        inner: str = "lu",
        rtol: float = 1e-12,
        kept: KeptFactorisation | None = None,
    ) -> list[np.ndarray]:
        """Solve and return the owned part of each block of the solution (collective).

        Args:
            solver: ``"mumps"``, ``"mumps-lu"``, ``"fieldsplit"``, ``"iterative"`` or
                :class:`SolverOptions` (PETSc options; with ``"iterative"``, changes of
                :data:`ITERATIVE_DEFAULTS`). What the direct or iterative solve did is in
                :attr:`stats`.
            inner: Primal-block solver of the fieldsplit: ``"lu"`` (MUMPS) or ``"gamg"``.
            rtol: Relative tolerance of the fieldsplit's outer FGMRES.
            kept: The direct solve's analysis shared with earlier systems of the same
                sparsity pattern (:func:`solve_lu`); not used by the other solvers.

        Raises:
            RuntimeError: on every rank, when the iterative solve does not converge.
        """
        options = solver_options(solver)
        solver = options.solver
        if inner not in ("lu", "gamg"):
            raise ValueError(f"inner={inner!r} is not known; use 'lu' or 'gamg'")
        augment = solver in ("fieldsplit", "iterative") and (
            options.petsc_options is None or solver == "iterative"
        )
        if augment and self.num_primal < len(self.blocks):
            nest, rhs, owned = self._augmented()
        else:
            nest, rhs, owned = self.nest, self.rhs, []
        aij = PETSc.Mat()
        nest.convert("aij", aij)
        b = aij.createVecLeft()
        b.setArray(np.concatenate([v.getArray(readonly=True) for v in rhs]))
        if solver == "iterative":
            x = self._iterative(aij, b, rhs, options)
        elif options.petsc_options is not None:
            x = self._from_options(aij, b, options)
        elif solver != "fieldsplit" or self.num_primal == len(self.blocks):
            self.stats = {}
            x = solve_lu(
                aij,
                b,
                factorisation="lu" if solver == "mumps-lu" else "auto",
                stats=self.stats,
                kept=kept,
            )
        else:
            x = self._fieldsplit(aij, b, rhs, inner, rtol)
        arr = x.getArray(readonly=True).copy()
        sizes = np.cumsum([v.getLocalSize() for v in self.rhs])[:-1]
        for obj in [aij, b, x, *owned]:
            obj.destroy()
        return np.split(arr, sizes)

    def _iterative(
        self, aij: PETSc.Mat, b: PETSc.Vec, rhs: list[PETSc.Vec], options: SolverOptions
    ) -> PETSc.Vec:
        """``solver="iterative"`` on the (augmented) AIJ system: see the class docstring."""
        p, n = self.num_primal, len(self.blocks)
        gdim = 1 if self.coordinates is None else int(self.coordinates[0].shape[1])
        is_u, is_l, n_primal, n_all = self._split_sets(aij, rhs)
        is_u.setBlockSize(gdim)
        template = PETSc.Vec().createMPI((n_primal, PETSc.DECIDE), bsize=gdim, comm=self.comm)
        objects: list = [is_u, is_l, template]
        if self.coordinates is not None:
            nullspace, vecs = rigid_body_modes(np.concatenate(self.coordinates), template)
            objects += [nullspace, *vecs]
        settings = dict(ITERATIVE_DEFAULTS)
        if p == n:  # no multipliers: the primal block's GAMG on the whole system
            settings = {k: v for k, v in settings.items() if not k.startswith(("pc_", "field"))}
            settings.update(pc_type="gamg", pc_gamg_threshold=0.05)
            aij.setBlockSize(gdim)
        settings.update(options.petsc_options or {})
        prefix = options.prefix or f"dolfinx_meshfree_it_{next(_prefix_counter)}_"
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(aij)
        pc = ksp.getPC()
        t0 = time.perf_counter()
        with scoped_options(prefix, settings):
            ksp.setFromOptions()
            if pc.getType() == PETSc.PC.Type.FIELDSPLIT:
                if self.coordinates is not None:
                    is_u.compose("nearnullspace", nullspace)
                pc.setFieldSplitIS(("u", is_u), ("lambda", is_l))
                Sp = self._schur_identity(n_all - n_primal)
                objects.append(Sp)
                pc.setFieldSplitSchurPreType(PETSc.PC.SchurPreType.USER, Sp)
                ksp.setFromOptions()  # the splits' own options, now that they exist
            elif self.coordinates is not None:
                aij.setNearNullSpace(nullspace)
            x = aij.createVecRight()
            ksp.solve(b, x)
            reason, its = ksp.getConvergedReason(), ksp.getIterationNumber()
            residual = ksp.getResidualNorm()
        self.iterations = {"outer": its}
        self.stats = {"seconds": time.perf_counter() - t0, "iterations": its, "residual": residual}
        pc.destroy()  # see solve_lu
        ksp.destroy()
        for obj in objects:
            obj.destroy()
        if reason < 0:
            raise RuntimeError(
                f"the iterative solve did not converge (KSP reason {reason}, {its} iterations, "
                f"residual {residual:.3e} against |b| = {b.norm():.3e}); raise ksp_max_it in "
                "petsc_options or use solver='mumps'"
            )
        return x

    def _schur_identity(self, n_local: int) -> PETSc.Mat:
        """``-(SCHUR_SCALE / gamma) I`` on the multipliers (:data:`SCHUR_SCALE`)."""
        size = (n_local, PETSc.DECIDE)
        S = PETSc.Mat().createAIJ((size, size), comm=self.comm)
        S.setPreallocationNNZ((1, 0))
        d = S.createVecLeft()
        d.set(-SCHUR_SCALE / self.gamma)
        S.setDiagonal(d)
        S.assemble()
        d.destroy()
        return S

    def _augmented(self) -> tuple[PETSc.Mat, list[PETSc.Vec], list]:
        """The augmented-Lagrangian nest and right-hand side (new objects, listed for cleanup)."""
        p, n = self.num_primal, len(self.blocks)
        blocks = [list(r) for r in self.blocks]
        rhs = list(self.rhs)
        owned: list = []
        products = {}
        for k in range(p, n):
            for i in range(p):
                for j in range(p):
                    Gki, Gkj = self.blocks[k][i], self.blocks[k][j]
                    if Gki is not None and Gkj is not None:
                        products.setdefault((i, j), []).append(Gki.transposeMatMult(Gkj))
        scale_a = max(
            (
                self.blocks[i][i].norm(PETSc.NormType.INFINITY)
                for i in range(p)
                if self.blocks[i][i] is not None
            ),
            default=1.0,
        )
        scale_g = max(
            (M.norm(PETSc.NormType.INFINITY) for ms in products.values() for M in ms), default=1.0
        )
        gamma = scale_a / scale_g if scale_g > 0 else 1.0
        #: The augmented Lagrangian's ``gamma`` of the last fieldsplit or iterative solve.
        self.gamma = gamma
        for (i, j), ms in products.items():
            if blocks[i][j] is None:
                A = ms[0].duplicate(copy=True)
                A.zeroEntries()
            else:
                A = blocks[i][j].copy()
            for M in ms:
                A.axpy(gamma, M, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                M.destroy()
            blocks[i][j] = A
            owned.append(A)
        for i in range(p):
            f = self.rhs[i].copy()
            owned.append(f)
            for k in range(p, n):
                if self.blocks[k][i] is not None:
                    g = self.rhs[k].copy()
                    g.scale(gamma)
                    self.blocks[k][i].multTransposeAdd(g, f, f)
                    g.destroy()
            rhs[i] = f
        nest = PETSc.Mat().createNest(blocks, comm=self.comm)
        owned.append(nest)
        return nest, rhs, owned

    def _split_sets(
        self, aij: PETSc.Mat, rhs: list[PETSc.Vec]
    ) -> tuple[PETSc.IS, PETSc.IS, int, int]:
        """The owned rows of the primal fields and of the multipliers in the AIJ system, as
        index sets ``(is_u, is_l)``, and this rank's primal and total row counts."""
        sizes = [v.getLocalSize() for v in rhs]
        n_primal, n_all = int(sum(sizes[: self.num_primal])), int(sum(sizes))
        start = aij.getOwnershipRange()[0]
        idx = np.arange(start, start + n_all, dtype=PETSc.IntType)
        is_u = PETSc.IS().createGeneral(idx[:n_primal], comm=self.comm)
        is_l = PETSc.IS().createGeneral(idx[n_primal:], comm=self.comm)
        return is_u, is_l, n_primal, n_all

    def _fieldsplit(self, aij, b, rhs, inner: str, rtol: float) -> PETSc.Vec:
        is_u, is_l = self._split_sets(aij, rhs)[:2]
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOptionsPrefix(f"dolfinx_meshfree_fs_{next(_prefix_counter)}_")
        ksp.setOperators(aij)
        ksp.setType(PETSc.KSP.Type.FGMRES)
        ksp.setTolerances(rtol=rtol, atol=0.0, max_it=200)
        pc = ksp.getPC()
        pc.setType(PETSc.PC.Type.FIELDSPLIT)
        pc.setFieldSplitIS(("u", is_u), ("lambda", is_l))
        pc.setFieldSplitType(PETSc.PC.CompositeType.SCHUR)
        pc.setFieldSplitSchurFactType(PETSc.PC.SchurFactType.FULL)
        pc.setFieldSplitSchurPreType(PETSc.PC.SchurPreType.SELFP)
        ksp.setUp()
        k_u, k_s = pc.getFieldSplitSubKSP()
        if inner == "lu":
            k_u.setType(PETSc.KSP.Type.PREONLY)
            k_u.getPC().setType(PETSc.PC.Type.LU)
            k_u.getPC().setFactorSolverType("mumps")
        else:
            k_u.setType(PETSc.KSP.Type.CG)
            k_u.setTolerances(rtol=1e-12)
            k_u.getPC().setType(PETSc.PC.Type.GAMG)
        k_u.getPC().setUp()
        k_s.setType(PETSc.KSP.Type.GMRES)
        k_s.setTolerances(rtol=1e-12)
        k_s.getPC().setType(PETSc.PC.Type.JACOBI)
        x = aij.createVecRight()
        ksp.solve(b, x)
        reason = ksp.getConvergedReason()
        self.iterations = {"outer": ksp.getIterationNumber(), "schur": k_s.getIterationNumber()}
        pc.destroy()  # see solve_lu
        ksp.destroy()
        is_u.destroy()
        is_l.destroy()
        if reason < 0:
            raise RuntimeError(
                f"the fieldsplit solve did not converge (KSP reason {reason}, "
                f"{self.iterations['outer']} iterations); use solver='mumps'"
            )
        return x

    def _from_options(self, aij: PETSc.Mat, b: PETSc.Vec, options: SolverOptions) -> PETSc.Vec:
        """A KSP configured from ``options.petsc_options`` under its prefix, with the nest's
        fields as named index sets for a fieldsplit; the options are removed afterwards. What
        cannot solve the system is refused before (:func:`check_factor_package`), and a
        ``preonly`` solve that did not solve it after (:func:`check_preonly`)."""
        saddle = self.num_primal < len(self.blocks)
        check_factor_package(options.petsc_options or {}, saddle)
        prefix = options.prefix or f"dolfinx_meshfree_{next(_prefix_counter)}_"
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(aij)
        with scoped_options(prefix, options.petsc_options):
            ksp.setFromOptions()
            pc = ksp.getPC()
            ises = []
            if pc.getType() == PETSc.PC.Type.FIELDSPLIT:
                ises = list(self.nest.getNestISs()[0])
                pc.setFieldSplitIS(*zip(self.names, ises, strict=True))
                ksp.setFromOptions()  # the split's own options, now that its fields exist
            x = aij.createVecRight()
            try:
                ksp.solve(b, x)
            except PETSc.Error as err:  # e.g. a zero pivot of an LU that does not pivot
                failed = err
            else:
                failed = None
            reason, its = ksp.getConvergedReason(), ksp.getIterationNumber()
        self.iterations = {"ksp": its}
        pc.destroy()  # see solve_lu
        ksp.destroy()
        for iset in ises:
            iset.destroy()
        given = dict(options.petsc_options or {})
        if failed is not None:
            raise RuntimeError(
                f"PETSc failed in the solve with petsc_options={given!r} ({failed}){SADDLE_HINT}"
                if saddle
                else f"PETSc failed in the solve with petsc_options={given!r} ({failed})"
            ) from failed
        if reason < 0:
            mumps = given.get("pc_factor_mat_solver_type") == "mumps"
            hint = (
                " (MUMPS's factorisation failed: a saddle point may need more workspace than it "
                "plans, 'mat_mumps_icntl_14': 100 as solver='mumps' gives it)"
                if mumps and reason == PETSc.KSP.ConvergedReason.DIVERGED_PCSETUP_FAILED
                else ""
            )
            raise RuntimeError(
                f"the KSP of petsc_options={given!r} did not converge (KSP reason "
                f"{_REASONS.get(reason, reason)}, {its} iterations){hint}"
                + (SADDLE_HINT if saddle else "")
            )
        check_preonly(aij, b, x, given)
        return x

    def destroy(self) -> None:
        self.nest.destroy()
