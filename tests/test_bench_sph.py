"""Smoke run of demos/bench_sph.py (no timing checked): it runs, and its two paths agree."""

import importlib.util
import pathlib

from dolfinx_meshfree.approx import jit

import pytest

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not installed")


def test_bench_sph_small(tmp_path):
    path = pathlib.Path(__file__).resolve().parents[1] / "demos" / "bench_sph.py"
    spec = importlib.util.spec_from_file_location("bench_sph", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    records = module.main(["--small", "--json", str(tmp_path / "sph.json")])
    assert len(records) == 2 and (tmp_path / "sph.json").exists()
    for r in records:
        assert r["max_difference"] <= 1e-12  # as tests/test_sph_compiled.py
