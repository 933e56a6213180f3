"""The ramps' stiffness blocks for explicit dynamics are assembled directly as BAIJ
(``statics.baij.create_baij``): the same entries as the AIJ assembly copied into blocks
(``dynamics.linalg.blocked(create_aij(...))``), products equal to the last bit; the FE block
keeps no block of exact zeros (DOLFINx's sparsity of the patch cells); ``LinearSystem`` keeps a
block already in its format and copies it for the other. Serial and 2 ranks."""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics.builders import build_coupled
from dolfinx_meshfree.dynamics.linalg import blocked
from dolfinx_meshfree.dynamics.system import LinearSystem
from dolfinx_meshfree.parallel import Layout
from dolfinx_meshfree.statics.baij import create_baij
from dolfinx_meshfree.statics.petsc import create_aij
from dolfinx_meshfree.verification.waves import GaussianPulseRod

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import CELL_TYPES, rectangle
from mpi4py import MPI
from petsc4py import PETSc

ROD = GaussianPulseRod()
STEEL = mf.LinearElastic(ROD.E, 0.0, "strain", rho=ROD.rho)


def _csr(A: PETSc.Mat) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Owned rows of ``A`` (any format) as scalar CSR with global columns."""
    ai, aj, av = A.getValuesCSR()
    return ai.copy(), aj.copy(), av.copy()


def _block_max(A: PETSc.Mat) -> np.ndarray:
    """The largest |entry| of each stored 2 x 2 block of ``A`` (owned rows)."""
    ai, aj, av = A.getValuesCSR()
    rows = np.repeat(np.arange(ai.size - 1), np.diff(ai))
    _, inverse = np.unique((rows // 2) * (A.getSize()[1] // 2 + 1) + aj // 2, return_inverse=True)
    out = np.zeros(inverse.max(initial=-1) + 1)
    np.maximum.at(out, inverse, np.abs(av))
    return out


def _contributions(comm, rows: Layout, cols: Layout, seed: int) -> sp.csr_matrix:
    """Random global triplets of this rank, in every rank's rows (so that some are sent), with
    duplicates, exact zeros and a 2 x 2 block that sums to exactly zero."""
    rng = np.random.default_rng(seed + 17 * comm.rank)
    m = 4000
    r = rng.integers(0, rows.size_global, m)
    c = rng.integers(0, cols.size_global, m)
    v = rng.standard_normal(m)
    v[::7] = 0.0  # stored zeros inside blocks
    # a block whose entries cancel: +1 and -1 on the same entry (rank 0 only)
    if comm.rank == 0:
        r = np.concatenate([r, [0, 0]])
        c = np.concatenate([c, [cols.size_global - 1, cols.size_global - 1]])
        v = np.concatenate([v, [1.0, -1.0]])
    return sp.csr_matrix((v, (r, c)), shape=(rows.size_global, cols.size_global))


@pytest.mark.parametrize("assembled", [False, True])
@pytest.mark.parametrize("shape", [(40, 40), (40, 24)])
def test_create_baij_equals_blocked_aij(shape, assembled):
    """``create_baij`` gives ``blocked(create_aij(...), 2)`` (with ``assembled``: of an
    assembled matrix plus ``create_aij(...)`` by ``axpy``, as the ramps' FE block was built):
    the same type, layout, stored entries (bit for bit: at most two contributions meet on 2
    ranks, summed in the same order) and products (bit for bit, the same blocks); a block of
    exact zeros is not stored."""
    comm = MPI.COMM_WORLD
    rows = Layout.from_local(comm, shape[0] // comm.size)  # even on 1 and 2 ranks
    cols = Layout.from_local(comm, shape[1] // comm.size)
    local = _contributions(comm, rows, cols, seed=3)
    A = create_aij(comm, local.copy(), rows, cols)
    owned = None
    if assembled:  # an assembled matrix: owned rows only
        full = _contributions(comm, rows, cols, seed=11).tolil()
        full[: rows.start] = 0.0
        full[rows.end :] = 0.0
        owned = full.tocsr()
        owned.eliminate_zeros()
        S = create_aij(comm, owned.copy(), rows, cols)
        S.axpy(1.0, A, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        A.destroy()
        A = S
    ref = blocked(A, 2, "baij")
    B = create_baij(comm, local, rows, cols, 2, owned)
    assert B.getType() == ref.getType() and B.getType().endswith("baij")
    assert B.getBlockSize() == 2
    assert B.getSizes() == ref.getSizes()
    assert B.getOwnershipRange() == ref.getOwnershipRange()
    for a, b in zip(_csr(ref), _csr(B), strict=True):
        assert np.array_equal(a, b)
    # every stored block holds a nonzero (the cancelled entry left no block of zeros), and
    # stored zeros inside blocks are there
    assert np.all(_block_max(B) > 0.0)
    zeros = comm.allreduce(int(np.sum(_csr(B)[2] == 0.0)), op=MPI.SUM)
    assert zeros > 0 or assembled  # (the assembled matrix fills the blocks: no zero left)
    x = B.createVecRight()
    x0, x1 = x.getOwnershipRange()
    x.array[:] = np.cos(np.arange(x0, x1) + 0.3)
    y, z = B.createVecLeft(), ref.createVecLeft()
    B.mult(x, y)
    ref.mult(x, z)
    assert np.array_equal(y.array_r, z.array_r)
    assert y.norm() > 0.0
    for obj in (A, ref, B, x, y, z):
        obj.destroy()


def test_create_baij_refuses_split_blocks():
    """Rows that cannot be cut into whole 2 x 2 blocks on every rank: a ValueError naming bs."""
    comm = MPI.COMM_WORLD
    lay = Layout.from_local(comm, 3)
    local = sp.csr_matrix((lay.size_global, lay.size_global))
    with pytest.raises(ValueError, match="block size bs=2 does not divide"):
        create_baij(comm, local, lay, lay, 2)


def _ramp_rod(comm, coupling: str = "ramp", h: float = 1.25):
    msh = rectangle(comm, [0.0, 0.0], [60.0, 5.0], [round(60 / h), round(5 / h)],
                    CELL_TYPES["quadrilateral"])  # fmt: skip
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 30.0), h / 2)
    V = _compat.vector_function_space(msh)
    return mf.CoupledElasticity(V, patch, STEEL, coupling=coupling, quadrature_degree=3)


@pytest.mark.parametrize("coupling", ["ramp", "ramp-cubic"])
def test_ramp_operators_are_baij_without_zero_blocks(coupling):
    """The ramps' four stiffness blocks are BAIJ (2 x 2); the FE block stores no block of exact
    zeros (DOLFINx's sparsity holds the patch cells' zeros: about half of its entries) and its
    rows of the nodes inside the patch are empty."""
    comm = MPI.COMM_WORLD
    ops = _ramp_rod(comm, coupling).operators()
    mats = [ops.K_fe, ops.K_p, ops.K_fp, ops.K_pf]
    for M in mats:
        assert M.getType().endswith("baij") and M.getBlockSize() == 2
    assert np.all(_block_max(ops.K_fe) > 0.0)
    ai = ops.K_fe.getValuesCSR()[0]
    # FE nodes only patch cells touch have no stiffness (and no stored block)
    active = np.repeat(ops.fe_active[: ops.fe_layout.size_local // 2], 2)
    assert np.all(np.diff(ai)[~active] == 0)
    n_inactive = comm.allreduce(int(np.sum(~active)), op=MPI.SUM)
    assert n_inactive > 0
    ops.destroy()


def test_ramp_baij_system_keeps_blocks():
    """``LinearSystem`` (BAIJ, the default) keeps the ramps' blocks: no copy."""
    model = build_coupled(_ramp_rod(MPI.COMM_WORLD))
    mats = [f.K for f in model.fields] + list(model.blocks.values())
    system = LinearSystem(model.fields, model.blocks, model.constraint)
    kept = [f.K for f in system.fields] + list(system.blocks.values())
    assert len(kept) == len(mats) == 4
    assert all(a is b for a, b in zip(kept, mats, strict=True))
    system.destroy()


def test_ramp_aij_system_copies_baij_blocks():
    """``LinearSystem(..., matrix_format="aij")`` stores the ramps' BAIJ blocks as AIJ with the
    same entries (the AIJ reference runs of test_block_formats)."""
    comm = MPI.COMM_WORLD
    model = build_coupled(_ramp_rod(comm))
    ref = [_csr(f.K) for f in model.fields]
    system = LinearSystem(model.fields, model.blocks, model.constraint, "aij")
    for f, (ai, aj, av) in zip(system.fields, ref, strict=True):
        assert not f.K.getType().endswith("baij")
        bi, bj, bv = f.K.getValuesCSR()
        assert np.array_equal(ai, bi) and np.array_equal(aj, bj) and np.array_equal(av, bv)
    for B in system.blocks.values():
        assert not B.getType().endswith("baij")
    system.destroy()
