"""Compiled MLS kernel: moment matrix, its inverse and the shape functions, one point at a time.

For each evaluation point ``x`` with pairs sorted by point (the CSR layout of the table), it
evaluates Belytschko et al. 1995, eq. (3.7a) and (3.9) in the basis shifted to ``x`` and scaled
by ``s`` (see :mod:`.mls`), ``p_I = p((x_I - x)/s)``:

.. math::
    A = \\sum_I w_I p_I p_I^T, \\quad A \\gamma = e_1, \\quad \\phi_I = w_I p_I^T \\gamma,

and the derivatives ``A_{,k} = \\sum_I w_{I,k} p_I p_I^T - (D_k A + A D_k^T)/s``,
``\\gamma_{,k} = -A^{-1} A_{,k} \\gamma`` and
``\\phi_{I,k} = w_I p_I^T (\\gamma_{,k} - D_k^T \\gamma / s) + w_{I,k} p_I^T \\gamma``, where
``D_k`` is the constant matrix with ``dp/d\\xi_k = D_k p`` (:func:`derivative_matrices`): the terms
of ``A_{,k}`` with basis derivatives are products of ``D_k`` and ``A``, summed once per point
instead of once per pair. The weights ``w(dist / d_I)`` and ``w_{I,k} = w'(r)/d_I \\, dist_{,k}``
are evaluated from the (possibly cut) distances and distance gradients of the pairs.

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
from .cell_lists import CellList, gather, pair_data
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
def _invert(A: np.ndarray, Ainv: np.ndarray, work: np.ndarray) -> None:
    """``Ainv = A^-1`` of the symmetric ``A`` by its ``L D L^T`` factors (no pivoting: ``A``
    is positive definite or rejected by the conditioning check; inf/nan if singular)."""
    m = A.shape[0]
    # work[:, :m]: L (unit lower, below the diagonal) and D (on it); work[:, m:]: L^-1
    for j in range(m):
        dj = A[j, j]
        for k in range(j):
            dj -= work[j, k] * work[j, k] * work[k, k]
        work[j, j] = dj
        inv_d = 1.0 / dj
        for i in range(j + 1, m):
            acc = A[i, j]
            for k in range(j):
                acc -= work[i, k] * work[j, k] * work[k, k]
            work[i, j] = acc * inv_d
    for j in range(m):  # X = L^-1 by forward substitution, column j
        for i in range(m):
            if i < j:
                work[i, m + j] = 0.0
            elif i == j:
                work[i, m + j] = 1.0
            else:
                acc = 0.0
                for k in range(j, i):
                    acc -= work[i, k] * work[k, m + j]
                work[i, m + j] = acc
    for a in range(m):  # A^-1 = X^T D^-1 X
        for b in range(a, m):
            acc = 0.0
            for k in range(b, m):
                acc += work[k, m + a] * work[k, m + b] / work[k, k]
            Ainv[a, b] = acc
            Ainv[b, a] = acc


@jit.jit
def _workspace(kmax: int, nb: int, g: int) -> tuple:
    """Per-point scratch arrays of :func:`_point` for up to ``kmax`` pairs."""
    return (
        np.empty((kmax, nb)),  # P: basis per pair
        np.empty(kmax),  # W: weight per pair
        np.empty((kmax, g)),  # DW: weight gradient per pair
        np.empty((nb, nb)),  # A
        np.empty((g, nb, nb)),  # sum of dw p p^T
        np.empty((nb, nb)),  # A^-1
        np.empty((nb, 2 * nb)),  # factors
        np.empty(nb),  # gamma
        np.empty((g, nb)),  # C_k
        np.empty(nb),  # v
        np.empty((nb, nb)),  # D_k A
    )


@jit.jit
def _point(
    cnt: int,
    dx: np.ndarray,
    dist: np.ndarray,
    ddist: np.ndarray,
    rho: np.ndarray,
    kind: int,
    exponents: tuple,
    D: np.ndarray,
    s: float,
    derivatives: bool,
    ws: tuple,
    phi: np.ndarray,
    dphi: np.ndarray,
    o0: int,
) -> float:
    """Shape functions of one point from its ``cnt`` pairs (rows ``0 .. cnt - 1`` of ``dx``,
    ``dist``, ``ddist``, ``rho``: the support radius of each pair's particle) into
    ``phi[o0 ...]`` and ``dphi[:, o0 ...]``; ``ws[3]`` holds ``A`` afterwards. Returns the bound
    ``1 / (tr A tr A^-1)`` of the eigenvalue ratio (0 where ``A`` is singular or indefinite)."""
    P, W, DW, A, dA, Ainv, work, gamma, C, v, DA = ws
    # the basis as a tuple of tuples: its sizes are compile-time constants (loops unrolled)
    nb = len(exponents)
    g = len(exponents[0])
    linear = nb == g + 1
    inv_s = 1.0 / s
    for a in range(nb):
        for b in range(nb):
            A[a, b] = 0.0
            for d in range(g):
                dA[d, a, b] = 0.0
    for t in range(cnt):
        inv_rho = 1.0 / rho[t]
        w, dwdr = _weight(kind, dist[t] * inv_rho)
        W[t] = w
        f = dwdr * inv_rho
        for d in range(g):
            DW[t, d] = f * ddist[t, d]
        if linear:
            P[t, 0] = 1.0
            for d in range(g):
                P[t, 1 + d] = -dx[t, d] * inv_s
        else:
            for a in range(nb):
                val = 1.0
                for d in range(g):
                    for _ in range(exponents[a][d]):
                        val *= -dx[t, d] * inv_s
                P[t, a] = val
        for a in range(nb):
            wa = w * P[t, a]
            for b in range(a, nb):
                A[a, b] += wa * P[t, b]
        if derivatives:
            for d in range(g):
                for a in range(nb):
                    da = DW[t, d] * P[t, a]
                    for b in range(a, nb):
                        dA[d, a, b] += da * P[t, b]
    for a in range(nb):
        for b in range(a):
            A[a, b] = A[b, a]
    _invert(A, Ainv, work)
    tr_a = 0.0
    tr_inv = 0.0
    for a in range(nb):
        tr_a += A[a, a]
        tr_inv += Ainv[a, a]
    lb = 1.0 / (tr_a * tr_inv)
    bound = lb if (tr_inv > 0.0 and lb > 0.0 and lb <= 1.0) else 0.0
    for a in range(nb):
        gamma[a] = Ainv[a, 0]
    if derivatives:
        for d in range(g):
            # full A_,k = sum dw p p^T - (D_k A + A D_k^T) / s; then v = A_,k gamma
            for a in range(nb):
                for b in range(nb):
                    acc = 0.0
                    for c in range(nb):
                        acc += D[d, a, c] * A[c, b]
                    DA[a, b] = acc
            for a in range(nb):
                acc = 0.0
                for b in range(nb):
                    dab = dA[d, a, b] if b >= a else dA[d, b, a]
                    acc += (dab - (DA[a, b] + DA[b, a]) * inv_s) * gamma[b]
                v[a] = acc
            # C_k = gamma_,k - D_k^T gamma / s, gamma_,k = -A^-1 v
            for a in range(nb):
                acc = 0.0
                dtg = 0.0
                for b in range(nb):
                    acc += Ainv[a, b] * v[b]
                    dtg += D[d, b, a] * gamma[b]
                C[d, a] = -acc - dtg * inv_s
    for t in range(cnt):
        pg = 0.0
        for a in range(nb):
            pg += P[t, a] * gamma[a]
        phi[o0 + t] = W[t] * pg
        if derivatives:
            for d in range(g):
                pc = 0.0
                for a in range(nb):
                    pc += P[t, a] * C[d, a]
                dphi[d, o0 + t] = W[t] * pc + DW[t, d] * pg
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
    ws = _workspace(kmax, nb, g)
    dxs, dists, ddists, rho = (
        np.empty((kmax, g)),
        np.empty(kmax),
        np.empty((kmax, g)),
        np.empty(kmax),
    )
    for q in range(m):
        a0 = indptr[q]
        cnt = indptr[q + 1] - a0
        for t in range(cnt):  # the pairs of the point into the scratch of the search path
            rho[t] = radii[j[a0 + t]]
            dists[t] = dist[a0 + t]
            for d in range(g):
                dxs[t, d] = dx[a0 + t, d]
                ddists[t, d] = ddist[a0 + t, d]
        bound[q] = _point(
            cnt, dxs, dists, ddists, rho, kind, exponents, D, s, derivatives, ws, phi, dphi, a0
        )
        Aout[q] = ws[3]
    return phi, dphi, bound, Aout


@jit.jit
def count_pairs(x: np.ndarray, grid: tuple, counts: np.ndarray) -> None:
    """The number of pairs of each point ``x`` (m, 3; zero-padded) into ``counts`` (m,)."""
    n = grid[1].size
    tmp, tmp_ss = np.empty(n + 1, np.int64), np.empty(n + 1)
    empty_i, empty_f = np.empty(0, np.int64), np.empty(0)
    for q in range(x.shape[0]):
        counts[q] = gather(x[q], grid, tmp, tmp_ss, empty_i, empty_f, empty_i, False)


@jit.jit
def fill_shape_functions(
    x: np.ndarray,
    grid: tuple,
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
        grid: :attr:`~.cell_lists.CellList.grid`.
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
    n = grid[1].size
    nb = len(exponents)
    g = len(exponents[0])
    tmp, tmp_ss = np.empty(n + 1, np.int64), np.empty(n + 1)
    cand = np.empty(n, np.int64)
    cdist = np.empty(n)
    key = np.empty(n, np.int64)
    kmax = 64
    ws = _workspace(kmax, nb, g)
    dx = np.empty((kmax, g))
    dist = np.empty(kmax)
    ddist = np.empty((kmax, g))
    rho = np.empty(kmax)
    radii = grid[1]
    cap = phi.size
    for q in range(x.shape[0]):
        nc = gather(x[q], grid, tmp, tmp_ss, cand, cdist, key, True)
        if k + nc > cap:
            return q, k
        if nc > kmax:  # more pairs than ever: grow the scratch
            kmax = 2 * nc
            ws = _workspace(kmax, nb, g)
            dx = np.empty((kmax, g))
            dist = np.empty(kmax)
            ddist = np.empty((kmax, g))
            rho = np.empty(kmax)
        pair_data(x[q], grid, nc, cand, cdist, dx, dist, ddist, 0)
        for t in range(nc):
            rho[t] = radii[cand[t]]
            j[k + t] = key[t]
        bound[q] = _point(
            nc, dx, dist, ddist, rho, kind, exponents, D, s, derivatives, ws, phi, dphi, k
        )
        for a in range(nb):
            for b in range(nb):
                Aout[q, a, b] = ws[3][a, b]
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
    starts = list(range(0, m, chunk))
    found: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def fill(start: int, k: int, cols: np.ndarray, j: np.ndarray) -> tuple[int, int]:
        stop = min(start + chunk, m)
        bound = np.empty(stop - start)
        A = np.empty((stop - start, nb, nb))
        q, k = fill_shape_functions(
            x3[start:stop], cells.grid, k, j, cols[0], cols[1:], counts[start:stop], bound, A,
            kind, exponents, D, s, derivatives,
        )  # fmt: skip
        sus = np.flatnonzero(~(bound[:q] > rcond))
        found[start] = (sus + start, A[sus])
        return start + q, k

    rows = 1 + (g if derivatives else 0)
    threads = min(jit.num_threads(), len(starts))
    if threads > 1:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(lambda a: count_pairs(x3[a : a + chunk], cells.grid, counts[a:]), starts))
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
