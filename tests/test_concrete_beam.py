"""The concrete beam demo at a reduced size (h = 25 mm: 8 cells over the depth), with the cohesive
crack (the default), with the crack band, and with the two combined: its own checks (the elastic
first step against the linear solve, the energy balance within 2 %, the damage in the patch, the
peak passed), what it reports, and the peak load between two limit loads of the ligament; plain
FE's crack band; the coupling against pure EFG; the shear beam's mixed-mode path found from the
notch (h = 15 mm), and (slow tier) against pure EFG's; a coupled model's FE mesh graded away from
its patch; bad options refused. Runs serially and on
2 ranks."""

from itertools import pairwise

import dolfinx_meshfree as mf

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


def test_reduced_combined():
    """The paper's combined model (``--crack combined``): damage in the bulk, and a cohesive
    crack where it localises (mf.CrackBandSwitch). The crack starts at the notch's tip where the
    band localises and runs up to the top edge within 3e-3 h of the vertical (measured 1.3e-3
    h), and its peak and dissipation are the cohesive crack's on the given path (the default
    run, an elastic bulk) within 1.7e-3 and 6e-4 (measured 4.0e-4 and 3.0e-4; the peaks 8.5e-4
    apart with the steps of the old first-step test); the demo's own
    checks pass (the energy balance: measured 2.8e-4)."""
    combined = demo.main(["--h", "25", "--end-cmod", "0.3", "--crack", "combined"])
    given = demo.main(["--h", "25", "--end-cmod", "0.3"])
    q = np.asarray(combined["crack_polyline"])
    assert q[-1, 1] == pytest.approx(200.0) and len(q) >= 4
    assert np.abs(q[:, 0] - 1000.0).max() <= 3e-3 * 25.0
    for key, tol in (("peak_load_N", 1.7e-3), ("dissipated_energy_J", 6e-4)):
        assert abs(combined[key] - given[key]) <= tol * given[key], (key, combined[key])
    assert combined["handed_over_J"] > 0.0


@pytest.mark.heavy(twin="tests/test_cohesive.py::test_ramps_carry_cracks")
def test_ramp_follows_pure_efg():
    """The ramp coupling (interface elements, Belytschko et al. 1995) carries the cohesive crack
    in its patch: its peak within 1.2 % of pure EFG's at h = 25 mm (measured -0.58 %; issue
    target 2 %), on the same crack path."""
    efg = demo.main(["--h", "25", "--method", "efg", "--end-cmod", "0.3"])
    ramp = demo.main(["--h", "25", "--method", "ramp", "--end-cmod", "0.3"])
    assert abs(ramp["peak_load_N"] / efg["peak_load_N"] - 1.0) <= 0.012
    assert np.allclose(np.asarray(ramp["path"])[:, 0], 1000.0)


@pytest.mark.heavy(twin="tests/test_cohesive.py::test_master_slave_bar_splits_as_the_closed_form")
def test_master_slave_follows_pure_efg():
    """Master-slave carries the cohesive crack in its patch (cut cells, Gauss quadrature): its
    peak within 1.5 % of pure EFG's at h = 20 mm (measured -0.22 %, -0.76 % with the steps of
    the old first-step test; issue target 2 %), on the
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
    assert P_LOW < r["peak_load_N"] < P_HIGH  # measured 1090 N


def test_reduced_fe_crack_band():
    """``--method fe`` (``mf.FEElasticity``: the crack band in plain FE cells, the notch a slit
    of one cell column): the demo's checks pass (the first step against the linear solve to
    1e-6, measured 1.7e-12; the energy balance within 2 %, measured 0.05 %; the peak passed),
    the slit is the middle column (24.7 mm wide) up to 100 mm, the damage zone runs up from its
    top inside that column, and the peak lies between the limit loads (measured 899 N; the
    coupled band's 1090 N spreads the damage over the MLS band, the cohesive crack's 876 N)."""
    r = demo.main(["--h", "25", "--end-cmod", "0.3", "--crack", "band", "--method", "fe"])
    assert r["particles"] == 0 and r["fe_cells"] == 81 * 8 - 4
    assert r["notch_width_mm"] == pytest.approx(2000.0 / 81) and r["notch_depth_mm"] == 100.0
    assert r["elastic_step_error"] <= 1e-6
    assert np.all(np.diff(r["deflection"]) > 0)
    zone = np.asarray(r["damage_zone"]).reshape(-1, 2)
    assert zone[:, 1].min() > 100.0 and zone[:, 1].max() > 150.0
    assert np.abs(zone[:, 0] - 1000.0).max() < r["notch_width_mm"] / 2
    assert P_LOW < r["peak_load_N"] < P_HIGH


@pytest.mark.heavy(twin="tests/test_concrete_beam.py::test_reduced_three_point_bend")
def test_coupled_peak_matches_pure_efg():
    """The issue's coupling target, at h = 25 mm with the crack band: the lagrange coupling's
    peak load within 0.5 % of pure EFG's on the same particles and mesh (measured 0.10 %: 1089.6
    against 1088.5 N; issue target 2 %; 0.22 % before the first step's convergence test was
    fixed: the peaks are the largest steps', and move with the steps by a few 1e-3), and its
    damage zone within two particle spacings of EFG's (its mean x)."""
    band = ["--h", "25", "--end-cmod", "0.3", "--crack", "band"]
    efg = demo.main([*band, "--method", "efg"])
    lag = demo.main([*band, "--method", "lagrange"])
    assert abs(lag["peak_load_N"] - efg["peak_load_N"]) <= 0.005 * efg["peak_load_N"]
    ze = np.asarray(efg["damage_zone"]).reshape(-1, 2)
    zl = np.asarray(lag["damage_zone"]).reshape(-1, 2)
    assert abs(ze[:, 0].mean() - zl[:, 0].mean()) <= 2 * 25.0
    assert abs(ze[:, 1].max() - zl[:, 1].max()) <= 2 * 25.0


@pytest.mark.heavy(twin="tests/test_softening.py::test_particle_band_is_the_dilation_by_default")
def test_ramp_band_matches_pure_efg():
    """The ramp coupling (interface elements) with the crack band, against pure EFG at the ramp's
    dilation 2.5 (the particle band its default, the dilation; h = 25 mm): the peak within 1.1 %
    (measured 0.56 %) and the dissipated energy within 7 % (measured 3.4 %). Before, the ramps'
    particle band was one cell: the peak 21.8 % above, the energy 1.48 G_f per unit area."""
    band = ["--h", "25", "--end-cmod", "0.3", "--crack", "band", "--dilation", "2.5"]
    efg = demo.main([*band, "--method", "efg"])
    ramp = demo.main([*band, "--method", "ramp"])
    assert abs(ramp["peak_load_N"] / efg["peak_load_N"] - 1.0) <= 0.011
    energy = [r["dissipated_energy_J"] for r in (efg, ramp)]
    assert abs(energy[1] / energy[0] - 1.0) <= 0.07


def _path_distance(a, b, below: float) -> float:
    """The largest distance from a point of the polyline ``a`` (sampled every 0.5 mm) below the
    height ``below`` to the polyline ``b`` (written here, apart from the benchmark's)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    x = np.concatenate([p + np.linspace(0, 1, 200)[:, None] * (q - p) for p, q in pairwise(a)])
    x = x[x[:, 1] <= below]
    d = np.full(len(x), np.inf)
    for p, q in pairwise(b):
        t = q - p
        xi = np.clip((x - p) @ t / (t @ t), 0.0, 1.0)
        d = np.minimum(d, np.linalg.norm(x - p - xi[:, None] * t, axis=1))
    return float(d.max())


SHEAR = ["--setup", "arrea-ingraffea", "--h", "15"]


@pytest.mark.heavy(twin="tests/test_cohesive_growth.py::test_crack_turns_normal_to_the_load")
def test_shear_beam_finds_a_mixed_mode_path(tmp_path):
    """The single-edge-notched beam in four-point shear (the dimensions of Arrea & Ingraffea's,
    lagrange, h = 15 mm, CMSD to 0.2 mm): the demo's own checks pass (first step within 5 % of
    the linear solve, measured 3.6 %; energy balance within 2 %, measured 0.6 %; the peak
    passed). The crack found from the notch leaves it at 16 to 64 degrees from the vertical
    (measured 32.0), runs upwards and towards the inner load point at every segment (the
    tension across the compressive strut from that load to the inner support), and splits the
    beam at the top edge between that load (x = 458 mm) and the notch (x = 661 mm) (measured
    at 487 mm), meeting it at a right angle."""
    out = tmp_path / "shear.json"
    r = demo.main([*SHEAR, "--json", str(out)])
    assert r["control"] == "cmsd"
    for key in ("cmsd", "cmod", "load", "peak_load_N", "cmsd_at_peak_mm", "crack_polyline",
                "dissipated_energy_J", "time_total", "particles", "fe_cells"):  # fmt: skip
        assert key in r
    q = np.asarray(r["crack_polyline"])
    grown = np.diff(q[1:], axis=0)  # from the notch's tip
    assert np.all(grown[:, 1] > 0.0) and np.all(grown[:, 0] <= 1e-9), q
    kink = np.degrees(np.arctan2(-grown[0, 0], grown[0, 1]))  # from the vertical notch
    assert 16.0 <= kink <= 64.0  # measured 32.0 degrees
    assert q[-1, 1] == pytest.approx(306.0, abs=1e-9)
    assert 458.0 < q[-1, 0] < 661.0
    assert q[-2, 0] == pytest.approx(q[-1, 0], abs=1e-9)  # the last stretch is vertical
    # one grown segment, at (585, 192) mm, would have run beside a particle row: turned 10 deg
    turns = np.asarray(r["turns_deg"])
    assert turns.size == len(q) - 3 and np.count_nonzero(turns) == 1 and 10.0 in np.abs(turns)


@pytest.mark.slow
def test_shear_beam_coupling_follows_pure_efg():
    """Issue 24's coupling target on the shear beam at h = 15 mm: the lagrange coupling's peak
    within 3.5 % of pure EFG's (measured +1.72 %; target 2 %), its found path within 1 mm of
    EFG's below three quarters of the depth (measured 0.46 mm), and within 2 mm over the whole
    depth (measured 0.83 mm, the top ends at x = 487.27 and 486.77 mm; target two spacings = 30
    mm). It measured 2.37 mm (top at 488.35 mm) while the branch guard (LEVER_JUMP, 20e3f8e)
    cut one of lagrange's steps past the peak: a 4.8-fold jump from a lever of 2.6e-3 of the
    first step's, where the path turns; measured from LEVER_FLOOR times the first step's, it is
    no jump. Pure EFG's energy balance (work minus stored against dissipated) within 1.5 %
    (measured 0.73 %), run without the demo's checks. Before grown segments kept off the
    particles, EFG's crack turned flat beside a particle row near the load: the paths parted by
    35 mm and its balance was 3.0 % off."""
    efg = demo.main([*SHEAR, "--method", "efg", "--no-check"])
    balance = abs(efg["energy_balance_J"] / efg["dissipated_energy_J"] - 1.0)
    assert balance <= 0.015
    lag = demo.main([*SHEAR, "--method", "lagrange"])
    assert abs(lag["peak_load_N"] / efg["peak_load_N"] - 1.0) <= 0.035
    assert _path_distance(lag["crack_polyline"], efg["crack_polyline"], 0.75 * 306.0) <= 1.0
    assert _path_distance(lag["crack_polyline"], efg["crack_polyline"], 306.0) <= 2.0


@pytest.mark.slow
def test_shear_beam_small_increments():
    """The same beam with CMSD increments from 2.4e-4 mm (`--end 0.06`: 0.3 of the default
    run's first and largest steps): at one of its extensions Newton's line search stalls at the
    faces' loading-unloading switches, and the re-equilibration falls back on the faces' secant
    stiffness (the path failed there before); the peak within 0.3 % of the default increments'
    (measured 0.12 %)."""
    small = demo.main([*SHEAR, "--end", "0.06", "--no-check"])
    default = demo.main([*SHEAR, "--no-check"])
    assert abs(small["peak_load_N"] / default["peak_load_N"] - 1.0) <= 3e-3


@pytest.mark.heavy(
    twin="tests/test_path_patch.py::test_a_patch_grown_into_yielded_cells_carries_their_states"
)
def test_adaptive_patch_finds_the_mode_one_path():
    """``--path found --adapt`` (lagrange, h = 25 mm): the patch starts as the cells within three
    spacings of the notch and its bonded lead and grows ahead of the tip; the demo's checks pass
    (first step, energy balance), the crack runs up the ligament as the given path (every face
    point past f_t within 1e-3 h of mid-span), and the peak is within 1 % of the given path's in
    the demo's fixed patch (measured -0.013 %: 875.14 N against 875.25 N, with the grown patch's
    increments of at most --end / ADAPT_STEPS)."""
    base = ["--h", "25", "--method", "lagrange", "--end-cmod", "0.3", "--quiet"]
    given = demo.main(base)
    grown = demo.main([*base, "--path", "found", "--adapt"])
    assert grown["patch_growths"] >= 1
    # the grown patch's increments are half the fixed one's (the header's ADAPT_STEPS = 50)
    assert (given["max_increment_mm"], grown["max_increment_mm"]) == (0.3 / 25, 0.3 / 50)
    zone = np.asarray(grown["path"]).reshape(-1, 2)
    assert zone[:, 1].max() > 150.0 and np.abs(zone[:, 0] - 1000.0).max() <= 1e-3 * 25.0
    assert abs(grown["peak_load_N"] / given["peak_load_N"] - 1.0) <= 0.01


def test_bad_options():
    with pytest.raises(SystemExit):
        demo.main(["--notch-width", "5"])
    with pytest.raises(SystemExit):
        demo.main(["--notch-depth", "250"])
    with pytest.raises(SystemExit):  # the shear beam's flags, and its path, are its own
        demo.main(["--supports", "10", "20"])
    with pytest.raises(SystemExit):
        demo.main(["--setup", "arrea-ingraffea", "--path", "given"])
    with pytest.raises(SystemExit):
        demo.main(["--setup", "arrea-ingraffea", "--load-split", "0.5", "0.6"])
    with pytest.raises(SystemExit):
        demo.main(["--setup", "arrea-ingraffea", "--loads", "458", "1400"])
    with pytest.raises(SystemExit):  # further cracks beside a growing cohesive crack only
        demo.main(["--further-cracks", "--path", "given"])
    with pytest.raises(SystemExit):
        demo.main(["--further-cracks", "--crack", "band"])
    with pytest.raises(SystemExit):  # the patch grows ahead of a cohesive crack that grows
        demo.main(["--adapt", "--path", "given"])
    with pytest.raises(SystemExit):
        demo.main(["--adapt", "--path", "found", "--method", "efg"])
    with pytest.raises(SystemExit):  # FE cells carry no crack: the band only
        demo.main(["--method", "fe"])
    with pytest.raises(SystemExit):  # plain FE has no particles; a cohesive beam no band
        demo.main(["--method", "fe", "--crack", "band", "--particle-band", "1"])
    with pytest.raises(SystemExit):
        demo.main(["--method", "efg", "--particle-band", "1"])
    with pytest.raises(SystemExit):  # plain FE has no particles
        demo.main(["--method", "fe", "--crack", "band", "--dilation", "2.5"])
    with pytest.raises(SystemExit):  # a coupling's FE columns graded, of the bending beam only
        demo.main(["--grade", "0.8"])
    with pytest.raises(SystemExit):
        demo.main(["--grade", "1.25", "--method", "efg"])
    with pytest.raises(SystemExit):
        demo.main(["--grade", "1.25", "--setup", "arrea-ingraffea"])
    with pytest.raises(SystemExit):
        demo.main(["--grade", "1.25", "--length", "2400"])
    with pytest.raises(SystemExit):
        demo.main(["--grade", "1.25", "--widest", "5"])
    with pytest.raises(SystemExit):
        demo.main(["--widest", "60"])
    with pytest.raises(SystemExit):  # a control increment, above 0
        demo.main(["--max-increment", "0"])


def test_graded_fe_mesh_keeps_the_answer():
    """``--grade``: the coupled model's FE columns widen away from the patch (by 1.25 per column,
    up to 4 h): the patch and its particles are the uniform mesh's, the FE cells fewer than half
    (measured 224 against 592), and the answer the uniform mesh's: the elastic CMOD per unit load
    within 1e-4 (measured -4.6e-5: the cells up to 4 h long are a little stiffer), the load-CMOD
    curve within 4e-5 of the peak (measured 1.9e-5), the peak within 4e-6 (measured -1.8e-6); and
    the peak within 1e-3 of pure EFG's (measured -4.7e-4, as the uniform mesh's). The columns:
    uniform over the patch and two more on each side, each wider than the one before it towards
    the ends (at most ``--widest`` times the ratio), ending at 0 and the span."""
    base = ["--h", "25", "--end-cmod", "0.3"]
    graded = demo.main([*base, "--grade", "1.25"])
    uniform = demo.main(base)
    efg = demo.main([*base, "--method", "efg"])
    assert graded["particles"] == uniform["particles"]
    assert graded["fe_cells"] < 0.5 * uniform["fe_cells"]
    assert abs(graded["control_per_load"] / uniform["control_per_load"] - 1.0) <= 1e-4
    peak = uniform["peak_load_N"]
    curve = np.interp(uniform["cmod"], graded["cmod"], graded["load"])
    assert np.abs(curve - uniform["load"]).max() <= 4e-5 * peak
    assert abs(graded["peak_load_N"] / peak - 1.0) <= 4e-6
    assert abs(graded["peak_load_N"] / efg["peak_load_N"] - 1.0) <= 1e-3
    h = 2000.0 / 81  # the demo's column width at h = 25: an odd count of 81 columns
    x = demo.graded_columns(2000.0, h, (900.0, 1100.0), 1.25, 100.0)
    w = np.diff(x)
    assert x[0] == 0.0 and x[-1] == pytest.approx(2000.0, rel=1e-14)
    middle = (x[:-1] > 900.0 - 3 * h) & (x[1:] < 1100.0 + 3 * h)
    assert np.allclose(x[:-1][middle] / h, np.round(x[:-1][middle] / h))  # the uniform edges
    assert np.allclose(w[middle], h) and middle.sum() == 13
    left, right = w[: np.argmax(middle)], w[len(w) - np.argmax(middle[::-1]) :]
    assert np.all(np.diff(left) <= 1e-9) and np.all(np.diff(right) >= -1e-9)
    assert w.max() <= 1.25 * 100.0


def test_newton_stops_at_the_residual_floor():
    """The notched beam's residual has a round-off floor of about 1e-9 N whatever the load,
    above ``rtol |t q|`` in its first steps (4.4e-10): Newton reached it in one iteration and
    then wandered on it until no step length decreased ``|R|`` (9 iterations serially, 11 on 2
    ranks, and the paths parted). With ``PathOptions.xtol`` it stops at the iteration that moves
    the fields by at most 1e-10 of their norm: the three elastic first steps in 2 iterations
    each (checked), the same count on 2 ranks; with ``xtol=0`` (no such test) the first takes
    at least 5 (measured 9 serially, 11 on 2 ranks)."""
    args = demo.parse(["--h", "25"])
    elastic = mf.LinearElastic(args.E, args.nu, plane="stress")
    iterations, default = {}, mf.PathOptions(1.0, 2.0).xtol
    for xtol in (default, 0.0):
        model, _, _, xm, hx = demo.beam_model(
            args, elastic, mf.LinearCohesive(ft=args.ft, Gf=args.Gf)
        )
        mouth = mf.DisplacementControl(
            [[xm - hx / 2, 0.0], [xm + hx / 2, 0.0]], [[-1.0, 0.0], [1.0, 0.0]]
        )
        options = mf.PathOptions(increment=1.2e-3, end=3.6e-3, xtol=xtol)
        iterations[xtol] = mf.follow_path(model, mouth, options).iterations
    assert iterations[default] == [2, 2, 2]
    assert iterations[0.0][0] >= 5
