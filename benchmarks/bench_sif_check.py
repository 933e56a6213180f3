# # Benchmark: a dynamic SIF check by kept linear functionals, against the full integral
#
# Issue 26, item 2: for a fixed tip and domains K_I and K_II are linear in the particle
# coefficients of the displacement and the acceleration, so a check of a growing crack can be
# a few dot products on weight vectors tabulated once per tip position
# (:class:`~dolfinx_meshfree.statics.sif_functional.SIFFunctional`; ``dynamic_sifs(...,
# j_integral=False)``, which the growth criterion uses). The target: a check at 1 % of the time
# of the full interaction integral.
#
# The model is Kalthoff–Winkler's (``demos/kalthoff_winkler.py``) at ``--nodes`` nodes per side
# (the paper's 101), with crack-face contact (the demo's default penalty, 10 E / h), run to
# ``--time`` (15 us: the waves have reached the notch tip). At that state, inside an output
# callback (where the step's own internal force serves the acceleration, as in a growth check),
# alternating ``--rounds`` times and keeping each one's fastest (``--calls`` calls per round):
#
# * ``full``: ``dynamic_sifs(..., probe=False)``, the interaction integral with J: the MLS is
#   tabulated at its points at each call;
# * ``tables``: the kept tables made again (``mls.changed()``, then a check): what a check
#   costs when the tip has moved;
# * ``kept``: ``dynamic_sifs(..., probe=False, j_integral=False)`` with its tables kept: the
#   acceleration, the gather of the particles the tables read, the dot products and the crack
#   faces' contact term.
#
# ``K diff`` is the largest difference of the kept check's K_I, K_II from the full integral's,
# relative to the largest |K| (checked by the smoke test: 1e-12). Then the demo's whole growth
# run (to ``--t-end``, 80 us) of the same method: its SIF seconds over its checks, the tables of
# each moved tip included. Methods: ``--methods`` (pure EFG and the couplings' particle box).
# Prints a table, writes JSON (``--json``); ``--small`` is a smoke run for CI (no timing is
# checked anywhere).

# +
from __future__ import annotations

import argparse
import time

import dolfinx_meshfree as mf  # first: the MPI of the lane
from dolfinx_meshfree.dynamics import CrackContact
from dolfinx_meshfree.dynamics.sifs import dynamic_sifs

import numpy as np
from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI

KW = load_demo("kalthoff_winkler")
CONTACT = 10.0  # the demo's default penalty factor (k = 10 E / h)


def fastest(fn, rounds: int, calls: int) -> float:
    """The fastest of ``rounds`` rounds of ``calls`` calls of ``fn``, seconds per call."""
    best = np.inf
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return float(best)


def check_costs(method: str, nodes: int, at: float, rounds: int, calls: int) -> dict:
    """The three costs of one check at ``at`` seconds (module header) and the K difference."""
    msh, h, slot_end, yc = KW.geometry(nodes, slot=method != "efg", box=KW.BOX)
    crack = mf.Crack([[slot_end, yc], [KW.NOTCH_A, yc]])
    dyn = KW.builder(method, msh, h, contact=CrackContact(CONTACT))(crack)
    radius = np.asarray(KW.RADII) * h
    tip = crack.points[-1].copy()
    out: dict = {}

    def kept():
        return dynamic_sifs(dyn, crack, tip, radius, probe=False, j_integral=False)

    def full():
        return dynamic_sifs(dyn, crack, tip, radius, probe=False)

    def tables():
        dyn.mls.changed()  # the version moves: every kept table is made again
        return kept()

    def measure(model, step, t) -> None:
        fast, whole = kept(), full()  # the first calls make the tables (and warm the JIT)
        scale = np.abs(np.concatenate([whole.K_I, whole.K_II])).max()
        diff = max(np.abs(fast.K_I - whole.K_I).max(), np.abs(fast.K_II - whole.K_II).max())
        times = {"full": np.inf, "tables": np.inf, "kept": np.inf}
        for _ in range(rounds):  # alternating: each case's fastest round
            for name, fn, n in (("full", full, 1), ("tables", tables, 1), ("kept", kept, calls)):
                times[name] = min(times[name], fastest(fn, 1, n))
        out.update(
            K_I=float(whole.K_I.mean()), K_II=float(whole.K_II.mean()),
            K_difference=float(diff / scale), **{f"time_{k}": v for k, v in times.items()},
        )  # fmt: skip

    dyn.run(at, outputs=[at], on_output=measure)
    out.update(method=method, nodes=nodes, time=at, particles=dyn.particles.num_particles)
    dyn.destroy()
    return out


def growth_run(method: str, nodes: int, t_end: float) -> dict:
    """The demo's growth run: its SIF seconds, checks and moved tips."""
    rec = KW.run(method, nodes, t_end, contact=CrackContact(CONTACT))
    return {
        "run_checks": len(rec["checks"]),
        "run_extensions": rec["extensions"],
        "run_time_sifs": rec["time_sifs"],
        "run_time_total": rec["time_total"],
        "run_kink_angle_deg": rec["kink_angle_deg"],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--methods", nargs="+", default=["efg", "lagrange"])
    parser.add_argument("--nodes", type=int, default=101)
    parser.add_argument("--time", type=float, default=15e-6, help="the state timed (s)")
    parser.add_argument("--t-end", type=float, default=80e-6, help="the growth run's end (s)")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--calls", type=int, default=20, help="kept checks per round")
    parser.add_argument("--small", action="store_true", help="smoke run: 41 nodes, 20 us")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    if args.small:
        args.nodes, args.t_end, args.rounds, args.calls = 41, 20e-6, 2, 3
    records = []
    for method in args.methods:
        rec = check_costs(method, args.nodes, args.time, args.rounds, args.calls)
        rec.update(growth_run(method, args.nodes, args.t_end))
        records.append(rec)
    if MPI.COMM_WORLD.rank == 0:
        print(f"Kalthoff-Winkler, {args.nodes} x {args.nodes} nodes, a check at "
              f"{args.time * 1e6:g} us; the growth run to {args.t_end * 1e6:g} us")  # fmt: skip
        rows = []
        for r in records:
            per_check = r["run_time_sifs"] / max(r["run_checks"], 1)
            rows.append([
                r["method"], r["particles"], 1e3 * r["time_full"], 1e3 * r["time_tables"],
                1e3 * r["time_kept"], 100 * ratio(r["time_kept"], r["time_full"]),
                r["K_difference"], r["run_checks"], r["run_extensions"], 1e3 * per_check,
                100 * ratio(per_check, r["time_full"]),
            ])  # fmt: skip
        print_table(
            [("method", "<9"), ("particles", "9d"), ("full ms", "8.2f"), ("tables ms", "9.2f"),
             ("kept ms", "8.3f"), ("kept %", "7.2f"), ("K diff", "9.1e"), ("checks", "6d"),
             ("tips", "4d"), ("run ms/check", "12.3f"), ("run %", "6.2f")],
            rows,
        )  # fmt: skip
    write_json(args.json, records)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
