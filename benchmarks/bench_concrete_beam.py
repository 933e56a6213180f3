# # The notched concrete beam: coupled against pure EFG, and the spacing dependence
#
# Issue 24's targets for the couplings, the objectivity and the cost: "every coupled path within
# two particle spacings of pure EFG's, and the peak load within 2 % of it"; "peak load and
# dissipated energy change <= 3 % between two particle spacings"; "coupled <= 0.3x pure EFG's
# time at equal accuracy". The beam of `demos/concrete_beam.py` (Petersson's, three-point
# bending, CMOD control to `--end-cmod`), with `--crack cohesive` (the default: an elastic bulk
# and `mf.LinearCohesive` on the ligament, Hillerborg's fictitious crack) or `--crack band`
# (`mf.RankineDamage` with the crack band) or `--crack combined` (the band handed to a cohesive
# crack where it localises, `mf.CrackBandSwitch`), for each cell size `h` (particle spacing =
# cell size: particles at the vertices), pure EFG and each coupling in one run: the peak load,
# its difference to EFG's, its change from the next coarser size, the dissipated energy and its
# ratio to G_f times the ligament, the Newton iterations, the time and its ratio to EFG's. JIT
# compilation is warmed up first (the smallest run of every method) and excluded.
#
# Measured (serial, a shared 2-core machine, `--h 20 10 5 --methods efg lagrange bridging
# edge-to-edge`, cohesive, CMOD to 0.5 mm):
#
# | method | h | particles | FE | peak N | vs EFG | change | J | x GfA | Newton | s | x EFG |
# |---|---|---|---|---|---|---|---|---|---|---|---|
# | efg | 20.0 | 1122 | 0 | 873.8 | 0 | - | 0.4826 | 0.78 | 91 | 4.3 | 1.00 |
# | lagrange | 20.0 | 110 | 920 | 867.0 | -0.79% | - | 0.4862 | 0.78 | 105 | 2.2 | 0.50 |
# | bridging | 20.0 | 110 | 920 | 866.9 | -0.80% | - | 0.4861 | 0.78 | 148 | 3.2 | 0.75 |
# | edge-to-edge | 20.0 | 110 | 920 | 847.1 | -3.06% | - | 0.4939 | 0.80 | 109 | 2.2 | 0.51 |
# | efg | 10.0 | 4242 | 0 | 851.2 | 0 | -2.59% | 0.4845 | 0.78 | 120 | 28.8 | 1.00 |
# | lagrange | 10.0 | 420 | 3640 | 852.9 | +0.20% | -1.62% | 0.4845 | 0.78 | 127 | 9.7 | 0.34 |
# | bridging | 10.0 | 420 | 3640 | 851.9 | +0.08% | -1.72% | 0.4845 | 0.78 | 131 | 11.3 | 0.39 |
# | edge-to-edge | 10.0 | 420 | 3640 | 840.2 | -1.29% | -0.81% | 0.4844 | 0.78 | 132 | 9.9 | 0.35 |
# | efg | 5.0 | 16482 | 0 | 852.9 | 0 | +0.20% | 0.4814 | 0.78 | 151 | 161.9 | 1.00 |
# | lagrange | 5.0 | 1640 | 14480 | 852.8 | -0.01% | -0.02% | 0.4812 | 0.78 | 170 | 51.2 | 0.32 |
# | bridging | 5.0 | 1640 | 14480 | 852.8 | -0.01% | +0.10% | 0.4812 | 0.78 | 168 | 56.3 | 0.35 |
# | edge-to-edge | 5.0 | 1640 | 14480 | 849.9 | -0.35% | +1.15% | 0.4814 | 0.78 | 171 | 53.4 | 0.33|
#
# And the ramps (`--h 20 10 --methods efg ramp ramp-cubic`, one run): peak 863.7 N at h = 20 mm
# (-1.16 % against EFG, 0.59x its time), 849.8 N at h = 10 mm (-0.17 %, 0.41x); the cubic ramp
# gives the same peaks (the crack is far from its interface cells).
#
# The cohesive crack is objective: the peak changes -2.6 % and +0.2 % per halving of h in pure
# EFG (-1.6 %, -0.02 % with lagrange), the energy at CMOD 0.5 mm by at most 0.6 % (target 3 %).
# Lagrange and bridging follow pure EFG within 0.8 % (target 2 %) at a third of its time from
# h = 10 mm (target 0.3x); edge-to-edge misses the 2 % at h = 20 mm (-3.1 %). With `--crack band`
# the peak is not objective: it fell 12.6 % from h = 20 to 10 mm (960.8 N at h = 10 mm, pure
# EFG, measured before the cohesive crack: a local law at a sharp notch tip).
#
# `--setup arrea-ingraffea`: the single-edge-notched beam in four-point shear of the demo (its
# header says what is not checked against the experiment), the crack's path found (mixed mode),
# CMSD control to 0.2 mm. `off mm` is then the largest distance of the method's crack path below
# three quarters of the depth from pure EFG's at the same h, `off all` over the whole depth, and
# `x GfA` the dissipated energy over G_f times the crack's area (its path beyond the notch).
# Measured (serial, `--h 20 15 10 --methods efg lagrange bridging master-slave ramp`): see
# `docs/guide/softening.md` (the table, and `docs/results/data/bench_concrete_beam_shear.json`).
#
#     python benchmarks/bench_concrete_beam.py [--h 20 10] [--methods efg lagrange]
#         [--end-cmod 0.5] [--setup three-point-bend|arrea-ingraffea] [--json F] [--png P]

from __future__ import annotations

import argparse
import itertools

import numpy as np
from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI

COMM = MPI.COMM_WORLD


def run(
    method: str,
    h: float,
    end_cmod: float,
    crack: str,
    path: str = "given",
    setup: str = "three-point-bend",
    notch_depth: float | None = None,
) -> dict:
    demo = load_demo("concrete_beam")
    extra = ["--path", path] if crack == "cohesive" else []
    if notch_depth is not None:
        extra += ["--notch-depth", str(notch_depth)]
    if setup == "three-point-bend":  # the patch: the notch tip's supports stay inside it
        extra += ["--patch-width", str(max(200.0, 10 * h))]
    return demo.main(
        ["--setup", setup, "--method", method, "--h", str(h), "--end", str(end_cmod),
         "--crack", crack, "--no-check", "--quiet", *extra]
    )  # fmt: skip


def path_distance(a: list, b: list, below: float) -> float:
    """The largest distance from a point of the polyline ``a`` below the height ``below``
    (sampled every mm) to the polyline ``b``: how far one found crack path strays from
    another."""
    pa, pb = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    pts = []
    for p, q in itertools.pairwise(pa):
        n = max(1, int(np.ceil(np.linalg.norm(q - p))))
        pts.append(p + np.linspace(0.0, 1.0, n + 1)[:, None] * (q - p))
    x = np.concatenate(pts)
    x = x[x[:, 1] <= below]
    s, e = pb[:-1], pb[1:]
    t = e - s
    r = x[:, None, :] - s[None]
    xi = np.clip(np.einsum("mkd,kd->mk", r, t) / np.einsum("kd,kd->k", t, t), 0.0, 1.0)
    return float(np.linalg.norm(r - xi[..., None] * t[None], axis=-1).min(axis=1).max())


def plot(records: list[dict], png: str) -> None:
    """The load against the control and the crack paths of every method at the finest spacing
    (the shear beam: like Rabczuk et al. 2006, Fig. 17 and 18), rank 0."""
    if COMM.rank != 0:
        return
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed, PNG skipped: apt-get install python3-matplotlib")
        return
    h = min(r["h_mm"] for r in records)
    fine = [r for r in records if r["h_mm"] == h]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for r in fine:
        (c,) = (k for k in r["curve"] if k != "load")
        ax[0].plot(r["curve"][c], np.asarray(r["curve"]["load"]) / 1e3, label=r["method"])
        if r.get("crack_polyline"):
            q = np.asarray(r["crack_polyline"])
            ax[1].plot(q[:, 0], q[:, 1], "-", lw=1, label=r["method"])
    ax[0].set_xlabel(f"{c.upper()} (mm)")
    ax[0].set_ylabel("load (kN)")
    ax[0].legend(fontsize=7)
    ax[1].set_xlim(0, fine[0]["length_mm"])
    ax[1].set_ylim(0, fine[0]["depth_mm"])
    ax[1].set_aspect("equal")
    ax[1].set_xlabel("x (mm)")
    ax[1].set_ylabel("y (mm)")
    ax[1].legend(fontsize=7)
    fig.suptitle(f"{fine[0]['setup']}, h = {h:g} mm")
    fig.tight_layout()
    fig.savefig(png, dpi=120)


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--h", nargs="+", type=float, default=[20.0, 10.0])
    p.add_argument("--methods", nargs="+", default=["efg", "lagrange", "bridging"])
    p.add_argument(
        "--end-cmod",
        "--end",
        type=float,
        default=None,
        help="mm: the control's end (default 0.5 CMOD; the shear beam's CMSD 0.2)",
    )
    p.add_argument("--crack", default="cohesive", choices=["cohesive", "band", "combined"])
    p.add_argument(
        "--path",
        default="given",
        choices=["given", "found"],
        help="cohesive: the crack's path given up the ligament, or found as it grows",
    )
    p.add_argument(
        "--setup",
        default="three-point-bend",
        choices=["three-point-bend", "arrea-ingraffea"],
        help="arrea-ingraffea: the four-point shear beam, its crack path found (mixed mode)",
    )
    p.add_argument(
        "--notch-depth",
        type=float,
        default=None,
        help="mm (three-point-bend; 0: an unnotched beam, its crack started where "
        "mf.initiation_site finds it with --path found)",
    )
    p.add_argument("--json", default=None)
    p.add_argument("--png", default=None, help="curves and crack paths at the finest h")
    args = p.parse_args(argv)
    shear = args.setup != "three-point-bend"
    if shear:
        args.path = "found"
    if args.end_cmod is None:
        args.end_cmod = 0.2 if shear else 0.5
    coarse = max(args.h)
    for m in args.methods:  # warm the JIT caches (forms, kernels)
        run(m, coarse, 0.02 if not shear else 0.005, args.crack, args.path, args.setup,
            args.notch_depth)  # fmt: skip
    records = []
    for h in sorted(args.h, reverse=True):
        base = None
        for m in args.methods:
            r = run(m, h, args.end_cmod, args.crack, args.path, args.setup, args.notch_depth)
            c = r["control"]
            r = {k: v for k, v in r.items() if k not in (c, "load", "deflection", "cmod")} | {
                "curve": {c: r[c], "load": r["load"]}
            }
            r.pop("damage_zone")
            zone = r.pop("path")  # the softened faces or damaged points
            if shear:  # from EFG's found path, below three quarters of the depth and over all
                ref = (base or r)["crack_polyline"]
                depth = r["depth_mm"]
                r["path_offset_mm"] = path_distance(r["crack_polyline"], ref, 0.75 * depth)
                r["path_offset_all_mm"] = path_distance(r["crack_polyline"], ref, depth)
            else:  # off mid-span
                r["path_offset_mm"] = max((abs(x - 1000.0) for x, _ in zone), default=0.0)
            if m == "efg":
                base = r
            r["peak_vs_efg"] = (
                None if base is None else r["peak_load_N"] / base["peak_load_N"] - 1.0
            )
            r["time_vs_efg"] = None if base is None else ratio(r["time_total"], base["time_total"])
            records.append(r)
    by = {(r["method"], r["h_mm"]): r for r in records}
    for r in records:  # the change of the peak from the next coarser size
        coarser = [h for h in args.h if h > r["h_mm"]]
        prev = by.get((r["method"], min(coarser))) if coarser else None
        r["peak_change"] = None if prev is None else r["peak_load_N"] / prev["peak_load_N"] - 1
    if COMM.rank == 0:
        what = "four-point shear" if shear else "three-point bend"
        if args.notch_depth is not None:
            what += f", notch {args.notch_depth:g} mm"
        control = "CMSD" if shear else "CMOD"
        print(
            f"concrete beam ({what}, {args.crack} crack, path {args.path}), "
            f"{COMM.size} rank(s), {control} to {args.end_cmod} mm"
        )
        off = [("off mm", "7.1f"), ("off all", "7.1f")] if shear else [("off mm", "7.3f")]
        columns = [
            ("method", "<12"), ("h mm", "5.1f"), ("particles", "9d"), ("FE cells", "8d"),
            ("peak N", "8.1f"), ("vs EFG", "+7.2%"), ("change", "+7.2%"), ("energy J", "8.4f"),
            ("x GfA", "5.2f"), *off, ("Newton", "6d"), ("time s", "7.1f"),
            ("x EFG", "5.2f"),
        ]  # fmt: skip
        started = any("initiation" in r for r in records)  # where and when the crack started
        if started:
            columns += [("start N", "8.1f"), ("margin", "6.3f")]
        rows = [
            [r["method"], r["h_mm"], r["particles"], r["fe_cells"], r["peak_load_N"],
             r["peak_vs_efg"], r["peak_change"], r["dissipated_energy_J"],
             r["energy_ratio_to_Gf_area"], r["path_offset_mm"],
             *([r["path_offset_all_mm"]] if shear else []), r["newton_iterations"],
             r["time_total"], r["time_vs_efg"],
             *([r["initiation"]["load_N"], r["initiation"]["margin"]] if started else [])]
            for r in records
        ]  # fmt: skip
        print_table(columns, rows, markdown=True)
    write_json(args.json, records)
    if args.png:
        plot(records, args.png)
    return records


if __name__ == "__main__":
    main()
