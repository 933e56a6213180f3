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
# edge-to-edge --grade 1 1.25`, cohesive, CMOD to 0.5 mm; `grade` 1.25: the coupled model's FE
# columns widen by 1.25 per column away from the patch, up to 4 h, the demo's `--grade`):
#
# | method | h | grade | particles | FE | peak N | vs EFG | change | J | Newton | s | x EFG |
# |---|---|---|---|---|---|---|---|---|---|---|---|
# | efg | 20 | 1 | 1122 | 0 | 873.8 | +0.00% | - | 0.4826 | 83 | 5.7 | 1.00 |
# | lagrange | 20 | 1 | 110 | 920 | 874.2 | +0.04% | - | 0.4827 | 85 | 2.4 | 0.43 |
# | lagrange | 20 | 1.25 | 110 | 320 | 874.2 | +0.04% | - | 0.4827 | 86 | 1.7 | 0.30 |
# | bridging | 20 | 1 | 110 | 920 | 874.5 | +0.08% | - | 0.4826 | 92 | 3.0 | 0.52 |
# | bridging | 20 | 1.25 | 110 | 320 | 874.5 | +0.08% | - | 0.4826 | 92 | 2.1 | 0.36 |
# | edge-to-edge | 20 | 1 | 110 | 920 | 852.0 | -2.50% | - | 0.4904 | 89 | 2.6 | 0.46 |
# | edge-to-edge | 20 | 1.25 | 110 | 320 | 852.0 | -2.50% | - | 0.4904 | 90 | 1.8 | 0.32 |
# | efg | 10 | 1 | 4242 | 0 | 851.2 | +0.00% | -2.59% | 0.4845 | 111 | 42.0 | 1.00 |
# | lagrange | 10 | 1 | 420 | 3640 | 851.2 | +0.00% | -2.63% | 0.4845 | 114 | 15.3 | 0.36 |
# | lagrange | 10 | 1.25 | 420 | 1080 | 851.2 | +0.00% | -2.63% | 0.4845 | 115 | 6.6 | 0.16 |
# | bridging | 10 | 1 | 420 | 3640 | 851.3 | +0.00% | -2.66% | 0.4845 | 115 | 16.8 | 0.40 |
# | bridging | 10 | 1.25 | 420 | 1080 | 851.3 | +0.00% | -2.66% | 0.4845 | 115 | 8.8 | 0.21 |
# | edge-to-edge | 10 | 1 | 420 | 3640 | 839.5 | -1.38% | -1.46% | 0.4844 | 113 | 15.6 | 0.37 |
# | edge-to-edge | 10 | 1.25 | 420 | 1080 | 839.5 | -1.38% | -1.46% | 0.4844 | 114 | 6.6 | 0.16 |
# | efg | 5 | 1 | 16482 | 0 | 852.9 | +0.00% | +0.20% | 0.4814 | 140 | 245.9 | 1.00 |
# | lagrange | 5 | 1 | 1640 | 14480 | 852.9 | +0.00% | +0.19% | 0.4814 | 144 | 66.3 | 0.27 |
# | lagrange | 5 | 1.25 | 1640 | 4000 | 852.9 | +0.00% | +0.19% | 0.4814 | 144 | 33.9 | 0.14 |
# | bridging | 5 | 1 | 1640 | 14480 | 852.9 | +0.00% | +0.19% | 0.4814 | 144 | 66.3 | 0.27 |
# | bridging | 5 | 1.25 | 1640 | 4000 | 852.9 | +0.00% | +0.19% | 0.4814 | 144 | 37.0 | 0.15 |
# | edge-to-edge | 5 | 1 | 1640 | 14480 | 850.0 | -0.34% | +1.25% | 0.4814 | 144 | 61.8 | 0.25 |
# | edge-to-edge | 5 | 1.25 | 1640 | 4000 | 850.0 | -0.34% | +1.25% | 0.4814 | 144 | 31.6 | 0.13 |
#
# And the ramps (`--h 20 10 --methods efg ramp ramp-cubic --grade 1 1.25`, one run): peak 864.5 N
# at h = 20 mm (-1.07 % against EFG, 0.42-0.49x its time, graded 0.28-0.32x), 852.8 N at h = 10
# mm (+0.19 %, 0.39-0.41x, graded 0.20-0.23x); the cubic ramp gives the same peaks (the crack is
# far from its interface cells).
#
# The cohesive crack is objective: the peak changes -2.6 % and +0.2 % per halving of h in pure
# EFG (-2.6 %, +0.2 % with lagrange), the energy at CMOD 0.5 mm by at most 0.6 % (target 3 %).
# Lagrange, bridging and the ramps follow pure EFG within 1.1 % at every h (target 2 %);
# edge-to-edge misses the 2 % at h = 20 mm (-2.5 %; -1.4 % at 10 mm, -0.3 % at 5 mm: its
# interface holds the fields equal at the interface nodes only). On the uniform mesh of the
# particle spacing, whose FE side has as many dofs as pure EFG's particles, a coupling takes
# 0.36-0.40x pure EFG's time at h = 10 mm and 0.25-0.27x at 5 mm (target 0.3x); with the FE
# columns graded (`--grade 1.25`: 1080 FE cells instead of 3640 at h = 10 mm, the paper's model
# had 2,700 elements beside 3,500 particles against 13,400 particles) 0.16-0.21x and 0.13-0.15x,
# at the same peaks and energies to the printed digits. With `--crack band`
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
#         [--end-cmod 0.5] [--setup three-point-bend|arrea-ingraffea] [--grade 1 1.25]
#         [--json F] [--png P]

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
    grade: float = 1.0,
) -> dict:
    demo = load_demo("concrete_beam")
    extra = ["--path", path] if crack == "cohesive" else []
    if grade > 1.0:
        extra += ["--grade", str(grade)]
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
        label = r["method"] + (f" graded {r['grade']:g}" if r["grade"] > 1.0 else "")
        ax[0].plot(r["curve"][c], np.asarray(r["curve"]["load"]) / 1e3, label=label)
        if r.get("crack_polyline"):
            q = np.asarray(r["crack_polyline"])
            ax[1].plot(q[:, 0], q[:, 1], "-", lw=1, label=label)
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
    p.add_argument(
        "--grade",
        type=float,
        nargs="+",
        default=[1.0],
        help="three-point-bend: run each coupling on FE meshes whose columns widen by these "
        "ratios away from the patch (the demo's --grade; 1: uniform)",
    )
    p.add_argument("--json", default=None)
    p.add_argument("--png", default=None, help="curves and crack paths at the finest h")
    args = p.parse_args(argv)
    shear = args.setup != "three-point-bend"
    if shear and args.grade != [1.0]:
        p.error("--grade: the demo grades the three-point-bend beam's FE mesh only")
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
        runs = [(m, g) for m in args.methods for g in ([1.0] if m in ("efg", "fe") else args.grade)]
        for m, g in runs:
            r = run(m, h, args.end_cmod, args.crack, args.path, args.setup, args.notch_depth, g)
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
    by = {(r["method"], r["grade"], r["h_mm"]): r for r in records}
    for r in records:  # the change of the peak from the next coarser size
        coarser = [h for h in args.h if h > r["h_mm"]]
        prev = by.get((r["method"], r["grade"], min(coarser))) if coarser else None
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
            ("method", "<12"), ("h mm", "5.1f"), ("grade", "5.2f"), ("particles", "9d"),
            ("FE cells", "8d"),
            ("peak N", "8.1f"), ("vs EFG", "+7.2%"), ("change", "+7.2%"), ("energy J", "8.4f"),
            ("x GfA", "5.2f"), *off, ("Newton", "6d"), ("time s", "7.1f"),
            ("x EFG", "5.2f"),
        ]  # fmt: skip
        started = any("initiation" in r for r in records)  # where and when the crack started
        if started:
            columns += [("start N", "8.1f"), ("margin", "6.3f")]
        rows = [
            [r["method"], r["h_mm"], r["grade"], r["particles"], r["fe_cells"], r["peak_load_N"],
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
