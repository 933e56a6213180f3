"""The reduced Kalthoff–Winkler demo (issue 11, item 5): ``demos/kalthoff_winkler.py`` at 41
nodes per side (h = 2.5 mm), 40 us, one time step for all runs (3e-7 s: the SIF checks of all
methods at the same times). Oracles: the maximum hoop stress criterion under the (nearly) pure
mode II loading of the impact, the experiment's 70 deg (the issue's target 70 +- 3 deg); the
coupled model against pure EFG (paths, kink, SIF histories before initiation: the issue's 5 %);
the energy balance of the model (kinetic + strain + released energy against the work of the
impact); the XDMF files read back with h5py and xml; serial against 2 ranks.

The impact: ``velocity`` (the demo's default, the paper's model: the edge driven at v0) and
``traction`` (rho c_d v0).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest
from conftest import load_demo
from mpi4py import MPI

COMM = MPI.COMM_WORLD
KW = load_demo("kalthoff_winkler")
NODES, T_END, DT = 41, 40e-6, 3e-7
UPDATES = ("local", "full")
KEYS = (
    "method", "path", "kink_angle_deg", "mean_angle_deg", "KI_history", "KII_history", "steps",
    "time_setup", "time_steps", "time_crack", "time_total",
)  # fmt: skip


@pytest.fixture(scope="module")
def runs():
    return {
        (m, impact): KW.run(m, NODES, T_END, impact=impact, dt=DT)
        for m in ("lagrange", "efg")
        for impact in ("velocity", "traction")
    }


def _extension(rec):
    ext = [c for c in rec["checks"] if c["extended"]]
    assert len(ext) == 1 and rec["extensions"] == 1
    p = np.asarray(rec["path"])
    seg = np.degrees(np.arctan2(*(p[1] - p[0])[::-1]))
    assert seg == pytest.approx(rec["kink_angle_deg"], abs=1e-6)  # the path follows theta
    return ext[0]


@pytest.mark.parametrize("method", ["lagrange", "efg"])
def test_kink_angle_traction(runs, method):
    """Traction impact: the first segment at 71.68 deg (lagrange) and 71.42 deg (efg), checked
    against 70 +- 3 deg; K_II < 0 (the impacted side slides ahead: the crack turns
    counterclockwise, away from the impact) and |K_I| < |K_II| at the extension."""
    rec = runs[method, "traction"]
    ext = _extension(rec)
    assert abs(rec["kink_angle_deg"] - 70.0) <= 3.0
    assert ext["K_II"] < 0 and abs(ext["K_I"]) < abs(ext["K_II"])


@pytest.mark.parametrize("method", ["lagrange", "efg"])
def test_kink_angle_velocity(runs, method):
    """Velocity impact (the paper's model): K_II < 0, |K_I| < |K_II| at the extension, and a
    kink of 73.21 deg (lagrange) / 73.42 deg (efg): 0.2-0.4 deg above the target band, because
    K_I < 0 there (-20 MPa sqrt(m) against K_II = -142: the notch faces pressed together,
    contact not modelled) turns the maximum hoop stress direction above the 70.5 deg of pure
    mode II. The band is checked strictly below (xfail at 70 +- 3) and at 70 +- 4 here."""
    rec = runs[method, "velocity"]
    ext = _extension(rec)
    assert ext["K_II"] < 0 and ext["K_I"] < 0 and abs(ext["K_I"]) < abs(ext["K_II"])
    assert abs(rec["kink_angle_deg"] - 70.0) <= 4.0


@pytest.mark.xfail(
    strict=True, reason="velocity impact: kink 73.21 / 73.42 deg (K_I < 0, no contact)"
)
def test_kink_angle_velocity_target(runs):
    assert all(
        abs(runs[m, "velocity"]["kink_angle_deg"] - 70.0) <= 3.0 for m in ("lagrange", "efg")
    )


@pytest.mark.parametrize("impact", ["velocity", "traction"])
def test_coupled_against_pure_efg(runs, impact):
    """lagrange vs efg: kink angles 0.20 (velocity) / 0.26 deg (traction) apart (check 1 deg),
    initiation within one check interval (1.5 us), paths within 0.5 mm = h / 5."""
    la, efg = runs["lagrange", impact], runs["efg", impact]
    assert abs(la["kink_angle_deg"] - efg["kink_angle_deg"]) <= 1.0
    interval = la["checks"][1]["time"] - la["checks"][0]["time"]
    assert abs(la["initiation_time"] - efg["initiation_time"]) <= interval * (1 + 1e-9)
    assert np.abs(np.subtract(la["path"], efg["path"])).max() <= 0.5


def test_sif_histories_before_initiation(runs):
    """K_I(t), K_II(t) of lagrange against efg up to initiation, at the same check times,
    relative to max |K_II|. Traction: K_I 4.91 %, K_II 4.64 % (the issue's 5 %: met, checked
    at 5 %). Velocity: K_I 2.34 %, K_II 6.35 %: the 5 % target missed (xfail below); checked
    at 2x measured."""
    d = KW.sif_difference(runs["lagrange", "traction"], runs["efg", "traction"])
    assert d["same_times"] and max(d["KI"], d["KII"]) <= 0.05
    d = KW.sif_difference(runs["lagrange", "velocity"], runs["efg", "velocity"])
    assert d["same_times"] and d["KI"] <= 0.05 and d["KII"] <= 0.13


def test_sif_histories_wider_box(runs):
    """The coupled models' SIF difference comes from the FE interface near the tip: with the
    particle box from 10 spacings behind and below the tip (default 6) the velocity impact's
    K_I, K_II are 1.52 %, 3.37 % off efg (16 spacings: 0.79 %, 1.94 %): the 5 % target met."""
    wide = KW.run("lagrange", NODES, 20e-6, dt=DT, box=10.0)
    d = KW.sif_difference(wide, runs["efg", "velocity"])
    assert d["same_times"] and max(d["KI"], d["KII"]) <= 0.05


def test_sif_histories_bridging(runs):
    """Bridging's patch reaches its band (OVERLAP cells) beyond the slot's end, so no crack
    crosses the band's uncut FE field (a crack there is refused, tests/test_crack_solvers.py).
    Velocity impact, dt = 3e-7 s: K_I 6.16 %, K_II 18.75 % off efg before initiation (lagrange
    2.34 %, 6.35 %; the rest of bridging's difference is not explained); checked at 12 % and
    30 % (about 2x and 1.6x)."""
    bridging = KW.run("bridging", NODES, 20e-6, dt=DT)
    d = KW.sif_difference(bridging, runs["efg", "velocity"])
    assert d["same_times"] and d["KI"] <= 0.12 and d["KII"] <= 0.30


@pytest.mark.xfail(strict=True, reason="velocity impact: K_II 6.35 % off efg before initiation")
def test_sif_histories_velocity_target(runs):
    d = KW.sif_difference(runs["lagrange", "velocity"], runs["efg", "velocity"])
    assert max(d["KI"], d["KII"]) <= 0.05


def test_energy_bookkeeping(runs):
    """Kinetic + strain + released energy against the work of the impact (the reaction of the
    driven edge: external work on FE nodes, constraint work on particles; the traction's
    work): drift measured 5.1e-4 (efg) / 1.5e-3 (lagrange) velocity, 8.6e-4 / 1.6e-3
    traction, checked at 3.5e-3. With G x crack area as fracture energy instead the drift is
    6.4-7.4 %: the model does not dissipate G da (its crack faces are traction-free, the
    rebuild releases only -5 to -29 J/m against G da = 650-1000 J/m); reported, not checked.
    The velocity impact does more work than the traction (14,082 / 13,890 J/m against 10,065 /
    10,047 at 40 us): the driven edge keeps its velocity when reflected waves return."""
    for rec in runs.values():
        e = rec["energy"]
        assert e["drift_released"] <= 3.5e-3
        assert e["fracture_G_area"] > 0 and e["external_work"] > 0
        assert e["kinetic"] + e["strain"] == pytest.approx(e["external_work"], rel=0.02)
    for m in ("lagrange", "efg"):
        v, t = runs[m, "velocity"]["energy"], runs[m, "traction"]["energy"]
        assert v["external_work"] > 1.2 * t["external_work"]


@pytest.mark.skipif(COMM.size == 1, reason="compares 2 ranks with one")
def test_serial_equals_two_ranks(runs):
    alone = KW.run("lagrange", NODES, T_END, comm=MPI.COMM_SELF, dt=DT)
    ref = runs["lagrange", "velocity"]
    KII = np.asarray(ref["KII_history"])
    assert np.abs(np.asarray(alone["KII_history"]) - KII).max() <= 1e-8 * np.abs(KII).max()
    assert np.abs(np.subtract(alone["path"], ref["path"])).max() <= 1e-9
    assert alone["energy"]["external_work"] == pytest.approx(ref["energy"]["external_work"], 1e-8)


def _load(path, item):
    dims = tuple(int(d) for d in item.get("Dimensions").split())
    name, dataset = item.text.strip().split(":", 1)
    with h5py.File(path.parent / name, "r") as f:
        arr = np.asarray(f[dataset])
    assert arr.shape == dims
    return arr


def test_demo_main_json_and_xdmf(shared_dir):
    """The JSON keys of the issue and the new ones; the XDMF files read back (xml + h5py): the
    particle cloud's last displacement against the final model evaluated at the positions read
    from the file, the crack polyline against the final crack, the FE file's time steps."""
    out, prefix = shared_dir / "kw.json", shared_dir / "kw"
    rec = KW.run("edge-to-edge", 21, 20e-6, xdmf=str(prefix), xdmf_every=2)
    args = [
        "--method",
        "efg",
        "edge-to-edge",
        "--nodes",
        "21",
        "--t-end",
        "20e-6",
        "--json",
        str(out),
    ]
    assert KW.main(args) == 0
    COMM.Barrier()
    efg, e2e = json.loads(out.read_text())
    for r in (efg, e2e):
        assert all(k in r for k in (*KEYS, "energy", "impact")) and r["impact"] == "velocity"
    assert e2e["method"] == "edge-to-edge" and e2e["sif_difference"]["against"] == "efg"
    assert e2e["path"][0] == pytest.approx([50.0, 25.0 + 2.5], abs=1e-9)  # h/2 = 2.5 mm
    # XDMF: the written times are the checks 0, 2, 4, ... and the last
    growth = rec["_growth"]
    times = [c.time for c in growth.history][::2]
    if len(growth.history) % 2 == 0:
        times.append(growth.history[-1].time)
    files = rec["xdmf"]
    path = shared_dir / "kw_edge-to-edge_particles.xdmf"
    assert files["particles"] == str(path)
    grids = ET.parse(path).getroot().findall("./Domain/Grid/Grid")
    assert [float(g.find("Time").get("Value")) for g in grids] == pytest.approx(times, rel=1e-12)
    first, last = grids[0], grids[-1]
    x = _load(path, first.find("Geometry/DataItem"))
    atts = {a.get("Name"): a for a in last.findall("Attribute")}
    u = _load(path, atts["displacement"].find("DataItem"))
    dyn = growth.model
    P = dyn.particles
    own = np.asarray(P.owned)
    mine = dyn.displacement_at(x[own, :2])
    assert np.abs(u[own, :2] - mine).max() <= 1e-12 * np.abs(mine).max()
    crack = ET.parse(shared_dir / "kw_edge-to-edge_crack.xdmf").getroot()
    last = crack.findall("./Domain/Grid/Grid")[-1]
    assert last.find("Topology").get("TopologyType") == "Polyline"
    pts = _load(shared_dir / "kw_edge-to-edge_crack.xdmf", last.find("Geometry/DataItem"))
    assert np.allclose(pts[:, :2], growth.crack.points, rtol=0, atol=1e-15)
    fe = ET.parse(shared_dir / "kw_edge-to-edge_fe.xdmf").getroot()
    fe_times = {float(t.get("Value")) for t in fe.iter("Time")}
    assert sorted(fe_times) == pytest.approx(times, rel=1e-12)


def test_local_update_keeps_the_driven_edge():
    """Pure EFG with the velocity impact, whose driven particles keep ``G v = g`` through the
    update: the local update equals the full rebuild (K_II history to 1e-10 relative, the
    released energy to 1e-8; before the fix the local projection dropped ``g`` and released
    -3.3e5 J/m against -29)."""
    recs = {u: KW.run("efg", NODES, T_END, impact="velocity", dt=DT, update=u) for u in UPDATES}
    local, full = recs["local"], recs["full"]
    assert local["local_updates"] == 1 and full["local_updates"] == 0
    a, b = np.array(local["KII_history"]), np.array(full["KII_history"])
    assert a.shape == b.shape and np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
    ea, eb = local["energy"]["fracture_released"], full["energy"]["fracture_released"]
    assert ea == pytest.approx(eb, rel=1e-8)
