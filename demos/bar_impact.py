# # Two bars meet head on: contact between bodies in explicit dynamics
#
# Two identical steel bars, each ``L = 0.1 m`` long and ``H = 0.01 m`` high (plane strain,
# ``nu = 0``: the 2D field is uniaxial and the 1D wave solution exact; ``--cell hexahedron`` or
# ``tetrahedron``: 3D bars of section ``H x H``), fly at each other at ``+-v0``
# (``--velocity``, default 10 m/s). From the moment they touch they press on each other
# with the stress ``sigma = rho c v0`` (the force ``rho c v0 H`` per unit thickness) for the time
# ``2 L / c`` the waves take to run to the far ends and back; then they part, their velocities
# reversed and no energy left in them (Graff, *Wave Motion in Elastic Solids*, sec. 1.4).
#
# The bars are two pieces of one mesh: a rectangle (box) less one column of cells
# (``mf.submesh``), the right bar then moved to a gap of 0.02 cells. The contact
# (``ExplicitDynamics.add_contact``, :mod:`dolfinx_meshfree.dynamics.body_contact`) is a
# node-to-facet penalty on the normal gap between the bars' facing ends, two-pass, with the
# penalty ``k = E / h`` per unit area (the default ``BodyContact()``). Each method
# (``--method``) discretises the bars its way:
#
# * ``fe``: Q1 elements on both bars;
# * every coupling of ``mf.dynamics.DYNAMICS_METHODS`` (in 3D: lagrange, edge-to-edge,
#   bridging): particles (spacing h) on the left bar's last 0.3 L, at the contact, coupled to
#   its FE cells; the right bar FE. So the contact presses particles (the MLS approximation at
#   the left bar's end vertices; the hybrid's, HA-F, SPH interpolant) against FE;
# * ``efg``: particles at the nodes of both bars, pure EFG. The gap (0.02 h) is far narrower
#   than the supports, but each bar's MLS is its own (the model cuts it at the gap:
#   ``mf.separate_bodies``), so particles press on particles.
#
# Printed per method: the force's plateau against ``rho c v0 H`` (3D: ``rho c v0 H^2``; the
# left bar's impulse over 0.2-1.8 L/c after touching); the contact's duration against
# ``2 L / c``; the mean velocity of each bar after parting against ``-+v0`` (the share of the
# impact left in the bars as ringing, which falls with h); the deepest penetration in cells;
# the drift of the energy balance (kinetic + strain + penalty; the contact's start and end are
# not smooth, so it falls with the step); the stable step with contact against the step
# without; the steps, the loop's time and the contact's share of it, and the time against FE.
# The run fails if a figure leaves its stated margin (about 2x what is measured at the default
# resolution, ``tests/test_body_contact.py``). At high speed (``--velocity 1060``: v0 / c = 0.2)
# the couplings fail them, and say so: the particle face tilts and slides off the FE face (the
# guide's dynamics page, contact between bodies, has the figures; not resolved).
#
# Usage:
#
#     python demos/bar_impact.py [--method fe lagrange ...] [--cells 40] [--velocity 10]
#         [--cell quadrilateral|triangle|hexahedron|tetrahedron] [--json out.json]
#     mpirun -n 2 python demos/bar_impact.py

# +
from __future__ import annotations

import argparse
import json
import sys

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import DYNAMICS_METHODS, ExplicitDynamics

import dolfinx
import numpy as np
from mpi4py import MPI

STEEL = mf.LinearElastic(210e9, 0.0, "strain", rho=7850.0)
STEEL_3D = mf.LinearElastic(210e9, 0.0, None, rho=7850.0)
CELLS = ["quadrilateral", "triangle", "hexahedron", "tetrahedron"]
LENGTH, HEIGHT = 0.1, 0.01
METHODS = list(DYNAMICS_METHODS)
#: The checks' margins (measured at 40 cells and at 20, the tests': see the module header).
MARGINS = {"force": 0.03, "duration_cells": 4.0, "exit": 0.07, "penetration": 0.025, "drift": 0.012}
# -


# ## The mesh: two bars, one mesh


def split_mesh(comm, n, length=LENGTH, height=HEIGHT, gap=0.02, cell="quadrilateral"):
    """Two bars ``[0, length]`` and ``[length + gap h, 2 length + gap h]`` of section
    ``[0, height]`` (2D; 3D: ``[0, height]^2``), ``n`` cells along x each (``h = length / n``),
    as one mesh: a rectangle (box) of ``2 n + 1`` columns less the middle one
    (``mf.submesh``), the right bar moved left by ``(1 - gap) h``. ``cell``: quadrilateral,
    triangle, hexahedron or tetrahedron. Returns the mesh, ``h`` and the gap."""
    h = length / n
    m = max(1, round(height / h))
    cell_type = getattr(dolfinx.mesh.CellType, cell)
    if cell in ("hexahedron", "tetrahedron"):
        corner = np.array([2 * length + h, height, height])
        big = dolfinx.mesh.create_box(comm, [np.zeros(3), corner], [2 * n + 1, m, m], cell_type)
    else:
        corner = np.array([2 * length + h, height])
        big = dolfinx.mesh.create_rectangle(comm, [np.zeros(2), corner], [2 * n + 1, m], cell_type)
    tdim = big.topology.dim
    ncells = big.topology.index_map(tdim).size_local
    mid = dolfinx.mesh.compute_midpoints(big, tdim, np.arange(ncells, dtype=np.int32))
    keep = np.flatnonzero(np.abs(mid[:, 0] - (length + h / 2)) > h / 2).astype(np.int32)
    msh = mf.submesh(big, keep)
    x = msh.geometry.x
    x[x[:, 0] > length + h / 4, 0] -= h * (1.0 - gap)
    return msh, h, gap * h


# ## The model: each method, the contact, the initial velocities


def build(method, n, comm=MPI.COMM_WORLD, material=STEEL, length=LENGTH, height=HEIGHT,
          v0=10.0, contact=None, cell="quadrilateral"):  # fmt: skip
    """The two bars at ``+-v0`` with contact on their facing ends; with a coupling, particles
    on the left bar's last 0.3 length. Returns the model, ``h`` and the gap."""
    msh, h, gap = split_mesh(comm, n, length, height, cell=cell)
    tdim = msh.topology.dim
    left_end = mf.boundary_facets(msh, lambda x: np.isclose(x[0], length))
    right_end = mf.boundary_facets(msh, lambda x: np.isclose(x[0], length + gap))
    V = _compat.vector_function_space(msh)
    if method == "fe":
        dyn = ExplicitDynamics.fe(V, material)
    elif method == "efg":  # particles at the nodes of both bars: each body's MLS its own
        dyn = ExplicitDynamics.efg(mf.ParticleSet.from_vertices(msh), material)
    else:
        ncells = msh.topology.index_map(tdim).size_local
        mid = dolfinx.mesh.compute_midpoints(msh, tdim, np.arange(ncells, dtype=np.int32))
        cells = np.flatnonzero((mid[:, 0] > 0.7 * length) & (mid[:, 0] < length))
        patch = mf.ParticlePatch(msh, cells, h)
        if method == "hybrid":  # SPH particles at the contact (HA-F), its sums cut at the gap
            problem = mf.HybridElasticity(V, patch, material, variant="HA-F")
        else:
            problem = mf.CoupledElasticity(V, patch, material, coupling=method)
        dyn = ExplicitDynamics.coupled(problem)
    dyn.critical_time_step()  # the step without contact, kept for the table
    without = dyn.critical_time_step()["critical"]
    dyn.add_contact(left_end, right_end, contact)
    dyn.step_without_contact = without

    def velocity(x):
        v = np.zeros_like(x)
        v[:, 0] = np.where(x[:, 0] < length + gap / 2, v0, -v0)
        return v

    dyn.set_initial(velocity=velocity)
    return dyn, h, gap


def left_momentum(dyn, split):
    """The x momentum of the left bar: the lumped masses times v_n of the dofs (FE nodes,
    particles) at x < split (mid-gap: the bar's end nodes sit at x = length up to round-off),
    summed over the ranks."""
    disc = dyn.evaluator.disc
    total = 0.0
    for k, (f, v) in enumerate(zip(dyn.fields, dyn.stepper.current_velocity(), strict=True)):
        left = disc.owned_points(k)[:, 0] < split
        gdim = disc.gdim
        total += np.dot(f.mass.array_r[0::gdim][left], v.array_r[0::gdim][left])
    return dyn.comm.allreduce(total)


def mean_velocities(dyn, length=LENGTH):
    """The mean x velocity (v_n) of the left and the right bar, by cell quadrature."""
    q, vals = dyn.evaluator.at_quadrature(dyn.stepper.current_velocity(), 3)
    out = []
    for m in (q.points[:, 0] < length, q.points[:, 0] > length):
        s = dyn.comm.allreduce(np.array([np.sum(q.weights[m] * vals[m, 0]), q.weights[m].sum()]))
        out.append(s[0] / s[1])
    return np.array(out)


# ## The run: the force's history at 240 outputs, through parting


def impact(method, n=40, comm=MPI.COMM_WORLD, material=STEEL, length=LENGTH, height=HEIGHT,
           v0=10.0, contact=None, dt=None, force=False, cell="quadrilateral"):  # fmt: skip
    """Run the bars through the impact (to ``t0 + 2.4 length / c``, ``t0`` the touching time).

    Returns a dict: ``hist`` rows ``(t, x force of the right bar on the left, deepest
    penetration, the left bar's x momentum)`` at the outputs; ``mean`` the bars' mean
    velocities over ``v0`` after; ``drift`` the energy balance's largest change over the
    initial energy; ``ke_after`` the kinetic energy after over before; ``t0``, ``h``, ``dt``,
    ``steps``, ``seconds`` (the loop), ``contact_seconds``, ``critical`` and
    ``critical_without`` (the critical steps with and without contact)."""
    dyn, h, gap = build(method, n, comm, material, length, height, v0, contact, cell)
    c = material.wave_speed()
    t0 = gap / (2 * v0)
    t_end = t0 + 2.4 * length / c
    hist = []

    def out(d, step, t):
        force = d.system.contact_force(d.u)[0]
        hist.append((t, force, d.system.last["penetration"], left_momentum(d, length + gap / 2)))

    outputs = list(np.linspace(0.0, t_end, 241))
    res = dyn.run(t_end, dt, force=force, outputs=outputs, on_output=out)
    e0 = res.energies[0].kinetic
    drift = max(abs(r.kinetic + r.internal - r.external - r.constraint - e0) for r in res.energies)
    result = {
        "method": method,
        "dim": dyn.evaluator.disc.gdim,
        "t0": t0,
        "hist": np.array(hist),
        "h": h,
        "mean": mean_velocities(dyn, length) / v0,
        "drift": drift / e0,
        "ke_after": res.energies[-1].kinetic / e0,
        "steps": res.steps,
        "dt": res.dt,
        "seconds": res.timings["steps"],
        "contact_seconds": dyn.system.seconds,
        "critical": dyn.critical_time_step()["critical"],
        "critical_without": dyn.step_without_contact,
    }
    dyn.destroy()
    return result


def plateau_force(result, length=LENGTH, c=None):
    """The mean contact force on the left bar from 0.2 to 1.8 ``length / c`` after t0: its
    momentum's change over that time (the exact impulse of the steps between, which sampling
    the ringing force at the outputs would alias)."""
    c = STEEL.wave_speed() if c is None else c
    hist, t0 = result["hist"], result["t0"]
    ia, ib = (int(np.argmin(np.abs(hist[:, 0] - (t0 + s * length / c)))) for s in (0.2, 1.8))
    return (hist[ib, 3] - hist[ia, 3]) / (hist[ib, 0] - hist[ia, 0])


def plateau(result, column, length=LENGTH, c=None):
    """The mean of a history column over the plateau, 0.2 to 1.8 ``length / c`` after t0."""
    c = STEEL.wave_speed() if c is None else c
    hist, t0 = result["hist"], result["t0"]
    on = (hist[:, 0] > t0 + 0.2 * length / c) & (hist[:, 0] < t0 + 1.8 * length / c)
    return hist[on, column].mean()


def figures(result, material=STEEL, length=LENGTH, height=HEIGHT, v0=10.0):
    """The figures of one run against the 1D solution (relative errors; the duration error in
    cells' transit times ``h / c``)."""
    c = material.wave_speed()
    section = height ** (result["dim"] - 1)  # per unit thickness in 2D
    hist = result["hist"]
    touching = hist[hist[:, 1] < 0.0, 0]
    duration = touching.max() - touching.min() if touching.size else 0.0
    return {
        "force": plateau_force(result, length, c) / -(material.rho * c * v0 * section) - 1.0,
        "duration_cells": (duration - 2 * length / c) / (result["h"] / c),
        "exit": float(np.max(np.abs(result["mean"] - [-1.0, 1.0]))),
        "penetration": float(hist[:, 2].max() / result["h"]),
        "drift": result["drift"],
        "parted": bool(hist[-1, 1] == 0.0),
    }


# ## The table, the checks, the JSON


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Two bars meet head on: contact between bodies")
    p.add_argument("--method", nargs="+", default=METHODS, choices=METHODS)
    p.add_argument("--cells", type=int, default=40, help="cells along each bar")
    p.add_argument("--velocity", type=float, default=10.0, help="each bar's speed (m/s)")
    p.add_argument("--cell", default="quadrilateral", choices=CELLS, help="3D: a square section")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    comm = MPI.COMM_WORLD
    material = STEEL_3D if args.cell in ("hexahedron", "tetrahedron") else STEEL
    options = dict(material=material, v0=args.velocity, cell=args.cell)
    impact("fe", 4, **options)  # compile the FE forms and the kernels first: times exclude JIT
    rows, failed = [], []
    header = (
        f"{'method':<14}{'force':>9}{'duration':>10}{'exit v':>9}{'pen/h':>8}{'drift':>9}"
        f"{'dt/dt0':>8}{'steps':>7}{'time s':>8}{'contact':>9}{'vs fe':>7}"
    )
    for method in args.method:
        r = impact(method, args.cells, **options)
        f = figures(r, material, v0=args.velocity)
        rows.append({**f, "method": method, "steps": r["steps"], "seconds": r["seconds"],
                     "contact_seconds": r["contact_seconds"], "dt": r["dt"],
                     "critical": r["critical"], "critical_without": r["critical_without"],
                     "mean": r["mean"].tolist(), "ke_after": r["ke_after"]})  # fmt: skip
        for key, margin in MARGINS.items():
            if abs(f[key]) > margin:
                failed.append(f"{method}: {key} {f[key]:+.3g} beyond {margin}")
        if not f["parted"]:
            failed.append(f"{method}: the bars did not part")
    fe_time = next((r["seconds"] for r in rows if r["method"] == "fe"), None)
    if comm.rank == 0:
        print(
            f"two bars at +-{args.velocity} m/s, {args.cells} {args.cell} columns each, "
            f"{comm.size} rank(s)"
        )
        print(header)
        for r in rows:
            ratio = f"{r['seconds'] / fe_time:.2f}x" if fe_time else "-"
            print(
                f"{r['method']:<14}{r['force']:>+9.2%}{r['duration_cells']:>+9.2f}h"
                f"{r['exit']:>9.2%}{r['penetration']:>8.4f}{r['drift']:>9.1e}"
                f"{r['critical'] / r['critical_without']:>8.2f}{r['steps']:>7d}"
                f"{r['seconds']:>8.2f}{r['contact_seconds'] / r['seconds']:>9.0%}{ratio:>7}"
            )
        print("force: plateau vs rho c v0 H (3D: H^2); duration: vs 2L/c in h/c; exit v: |mean v| "
              "vs v0; dt/dt0: the critical step with contact over without")  # fmt: skip
        if args.json:
            with open(args.json, "w") as fh:
                json.dump({"cells": args.cells, "cell": args.cell, "velocity": args.velocity,
                           "ranks": comm.size, "margins": MARGINS, "rows": rows},
                          fh, indent=1)  # fmt: skip
        for line in failed:
            print("FAILED", line)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
