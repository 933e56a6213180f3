"""Smoke run of benchmarks/bench_bulk_viscosity.py (no timing checked): it runs, and its FE bar
at 20 cells takes more steps with the viscosity's damper than without (the stable step is
divided by Wilkins' factor, tests/test_bulk_viscosity.py)."""

import pytest
from conftest import load_benchmark

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial


def test_bench_bulk_viscosity_small(tmp_path):
    bench = load_benchmark("bench_bulk_viscosity")
    records = bench.main(["--small", "--json", str(tmp_path / "r.json")])
    assert len(records) == 2 and (tmp_path / "r.json").exists()
    damped, plain = records
    assert damped["viscosity"] and not plain["viscosity"]
    assert damped["steps"] > plain["steps"]
