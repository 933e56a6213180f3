"""Explicit dynamics (central differences, lumped masses, Lagrange coupling in dynamics) and the
exact rod solutions; serial and on 2 ranks."""

from __future__ import annotations

import json
import pathlib

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.dynamics import ExplicitDynamics, check_method, fe_lumped_mass
from dolfinx_meshfree.dynamics.constraint import VelocityProjection
from dolfinx_meshfree.verification.waves import GaussianPulseRod

import numpy as np
import pytest
import ufl
from conftest import CELL_TYPES, fitted_rate, load_demo, rectangle
from mpi4py import MPI
from petsc4py import PETSc

DEMOS = pathlib.Path(__file__).resolve().parents[1] / "demos"

ROD = GaussianPulseRod()
STEEL = mf.LinearElastic(ROD.E, 0.0, "strain", rho=ROD.rho)


def rod_mesh(comm, h, cell="quadrilateral", length=60.0, height=5.0):
    return rectangle(
        comm, [0.0, 0.0], [length, height], [round(length / h), round(height / h)], CELL_TYPES[cell]
    )


def build(method, comm, h, material=STEEL, ratio=1.0, **options):
    """Explicit dynamics of the rod: fe, efg (particle spacing h) or lagrange (x > 30 particles,
    spacing h / sqrt(ratio))."""
    msh = rod_mesh(comm, h)
    if method == "fe":
        return ExplicitDynamics.fe(_compat.vector_function_space(msh), material, **options)
    if method == "efg":
        particles = mf.ParticleSet.from_cells(msh, h)
        return ExplicitDynamics.efg(particles, material, quadrature_degree=3, **options)
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 30.0), h / np.sqrt(ratio))
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, material, coupling="lagrange", quadrature_degree=3)
    return ExplicitDynamics.coupled(problem, **options)


def wavy(x):
    """A smooth field with both components, for energy tests."""
    return np.stack([np.sin(0.3 * x[:, 0]) * np.cos(0.7 * x[:, 1]), np.cos(0.2 * x[:, 0])], 1)


# --- lumped masses -------------------------------------------------------------------------------


def test_fe_lumped_mass_is_row_sum_of_consistent_mass():
    msh = rod_mesh(MPI.COMM_WORLD, 1.0, "triangle", length=6.0, height=3.0)
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    M = _compat.assemble_matrix(_compat.create_form(STEEL.rho * ufl.inner(u, v) * ufl.dx))
    ones = M.createVecRight()
    ones.set(1.0)
    row_sums = M.createVecLeft()
    M.mult(ones, row_sums)
    m = fe_lumped_mass(V, STEEL.rho)
    assert np.allclose(m.array_r, row_sums.array_r, rtol=1e-13, atol=0)
    assert m.sum() == pytest.approx(2 * STEEL.rho * 18.0, rel=1e-13)  # two components
    for obj in (M, ones, row_sums, m):
        obj.destroy()


@pytest.mark.parametrize("method", ["efg", "lagrange"])
def test_total_mass_is_exact(method):
    """Row-sum masses: partition of unity makes the total mass rho |Omega| per component."""
    dyn = build(method, MPI.COMM_WORLD, 1.0, ratio=4.0)
    total = sum(f.mass.sum() for f in dyn.fields)
    assert total == pytest.approx(2 * STEEL.rho * 300.0, rel=1e-12)
    assert all(f.mass.min()[1] >= 0.0 for f in dyn.fields)
    dyn.destroy()


# --- energy and constraints ----------------------------------------------------------------------


@pytest.mark.parametrize("method", ["fe", "efg", "lagrange"])
def test_energy_is_conserved_without_load(method):
    dyn = build(method, MPI.COMM_WORLD, 1.0, ratio=4.0)
    dyn.set_initial(velocity=lambda x: 100.0 * wavy(x), displacement=lambda x: 1e-3 * wavy(x))
    res = dyn.run(2.0 * ROD.transit_time, energy_records=50)
    # the discrete energy of central differences: round-off over ~270 steps
    assert res.energy_drift < 1e-11
    # the kinetic energy at integer steps oscillates by O((omega dt)^2), without drift
    assert res.energy_oscillation < 0.05
    e = res.energies
    assert e[0].kinetic > 0 and e[0].internal > 0 and max(r.internal for r in e) > e[0].internal
    assert all(r.external == 0.0 for r in e)
    if method == "lagrange":
        assert res.max_residual < 1e-13
        assert abs(e[-1].constraint) < 1e-12 * e[0].total  # the constraints do no work
        assert max(abs(r.transfer) for r in e) > 1e-6 * e[0].total  # but energy crosses
    dyn.destroy()


def test_energy_balance_with_step_load():
    """A step traction on the right end (a particle facet for the coupling): the work of the
    load balances the discrete energy exactly, and equals twice the internal energy at rest."""
    dyn = build("lagrange", MPI.COMM_WORLD, 1.0)
    right = mf.boundary_facets(dyn.mesh, lambda x: np.isclose(x[0], 60.0))
    left = mf.boundary_facets(dyn.mesh, lambda x: np.isclose(x[0], 0.0))
    dyn.add_traction(right, lambda x, n: np.tile([10.0, 0.0], (len(x), 1)))
    dyn.add_traction(left, lambda x, n: np.tile([10.0, 0.0], (len(x), 1)), lambda t: 0.5)
    dyn.set_initial()
    res = dyn.run(0.5 * ROD.transit_time)
    assert res.energy_drift < 1e-11
    last = res.energies[-1]
    assert last.external > 0
    assert last.kinetic + last.internal == pytest.approx(last.external, rel=0.02)
    dyn.destroy()


@pytest.mark.parametrize("solver", ["dense", "mumps"])
def test_lagrange_constraint_at_round_off(solver):
    dyn = build("lagrange", MPI.COMM_WORLD, 1.0, ratio=2.0, multiplier_solver=solver)
    if solver == "mumps":  # the factorisation actually used
        assert dyn.projection.ksp.getPC().getFactorSolverType() == "mumps"
    else:
        assert dyn.projection.ksp is None and dyn.projection.chol[0].shape == (12, 12)
    dyn.set_initial(velocity=ROD.initial_velocity)
    assert dyn.constraint_residual() < 1e-14  # the projected initial velocity
    errors = []
    res = dyn.run(
        ROD.transit_time,
        outputs=[0.5 * ROD.transit_time],
        on_output=lambda d, n, t: errors.append(d.constraint_residual()),
    )
    assert errors and errors[0] < 1e-13
    assert res.max_residual < 1e-13
    assert dyn.constraint_residual() < 1e-13
    assert dyn.num_dofs()["multiplier_dofs"] == 12  # 6 interface nodes, 2 components
    dyn.destroy()


def test_dense_and_mumps_multipliers_agree():
    errs = []
    for solver in ("dense", "mumps"):
        dyn = build("lagrange", MPI.COMM_WORLD, 1.0, multiplier_solver=solver)
        dyn.set_initial(velocity=ROD.initial_velocity)
        dyn.run(0.5 * ROD.transit_time)
        errs.append(dyn.velocity_error(ROD.velocity))
        dyn.destroy()
    assert errs[0] == pytest.approx(errs[1], rel=1e-10)


# --- time step -----------------------------------------------------------------------------------


def test_critical_time_step_estimates():
    """The guard is 2 / omega_bound (tests/test_time_step.py checks the bound against dense
    eigenvalues); square Q1 at nu = 0 with lumped masses: the critical step is h / c, and the
    bound gives 0.918 h / c at h = 1."""
    dyn = build("fe", MPI.COMM_WORLD, 1.0)
    crit = dyn.critical_time_step()
    c = STEEL.wave_speed()
    assert crit["courant"] == pytest.approx(1.0 / c, rel=1e-12)
    assert crit["critical"] == crit["spectral"]
    assert 0.88 * crit["courant"] < crit["critical"] <= crit["courant"]
    assert dyn.stable_time_step() == pytest.approx(0.9 * crit["critical"], rel=1e-12)
    dyn.destroy()
    # right triangles: the Courant step is above the critical one (0.69 h/c), the bound binds
    msh = rod_mesh(MPI.COMM_WORLD, 1.0, "triangle", length=20.0)
    dyn = ExplicitDynamics.fe(_compat.vector_function_space(msh), STEEL)
    crit = dyn.critical_time_step()
    assert crit["critical"] == crit["spectral"] < 0.75 * crit["courant"]
    dyn.set_initial(velocity=lambda x: 100.0 * wavy(x))
    assert dyn.run(ROD.transit_time).energy_drift < 1e-11  # stable at 0.9 x critical
    dyn.destroy()


def test_time_step_guard():
    dyn = build("efg", MPI.COMM_WORLD, 1.0)
    dyn.set_initial(velocity=ROD.initial_velocity)
    stable = dyn.stable_time_step()
    with pytest.raises(ValueError, match=r"dt=.* is above the stable time step .*force=True"):
        dyn.run(10 * stable, dt=1.01 * stable)
    with pytest.raises(ValueError, match="must be a positive number"):
        dyn.run(10 * stable, dt=-stable)
    res = dyn.run(10 * stable, dt=1.01 * stable, force=True)
    assert res.dt == pytest.approx(10 * stable / 10)
    with pytest.raises(ValueError, match="must lie after the current time"):
        dyn.run(5 * stable)
    res = dyn.run(20 * stable, dt=0.5 * stable)  # continues from t = 10 stable
    assert res.steps == 20 and res.time == pytest.approx(20 * stable)
    dyn.destroy()


# --- exact solutions -----------------------------------------------------------------------------


def test_gaussian_pulse_rod_exact_solution():
    x = np.stack([np.linspace(0.0, 60.0, 241), np.zeros(241)], axis=1)
    v0 = np.exp(-0.025 * (x[:, 0] - 30.0) ** 2)
    assert np.abs(ROD.initial_velocity(x)[:, 0] - v0).max() < 1e-9
    assert ROD.wave_speed == pytest.approx(5188.7452, rel=1e-7)
    assert ROD.transit_time == pytest.approx(0.011563, rel=1e-4)
    T = ROD.transit_time
    for t in (T, 2 * T, 7 * T):  # back at the start after each transit
        assert np.abs(ROD.velocity(x, t) - ROD.initial_velocity(x)).max() < 1e-12
    shifted = GaussianPulseRod(center=20.0)  # off-centre: mirrored after one transit
    assert np.allclose(shifted.velocity(x, T)[:, 0], shifted.initial_velocity(x[::-1])[:, 0])
    dt = 1e-8
    for t in (0.3 * T, 5.3 * T):  # u_t = v, and free ends (u_x = 0)
        du = (ROD.displacement(x, t + dt) - ROD.displacement(x, t - dt)) / (2 * dt)
        assert np.abs(du - ROD.velocity(x, t)).max() < 1e-6
        ends = np.array([[0.0, 0.0], [1e-6, 0.0], [60.0 - 1e-6, 0.0], [60.0, 0.0]])
        u = ROD.displacement(ends, t)[:, 0]
        assert abs(u[1] - u[0]) < 1e-10 * abs(u).max() and abs(u[3] - u[2]) < 1e-10 * abs(u).max()
    with pytest.raises(ValueError, match="center=70"):
        GaussianPulseRod(center=70.0)


@pytest.mark.parametrize("method", ["fe", "efg", "lagrange"])
def test_rod_converges_to_exact_solution(method):
    """Velocity error (Rabczuk eq. 137) at t = L/(4c), when the half-pulses are at x = 15 and 45
    (the coupling's pulse has crossed the interface): fitted slope over h = 1, 0.5, 0.25."""
    hs = [1.0, 0.5, 0.25]
    errors = []
    for h in hs:
        dyn = build(method, MPI.COMM_WORLD, h)
        dyn.set_initial(velocity=ROD.initial_velocity)
        dyn.run(0.25 * ROD.transit_time)
        errors.append(dyn.velocity_error(ROD.velocity))
        if h == 0.5:  # the field has moved: far from the initial one, close to the exact one
            moved = dyn.velocity_error(lambda x, t: ROD.initial_velocity(x))
            assert moved > 0.5 and errors[-1] < 0.02
        dyn.destroy()
    rate = fitted_rate(hs, errors)
    # measured (h = 1, 0.5, 0.25): fe 5.36e-3, 1.29e-3, 3.15e-4 (rate 2.05); efg 2.96e-2,
    # 7.12e-3, 1.74e-3 (2.04); lagrange 2.29e-2, 5.59e-3, 1.38e-3 (2.03)
    finest = {"fe": 3.15e-4, "efg": 1.74e-3, "lagrange": 1.38e-3}[method]
    assert errors[-1] < 2.0 * finest, errors
    assert 1.8 < rate < 2.3, (errors, rate)


def test_two_ranks_equal_serial():
    """The coupled rod on this communicator and on COMM_SELF (each rank alone) agree."""
    results = []
    for comm in (MPI.COMM_WORLD, MPI.COMM_SELF):
        dyn = build("lagrange", comm, 1.0, ratio=4.0)
        dyn.set_initial(velocity=ROD.initial_velocity)
        res = dyn.run(ROD.transit_time)
        pts = np.array([[10.0, 2.5], [29.6, 0.1], [44.3, 4.9]])  # (not on the interface)
        v = dyn.velocity_at(pts if comm.rank == 0 else np.zeros((0, 2)))
        results.append((dyn.velocity_error(ROD.velocity), res.steps, res.energies[-1].kinetic))
        if comm.rank == 0:
            results[-1] += (v,)
        dyn.destroy()
    (e1, s1, k1, *v1), (e2, s2, k2, *v2) = results
    assert s1 == s2
    assert e1 == pytest.approx(e2, rel=1e-10) and k1 == pytest.approx(k2, rel=1e-12)
    if v1 and v2:
        assert np.allclose(v1[0], v2[0], rtol=1e-9, atol=1e-12)


# --- bad input -----------------------------------------------------------------------------------


@pytest.mark.parametrize("rho", [0.0, -7.8e-9])
def test_bad_density(rho):
    with pytest.raises(ValueError, match="zero or negative density"):
        mf.LinearElastic(210000.0, 0.0, "strain", rho=rho)


@pytest.mark.parametrize("method", ["fe", "efg", "lagrange"])
def test_dynamics_warns_on_a_law_without_density(method):
    """A law built without ``rho`` takes the default 1.0 (statics does not use it); explicit
    dynamics on it warns on every rank, naming the fix (issue 23, item 4), and a law with a
    density (1.0 given explicitly too) runs without a warning. The density was used as given:
    the stable step scales as sqrt(rho) (a 100x density, 10x the step, to 1e-12)."""
    import warnings

    from dolfinx_meshfree.dynamics.time_step import DefaultDensityWarning

    comm = MPI.COMM_WORLD
    law = mf.LinearElastic(ROD.E, 0.0, "strain")
    assert not law.density_given and law.rho == 1.0
    assert law == mf.LinearElastic(ROD.E, 0.0, "strain", rho=1.0)  # the same law
    with pytest.warns(DefaultDensityWarning, match=r"without a density.*pass rho="):
        dyn = build(method, comm, 2.5, material=law)
    dt1 = dyn.stable_time_step()
    dyn.destroy()
    with warnings.catch_warnings():
        warnings.simplefilter("error", DefaultDensityWarning)
        for rho in (1.0, 100.0):
            dyn = build(method, comm, 2.5, material=mf.LinearElastic(ROD.E, 0.0, "strain", rho=rho))
            dt = dyn.stable_time_step()
            dyn.destroy()
            assert dt == pytest.approx(dt1 * np.sqrt(rho), rel=1e-12)
    # the finite-strain laws and the linear twin of a law without density keep "not given"
    assert not mf.physics.materials.linear_twin(mf.NeoHookean(1.0, 0.3)).density_given
    assert mf.physics.materials.linear_twin(mf.NeoHookean(1.0, 0.3, rho=2.0)).density_given


def test_unknown_method_and_coupling():
    with pytest.raises(ValueError, match=r"method='sph' is not available.*'lagrange'"):
        check_method("sph")
    # every name check_method accepts has a builder: each coupling builds an explicit model
    msh = rod_mesh(MPI.COMM_WORLD, 1.0, length=8.0, height=2.0)
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 4.0), 0.5)
    V = _compat.vector_function_space(msh)
    for m in mf.COUPLINGS:
        check_method(m)
        dilation = 3.5 if m.startswith("ramp") else None
        problem = mf.CoupledElasticity(V, patch, STEEL, coupling=m, dilation=dilation, overlap=1)
        dyn = ExplicitDynamics.coupled(problem)
        assert [f.name for f in dyn.fields] == ["fe", "particles"]
        assert 0.0 < dyn.stable_time_step() < np.inf
        dyn.destroy()
    with pytest.raises(TypeError, match="problem must be a CoupledElasticity"):
        ExplicitDynamics.coupled("lagrange")
    with pytest.raises(ValueError, match=r"safety=1\.5 must lie in"):
        build("fe", MPI.COMM_WORLD, 2.0, safety=1.5)


def test_probe_outside_the_body():
    dyn = build("efg", MPI.COMM_WORLD, 1.0)
    dyn.set_initial(velocity=ROD.initial_velocity)
    pts = np.array([[70.0, 1.0]]) if MPI.COMM_WORLD.rank == 0 else np.zeros((0, 2))
    with pytest.raises(ValueError, match="outside the mesh"):
        dyn.velocity_at(pts)
    dyn.destroy()


# --- the demo ------------------------------------------------------------------------------------


def test_rod_gauss_demo_json_and_probe(shared_dir):
    comm = MPI.COMM_WORLD
    out, pin, pout = shared_dir / "rod.json", shared_dir / "p.npy", shared_dir / "v.npy"
    pts = np.array([[30.0, 2.5], [10.0, 1.0], [50.0, 4.0]])
    if comm.rank == 0:
        np.save(pin, pts)
    comm.Barrier()
    demo = load_demo("rod_gauss")
    records = demo.main(
        ["--method", "fe", "lagrange", "--nodes", "600", "--json", str(out),
         "--probe-in", str(pin), "--probe-out", str(pout)]
    )  # fmt: skip
    # measured at 600 nodes, ratio 4 (serial = 2 ranks): fe 1.54e-3 / 2.36e-3, lagrange
    # 9.19e-3 / 2.39e-2 at t1 / t2; the checks allow about twice that
    bounds = [(3.1e-3, 4.7e-3), (1.9e-2, 4.8e-2)]
    for r, (b1, b2) in zip(records, bounds, strict=True):
        assert r["error_t1"] < b1 and r["error_t2"] < b2, r
        assert r["energy_drift"] < 1e-10 and r["ranks"] == comm.size
    assert records[0]["particles"] == 0 and records[0]["fe_nodes"] == records[0]["nodes"]
    assert records[1]["particles"] > 3 * records[1]["fe_nodes"]
    comm.Barrier()
    data = json.loads(out.read_text())
    assert len(data) == 2 and {"error_t1", "error_t2", "time_total", "steps", "dt"} <= set(data[0])
    v = np.load(pout)
    assert v.shape == (3, 2)
    assert np.abs(v - ROD.velocity(pts, records[1]["t_end"])).max() < 0.05
    with pytest.raises(SystemExit):  # argparse: an unknown method
        demo.main(["--method", "sph", "--nodes", "100"])


def _projection(rows: list[list[float]], minv: list[float], product: str | None = None):
    """A dense :class:`VelocityProjection` of one field on this rank alone."""
    G = PETSc.Mat().createAIJ(size=(len(rows), len(minv)), comm=PETSc.COMM_SELF)
    G.setUp()
    for i, row in enumerate(rows):
        G.setValues([i], range(len(row)), row)
    G.assemble()
    m = PETSc.Vec().createWithArray(np.array(minv, dtype=float), comm=PETSc.COMM_SELF)
    return VelocityProjection([G], [m], MPI.COMM_SELF, "dense", product=product)


@pytest.mark.skipif(not jit.AVAILABLE, reason="the compiled products need numba")
def test_compiled_projection_equals_the_reference_to_the_bit():
    """The dense projection's local products compiled (``product="numba"``) and by scipy and
    numpy (``"petsc"``): the same corrected velocity and impulse to the last bit (the sums in
    the same order), on 12 random constraints of 40 dofs, some held, a target given; and the
    corrected velocity satisfies ``G v = target`` (1e-13 relative)."""
    rng = np.random.default_rng(3)
    rows = np.where(rng.random((12, 40)) < 0.2, rng.standard_normal((12, 40)), 0.0)
    minv = np.where(rng.random(40) < 0.1, 0.0, rng.uniform(0.5, 2.0, 40))
    target, v0 = rng.standard_normal(12), rng.standard_normal(40)
    out = {}
    for product in ("numba", "petsc"):
        proj = _projection(rows.tolist(), minv.tolist(), product)
        assert proj.product == product and proj.chol is not None
        v = PETSc.Vec().createWithArray(v0.copy(), comm=PETSc.COMM_SELF)
        imp = v.duplicate()
        proj.correct([v], [imp], target)
        out[product] = (v.array.copy(), imp.array.copy())
    assert np.array_equal(out["numba"][0], out["petsc"][0])
    assert np.array_equal(out["numba"][1], out["petsc"][1])
    scale = np.abs(rows).sum(axis=1).max() * np.abs(out["numba"][0]).max()
    assert np.abs(rows @ out["numba"][0] - target).max() <= 1e-13 * scale


def test_constraints_of_any_scale_count():
    """Two independent constraints 1e7 apart in scale (a coupling's unit rows beside a wall's
    facet integrals in millimetres): neither is read as redundant, and the projection meets
    both to round-off of each row's own scale. Unscaled, the small row's pivot was 1e-14 of the
    largest diagonal and it was dropped (the velocity left unconstrained)."""
    rows = [[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1e-7, 2e-7]]
    proj = _projection(rows, [1.0, 0.5, 2.0, 1.0])
    assert proj.redundant == 0 and proj.chol is not None
    v = PETSc.Vec().createWithArray(np.array([3.0, 1.0, -2.0, 5.0]), comm=PETSc.COMM_SELF)
    proj.correct([v])
    assert abs(v.array[0] + v.array[1]) < 1e-14 * 3.0
    assert abs(v.array[2] + 2.0 * v.array[3]) < 1e-14 * 5.0


def test_redundant_constraints_are_deflated():
    """``S = G M^-1 G^T`` singular because two rows combine to act on a held dof only (as a
    bridging band's rows at roller nodes with the roller's rows on the particles): the
    projection deflates that null direction and gives the projection of the independent
    constraints, computed by hand. Rows ``v0 + v3``, ``v0 - v3``, ``v1 - v2`` with ``v3`` held
    (``M^-1 = 0``): ``v0 -> 0`` and ``v1 = v2 ->`` the mass-weighted mean, as the Cholesky
    solve without the redundant row gives. A negative mass (an indefinite ``S``) is refused, and
    so is a velocity with a NaN."""
    rows = [[1.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, -1.0], [0.0, 1.0, -1.0, 0.0]]
    minv = [0.5, 1.0, 0.25, 0.0]  # masses 2, 1, 4; dof 3 held
    proj = _projection(rows, minv)
    assert proj.redundant == 1 and proj.chol is None
    v = PETSc.Vec().createWithArray(np.array([3.0, 1.0, -2.0, 0.0]), comm=PETSc.COMM_SELF)
    proj.correct([v])
    mean = (1.0 * 1.0 + 4.0 * -2.0) / 5.0
    assert np.allclose(v.array, [0.0, mean, mean, 0.0], rtol=0, atol=1e-14)
    full = _projection([rows[0], rows[2]], minv)  # the same without the redundant row
    assert full.redundant == 0 and full.chol is not None
    v = PETSc.Vec().createWithArray(np.array([3.0, 1.0, -2.0, 0.0]), comm=PETSc.COMM_SELF)
    full.correct([v])
    assert np.allclose(v.array, [0.0, mean, mean, 0.0], rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="not positive semi-definite"):
        _projection(rows, [0.5, -1.0, 0.25, 0.0])
    v.array[1] = np.nan  # an unstable run's velocity: refused, not carried on
    with pytest.raises(FloatingPointError, match="non-finite G v: the velocities hold NaN"):
        full.correct([v])
