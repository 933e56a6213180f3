# # Benchmark: the explicit step's sparse products against the machine's memory bandwidth
#
# Issue 26, item 4. An explicit step is memory-bound: its cost is the stiffness product
# `f_int = K u` of every field, and a product streams the matrix once. This benchmark measures
# the machine's bandwidth by the STREAM triad (`a = b + s c` over arrays far larger than the
# caches: 3 x 8 bytes per entry, the best of `--repeats`; compiled with numba, or two numpy
# passes, 5 x 8 bytes, without it) and, in the same run, the products of explicit models of a
# plate: FE (vector Q1) and pure EFG (particles at the element size), each stiffness as BAIJ
# with block size 2 (the default of `ExplicitDynamics`) and converted to AIJ. For
# each product: the bytes it must move at least (values and column indices of every stored
# entry, the row offsets, `u` read once and `f` written once), the CPU time of one product
# (`MatMult`, one rank; best of `--repeats` batches of 20, `bench_blocks.best_product`) and the
# achieved bandwidth, also as a fraction of STREAM's.
# Prints a table and writes JSON (`--json`). `--small` is a smoke run for CI (no timing is
# checked anywhere).

# +
from __future__ import annotations

import argparse

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx import jit

import dolfinx
import numpy as np
from bench_blocks import best_product
from harness import median_time, print_table, write_json
from mpi4py import MPI
from petsc4py import PETSc

MATERIAL = mf.LinearElastic(E=200.0, nu=0.3, plane="strain", rho=7.8)
#: Bytes of a PETSc index (PetscInt) and of a value.
INDEX = np.dtype(PETSc.IntType).itemsize
VALUE = np.dtype(PETSc.ScalarType).itemsize
# -


# ## STREAM triad


# +
if jit.AVAILABLE:

    @jit.jit
    def _triad(a: np.ndarray, b: np.ndarray, c: np.ndarray, s: float) -> None:
        for i in range(a.size):
            a[i] = b[i] + s * c[i]


def stream_triad(n: int, repeats: int) -> tuple[float, str]:
    """Best bandwidth (bytes/s) of ``a = b + s c`` over ``n`` doubles, and how it was run."""
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    if jit.AVAILABLE:
        _triad(a[:8], b[:8], c[:8], 3.0)  # compile (or load the cache) outside the timing
        best = min(median_time(lambda: _triad(a, b, c, 3.0), 1) for _ in range(repeats))
        return 3 * VALUE * n / best, "numba loop, 3 x 8 bytes per entry"

    def passes() -> None:
        np.multiply(c, 3.0, out=a)
        np.add(a, b, out=a)

    best = min(median_time(passes, 1) for _ in range(repeats))
    return 5 * VALUE * n / best, "numpy, two passes, 5 x 8 bytes per entry"


# -


# ## The products of explicit models


# +
def product_bytes(K: PETSc.Mat) -> tuple[int, int, int]:
    """``(bytes, rows, stored entries)`` a product ``K u`` must move at least: every stored
    value and block column index, the row offsets, ``u`` read once and ``f`` written once."""
    rows, cols = K.getSize()
    bs = K.getBlockSize() if K.getType().endswith("baij") else 1
    nnz = int(K.getInfo()["nz_used"])
    blocks = nnz // (bs * bs)
    matrix = nnz * VALUE + blocks * INDEX + (rows // bs + 1) * INDEX
    return matrix + (rows + cols) * VALUE, rows, nnz


def models(n: int) -> list[tuple[str, PETSc.Mat, list]]:
    """The stiffness matrices of an FE and a pure-EFG explicit model of the unit square with
    ``n x n`` quadrilaterals (and the objects to destroy)."""
    msh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, n, n, dolfinx.mesh.CellType.quadrilateral)
    V = _compat.vector_function_space(msh)
    fe = mf.ExplicitDynamics.fe(V, MATERIAL)
    efg = mf.ExplicitDynamics.efg(mf.ParticleSet.from_cells(msh, 1.0 / n), MATERIAL)
    out = []
    for name, dyn in (("FE Q1", fe), ("EFG", efg)):
        K = dyn.system.fields[0].K  # BAIJ, block size 2 (the default)
        aij = PETSc.Mat()
        K.convert("aij", aij)
        out += [(name, K, [dyn]), (name, aij, [aij])]
    return out


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--cells", nargs="+", type=int, default=[100, 200, 400])
    p.add_argument("--stream", type=int, default=2**25, help="STREAM array length")
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--small", action="store_true", help="a smoke run (CI)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    if args.small:
        args.cells, args.stream, args.repeats = [8], 2**16, 2
    stream, how = stream_triad(args.stream, args.repeats)
    records = []
    for n in args.cells:
        for name, K, owned in models(n):
            seconds = best_product(K, args.repeats)
            nbytes, rows, nnz = product_bytes(K)
            records.append({
                "model": name, "cells": n, "format": K.getType(),
                "block_size": K.getBlockSize() if K.getType().endswith("baij") else 1,
                "rows": rows, "stored": nnz, "bytes": nbytes, "seconds": seconds,
                "bandwidth": nbytes / seconds, "of_stream": nbytes / seconds / stream,
            })  # fmt: skip
            for obj in owned:
                obj.destroy()
    print(f"STREAM triad: {stream / 1e9:.2f} GB/s ({how}, {args.stream} entries, best of "
          f"{args.repeats}); products K u on one rank, best of {args.repeats} x 20")  # fmt: skip
    columns = [("model", "<6"), ("cells", "6d"), ("format", "<8"), ("bs", "3d"),
               ("rows", "8d"), ("stored", "9d"), ("MB", "8.2f"), ("ms", "8.3f"),
               ("GB/s", "6.2f"), ("of STREAM", "9.0%")]  # fmt: skip
    rows = [[r["model"], r["cells"], r["format"], r["block_size"], r["rows"], r["stored"],
             r["bytes"] / 1e6, 1e3 * r["seconds"], r["bandwidth"] / 1e9, r["of_stream"]]
            for r in records]  # fmt: skip
    print_table(columns, rows)
    write_json(args.json, records, stream_bytes_per_second=stream, stream_method=how)
    return {"stream": stream, "stream_method": how, "records": records}


if __name__ == "__main__":
    main()
# -
