"""Smoke run of ``benchmarks/bench_adaptive_quadrature.py --small`` (Kalthoff–Winkler at 21 nodes,
20 us; serial and 2 ranks; no timing is checked): it writes its JSON with the four runs
(efg and lagrange, uniform and adaptive) and the issue's keys; the adaptive rule's K_I / K_II
histories agree with the uniform rule's (measured 1.1e-3 efg, 1.6e-5 lagrange; check 2.5e-3);
serial = 2 ranks (K histories to 1e-8 relative)."""

from __future__ import annotations

import json
import pathlib

import numpy as np
from conftest import load_benchmark
from mpi4py import MPI

DEMOS = pathlib.Path(__file__).resolve().parents[1] / "demos"
KEYS = (
    "method", "quadrature", "kink_angle_deg", "mean_angle_deg", "K_I_initiation",
    "K_II_initiation", "KI_history", "KII_history", "time_setup", "time_steps", "time_sifs",
    "time_crack", "time_total", "ratio_to_efg_uniform", "K_history_difference",
)  # fmt: skip


def test_bench_adaptive_quadrature_small(shared_dir, monkeypatch):
    monkeypatch.syspath_prepend(str(DEMOS))
    demo = load_benchmark("bench_adaptive_quadrature")
    path = shared_dir / "bench_adaptive_quadrature.json"
    assert demo.main(["--small", "--json", str(path)]) == 0
    MPI.COMM_WORLD.Barrier()
    data = json.loads(path.read_text())
    assert data["ranks"] == MPI.COMM_WORLD.size and data["nodes"] == 21
    runs = {(r["method"], r["quadrature"]): r for r in data["records"]}
    assert set(runs) == {(m, q) for m in ("efg", "lagrange") for q in ("uniform", "adaptive")}
    for r in runs.values():
        assert all(k in r for k in KEYS)
        assert r["K_I_initiation"] is not None  # initiated by 20 us (measured 16.9 us)
        assert r["K_history_difference"] <= 2.5e-3
    assert runs["efg", "uniform"]["ratio_to_efg_uniform"] == 1.0
    if MPI.COMM_WORLD.size > 1:
        kw = demo.load_demo("kalthoff_winkler")
        alone = demo.run_all(kw, 21, 20e-6, 8.0, 3, ["efg"], MPI.COMM_SELF)
        for rec in alone:
            ref = runs["efg", rec["quadrature"]]
            for key in ("KI_history", "KII_history"):
                a, b = np.asarray(rec[key]), np.asarray(ref[key])
                assert a.shape == b.shape
                assert np.abs(a - b).max() <= 1e-8 * np.abs(b[:, 1]).max()
