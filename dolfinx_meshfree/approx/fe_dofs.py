"""FE dofs of a vector P1/Q1 space: their PETSc layout, and node and cell flags on every rank.

Small helpers on a DOLFINx space that the coupled and the finite-strain systems share.
"""

from __future__ import annotations

import dolfinx
import numpy as np

from .. import _compat
from ..parallel import Layout

__all__ = ["cell_indicator", "fe_dof_layout", "node_flags"]


def fe_dof_layout(V: dolfinx.fem.FunctionSpace) -> tuple[Layout, np.ndarray]:
    """PETSc layout of the interleaved dofs of a vector P1/Q1 space (DOLFINx's numbering, block
    size ``gdim``), and the global node number of every local node."""
    imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    l2g = np.asarray(
        imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    )
    return Layout(bs * imap.size_local, bs * imap.size_global, bs * imap.local_range[0]), l2g


def node_flags(V: dolfinx.fem.FunctionSpace, local_nodes: np.ndarray) -> np.ndarray:
    """Flag nodes (local block indices) of ``V`` on every rank that has them, owned or ghost
    (collective)."""
    bs = V.dofmap.index_map_bs
    f = dolfinx.fem.Function(V)
    f.x.array[:] = 0.0
    f.x.array[bs * np.asarray(local_nodes, dtype=np.int64)] = 1.0
    _compat.scatter_reverse_add(f)
    f.x.scatter_forward()
    return f.x.array[0::bs] > 0.5


def cell_indicator(msh: dolfinx.mesh.Mesh, owned_flags: np.ndarray) -> dolfinx.fem.Function:
    """DG0 Function equal to 1 on the owned cells flagged in ``owned_flags`` (and on their ghost
    copies), 0 elsewhere (collective)."""
    Q = _compat.scalar_function_space(msh, "DG", 0)
    chi = dolfinx.fem.Function(Q)
    dof_of_cell = _compat.dofmap_array(Q)[:, 0]
    n_owned = msh.topology.index_map(msh.topology.dim).size_local
    chi.x.array[:] = 0.0
    chi.x.array[dof_of_cell[:n_owned]] = np.asarray(owned_flags[:n_owned], dtype=float)
    chi.x.scatter_forward()
    return chi
