"""benchmarks/speed_vs_error.py: the interpolation of the time to a target error (exact on
power laws), and a smoke run (no timing checked) that writes its JSON and plots."""

import json

import numpy as np
import pytest
from conftest import load_benchmark

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial


def test_time_to_a_target_error():
    """On a power law ``e = t^-2`` the log-log interpolation is exact; a series already below
    the target gives its coarsest time as a bound, one above it none, unless within a factor
    2 of its finest error (extrapolated along its last two runs, exact on the power law)."""
    bench = load_benchmark("speed_vs_error")
    times = [1.0, 2.0, 4.0, 8.0]
    errors = [t**-2.0 for t in times]
    t, how = bench.time_to(errors, times, 3.0**-2.0)
    assert how == "interpolated" and abs(t - 3.0) <= 1e-12
    assert bench.time_to(errors, times, 2.0) == (1.0, "at most")
    assert bench.time_to(errors, times, 1e-3) == (None, "not reached")
    t, how = bench.time_to(errors, times, 0.5 * 8.0**-2.0)  # a factor 2 past the finest
    assert how == "extrapolated" and abs(t - 8.0 * np.sqrt(2.0)) <= 1e-12


def test_smoke_run(tmp_path):
    bench = load_benchmark("speed_vs_error")
    out = tmp_path / "sve.json"
    result = bench.main(["--small", "--problem", "cantilever", "kirsch", "--json", str(out),
                         "--png-dir", str(tmp_path)])  # fmt: skip
    records = json.loads(out.read_text())["records"]
    assert {r["problem"] for r in records} == {"cantilever", "kirsch"}
    assert all(np.isfinite(r["time"]) and r["time"] > 0 for r in records)
    # the reference reaches its own errors at its own times, ratio 1
    for row in result["targets"]:
        if row["method"] in ("fe",):
            assert row["found"] == "interpolated" and abs(row["x_reference"] - 1.0) <= 1e-12
    assert (
        len(result["plots"]) == 3
    )  # cantilever L2, energy; kirsch L2 and all((tmp_path / p).exists() for p in result["plots"])
