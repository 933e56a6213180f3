"""The PETSc nest of every coupling against a monolithic matrix solved independently.

:class:`~dolfinx_meshfree.statics.petsc.BlockSystem` converts the MatNest to AIJ and factorises it
with
MUMPS. Here each block's owned rows are read back (``getValuesCSR``), gathered, stacked into one
monolithic scipy matrix in the nest's field order and solved with scipy's SuperLU on rank 0: the
two solutions must agree, and the monolithic residual of the nest's solution must vanish. This
checks the block layout (rows, columns, offsets of every field) independently of PETSc's nest
conversion.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.statics.petsc import BlockSystem

import dolfinx
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mpi4py import MPI


def _gather_block(comm, A, shape) -> sp.csr_matrix:
    """The whole matrix of a distributed PETSc block on every rank (small systems only)."""
    if A is None:
        return sp.csr_matrix(shape)
    lo, hi = A.getOwnershipRange()
    indptr, indices, data = A.getValuesCSR()
    rows = np.repeat(np.arange(lo, hi), np.diff(indptr))
    parts = comm.allgather((rows, np.asarray(indices), np.asarray(data)))
    r = np.concatenate([p[0] for p in parts])
    c = np.concatenate([p[1] for p in parts])
    v = np.concatenate([p[2] for p in parts])
    return sp.csr_matrix((v, (r, c)), shape=shape)


def monolithic_check(monkeypatch) -> dict:
    """Patch BlockSystem.solve: also solve the stacked monolithic system with scipy and record
    the relative difference of the solutions and the relative residual."""
    original = BlockSystem.solve
    seen: dict = {}

    def spy(self, solver="mumps", **kwargs):
        parts = original(self, solver, **kwargs)
        comm = self.comm.tompi4py()
        sizes = [v.getSize() for v in self.rhs]
        blocks = [
            [_gather_block(comm, B, (sizes[i], sizes[j])) for j, B in enumerate(row)]
            for i, row in enumerate(self.blocks)
        ]
        A = sp.bmat(blocks, format="csc")
        b = np.concatenate([np.concatenate(comm.allgather(v.getArray())) for v in self.rhs])
        x_nest = np.concatenate([np.concatenate(comm.allgather(p)) for p in parts])
        x_mono = spla.spsolve(A, b) if comm.rank == 0 else None
        x_mono = comm.bcast(x_mono, root=0)
        seen["difference"] = np.abs(x_nest - x_mono).max() / np.abs(x_mono).max()
        seen["residual"] = np.abs(A @ x_nest - b).max() / np.abs(b).max()
        seen["fields"] = len(sizes)
        return parts

    monkeypatch.setattr(BlockSystem, "solve", spy)
    return seen


@pytest.mark.parametrize("coupling", mf.COUPLINGS)
def test_nest_equals_monolithic(coupling, monkeypatch):
    """Patch test set-up (Dirichlet on the whole boundary, so that patch-side multipliers exist
    as well): every field of every coupling's nest."""
    seen = monolithic_check(monkeypatch)
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.full(2, 2.0)], [6, 6], dolfinx.mesh.CellType.quadrilateral
    )
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(mid[:, 0] > 2 / 3), 1 / 3)
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1000.0, 0.3), coupling=coupling)
    problem.add_dirichlet(mf.boundary_facets(msh), mf.LinearField().displacement)
    problem.solve()
    assert seen["fields"] >= 3
    assert seen["difference"] <= 1e-8
    assert seen["residual"] <= 1e-10
