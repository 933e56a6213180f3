"""A cohesive crack that finds its path (dolfinx_meshfree.statics.cohesive_growth).

Oracles: the direction rule against the eigenvectors of a uniform stress (MLS reproduces the
linear field exactly); the ray to the boundary against the exact intersection; a bar in uniaxial
tension with an inclined starting crack, whose grown path turns normal to the load (the
principal stress of uniaxial tension); the notched beam in three-point bending, whose path
found by growth is the mode I path given in advance (vertical, by symmetry) with the same peak;
the first segment out of a notch (initiation_direction) against a uniform stress and the
symmetric beam; the last stretch to a free edge against the edge's normal; bad input.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.statics import path_following
from dolfinx_meshfree.statics.cohesive_growth import (
    _to_free_edge,
    principal_direction,
    ray_to_boundary,
)

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "demos"))
import concrete_beam as demo

L, H, E, NU, FT, GF = 200.0, 100.0, 30000.0, 0.2, 3.0, 0.1


def test_direction_is_normal_to_the_largest_principal_stress():
    """A linear displacement field (reproduced exactly by MLS) with principal stresses 2 and -1
    at the angle phi: the direction is (-sin phi, cos phi), oriented along ``along``; leaving out
    the points near a crack does not change it."""
    msh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 8, 8)
    particles = mf.ParticleSet.from_cells(msh, 1.0 / 8)
    mls = mf.MLS(particles)
    law = mf.LinearElastic(E, NU, plane="stress")
    crack = mf.Crack([[0.2, 0.51], [0.5, 0.51]])
    for phi in (0.0, 0.3, -1.1, 2.0):
        R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        sigma = R @ np.diag([2.0, -1.0]) @ R.T
        # the strain of sigma in plane stress: eps = ((1 + nu) sigma - nu tr(sigma) I) / E
        eps = ((1 + NU) * sigma - NU * np.trace(sigma) * np.eye(2)) / E
        coefficients = particles.positions[:, :2] @ eps.T
        expected = np.array([-np.sin(phi), np.cos(phi)])
        along = expected + 0.1 * np.array([1.0, -0.5])
        centre = np.array([0.5, 0.5])
        d = principal_direction(mls, coefficients, law, centre, 0.05, along)
        assert np.abs(d - expected).max() <= 1e-9
        d = principal_direction(mls, coefficients, law, centre, 0.05, -along)
        assert np.abs(d + expected).max() <= 1e-9
        d = principal_direction(mls, coefficients, law, centre, 0.05, along, None, crack, 0.05)
        assert np.abs(d - expected).max() <= 1e-9


def _notched_plate(sigma: np.ndarray):
    """A pure EFG plate 200 x 100 mm with an edge notch up from (103, 0) to (103, 40), and the
    solution object of the linear field whose stress is ``sigma`` (MLS reproduces it exactly,
    the notch's visibility cut too)."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([0.0, 0.0]), np.array([L, H])], [20, 10]
    )
    notch = mf.Crack([[103.0, 0.0], [103.0, 40.0]])
    law = mf.LinearElastic(E, NU, plane="stress")
    model = mf.EFGElasticity(mf.ParticleSet.from_vertices(msh), law, cracks=[notch])
    eps = ((1 + NU) * sigma - NU * np.trace(sigma) * np.eye(2)) / E
    coefficients = model.particles.positions[:, :2] @ eps.T
    solution = mf.EFGSolution(
        mls=model.mls, coefficients=coefficients, multipliers=np.zeros(0), material=law,
        cracks=model.cracks, domain=model._domain,
    )  # fmt: skip
    return solution, notch


def test_initiation_direction_of_a_uniform_stress():
    """Out of the notch's tip, normal to the largest principal stress of a uniform field (to
    1e-9), oriented away from the notch; the tip given by index or by coordinates."""
    for phi in (0.0, 0.4, -0.7):
        R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        solution, notch = _notched_plate(R @ np.diag([2.0, -1.0]) @ R.T)
        expected = np.array([-np.sin(phi), np.cos(phi)])
        expected *= np.sign(expected[1])  # away from the notch (upwards)
        d = mf.initiation_direction(solution, notch)
        assert np.abs(d - expected).max() <= 1e-9
        d = mf.initiation_direction(solution, notch, tip=[103.0, 40.0], radius=5.0, clearance=0.0)
        assert np.abs(d - expected).max() <= 1e-9


def test_initiation_direction_bad_input():
    solution, notch = _notched_plate(np.diag([1.0, 0.0]))
    with pytest.raises(ValueError, match="not one of the solved model's cracks"):
        mf.initiation_direction(solution, mf.Crack([[103.0, 0.0], [103.0, 40.0]]))
    with pytest.raises(ValueError, match=r"tip=1: the crack has 1 tip\(s\) \[\(103, 40\)\]"):
        mf.initiation_direction(solution, notch, tip=1)
    with pytest.raises(ValueError, match=r"tip=\(103, 0\) is not a tip of the crack"):
        mf.initiation_direction(solution, notch, tip=[103.0, 0.0])


def test_initiation_direction_of_the_symmetric_beam():
    """Petersson's notched beam (pure EFG, h = 25 mm; symmetric about the notch): the first
    segment goes straight up, to 4e-3 rad (measured 1.8e-3: the discrete solution of the notched
    beam is mirror-symmetric only to 3e-4 of its displacement, the uncut beam's to 1e-13. The
    cause: cut_cell_quadrature fan-triangulates each piece of a cut cell from its first vertex,
    so mirror pieces get different rules for the rational MLS integrand; triangulated from the
    centroid instead, the beam is symmetric to 9e-14 and this direction vertical to 8e-14,
    measured by hand, not adopted: it would move every cracked figure)."""
    ns = demo.parse(["--h", "25", "--method", "efg"])
    model, *_ = demo.beam_model(ns, mf.LinearElastic(ns.E, ns.nu, plane="stress"))
    d = mf.initiation_direction(model.solve(), demo.particles_cracks(model)[0])
    assert abs(d[0]) <= 4e-3 and d[1] > 0


def test_a_free_edge_is_met_at_a_right_angle():
    """The last stretch to the edge of the unit square: to the nearest point of the edge ahead
    (along its normal), whatever the ray's slant; along the ray when the nearest edge is behind."""
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float)
    seg = np.stack([sq[:-1], sq[1:]], axis=1)
    tip = np.array([0.3, 0.9])
    for deg in (0.0, 30.0, 70.0):
        d = np.array([-np.sin(np.deg2rad(deg)), np.cos(np.deg2rad(deg))])
        to_edge = 0.1 / d[1]
        e, length = _to_free_edge(tip, d, to_edge, seg)
        assert np.abs(e - [0.0, 1.0]).max() <= 1e-15 and length == pytest.approx(0.1, abs=1e-15)
    tip, d = np.array([0.5, 0.05]), np.array([0.0, 1.0])  # the bottom edge is behind
    e, length = _to_free_edge(tip, d, 0.95, seg)
    assert np.array_equal(e, d) and length == 0.95


def test_ray_to_the_boundary():
    """From (0.3, 0.2) in the unit square: to x = 1 along (1, 0) at 0.7, to y = 1 along a unit
    direction at 30 degrees from the vertical at 0.8 / cos(30)."""
    msh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 5, 5)
    patch = mf.ParticlePatch(msh, np.arange(msh.topology.index_map(2).size_local), 0.2)
    start = np.array([0.3, 0.2])
    assert ray_to_boundary(patch, start, np.array([1.0, 0.0])) == pytest.approx(0.7, abs=1e-12)
    t = np.deg2rad(30.0)
    d = np.array([np.sin(t), np.cos(t)])
    assert ray_to_boundary(patch, start, d) == pytest.approx(0.8 / np.cos(t), abs=1e-12)


def _bar(
    method: str,
    angle: float,
    nx: int = 20,
    through: bool = True,
    patch_top: float = np.inf,
    law: object = None,
    cells: object = None,
    lead: bool = True,
):
    """A plate L x H in uniaxial tension (traction 1 on the right end; rollers on the left end
    and on the bottom's first 20 mm), with an edge crack from the bottom at x0: a traction-free
    notch of 20 mm and (``lead``) a bonded cohesive stretch of four spacings, both at ``angle``
    degrees from the vertical; its bulk ``law`` (default: linear elastic). A coupled model's
    patch is the cells within 50 mm of x = 100 mm below ``patch_top``, or ``cells(msh, crack,
    h)``."""
    ny = nx // 2
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([0.0, 0.0]), np.array([L, H])], [nx, ny],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    h = L / nx
    law = mf.LinearElastic(E, NU, plane="stress") if law is None else law
    x0 = np.array([100.0 + 0.37 * h, 0.0])
    t = np.deg2rad(angle)
    d = np.array([np.sin(t), np.cos(t)])
    points = [x0, x0 + 20.0 * d] + ([x0 + (20.0 + 4 * h) * d] if lead else [])
    crack = mf.Crack(points, through=through)
    if method == "efg":
        model = mf.EFGElasticity(mf.ParticleSet.from_vertices(msh), law, cracks=[crack])
    else:
        V = _compat.vector_function_space(msh)
        if cells is None:
            chosen = dolfinx.mesh.locate_entities(
                msh, 2, lambda p: (np.abs(p[0] - 100.0) < 50.0) & (p[1] < patch_top)
            )
        else:
            chosen = cells(msh, crack, h)
        patch = mf.ParticlePatch(msh, chosen, placement="vertices", cracks=[crack])
        model = mf.CoupledElasticity(V, patch, law, coupling=method)
    left = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0))
    bottom = mf.boundary_facets(msh, lambda p: np.isclose(p[1], 0.0) & (p[0] < 20.0))
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    model.add_dirichlet(left, lambda x: np.zeros_like(x), components=(0,))
    model.add_dirichlet(bottom, lambda x: np.zeros_like(x), components=(1,))
    model.add_traction(right, lambda x, n: np.tile([1.0, 0.0], (len(x), 1)))
    control = mf.DisplacementControl(
        [x0 - np.array([h / 2, 0.0]), x0 + np.array([h / 2, 0.0])], [[-1.0, 0.0], [1.0, 0.0]]
    )
    return model, crack, control


def _options(end: float = 0.12) -> mf.PathOptions:
    return mf.PathOptions(increment=end / 200, end=end, max_increment=end / 20, min_load=0.05)


@pytest.mark.parametrize(("angle", "measured"), [(30.0, 7.0), (-30.0, 5.7)])
def test_crack_turns_normal_to_the_load(angle, measured):
    """Uniaxial tension across a crack started at +-30 degrees: every grown segment runs within
    14 degrees of the normal to the load (the largest measured: 7.0 and 5.7 degrees at
    h = 10 mm; 8.0 over 13 extensions at 5 mm), the crack splits the plate at its top, and the
    work of the load minus the stored energy equals the energy the faces dissipated (measured
    5e-4, 3e-4; checked 1e-2). Serial and 2 ranks (equal to 1e-14)."""
    model, crack, control = _bar("efg", angle)
    law = mf.LinearCohesive(FT, GF)
    model.add_cohesive(crack, law, segments=[1])
    path = mf.follow_path(model, control, _options(), growth=mf.CohesiveGrowth(crack))
    assert len(path.extensions) >= 3
    grown = np.diff(crack.points[2:], axis=0)
    angles = np.degrees(np.arctan2(grown[:, 0], grown[:, 1]))
    assert np.abs(angles).max() <= 2 * measured, angles
    assert crack.points[-1, 1] == pytest.approx(H, abs=1e-9)
    assert crack.is_tip == [False, False]
    balance = path.external_work[-1] - path.stored_energy[-1]
    assert abs(balance - path.dissipated_energy[-1]) <= 1e-2 * path.dissipated_energy[-1]
    # the grown faces carry the law: the dissipation is beyond what the starting stretch holds
    assert path.dissipated_energy[-1] > GF * 4 * (L / 20)


def test_growth_in_a_plastic_bulk(monkeypatch):
    """The plate of ``test_crack_turns_normal_to_the_load`` (+30 degrees) in plane strain with a
    J2 bulk that yields before the faces open (sigma_y = 1.5 MPa, H = 3 GPa): the crack grows
    through yielded material, the cut cells' new points take their states from the old points
    of their cells (statics.state_carry), and

    * the bulk's plastic dissipation moves by at most 1.5e-4 of itself at a rebuild (measured
      6.4e-5);
    * the work of the load minus the stored energy equals the energy dissipated by the faces and
      the bulk within 3e-3 (measured 1.5e-3);
    * with ``CARRY_TOLERANCE`` lowered to 1e-5, each rebuild whose change passes it warns
      (``mf.StateCarryWarning``), and no other.

    Serial and 2 ranks take the same 32 steps, equal to 5e-14."""
    law = mf.J2Plasticity(E=E, nu=NU, sigma_y=1.5, H=3000.0, plane="strain")
    model, crack, control = _bar("efg", 30.0, law=law)
    model.add_cohesive(crack, mf.LinearCohesive(FT, GF), segments=[1])
    # a tolerance below the measured changes: every rebuild that passes it warns, no other
    monkeypatch.setattr(path_following, "CARRY_TOLERANCE", 1e-5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", mf.StateCarryWarning)
        path = mf.follow_path(model, control, _options(), growth=mf.CohesiveGrowth(crack))
    assert len(path.extensions) >= 3 and crack.points[-1, 1] == pytest.approx(H, abs=1e-9)
    assert len(path.carried) == len(path.extensions)
    _, before, after, moved, _ = np.array(path.carried).T
    assert moved.min() > 0 and before[-1] > 0.2 * path.dissipated_energy[-1]  # plastic
    assert np.all(np.abs(after - before) <= 1.5e-4 * before)
    above = int(np.sum(np.abs(after - before) > 1e-5 * before))
    carry = [w for w in caught if issubclass(w.category, mf.StateCarryWarning)]
    assert above >= 1 and len(carry) == above, (above, [str(w.message) for w in carry])
    balance = path.external_work[-1] - path.stored_energy[-1]
    assert abs(balance - path.dissipated_energy[-1]) <= 3e-3 * path.dissipated_energy[-1]


def test_a_damaging_bulk_as_strong_as_the_faces_is_not_silent():
    """A RankineDamage bulk with the faces' f_t softens beside them ahead of the tip (the
    energy dissipated twice there): follow_path warns before the first step; a bulk twice as
    strong does not."""
    for ft_bulk, warned in ((FT, True), (2 * FT, False)):
        law = mf.RankineDamage(E=E, nu=NU, ft=ft_bulk, Gf=GF, plane="stress")
        model, crack, control = _bar("efg", 0.0, law=law)
        model.add_cohesive(crack, mf.LinearCohesive(FT, GF), segments=[1])
        options = mf.PathOptions(increment=1e-3, end=0.12, max_steps=1)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            mf.follow_path(model, control, options, growth=mf.CohesiveGrowth(crack))
        double = [
            str(w.message) for w in caught if issubclass(w.category, mf.DoubleSofteningWarning)
        ]
        assert len(double) == int(warned)
        assert all("f_t=3, not above the growing cohesive faces' f_t=3" in m for m in double)


@pytest.mark.heavy(twin="tests/test_cohesive_growth.py::test_crack_turns_normal_to_the_load")
def test_found_path_is_the_given_mode_one_path():
    """The notched beam (h = 25 mm, lagrange): grown from a bonded stretch of four spacings, the
    crack runs up the ligament as the path given in advance (every face point past f_t within
    1e-3 h of mid-span) and its peak is within 1 % of the given path's (measured +0.11 % at
    h = 20 mm: the faces are sampled on other pieces)."""
    base = ["--h", "25", "--method", "lagrange", "--end-cmod", "0.3", "--quiet"]
    given = demo.main(base)
    found = demo.main([*base, "--path", "found"])
    zone = np.asarray(found["path"]).reshape(-1, 2)
    assert zone[:, 1].max() > 150.0
    assert np.abs(zone[:, 0] - 1000.0).max() <= 1e-3 * 25.0
    assert abs(found["peak_load_N"] / given["peak_load_N"] - 1.0) <= 0.01


def test_bad_input():
    model, crack, control = _bar("lagrange", 0.0, through=False)
    with pytest.raises(ValueError, match=r"ahead=1\.0 must exceed step=1\.0"):
        mf.CohesiveGrowth(crack, ahead=1.0)
    with pytest.raises(ValueError, match="radius=-1 must be a positive number"):
        mf.CohesiveGrowth(crack, radius=-1)
    with pytest.raises(ValueError, match=r"clearance=-0\.5 must be a number"):
        mf.CohesiveGrowth(crack, clearance=-0.5)
    with pytest.raises(TypeError, match="crack must be a Crack"):
        mf.CohesiveGrowth([[0.0, 0.0], [1.0, 1.0]])
    with pytest.raises(ValueError, match="carries no traction-separation law"):
        mf.follow_path(model, control, _options(), growth=mf.CohesiveGrowth(crack))
    model.add_cohesive(crack, mf.LinearCohesive(FT, GF), segments=[0])
    with pytest.raises(ValueError, match=r"segment 1 .* at its tip \[.*\] is not cohesive"):
        mf.follow_path(model, control, _options(), growth=mf.CohesiveGrowth(crack))
    with pytest.raises(ValueError, match="ArcLength has not"):
        mf.follow_path(model, mf.ArcLength(), _options(), growth=mf.CohesiveGrowth(crack))
    finite = mf.NeoHookean(E, NU, plane="stress")
    msh = model.V.mesh
    patch = mf.ParticlePatch(msh, model.patch.cells, placement="vertices", cracks=[mf.Crack(
        crack.points)])  # fmt: skip
    large = mf.CoupledElasticity(model.V, patch, finite, coupling="lagrange")
    large.add_cohesive(patch.cracks[0], mf.LinearCohesive(FT, GF))
    with pytest.raises(ValueError, match="NeoHookean bulk: cracks grow in a small-strain bulk"):
        mf.follow_path(large, control, _options(), growth=mf.CohesiveGrowth(patch.cracks[0]))


def test_growth_stops_where_the_model_cannot_follow():
    """A crack that would split the body without ``through=True``, and one that would run
    within a support radius of the FE interface (a patch up to y = 90 mm): refused with the
    point, never carried on."""
    model, crack, control = _bar("efg", 0.0, through=False)
    model.add_cohesive(crack, mf.LinearCohesive(FT, GF), segments=[1])
    with pytest.raises(ValueError, match=r"reaches the exterior boundary at \[10[0-9.]+, 100"):
        mf.follow_path(model, control, _options(), growth=mf.CohesiveGrowth(crack))
    model, crack, control = _bar("lagrange", 0.0, patch_top=90.0)
    model.add_cohesive(crack, mf.LinearCohesive(FT, GF), segments=[1])
    with pytest.raises(ValueError, match="from the FE interface, less than the support radius"):
        mf.follow_path(model, control, _options(), growth=mf.CohesiveGrowth(crack))


def _slanted_beam(increment: float = 0.002):
    """A user's model (written from the README): a beam 600 x 150 mm on triangles in three-point
    bending, a lagrange patch around a notch slanted 15 degrees, a cohesive crack grown from a
    bonded lead, the CMOD to 0.3 mm from ``increment``. Returns the path and the crack."""
    L, D, h = 600.0, 150.0, 10.0
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([0.0, 0.0]), np.array([L, D])], [60, 15],
        dolfinx.mesh.CellType.triangle,
    )  # fmt: skip
    V = _compat.vector_function_space(msh)
    p0 = np.array([303.3, 0.0])
    d = np.array([np.sin(np.deg2rad(15.0)), np.cos(np.deg2rad(15.0))])
    crack = mf.Crack([p0, p0 + 40 * d, p0 + (40 + 4 * h) * d], through=True)
    cells = dolfinx.mesh.locate_entities(msh, 2, lambda p: np.abs(p[0] - 300.0) < 100.0)
    patch = mf.ParticlePatch(msh, cells, placement="vertices", cracks=[crack])
    model = mf.CoupledElasticity(V, patch, mf.LinearElastic(E, NU, plane="stress"))
    model.add_cohesive(crack, mf.LinearCohesive(ft=FT, Gf=GF), segments=[1])
    left = mf.boundary_facets(msh, lambda p: np.isclose(p[1], 0.0) & (p[0] < h))
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[1], 0.0) & (p[0] > L - h))
    model.add_dirichlet(left, lambda x: np.zeros_like(x))
    model.add_dirichlet(right, lambda x: np.zeros_like(x), components=(1,))
    top = mf.boundary_facets(msh, lambda p: np.isclose(p[1], D) & (np.abs(p[0] - 300.0) < 15.0))
    model.add_traction(top, lambda x, n: np.tile([0.0, -1.0], (len(x), 1)))
    cmod = mf.DisplacementControl(
        [p0 - np.array([5.0, 0.0]), p0 + np.array([5.0, 0.0])], [[-1.0, 0.0], [1.0, 0.0]]
    )
    options = mf.PathOptions(increment=increment, end=0.3, max_increment=0.02, min_load=0.1)
    return mf.follow_path(model, cmod, options, growth=mf.CohesiveGrowth(crack)), crack


@pytest.mark.heavy(twin="tests/test_cohesive_growth.py::test_crack_turns_normal_to_the_load")
def test_slanted_notch_in_a_beam_on_triangles():
    """The slanted notch's beam (:func:`_slanted_beam`). The crack grows up from the notch,
    turns towards the load (x = 300 mm) and splits the beam at its top within two spacings
    of the load (measured 14.3 mm from it, the last stretch normal to the edge; 11 mm along the
    ray before; straight on from the notch it would have reached the top
    at 343.5 mm); every grown segment runs upwards: where the bulk around the front is
    compressed all round (next to the beam's compression zone) the crack goes straight on (before
    that rule it turned sideways there, and down). Work minus stored energy equals the
    dissipated energy within 1 % (measured 0.12 %), and follow_path does not warn of it."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", mf.EnergyBalanceWarning)
        path, crack = _slanted_beam()
    grown = np.diff(crack.points[2:], axis=0)
    assert np.all(grown[:, 1] > 0.0), crack.points
    end = crack.points[-1]
    assert end[1] == pytest.approx(150.0, abs=1e-9)
    assert abs(end[0] - 300.0) <= 2 * 10.0
    balance = path.external_work[-1] - path.stored_energy[-1]
    assert abs(balance - path.dissipated_energy[-1]) <= 1e-2 * path.dissipated_energy[-1]


@pytest.mark.heavy(twin="tests/test_cohesive_growth.py::test_crack_turns_normal_to_the_load")
def test_an_unbalanced_energy_record_warns():
    """The slanted notch's beam from CMOD increments of 0.003 mm, not 0.002: its crack extends
    at fixed openings where the finer steps follow it, and the energy record misses by 9.1 % of
    the work (10.9 % of the dissipated energy). follow_path warns (mf.EnergyBalanceWarning, the
    tolerance 3 % of the work) with the figures, and PathResult.energy_error is the share
    computed from the record's own lists. Before, nothing said so: the 0.002 mm run balances to
    0.10 % of the work."""
    with pytest.warns(mf.EnergyBalanceWarning, match="does not balance") as caught:
        path, _ = _slanted_beam(0.003)
    work = path.external_work[-1]
    gap = abs(work - path.stored_energy[-1] - path.dissipated_energy[-1])
    assert path.energy_error == pytest.approx(gap / work, rel=1e-12)
    assert 0.06 <= path.energy_error <= 0.15  # measured 0.0913
    message = str(next(w for w in caught if w.category is mf.EnergyBalanceWarning).message)
    assert f"by {path.energy_error:.1%} of the work" in message


# ## Where a crack starts without a notch (statics.cohesive_initiation)


def _uniform_plate(sigma: np.ndarray):
    """A pure EFG plate 200 x 100 mm without a crack, and the solution object of the linear
    field whose stress is ``sigma`` (MLS reproduces it exactly)."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([0.0, 0.0]), np.array([L, H])], [20, 10]
    )
    law = mf.LinearElastic(E, NU, plane="stress")
    model = mf.EFGElasticity(mf.ParticleSet.from_vertices(msh), law)
    eps = ((1 + NU) * sigma - NU * np.trace(sigma) * np.eye(2)) / E
    coefficients = model.particles.positions[:, :2] @ eps.T
    return mf.EFGSolution(
        mls=model.mls, coefficients=coefficients, multipliers=np.zeros(0), material=law,
        particles=model.particles,
    )  # fmt: skip


def test_initiation_site_of_a_uniform_stress():
    """A uniform stress with principal stresses 2 and -1: the crack starts at ``f_t / 2`` (to
    1e-9), normal to the largest principal stress (1e-9); every point is as good as the site,
    which the margin says (0 to 1e-9)."""
    for phi in (0.0, 0.4, -0.7):
        R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        site = mf.initiation_site(_uniform_plate(R @ np.diag([2.0, -1.0]) @ R.T), FT)
        assert site.load_factor == pytest.approx(FT / 2.0, rel=1e-9)
        n = np.array([np.cos(phi), np.sin(phi)])  # the largest principal direction
        assert abs(site.direction @ n) <= 1e-9
        assert np.linalg.norm(site.direction) == pytest.approx(1.0, abs=1e-12)
        assert abs(site.margin) <= 1e-9 and site.runner_up is not None


def test_initiation_site_bad_input():
    solution = _uniform_plate(np.diag([1.0, 0.0]))
    with pytest.raises(ValueError, match=r"ft=0\.0 must be a positive number"):
        mf.initiation_site(solution, 0.0)
    with pytest.raises(ValueError, match=r"radius=-1\.0 must be a positive number"):
        mf.initiation_site(solution, FT, radius=-1.0)
    with pytest.raises(TypeError, match="region must be a callable"):
        mf.initiation_site(solution, FT, region=[1, 2])
    with pytest.raises(ValueError, match=r"region returned shape \(1,\)"):
        mf.initiation_site(solution, FT, region=lambda x: np.ones(1, dtype=bool))
    with pytest.raises(ValueError, match=r"returned shape \(2,\) .* not as DOLFINx markers"):
        mf.initiation_site(solution, FT, region=lambda x: x[1] > 40.0)  # DOLFINx's layout
    with pytest.raises(ValueError, match="region selects none"):
        mf.initiation_site(solution, FT, region=lambda x: x[:, 0] > 1e3)
    with pytest.raises(ValueError, match=r"principal stress is -1 <= 0 .* compresses"):
        mf.initiation_site(_uniform_plate(np.diag([-1.0, -2.0])), FT)
    site = mf.initiation_site(solution, FT)
    with pytest.raises(ValueError, match=r"lead=-2\.0 must be a positive length"):
        site.crack(lead=-2.0)
    hyper = mf.EFGSolution(
        mls=solution.mls, coefficients=solution.coefficients, multipliers=np.zeros(0),
        material=mf.NeoHookean(E, NU), particles=solution.particles,
    )  # fmt: skip
    with pytest.raises(ValueError, match="law is NeoHookean, not LinearElastic"):
        mf.initiation_site(hyper, FT)
    cube = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 2, 2, 2)
    particles = mf.ParticleSet.from_vertices(cube)
    solid = mf.EFGSolution(
        mls=mf.MLS(particles), coefficients=np.zeros((particles.num_particles, 3)),
        multipliers=np.zeros(0), material=mf.LinearElastic(E, NU), particles=particles,
    )  # fmt: skip
    with pytest.raises(ValueError, match="cracks are 2D; the mesh has gdim=3"):
        mf.initiation_site(solid, FT)


def _beam_theory_site_load(ns, h: float) -> float:
    """The load (N) at which the averaged largest principal stress at the bottom of the
    unnotched beam's mid-span reaches f_t, from Euler-Bernoulli's stress (the load spread over
    the three middle cells of the top) averaged over the half disc with the Gaussian weight of
    length h (closed-form field, integrated by scipy's dblquad: independent of the code's rule
    and of its solve)."""
    from scipy import integrate

    S, D, w = ns.span, ns.depth, 3 * h

    def sigma(x, y):
        a = abs(x)
        m = 0.5 * (S / 2 - a) - ((w / 2 - a) ** 2 / (2 * w) if a < w / 2 else 0.0)
        return m * (D / 2 - y) / (D**3 / 12)  # per N/mm of load

    def weight(r):
        return np.exp(-0.5 * (r / h) ** 2) * r

    num = integrate.dblquad(
        lambda r, t: weight(r) * sigma(r * np.cos(t), r * np.sin(t)), 0, np.pi, 0, 3 * h
    )[0]
    den = integrate.dblquad(lambda r, t: weight(r), 0, np.pi, 0, 3 * h)[0]
    return ns.ft / (num / den) * ns.thickness


def test_initiation_site_of_the_unnotched_beam():
    """Petersson's beam without its notch (lagrange, a patch 200 mm wide at mid-span): the crack
    starts at the bottom of mid-span (to 1e-9 mm), vertical (1e-9), at the load of beam theory's
    averaged stress within 2 % (measured +0.55 % at h = 25 mm, +0.83 % at 20: beam theory
    overestimates the bottom stress under a load by about 0.133 P / D, Timoshenko & Goodier's
    correction, 0.9 % here). With the patch moved 150 mm right the largest stress is on the FE
    side: refused, naming the point, never a site inside the patch."""
    for h in (25.0, 20.0):
        ns = demo.parse(["--h", str(h), "--notch-depth", "0"])
        model, *_ = demo.beam_model(ns, mf.LinearElastic(ns.E, ns.nu, plane="stress"))
        site = mf.initiation_site(model.solve(), ns.ft)
        assert np.abs(site.point - [1000.0, 0.0]).max() <= 1e-9 and site.on_edge
        assert np.abs(site.direction - [0.0, 1.0]).max() <= 1e-9
        expected = _beam_theory_site_load(ns, h)
        assert abs(site.load_factor * ns.thickness / expected - 1.0) <= 0.02
    ns = demo.parse(["--h", "25", "--notch-depth", "0", "--patch-offset", "150"])
    model, *_ = demo.beam_model(ns, mf.LinearElastic(ns.E, ns.nu, plane="stress"))
    with pytest.raises(ValueError, match=r"at \[1000\.0, 0\.0\] on the FE side .* outside the"):
        mf.initiation_site(model.solve(), ns.ft)


@pytest.mark.heavy(twin="tests/test_cohesive_growth.py::test_crack_turns_normal_to_the_load")
def test_unnotched_beam_cracks_where_and_as_the_given_path():
    """The unnotched beam (h = 25 mm, lagrange; demo, `--notch-depth 0 --path found`): the
    crack started at the initiation site grows straight up (every face point past f_t within
    1e-3 h of mid-span) and splits the beam, with the peak of the path given in advance within
    1 % (measured -0.15 %; -0.21 % at h = 20 mm)."""
    base = ["--h", "25", "--notch-depth", "0", "--end-cmod", "0.3", "--quiet"]
    given = demo.main(base)
    found = demo.main([*base, "--path", "found"])
    zone = np.asarray(found["path"]).reshape(-1, 2)
    assert np.abs(zone[:, 0] - 1000.0).max() <= 1e-3 * 25.0
    assert found["crack_polyline"][-1][1] == pytest.approx(200.0, abs=1e-9)
    assert found["initiation"]["point_mm"] == pytest.approx([1000.0, 0.0], abs=1e-9)
    assert abs(found["peak_load_N"] / given["peak_load_N"] - 1.0) <= 0.01


@pytest.mark.heavy(twin="tests/test_cohesive_growth.py::test_crack_turns_normal_to_the_load")
def test_a_crack_inside_the_body_grows_both_ways():
    """The unnotched beam with the crack's start kept 40 mm above the bottom (``region``; h =
    20 mm, lagrange): an interior site at (1000, 50) mm, a crack with two tips that grows down
    to the bottom edge (a mouth) and up through the top, every point within 1e-3 h of mid-span;
    the peak within 1 % of the given path's (measured -0.57 %), work minus stored energy equal
    to the dissipated energy within 1 % (measured 7.9e-4). No step is cut: before the branch
    guard's floor (LEVER_FLOOR) one step was cut four times, the lever jumping 4.6- to 9.3-fold
    from 5.5e-4 of the first step's as the crack grew down to the controlled mouth."""
    ns = demo.parse(["--h", "20", "--notch-depth", "0"])
    elastic = mf.LinearElastic(ns.E, ns.nu, plane="stress")
    twin, *_ = demo.beam_model(ns, elastic)
    site = mf.initiation_site(twin.solve(), ns.ft, region=lambda x: x[:, 1] > 40.0)
    assert not site.on_edge and np.abs(site.point - [1000.0, 50.0]).max() <= 1e-9
    crack = site.crack(lead=30.0)
    assert crack.is_tip == [True, True]
    law = mf.LinearCohesive(ft=ns.ft, Gf=ns.Gf)
    model, _, _, xm, hx = demo.beam_model(ns, elastic, law, None, crack)
    cmod = mf.DisplacementControl([[xm - hx / 2, 0.0], [xm + hx / 2, 0.0]], [[-1.0, 0], [1.0, 0]])
    options = mf.PathOptions(increment=0.3 / 250, end=0.3, min_load=0.1, max_increment=0.3 / 25)
    path = mf.follow_path(model, cmod, options, growth=mf.CohesiveGrowth(crack))
    assert path.cuts == 0
    assert crack.is_tip == [False, False]
    assert crack.points[0, 1] == pytest.approx(0.0, abs=1e-9)
    assert crack.points[-1, 1] == pytest.approx(200.0, abs=1e-9)
    assert np.abs(crack.points[:, 0] - 1000.0).max() <= 1e-3 * 20.0
    given = demo.main(["--h", "20", "--notch-depth", "0", "--end-cmod", "0.3", "--quiet"])
    peak = max(path.load_factor) * ns.thickness
    assert abs(peak / given["peak_load_N"] - 1.0) <= 0.01
    balance = path.external_work[-1] - path.stored_energy[-1]
    assert abs(balance - path.dissipated_energy[-1]) <= 1e-2 * path.dissipated_energy[-1]


@pytest.mark.slow
def test_a_nearly_isotropic_stress_does_not_turn_the_crack():
    """The unnotched beam at h = 10 mm with the direction averaged over 20 mm (lagrange): near
    three quarters of the depth the averaged stress is nearly isotropic (sigma_xx 0.386 against
    sigma_yy 0.406 per unit load) and its principal direction turned the crack by 90 degrees,
    out of the patch; a turn beyond 70.5 degrees (the largest kink of any mixed-mode tip field)
    now goes straight on: the crack runs up mid-span (within 1e-3 h) and splits the beam. With
    the averaging length fixed, the load at which it starts does not depend on h: within 0.5 %
    of h = 20 mm's (measured 0.17 %)."""
    runs = {}
    for h in ("20", "10"):
        runs[h] = demo.main(
            ["--h", h, "--notch-depth", "0", "--path", "found", "--end", "0.3",
             "--growth-radius", "20", "--quiet"]
        )  # fmt: skip
    q = np.asarray(runs["10"]["crack_polyline"])
    assert np.abs(q[:, 0] - 1000.0).max() <= 1e-3 * 10.0
    assert q[-1, 1] == pytest.approx(200.0, abs=1e-9)
    start = [runs[h]["initiation"]["load_N"] for h in ("20", "10")]
    assert abs(start[1] / start[0] - 1.0) <= 0.005


# ## A further crack: the bulk's strength away from the cracks (PathResult.bulk_stress)


def test_a_crack_in_the_wrong_place_is_not_silent():
    """The unnotched beam (h = 25 mm, lagrange) with its cohesive crack given 300 mm off
    mid-span, where beam theory's bottom stress is 0.7 of mid-span's: the bulk at mid-span
    reaches f_t first. follow_path warns (BulkStrengthWarning) at a step where the crack's faces
    have not yet softened (no energy dissipated), naming a point within two spacings of the
    bottom of mid-span, and records the bulk's stress per step."""
    ns = demo.parse(["--h", "25", "--notch-depth", "0", "--patch-offset", "300"])
    elastic = mf.LinearElastic(ns.E, ns.nu, plane="stress")
    crack = mf.Crack([[1300.0, 0.0], [1300.0, 200.0]], through=True)
    model, _, _, _, hx = demo.beam_model(ns, elastic, None, None, crack)
    model.add_cohesive(crack, mf.LinearCohesive(ft=ns.ft, Gf=ns.Gf))
    cmod = mf.DisplacementControl([[1300 - hx / 2, 0.0], [1300 + hx / 2, 0.0]], [[-1, 0], [1, 0]])
    options = mf.PathOptions(increment=2e-4, end=0.004, max_increment=4e-4, min_load=0.1)
    with pytest.warns(mf.BulkStrengthWarning, match=r"reaches 1\.[0-9]+ f_t at \((9|10)"):
        path = mf.follow_path(model, cmod, options)
    first = next(k for k, s in enumerate(path.bulk_stress) if s > ns.ft)
    assert path.dissipated_energy[first] == 0.0
    assert np.linalg.norm(np.subtract(path.bulk_point[first], [1000.0, 0.0])) <= 2 * 25.0
    assert len(path.bulk_stress) == len(path.load_factor)


def test_the_notched_beam_stays_below_the_bulk_strength():
    """Petersson's notched beam (h = 25 mm, lagrange, the crack given up the ligament): the bulk
    three spacings or more from the crack stays below f_t over the whole path (measured 0.24 f_t),
    and follow_path says nothing."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", mf.BulkStrengthWarning)
        r = demo.main(["--h", "25", "--end-cmod", "0.3", "--quiet"])
    assert 0.0 < r["bulk_stress_ratio"] <= 0.5


def test_initiation_site_of_the_pressurised_bushing():
    """A user's model written for plain DOLFINx (demos/plug_into_existing_model.py: the bushing
    on unstructured triangles, its inner ring a lagrange patch, CoupledLinearProblem) under an
    internal pressure: the crack starts on the inner surface (the midpoint of a chord, r within
    2e-3 of 1), radially (1e-4), at the averaged stress of Lamé's closed form within 3.5 %
    (averaged by a fine midpoint rule over the disc clipped to the annulus; measured +1.7 % at
    h = 0.1, +1.2 % at 0.05), and the margin says the ring is a near tie (below 0.05; measured
    7e-4), never below 0."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "demos"))
    from dolfinx_meshfree.verification.analytic import PressurizedBushing

    import plug_into_existing_model as bushing

    msh = bushing.read_mesh(MPI.COMM_WORLD, 0.1)
    V, a, L_form, bcs = bushing.existing_model(msh, 1.0, 0.3, 1.0)
    material = mf.LinearElastic(1.0, 0.3, plane="strain")
    solution = bushing.with_patch(msh, V, a, L_form, bcs, material, "lagrange", {})
    site = mf.initiation_site(solution, 1.0)
    r = np.hypot(*site.point)
    assert site.on_edge and abs(r - 1.0) <= 2e-3
    assert abs(site.direction @ (site.point / r)) >= 1.0 - 1e-4
    assert 0.0 <= site.margin <= 0.05
    exact = PressurizedBushing(material)
    length = site.spacing
    R = (np.arange(400) + 0.5) / 400 * 3 * length
    A = (np.arange(720) + 0.5) / 720 * 2 * np.pi
    RR, AA = np.meshgrid(R, A, indexing="ij")
    x = site.point + np.stack([RR * np.cos(AA), RR * np.sin(AA)], -1).reshape(-1, 2)
    w = (np.exp(-0.5 * (RR / length) ** 2) * RR).ravel()
    inside = np.hypot(x[:, 0], x[:, 1]) >= 1.0
    sigma = material.stress(exact.displacement_gradient(x[inside]))
    s = np.einsum("q,qij->ij", w[inside], sigma) / w[inside].sum()
    assert abs(site.stress / np.linalg.eigvalsh(s)[-1] - 1.0) <= 0.035
