"""Every static coupling in explicit dynamics: the operators of CoupledElasticity.operators(),
masses, energy, constraints, convergence to the exact rod solution, fixed facets, parallel =
serial; and the step-loaded rod (exact solution, demo)."""

from __future__ import annotations

import json
import pathlib
import tempfile

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import ExplicitDynamics
from dolfinx_meshfree.verification.waves import GaussianPulseRod, StepLoadedRod

import numpy as np
import pytest
from conftest import CELL_TYPES, fitted_rate, load_demo, rectangle
from mpi4py import MPI
from petsc4py import PETSc

DEMOS = pathlib.Path(__file__).resolve().parents[1] / "demos"
ROD = GaussianPulseRod()
STEEL = mf.LinearElastic(ROD.E, 0.0, "strain", rho=ROD.rho)
COUPLINGS = list(mf.COUPLINGS)
MULTIPLIERS = ["lagrange", "edge-to-edge", "bridging"]


def problem_on(comm, coupling, h, k=1, length=60.0, height=5.0, split=30.0, material=STEEL):
    """The rod with FE on x < split and particles (spacing h / k) on x > split."""
    msh = rectangle(
        comm,
        [0.0, 0.0],
        [length, height],
        [round(length / h), round(height / h)],
        CELL_TYPES["quadrilateral"],
    )
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > split), h / k)
    V = _compat.vector_function_space(msh)
    dilation = max(2.5, k + 1.5) if coupling.startswith("ramp") else None
    return mf.CoupledElasticity(
        V, patch, material, coupling=coupling, quadrature_degree=3, dilation=dilation, overlap=1
    )


def build(coupling, comm, h, k=1, **options):
    return ExplicitDynamics.coupled(problem_on(comm, coupling, h, k), **options)


def wavy(x):
    return np.stack([np.sin(0.3 * x[:, 0]) * np.cos(0.7 * x[:, 1]), np.cos(0.2 * x[:, 0])], 1)


# --- the operators -------------------------------------------------------------------------------


def _vec(A: PETSc.Mat, values: np.ndarray, right: bool = True) -> PETSc.Vec:
    x = A.createVecRight() if right else A.createVecLeft()
    x.array[:] = values
    return x


@pytest.mark.parametrize("coupling", COUPLINGS)
def test_operators_annihilate_rigid_and_tie_linear_fields(coupling):
    """K of a rigid translation is zero (every block); the constraints G_FE u_FE + G_P u_P of a
    linear field vanish (MLS reproduces linear fields with the particle values as coefficients);
    master-slave: T reproduces rigid motions."""
    problem = problem_on(MPI.COMM_WORLD, coupling, 2.0, 2, length=16.0, height=4.0, split=8.0)
    ops = problem.operators()
    V, P = problem.V, problem.patch.particles
    n_owned = V.dofmap.index_map.size_local
    x_fe = V.tabulate_dof_coordinates()[:n_owned, :2]
    own = P.owned[np.argsort(P.petsc_index[P.owned], kind="stable")]
    x_p = P.positions[own]
    act = np.repeat(ops.fe_active[:n_owned], 2)

    def lin(x):
        return np.stack([0.3 + 0.01 * x[:, 0] - 0.02 * x[:, 1], -0.1 + 0.03 * x[:, 0]], 1).ravel()

    tr_fe, tr_p = np.tile([1.0, -2.0], n_owned) * act, np.tile([1.0, -2.0], len(own))
    u_fe, u_p = _vec(ops.K_fe, tr_fe), _vec(ops.K_p, tr_p)
    r_fe, r_p = ops.K_fe.createVecLeft(), ops.K_p.createVecLeft()
    ops.K_fe.mult(u_fe, r_fe)
    ops.K_p.mult(u_p, r_p)
    if ops.K_fp is not None:
        ops.K_fp.multAdd(u_p, r_fe, r_fe)
        ops.K_pf.multAdd(u_fe, r_p, r_p)
    scale = STEEL.E * 10.0
    assert r_fe.norm(PETSc.NormType.INFINITY) < 1e-9 * scale
    assert r_p.norm(PETSc.NormType.INFINITY) < 1e-9 * scale
    if ops.G_fe is not None:
        g = ops.G_fe.createVecLeft()
        ops.G_fe.mult(_vec(ops.G_fe, lin(x_fe)), g)
        ops.G_p.multAdd(_vec(ops.G_p, lin(x_p)), g, g)
        assert g.norm(PETSc.NormType.INFINITY) < 1e-12
        assert ops.G_fe.norm(PETSc.NormType.INFINITY) > 0.1  # unit scaling, not E
        g.destroy()
    if ops.reduction is not None:
        Tpf, S = ops.reduction
        omega = 1e-3  # small rotation about the origin: u = omega (-y, x)
        rot = lambda x: (omega * np.stack([-x[:, 1], x[:, 0]], 1)).ravel()  # noqa: E731
        full = Tpf.createVecLeft()
        Tpf.mult(_vec(Tpf, rot(x_fe) * act), full)
        is_slave = np.zeros(P.num_particles, dtype=bool)
        is_slave[ops.interface.slaves] = True
        masters = _vec(S, rot(P.positions[own[~is_slave[own]]]))
        S.multAdd(masters, full, full)
        assert np.abs(full.array_r - rot(x_p)).max(initial=0.0) < 1e-13
    ops.destroy()


# --- masses, energy, constraints -----------------------------------------------------------------


@pytest.mark.parametrize("coupling", COUPLINGS)
def test_total_mass_is_exact(coupling):
    """Row sums with a partition of unity (blended, weighted beta_FE + beta_P = 1, or reduced
    with T 1 = 1) keep the total mass rho |Omega| per component."""
    dyn = build(coupling, MPI.COMM_WORLD, 1.0, 2)
    total = sum(f.mass.sum() for f in dyn.fields)
    assert total == pytest.approx(2 * STEEL.rho * 300.0, rel=1e-12)
    assert all(f.mass.min()[1] >= 0.0 for f in dyn.fields)
    dyn.destroy()


@pytest.mark.parametrize("coupling", COUPLINGS)
def test_energy_is_conserved_without_load(coupling):
    dyn = build(coupling, MPI.COMM_WORLD, 1.0, 2)
    dyn.set_initial(velocity=lambda x: 100.0 * wavy(x), displacement=lambda x: 1e-3 * wavy(x))
    res = dyn.run(2.0 * ROD.transit_time, energy_records=50)
    assert res.energy_drift < 1e-11
    assert res.energy_oscillation < 0.05
    assert all(r.external == 0.0 for r in res.energies)
    if coupling in MULTIPLIERS:
        assert res.max_residual < 1e-13
        assert abs(res.energies[-1].constraint) < 1e-12 * res.energies[0].total
    dyn.destroy()


@pytest.mark.parametrize("coupling", MULTIPLIERS)
@pytest.mark.parametrize("solver", ["dense", "mumps"])
def test_constraint_at_round_off(coupling, solver):
    dyn = build(coupling, MPI.COMM_WORLD, 1.0, 2, multiplier_solver=solver)
    dyn.set_initial(velocity=ROD.initial_velocity)
    assert dyn.constraint_residual() < 1e-14
    res = dyn.run(ROD.transit_time)
    assert res.max_residual < 1e-13 and dyn.constraint_residual() < 1e-13
    dyn.destroy()


def test_bridging_weights_masses_and_penalty_is_a_stiffness():
    """Bridging: the band's FE masses are weighted by 1 - alpha (less than the unweighted ones),
    and the augmented-Lagrangian penalty (on the pointwise gaps at the band particles, eq. 72-75,
    stiffer than the multipliers' projected constraint) enters as stiffness blocks: the energy
    is conserved, the critical step shrinks, the error stays small."""
    base = build("bridging", MPI.COMM_WORLD, 1.0, 2)
    problem = problem_on(MPI.COMM_WORLD, "bridging", 1.0, 2)
    problem.penalty = 1e3 * STEEL.E
    pen = ExplicitDynamics.coupled(problem)
    assert set(pen.blocks) == {(0, 1), (1, 0)} and not base.blocks
    lag = build("lagrange", MPI.COMM_WORLD, 1.0, 2)
    # FE masses: the band (x in [30, 31]) adds mass (1 - alpha) rho on the FE side
    assert base.fields[0].mass.sum() > lag.fields[0].mass.sum()
    assert base.fields[1].mass.sum() < lag.fields[1].mass.sum()
    errs = []
    for dyn in (base, pen):
        dyn.set_initial(velocity=ROD.initial_velocity)
        res = dyn.run(0.5 * ROD.transit_time)
        assert res.energy_drift < 1e-11
        errs.append(dyn.velocity_error(ROD.velocity))
    assert max(errs) < 0.01 and errs[1] != errs[0]
    assert pen.critical_time_step()["spectral"] < base.critical_time_step()["spectral"]
    for dyn in (base, pen, lag):
        dyn.destroy()


# --- convergence to the exact solution -----------------------------------------------------------


@pytest.mark.parametrize("coupling", COUPLINGS)
def test_rod_converges_to_exact_solution(coupling):
    """Velocity error (Rabczuk eq. 137) at t = L/(4c), once the half-pulse has crossed the
    interface: fitted slope over h = 1, 0.5, 0.25 (ratio 1:1)."""
    hs = [1.0, 0.5, 0.25]
    errors = []
    for h in hs:
        dyn = build(coupling, MPI.COMM_WORLD, h)
        dyn.set_initial(velocity=ROD.initial_velocity)
        dyn.run(0.25 * ROD.transit_time)
        errors.append(dyn.velocity_error(ROD.velocity))
        dyn.destroy()
    rate = fitted_rate(hs, errors)
    # measured at h = 0.25 (rate): lagrange 1.38e-3 (2.03), edge-to-edge 1.38e-3 (2.03), ramp
    # 2.39e-3 (2.02), ramp-cubic 2.41e-3 (2.02), bridging 1.41e-3 (2.01), master-slave 2.63e-3
    # (1.96); the checks allow twice the error and rates within [1.8, 2.3]
    finest = {"lagrange": 1.38e-3, "edge-to-edge": 1.38e-3, "ramp": 2.39e-3,
              "ramp-cubic": 2.41e-3, "bridging": 1.41e-3, "master-slave": 2.63e-3}  # fmt: skip
    assert errors[-1] < 2.0 * finest[coupling], errors
    assert 1.8 < rate < 2.3, (errors, rate)


@pytest.mark.parametrize("coupling", COUPLINGS)
def test_two_ranks_equal_serial(coupling):
    results = []
    for comm in (MPI.COMM_WORLD, MPI.COMM_SELF):
        dyn = build(coupling, comm, 1.0, 2)
        dyn.set_initial(velocity=ROD.initial_velocity)
        res = dyn.run(0.5 * ROD.transit_time)
        pts = np.array([[10.0, 2.5], [29.6, 0.1], [44.3, 4.9]])
        v = dyn.velocity_at(pts if comm.rank == 0 else np.zeros((0, 2)))
        results.append((dyn.velocity_error(ROD.velocity), res.steps, res.energies[-1].kinetic, v))
        dyn.destroy()
    (e1, s1, k1, v1), (e2, s2, k2, v2) = results
    assert s1 == s2
    assert e1 == pytest.approx(e2, rel=1e-10) and k1 == pytest.approx(k2, rel=1e-12)
    if MPI.COMM_WORLD.rank == 0:
        assert np.allclose(v1, v2, rtol=1e-9, atol=1e-12)


# --- fixed facets and the step-loaded rod --------------------------------------------------------


def test_step_loaded_rod_exact_solution():
    rod = StepLoadedRod()
    x = np.array([[0.3, 0.0], [0.7, 0.0], [0.0, 0.0], [1.0, 0.0]])
    table = {0.2: [0, 0, 1, 0], 0.5: [1, 0, 1, 0], 1.0: [1, 1, 1, 0], 1.5: [1, 0, 1, 0]}
    table.update({1.8: [0, 0, 1, 0], 2.4: [-1, 0, -1, 0], 3.0: [-1, -1, -1, 0], 4.1: [0, 0, 1, 0]})
    for t, v in table.items():
        assert np.array_equal(rod.velocity(x, t)[:, 0], v), t
    assert np.allclose(rod.arrivals(0.3, 2.0), [0.3, 1.7])
    # energy: the work of the load sigma0 v0 t is half kinetic, half internal (t < 2L/c)
    with pytest.raises(ValueError, match="rho=0"):
        StepLoadedRod(rho=0.0)


@pytest.mark.parametrize("method", ["fe", "efg", "ramp", "lagrange", "bridging", "master-slave"])
def test_fixed_end_and_step_load(method):
    """A strip under a step traction on x = 0, fixed on x = 1 (Belytschko 1995, 5.2.1), up to
    t = 0.75: the fixed end stays at rest (FE nodes exactly; particles weakly, int_f v = 0 per
    facet to round-off, pointwise below 1e-6 v0), the energy balance holds, and the mean
    velocity of x < 0.5 (behind the front) is v0 = 1 within 2 % (the Gibbs oscillation averages
    out)."""
    comm = MPI.COMM_WORLD
    cells = 40
    msh = rectangle(comm, [0.0, 0.0], [1.0, 1.0 / cells], [cells, 1], CELL_TYPES["quadrilateral"])
    mat = mf.LinearElastic(1.0, 0.0, "strain", rho=1.0)
    fixed = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 1.0))
    V = _compat.vector_function_space(msh)
    if method == "fe":
        dyn = ExplicitDynamics.fe(V, mat, 0.5, fixed_facets=fixed)
    elif method == "efg":
        P = mf.ParticleSet.from_cells(msh, 1.0 / cells)
        dyn = ExplicitDynamics.efg(P, mat, weight="cubic", safety=0.5, fixed_facets=fixed)
    else:
        n = msh.topology.index_map(2).size_local
        xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
        patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 0.5), 1.0 / cells)
        problem = mf.CoupledElasticity(V, patch, mat, coupling=method, weight="cubic", overlap=1)
        dyn = ExplicitDynamics.coupled(problem, safety=0.5, fixed_facets=fixed)
    load = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0))
    dyn.add_traction(load, lambda x, n: np.tile([1.0, 0.0], (len(x), 1)))
    dyn.set_initial()
    res = dyn.run(0.75)
    assert res.energy_drift < 1e-11 and res.max_residual < 1e-13
    last = res.energies[-1]
    assert last.kinetic + last.internal == pytest.approx(last.external, rel=0.02)
    end = np.array([[1.0, 0.0], [1.0, 0.5 / cells]]) if comm.rank == 0 else np.zeros((0, 2))
    v_end = dyn.velocity_at(end)
    assert np.abs(v_end).max(initial=0.0) < (1e-14 if method == "fe" else 1e-6)
    q, vh = dyn.velocity_at_quadrature(3)
    behind = q.points[:, 0] < 0.5
    s = comm.allreduce(np.array([np.sum(q.weights[behind] * vh[behind, 0]),
                                 np.sum(q.weights[behind])]), op=MPI.SUM)  # fmt: skip
    assert s[0] / s[1] == pytest.approx(1.0, abs=0.02)
    dyn.destroy()


def test_bad_fixed_facets():
    msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [4.0, 1.0], [4, 1], CELL_TYPES["quadrilateral"])
    V = _compat.vector_function_space(msh)
    mat = mf.LinearElastic(1.0, 0.0, "strain", rho=1.0)
    with pytest.raises(ValueError, match="fixed_facets names facets that are not owned"):
        ExplicitDynamics.fe(V, mat, fixed_facets=np.array([10**6]))
    with pytest.raises(ValueError, match="fixed_facets must be a 1D array"):
        ExplicitDynamics.fe(V, mat, fixed_facets=np.array([[0.5]]))


# --- the demos -----------------------------------------------------------------------------------


@pytest.fixture
def shared_dir():
    comm = MPI.COMM_WORLD
    path = tempfile.mkdtemp() if comm.rank == 0 else None
    yield pathlib.Path(comm.bcast(path, root=0))
    comm.Barrier()


def test_rod_step_1d_demo(shared_dir):
    out = shared_dir / "step.json"
    res = load_demo("rod_step_1d").main(["--method", "lagrange", "--png", "", "--json", str(out)])
    for o in ("fe-loaded", "efg-loaded"):
        r = res[o]
        assert r["t_end"] == pytest.approx(2.0) and r["reflection"] < r["gibbs_pure_max"]
        assert r["coupled_energy_drift"] < 1e-11
    # FE -> EFG reflects (the FE's high frequencies), EFG -> FE hardly (Belytschko, Fig. 9)
    assert res["efg-loaded"]["reflection"] < 0.5 * res["fe-loaded"]["reflection"]
    MPI.COMM_WORLD.Barrier()
    data = json.loads(out.read_text())  # the file holds what the demo returned
    assert data["ranks"] == MPI.COMM_WORLD.size
    for o in ("fe-loaded", "efg-loaded"):
        assert data[o]["reflection"] == res[o]["reflection"] and data[o]["steps"] == res[o]["steps"]


def test_rod_gauss_demo_sweep():
    """The ratio sweep at 300 nodes (--no-check: the coarse ramp at 4:1 is above the demo's
    0.2). Measured errors at t1 / t2 (lane A, serial = 2 ranks): bridging 1:1 5.56e-2 / 6.09e-2,
    ramp 1:1 9.43e-2 / 0.127, bridging 4:1 2.34e-2 / 6.06e-2, ramp 4:1 0.121 / 0.223; the
    checks allow about twice that (ramp 4:1: 0.3, 1.35x)."""
    recs = load_demo("rod_gauss").main(
        ["--method", "bridging", "ramp", "--nodes", "300", "--sweep", "1", "4", "--no-check"]
    )
    assert len(recs) == 4
    assert recs[0]["ratio"] < 1.5 < 3.0 < recs[2]["ratio"]
    bounds = {  # (method, sweep ratio): (t1, t2)
        ("bridging", 1): (0.11, 0.12),
        ("ramp", 1): (0.19, 0.25),
        ("bridging", 4): (0.047, 0.12),
        ("ramp", 4): (0.24, 0.3),
    }
    for r, ratio in zip(recs, (1, 1, 4, 4), strict=True):
        b1, b2 = bounds[r["method"], ratio]
        assert r["energy_drift"] < 1e-10
        assert r["error_t1"] < b1 and r["error_t2"] < b2, r


#: rod_gauss at --nodes 2000, ratio 4 (lane A, serial = 2 ranks): measured velocity errors at
#: t1 and t2 and the growth t2 / t1. At this size the pulse is resolved by about 8 cells, so
#: dispersion makes most errors grow (FE 1.04, EFG 4.4); the ramps' interface error, large at
#: t1, falls. The hybrid's bounds belong to its own tests (tests/test_hybrid.py).
ROD_2000 = {
    "fe": (5.92e-4, 6.15e-4, 1.04),
    "efg": (8.05e-4, 3.57e-3, 4.43),
    "lagrange": (1.54e-3, 2.20e-3, 1.43),
    "edge-to-edge": (1.54e-3, 2.20e-3, 1.43),
    "ramp": (1.54e-2, 1.15e-2, 0.743),
    "ramp-cubic": (1.56e-2, 1.10e-2, 0.707),
    "bridging": (1.72e-3, 2.24e-3, 1.31),
    "master-slave": (4.28e-3, 7.34e-3, None),  # rigid links: growth not checked (1.71)
}


def test_rod_gauss_errors_and_growth_per_method():
    """Every method's errors at t1 and t2 below twice the measured value (the demo's own check,
    0.2 at this size, is far looser), and the growth t1 -> t2 below 1.3x the measured growth
    for every method but master-slave (2x would let the error double, which is the failure
    this check exists for)."""
    recs = load_demo("rod_gauss").main(["--method", *ROD_2000, "--nodes", "2000"])
    assert len(recs) == len(ROD_2000)
    for r in recs:
        e1, e2, growth = ROD_2000[r["method"]]
        assert r["error_t1"] < 2.0 * e1 and r["error_t2"] < 2.0 * e2, r
        if growth is not None:
            assert r["error_t2"] / r["error_t1"] < 1.3 * growth, r
