"""Explicit dynamics at finite strain of the ramps (blended interface cells), master-slave
(finite-rotation links through the reduction), the bridging penalty and the hybrid SPH-FE
coupling (HA-F, SPH sums of P): rigid motions, the
small-amplitude limit (the linear system's force and the linear rod run), the spinning plate,
energy conservation at large amplitude; serial and 2 ranks."""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import ExplicitDynamics, NonlinearSystem
from dolfinx_meshfree.verification.waves import GaussianPulseRod

import numpy as np
import pytest
from conftest import CELL_TYPES, rectangle
from mpi4py import MPI
from test_dynamics_finite_strain import LIN, NH, mesh, patch_problem, rotation

#: The new couplings at finite strain: (coupling, CoupledElasticity options, dynamics options).
#: The ramps in dynamics are not VCI-corrected (consistent=False) and need supports over the
#: interface cells (dilation 3 on the 4 x 4 plate: 2.5 gives a negative particle mass);
#: master-slave's "band" slaves have links of one spacing (the finite-rotation correction).
CASES = {
    "ramp": ("ramp", {"consistent": False, "dilation": 3.0, "quadrature_degree": 5}, {}),
    "ramp-cubic": (
        "ramp-cubic",
        {"consistent": False, "dilation": 3.0, "quadrature_degree": 5},
        {},
    ),
    "master-slave": ("master-slave", {}, {}),
    "master-slave-band": ("master-slave", {}, {"slaves": "band"}),
    "bridging-penalty": ("bridging", {"penalty": 10.0}, {}),
    "hybrid": ("hybrid", {}, {}),
}


#: The long runs (a quarter turn, 300-600 steps at large amplitude) on 2 ranks: two cases
#: only (each case costs about a minute on 2 shared cores; that 2 ranks equal serial is
#: checked for four cases by test_two_ranks_equal_serial).
LONG = list(CASES) if MPI.COMM_WORLD.size == 1 else ["ramp", "hybrid"]


def coupled(V, patch, material, coupling: str, **options):
    """A HybridElasticity (HA-F, smoothed strains) or a CoupledElasticity."""
    if coupling == "hybrid":
        return mf.HybridElasticity(V, patch, material, **options)
    return mf.CoupledElasticity(V, patch, material, coupling=coupling, **options)


def build(case: str, material=NH, n: int = 4) -> ExplicitDynamics:
    """The case on the plate [-1, 1]^2 of n x n cells with the patch |x|, |y| < 1/2."""
    coupling, options, dyn_options = CASES[case]
    msh = mesh(n)
    if coupling == "hybrid":
        V = _compat.vector_function_space(msh)
        cells = msh.topology.index_map(2).size_local
        xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:cells], :2].mean(axis=1)
        patch = mf.ParticlePatch(msh, np.flatnonzero(np.all(np.abs(xc) < 0.5, axis=1)), 1 / n)
        problem = coupled(V, patch, LIN, coupling, **options)
    else:
        problem = patch_problem(msh, coupling, **options)
    return ExplicitDynamics.coupled(problem, material=material, **dyn_options)


# --- rigid motions --------------------------------------------------------------------------------


@pytest.mark.parametrize("case", list(CASES))
def test_rigid_motions_are_force_free(case):
    """A rigid translation and a finite rigid rotation (0.9 rad) give no internal force
    (measured <= 2e-14 of the reference stiffness times |u|, bound 1e-12) and W = 0 (<= 6e-17,
    bound 1e-13); a homogeneous stretch is not force-free. With master-slave's band slaves
    (links of one spacing) the small-rotation links would not be: the rotation then gives a
    force of 7.1e-4 and W = 3.8e-3 (measured), which the finite-rotation links remove."""
    dyn = build(case)
    system = dyn.system
    assert isinstance(system, NonlinearSystem)
    scale = max(K.norm() for K in system.tangent().values())
    R = rotation(0.9)
    for disp in (
        lambda x: np.tile([0.3, -0.2], (len(x), 1)),
        lambda x: x[:, :2] @ (R - np.eye(2)).T,
    ):
        dyn.set_initial(displacement=disp)
        f = system.internal_force(dyn.u)
        size = max(x.norm() for x in dyn.u)
        assert max(g.norm() for g in f) <= 1e-12 * scale * size
        assert abs(system.strain_energy(dyn.u, f)) <= 1e-13
    if case == "master-slave-band":  # the links' finite rotation is what makes it force-free
        shared = system.shared[0]
        assert shared.correction is not None and shared.correction.length > 0.0
        shared.correction, correction = None, shared.correction
        f = system.internal_force(dyn.u)
        assert max(g.norm() for g in f) >= 1e-5 * scale * size
        assert system.strain_energy(dyn.u, f) >= 1e-3
        shared.correction = correction
    dyn.set_initial(displacement=lambda x: 0.1 * x[:, :2])
    f = system.internal_force(dyn.u)
    assert max(g.norm() for g in f) >= 1e-3 * scale * max(x.norm() for x in dyn.u)
    dyn.destroy()


# --- the small-amplitude limit --------------------------------------------------------------------


@pytest.mark.parametrize("case", list(CASES))
def test_force_is_the_gradient_of_the_energy_and_tends_to_the_linear_force(case):
    """f^int = dW/du (central difference of the stored energy along a random direction, at a
    state of finite rotation plus a wavy strain: relative difference measured <= 4e-9, bound
    1e-6) and, at a small random displacement of amplitude a, f^int(u) = K u + O(a^2) with K the
    linear model's stiffness (the same coupling, LinearElastic): |f - K u| / |K u| measured
    a x (0.3 ... 2) at a = 1e-4 and 1e-3, checked below 5 a and scaling with a (ratio 10 within
    [7, 13])."""
    dyn = build(case)
    linear = build(case, LIN)
    system = dyn.system
    rng = np.random.default_rng(7 + MPI.COMM_WORLD.rank)
    R = rotation(0.4)
    dyn.set_initial(
        displacement=lambda x: x[:, :2] @ (R - np.eye(2)).T + 0.02 * np.sin(2.0 * x[:, :2])
    )
    f = system.internal_force(dyn.u)
    dirs = [x.duplicate() for x in dyn.u]
    for d, active in zip(dirs, dyn.free, strict=True):
        d.array[:] = rng.uniform(-1.0, 1.0, d.getLocalSize()) * active
    eps, energies = 1e-6, []
    for sign in (1.0, -1.0):
        for x, d in zip(dyn.u, dirs, strict=True):
            x.axpy(sign * eps, d)
        energies.append(system.strain_energy(dyn.u, None))
        for x, d in zip(dyn.u, dirs, strict=True):
            x.axpy(-sign * eps, d)
    fd = (energies[0] - energies[1]) / (2.0 * eps)
    exact = sum(g.dot(d) for g, d in zip(f, dirs, strict=True))
    assert fd == pytest.approx(exact, rel=1e-6)

    ratios = []
    for a in (1e-4, 1e-3):
        for x, y, d in zip(dyn.u, linear.u, dirs, strict=True):
            x.array[:] = a * d.array_r
            y.array[:] = a * d.array_r
        f_nl = system.internal_force(dyn.u)
        f_lin = linear.system.internal_force(linear.u)
        diff = np.sqrt(sum((p - q).norm() ** 2 for p, q in zip(f_nl, f_lin, strict=True)))
        ratios.append(diff / np.sqrt(sum(q.norm() ** 2 for q in f_lin)))
        assert ratios[-1] <= 5.0 * a
    assert 7.0 <= ratios[1] / ratios[0] <= 13.0
    dyn.destroy()
    linear.destroy()


ROD_LENGTH, ROD_HEIGHT = 20.0, 2.0


def rod(case: str, material, amplitude: float, comm=MPI.COMM_WORLD) -> ExplicitDynamics:
    """A rod 20 x 2 of unit cells, FE on x < 10 and particles (spacing 1/2) on x > 10, with
    a Gaussian pulse (centre x = 6, alpha = 0.25; E = 1, rho = 1, nu = 0) of velocity
    amplitude ``amplitude`` (= the strain amplitude, c = 1)."""
    coupling, options, dyn_options = CASES[case]
    msh = rectangle(
        comm, [0.0, 0.0], [ROD_LENGTH, ROD_HEIGHT], [20, 2], CELL_TYPES["quadrilateral"]
    )
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 10.0), 0.5)
    V = _compat.vector_function_space(msh)
    options = {"quadrature_degree": 3, **options}
    if coupling == "bridging":
        options["overlap"] = 1
    problem = coupled(V, patch, LIN_ROD, coupling, **options)
    dyn = ExplicitDynamics.coupled(problem, material=material, **dyn_options)
    pulse = GaussianPulseRod(
        E=1.0, rho=1.0, length=ROD_LENGTH, center=6.0, alpha=0.25, amplitude=amplitude
    )
    dyn.set_initial(velocity=pulse.initial_velocity)
    return dyn


LIN_ROD = mf.LinearElastic(1.0, 0.0, "strain", rho=1.0)
NH_ROD = mf.NeoHookean(E=1.0, nu=0.0, plane="strain", rho=1.0)


@pytest.mark.parametrize("case", list(CASES))
def test_small_amplitude_rod_matches_the_linear_run(case):
    """The Gaussian pulse crossing the interface (t = 8: its right half from x = 6 to x = 14,
    past the interface at x = 10) with the neo-Hookean law at strain amplitude A and with its
    linear twin, same step: the velocities differ by |v_NH - v_lin| / |v_lin| (at 60 points)
    measured 0.26 A (ramps) ... 0.31 A (master-slave) at A = 1e-3 and 1e-2, checked below
    0.6 A and scaling with A (ratio measured 10.0, checked in [9, 11])."""
    points = np.stack([np.linspace(0.5, 19.5, 30).repeat(2), np.tile([0.4, 1.6], 30)], axis=1)
    mine = points if MPI.COMM_WORLD.rank == 0 else np.zeros((0, 2))
    rel = []
    for A in (1e-3, 1e-2):
        runs, dt = [], None
        for material in (LIN_ROD, NH_ROD):  # the linear run's step for both
            dyn = rod(case, material, A)
            dt = dt or 0.5 * dyn.stable_time_step()
            dyn.run(8.0, dt)
            runs.append(MPI.COMM_WORLD.allgather(dyn.velocity_at(mine)))
            dyn.destroy()
        lin, nl = (np.concatenate(r) for r in runs)
        rel.append(np.linalg.norm(nl - lin) / np.linalg.norm(lin))
        assert rel[-1] <= 0.6 * A, (case, A, rel)
    assert 9.0 <= rel[1] / rel[0] <= 11.0, (case, rel)


# --- the spinning plate and a large-amplitude run -------------------------------------------------


def angular_momentum(dyn: ExplicitDynamics) -> float:
    local = 0.0
    for k, m in enumerate(dyn.system.mass()):
        X = dyn.evaluator.disc.owned_points(k)[:, :2]
        x = X + dyn.u[k].array_r.reshape(-1, 2)
        mv = (m.array_r * dyn.v[k].array_r).reshape(-1, 2)
        local += float(np.sum(x[:, 0] * mv[:, 1] - x[:, 1] * mv[:, 0]))
    return dyn.comm.allreduce(local, op=MPI.SUM)


def spin_quarter_turn(case: str, omega: float = 0.005) -> tuple[float, float, float]:
    """demos/spinning_plate.py's set-up (n = 4, omega = 0.005, a quarter turn at half the
    stable step): (velocity error against the rigid rotation, angular momentum drift, energy
    drift)."""
    dyn = build(case)
    dyn.set_initial(velocity=lambda x: omega * np.stack([-x[:, 1], x[:, 0]], axis=1))
    L0 = angular_momentum(dyn)
    dt = 0.5 * dyn.stable_time_step()
    result = dyn.run(0.25 * 2.0 * np.pi / omega, dt)

    def exact(x, t):
        c, s = np.cos(omega * t), np.sin(omega * t)
        return omega * np.stack([-(s * x[:, 0] + c * x[:, 1]), c * x[:, 0] - s * x[:, 1]], 1)

    err = dyn.velocity_error(exact)
    drift = abs(angular_momentum(dyn) - L0) / abs(L0)
    dyn.destroy()
    return err, drift, result.energy_drift


@pytest.mark.parametrize("case", LONG)
def test_spinning_plate(case):
    """The demo's targets: velocity error <= 1e-2 (measured 1.1e-3 ... 1.8e-3; master-slave
    with band slaves 1.6e-3, whose slaves' velocities are T(u) v at the current state: the
    reference's linear expansion T_PF v gave 5.2e-2), angular momentum drift <= 1e-10
    (measured <= 7e-15, bridging with penalty 2.5e-12) and energy drift <= 1e-6 (measured
    1.4e-7 ... 5.1e-7, band slaves 7.7e-7)."""
    err, drift, energy = spin_quarter_turn(case)
    assert err <= 1e-2, err
    assert drift <= 1e-10, drift
    assert energy <= 1e-6, energy


#: Energy drift at 0.9 x the stable step of the large-amplitude run (measured; the ratio to
#: half the step measured 4.94, 3.88, 5.17, 1.42, 3.70, 3.77).
DRIFT = {
    "ramp": 2.86e-4,
    "ramp-cubic": 2.71e-4,
    "master-slave": 2.99e-3,
    "master-slave-band": 8.80e-4,
    "bridging-penalty": 3.33e-4,
    "hybrid": 8.43e-4,
}


@pytest.mark.parametrize("case", LONG)
def test_large_amplitude_energy_drift(case):
    """A plate stretched and sheared from rest, v = 0.03 (X + Y/2, -Y) (|F - I| up to 0.37 ...
    0.72, measured), 300 steps of 0.9 x the stable step: the energy balance (kinetic + W(F))
    drifts by DRIFT (measured; bound 2x) and less at half the step, by O(dt^2): ratio measured
    3.7 ... 5.2, checked in [3, 6.5]. master-slave with band slaves is not yet in the
    asymptotic range at these steps (ratio 1.42 for 0.9 -> 0.45, 3.1 for 0.45 -> 0.225 at
    v = 0.01, measured): only its drift is bounded, and that the half step lowers it."""
    drifts = []
    for factor, steps in ((0.9, 300), (0.45, 600)):
        dyn = build(case)
        dyn.set_initial(velocity=lambda x: 0.03 * np.stack([x[:, 0] + 0.5 * x[:, 1], -x[:, 1]], 1))
        dt = factor * dyn.stable_time_step()
        result = dyn.run(steps * dt, dt)
        drifts.append(result.energy_drift)
        dyn.destroy()
    assert drifts[0] <= 2.0 * DRIFT[case], drifts
    if case == "master-slave-band":
        assert drifts[1] < drifts[0], drifts
    else:
        assert 3.0 <= drifts[0] / drifts[1] <= 6.5, drifts


# --- parallel -------------------------------------------------------------------------------------


@pytest.mark.parametrize("case", ["ramp", "master-slave-band", "bridging-penalty", "hybrid"])
def test_two_ranks_equal_serial(case):
    """The small-amplitude rod at A = 1e-2 (finite strain) on every rank and on one: the same
    steps, kinetic energy and velocities to round-off."""
    results = []
    for comm in (MPI.COMM_WORLD, MPI.COMM_SELF):
        dyn = rod(case, NH_ROD, 1e-2, comm)
        res = dyn.run(4.0)
        pts = np.array([[5.0, 1.0], [9.9, 0.1], [14.3, 1.9]])
        v = dyn.velocity_at(pts if comm.rank == 0 else np.zeros((0, 2)))
        results.append((res.steps, res.energies[-1].kinetic, res.energies[-1].internal, v))
        dyn.destroy()
    (s1, k1, w1, v1), (s2, k2, w2, v2) = results
    assert s1 == s2
    assert k1 == pytest.approx(k2, rel=1e-10) and w1 == pytest.approx(w2, rel=1e-10)
    if MPI.COMM_WORLD.rank == 0:
        assert np.allclose(v1, v2, rtol=1e-9, atol=1e-14)
