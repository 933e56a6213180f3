# # Cost of a crack growth step against the patch size: full rebuild against local update
#
# Issue 10, item 5: "each growth step rebuilds only the tables, cells and operator rows that the
# crack extension changes: the cost of a growth step grows with the particles near the tip, not
# with the patch". The model of ``demos/crack_growth.py`` (pure EFG; a W x W plate, edge crack at
# 30 degrees from (0, Y0), a = 0.3, tension on top and bottom) at fixed spacing ``h`` for several
# plate sizes W: the tip region is the same, only the patch grows. Each size runs the same growth
# twice in one process, ``update="full"`` and ``update="local"``
# (:mod:`~dolfinx_meshfree.statics.growth_update`), and reports per step (median over the steps
# after the first, whose full build both share): setup (crack rules, MLS tables, facet tables;
# without the problem constructor's time, which the solution's timings add to every solve),
# assemble (stiffness update or product, PETSc matrices, loads), solve (MUMPS), SIFs, and the
# total; the local/full ratio; and the largest difference of K_I, K_II between the two paths
# (relative to |K|; a full rebuild and the local update must agree to round-off, checked 1e-10,
# the run exits 1 on a miss). JIT compilation is warmed up first (a small model) and excluded.
#
# Measured (h = 0.025, da = 0.1, 4 steps, serial, on a shared 2-core machine under a load of 7;
# seconds per step, full / local, median of steps 2-4):
#
# | W | particles | setup | assemble | update (sum) | solve | total | K diff |
# |---|---|---|---|---|---|---|---|
# | 1 | 1681 | 0.413/0.080 | 0.478/0.160 | 0.891 / 0.240 | 0.172 / 0.180 | 1.128 / 0.460 | 1e-13 |
# | 1.5 | 3721 | 0.727/0.102 | 1.237/0.182 | 1.964 / 0.284 | 0.505 / 0.551 | 2.541 / 0.892 | 1e-13 |
# | 2 | 6561 | 1.264/0.106 | 2.225/0.230 | 3.489 / 0.336 | 1.044 / 1.158 | 4.640 / 1.555 | 2e-14 |
#
# The local update re-tabulates about 850 cell rows (of 27k-104k) and changes about 110 dofs of K
# at every size; its time grows 1.4x while the patch grows 3.9x (full: 3.9x). What remains linear
# in it: the sparse sum K_old + dK, the PETSc matrix of K, the rules' point arrays (memory
# copies). The direct solve (MUMPS) grows with the patch and is now most of a local step.
# 2 ranks: local and full agree to 9e-14; the timings were dominated by the machine's load.
#
#     python benchmarks/bench_growth.py [--h 0.025] [--widths 1 1.5 2] [--steps 4] [--da 0.1]
#         [--json F] [--quick]

from __future__ import annotations

import argparse
import statistics
import sys

import dolfinx_meshfree as mf

import numpy as np
from harness import load_demo, print_table, write_json
from mpi4py import MPI

COMM = MPI.COMM_WORLD

PARTS = ("setup", "assemble", "solve", "sifs", "total")
AGREE = 1e-10  # local against full, relative to |K|


def run(h: float, width: float, steps: int, da: float, update: str) -> dict:
    prob, crack, sizes = load_demo("crack_growth").model("efg", h, width)
    growth = mf.QuasiStaticCrackGrowth(prob, crack, increment=da, steps=steps, update=update)
    hist = growth.run()
    # EFGSolution.timings["setup"] includes the constructor's (MLS, crack placement), spent once
    constructor = getattr(prob, "_setup_time", 0.0)
    per = {p: [] for p in PARTS}
    for r in hist[1:]:  # the first step is the full build of both paths
        for p in ("setup", "assemble", "solve"):
            per[p].append(r.timings[p] - (constructor if p == "setup" else 0.0))
        per["sifs"].append(r.time_sifs)
        per["total"].append(r.time_solve + r.time_sifs)
    rows = growth.local.last if growth.local is not None else {}
    return {
        "update": update, "width": width, "h": h, "particles": sizes["particles"],
        "K": [[r.K_I, r.K_II] for r in hist],
        "seconds": {p: COMM.allreduce(statistics.median(v), op=MPI.MAX) for p, v in per.items()},
        "last_update": rows,
    }  # fmt: skip


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--h", type=float, default=0.025)
    parser.add_argument("--widths", nargs="+", type=float, default=[1.0, 1.5, 2.0])
    parser.add_argument("--steps", type=int, default=4)
    parser.add_argument("--da", type=float, default=0.1)
    parser.add_argument("--json", default=None)
    parser.add_argument("--quick", action="store_true", help="h = 0.05, widths 1 1.2, 2 steps")
    args = parser.parse_args(argv)
    if args.quick:
        args.h, args.widths, args.steps = 0.05, [1.0, 1.2], 2
    run(0.05, 1.0, 2, args.da, "local")  # JIT warm-up, not timed
    records, ok = [], True
    for w in args.widths:
        full = run(args.h, w, args.steps, args.da, "full")
        local = run(args.h, w, args.steps, args.da, "local")
        K = np.asarray(full["K"])
        diff = float(np.abs(np.asarray(local["K"]) - K).max() / np.abs(K).max())
        ok &= diff < AGREE
        records.append({"full": full, "local": local, "K_difference": diff})
    if COMM.rank == 0:
        print(f"EFG growth step, h = {args.h:g}, da = {args.da:g}, median of steps 2..{args.steps}"
              f", {COMM.size} rank(s); seconds per step: full / local (ratio)")  # fmt: skip
        columns = [("W", "g"), ("particles", "d"), *((p, "") for p in PARTS),
                   ("rows re-tabulated, K dofs changed", ""), ("K diff", ".1e")]  # fmt: skip
        table = []
        for r in records:
            f, lo = r["full"]["seconds"], r["local"]["seconds"]
            cells = [f"{f[p]:.3f} / {lo[p]:.3f} ({lo[p] / f[p]:.2f})" for p in PARTS]
            last = r["local"]["last_update"]
            rows, cells_, dofs = (last.get(k, 0) for k in ("rows", "cell_rows", "stiffness_dofs"))
            table.append([r["full"]["width"], r["full"]["particles"], *cells,
                          f"{rows} of {cells_}, {dofs} dofs", r["K_difference"]])  # fmt: skip
        print_table(columns, table, markdown=True)
    write_json(
        args.json, records, h=args.h, da=args.da, steps=args.steps, ranks=COMM.size, agree=AGREE
    )
    if not ok:
        if COMM.rank == 0:
            print(f"MISSED: local and full K differ by more than {AGREE:g}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
