# # Benchmark: the explicit step's sparse products against the machine's memory bandwidth
#
# Issue 26, item 4. An explicit step is memory-bound: its cost is the stiffness product
# `f_int = K u` of every field, and a product streams the matrix once. This benchmark measures
# one core's bandwidth by STREAM's triad (`a = b + s c` over arrays far larger than the caches,
# a compiled single-threaded loop: 3 x 8 bytes per entry, the best of `--repeats`) and, in the
# same run, the products of explicit models of a plate: FE (vector Q1) and pure EFG (particles
# at the element size), each stiffness as BAIJ with block size 2 (the default of
# `ExplicitDynamics`), converted to AIJ, and multiplied by the compiled block product
# (`dynamics.compiled_product`, the default product of `ExplicitDynamics` with numba). For
# each product: the bytes it must move at least (values and column indices of every stored
# entry, the row offsets, `u` read once and `f` written once), the CPU time of one product
# (one rank; best of `--repeats` batches of 20, `bench_blocks.best_product`) and the
# achieved bandwidth, also as a fraction of STREAM's.
# Prints a table and writes JSON (`--json`). `--small` is a smoke run for CI (no timing is
# checked anywhere).
#
# Until stop 57 the bandwidth was PETSc's `VecAXPY`, which the Debian build runs through
# OpenBLAS's `daxpy` on as many threads as there are cores: 47 GB/s on these 2-core machines
# without `OMP_NUM_THREADS=1`, against 24 GB/s on one thread, so that every product's fraction
# of it was halved.

# +
from __future__ import annotations

import argparse
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.dynamics.compiled_product import CompiledProduct

import dolfinx
import numpy as np
from bench_blocks import best_product
from harness import print_table, write_json
from mpi4py import MPI
from petsc4py import PETSc

if jit.AVAILABLE:
    import numba

MATERIAL = mf.LinearElastic(E=200.0, nu=0.3, plane="strain", rho=7.8)
#: Bytes of a PETSc index (PetscInt) and of a value.
INDEX = np.dtype(PETSc.IntType).itemsize
VALUE = np.dtype(PETSc.ScalarType).itemsize
# -


# ## STREAM triad


# +
def _triad_loop(a, b, c, s):  # pragma: no cover - compiled
    for i in range(a.size):
        a[i] = b[i] + s * c[i]


# not cached on disk: numba's cache of a script's function cannot be loaded back when the
# script is imported under another module name (as the tests load benchmarks)
_triad = numba.njit(cache=False)(_triad_loop) if jit.AVAILABLE else None


def stream_triad(n: int, repeats: int) -> float:
    """Best bandwidth (bytes/s) of STREAM's triad ``a = b + s c`` over ``n`` doubles, one
    thread (compiled: numba vectorises the loop for the machine; two streams read, one
    written, 3 x 8 bytes per entry as STREAM counts them). Without numba: ``numpy`` in two
    passes, counted as one triad (a lower bound)."""
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)

    def triad() -> None:
        if jit.AVAILABLE:
            _triad(a, b, c, 3.0)
        else:
            np.multiply(c, 3.0, out=a)
            np.add(a, b, out=a)

    triad()  # first touch and compilation outside the timing
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        triad()
        best = min(best, time.perf_counter() - t0)
    return 3 * VALUE * n / best


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


def compiled_bytes(K: PETSc.Mat) -> int:
    """The bytes of the compiled block product of ``K`` (BAIJ): the stored values, one 32-bit
    block column index per block and one row offset per block row (``compiled_product._bsr``),
    ``u`` read once and ``f`` written once."""
    rows, cols = K.getSize()
    bs = K.getBlockSize()
    nnz = int(K.getInfo()["nz_used"])
    return nnz * VALUE + (nnz // (bs * bs) + rows // bs + 1) * 4 + (rows + cols) * VALUE


def best_compiled(K: PETSc.Mat, repeats: int) -> float:
    """CPU seconds of one compiled ``K x`` (:func:`bench_blocks.best_product`), checked against
    PETSc's product of the same matrix."""
    prod = CompiledProduct(K, K.getBlockSize())
    x, y = K.createVecs()
    x.setRandom()
    z = y.duplicate()
    K.mult(x, z)
    prod.mult(x, y)  # the copy and the compilation outside the timing
    assert np.abs(y.array_r - z.array_r).max() <= 1e-12 * np.abs(z.array_r).max()
    best = best_product(K, repeats, multiply=prod.mult)
    for obj in (prod, x, y, z):
        obj.destroy()
    return best


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
    p.add_argument("--stream", type=int, default=2**26, help="STREAM array length")
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--small", action="store_true", help="a smoke run (CI)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    if args.small:
        args.cells, args.stream, args.repeats = [8], 2**16, 2
    stream = stream_triad(args.stream, args.repeats)
    records = []
    for n in args.cells:
        for name, K, owned in models(n):
            _, rows, nnz = product_bytes(K)
            runs = [(K.getType(), product_bytes(K)[0], best_product(K, args.repeats))]
            if K.getType().endswith("baij") and jit.AVAILABLE:
                runs.append(("compiled", compiled_bytes(K), best_compiled(K, args.repeats)))
            for fmt, nbytes, seconds in runs:
                records.append({
                    "model": name, "cells": n, "format": fmt,
                    "block_size": K.getBlockSize() if K.getType().endswith("baij") else 1,
                    "rows": rows, "stored": nnz, "bytes": nbytes, "seconds": seconds,
                    "bandwidth": nbytes / seconds, "of_stream": nbytes / seconds / stream,
                })  # fmt: skip
            for obj in owned:
                obj.destroy()
    print(f"STREAM triad a = b + s c, one thread: {stream / 1e9:.2f} GB/s ({args.stream} "
          f"entries, best of {args.repeats}); products K u on one rank, best of "
          f"{args.repeats} x 20 (compiled: dynamics.compiled_product)")  # fmt: skip
    columns = [("model", "<6"), ("cells", "6d"), ("format", "<8"), ("bs", "3d"),
               ("rows", "8d"), ("stored", "9d"), ("MB", "8.2f"), ("ms", "8.3f"),
               ("GB/s", "6.2f"), ("of STREAM", "9.0%")]  # fmt: skip
    rows = [[r["model"], r["cells"], r["format"], r["block_size"], r["rows"], r["stored"],
             r["bytes"] / 1e6, 1e3 * r["seconds"], r["bandwidth"] / 1e9, r["of_stream"]]
            for r in records]  # fmt: skip
    print_table(columns, rows)
    write_json(args.json, records, stream_bytes_per_second=stream)
    return {"stream": stream, "records": records}


if __name__ == "__main__":
    main()
# -
