"""Smoke run of ``benchmarks/bench_growth.py --quick`` (serial and 2 ranks; no timing is checked):
it writes its JSON, the full and local growth paths agree (K_I, K_II to 1e-10 relative;
measured 2e-15 and 1e-14), the local path re-tabulated a part of the rows only."""

from __future__ import annotations

import json
import pathlib

from conftest import load_benchmark
from mpi4py import MPI

DEMOS = pathlib.Path(__file__).resolve().parents[1] / "demos"


def test_bench_growth_quick(shared_dir, monkeypatch):
    monkeypatch.syspath_prepend(str(DEMOS))
    demo = load_benchmark("bench_growth")
    path = shared_dir / "bench_growth.json"
    assert demo.main(["--quick", "--json", str(path)]) == 0
    MPI.COMM_WORLD.Barrier()
    data = json.loads(path.read_text())
    assert data["ranks"] == MPI.COMM_WORLD.size and len(data["records"]) == 2
    for r in data["records"]:
        assert r["K_difference"] < 1e-10
        assert r["full"]["update"] == "full" and r["local"]["update"] == "local"
        assert r["local"]["last_update"]["mode"] == "local"
