"""A mesh of some of another mesh's cells: the pieces of a model with several bodies.

Bodies that touch only through contact
(:meth:`~dolfinx_meshfree.ExplicitDynamics.add_contact`) are separate pieces of one mesh: cells
that share no vertex. :func:`submesh` makes such a mesh from a larger one (e.g. a rectangle less
a column of cells between two bars), distributed and ghosted as ``create_rectangle`` makes its
meshes, which a :class:`~dolfinx_meshfree.ParticlePatch` needs on several ranks
(``dolfinx.mesh.create_submesh`` of DOLFINx 0.11 keeps no ghost cells).
"""

from __future__ import annotations

import dolfinx
import numpy as np
import numpy.typing as npt

from .. import _compat
from ..parallel import owned_indices, raise_on_all_ranks

__all__ = ["submesh"]


def submesh(msh: dolfinx.mesh.Mesh, cells: npt.ArrayLike) -> dolfinx.mesh.Mesh:
    """A new mesh of ``msh``'s owned ``cells`` (local indices on each rank), with their nodes
    at their coordinates, repartitioned with ghost cells across facets (collective).

    Raises:
        ValueError: ``cells`` not a 1D integer array of owned cells, or empty on every rank
            (on every rank).
    """
    tdim = msh.topology.dim
    n_own = msh.topology.index_map(tdim).size_local

    def check() -> np.ndarray:
        fix = "pass owned cells, e.g. np.flatnonzero(marker(midpoints)) over range(size_local)"
        c = owned_indices(cells, "cells", "cell", n_own, fix)
        return np.unique(c.astype(np.int32))

    kept = raise_on_all_ranks(msh.comm, check)
    if msh.comm.allreduce(kept.size) == 0:
        raise_on_all_ranks(msh.comm, _empty)
    imap = msh.geometry.index_map()
    local = _compat.geometry_dofmap(msh)[kept]
    l2g = np.asarray(
        imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)),
        dtype=np.int64,
    )
    nodes = l2g[local].reshape(len(kept), -1)
    x = msh.geometry.x[: imap.size_local, : msh.geometry.dim]
    return _compat.create_mesh_ghosted(msh, nodes, x)


def _empty() -> None:
    raise ValueError("cells is empty on every rank: a submesh needs at least one cell")
