"""Compiled neighbour search by cell lists, with pairs sorted by point and then by particle.

The particles are binned into uniform grids: most of them into a grid of bins a fraction of the
typical support radius wide, the few with a much larger support (near boundaries, in sparse
regions) into a second, coarser grid, so that a point does not test the particles of the whole
reach of the largest support. A point visits, in each grid, the bins within that grid's largest
radius, skipping the bins farther from it than the largest radius of their own particles. For a
chunk of evaluation points the search returns the pairs ``|x_i - x_I| < d_I`` grouped by point
and, within a point, in increasing particle index: the CSR layout of a shape table, with no sort
of the whole pair list. The pair set and the distances are those of
:func:`~dolfinx_meshfree.approx.neighbours.pairs_within_support` and
:func:`~dolfinx_meshfree.approx.mls.pair_distances` (same formulas; tested equal).
"""

from __future__ import annotations

import numpy as np

from .jit import AVAILABLE, jit

__all__ = ["CellList", "gather", "pair_data"]

#: At most this many bins per particle (a sparse cloud in a large box gets coarser bins).
_MAX_BINS_PER_PARTICLE = 4
#: Bins per support radius of the particles of a grid (bin width: radius / this).
_BINS_PER_RADIUS = 2.0
#: The fine grid takes the particles with radii up to this quantile (times :data:`_SPREAD`);
#: the others go to the coarse grid.
_QUANTILE = 0.95
_SPREAD = 1.05
#: The number of grids (fixed, so that the compiled functions have one signature; the second
#: may be empty).
_LEVELS = 2


@jit
def _build(bins: np.ndarray, nbins: int) -> tuple[np.ndarray, np.ndarray]:
    """Counting sort of the particles by (global) bin: ``(start, order)``; within a bin by index."""
    n = bins.size
    start = np.zeros(nbins + 1, np.int64)
    for p in range(n):
        start[bins[p] + 1] += 1
    for b in range(nbins):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for p in range(n):
        order[fill[bins[p]]] = p
        fill[bins[p]] += 1
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
def _span(x: float, h: float, lo: float, inv_size: float, bins: int) -> tuple[int, int]:
    """The bins ``first .. last`` of an axis (``bins`` of ``1 / inv_size`` from ``lo``) that
    meet ``[x - h, x + h]`` (``first > last`` if none). ``h`` carries a relative margin (the
    reach's) far above the rounding of the product."""
    a = np.floor((x - h - lo) * inv_size)
    e = np.floor((x + h - lo) * inv_size)
    return int(min(max(a, 0.0), float(bins))), int(min(max(e, -1.0), float(bins - 1)))


@jit
def gather(
    xq: np.ndarray,
    grid: tuple,
    tmp: np.ndarray,
    tmp_ss: np.ndarray,
    cand: np.ndarray,
    cdist: np.ndarray,
    key: np.ndarray,
    store: bool,
) -> int:
    """The particles within the support of the point ``xq`` (3,; zero-padded), sorted by index.

    In each grid, the bins within its reach form rows along the last axis whose particles are
    contiguous in bin order: each row is trimmed to the disc (ball) of the reach and its
    particles are tested in one loop without branches (the candidates passing the cheap test on
    squared distances are compacted into ``tmp``), then tested exactly and sorted.

    Args:
        xq: The point.
        grid: :attr:`CellList.grid`.
        tmp, tmp_ss: Work arrays (n + 1,) of ints and floats.
        cand, cdist, key: Outputs (n,): position in bin order, distance and particle index of
            each pair, in increasing particle index.
        store: Whether to write the outputs (else only count the pairs).

    Returns:
        The number of pairs.
    """
    packed, radii, order, start, los, sizes, shapes, reaches, boff = grid
    g = los.shape[1]
    last = g - 1
    x0, x1, x2 = xq[0], xq[1], xq[2]
    xl = xq[last]
    nt = 0
    for lev in range(boff.size - 1):
        if start[boff[lev]] == start[boff[lev + 1]]:  # an empty grid
            continue
        size, reach = sizes[lev], reaches[lev]
        inv_size = 1.0 / size
        reach2 = reach * reach
        s1, s2 = shapes[lev, 1], shapes[lev, 2]
        # outer axes: 0 (2D, 3D) and 1 (3D); the rows run along the last axis
        a0, z0 = _span(x0, reach, los[lev, 0], inv_size, shapes[lev, 0]) if g > 1 else (0, 0)
        a1, z1 = _span(x1, reach, los[lev, 1], inv_size, s1) if g > 2 else (0, 0)
        lol, sl = los[lev, last], shapes[lev, last]
        for c0 in range(a0, z0 + 1):
            g0 = _gap(x0, los[lev, 0] + c0 * size, size) if g > 1 else 0.0
            if g0 > reach2:
                continue
            for c1 in range(a1, z1 + 1):
                g1 = g0 + (_gap(x1, los[lev, 1] + c1 * size, size) if g > 2 else 0.0)
                if g1 > reach2:
                    continue
                first, stop = _span(xl, np.sqrt(reach2 - g1), lol, inv_size, sl)
                if first > stop:
                    continue
                base = boff[lev] + (c0 * s1 + c1) * s2
                for s in range(start[base + first], start[base + stop + 1]):
                    e0 = x0 - packed[s, 0]
                    e1 = x1 - packed[s, 1]
                    e2 = x2 - packed[s, 2]
                    ss = e0 * e0 + e1 * e1 + e2 * e2
                    tmp[nt] = s
                    tmp_ss[nt] = ss
                    nt += ss <= packed[s, 3]  # the cheap pre-test, then the exact one
    nc = 0
    for u in range(nt):
        s = tmp[u]
        r = np.sqrt(tmp_ss[u])
        if r < radii[s] and not store:
            nc += 1
        elif r < radii[s]:
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
    g = grid[4].shape[1]
    counts = np.zeros(m, np.int64)
    cap = max(capacity, 16)
    j = np.empty(cap, np.int32)
    dx = np.empty((cap, g))
    dist = np.empty(cap)
    ddist = np.empty((cap, g))
    tmp = np.empty(n + 1, np.int64)
    tmp_ss = np.empty(n + 1)
    cand = np.empty(n, np.int64)
    cdist = np.empty(n)
    key = np.empty(n, np.int64)
    k = 0
    for q in range(m):
        nc = gather(x[q], grid, tmp, tmp_ss, cand, cdist, key, True)
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


def _grid_shape(extent: np.ndarray, size: float, n: int) -> tuple[float, np.ndarray]:
    """Bin size (``size``, or coarser for a sparse cloud in a large box) and bins per axis."""
    g = extent.size
    bins = np.floor(extent / size) + 1
    if bins.prod() > _MAX_BINS_PER_PARTICLE * n + 64:
        size *= (bins.prod() / (_MAX_BINS_PER_PARTICLE * n + 64)) ** (1.0 / g)
        bins = np.floor(extent / size) + 1
    return size, bins.astype(np.int64)


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
        radii = np.ascontiguousarray(radii, dtype=float)
        n, g = pts.shape
        if n >= np.iinfo(np.int32).max:
            raise ValueError(f"{n} particles do not fit 32-bit column indices")
        self.gdim = g
        lo = pts.min(axis=0) if n else np.zeros(g)
        extent = pts.max(axis=0) - lo if n else np.zeros(g)
        # the fine grid: radii up to a quantile; the coarse one: the rest (maybe none)
        r_max = float(radii.max()) if n else 1.0
        r_cut = min(_SPREAD * float(np.quantile(radii, _QUANTILE)), r_max) if n else 1.0
        level = (radii > r_cut).astype(np.int64)
        los = np.zeros((_LEVELS, g))
        sizes = np.ones(_LEVELS)
        shapes = np.ones((_LEVELS, 3), np.int64)
        reaches = np.zeros(_LEVELS)
        boff = np.zeros(_LEVELS + 1, np.int64)
        bins = np.empty(n, np.int64)
        for lev, r_top in enumerate((r_cut, r_max)):
            sel = np.flatnonzero(level == lev)
            # the reach: the largest radius of the grid (plus a margin for the rounding of
            # the bin coordinates); bins a fraction of it wide
            reach = r_top * (1.0 + 1e-9)
            size, shape = _grid_shape(extent, reach / _BINS_PER_RADIUS, max(sel.size, 1))
            los[lev], sizes[lev], shapes[lev, :g], reaches[lev] = lo, size, shape, reach
            c = np.clip(np.floor((pts[sel] - lo) / size), 0, shape - 1).astype(np.int64)
            local = np.zeros(sel.size, np.int64)
            for d in range(3):
                local = local * shapes[lev, d] + (c[:, d] if d < g else 0)
            bins[sel] = boff[lev] + local
            boff[lev + 1] = boff[lev] + shapes[lev].prod()
        start, order = _build(bins, int(boff[-1]))
        radii = radii[order]
        packed = np.zeros((n, 4))  # x, y, z and the squared radius of the cheap pre-test
        packed[:, :g] = pts[order]
        packed[:, 3] = radii * radii * (1.0 + 1e-10)
        #: What the compiled functions take: ``(packed, radii, order, start, lo, size, shape,
        #: reach, boff)``: per particle in bin order, its position (zero-padded) and squared
        #: radius with a margin (n, 4), radius and index; the first particle of each bin
        #: (nbins + 1,); per grid its corner (levels, gdim), bin size, shape (levels, 3; padded
        #: with ones) and reach (its largest radius with a margin for the rounding of the bin
        #: coordinates); the first bin of each grid (levels + 1,).
        self.grid = (packed, radii, order, start, los, sizes, shapes, reaches, boff)
        #: Pairs per point of the last query: the capacity guess of the next one.
        self.pairs_per_point = 16.0

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
        capacity = int(1.1 * self.pairs_per_point * x.shape[0]) + 16
        out = _search(x3, self.grid, capacity)
        if x.shape[0]:
            self.pairs_per_point = max(out[1].size / x.shape[0], 1.0)
        return out
