# # The notched concrete beam: coupled against pure EFG, and the spacing dependence
#
# Issue 24's targets for the couplings and the cost: "every coupled path within two particle
# spacings of pure EFG's, and the peak load within 2 % of it"; "coupled <= 0.3x pure EFG's time at
# equal accuracy". The beam of `demos/concrete_beam.py` (Petersson's, three-point bending,
# `mf.RankineDamage` with the crack band, CMOD control to `--end-cmod`), for each cell size `h`
# (particle spacing = cell size: particles at the vertices), pure EFG and each coupling in one
# run: the peak load, its difference to EFG's, the dissipated energy and its ratio to G_f times
# the ligament, the Newton iterations, the time and its ratio to EFG's. Across sizes the peak's
# change per halving of `h` is the objectivity figure (issue target: 3 %). JIT compilation is
# warmed up first (the smallest run of every method) and excluded.
#
# Measured (serial, a shared 2-core machine, `--h 20 10`, CMOD to 0.5 mm):
#
# | method | h mm | particles | FE cells | peak N | vs EFG | change | J | x GfA | s | x EFG |
# |---|---|---|---|---|---|---|---|---|---|---|
# | efg | 20 | 1122 | 0 | 1099.8 | 0 | - | 0.5879 | 0.95 | 8.7 | 1.00 |
# | lagrange | 20 | 110 | 920 | 1100.9 | +0.10 % | - | 0.5886 | 0.95 | 3.4 | 0.39 |
# | bridging | 20 | 110 | 920 | 1101.0 | +0.11 % | - | 0.5878 | 0.95 | 4.6 | 0.53 |
# | efg | 10 | 4242 | 0 | 960.8 | 0 | -12.6 % | 0.5365 | 0.87 | 47.1 | 1.00 |
# | lagrange | 10 | 420 | 3640 | 958.9 | -0.19 % | -12.9 % | 0.5365 | 0.87 | 15.6 | 0.33 |
# | bridging | 10 | 420 | 3640 | 959.0 | -0.19 % | -12.9 % | 0.5365 | 0.87 | 18.1 | 0.38 |
#
# The couplings follow pure EFG to 0.2 % (issue target 2 %) at a third of its time (target
# 0.3x). The peak is not objective: it falls 12.6 % per halving of h (target 3 %), with any band
# factor (1, 2 or 3 cell sizes: 13 % each), so the cause is not the band width but how the local
# law resolves the notch tip; the answer is the cohesive crack once damage localises.
#
#     python benchmarks/bench_concrete_beam.py [--h 20 10] [--methods efg lagrange]
#         [--end-cmod 0.5] [--json F]

from __future__ import annotations

import argparse

from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI

COMM = MPI.COMM_WORLD


def run(method: str, h: float, end_cmod: float) -> dict:
    demo = load_demo("concrete_beam")
    width = max(200.0, 10 * h)  # the patch: the notch tip's supports stay inside it
    return demo.main(
        ["--method", method, "--h", str(h), "--end-cmod", str(end_cmod), "--patch-width",
         str(width), "--no-check", "--quiet"]
    )  # fmt: skip


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--h", nargs="+", type=float, default=[20.0, 10.0])
    p.add_argument("--methods", nargs="+", default=["efg", "lagrange", "bridging"])
    p.add_argument("--end-cmod", type=float, default=0.5)
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    coarse = max(args.h)
    for m in args.methods:  # warm the JIT caches (forms, kernels)
        run(m, coarse, 0.02)
    records = []
    for h in sorted(args.h, reverse=True):
        base = None
        for m in args.methods:
            r = run(m, h, args.end_cmod)
            r = {k: v for k, v in r.items() if k not in ("cmod", "load", "deflection")} | {
                "curve": {"cmod": r["cmod"], "load": r["load"]}
            }
            r.pop("damage_zone")
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
        print(f"concrete beam (three-point bend), {COMM.size} rank(s), CMOD to {args.end_cmod} mm")
        columns = [
            ("method", "<12"), ("h mm", "5.1f"), ("particles", "9d"), ("FE cells", "8d"),
            ("peak N", "8.1f"), ("vs EFG", "+7.2%"), ("change", "+7.2%"), ("energy J", "8.4f"),
            ("x GfA", "5.2f"), ("Newton", "6d"), ("time s", "7.1f"), ("x EFG", "5.2f"),
        ]  # fmt: skip
        rows = [
            [r["method"], r["h_mm"], r["particles"], r["fe_cells"], r["peak_load_N"],
             r["peak_vs_efg"], r["peak_change"], r["dissipated_energy_J"],
             r["energy_ratio_to_Gf_area"], r["newton_iterations"], r["time_total"],
             r["time_vs_efg"]]
            for r in records
        ]  # fmt: skip
        print_table(columns, rows, markdown=True)
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
