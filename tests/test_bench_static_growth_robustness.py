"""Smoke run of ``benchmarks/bench_static_growth_robustness.py --small`` (serial and 2 ranks):
two random user edge cracks grown by pure EFG. Draw 1 meets the edge at 36 degrees and was
refused at its mouth before its supports were widened: it takes its 4 steps. Draw 5 reaches the
top edge: the growth stops there with ``mf.GrowthStopped`` after 2 steps (it was refused at its
first step, its default domains reaching out of the plate)."""

from __future__ import annotations

import json

from conftest import load_benchmark
from mpi4py import MPI


def test_bench_static_growth_robustness_small(shared_dir):
    bench = load_benchmark("bench_static_growth_robustness")
    path = shared_dir / "bench_static_growth_robustness.json"
    bench.main(["--small", "--json", str(path)])
    MPI.COMM_WORLD.Barrier()
    (rec,) = json.loads(path.read_text())["records"]
    assert rec["method"] == "efg" and rec["runs"] == 2 and rec["refused"] == 0
    assert rec["outcomes"]["1"] == {"outcome": "ran", "steps": 4}
    assert rec["outcomes"]["5"] == {"outcome": "edge", "steps": 2}
