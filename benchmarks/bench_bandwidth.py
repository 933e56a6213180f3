# # Benchmark: the explicit step's sparse products against the machine's memory bandwidth
#
# Issue 26, item 4. An explicit step is memory-bound: its cost is the stiffness product
# `f_int = K u` of every field, and a product streams the matrix once. This benchmark measures
# the machine's bandwidth by a STREAM-like sweep (`y = y + s x` over vectors far larger than the
# caches, PETSc's `VecAXPY`: the triad's 3 x 8 bytes per entry, the best of `--repeats`) and,
# in the same run, the products of explicit models of a plate: FE (vector Q1) and pure EFG
# (particles at the element size), each stiffness as BAIJ with block size 2 (the default of
# `ExplicitDynamics`) and converted to AIJ. For
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
def stream_triad(n: int, repeats: int) -> float:
    """Best bandwidth (bytes/s) of ``y = y + s x`` over ``n`` doubles (PETSc's ``VecAXPY``, C,
    one rank: two streams read, one written, 3 x 8 bytes per entry, the traffic of STREAM's
    triad). ``VecWAXPY``, the triad itself, ran at a third of ``VecAXPY``'s speed on these
    machines, and ``VecSum`` (a read) at 40 %: neither is the memory's limit. A product reads
    more than it writes, so it can exceed this figure (the caches help it at the small sizes)."""
    x, y = (PETSc.Vec().createSeq(n, comm=PETSc.COMM_SELF) for _ in range(2))
    x.set(2.0)
    y.set(1.0)
    y.axpy(3.0, x)  # first touch outside the timing
    best = min(median_time(lambda: y.axpy(1e-9, x), 1) for _ in range(repeats))
    for v in (x, y):
        v.destroy()
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
    stream = stream_triad(args.stream, args.repeats)
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
    print(f"STREAM-like y += s x: {stream / 1e9:.2f} GB/s (PETSc VecAXPY, {args.stream} "
          f"entries, best of {args.repeats}); products K u on one rank, best of "
          f"{args.repeats} x 20")  # fmt: skip
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
