"""MUMPS's analysis kept between systems of one sparsity pattern
(:class:`~dolfinx_meshfree.statics.kept_factor.KeptFactorisation`): the answers against dense
solves, the analyses counted by PETSc's own event log (not by the class), and a path followed
with the kept analysis equal to one analysed afresh at every iteration. Serial and 2 ranks."""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree.statics.kept_factor import KeptFactorisation
from dolfinx_meshfree.statics.petsc import solve_lu

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from test_block_formats import _distributed
from test_softening import _bar
from test_sweeps import POINTS, linear_problem

PETSc.Log.begin()  # the symbolic factorisations are counted by PETSc's events


def _analyses() -> int:
    """Symbolic factorisations (MUMPS's analyses) so far, LU and Cholesky, by PETSc's log."""
    return sum(
        PETSc.Log.Event(name).getPerfInfo()["count"]
        for name in ("MatLUFactorSym", "MatCholFctrSym")
    )


def _saddle(comm, seed: int, skew: float = 0.0, extra: bool = False, decoupled: int = 0):
    """A saddle point ``[[K, G^T + skew E], [G, 0]]`` (40 + 8 rows) with the sparsity pattern
    of every seed (K tridiagonal, G with 3 entries a row at fixed places), whose values change
    with ``seed``; ``extra``: one more nonzero pair (another pattern); ``decoupled``: that many
    rows of K made identity rows (solved apart by solve_lu). Its PETSc matrix and rhs over the
    ranks, and (every rank) the dense matrix and rhs."""
    rng = np.random.default_rng(seed)
    n, m = 40, 8
    K = np.diag(2.5 + rng.random(n)) + np.diag(-0.5 - rng.random(n - 1), 1)
    K = K + np.triu(K, 1).T
    G = np.zeros((m, n))
    for i in range(m):
        G[i, [5 * i, 5 * i + 2, 5 * i + 4]] = 1.0 + rng.random(3)
    E = np.where(G.T != 0.0, rng.standard_normal((n, m)), 0.0)
    if extra:
        K[0, n - 1] = K[n - 1, 0] = -0.25
    for i in range(decoupled):  # rows (and columns) 1, 6, 11, ...: no multiplier touches them
        k = 5 * i + 1
        assert not G[:, k].any()
        K[k, :] = K[:, k] = 0.0
        K[k, k] = 3.0
    dense = np.block([[K, G.T + skew * E], [G, np.zeros((m, m))]])
    b = rng.standard_normal(n + m)
    A, v = _distributed(comm, dense, b)
    return A, v, dense, b


def _solve(kept: KeptFactorisation, seed: int, **kw) -> tuple[dict, int, float]:
    """Solve one system with ``kept``: the stats, the analyses it made (PETSc's count) and its
    largest difference to the dense solve relative to the solution."""
    comm = MPI.COMM_WORLD
    A, b, dense, rhs = _saddle(comm, seed, **kw)
    exact = np.linalg.solve(dense, rhs)
    lo, hi = A.getOwnershipRange()
    stats: dict = {}
    before = _analyses()
    x = solve_lu(A, b, stats=stats, kept=kept)
    made = _analyses() - before
    error = comm.allreduce(float(np.abs(x.array_r - exact[lo:hi]).max()), op=MPI.MAX)
    for obj in (A, b, x):
        obj.destroy()
    return stats, made, error / np.abs(exact).max()


@pytest.mark.parametrize("skew, factorisation", [(0.0, "ldlt"), (1e-3, "lu")])
def test_kept_analysis_serves_the_next_values_of_its_pattern(skew, factorisation):
    """Three systems of one pattern and other values: one analysis (PETSc's count), three
    factorisations, each answer equal to the dense solve to 1e-12."""
    kept = KeptFactorisation()
    for seed, analysis in ((1, "new"), (2, "kept"), (3, "kept")):
        stats, made, error = _solve(kept, seed, skew=skew)
        assert (stats["analysis"], stats["factorisation"]) == (analysis, factorisation)
        assert made == (1 if analysis == "new" else 0)
        assert error < 1e-12
    assert (kept.analysed, kept.reused) == (1, 2)
    kept.destroy()


def test_another_pattern_or_factorisation_is_analysed_afresh():
    """A new nonzero, then the same pattern but unsymmetric values (LU instead of LDL^T): each
    analysed afresh (PETSc's count) and right; the kept one serves only its own kind."""
    kept = KeptFactorisation()
    cases = [
        (dict(), "new", "ldlt"),
        (dict(extra=True), "new", "ldlt"),
        (dict(extra=True), "kept", "ldlt"),
        (dict(extra=True, skew=1e-3), "new", "lu"),
        (dict(extra=True, skew=2e-3), "kept", "lu"),
    ]
    for seed, (kw, analysis, factorisation) in enumerate(cases):
        stats, made, error = _solve(kept, seed, **kw)
        assert (stats["analysis"], stats["factorisation"]) == (analysis, factorisation), seed
        assert made == (1 if analysis == "new" else 0)
        assert error < 1e-12
    kept.destroy()


def test_kept_analysis_of_the_rows_left_after_decoupled_ones():
    """With identity rows (solved apart, 3 of 48: above the 1 % share) the rest's analysis is
    kept: one analysis for two systems, both right."""
    kept = KeptFactorisation()
    for seed, analysis in ((4, "new"), (5, "kept")):
        stats, made, error = _solve(kept, seed, decoupled=3)
        assert stats["decoupled"] == 3
        assert stats["analysis"] == analysis
        assert made == (1 if analysis == "new" else 0)
        assert error < 1e-12
    kept.destroy()


def test_a_singular_system_on_a_kept_analysis_is_refused_and_nothing_kept():
    """A singular system of the kept pattern (a multiplier's row of G zeroed, its entries
    stored): the kept factorisation fails, the system is analysed afresh, fails again and is
    refused with MUMPS's diagnosis; nothing is kept after it, and the next system is right."""
    comm = MPI.COMM_WORLD
    kept = KeptFactorisation()
    stats, _, error = _solve(kept, 6)
    assert error < 1e-12
    A, b, _, _ = _saddle(comm, 7)
    lo, hi = A.getOwnershipRange()
    ai, aj, av = A.getValuesCSR()
    rows = np.repeat(np.arange(lo, hi), np.diff(ai))
    av = np.where((rows == 40) | (aj == 40), 0.0, av)  # the first multiplier's row and column
    A.zeroEntries()
    for r in range(lo, hi):
        cols = aj[ai[r - lo] : ai[r - lo + 1]]
        A.setValues([r], cols, av[ai[r - lo] : ai[r - lo + 1]])
    A.assemble()
    before = _analyses()
    with pytest.raises(RuntimeError, match="MUMPS INFOG"):
        solve_lu(A, b, kept=kept)
    assert _analyses() - before >= 1  # the fresh retry (and LU after LDL^T) analysed again
    for obj in (A, b):
        obj.destroy()
    stats, made, error = _solve(kept, 8)
    assert (stats["analysis"], made) == ("new", 1)
    assert error < 1e-12
    kept.destroy()


def test_path_with_kept_analyses_equals_fresh_ones(monkeypatch):
    """The notched softening bar (lagrange) followed through its peak with the problem's kept
    analysis and again with a fresh analysis at every factorisation (``take`` disabled): the
    same path to 1e-12 (measured: equal to the bit), and the kept run analyses at most a third
    as often (PETSc's count; measured: 1 analysis for 77 Newton iterations, against 96)."""

    def run() -> tuple[np.ndarray, int, mf.PathResult]:
        xc = 1.0 + 0.5 / 4  # mid-cell
        model = _bar(4, "lagrange", notch=xc)  # localises at the notch
        control = mf.DisplacementControl([[xc - 0.3, 0.5], [xc + 0.3, 0.5]], [[-1, 0], [1, 0]])
        options = mf.PathOptions(increment=2e-4, end=0.05, min_load=0.15, max_increment=4e-3)
        before = _analyses()
        res = mf.follow_path(model, control, options)
        return np.array([res.control, res.load_factor]), _analyses() - before, res

    kept_path, kept_analyses, res = run()
    factorisations = sum(res.iterations)
    monkeypatch.setattr(KeptFactorisation, "take", lambda self, A, key: self.clear())
    fresh_path, fresh_analyses, _ = run()
    assert fresh_path.shape == kept_path.shape
    assert np.abs(fresh_path - kept_path).max() <= 1e-12 * np.abs(fresh_path).max()
    assert fresh_analyses >= factorisations  # every factorisation analysed afresh
    assert 1 <= kept_analyses <= fresh_analyses / 3


def _numeric() -> int:
    """Numerical factorisations so far, LU and Cholesky, by PETSc's log."""
    return sum(
        PETSc.Log.Event(name).getPerfInfo()["count"]
        for name in ("MatLUFactorNum", "MatCholFctrNum")
    )


def test_the_kept_values_are_solved_by_the_kept_factors():
    """A system with the kept operator's values is not factorised again (PETSc's count of
    numerical factorisations: 0), one with other values of its pattern is (1, on the kept
    analysis); each answer equal to the dense solve to 1e-12."""
    kept = KeptFactorisation()
    cases = [
        (1, "new", "new", 1),
        (1, "kept", "kept", 0),
        (2, "kept", "new", 1),
        (2, "kept", "kept", 0),
    ]
    for seed, analysis, factors, numeric in cases:
        before = _numeric()
        stats, made, error = _solve(kept, seed)
        assert (stats["analysis"], stats["factors"]) == (analysis, factors), seed
        assert (made, _numeric() - before) == (1 if analysis == "new" else 0, numeric), seed
        assert error < 1e-12
    assert (kept.analysed, kept.reused, kept.repeated) == (1, 1, 2)
    kept.destroy()


@pytest.mark.parametrize("coupling", ["lagrange", "bridging", "ramp", "master-slave"])
def test_a_load_sweep_is_factorised_once(coupling):
    """A ``CoupledLinearProblem`` swept through three tractions and prescribed displacements
    with ``kept=``: one numerical factorisation for the three solves (PETSc's count), and each
    answer equal to a twin problem solved afresh at the same values: to the bit serially, to
    1e-13 on 2 ranks (not repeatable to the bit there: two runs of one bridging model, no kept
    factors, differed by 2.2e-16, relative)."""
    problem, _, t, g = linear_problem("end", coupling, g0=0.01)
    twin, _, t2, g2 = linear_problem("end", coupling, g0=0.01)
    kept = mf.KeptFactorisation()
    numeric = 0
    for tv, gv in (([0.0, -1.0], 0.01), ([0.5, -2.0], 0.01), ([0.0, -1.0], -0.02)):
        t.value, g.value, t2.value, g2.value = tv, gv, tv, gv
        before = _numeric()
        u = problem.solve(kept=kept).displacement(POINTS)
        numeric += _numeric() - before
        ref = twin.solve().displacement(POINTS)
        if MPI.COMM_WORLD.size == 1:
            assert np.array_equal(u, ref), (tv, gv)
        assert np.abs(u - ref).max() <= 1e-13 * np.abs(ref).max(), (tv, gv)
    assert numeric == 1
    assert (kept.analysed, kept.repeated) == (1, 2)
    kept.destroy()


def test_an_efg_load_sweep_is_factorised_once():
    """``EFGElasticity.solve(kept=)`` with a traction scaled between solves: one numerical
    factorisation, and twice the load gives twice the answer (linearity, to 1e-12)."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0.0, 0.0], [4.0, 1.0]], [8, 2], dolfinx.mesh.CellType.quadrilateral
    )
    scale = [1.0]
    problem = mf.EFGElasticity(
        mf.ParticleSet.from_cells(msh, spacing=0.25), mf.LinearElastic(E=1000.0, nu=0.3)
    )
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0)), lambda x: 0 * x)
    right = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 4.0))
    problem.add_traction(right, lambda x, n: scale[0] * np.tile([0.0, -1.0], (len(x), 1)))
    kept = mf.KeptFactorisation()
    before = _numeric()
    u1 = problem.solve(kept=kept).displacement(POINTS)
    scale[0] = 2.0
    u2 = problem.solve(kept=kept).displacement(POINTS)
    assert _numeric() - before == 1
    assert kept.repeated == 1
    assert np.abs(u2 - 2.0 * u1).max() <= 1e-12 * np.abs(u2).max()
    kept.destroy()


def test_kept_that_is_not_a_kept_factorisation_is_refused():
    """``kept=True`` (a flag, not the object) is refused by name before any solve, with the
    fix, on every rank."""
    problem, *_ = linear_problem("end", "lagrange")
    with pytest.raises(TypeError, match=r"kept=True must be an mf.KeptFactorisation or None"):
        problem.solve(kept=True)
    assert np.isfinite(problem.solve(kept=None).displacement(POINTS)).all()
