"""Smoke run of benchmarks/bench_kept_analysis.py (no timing checked): it runs, and every model
solved with MUMPS's analysis kept equals the run that analyses every tangent afresh (measured:
to the bit), with fewer analyses by PETSc's own count; the load sweep factorises once."""

import pytest
from conftest import load_benchmark

# serial: the kept analysis on 2 ranks is tests/test_kept_factor.py's (the tiers: conftest.py)
pytestmark = pytest.mark.serial


def test_bench_kept_analysis_small(tmp_path):
    out = tmp_path / "k.json"
    records = load_benchmark("bench_kept_analysis").main(["--small", "--json", str(out)])
    assert out.exists()
    assert [r["method"] for r in records] == ["lagrange", "fe", "lagrange", "lagrange"]
    for r in records[:3]:
        assert r["max_difference"] <= 1e-12
        assert r["analyses_fresh"] >= r["factorisations"] > 0
        assert 1 <= r["analyses_kept"] < r["analyses_fresh"] / 3
    # the load sweep (3 loads): one analysis and one factorisation for the three solves, the
    # same deflections to the bit as three fresh factorisations
    (sweep,) = records[3:]
    assert sweep["model"] == "sweep h=2"
    assert (sweep["analyses_kept"], sweep["factorisations"], sweep["analyses_fresh"]) == (1, 1, 3)
    assert sweep["max_difference"] == 0.0
