"""The compiled block products of the explicit step (issue 26, item 4): the same products as an
independent (scipy) product of the gathered matrix, with ghost columns on 2 ranks; never stale
when the matrix changes (scaled, a new pattern, values set); explicit runs with it give PETSc's
runs to round-off, in 2D and 3D; bad input refused. Serial and 2 ranks."""

from __future__ import annotations

from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.dynamics.compiled_product import (
    PRODUCT_ENV,
    CompiledProduct,
    _whole_blocks,
    blockable,
    multiply,
    resolve_product,
)
from dolfinx_meshfree.parallel import Layout
from dolfinx_meshfree.statics.petsc import create_aij

import numpy as np
import pytest
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from test_block_formats import ROD, assert_same_states, final_state, rod
from test_dynamics_3d import bar_model, wave

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason="the compiled product needs numba")


def block_matrix(comm, bs: int, nodes_per_rank: int = 7, seed: int = 5):
    """A random sparse matrix of ``bs x bs`` blocks over ``nodes_per_rank`` nodes per rank
    (the same global matrix on every rank; columns owned by other ranks on 2 ranks), as a PETSc
    AIJ and as the global scipy matrix."""
    n = nodes_per_rank * comm.size
    rng = np.random.default_rng(seed + bs)
    nodes = sp.random(n, n, density=0.3, random_state=rng, format="coo") + sp.eye(n)
    dense = np.kron(nodes.toarray() != 0, np.ones((bs, bs))) * rng.uniform(-1, 1, (n * bs,) * 2)
    glob = sp.csr_matrix(dense)
    lay = Layout.from_local(comm, nodes_per_rank * bs)
    A = create_aij(comm, owned_rows(glob, lay), lay, lay, block_size=bs)
    return A, glob, lay


def owned_rows(glob: sp.csr_matrix, lay: Layout) -> sp.csr_matrix:
    """``glob`` with the rows other ranks own zeroed (this rank's contributions)."""
    mask = np.zeros(glob.shape[0])
    mask[lay.start : lay.end] = 1.0
    return sp.csr_matrix(sp.diags(mask) @ glob)


def _x(lay: Layout, A: PETSc.Mat) -> PETSc.Vec:
    x = A.createVecRight()
    x.array[:] = np.cos(0.7 * np.arange(lay.start, lay.end) + 0.3)
    return x


def _global_x(n: int) -> np.ndarray:
    return np.cos(0.7 * np.arange(n) + 0.3)


@pytest.mark.parametrize("bs", [2, 3])
def test_compiled_product_equals_an_independent_product(bs):
    """``y = A x`` and ``y += A x`` equal scipy's product of the global matrix (measured
    7e-17 to 3e-16 relative, serially and on 2 ranks; bound 1e-13), on 2 ranks with ghost
    columns from the other rank."""
    comm = MPI.COMM_WORLD
    A, glob, lay = block_matrix(comm, bs)
    assert blockable(A, bs)
    prod = CompiledProduct(A, bs)
    x = _x(lay, A)
    expected = (glob @ _global_x(glob.shape[1]))[lay.start : lay.end]
    y = A.createVecLeft()
    y.array[:] = 123.0  # overwritten
    prod.mult(x, y)
    scale = np.abs(expected).max()
    assert np.abs(y.array_r - expected).max() <= 1e-13 * scale
    y.array[:] = 1.0
    prod.mult_add(x, y)
    assert np.abs(y.array_r - (1.0 + expected)).max() <= 1e-13 * scale
    if comm.size > 1:  # the test exercises the ghost columns
        c0, c1 = A.getOwnershipRangeColumn()
        cols = A.getValuesCSR()[1]
        assert comm.allreduce(int(np.sum((cols < c0) | (cols >= c1)))) > 0
    prod.destroy()
    A.destroy()


def test_products_with_one_check_equal_the_products_one_by_one():
    """``multiply``: products of several blocks in order, compiled and PETSc's mixed, with one
    collective check, give ``mult``/``mult_add`` one by one to the bit; a matrix changed
    before the call is multiplied as it is now; a wrong vector on one rank only is refused
    on every rank before any product (serially and on 2 ranks)."""
    comm = MPI.COMM_WORLD
    A, glob, lay = block_matrix(comm, 2)
    B, globb, _ = block_matrix(comm, 2, seed=11)
    pa, pb = CompiledProduct(A, 2), CompiledProduct(B, 2)
    x = _x(lay, A)
    y1, y2 = A.createVecLeft(), A.createVecLeft()
    pa.mult(x, y1)  # one by one: A x, + B x, + A x by PETSc
    pb.mult_add(x, y1)
    A.multAdd(x, y1, y1)
    y2.array[:] = 99.0  # overwritten by the first product
    multiply([(pa, x, y2, False), (pb, x, y2, True), (A, x, y2, True)], comm)
    assert np.array_equal(y1.array_r, y2.array_r)
    expected = ((2.0 * glob + globb) @ _global_x(glob.shape[1]))[lay.start : lay.end]
    assert np.abs(y2.array_r - expected).max() <= 1e-13 * np.abs(expected).max()
    B.scale(3.0)  # stale copy of B: rebuilt before the products
    multiply([(pa, x, y2, False), (pb, x, y2, True)], comm)
    expected = ((glob + 3.0 * globb) @ _global_x(glob.shape[1]))[lay.start : lay.end]
    assert np.abs(y2.array_r - expected).max() <= 1e-13 * np.abs(expected).max()
    short = PETSc.Vec().createMPI((lay.size_local - (2 if lay.start == 0 else 0), None))
    y2.array[:] = 5.0
    with pytest.raises(ValueError, match=r"local sizes x .*create them with A\.createVecs"):
        multiply([(pa, x, y2, False), (pb, short, y2, True)], comm)
    assert np.all(y2.array_r == 5.0)  # refused before the first product
    for obj in (pa, pb, x, y1, y2, short, A, B):
        obj.destroy()


def test_a_changed_matrix_is_never_multiplied_stale():
    """After each change of ``A`` the product follows it: scaled, a new nonzero added through
    ``axpy`` with a different pattern, and values set then assembled; the copy block by block
    (whole blocks) and through scipy (a block with an entry missing) both checked."""
    comm = MPI.COMM_WORLD
    A, glob, lay = block_matrix(comm, 2)
    prod = CompiledProduct(A, 2)
    x, y = _x(lay, A), A.createVecLeft()
    xg = _global_x(glob.shape[1])

    def check(matrix):
        prod.mult(x, y)
        expected = (matrix @ xg)[lay.start : lay.end]
        assert np.abs(y.array_r - expected).max() <= 1e-13 * np.abs(expected).max()

    def whole() -> bool:  # which copy _build takes: block by block, or through scipy
        ai, aj, _ = A.getValuesCSR()
        c0, c1 = A.getOwnershipRangeColumn()
        return bool(comm.allreduce(bool(_whole_blocks(ai, aj, 2, c0, c1 - c0)[0]), op=MPI.LAND))

    check(glob)
    assert whole()  # the block-by-block copy
    A.scale(2.0)
    check(2.0 * glob)
    # a new entry in the last row, in the first column (another rank's on 2 ranks)
    n = glob.shape[0]
    extra = sp.csr_matrix(([5.0], ([n - 1], [0])), shape=glob.shape)
    E = create_aij(comm, owned_rows(extra, lay), lay, lay, block_size=2)
    A.axpy(1.0, E, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert not whole()  # a lone entry in a block: the copy through scipy
    check(2.0 * glob + extra)
    if lay.start <= 0 < lay.end:
        A.setValue(0, 0, 7.0, addv=PETSc.InsertMode.ADD_VALUES)
    A.assemble()
    bump = sp.csr_matrix(([7.0], ([0], [0])), shape=glob.shape)
    check(2.0 * glob + extra + bump)
    for obj in (prod, E, A):
        obj.destroy()


@pytest.mark.parametrize("method", ["efg", "lagrange", "ramp"])
def test_compiled_run_equals_petsc_run(method):
    """40 central-difference steps of the rod with the compiled products (the default with
    numba; ramp: off-diagonal blocks too) give the displacements and velocities of the run with
    PETSc's products (measured: the same to the last bit, serially and on 2 ranks, as the
    kernels sum in the order of PETSc's BAIJ product; bound 1e-12, round-off)."""
    comm = MPI.COMM_WORLD
    states = []
    for product in ("petsc", "numba"):
        dyn = rod(method, comm, product=product)
        assert dyn.system.product == product
        dyn.set_initial(velocity=ROD.initial_velocity)
        dt = dyn.stable_time_step()
        dyn.run(40 * dt, dt=dt)
        states.append(final_state(dyn))
        if product == "numba":  # every stiffness block multiplied by the compiled kernels
            system = dyn.system
            made = [system.compiled_product(k, k) for k in range(len(system.fields))]
            made += [system.compiled_product(k, j) for k, j in system.blocks]
            assert made and all(p is not None for p in made)
        dyn.destroy()
    assert_same_states(states, comm)


@pytest.mark.parametrize("method", ["efg", "lagrange"])
def test_compiled_run_equals_petsc_run_in_3d(method, monkeypatch):
    """The same in 3D (3 x 3 blocks; the bar of ``tests/test_dynamics_3d.py`` in 8 x 2 x 2
    hexahedra, ends held, particles on its right half for lagrange): 20 steps with the
    product chosen by ``DOLFINX_MESHFREE_PRODUCT`` (measured: the same to the last bit,
    serially and on 2 ranks; bound 1e-12)."""
    comm = MPI.COMM_WORLD
    states = []
    for product in ("petsc", "numba"):
        monkeypatch.setenv(PRODUCT_ENV, product)
        dyn = bar_model(method, "hexahedron", 2)
        assert dyn.system.product == product
        dyn.set_initial(displacement=lambda x: wave(x, 0.0))
        dt = dyn.stable_time_step()
        dyn.run(20 * dt, dt=dt)
        states.append(final_state(dyn))
        if product == "numba":
            system = dyn.system
            made = [system.compiled_product(k, k) for k in range(len(system.fields))]
            made += [system.compiled_product(k, j) for k, j in system.blocks]
            assert made and all(p is not None and p.bs == 3 for p in made)
        dyn.destroy()
    assert_same_states(states, comm)


def test_bad_product_and_block_size(monkeypatch):
    """An unknown product names the argument and its environment variable; a block size
    without a kernel is refused; the default follows the environment variable."""
    with pytest.raises(
        ValueError, match=r"product='cuda' \(argument or DOLFINX_MESHFREE_PRODUCT\)"
    ):
        resolve_product("cuda")
    monkeypatch.setenv("DOLFINX_MESHFREE_PRODUCT", "petsc")
    assert resolve_product(None) == "petsc"
    monkeypatch.delenv("DOLFINX_MESHFREE_PRODUCT")
    assert resolve_product(None) == "numba"
    A, _, lay = block_matrix(MPI.COMM_WORLD, 2)
    with pytest.raises(ValueError, match="bs=4 has no compiled kernel"):
        CompiledProduct(A, 4)
    assert not blockable(A, 1)
    # vectors the kernels would read or write out of bounds, on one rank only: refused on all
    prod = CompiledProduct(A, 2)
    x, y = _x(lay, A), A.createVecLeft()
    short = PETSc.Vec().createMPI((lay.size_local - (2 if lay.start == 0 else 0), None))
    with pytest.raises(ValueError, match=r"local sizes x .*create them with A\.createVecs"):
        prod.mult(short, y)
    with pytest.raises(ValueError, match="a different y"):
        prod.mult(x, x)
    prod.mult(x, y)  # still usable
    for obj in (prod, x, y, short, A):
        obj.destroy()


def test_stored_zero_blocks_are_left_out_with_the_same_products():
    """The blocks of exact zeros a matrix stores (DOLFINx's FE block of a coupled model holds
    the cells under the patch so) are not copied: as many dropped as the zeroed block rows
    hold in the global pattern (counted by scipy), and the product is PETSc's BAIJ product to
    the bit and the independent product to round-off (serially and on 2 ranks)."""
    comm = MPI.COMM_WORLD
    A0, glob, lay = block_matrix(comm, 2, nodes_per_rank=9)
    A = A0.convert("baij")
    A.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)
    nodes = glob.shape[0] // 2
    zeroed = np.arange(1, nodes, 3)  # every third node's block row
    rows = np.concatenate([2 * zeroed, 2 * zeroed + 1])
    mine = rows[(rows >= lay.start) & (rows < lay.end)].astype(PETSc.IntType)
    A.zeroRows(mine, diag=0.0)
    stored = A.getInfo(PETSc.Mat.InfoType.LOCAL)["nz_used"]
    assert stored == owned_rows(glob, lay).nnz  # the zeros are still stored
    prod = CompiledProduct(A, 2)
    x, y, y_petsc = _x(lay, A), A.createVecLeft(), A.createVecLeft()
    prod.mult(x, y)
    A.mult(x, y_petsc)
    assert np.array_equal(y.array_r, y_petsc.array_r)
    kept = sp.diags(np.isin(np.arange(glob.shape[0]), rows, invert=True).astype(float)) @ glob
    expected = (kept @ _global_x(glob.shape[1]))[lay.start : lay.end]
    assert np.abs(y.array_r - expected).max() <= 1e-13 * np.abs(expected).max()
    pattern = sp.csr_matrix(glob).tobsr(blocksize=(2, 2))
    blocks = int(np.diff(pattern.indptr)[zeroed].sum())
    assert blocks > 0
    assert comm.allreduce(prod.dropped_blocks) == blocks
    for obj in (prod, x, y, y_petsc, A, A0):
        obj.destroy()
