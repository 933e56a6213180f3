# # Benchmark: speed and scale (issue 12), first version
#
# Two parts, each printed as a table and written to JSON (``--json``, one record per run):
#
# 1. **MLS tabulation with gradients**, points per second, the numpy reference and the compiled
#    (numba) path in the same run, for the 2D linear, 2D quadratic and 3D linear bases (quartic
#    weight) at three sizes: particles on a jittered grid in the unit square / cube, four
#    evaluation points per particle at random inside. Next to the speed, the largest difference
#    between the two paths (relative to the largest entry, values and gradients): the cost of
#    speed in accuracy. The first compiled call (compilation, or loading numba's on-disk cache)
#    is timed separately and excluded; timings are medians of ``--repeats``.
# 2. **Static cantilever** (``demos/cantilever.py``, Timoshenko beam): pure FE and pure EFG at
#    the same element size (particles on the vertices: equal dofs), EFG with each MLS backend;
#    total time (setup + assembly + solve; FE JIT excluded) and L2 error, and EFG/FE ratios.
#
#    The compiled path runs on one thread and on two (``--threads``, set through
#    ``DOLFINX_MESHFREE_THREADS``): per CPU second the figure per core, per wall-clock second the
#    parallel speed.
#
# Run with ``OMP_NUM_THREADS=1`` (as recorded in the JSON);
# the numbers are machine dependent, compare the ratios of one run. ``--small`` is a smoke run
# of a few seconds for CI (no timing is checked anywhere). This supersedes the MLS part of
# ``demos/bench_tabulation.py``.

# +
from __future__ import annotations

import argparse
import json
import os
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.approx import mls as mls_module

import numpy as np
from bench_common import load_demo
from mpi4py import MPI

# -

#: (gdim, basis, dilation, particles per side at the three sizes, and with --small)
CASES = [
    (2, "linear", 2.0, (50, 100, 200), (20,)),
    (2, "quadratic", 2.8, (25, 50, 100), (12,)),
    (3, "linear", 2.0, (10, 16, 25), (6,)),
]


def particles_and_points(gdim: int, n_side: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Jittered grid of ``(n_side + 1)^gdim`` particles in the unit box, and four random
    evaluation points per particle inside it."""
    rng = np.random.default_rng(seed)
    ax = np.linspace(0.0, 1.0, n_side + 1)
    P = np.stack(np.meshgrid(*[ax] * gdim, indexing="ij"), axis=-1).reshape(-1, gdim)
    inner = np.all((P > 0) & (P < 1), axis=1)
    P[inner] += rng.uniform(-0.3, 0.3, (inner.sum(), gdim)) / n_side
    x = rng.uniform(0.0, 1.0, (4 * P.shape[0], gdim))
    return P, x


def spatial_order(x: np.ndarray, n_side: int) -> np.ndarray:
    """An ordering of the points ``x`` by the cells of the particle grid (lexicographic), as
    quadrature points come cell by cell: the random points' order is the worst case for the
    caches, this one the usual case."""
    cells = np.floor(x * n_side).astype(np.int64)
    return np.lexsort(cells.T[::-1])


def median_time(fn, repeats: int) -> tuple[float, float]:
    """Median wall-clock and CPU (process) time of ``fn``: on a shared machine the CPU time is
    the steadier figure of the two."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.median(cpu))


def max_difference(a: mf.ShapeTable, b: mf.ShapeTable) -> float:
    """Largest difference of values and gradients, relative to the largest entry of each."""
    out = 0.0
    for ma, mb in zip([a.values, *a.gradients], [b.values, *b.gradients], strict=True):
        out = max(out, float(abs(ma - mb).max() / abs(ma).max()))
    return out


def set_threads(n: int | None) -> None:
    """Let the compiled path use ``n`` threads (``DOLFINX_MESHFREE_THREADS``; None: unset)."""
    if n is None:
        os.environ.pop("DOLFINX_MESHFREE_THREADS", None)
    else:
        os.environ["DOLFINX_MESHFREE_THREADS"] = str(n)


def bench_mls(sizes_index: str, repeats: int, threads: list[int]) -> list[dict]:
    records = []
    runs = ["numpy"]
    if jit.AVAILABLE:
        runs += ["numba"] + [f"numba{t}" for t in threads if t != 1]  # 1 thread always
    saved = os.environ.get("DOLFINX_MESHFREE_THREADS")
    for gdim, basis, dilation, sizes, small in CASES:
        for n_side in small if sizes_index == "small" else sizes:
            P, x = particles_and_points(gdim, n_side)
            tables, rec = {}, {}
            for run in runs:
                backend = "numpy" if run == "numpy" else "numba"
                if backend == "numba":
                    set_threads(int(run[5:] or 1))
                mls = mf.MLS(P, dilation=dilation, basis=basis, backend=backend)
                t0 = time.perf_counter()
                mls.tabulate(x[:8])  # compile or load the cache; builds the cell list
                first = time.perf_counter() - t0
                tables[run] = mls.tabulate(x)
                t, cpu = median_time(lambda mls=mls, x=x: mls.tabulate(x), repeats)
                if run == "numba":  # the same points in spatial order (as quadrature by cell)
                    xs = x[spatial_order(x, n_side)]
                    mls.tabulate(xs)
                    ts, cs = median_time(lambda mls=mls, xs=xs: mls.tabulate(xs), repeats)
                    rec["numba_sorted"] = {
                        "time": ts,
                        "cpu_time": cs,
                        "points_per_second": x.shape[0] / ts,
                        "points_per_cpu_second": x.shape[0] / cs,
                    }
                rec[run] = {
                    "time": t,
                    "cpu_time": cpu,
                    "points_per_second": x.shape[0] / t,
                    "points_per_cpu_second": x.shape[0] / cpu,
                    "first": first,
                }
            records.append(
                {
                    "kind": "mls",
                    "gdim": gdim,
                    "basis": basis,
                    "weight": "quartic",
                    "dilation": dilation,
                    "particles": P.shape[0],
                    "points": x.shape[0],
                    "pairs_per_point": tables["numpy"].values.nnz / x.shape[0],
                    **{f"time_{b}": r["time"] for b, r in rec.items()},
                    **{f"cpu_time_{b}": r["cpu_time"] for b, r in rec.items()},
                    **{f"points_per_second_{b}": r["points_per_second"] for b, r in rec.items()},
                    **{
                        f"points_per_cpu_second_{b}": r["points_per_cpu_second"]
                        for b, r in rec.items()
                    },
                    "time_first_call_numba": rec.get("numba", {}).get("first"),
                    "max_difference": (
                        max_difference(tables["numpy"], tables["numba"])
                        if "numba" in tables
                        else None
                    ),
                    "repeats": repeats,
                    "max_difference_threads": max(
                        (max_difference(tables["numba"], tables[r]) for r in runs[2:]),
                        default=None,
                    ),
                }
            )
    set_threads(None if saved is None else int(saved))
    return records


def bench_static(hs: list[float]) -> list[dict]:
    """FE and EFG (each MLS backend) on the cantilever; EFG/FE time ratios at equal h."""
    cantilever = load_demo("cantilever")
    h_args = [str(h) for h in hs]
    records = []
    saved = mls_module.DEFAULT_BACKEND
    try:
        for backend in ["numpy", "numba"] if jit.AVAILABLE else ["numpy"]:
            mls_module.DEFAULT_BACKEND = backend
            methods = ["fe", "efg"] if backend == "numpy" else ["efg"]
            for r in cantilever.main(["--method", *methods, "--h", *h_args, "--no-check"]):
                r = {"kind": "static", **r}
                r["mls_backend"] = backend if r["method"] == "efg" else None
                records.append(r)
    finally:
        mls_module.DEFAULT_BACKEND = saved
    fe = {r["h"]: r for r in records if r["method"] == "fe"}
    for r in records:
        r["time_ratio_to_fe"] = r["time_total"] / fe[r["h"]]["time_total"]
    return records


def report(mls: list[dict], static: list[dict]) -> None:
    print(
        f"MLS tabulation with gradients, quartic weight, 1 rank (OMP_NUM_THREADS="
        f"{os.environ.get('OMP_NUM_THREADS', 'unset')}), median of {mls[0]['repeats']}; "
        "first numba call (compile or cache load) excluded"
    )
    print(
        "points per second of wall-clock time (per CPU second in brackets); numba2: 2 threads; "
        "numba sorted: the same points in spatial order"
    )
    two = "points_per_second_numba2" in mls[0]
    head = (
        f"{'case':>12} {'particles':>9} {'points':>8} {'pairs/pt':>8} {'numpy pts/s':>21} "
        f"{'numba pts/s':>21} {'numba sorted pts/s':>21} {'numba2 pts/s' if two else '':>21} "
        f"{'speed-up':>8} "
        f"{'1st call s':>10} {'max diff':>9}"
    )
    print(head)
    print("-" * len(head))
    for r in mls:
        nan = float("nan")
        nb = r.get("points_per_second_numba") or nan
        nb_cpu = r.get("points_per_cpu_second_numba") or nan
        first = r["time_first_call_numba"] or nan
        diff = nan if r["max_difference"] is None else r["max_difference"]
        numpy = f"{r['points_per_second_numpy']:.3g} ({r['points_per_cpu_second_numpy']:.3g})"
        numba = f"{nb:.3g} ({nb_cpu:.3g})"
        srt = (
            f"{r['points_per_second_numba_sorted']:.3g} "
            f"({r['points_per_cpu_second_numba_sorted']:.3g})"
            if "points_per_second_numba_sorted" in r
            else ""
        )
        numba2 = (
            f"{r['points_per_second_numba2']:.3g} ({r['points_per_cpu_second_numba2']:.3g})"
            if two
            else ""
        )
        print(
            f"{r['gdim']}D {r['basis']:>9} {r['particles']:9d} {r['points']:8d} "
            f"{r['pairs_per_point']:8.1f} {numpy:>21} {numba:>21} {srt:>21} {numba2:>21} "
            f"{nb / r['points_per_second_numpy']:8.1f} {first:10.3f} {diff:9.1e}"
        )
    if not static:
        return
    print("\nStatic cantilever, EFG vs FE at equal h (particles on the vertices)")
    head = (
        f"{'method':>6} {'backend':>7} {'h':>5} {'dofs':>7} {'L2 error':>9} {'total s':>8} "
        f"{'x FE':>6}"
    )
    print(head)
    print("-" * len(head))
    for r in static:
        dofs = r["fe_dofs"] + r["particle_dofs"]
        print(
            f"{r['method']:>6} {(r['mls_backend'] or '-'):>7} {r['h']:5.3g} {dofs:7d} "
            f"{r['error_l2']:9.2e} {r['time_total']:8.3f} {r['time_ratio_to_fe']:6.2f}"
        )


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--small", action="store_true", help="a smoke run of a few seconds (CI)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--h", nargs="+", type=float, default=[1.0, 0.5], help="static: FE sizes")
    p.add_argument("--no-static", action="store_true", help="only the MLS tabulation")
    p.add_argument("--json", default=None)
    p.add_argument(
        "--threads", nargs="+", type=int, default=[1, 2], help="MLS: threads of the compiled path"
    )
    args = p.parse_args(argv)
    repeats = 1 if args.small else args.repeats
    mls = bench_mls("small" if args.small else "full", repeats, args.threads)
    static = [] if args.no_static else bench_static([3.0] if args.small else args.h)
    comm = MPI.COMM_WORLD
    env = {
        "ranks": comm.size,
        "dolfinx_version": mf.DOLFINX_VERSION,
        "numba": jit.AVAILABLE,
        "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS"),
        "NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS"),
    }
    records = [{**r, **env} for r in mls + static]
    if comm.rank == 0:
        report(mls, static)
        if args.json:
            with open(args.json, "w") as f:
                json.dump(records, f, indent=1)
    return records


if __name__ == "__main__":
    main()
