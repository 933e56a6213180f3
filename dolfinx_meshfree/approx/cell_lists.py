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

For the fused MLS path the evaluation points are grouped instead (:meth:`CellList.candidates`):
the points are binned into a grid of bins about one reach wide (about 16 points each), and the
particles whose support meets the bounding box of a bin's points are gathered once per bin and
sorted by index. A point then tests its group's candidates in one branch-free loop over
contiguous arrays (about twice as many candidates as pairs), and its pairs come sorted: the
per-point bin walks and insertion sorts of :func:`gather` are paid once per group.
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
#: Evaluation points per group sharing one candidate list (:meth:`CellList.candidates`), and
#: the bounds of the groups' bin size in units of the fine grid's reach.
_POINTS_PER_GROUP = 16.0
_GROUP_SIZE = (0.5, 1.0)
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
def _box_gap(lo: float, hi: float, a: float, size: float) -> float:
    """Squared distance between the intervals ``[lo, hi]`` and ``[a, a + size]``."""
    if hi < a:
        return (a - hi) * (a - hi)
    if lo > a + size:
        return (lo - a - size) * (lo - a - size)
    return 0.0


@jit
def gather_box(
    blo: np.ndarray, bhi: np.ndarray, grid: tuple, tmp: np.ndarray, cand: np.ndarray, k: int
) -> int:
    """The particles whose support meets the box ``[blo, bhi]`` (3,; zero-padded) into
    ``cand[k], cand[k + 1], ...`` (positions in bin order), sorted by particle index; as
    :func:`gather` for a point, with the distance from a particle to the box (a superset of the
    pairs of every point in the box). ``tmp``: work array (n + 1,). Returns the next free entry."""
    packed, _, order, start, los, sizes, shapes, reaches, boff = grid
    g = los.shape[1]
    last = g - 1
    nt = 0
    for lev in range(boff.size - 1):
        if start[boff[lev]] == start[boff[lev + 1]]:  # an empty grid
            continue
        size, reach = sizes[lev], reaches[lev]
        inv_size = 1.0 / size
        reach2 = reach * reach
        s1, s2 = shapes[lev, 1], shapes[lev, 2]
        if g > 1:
            a0, _ = _span(blo[0], reach, los[lev, 0], inv_size, shapes[lev, 0])
            _, z0 = _span(bhi[0], reach, los[lev, 0], inv_size, shapes[lev, 0])
        else:
            a0, z0 = 0, 0
        if g > 2:
            a1, _ = _span(blo[1], reach, los[lev, 1], inv_size, s1)
            _, z1 = _span(bhi[1], reach, los[lev, 1], inv_size, s1)
        else:
            a1, z1 = 0, 0
        lol, sl = los[lev, last], shapes[lev, last]
        for c0 in range(a0, z0 + 1):
            g0 = _box_gap(blo[0], bhi[0], los[lev, 0] + c0 * size, size) if g > 1 else 0.0
            if g0 > reach2:
                continue
            for c1 in range(a1, z1 + 1):
                g1 = g0
                if g > 2:
                    g1 += _box_gap(blo[1], bhi[1], los[lev, 1] + c1 * size, size)
                if g1 > reach2:
                    continue
                rem = np.sqrt(reach2 - g1)
                first, _ = _span(blo[last], rem, lol, inv_size, sl)
                _, stop = _span(bhi[last], rem, lol, inv_size, sl)
                if first > stop:
                    continue
                base = boff[lev] + (c0 * s1 + c1) * s2
                for s in range(start[base + first], start[base + stop + 1]):
                    ss = 0.0
                    for d in range(3):
                        p = packed[s, d]
                        e = max(blo[d] - p, p - bhi[d], 0.0)
                        ss += e * e
                    tmp[nt] = s
                    nt += ss <= packed[s, 3]
    for u in range(nt):  # insertion by particle index (bins are sorted by index: short moves)
        s = tmp[u]
        key = order[s]
        t = k + u
        while t > k and order[cand[t - 1]] > key:
            cand[t] = cand[t - 1]
            t -= 1
        cand[t] = s
    return k + nt


@jit
def _candidate_lists(
    x: np.ndarray, grid: tuple, lo: np.ndarray, size: float, shape: np.ndarray, capacity: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points ``x`` (m, 3; zero-padded) binned by a grid (corner ``lo`` (3,), bins of ``size``,
    ``shape`` (3,)); per non-empty bin the particles whose support meets the box of its points.

    Returns:
        ``(group, cstart, cand)``: the bin (group) of each point (m,), the first candidate of
        each group (groups + 1,) and the candidates (positions in bin order, by particle index).
    """
    m = x.shape[0]
    n = grid[1].size
    keys = np.empty(m, np.int64)
    for q in range(m):
        key = 0
        for d in range(3):
            c = int(min(max(np.floor((x[q, d] - lo[d]) / size), 0.0), float(shape[d] - 1)))
            key = key * shape[d] + c
        keys[q] = key
    start, order = _build(keys, int(shape[0] * shape[1] * shape[2]))
    group = np.empty(m, np.int64)
    cstart = [0]
    cand = np.empty(max(capacity, 16), np.int64)
    tmp = np.empty(n + 1, np.int64)
    blo, bhi = np.empty(3), np.empty(3)
    k = 0
    for b in range(start.size - 1):
        if start[b] == start[b + 1]:
            continue
        blo[:] = np.inf
        bhi[:] = -np.inf
        for u in range(start[b], start[b + 1]):
            q = order[u]
            group[q] = len(cstart) - 1
            for d in range(3):
                blo[d] = min(blo[d], x[q, d])
                bhi[d] = max(bhi[d], x[q, d])
        if k + n > cand.size:  # room for every particle
            grown = np.empty(max(2 * cand.size, k + n), np.int64)
            grown[:k] = cand[:k]
            cand = grown
        k = gather_box(blo, bhi, grid, tmp, cand, np.int64(k))  # not a literal 0: one compile
        cstart.append(k)
    return group, np.array(cstart, dtype=np.int64), cand[:k]


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
        pair_data(x[q], grid, nc, cand, cdist, dx, dist, ddist, np.int64(k))  # one compile
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

    def candidates(self, x3: np.ndarray) -> tuple:
        """The points ``x3`` (m, 3; zero-padded) in groups of nearby points (bins of a grid
        about the fine grid's reach wide, holding about :data:`_POINTS_PER_GROUP` points), each
        with the candidate particles of all its points, gathered once: what
        :func:`~.mls_kernel.fill_shape_functions` takes.

        Returns:
            ``(group, cstart, cpacked, cradii, ckey)``: the group of each point (m,), the first
            candidate of each group (groups + 1,), and per candidate its position and squared
            radius with a margin (ncand, 4), radius and particle index, by index within a group.
        """
        m = x3.shape[0]
        g = self.gdim
        lo = np.zeros(3)
        extent = np.zeros(g)
        if m:
            lo[:g] = x3[:, :g].min(axis=0)
            extent = x3[:, :g].max(axis=0) - lo[:g]
        reach = float(self.grid[7][0])
        volume = float(np.prod(np.maximum(extent, reach)))
        size = (volume * _POINTS_PER_GROUP / max(m, 1)) ** (1.0 / g)
        size = min(max(size, _GROUP_SIZE[0] * reach), _GROUP_SIZE[1] * reach)
        size, shape = _grid_shape(extent, size, max(m, 1))
        shape3 = np.ones(3, np.int64)
        shape3[:g] = shape
        capacity = int(2.5 * self.pairs_per_point * m / _POINTS_PER_GROUP) + 1024
        group, cstart, cand = _candidate_lists(x3, self.grid, lo, size, shape3, capacity)
        packed, radii, order = self.grid[0], self.grid[1], self.grid[2]
        return group, cstart, packed[cand], radii[cand], order[cand]

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
