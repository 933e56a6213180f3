# # A spinning plate: explicit dynamics at finite strain, with a particle patch inside
#
# A free square plate [-a, a]^2 of compressible neo-Hookean material (plane strain), with a
# square patch of particles in its centre (|x|, |y| < a/2), is given the velocity of a rigid
# rotation about its centre, v0 = omega e_z x X = omega (-Y, X), and left alone. In the total
# Lagrangian frame (Rabczuk et al. 2006, eq. 1–5, 34) a rigid rotation F = R costs no energy
# (W(R) = W(I) = 0, P(R) = 0), so the plate keeps rotating; the only strain is the centrifugal
# stretching that supplies the centripetal acceleration. At time t the exact rigid motion has,
# at the material point X (the reference configuration, where every field lives),
#
#     v(X, t) = omega e_z x (R(omega t) X).
#
# The small-strain model (LinearElastic, f = K d) cannot rotate: its linearised rotation
# d = theta e_z x X is a zero-energy mode, so the plate keeps the initial velocity field; after a
# quarter turn its error is |R(pi/2) - I| = sqrt(2), O(1). The demo shows both.
#
#     python demos/spinning_plate.py [--method lagrange fe efg edge-to-edge bridging ramp
#         ramp-cubic master-slave hybrid] [--n 8]
#         [--omega 0.005] [--turns 0.25] [--json F]
#     mpirun -n 2 python demos/spinning_plate.py
#
# Reported per method and model: the relative L2 velocity error against the rigid rotation at
# the end (Rabczuk et al. 2006, eq. 137), the largest strain energy over the run relative to the
# kinetic energy, the angular momentum drift (relative) and the energy drift (the balance of
# kinetic + W(F), relative to the total energy).
#
# How small the strain energy must be (the bound checked): the centripetal acceleration omega^2 r
# is supplied by a stress of at most sigma <= rho omega^2 R^2 (R = sqrt(2) a the largest radius,
# integrating rho omega^2 r from the centre to the edge), reached from a stress-free start:
# an undamped suddenly applied load overshoots to twice the static strain, four times its
# energy. With W <= (1 + nu) |sigma|^2 / E per unit volume (|sigma|^2 <= 2 sigma^2 for the two
# in-plane principal stresses) and the kinetic energy 1/2 rho omega^2 J, J = int r^2 dA =
# (2/3) a^2 |A|, this gives
#
#     W / KE <= 4 (1 + nu) 2 (rho omega^2 R^2)^2 / E / (rho omega^2 (2/3) a^2)
#            = 48 (1 + nu) rho omega^2 a^2 / E.
#
# The velocity error has the same origin: the stretching oscillates radially (breathing) with
# a velocity of order eps c with eps = rho omega^2 R^2 / E, i.e. relative to omega R of order
# omega R / c (c the wave speed); omega is chosen so that omega R / c is about 0.6 %.

# +
from __future__ import annotations

import argparse
import json
import time

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import FINITE_STRAIN_DYNAMICS, ExplicitDynamics

import dolfinx
import numpy as np
from mpi4py import MPI

METHODS = FINITE_STRAIN_DYNAMICS
# targets of the issue (the energy drift one measured against dt refinement, see below)
TARGETS = {"velocity_error": 0.01, "momentum_drift": 1e-10, "energy_drift": 1e-6}
# -


# ## The model
#
# One mesh of n x n quadrilaterals; the patch cells (centre inside |x|, |y| < a/2) carry
# particles at half the element size. The finite-strain model is NeoHookean, the small-strain
# one its linear twin (same E, nu, rho); couplings are built on the linear twin
# (CoupledElasticity) and take the finite-strain law through ExplicitDynamics.coupled(material=).


# +
def build(method: str, material, n: int, a: float) -> ExplicitDynamics:
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.array([-a, -a]), np.array([a, a])], [n, n], dolfinx.mesh.CellType.quadrilateral
    )
    V = _compat.vector_function_space(msh)
    spacing = a / n  # half the element size 2a/n
    if method == "fe":
        return ExplicitDynamics.fe(V, material)
    if method == "efg":
        return ExplicitDynamics.efg(mf.ParticleSet.from_cells(msh, spacing), material)
    ncell = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:ncell], :2].mean(axis=1)
    cells = np.flatnonzero(np.all(np.abs(xc) < 0.5 * a, axis=1))
    patch = mf.ParticlePatch(msh, cells, spacing)
    linear = mf.LinearElastic(material.E, material.nu, material.plane, rho=material.rho)
    # the ramps in dynamics: plain Gauss integration (no VCI) and supports over the interface
    # cells wide enough for positive row-sum particle masses (dilation 4: 3.5 gives a negative
    # one at n = 8)
    if method == "hybrid":  # SPH-FE, HA-F with smoothed strains
        return ExplicitDynamics.coupled(mf.HybridElasticity(V, patch, linear), material=material)
    options = {"consistent": False, "dilation": 4.0} if method.startswith("ramp") else {}
    problem = mf.CoupledElasticity(V, patch, linear, coupling=method, **options)
    return ExplicitDynamics.coupled(problem, material=material)


def angular_momentum(dyn: ExplicitDynamics) -> float:
    """``L = sum_I m_I (X_I + d_I) x v_I`` over the dofs of every field with ``d_n`` and
    ``v_{n-1/2}`` (the state after a run): the discrete angular momentum central differences
    keep, since ``x_n x v_{n+1/2} = x_{n+1} x v_{n+1/2}`` and the internal and constraint forces
    have no moment about the current positions (collective)."""
    local = 0.0
    for k, m in enumerate(dyn.system.mass()):
        X = dyn.evaluator.disc.owned_points(k)[:, :2]
        x = X + dyn.u[k].array_r.reshape(-1, 2)
        mv = (m.array_r * dyn.v[k].array_r).reshape(-1, 2)
        local += float(np.sum(x[:, 0] * mv[:, 1] - x[:, 1] * mv[:, 0]))
    return dyn.comm.allreduce(local, op=MPI.SUM)


def run(method: str, model: str, args) -> dict:
    comm = MPI.COMM_WORLD
    nh = mf.NeoHookean(E=args.E, nu=args.nu, plane="strain", rho=args.rho)
    material = nh if model == "neo-Hookean" else mf.LinearElastic(
        args.E, args.nu, "strain", rho=args.rho)  # fmt: skip
    omega, a = args.omega, args.a
    t0 = time.perf_counter()
    dyn = build(method, material, args.n, a)
    dyn.set_initial(velocity=lambda x: omega * np.stack([-x[:, 1], x[:, 0]], axis=1))
    L0 = angular_momentum(dyn)
    t_end = args.turns * 2.0 * np.pi / omega
    dt = None if args.dt_factor == 1.0 else args.dt_factor * dyn.stable_time_step()
    result = dyn.run(t_end, dt, energy_records=200)

    def exact(x: np.ndarray, t: float) -> np.ndarray:
        c, s = np.cos(omega * t), np.sin(omega * t)
        rx = c * x[:, 0] - s * x[:, 1]
        ry = s * x[:, 0] + c * x[:, 1]
        return omega * np.stack([-ry, rx], axis=1)

    err = dyn.velocity_error(exact)
    L1 = angular_momentum(dyn)
    kin = np.array([r.kinetic for r in result.energies])
    strain = np.array([r.internal for r in result.energies])
    out = {
        "method": method,
        "model": model,
        "n": args.n,
        "omega": omega,
        "turns": args.turns,
        "dt": result.dt,
        "steps": result.steps,
        "bounds": int(result.critical.get("bounds", 1)),
        "velocity_error": err,
        "strain_over_kinetic": float(np.max(strain / kin)),
        "strain_bound": 48.0 * (1.0 + args.nu) * args.rho * omega**2 * a**2 / args.E,
        "momentum_drift": abs(L1 - L0) / abs(L0),
        "energy_drift": result.energy_drift,
        "time": comm.allreduce(time.perf_counter() - t0, op=MPI.MAX),
    }
    dyn.destroy()
    return out


# -


# ## Table and checks
#
# The energy drift of central differences is exact (round-off) for a linear system only; for a
# nonlinear internal force the discrete energy is conserved to O(dt^2). `--dt-factor 0.5`
# halves the step to show it.


# +
def main(argv: list[str] | None = None) -> list[dict]:
    """Run, print the table, write the JSON; raise ``SystemExit(1)`` when a check fails."""
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--method", nargs="+", default=["lagrange"], choices=METHODS)
    p.add_argument("--n", type=int, default=8, help="cells per side")
    p.add_argument("--a", type=float, default=1.0, help="half width")
    p.add_argument("--omega", type=float, default=0.005)
    p.add_argument("--turns", type=float, default=0.25)
    p.add_argument("--E", type=float, default=1.0)
    p.add_argument("--nu", type=float, default=0.3)
    p.add_argument("--rho", type=float, default=1.0)
    p.add_argument("--dt-factor", type=float, default=1.0, help="dt / stable step")
    p.add_argument("--no-linear", action="store_true", help="skip the small-strain runs")
    p.add_argument("--json", default=None)
    p.add_argument("--no-check", action="store_true")
    args = p.parse_args(argv)
    comm = MPI.COMM_WORLD
    models = ["neo-Hookean"] + ([] if args.no_linear else ["small strain"])
    records = [run(m, model, args) for m in args.method for model in models]
    c = mf.NeoHookean(E=args.E, nu=args.nu, plane="strain", rho=args.rho).wave_speed()
    if comm.rank == 0:
        print(
            f"Spinning plate, a = {args.a:g}, n = {args.n}, omega = {args.omega:g} "
            f"(omega R / c = {args.omega * np.sqrt(2) * args.a / c:.2e}), {args.turns:g} turn, "
            f"{comm.size} rank(s)"
        )
        cols = (
            "method        model          steps  bounds  vel err   W/KE max  (bound)   "
            "L drift   E drift    time s"
        )
        print(cols)
        print("-" * len(cols))
        for r in records:
            print(
                f"{r['method']:13s} {r['model']:13s} {r['steps']:6d} {r['bounds']:7d} "
                f"{r['velocity_error']:8.2e} {r['strain_over_kinetic']:9.2e} "
                f"{r['strain_bound']:9.2e} {r['momentum_drift']:9.2e} {r['energy_drift']:9.2e} "
                f"{r['time']:8.1f}"
            )
        if args.json:
            with open(args.json, "w") as f:
                json.dump(records, f, indent=1)
    failures = []
    if not args.no_check:
        for r in records:
            name = f"{r['method']} ({r['model']})"
            if r["model"] == "small strain":
                if not r["velocity_error"] > 0.5:  # sqrt(2) after a quarter turn
                    failures.append(f"{name}: velocity error {r['velocity_error']:.2e} not O(1)")
                continue
            if not r["strain_over_kinetic"] <= r["strain_bound"]:
                failures.append(f"{name}: W/KE {r['strain_over_kinetic']:.2e} above the bound")
            for key, target in TARGETS.items():
                if not r[key] <= target:
                    failures.append(f"{name}: {key} {r[key]:.2e} > {target:.0e}")
    if failures:
        if comm.rank == 0:
            print("FAILED:\n  " + "\n  ".join(failures))
        raise SystemExit(1)
    return records


if __name__ == "__main__":
    main()
# -
