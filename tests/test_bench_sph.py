"""Smoke run of benchmarks/bench_sph.py (no timing checked): it runs, and its two paths agree."""

from dolfinx_meshfree.approx import jit

import pytest
from conftest import load_benchmark

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = [
    pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not installed"),
    pytest.mark.serial,
]


def test_bench_sph_small(tmp_path):
    records = load_benchmark("bench_sph").main(["--small", "--json", str(tmp_path / "sph.json")])
    assert len(records) == 2 and (tmp_path / "sph.json").exists()
    for r in records:
        assert r["max_difference"] <= 1e-12  # as tests/test_sph_compiled.py
