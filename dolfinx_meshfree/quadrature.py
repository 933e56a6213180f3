"""Quadrature on background cells and boundary facets of a DOLFINx mesh (vectorised).

The FE mesh's own cells serve as EFG integration cells (Belytschko et al. 1995, sec. 5.1: "a cell
structure that overlays Omega_E"). Each rank integrates over the cells it owns and the exterior
facets it owns, so sums over ranks count every point once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from . import _compat

__all__ = ["QuadraturePoints", "boundary_facets", "cell_quadrature", "facet_quadrature"]


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


def cell_quadrature(msh, degree: int, cells: npt.ArrayLike | None = None) -> QuadraturePoints:
    """Gauss(–Jacobi) points on owned cells, exact for polynomials of ``degree`` on affine cells.

    Args:
        msh: Mesh with a degree-1 geometry.
        degree: Quadrature degree; 7 gives the 4 x 4 Gauss rule on quadrilaterals used by
            Belytschko et al. 1995, sec. 5.1.2.
        cells: Local cell indices (default: every owned cell).
    """
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    if cells is None:
        cells = np.arange(msh.topology.index_map(tdim).size_local, dtype=np.int64)
    cells = np.asarray(cells, dtype=np.int64)
    cname = msh.topology.cell_type.name
    X, w = _compat.quadrature_rule(cname, degree)
    tab = _compat.basix_lagrange_p1(cname).tabulate(1, X)  # (1+tdim, nqr, nv, 1)
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]  # (nc, nv, gdim)
    x = np.einsum("qv,cvg->cqg", tab[0, :, :, 0], nodes)
    J = np.einsum("dqv,cvg->cqgd", tab[1:, :, :, 0], nodes)
    detJ = np.abs(np.linalg.det(J))
    nq = X.shape[0]
    return QuadraturePoints(
        points=x.reshape(-1, gdim),
        weights=(detJ * w[None, :]).ravel(),
        cells=np.repeat(cells, nq),
        entities=np.repeat(cells, nq),
    )


def boundary_facets(msh, marker=None) -> np.ndarray:
    """Owned exterior facets (local indices), optionally those whose midpoints satisfy ``marker``.

    ``marker(x)`` takes coordinates shaped (3, n) like DOLFINx's ``locate_entities_boundary``.
    """
    import dolfinx.mesh as dmesh

    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = dmesh.exterior_facet_indices(msh.topology)
    facets = facets[facets < msh.topology.index_map(tdim - 1).size_local]
    if marker is not None and facets.size:
        nodes = msh.geometry.x[_compat.entities_to_geometry(msh, tdim - 1, facets)]
        mid = nodes.mean(axis=1).T
        keep = np.asarray(marker(mid), dtype=bool)
        facets = facets[keep]
    return np.asarray(facets, dtype=np.int32)


def facet_quadrature(
    msh, facets: npt.ArrayLike, degree: int, cells: npt.ArrayLike | None = None
) -> QuadraturePoints:
    """Gauss–Legendre points on straight facets (2D meshes), with unit normals.

    Args:
        facets: Local facet indices.
        degree: Exactness degree of the rule.
        cells: The local cell beside each facet that the normal points out of (needed on interior
            facets, e.g. a patch interface); default: the facet's first cell, which on exterior
            facets gives the outward normal.
    """
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    if tdim != 2:
        raise ValueError(f"facet quadrature is implemented for 2D meshes; got tdim={tdim}")
    facets = np.asarray(facets, dtype=np.int32)
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    npts = max(1, (degree + 2) // 2)
    s, ws = np.polynomial.legendre.leggauss(npts)
    s, ws = 0.5 * (s + 1.0), 0.5 * ws
    if facets.size == 0:
        z = np.zeros((0, gdim))
        return QuadraturePoints(z, np.zeros(0), np.zeros(0, np.int64), z.copy(), np.zeros(0, int))
    ends = msh.geometry.x[_compat.entities_to_geometry(msh, tdim - 1, facets), :gdim]  # (nf, 2, 2)
    if cells is None:
        offsets = np.asarray(f2c.offsets)
        cells = np.asarray(f2c.array)[offsets[facets]].astype(np.int64)
    else:
        cells = np.asarray(cells, dtype=np.int64)
        if cells.shape != facets.shape:
            raise ValueError(f"cells should have shape {facets.shape}, got {cells.shape}")
    a, b = ends[:, 0], ends[:, 1]
    t = b - a
    length = np.linalg.norm(t, axis=1)
    n = np.stack([t[:, 1], -t[:, 0]], axis=1) / length[:, None]
    centroid = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim].mean(axis=1)
    flip = np.einsum("fg,fg->f", n, 0.5 * (a + b) - centroid) < 0
    n[flip] *= -1.0
    x = a[:, None, :] + s[None, :, None] * t[:, None, :]
    return QuadraturePoints(
        points=x.reshape(-1, gdim),
        weights=(length[:, None] * ws[None, :]).ravel(),
        cells=np.repeat(cells, npts),
        normals=np.repeat(n, npts, axis=0),
        entities=np.repeat(facets, npts),
    )
