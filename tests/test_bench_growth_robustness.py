"""Smoke run of ``benchmarks/bench_growth_robustness.py --small`` (serial and 2 ranks): two
random draws of pure EFG on quadrilaterals; the first stops with the paper's segments (a
refused model) and runs through with fitted segments, one of them turned; the JSON holds both
records."""

from __future__ import annotations

import json

from conftest import load_benchmark
from mpi4py import MPI


def test_bench_growth_robustness_small(shared_dir):
    bench = load_benchmark("bench_growth_robustness")
    path = shared_dir / "bench_growth_robustness.json"
    bench.main(["--small", "--json", str(path)])
    MPI.COMM_WORLD.Barrier()
    fitted, plain = json.loads(path.read_text())["records"]
    assert fitted["fit_segments"] and not plain["fit_segments"]
    assert plain["refused"] == 1 and plain["stopped_draws"] == [0]
    assert fitted["refused"] == fitted["other"] == 0 and fitted["turned_runs"] >= 1
    assert 0.0 < fitted["largest_turn"] <= 15.0
