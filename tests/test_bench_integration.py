"""Smoke run of benchmarks/bench_integration.py (no timing checked): it runs, writes its JSON,
and its errors are the demo's (the smoothed EFG cantilever within 1.25x VCI's L2 error, as
tests/test_smoothing.py checks on the same beam)."""

import json

import pytest
from conftest import load_benchmark

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial


def test_bench_integration_small(tmp_path):
    out = tmp_path / "integration.json"
    records = load_benchmark("bench_integration").main(["--small", "--json", str(out)])
    assert [(r["method"], r["integration"]) for r in records] == [
        ("fe", None), ("efg", "vci"), ("efg", "smoothed"),
        ("lagrange", "vci"), ("lagrange", "smoothed"),
    ]  # fmt: skip
    assert json.loads(out.read_text())["records"][2]["integration"] == "smoothed"
    by = {(r["method"], r["integration"]): r for r in records}
    assert by[("efg", "smoothed")]["l2_x_vci"] <= 1.25  # measured 1.06 at h = 2
    assert all(r["x_fe"] > 0 for r in records)
