"""Work-balanced distribution of a mesh over MPI ranks (issue 12, item 3).

DOLFINx partitions a mesh so that every rank owns about as many *cells*; a particle patch cell
carries far more work than an FE cell (its quadrature points each see 10-50 particles, and the
particles are owned by the rank of the cell that contains them), so on a coupled model one rank
ends up with nearly all of the particle work: on the cantilever with half the beam in particles
one rank owned 99 % of the particles and two ranks ran no faster than one.

:func:`balanced_mesh` redistributes a user's mesh (the same cells and nodes) so that every rank
carries the same *work*, ``sum of cell_weight`` over its cells, by recursive coordinate bisection
(each cut across the longest extent of the cells' midpoints, at the weighted quantile that gives
each side its share of the parts): compact parts, the cut across the patch where the patch is
heavy. Ghost cells (the facet neighbours of every other rank's cells) are added as DOLFINx's own
partitioner adds them for the input mesh's ghost mode. Build the patch, the function spaces and
any ``MeshTags`` on the returned mesh (tags located geometrically carry over; cell indices do not).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import basix
import dolfinx
import numpy as np
from scipy.optimize import linear_sum_assignment

from .. import _compat
from ..parallel import raise_on_all_ranks

__all__ = [
    "IMBALANCE_WARN",
    "MAX_CLASSES",
    "PATCH_CELL_WORK",
    "CellWeight",
    "PartitionImbalanceWarning",
    "balanced_mesh",
    "class_bisection",
    "coordinate_bisection",
    "warn_imbalance",
    "work_per_rank",
]

#: Work of a patch cell relative to an FE cell in a coupled static solve (particles at about the
#: element size, quadrature and MLS tables, the particle block's 86 entries per row against 18):
#: the weight that balanced the busiest rank's flops in issue 12's benchmark
#: (``benchmarks/bench_balance.py --weight 7``).
PATCH_CELL_WORK = 7.0

#: The busiest rank's estimated work over the mean above which a coupled model warns.
IMBALANCE_WARN = 1.5

#: :func:`balanced_mesh` splits each class of cells of one weight on its own up to this many
#: distinct weights; beyond, it balances their sum (a weight that varies cell by cell).
MAX_CLASSES = 8


class PartitionImbalanceWarning(UserWarning):
    """A coupled model's particle work sits on a few ranks (the mesh partition ignores it)."""


#: ``cell_weight(x) -> w``: the work of the cells whose midpoints are the columns of ``x``
#: ((gdim, m), as DOLFINx's marker functions take them), ``w`` (m,) positive and finite.
CellWeight = Callable[[np.ndarray], np.ndarray]


def coordinate_bisection(points: np.ndarray, weights: np.ndarray, nparts: int) -> np.ndarray:
    """Part (0 .. nparts-1) of every point by weighted recursive coordinate bisection.

    A set of points going to ``k`` parts is cut across its longest extent, sorted along that
    axis, at the prefix whose weight is closest to ``floor(k/2)/k`` of the set's weight; the two
    sides recurse with ``floor(k/2)`` and ``k - floor(k/2)`` parts. Each part's weight differs
    from its share by at most the largest single weight per level of cuts. Deterministic (stable
    sort; ties broken by input order).
    """
    points = np.asarray(points, dtype=float)
    weights = np.asarray(weights, dtype=float)
    if points.ndim != 2 or weights.shape != (points.shape[0],):
        raise ValueError(
            f"points of shape {points.shape} and weights of shape {weights.shape}: pass "
            f"points (m, gdim) and one weight per point"
        )
    if nparts < 1:
        raise ValueError(f"nparts={nparts} must be at least 1")
    part = np.zeros(points.shape[0], dtype=np.int32)
    stack = [(np.arange(points.shape[0]), 0, nparts)]
    while stack:
        idx, first, k = stack.pop()
        if k == 1 or idx.size == 0:
            part[idx] = first
            continue
        left_parts = k // 2
        p = points[idx]
        axis = int(np.argmax(p.max(axis=0) - p.min(axis=0)))
        order = idx[np.argsort(p[:, axis], kind="stable")]
        cum = np.cumsum(weights[order])
        target = cum[-1] * left_parts / k
        # the cut after position j keeps order[:j + 1] on the left: closest prefix weight
        j = int(np.argmin(np.abs(cum - target)))
        stack.append((order[: j + 1], first, left_parts))
        stack.append((order[j + 1 :], first + left_parts, k - left_parts))
    return part


def _cross_facets(vertices: np.ndarray, cell_name: str) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of cells that share a facet, as two arrays ``(a, b)``."""
    facets = basix.topology(getattr(basix.CellType, cell_name))[-2]
    keys = np.concatenate([np.sort(vertices[:, f], axis=1) for f in facets])
    cell_of = np.tile(np.arange(vertices.shape[0]), len(facets))
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    order = np.argsort(inv.ravel(), kind="stable")
    inv_s, cell_s = inv.ravel()[order], cell_of[order]
    pair = np.flatnonzero(inv_s[1:] == inv_s[:-1])  # interior facets appear twice in a row
    return cell_s[pair], cell_s[pair + 1]


def class_bisection(
    points: np.ndarray,
    weights: np.ndarray,
    nparts: int,
    neighbours: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray | None:
    """Part of every point when each class of points of one weight is split evenly over the
    ``nparts`` parts on its own (a multi-constraint partition, Karypis & Kumar 1998, "Multilevel
    algorithms for multi-constraint graph partitioning", SC'98): every class by
    :func:`coordinate_bisection`, then its parts matched to those of the classes before it so
    that the most pairs of ``neighbours`` (points sharing a facet) across classes fall in one
    part (an assignment problem, scipy's ``linear_sum_assignment``). ``None`` with more than
    :data:`MAX_CLASSES` distinct weights. Deterministic."""
    values, cls = np.unique(np.asarray(weights, dtype=float), return_inverse=True)
    if values.size > MAX_CLASSES:
        return None
    part = np.full(cls.size, -1, dtype=np.int32)
    # the largest class first: the others are matched to it
    for c in np.argsort(-np.bincount(cls, minlength=values.size), kind="stable"):
        members = np.flatnonzero(cls == c)
        own = coordinate_bisection(points[members], np.ones(members.size), nparts)
        if neighbours is not None and np.any(part >= 0):
            a, b = neighbours
            tally = np.zeros((nparts, nparts))  # [this class's part, an earlier part]
            here = np.full(cls.size, -1)
            here[members] = own
            for x, y in ((a, b), (b, a)):
                sel = (here[x] >= 0) & (part[y] >= 0)
                np.add.at(tally, (here[x][sel], part[y][sel]), 1.0)
            rows, cols = linear_sum_assignment(tally, maximize=True)
            own = cols[np.argsort(rows)][own].astype(np.int32)
        part[members] = own
    return part


def _facet_neighbour_ranks(
    neighbours: tuple[np.ndarray, np.ndarray], owner: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: its owner, then the other ranks owning a cell that shares a facet with it (the
    ranks that ghost it in DOLFINx's ``shared_facet`` mode), as CSR (offsets, ranks), from the
    pairs of cells that share a facet (:func:`_cross_facets`)."""
    n = owner.size
    a, b = neighbours
    cross = owner[a] != owner[b]
    a, b = a[cross], b[cross]
    ghost_cell = np.concatenate([a, b])
    ghost_rank = np.concatenate([owner[b], owner[a]])
    # unique (cell, rank) pairs, grouped by cell
    key = np.unique(ghost_cell.astype(np.int64) * (owner.max() + 1) + ghost_rank)
    gc, gr = key // (owner.max() + 1), key % (owner.max() + 1)
    counts = 1 + np.bincount(gc, minlength=n)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    ranks = np.empty(offsets[-1], dtype=np.int32)
    ranks[offsets[:-1]] = owner
    slot = offsets[gc] + 1 + (np.arange(gc.size) - np.searchsorted(gc, gc))
    ranks[slot] = gr
    return offsets, ranks


def _gathered(msh: dolfinx.mesh.Mesh) -> tuple[np.ndarray, np.ndarray] | None:
    """Owned cells (global geometry nodes) and all node coordinates, gathered on rank 0."""
    comm, tdim, gdim = msh.comm, msh.topology.dim, msh.geometry.dim
    ncells = msh.topology.index_map(tdim).size_local
    imap = msh.geometry.index_map()
    cells = imap.local_to_global(_compat.geometry_dofmap(msh)[:ncells].ravel().astype(np.int32))
    cells = np.asarray(cells, dtype=np.int64).reshape(ncells, -1)
    nown = imap.size_local
    first = imap.local_range[0]
    x = np.asarray(msh.geometry.x[:nown, :gdim], dtype=float)
    parts = comm.gather((cells, first, x), root=0)
    if comm.rank != 0:
        return None
    X = np.empty((imap.size_global, gdim))
    for _, start, xr in parts:
        X[start : start + xr.shape[0]] = xr
    return np.concatenate([c for c, _, _ in parts]), X


def _weights(cell_weight: CellWeight, midpoints: np.ndarray) -> np.ndarray:
    w = np.asarray(cell_weight(midpoints.T), dtype=float)
    m = midpoints.shape[0]
    if w.shape != (m,):
        raise ValueError(
            f"cell_weight returned shape {w.shape} for {m} cells: it takes the midpoints as "
            f"x of shape (gdim, {m}) and must return one weight per cell, shape ({m},)"
        )
    bad = ~(np.isfinite(w) & (w > 0.0))
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"cell_weight returned {w[k]} at the cell with midpoint {midpoints[k].tolist()}: "
            f"every weight must be positive and finite (the work of the cell; 1 for an FE cell)"
        )
    return w


def work_per_rank(msh: dolfinx.mesh.Mesh, cell_weight: CellWeight) -> np.ndarray:
    """Sum of ``cell_weight`` over the owned cells of every rank (collective; on every rank)."""
    tdim = msh.topology.dim
    ncells = msh.topology.index_map(tdim).size_local
    nv = basix.geometry(getattr(basix.CellType, msh.topology.cell_type.name)).shape[0]
    nodes = _compat.geometry_dofmap(msh)[:ncells, :nv]
    mid = msh.geometry.x[nodes, : msh.geometry.dim].mean(axis=1)
    w = raise_on_all_ranks(msh.comm, lambda: _weights(cell_weight, mid))
    return np.asarray(msh.comm.allgather(float(w.sum())))


def balanced_mesh(
    msh: dolfinx.mesh.Mesh,
    cell_weight: CellWeight,
    ghosted: bool | None = None,
    by_class: bool = True,
) -> dolfinx.mesh.Mesh:
    """The same mesh, distributed so that every rank owns cells of equal total ``cell_weight``.

    Args:
        msh: The user's mesh (any cell type DOLFINx builds from cells and nodes; the coordinate
            element is kept).
        cell_weight: Work of a cell as a function of its midpoint (``x`` of shape (gdim, m),
            like DOLFINx's marker functions; returns (m,) positive weights). For a coupled
            model: 1 for FE cells and the patch cells' cost relative to an FE cell, e.g.
            ``lambda x: np.where(x[0] > 5.0, 20.0, 1.0)``; ``benchmarks/bench_balance.py``
            measures it.

        ghosted: Give the new mesh facet ghosts (DOLFINx's ``shared_facet`` mode, which a
            particle patch needs on several ranks) or none; ``None``: like ``msh``. E.g. a
            ``create_submesh`` has no ghosts in DOLFINx 0.11: ``balanced_mesh(sub, w,
            ghosted=True)`` gives it some.
        by_class: Split the cells of each weight evenly over the ranks on their own
            (:func:`class_bisection`; up to :data:`MAX_CLASSES` distinct weights, else as
            ``False``), so that every rank holds its share of the FE cells *and* of the patch
            cells. The work of a coupled model runs field by field (the FE product, then the
            particles', each ending in an exchange of ghost values), so each field must be
            balanced, not only their weighted sum: on the explicit rod of
            ``demos/rod_gauss.py`` (lagrange, 20k nodes and particles, 2 ranks) a step took
            3.1-3.2 ms at any patch weight from 10 to 30 with ``False`` (the FE product 2.8x
            heavier on one rank, the particles' 1.1x on the other), 2.9 ms by class, against
            5.5 ms on one rank.
            ``False``: one bisection of the summed weight (compact parts).

    Returns:
        A new mesh on ``msh.comm`` with the same cells and nodes (cell and node numbering
        differ), ghosted as asked. On one rank it is a renumbered copy.

    Collective. Everything is gathered on rank 0 to be cut (cells and coordinates: fine for
    meshes that fit one rank's memory, as every DOLFINx mesh generator assumes).
    """
    comm, tdim = msh.comm, msh.topology.dim
    cell_name = msh.topology.cell_type.name
    nv = basix.geometry(getattr(basix.CellType, cell_name)).shape[0]
    if ghosted is None:
        ghosted = comm.allreduce(len(msh.topology.index_map(tdim).ghosts) > 0)
    ghosted = bool(ghosted)
    gathered = _gathered(msh)

    def cut() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        if gathered is None:
            empty = np.zeros(0, dtype=np.int32)
            return np.zeros((0, 0), np.int64), np.zeros((0, msh.geometry.dim)), np.zeros(1), empty
        cells, X = gathered
        mid = X[cells[:, :nv]].mean(axis=1)
        w = _weights(cell_weight, mid)
        owner = None
        several = comm.size > 1 and (by_class or ghosted)  # the facet pairs are needed
        neighbours = _cross_facets(cells[:, :nv], cell_name) if several else None
        if by_class and comm.size > 1:
            owner = class_bisection(mid, w, comm.size, neighbours)
        if owner is None:
            owner = coordinate_bisection(mid, w, comm.size)
        if ghosted and comm.size > 1:
            offsets, ranks = _facet_neighbour_ranks(neighbours, owner)
        else:
            offsets, ranks = np.arange(owner.size + 1), owner
        return cells, X, offsets, ranks

    cells, X, offsets, ranks = raise_on_all_ranks(comm, cut)
    if comm.rank != 0:
        cells = np.zeros((0, _compat.geometry_dofmap(msh).shape[1]), dtype=np.int64)

    def destinations(nparts: int) -> tuple[np.ndarray, np.ndarray]:
        if nparts != comm.size:  # DOLFINx asks for one part per rank
            raise RuntimeError(f"asked for {nparts} parts on {comm.size} ranks")
        return offsets, ranks

    return _compat.create_mesh_partitioned(msh, cells, X, destinations, ghosted)


def warn_imbalance(
    msh: dolfinx.mesh.Mesh, in_patch: np.ndarray, weight: float = PATCH_CELL_WORK
) -> np.ndarray:
    """Warn (:class:`PartitionImbalanceWarning`, the same on every rank) when the estimated work
    of a coupled model, ``1`` per owned FE cell and ``weight`` per owned patch cell, is more than
    :data:`IMBALANCE_WARN` times the mean on the busiest rank: DOLFINx partitions the mesh by
    cells alone, so a patch that lies in one rank's part puts the particle work there (issue
    23, item 15: a user's mesh on 2 ranks solved in 3.7 s against 1.7 s serially). The message
    gives the one-line fix, :func:`balanced_mesh`. Returns the work per rank (collective)."""
    comm, tdim = msh.comm, msh.topology.dim
    n = msh.topology.index_map(tdim).size_local
    patch_cells = int(np.count_nonzero(in_patch[:n]))
    work = np.asarray(comm.allgather(float(n - patch_cells) + weight * patch_cells))
    if comm.size > 1 and work.max() > IMBALANCE_WARN * work.mean():
        shares = ", ".join(f"{100 * w / work.sum():.0f} %" for w in work)
        warnings.warn(
            f"the coupled model's work is unevenly spread over the {comm.size} ranks (estimated "
            f"shares {shares}, with a patch cell counted as {weight:g} FE cells): the mesh "
            "partition ignores the particles. Rebalance the mesh before building the patch: "
            "msh = mf.balanced_mesh(msh, lambda x: np.where(<x in the patch>, "
            f"{weight:g}, 1.0)), then locate the patch cells on the new mesh",
            PartitionImbalanceWarning,
            stacklevel=3,
        )
    return work
