"""Smoke run of benchmarks/bench_rate_law.py (no timing checked): it runs, and the closed forms
meet the LAPACK forms they replaced (as tests/test_hjc.py::test_closed_forms_meet_lapack)."""

import pytest
from conftest import load_benchmark

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial


def test_bench_rate_law_small(tmp_path):
    records = load_benchmark("bench_rate_law").main(["--small", "--json", str(tmp_path / "r.json")])
    assert len(records) == 1 and (tmp_path / "r.json").exists()
    assert records[0]["max_difference"] <= 1e-12
