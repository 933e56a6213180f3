# # The notched concrete beam: coupled against pure EFG, and the spacing dependence
#
# Issue 24's targets for the couplings, the objectivity and the cost: "every coupled path within
# two particle spacings of pure EFG's, and the peak load within 2 % of it"; "peak load and
# dissipated energy change <= 3 % between two particle spacings"; "coupled <= 0.3x pure EFG's
# time at equal accuracy". The beam of `demos/concrete_beam.py` (Petersson's, three-point
# bending, CMOD control to `--end-cmod`), with `--crack cohesive` (the default: an elastic bulk
# and `mf.LinearCohesive` on the ligament, Hillerborg's fictitious crack) or `--crack band`
# (`mf.RankineDamage` with the crack band), for each cell size `h` (particle spacing = cell size:
# particles at the vertices), pure EFG and each coupling in one run: the peak load, its difference
# to EFG's, its change from the next coarser size, the dissipated energy and its ratio to G_f
# times the ligament, the Newton iterations, the time and its ratio to EFG's. JIT compilation is
# warmed up first (the smallest run of every method) and excluded.
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
#     python benchmarks/bench_concrete_beam.py [--h 20 10] [--methods efg lagrange]
#         [--end-cmod 0.5] [--json F]

from __future__ import annotations

import argparse

from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI

COMM = MPI.COMM_WORLD


def run(method: str, h: float, end_cmod: float, crack: str, path: str = "given") -> dict:
    demo = load_demo("concrete_beam")
    width = max(200.0, 10 * h)  # the patch: the notch tip's supports stay inside it
    extra = ["--path", path] if crack == "cohesive" else []
    return demo.main(
        ["--method", method, "--h", str(h), "--end-cmod", str(end_cmod), "--patch-width",
         str(width), "--crack", crack, "--no-check", "--quiet", *extra]
    )  # fmt: skip


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--h", nargs="+", type=float, default=[20.0, 10.0])
    p.add_argument("--methods", nargs="+", default=["efg", "lagrange", "bridging"])
    p.add_argument("--end-cmod", type=float, default=0.5)
    p.add_argument("--crack", default="cohesive", choices=["cohesive", "band"])
    p.add_argument(
        "--path",
        default="given",
        choices=["given", "found"],
        help="cohesive: the crack's path given up the ligament, or found as it grows",
    )
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    coarse = max(args.h)
    for m in args.methods:  # warm the JIT caches (forms, kernels)
        run(m, coarse, 0.02, args.crack, args.path)
    records = []
    for h in sorted(args.h, reverse=True):
        base = None
        for m in args.methods:
            r = run(m, h, args.end_cmod, args.crack, args.path)
            r = {k: v for k, v in r.items() if k not in ("cmod", "load", "deflection")} | {
                "curve": {"cmod": r["cmod"], "load": r["load"]}
            }
            r.pop("damage_zone")
            zone = r.pop("path")  # the softened faces or damaged points: off mid-span by
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
        print(
            f"concrete beam (three-point bend, {args.crack} crack, path {args.path}), "
            f"{COMM.size} rank(s), CMOD to {args.end_cmod} mm"
        )
        columns = [
            ("method", "<12"), ("h mm", "5.1f"), ("particles", "9d"), ("FE cells", "8d"),
            ("peak N", "8.1f"), ("vs EFG", "+7.2%"), ("change", "+7.2%"), ("energy J", "8.4f"),
            ("x GfA", "5.2f"), ("off mm", "7.3f"), ("Newton", "6d"), ("time s", "7.1f"),
            ("x EFG", "5.2f"),
        ]  # fmt: skip
        rows = [
            [r["method"], r["h_mm"], r["particles"], r["fe_cells"], r["peak_load_N"],
             r["peak_vs_efg"], r["peak_change"], r["dissipated_energy_J"],
             r["energy_ratio_to_Gf_area"], r["path_offset_mm"], r["newton_iterations"],
             r["time_total"], r["time_vs_efg"]]
            for r in records
        ]  # fmt: skip
        print_table(columns, rows, markdown=True)
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
