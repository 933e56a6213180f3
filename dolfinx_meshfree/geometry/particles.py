"""Particle sets: positions, volumes, ownership under MPI and particle generation in mesh cells.

Parallel model: a particle patch is small next to the FE mesh, so every rank holds every particle's
position (``positions`` is replicated and identical on all ranks). Each particle is *owned* by the
rank that owns the mesh cell containing it (the lowest such rank on shared boundaries); PETSc
numbers particles owner by owner, so each rank's particle dofs form one contiguous range
(:attr:`ParticleSet.layout`), with vector components interleaved like a DOLFINx block size gdim.
Gathering positions sits behind :meth:`ParticleSet.from_cells` so that it can become a halo
exchange later.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from scipy.spatial import cKDTree

from .. import _compat
from ..approx.fe_points import locate_points
from ..approx.neighbours import check_points
from ..parallel import Layout, raise_on_all_ranks
from .bodies import mesh_bodies
from .placement_3d import check_border_3d, conforming_layer_3d, distance_to_facets
from .quadrature import cell_quadrature, cell_sizes, lattice_quadrature, require_affine

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = ["ParticleSet"]

#: Lattice points per chunk of the Voronoi volumes' quadrature (bounds its temporaries).
_VOLUME_CHUNK_POINTS = 1 << 17
#: Sub-cells per particle spacing along each edge of the Voronoi volumes' lattice rule (and the
#: fewest per cell edge): on a grid of particles at the vertices 4 x 4 points a cell, at ``h /
#: 2`` 8 x 8 (:meth:`ParticleSet._voronoi_volumes`).
VOLUME_SUBDIVISIONS = 4
#: The most sub-cells per cell edge of the Voronoi volumes' lattice (4,096 points a cell), by
#: the cells' dimension: a cell far larger than the particles' spacing (a graded mesh's outer
#: cells) only feeds the border particles' regions.
VOLUME_MAX_LATTICE = {1: 4096, 2: 64, 3: 16}


def _lattice_chunks(
    msh: dolfinx.mesh.Mesh, cells: np.ndarray, tree: cKDTree
) -> list[tuple[np.ndarray, int]]:
    """The local ``cells`` in chunks of one lattice size each, ``(cells, m)``: ``m`` sub-cells
    per edge, :data:`VOLUME_SUBDIVISIONS` per spacing of the particle nearest the cell's
    midpoint (its mean distance to its ``2 d`` nearest neighbours) over the cell's size, within
    ``[VOLUME_SUBDIVISIONS, VOLUME_MAX_LATTICE]`` (local)."""
    if cells.size == 0:
        return []
    tdim = msh.topology.dim
    mid = cell_quadrature(msh, 1, cells)
    size = cell_sizes(msh, cells)
    if tree.n > 1:
        k = min(2 * tdim, tree.n - 1)
        nearest = tree.query(mid.points, k=1)[1]
        spacing = tree.query(tree.data[nearest], k=k + 1)[0][:, 1:].mean(axis=1)
        m = np.ceil(VOLUME_SUBDIVISIONS * size / spacing - 1e-9)
    else:
        m = np.zeros(cells.size)
    m = np.clip(m, VOLUME_SUBDIVISIONS, VOLUME_MAX_LATTICE[tdim]).astype(np.int64)
    chunks = []
    for mi in np.unique(m):
        group = cells[m == mi]
        per = max(1, _VOLUME_CHUNK_POINTS // int(mi) ** tdim)
        chunks += [(group[i : i + per], int(mi)) for i in range(0, len(group), per)]
    return chunks


def _points_in_cells(msh: dolfinx.mesh.Mesh, points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Whether each point lies in one of the given local cells (local, no communication)."""
    m = points.shape[0]
    inside = np.zeros(m, dtype=bool)
    if m == 0 or cells.size == 0:
        return inside
    p3 = np.zeros((m, 3))
    p3[:, : points.shape[1]] = points
    offsets, arr = _compat.colliding_cells(msh, _compat.bb_tree(msh, msh.topology.dim), p3)
    hit = np.isin(arr, cells)
    pt = np.repeat(np.arange(m), np.diff(offsets))
    inside[pt[hit]] = True
    return inside


def _owned_cells(mesh: dolfinx.mesh.Mesh, cells: npt.ArrayLike | None) -> np.ndarray:
    """Validated owned local cells (default: every owned cell); an error on every rank when
    they are not owned cells or when no rank names any (collective)."""
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local

    def check() -> np.ndarray:
        c = np.arange(num_owned) if cells is None else np.asarray(cells, dtype=np.int64)
        if c.ndim != 1 or (c.size and (c.min() < 0 or c.max() >= num_owned)):
            raise ValueError(
                f"cells must be owned local cell indices in [0, {num_owned}); got "
                f"{c.min() if c.size else ''}..{c.max() if c.size else ''}"
            )
        return c

    c = raise_on_all_ranks(mesh.comm, check)
    if mesh.comm.allreduce(c.size) == 0:
        raise ValueError("cells is empty on every rank: the patch has no cells")
    return c


def _check_border(border: npt.ArrayLike, gdim: int) -> np.ndarray:
    """Border facets as segments (k, 2, gdim) (a 1D facet, a point, is a segment of length 0)."""
    b = np.asarray(border, dtype=float)
    if b.ndim != 3 or b.shape[1] not in (1, 2) or b.shape[2] < gdim:
        raise ValueError(
            f"border should have shape (num_facets, 2, {gdim}) (facet end points), got {b.shape}"
        )
    b = b[:, :, :gdim]
    return np.concatenate([b, b], axis=1) if b.shape[1] == 1 else b


def _distance_to_segments(points: np.ndarray, segments: np.ndarray, reach: float) -> np.ndarray:
    """Distance (m,) from each point to the nearest segment, exact where it is at most ``reach``
    (``inf`` further away)."""
    d = np.full(points.shape[0], np.inf)
    if points.shape[0] == 0 or segments.shape[0] == 0:
        return d
    a, t = segments[:, 0], segments[:, 1] - segments[:, 0]
    length = np.linalg.norm(t, axis=1)
    near = cKDTree(points).query_ball_point(a + 0.5 * t, 0.5 * length + reach)
    for f, cand in enumerate(near):
        if not cand:
            continue
        cand = np.asarray(cand, dtype=np.int64)
        r = points[cand] - a[f]
        xi = np.clip(r @ t[f] / max(length[f] ** 2, np.finfo(float).tiny), 0.0, 1.0)
        d[cand] = np.minimum(d[cand], np.linalg.norm(r - xi[:, None] * t[f], axis=1))
    return d


def _conforming_layer(
    grid: np.ndarray, segments: np.ndarray, spacing: float, tol: float
) -> np.ndarray:
    """Grid points ``grid`` (m, gdim) in the cells joined with particles on the border
    ``segments`` (k, 2, gdim): on every border vertex and at ``max(1, round(length / spacing))``
    intervals along every facet. Grid points closer than ``spacing / 2`` to the border are
    dropped, except those that coincide (within ``tol``) with a border particle, which they
    replace: a grid whose lines hold the border is returned unchanged (and in its order). The
    border particles follow the grid's, sorted by (y, x) (local; identical on every rank when the
    inputs are)."""
    a, b = segments[:, 0], segments[:, 1]
    pieces = np.maximum(1, np.round(np.linalg.norm(b - a, axis=1) / spacing)).astype(np.int64)
    facet = np.repeat(np.arange(len(segments)), pieces + 1)
    start = np.repeat(np.cumsum(pieces + 1) - (pieces + 1), pieces + 1)
    xi = (np.arange(facet.size) - start) / pieces[facet]
    on = a[facet] + xi[:, None] * (b - a)[facet]
    # one particle per border point (neighbouring facets share their end points)
    key = np.round(on / tol).astype(np.int64)
    on = on[np.sort(np.unique(key, axis=0, return_index=True)[1])]
    keep = ~(_distance_to_segments(grid, segments, 0.5 * spacing) < 0.5 * spacing)
    if grid.shape[0] and on.shape[0]:
        dist, idx = cKDTree(on).query(grid, distance_upper_bound=2.0 * tol)
        same = dist <= tol
        keep |= same
        on = np.delete(on, idx[same], axis=0)
    return np.vstack([grid[keep], on[np.lexsort(on.T)]])


def _nearest_shares(tree: cKDTree, points: np.ndarray, gdim: int) -> tuple[np.ndarray, np.ndarray]:
    """The nearest particles of each point and each one's share of it: ``(idx, share)``, both
    (points, k); a point equidistant (to 1e-10 relative) from several nearest particles is
    shared equally among them, the other columns get 0.

    ``k = 2**gdim`` covers the ties of regular grids (a cell centre is equidistant from its
    ``2**gdim`` corners) at half the cost of a wider query; the rows whose ``k`` neighbours
    are all tied are queried again with twice ``k`` until they are not (or every particle is
    in), so no tie is ever cut off."""
    n = tree.n

    def nearest(x: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Indices (len(x), k) of the k nearest and which of them tie with the nearest."""
        dist, idx = tree.query(x, k=k)
        dist, idx = dist.reshape(len(x), k), idx.reshape(len(x), k)
        return idx, dist <= dist[:, :1] * (1.0 + 1e-10)

    k = min(2**gdim, n)
    idx, tied = nearest(points, k)
    full = np.flatnonzero(tied[:, -1]) if k < n else np.empty(0, dtype=np.int64)
    if full.size:  # ties beyond k: these rows again, wider, padded back to one width
        wide = k
        while True:
            wide = min(2 * wide, n)
            i2, t2 = nearest(points[full], wide)
            if wide == n or not t2[:, -1].any():
                break
        idx = np.pad(idx, ((0, 0), (0, wide - k)))
        tied = np.pad(tied, ((0, 0), (0, wide - k)))
        idx[full], tied[full] = i2, t2
    return idx, tied / tied.sum(axis=1, keepdims=True)


def _body_grid(
    mesh: dolfinx.mesh.Mesh,
    c: np.ndarray,
    spacing: float,
    jitter: float,
    seed: int,
    segments: np.ndarray | None,
) -> tuple[np.ndarray, float]:
    """The grid points of :meth:`ParticleSet.from_cells` in this rank's owned cells ``c`` (one
    body's; any rank may have none) and its tolerance: the box of every rank's ``c`` with
    ``round(extent / spacing)`` intervals per direction, interior points jittered (not those on
    the border ``segments``), the points in the cells kept (collective)."""
    comm = mesh.comm
    gdim = mesh.geometry.dim
    nodes = mesh.geometry.x[_compat.geometry_dofmap(mesh)[c], :gdim].reshape(-1, gdim)
    lo = nodes.min(axis=0) if nodes.size else np.full(gdim, np.inf)
    hi = nodes.max(axis=0) if nodes.size else np.full(gdim, -np.inf)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    counts = [max(1, round((hi[k] - lo[k]) / spacing)) for k in range(gdim)]
    axes = [np.linspace(lo[k], hi[k], counts[k] + 1) for k in range(gdim)]
    grid = np.stack(np.meshgrid(*axes, indexing="xy"), axis=-1).reshape(-1, gdim)
    step = (hi - lo) / np.asarray(counts)
    tol = 1e-9 * float(step.max())
    if jitter > 0.0:
        if segments is None:
            on_border = np.zeros(grid.shape[0], dtype=bool)
        elif gdim == 3:
            on_border = distance_to_facets(grid, segments, tol) <= tol
        else:
            on_border = _distance_to_segments(grid, segments, tol) <= tol
        rng = np.random.default_rng(seed)
        interior = np.all((grid > lo + 1e-9 * step) & (grid < hi - 1e-9 * step), axis=1)
        moves = rng.uniform(-jitter, jitter, (interior.sum(), gdim)) * step
        moves[on_border[interior]] = 0.0
        grid[interior] += moves
    inside = _points_in_cells(mesh, grid, c).astype(np.int8)
    comm.Allreduce(MPI.IN_PLACE, inside, op=MPI.MAX)
    return grid[inside.astype(bool)], tol


class ParticleSet:
    """Particles with positions, volumes and MPI ownership.

    Args:
        positions: (n, gdim) coordinates, identical on every rank.
        comm: Communicator (defaults to the mesh's).
        mesh: Background mesh; particles are owned by the rank owning their cell, and volumes are
            computed from its quadrature when ``volumes`` is not given. Without a mesh particles
            are distributed in contiguous blocks and ``volumes`` stays ``None`` unless given.
        cells: Local cells that the particles fill (the patch); default every owned cell.
        volumes: (n,) particle volumes.
    """

    def __init__(
        self,
        positions: npt.ArrayLike,
        comm: MPI.Comm | None = None,
        mesh: dolfinx.mesh.Mesh | None = None,
        cells: npt.ArrayLike | None = None,
        volumes: npt.ArrayLike | None = None,
    ) -> None:
        if comm is None:
            if mesh is None:
                raise ValueError("ParticleSet needs comm= or mesh=")
            comm = mesh.comm
        if mesh is not None:
            require_affine(mesh, "ParticleSet")
        self.comm = comm
        gdim = mesh.geometry.dim if mesh is not None else np.asarray(positions).shape[-1]
        x = raise_on_all_ranks(comm, lambda: check_points(positions, gdim, "positions"))
        sums = comm.allgather((x.shape[0], float(np.sum(x))))
        if len(set(sums)) != 1:
            raise ValueError(
                "positions must be identical on every rank (particle positions are replicated); "
                f"got (count, sum) per rank {sums}"
            )
        if x.shape[0] == 0:
            raise ValueError("the particle set is empty; give at least one particle")
        self.positions = x
        self.mesh = mesh
        n = x.shape[0]
        size = comm.size
        if mesh is not None:
            cl = locate_points(mesh, x)
            claim = np.where(cl >= 0, comm.rank, size).astype(np.int32)
            owner = np.empty_like(claim)
            comm.Allreduce(claim, owner, op=MPI.MIN)
            outside = np.flatnonzero(owner == size)
            if outside.size:
                raise ValueError(
                    f"{outside.size} particle(s) lie outside the mesh, first {x[outside[0]]}; "
                    "particles must lie in the background cells"
                )
        else:
            owner = np.minimum((np.arange(n) * size) // n, size - 1).astype(np.int32)
        self.owner = owner
        order = np.argsort(owner, kind="stable")
        #: PETSc (global) particle number of each particle, owner by owner.
        self.petsc_index = np.empty(n, dtype=np.int64)
        self.petsc_index[order] = np.arange(n)
        self.owned = np.flatnonzero(owner == comm.rank)
        self.layout = Layout(self.owned.size, n, int(np.sum(owner < comm.rank)))
        self.cells = None if cells is None else np.asarray(cells, dtype=np.int64)
        if volumes is not None:
            v = np.asarray(volumes, dtype=float)
            if v.shape != (n,) or not np.all(v > 0):
                raise ValueError(f"volumes should be positive with shape ({n},), got {v.shape}")
            self.volumes = v
        elif mesh is not None:
            self.volumes = self._voronoi_volumes(mesh, self.cells)
        else:
            self.volumes = None
        #: (n,) the volumes revolved about the axis ``r = 0`` (``int 2 pi r dA`` over each
        #: particle's region) where the set's maker measured them (the hybrid's centred
        #: particles, :func:`~dolfinx_meshfree.couplings.hybrid_sph.centred_particles`); an
        #: axisymmetric model's ``rho V_I`` masses take them. ``None``: ``2 pi r_I V_I``.
        self.revolved_volumes: np.ndarray | None = None

    @property
    def num_particles(self) -> int:
        return self.positions.shape[0]

    def integration_cells(self) -> np.ndarray:
        """The local cells the particles are integrated on (int64): :attr:`cells`, or every
        owned cell of the mesh when it is ``None`` (local; needs a mesh)."""
        if self.cells is not None:
            return self.cells
        return np.arange(self.mesh.topology.index_map(self.mesh.topology.dim).size_local)

    @property
    def gdim(self) -> int:
        return self.positions.shape[1]

    def _voronoi_volumes(self, msh: dolfinx.mesh.Mesh, cells: np.ndarray | None) -> np.ndarray:
        """Voronoi volumes by quadrature: every point of a lattice rule on the background cells
        (:func:`~dolfinx_meshfree.geometry.quadrature.lattice_quadrature`) gives its weight to
        the nearest particle (collective). Their sum is the volume of the cells: each cell's
        weights are scaled to its volume by Gauss (exact for its degree-1 geometry).

        The lattice has :data:`VOLUME_SUBDIVISIONS` sub-cells per particle spacing along each
        edge (the spacing of the particle nearest the cell's midpoint: the mean distance to its
        ``2 d`` nearest neighbours), at least that many per cell and at most
        :data:`VOLUME_MAX_LATTICE`. The cells' degree-4 Gauss rule (3 x 3 points a square)
        made the regions of a grid at ``h / 2`` up to 23 % off (37 % on hexahedra, 128 % on
        tetrahedra), and finer Gauss rules do not converge on this discontinuous integrand; on
        regular grids at ``h / k`` the lattice's sub-cells' edges lie on the regions' and the
        volumes are exact (``tests/test_particles.py``, with jittered sets against a pixel
        count).

        A point equidistant from several particles (on a Voronoi edge) shares its weight equally
        among them; giving it to whichever the k-d tree returns first made regular-grid volumes
        uneven."""
        if cells is None:
            cells = np.arange(msh.topology.index_map(msh.topology.dim).size_local)
        cells = np.asarray(cells, dtype=np.int64)
        tree = cKDTree(self.positions)
        v = np.zeros(self.num_particles)
        for chunk, m in _lattice_chunks(msh, cells, tree):
            q = lattice_quadrature(msh, m, chunk)
            # the rules' points come cell by cell: each cell's lattice weights scaled to its
            # Gauss volume
            w = q.weights.reshape(len(chunk), -1)
            exact = cell_quadrature(msh, 4, chunk).weights.reshape(len(chunk), -1).sum(axis=1)
            w = w * (exact / w.sum(axis=1))[:, None]
            idx, share = _nearest_shares(tree, q.points, self.gdim)
            share *= w.reshape(-1, 1)
            v += np.bincount(idx.ravel(), weights=share.ravel(), minlength=self.num_particles)
        v = self.comm.allreduce(v, op=MPI.SUM)
        return np.maximum(v, 1e-300)

    @classmethod
    def from_cells(
        cls,
        mesh: dolfinx.mesh.Mesh,
        spacing: float,
        cells: npt.ArrayLike | None = None,
        jitter: float = 0.0,
        seed: int = 0,
        border: npt.ArrayLike | None = None,
    ) -> ParticleSet:
        """A regular grid of particles with the given spacing filling the given cells, optionally
        with a boundary-conforming layer on the cells' border.

        The grid spans the bounding box of the cells with ``round(extent / spacing)`` intervals
        per direction (so its corners are the box's corners) and keeps the points that lie in
        the cells; on a mesh of several bodies (:func:`~dolfinx_meshfree.mesh_bodies`: a
        projectile and its target) each body's cells get a grid of their own box, so that a
        body's particles do not depend on another's cells (nor on a gap between them).
        ``jitter`` moves each interior point by up to ``jitter * spacing`` at random (an
        irregular particle set; boundary points stay on the boundary; body ``b``'s seed is
        ``seed + b``).

        ``border``: this rank's facets (k, 2, gdim) (segments; (k, 1, gdim) in 1D; in 3D
        triangles (k, 3, 3) or quadrilaterals (k, 4, 3) in DOLFINx's vertex order) of the border
        of the cells (e.g. :meth:`ParticlePatch.boundary`). Then particles also sit on every
        border vertex and along every border facet at about the spacing
        (``max(1, round(length / spacing))`` intervals; in 3D along every border edge and on a
        lattice inside every border facet, ``ceil(length / spacing)`` subdivisions, plus the
        centroid of a cell left without a particle off the border, see
        :mod:`~dolfinx_meshfree.geometry.placement_3d`), and grid points closer than half a
        spacing to the border are dropped: every border facet carries particles at its ends
        whatever the spacing and whatever the shape of the border (slanted, curved), so the
        MLS moment matrices stay well-conditioned up to the border, and the FE nodes of the
        border (the interface nodes that the ramp couplings need, Belytschko et al. 1995,
        sec. 3.2) are particles. When the border lies on grid lines (planes) and the spacing
        divides the facets (the grid already has those particles) the set is the grid's.
        The set does not depend on the partition. Collective.
        """
        comm = mesh.comm
        gdim = mesh.geometry.dim

        def check() -> np.ndarray | None:
            if not (isinstance(spacing, int | float) and np.isfinite(spacing) and spacing > 0):
                raise ValueError(f"spacing={spacing!r} must be a positive number")
            if not (0.0 <= jitter < 0.5):
                raise ValueError(f"jitter={jitter} must lie in [0, 0.5)")
            if border is None:
                return None
            if gdim == 3:
                return check_border_3d(border)
            return _check_border(border, gdim)

        mine = raise_on_all_ranks(comm, check)  # this rank's border facets, checked
        every = comm.allgather((spacing, jitter, seed))
        if any(e != every[0] for e in every):  # else the ranks' grids differ, or hang
            raise ValueError(  # on every rank: each sees every value
                "spacing, jitter and seed must be the same on every rank (the particles are "
                f"built collectively), got (spacing, jitter, seed) per rank {every}: compute "
                "them from data every rank shares (e.g. the mesh's extent reduced with "
                "comm.allreduce), not from a rank's own cells"
            )
        c = _owned_cells(mesh, cells)
        segments = np.concatenate(comm.allgather(mine)) if mine is not None else None
        # one grid per body of the mesh (its connected pieces: a projectile and its target),
        # in the box of that body's cells: a body's particles do not depend on another's cells
        bodies = mesh_bodies(mesh)
        body = bodies.cell_body[c]
        present = np.zeros(bodies.count, dtype=np.int8)
        present[body] = 1
        comm.Allreduce(MPI.IN_PLACE, present, op=MPI.MAX)
        grids, tol = [], np.inf
        for b in np.flatnonzero(present):
            g, t = _body_grid(mesh, c[body == b], spacing, jitter, seed + int(b), segments)
            grids.append(g)
            tol = min(tol, t)
        x = np.concatenate(grids)
        if len(grids) > 1:  # bodies that touch share their face's points: one particle each
            key = np.round(x / tol).astype(np.int64)
            x = x[np.sort(np.unique(key, axis=0, return_index=True)[1])]
        if segments is not None and gdim == 3:
            x = conforming_layer_3d(mesh, c, x, segments, spacing, tol)
        elif segments is not None:
            x = _conforming_layer(x, segments, spacing, tol)
        return cls(x, comm=comm, mesh=mesh, cells=c)

    @classmethod
    def from_vertices(
        cls, mesh: dolfinx.mesh.Mesh, cells: npt.ArrayLike | None = None
    ) -> ParticleSet:
        """One particle at every vertex of the given cells (collective).

        The natural particle set of an unstructured (e.g. gmsh) patch: particles sit on the FE
        nodes, also on a curved boundary or interface, as the ramp interface elements need
        (Belytschko et al. 1995, sec. 3.2). Positions are gathered from every rank and sorted, so
        they are identical on every rank.
        """
        comm = mesh.comm
        gdim = mesh.geometry.dim
        c = _owned_cells(mesh, cells)
        nodes = np.unique(_compat.geometry_dofmap(mesh)[c].ravel())
        x = np.concatenate(comm.allgather(mesh.geometry.x[nodes, :gdim]))
        scale = np.abs(x).max() + 1.0
        key = np.round(x / (1e-10 * scale)).astype(np.int64)
        _, first = np.unique(key, axis=0, return_index=True)
        return cls(x[first], comm=comm, mesh=mesh, cells=c)

    def owned_positions(self) -> np.ndarray:
        """Positions (owned particles, gdim) of this rank's particles in the order of their PETSc
        numbers (owner by owner, original order within a rank: :attr:`owned` is that order), as
        :class:`~dolfinx_meshfree.statics.petsc.BlockSystem`'s ``coordinates`` take them."""
        return self.positions[self.owned]

    def dof_layout(self, bs: int = 2) -> Layout:
        """PETSc layout of the particles' ``bs`` interleaved dofs (owner by owner)."""
        return Layout(bs * self.layout.size_local, bs * self.num_particles, bs * self.layout.start)

    def petsc_dofs(self, bs: int = 2) -> np.ndarray:
        """PETSc dof numbers (n, bs) of each particle's components."""
        return bs * self.petsc_index[:, None] + np.arange(bs)[None, :]
