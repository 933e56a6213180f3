"""Quadrature of cells and facets cut by a crack (geometry/cut_cells.py, issue 10 item 3).

The oracle is the divergence theorem on the cracked domain, which consistent integration needs
under the quadrature actually used: for ``f`` polynomial on each side of the crack,
``sum_q grad f w_q = sum_b f n w_b + sum_c f_side n w_c`` (exterior boundary + both crack faces),
exact to round-off. Areas are checked against the shoelace area of the exact split of the domain
(computed from the crack's points, without the mesh) and of each cell (its own ``cell_quadrature``).

A jump that a polynomial carries cannot end at a tip (a polynomial that vanishes on the crack's
extension vanishes on the whole line), so the tip cases use a jump that vanishes at the tip and
on a rectangle ``R`` beside the last segment: ``f = (c - eta)(xi - s0)(-xi) p(x)`` on ``R``
(``xi``, ``eta``: coordinates along and across the last segment from the tip), 0 elsewhere; the
other three sides of ``R`` are given to ``cut_cell_quadrature`` as extra cut lines (not crack
faces), so that ``f`` is a polynomial on every piece.

Meshes: unit square, triangles and quadrilaterals, regular and perturbed (interior vertices
moved by a smooth deterministic field of up to 0.25 h, so the quadrilaterals are not
parallelograms). Serial and 2 ranks: each rank integrates its owned cells and facets, sums are
allreduced.
"""

import dolfinx_meshfree  # noqa: F401, I001  (must come first: loads lane B's MPI)

import itertools

import dolfinx
import numpy as np
import pytest
import scipy.sparse as sp
from mpi4py import MPI

from conftest import CELL_TYPES, rectangle
from dolfinx_meshfree import _compat
from dolfinx_meshfree.geometry.cut_cells import (
    cells_cut_by,
    crack_face_quadrature,
    crack_polylines,
    cracked_boundary_quadrature,
    cut_cell_quadrature,
    cut_facet_quadrature,
    join_quadrature,
    replace_cells,
)
from dolfinx_meshfree.geometry.quadrature import boundary_facets, cell_quadrature
from dolfinx_meshfree.physics.operators import consistent_gradients

COMM = MPI.COMM_WORLD
N = 8  # cells per side
H = 1.0 / N
#: Divergence-theorem residuals (absolute; f and its terms are O(1)) and areas (relative).
#: Measured (serial and 2 ranks): divergence <= 4.7e-15, side areas <= 3.3e-16, cell areas <=
#: 1.2e-15 (relative); the bounds are far above round-off and far below any real defect.
DIV_TOL = 1e-12
AREA_TOL = 1e-13


def _perturb(x: np.ndarray) -> np.ndarray:
    """Smooth displacement, zero on the boundary of the unit square, at most 0.25 h."""
    b = np.sin(np.pi * x[:, 0]) * np.sin(np.pi * x[:, 1])
    return (
        0.25
        * H
        * b[:, None]
        * np.stack(
            [np.sin(12.9 * x[:, 0] + 7.1 * x[:, 1]), np.cos(5.3 * x[:, 0] - 11.7 * x[:, 1])], axis=1
        )
    )


def _mesh(cell, perturbed, comm=COMM):
    msh = rectangle(comm, [0, 0], [1, 1], [N, N], CELL_TYPES[cell])
    if perturbed:
        x = msh.geometry.x
        x[:, :2] += _perturb(x[:, :2])
    return msh


def _vertex(i, j, perturbed):
    """The mesh vertex that starts at (i h, j h)."""
    x = np.array([[i * H, j * H]])
    return (x + _perturb(x) if perturbed else x)[0]


def _owned(msh):
    return np.arange(msh.topology.index_map(2).size_local, dtype=np.int64)


def _sum(a):
    return COMM.allreduce(np.asarray(a, dtype=float), op=MPI.SUM)


def _dist_to_polyline(x, p):
    d = np.full(x.shape[0], np.inf)
    for a, b in itertools.pairwise(p):
        t = np.clip((x - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
        d = np.minimum(d, np.linalg.norm(x - a - t[:, None] * (b - a), axis=1))
    return d


def _shoelace(p):
    q = np.roll(p, -1, axis=0)
    return 0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1])


# f_+ and f_- with their gradients: linear for degree 1, quadratic for degree >= 2
def _f(x, side, quadratic):
    X, Y = x[:, 0], x[:, 1]
    if side > 0:
        f, g = 1 + 2 * X - 3 * Y, np.stack([2 + 0 * X, -3 + 0 * X], axis=1)
        if quadratic:
            f = f + X**2 - X * Y + 2 * Y**2
            g = g + np.stack([2 * X - Y, -X + 4 * Y], axis=1)
    else:
        f, g = -2 + X + 4 * Y, np.stack([1 + 0 * X, 4 + 0 * X], axis=1)
        if quadratic:
            f = f + 3 * X**2 + X * Y - Y**2
            g = g + np.stack([6 * X + Y, X - 2 * Y], axis=1)
    return f, g


def _through_crack(kind, perturbed):
    """x-monotone cracks from the left edge to the right edge (mouths off the vertices, except
    along the mesh edges)."""
    if kind == "straight":
        return np.array([[0.0, 0.4437], [1.0, 0.4437]])
    if kind == "inclined":
        return np.array([[0.0, 0.2113], [1.0, 0.7391]])
    if kind == "kinked-in-cell":
        return np.array([[0.0, 0.3311], [0.4723, 0.6049], [1.0, 0.4172]])
    if kind == "diagonal":  # corner to corner: through the vertices (regular mesh)
        return np.array([[0.0, 0.0], [1.0, 1.0]])
    if kind == "kinked-at-vertex":  # segments along no mesh edge
        return np.array([[0.0, 0.3311], _vertex(4, 5, perturbed), [1.0, 0.4172]])
    # along mesh edges (through the vertices that start on y = 0.5): no cell is cut
    return np.array([_vertex(i, N // 2, perturbed) for i in range(N + 1)])


THROUGH = ["straight", "inclined", "diagonal", "kinked-in-cell", "kinked-at-vertex", "along-edges"]


def through_crack_figures(cell, perturbed, kind, degree):
    """Divergence-theorem residual and side areas for a crack across the whole square, with
    f = f_+ above and f_- below (different polynomials of the rule's degree, at most 2)."""
    msh = _mesh(cell, perturbed)
    crack = _through_crack(kind, perturbed)
    cells = _owned(msh)
    q = cut_cell_quadrature(msh, cells, crack, degree)
    faces = crack_face_quadrature(msh, cells, crack, degree)
    ext = cut_facet_quadrature(msh, boundary_facets(msh), crack, degree)
    bnd = cracked_boundary_quadrature(msh, boundary_facets(msh), cells, crack, degree)
    assert np.array_equal(bnd.points, join_quadrature(ext, faces).points)
    quadratic = degree >= 2

    def side(x):  # above (+, left of the left-to-right polyline) or below
        return np.where(x[:, 1] > np.interp(x[:, 0], crack[:, 0], crack[:, 1]), 1, -1)

    lhs = np.zeros(2)
    s = side(q.points)
    for sd in (1, -1):
        _, g = _f(q.points[s == sd], sd, quadratic)
        lhs += g.T @ q.weights[s == sd]
    sb = np.where(bnd.sides == 0, side(bnd.points), bnd.sides)
    rhs = np.zeros(2)
    for sd in (1, -1):
        f, _ = _f(bnd.points[sb == sd], sd, quadratic)
        rhs += bnd.normals[sb == sd].T @ (f * bnd.weights[sb == sd])
    lhs, rhs = _sum(lhs), _sum(rhs)
    # areas of the two sides: shoelace of the exact split of the square
    above = np.vstack([crack, [[1.0, 1.0], [0.0, 1.0]]])
    below = np.vstack([[[0.0, 0.0], [1.0, 0.0]], crack[::-1]])
    length = np.linalg.norm(np.diff(crack, axis=0), axis=1).sum()
    no_split = cut_facet_quadrature(msh, boundary_facets(msh), [[2, 2], [3, 3]], degree)
    return {
        "lhs": float(np.abs(lhs).max()),
        "divergence": float(np.abs(lhs - rhs).max()),
        "area_plus": abs(_sum(q.weights[s > 0].sum()) - _shoelace(above)),
        "area_minus": abs(_sum(q.weights[s < 0].sum()) - _shoelace(below)),
        "faces": max(abs(_sum(faces.weights[faces.sides == sd].sum()) - length) for sd in (1, -1)),
        "d_min": COMM.allreduce(float(_dist_to_polyline(q.points, crack).min()), op=MPI.MIN),
        "mouths_split": _sum(len(ext)) > _sum(len(no_split)),
        "cut_cells": int(_sum(cells_cut_by(msh, cells, crack).size)),
    }


@pytest.mark.parametrize("kind", THROUGH)
@pytest.mark.parametrize("perturbed", [False, True])
@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_divergence_theorem_through_crack(cell, perturbed, kind):
    """A crack across the whole square: f = f_+ above, f_- below (degrees 1 and 2)."""
    for degree in (1, 2):
        r = through_crack_figures(cell, perturbed, kind, degree) | {"degree": degree}
        assert r["lhs"] > 0.1  # a real test: the jump matters
        assert r["divergence"] < DIV_TOL, r
        assert r["area_plus"] < AREA_TOL and r["area_minus"] < AREA_TOL, r
        assert r["faces"] < AREA_TOL, r  # each face is as long as the crack
        assert r["d_min"] > 1e-8 * H, r  # no point on the crack (a sliver near a vertex is close)
        # the exterior facets are split at the mouths unless these are mesh vertices (corners);
        # along the edges no cell is cut
        assert r["mouths_split"] == (kind not in ("along-edges", "diagonal")), r
        # (DOLFINx's "right" diagonals run from (0, 0) to (1, 1) on the regular triangle mesh)
        along = kind == "along-edges" or (
            kind == "diagonal" and cell == "triangle" and not perturbed
        )
        assert (r["cut_cells"] == 0) == along, r


def _per_cell(q, values, cells):
    pos = np.full(int(cells.max()) + 1, -1)
    pos[cells] = np.arange(cells.size)
    return np.bincount(pos[q.cells], weights=values, minlength=cells.size)


@pytest.mark.parametrize("degree", [1, 3, 6])
@pytest.mark.parametrize("perturbed", [False, True])
@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_cut_cells_integrate_polynomials(cell, perturbed, degree):
    """Per cut cell, the pieces integrate x^i y^j (i + j <= degree) as the cell's own rule of
    degree + 2 does (exact also on non-affine quadrilaterals, where the rule of ``degree`` itself
    is not: x^i y^j times det J has degree i + j + 1 in each reference variable); uncut cells keep
    their points."""
    msh = _mesh(cell, perturbed)
    cells = _owned(msh)
    crack = _through_crack("kinked-in-cell", perturbed)
    q = cut_cell_quadrature(msh, cells, crack, degree)
    ref = cell_quadrature(msh, degree + 2, cells)
    cut = cells_cut_by(msh, cells, crack)
    assert _sum(cut.size) >= N  # the crack crosses the square
    worst = 0.0
    for i in range(degree + 1):
        for j in range(degree + 1 - i):
            v = _per_cell(q, q.points[:, 0] ** i * q.points[:, 1] ** j * q.weights, cells)
            r = _per_cell(ref, ref.points[:, 0] ** i * ref.points[:, 1] ** j * ref.weights, cells)
            worst = max(worst, float(np.abs(v - r)[np.isin(cells, cut)].max() / H**2))
    assert COMM.allreduce(worst, op=MPI.MAX) < AREA_TOL
    # uncut cells: exactly cell_quadrature's points, weights and order
    plain = cell_quadrature(msh, degree, np.setdiff1d(cells, cut))
    mine = ~np.isin(q.cells, cut)
    assert np.array_equal(q.points[mine], plain.points)
    assert np.array_equal(q.weights[mine], plain.weights)
    assert np.array_equal(q.cells[mine], plain.cells)


def test_no_crack_in_the_cells_changes_nothing():
    msh = _mesh("quadrilateral", True)
    cells = _owned(msh)
    left = cells[: cells.size // 2]
    far = np.array([[1.5, 0.2], [1.7, 0.9]])  # outside the square
    q, ref = cut_cell_quadrature(msh, left, far, 3), cell_quadrature(msh, 3, left)
    for name in ("points", "weights", "cells", "entities"):
        assert np.array_equal(getattr(q, name), getattr(ref, name))
    assert len(crack_face_quadrature(msh, left, far, 3)) == 0


def _tip_crack(kind, tip_at, perturbed):
    """Edge crack from the left edge to a tip at (near) (0.56, 0.5): in a cell, at the midpoint
    of a mesh edge, or at a mesh vertex; straight or with a kink."""
    if tip_at == "cell":
        tip = np.array([0.5637, 0.5281])
    elif tip_at == "edge":
        tip = 0.5 * (_vertex(4, 4, perturbed) + _vertex(5, 4, perturbed))
    else:
        tip = _vertex(5, 4, perturbed)
    if kind == "straight":
        return np.array([[0.0, 0.4113], tip])
    return np.array([[0.0, 0.3309], [0.3127, 0.4211], tip])


def tip_figures(cell, perturbed, kind, tip_at):
    """Edge crack with its tip inside: residuals of a jump that runs up to the tip (f on the
    rectangle R beside the last segment) and of a continuous f over the whole square."""
    degree = 4  # f is quartic; grad f cubic (exact on the non-affine quads' rule of degree 4)
    msh = _mesh(cell, perturbed)
    crack = _tip_crack(kind, tip_at, perturbed)
    cells = _owned(msh)
    tip, prev = crack[-1], crack[-2]
    t = (tip - prev) / np.linalg.norm(tip - prev)
    n = np.array([-t[1], t[0]])  # + side of the last segment
    s0, c = -0.5 * np.linalg.norm(tip - prev), 0.2
    R = tip + np.array([[0.0, c], [s0, c], [s0, 0.0]]) @ np.stack([t, n])
    rect = np.vstack([tip, R])  # the three sides of R that are not crack
    q = cut_cell_quadrature(msh, cells, [crack, rect], degree)
    # f has a kink on the crack at xi = s0: the faces are split there by an extra (collinear)
    # point of the polyline, which does not change the crack
    split = np.vstack([crack[:-1], R[2], tip])
    faces = crack_face_quadrature(msh, cells, split, degree)

    def local(x):
        return (x - tip) @ t, (x - tip) @ n

    def f_R(x):
        xi, eta = local(x)
        inside = (xi > s0) & (xi < 0) & (eta > 0) & (eta < c)
        p = 1 + x[:, 0] - 2 * x[:, 1]
        dp = np.array([1.0, -2.0])
        b = (c - eta) * (xi - s0) * (-xi)
        db = np.outer(-(xi - s0) * (-xi), n) + np.outer((c - eta) * (s0 - 2 * xi), t)
        scale = 1.0 / (c * s0**2 / 4)
        f = np.where(inside, b * p, 0.0) * scale
        g = np.where(inside[:, None], db * p[:, None] + b[:, None] * dp, 0.0) * scale
        return f, g, inside

    _, g, inside = f_R(q.points)
    lhs = g.T @ q.weights
    on_last = faces.entities == split.shape[0] - 2  # the part of the crack beside R
    xi, _ = local(faces.points)  # the + side's limit of f (eta -> 0+); f_- = 0
    p = 1 + faces.points[:, 0] - 2 * faces.points[:, 1]
    f_plus = c * (xi - s0) * (-xi) * p / (c * s0**2 / 4)
    fc = np.where((faces.sides > 0) & on_last, f_plus, 0.0)
    rhs = faces.normals.T @ (fc * faces.weights)  # f = 0 on the exterior boundary
    lhs, rhs = _sum(lhs), _sum(rhs)
    out = {
        "lhs": float(np.abs(lhs).max()),
        "divergence_jump": float(np.abs(lhs - rhs).max()),
        "area_R": abs(_sum(q.weights[inside].sum()) - c * abs(s0)),
    }

    # crack only: continuous quadratic f, the crack faces cancel pairwise
    q = cut_cell_quadrature(msh, cells, crack, degree)
    faces = crack_face_quadrature(msh, cells, crack, degree)
    ext = cut_facet_quadrature(msh, boundary_facets(msh), crack, degree)
    bnd = join_quadrature(ext, faces)
    _, g = _f(q.points, 1, True)
    f, _ = _f(bnd.points, 1, True)
    res = _sum(g.T @ q.weights - bnd.normals.T @ (f * bnd.weights))
    ref = cell_quadrature(msh, degree, cells)
    area = np.abs(_per_cell(q, q.weights, cells) - _per_cell(ref, ref.weights, cells)) / H**2
    length = np.linalg.norm(np.diff(crack, axis=0), axis=1).sum()
    tip_cells = cells_cut_by(msh, cells, crack[-2:])
    return out | {
        "divergence_smooth": float(np.abs(res).max()),
        "area_cells": COMM.allreduce(float(area.max()), op=MPI.MAX),
        "faces": max(abs(_sum(faces.weights[faces.sides == sd].sum()) - length) for sd in (1, -1)),
        "d_min": COMM.allreduce(float(_dist_to_polyline(q.points, crack).min()), op=MPI.MIN),
        "cut_cells": int(_sum(cells_cut_by(msh, cells, crack).size)),
        "last_segment_cells": int(_sum(tip_cells.size)),
    }


@pytest.mark.parametrize("kind", ["straight", "kinked"])
@pytest.mark.parametrize("perturbed", [False, True])
@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_divergence_theorem_at_a_tip(cell, perturbed, kind):
    for tip_at in ("cell", "edge", "vertex"):
        r = tip_figures(cell, perturbed, kind, tip_at) | {"tip_at": tip_at}
        assert r["lhs"] > 0.02, r  # a real test: measured >= 0.04
        assert r["divergence_jump"] < DIV_TOL and r["divergence_smooth"] < DIV_TOL, r
        assert r["area_R"] < AREA_TOL and r["area_cells"] < AREA_TOL, r
        assert r["faces"] < AREA_TOL, r  # both faces end at the tip
        assert r["d_min"] > 1e-8 * H, r
        assert r["last_segment_cells"] >= 2, r


def _sorted_points(q):
    pts = np.vstack(COMM.allgather(np.column_stack([q.points, q.weights])))
    return pts[np.lexsort(pts.T[::-1])]


@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_same_points_serial_and_parallel(cell):
    """The points of the distributed mesh (gathered) are those of the same mesh on one rank."""
    crack = _tip_crack("kinked", "cell", True)
    dist, local = _mesh(cell, True), _mesh(cell, True, MPI.COMM_SELF)
    for fn in (cut_cell_quadrature, crack_face_quadrature):
        a = _sorted_points(fn(dist, _owned(dist), crack, 3))
        b = fn(local, _owned(local), crack, 3)
        b = np.column_stack([b.points, b.weights])
        b = b[np.lexsort(b.T[::-1])]
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)


def test_growth_reintegrates_only_the_cells_the_new_segment_cuts():
    msh = _mesh("triangle", True)
    cells = _owned(msh)
    old = _tip_crack("kinked", "cell", True)
    step = np.array([old[-1], old[-1] + [0.16, 0.09]])  # a kink at the old tip
    new = np.vstack([old, step[1:]])
    touched = cells_cut_by(msh, cells, step)
    q_old, q_new = cut_cell_quadrature(msh, cells, old, 3), cut_cell_quadrature(msh, cells, new, 3)

    def by_cell(q):
        key = np.lexsort((q.points[:, 1], q.points[:, 0], q.cells))
        return np.column_stack([q.cells, q.points, q.weights])[key]

    changed = [
        c
        for c in cells
        if not np.array_equal(
            by_cell(q_old)[by_cell(q_old)[:, 0] == c], by_cell(q_new)[by_cell(q_new)[:, 0] == c]
        )
    ]
    assert np.array_equal(np.array(changed, dtype=np.int64), touched)
    assert _sum(touched.size) >= 2
    q_up = replace_cells(q_old, touched, cut_cell_quadrature(msh, touched, new, 3))
    assert np.array_equal(by_cell(q_up), by_cell(q_new))


@pytest.mark.parametrize(
    ("crack", "degree", "match"),
    [
        ([[0.1, 0.5]], 2, "at least two points"),
        ([[0.1, 0.5], [np.nan, 0.5]], 2, "non-finite"),
        ([[0.1, 0.5], [0.4, 0.5], [0.4, 0.5]], 2, "zero length"),
        ([0.1, 0.5, 0.4], 2, r"\(n, 2\)"),
        ([[0.1, 0.5], [0.4, 0.5]], 0, "degree"),
        ([[0.1, 0.5], [0.4, 0.5]], 1.5, "degree"),
    ],
)
def test_bad_input(crack, degree, match):
    msh = _mesh("triangle", False)
    cells = _owned(msh)
    for fn in (cut_cell_quadrature, crack_face_quadrature):
        with pytest.raises(ValueError, match=match):
            fn(msh, cells, crack, degree)


def test_crack_objects_and_lists():
    """A ``Crack``-like object (with ``points``) and a list of polylines are accepted."""

    class Crack:
        points = np.array([[0.1, 0.5], [0.4, 0.5]])

    assert np.array_equal(crack_polylines(Crack())[0], Crack.points)
    two = crack_polylines([Crack(), [[0.6, 0.1], [0.7, 0.2], [0.9, 0.2]]])
    assert [p.shape for p in two] == [(2, 2), (3, 2)]
    assert crack_polylines([[0.0, 0.0], [1.0, 1.0]])[0].shape == (2, 2)


def test_bad_meshes():
    """A 3D mesh, and a non-convex cell that a crack cuts (a local check: the mesh is on one
    rank here; callers with a distributed mesh wrap the call in ``raise_on_all_ranks``)."""
    cube = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
    with pytest.raises(ValueError, match="2D meshes"):
        cut_cell_quadrature(cube, [0], [[0.1, 0.5], [0.4, 0.5]], 2)
    msh = _mesh("quadrilateral", False, MPI.COMM_SELF)
    x = msh.geometry.x
    v = np.flatnonzero(np.all(np.isclose(x[:, :2], [4 * H, 4 * H]), axis=1))
    x[v, :2] += 0.8 * H  # beyond the diagonal of the cell [4h, 5h]^2: a reflex vertex
    crack = [[0.0, 4.5 * H], [1.0, 4.5 * H]]
    with pytest.raises(ValueError, match=r"not convex \(vertices .*0\.6"):
        cut_cell_quadrature(msh, _owned(msh), crack, 2)


@pytest.mark.parametrize("perturbed", [False, True])
def test_consistent_integration_sees_the_crack_faces(perturbed):
    """``consistent_gradients`` with P1 hats split by the crack (phi_I on the + side, phi_I on
    the - side: linear on every piece, discontinuous across the crack only). The quadrature is
    exact for them, so with the crack faces in the boundary set the VCI correction xi_I must
    vanish (round-off); without them it is O(1). One mesh per rank (COMM_SELF)."""
    msh = _mesh("triangle", perturbed, MPI.COMM_SELF)
    crack = _through_crack("kinked-in-cell", perturbed)
    cells, degree = _owned(msh), 2
    q = cut_cell_quadrature(msh, cells, crack, degree)
    bnd = cracked_boundary_quadrature(msh, boundary_facets(msh), cells, crack, degree)
    dofs = _compat.geometry_dofmap(msh)
    X = msh.geometry.x[:, :2]
    ncols = 2 * X.shape[0]

    def side(x):
        return np.where(x[:, 1] > np.interp(x[:, 0], crack[:, 0], crack[:, 1]), 1, -1)

    def hats(points, owner, sides):
        """Values and gradients of the split hats at points in cells ``owner``."""
        v = X[dofs[owner]]  # (n, 3, 2)
        J = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]], axis=2)  # columns: edges
        Jinv = np.linalg.inv(J)
        ref = np.einsum("nij,nj->ni", Jinv, points - v[:, 0])
        lam = np.column_stack([1 - ref.sum(axis=1), ref])
        dref = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
        grad = np.einsum("kj,nji->nki", dref, Jinv)  # (n, 3, 2)
        rows = np.repeat(np.arange(points.shape[0]), 3)
        cols = (2 * dofs[owner] + (sides < 0)[:, None]).ravel()

        def mat(vals):
            return sp.csr_matrix((vals.ravel(), (rows, cols)), shape=(points.shape[0], ncols))

        return mat(lam), [mat(grad[..., k]) for k in range(2)]

    N, G = hats(q.points, q.cells, side(q.points))
    sb = np.where(bnd.sides == 0, side(bnd.points), bnd.sides)
    Nb, _ = hats(bnd.points, bnd.cells, sb)
    used = np.flatnonzero(np.abs(N).sum(axis=0).A1 > 0)
    N, G, Nb = N[:, used], [g[:, used] for g in G], Nb[:, used]

    def correction(Nb, w, n):
        G2 = consistent_gradients(N, G, q.weights, Nb, w, n, MPI.COMM_SELF)
        return max(abs(G2[k] - G[k]).max() for k in range(2)) / max(abs(g).max() for g in G)

    full = correction(Nb, bnd.weights, bnd.normals)
    assert full < 1e-12  # measured 1.3e-14 (regular), 5e-15 (perturbed)
    ext = bnd.sides == 0  # the crack faces left out: a large correction
    assert correction(Nb[ext], bnd.weights[ext], bnd.normals[ext]) > 0.1  # measured 2.1, 1.2
