"""The concrete beam demo at a reduced size (h = 25 mm: 8 cells over the depth): its own checks
(the elastic first step equals the linear solve to 1e-6, the energy balance within 2 %, the damage
in the patch, the peak passed), what it reports, and the peak load between two limit loads of
the ligament; bad options refused. Runs serially and on 2 ranks."""

import numpy as np
import pytest
from conftest import load_demo

demo = load_demo("concrete_beam")


def test_reduced_three_point_bend(tmp_path):
    out = tmp_path / "beam.json"
    r = demo.main(["--h", "25", "--json", str(out), "--end-cmod", "0.3"])
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
    # limit loads of the ligament (depth 100 mm, thickness 50 mm, span 2000 mm, f_t 3.33 MPa):
    # the linear-elastic net-section stress reaching f_t, P = 4 f_t B l^2 / (6 S) = 555 N, is
    # passed (the process zone carries load past it); the ligament in tension at f_t throughout
    # (a rigid-plastic hinge with the compression at the top edge), P = 2 f_t B l^2 / S = 1665 N,
    # is not (softening only lowers the stress). Measured: 1181 N
    ft, B, lig, S = 3.33, 50.0, 100.0, 2000.0
    assert 4 * ft * B * lig**2 / (6 * S) < r["peak_load_N"] < 2 * ft * B * lig**2 / S


def test_coupled_peak_matches_pure_efg():
    """The issue's coupling target, at h = 25 mm: the lagrange coupling's peak load within 0.5 %
    of pure EFG's on the same particles and mesh (measured 0.22 %; issue target 2 %), and its
    damage zone within two particle spacings of EFG's (its mean x)."""
    efg = demo.main(["--h", "25", "--method", "efg", "--end-cmod", "0.3"])
    lag = demo.main(["--h", "25", "--method", "lagrange", "--end-cmod", "0.3"])
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
    with pytest.raises(SystemExit):
        demo.main(["--method", "ramp"])
