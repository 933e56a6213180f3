"""The reduced Kalthoff–Winkler demo (issue 11, item 5): ``demos/kalthoff_winkler.py`` at 41
nodes per side (h = 2.5 mm), 40 us. Oracles: the maximum hoop stress criterion under the
(nearly) pure mode II loading of the impact, the experiment's 70 deg (the issue's target
70 +- 3 deg); the coupled model against pure EFG; serial against 2 ranks.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import load_demo
from mpi4py import MPI

COMM = MPI.COMM_WORLD
KW = load_demo("kalthoff_winkler")
NODES, T_END = 41, 40e-6
KEYS = (
    "method", "path", "kink_angle_deg", "mean_angle_deg", "KI_history", "KII_history", "steps",
    "time_setup", "time_steps", "time_crack", "time_total",
)  # fmt: skip


@pytest.fixture(scope="module")
def runs():
    return {m: KW.run(m, NODES, T_END) for m in ("lagrange", "efg")}


def test_kink_angle(runs):
    """Measured: the first segment at 71.56 deg (lagrange) and 71.53 deg (efg), checked against
    70 +- 3 deg; K_II < 0 (the impacted side slides ahead: the crack turns counterclockwise,
    away from the impact) and |K_I| < |K_II| at the extension; one extension each."""
    for rec in runs.values():
        assert abs(rec["kink_angle_deg"] - 70.0) <= 3.0
        ext = [c for c in rec["checks"] if c["extended"]]
        assert len(ext) == 1 and ext[0]["K_II"] < 0 and abs(ext[0]["K_I"]) < abs(ext[0]["K_II"])
        p = np.asarray(rec["path"])
        seg = np.degrees(np.arctan2(*(p[1] - p[0])[::-1]))
        assert seg == pytest.approx(rec["kink_angle_deg"], abs=1e-6)  # the path follows theta


def test_coupled_against_pure_efg(runs):
    """lagrange vs efg: kink angles 0.03 deg apart (check 1 deg), initiation at 16.40 / 16.23
    us (check: one check interval, 1.8 us), paths 0.01 mm apart (check 0.5 mm = h / 5)."""
    la, efg = runs["lagrange"], runs["efg"]
    assert abs(la["kink_angle_deg"] - efg["kink_angle_deg"]) <= 1.0
    interval = la["checks"][1]["time"] - la["checks"][0]["time"]
    assert abs(la["initiation_time"] - efg["initiation_time"]) <= interval
    assert np.abs(np.subtract(la["path"], efg["path"])).max() <= 0.5


@pytest.mark.skipif(COMM.size == 1, reason="compares 2 ranks with one")
def test_serial_equals_two_ranks(runs):
    alone = KW.run("lagrange", NODES, T_END, comm=MPI.COMM_SELF)
    KII = np.asarray(runs["lagrange"]["KII_history"])
    assert np.abs(np.asarray(alone["KII_history"]) - KII).max() <= 1e-8 * np.abs(KII).max()
    assert np.abs(np.subtract(alone["path"], runs["lagrange"]["path"])).max() <= 1e-9


def test_demo_main_json(shared_dir):
    out = shared_dir / "kw.json"
    args = ["--method", "edge-to-edge", "--nodes", "21", "--t-end", "20e-6", "--json", str(out)]
    assert KW.main(args) == 0
    COMM.Barrier()
    (rec,) = json.loads(out.read_text())
    assert all(k in rec for k in KEYS) and rec["method"] == "edge-to-edge"
    assert rec["path"][0] == pytest.approx([50.0, 25.0 + 2.5], abs=1e-9)  # h/2 = 2.5 mm
