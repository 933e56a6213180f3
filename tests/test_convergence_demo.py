"""``demos/convergence.py`` on two coarse meshes: the records and their fields, the JSON, the
fitted FE rate, the patch-size sweep (pure EFG at fraction 1.0) and the self-check."""

from __future__ import annotations

import json
import pathlib

import numpy as np
import pytest
from conftest import load_demo
from mpi4py import MPI

DEMOS = pathlib.Path(__file__).resolve().parents[1] / "demos"

SERIES_KEYS = {
    "method", "h", "particle_spacing", "patch_fraction", "fe_dofs", "particle_dofs",
    "multiplier_dofs", "error_l2", "error_energy", "rate_l2", "rate_energy", "paper_rate_l2",
    "time_setup", "time_assemble", "time_solve", "time_total", "repeat", "ranks",
    "dolfinx_version",
}  # fmt: skip


def test_series_sweep_json_and_fe_rate(shared_dir):
    comm = MPI.COMM_WORLD
    out = shared_dir / "conv.json"
    prefix = shared_dir / "plots" / "conv"
    demo = load_demo("convergence")
    result = demo.main(
        ["--method", "fe", "lagrange", "--h", "3", "1.5", "--repeat", "2",
         "--fractions", "0.25", "1.0", "--sweep-h", "3", "--json", str(out),
         "--png-prefix", str(prefix)]
    )  # fmt: skip
    comm.Barrier()
    data = json.loads(out.read_text())
    assert data["repeat"] == 2 and data["ranks"] == comm.size and data["jit_excluded"]
    series = data["series"]
    assert [(r["method"], r["h"]) for r in series] == [
        ("fe", 3.0), ("fe", 1.5), ("lagrange", 3.0), ("lagrange", 1.5)
    ]  # fmt: skip
    for r in series:
        assert SERIES_KEYS <= set(r)
        assert r["time_total"] == pytest.approx(
            r["time_setup"] + r["time_assemble"] + r["time_solve"], rel=0.5
        )
    fe = [r for r in series if r["method"] == "fe"]
    # the published FE error at h = 3 (benchmarks.md) and an honest rate: optimal is 2
    assert fe[0]["error_l2"] == pytest.approx(2.81e-2, rel=0.01)
    rate = np.polyfit(np.log([r["h"] for r in fe]), np.log([r["error_l2"] for r in fe]), 1)[0]
    assert rate > 1.8
    assert fe[1]["rate_l2"] == pytest.approx(rate)
    # Rabczuk et al. 2006, Table II: compatibility coupling, h 3 -> 1.5
    assert series[3]["paper_rate_l2"] == 1.72
    # the sweep: pure FE, the coupling at 0.25, pure EFG for 1.0
    sweep = data["sweep"]
    assert [(r["method"], r["patch_fraction"]) for r in sweep] == [
        ("fe", 0.0), ("lagrange", 0.25), ("efg", 1.0)
    ]  # fmt: skip
    assert sweep[1]["fe_dofs"] < fe[0]["fe_dofs"] and sweep[2]["fe_dofs"] == 0
    # the check that ran (one refinement: no rate check) passed
    assert [c["passed"] for c in data["checks"]] == [True]
    assert result["series"][0]["error_l2"] == series[0]["error_l2"]
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return  # the demo says which package to install and skips the plots
    if comm.rank == 0:
        assert (shared_dir / "plots" / "conv_error_h.png").stat().st_size > 0
        assert (shared_dir / "plots" / "conv_error_time.png").stat().st_size > 0


def test_self_check_fails_on_a_coupling_worse_than_fe():
    demo = load_demo("convergence")
    demo.FE_FACTOR = 0.5  # the Lagrange coupling is 0.9 x FE at h = 3
    with pytest.raises(SystemExit) as e:
        demo.main(["--method", "fe", "lagrange", "--h", "3", "--repeat", "1", "--fractions"])
    assert e.value.code == 1
