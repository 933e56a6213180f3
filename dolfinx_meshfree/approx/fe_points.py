"""Degree-1 Lagrange (P1 triangles, Q1 quadrilaterals) basis functions at arbitrary points.

Two entry points:

* :func:`tabulate_in_cells` — points whose owned cell is already known (quadrature points); local,
  no communication, columns are *local* node indices of the function space.
* :func:`tabulate_fe_basis` — arbitrary points on each rank; collective. Each point is located in
  the mesh, computed by the rank that owns its cell and returned to the rank that asked, so the
  result is correct when a point lies in another rank's part of the mesh. Columns are *global*
  node (block) indices; vector dof ``(node, comp)`` is ``bs * node + comp`` in PETSc numbering.

Reference coordinates are found by a batched Newton iteration on the degree-1 coordinate map
(only the points not yet converged iterate); the basis values and ``J`` are those of the last
iterate's tabulation, the gradients ``J^-T`` times the reference ones (no loop over cells).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from .. import _compat
from ..geometry.quadrature import require_affine
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
    "check_p1_space",
    "ensure_points_in_mesh",
    "evaluate_fe_function",
    "locate_points",
    "point_value_nodes",
    "route_to_owners",
    "tabulate_fe_basis",
    "tabulate_in_cells",
]


class PointsOutsideMeshError(ValueError):
    """Some evaluation points lie in no cell of the mesh."""


def check_p1_space(V: dolfinx.fem.FunctionSpace) -> None:
    """Refuse a space other than degree-1 Lagrange on affine cells (local)."""
    msh = V.mesh
    require_affine(msh, "FE values at points")
    ncv = _compat.geometry_dofmap(msh).shape[1]
    if V.dofmap.dof_layout.num_dofs != ncv:
        raise ValueError(
            f"only degree-1 Lagrange spaces (P1/Q1) are supported; this space has "
            f"{V.dofmap.dof_layout.num_dofs} nodes per cell where the cell has {ncv} vertices"
        )


def _pull_back(
    msh: dolfinx.mesh.Mesh, points: np.ndarray, cells: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton pull-back of physical points to the reference cells of their (local) cells.

    Returns the reference coordinates X (m, tdim), the P1/Q1 tabulation at X (1 + tdim, m, nv)
    and the Jacobians ``J[q, g, d] = dx_g / dX_d`` at X (m, gdim, tdim): the basis and its
    gradients without tabulating again.

    Every point starts at the reference centre, whose tabulation is one point's broadcast; only
    the points not yet converged (residual above 1e-13 of their cell's diameter) are iterated
    and tabulated again, so an affine cell costs one tabulation per point (the step from the
    centre is exact, the second tabulation both checks it and gives the basis).
    """
    element = _compat.basix_lagrange_p1(msh.topology.cell_type.name)
    gdim, tdim = msh.geometry.dim, msh.topology.dim
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]  # (m, nv, gdim)
    m, nv = nodes.shape[0], nodes.shape[1]
    centre = np.full((1, tdim), 1.0 / (tdim + 1) if nv == tdim + 1 else 0.5)
    X = np.repeat(centre, m, axis=0)
    # the centre's tabulation, broadcast over the points (1 + tdim, 1, nv) until they move
    tab = element.tabulate(1, centre)[:, :, :, 0]
    J = np.empty((m, gdim, tdim))
    hi, lo = nodes[:, 0].copy(), nodes[:, 0].copy()
    for v in range(1, nv):
        np.maximum(hi, nodes[:, v], out=hi)
        np.minimum(lo, nodes[:, v], out=lo)
    tol = 1e-13 * np.sqrt(np.sum((hi - lo) ** 2, axis=1))  # of the cell's diameter
    active: slice | np.ndarray = slice(None)  # a slice while every point iterates: no gathers
    for it in range(20):
        if it == 1:
            tab = element.tabulate(1, X)[:, :, :, 0]
        elif it:
            tab[:, active] = element.tabulate(1, X[active])[:, :, :, 0]
        t, xv = (tab, nodes) if it == 0 else (tab[:, active], nodes[active])
        # x = sum_v phi_v x_v and J[:, g, d] = sum_v dphi_v/dX_d x_v[g], summed over the few
        # nodes and vectorised over the points (numpy's batched matmul is slower for 2 x 4)
        x = t[0][:, 0, None] * xv[:, 0]
        Ja = t[1:, :, 0, None].transpose(1, 2, 0) * xv[:, 0, :, None]
        for v in range(1, nv):
            x += t[0][:, v, None] * xv[:, v]
            Ja += t[1:, :, v, None].transpose(1, 2, 0) * xv[:, v, :, None]
        J[active] = Ja
        res = points[active] - x
        left = np.sum(res**2, axis=1) > tol[active] ** 2
        if not left.any():
            break
        if not left.all():
            active, Ja, res = np.arange(m)[active][left], Ja[left], res[left]
        X[active] += np.einsum("qij,qj->qi", batched.inv(Ja), res)
    if tab.shape[1] != m:  # every point converged at the centre
        tab = np.repeat(tab, m, axis=1)
    return X, tab, J


def reference_coordinates(
    msh: dolfinx.mesh.Mesh, points: np.ndarray, cells: np.ndarray
) -> np.ndarray:
    """Pull physical points back to the reference cell of their (local) cells by Newton.

    Args:
        points: (m, gdim); cells: (m,) local cell indices.

    Returns:
        Reference coordinates (m, tdim).
    """
    return _pull_back(msh, np.asarray(points, dtype=float), np.asarray(cells))[0]


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
    check_p1_space(V)
    msh = V.mesh
    gdim = msh.geometry.dim
    x = check_points(points, gdim, "points")
    cells = np.asarray(cells, dtype=np.int64)
    imap = V.dofmap.index_map
    n = imap.size_local + imap.num_ghosts
    if x.shape[0] == 0:  # basix cannot tabulate at no points
        empty = sp.csr_matrix((0, n))
        return ShapeTable(points=x, values=empty, gradients=[empty.copy()] * (gdim * derivatives))
    _, tab, J = _pull_back(msh, x, cells)
    dofs = _compat.dofmap_array(V)[cells]  # (m, nv)
    m, nv = dofs.shape
    # one row per point holding its cell's nv distinct nodes: the CSR arrays directly, columns
    # sorted within each row (the canonical CSR that a COO conversion gave)
    order = np.argsort(dofs, axis=1, kind="stable")
    indptr = np.arange(0, m * nv + 1, nv)
    columns = np.take_along_axis(dofs, order, axis=1).ravel()

    def table(data: np.ndarray) -> sp.csr_matrix:
        data = np.take_along_axis(data, order, axis=1).ravel()
        return sp.csr_matrix((data, columns, indptr), shape=(m, n))

    values = table(tab[0])
    grads: list[sp.csr_matrix] = []
    if derivatives:
        # J^-T dphi/dX: dphi[q, v, g] = sum_d Jinv[q, d, g] dphi/dX_d[q, v]
        dphi = np.matmul(tab[1:].transpose(1, 2, 0), batched.inv(J))  # (m, nv, gdim)
        grads = [table(dphi[:, :, k]) for k in range(gdim)]
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
    check_p1_space(V)
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
    check_p1_space(V)
    msh = V.mesh
    x = raise_on_all_ranks(msh.comm, lambda: check_points(points, msh.geometry.dim, "points"))
    bs = V.dofmap.index_map_bs
    local = u.x.array.reshape(-1, bs)

    def compute(pts: np.ndarray, cells: np.ndarray) -> list:
        vals = tabulate_in_cells(V, pts, cells, derivatives=0).values @ local
        return list(vals)

    rows = route_to_owners(msh, x, compute)
    return np.array(rows, dtype=float).reshape(-1, bs)


def point_value_nodes(
    V: dolfinx.fem.FunctionSpace, gdim: int, mesh: dolfinx.mesh.Mesh | None = None
) -> np.ndarray:
    """The coordinates (local nodes, owned then ghost, ``gdim``) of the nodes of a vector space
    whose dofs are point values, for exporting a field as a Function on ``V``; a ``ValueError``
    naming the fix when ``V`` is not a vector space of ``gdim`` components on a ``gdim``-D mesh
    (on ``mesh``, if given) or its dofs are not point values (local)."""
    if mesh is not None and V.mesh is not mesh:
        raise ValueError("V must be a function space on the solution's mesh")
    bs, dim = V.dofmap.index_map_bs, V.mesh.geometry.dim
    if bs != gdim or dim != gdim:
        raise ValueError(
            f"V must be a vector space of {gdim} components (the displacement's) on a {gdim}D "
            f"mesh, like _compat.vector_function_space(mesh, degree); this space has block size "
            f"{bs} on a {dim}D mesh"
        )
    try:
        x = V.tabulate_dof_coordinates()
    except RuntimeError as e:
        raise ValueError(
            f"V's dofs must be point values (a Lagrange space, continuous or discontinuous): {e}"
        ) from e
    return np.ascontiguousarray(x[:, :gdim])
