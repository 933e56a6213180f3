# # Quasi-static mixed-mode crack growth from an inclined edge crack (issue 10, item 5)
#
# Plate [0, 1] x [-0.5, 0.5] under remote tension sigma_yy = 1 (tractions on the top and bottom
# edges, self-equilibrated), plane strain; the rigid motions are removed far from the crack by
# three scalar conditions, statically determinate: pure EFG, u = 0 on the bottom edge's left end
# facet and u_y = 0 on its right end facet (one constant multiplier per facet and component);
# coupled, a user's model (``mf.CoupledLinearProblem`` with UFL forms and dolfinx
# ``DirichletBC``s): u = 0 at the FE node (0, -0.5), u_y = 0 at the FE node (1, -0.5) on
# ``V.sub(1)``. An edge crack from (0, Y0) rising at 30 degrees, length a = 0.3, grows by ``da``
# per step (``mf.QuasiStaticCrackGrowth``, prescribed increments: K_Ic = None): each step
# solves, computes K_I, K_II at the tip (domain interaction integral), kinks by the maximum hoop
# stress angle theta_c = 2 atan[(K_I - sqrt(K_I^2 + 8 K_II^2)) / (4 K_II)] and extends the
# crack.
#
# Methods: ``efg`` (particles everywhere), ``lagrange`` and ``bridging`` (a particle patch around
# the crack and its path, x < 0.85, y > -0.2; Q1 elements elsewhere). Checks: the first kink is
# the maximiser of the hoop stress of the computed K's (a 1e-4 rad grid search; the formula is
# exact, so this checks the criterion's sign and branch) and turns the crack towards the
# mode-I direction (clockwise); the paths of successive resolutions are compared (max distance
# of the tips after each step, relative to the final crack length), the two finest against
# issue 10's target 1 %. The run exits 1 on a miss. Measured (da = 0.1, 3 steps, crack length
# 0.6): h = 0.025 vs 0.0125: EFG 0.165 %, lagrange 0.160 %, bridging 0.160 %; h = 0.0125 vs
# 0.00625: 0.121 / 0.120 / 0.120 %; the coupled paths differ from EFG's by 8e-5, 3e-5, 6e-6
# (h = 0.025, 0.0125, 0.00625). (With the conditions on the left edge's facets next to the
# mouth, where they had to sit before component DirichletBCs, the coupled models missed: 4.4 %;
# their multipliers grew under refinement, 0.08 -> 0.56, those at the bottom corners of EFG
# shrink, 0.063 -> 0.038.)
# The time of a step is the full rebuild (tables, cut cells, assembly) and the solve.
# ``--adaptive-patch K`` (issue 25): each coupled method runs again on a patch that starts as the
# cells within K spacings of the crack (``mf.cells_near``) and grows about the tip before each
# extension (``mf.NearTips(K)``; K = 0: the SIF domains' radius plus 2 spacings); its path is
# checked against the large fixed patch's (target 1 % of the crack length) and the times are
# compared in the same run. Measured (``--methods lagrange bridging --h 0.0125 0.00625 0.003125
# --adaptive-patch 0``): path differences 2.0e-4, 4.3e-5, 1.1e-5 (lagrange) and 1.9e-4, 3.3e-5,
# 7.3e-6 (bridging); time 0.76x, 0.62x, 0.37x and 0.60x, 0.42x, 0.46x the fixed patch's (one
# run; the FE side, solved whole at every step, bounds the gain). JSON per adaptive record:
# ``conversions`` (the growth events) and ``particles_final``.
# ``--xdmf P``: per step, the FE displacement (coupled), the particle cloud with the
# displacement at the particles, and the crack the step solved with
# (``dolfinx_meshfree.output.SeriesWriter``; files P_<method>_h<h>_{fe,particles,cracks}.xdmf).
#
#     python demos/crack_growth.py [--methods efg lagrange bridging] [--h 0.025 0.0125]
#         [--steps 3] [--da 0.1] [--adaptive-patch K] [--json F] [--png F] [--xdmf P] [--quick]

from __future__ import annotations

import argparse
import itertools
import sys
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree.output import SeriesWriter

import dolfinx
import numpy as np
from sif_common import COMM, coupled_forms, owned_cells, rigid_motion_bcs, write_json

MATERIAL = mf.LinearElastic(1000.0, 0.3, plane="strain")
Y0, ANGLE, A = 0.0063, 30.0, 0.3  # Y0: off the particle rows of every demo spacing
RADII = (0.05, 0.065, 0.08)  # interaction integral domains, below da = 0.1 (the last kink)
PATH_TARGET = 0.01  # issue 10: paths of the two finest resolutions within 1 % of the length


def adaptive_radius(h: float, k: float, radius) -> float:
    """The patch's radius about the tips with ``--adaptive-patch k`` (``k = 0``: the SIF
    domains' outer radius plus 2 spacings, ``mf.NearTips()``'s default)."""
    if k:
        return k * h
    return (max(radius) if radius else 5.0 * h) + 2.0 * h


def model(method: str, h: float, width: float = 1.0, adaptive: float | None = None):
    """The plate (``width`` x ``width``, centred on y = 0), the crack and the problem; with
    ``adaptive`` (a radius), the coupled patch starts as the cells within it of the crack."""
    t = np.deg2rad(ANGLE)
    crack = mf.Crack([[0.0, Y0], [A * np.cos(t), Y0 + A * np.sin(t)]])
    n = round(width / h)
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.array([0.0, -width / 2]), np.array([width, width / 2])], [n, n],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    top = mf.boundary_facets(msh, lambda x: np.isclose(x[1], width / 2))
    bottom = mf.boundary_facets(msh, lambda x: np.isclose(x[1], -width / 2))
    tractions = ((top, (0.0, 1.0)), (bottom, (0.0, -1.0)))  # self-equilibrated
    if method == "efg":
        # the bottom edge's end facets, far from the crack: u = 0 (mean over the facet) on the
        # left one, u_y = 0 on the right one (one constant multiplier per facet and component:
        # three scalar conditions, statically determinate)
        P = mf.ParticleSet.from_cells(msh, h)
        prob = mf.EFGElasticity(P, MATERIAL, cracks=[crack])
        on_bottom = lambda x: np.isclose(x[1], -width / 2)  # noqa: E731
        pin = mf.boundary_facets(msh, lambda x: on_bottom(x) & (x[0] < h + 1e-9))
        roll = mf.boundary_facets(msh, lambda x: on_bottom(x) & (x[0] > width - h - 1e-9))
        zero = lambda x: np.zeros((len(x), 2))  # noqa: E731
        for facets, c in zip((pin, roll), ((0, 1), (1,)), strict=True):
            if COMM.allreduce(facets.size) == 0:
                raise RuntimeError("no facet for the rigid-motion conditions")
            prob.add_dirichlet(facets, zero, components=c)
        for facets, t in tractions:
            prob.add_traction(facets, lambda x, n, t=t: np.tile(t, (len(x), 1)))
        sizes = {"particles": P.num_particles, "fe_dofs": 0}
    else:
        # a user's model: UFL forms, dolfinx DirichletBCs at the bottom corners (FE nodes, far
        # from the crack): u = 0 at (0, -w/2), u_y = 0 at (w, -w/2) (V.sub(1))
        if adaptive is None:
            cells = owned_cells(msh, lambda c: (c[:, 0] < 0.85) & (c[:, 1] > -0.2))
        else:  # the cells near the initial crack; NearTips grows the patch ahead of the tip
            cells = mf.cells_near(msh, crack.points, adaptive)
        patch = mf.ParticlePatch(msh, cells, h, cracks=[crack])
        V, a, L = coupled_forms(msh, MATERIAL, tractions)
        bcs = rigid_motion_bcs(V, (0.0, -width / 2), (width, -width / 2))
        prob = mf.CoupledLinearProblem(a, L, bcs, patch, material=MATERIAL, coupling=method)
        sizes = {
            "particles": patch.particles.num_particles,
            "fe_dofs": 2 * V.dofmap.index_map.size_global,
        }
    return prob, crack, sizes


def run(
    method: str,
    h: float,
    steps: int,
    da: float,
    width: float = 1.0,
    radius=None,
    xdmf=None,
    adaptive: float | None = None,
) -> dict:
    t0 = time.perf_counter()
    r0 = None if adaptive is None else adaptive_radius(h, adaptive, radius)
    prob, crack, sizes = model(method, h, width, r0)
    build = time.perf_counter() - t0
    adapt = None if adaptive is None else mf.NearTips(adaptive or None)
    growth = mf.QuasiStaticCrackGrowth(
        prob, crack, increment=da, steps=steps, radius=radius, adapt=adapt
    )
    writer = particles = None
    for _ in range(steps):  # growth.run(), with the output of each step
        solved = crack.points.copy()  # the crack of this step's solution
        grown = growth.step().grown
        coupled = hasattr(prob, "patch")
        solved_on = growth.solution.patch.particles if coupled else prob.particles
        if xdmf and solved_on is not particles:  # the first step, or the patch grew
            if writer is not None:
                writer.close()  # a grown patch: a new particle series from this step
            particles, step = solved_on, len(growth.history) - 1
            writer = SeriesWriter(
                f"{xdmf}_{method}{'_adaptive' if adaptive is not None else ''}_h{h:g}"
                + (f"_s{step}" if step else ""),
                comm=COMM, mesh=prob.V.mesh if coupled else None,
                particles=particles, polylines=True,
            )  # fmt: skip
        if writer is not None:
            write_step(writer, growth, solved)
        if not grown:
            break
    if writer is not None:
        writer.close()
    total = time.perf_counter() - t0
    hist = growth.history
    s = hist[0]
    grid = np.linspace(-np.pi + 1e-4, np.pi - 1e-4, 62831)
    best = float(grid[np.argmax(mf.fracture.criteria.hoop_stress_factor(grid, s.K_I, s.K_II))])
    return {
        "method": method + ("+adaptive" if adaptive is not None else ""),
        "h": h, "da": da, "steps": steps, "width": width,
        "path": crack.points.tolist(),
        "history": [r.as_dict() for r in hist],
        "first_kink_deg": np.rad2deg(s.theta),
        "first_kink_hoop_max_deg": np.rad2deg(best),
        "crack_length": crack.length,
        "time_build": build,
        "time_per_step": [r.time_solve + r.time_sifs for r in hist],
        "time_total": total,
        "conversions": [e.as_dict() for e in growth.events],
        "particles_final": growth.problem.patch.particles.num_particles
        if hasattr(growth.problem, "patch") else sizes["particles"],
        **sizes, "ranks": COMM.size,
    }  # fmt: skip


def write_step(writer: SeriesWriter, growth: mf.QuasiStaticCrackGrowth, crack_points) -> None:
    """One XDMF output per growth step: the FE displacement (coupled models), the displacement
    at the particles (the MLS, or coupled, field at x_J, not the MLS coefficients) and the crack
    the step solved with (time = the step's number)."""
    sol, P = growth.solution, writer.particles
    u = sol.mls.tabulate(P.positions[P.owned], 0).values @ sol.coefficients
    fe = {"displacement": sol.u} if hasattr(sol, "u") else None
    step = len(growth.history) - 1
    writer.write(step, fe, {"displacement": u}, [crack_points])


def path_difference(p: dict, q: dict) -> float:
    """Max distance of the tips after each step, relative to the final crack length."""
    a, b = np.asarray(p["path"])[1:], np.asarray(q["path"])[1:]
    return float(np.linalg.norm(a - b, axis=1).max() / q["crack_length"])


def plot(records: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for r in records:
        p = np.asarray(r["path"])
        ax.plot(p[:, 0], p[:, 1], "-o", ms=3, label=f"{r['method']}, h = {r['h']:g}")
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_title(f"crack paths (maximum hoop stress, da = {records[0]['da']:g})")
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--methods", nargs="+", default=["efg", "lagrange", "bridging"])
    parser.add_argument("--h", nargs="+", type=float, default=[0.025, 0.0125])
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--da", type=float, default=0.1)
    parser.add_argument("--width", type=float, default=1.0, help="plate size (EFG timing)")
    parser.add_argument(
        "--radius", nargs="+", type=float, default=None,
        help="outer domain radii (default: 0.05 0.065 0.08, fixed in the plate so that the "
        "paths converge with h, below da; --quick: 3, 4, 5 h capped at 0.9 da)",
    )  # fmt: skip
    parser.add_argument("--json", default=None)
    parser.add_argument("--png", default=None)
    parser.add_argument(
        "--xdmf", default=None, metavar="P",
        help="XDMF per growth step: P_<method>_h<h>_fe.xdmf (FE displacement, coupled models), "
        "..._particles.xdmf (particle positions and displacement), ..._cracks.xdmf (the crack)",
    )  # fmt: skip
    parser.add_argument(
        "--adaptive-patch", type=float, default=None, metavar="K",
        help="also run each coupled method with a patch that starts as the cells within K "
        "spacings of the crack and grows K spacings about the tip (mf.NearTips(K)); K = 0: the "
        "SIF domains' radius plus 2 spacings (mf.NearTips()); compared with the large patch",
    )  # fmt: skip
    parser.add_argument("--quick", action="store_true", help="smoke run: h = 0.05, 2 steps")
    args = parser.parse_args(argv)
    hs, steps = ([0.05], 2) if args.quick else (args.h, args.steps)
    radius = args.radius or (None if args.quick else RADII)
    records = [
        run(m, h, steps, args.da, args.width, radius, args.xdmf) for m in args.methods for h in hs
    ]
    if args.adaptive_patch is not None:
        records += [
            run(m, h, steps, args.da, args.width, radius, args.xdmf, args.adaptive_patch)
            for m in args.methods if m != "efg" for h in hs
        ]  # fmt: skip
    ok = True
    out = {"records": records, "path_difference": {}}
    if COMM.rank == 0:
        print(f"inclined edge crack ({ANGLE:g} deg, a = {A:g}), da = {args.da:g}, {steps} steps")
        print(" method      h        step  tip                 K_I       K_II      theta[deg]"
              "  radius   step[s]")  # fmt: skip
    for r in records:
        for s in r["history"]:
            if COMM.rank == 0:
                print(
                    f" {r['method']:10s} {r['h']:<8g} {s['step']:4d}  "
                    f"({s['tip'][0]:.4f}, {s['tip'][1]:.4f})  {s['K_I']:8.5f}  "
                    f"{s['K_II']:+8.5f}  {np.rad2deg(s['theta']):+8.3f}    "
                    f"{s['radius'][-1]:.4f}   {s['time_solve'] + s['time_sifs']:.3f}"
                )
        # the criterion's branch: the formula's angle maximises the hoop stress (grid 1e-4 rad)
        kink_ok = abs(r["first_kink_deg"] - r["first_kink_hoop_max_deg"]) < 0.01
        ok &= kink_ok and r["first_kink_deg"] < 0  # K_II > 0: clockwise, towards mode I
    for m in args.methods:
        rs = [r for r in records if r["method"] == m]
        for p, q in itertools.pairwise(rs):  # each refinement, the last one checked
            d = path_difference(p, q)
            out["path_difference"][f"{m} h={p['h']:g} vs {q['h']:g}"] = d
            if q is rs[-1]:
                out["path_difference"][m] = d
                ok &= d <= PATH_TARGET
            if COMM.rank == 0:
                print(f" {m}: path difference h = {p['h']:g} vs {q['h']:g}: {d:.3%} "
                      "of the crack length (target 1 %: the two finest)")  # fmt: skip
    if COMM.rank == 0:  # the coupled paths against pure EFG's at the same h (reported)
        for r in records:
            ref = [e for e in records if e["method"] == "efg" and e["h"] == r["h"]]
            if r["method"] != "efg" and ref:
                d = path_difference(r, ref[0])
                print(f" {r['method']} vs efg, h = {r['h']:g}: path difference {d:.2e}")
    for r in records:  # the adaptive patch against the large fixed one (issue 25: 1 %)
        if not r["method"].endswith("+adaptive"):
            continue
        base = r["method"].removesuffix("+adaptive")
        q = next(e for e in records if e["method"] == base and e["h"] == r["h"])
        d = path_difference(r, q)
        out["path_difference"][f"{r['method']} vs fixed h={r['h']:g}"] = d
        ok &= d <= PATH_TARGET
        if COMM.rank == 0:
            ev = r["conversions"]
            print(
                f" {r['method']} h = {r['h']:g}: path difference to the fixed patch {d:.2e} of "
                f"the crack length (target 1 %); particles {r['particles_final']} at the end "
                f"(fixed {q['particles']}), {len(ev)} growth event(s) "
                f"(cells added {[e['cells_added'] for e in ev]}, rebuilds "
                f"{sum(e['time_rebuild'] for e in ev):.2f} s); time {r['time_total']:.2f} s "
                f"against {q['time_total']:.2f} s: {r['time_total'] / q['time_total']:.2f}x"
            )
    if COMM.rank == 0:
        for r in records:
            print(f" {r['method']:10s} h = {r['h']:g}: first kink {r['first_kink_deg']:+.3f} deg "
                  f"(hoop max {r['first_kink_hoop_max_deg']:+.3f}), particles {r['particles']}, "
                  f"FE dofs {r['fe_dofs']}, "
                  f"median step {np.median(r['time_per_step']):.3f} s")  # fmt: skip
        print(f" checks: {'met' if ok else 'MISSED'}")
        if args.png:
            plot(records, args.png)
    write_json(args.json, out)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
