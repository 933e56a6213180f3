"""Degree-1 Lagrange (P1 triangles, Q1 quadrilaterals) basis functions at arbitrary points.

Two entry points:

* :func:`tabulate_in_cells` — points whose owned cell is already known (quadrature points); local,
  no communication, columns are *local* node indices of the function space.
* :func:`tabulate_fe_basis` — arbitrary points on each rank; collective. Each point is located in
  the mesh, computed by the rank that owns its cell and returned to the rank that asked, so the
  result is correct when a point lies in another rank's part of the mesh. Columns are *global*
  node (block) indices; vector dof ``(node, comp)`` is ``bs * node + comp`` in PETSc numbering.

Reference coordinates are found by a batched Newton iteration on the degree-1 coordinate map,
basis values by one basix tabulation for all points; gradients by ``J^-T`` (no loop over cells).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from .. import _compat
from ..parallel import raise_on_all_ranks
from . import batched
from .neighbours import check_points
from .tables import ShapeTable

if TYPE_CHECKING:  # annotations only
    import dolfinx.fem
    import dolfinx.mesh
    from mpi4py import MPI

__all__ = [
    "PointsOutsideMeshError",
    "ensure_points_in_mesh",
    "evaluate_fe_function",
    "locate_points",
    "route_to_owners",
    "tabulate_fe_basis",
    "tabulate_in_cells",
]


class PointsOutsideMeshError(ValueError):
    """Some evaluation points lie in no cell of the mesh."""


def _check_space(V: dolfinx.fem.FunctionSpace) -> None:
    msh = V.mesh
    ncv = _compat.geometry_dofmap(msh).shape[1]
    if V.dofmap.dof_layout.num_dofs != ncv:
        raise ValueError(
            f"only degree-1 Lagrange spaces (P1/Q1) are supported; this space has "
            f"{V.dofmap.dof_layout.num_dofs} nodes per cell where the cell has {ncv} vertices"
        )


def reference_coordinates(
    msh: dolfinx.mesh.Mesh, points: np.ndarray, cells: np.ndarray
) -> np.ndarray:
    """Pull physical points back to the reference cell of their (local) cells by Newton.

    Args:
        points: (m, gdim); cells: (m,) local cell indices.

    Returns:
        Reference coordinates (m, tdim).
    """
    element = _compat.basix_lagrange_p1(msh.topology.cell_type.name)
    gdim = msh.geometry.dim
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]  # (m, nv, gdim)
    m = points.shape[0]
    X = np.full((m, msh.topology.dim), 1.0 / 3.0 if nodes.shape[1] == 3 else 0.5)
    diam = np.linalg.norm(nodes.max(axis=1) - nodes.min(axis=1), axis=1) if m else np.zeros(0)
    for _ in range(20):
        tab = element.tabulate(1, X)  # (1 + tdim, m, nv, 1)
        x = np.einsum("qv,qvg->qg", tab[0, :, :, 0], nodes)
        J = np.einsum("dqv,qvg->qgd", tab[1:, :, :, 0], nodes)
        res = points - x
        if m == 0 or np.all(np.linalg.norm(res, axis=1) <= 1e-13 * diam):
            break
        X = X + np.einsum("qij,qj->qi", batched.inv(J), res)
    return X


def tabulate_in_cells(
    V: dolfinx.fem.FunctionSpace, points: npt.ArrayLike, cells: npt.ArrayLike, derivatives: int = 1
) -> ShapeTable:
    """Basis of ``V`` at points that lie in the given local cells; columns are local nodes.

    Args:
        V: Degree-1 Lagrange (vector or scalar) function space.
        points: (m, gdim) physical points; cells: (m,) local cell index of each point.

    Returns:
        :class:`ShapeTable` with ``num_local_nodes`` columns (owned and ghost nodes of ``V``).
    """
    _check_space(V)
    msh = V.mesh
    gdim = msh.geometry.dim
    x = check_points(points, gdim, "points")
    cells = np.asarray(cells, dtype=np.int64)
    imap = V.dofmap.index_map
    n = imap.size_local + imap.num_ghosts
    if x.shape[0] == 0:  # basix cannot tabulate at no points
        empty = sp.csr_matrix((0, n))
        return ShapeTable(points=x, values=empty, gradients=[empty.copy()] * (gdim * derivatives))
    element = _compat.basix_lagrange_p1(msh.topology.cell_type.name)
    X = reference_coordinates(msh, x, cells)
    tab = element.tabulate(1, X)
    dofs = _compat.dofmap_array(V)[cells]  # (m, nv)
    m, nv = dofs.shape
    rows = np.repeat(np.arange(m), nv)
    values = sp.csr_matrix((tab[0, :, :, 0].ravel(), (rows, dofs.ravel())), shape=(m, n))
    grads: list[sp.csr_matrix] = []
    if derivatives:
        nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]
        J = np.einsum("dqv,qvg->qgd", tab[1:, :, :, 0], nodes)
        dphi = np.einsum("qdg,dqv->qvg", batched.inv(J), tab[1:, :, :, 0])  # J^-T dphi/dX
        for k in range(gdim):
            grads.append(sp.csr_matrix((dphi[:, :, k].ravel(), (rows, dofs.ravel())), shape=(m, n)))
    return ShapeTable(points=x, values=values, gradients=grads)


def locate_points(
    msh: dolfinx.mesh.Mesh, points: np.ndarray, preferred: np.ndarray | None = None
) -> np.ndarray:
    """Owned local cell containing each point (-1 where this rank owns none); local.

    ``preferred`` (bool per local cell): among several owned cells containing a point (points
    on shared facets), take a preferred one if there is one.
    """
    num_owned = msh.topology.index_map(msh.topology.dim).size_local
    m = points.shape[0]
    cells = np.full(m, -1, dtype=np.int64)
    if m == 0:
        return cells
    p3 = np.zeros((m, 3))
    p3[:, : points.shape[1]] = points
    offsets, arr = _compat.colliding_cells(msh, _compat.bb_tree(msh, msh.topology.dim), p3)
    counts = np.diff(offsets)
    owner_pt = np.repeat(np.arange(m), counts)
    own = arr < num_owned
    pts, first = np.unique(owner_pt[own], return_index=True)
    cells[pts] = arr[own][first]
    if preferred is not None:
        good = own & preferred[arr]
        pts, first = np.unique(owner_pt[good], return_index=True)
        cells[pts] = arr[good][first]
    return cells


def _owners(
    msh: dolfinx.mesh.Mesh,
    everything: np.ndarray,
    counts: np.ndarray,
    preferred: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Owning rank and owned local cell of every gathered point; raises on every rank if any
    point lies outside the mesh. With ``preferred`` (bool per local cell), a rank owning a
    preferred cell that contains the point wins over ranks that own only other cells, so the
    choice does not depend on the partition. Collective."""
    from mpi4py import MPI

    comm = msh.comm
    size = comm.size
    cells = locate_points(msh, everything, preferred)
    good = cells >= 0
    if preferred is not None:
        first_class = good & preferred[np.maximum(cells, 0)]
        claim = np.where(first_class, comm.rank, np.where(good, size + comm.rank, 2 * size))
    else:
        claim = np.where(good, comm.rank, 2 * size)
    claim = claim.astype(np.int32)
    best = np.empty_like(claim)
    comm.Allreduce(claim, best, op=MPI.MIN)
    owner = np.where(best < 2 * size, best % size, size)
    missing = np.flatnonzero(owner == comm.size)
    if missing.size:
        starts = np.concatenate([[0], np.cumsum(counts)])
        src = np.searchsorted(starts, missing, side="right") - 1
        which = [
            f"rank {int(r)} point {int(k - starts[r])} "
            f"{np.array2string(everything[k], precision=6)}"
            for k, r in zip(missing[:10], src[:10], strict=True)
        ]
        raise PointsOutsideMeshError(
            f"{missing.size} point(s) lie outside the mesh: {'; '.join(which)}"
            + (" ..." if missing.size > 10 else "")
            + ". Move them into the domain."
        )
    return owner, cells


def _gather(comm: MPI.Comm, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    counts = np.array(comm.allgather(points.shape[0]))
    everything = np.vstack(comm.allgather(points)) if counts.sum() else points
    return everything, counts


def ensure_points_in_mesh(msh: dolfinx.mesh.Mesh, points: npt.ArrayLike) -> np.ndarray:
    """Validate this rank's points and check that every rank's points lie in the mesh.

    Raises :class:`PointsOutsideMeshError` on every rank otherwise (collective).
    """
    x = raise_on_all_ranks(msh.comm, lambda: check_points(points, msh.geometry.dim, "points"))
    _owners(msh, *_gather(msh.comm, x))
    return x


def route_to_owners(
    msh: dolfinx.mesh.Mesh,
    points: np.ndarray,
    compute: Callable[[np.ndarray, np.ndarray], list],
    preferred: np.ndarray | None = None,
) -> list:
    """Locate every rank's points, let the owning ranks ``compute`` on them, send results back.

    ``compute(points, cells)`` returns a list of per-point results (rows); the return value is
    that list in the order of this rank's ``points``. ``preferred`` (bool per local cell):
    points on shared facets go to a preferred cell where there is one. Collective.
    """
    comm = msh.comm
    rank, size = comm.rank, comm.size
    everything, counts = _gather(comm, points)
    owner, cells = _owners(msh, everything, counts, preferred)
    mine = np.flatnonzero(owner == rank)
    results = compute(everything[mine], cells[mine]) if mine.size else []
    starts = np.concatenate([[0], np.cumsum(counts)])
    dest = np.searchsorted(starts, mine, side="right") - 1
    outgoing = [
        (mine[dest == r] - starts[r], [results[k] for k in np.flatnonzero(dest == r)])
        for r in range(size)
    ]
    incoming = comm.alltoall(outgoing)
    ordered: list = [None] * points.shape[0]
    for idx, rows in incoming:
        for k, row in zip(idx, rows, strict=True):
            ordered[k] = row
    return ordered


def tabulate_fe_basis(
    V: dolfinx.fem.FunctionSpace, points: npt.ArrayLike, derivatives: int = 1
) -> ShapeTable:
    """Values and gradients of the basis of ``V`` at any points of the mesh (collective).

    Every rank passes its own points (possibly none). Points outside the mesh raise
    :class:`PointsOutsideMeshError` on every rank, listing how many and which.

    Returns:
        :class:`ShapeTable` (m x num_global_nodes) with global node (block) columns.
    """
    _check_space(V)
    msh = V.mesh
    gdim = msh.geometry.dim
    x = raise_on_all_ranks(msh.comm, lambda: check_points(points, gdim, "points"))
    imap = V.dofmap.index_map
    l2g = np.asarray(
        imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    )

    def compute(pts: np.ndarray, cells: np.ndarray) -> list:
        t = tabulate_in_cells(V, pts, cells, derivatives)
        mats = [t.values, *t.gradients]
        rows = []
        for q in range(pts.shape[0]):
            cols = mats[0].indices[mats[0].indptr[q] : mats[0].indptr[q + 1]]
            rows.append((l2g[cols], [mm.data[mm.indptr[q] : mm.indptr[q + 1]] for mm in mats]))
        return rows

    rows = route_to_owners(msh, x, compute)
    n = imap.size_global
    m = x.shape[0]
    nmat = 1 + (gdim if derivatives else 0)
    if m:
        cols = np.concatenate([r[0] for r in rows])
        ptr = np.concatenate([[0], np.cumsum([len(r[0]) for r in rows])])
        mats = [
            sp.csr_matrix((np.concatenate([r[1][k] for r in rows]), cols, ptr), shape=(m, n))
            for k in range(nmat)
        ]
    else:
        mats = [sp.csr_matrix((0, n)) for _ in range(nmat)]
    return ShapeTable(points=x, values=mats[0], gradients=mats[1:])


def evaluate_fe_function(u: dolfinx.fem.Function, points: npt.ArrayLike) -> np.ndarray:
    """Values of a degree-1 Lagrange :class:`dolfinx.fem.Function` at any points (collective).

    Ghost values of ``u`` must be up to date (``u.x.scatter_forward()``).

    Returns:
        (m, bs) values at this rank's points.
    """
    V = u.function_space
    _check_space(V)
    msh = V.mesh
    x = raise_on_all_ranks(msh.comm, lambda: check_points(points, msh.geometry.dim, "points"))
    bs = V.dofmap.index_map_bs
    local = u.x.array.reshape(-1, bs)

    def compute(pts: np.ndarray, cells: np.ndarray) -> list:
        vals = tabulate_in_cells(V, pts, cells, derivatives=0).values @ local
        return list(vals)

    rows = route_to_owners(msh, x, compute)
    return np.array(rows, dtype=float).reshape(-1, bs)
