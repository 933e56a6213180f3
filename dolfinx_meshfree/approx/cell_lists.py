"""Compiled neighbour search by cell lists, with pairs sorted by point and then by particle.

The particles are binned once into a uniform grid whose bin size is at least the largest
support radius, so the particles within the support of an evaluation point lie in the
``3^gdim`` bins around the point's bin. For a chunk of evaluation points the search returns the
pairs ``|x_i - x_I| < d_I`` grouped by point and, within a point, in increasing particle index:
the CSR layout of a shape table, with no sort of the whole pair list. The pair set and the
distances are those of :func:`~dolfinx_meshfree.approx.neighbours.pairs_within_support` and
:func:`~dolfinx_meshfree.approx.mls.pair_distances` (same formulas; tested equal).
"""

from __future__ import annotations

import numpy as np

from .jit import AVAILABLE, jit

__all__ = ["CellList", "gather", "pair_data"]

#: At most this many bins per particle (a sparse cloud in a large box gets coarser bins).
_MAX_BINS_PER_PARTICLE = 4


@jit
def _bin_of(x: np.ndarray, lo: np.ndarray, size: float, shape: np.ndarray, out: np.ndarray) -> None:
    """Bin coordinates of the point ``x`` (clamped to the grid, padded to 3 dims) into ``out``."""
    out[:] = 0
    for d in range(x.size):
        c = np.floor((x[d] - lo[d]) / size)
        c = min(max(c, 0.0), float(shape[d] - 1))
        out[d] = int(c)


@jit
def _build(
    pts: np.ndarray, lo: np.ndarray, size: float, shape: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Counting sort of the particles by bin: ``(start, order)``; within a bin by index."""
    n = pts.shape[0]
    nbins = shape[0] * shape[1] * shape[2]
    ids = np.empty(n, np.int64)
    c = np.zeros(3, np.int64)
    start = np.zeros(nbins + 1, np.int64)
    for p in range(n):
        _bin_of(pts[p], lo, size, shape, c)
        ids[p] = (c[0] * shape[1] + c[1]) * shape[2] + c[2]
        start[ids[p] + 1] += 1
    for b in range(nbins):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for p in range(n):
        order[fill[ids[p]]] = p
        fill[ids[p]] += 1
    return start, order


@jit
def _gap(x: float, a: float, size: float) -> float:
    """Squared distance from ``x`` to the interval ``[a, a + size]``."""
    if x < a:
        return (a - x) * (a - x)
    if x > a + size:
        return (x - a - size) * (x - a - size)
    return 0.0


@jit
def gather(
    xq: np.ndarray,
    grid: tuple,
    cand: np.ndarray,
    cdist: np.ndarray,
    key: np.ndarray,
    range3: np.ndarray,
) -> int:
    """The particles within the support of the point ``xq`` (3,; zero-padded), sorted by index.

    Args:
        xq: The point.
        grid: :attr:`CellList.grid`.
        cand, cdist, key: Outputs (n,): position in bin order, distance and particle index of
            each pair, in increasing particle index.
        range3: Work array (2, 3) of ints.

    Returns:
        The number of pairs.
    """
    pts, radii, order, start, lo, size, shape, reach, bin_reach = grid
    g = lo.size
    range3[:, :] = 0
    for d in range(g):
        a = np.floor((xq[d] - reach - lo[d]) / size)
        e = np.floor((xq[d] + reach - lo[d]) / size)
        range3[0, d] = int(min(max(a, 0.0), float(shape[d])))
        range3[1, d] = int(min(max(e, -1.0), float(shape[d] - 1)))
    x0, x1, x2 = xq[0], xq[1], xq[2]
    nc = 0
    for c0 in range(range3[0, 0], range3[1, 0] + 1):
        g0 = _gap(x0, lo[0] + c0 * size, size)
        for c1 in range(range3[0, 1], range3[1, 1] + 1):
            g1 = g0 + (_gap(x1, lo[1] + c1 * size, size) if g > 1 else 0.0)
            for c2 in range(range3[0, 2], range3[1, 2] + 1):
                g2 = g1 + (_gap(x2, lo[2] + c2 * size, size) if g > 2 else 0.0)
                b = (c0 * shape[1] + c1) * shape[2] + c2
                if g2 > bin_reach[b]:  # the bin is beyond the supports of its particles
                    continue
                for s in range(start[b], start[b + 1]):
                    e0 = x0 - pts[s, 0]
                    e1 = x1 - pts[s, 1]
                    e2 = x2 - pts[s, 2]
                    ss = e0 * e0 + e1 * e1 + e2 * e2
                    rs = radii[s]
                    if ss <= rs * rs * (1.0 + 1e-10):  # cheap pre-test, then the exact one
                        r = np.sqrt(ss)
                        if r < rs:
                            jj = order[s]  # insertion by particle index
                            t = nc
                            while t > 0 and key[t - 1] > jj:
                                key[t] = key[t - 1]
                                cand[t] = cand[t - 1]
                                cdist[t] = cdist[t - 1]
                                t -= 1
                            key[t] = jj
                            cand[t] = s
                            cdist[t] = r
                            nc += 1
    return nc


@jit
def pair_data(
    xq: np.ndarray,
    grid: tuple,
    nc: int,
    cand: np.ndarray,
    cdist: np.ndarray,
    dx: np.ndarray,
    dist: np.ndarray,
    ddist: np.ndarray,
    k: int,
) -> None:
    """Write ``x - x_I``, the distance and its gradient (0 at distance 0) of the ``nc`` pairs
    found by :func:`gather` into rows ``k, k + 1, ...`` of ``dx``, ``dist``, ``ddist``."""
    pts = grid[0]
    g = dx.shape[1]
    for t in range(nc):
        r = cdist[t]
        dist[k + t] = r
        for d in range(g):
            e = xq[d] - pts[cand[t], d]
            dx[k + t, d] = e
            ddist[k + t, d] = e / r if r > 0.0 else 0.0


@jit
def _search(
    x: np.ndarray, grid: tuple, capacity: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pairs of the points ``x`` (m, 3; zero-padded) with the particles of ``grid``."""
    m = x.shape[0]
    n = grid[1].size
    g = grid[4].size
    counts = np.zeros(m, np.int64)
    cap = max(capacity, 16)
    j = np.empty(cap, np.int32)
    dx = np.empty((cap, g))
    dist = np.empty(cap)
    ddist = np.empty((cap, g))
    cand = np.empty(n, np.int64)
    cdist = np.empty(n)
    key = np.empty(n, np.int64)
    range3 = np.zeros((2, 3), np.int64)
    k = 0
    for q in range(m):
        nc = gather(x[q], grid, cand, cdist, key, range3)
        if k + nc > cap:  # grow the output
            cap = max(2 * cap, k + nc)
            j2 = np.empty(cap, np.int32)
            j2[:k] = j[:k]
            j = j2
            dx2 = np.empty((cap, g))
            dx2[:k] = dx[:k]
            dx = dx2
            dist2 = np.empty(cap)
            dist2[:k] = dist[:k]
            dist = dist2
            ddist2 = np.empty((cap, g))
            ddist2[:k] = ddist[:k]
            ddist = ddist2
        for t in range(nc):
            j[k + t] = key[t]
        pair_data(x[q], grid, nc, cand, cdist, dx, dist, ddist, k)
        k += nc
        counts[q] = nc
    return counts, j[:k], dx[:k], dist[:k], ddist[:k]


class CellList:
    """Particles binned for repeated support queries (compiled; needs numba).

    Args:
        particles: Positions (n, gdim), gdim 1-3.
        radii: Support radius of each particle (n,).
    """

    def __init__(self, particles: np.ndarray, radii: np.ndarray) -> None:
        if not AVAILABLE:
            raise RuntimeError("CellList needs numba; use neighbours.pairs_within_support")
        pts = np.ascontiguousarray(particles, dtype=float)
        n, g = pts.shape
        if n >= np.iinfo(np.int32).max:
            raise ValueError(f"{n} particles do not fit 32-bit column indices")
        self.gdim = g
        lo = pts.min(axis=0)
        extent = pts.max(axis=0) - lo
        # bins of half the largest radius; a point visits the bins within that radius (plus a
        # margin for the rounding of the bin coordinates)
        self._reach = float(radii.max()) * (1.0 + 1e-9)
        size = 0.5 * self._reach
        bins = np.floor(extent / size) + 1
        if bins.prod() > _MAX_BINS_PER_PARTICLE * n + 64:
            size *= (bins.prod() / (_MAX_BINS_PER_PARTICLE * n + 64)) ** (1.0 / g)
            bins = np.floor(extent / size) + 1
        shape = np.ones(3, np.int64)
        shape[:g] = bins.astype(np.int64)
        self._lo, self._size, self._shape = lo, size, shape
        self._start, self._order = _build(pts, lo, size, shape)
        self._pts = np.zeros((n, 3))
        self._pts[:, :g] = pts[self._order]
        self._radii = np.ascontiguousarray(radii[self._order], dtype=float)
        self._pairs_per_point = 16.0  # capacity guess, updated from each query
        #: What the compiled functions take: ``(pts, radii, order, start, lo, size, shape,
        #: reach, bin_reach)``, the positions (n, 3; zero-padded) and radii in bin order, the
        #: particle index of each, the first of each bin (nbins + 1,), the grid's corner, bin
        #: size and shape (3,), the reach of the search and the squared largest radius per bin.
        # squared largest radius per bin, with a margin for the rounding of the bin boundaries
        bin_of = np.repeat(np.arange(self._start.size - 1), np.diff(self._start))
        bin_reach = np.zeros(self._start.size - 1)
        np.maximum.at(bin_reach, bin_of, self._radii * (1.0 + 1e-6) + 1e-9 * size)
        self.grid = (
            self._pts, self._radii, self._order, self._start, self._lo, self._size,
            self._shape, self._reach, bin_reach**2,
        )  # fmt: skip

    def pairs(
        self, x: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Pairs ``|x_i - x_I| < d_I`` of the points ``x`` (m, gdim), by point, then particle.

        Returns:
            ``(counts, j, dx, dist, ddist)``: the number of pairs of each point (m,), and per pair
            the particle index (int32), ``x_i - x_I`` (npairs, gdim), ``|x_i - x_I|`` and its
            gradient with respect to ``x_i`` (npairs, gdim; zero where the distance is zero).
        """
        x3 = np.zeros((x.shape[0], 3))
        x3[:, : self.gdim] = x
        capacity = int(1.1 * self._pairs_per_point * x.shape[0]) + 16
        out = _search(x3, self.grid, capacity)
        if x.shape[0]:
            self._pairs_per_point = max(out[1].size / x.shape[0], 1.0)
        return out
