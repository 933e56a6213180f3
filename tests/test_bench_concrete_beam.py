"""The concrete beam benchmark at a tiny size: it runs, prints its table and writes its JSON
(a record per method and size, the ratios to pure EFG's filled in), and its figures are those of
the demo (the peak of the coupled run within 1 % of EFG's at h = 50 mm). Serial only: the
benchmark is a driver of the demo, whose parallel path its own test runs."""

import json

import pytest
from conftest import load_benchmark

pytestmark = pytest.mark.serial

bench = load_benchmark("bench_concrete_beam")


@pytest.mark.heavy(twin="tests/test_concrete_beam.py::test_reduced_cohesive")
def test_tiny_run(tmp_path, capsys):
    out = tmp_path / "b.json"
    records = bench.main(
        ["--h", "50", "--methods", "efg", "lagrange", "--end-cmod", "0.2", "--json", str(out)]
    )
    assert [r["method"] for r in records] == ["efg", "lagrange"]
    efg, lag = records
    assert efg["peak_vs_efg"] == 0.0 and lag["time_vs_efg"] > 0.0
    assert abs(lag["peak_vs_efg"]) <= 0.01
    assert "| lagrange" in capsys.readouterr().out
    saved = json.loads(out.read_text())
    assert len(saved["records"]) == 2 and "machine" in saved
