"""Compiled MLS kernel: moment matrix, its inverse and the shape functions, one point at a time.

For each evaluation point ``x`` with pairs sorted by point (the CSR layout of the table), it
evaluates Belytschko et al. 1995, eq. (3.7a) and (3.9) in the basis shifted to ``x`` and scaled
by ``s`` (see :mod:`.mls`), ``p_I = p((x_I - x)/s)``:

.. math::
    A = \\sum_I w_I p_I p_I^T, \\quad A \\gamma = e_1, \\quad \\phi_I = w_I p_I^T \\gamma,

and the derivatives ``\\phi_{I,k} = w_I p_I^T C_k + w_{I,k} p_I^T \\gamma`` with
``C_k = \\gamma_{,k} - D_k^T \\gamma / s``, where ``D_k`` is the constant matrix with
``dp/d\\xi_k = D_k p`` (:func:`derivative_matrices`). From ``A_{,k} = \\sum_I w_{I,k} p_I p_I^T
- (D_k A + A D_k^T)/s`` and ``\\gamma_{,k} = -A^{-1} A_{,k} \\gamma`` with ``A \\gamma = e_1``,
the terms with ``D_k^T \\gamma`` cancel:

.. math::
    C_k = A^{-1} u_k, \\quad u_k = D_k e_1 / s - \\sum_I w_{I,k} p_I (p_I^T \\gamma),

so that a point needs the sums of ``A`` (one pass over its pairs), then ``p_I^T \\gamma`` and
``u_k`` (a second pass, with the values), then the gradients (a third): about half the
arithmetic of summing every ``A_{,k}``. The weights ``w(dist / d_I)`` and
``w_{I,k} = w'(r)/d_I \\, dist_{,k}`` are evaluated from the (possibly cut) distances and
distance gradients of the pairs. The small matrices live on the stack
(:func:`~.jit.stack_pointer`), where LLVM keeps them in registers.

The inverse is computed from the ``L D L^T`` factors of the symmetric ``A`` (no pivoting: ``A``
is positive definite where it is accepted). For the conditioning check the kernel returns a lower
bound of the eigenvalue ratio of ``A``, ``1 / (tr A \\, tr A^{-1})`` (it is within a factor
``m^2`` of the ratio for a symmetric positive definite ``A`` of size m): where the bound is above
``rcond`` the point is accepted; elsewhere ``A`` is returned for the exact ``eigvalsh`` check of
:class:`~dolfinx_meshfree.approx.mls.MLS`.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import jit
from .cell_lists import CellList
from .kernels import cubic_inner_piece, cubic_outer_piece, gaussian_piece, quartic_piece

__all__ = [
    "WEIGHT_IDS",
    "count_pairs",
    "derivative_matrices",
    "fill_shape_functions",
    "mls_shape_functions",
    "monomial_exponents",
    "tabulate_cells",
]

#: The weights of :data:`~dolfinx_meshfree.approx.kernels.WEIGHTS` by kernel code.
WEIGHT_IDS = {"gaussian": 0, "cubic": 1, "quartic": 2}

_gaussian = jit.jit(gaussian_piece)
_cubic_inner = jit.jit(cubic_inner_piece)
_cubic_outer = jit.jit(cubic_outer_piece)
_quartic = jit.jit(quartic_piece)


def monomial_exponents(gdim: int, order: int) -> np.ndarray:
    """Exponents (m, gdim) of the monomials of the basis, in the order of
    :func:`~dolfinx_meshfree.approx.mls.polynomial_basis`: ``1, x, y(, z)`` then
    ``x^2, xy, y^2`` for the 2D quadratic basis."""
    rows = [[0] * gdim] + [[int(d == k) for d in range(gdim)] for k in range(gdim)]
    if order == 2 and gdim == 2:
        rows += [[2, 0], [1, 1], [0, 2]]
    elif order != 1:
        raise ValueError(
            f"basis of order {order} in {gdim}D is not supported; use linear or 2D quadratic"
        )
    return np.array(rows, dtype=np.int64)


def derivative_matrices(exponents: np.ndarray) -> np.ndarray:
    """``D`` (gdim, m, m) with ``dp/dxi_k = D_k p`` for the monomials of ``exponents`` (m, gdim):
    ``D_k[a, b] = e_ak`` where monomial ``b`` is monomial ``a`` with ``e_ak`` lowered by one."""
    m, gdim = exponents.shape
    index = {tuple(e): b for b, e in enumerate(exponents.tolist())}
    D = np.zeros((gdim, m, m))
    for k in range(gdim):
        for a, e in enumerate(exponents.tolist()):
            if e[k] > 0:
                lowered = list(e)
                lowered[k] -= 1
                D[k, a, index[tuple(lowered)]] = e[k]
    return D


@jit.jit
def _weight(kind: int, r: float) -> tuple[float, float]:
    """``(w, dw/dr)`` of weight ``kind`` (:data:`WEIGHT_IDS`), zero outside ``r <= 1``."""
    if not r <= 1.0:
        return 0.0, 0.0
    if kind == 0:
        return _gaussian(r)
    if kind == 1:
        if r <= 0.5:
            return _cubic_inner(r)
        return _cubic_outer(r)
    return _quartic(r)


@jit.jit
def _inverse(A: np.ndarray, Ainv: np.ndarray, nb: int) -> None:
    """``Ainv = A^-1`` of the symmetric ``nb x nb`` matrix ``A`` by its ``L D L^T`` factors (no
    pivoting: ``A`` is positive definite or rejected by the conditioning check; inf/nan if
    singular). The factors live on the stack (``nb <= 8``)."""
    L = jit.carray(jit.stack_pointer(64), (8, 8))  # unit lower triangle, below the diagonal
    X = jit.carray(jit.stack_pointer(64), (8, 8))  # L^-1
    dd = jit.carray(jit.stack_pointer(8), (8,))  # D
    inv_d = jit.carray(jit.stack_pointer(8), (8,))  # D^-1
    for j in range(nb):
        dj = A[j, j]
        for k in range(j):
            dj -= L[j, k] * L[j, k] * dd[k]
        dd[j] = dj
        inv_d[j] = 1.0 / dj
        for i in range(j + 1, nb):
            acc = A[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k] * dd[k]
            L[i, j] = acc * inv_d[j]
    for j in range(nb):  # X = L^-1 by forward substitution, column j
        for i in range(nb):
            if i < j:
                X[i, j] = 0.0
            elif i == j:
                X[i, j] = 1.0
            else:
                acc = 0.0
                for k in range(j, i):
                    acc -= L[i, k] * X[k, j]
                X[i, j] = acc
    for a in range(nb):  # A^-1 = X^T D^-1 X
        for b in range(a, nb):
            acc = 0.0
            for k in range(b, nb):
                acc += X[k, a] * X[k, b] * inv_d[k]
            Ainv[a, b] = acc
            Ainv[b, a] = acc


@jit.jit
def _point(
    cnt: int,
    a0: int,
    dx: np.ndarray,
    dist: np.ndarray,
    ddist: np.ndarray,
    rho: np.ndarray,
    kind: int,
    exponents: tuple,
    D: np.ndarray,
    s: float,
    derivatives: bool,
    work: np.ndarray,
    phi: np.ndarray,
    dphi: np.ndarray,
    o0: int,
    Aout: np.ndarray,
    q: int,
) -> float:
    """Shape functions of one point from its ``cnt`` pairs (rows ``a0 ...`` of ``dx``, ``dist``,
    ``ddist`` and ``rho``, the support radius of each pair's particle) into ``phi[o0 ...]`` and
    ``dphi[:, o0 ...]``; its moment matrix into ``Aout[q]``. ``work``: scratch (>= cnt,
    2 + gdim + nb). Returns the bound ``1 / (tr A tr A^-1)`` of the eigenvalue ratio (0 where
    ``A`` is singular or indefinite).

    Three passes over the pairs: ``A``; then the values and ``u_k``; then the gradients (see
    the module docstring). The matrices live on the stack (``nb <= 8``, ``gdim <= 3``)."""
    # the basis as a tuple of tuples: its sizes are compile-time constants (loops unrolled)
    nb = len(exponents)
    g = len(exponents[0])
    inv_s = 1.0 / s
    A = jit.carray(jit.stack_pointer(64), (8, 8))
    Ainv = jit.carray(jit.stack_pointer(64), (8, 8))
    u = jit.carray(jit.stack_pointer(24), (3, 8))
    C = jit.carray(jit.stack_pointer(24), (3, 8))
    p = jit.carray(jit.stack_pointer(8), (8,))
    ip, ig = 1 + g, 1 + g + nb  # columns of work: w, w_,k (g), p_I (nb), p_I^T gamma
    for a in range(nb):
        for b in range(nb):
            A[a, b] = 0.0
    for t in range(cnt):  # weights, basis and moment matrix, eq. (3.7a)
        inv_rho = 1.0 / rho[a0 + t]
        w, dwdr = _weight(kind, dist[a0 + t] * inv_rho)
        f = dwdr * inv_rho
        if nb == g + 1:
            p[0] = 1.0
            for d in range(g):
                p[1 + d] = -dx[a0 + t, d] * inv_s
        else:
            for a in range(nb):
                val = 1.0
                for d in range(g):
                    for _ in range(exponents[a][d]):
                        val *= -dx[a0 + t, d] * inv_s
                p[a] = val
        work[t, 0] = w
        for d in range(g):
            work[t, 1 + d] = f * ddist[a0 + t, d]
        for a in range(nb):
            work[t, ip + a] = p[a]
            wa = w * p[a]
            for b in range(a, nb):
                A[a, b] += wa * p[b]
    for a in range(nb):
        for b in range(a):
            A[a, b] = A[b, a]
        for b in range(nb):
            Aout[q, a, b] = A[a, b]
    _inverse(A, Ainv, nb)
    tr_a = 0.0
    tr_inv = 0.0
    for a in range(nb):
        tr_a += A[a, a]
        tr_inv += Ainv[a, a]
    lb = 1.0 / (tr_a * tr_inv)
    bound = lb if (tr_inv > 0.0 and lb > 0.0 and lb <= 1.0) else 0.0
    for d in range(g):  # u_k = D_k e_1 / s - sum_I w_I,k p_I p_I^T gamma
        for a in range(nb):
            u[d, a] = D[d, a, 0] * inv_s
    for t in range(cnt):  # values, eq. (3.9), gamma = A^-1 e_1
        pg = 0.0
        for a in range(nb):
            pg += work[t, ip + a] * Ainv[a, 0]
        phi[o0 + t] = work[t, 0] * pg
        work[t, ig] = pg
        if derivatives:
            for d in range(g):
                wpg = work[t, 1 + d] * pg
                for a in range(nb):
                    u[d, a] -= wpg * work[t, ip + a]
    if derivatives:
        for d in range(g):  # C_k = A^-1 u_k
            for a in range(nb):
                acc = 0.0
                for b in range(nb):
                    acc += Ainv[a, b] * u[d, b]
                C[d, a] = acc
        for t in range(cnt):  # phi_I,k = w_I p_I^T C_k + w_I,k p_I^T gamma
            for d in range(g):
                pc = 0.0
                for a in range(nb):
                    pc += work[t, ip + a] * C[d, a]
                dphi[d, o0 + t] = work[t, 0] * pc + work[t, 1 + d] * work[t, ig]
    return bound


@jit.jit
def mls_shape_functions(
    indptr: np.ndarray,
    j: np.ndarray,
    dx: np.ndarray,
    dist: np.ndarray,
    ddist: np.ndarray,
    radii: np.ndarray,
    kind: int,
    exponents: tuple,
    D: np.ndarray,
    s: float,
    derivatives: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """MLS shape functions of the given pairs of ``len(indptr) - 1`` points (CSR layout).

    Args:
        indptr: Pair offsets per point (m + 1,).
        j, dx, dist, ddist: Per pair: particle index, ``x_i - x_I`` (npairs, gdim), the distance
            entering the weight and its gradient (npairs, gdim).
        radii: Support radii of all particles (n,).
        kind: Weight code (:data:`WEIGHT_IDS`).
        exponents: Monomial exponents, a tuple of ``nb`` tuples of ``gdim`` ints (tuples, so
            that numba compiles one kernel per basis with constant loop bounds); ``D``:
            derivative matrices (gdim, nb, nb).
        s: Length scale of the basis.
        derivatives: Whether to compute the gradients.

    Returns:
        ``(phi, dphi, bound, A)``: values (npairs,), gradients (gdim, npairs) (none without
        derivatives), the lower bound ``1 / (tr A tr A^-1)`` of the eigenvalue ratio per point
        (m,; 0 where ``A`` is singular or indefinite) and the moment matrices (m, nb, nb), which
        the caller checks exactly where the bound is not above its ``rcond``.
    """
    m = indptr.size - 1
    nb = len(exponents)
    g = len(exponents[0])
    kmax = 0
    for q in range(m):
        kmax = max(kmax, indptr[q + 1] - indptr[q])
    phi = np.empty(dist.size)
    dphi = np.empty((g if derivatives else 0, dist.size))
    bound = np.empty(m)
    Aout = np.empty((m, nb, nb))
    work = np.empty((kmax, 2 + g + nb))
    rho = np.empty(dist.size)
    for t in range(dist.size):
        rho[t] = radii[j[t]]
    for q in range(m):
        a0 = indptr[q]
        bound[q] = _point(
            indptr[q + 1] - a0, a0, dx, dist, ddist, rho, kind, exponents, D, s, derivatives,
            work, phi, dphi, a0, Aout, q,
        )  # fmt: skip
    return phi, dphi, bound, Aout


@jit.jit
def _candidates_of(
    xq: np.ndarray, c0: int, c1: int, cpacked: np.ndarray, sel: np.ndarray, ss: np.ndarray
) -> int:
    """The candidates ``c0 .. c1 - 1`` of a group passing the cheap test for the point ``xq``
    (3,) into ``sel`` with their squared distances ``ss``, in order (one loop without
    branches); their number."""
    nt = 0
    x0, x1, x2 = xq[0], xq[1], xq[2]
    for c in range(c0, c1):
        e0 = x0 - cpacked[c, 0]
        e1 = x1 - cpacked[c, 1]
        e2 = x2 - cpacked[c, 2]
        r2 = e0 * e0 + e1 * e1 + e2 * e2
        sel[nt] = c
        ss[nt] = r2
        nt += r2 <= cpacked[c, 3]
    return nt


@jit.jit
def count_pairs(x: np.ndarray, candidates: tuple, counts: np.ndarray) -> None:
    """The number of pairs of each point ``x`` (m, 3; zero-padded) into ``counts`` (m,)
    (``candidates``: :meth:`~.cell_lists.CellList.candidates` of these points)."""
    group, cstart, cpacked, cradii, _ = candidates
    kmax = 0
    for gr in range(cstart.size - 1):
        kmax = max(kmax, cstart[gr + 1] - cstart[gr])
    sel, ss = np.empty(kmax, np.int64), np.empty(kmax)
    for q in range(x.shape[0]):
        gr = group[q]
        nt = _candidates_of(x[q], cstart[gr], cstart[gr + 1], cpacked, sel, ss)
        nc = 0
        for t in range(nt):
            nc += np.sqrt(ss[t]) < cradii[sel[t]]
        counts[q] = nc


@jit.jit
def fill_shape_functions(
    x: np.ndarray,
    candidates: tuple,
    k: int,
    j: np.ndarray,
    phi: np.ndarray,
    dphi: np.ndarray,
    counts: np.ndarray,
    bound: np.ndarray,
    Aout: np.ndarray,
    kind: int,
    exponents: tuple,
    D: np.ndarray,
    s: float,
    derivatives: bool,
) -> tuple[int, int]:
    """Neighbour search and shape functions of the points ``x`` (m, 3; zero-padded) in one pass,
    written straight into the table's buffers from pair ``k`` on (no cuts).

    Args:
        x: The points.
        candidates: :meth:`~.cell_lists.CellList.candidates` of these points: each point tests
            the candidate particles of its group, sorted by index, so its pairs come sorted.
        k: The first free pair of the buffers.
        j, phi, dphi: Output buffers of the table (capacity,), (capacity,), (gdim, capacity)
            (``dphi`` with no rows without derivatives): particle index, value and gradient
            per pair, by point and particle.
        counts, bound, Aout: Outputs per point (m,), (m,), (m, nb, nb): the number of pairs,
            the eigenvalue-ratio bound and the moment matrix (see :func:`mls_shape_functions`).
        kind, exponents, D, s, derivatives: As for :func:`mls_shape_functions`.

    Returns:
        ``(q, k)``: the points done (``m`` unless the buffers are full: then the caller grows
        them and resumes from point ``q``) and the next free pair.
    """
    group, cstart, cpacked, cradii, ckey = candidates
    nb = len(exponents)
    g = len(exponents[0])
    kmax = 1
    for gr in range(cstart.size - 1):
        kmax = max(kmax, cstart[gr + 1] - cstart[gr])
    sel, ss = np.empty(kmax, np.int64), np.empty(kmax)
    dx, dist, ddist, rho = np.empty((kmax, g)), np.empty(kmax), np.empty((kmax, g)), np.empty(kmax)
    work = np.empty((kmax, 2 + g + nb))
    cap = phi.size
    for q in range(x.shape[0]):
        gr = group[q]
        nt = _candidates_of(x[q], cstart[gr], cstart[gr + 1], cpacked, sel, ss)
        if k + nt > cap:
            return q, k
        nc = 0
        for t in range(nt):  # the exact test, as pairs_within_support and pair_distances
            c = sel[t]
            r = np.sqrt(ss[t])
            if r < cradii[c]:
                dist[nc] = r
                rho[nc] = cradii[c]
                for d in range(g):
                    e = x[q, d] - cpacked[c, d]
                    dx[nc, d] = e
                    ddist[nc, d] = e / r if r > 0.0 else 0.0
                j[k + nc] = ckey[c]
                nc += 1
        bound[q] = _point(  # int64 counts, not literal zeros: one compilation, not three
            np.int64(nc), np.int64(0), dx, dist, ddist, rho, kind, exponents, D, s, derivatives,
            work, phi, dphi, k, Aout, q,
        )  # fmt: skip
        counts[q] = nc
        k += nc
    return x.shape[0], k


def _grown(a: np.ndarray, n: int, cap: int) -> np.ndarray:
    """A buffer of ``cap`` entries (along the last axis) holding the first ``n`` of ``a``."""
    b = np.empty((*a.shape[:-1], cap), a.dtype)
    b[..., :n] = a[..., :n]
    return b


def _trimmed(a: np.ndarray, k: int) -> list[np.ndarray]:
    """The first ``k`` entries of each row of ``a`` (2D): views when the unused tail is small
    (at most 1/8 of the rows' size is held needlessly), else copies that free the buffer."""
    if 8 * (a.shape[-1] - k) <= k:
        return list(a[:, :k])
    return [r[:k].copy() for r in a]


def tabulate_cells(
    cells: CellList,
    x: np.ndarray,
    kind: int,
    exponents: tuple,
    D: np.ndarray,
    s: float,
    derivatives: bool,
    rcond: float,
    chunk: int,
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray, np.ndarray]:
    """Shape functions at the points ``x`` (m, gdim) from the particles of ``cells`` (no pair
    cuts): search and kernel fused (:func:`fill_shape_functions`), chunk by chunk, written
    straight into the table's buffers.

    One thread: one pass, the buffers sized from the pair density of the last query and grown
    from the density seen so far when full. More threads (:func:`~.jit.num_threads`, set by
    ``DOLFINX_MESHFREE_THREADS``): a counting pass, then exactly sized buffers filled chunk by
    chunk in parallel (the kernels release the GIL); the table is the same to the last bit.

    Returns:
        ``(counts, j, columns, suspects, suspect_A)``: pairs per point (m,), the particle index
        (int32) and ``[phi, dphi_x, ...]`` per pair, the points whose eigenvalue-ratio bound is
        not above ``rcond`` and their moment matrices (k, nb, nb), for the exact check.
    """
    m, g = x.shape
    nb = len(exponents)
    x3 = np.zeros((m, 3))
    x3[:, :g] = x
    counts = np.empty(m, np.int64)
    cand = cells.candidates(x3)
    starts = list(range(0, m, chunk))

    def part(start: int) -> tuple:  # the candidates of the chunk from point ``start``
        return (cand[0][start : start + chunk], *cand[1:])

    found: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def fill(start: int, k: int, cols: np.ndarray, j: np.ndarray) -> tuple[int, int]:
        stop = min(start + chunk, m)
        bound = np.empty(stop - start)
        A = np.empty((stop - start, nb, nb))
        q, k = fill_shape_functions(
            x3[start:stop], part(start), k, j, cols[0], cols[1:], counts[start:stop], bound, A,
            kind, exponents, D, s, derivatives,
        )  # fmt: skip
        sus = np.flatnonzero(~(bound[:q] > rcond))
        found[start] = (sus + start, A[sus])
        return start + q, k

    rows = 1 + (g if derivatives else 0)
    threads = min(jit.num_threads(), len(starts))
    if threads > 1:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(lambda a: count_pairs(x3[a : a + chunk], part(a), counts[a:]), starts))
            offsets = np.concatenate([[0], np.cumsum(counts)])
            k = int(offsets[-1])
            j, cols = np.empty(k, np.int32), np.empty((rows, k))
            list(pool.map(lambda a: fill(a, int(offsets[a]), cols, j), starts))
    else:
        cap = int(1.1 * cells.pairs_per_point * m) + 1024
        j, cols = np.empty(cap, np.int32), np.empty((rows, cap))
        start = k = 0
        while start < m:
            stop = min(start + chunk, m)
            start, k = fill(start, k, cols, j)
            if start < stop:  # the buffers are full: grow them, resume at the next point
                cap = max(int(1.1 * k * m / max(start, 1)) + 1024, int(1.5 * cap))
                j, cols = _grown(j, k, cap), _grown(cols, k, cap)
            else:
                start = stop
        j.resize(k, refcheck=False)
    if m:
        cells.pairs_per_point = max(k / m, 1.0)
    parts = [found[a] for a in sorted(found)]
    suspects = np.concatenate([np.zeros(0, np.int64)] + [p[0] for p in parts])
    suspect_A = np.concatenate([np.zeros((0, nb, nb))] + [p[1] for p in parts])
    return counts, j, _trimmed(cols, k), suspects, suspect_A
