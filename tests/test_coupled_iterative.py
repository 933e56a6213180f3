"""``solver="iterative"``: the coupled saddle points solved without a factorisation.

The augmented Lagrangian (``BlockSystem``) by FGMRES with a block upper-triangular Schur
preconditioner (one GAMG V-cycle with the rigid-body modes on FE and particles, ``S`` a multiple
of the identity) must give MUMPS's solution to the solver tolerance (``ksp_rtol`` 1e-12 of the
unpreconditioned residual), keep the patch test exact to that tolerance, give the same answer on
one and on two ranks, fail loudly when it does not converge, and leave nothing in PETSc's options
database.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree.statics.petsc import BlockSystem, SolverOptions

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

MAT = mf.LinearElastic(3e7, 0.3)
BEAM = mf.TimoshenkoBeam(MAT)


def cantilever(comm, coupling: str, cell: str = "quadrilateral") -> mf.CoupledElasticity:
    """The Timoshenko cantilever (48 x 12, h = 2), the right half in particles at spacing h."""
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.array([0.0, -6.0]), np.array([48.0, 6.0])], [24, 6],
        getattr(dolfinx.mesh.CellType, cell),
    )  # fmt: skip
    n = msh.topology.index_map(2).size_local
    nodes = msh.geometry.x[mf._compat.geometry_dofmap(msh)[:n], :2]
    patch = mf.ParticlePatch(msh, np.flatnonzero(nodes[:, :, 0].mean(axis=1) > 24.0), 2.0)
    V = mf._compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, MAT, coupling=coupling)
    left = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0))
    problem.add_dirichlet(left, BEAM.displacement)
    problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48.0)), BEAM.traction)
    return problem


def difference(a: mf.CoupledSolution, b: mf.CoupledSolution) -> float:
    """Largest difference of the FE dofs and particle coefficients over the largest of ``b``'s
    (over all ranks)."""
    comm = b.patch.comm
    n = b.u.function_space.dofmap.index_map.size_local * b.u.function_space.dofmap.index_map_bs
    fe = comm.allreduce(float(np.abs(a.u.x.array[:n] - b.u.x.array[:n]).max(initial=0)), MPI.MAX)
    scale = comm.allreduce(float(np.abs(b.u.x.array[:n]).max(initial=0)), MPI.MAX)
    scale = max(scale, float(np.abs(b.coefficients).max()))
    return max(fe, float(np.abs(a.coefficients - b.coefficients).max())) / scale


@pytest.fixture
def iterations(monkeypatch):
    """The outer iterations of every BlockSystem solve of the test."""
    seen: list[int] = []
    original = BlockSystem.solve

    def spy(self, *args, **kwargs):
        out = original(self, *args, **kwargs)
        seen.append(self.stats.get("iterations"))
        return out

    monkeypatch.setattr(BlockSystem, "solve", spy)
    return seen


# measured (lane A, serial / 2 ranks): difference to MUMPS, iterations: lagrange 5e-14 / 5e-14,
# 58 / 59; edge-to-edge 4e-13 / 2e-14, 46 / 49; bridging 2e-13 / 3e-13, 227 / 161; lagrange on
# triangles 2e-13 / 3e-13, 62 / 62. Bounds: 1e-11 (the solver's rtol is 1e-12 of the residual)
# and about 2x the iterations
CASES = {
    ("lagrange", "quadrilateral"): 120,
    ("edge-to-edge", "quadrilateral"): 100,
    ("bridging", "quadrilateral"): 450,
    ("lagrange", "triangle"): 130,
    # no multipliers: FGMRES + GAMG on the whole system; 109 / 110 iterations
    ("ramp", "quadrilateral"): 220,
}


@pytest.mark.parametrize(("coupling", "cell"), list(CASES))
def test_iterative_equals_mumps(coupling, cell, iterations):
    problem = cantilever(MPI.COMM_WORLD, coupling, cell)
    direct = problem.solve("mumps")
    its = problem.solve("iterative")
    assert difference(its, direct) <= 1e-11
    assert 0 < iterations[-1] <= CASES[(coupling, cell)]


def test_iterative_patch_test_exact():
    """A linear field with a floating-free patch touching the boundary (four fields: FE,
    particles, interface and patch-boundary multipliers) is reproduced to the solver tolerance
    (MUMPS: round-off).

    At ``ksp_rtol`` 1e-14, measured: lane A 6.0e-14 serial, 1.1e-13 on 2 ranks; lane B 1.6e-12
    and 9.8e-14 (bound 5e-12). The check runs there because at the default 1e-12 the error is
    where FGMRES happens to stop, which round-off moves: lane A serial 1.0e-10 until
    ``cell_quadrature``'s Jacobians changed in the 16th digit (matmul for einsum), 3.2e-10 after
    (the bound was 3e-10); lane B 2.0e-11 and 8.3e-11. MUMPS gives 3e-16 to 4e-15."""
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.full(2, 2.0)], [6, 6], dolfinx.mesh.CellType.quadrilateral
    )
    n = msh.topology.index_map(2).size_local
    nodes = msh.geometry.x[mf._compat.geometry_dofmap(msh)[:n], :2]
    patch = mf.ParticlePatch(msh, np.flatnonzero(nodes[:, :, 0].mean(axis=1) > 1.0), 1 / 3)
    V = mf._compat.vector_function_space(msh)
    field = mf.LinearField(G=((0.1, 0.3), (-0.2, 0.05)))
    problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1000.0, 0.3))
    problem.add_dirichlet(mf.boundary_facets(msh), field.displacement)
    sol = problem.solve(SolverOptions("iterative", {"ksp_rtol": 1e-14}))
    x = np.array([[0.1, 0.2], [0.9, 1.7], [1.3, 0.4], [1.9, 1.95], [1.5, 1.5]])
    error = np.abs(sol.displacement(x) - field.displacement(x)).max()
    assert error <= 5e-12


def test_iterative_same_on_one_and_two_ranks():
    """The iterative solve on all ranks equals the one on each rank alone (to the solver
    tolerance: the iterates differ with the partition, not the solution)."""
    world = cantilever(MPI.COMM_WORLD, "lagrange").solve("iterative")
    alone = cantilever(MPI.COMM_SELF, "lagrange").solve("iterative")
    x = np.array([[1.0, 0.0], [20.0, 5.0], [30.0, -4.0], [47.0, 0.5], [24.0, 0.0]])
    a, b = world.displacement(x), alone.displacement(x)
    assert np.abs(a - b).max() <= 1e-11 * np.abs(b).max()  # measured 5e-14


def _our_options() -> list[str]:
    return [k for k in PETSc.Options().getAll() if k.startswith(("test_it_", "dolfinx_meshfree"))]


def test_iterative_leaves_no_options_and_fails_loudly():
    """The shorthand's options and the user's changes of them (``ksp_max_it``) are used (three
    iterations cannot converge: RuntimeError on every rank) and removed from the database."""
    problem = cantilever(MPI.COMM_WORLD, "lagrange")
    before = PETSc.Options().getAll()
    problem.solve("iterative")
    assert PETSc.Options().getAll() == before
    weak = SolverOptions("iterative", {"ksp_max_it": 3}, prefix="test_it_weak_")
    with pytest.raises(RuntimeError, match=r"iterative solve did not converge.*3 iterations"):
        problem.solve(weak)
    assert _our_options() == []
    assert PETSc.Options().getAll() == before


def test_iterative_options_refine_the_shorthand():
    """A tighter ``ksp_rtol`` given with the shorthand reaches its KSP: more iterations, a
    smaller difference to MUMPS."""
    problem = cantilever(MPI.COMM_WORLD, "lagrange")
    direct = problem.solve("mumps")
    loose = problem.solve(SolverOptions("iterative", {"ksp_rtol": 1e-6}))
    tight = problem.solve("iterative")
    # measured: 3.9e-8 / 1.2e-8 (serial / 2 ranks) with 1e-6, 5e-14 / 1.2e-13 with the default
    assert difference(tight, direct) <= 1e-11 < 1e-9 < difference(loose, direct) <= 1e-6


def test_coordinates_must_match_the_primal_fields():
    A = PETSc.Mat().createAIJ(((2, PETSc.DECIDE), (2, PETSc.DECIDE)), comm=MPI.COMM_SELF)
    A.setPreallocationNNZ(1)
    A.setDiagonal(A.createVecLeft())
    A.assemble()
    with pytest.raises(ValueError, match="coordinates must give the nodes of each of the 1"):
        BlockSystem([[A]], [A.createVecLeft()], coordinates=[np.zeros((1, 2))] * 2)


def test_pure_efg_iterative_uses_the_particle_positions(iterations, monkeypatch):
    """Pure EFG (the clamped end by multipliers) by ``solver="iterative"``: MUMPS's solution to
    1e-11 (measured 1.3e-13 serial) and, with the particle positions as GAMG's block size and
    rigid-body modes (``ParticleSet.owned_positions``), fewer iterations than without them
    (measured 61 against 78 serial, on quadrilaterals and triangles alike)."""
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.array([0.0, -6.0]), np.array([48.0, 6.0])], [24, 6],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    P = mf.ParticleSet.from_cells(msh, 2.0)
    original = np.argsort(P.petsc_index)  # the particles in PETSc order
    start = P.layout.start
    assert np.array_equal(
        P.owned_positions(), P.positions[original[start : start + P.layout.size_local]]
    )
    problem = mf.EFGElasticity(P, MAT)
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0)),
                          BEAM.displacement)  # fmt: skip
    problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48.0)), BEAM.traction)
    direct = problem.solve("mumps")
    its = problem.solve("iterative")
    scale = np.abs(direct.coefficients).max()
    assert np.abs(its.coefficients - direct.coefficients).max() <= 1e-11 * scale
    with_positions = iterations[-1]
    assert 0 < with_positions <= 120
    init = BlockSystem.__init__
    monkeypatch.setattr(
        BlockSystem, "__init__", lambda self, *a, **k: init(self, *a, **{**k, "coordinates": None})
    )
    problem.solve("iterative")
    assert with_positions < iterations[-1]
