"""The approximation of the hybrid SPH–FE coupling: FE integration points join the particle sums.

Rabczuk et al. 2006, sec. 5.5, eq. 125–130 (Sauer 2000). In the hybrid zone the FE field enters
the SPH sums of the particle approximation as extra "particles": the integration points ``X_g``
of the FE cells near the patch, with volume ``w_g |J_g|`` (eq. 129–130) and value
``u^FE(X_g) = sum_a N_a(X_g) u_a`` (eq. 125–126):

.. math::
    u^h(X) = \\sum_J u_J N_J(X) + \\sum_g u^{FE}(X_g) N_g(X).

Two pieces live here:

* :class:`CorrectedSPH`: an SPH approximation on points with volumes that reproduces linear
  fields, values and gradients: the Shepard values ``Nhat_J`` with a first-order correction and
  the corrected kernel gradients ``G_J`` of :class:`~dolfinx_meshfree.SPH` (Bonet & Lok 1999),
  ``N_J(x) = Nhat_J(x) + G_J(x) . (x - xbar(x))``, ``xbar = sum_J Nhat_J x_J``;
* :func:`hybrid_points`: the FE integration points of the hybrid zone, replicated on every rank
  like the particles, with the sparse map ``E`` (FE nodal values to values at the points);
* :func:`centred_particles`: the SPH particles of the patch, at the centres of a lattice of
  squares, each carrying the area of its square within the patch as its volume.

Why the particles sit at the centres of squares: the points of the hybrid sums stand for the
body, each with the volume of the piece around it (eq. 10, 129). The FE integration points stand
for the FE side up to the interface; the particles must stand for the patch side. A particle grid
through the interface nodes (:meth:`~dolfinx_meshfree.ParticleSet.from_cells`) puts a particle
on every interface FE node: two independent dofs at one point, joined only through the kernel
sums, a compliant interface layer that reflects waves (measured on the rod of Rabczuk et al.
2006, Table III: a reflected wave of 20 % of the pulse at about 2,000 nodes + particles); and the
Voronoi volumes that :class:`~dolfinx_meshfree.ParticleSet` computes by nearest-point assignment
of 3 x 3 Gauss points per cell are only as accurate as that sampling: exact when the particle
grid divides the cells (ratios 1 and 4 on the rod), scattered by 30-70 % (some particles with
no volume at all) otherwise, so masses and kernel sums changed with the particle:node ratio.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from mpi4py import MPI
from scipy.spatial import cKDTree

from .. import _compat
from ..approx.fe_points import locate_points, tabulate_in_cells
from ..approx.neighbours import check_points
from ..approx.sph import SPH
from ..approx.tables import ShapeTable
from ..geometry.particles import ParticleSet
from ..geometry.quadrature import cell_quadrature

if TYPE_CHECKING:  # annotations only
    import dolfinx.fem

    from ..geometry.patch import ParticlePatch

__all__ = [
    "CorrectedSPH",
    "HybridPoints",
    "centred_particles",
    "hybrid_points",
    "particle_spacing_median",
]


class CorrectedSPH:
    """SPH on points with volumes, corrected so that linear fields are reproduced exactly.

    The Shepard values ``Nhat_J = V_J W(x - x_J, h) / sum_K V_K W(x - x_K, h)`` (Rabczuk et al.
    2006, eq. 10, normalised) and the corrected gradients ``G_J`` of
    :class:`~dolfinx_meshfree.SPH` (``correction="shepard"``: ``sum_J G_J = 0`` and
    ``sum_J G_J (x) x_J = I``) give the values

    .. math::
        N_J(x) = \\hat N_J(x) + G_J(x) \\cdot (x - \\bar x(x)), \\qquad
        \\bar x = \\sum_J \\hat N_J x_J,

    which reproduce constants and linear fields (``sum_J N_J x_J = xbar + (x - xbar) = x``). The
    gradients of the table are ``G_J``, the corrected kernel gradients (eq. 126/128 with the
    correction), exact for linear fields; they are not the derivatives of ``N_J``.

    Args:
        points: (n, 2) positions (particles, and FE integration points in the hybrid zone).
        volumes: (n,) positive volumes.
        smoothing_length: ``h``; the cubic-spline kernel's support is ``2 h``.
    """

    def __init__(
        self, points: npt.ArrayLike, volumes: npt.ArrayLike, smoothing_length: float
    ) -> None:
        self._sph = SPH(points, volumes, smoothing_length=smoothing_length, correction="shepard")
        self.points = self._sph.points
        self.volumes = self._sph.volumes
        self.h = self._sph.h
        self.gdim = self._sph.gdim

    @property
    def support(self) -> float:
        """Kernel support radius ``2 h``."""
        return 2.0 * self.h

    @property
    def pair_cuts(self) -> list:
        """The sums' pair cuts (:attr:`~dolfinx_meshfree.SPH.pair_cuts`): the bodies' cut."""
        return self._sph.pair_cuts

    @property
    def num_points(self) -> int:
        return self.points.shape[0]

    def tabulate(self, x: npt.ArrayLike, derivatives: int = 1) -> ShapeTable:
        """Values and corrected gradients at ``x`` (m, 2); local, no communication.

        Raises:
            ValueError: a point has no point within ``2 h`` or too few, collinear neighbours
                for the gradient correction (increase the smoothing length).
        """
        x = check_points(x, self.gdim, "x")
        t = self._sph.tabulate(x, 1)
        nhat = t.values
        d = x - nhat @ self.points  # x - xbar, (m, gdim)
        values = nhat.copy()
        for k, g in enumerate(t.gradients):
            values = values + sp.diags(d[:, k]) @ g
        return ShapeTable(
            points=x, values=values.tocsr(), gradients=t.gradients if derivatives else []
        )


@dataclass
class HybridPoints:
    """FE integration points of the hybrid zone, the same on every rank.

    Attributes:
        points: (ng, 2) positions ``X_g``. weights: (ng,) volumes ``w_g |J_g|`` (eq. 129).
        interpolation: (ng x N) CSR ``E`` with ``E[g, a] = N_a(X_g)`` over the global FE nodes
            (scalar; the displacement at ``X_g`` is ``E`` applied to each component).
        cells_per_rank: How many hybrid FE cells each rank contributed.
    """

    points: np.ndarray
    weights: np.ndarray
    interpolation: sp.csr_matrix
    cells_per_rank: list[int]

    @property
    def num_points(self) -> int:
        return self.points.shape[0]


def particle_spacing_median(positions: np.ndarray) -> float:
    """Median distance from a particle to its nearest neighbour (local)."""
    d, _ = cKDTree(positions).query(positions, k=2)
    return float(np.median(d[:, 1]))


def hybrid_points(
    V: dolfinx.fem.FunctionSpace,
    fe_cells: np.ndarray,
    particles: np.ndarray,
    radius: float,
    degree: int,
) -> HybridPoints:
    """The integration points of the FE cells within ``radius`` of a particle (collective).

    Each rank takes its owned FE cells ``fe_cells`` whose vertices come within ``radius`` of a
    particle, puts a Gauss rule of ``degree`` on them (Sauer 2000: about the particles' density,
    Rabczuk eq. 129–130), keeps the points within ``radius`` of a particle, tabulates the FE
    basis there, and the points, volumes and interpolation rows are gathered on every rank in
    rank order.

    Args:
        V: Vector P1/Q1 space. fe_cells: Owned FE cells (local indices).
        particles: (n, 2) particle positions (replicated).
        radius: The kernel support ``2 h``. degree: Gauss degree on the hybrid cells.

    Returns:
        :class:`HybridPoints`.
    """
    msh = V.mesh
    comm = msh.comm
    gdim = msh.geometry.dim
    tree = cKDTree(particles)
    fe_cells = np.asarray(fe_cells, dtype=np.int64)
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[fe_cells], :gdim]  # (nc, nv, gdim)
    if fe_cells.size:
        dist, _ = tree.query(nodes.reshape(-1, gdim))
        # a point of the cell within radius of a particle has a vertex within radius + diameter
        diam = np.linalg.norm(nodes.max(axis=1) - nodes.min(axis=1), axis=1)
        cells = fe_cells[dist.reshape(nodes.shape[:2]).min(axis=1) < radius + diam]
    else:
        cells = fe_cells
    q = cell_quadrature(msh, degree, cells)
    if len(q):
        d, _ = tree.query(q.points)
        keep = d < radius
    else:
        keep = np.zeros(0, dtype=bool)
    pts, w, qc = q.points[keep], q.weights[keep], q.cells[keep]
    tab = tabulate_in_cells(V, pts, qc, derivatives=0).values.tocoo()
    imap = V.dofmap.index_map
    l2g = np.asarray(
        imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    )
    parts = comm.allgather((pts, w, tab.row, l2g[tab.col], tab.data, int(cells.size)))
    offsets = np.cumsum([0] + [p[0].shape[0] for p in parts])
    rows = np.concatenate([p[2] + off for p, off in zip(parts, offsets[:-1], strict=True)])
    E = sp.csr_matrix(
        (
            np.concatenate([p[4] for p in parts]),
            (rows, np.concatenate([p[3] for p in parts]).astype(np.int64)),
        ),
        shape=(int(offsets[-1]), int(imap.size_global)),
    )
    return HybridPoints(
        points=np.concatenate([p[0] for p in parts]).reshape(-1, gdim),
        weights=np.concatenate([p[1] for p in parts]),
        interpolation=E,
        cells_per_rank=[p[5] for p in parts],
    )


def _in_patch(patch: ParticlePatch, points: np.ndarray) -> np.ndarray:
    """Whether each point lies in a patch cell of some rank (collective, the same on every rank)."""
    cells = locate_points(patch.mesh, points, preferred=patch.in_patch)
    inside = ((cells >= 0) & patch.in_patch[np.maximum(cells, 0)]).astype(np.int8)
    patch.comm.Allreduce(MPI.IN_PLACE, inside, op=MPI.MAX)
    return inside.astype(bool)


def _poorly_seen(centres: np.ndarray, vertices: np.ndarray, radius: float) -> np.ndarray:
    """For each cell (vertices (nc, nv, gdim)), the first of its points (vertices, midpoints of
    every pair of them, centroid) that has fewer than three non-collinear ``centres`` within
    ``0.9 radius``, or NaN where every point has enough (local); (nc, gdim)."""
    nc, nv, gdim = vertices.shape
    pairs = [(a, b) for a in range(nv) for b in range(a + 1, nv)]
    probes = np.concatenate(
        [vertices]
        + [0.5 * (vertices[:, a : a + 1] + vertices[:, b : b + 1]) for a, b in pairs]
        + [vertices.mean(axis=1, keepdims=True)],
        axis=1,
    )
    per = probes.shape[1]
    out = np.full((nc, gdim), np.nan)
    if nc == 0:
        return out
    if centres.shape[0] < 3:
        return probes[:, 0].copy()
    near = cKDTree(centres).query_ball_point(probes.reshape(-1, gdim), 0.9 * radius)
    for k, idx in enumerate(near):
        c, j = divmod(k, per)
        if not np.isnan(out[c, 0]) or len(idx) >= 8:  # a lattice row holds at most 5 in reach
            continue
        if len(idx) < 3:
            out[c] = probes[c, j]
            continue
        d = centres[idx] - centres[idx].mean(axis=0)
        if np.linalg.eigvalsh(d.T @ d)[0] < 1e-2 * radius**2:  # (nearly) collinear
            out[c] = probes[c, j]
    return out


def _apart(centres: np.ndarray, extra: np.ndarray, gap: float) -> np.ndarray:
    """The points of ``extra``, in order, that lie at least ``gap`` from ``centres`` and from
    the points of ``extra`` kept before them."""
    kept: list[np.ndarray] = []
    near = cKDTree(centres).query(extra)[0] if centres.shape[0] else np.full(len(extra), np.inf)
    for x, d in zip(extra, near, strict=True):
        if d >= gap and all(np.linalg.norm(x - y) >= gap for y in kept):
            kept.append(x)
    return np.asarray(kept).reshape(-1, extra.shape[1])


def centred_particles(patch: ParticlePatch, spacing: float, samples: int = 4) -> ParticleSet:
    """SPH particles at the centres of a lattice of squares over the patch cells (collective).

    The lattice spans the bounding box of the patch cells with ``round(extent / spacing)``
    squares per direction (the box's sides are lattice lines, so an axis-aligned interface or
    boundary is one too); a particle sits at the centre of every square whose centre lies in a
    patch cell (so none on the interface, where the FE nodes are), and halfway between the
    centroid and the point of a patch cell that sees fewer than three non-collinear particles
    within 1.8 spacings (a corner of a staircase border; a cell whose centroid is blind, e.g. a
    lone cell, first gets one a quarter of the way from each vertex to its centroid); a
    particle's volume is the area of the patch that is nearer to it than to any other particle
    (its Voronoi cell within the patch): the square itself inside the patch. The areas are
    measured by nearest-particle assignment of ``samples x samples`` points per square at the
    centres of a finer lattice aligned with the squares (no point is equidistant from two
    particles), then scaled so that they sum to the area of the patch cells: exact for squares
    inside the patch and along lattice-aligned boundaries, within about ``1 / samples`` of a
    square's area along others. In 2D the same
    samples, each at its radius ``|x|``, give the regions' volumes revolved about the axis
    ``x = 0`` (:attr:`~dolfinx_meshfree.ParticleSet.revolved_volumes`: an axisymmetric model's
    masses), scaled so that they sum to the cells' revolved volume ``int 2 pi r dA``.

    Args:
        patch: :class:`~dolfinx_meshfree.ParticlePatch` whose cells the particles fill.
        spacing: Target particle spacing (the lattice's is ``extent / round(extent / spacing)``
            per direction).
        samples: Sampling points per square and direction for the volumes (even).

    Returns:
        A :class:`~dolfinx_meshfree.ParticleSet` on the patch's mesh and cells, the same on
        every rank.
    """
    msh, comm = patch.mesh, patch.comm
    gdim = msh.geometry.dim
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[patch.cells], :gdim].reshape(-1, gdim)
    lo = nodes.min(axis=0) if nodes.size else np.full(gdim, np.inf)
    hi = nodes.max(axis=0) if nodes.size else np.full(gdim, -np.inf)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    counts = np.array([max(1, round((hi[k] - lo[k]) / spacing)) for k in range(gdim)])
    step = (hi - lo) / counts

    def lattice(per: int) -> np.ndarray:
        axes = [lo[k] + (np.arange(per * counts[k]) + 0.5) * step[k] / per for k in range(gdim)]
        return np.stack(np.meshgrid(*axes, indexing="xy"), axis=-1).reshape(-1, gdim)

    centres = lattice(1)
    centres = centres[_in_patch(patch, centres)]
    # a patch cell with a point that sees fewer than three non-collinear centres within the
    # kernel support 2 spacings (a corner of a staircase border) gets a particle halfway
    # between that point and its centroid (if still blind: at the point itself, ...), so that
    # the corrected sums are defined there
    vertices = msh.geometry.x[_compat.geometry_dofmap(msh)[patch.cells], :gdim]
    mid = vertices.mean(axis=1)
    # two blind points of neighbouring cells (a shared vertex) would put two particles a few
    # hundredths of a spacing apart: a pair whose relative motion the kernel sums hardly see, a
    # near-zero-energy mode (measured: the curved gmsh patch at 0.75 h under a body load, 3.3 x
    # the FE error at one level, 1.2 x at the next): a particle closer than half a spacing to
    # another is added only if the points farther away leave a cell blind
    half = 0.5 * float(step.min())
    # a cell whose centroid is blind (a lone cell, a strip one cell wide: the tries below
    # would add every particle on the line from its first blind point to the centroid, and a
    # lone cell of the Hanchak slab's conversions was refused as "singular") gets a particle a
    # quarter of the way from each of its vertices to its centroid first
    blind = ~np.isnan(_poorly_seen(centres, mid[:, None, :], 2.0 * float(step.min()))[:, 0])
    corners = vertices[blind] + 0.25 * (mid[blind][:, None, :] - vertices[blind])
    extra = np.concatenate(comm.allgather(corners.reshape(-1, gdim)))
    if extra.shape[0]:
        centres = np.vstack([centres, _apart(centres, extra[np.lexsort(extra.T[::-1])], 0.0)])
    # then between; then, for a point still blind, without the gap, and at the point itself
    tries = [(0.5, half), (0.25, half), (0.75, half), (0.5, 0.0), (0.0, 0.0), (0.25, 0.0)]
    for t, gap in [*tries, (0.75, 0.0)]:
        probe = _poorly_seen(centres, vertices, 2.0 * float(step.min()))
        blind = ~np.isnan(probe[:, 0])
        extra = np.concatenate(comm.allgather(probe[blind] + t * (mid[blind] - probe[blind])))
        if extra.shape[0] == 0:
            break
        centres = np.vstack([centres, _apart(centres, extra[np.lexsort(extra.T[::-1])], gap)])
    fine = lattice(samples)
    fine = fine[_in_patch(patch, fine)]
    q = cell_quadrature(msh, 2, patch.cells)
    area = comm.allreduce(float(q.weights.sum()), op=MPI.SUM)
    while True:  # drop a particle whose centre is in the patch but none of its samples is
        nearest = cKDTree(centres).query(fine)[1]
        count = np.bincount(nearest, minlength=centres.shape[0])
        if np.all(count > 0):
            break
        centres = centres[count > 0]
    volumes = count * (area / count.sum())
    particles = ParticleSet(centres, mesh=msh, cells=patch.cells, volumes=volumes)
    if gdim == 2:  # an axisymmetric model's masses: each sample's area revolved at its radius
        # (Pappus at the particle itself is exact only for a region centred on it, not for the
        # particles added at a staircase's corners: a one-column patch on the axis weighed 23 %
        # too little), scaled to the cells' revolved volume as the areas are to their area
        moment = np.bincount(nearest, weights=np.abs(fine[:, 0]), minlength=centres.shape[0])
        q4 = cell_quadrature(msh, 4, patch.cells)
        exact = comm.allreduce(float(np.dot(q4.weights, np.abs(q4.points[:, 0]))), op=MPI.SUM)
        if moment.sum() > 0.0:
            particles.revolved_volumes = 2.0 * np.pi * moment * (exact / moment.sum())
    return particles
