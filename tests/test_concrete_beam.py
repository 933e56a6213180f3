"""The concrete beam demo at a reduced size (h = 25 mm: 8 cells over the depth), with the cohesive
crack (the default) and with the crack band: its own checks (the elastic first step against the
linear solve, the energy balance within 2 %, the damage in the patch, the peak passed), what it
reports, and the peak load between two limit loads of the ligament; the coupling against pure
EFG; bad options refused. Runs serially and on 2 ranks."""

import numpy as np
import pytest
from conftest import load_demo

demo = load_demo("concrete_beam")


# limit loads of the ligament (depth 100 mm, thickness 50 mm, span 2000 mm, f_t 3.33 MPa): the
# linear-elastic net-section stress reaching f_t, P = 4 f_t B l^2 / (6 S) = 555 N, is passed (the
# process zone carries load past it); the ligament in tension at f_t throughout (a rigid-plastic
# hinge with the compression at the top edge), P = 2 f_t B l^2 / S = 1665 N, is not (neither a
# cohesive traction nor a softening stress exceeds f_t)
FT, B, LIG, S = 3.33, 50.0, 100.0, 2000.0
P_LOW, P_HIGH = 4 * FT * B * LIG**2 / (6 * S), 2 * FT * B * LIG**2 / S


def test_reduced_cohesive(tmp_path):
    """Hillerborg's fictitious crack up the ligament: the faces past f_t lie on the crack line
    from the notch tip up, the bonded ligament's first step within 5 % of the uncut beam's
    (measured 3.9 % at h = 25 mm), and the peak between the limit loads (measured 876 N)."""
    out = tmp_path / "beam.json"
    r = demo.main(["--h", "25", "--json", str(out), "--end-cmod", "0.3"])
    assert r["crack"] == "cohesive"
    for key in ("cmod", "load", "deflection", "peak_load_N", "cmod_at_peak_mm",
                "dissipated_energy_J", "time_total", "particles", "fe_cells",
                "newton_iterations", "path"):  # fmt: skip
        assert key in r
    assert 1e-3 < r["elastic_step_error"] <= 0.05  # bonded faces are not the uncut beam
    assert np.all(np.diff(r["deflection"]) > 0)
    path = np.asarray(r["path"]).reshape(-1, 2)
    assert np.allclose(path[:, 0], 1000.0)
    assert path[:, 1].min() >= 100.0 and path[:, 1].max() > 150.0
    assert P_LOW < r["peak_load_N"] < P_HIGH


def test_ramp_follows_pure_efg():
    """The ramp coupling (interface elements, Belytschko et al. 1995) carries the cohesive crack
    in its patch: its peak within 1.2 % of pure EFG's at h = 25 mm (measured -0.58 %; issue
    target 2 %), on the same crack path."""
    efg = demo.main(["--h", "25", "--method", "efg", "--end-cmod", "0.3"])
    ramp = demo.main(["--h", "25", "--method", "ramp", "--end-cmod", "0.3"])
    assert abs(ramp["peak_load_N"] / efg["peak_load_N"] - 1.0) <= 0.012
    assert np.allclose(np.asarray(ramp["path"])[:, 0], 1000.0)


def test_master_slave_follows_pure_efg():
    """Master-slave carries the cohesive crack in its patch (cut cells, Gauss quadrature): its
    peak within 1.5 % of pure EFG's at h = 20 mm (measured -0.76 %; issue target 2 %), on the
    same crack path. At h = 25 mm its first step fails the demo's 5 % check (5.1 %, see the
    demo's header)."""
    efg = demo.main(["--h", "20", "--method", "efg", "--end-cmod", "0.3"])
    ms = demo.main(["--h", "20", "--method", "master-slave", "--end-cmod", "0.3"])
    assert abs(ms["peak_load_N"] / efg["peak_load_N"] - 1.0) <= 0.015
    assert np.allclose(np.asarray(ms["path"])[:, 0], 1000.0)


def test_reduced_three_point_bend(tmp_path):
    out = tmp_path / "beam.json"
    r = demo.main(["--h", "25", "--json", str(out), "--end-cmod", "0.3", "--crack", "band"])
    for key in ("cmod", "load", "deflection", "peak_load_N", "cmod_at_peak_mm",
                "dissipated_energy_J", "time_total", "particles", "fe_cells",
                "newton_iterations", "damage_zone"):  # fmt: skip
        assert key in r
    assert r["elastic_step_error"] <= 1e-6
    assert r["fe_max_damage"] == 0.0
    # the deflection grows monotonically with the CMOD (no snap-back in this beam)
    assert np.all(np.diff(r["deflection"]) > 0)
    # the damage zone runs up from the notch tip (100 mm) along mid-span
    zone = np.asarray(r["damage_zone"]).reshape(-1, 2)
    assert zone[:, 1].max() > 150.0
    assert np.abs(zone[:, 0] - 1000.0).max() < 2 * 25.0
    assert P_LOW < r["peak_load_N"] < P_HIGH  # measured 1181 N


def test_coupled_peak_matches_pure_efg():
    """The issue's coupling target, at h = 25 mm with the crack band: the lagrange coupling's
    peak load within 0.5 % of pure EFG's on the same particles and mesh (measured 0.22 %; issue
    target 2 %), and its damage zone within two particle spacings of EFG's (its mean x)."""
    band = ["--h", "25", "--end-cmod", "0.3", "--crack", "band"]
    efg = demo.main([*band, "--method", "efg"])
    lag = demo.main([*band, "--method", "lagrange"])
    assert abs(lag["peak_load_N"] - efg["peak_load_N"]) <= 0.005 * efg["peak_load_N"]
    ze = np.asarray(efg["damage_zone"]).reshape(-1, 2)
    zl = np.asarray(lag["damage_zone"]).reshape(-1, 2)
    assert abs(ze[:, 0].mean() - zl[:, 0].mean()) <= 2 * 25.0
    assert abs(ze[:, 1].max() - zl[:, 1].max()) <= 2 * 25.0


def test_bad_options():
    with pytest.raises(SystemExit):
        demo.main(["--notch-width", "5"])
    with pytest.raises(SystemExit):
        demo.main(["--notch-depth", "250"])
