"""Compiled block products ``y = K x`` for the explicit step.

An explicit step is the stiffness product ``f^int = K d`` of every field and little else
(Belytschko et al. 1995, eq. 4.4; Rabczuk et al. 2006, eq. 86): 84-93 % of a step of the
Gaussian-pulse rod (``demos/rod_gauss.py``, 20k nodes, one rank). PETSc's BAIJ product of the
Debian build (PETSc 3.18, compiled for a generic x86-64) moves about 6 GB/s on these machines
at every size, 35-40 % of one core's STREAM triad (16 GB/s; ``benchmarks/bench_bandwidth.py``).
A block-row product compiled by numba for the machine it runs on, with the block size a
compile-time constant, multiplies the same blocks 2.7-3.9x faster while they stay in the
480 MB cache, and 1.4x faster for a 264 MB EFG matrix (the same benchmark, one run).

:class:`CompiledProduct` keeps a copy of a PETSc matrix's owned rows in block compressed rows
(BSR, the blocks ``gdim x gdim`` of node-interleaved dofs ``gdim * node + component``), split as
PETSc splits an MPI matrix: the columns this rank owns (the diagonal part) and the ghost
columns, whose values come through a PETSc scatter (no hand-written messaging). It is rebuilt
whenever the matrix changes: PETSc raises a matrix's state at every change (assembly, ``axpy``,
``scale``, ...), and each product compares it, so a copy is never stale (a crack's local update
of the particle stiffness, :mod:`~dolfinx_meshfree.dynamics.growth_local`, rebuilds it).
Blocks of exact zeros are left out of the copy (:func:`_pruned`): a coupled model's FE block
stores the cells under the patch, which its form does not integrate, as zeros.

The kernels sum a block row in the order of PETSc's BAIJ product, the owned columns first and
the ghost columns after: explicit runs agree with PETSc's to the last bit, serially and on 2
ranks (``tests/test_compiled_product.py``); against AIJ only the summation order differs
(round-off). IEEE semantics are kept (no ``fastmath``, as every kernel of
:mod:`~dolfinx_meshfree.approx.jit`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from ..approx import jit

__all__ = [
    "BLOCK_SIZES",
    "PRODUCTS",
    "PRODUCT_ENV",
    "CompiledProduct",
    "blockable",
    "multiply",
    "resolve_product",
]

#: The products of :class:`~dolfinx_meshfree.dynamics.system.LinearSystem`: ``"numba"`` (this
#: module's; the default with numba) and ``"petsc"`` (PETSc's ``MatMult``, the reference).
PRODUCTS = ("numba", "petsc")
#: The environment variable that selects the default product (e.g. ``petsc``, to run a test
#: suite on the reference product).
PRODUCT_ENV = "DOLFINX_MESHFREE_PRODUCT"
#: The block sizes with a compiled kernel (2D and 3D); other matrices keep PETSc's product.
BLOCK_SIZES = (2, 3)


def resolve_product(product: str | None) -> str:
    """``product``, or the default (``$DOLFINX_MESHFREE_PRODUCT``, else ``"numba"`` with numba,
    else ``"petsc"``), checked.

    Raises:
        ValueError: an unknown product, or ``"numba"`` without numba.
    """
    name = product if product is not None else jit.default_backend(PRODUCT_ENV, "petsc")
    return jit.resolve_backend(name, PRODUCT_ENV, PRODUCTS, argument="product")


def blockable(A: PETSc.Mat, bs: int) -> bool:
    """Whether ``A`` can be multiplied in ``bs x bs`` blocks: ``bs`` has a kernel
    (:data:`BLOCK_SIZES`) and every rank's row and column ranges start and end on whole blocks
    (collective: the same answer on every rank)."""
    (rl, _), (cl, _) = A.getSizes()
    r0, c0 = A.getOwnershipRange()[0], A.getOwnershipRangeColumn()[0]
    whole = bs in BLOCK_SIZES and all(v % bs == 0 for v in (rl, cl, r0, c0))
    return bool(A.getComm().tompi4py().allreduce(whole, op=MPI.LAND))


@jit.jit
def _bsr2(indptr, indices, data, x, y, add):  # pragma: no cover - compiled
    """``y (+)= A x`` for a BSR matrix of 2 x 2 blocks (``data`` flat, block rows row-major)."""
    for i in range(indptr.size - 1):
        s0 = y[2 * i] if add else 0.0
        s1 = y[2 * i + 1] if add else 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = 2 * indices[k]
            x0 = x[j]
            x1 = x[j + 1]
            s0 += data[4 * k] * x0 + data[4 * k + 1] * x1
            s1 += data[4 * k + 2] * x0 + data[4 * k + 3] * x1
        y[2 * i] = s0
        y[2 * i + 1] = s1


@jit.jit
def _bsr3(indptr, indices, data, x, y, add):  # pragma: no cover - compiled
    """``y (+)= A x`` for a BSR matrix of 3 x 3 blocks (``data`` flat, block rows row-major)."""
    for i in range(indptr.size - 1):
        s0 = y[3 * i] if add else 0.0
        s1 = y[3 * i + 1] if add else 0.0
        s2 = y[3 * i + 2] if add else 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = 3 * indices[k]
            x0 = x[j]
            x1 = x[j + 1]
            x2 = x[j + 2]
            b = 9 * k
            s0 += data[b] * x0 + data[b + 1] * x1 + data[b + 2] * x2
            s1 += data[b + 3] * x0 + data[b + 4] * x1 + data[b + 5] * x2
            s2 += data[b + 6] * x0 + data[b + 7] * x1 + data[b + 8] * x2
        y[3 * i] = s0
        y[3 * i + 1] = s1
        y[3 * i + 2] = s2


_KERNELS = {2: _bsr2, 3: _bsr3}


@jit.jit
def _whole_blocks(ai, aj, bs, c0, cl):  # pragma: no cover - compiled
    """Whether the scalar CSR ``(ai, aj)`` (sorted rows) stores whole ``bs x bs`` blocks: the
    ``bs`` rows of each block row hold the same columns, in runs of ``bs`` that start on a
    block. Returns ``(whole, diagonal blocks per block row, ghost blocks per block row)``,
    the ghost blocks being those outside the owned columns ``[c0, c0 + cl)``."""
    nb = (ai.size - 1) // bs
    diag = np.zeros(nb, np.int64)
    off = np.zeros(nb, np.int64)
    for i in range(nb):
        s0 = ai[bs * i]
        n = ai[bs * i + 1] - s0
        if n % bs != 0:
            return False, diag, off
        for r in range(1, bs):
            if ai[bs * i + r + 1] - ai[bs * i + r] != n:
                return False, diag, off
        for k in range(0, n, bs):
            col = aj[s0 + k]
            if col % bs != 0:
                return False, diag, off
            for r in range(bs):
                sr = ai[bs * i + r] + k
                for c in range(bs):
                    if aj[sr + c] != col + c:
                        return False, diag, off
            if c0 <= col < c0 + cl:
                diag[i] += 1
            else:
                off[i] += 1
    return True, diag, off


@jit.jit
def _fill_blocks(  # pragma: no cover - compiled
    ai, aj, av, bs, c0, cl, gnodes, dptr, dind, ddata, optr, oind, odata
):
    """Copy the whole blocks of ``(ai, aj, av)`` (:func:`_whole_blocks`) into the diagonal BSR
    part (local block columns) and the ghost part (positions in ``gnodes``), in place."""
    nb = (ai.size - 1) // bs
    bb = bs * bs
    for i in range(nb):
        s0 = ai[bs * i]
        n = ai[bs * i + 1] - s0
        kd = dptr[i]
        ko = optr[i]
        for k in range(0, n, bs):
            col = aj[s0 + k]
            if c0 <= col < c0 + cl:
                dind[kd] = (col - c0) // bs
                data, b = ddata, bb * kd
                kd += 1
            else:
                oind[ko] = np.searchsorted(gnodes, col // bs)
                data, b = odata, bb * ko
                ko += 1
            for r in range(bs):
                sr = ai[bs * i + r] + k
                for c in range(bs):
                    data[b + bs * r + c] = av[sr + c]


def _bsr(
    rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, shape: tuple[int, int], bs: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, block columns, flat block values)`` of the entries ``(rows, cols, vals)`` in
    ``bs x bs`` blocks (zeros inside a stored block are stored), indices as int32 where they fit."""
    m = sp.csr_matrix((vals, (rows, cols)), shape=shape).tobsr(blocksize=(bs, bs))
    m.sort_indices()
    itype = np.int32 if max(m.indices.size, shape[1]) < np.iinfo(np.int32).max else np.int64
    return (
        m.indptr.astype(itype),
        m.indices.astype(itype),
        np.ascontiguousarray(m.data, dtype=np.float64).reshape(-1),
    )


def _pruned(
    part: tuple[np.ndarray, np.ndarray, np.ndarray], bs: int
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], int]:
    """The BSR ``part`` without its blocks of exact zeros, and how many were dropped. A stored
    zero block adds ``0 * x = +-0`` to its row's sum, which changes no sum but the sign of an
    exact zero: the products are PETSc's to the bit without them (a NaN is not zero, and is
    kept). DOLFINx stores such blocks where a form integrates only part of the mesh: the FE
    block of a coupled model holds the cells under the patch as zeros (45 % of its entries in
    Kalthoff-Winkler's lagrange box at 101 x 101 nodes)."""
    indptr, indices, data = part
    keep = np.any(data.reshape(indices.size, bs * bs) != 0.0, axis=1)
    dropped = int(indices.size - np.count_nonzero(keep))
    if dropped == 0:
        return part, 0
    kept = np.zeros(indices.size + 1, np.int64)
    np.cumsum(keep, out=kept[1:])
    new_ptr = kept[indptr].astype(indptr.dtype)
    values = data.reshape(indices.size, bs * bs)[keep].reshape(-1)
    return (new_ptr, np.ascontiguousarray(indices[keep]), np.ascontiguousarray(values)), dropped


def _ghost_nodes(
    ai: np.ndarray, aj: np.ndarray, bs: int, c0: int, cl: int, count: int
) -> np.ndarray:
    """The sorted global nodes of the ghost blocks of whole-block CSR arrays (the first row
    of each block row holds every block's first column)."""
    if count == 0:
        return np.zeros(0, np.int64)
    first = np.zeros(ai.size - 1, bool)
    first[::bs] = True
    starts = np.repeat(first, np.diff(ai))  # the entries of each block row's first row
    cols = aj[starts]
    cols = cols[(cols % bs == 0) & ((cols < c0) | (cols >= c0 + cl))]
    return np.unique(cols.astype(np.int64) // bs)


def _empty_parts(
    dcount: np.ndarray, ocount: np.ndarray, bs: int, width: int
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """The arrays of the diagonal and ghost BSR parts with these blocks per block row, to be
    filled by :func:`_fill_blocks` (indices as int32 where they fit)."""
    parts = []
    for count in (dcount, ocount):
        total = int(count.sum())
        itype = np.int32 if max(total, width) < np.iinfo(np.int32).max else np.int64
        indptr = np.zeros(count.size + 1, itype)
        np.cumsum(count, out=indptr[1:])
        parts.append((indptr, np.zeros(total, itype), np.zeros(total * bs * bs)))
    return parts[0], parts[1]


class CompiledProduct:
    """``y = A x`` and ``y += A x`` for a PETSc matrix ``A`` of node-interleaved ``bs x bs``
    blocks (:func:`blockable`), by the compiled block-row kernels of this module.

    The copy of ``A`` is made at the first product and again after every change of ``A``
    (PETSc's object state), on every rank together. ``A`` stays the caller's: this object
    never changes or destroys it.

    Args:
        A: An assembled AIJ or BAIJ matrix (owned rows; its columns laid out as the vectors it
            multiplies).
        bs: The block size (the geometric dimension), one of :data:`BLOCK_SIZES`.
    """

    def __init__(self, A: PETSc.Mat, bs: int) -> None:
        if bs not in BLOCK_SIZES:
            raise ValueError(f"bs={bs} has no compiled kernel; use one of {BLOCK_SIZES}")
        self.A = A
        self.bs = bs
        self._comm = A.getComm().tompi4py()
        self._state: int | None = None
        self._diag: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._off: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._ghosts: PETSc.Vec | None = None
        self._scatter: PETSc.Scatter | None = None
        self.dropped_blocks = 0

    def local_flags(self, x: PETSc.Vec, y: PETSc.Vec) -> int:
        """This rank's view of a product with ``x`` and ``y`` (no collective call): bit 0, the
        copy must be rebuilt (``A`` changed since it was made); bit 1, ``x`` or ``y`` not laid
        out as ``A``'s columns and rows, or ``y`` the same vector as ``x`` (the kernels do not
        check bounds). :func:`multiply` combines them over the ranks, rebuilds the stale copies
        together (the scatter is collective) and raises :meth:`layout_error` on every rank."""
        (rl, _), (cl, _) = self.A.getSizes()
        sizes = (x.getLocalSize(), y.getLocalSize())
        bad = sizes != (cl, rl) or x.handle == y.handle
        return int(self._state != self.A.stateGet()) | 2 * int(bad)

    def layout_error(self, x: PETSc.Vec, y: PETSc.Vec) -> ValueError:
        """The error of a product whose ``x`` or ``y`` is laid out wrong on some rank."""
        (rl, _), (cl, _) = self.A.getSizes()
        return ValueError(
            f"a compiled product y = A x needs x with A's {self.A.getSize()[1]} columns and "
            f"a different y with its {self.A.getSize()[0]} rows, laid out alike on every "
            f"rank; got local sizes x {x.getLocalSize()}, y {y.getLocalSize()} on some rank "
            f"(this rank: A {rl} x {cl}); create them with A.createVecs()"
        )

    def _build(self) -> None:
        """Copy ``A``'s owned rows into the diagonal and ghost BSR parts and make the scatter
        of the ghost values (collective)."""
        A, bs = self.A, self.bs
        self._free_scatter()
        (rl, _), (cl, _) = A.getSizes()
        c0 = A.getOwnershipRangeColumn()[0]
        ai, aj, av = A.getValuesCSR()  # owned rows, global columns
        whole, dcount, ocount = _whole_blocks(ai, aj, bs, c0, cl)
        if whole:  # (BAIJ, the default of LinearSystem) copied block by block, in place
            gnodes = _ghost_nodes(ai, aj, bs, c0, cl, int(ocount.sum()))
            self._diag, self._off = _empty_parts(dcount, ocount, bs, max(cl, bs * gnodes.size))
            _fill_blocks(ai, aj, av, bs, c0, cl, gnodes, *self._diag, *self._off)
        else:  # blocks with entries missing (AIJ): through scipy
            rows = np.repeat(np.arange(rl), np.diff(ai))
            aj = aj.astype(np.int64)
            own = (aj >= c0) & (aj < c0 + cl)
            self._diag = _bsr(rows[own], aj[own] - c0, av[own], (rl, cl), bs)
            gnodes = np.unique(aj[~own] // bs)
            gcol = np.searchsorted(gnodes, aj[~own] // bs) * bs + aj[~own] % bs
            self._off = _bsr(rows[~own], gcol, av[~own], (rl, gnodes.size * bs), bs)
        del ai, aj, av
        self._diag, dropped_diag = _pruned(self._diag, bs)
        self._off, dropped_off = _pruned(self._off, bs)
        #: the blocks of exact zeros ``A`` stores on this rank and the copy does not (owned and
        #: ghost columns; :func:`_pruned`)
        self.dropped_blocks = dropped_diag + dropped_off
        if self._comm.size > 1:  # collective, also on a rank without ghosts
            ghost = (gnodes[:, None] * bs + np.arange(bs)).ravel().astype(PETSc.IntType)
            self._ghosts = PETSc.Vec().createSeq(ghost.size, comm=PETSc.COMM_SELF)
            index = PETSc.IS().createGeneral(ghost, comm=PETSc.COMM_SELF)
            x = A.createVecRight()
            self._scatter = PETSc.Scatter().create(x, index, self._ghosts, None)
            index.destroy()
            x.destroy()
        self._state = A.stateGet()

    def _product(self, x: PETSc.Vec, y: PETSc.Vec, add: bool) -> None:
        """One product, checked on every rank and rebuilt if stale (:func:`multiply`)."""
        multiply([(self, x, y, add)], self._comm)

    def _run(self, x: PETSc.Vec, y: PETSc.Vec, add: bool) -> None:
        """The product on a checked, current copy (collective: the ghost scatter)."""
        kernel = _KERNELS[self.bs]
        mode = (PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        if self._scatter is not None:
            self._scatter.begin(x, self._ghosts, *mode)
        ya = y.array
        kernel(*self._diag, x.array_r, ya, add)
        if self._scatter is not None:
            self._scatter.end(x, self._ghosts, *mode)
            kernel(*self._off, self._ghosts.array_r, ya, True)

    def mult(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """``y = A x`` (collective)."""
        self._product(x, y, False)

    def mult_add(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """``y = y + A x`` (collective)."""
        self._product(x, y, True)

    def _free_scatter(self) -> None:
        for obj in (self._scatter, self._ghosts):
            if obj is not None:
                obj.destroy()
        self._scatter = self._ghosts = None

    def destroy(self) -> None:
        """Free the scatter and the copy (collective); ``A`` is left alone."""
        self._free_scatter()
        self._diag = self._off = None
        self._state = None


def multiply(
    products: Sequence[tuple[CompiledProduct | PETSc.Mat, PETSc.Vec, PETSc.Vec, bool]],
    comm: MPI.Comm,
) -> None:
    """``y = A x`` (``add`` false) or ``y += A x`` for each ``(A, x, y, add)`` in order, with
    one collective check for all of them instead of one per product (collective).

    An entry's ``A`` is a :class:`CompiledProduct`, or a PETSc matrix multiplied by PETSc. The
    compiled products' :meth:`~CompiledProduct.local_flags` are combined over the ranks in one
    ``Allreduce``: a layout error is raised on every rank before any product, and the stale
    copies are rebuilt together. The products are then taken in the given order, each as
    :meth:`CompiledProduct.mult` would take it: the same result to the bit. On 2 ranks an
    explicit step of a coupled model multiplies 2-4 blocks, and one check instead of one per
    block is what this saves.

    Raises:
        ValueError: on every rank, some ``x`` or ``y`` laid out wrong
            (:meth:`CompiledProduct.layout_error`).
    """
    compiled = [(i, p) for i, p in enumerate(products) if isinstance(p[0], CompiledProduct)]
    flags = np.array([prod.local_flags(x, y) for _, (prod, x, y, _) in compiled], np.int64)
    if comm.size > 1 and flags.size:
        comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.BOR)
    for (_, (prod, x, y, _)), f in zip(compiled, flags, strict=True):
        if f & 2:
            raise prod.layout_error(x, y)
    for (_, (prod, _, _, _)), f in zip(compiled, flags, strict=True):
        if f & 1:
            prod._build()
    for A, x, y, add in products:
        if isinstance(A, CompiledProduct):
            A._run(x, y, add)
        elif add:
            A.multAdd(x, y, y)
        else:
            A.mult(x, y)
