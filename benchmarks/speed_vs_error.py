# # Benchmark: time to a given error, FE against particles and patches (issue 26, item 3)
#
# The user's question is not the time at equal dofs but what a given accuracy costs. For each
# problem this benchmark runs every method over a refinement series (the demos' own models and
# runners), records its error beside its wall time (setup, assembly and solve; JIT excluded by
# an untimed first run at the coarsest size), and interpolates, between the two runs that
# bracket it, the time each method needs to reach the errors of the reference method (log-log,
# linear; up to a factor 2 below the finest run's error along its last two runs, flagged). Problems
# and methods:
#
# * ``cantilever`` (``demos/cantilever.py``, L2 and energy errors against Timoshenko's solution):
#   Q1 FE, pure EFG (VCI and smoothed integration), the Lagrange coupling with a patch of the
#   last 10, 25 and 50 % of the beam;
# * ``kirsch`` (``demos/kirsch_plate.py``, L2 error against Kirsch's solution): FE, pure EFG
#   (particles at the graded mesh's vertices), the Lagrange coupling on the ring r < 1.8 around
#   the hole;
# * ``cook`` (``demos/cooks_membrane.py``, finite strain, the corner's displacement against a P2
#   reference): FE, EFG, the Lagrange coupling on x > 32;
# * ``edge-crack`` (``demos/sif_edge_crack.py``, K_I against Tada's formula): EFG, the Lagrange
#   coupling on a box around the crack (FE alone carries no crack here: EFG is the reference).
#
# The Kalthoff–Winkler kink angle against its converged value is left out: one converged run
# takes minutes on these machines.
#
# Output: per problem and error measure, a table of each run (error, time) and a table of the
# time to reach each target error with its ratio to the reference method's (one run, the same
# machine: the ratios compare); PNG plots (``--png-dir``, error against time, log-log, one
# curve per method); JSON (``--json``). ``--small`` is the CI smoke run. Run:
# ``OMP_NUM_THREADS=1 python benchmarks/speed_vs_error.py --json out.json --png-dir out/``.

# +
from __future__ import annotations

import argparse
import pathlib
import time

import dolfinx_meshfree as mf

import numpy as np
from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI

PROBLEMS = ("cantilever", "kirsch", "cook", "edge-crack")
# -


# ## One run of each problem: (error measures, seconds)


# +
def cantilever(method: str, size: float, small: bool) -> tuple[dict, float]:
    """``method``: ``fe``, ``efg:<integration>`` or ``lagrange:<patch fraction>``; ``size``: h."""
    demo = load_demo("cantilever")
    name, _, option = method.partition(":")
    cli = ["--h", str(size), "--no-check"]
    if name == "efg":
        cli += ["--integration", option]
    if name == "lagrange":
        cli += ["--patch-fraction", option]
    args = demo.parse(cli)
    material = mf.LinearElastic(args.E, args.nu, args.plane)
    beam = mf.TimoshenkoBeam(material, L=args.L, D=args.D, P=args.P)
    comm = MPI.COMM_WORLD
    comm.Barrier()
    t0 = time.perf_counter()
    msh = demo.make_mesh(comm, args, size)
    errors, *_ = demo.run_method(msh, args, beam, material, size, name)
    seconds = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    return {"L2": errors["l2"], "energy": errors["energy"]}, seconds


def kirsch(method: str, size: float, small: bool) -> tuple[dict, float]:
    """``size``: cells per sector side. The demo's run times itself (mesh excluded)."""
    demo = load_demo("kirsch_plate")
    args = argparse.Namespace(grading=2.5, cell="quadrilateral", ring=1.8,
                              placement="conforming", spacing=1.0, integration="vci")  # fmt: skip
    r = demo.run(method, int(size), args)
    return {"L2": r["l2"]}, r["time"]


_COOK_REFERENCE: dict = {}


def cook(method: str, size: float, small: bool) -> tuple[dict, float]:
    """``size``: cells per side; the P2 reference computed once (not timed)."""
    demo = load_demo("cooks_membrane")
    args = argparse.Namespace(force=0.25, steps=2, ref_cells=16 if small else 48)
    if args.ref_cells not in _COOK_REFERENCE:
        _COOK_REFERENCE[args.ref_cells] = demo.reference(args)
    ref = _COOK_REFERENCE[args.ref_cells]
    r = demo.run(method, int(size), args)
    return {"corner": abs(r["corner_v"] - ref) / abs(ref)}, r["time_total"]


def edge_crack(method: str, size: float, small: bool) -> tuple[dict, float]:
    """``size``: h; the time is the solve's and the SIF's."""
    demo = load_demo("sif_edge_crack")
    r = demo.run(method, 0.4, size)
    seconds = MPI.COMM_WORLD.allreduce(r["times"]["solve"] + r["times"]["sif"], op=MPI.MAX)
    return {"K_I": abs(r["relative_error_KI"])}, seconds


#: Per problem: the runner and its methods (the first is the reference), each with its sizes
#: (coarse to fine) and the CI smoke run's. EFG starts coarser than FE: it is more accurate at
#: equal size, and its series must bracket FE's errors.
SERIES = {
    "cantilever": (
        cantilever,
        {
            "fe": ([2.0, 1.0, 0.5, 0.25], [3.0, 2.0]),
            "efg:vci": ([6.0, 4.0, 3.0, 2.0, 1.0], [6.0, 4.0]),
            "efg:smoothed": ([6.0, 4.0, 3.0, 2.0, 1.0], [6.0, 4.0]),
            "lagrange:0.1": ([2.0, 1.0, 0.5, 0.25], [3.0, 2.0]),
            "lagrange:0.25": ([2.0, 1.0, 0.5, 0.25], [3.0, 2.0]),
            "lagrange:0.5": ([2.0, 1.0, 0.5, 0.25], [3.0, 2.0]),
        },
    ),
    "kirsch": (
        kirsch,
        {
            "fe": ([8, 16, 32], [4, 8]),
            "efg": ([8, 16, 32], [4, 8]),
            "lagrange": ([8, 16, 32], [4, 8]),
        },
    ),
    "cook": (
        cook,
        {
            "fe": ([8, 16, 32], [4, 8]),
            "efg": ([4, 8, 16], [4, 8]),
            "lagrange": ([8, 16, 32], [4, 8]),
        },
    ),
    "edge-crack": (
        edge_crack,
        {
            "efg": ([0.05, 0.025, 0.0125], [0.1, 0.05]),
            "lagrange": ([0.05, 0.025, 0.0125], [0.1, 0.05]),
        },
    ),
}
# -


# ## Time to a target error


# +
#: How far below its finest run a method's series is extended (a factor on the error).
EXTRAPOLATION = 2.0


def time_to(errors: list[float], times: list[float], target: float) -> tuple[float | None, str]:
    """The time at which a method's error reaches ``target`` (runs in refinement order) and how
    it was found: ``"interpolated"`` (log-log, between the two runs that bracket it, or a run
    that hits it), ``"at most"`` (the coarsest run is already below it: its time bounds the
    cost from above), ``"extrapolated"`` (below the finest run's error by at most
    :data:`EXTRAPOLATION`, along the last two runs' log-log line, if the error fell there) or
    ``"not reached"`` (the time is ``None``)."""

    def along(k: int) -> float:
        e0, e1 = errors[k], errors[k + 1]
        s = (np.log(target) - np.log(e0)) / (np.log(e1) - np.log(e0))
        return float(np.exp(np.log(times[k]) + s * (np.log(times[k + 1]) - np.log(times[k]))))

    for k in range(len(errors) - 1):
        e0, e1 = errors[k], errors[k + 1]
        if min(e0, e1) <= target <= max(e0, e1) and e0 != e1:
            return along(k), "interpolated"
    if errors and errors[0] <= target:
        return times[0], "at most"
    if len(errors) >= 2 and errors[-1] < errors[-2] and target >= errors[-1] / EXTRAPOLATION:
        return along(len(errors) - 2), "extrapolated"
    return None, "not reached"


def targets_of(records: list[dict], measure: str, reference: str) -> list[float]:
    """The reference method's errors past its coarsest run: the accuracies to reach."""
    ref = [r["errors"][measure] for r in records if r["method"] == reference]
    return ref[1:]


def _plot(problem: str, measure: str, records: list[dict], methods: list[str], folder) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.0))
    for m in methods:
        runs = [r for r in records if r["method"] == m]
        ax.loglog([r["time"] for r in runs], [r["errors"][measure] for r in runs], "o-", label=m)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"{measure} error")
    ax.set_title(f"{problem}: {measure} error against time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    path = pathlib.Path(folder) / f"speed_vs_error_{problem}_{measure}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return str(path)


# -


# ## Main


# +
def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--problem", nargs="+", choices=PROBLEMS, default=list(PROBLEMS))
    p.add_argument("--small", action="store_true", help="CI smoke run: two coarse sizes")
    p.add_argument("--json", default=None)
    p.add_argument("--png-dir", default=None, help="write the plots there")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> dict:
    args = parse(argv)
    comm = MPI.COMM_WORLD
    out: dict = {"runs": [], "targets": [], "plots": []}
    for problem in args.problem:
        runner, series = SERIES[problem]
        methods = list(series)
        records = []
        for m in methods:
            sizes = series[m][1] if args.small else series[m][0]
            runner(m, sizes[0], args.small)  # untimed: JIT, caches
            for s in sizes:
                errors, seconds = runner(m, s, args.small)
                records.append({"problem": problem, "method": m, "size": s, "errors": errors,
                                "time": seconds, "ranks": comm.size})  # fmt: skip
        out["runs"] += records
        for measure in records[0]["errors"]:
            rows = []
            for target in targets_of(records, measure, methods[0]):
                ref_time = None
                for m in methods:
                    runs = [r for r in records if r["method"] == m]
                    t, how = time_to(
                        [r["errors"][measure] for r in runs], [r["time"] for r in runs], target
                    )
                    ref_time = t if m == methods[0] else ref_time
                    rows.append({
                        "problem": problem, "measure": measure, "target": target, "method": m,
                        "time": t, "found": how, "x_reference": ratio(t, ref_time),
                    })  # fmt: skip
            out["targets"] += rows
            if comm.rank == 0:
                print(f"\n{problem}: {measure} error, {comm.size} rank(s) (JIT excluded)")
                print_table(
                    [("method", "<14"), ("size", "7.4g"), ("error", "10.3e"), ("time s", "8.3f")],
                    [(r["method"], r["size"], r["errors"][measure], r["time"]) for r in records],
                )  # fmt: skip
                print(f"time to reach the errors of {methods[0]} (x {methods[0]}'s time):")
                print_table(
                    [("method", "<14"), ("target", "10.3e"), ("time s", "8.3f"),
                     (f"x {methods[0]}", "8.2f"), ("found", "<12")],
                    [(r["method"], r["target"], r["time"], r["x_reference"], r["found"])
                     for r in rows],
                )  # fmt: skip
                if args.png_dir:
                    out["plots"].append(_plot(problem, measure, records, methods, args.png_dir))
    write_json(args.json, out["runs"], targets=out["targets"], plots=out["plots"])
    return out


if __name__ == "__main__":
    main()
