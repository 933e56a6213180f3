"""Quadrature on background cells and facets cut by a crack (2D).

Belytschko et al. 1995 integrate the weak form over the cells of a background mesh (sec. 5.1);
across a crack the shape functions are discontinuous (sec. 3.1, the remark after eq. (3.11), and
sec. 5.2.2), so a cell that a crack cuts is integrated on each side separately and the two crack
faces are traction-free boundaries of the domain.

Method: a cell (a convex polygon: a triangle, or a quadrilateral with straight edges, the image of
a degree-1 map) is cut when a crack segment passes through its interior. It is clipped
successively by the infinite lines of the segments that pass through it (half-plane clipping,
Sutherland–Hodgman: convex pieces stay convex; in the cell that holds a tip or a kink the line
also splits the cell beyond the tip, which only adds pieces). Each piece is fan-triangulated from
its lexicographically smallest vertex and each triangle gets basix's Gauss–Jacobi rule of the
given degree, exact for polynomials of that degree on each piece. No point lies on a crack. Cells
not cut keep exactly the points of :func:`~dolfinx_meshfree.cell_quadrature`.

Crack faces (:func:`crack_face_quadrature`): each segment is split at the cell edges it crosses
and each piece gets Gauss–Legendre points, every point twice, once per side. Sides and normals:
along the polyline's direction (from ``points[i]`` to ``points[i + 1]``, tangent ``t``) the
**+ side is on the left**, the side of ``n_L = (-t_y, t_x)``. The domain on the + side has outward
normal ``-n_L`` on the crack face (pointing to the - side), the domain on the - side ``+n_L``.
With the exterior boundary facets, split where the crack's mouth meets them
(:func:`cut_facet_quadrature`), they give the whole boundary of the cracked domain
(:func:`cracked_boundary_quadrature`), which consistent integration (Chen, Hillman & Rüter 2013,
:func:`~dolfinx_meshfree.physics.operators.consistent_gradients`) needs: for ``f`` smooth on each
side of the crack (continuous elsewhere), ``sum_q grad f w_q = sum_b f n w_b + sum_c f_side(c)
n_c w_c``, exactly when ``f`` is a polynomial of the rule's degree on each piece (on a non-affine
quadrilateral that is not cut, as exact as its own rule).

Growth: a new segment changes the points of :func:`cells_cut_by` it only; re-integrate those
with :func:`cut_cell_quadrature` (the whole crack, those cells) and swap them in with
:func:`replace_cells`; the faces of the old segments do not change.

Parallel: every function works on the local cells (and facets) it is given, without
communication; with the owned ones each crack-face piece is counted on one rank only (a piece
that runs along a cell edge belongs to the cell on its + side), so sums over ranks count every
point once. Checks of the crack's points fail alike on every rank; the convexity check of the
cells near the crack is local (wrap the call in ``parallel.raise_on_all_ranks`` before a
collective call).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from .. import _compat
from .quadrature import QuadraturePoints, _facet_rule, cell_quadrature, facet_quadrature

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = [
    "SidedQuadraturePoints",
    "cells_cut_by",
    "crack_face_quadrature",
    "crack_polylines",
    "cracked_boundary_quadrature",
    "cut_cell_quadrature",
    "cut_facet_quadrature",
    "join_quadrature",
    "replace_cells",
]

#: Relative tolerance (to a cell's diameter) below which a point counts as on a line: a crack that
#: passes closer than this to a cell's boundary does not cut it (the sliver it would cut off has an
#: area below ``TOL`` times the cell's area).
TOL = 1e-12


@dataclass
class SidedQuadraturePoints(QuadraturePoints):
    """Boundary quadrature points with the side of the crack each one is evaluated on.

    Attributes:
        sides: (nq,) +1 or -1 on crack faces (evaluate the shape functions as seen from the + or
            the - side, the + side being left of the polyline's direction), 0 on ordinary boundary
            points (evaluate as usual). On crack faces ``entities`` is the crack segment (numbered
            over all polylines in order) and ``cells`` the local cell that holds the piece.
    """

    sides: np.ndarray | None = None


def _polyline(points: Any, name: str) -> np.ndarray:
    """One polyline as a float (n, 2) array, checked."""
    p = np.asarray(points, dtype=float)
    if p.ndim == 2 and p.shape[1] == 3 and np.all(p[:, 2] == 0.0):
        p = p[:, :2]
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(
            f"{name} should be an (n, 2) array of points (n >= 2), got shape {p.shape}; "
            f"give the polyline's vertices in order"
        )
    if p.shape[0] < 2:
        raise ValueError(
            f"{name} has {p.shape[0]} point(s) {p.tolist()}; a crack needs at least two points"
        )
    bad = ~np.isfinite(p).all(axis=1)
    if np.any(bad):
        raise ValueError(f"{name} has non-finite points {p[bad].tolist()}; give finite coordinates")
    lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
    zero = lengths <= TOL * max(float(lengths.max()), np.finfo(float).tiny)
    if np.any(zero):
        i = int(np.flatnonzero(zero)[0])
        raise ValueError(
            f"{name}: segment {i} from {p[i].tolist()} to {p[i + 1].tolist()} has zero length; "
            f"remove the repeated point"
        )
    return p


def crack_polylines(cracks: Any) -> list[np.ndarray]:
    """The crack polylines as a list of checked (n, 2) arrays.

    Accepts one polyline (an (n, 2) array-like, or an object with a ``points`` attribute such as
    a ``Crack``) or a sequence of them. Raises ``ValueError`` for fewer than two points, non-finite
    coordinates, a wrong shape or a zero-length segment.
    """
    if hasattr(cracks, "points"):
        return [_polyline(cracks.points, "crack")]
    if isinstance(cracks, np.ndarray):
        if cracks.ndim == 3:
            return [_polyline(c, f"crack {i}") for i, c in enumerate(cracks)]
        return [_polyline(cracks, "crack")]
    if isinstance(cracks, list | tuple) and cracks:
        first = cracks[0]
        if hasattr(first, "points") or np.ndim(first) == 2:
            return [
                _polyline(c.points if hasattr(c, "points") else c, f"crack {i}")
                for i, c in enumerate(cracks)
            ]
    return [_polyline(cracks, "crack")]


def _check_degree(degree: int) -> int:
    if int(degree) != degree or degree < 1:
        raise ValueError(f"degree should be an integer >= 1, got {degree!r}")
    return int(degree)


def _cell_polygons(msh: dolfinx.mesh.Mesh, cells: np.ndarray) -> np.ndarray:
    """Vertices of ``cells`` as counter-clockwise convex polygons, shape (nc, nv, 2)."""
    if msh.geometry.dim != 2 or msh.topology.dim != 2:
        raise ValueError(
            f"cut-cell quadrature works on 2D meshes (gdim = tdim = 2), got tdim="
            f"{msh.topology.dim}, gdim={msh.geometry.dim}"
        )
    name = msh.topology.cell_type.name
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :2]
    if name == "quadrilateral":  # DOLFINx's tensor-product vertex order -> around the boundary
        nodes = nodes[:, [0, 1, 3, 2]]
    elif name != "triangle":
        raise ValueError(f"cut-cell quadrature needs triangles or quadrilaterals, got {name}")
    if nodes.shape[1] != (3 if name == "triangle" else 4):
        raise ValueError("cut-cell quadrature needs a degree-1 geometry")
    area = _shoelace(nodes)
    nodes[area < 0] = nodes[area < 0, ::-1]
    return nodes


def _shoelace(p: np.ndarray) -> np.ndarray:
    """Signed areas of polygons (..., nv, 2) (positive when counter-clockwise)."""
    q = np.roll(p, -1, axis=-2)
    return 0.5 * np.sum(p[..., 0] * q[..., 1] - q[..., 0] * p[..., 1], axis=-1)


@dataclass
class _Pieces:
    """Where crack segments meet cells: one row per (cell, segment) pair whose common part has a
    positive length. ``row`` indexes the cell array given, ``seg`` the segment, ``t0 < t1`` the
    segment's parameters of the common part, ``interior`` whether it runs through the cell's
    interior (else along its boundary), ``left`` whether the cell lies on the segment's + side."""

    row: np.ndarray
    seg: np.ndarray
    t0: np.ndarray
    t1: np.ndarray
    interior: np.ndarray
    left: np.ndarray


def _segments(polylines: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Start and end points (ns, 2) of every segment of every polyline, in order."""
    a = np.concatenate([p[:-1] for p in polylines])
    b = np.concatenate([p[1:] for p in polylines])
    return a, b


def _pieces(polys: np.ndarray, a: np.ndarray, b: np.ndarray) -> _Pieces:
    """Clip every segment ``[a_s, b_s]`` to every convex polygon (Cyrus–Beck), a bounding-box
    filter first (the cracks' box, then each segment's); loops over segments (few), vectorised
    over cells."""
    lo, hi = polys.min(axis=1), polys.max(axis=1)
    diam = np.linalg.norm(hi - lo, axis=1)
    near = np.flatnonzero(
        np.all(np.minimum(a, b).min(axis=0) <= hi + TOL * diam[:, None], axis=1)
        & np.all(np.maximum(a, b).max(axis=0) >= lo - TOL * diam[:, None], axis=1)
    )
    polys, lo, hi, diam = polys[near], lo[near], hi[near], diam[near]
    _check_convex(polys)
    edges = np.roll(polys, -1, axis=1) - polys
    normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)  # outward on CCW polygons
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    out: list[tuple[np.ndarray, ...]] = []
    for s in range(a.shape[0]):
        sa, sb = a[s], b[s]
        tol = TOL * diam
        cand = np.flatnonzero(
            np.all(np.minimum(sa, sb) <= hi + tol[:, None], axis=1)
            & np.all(np.maximum(sa, sb) >= lo - tol[:, None], axis=1)
        )
        if cand.size == 0:
            continue
        d = sb - sa
        n, v, tc = normals[cand], polys[cand], tol[cand]
        num = np.einsum("cvg,cvg->cv", n, sa - v)  # signed distance of a from each edge line
        den = n @ d
        par = np.abs(den) <= TOL * np.linalg.norm(d)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -num / den
        t0 = np.max(np.where(~par & (den < 0), t, 0.0), axis=1)
        t1 = np.min(np.where(~par & (den > 0), t, 1.0), axis=1)
        outside = np.any(par & (num > tc[:, None]), axis=1)
        length = (t1 - t0) * np.linalg.norm(d)
        keep = ~outside & (length > tc)
        if not np.any(keep):
            continue
        cand, t0, t1, n, v, tc = cand[keep], t0[keep], t1[keep], n[keep], v[keep], tc[keep]
        mid = sa + 0.5 * (t0 + t1)[:, None] * d
        depth = -np.max(np.einsum("cvg,cvg->cv", n, mid[:, None, :] - v), axis=1)
        interior = depth > tc
        left = (polys[cand].mean(axis=1) - sa) @ np.array([-d[1], d[0]]) > 0.0
        out.append((near[cand], np.full(cand.size, s), t0, t1, interior, left))
    if not out:
        e = np.zeros(0)
        return _Pieces(e.astype(np.int64), e.astype(np.int64), e, e, e.astype(bool), e.astype(bool))
    cols = [np.concatenate(c) for c in zip(*out, strict=True)]
    order = np.lexsort((cols[1], cols[0]))  # by cell, then segment
    return _Pieces(*(c[order] for c in cols))


def _split(poly: np.ndarray, a: np.ndarray, n: np.ndarray, tol: float) -> list[np.ndarray]:
    """The two halves of a convex polygon (nv, 2) cut by the line through ``a`` with unit normal
    ``n`` (Sutherland–Hodgman); vertices within ``tol`` of the line go to both halves."""
    dist = (poly - a) @ n
    side = np.where(dist > tol, 1, np.where(dist < -tol, -1, 0))
    if np.all(side >= 0) or np.all(side <= 0):
        return [poly]
    pos: list[np.ndarray] = []
    neg: list[np.ndarray] = []
    nv = poly.shape[0]
    for i in range(nv):
        j = (i + 1) % nv
        if side[i] >= 0:
            pos.append(poly[i])
        if side[i] <= 0:
            neg.append(poly[i])
        if side[i] * side[j] < 0:
            x = poly[i] + dist[i] / (dist[i] - dist[j]) * (poly[j] - poly[i])
            pos.append(x)
            neg.append(x)
    return [np.array(pos), np.array(neg)]


def _clean(poly: np.ndarray, tol2: float) -> np.ndarray:
    """Drop repeated and collinear vertices (|cross| <= ``tol2``) of a convex polygon; start at
    the lexicographically smallest vertex, so that the fan does not depend on the input order."""
    p = poly
    while p.shape[0] >= 3:
        prev, nxt = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
        u, w = p - prev, nxt - p
        cross = u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]
        flat = np.flatnonzero(np.abs(cross) <= tol2)
        if flat.size == 0:
            break
        p = np.delete(p, flat[0], axis=0)
    if p.shape[0] < 3:
        return p
    start = int(np.lexsort((p[:, 1], p[:, 0]))[0])
    return np.roll(p, -start, axis=0)


def _check_convex(polys: np.ndarray) -> None:
    """Refuse polygons (nc, nv, 2) that are not strictly convex: clipping needs convex cells (a
    valid degree-1 quadrilateral is). A local check, on the cells near the crack."""
    e = np.roll(polys, -1, axis=1) - polys
    f = np.roll(e, -1, axis=1)
    cross = e[..., 0] * f[..., 1] - e[..., 1] * f[..., 0]
    bad = np.flatnonzero(np.any(cross <= 0.0, axis=1))
    if bad.size:
        raise ValueError(
            f"a cell near the crack is not convex (vertices {polys[bad[0]].tolist()}); "
            "cut-cell quadrature clips convex cells: fix the mesh (a valid quadrilateral is convex)"
        )


def _sub_triangles(poly: np.ndarray, a: np.ndarray, b: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Triangles (nt, 3, 2) of one cell's polygon cut by the lines of segments ``segs``."""
    diam = float(np.linalg.norm(poly.max(axis=0) - poly.min(axis=0)))
    pieces = [poly]
    for s in segs:
        d = b[s] - a[s]
        n = np.array([-d[1], d[0]]) / np.linalg.norm(d)
        pieces = [h for p in pieces for h in _split(p, a[s], n, TOL * diam)]
    tris = []
    for p in pieces:
        p = _clean(p, TOL * diam**2)
        for i in range(1, p.shape[0] - 1):
            tris.append(p[[0, i, i + 1]])
    return np.array(tris).reshape(-1, 3, 2)


def cells_cut_by(msh: dolfinx.mesh.Mesh, cells: npt.ArrayLike, cracks: Any) -> np.ndarray:
    """The cells among ``cells`` (local indices) through whose interior a crack segment passes:
    the cells that :func:`cut_cell_quadrature` splits. A crack along a cell edge or through a
    vertex only does not cut the cell.

    Args:
        msh: 2D mesh of triangles or quadrilaterals, degree-1 geometry.
        cells: Local cell indices.
        cracks: One crack polyline ((n, 2) points or an object with ``points``) or a sequence.
    """
    cells = np.asarray(cells, dtype=np.int64)
    a, b = _segments(crack_polylines(cracks))
    pc = _pieces(_cell_polygons(msh, cells), a, b)
    return np.unique(cells[pc.row[pc.interior]])


def cut_cell_quadrature(
    msh: dolfinx.mesh.Mesh, cells: npt.ArrayLike, cracks: Any, degree: int
) -> QuadraturePoints:
    """Cell quadrature of ``cells`` with every cell cut by a crack integrated piece by piece.

    Cells not cut get :func:`~dolfinx_meshfree.cell_quadrature`'s points and weights (bit for bit,
    so without a crack nothing changes). A cut cell is clipped by the lines of the segments that
    pass through it, its convex pieces fan-triangulated, and each triangle gets the Gauss–Jacobi
    rule of ``degree``: exact for polynomials of ``degree`` on each piece; no point lies on a
    crack. Points come grouped by cell in the order of ``cells``; ``entities`` is the cell.

    Args:
        msh: 2D mesh of triangles or quadrilaterals with a degree-1 geometry.
        cells: Local cell indices (e.g. a patch's owned cells).
        cracks: One crack polyline ((n, 2) points, or an object with a ``points`` attribute, e.g.
            a ``Crack``) or a sequence of them.
        degree: Exactness degree (>= 1) of the rules, as in ``cell_quadrature``.
    """
    degree = _check_degree(degree)
    cells = np.asarray(cells, dtype=np.int64)
    a, b = _segments(crack_polylines(cracks))
    polys = _cell_polygons(msh, cells)
    pc = _pieces(polys, a, b)
    rows = np.unique(pc.row[pc.interior])
    if rows.size == 0:
        return cell_quadrature(msh, degree, cells)
    uncut = np.ones(cells.size, dtype=bool)
    uncut[rows] = False
    q = cell_quadrature(msh, degree, cells[uncut])
    tris, owner = [], []
    for r in rows:
        segs = pc.seg[(pc.row == r) & pc.interior]
        t = _sub_triangles(polys[r], a, b, segs)
        tris.append(t)
        owner.append(np.full(t.shape[0], r))
    T, row = np.concatenate(tris), np.concatenate(owner)
    X, w = _compat.quadrature_rule("triangle", degree)
    e1, e2 = T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
    x = T[:, None, 0] + X[None, :, :1] * e1[:, None] + X[None, :, 1:] * e2[:, None]
    jac = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    nq = X.shape[0]
    cut_cells = np.repeat(cells[row], nq)
    pts = np.concatenate([q.points, x.reshape(-1, 2)])
    wts = np.concatenate([q.weights, (jac[:, None] * w[None, :]).ravel()])
    owner_cells = np.concatenate([q.cells, cut_cells])
    per_cell = len(q) // max(int(uncut.sum()), 1)  # cell_quadrature's points per cell
    position = np.concatenate([np.repeat(np.flatnonzero(uncut), per_cell), np.repeat(row, nq)])
    order = np.argsort(position, kind="stable")
    return QuadraturePoints(
        points=pts[order],
        weights=wts[order],
        cells=owner_cells[order],
        entities=owner_cells[order].copy(),
    )


def crack_face_quadrature(
    msh: dolfinx.mesh.Mesh, cells: npt.ArrayLike, cracks: Any, degree: int
) -> SidedQuadraturePoints:
    """Gauss points on both faces of the cracks, within ``cells``.

    Each segment is cut at the cell edges it crosses; each piece inside one of ``cells`` gets the
    Gauss–Legendre rule exact to ``degree`` (that of ``facet_quadrature``). Every point appears
    twice: first all points of the + side (``sides = +1``, left of the polyline's direction, unit
    normal ``-n_L`` pointing to the - side: the outward normal of the domain on the + side), then
    the same points with ``sides = -1`` and normal ``+n_L``, ``n_L = (-t_y, t_x)`` for the
    segment's unit tangent ``t``. A piece that runs along a cell edge belongs to the cell on its
    + side, so with the owned cells each piece is counted on one rank once.

    Args:
        msh: 2D mesh of triangles or quadrilaterals with a degree-1 geometry.
        cells: Local cell indices (the patch's owned cells).
        cracks: One crack polyline or a sequence (as in :func:`cut_cell_quadrature`).
        degree: Exactness degree (>= 1) along the crack.
    """
    degree = _check_degree(degree)
    cells = np.asarray(cells, dtype=np.int64)
    a, b = _segments(crack_polylines(cracks))
    pc = _pieces(_cell_polygons(msh, cells), a, b)
    take = pc.interior | pc.left
    row, seg, t0, t1 = pc.row[take], pc.seg[take], pc.t0[take], pc.t1[take]
    S, ws = _facet_rule("interval", degree)
    npts = S.shape[0]
    d = b[seg] - a[seg]
    length = np.linalg.norm(d, axis=1)
    t = t0[:, None] + (t1 - t0)[:, None] * S[None, :, 0]  # (np, nq)
    x = (a[seg][:, None, :] + t[..., None] * d[:, None, :]).reshape(-1, 2)
    w = ((t1 - t0) * length)[:, None] * ws[None, :]
    n_left = np.repeat(np.stack([-d[:, 1], d[:, 0]], axis=1) / length[:, None], npts, axis=0)
    c = np.repeat(cells[row], npts)
    e = np.repeat(seg, npts)
    m = x.shape[0]
    return SidedQuadraturePoints(
        points=np.concatenate([x, x]),
        weights=np.concatenate([w.ravel(), w.ravel()]),
        cells=np.concatenate([c, c]),
        normals=np.concatenate([-n_left, n_left]),
        entities=np.concatenate([e, e]),
        sides=np.concatenate([np.ones(m, dtype=np.int8), -np.ones(m, dtype=np.int8)]),
    )


def cut_facet_quadrature(
    msh: dolfinx.mesh.Mesh,
    facets: npt.ArrayLike,
    cracks: Any,
    degree: int,
    cells: npt.ArrayLike | None = None,
) -> QuadraturePoints:
    """:func:`~dolfinx_meshfree.facet_quadrature` with the facets that a crack meets (its mouth
    on the exterior boundary) split where it meets them, so that each side of the mouth is
    integrated on its own and no point lies on the crack. Facets not met keep their points bit
    for bit; points stay grouped by facet in the order of ``facets``.

    Args:
        msh: 2D mesh; facets: local facet indices; cracks: as in :func:`cut_cell_quadrature`;
        degree: exactness degree; cells: the cell beside each facet that the normals point out
        of (as in ``facet_quadrature``).
    """
    degree = _check_degree(degree)
    facets = np.asarray(facets, dtype=np.int32)
    a, b = _segments(crack_polylines(cracks))
    q = facet_quadrature(msh, facets, degree, cells)
    if facets.size == 0:
        return q
    ends = msh.geometry.x[_compat.entities_to_geometry(msh, 1, facets), :2]  # (nf, 2, 2)
    p, e = ends[:, 0], ends[:, 1] - ends[:, 0]
    flen = np.linalg.norm(e, axis=1)
    cuts: list[list[float]] = [[] for _ in range(facets.size)]
    for s in range(a.shape[0]):
        d = b[s] - a[s]
        den = e[:, 0] * d[1] - e[:, 1] * d[0]
        r = a[s] - p
        ok = np.abs(den) > TOL * flen * np.linalg.norm(d)
        with np.errstate(divide="ignore", invalid="ignore"):
            sf = (r[:, 0] * d[1] - r[:, 1] * d[0]) / den  # parameter on the facet
            tc = (r[:, 0] * e[:, 1] - r[:, 1] * e[:, 0]) / den  # parameter on the segment
        ttol = TOL * flen / np.linalg.norm(d)
        hit = ok & (sf > TOL) & (sf < 1 - TOL) & (tc >= -ttol) & (tc <= 1 + ttol)
        for f in np.flatnonzero(hit):
            cuts[f].append(float(sf[f]))
    split = np.array([bool(c) for c in cuts])
    if not np.any(split):
        return q
    S, ws = _facet_rule("interval", degree)
    npts = S.shape[0]
    pts, wts, cls, nrm, ent, pos = [], [], [], [], [], []
    keep = ~np.repeat(split, npts)
    for f in np.flatnonzero(split):
        br = np.concatenate([[0.0], np.unique(cuts[f]), [1.0]])
        s = (br[:-1, None] + np.diff(br)[:, None] * S[None, :, 0]).ravel()
        pts.append(p[f] + s[:, None] * e[f])
        wts.append((np.diff(br)[:, None] * ws[None, :]).ravel() * flen[f])
        k = s.size
        cls.append(np.full(k, q.cells[f * npts]))
        nrm.append(np.repeat(q.normals[f * npts][None, :], k, axis=0))
        ent.append(np.full(k, facets[f]))
        pos.append(np.full(k, f))
    position = np.concatenate([np.repeat(np.arange(facets.size), npts)[keep], *pos])
    order = np.argsort(position, kind="stable")
    return QuadraturePoints(
        points=np.concatenate([q.points[keep], *pts])[order],
        weights=np.concatenate([q.weights[keep], *wts])[order],
        cells=np.concatenate([q.cells[keep], *cls])[order],
        normals=np.concatenate([q.normals[keep], *nrm])[order],
        entities=np.concatenate([q.entities[keep], *ent])[order],
    )


def cracked_boundary_quadrature(
    msh: dolfinx.mesh.Mesh,
    facets: npt.ArrayLike,
    cells: npt.ArrayLike,
    cracks: Any,
    degree: int,
    facet_cells: npt.ArrayLike | None = None,
) -> SidedQuadraturePoints:
    """The whole boundary of a cracked patch: its boundary facets (split at the crack's mouths,
    :func:`cut_facet_quadrature`, ``sides = 0``) and both crack faces in ``cells``
    (:func:`crack_face_quadrature`, ``sides = +-1``): the boundary set that consistent
    integration (:func:`~dolfinx_meshfree.physics.operators.consistent_gradients`) needs, with
    shape functions evaluated one-sidedly where ``sides != 0``.

    Args:
        msh: 2D mesh. facets: the patch's boundary facets (local, owned), e.g. from
        ``ParticlePatch.boundary()``. cells: the patch's owned cells. cracks: as in
        :func:`cut_cell_quadrature`. degree: exactness degree. facet_cells: the patch cell beside
        each facet (the normals point out of it; default: the facet's first cell).
    """
    return join_quadrature(
        cut_facet_quadrature(msh, facets, cracks, degree, facet_cells),
        crack_face_quadrature(msh, cells, cracks, degree),
    )


def join_quadrature(*parts: QuadraturePoints) -> SidedQuadraturePoints:
    """Concatenate quadrature point sets (e.g. the exterior boundary from
    :func:`cut_facet_quadrature` and the crack faces from :func:`crack_face_quadrature`) into one
    boundary set; ``sides`` is 0 on parts without sides. Fields that some part lacks
    (``normals``, ``entities``) are ``None`` in the result."""
    if not parts:
        raise ValueError("join_quadrature needs at least one set of points")
    out: dict[str, np.ndarray | None] = {}
    for fld in fields(QuadraturePoints):
        vals = [getattr(p, fld.name) for p in parts]
        out[fld.name] = None if any(v is None for v in vals) else np.concatenate(vals)
    sides = [
        p.sides if getattr(p, "sides", None) is not None else np.zeros(len(p), dtype=np.int8)
        for p in parts
    ]
    return SidedQuadraturePoints(**out, sides=np.concatenate(sides))


def replace_cells(
    q: QuadraturePoints, cells: npt.ArrayLike, q_new: QuadraturePoints
) -> QuadraturePoints:
    """``q`` with the points of ``cells`` replaced by ``q_new`` (appended at the end): after a
    crack grows, re-integrate only :func:`cells_cut_by` the new segment with
    :func:`cut_cell_quadrature` and swap their points in."""
    keep = ~np.isin(q.cells, np.asarray(cells))
    out = {}
    for fld in fields(QuadraturePoints):
        old, new = getattr(q, fld.name), getattr(q_new, fld.name)
        out[fld.name] = None if old is None or new is None else np.concatenate([old[keep], new])
    return QuadraturePoints(**out)
