"""Block-system solvers: the Schur-complement fieldsplit route agrees with MUMPS.

The saddle point of EFG with Lagrange-multiplier boundary conditions has a singular primal block
(the multipliers hold the rigid modes), so the fieldsplit works on the augmented Lagrangian; the
solution must not change, which the direct solve checks independently.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree.statics.petsc import BlockSystem, mumps_failure, solve_lu

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc


def cantilever(comm):
    mat = mf.LinearElastic(3e7, 0.3)
    beam = mf.TimoshenkoBeam(mat)
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.array([0, -6.0]), np.array([48.0, 6.0])], [24, 6],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    P = mf.ParticleSet.from_cells(msh, 2.0)
    problem = mf.EFGElasticity(P, mat)
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0)), beam.displacement)
    problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48)), beam.traction)
    return problem


@pytest.mark.parametrize("inner", ["lu", "gamg"])
def test_fieldsplit_equals_mumps(inner, monkeypatch):
    problem = cantilever(MPI.COMM_WORLD)
    direct = problem.solve("mumps").coefficients
    seen = {}
    original = BlockSystem.solve

    def spy(self, solver="mumps", **kwargs):
        out = original(self, solver, inner=inner)
        seen.update(self.iterations)
        return out

    monkeypatch.setattr(BlockSystem, "solve", spy)
    split = problem.solve("fieldsplit").coefficients
    assert np.abs(split - direct).max() <= 1e-9 * np.abs(direct).max()
    # exact primal solves give convergence in one outer iteration of the full factorisation
    if inner == "lu":
        assert seen["outer"] <= 2


def test_fieldsplit_patch_test_exact():
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.full(2, 2.0)], [6, 6], dolfinx.mesh.CellType.triangle
    )
    P = mf.ParticleSet.from_cells(msh, 1 / 3, jitter=0.3)
    problem = mf.EFGElasticity(P, mf.LinearElastic(1000.0, 0.3), consistent=True)
    problem.add_dirichlet(mf.boundary_facets(msh), mf.LinearField().displacement)
    sol = problem.solve("fieldsplit")
    x = P.positions
    assert np.abs(sol.displacement(x) - x).max() <= 1e-10


def test_unknown_solver_names():
    problem = cantilever(MPI.COMM_WORLD)
    with pytest.raises(ValueError, match="solver='cg' is not known"):
        problem.solve("cg")


@pytest.mark.parametrize("coupling", ["lagrange", "ramp"])
def test_fieldsplit_equals_mumps_for_couplings(coupling):
    """Four fields for Lagrange (FE, particles, interface and patch-boundary multipliers) with
    the patch floating on its multipliers; ramp has only the patch-boundary multipliers."""
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.full(2, 2.0)], [6, 6], dolfinx.mesh.CellType.quadrilateral
    )
    n = msh.topology.index_map(2).size_local
    nodes = msh.geometry.x[mf._compat.geometry_dofmap(msh)[:n], :2]
    patch = mf.ParticlePatch(msh, np.flatnonzero(nodes[:, :, 0].mean(axis=1) > 1.0), 1 / 3)
    V = mf._compat.vector_function_space(msh)
    field = mf.LinearField(G=((0.1, 0.3), (-0.2, 0.05)))

    def solve(solver):
        problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1000.0, 0.3), coupling=coupling)
        problem.add_dirichlet(mf.boundary_facets(msh), field.displacement)
        return problem.solve(solver)

    direct, split = solve("mumps"), solve("fieldsplit")
    scale = np.abs(direct.coefficients).max()
    assert np.abs(split.coefficients - direct.coefficients).max() <= 1e-9 * scale
    assert np.abs(split.u.x.array - direct.u.x.array).max() <= 1e-9 * scale


def test_repeated_lu_solves_release_their_factorisations():
    """solve_lu destroys every handle it takes (KSP, PC, factor matrix): 40 MUMPS solves of a
    3,000-dof system leave the resident memory where it was (it grew by 1.3 MB per solve when
    the PC and factor handles were left to petsc4py, gigabytes over the robustness matrix).
    Bound: 8 MB over the 40 solves (the leak would be about 40 MB)."""
    import gc

    from dolfinx_meshfree.statics.petsc import solve_lu

    import scipy.sparse as sp
    from petsc4py import PETSc

    def rss_mb() -> float:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096 / 2**20

    n = 3000
    M = sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(n, n)).tocsr()
    A = PETSc.Mat().createAIJ(size=(n, n), csr=(M.indptr, M.indices, M.data), comm=PETSc.COMM_SELF)
    A.assemble()
    b = A.createVecLeft()
    b.set(1.0)
    solve_lu(A, b).destroy()  # MUMPS's first-call allocations
    gc.collect()
    before = rss_mb()
    for _ in range(40):
        solve_lu(A, b).destroy()
    gc.collect()
    assert rss_mb() - before < 8.0
    A.destroy()
    b.destroy()


# -- PETSc options, as DOLFINx's LinearProblem takes them ----------------------------------------


def _lagrange_problem(comm):
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.full(2, 2.0)], [6, 6], dolfinx.mesh.CellType.quadrilateral
    )
    n = msh.topology.index_map(2).size_local
    nodes = msh.geometry.x[mf._compat.geometry_dofmap(msh)[:n], :2]
    patch = mf.ParticlePatch(msh, np.flatnonzero(nodes[:, :, 0].mean(axis=1) > 1.0), 1 / 3)
    V = mf._compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1000.0, 0.3))
    field = mf.LinearField(G=((0.1, 0.3), (-0.2, 0.05)))
    problem.add_dirichlet(mf.boundary_facets(msh), field.displacement)
    return problem


def _our_options() -> list[str]:
    from petsc4py import PETSc

    return [k for k in PETSc.Options().getAll() if k.startswith("test_opts_")]


def test_petsc_options_reach_the_solver_and_leave_no_trace():
    """A KSP from options (GMRES preconditioned by MUMPS LU) gives the shorthand's solution;
    options that cannot solve the saddle point (no preconditioner, 3 iterations) must fail,
    which shows they were used; neither leaves an option in PETSc's database."""
    problem = _lagrange_problem(MPI.COMM_WORLD)
    direct = problem.solve("mumps")
    lu = {
        "ksp_type": "gmres",
        "ksp_rtol": 1e-13,
        "pc_type": "lu",
        "pc_factor_mat_solver_type": "mumps",
        "mat_mumps_icntl_14": 100,
        "mat_mumps_cntl_1": 0.1,
    }
    sol = problem.solve(petsc_options=lu, prefix="test_opts_lu_")
    scale = np.abs(direct.coefficients).max()
    assert np.abs(sol.coefficients - direct.coefficients).max() <= 1e-9 * scale
    assert np.abs(sol.u.x.array - direct.u.x.array).max() <= 1e-9 * scale
    assert _our_options() == []
    weak = {"ksp_type": "gmres", "pc_type": "none", "ksp_max_it": 3, "ksp_rtol": 1e-12}
    with pytest.raises(RuntimeError, match="did not converge"):
        problem.solve(petsc_options=weak, prefix="test_opts_weak_")
    assert _our_options() == []


def test_options_that_cannot_solve_the_saddle_point_say_why():
    """DOLFINx's habits on a coupled system (VCI: unsymmetric, with multipliers). Before,
    ``preonly`` + ``cholesky`` (MUMPS) returned a solution 2.9e-3 off and ``preonly`` +
    ``jacobi`` one 100 % off, both as converged; SuperLU_DIST aborted the process; PETSc's own
    LU and ILU stopped at a zero pivot with "error code 73". Now each is named (the backward
    error of a ``preonly`` solve above 1e-8: measured 1.6e-5 and 0.086 for the two), and
    ``preonly`` + MUMPS LU, DOLFINx's direct solve, gives the shorthand's solution (its backward
    error is round-off, 7e-14). No option is left in PETSc's database."""
    problem = _lagrange_problem(MPI.COMM_WORLD)
    direct = problem.solve("mumps")
    lu = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
    sol = problem.solve(petsc_options=lu, prefix="test_opts_pre_")
    scale = np.abs(direct.coefficients).max()
    assert np.abs(sol.coefficients - direct.coefficients).max() <= 1e-9 * scale
    refused = [
        ({"ksp_type": "preonly", "pc_type": "lu"}, ValueError, "factor package 'petsc' cannot"),
        (
            {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "superlu_dist"},
            ValueError,
            "SuperLU_DIST aborts",
        ),
        (
            {"ksp_type": "preonly", "pc_type": "cholesky", "pc_factor_mat_solver_type": "mumps"},
            RuntimeError,
            r"backward error .* factors a symmetric matrix, and this one is not",
        ),
        (
            {"ksp_type": "preonly", "pc_type": "jacobi"},
            RuntimeError,
            r"backward error .* applies pc_type='jacobi' once",
        ),
        (
            {"ksp_type": "gmres", "pc_type": "ilu"},
            RuntimeError,
            r"(?s)PETSc failed .* saddle point",
        ),
    ]
    for options, error, message in refused:
        with pytest.raises(error, match=message):
            problem.solve(petsc_options=options, prefix="test_opts_bad_")
    assert _our_options() == []


def test_fieldsplit_options_name_the_nest_fields():
    """The nest's fields reach a PETSc fieldsplit by name: on a block-diagonal SPD system an
    additive split with an exact LU per named field is the inverse, one GMRES iteration."""
    from petsc4py import PETSc

    comm = MPI.COMM_WORLD
    n = 10
    blocks = []
    for shift in (2.5, 4.0):
        A = PETSc.Mat().createAIJ(size=((None, n), (None, n)), comm=comm)
        A.setUp()
        r0, r1 = A.getOwnershipRange()
        for i in range(r0, r1):
            A.setValue(i, i, shift)
            if i + 1 < n:
                A.setValue(i, i + 1, -1.0)
            if i > 0:
                A.setValue(i, i - 1, -1.0)
        A.assemble()
        blocks.append(A)
    rhs = [blocks[0].createVecLeft(), blocks[1].createVecLeft()]
    rhs[0].set(1.0)
    rhs[1].set(2.0)
    system = BlockSystem([[blocks[0], None], [None, blocks[1]]], rhs, names=["soft", "stiff"])
    options = {
        "ksp_type": "gmres",
        "ksp_rtol": 1e-12,
        "pc_type": "fieldsplit",
        "pc_fieldsplit_type": "additive",
        "fieldsplit_soft_ksp_type": "preonly",
        "fieldsplit_soft_pc_type": "lu",
        "fieldsplit_stiff_ksp_type": "preonly",
        "fieldsplit_stiff_pc_type": "lu",
    }
    parts = system.solve(
        mf.statics.petsc.SolverOptions(petsc_options=options, prefix="test_opts_fs_")
    )
    assert system.iterations["ksp"] == 1
    for k, A in enumerate(blocks):  # each part solves its own block
        x = A.createVecRight()
        x.setArray(parts[k])
        r = A.createVecLeft()
        A.mult(x, r)
        r.axpy(-1.0, rhs[k])
        assert r.norm() <= 1e-10 * rhs[k].norm()
    assert _our_options() == []
    system.destroy()


def test_bad_solver_arguments_are_named():
    problem = _lagrange_problem(MPI.COMM_WORLD)
    with pytest.raises(ValueError, match="petsc_options must be a dict"):
        problem.solve(petsc_options=["ksp_type", "cg"])
    with pytest.raises(ValueError, match="prefix=' ' must be"):
        problem.solve(petsc_options={}, prefix=" ")


def test_a_singular_system_is_named_by_mumps_code():
    """A numerically singular matrix (a zero pivot stored explicitly): MUMPS's INFOG(1) = -10,
    reported as numerically singular with the usual fix; the workspace codes are not called a
    singular system (they were, before: every failure had the same message)."""
    A = PETSc.Mat().createAIJ([2, 2], nnz=2, comm=PETSc.COMM_SELF)
    A.setValues([0, 1], [0, 1], [[1.0, 0.0], [0.0, 0.0]])
    A.assemble()
    b = A.createVecLeft()
    b.set(1.0)
    with pytest.raises(RuntimeError, match=r"INFOG\(1\)=-10\): the system is numerically singular"):
        solve_lu(A, b)
    assert "workspace was too small" in mumps_failure(-9)
    assert "singular" in mumps_failure(None)
    A.destroy()
    b.destroy()


@pytest.mark.parametrize("solver", ["mumps", "mumps-lu", "fieldsplit"])
def test_solve_many_equals_separate_solves(solver):
    """``BlockSystem.solve_many`` (one factorisation, several right-hand sides: path following's
    two per Newton iteration) gives each right-hand side's solution of its own solve, on a saddle
    point with multipliers (EFG with Dirichlet facets)."""
    problem = cantilever(MPI.COMM_WORLD)
    system, objects, _ = problem.system()
    other = [v.copy() for v in system.rhs]
    for k, v in enumerate(other):
        v.array[:] = np.sin(np.arange(v.getLocalSize()) + 3.0 * k + 1.0)
    first, second = system.solve_many([other], solver)
    alone = system.solve(solver)
    twin = BlockSystem(system.blocks, other, system.num_primal, system.names)
    alone_other = twin.solve(solver)
    for a, b in ((first, alone), (second, alone_other)):
        scale = max(np.abs(np.concatenate(b)).max(), 1e-300)
        diff = np.abs(np.concatenate(a) - np.concatenate(b)).max() / scale
        # direct: the same factorisation's triangular solves; fieldsplit: solved one by one
        # (measured 0 for all three)
        assert diff <= 1e-12
    for obj in (twin, system, *objects, *other):
        obj.destroy()
