"""The particles of one body do not reach into another (issue 27, item 2).

An MLS support is a ball: near the gap between two bodies of one mesh (a projectile and its
target, two bars meeting head-on) it holds particles of both, and the shape functions
(Belytschko et al. 1995, eq. 3.9) join the bodies as if the gap were material. They could then
neither part nor press on each other: the contact's penalty would act inside one field. Here a
pair cut (:attr:`~dolfinx_meshfree.MLS.pair_cuts`) drops every (point, particle) pair whose
point and particle lie in different bodies (:func:`~dolfinx_meshfree.geometry.bodies.mesh_bodies`:
the mesh's connected pieces), so that each body's functions are the MLS of its own particles:
they reproduce linear fields on it exactly (the consistency conditions of eq. 3.7 hold per
body), and vanish on the others.

**Which body a point is in.** A particle's body is the body of the cell it lies in. A point's
body matters only where its support holds a particle of a body that is not its own (beside
its own body's, or alone); such a point lies within the largest support radius ``reach`` of
that particle, hence in one of the cells within ``reach`` plus their size of another body's
particles: the gap's cells. The points with particles of two bodies in support, and the points
near a gap cell, are located.
Those are few (a band along the bodies' facing surfaces); their vertices are gathered on every
rank, so that the cut locates a point by itself (local: an MLS tabulates without
communication, at any point of the mesh). A cell is split into simplices (a quadrilateral in
two triangles, a hexahedron in six tetrahedra about its diagonal), in which the point's
barycentric coordinates are ``>= -TOL``.

Refused, by coordinates: a particle in cells of two bodies (the bodies touch there: one particle
cannot carry both; leave a gap, or place particles in one of them); a point with particles of
two bodies in support that lies in no gap cell or in cells of two bodies (outside the mesh, or
where bodies touch); a point whose support holds no particle of its own body (all its pairs
dropped: the MLS's singular-moment-matrix error names it; it is not extrapolated from the other
body).
"""

from __future__ import annotations

import copy
from itertools import permutations

import dolfinx
import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

from .. import _compat
from ..geometry.bodies import mesh_bodies
from ..parallel import raise_on_all_ranks
from .mls import MLS

__all__ = ["TOL", "BodyCut", "body_cut", "separate_bodies"]

#: A point lies in a simplex when its barycentric coordinates are ``>= -TOL``.
TOL = 1e-9


def _kuhn(dim: int) -> list[tuple[int, ...]]:
    """Kuhn's split of a tensor-ordered quadrilateral (hexahedron) into 2 (6) simplices about
    its diagonal: the paths from vertex 0 to vertex ``2**dim - 1`` adding one coordinate bit at
    a time (DOLFINx's vertex ``k`` has the coordinate bits of ``k``)."""
    return [
        tuple(int(v) for v in np.cumsum([0, *(1 << b for b in order)]))
        for order in permutations(range(dim))
    ]


#: Simplices of a cell, by local vertex.
_SIMPLICES = {
    "interval": [(0, 1)],
    "triangle": [(0, 1, 2)],
    "tetrahedron": [(0, 1, 2, 3)],
    "quadrilateral": _kuhn(2),
    "hexahedron": _kuhn(3),
}


def _range_by(
    index: np.ndarray, values: np.ndarray, n: int, none: int
) -> tuple[np.ndarray, np.ndarray]:
    """The smallest and largest of ``values`` per ``index`` in ``0 .. n - 1``: ``(none, -1)``
    where an index has none."""
    lo = np.full(n, none, dtype=np.int64)
    hi = np.full(n, -1, dtype=np.int64)
    np.minimum.at(lo, index, values)
    np.maximum.at(hi, index, values)
    return lo, hi


class BodyCut:
    """A pair cut that keeps the (point, particle) pairs of one body (see the module).

    Args:
        particle_body: The body of every particle (n,), the same on every rank.
        simplices: The gap cells' simplices (k, gdim + 1, gdim), every rank's.
        simplex_body: The body of each simplex (k,).
        reach: The largest support radius the gap cells were chosen for.

    Attributes:
        particle_body, reach: As given. dropped: The pairs dropped by the last call.
    """

    def __init__(
        self,
        particle_body: np.ndarray,
        simplices: np.ndarray,
        simplex_body: np.ndarray,
        reach: float,
    ) -> None:
        self.particle_body = np.asarray(particle_body, dtype=np.int64)
        self.reach = float(reach)
        self._simplices = np.asarray(simplices, dtype=float)
        self._simplex_body = np.asarray(simplex_body, dtype=np.int64)
        gdim = self._simplices.shape[2] if self._simplices.ndim == 3 else 1
        centres = self._simplices.mean(axis=1) if len(self._simplices) else np.zeros((0, gdim))
        self._tree = cKDTree(centres) if len(centres) else None
        size = np.linalg.norm(self._simplices - centres[:, None, :], axis=2)
        self._size = float(size.max()) if size.size else 0.0
        # barycentric maps: lambda_1..d = T^-1 (x - v_0), lambda_0 = 1 - sum
        if len(self._simplices):
            T = np.transpose(self._simplices[:, 1:] - self._simplices[:, :1], (0, 2, 1))
            self._Tinv = np.linalg.inv(T)
        self.dropped = 0

    def subset(self, indices: np.ndarray) -> BodyCut:
        """The cut of the particles ``indices`` (:meth:`~dolfinx_meshfree.MLS.subset`: a halo's
        MLS), the same gap cells."""
        cut = copy.copy(self)
        cut.particle_body = self.particle_body[np.asarray(indices, dtype=np.int64)]
        cut.dropped = 0
        return cut

    def bodies_at(self, x: np.ndarray) -> np.ndarray:
        """The body of each point (m,) from the gap cells: ``-1`` in none, ``-2`` in cells of
        two bodies (local)."""
        out = np.full(x.shape[0], -1, dtype=np.int64)
        if self._tree is None or x.shape[0] == 0:
            return out
        near = self._tree.query_ball_point(x, self._size * (1.0 + 1e-9))
        pt = np.repeat(np.arange(x.shape[0]), [len(n) for n in near])
        s = np.fromiter((k for n in near for k in n), dtype=np.int64, count=pt.size)
        lam = np.einsum("pab,pb->pa", self._Tinv[s], x[pt] - self._simplices[s, 0])
        inside = (lam >= -TOL).all(axis=1) & (lam.sum(axis=1) <= 1.0 + TOL)
        pt, b = pt[inside], self._simplex_body[s[inside]]
        lo, hi = _range_by(pt, b, x.shape[0], np.iinfo(np.int64).max)
        out[hi >= 0] = np.where(lo == hi, hi, -2)[hi >= 0]
        return out

    def __call__(
        self, x: np.ndarray, i: np.ndarray, j: np.ndarray, dx: np.ndarray, dist: np.ndarray,
        ddist: np.ndarray, sides: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
        """Drop the pairs whose point and particle lie in different bodies."""
        self.dropped = 0
        if i.size == 0:
            return i, j, dx, dist, ddist
        bj = self.particle_body[j]
        # each point's smallest and largest particle body, over its pairs (by point)
        order = np.argsort(i, kind="stable") if np.any(np.diff(i) < 0) else slice(None)
        ii, bb = i[order], bj[order]
        starts = np.flatnonzero(np.r_[True, ii[1:] != ii[:-1]])
        pts = ii[starts]  # increasing point indices
        lo, hi = np.minimum.reduceat(bb, starts), np.maximum.reduceat(bb, starts)
        # the points whose body matters: those with particles of two bodies, and those near
        # a gap cell (a point of one body may see only another body's particles)
        near = np.zeros(pts.size, dtype=bool)
        if self._tree is not None:
            d, _ = self._tree.query(x[pts], distance_upper_bound=self._size * (1.0 + 1e-9))
            near = np.isfinite(d)
        ask = (hi > lo) | near
        pts, lo, hi = pts[ask], lo[ask], hi[ask]
        if pts.size == 0:
            return i, j, dx, dist, ddist
        body = self.bodies_at(x[pts])
        bad = np.flatnonzero((body < 0) & (hi > lo))
        if bad.size:
            q = int(bad[0])
            where = (
                "in cells of two bodies (they touch there)"
                if body[q] == -2
                else "in no cell of either (in a gap between them, or outside the mesh)"
            )
            raise ValueError(
                f"the point {x[pts[q]].tolist()} has particles of bodies {int(lo[q])} and "
                f"{int(hi[q])} in its MLS support but lies {where} ({bad.size} such point(s)): "
                "evaluate at points inside one body, and leave a gap between bodies that carry "
                "particles"
            )
        at = np.minimum(np.searchsorted(pts, i), pts.size - 1)
        # a point outside the gap cells (body -1, its particles all of one body) keeps its pairs
        keep = (pts[at] != i) | (body[at] < 0) | (bj == body[at])
        self.dropped = int(keep.size - np.count_nonzero(keep))
        return i[keep], j[keep], dx[keep], dist[keep], ddist[keep]


def separate_bodies(mls: MLS, msh: dolfinx.mesh.Mesh) -> BodyCut | None:
    """Add a :class:`BodyCut` to ``mls``'s pair cuts where the particles of two bodies of
    ``msh`` lie within a support radius of each other's cells, and return it (``None``, and
    ``mls`` unchanged, where no support can reach from one body into another). Collective;
    errors on every rank before any collective call of their own.

    Raises:
        ValueError: a particle lies in cells of two bodies (they touch at it).
    """
    cut = body_cut(mls.points, float(mls.radii.max()), msh)
    if cut is not None:
        mls.pair_cuts.append(cut)
        mls.changed()
    return cut


def body_cut(x: np.ndarray, reach: float, msh: dolfinx.mesh.Mesh) -> BodyCut | None:
    """The :class:`BodyCut` of particles at ``x`` (n, gdim; the same on every rank) whose
    supports reach ``reach`` at most, ``None`` where none can reach from one body of ``msh``
    into another (collective; errors on every rank before any collective call of their own).

    Raises:
        ValueError: a particle lies in cells of two bodies (they touch at it), or in none.
    """
    comm = msh.comm
    bodies = mesh_bodies(msh)
    if bodies.count == 1:
        return None
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    n = x.shape[0]
    # each particle's body: of the local cells that contain it, agreed over the ranks
    p3 = np.zeros((n, 3))
    p3[:, :gdim] = x
    offsets, cells = _compat.colliding_cells(msh, _compat.bb_tree(msh, tdim), p3)
    pt = np.repeat(np.arange(n), np.diff(offsets))
    lo, hi = _range_by(pt, bodies.cell_body[cells].astype(np.int64), n, bodies.count)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    two = np.flatnonzero(lo != hi)

    def check() -> None:
        if two.size:
            q = int(two[0])
            state = "lies in no cell" if hi[q] < 0 else f"lies in bodies {lo[q]} and {hi[q]}"
            raise ValueError(
                f"the particle at {x[q].tolist()} {state} ({two.size} such particle(s)): two "
                "bodies of the mesh touch at it, and one particle cannot carry both; leave a gap "
                "between the bodies, or place particles in one of them"
            )

    raise_on_all_ranks(comm, check)
    particle_body = lo
    if np.unique(particle_body).size < 2:
        return None
    # the gap's cells: owned cells within reach (+ their size) of another body's particles
    num_owned = msh.topology.index_map(tdim).size_local
    cell_name = msh.topology.cell_type.name
    nv = max(max(s) for s in _SIMPLICES[cell_name]) + 1
    dofs = _compat.geometry_dofmap(msh)[:num_owned, :nv]
    verts = msh.geometry.x[dofs][:, :, :gdim]  # (cells, nv, gdim)
    centre = verts.mean(axis=1)
    radius = np.linalg.norm(verts - centre[:, None, :], axis=2).max(axis=1)
    own_body = bodies.cell_body[:num_owned]
    near = np.zeros(num_owned, dtype=bool)
    for body in np.unique(particle_body):
        mine = np.flatnonzero(own_body != body)  # cells a particle of `body` may reach
        if mine.size == 0:
            continue
        d, _ = cKDTree(x[particle_body == body]).query(centre[mine])
        near[mine[d < reach + radius[mine]]] = True
    idx = np.flatnonzero(near)
    local = [verts[idx][:, list(s)] for s in _SIMPLICES[cell_name]]
    simplices = np.concatenate(local) if local else np.zeros((0, gdim + 1, gdim))
    simplex_body = np.tile(own_body[idx], len(_SIMPLICES[cell_name]))
    simplices = np.concatenate(comm.allgather(simplices))
    simplex_body = np.concatenate(comm.allgather(simplex_body))
    if len(simplices) == 0:  # the bodies' particles are farther apart than any support
        return None
    return BodyCut(particle_body, simplices, simplex_body, reach)
