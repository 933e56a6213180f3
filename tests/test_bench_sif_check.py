"""Smoke run of ``benchmarks/bench_sif_check.py --small`` (serial and 2 ranks; no timing is
checked): it writes its JSON, and the kept check's K_I, K_II equal the full interaction
integral's (relative to max |K|: measured 1.2e-15 to 1.4e-15 at 41 nodes; bound 1e-12, the
functional's test bound), for pure EFG and lagrange with crack-face contact."""

from __future__ import annotations

import json

from conftest import load_benchmark
from mpi4py import MPI


def test_bench_sif_check_small(shared_dir):
    bench = load_benchmark("bench_sif_check")
    path = shared_dir / "bench_sif_check.json"
    assert bench.main(["--small", "--json", str(path)]) == 0
    MPI.COMM_WORLD.Barrier()
    data = json.loads(path.read_text())
    assert [r["method"] for r in data["records"]] == ["efg", "lagrange"]
    for r in data["records"]:
        assert r["K_difference"] < 1e-12
        assert abs(r["K_II"]) > 0.0  # the waves have reached the tip: K is not trivially equal
        assert r["run_checks"] > 0
