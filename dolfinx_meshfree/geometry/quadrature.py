"""Quadrature on background cells and boundary facets of a DOLFINx mesh (vectorised).

The FE mesh's own cells serve as EFG integration cells (Belytschko et al. 1995, sec. 5.1: "a cell
structure that overlays Omega_E"). Each rank integrates over the cells it owns and the exterior
facets it owns, so sums over ranks count every point once. Any dimension: cells are triangles,
quadrilaterals, tetrahedra or hexahedra (basix rules), facets segments, triangles or
quadrilaterals.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import basix
import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from .. import _compat

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = [
    "DYNAMIC_FACET_DEGREE",
    "QuadraturePoints",
    "boundary_facets",
    "cell_quadrature",
    "cell_sizes",
    "facet_normals",
    "facet_quadrature",
    "gauss_legendre",
    "lattice_quadrature",
    "particle_quadrature_degree",
    "reference_facet_points",
    "require_affine",
]

#: The exactness degree of the facet rule of tractions in explicit dynamics (3 Gauss points on
#: a segment). The smoothed particle integration of a dynamic model uses it on the cells'
#: facets, so that the particles' boundary terms and the tractions share one rule (the patch
#: test, :mod:`~dolfinx_meshfree.geometry.smoothing`).
DYNAMIC_FACET_DEGREE = 4


@dataclass
class QuadraturePoints:
    """Physical quadrature points with weights.

    Attributes:
        points: (nq, gdim). weights: (nq,), reference weight times |det J|.
        cells: (nq,) local cell (or, on facets, the local cell adjacent to the facet).
        normals: (nq, gdim) outward unit normals on facets, ``None`` on cells.
        entities: (nq,) local facet index on facets, the cell index on cells.
    """

    points: np.ndarray
    weights: np.ndarray
    cells: np.ndarray
    normals: np.ndarray | None = None
    entities: np.ndarray | None = None

    def __len__(self) -> int:
        return self.weights.shape[0]


@functools.lru_cache(maxsize=64)
def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """NumPy's ``leggauss(n)`` (points and weights on [-1, 1]), computed once per ``n`` and
    kept read-only: the same arrays, without its eigenvalue solve and Newton refinement at
    each call (5 ms of a 31 ms rebuild of Kalthoff-Winkler's SIF tables, 9 calls)."""
    x, w = np.polynomial.legendre.leggauss(n)
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


def require_affine(msh: dolfinx.mesh.Mesh, what: str) -> None:
    """Refuse a mesh whose coordinate element has degree > 1 (curved cells, e.g. gmsh's
    second-order meshes), naming ``what`` and the fix. The particle methods map quadrature,
    particles, facets and point evaluation with the cells' vertices (P1/Q1 geometry). The
    degree is the same on every rank: every rank raises."""
    degree = _compat.coordinate_degree(msh)
    if degree != 1:
        raise ValueError(
            f"{what}: the mesh has a degree-{degree} coordinate element (curved cells); the "
            "particle methods need degree-1 (straight-sided) cells. Make the mesh with "
            "first-order geometry (gmsh: leave out gmsh.model.mesh.setOrder; "
            "dolfinx.io.gmshio.model_to_mesh then builds degree-1 cells), refined where the "
            "boundary curves: mf.boundary_facets selects its straight facets by their vertices"
        )


def cell_quadrature(
    msh: dolfinx.mesh.Mesh, degree: int, cells: npt.ArrayLike | None = None
) -> QuadraturePoints:
    """Gauss(–Jacobi) points on owned cells, exact for polynomials of ``degree`` on affine cells.

    Args:
        msh: Mesh with a degree-1 geometry.
        degree: Quadrature degree; 7 gives the 4 x 4 Gauss rule on quadrilaterals used by
            Belytschko et al. 1995, sec. 5.1.2 (4 x 4 x 4 on hexahedra).
        cells: Local cell indices (default: every owned cell).
    """
    require_affine(msh, "cell_quadrature")
    X, w = _compat.quadrature_rule(msh.topology.cell_type.name, degree)
    return _mapped_rule(msh, X, w, cells)


def lattice_quadrature(
    msh: dolfinx.mesh.Mesh, subdivisions: int, cells: npt.ArrayLike | None = None
) -> QuadraturePoints:
    """The composite midpoint rule of ``subdivisions`` sub-cells per reference edge on owned
    ``cells`` (default every owned cell): the midpoints of the ``m^d`` sub-squares (sub-cubes) of
    the reference cell, or on a simplex the centroids of its ``m^d`` equal sub-simplices
    (Freudenthal's subdivision, :func:`_kuhn_centroids`), mapped as :func:`cell_quadrature`'s
    points.

    For integrands that are not smooth (the indicator of a particle's Voronoi region,
    :class:`~dolfinx_meshfree.ParticleSet`'s volumes) a Gauss rule of any degree errs by the
    placement of its few points about the discontinuity, and does not converge steadily (3 x 3,
    5 x 5 and 6 x 6 points on square cells of four particles each: regions up to 23, 105 and
    13 % off their area, measured). The lattice's error falls as ``1 / m``, and it is zero
    where the regions' edges lie on its sub-cells' edges: a grid of particles at the vertices,
    or at ``h / k`` with ``m`` a multiple of ``2 k``. Exact for linear functions on affine
    cells, and for the area of a quadrilateral."""
    cname = msh.topology.cell_type.name
    tdim = msh.topology.dim
    m = int(subdivisions)
    if m < 1:
        raise ValueError(f"subdivisions={subdivisions!r} must be an integer >= 1")
    if cname in ("triangle", "tetrahedron"):
        X = _kuhn_centroids(tdim, m)
        w = np.full(len(X), (0.5 if tdim == 2 else 1.0 / 6.0) / len(X))
    else:
        c = (np.arange(m) + 0.5) / m
        X = np.stack(np.meshgrid(*[c] * tdim, indexing="ij"), axis=-1).reshape(-1, tdim)
        w = np.full(len(X), 1.0 / m**tdim)
    return _mapped_rule(msh, X, w, cells)


def _kuhn_centroids(tdim: int, m: int) -> np.ndarray:
    """The centroids of the ``m^d`` simplices of the reference simplex's Freudenthal (Kuhn)
    subdivision: the sub-cubes of the ``m``-lattice on the unit box, each cut into the ``d!``
    simplices ``x_s(1) >= ... >= x_s(d)``, those inside the Kuhn simplex ``1 >= x >= y (>= z) >=
    0``, mapped onto the reference simplex by ``X = x - y, Y = y (- z), (Z = z)``. Their faces
    lie on the planes ``X, Y, Z, X + Y, Y + Z, X + Y + Z = k / m``."""
    corners = np.stack(np.meshgrid(*[np.arange(m)] * tdim, indexing="ij"), axis=-1)
    corners = corners.reshape(-1, tdim).astype(float)
    points = []
    for order in itertools.permutations(range(tdim)):
        # the simplex of the unit cube whose coordinates decrease in this order: its vertices
        # 0, e_s1, e_s1 + e_s2, ...; centroid sum_k (d - k) e_sk / (d + 1)
        local = np.zeros(tdim)
        local[list(order)] = (tdim - np.arange(tdim)) / (tdim + 1.0)
        x = (corners + local) / m
        inside = np.all(np.diff(x, axis=1) < 0.0, axis=1)  # x > y (> z): in the Kuhn simplex
        points.append(x[inside])
    x = np.concatenate(points)
    return np.column_stack([x[:, :-1] - x[:, 1:], x[:, -1]])


def _mapped_rule(
    msh: dolfinx.mesh.Mesh, X: np.ndarray, w: np.ndarray, cells: npt.ArrayLike | None
) -> QuadraturePoints:
    """The reference rule ``(X, w)`` mapped onto the local ``cells`` (default every owned cell)
    by their degree-1 geometry: points and weights times ``|det J|``."""
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    if cells is None:
        cells = np.arange(msh.topology.index_map(tdim).size_local, dtype=np.int64)
    cells = np.asarray(cells, dtype=np.int64)
    cname = msh.topology.cell_type.name
    tab = _compat.basix_lagrange_p1(cname).tabulate(1, X)  # (1+tdim, nqr, nv, 1)
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]  # (nc, nv, gdim)
    x = np.matmul(tab[0, :, :, 0], nodes)  # (nc, nqr, gdim)
    # J[c, q, g, d] = sum_v dphi_v/dX_d(X_q) x_cvg, as (nc, tdim, nqr, gdim) products
    J = np.matmul(tab[1:, None, :, :, 0], nodes[None]).transpose(1, 2, 3, 0)
    detJ = np.abs(_det(J))
    nq = X.shape[0]
    return QuadraturePoints(
        points=x.reshape(-1, gdim),
        weights=(detJ * w[None, :]).ravel(),
        cells=np.repeat(cells, nq),
        entities=np.repeat(cells, nq),
    )


#: The factor that turns a cell's volume into the side of the square or cube it stands for: a
#: triangle is half a square, a tetrahedron a sixth of a cube.
_CELL_FILL = {
    "interval": 1.0,
    "triangle": 0.5,
    "quadrilateral": 1.0,
    "tetrahedron": 1.0 / 6.0,
    "hexahedron": 1.0,
}


def cell_sizes(msh: dolfinx.mesh.Mesh, cells: npt.ArrayLike) -> np.ndarray:
    """The size ``h`` of local ``cells``: the side of the square (cube) whose area (volume) the
    cell fills, ``(|c| / f)^(1/tdim)`` with ``f`` 1 for quadrilaterals and hexahedra, 1/2 for
    triangles and 1/6 for tetrahedra (so that the cells of a structured mesh of squares split in
    simplices have the squares' side). The crack band width of a law that softens (Bazant & Oh
    1983) on a cell or a particle rule's cell."""
    cells = np.asarray(cells, dtype=np.int64)
    if cells.size == 0:
        return np.zeros(0)
    unique, inverse = np.unique(cells, return_inverse=True)
    q = cell_quadrature(msh, 1, unique)
    volume = np.bincount(np.searchsorted(unique, q.cells), weights=q.weights, minlength=unique.size)
    fill = _CELL_FILL[msh.topology.cell_type.name]
    return ((volume / fill) ** (1.0 / msh.topology.dim))[inverse]


#: The fewest Gauss points per particle of a particle stiffness's default rule
#: (:func:`particle_quadrature_degree`): a square cell's 4 x 4 points with a particle at each
#: vertex give 16, less one so that no mesh of squares or cubes with particles at its vertices
#: or at ``h / 2`` sits on the threshold.
POINTS_PER_PARTICLE = 15


def particle_quadrature_degree(
    msh: dolfinx.mesh.Mesh,
    cells: npt.ArrayLike,
    positions: np.ndarray,
    degree: object = None,
    cracked: bool = False,
) -> int:
    """The Gauss degree of a particle stiffness on the local integration ``cells``: ``degree``
    if given (refused unless an integer >= 1: ValueError, on every rank alike), 7 in a model
    with cracks, else the default (collective): the lowest odd degree from 7 whose rule has at
    least
    :data:`POINTS_PER_PARTICLE` points per particle, the particles per cell counted as the
    cells' mean volume (over every rank) over ``s^d``, ``s`` the median over the particles of the
    mean distance to their ``2 d`` nearest neighbours (``positions`` replicated): on a grid its
    spacing, which the border particles do not change; on a jittered grid a little shorter,
    which errs on the side of more points. Particles at the vertices keep degree 7 (4 x 4
    points on quadrilaterals, 4 x 4 x 4 on hexahedra, 15 and 64 points on triangles and
    tetrahedra); particles at ``h / 2`` get 15 on quadrilaterals (8 x 8), 13 on triangles, 9 on
    hexahedra, and 7 still on tetrahedra (six to a cube).

    Why: consistent integration (VCI, Chen, Hillman & Rüter 2013) corrects each test gradient
    by the cell rule's error in integrating it, and with four particles to a cell on 4 x 4
    points that error is large near the free edges. The EFG cantilever with particles at
    ``h / 2`` stalled (L2 error 6.69e-4, 3.18e-4, 2.05e-4 at h = 2, 1, 0.5: rates 1.07, 0.63),
    converges at 7 x 7 (7.94e-4, 1.09e-4, 1.73e-5: 2.86, 2.66) and at 8 x 8 as particles at
    the vertices do on 4 x 4 (7.78e-4, 1.01e-4, 1.33e-5: 2.94, 2.93); the boundary rule's
    degree made no difference. On triangles at ``h / 2`` the L2 rate fell too (9.88e-4,
    2.27e-4, 7.12e-5 at degree 7: 2.12, 1.67; 8.05e-4, 1.13e-4, 1.82e-5 at 13: 2.83, 2.63).

    With cracks the cut cells' pieces have rules of their own, and a finer rule on the crack
    faces met one-sided supports too thin for the MLS: three collinear particles at a face
    point half a spacing from an edge crack's mouth (the crack 0.05 spacings above a particle
    row, particles at ``h / 2``: a singular moment matrix). A cracked model keeps degree 7
    unless given one."""
    if degree is not None:
        if isinstance(degree, bool) or not (isinstance(degree, int | np.integer) and degree >= 1):
            raise ValueError(
                f"quadrature_degree={degree!r} must be an integer >= 1, or None for the default "
                f"(at least {POINTS_PER_PARTICLE} Gauss points per particle)"
            )
        return int(degree)
    if cracked:
        return 7
    cells = np.asarray(cells, dtype=np.int64)
    q = cell_quadrature(msh, 1, cells)
    total = msh.comm.allreduce(np.array([q.weights.sum(), cells.size], dtype=float))
    spacing = 0.0
    if len(positions) > 1:
        k = min(2 * msh.topology.dim, len(positions) - 1)  # a grid's axis neighbours
        d = cKDTree(positions).query(positions, k=k + 1)[0][:, 1:]
        spacing = float(np.median(d.mean(axis=1)))
    if total[1] == 0 or spacing <= 0.0:
        return 7
    per_cell = total[0] / total[1] / spacing**msh.topology.dim
    cname = msh.topology.cell_type.name
    degree = 7
    while degree < 31 and len(_compat.quadrature_rule(cname, degree)[1]) < (
        POINTS_PER_PARTICLE * per_cell
    ):
        degree += 2
    return degree


def _det(J: np.ndarray) -> np.ndarray:
    """Determinants of a stack of square matrices (..., n, n), written out for n = 2, 3 (numpy's
    LAPACK loop over small matrices took as long as the whole rule), else numpy's."""
    n = J.shape[-1]
    if J.shape[-2] != n or n not in (2, 3):
        return np.linalg.det(J)
    if n == 2:
        return J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    return (
        J[..., 0, 0] * (J[..., 1, 1] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 1])
        - J[..., 0, 1] * (J[..., 1, 0] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 0])
        + J[..., 0, 2] * (J[..., 1, 0] * J[..., 2, 1] - J[..., 1, 1] * J[..., 2, 0])
    )


def boundary_facets(
    msh: dolfinx.mesh.Mesh, marker: Callable[[np.ndarray], npt.ArrayLike] | None = None
) -> np.ndarray:
    """Owned exterior facets (local indices), optionally those that ``marker`` selects.

    ``marker(x)`` takes coordinates shaped (3, n) like DOLFINx's ``locate_entities_boundary``.
    A facet is selected when the marker holds at all its vertices, as DOLFINx selects it, or at
    its midpoint. The vertices carry a marker of a curved boundary (``np.isclose(r, R)``), whose
    straight facets' midpoints lie off the curve; the midpoint carries a strict inequality at a
    facet's end (``x[0] < 0.5`` on a facet ending at 0.5).
    """
    import dolfinx.mesh as dmesh

    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = dmesh.exterior_facet_indices(msh.topology)
    facets = facets[facets < msh.topology.index_map(tdim - 1).size_local]
    if marker is not None and facets.size:
        nodes = msh.geometry.x[_compat.entities_to_geometry(msh, tdim - 1, facets)]
        keep = np.asarray(marker(nodes.mean(axis=1).T), dtype=bool)
        # the vertices: the first nodes of each facet (DOLFINx numbers a facet's vertices
        # before its higher-order nodes)
        facet_name = _FACET_CELLS.get(msh.topology.cell_type.name, "point")
        nv = {"point": 1, "interval": 2, "triangle": 3, "quadrilateral": 4}[facet_name]
        vertices = nodes[:, :nv]  # (nf, nv, 3)
        at_vertices = np.asarray(marker(vertices.reshape(-1, 3).T), dtype=bool)
        keep |= at_vertices.reshape(vertices.shape[:2]).all(axis=1)
        facets = facets[keep]
    return np.asarray(facets, dtype=np.int32)


_FACET_CELLS = {
    "triangle": "interval",
    "quadrilateral": "interval",
    "tetrahedron": "triangle",
    "hexahedron": "quadrilateral",
}


def _facet_rule(facet_name: str, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Reference points (nqr, tdim - 1) and weights of a facet rule exact to ``degree``.

    Intervals: Gauss–Legendre on [0, 1] with ``(degree + 2) // 2`` points; triangles and
    quadrilaterals: basix's default rule on the reference facet cell.
    """
    if facet_name == "interval":
        npts = max(1, (degree + 2) // 2)
        s, ws = np.polynomial.legendre.leggauss(npts)
        return 0.5 * (s[:, None] + 1.0), 0.5 * ws
    return _compat.quadrature_rule(facet_name, degree)


def _p1_reference(facet_name: str, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Degree-1 Lagrange basis on the reference facet (DOLFINx vertex order) at ``X``: values
    (npts, nv) and derivatives (tdim - 1, npts, nv), written out so that they are exact."""
    s = X[:, 0]
    one, zero = np.ones_like(s), np.zeros_like(s)
    if facet_name == "interval":
        return np.stack([1.0 - s, s], axis=1), np.stack([np.stack([-one, one], axis=1)])
    t = X[:, 1]
    if facet_name == "triangle":
        N = np.stack([1.0 - s - t, s, t], axis=1)
        dN = np.stack([np.stack([-one, one, zero], axis=1), np.stack([-one, zero, one], axis=1)])
        return N, dN
    N = np.stack([(1.0 - s) * (1.0 - t), s * (1.0 - t), (1.0 - s) * t, s * t], axis=1)
    ds = np.stack([t - 1.0, 1.0 - t, -t, t], axis=1)
    dt = np.stack([s - 1.0, -s, 1.0 - s, s], axis=1)
    return N, np.stack([ds, dt])


def reference_facet_points(cell_name: str, degree: int) -> np.ndarray:
    """The points of :func:`facet_quadrature`'s rule of ``degree`` on every facet of the
    reference cell, facet by facet in basix's order, shape (num_facets * nqr, tdim): where a
    cell-wise evaluation (a DOLFINx ``Expression``) meets the facet rule's points."""
    cell = getattr(basix.CellType, cell_name)
    ref = np.asarray(basix.geometry(cell))
    tdim = ref.shape[1]
    X, _ = _facet_rule(_FACET_CELLS[cell_name], degree)
    N, _ = _p1_reference(_FACET_CELLS[cell_name], X)
    out = []
    for f in basix.topology(cell)[tdim - 1]:
        corners = ref[f]
        out.append(corners[0] + np.einsum("qv,vg->qg", N[:, 1:], corners[1:] - corners[0]))
    return np.concatenate(out)


def facet_normals(points: np.ndarray, facets: np.ndarray, unit: bool = True) -> np.ndarray:
    """The normal (nf, gdim) of each facet given by its vertices' rows of ``points``: ``(t_2,
    -t_1)`` of a segment ``t = b - a`` (2D), ``(b - a) x (c - a) / 2`` of a triangle or of a
    quadrilateral's first three vertices (3D); unit, or (``unit=False``) with the facet's
    length (2D) or area (3D, of the triangle) as its norm."""
    p = points[facets]
    if facets.shape[1] == 2:
        t = p[:, 1] - p[:, 0]
        n = np.stack([t[:, 1], -t[:, 0]], axis=1)
    else:
        n = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    if unit:
        n = n / np.linalg.norm(n, axis=1)[:, None]
    return n


def _unit_normals(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (..., gdim) and area elements (...,) of facet Jacobians (..., gdim, gdim - 1).

    2D: the tangent ``t`` rotated clockwise, ``(t_y, -t_x) / |t|``, area element ``|t|``; 3D:
    ``t_0 x t_1 / |t_0 x t_1|``, area element ``|t_0 x t_1|``. Their sign is fixed by the caller.
    """
    if J.shape[-1] == 1:
        t = J[..., 0]
        length = np.linalg.norm(t, axis=-1)
        return np.stack([t[..., 1], -t[..., 0]], axis=-1) / length[..., None], length
    c = np.cross(J[..., 0], J[..., 1])
    area = np.linalg.norm(c, axis=-1)
    return c / area[..., None], area


def facet_quadrature(
    msh: dolfinx.mesh.Mesh, facets: npt.ArrayLike, degree: int, cells: npt.ArrayLike | None = None
) -> QuadraturePoints:
    """Quadrature on facets of a 2D or 3D mesh, with unit normals pointing out of ``cells``.

    Facets are mapped with their degree-1 geometry: segments in 2D (Gauss–Legendre), triangles
    and (possibly non-planar, bilinear) quadrilaterals in 3D (basix rules on the reference facet
    cell). Weights are the reference weights times the area element; normals are those of the
    mapped facet at each point (constant on straight and planar facets).

    Args:
        facets: Local facet indices.
        degree: Exactness degree of the rule (for affine facets).
        cells: The local cell beside each facet that the normal points out of (needed on interior
            facets, e.g. a patch interface); default: the facet's first cell, which on exterior
            facets gives the outward normal.
    """
    require_affine(msh, "facet_quadrature")
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    cname = msh.topology.cell_type.name
    if cname not in _FACET_CELLS or gdim != tdim:
        raise ValueError(
            f"facet quadrature needs a 2D or 3D mesh of triangles, quadrilaterals, tetrahedra or "
            f"hexahedra with gdim == tdim; got {cname} cells, tdim={tdim}, gdim={gdim}"
        )
    facets = np.asarray(facets, dtype=np.int32)
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    X, ws = _facet_rule(_FACET_CELLS[cname], degree)
    npts = X.shape[0]
    if facets.size == 0:
        z = np.zeros((0, gdim))
        return QuadraturePoints(z, np.zeros(0), np.zeros(0, np.int64), z.copy(), np.zeros(0, int))
    nodes = msh.geometry.x[_compat.entities_to_geometry(msh, tdim - 1, facets), :gdim]
    if cells is None:
        offsets = np.asarray(f2c.offsets)
        cells = np.asarray(f2c.array)[offsets[facets]].astype(np.int64)
    else:
        cells = np.asarray(cells, dtype=np.int64)
        if cells.shape != facets.shape:
            raise ValueError(f"cells should have shape {facets.shape}, got {cells.shape}")
    # x = x_0 + sum_v N_v(X) (x_v - x_0) (on a segment a + s (b - a))
    N, dN = _p1_reference(_FACET_CELLS[cname], X)
    x = nodes[:, :1] + np.einsum("qv,fvg->fqg", N[:, 1:], nodes[:, 1:] - nodes[:, :1])
    J = np.einsum("dqv,fvg->fqgd", dN, nodes)  # (nf, npts, gdim, tdim - 1)
    n, area = _unit_normals(J)
    centroid = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim].mean(axis=1)
    outward = np.einsum("fg,fg->f", n.mean(axis=1), nodes.mean(axis=1) - centroid)
    n[outward < 0] *= -1.0
    return QuadraturePoints(
        points=x.reshape(-1, gdim),
        weights=(area * ws[None, :]).ravel(),
        cells=np.repeat(cells, npts),
        normals=n.reshape(-1, gdim),
        entities=np.repeat(facets, npts),
    )
