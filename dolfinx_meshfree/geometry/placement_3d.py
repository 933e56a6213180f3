"""The boundary-conforming particle layer on a 3D border (triangular and quadrilateral facets).

The 3D counterpart of the segments of :meth:`ParticleSet.from_cells` with ``border``: particles on
every vertex of the border facets, along every border edge and inside every border facet at about
the spacing, and the interior grid without its points near the border.

Every border point is computed from the global entity it belongs to, so that the copies of it
that different facets (and ranks) produce are bitwise equal and the set does not depend on the
partition:

* vertices are the facets' corner coordinates (DOLFINx copies coordinates to the ghosts), merged
  when they coincide;
* an edge gets ``n_e = ceil(length / spacing)`` intervals (at least 1), computed from its two
  end points in a canonical order (lexicographically smaller first), once per edge;
* a facet gets a lattice in a canonical vertex order: a triangle ``n_f = ceil(longest edge /
  spacing)`` subdivisions per side (barycentric lattice, its strictly interior points), a
  quadrilateral ``n_u x n_v`` (the longer of each pair of opposite edges over the spacing) on its
  bilinear map (interior points).

Edge and facet lattices need not match along shared edges (a triangle's sides differ in length),
so the candidates are thinned deterministically: in the order vertices, edge points, facet points
(each sorted), a point closer than :data:`THIN` times the spacing to a point kept before it is
dropped. The border particles are then at least ``THIN * spacing`` apart (vertices excepted:
they are all kept, at least an edge length apart), and every point of a facet is within the
lattice's covering radius plus ``THIN * spacing`` of a border particle. Grid points closer than
:data:`DROP` times the spacing to a border facet are dropped, except those that coincide (within
``tol``) with a border particle, which replace it: the 2D rule, so that a grid whose planes hold
the border and whose spacing divides its edges is returned unchanged.

A patch cell then left without a particle off the border gets one at its centroid (at least
``DROP * spacing`` from the border and from every other particle): in a part of the patch about
one cell thick the grid can fall between the two sides of the border and be dropped, and the MLS
supports of the border particles (twice the distance to their 4th nearest neighbour, which on a
facet lattice is the lattice step) then stop short of the other side: the moment matrices there
are singular. Ownership needs no rule: every rank gathers every rank's border facets (and hollow
cell centroids) and computes the same set.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from .. import _compat

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = ["DROP", "THIN", "check_border_3d", "conforming_layer_3d", "distance_to_facets"]

#: Border particles from edges and facets closer than ``THIN * spacing`` to a particle kept
#: before them are dropped (the smallest distance between border particles off the vertices).
THIN = 0.4
#: Grid points closer than ``DROP * spacing`` to a border facet are dropped (the 2D rule).
DROP = 0.5
#: A subdivision count is ``ceil(length / spacing - _CEIL_SLACK)``: a length that is a multiple
#: of the spacing up to round-off gets that multiple.
_CEIL_SLACK = 1e-9
#: Triangles per chunk of the point-to-facet distances (bounds the temporaries).
_CHUNK = 4096
#: Quadrilateral corners in cyclic order from DOLFINx's tensor-product order.
_CYCLIC = np.array([0, 1, 3, 2])


def check_border_3d(border: npt.ArrayLike) -> np.ndarray:
    """Border facets as an array (k, 3, 3) (triangles) or (k, 4, 3) (quadrilaterals in DOLFINx's
    vertex order: edges 0-1, 0-2, 1-3, 2-3); a ``ValueError`` naming the problem otherwise
    (local, no communication)."""
    b = np.asarray(border, dtype=float)
    if b.ndim != 3 or b.shape[1] not in (3, 4) or b.shape[2] != 3:
        raise ValueError(
            f"border should have shape (num_facets, 3, 3) (triangles) or (num_facets, 4, 3) "
            f"(quadrilaterals) on a 3D mesh, got {b.shape}: give each border facet's vertex "
            "coordinates (e.g. mesh.geometry.x[entities_to_geometry(mesh, 2, facets)])"
        )
    if not np.all(np.isfinite(b)):
        bad = np.flatnonzero(~np.all(np.isfinite(b), axis=(1, 2)))[0]
        raise ValueError(f"border facet {bad} has a non-finite coordinate: {b[bad].tolist()}")
    if b.shape[1] == 4 and b.shape[0]:
        # tensor order: the opposite edges 0-1 and 2-3 (0-2 and 1-3) run the same way
        along = np.einsum("ki,ki->k", b[:, 1] - b[:, 0], b[:, 3] - b[:, 2])
        across = np.einsum("ki,ki->k", b[:, 2] - b[:, 0], b[:, 3] - b[:, 1])
        wrong = np.flatnonzero((along < 0) | (across < 0))
        if wrong.size:
            f = wrong[0]
            raise ValueError(
                f"border facet {f} with vertices {b[f].tolist()} is not in DOLFINx's "
                "quadrilateral vertex order (edges 0-1, 0-2, 1-3, 2-3; opposite edges running "
                "the same way): a cyclic quadrilateral [p0, p1, p2, p3] is [p0, p1, p3, p2]"
            )
    return b


def _canonical(border: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The border's distinct vertices (sorted lexicographically) and its distinct facets as
    vertex ids in a canonical order: a triangle's ids sorted; a quadrilateral (tensor order
    kept) starting at its smallest id, its neighbour with the smaller id as vertex 1. Both are
    the same whatever the facets' order, their vertices' order and the partition."""
    k, nv = border.shape[:2]
    vertices, inverse = np.unique(border.reshape(-1, 3), axis=0, return_inverse=True)
    ids = inverse.reshape(k, nv)
    if nv == 3:
        ids = np.sort(ids, axis=1)
    elif k:
        cyc = ids[:, _CYCLIC]
        first = np.argmin(cyc, axis=1)
        rolled = cyc[np.arange(k)[:, None], (first[:, None] + np.arange(4)) % 4]
        flip = rolled[:, 1] > rolled[:, 3]
        rolled[flip] = rolled[flip][:, [0, 3, 2, 1]]
        ids = rolled[:, _CYCLIC]  # back to tensor order (the permutation is its own inverse)
    facets = np.unique(ids, axis=0) if k else ids
    return vertices, facets


def _count(length: np.ndarray, spacing: float) -> np.ndarray:
    """Intervals ``max(1, ceil(length / spacing))`` (a multiple up to round-off kept)."""
    return np.maximum(1, np.ceil(length / spacing - _CEIL_SLACK)).astype(np.int64)


def _edge_points(vertices: np.ndarray, facets: np.ndarray, spacing: float) -> np.ndarray:
    """Points strictly inside every distinct edge of the facets, ``_count(length)`` intervals,
    from the end point with the smaller id."""
    pairs = [(0, 1), (0, 2), (1, 2)] if facets.shape[1] == 3 else [(0, 1), (0, 2), (1, 3), (2, 3)]
    edges = np.concatenate([facets[:, list(p)] for p in pairs])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    a, b = vertices[edges[:, 0]], vertices[edges[:, 1]]
    n = _count(np.linalg.norm(b - a, axis=1), spacing)
    edge = np.repeat(np.arange(len(edges)), n - 1)
    start = np.repeat(np.cumsum(n - 1) - (n - 1), n - 1)
    i = np.arange(edge.size) - start + 1
    return a[edge] + (i / n[edge])[:, None] * (b - a)[edge]


def _facet_points(vertices: np.ndarray, facets: np.ndarray, spacing: float) -> np.ndarray:
    """Points strictly inside every facet on its lattice (triangles: ``n`` per side from the
    longest edge; quadrilaterals: ``n_u x n_v`` from the longer of each pair of opposite edges),
    facets grouped by their subdivision."""
    p = vertices[facets]  # (k, nv, 3) in canonical order
    out = []
    if facets.shape[1] == 3:
        a, b, c = p[:, 0], p[:, 1], p[:, 2]
        longest = np.max(
            [
                np.linalg.norm(b - a, axis=1),
                np.linalg.norm(c - a, axis=1),
                np.linalg.norm(c - b, axis=1),
            ],
            axis=0,
        )
        count = _count(longest, spacing)
        for n in np.unique(count[count > 2]):
            i, j = np.meshgrid(np.arange(1, n), np.arange(1, n), indexing="ij")
            keep = i + j <= n - 1
            s, t = (i[keep] / n), (j[keep] / n)
            f = np.flatnonzero(count == n)
            pts = (
                a[f, None]
                + s[None, :, None] * (b - a)[f, None]
                + t[None, :, None] * (c - a)[f, None]
            )
            out.append(pts.reshape(-1, 3))
    else:  # tensor order: a = 0, b = 1, d = 2, c = 3
        a, b, d, c = p[:, 0], p[:, 1], p[:, 2], p[:, 3]
        nu = _count(
            np.maximum(np.linalg.norm(b - a, axis=1), np.linalg.norm(c - d, axis=1)), spacing
        )
        nv = _count(
            np.maximum(np.linalg.norm(d - a, axis=1), np.linalg.norm(c - b, axis=1)), spacing
        )
        both = np.stack([nu, nv], axis=1)
        for n_u, n_v in np.unique(both[(nu > 1) & (nv > 1)], axis=0):
            i, j = np.meshgrid(np.arange(1, n_u), np.arange(1, n_v), indexing="ij")
            u, v = (i.ravel() / n_u)[None, :, None], (j.ravel() / n_v)[None, :, None]
            f = np.flatnonzero((nu == n_u) & (nv == n_v))
            pts = (
                (1 - u) * (1 - v) * a[f, None]
                + u * (1 - v) * b[f, None]
                + (1 - u) * v * d[f, None]
                + u * v * c[f, None]
            )
            out.append(pts.reshape(-1, 3))
    return np.concatenate(out) if out else np.empty((0, 3))


def _thin(points: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Which points to keep, greedily in their order: a point is dropped when a point kept before
    it lies closer than its ``radius``."""
    keep = np.ones(points.shape[0], dtype=bool)
    if points.shape[0] < 2:
        return keep
    pairs = cKDTree(points).query_pairs(float(radius.max()), output_type="ndarray")
    if pairs.size == 0:
        return keep
    pairs = np.sort(pairs, axis=1)  # (earlier, later)
    dist = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    pairs = pairs[dist < radius[pairs[:, 1]]]
    if pairs.size == 0:
        return keep
    pairs = pairs[np.argsort(pairs[:, 1], kind="stable")]
    later, start = np.unique(pairs[:, 1], return_index=True)
    stop = np.append(start[1:], len(pairs))
    for j, s, e in zip(later, start, stop, strict=True):  # increasing j: earlier ones are final
        if keep[pairs[s:e, 0]].any():
            keep[j] = False
    return keep


def _triangles(facets: np.ndarray) -> np.ndarray:
    """Facets (k, 3 or 4, 3) as triangles: a quadrilateral as the four triangles from its edges
    to its centroid (exact for a plane quadrilateral; close to a warped one's bilinear face)."""
    if facets.shape[1] == 3:
        return facets
    cyc = facets[:, _CYCLIC]
    centre = cyc.mean(axis=1)
    return np.concatenate(
        [np.stack([cyc[:, m], cyc[:, (m + 1) % 4], centre], axis=1) for m in range(4)]
    )


def _point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise distance from points ``p`` to segments ``a``-``b``."""
    t = b - a
    tt = np.maximum(np.einsum("ki,ki->k", t, t), np.finfo(float).tiny)
    xi = np.clip(np.einsum("ki,ki->k", p - a, t) / tt, 0.0, 1.0)
    return np.linalg.norm(p - a - xi[:, None] * t, axis=1)


def _point_triangle(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Row-wise distance from points ``p`` (m, 3) to triangles ``tri`` (m, 3, 3): to the plane
    where the projection falls inside, else to the nearest side."""
    a, e0, e1 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    r = p - a
    d00, d01, d11 = (np.einsum("ki,ki->k", x, y) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
    r0, r1 = np.einsum("ki,ki->k", r, e0), np.einsum("ki,ki->k", r, e1)
    det = d00 * d11 - d01 * d01
    flat = det <= 1e-14 * np.maximum(d00 * d11, np.finfo(float).tiny)  # degenerate: the sides
    det = np.where(flat, 1.0, det)
    s, t = (d11 * r0 - d01 * r1) / det, (d00 * r1 - d01 * r0) / det
    inside = ~flat & (s >= 0.0) & (t >= 0.0) & (s + t <= 1.0)
    normal = np.cross(e0, e1)
    plane = np.abs(np.einsum("ki,ki->k", r, normal)) / np.sqrt(np.where(flat, 1.0, det))
    sides = np.minimum.reduce(
        [_point_segment(p, tri[:, m], tri[:, k]) for m, k in ((0, 1), (0, 2), (1, 2))]
    )
    return np.where(inside, plane, sides)


def distance_to_facets(points: np.ndarray, facets: np.ndarray, reach: float) -> np.ndarray:
    """Distance (m,) from each point (m, 3) to the nearest facet (k, 3 or 4, 3), exact where it is
    at most ``reach`` (``inf`` further away; quadrilaterals as four triangles, see
    :func:`_triangles`). Local, no communication."""
    d = np.full(points.shape[0], np.inf)
    if points.shape[0] == 0 or facets.shape[0] == 0:
        return d
    tris = _triangles(facets)
    tree = cKDTree(points)
    for start in range(0, len(tris), _CHUNK):
        tri = tris[start : start + _CHUNK]
        centre = tri.mean(axis=1)
        radius = np.linalg.norm(tri - centre[:, None], axis=2).max(axis=1)
        near = tree.query_ball_point(centre, radius + reach)
        count = np.fromiter((len(c) for c in near), dtype=np.int64, count=len(near))
        if count.sum() == 0:
            continue
        which = np.repeat(np.arange(len(tri)), count)
        pt = np.concatenate([np.asarray(c, dtype=np.int64) for c in near])
        np.minimum.at(d, pt, _point_triangle(points[pt], tri[which]))
    return d


def _hollow_centroids(mesh: dolfinx.mesh.Mesh, cells: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """Centroids of the given owned ``cells`` whose closure holds none of the points ``inner``
    (the particles off the border), every rank's, sorted by (x, y, z) (collective). A centroid
    is the mean of the cell's vertices sorted lexicographically: the same bits on every rank."""
    gdim = mesh.geometry.dim
    hollow = np.ones(cells.size, dtype=bool)
    if cells.size and inner.shape[0]:
        _, hit = _compat.colliding_cells(mesh, _compat.bb_tree(mesh, mesh.topology.dim), inner)
        hollow &= ~np.isin(cells, hit)
    nodes = mesh.geometry.x[_compat.geometry_dofmap(mesh)[cells[hollow]], :gdim]
    order = np.lexsort(nodes.transpose(2, 0, 1)[::-1], axis=-1) if nodes.size else None
    if order is not None:
        nodes = np.take_along_axis(nodes, order[:, :, None], axis=1)
    mine = nodes.sum(axis=1) / nodes.shape[1] if nodes.size else np.empty((0, gdim))
    every = np.concatenate(mesh.comm.allgather(mine))
    return every[np.lexsort(every.T[::-1])]


def conforming_layer_3d(
    mesh: dolfinx.mesh.Mesh,
    cells: np.ndarray,
    grid: np.ndarray,
    border: np.ndarray,
    spacing: float,
    tol: float,
) -> np.ndarray:
    """Grid points ``grid`` (m, 3) in the owned ``cells`` (identical on every rank) joined with
    the border layer of the facets ``border`` (k, 3 or 4, 3), every rank's (see the module
    docstring for the rules); collective.

    Grid points closer than ``DROP * spacing`` to a facet are dropped, except those within
    ``tol`` of a border particle, which replace it. A patch cell whose closure is then left
    without a particle off the border (a part of the patch about one cell thick, where the grid
    fell between the border's planes and was dropped) gets one at its centroid when that lies at
    least ``DROP * spacing`` from the border and from every other particle (greedily, in sorted
    order): without it the MLS supports of the two sides' border particles, twice the lattice
    step, stop short of each other. The kept grid points come first, then those centroids, then
    the border particles sorted by (z, y, x). The same set on every rank and whatever the
    partition."""
    vertices, facets = _canonical(border)
    groups = [vertices, _edge_points(vertices, facets, spacing)]
    groups.append(_facet_points(vertices, facets, spacing))
    groups = [g[np.lexsort(g.T[::-1])] for g in groups]  # each sorted by (x, y, z)
    on = np.concatenate(groups)
    radius = np.full(on.shape[0], THIN * spacing)
    radius[: len(vertices)] = tol  # vertices are all kept (merged only when they coincide)
    on = on[_thin(on, radius)]
    # distances to the canonical facets: the same values whatever the partition
    drop = DROP * spacing
    canonical = vertices[facets]
    keep = ~(distance_to_facets(grid, canonical, drop) < drop)
    same = np.zeros(grid.shape[0], dtype=bool)
    if grid.shape[0] and on.shape[0]:
        dist, idx = cKDTree(on).query(grid, distance_upper_bound=2.0 * tol)
        same = dist <= tol
        keep |= same
        on = np.delete(on, idx[same], axis=0)
    kept = grid[keep]
    centroids = _hollow_centroids(mesh, cells, grid[keep & ~same])
    far = distance_to_facets(centroids, canonical, drop) >= drop - tol
    centroids = centroids[far]
    both = np.vstack([kept, on, centroids])
    radius = np.zeros(both.shape[0])  # the grid and border particles are all kept
    radius[kept.shape[0] + on.shape[0] :] = drop - tol
    fill = centroids[_thin(both, radius)[kept.shape[0] + on.shape[0] :]]
    return np.vstack([kept, fill, on[np.lexsort(on.T)]])
