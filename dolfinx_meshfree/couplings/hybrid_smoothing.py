"""Smoothing cells of the hybrid particle energy: strains smoothed over sub-cells of the patch.

The corrected kernel gradients of :class:`~dolfinx_meshfree.couplings.hybrid_sph.CorrectedSPH` are
exact
for linear fields but are not the derivatives of the kernel sums, so a Gauss rule on the patch
cells does not satisfy the divergence theorem for them: a constant stress leaves forces of the
order of the stress times the spacing at the particles near the patch's boundary and interface
(the missed patch test of ``consistent=False``), which in dynamics reflect part of every wave
that crosses the interface. Integration-consistent test gradients (Chen, Hillman & Rüter 2013)
pass the patch test but make ``K`` unsymmetric, so central differences no longer conserve energy.

Strain smoothing (Chen, Wu, Yoon & You 2001, stabilized conforming nodal integration) gives both:
each patch cell is divided into ``n x n`` sub-cells ``Omega_k`` (``n^2`` sub-triangles on
triangles), and the strain of sub-cell ``k`` is the mean of the displacement gradient by the
divergence theorem,

.. math::
    \\tilde\\nabla u_k = \\frac{1}{|\\Omega_k|}
        \\oint_{\\partial\\Omega_k} u^h \\otimes n \\, d\\Gamma,

with ``u^h`` the hybrid sums (Rabczuk et al. 2006, eq. 125) on edges inside the patch, the
particles' own interpolant (the functions of the traction loads) on edges on the exterior
boundary and the FE trace on edges on the interface; the edges are integrated by the midpoint
rule, exact for the linear fields that all three reproduce. ``K = sum_k |Omega_k| B_k^T D B_k``
is symmetric; a linear field has its exact strain in every sub-cell; the edges inside the patch
cancel pairwise, so the force of a constant stress on a particle is its exterior boundary
integral ``int N_J sigma n`` (by the edge rule), and on an FE node of the interface the patch's
``int N_a sigma n_P`` cancels the FE cells' own. With the traction loads on the patch's facets
integrated by the same edge rule (:meth:`SmoothingCells.exterior_quadrature`), ``K`` is
symmetric and the linear patch test holds to round-off at every FE node and particle (measured
7e-15 of the loads). This module builds the geometry: sub-cells, their
areas and centroids, and the points of their edges with the outward normal times the edge
length.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .. import _compat
from ..geometry.quadrature import QuadraturePoints

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = ["EXTERIOR", "INTERIOR", "SmoothingCells", "smoothing_cells"]

#: ``fe_cell`` of an edge point inside the patch (the hybrid sums apply).
INTERIOR = -1
#: ``fe_cell`` of an edge point on the exterior boundary (the particles' own interpolant applies,
#: the functions of the traction loads).
EXTERIOR = -2


@dataclass
class SmoothingCells:
    """Sub-cells of this rank's patch cells and the Gauss points of their edges.

    Attributes:
        centroids: (ns, 2) sub-cell centroids. areas: (ns,) sub-cell areas. cells: (ns,) the
            local patch cell of each sub-cell.
        points: (m, 2) edge Gauss points. normals: (m, 2) outward normal times the edge length
            times the Gauss weight (on [0, 1]). owner: (m,) the sub-cell of each point.
        fe_cell: (m,) the local FE cell across the interface for points on an interface facet,
            :data:`EXTERIOR` for points on an exterior facet, else :data:`INTERIOR`.
        facet: (m,) the local facet that a point on the cell's boundary lies on, else -1.
    """

    centroids: np.ndarray
    areas: np.ndarray
    cells: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    owner: np.ndarray
    fe_cell: np.ndarray
    facet: np.ndarray

    def exterior_quadrature(self, msh: dolfinx.mesh.Mesh, facets: np.ndarray) -> QuadraturePoints:
        """The edge points on the given exterior facets (local indices, any owner), as a facet
        quadrature: points, weights (edge length times rule weight), unit normals, the local
        patch cell and the facet of each point. The traction loads on these points are the
        boundary terms of the smoothed strains (the patch test holds to round-off)."""
        on = (self.fe_cell == EXTERIOR) & np.isin(self.facet, facets)
        w = np.linalg.norm(self.normals[on], axis=1)
        return QuadraturePoints(
            points=self.points[on],
            weights=w,
            cells=self.cells[self.owner[on]],
            normals=self.normals[on] / w[:, None],
            entities=self.facet[on],
        )


def _reference_subcells(cell_name: str, n: int) -> np.ndarray:
    """Vertices (ns, nv, 2) of the ``n``-fold subdivision of the reference cell, counter-
    clockwise: ``n^2`` squares of [0, 1]^2 or ``n^2`` triangles of the reference triangle."""
    out = []
    if cell_name == "quadrilateral":
        for j in range(n):
            for i in range(n):
                out.append([(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)])
    elif cell_name == "triangle":
        for j in range(n):
            for i in range(n - j):
                out.append([(i, j), (i + 1, j), (i, j + 1)])
                if i + j <= n - 2:
                    out.append([(i + 1, j), (i + 1, j + 1), (i, j + 1)])
    else:
        raise ValueError(f"strain smoothing is 2D: cell type {cell_name!r} is not supported")
    return np.asarray(out, dtype=float) / n


def smoothing_cells(
    msh: dolfinx.mesh.Mesh, cells: np.ndarray, in_cells: np.ndarray, n: int, degree: int = 1
) -> SmoothingCells:
    """Sub-cells of the local ``cells`` and the Gauss points of their edges (local).

    Args:
        msh: Degree-1 2D mesh (the sub-cells of a bilinear quadrilateral have straight edges:
            lines of constant reference coordinate are straight).
        cells: Local cells to subdivide (the patch cells of this rank).
        in_cells: bool per local cell (owned and ghost), True for the cells' own kind (the
            patch); an edge on a facet shared with a cell where it is False is an interface edge.
        n: Subdivisions per reference direction.
        degree: Gauss degree on each edge.

    Returns:
        :class:`SmoothingCells`.
    """
    cells = np.asarray(cells, dtype=np.int64)
    cname = msh.topology.cell_type.name
    ref = _reference_subcells(cname, n)  # (ns, nv, 2)
    ns, nv = ref.shape[:2]
    element = _compat.basix_lagrange_p1(cname)
    phi = element.tabulate(0, ref.reshape(-1, 2))[0, :, :, 0]  # (ns nv, cell vertices)
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :2]  # (nc, cv, 2)
    verts = np.einsum("pv,cvg->cpg", phi, nodes).reshape(cells.size, ns, nv, 2)
    nxt = np.roll(verts, -1, axis=2)
    cross = verts[..., 0] * nxt[..., 1] - verts[..., 1] * nxt[..., 0]
    signed = 0.5 * cross.sum(axis=2)  # (nc, ns)
    cen = ((verts + nxt) * cross[..., None]).sum(axis=2) / (6.0 * signed[..., None])
    sign = np.sign(signed)[..., None, None]
    X, w = _compat.quadrature_rule("interval", degree)
    s = X[:, 0]
    # edge Gauss points (nc, ns, nv, nq, 2) and outward normal times length times weight
    pts = verts[..., None, :] + s[:, None] * (nxt - verts)[..., None, :]
    e = nxt - verts
    normal = sign * np.stack([e[..., 1], -e[..., 0]], axis=-1)  # (nc, ns, nv, 2)
    wn = normal[..., None, :] * w[:, None]
    nq = s.size
    # interface edges: sub-cell edges on a facet of the cell whose other cell is not in_cells
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim, tdim - 1)
    msh.topology.create_connectivity(tdim - 1, tdim)
    c2f = msh.topology.connectivity(tdim, tdim - 1)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    across = np.full((cells.size, ns, nv), INTERIOR, dtype=np.int64)
    on_facet = np.full((cells.size, ns, nv), -1, dtype=np.int64)
    if cells.size:
        per = int(np.asarray(c2f.offsets)[1] - np.asarray(c2f.offsets)[0])
        facets = np.asarray(c2f.array).reshape(-1, per)[cells]  # (nc, nf)
        nf = facets.shape[1]
        fo, fa = np.asarray(f2c.offsets), np.asarray(f2c.array)
        count = fo[facets + 1] - fo[facets]
        a0, a1 = fa[fo[facets]], fa[np.minimum(fo[facets] + 1, fa.size - 1)]
        other = np.where(count == 2, np.where(a0 == cells[:, None], a1, a0), -1)
        iface = (other >= 0) & ~in_cells[np.maximum(other, 0)]
        label = np.where(iface, other, np.where(other < 0, EXTERIOR, INTERIOR))
        fx = msh.geometry.x[_compat.entities_to_geometry(msh, tdim - 1, facets.ravel()), :2]
        fx = fx.reshape(cells.size, nf, 2, 2)
        mid = 0.5 * (verts + nxt)  # (nc, ns, nv, 2) edge midpoints, and the edge ends
        size = np.linalg.norm(nodes.max(axis=1) - nodes.min(axis=1), axis=1)[:, None, None]
        for k in range(nf):
            a, b = fx[:, k, 0][:, None, None], fx[:, k, 1][:, None, None]
            t = b - a
            tt = np.maximum(np.sum(t * t, axis=-1), 1e-300)
            on = np.ones(mid.shape[:3], dtype=bool)
            for p in (verts, nxt, mid):
                d = p - a
                dist = np.abs(d[..., 0] * t[..., 1] - d[..., 1] * t[..., 0]) / np.sqrt(tt)
                on &= dist < 1e-10 * size
            across[on] = np.broadcast_to(label[:, k][:, None, None], on.shape)[on]
            on_facet[on] = np.broadcast_to(facets[:, k][:, None, None], on.shape)[on]
    owner = np.broadcast_to(np.arange(cells.size * ns).reshape(cells.size, ns, 1, 1), wn.shape[:4])
    return SmoothingCells(
        centroids=cen.reshape(-1, 2),
        areas=np.abs(signed).ravel(),
        cells=np.repeat(cells, ns),
        points=pts.reshape(-1, 2),
        normals=wn.reshape(-1, 2),
        owner=owner.ravel().copy(),
        fe_cell=np.repeat(across[..., None], nq, axis=3).ravel(),
        facet=np.repeat(on_facet[..., None], nq, axis=3).ravel(),
    )
