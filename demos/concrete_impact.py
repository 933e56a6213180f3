# # A concrete bar thrown against a wall: the Holmquist–Johnson–Cook concrete in explicit dynamics
#
# A bar of the 48 MPa concrete of Holmquist, Johnson & Cook (``mf.HolmquistJohnsonCook.
# concrete_48mpa``), ``L = 0.1 m`` long and ``H = 0.02 m`` high, plane strain, on rollers along
# its long sides (``u_y = 0``: a state of uniaxial strain, the 1D wave problem), flies at ``v0``
# (``--velocity``) against a wall at ``x = 0`` (its end held) for 20 microseconds. The concrete
# is a rate-form law at finite strain (:mod:`dolfinx_meshfree.physics.hjc`): a point's stress is
# integrated step by step from its deformation gradients (Jaumann rate), its pressure from the
# crush-and-lock equation of state, its strength from the pressure, the damage and the rate, its
# damage from the plastic and crushing strain. ``--method fe`` runs it on Q1 elements, ``efg``
# on particles (spacing h), and ``lagrange``, ``edge-to-edge``, ``bridging``, ``master-slave``,
# ``ramp``, ``ramp-cubic`` or ``hybrid`` on particles in the quarter of the bar at the wall,
# where it crushes and fails, coupled to Q1 elements beyond (all through
# :mod:`dolfinx_meshfree.dynamics.rate_forms`).
#
# Printed per method and speed: the steps, the step and the loop's time per step; the energy
# balance ``(kinetic + stress work - initial kinetic) / initial kinetic`` (the wall does no work;
# the stress work holds the bulk viscosity's); the depth from the wall to which the concrete
# crushed (plastic volumetric strain), was half damaged (``D >= 0.5``) and failed (``D >=
# 0.99``), and the largest damage. At 0.5 m/s the bar stays elastic (asserted from the
# state), and the stress behind the wave front at ``t = L / 2c`` is the 1D solution ``sigma_xx =
# -rho c v0``, ``c = sqrt((K_e + 4 G / 3) / rho)`` (Graff, *Wave Motion in Elastic Solids*, sec.
# 1.4): its mean over the points with ``x < 0.3 L`` is printed against it. The time per step
# is printed against FE's and pure EFG's. The run fails if a figure leaves its stated margin
# (about 2x what is measured at 40 cells; every method's depths are compared with pure EFG's,
# within 2, 2 and 4 cells, ``MARGINS``).
#
# At 300 m/s (``--velocity 300``) on rollers the front is a shock. The concrete's bulk viscosity
# (``mf.BulkViscosity``, on by default: von Neumann and Richtmyer's, LS-DYNA's coefficients)
# spreads it over a few cells; behind it the damage settles on a plateau (0.71 FE, 0.72 EFG at
# 40 cells) that the mesh and the step leave in place, and every method damages the bar to
# ``D >= 0.5`` to 52 mm (51.7-52.0 at 40 cells; FE 53.9, 52.0 and 53.5 mm at 20, 40 and 80
# cells; 52.0 at 1, 0.5 and 0.25 of the stable step: ``tests/test_bulk_viscosity.py``). No FE
# point fails (``D >= 0.99``); the particles fail a layer at the held wall, where the shock
# starts from the velocity jump of ``t = 0``, that thins with the spacing (EFG 13.3, 10.2 and
# 3.3 mm at 20, 40 and 80 cells; lagrange 13.3, 6.7 and 3.3 mm): the demo's check flags it (FE
# and EFG 4.1 cells apart at 40 cells). Without the viscosity (``viscosity=None``) the front
# rang, the damage behind it alternated from cell to cell and the deepest failed point moved
# with the step (FE 37.0 mm at the stable step, 17.0 at 0.6 of it). With free sides (``--sides
# free``: no longer uniaxial, so no 1D check) every method fails to within half a cell of EFG
# (40 cells: FE 27.0, EFG 25.8, lagrange 25.5, its grown patch 26.7 mm).
#
# **Particles only where the concrete fails** (``--method lagrange-adaptive``, also
# ``edge-to-edge-adaptive`` and ``bridging-adaptive``): the run starts with one column of
# particle cells at the wall and ``mf.dynamics.AdaptiveRun`` turns every FE cell whose damage
# reaches 0.1 at a Gauss point (``mf.StateAbove("damage", 0.1)``, checked every 5 steps) into
# particles, which carry its points' state and stress (``dynamics.rate_forms.carry_state``). The
# row adds the conversions, the particle cells at the end, the largest mass error and momentum
# correction of a conversion (checked below 1e-13 and, lagrange and edge-to-edge, whose fit
# conserves momentum by itself, 1e-12) and the kinetic and strain energy
# the conversions changed (the balance counts them), and the largest change of the velocity at
# the old particles a conversion's fit made (``Conversion.velocity_change``, over their
# largest speed: 2-8 % at 100 m/s on rollers, 3-13 % at 300 m/s with free sides, 40 cells).
# Its time includes the conversions; ``vs EFG`` then compares whole runs (``s total``), the
# cost the issue asks about. With free sides the grown models fail to within a cell of EFG
# (300 m/s, 40 cells: 26.7 mm against 25.8, 15 conversions), at 3.3-4.5x EFG's time on this bar
# (three quarters of it the conversions' full rebuilds). On rollers at 100 m/s they fail points
# of their first column at the wall, where EFG fails none (40 cells: lagrange, edge-to-edge and
# master-slave to 2.33 mm, bridging 7.33, the ramp 4.83, the hybrid 0.63; at 20 cells
# lagrange's fails none, the others to 1.25-14.65 mm). The check below names it ("fails
# concrete where EFG fails none"); a known limit, not resolved (guide: impact materials).
#
# **The ramps** (``--method ramp``, ``ramp-cubic``, and their ``-adaptive`` runs; not in the
# default run): the interface cells' blended points carry their own state. At 0.5 m/s the
# stress is the 1D solution's within 1.2 % at 40 cells (1.9 % at 20). On rollers at 100 m/s
# they fail no concrete, as EFG (before the bulk viscosity they failed the first row of points
# at the held wall). With free sides at 300 m/s they fail to 27.3 mm (EFG 25.8), grown from the
# wall to 25.8 mm; a conversion's fit misses up to 2.2e-4 of the momentum (the blended cells are
# not a partition of unity on the particle side; restored and reported, not checked).
#
# **Master–slave** (``--method master-slave``): the particles' points carry the state, the
# particle field reduced to the masters (Rabczuk et al. 2006, eq. 27). At 0.5 m/s the stress is
# the 1D solution's within 0.04 % (40 cells); at 100 m/s on rollers it fails no concrete, as
# EFG; with free sides at 300 m/s it fails to 25.5 mm (EFG 25.8), grown from the wall to 27.3 mm;
# its conversions' fit misses up to 1.6e-4 of the momentum (the masters' functions miss the
# slaves' share; restored and reported, not checked).
#
# **The hybrid** (``--method hybrid``, HA-F: the SPH sums of the nominal stress; ``rho V_I``
# particle masses; not in the default run): at 0.5 m/s the stress is the 1D solution's within
# 1.0 % at 40 cells (1.6 % at 20); at 100 m/s on rollers it fails no concrete, as EFG; with free
# sides at 300 m/s it fails to 28.0 mm (EFG 25.8) at 0.94x EFG's time. ``hybrid-adaptive`` grows
# its SPH patch from the wall (Sauer's adaptive conversion, Rabczuk et al. 2006, sec. 5.5): a
# particle kept by a conversion keeps its values, a new one samples the old field (no fit: SPH
# particles carry their values); 19 conversions at 40 cells, failed to 29.4 mm, the samples
# miss up to 2.0e-3 of the momentum (restored and reported, not checked) and change the
# kinetic energy by -0.26 % of the initial in all (counted in the balance).
#
# The Hanchak slab: ``demos/hanchak.py``. The projectile's contact with a converting target:
# ``tests/test_bodies.py``.
#
# Usage:
#
#     python demos/concrete_impact.py [--method fe efg lagrange ...] [--cells 40]
#         [--velocity 0.5 100] [--sides rollers|free] [--json out.json]
#     mpirun -n 2 python demos/concrete_impact.py

# +
from __future__ import annotations

import argparse
import json
import sys

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
from mpi4py import MPI

LENGTH, HEIGHT, T_END = 0.1, 0.02, 2e-5
CONCRETE = mf.HolmquistJohnsonCook.concrete_48mpa(plane="strain")
COUPLINGS = ["lagrange", "edge-to-edge", "bridging", "ramp", "ramp-cubic", "master-slave", "hybrid"]
#: A coupling with "-adaptive": particles grow from the wall where the concrete fails.
ADAPTIVE = [f"{m}-adaptive" for m in COUPLINGS]
METHODS = ["fe", "efg", *COUPLINGS, *ADAPTIVE]
#: The default run (the grown patches fail on rollers at 100 m/s, and the ramps, whose wider
#: supports (dilation 2.5) strain the points at the held wall: see the header).
DEFAULT_METHODS = ["fe", "efg", "lagrange", "edge-to-edge", "bridging", "master-slave"]
#: Damage at a Gauss point that turns its FE cell into particles (adaptive methods).
CONVERT_AT = 0.1
#: Elastic speeds (m/s): the 1D stress check applies.
ELASTIC = 1.0
MARGINS = {
    "balance": 0.016,  # |balance| (measured up to 0.79 % at 300 m/s, EFG)
    "elastic_stress": 0.02,  # |mean sigma_xx / (-rho c v0) - 1| (measured 0.5 % FE, 1.1 % EFG)
    "crushed_cells": 2.0,  # |method - EFG| crushed depth, in cells (measured up to 0.5)
    "damaged_cells": 2.0,  # |method - EFG| depth of D >= 0.5, in cells (measured up to 0.9)
    # |method - EFG| failed depth, in cells (measured up to 1.9 before the bulk viscosity; with
    # it the particles' wall layer, header: FE 4.1 cells from EFG at 300 m/s on rollers)
    "failed_cells": 4.0,
    "mass": 1e-13,  # a conversion's mass error (round-off: measured up to 2e-16)
    # the momentum a conversion's fit missed (restored by a uniform velocity), lagrange and
    # edge-to-edge: their fit conserves it (measured up to 2.5e-16); bridging's band masses
    # make its fit miss up to 1.8e-5, the ramps' blended interface cells (not a partition of
    # unity on the particle side) 2.7e-4 (reported, not checked)
    "momentum": 1e-12,
}
# -


def wave_speed(law: mf.HolmquistJohnsonCook) -> float:
    """The elastic dilatational speed of region I."""
    return float(np.sqrt((law.K_elastic + 4.0 * law.G / 3.0) / law.rho))


def build(
    method: str,
    cells: int,
    comm=MPI.COMM_WORLD,
    sides: str = "rollers",
    msh: dolfinx.mesh.Mesh | None = None,
    patch_cells: np.ndarray | None = None,
    law: object | None = None,
) -> mf.ExplicitDynamics:
    """The bar in ``cells`` x ``cells / 5`` quadrilaterals, its end x = 0 held, its long sides
    on rollers (``sides="rollers"``) or free (``"free"``). A coupling's patch: the quarter at
    the wall, or ``patch_cells`` (this rank's local cells of ``msh``). ``law``: the material
    (default :data:`CONCRETE`)."""
    law = CONCRETE if law is None else law
    if msh is None:
        msh = bar_mesh(method, cells, comm)
    wall = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0))
    fixed = [(wall, (0, 1))]
    if sides == "rollers":
        long = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], HEIGHT))
        fixed.append((long, (1,)))
    if method == "fe":
        V = _compat.vector_function_space(msh)
        return mf.ExplicitDynamics.fe(V, law, fixed_facets=fixed)
    if method == "efg":
        particles = mf.ParticleSet.from_cells(msh, LENGTH / cells)
        return mf.ExplicitDynamics.efg(particles, law, fixed_facets=fixed)
    V = _compat.vector_function_space(msh)
    if patch_cells is None:
        patch_cells = np.flatnonzero(cell_midpoints(msh)[:, 0] < LENGTH / 4)
    patch = mf.ParticlePatch(msh, patch_cells, LENGTH / cells)
    # the problem's law gives the masses only (same density and plane)
    masses = mf.LinearElastic(30e9, 0.2, "strain", rho=law.rho)
    coupling = method.removesuffix("-adaptive")
    options = {"overlap": 1} if coupling == "bridging" else {}
    if coupling == "hybrid":  # HA-F: the finite-strain hybrid (SPH sums of the nominal stress)
        problem = mf.HybridElasticity(V, patch, masses, variant="HA-F")
        return mf.ExplicitDynamics.coupled(
            problem, particle_mass="volume", material=law, fixed_facets=fixed
        )  # the SPH mass rho V_I: the corrected interpolant's row sums can be negative
    else:
        problem = mf.CoupledElasticity(V, patch, masses, coupling=coupling, **options)
    return mf.ExplicitDynamics.coupled(problem, material=law, fixed_facets=fixed)


def bar_mesh(method: str, cells: int, comm=MPI.COMM_WORLD) -> dolfinx.mesh.Mesh:
    """The bar's mesh; a coupling's balanced for its patch at the wall (a patch cell costs
    about 7 FE cells: the work shared between the ranks)."""
    msh = dolfinx.mesh.create_rectangle(
        comm,
        [np.zeros(2), np.array([LENGTH, HEIGHT])],
        [cells, max(1, cells // 5)],
        dolfinx.mesh.CellType.quadrilateral,
    )
    if method not in ("fe", "efg"):
        msh = mf.balanced_mesh(msh, lambda x: np.where(x[0] < LENGTH / 4, 7.0, 1.0))
    return msh


def cell_midpoints(msh: dolfinx.mesh.Mesh) -> np.ndarray:
    """Midpoints (vertex means) of this rank's owned cells."""
    n = msh.topology.index_map(2).size_local
    return msh.geometry.x[_compat.geometry_dofmap(msh)[:n]].mean(axis=1)


def depth(dyn: mf.ExplicitDynamics, mask: np.ndarray) -> float:
    """The largest x of the points in ``mask`` over every rank (0 if none)."""
    x = dyn.material.points[mask, 0]
    return dyn.comm.allreduce(float(x.max()) if x.size else 0.0, op=MPI.MAX)


def impact(method: str, cells: int, v0: float, comm=MPI.COMM_WORLD, sides: str = "rollers") -> dict:
    """One run; its row of figures."""

    def thrown(dyn: mf.ExplicitDynamics) -> mf.ExplicitDynamics:
        dyn.set_initial(velocity=lambda x: np.stack([np.full(len(x), -v0), 0 * x[:, 0]], axis=1))
        return dyn

    t_end = 0.5 * LENGTH / wave_speed(CONCRETE) if v0 <= ELASTIC else T_END
    adaptive = method in ADAPTIVE
    if adaptive:  # one column of particle cells at the wall; the rest grows where D >= 0.1
        msh = bar_mesh(method, cells, comm)
        width = 2 if method.startswith("bridging") else 1  # bridging: a column past its band
        first_column = np.flatnonzero(cell_midpoints(msh)[:, 0] < width * LENGTH / cells)

        n_cells = cells

        def rebuilt(cells: np.ndarray | None = None) -> mf.ExplicitDynamics:
            on = first_column if cells is None else cells
            return thrown(build(method, n_cells, comm, sides, msh, on))

        run = mf.dynamics.AdaptiveRun(rebuilt, mf.StateAbove("damage", CONVERT_AT), check_every=5)
        dyn = run.run(t_end)
        records, conversions = dyn.stepper.records, run.conversions
        steps, seconds = dyn.step, run.timings["steps"] + run.timings["conversions"]
        dt = None
    else:
        dyn = thrown(build(method, cells, comm, sides))
        res = dyn.run(t_end)
        records, conversions = res.energies, []
        steps, seconds, dt = res.steps, res.timings["steps"], res.dt
    first, last = records[0], records[-1]
    changed = sum(c.energy_change for c in conversions)
    law, comm = dyn.material, dyn.comm
    state = law.state
    row = {
        "method": method,
        "velocity": v0,
        "steps": steps,
        "dt": dt,
        "seconds": seconds,
        "seconds_per_step": seconds / steps,
        # the energy the conversions changed (the fit of the new particles) counted as removed
        "balance": (last.kinetic + last.internal - changed - first.kinetic) / first.kinetic,
        "crushed_depth": depth(dyn, state["mu_plastic"][:, 0] > 0.0),
        "damaged_depth": depth(dyn, state["damage"][:, 0] >= 0.5),
        "failed_depth": depth(dyn, state["damage"][:, 0] >= 0.99),
        "max_damage": comm.allreduce(float(state["damage"].max(initial=0.0)), op=MPI.MAX),
        "elastic": None,
        "conversions": None,
    }
    if adaptive:
        in_patch = comm.allreduce(int(np.count_nonzero(dyn.in_patch[: law_cells(dyn)])))
        row["conversions"] = {
            "count": len(conversions),
            "particle_cells": in_patch,
            "cells": comm.allreduce(law_cells(dyn)),
            "mass_error": max((c.mass_error for c in conversions), default=0.0),
            "momentum_correction": max((c.momentum_correction for c in conversions), default=0.0),
            "wall_reaction": max((c.momentum_reaction for c in conversions), default=0.0),
            "velocity_change": max((c.velocity_change for c in conversions), default=0.0),
            "kinetic_change": sum(c.kinetic_change for c in conversions) / first.kinetic,
            "strain_change": sum(c.strain_change for c in conversions) / first.kinetic,
            "seconds": run.timings["conversions"],
        }
    if v0 <= ELASTIC and sides == "rollers":  # uniaxial strain: the 1D solution
        behind = law.points[:, 0] < 0.3 * LENGTH
        local = np.array([law.sigma[behind, 0, 0].sum(), behind.sum()])
        total = comm.allreduce(local, op=MPI.SUM)
        plastic = comm.allreduce(float(state["plastic_strain"].max(initial=0.0)), op=MPI.MAX)
        one_d = -CONCRETE.rho * wave_speed(CONCRETE) * v0
        row["elastic"] = {
            "stress_ratio": float(total[0] / total[1]) / one_d,
            "plastic_strain": plastic,
        }
    dyn.destroy()
    return row


def law_cells(dyn: mf.ExplicitDynamics) -> int:
    """This rank's owned cells."""
    return dyn.evaluator.disc.mesh.topology.index_map(2).size_local


def check(rows: list[dict], cells: int) -> list[str]:
    """What leaves its margin (module header)."""
    bad = []
    for r in rows:
        name = f"{r['method']} at {r['velocity']:g} m/s"
        if abs(r["balance"]) > MARGINS["balance"]:
            bad.append(f"{name}: balance {r['balance']:.2e} beyond {MARGINS['balance']}")
        e = r["elastic"]
        if e is not None:
            if e["plastic_strain"] > 0.0 or r["max_damage"] > 0.0:
                bad.append(f"{name}: not elastic (plastic strain {e['plastic_strain']:.2e})")
            if abs(e["stress_ratio"] - 1.0) > MARGINS["elastic_stress"]:
                bad.append(f"{name}: sigma_xx / (-rho c v0) = {e['stress_ratio']:.4f}")
        c = r["conversions"]
        if c is not None:
            if c["mass_error"] > MARGINS["mass"]:
                bad.append(f"{name}: a conversion's mass error {c['mass_error']:.2e}")
            fit_conserves = r["method"].startswith(("lagrange", "edge-to-edge"))
            if fit_conserves and c["momentum_correction"] > MARGINS["momentum"]:
                bad.append(f"{name}: a conversion's momentum {c['momentum_correction']:.2e}")
    h = LENGTH / cells
    for v0 in sorted({r["velocity"] for r in rows}):
        by = {r["method"]: r for r in rows if r["velocity"] == v0}
        if "efg" not in by:
            continue
        for method, r in by.items():
            for key, margin in (
                ("crushed_depth", "crushed_cells"),
                ("damaged_depth", "damaged_cells"),
                ("failed_depth", "failed_cells"),
            ):
                gap = abs(r[key] - by["efg"][key]) / h
                if gap > MARGINS[margin]:
                    bad.append(f"{v0:g} m/s: {method} and EFG {key} {gap:.1f} cells apart")
            # within the margin in cells, but failed where pure EFG fails nowhere
            if by["efg"]["failed_depth"] == 0.0 and r["failed_depth"] > 0.0:
                bad.append(
                    f"{v0:g} m/s: {method} fails concrete (D >= 0.99) to"
                    f" {1e3 * r['failed_depth']:.2f} mm where EFG fails none"
                )
    return bad


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="A concrete bar (HJC) thrown against a wall")
    p.add_argument("--method", nargs="+", default=DEFAULT_METHODS, choices=METHODS)
    p.add_argument("--cells", type=int, default=40, help="cells along the bar")
    p.add_argument("--velocity", nargs="+", type=float, default=[0.5, 100.0])
    p.add_argument("--sides", default="rollers", choices=["rollers", "free"])
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    rows = [impact(m, args.cells, v, sides=args.sides) for v in args.velocity for m in args.method]
    comm = MPI.COMM_WORLD
    per_step = {(r["method"], r["velocity"]): r["seconds_per_step"] for r in rows}
    total = {(r["method"], r["velocity"]): r["seconds"] for r in rows}
    if comm.rank == 0:
        print(
            f"HJC concrete bar against a wall, {args.cells} cells, sides {args.sides}, "
            f"{comm.size} rank(s)"
        )
        head = (
            "method               v0 m/s  steps  s/step  vs FE  s total  vs EFG  balance"
            "  crushed mm  D>=0.5 mm  failed mm  D"
        )
        print(head)
        for r in rows:
            v0 = r["velocity"]
            fe = r["seconds_per_step"] / per_step.get(("fe", v0), np.nan)
            efg = r["seconds"] / total.get(("efg", v0), np.nan)
            print(
                f"{r['method']:20s} {v0:7g} {r['steps']:6d} {r['seconds_per_step']:7.4f}"
                f" {fe:5.2f}x {r['seconds']:8.3f} {efg:5.2f}x {r['balance']:+9.2e}"
                f" {1e3 * r['crushed_depth']:10.2f} {1e3 * r['damaged_depth']:10.2f}"
                f" {1e3 * r['failed_depth']:10.2f}"
                f" {r['max_damage']:5.3f}"
            )
            if r["elastic"] is not None:
                ratio = r["elastic"]["stress_ratio"]
                print(f"        elastic: sigma_xx / (-rho c v0) = {ratio:.4f}")
            c = r["conversions"]
            if c is not None:
                print(
                    f"        {c['count']} conversions ({c['seconds']:.3f} s): particles on"
                    f" {c['particle_cells']} of {c['cells']} cells; largest mass error"
                    f" {c['mass_error']:.1e}; momentum missed by the fit"
                    f" {c['momentum_correction']:.1e}, the held wall's reaction"
                    f" {c['wall_reaction']:.1e}; velocity at the old particles changed by up to"
                    f" {c['velocity_change']:.1%} of their speed; energy"
                    f" changed: kinetic {c['kinetic_change']:+.2e}, strain"
                    f" {c['strain_change']:+.2e} of the initial kinetic"
                )
    bad = check(rows, args.cells)
    if comm.rank == 0:
        if args.json:
            with open(args.json, "w") as fh:
                out = {"cells": args.cells, "sides": args.sides, "ranks": comm.size, "rows": rows}
                json.dump(out, fh, indent=1)
        for b in bad:
            print("FAILED:", b)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
