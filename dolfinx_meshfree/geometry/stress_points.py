"""Stress-point (nodal) integration of the particle stiffness for explicit dynamics.

Rabczuk, Belytschko & Xiao 2004 (Rabczuk et al. 2006, sec. 4, ref. [44]): the particle energy is
integrated at the particles and at *stress points* placed between them, each carrying a volume,

.. math::
    K_{IJ} = \\sum_{q \\in \\text{particles} \\cup \\text{stress points}}
        B_I^T(x_q) \\, D \\, B_J(x_q) \\, V_q ,

with MLS shape functions on a *Lagrangian kernel*: supports, neighbour lists and the functions
are those of the reference configuration, evaluated once (Rabczuk et al. 2006, sec. 4: "the shape
functions are evaluated in the reference configuration only"). For the small-deformation linear
dynamics of this package that means the MLS tables at the integration points are computed once at
``t = 0`` and ``K`` is constant; the Lagrangian kernel is what removes the tensile instability of
Eulerian SPH kernels, which cannot arise here. Integrating at the particles alone (nodal
integration) is rank deficient: the stripe modes ``u_I = (-1)^(i_x)`` (or ``i_y``) of a regular
grid have zero strain at every interior particle (by the symmetry of the MLS functions), so their
energy comes from the boundary and from a modulating envelope only and falls like ``1/L^2`` with
the domain; the stress points at the cells' centres sample them where their strain is largest and
keep them as stiff as the background cells do (measured in ``tests/test_stress_points.py``). The
checkerboard ``(-1)^(i_x + i_y)`` is not stiffened by them (the cells' centres are symmetry
centres of the lattice too), but MLS with ``d_max = 2`` nearly annihilates that mode's field.

Construction (:func:`stress_point_quadrature`):

* stress points: the vertices of the particles' Voronoi diagram inside the integration cells
  (the Voronoi-dual point set; on a regular grid, the centres of the particle grid's cells),
  merged when closer than a tenth of the particle spacing;
* volumes: the Voronoi volumes of the joint set (particles and stress points) within the
  integration cells, by nearest-point assignment of a uniform sampling of every cell (``samples``
  points per particle spacing and direction; ties shared equally). On a regular grid aligned with
  the sampling every interior particle and stress point gets the same volume ``s^2 / 2``; the
  volumes sum to the area of the cells exactly;
* ownership: each point is integrated by the lowest rank owning an integration cell that
  contains it, so the sums over ranks count each point once.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI
from scipy.spatial import Voronoi, cKDTree

from .. import _compat
from .particles import ParticleSet
from .quadrature import QuadraturePoints

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = ["INTEGRATIONS", "check_integration", "stress_point_quadrature"]

#: Particle integration in explicit dynamics: background cells (Gauss), stress points, or
#: strains smoothed over the cells and stabilised (symmetric and consistent,
#: :mod:`~dolfinx_meshfree.geometry.smoothing`; pure EFG, small strain).
INTEGRATIONS = ("cells", "stress-points", "smoothed")


def check_integration(integration: str) -> str:
    """Return ``integration`` if it is one of :data:`INTEGRATIONS`, else raise ``ValueError``
    (the same on every rank: the check is local and deterministic)."""
    if integration not in INTEGRATIONS:
        raise ValueError(
            f"integration={integration!r} is not known; use one of {list(INTEGRATIONS)}"
        )
    return integration


def _cell_of(msh: dolfinx.mesh.Mesh, points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """A cell among ``cells`` (local) containing each point, or -1 (local, no communication)."""
    m = points.shape[0]
    out = np.full(m, -1, dtype=np.int64)
    if m == 0 or cells.size == 0:
        return out
    p3 = np.zeros((m, 3))
    p3[:, : points.shape[1]] = points
    offsets, arr = _compat.colliding_cells(msh, _compat.bb_tree(msh, msh.topology.dim), p3)
    pt = np.repeat(np.arange(m), np.diff(offsets))
    hit = np.isin(arr, cells)
    # the first hit of each point (reverse assignment keeps the first)
    out[pt[hit][::-1]] = np.asarray(arr)[hit][::-1]
    return out


def _sampling(msh: dolfinx.mesh.Mesh, cells: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Uniform sampling of the cells: ``m x m`` sub-cell midpoints of each quadrilateral (``m^2``
    sub-triangle centroids of each triangle), with their areas. Returns (points, weights)."""
    cname = msh.topology.cell_type.name
    gdim = msh.geometry.dim
    t = (np.arange(m) + 0.5) / m
    if cname == "quadrilateral":
        X = np.stack(np.meshgrid(t, t, indexing="xy"), -1).reshape(-1, 2)
        w = np.full(X.shape[0], 1.0 / m**2)
    elif cname == "triangle":
        pts = []
        for i in range(m):
            for j in range(m - i):
                pts.append(((i + 1.0 / 3.0) / m, (j + 1.0 / 3.0) / m))  # upright sub-triangle
                if i + j < m - 1:
                    pts.append(((i + 2.0 / 3.0) / m, (j + 2.0 / 3.0) / m))  # inverted one
        X = np.asarray(pts)
        w = np.full(X.shape[0], 0.5 / m**2)
    else:
        raise ValueError(f"stress points are implemented on 2D cells; got {cname}")
    tab = _compat.basix_lagrange_p1(cname).tabulate(1, X)
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]
    x = np.einsum("qv,cvg->cqg", tab[0, :, :, 0], nodes)
    J = np.einsum("dqv,cvg->cqgd", tab[1:, :, :, 0], nodes)
    detJ = np.abs(np.linalg.det(J))
    return x.reshape(-1, gdim), (detJ * w[None, :]).ravel()


def stress_point_quadrature(
    particles: ParticleSet, stress_points: bool = True, samples: int = 8
) -> QuadraturePoints:
    """This rank's integration points of stress-point integration, with their volumes.

    Rabczuk, Belytschko & Xiao 2004; Rabczuk et al. 2006, sec. 4 (see the module docstring).
    Collective; the same point set and volumes on any partition.

    Args:
        particles: Particles with a background mesh; their integration cells
            (``particles.cells``, default every owned cell) bound the integration domain.
        stress_points: ``False`` gives nodal integration (the particles alone, with their
            Voronoi volumes): rank deficient, for comparison only.
        samples: Sampling points per particle spacing and direction for the volumes (rounded
            up to an even number per cell).

    Returns:
        :class:`~dolfinx_meshfree.geometry.quadrature.QuadraturePoints` of the owned integration
        points:
        ``points`` (nq, 2), ``weights`` (nq,) the volumes ``V_q``, ``cells`` (nq,) a local
        integration cell containing each point, ``entities`` (nq,) the point's global index in
        the joint set (particles first, in their original order, then the stress points).

    Raises:
        ValueError: on every rank, without a background mesh or with ``samples < 1``.
    """
    msh = particles.mesh
    if msh is None:
        raise ValueError("stress-point integration needs particles with a background mesh")
    if not (isinstance(samples, int) and samples >= 1):
        raise ValueError(f"samples={samples!r} must be an integer >= 1")
    comm = particles.comm
    x = particles.positions
    n = x.shape[0]
    cells = particles.integration_cells()
    d, _ = cKDTree(x).query(x, k=2) if n > 1 else (np.ones((n, 2)), None)
    s = float(np.median(d[:, 1]))
    pts = x
    if stress_points and n >= 3:
        lo, hi = x.min(axis=0), x.max(axis=0)
        span = float(np.max(hi - lo)) + s
        mid = 0.5 * (lo + hi)
        frame = mid + 10.0 * span * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
        vor = Voronoi(np.vstack([x, frame]))
        v = vor.vertices
        # merge vertices closer than s / 10 (cocircular particles give repeated vertices)
        key = np.round(v / (0.1 * s)).astype(np.int64)
        _, first = np.unique(key, axis=0, return_index=True)
        v = v[np.sort(first)]
        tree = cKDTree(v)
        drop = np.zeros(v.shape[0], dtype=bool)
        for i, j in sorted(tree.query_pairs(0.1 * s)):
            if not drop[i]:
                drop[j] = True
        v = v[~drop]
        # keep those inside the integration cells (of any rank) and off the particles
        inside = (_cell_of(msh, v, cells) >= 0).astype(np.int8)
        comm.Allreduce(MPI.IN_PLACE, inside, op=MPI.MAX)
        dist, _ = cKDTree(x).query(v)
        v = v[inside.astype(bool) & (dist > 0.1 * s)]
        pts = np.vstack([x, v])
    # volumes: Voronoi cells of the joint set within the integration cells, by sampling
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :2]
    size = np.linalg.norm(nodes.max(axis=1) - nodes.min(axis=1), axis=1) if cells.size else [0]
    h = comm.allreduce(float(np.max(size, initial=0.0)), op=MPI.MAX) / np.sqrt(2.0)
    m = 2 * int(np.ceil(0.5 * samples * h / s - 1e-9))
    volumes = np.zeros(pts.shape[0])
    tree = cKDTree(pts)
    k = min(4, pts.shape[0])
    chunk = max(1, 400_000 // max(1, m * m))
    for c0 in range(0, cells.size, chunk):
        xs, ws = _sampling(msh, cells[c0 : c0 + chunk], m)
        dist, idx = tree.query(xs, k=k)
        dist, idx = dist.reshape(-1, k), idx.reshape(-1, k)
        tied = dist <= dist[:, :1] * (1.0 + 1e-10) + 1e-14 * s
        share = ws[:, None] * tied / tied.sum(axis=1, keepdims=True)
        volumes += np.bincount(idx.ravel(), weights=share.ravel(), minlength=pts.shape[0])
    volumes = comm.allreduce(volumes, op=MPI.SUM)
    # ownership: the lowest rank owning an integration cell that contains the point
    cell = _cell_of(msh, pts, cells)
    claim = np.where(cell >= 0, comm.rank, comm.size).astype(np.int32)
    owner = np.empty_like(claim)
    comm.Allreduce(claim, owner, op=MPI.MIN)
    # points in no integration cell (round-off on the boundary) go to the particle's owner
    lost = owner == comm.size
    owner[lost] = np.concatenate([particles.owner, np.zeros(pts.shape[0] - n, np.int32)])[lost]
    mine = np.flatnonzero((owner == comm.rank) & (volumes > 0.0))
    if cells.size and np.any(cell[mine] < 0):  # a lost point here: the nearest owned cell
        mid = nodes.mean(axis=1)
        bad = mine[cell[mine] < 0]
        cell[bad] = cells[cKDTree(mid).query(pts[bad])[1]]
    return QuadraturePoints(
        points=pts[mine].copy(),
        weights=volumes[mine],
        cells=cell[mine],
        entities=mine.astype(np.int64),
    )
