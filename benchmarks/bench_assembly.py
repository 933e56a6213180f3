# # Benchmark: the particle stiffness assembly, scipy products against the compiled pass
#
# The EFG stiffness ``K = sum_q B_test^T D B_trial w_q`` (Belytschko et al. 1995, eq. 4.3) of the
# cantilever beam (48 x 12, quadrilateral cells of size h, particles on a grid of spacing h,
# Gauss degree 2, the library's defaults: VCI test gradients, so ``B_test != B_trial``) from the
# same tables by :func:`~dolfinx_meshfree.physics.operators.stiffness_matrix` with
# ``backend="scipy"`` (the sparse product) and ``backend="numba"``
# (:mod:`~dolfinx_meshfree.physics.assembly_kernel`). Each (size, backend) runs in its own
# process. Peak memory is the peak of ``tracemalloc`` during one assembly (numpy's arrays,
# which include the kernel's: it allocates its arrays with numpy; the output included), beside
# the size of the assembled matrix (data + indices + indptr). Times are medians of
# ``--repeats`` after one warm-up call (the numba compile or cache load excluded).
#
# Run: ``python benchmarks/bench_assembly.py [--h 1.0 0.5 0.25] [--json out.json]``.

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import tracemalloc

import dolfinx_meshfree as mf
from dolfinx_meshfree.geometry.quadrature import boundary_facets
from dolfinx_meshfree.physics.operators import stiffness_matrix
from dolfinx_meshfree.statics.efg import particle_stiffness

import dolfinx
import numpy as np
from harness import print_table, ratio, write_json
from mpi4py import MPI


def _status(field: str) -> int:
    """A ``/proc/self/status`` entry in bytes (VmRSS, VmHWM)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    raise RuntimeError(f"{field} not in /proc/self/status")


def peak_memory(fn) -> int:
    """Peak of the memory traced by ``tracemalloc`` while ``fn`` runs (numpy's arrays are
    traced; the compiled kernel's arrays are allocated by numpy for that reason), in bytes."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def worker(h: float, backend: str, repeats: int, consistent: bool) -> dict:
    """One size and backend: tables, then the assembly timed and its peak memory measured."""
    comm = MPI.COMM_SELF
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.array([0.0, -6.0]), np.array([48.0, 6.0])],
        [round(48 / h), round(12 / h)], dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    material = mf.LinearElastic(3e7, 0.3, plane="stress")
    particles = mf.ParticleSet.from_cells(msh, h)
    problem = mf.EFGElasticity(particles, material)
    tabs: dict = {}
    boundary = (boundary_facets(msh), None) if consistent else None
    particle_stiffness(
        particles, problem.mls, material, problem.quadrature_degree, boundary, tables=tabs
    )
    q, table = tabs["quadrature"], tabs["table"]

    def assemble():
        return stiffness_matrix(
            tabs["test_gradients"], q.weights, material, table.gradients,
            particles.petsc_index, backend=backend,
        )  # fmt: skip

    K = assemble()  # warm-up (numba: compile or cache load)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        assemble()
        times.append(time.perf_counter() - t0)
    peak = peak_memory(assemble)
    return {
        "h": h,
        "backend": backend,
        "consistent": consistent,
        "particles": particles.num_particles,
        "points": len(q.weights),
        "table_nnz": int(table.values.nnz),
        "K_nnz": int(K.nnz),
        "K_bytes": int(K.data.nbytes + K.indices.nbytes + K.indptr.nbytes),
        "time": float(np.median(times)),
        "peak_bytes": int(peak),
        "repeats": repeats,
        "K_norm": float(np.abs(K.data).max()),
        "K_sum": float(np.abs(K.data).sum()),
    }


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--h", nargs="+", type=float, default=[1.0, 0.5, 0.25])
    p.add_argument("--backends", nargs="+", default=["scipy", "numba"])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--no-consistent", action="store_true", help="plain Gauss (symmetric K)")
    p.add_argument("--json", default=None)
    p.add_argument("--worker", nargs=2, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    consistent = not args.no_consistent
    if args.worker is not None:
        print(json.dumps(worker(float(args.worker[0]), args.worker[1], args.repeats, consistent)))
        return []
    records = []
    for h in args.h:
        for backend in args.backends:
            cmd = [sys.executable, __file__, "--worker", str(h), backend]
            cmd += ["--repeats", str(args.repeats)] + (
                ["--no-consistent"] if not consistent else []
            )
            out = subprocess.run(cmd, check=True, capture_output=True, text=True)
            records.append(json.loads(out.stdout.strip().splitlines()[-1]))
    print(
        f"EFG stiffness assembly, cantilever, {'VCI' if consistent else 'Gauss'}, 1 process, "
        f"median of {args.repeats} (warm); peak = tracemalloc peak of one assembly"
    )
    columns = [("h", "5.3g"), ("particles", "9d"), ("points", "7d"), ("K nnz", "9d"),
               ("K MB", "6.1f"), ("backend", ">7"), ("time s", "8.3f"), ("peak MB", "8.1f"),
               ("peak/K", "6.2f")]  # fmt: skip
    rows = [
        [r["h"], r["particles"], r["points"], r["K_nnz"], r["K_bytes"] / 1e6, r["backend"],
         r["time"], r["peak_bytes"] / 1e6, ratio(r["peak_bytes"], r["K_bytes"])]
        for r in records
    ]  # fmt: skip
    print_table(columns, rows)
    by = {(r["h"], r["backend"]): r for r in records}
    for h in args.h:
        a, b = by.get((h, "scipy")), by.get((h, "numba"))
        if a and b:
            # the same matrix: norms of both equal to round-off (the tests check entries)
            assert abs(a["K_sum"] - b["K_sum"]) <= 1e-10 * a["K_sum"], (a["K_sum"], b["K_sum"])
            print(f"h = {h}: numba {a['time'] / b['time']:.1f}x faster, "
                  f"{a['peak_bytes'] / max(b['peak_bytes'], 1):.1f}x less peak memory")  # fmt: skip
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
