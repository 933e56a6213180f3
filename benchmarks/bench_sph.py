# # Benchmark: SPH tabulation, the numpy reference against the compiled path
#
# Particles on a jittered grid in the unit square (volumes 1/n^2), four evaluation points per
# particle at random inside; SPH values and gradients (cubic spline, default smoothing length)
# without correction and with the gradient correction, by the numpy reference and the compiled
# (numba) path in the same run: points per CPU second (median of ``--repeats``; the first call,
# compilation or loading numba's cache, excluded) and the largest difference between the two
# (relative to the largest entry, values and gradients). Prints a table and writes JSON
# (``--json``). ``--small`` is a smoke run for CI (no timing is checked anywhere).

# +
from __future__ import annotations

import argparse
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx import jit

import numpy as np
from harness import median_time, print_table, ratio, write_json

# -


def cloud(n_side: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Jittered grid of ``(n_side + 1)^2`` particles, their volumes and four random
    evaluation points per particle."""
    rng = np.random.default_rng(seed)
    ax = np.linspace(0.0, 1.0, n_side + 1)
    P = np.stack(np.meshgrid(ax, ax, indexing="ij"), axis=-1).reshape(-1, 2)
    inner = np.all((P > 0) & (P < 1), axis=1)
    P[inner] += rng.uniform(-0.3, 0.3, (inner.sum(), 2)) / n_side
    return P, np.full(P.shape[0], n_side**-2.0), rng.uniform(0.0, 1.0, (4 * P.shape[0], 2))


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--sizes", nargs="+", type=int, default=[50, 100, 200])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--small", action="store_true", help="a smoke run (CI)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    sizes, repeats = ([10], 1) if args.small else (args.sizes, args.repeats)
    backends = ["numpy", "numba"] if jit.AVAILABLE else ["numpy"]
    records = []
    for n_side in sizes:
        P, vol, x = cloud(n_side)
        for correction in (None, "gradient"):
            rec = {"particles": P.shape[0], "points": x.shape[0], "correction": correction}
            tables = {}
            for backend in backends:
                sph = mf.SPH(P, vol, correction=correction, backend=backend)
                sph.tabulate(x[:8])  # compile or load the cache
                tables[backend] = sph.tabulate(x)
                t = median_time(lambda sph=sph, x=x: sph.tabulate(x), repeats, time.process_time)
                rec[f"points_per_cpu_second_{backend}"] = x.shape[0] / t
            rec["pairs_per_point"] = tables["numpy"].values.nnz / x.shape[0]
            if "numba" in tables:
                a, b = tables["numpy"], tables["numba"]
                rec["max_difference"] = max(
                    float(abs(u - v).max() / abs(u).max())
                    for u, v in zip([a.values, *a.gradients], [b.values, *b.gradients], strict=True)
                )
            records.append(rec)
    print(f"SPH tabulation with gradients, 1 thread, points per CPU second, median of {repeats}")
    columns = [("particles", "9d"), ("points", "8d"), ("correction", "10"), ("numpy", "9.3g"),
               ("numba", "9.3g"), ("x", "5.1f"), ("max diff", "9.1e")]  # fmt: skip
    rows = []
    for r in records:
        numpy, nb = r["points_per_cpu_second_numpy"], r.get("points_per_cpu_second_numba")
        rows.append([r["particles"], r["points"], str(r["correction"]), numpy, nb,
                     ratio(nb, numpy), r.get("max_difference")])  # fmt: skip
    print_table(columns, rows)
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
