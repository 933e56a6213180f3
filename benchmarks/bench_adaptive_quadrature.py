# # Benchmark: adaptive quadrature ahead of the tip on Kalthoff–Winkler (issue 11, item 4)
#
# Belytschko et al. 1995 (sec. 5.2.2) integrate the EFG cells with 4 x 4 Gauss and note that the
# dense rule is needed only near the crack tip; with the coupling that would make the model about
# ten times cheaper than pure EFG. This benchmark runs the Kalthoff–Winkler set-up of
# ``demos/kalthoff_winkler.py`` (its ``run``: the same mesh, loads, growth law) with the uniform
# rule (degree 7, 4 x 4 Gauss, cut cells piece by piece) and with ``mf.AdaptiveQuadrature``
# (degree ``near`` = 7 within ``radius`` of the tip, ``far`` elsewhere), for pure EFG and the
# lagrange coupling, and prints, side by side (one run, the same machine):
#
# - the kink angle, the mean path angle, K_I and K_II at initiation, the largest difference of
#   the K_I / K_II histories from the uniform rule's (relative to the largest |K|, before the
#   first extension: afterwards the paths may part);
# - the times (setup, steps, SIFs, rebuilds, total) and the ratio of the total to pure EFG with
#   the uniform rule (the target: <= 0.2 with adaptive quadrature; the paper's 0.1).
#
# The set-up by default: the impact as the traction rho c_d v0 and no crack-face contact (the
# set-up of the measured tables); ``--impact velocity --contact 10`` gives the demo's defaults.
# The JIT compile time is excluded (a tiny warm-up run first). ``--small`` is the CI smoke run
# (21 nodes, 20 us); no timing is checked anywhere (the machines are noisy: compare the ratios
# of one run). Run: ``OMP_NUM_THREADS=1 python benchmarks/bench_adaptive_quadrature.py --nodes 41``.

# +
from __future__ import annotations

import argparse
import sys

import dolfinx_meshfree as mf

import numpy as np
from harness import load_demo, print_table, write_json
from mpi4py import MPI

# -


def _initiation(rec: dict) -> tuple[float | None, float | None]:
    """K_I, K_II (Pa sqrt(m)) at the check where the crack initiated."""
    t = rec["initiation_time"]
    for c in rec["checks"]:
        if t is not None and c["time"] == t:
            return c["K_I"], c["K_II"]
    return None, None


def _history_difference(rec: dict, ref: dict) -> float | None:
    """max |K - K_ref| / max |K_ref| over K_I and K_II at ``ref``'s check times before the
    first extension of either run (``rec`` interpolated linearly: the stable time steps, hence
    the check times, differ slightly with the rule)."""
    ends = []
    for r in (rec, ref):
        ext = [c["time"] for c in r["checks"] if c["extended"]]
        ends.append(ext[0] if ext else np.inf)
    t_end = min(ends)
    diffs, scale = [], 0.0
    for key in ("KI_history", "KII_history"):
        a, b = np.asarray(rec[key]), np.asarray(ref[key])
        if len(a) < 2 or len(b) == 0:
            continue
        keep = (b[:, 0] < t_end) & (b[:, 0] >= a[0, 0]) & (b[:, 0] <= a[-1, 0])
        ai = np.interp(b[keep, 0], a[:, 0], a[:, 1])
        diffs.append(np.abs(ai - b[keep, 1]).max(initial=0.0))
        scale = max(scale, np.abs(b[keep, 1]).max(initial=0.0))
    return float(max(diffs) / scale) if diffs and scale > 0 else None


def run_all(
    kw,
    nodes: int,
    t_end: float,
    radius: float,
    far: int,
    methods,
    comm,
    contact: float = 0.0,
    impact: str = "traction",
) -> list[dict]:
    """Every method with the uniform and the adaptive rule (``impact``: the demo's
    ``traction`` or ``velocity``; crack-face contact of penalty factor ``contact``, 0: none,
    the demo's default 10); the records of
    ``kw.run`` plus the quadrature, K at initiation, the history difference and the ratio to
    pure EFG uniform."""
    faces = kw.CrackContact(factor=contact) if contact > 0 else None
    records = []
    for method in methods:
        for name in ("uniform", "adaptive"):
            quadrature = None
            if name == "adaptive":

                def quadrature(h):
                    return mf.AdaptiveQuadrature(radius * h, near=7, far=far)

            rec = kw.run(
                method, nodes, t_end, comm=comm, contact=faces, impact=impact,
                quadrature=quadrature,
            )  # fmt: skip
            rec["quadrature"] = name
            rec["radius_spacings"] = radius if name == "adaptive" else None
            rec["far_degree"] = far if name == "adaptive" else 7
            rec["K_I_initiation"], rec["K_II_initiation"] = _initiation(rec)
            records.append(rec)
    ref = next((r for r in records if (r["method"], r["quadrature"]) == ("efg", "uniform")), None)
    for rec in records:
        same = next(
            r for r in records if r["method"] == rec["method"] and r["quadrature"] == "uniform"
        )
        rec["K_history_difference"] = _history_difference(rec, same)
        rec["ratio_to_efg_uniform"] = (
            rec["time_total"] / ref["time_total"] if ref is not None else None
        )
    return records


def report(records: list[dict]) -> None:
    """The runs as a markdown table."""
    columns = [("method", ""), ("quadrature", ""), ("dofs", "d"), ("kink (deg)", ".2f"),
               ("mean (deg)", ".2f"), ("K_I / K_II at init. (MPa m^.5)", ""), ("K diff.", ".1e"),
               ("steps", "d"), ("setup / steps / SIFs / rebuild / total (s)", ""),
               ("ratio to efg uniform", ".3f")]  # fmt: skip
    rows = []
    for r in records:
        k = (
            None
            if r["K_I_initiation"] is None
            else f"{r['K_I_initiation'] / 1e6:.2f} / {r['K_II_initiation'] / 1e6:.2f}"
        )
        times = " / ".join(
            f"{r[k2]:.2f}"
            for k2 in ("time_setup", "time_steps", "time_sifs", "time_crack", "time_total")
        )
        rows.append([r["method"], r["quadrature"], sum(r["dofs"].values()), r["kink_angle_deg"],
                     r["mean_angle_deg"], k, r["K_history_difference"], r["steps"], times,
                     r["ratio_to_efg_uniform"]])  # fmt: skip
    print_table(columns, rows, markdown=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--nodes", type=int, default=41, help="nodes per side (the paper: 101)")
    parser.add_argument("--t-end", type=float, default=40e-6)
    parser.add_argument("--method", nargs="+", default=["efg", "lagrange"])
    parser.add_argument(
        "--radius", type=float, default=8.0, help="dense zone radius in spacings (default 8)"
    )
    parser.add_argument("--far", type=int, default=3, help="coarse degree (3: 2 x 2 Gauss)")
    parser.add_argument(
        "--contact", type=float, default=0.0, help="crack-face contact factor (demo: 10)"
    )
    parser.add_argument("--impact", default="traction", help="traction or velocity (demo)")
    parser.add_argument("--small", action="store_true", help="CI smoke run: 21 nodes, 20 us")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    kw = load_demo("kalthoff_winkler")
    if args.small:
        args.nodes, args.t_end = 21, 20e-6
    # warm-up (JIT compilation excluded from the timings)
    for method in args.method:
        kw.run(method, 21, 2e-6, comm=comm, quadrature=lambda h: mf.AdaptiveQuadrature(8 * h))
    records = run_all(
        kw,
        args.nodes,
        args.t_end,
        args.radius,
        args.far,
        args.method,
        comm,
        args.contact,
        args.impact,
    )
    if comm.rank == 0:
        us = args.t_end * 1e6
        print(f"Kalthoff–Winkler, {args.nodes} nodes, {us:.0f} us, {comm.size} rank(s)")
        report(records)
        plain = [{k: v for k, v in r.items() if not k.startswith("_")} for r in records]
        write_json(
            args.json,
            plain,
            nodes=args.nodes,
            t_end=args.t_end,
            ranks=comm.size,
            dolfinx=mf.DOLFINX_VERSION,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
