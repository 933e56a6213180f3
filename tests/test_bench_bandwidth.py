"""Smoke run of benchmarks/bench_bandwidth.py (no timing checked): it runs, and the bytes it
counts for a product are those of the matrix as stored (counted here from its CSR arrays), for
PETSc's products and the compiled one."""

from dolfinx_meshfree.approx import jit

import numpy as np
import pytest
from conftest import load_benchmark
from petsc4py import PETSc

# serial: one-rank products (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial


def test_bench_bandwidth_small(tmp_path):
    bench = load_benchmark("bench_bandwidth")
    out = bench.main(["--small", "--json", str(tmp_path / "bw.json")])
    assert (tmp_path / "bw.json").exists() and out["stream"] > 0
    compiled = {("FE Q1", "compiled"), ("EFG", "compiled")} if jit.AVAILABLE else set()
    assert {(r["model"], r["format"]) for r in out["records"]} == {
        ("FE Q1", "seqbaij"),
        ("FE Q1", "seqaij"),
        ("EFG", "seqbaij"),
        ("EFG", "seqaij"),
        *compiled,
    }
    for name, K, owned in bench.models(8):
        nbytes, rows, nnz = bench.product_bytes(K)
        # independent count: the AIJ arrays of the same matrix
        aij = PETSc.Mat()
        K.convert("aij", aij)
        indptr, indices, values = aij.getValuesCSR()
        assert nnz == values.size == indices.size
        bs = K.getBlockSize() if K.getType().endswith("baij") else 1
        index_bytes = (indices.size // (bs * bs) + rows // bs + 1) * bench.INDEX
        expected = values.size * bench.VALUE + index_bytes + 2 * rows * bench.VALUE
        assert nbytes == expected, (name, K.getType())
        if bs == 2:  # the compiled product's copy: 32-bit block indices and row offsets
            blocks = indices.size // 4
            compiled_expected = values.size * bench.VALUE + (blocks + rows // 2 + 1) * 4
            assert bench.compiled_bytes(K) == compiled_expected + 2 * rows * bench.VALUE
        assert np.all(np.diff(indptr) > 0)  # every row stored
        for obj in (aij, *owned):
            obj.destroy()
