"""The bodies of a mesh: its connected pieces (issue 27, item 2).

Contact between bodies works on two pieces of one mesh (``dynamics/body_contact.py``): a
projectile and its target, two bars meeting head-on. A body is a connected component of the
cells, two cells being connected when they share a vertex. Everything a body carries follows
from it; here, that the particles' approximation of one body does not reach into another
(:mod:`~dolfinx_meshfree.approx.body_cuts`).

The components are found on each rank's local cells (owned and ghost) by
``scipy.sparse.csgraph`` on the cell-vertex graph, then joined across ranks where a rank's
ghost vertex meets its owner's component: the pairs are gathered (O(partition interface)), and
every rank labels the joined graph alike. The bodies are numbered by the lexicographically
smallest midpoint of their cells, so the numbering does not depend on the partition.
"""

from __future__ import annotations

from dataclasses import dataclass

import dolfinx
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

__all__ = ["Bodies", "mesh_bodies"]


@dataclass(frozen=True)
class Bodies:
    """The connected pieces of a mesh.

    Attributes:
        cell_body: The body (``0 .. count - 1``) of every local cell, owned then ghost (int32);
            the same body on every rank that holds a cell.
        count: The number of bodies (every rank).
    """

    cell_body: np.ndarray
    count: int


def mesh_bodies(msh: dolfinx.mesh.Mesh) -> Bodies:
    """The bodies (connected components, cells joined by a shared vertex) of ``msh``, numbered
    by their cells' lexicographically smallest midpoint (collective)."""
    comm = msh.comm
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim, 0)
    c2v = msh.topology.connectivity(tdim, 0)
    cmap, vmap = msh.topology.index_map(tdim), msh.topology.index_map(0)
    n_cells = cmap.size_local + cmap.num_ghosts
    n_verts = vmap.size_local + vmap.num_ghosts
    offsets = np.asarray(c2v.offsets)[: n_cells + 1]
    verts = np.asarray(c2v.array)[: offsets[-1]].astype(np.int64)
    rows = np.repeat(np.arange(n_cells, dtype=np.int64), np.diff(offsets))
    graph = sp.csr_matrix(
        (np.ones(rows.size), (rows, n_cells + verts)), shape=(n_cells + n_verts,) * 2
    )
    _, local = connected_components(graph, directed=False)
    # the cells' components numbered 0 .. n_comp - 1 (a vertex of no local cell: -1)
    comps = np.unique(local[:n_cells])
    n_comp = comps.size
    at = np.minimum(np.searchsorted(comps, local), max(n_comp - 1, 0))
    found = comps[at] == local if n_comp else np.zeros(local.size, dtype=bool)
    start = comm.exscan(n_comp) or 0
    total = comm.allreduce(n_comp)
    label = np.where(found, at + start, -1)  # global component labels, cells then vertices
    # join the components that meet at a vertex: each ghost vertex's label against its owner's
    ghosts = np.asarray(vmap.ghosts, dtype=np.int64)
    mine = np.stack([ghosts, label[n_cells + vmap.size_local : n_cells + n_verts]], axis=1)
    everyone = np.concatenate(comm.allgather(mine.reshape(-1, 2)))
    lo, hi = vmap.local_range
    owned = everyone[(everyone[:, 0] >= lo) & (everyone[:, 0] < hi) & (everyone[:, 1] >= 0)]
    edges = np.stack([label[n_cells + owned[:, 0] - lo], owned[:, 1]], axis=1)
    edges = edges[edges[:, 0] >= 0]
    edges = np.concatenate(comm.allgather(edges.reshape(-1, 2)))
    joined = sp.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(total,) * 2)
    count, body_of = connected_components(joined, directed=False)
    # partition-independent numbering: the lexicographically smallest owned cell midpoint
    cell_label = label[:n_cells]
    owned_cells = np.arange(cmap.size_local, dtype=np.int32)
    mid = dolfinx.mesh.compute_midpoints(msh, tdim, owned_cells)
    keys = np.full((count, 3), np.inf)
    if owned_cells.size:
        order = np.lexsort(mid.T[::-1])  # by x, then y, then z
        b = body_of[cell_label[owned_cells[order]]]
        first = np.unique(b, return_index=True)[1]
        keys[b[first]] = mid[order[first]]
    every = np.stack(comm.allgather(keys))  # (ranks, count, 3)
    best = np.array([min(map(tuple, every[:, k])) for k in range(count)])
    rank_of = np.empty(count, dtype=np.int64)
    rank_of[np.lexsort(best.T[::-1])] = np.arange(count)
    return Bodies(rank_of[body_of[cell_label]].astype(np.int32), int(count))
