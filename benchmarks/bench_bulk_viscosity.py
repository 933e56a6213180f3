# # Benchmark: the rate-form laws' bulk viscosity, what it costs and what it buys
#
# ``mf.BulkViscosity`` (``physics/bulk_viscosity.py``) is on by default. Its damper lowers the
# stable step, so a run takes more steps, and each step costs a little more (``q`` at every
# point, its work, the damper checked at every step). What it buys is a damage field that does
# not move with the time step. This benchmark measures both on the concrete bar of
# ``demos/concrete_impact.py`` (300 m/s, on rollers) for each ``--method``, with the default
# viscosity and with ``viscosity=None``, in one run. Per case it reports:
#
# - the steps and the seconds of the run at the stable step, and the ratio with/without;
# - the failed depth (``D >= 0.99``) and the half-damaged depth (``D >= 0.5``) at the stable
#   step and at half of it, and how far they moved (in cells): the error the ringing makes.
#
# It also times the Hanchak shot of ``demos/hanchak.py`` (lagrange, 16 cells, 1060 m/s, rigid
# projectile) with and without the viscosity, and prints its exit velocity and steps. The
# seconds are the median of ``--repeats`` runs after one warm-up run, so the JIT's compile is
# not counted. The table is printed and JSON is written (``--json``). ``--small`` is a smoke
# run for CI (FE at 20 cells, no Hanchak shot; no timing is checked anywhere).

# +
from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
from harness import load_demo, print_table, ratio, write_json

# -


def bar_run(demo, method: str, cells: int, law, fraction: float) -> dict:
    """One run of the demo's bar at 300 m/s at ``fraction`` of the stable step."""
    dyn = demo.build(method, cells, law=law)
    dyn.set_initial(velocity=lambda x: np.stack([np.full(len(x), -300.0), 0 * x[:, 0]], 1))
    t0 = time.perf_counter()
    res = dyn.run(demo.T_END, dt=fraction * dyn.stable_time_step())
    seconds = time.perf_counter() - t0
    damage = dyn.material.state["damage"][:, 0]
    out = {
        "steps": res.steps,
        "seconds": seconds,
        "failed": demo.depth(dyn, damage >= 0.99),
        "half": demo.depth(dyn, damage >= 0.5),
    }
    dyn.destroy()
    return out


def bar_case(demo, method: str, cells: int, viscous: bool, repeats: int) -> dict:
    """The bar with or without the viscosity: its cost at the stable step (median seconds) and
    its depths at the stable step and at half of it."""
    law = demo.CONCRETE if viscous else dataclasses.replace(demo.CONCRETE, viscosity=None)
    bar_run(demo, method, cells, law, 1.0)  # warm-up: the laws' and the kernels' compile
    runs = [bar_run(demo, method, cells, law, 1.0) for _ in range(repeats)]
    half = bar_run(demo, method, cells, law, 0.5)
    h = demo.LENGTH / cells
    return {
        "case": "bar",
        "method": method,
        "cells": cells,
        "viscosity": viscous,
        "steps": runs[0]["steps"],
        "seconds": float(np.median([r["seconds"] for r in runs])),
        "failed_depth": runs[0]["failed"],
        "failed_depth_half_step": half["failed"],
        "failed_moved_cells": abs(runs[0]["failed"] - half["failed"]) / h,
        "half_depth": runs[0]["half"],
        "half_depth_half_step": half["half"],
        "half_moved_cells": abs(runs[0]["half"] - half["half"]) / h,
    }


def shot_case(viscous: bool, repeats: int) -> dict:
    """The Hanchak lagrange shot, 16 cells, 1060 m/s: median seconds, steps, exit velocity."""
    demo = load_demo("hanchak")
    concrete = demo.CONCRETE if viscous else dataclasses.replace(demo.CONCRETE, viscosity=None)

    def shot() -> dict:
        t0 = time.perf_counter()
        r = demo.perforate("lagrange", 16, 1060.0, readings=False, concrete=concrete)
        return {**r, "seconds": time.perf_counter() - t0}

    shot()  # warm-up
    runs = [shot() for _ in range(repeats)]
    return {
        "case": "hanchak",
        "method": "lagrange",
        "cells": 16,
        "viscosity": viscous,
        "steps": runs[0]["steps"],
        "seconds": float(np.median([r["seconds"] for r in runs])),
        "residual_velocity": runs[0]["residual_velocity"],
    }


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--method", nargs="+", default=["fe", "efg", "lagrange"])
    p.add_argument("--cells", nargs="+", type=int, default=[20, 40])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--small", action="store_true", help="a smoke run (CI)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    methods, cells, repeats = (["fe"], [20], 1) if args.small else (
        args.method, args.cells, args.repeats)  # fmt: skip
    demo = load_demo("concrete_impact")
    records = [
        bar_case(demo, m, n, viscous, repeats)
        for n in cells
        for m in methods
        for viscous in (True, False)
    ]
    if not args.small:
        records += [shot_case(viscous, repeats) for viscous in (True, False)]
    print(
        "The bulk viscosity: cost (steps, median seconds after a warm-up, with/without in one run)"
        " and the depths at the stable step and at half of it (mm; moved: in cells)"
    )
    plain = {(r["case"], r["method"], r["cells"]): r for r in records if not r["viscosity"]}
    columns = [("case", "<8"), ("method", "<9"), ("cells", "5d"), ("visc", ">5"),
               ("steps", "6d"), ("s", "8.3f"), ("x none", "7.2f"), ("failed", "7.1f"),
               ("at dt/2", "8.1f"), ("moved", "6.1f"), ("D>=0.5", "7.1f"), ("at dt/2", "8.1f"),
               ("moved", "6.1f"), ("exit m/s", "9.2f")]  # fmt: skip
    rows = []
    for r in records:
        ref = plain[(r["case"], r["method"], r["cells"])]
        bar = r["case"] == "bar"
        rows.append([
            r["case"], r["method"], r["cells"], "on" if r["viscosity"] else "none", r["steps"],
            r["seconds"], ratio(r["seconds"], ref["seconds"]),
            1e3 * r["failed_depth"] if bar else None,
            1e3 * r["failed_depth_half_step"] if bar else None,
            r["failed_moved_cells"] if bar else None,
            1e3 * r["half_depth"] if bar else None,
            1e3 * r["half_depth_half_step"] if bar else None,
            r["half_moved_cells"] if bar else None,
            r.get("residual_velocity"),
        ])  # fmt: skip
    print_table(columns, rows)
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
