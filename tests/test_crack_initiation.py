"""Further cohesive cracks that start during a path (multiple cracking, issue 24;
``follow_path(initiation=mf.CrackInitiation(law))``, ``statics/crack_initiation.py``).

The model: a two-span continuous concrete beam (two 600 mm spans, 100 mm deep, 50 mm thick, three
supports on the bottom face, loads at both mid-spans), notched under the first span's load, a
cohesive crack grown from the notch by indirect displacement control of its mouth opening. Beam
theory puts the largest hogging moment over the middle support, so that once the first crack
softens the top face above the middle support is where the bulk's stress reaches ``f_t`` next."""

import warnings

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.geometry.crack import CrackDomain, point_segment_distance
from dolfinx_meshfree.statics.cohesive_initiation import InitiationSite, _regions
from dolfinx_meshfree.statics.crack_initiation import first_stretch

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

COMM = MPI.COMM_WORLD
S, D, B, H = 600.0, 100.0, 50.0, 10.0
E, NU, FT, GF = 30000.0, 0.2, 3.0, 0.1
LAW = mf.LinearCohesive(ft=FT, Gf=GF)


def two_span_beam(patch_cells=None, second=1.0):
    """The beam (module docstring), pure EFG (particles at the vertices, h = 10 mm) or coupled
    (Lagrange) with the particles in the cells whose midpoints ``patch_cells(x)`` selects, the
    second span's load ``second`` times the first's; returns ``(model, notch, control)``."""
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.array([0.0, 0.0]), np.array([2 * S, D])], [round(2 * S / H), round(D / H)],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    x0 = S / 2 + 0.5 * H
    notch = mf.Crack([[x0, 0.0], [x0, 20.0], [x0, 20.0 + 4 * H]], through=True)
    material = mf.LinearElastic(E, NU, plane="stress")
    if patch_cells is None:
        model = mf.EFGElasticity(mf.ParticleSet.from_vertices(msh), material, cracks=[notch])
    else:
        cells = dolfinx.mesh.locate_entities(msh, 2, patch_cells)
        patch = mf.ParticlePatch(msh, cells, placement="vertices", cracks=[notch])
        model = mf.CoupledElasticity(_compat.vector_function_space(msh), patch, material)
    model.add_cohesive(notch, LAW, segments=[1])
    for xs in (0.0, S, 2 * S):
        sup = mf.boundary_facets(
            msh, lambda x, xs=xs: np.isclose(x[1], 0.0) & (np.abs(x[0] - xs) < H + 1e-9)
        )
        model.add_dirichlet(sup, lambda x: np.zeros_like(x), components=(1,))
    mid = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.0) & (np.abs(x[0] - S) < H + 1e-9))
    model.add_dirichlet(mid, lambda x: np.zeros_like(x), components=(0,))
    for xl, share in ((S / 2, 1.0), (1.5 * S, second)):
        pad = mf.boundary_facets(
            msh, lambda x, xl=xl: np.isclose(x[1], D) & (np.abs(x[0] - xl) < H + 1e-9)
        )
        w = COMM.allreduce(len(pad)) * H / share
        model.add_traction(pad, lambda x, n, w=w: np.tile([0.0, -1.0 / w], (len(x), 1)))
    cmod = mf.DisplacementControl(
        [[x0 + 0.5 * H, 0.0], [x0 - 0.5 * H, 0.0]], [[1.0, 0.0], [-1.0, 0.0]]
    )
    return model, notch, cmod


OPTIONS = mf.PathOptions(increment=0.005, end=0.025, max_increment=0.02)


def follow(model, notch, cmod, initiation, options=OPTIONS):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        path = mf.follow_path(
            model, cmod, options, growth=mf.CohesiveGrowth(notch), initiation=initiation
        )
    bulk = [w for w in caught if issubclass(w.category, mf.BulkStrengthWarning)]
    return path, bulk


def check_support_crack(path, bulk):
    """The crack that starts: over the middle support (beam theory's largest hogging moment),
    on the top face, running down (normal to sigma_xx), its bonded stretch 4 spacings long,
    started at the step where the bulk first passed f_t (measured 1.07-1.08 f_t at step 5 with
    no crack started there); no BulkStrengthWarning, since the crack that started took the
    stress off (the bulk after it: 0.92-0.93 f_t)."""
    assert bulk == []
    assert len(path.initiations) == 1
    step, control, (a, b) = path.initiations[0]
    assert step == 5 and control == pytest.approx(0.025)
    assert abs(a[0] - S) <= H and a[1] == pytest.approx(D)
    d = np.subtract(b, a)
    assert np.linalg.norm(d) == pytest.approx(4 * H, rel=1e-9)
    assert d[1] < 0 and abs(d[0]) <= np.tan(np.radians(1.0)) * abs(d[1])
    assert path.bulk_stress[4] < FT


@pytest.mark.heavy(
    twin="tests/test_crack_initiation.py::test_a_peak_on_the_fe_side_is_not_started_and_says_so"
)
def test_a_crack_starts_over_the_middle_support_efg():
    """Pure EFG: the crack over the support starts (check_support_crack), is one of the model's
    cracks with the law on its faces, and is followed (grows by the notch's CohesiveGrowth
    parameters)."""
    model, notch, cmod = two_span_beam()
    path, bulk = follow(model, notch, cmod, mf.CrackInitiation(LAW))
    check_support_crack(path, bulk)
    new = model.cracks[-1]
    assert len(model.cracks) == 2 and model.cohesive[-1].crack is new
    assert model.cohesive[-1].law is LAW and model.cohesive[-1].segments is None
    np.testing.assert_allclose(new.points[[0, 1]], path.initiations[0][2], atol=1e-12)


@pytest.mark.heavy(
    twin="tests/test_crack_initiation.py::test_a_peak_on_the_fe_side_is_not_started_and_says_so"
)
def test_a_crack_starts_in_a_coupled_patch_as_in_efg():
    """A Lagrange-coupled model whose patch holds the notch and the middle support (x in 150
    .. 750 mm): the same crack starts at the same step (check_support_crack), and the load
    factors follow pure EFG's within 2 % (measured 0.95-1.25 %: the FE spans are Q1)."""
    model, notch, cmod = two_span_beam(lambda x: (x[0] > 150.0) & (x[0] < 750.0))
    path, bulk = follow(model, notch, cmod, mf.CrackInitiation(LAW))
    check_support_crack(path, bulk)
    assert len(model.patch.cracks) == 2 and model.cohesive[-1].crack is model.patch.cracks[-1]
    efg = [1154.0, 1862.0, 2406.0, 2764.0, 2962.0]  # pure EFG's loads (N), this run
    loads = np.asarray(path.load_factor) * B
    np.testing.assert_allclose(loads, efg, rtol=0.02)


def test_a_peak_on_the_fe_side_is_not_started_and_says_so():
    """The patch holds only the first span (x in 150 .. 450 mm): the bulk's peak over the
    middle support is on the FE side, no crack starts, and the warning names the point and
    why. The peak's region of tension, which grows along the top face as the load rises (to
    1.16 f_t at step 6), is refused once (``PathResult.refused``): left out by a fixed radius
    of three spacings instead, the sites beside the refused one were tried and refused in turn
    (three by step 6)."""
    model, notch, cmod = two_span_beam(lambda x: (x[0] > 150.0) & (x[0] < 450.0))
    options = mf.PathOptions(increment=0.005, end=0.03, max_increment=0.02)
    path, bulk = follow(model, notch, cmod, mf.CrackInitiation(LAW), options)
    assert path.initiations == [] and len(bulk) == 1
    message = str(bulk[0].message)
    assert "at (595, 100)" in message and "at step 5" in message
    assert "no crack is started at (595, 100): it lies on the FE side of the coupled" in message
    assert "add the cells around it to the patch" in message
    assert "its region of tension is left out" in message
    assert [r[:2] for r in path.refused] == [(5, [595.0, 100.0])]
    assert path.refused[0][2] == pytest.approx(path.bulk_stress[4]) and path.refused[0][2] > FT
    assert path.bulk_stress[5] > 1.1 * FT  # the region grew past f_t: refused only once


def test_a_refused_peak_leaves_other_regions_free():
    """Patches on the first span and on the second (x in 750 .. 1050 mm), the second span's
    load 1.2 times the first's. At step 4 the peak over the middle support (1.11 f_t) is on
    the FE side and refused; its region of tension is left out, and the second span's bottom,
    its own region above f_t, starts a crack there in the same step: under its load (within
    two spacings of x = 900 mm, measured 915), from the bottom face, vertical. Before, the
    refused peak kept every other site from starting for the rest of the path."""
    model, notch, cmod = two_span_beam(
        lambda x: ((x[0] > 150.0) & (x[0] < 450.0)) | ((x[0] > 750.0) & (x[0] < 1050.0)), 1.2
    )
    path, bulk = follow(model, notch, cmod, mf.CrackInitiation(LAW))
    assert [r[:2] for r in path.refused] == [(4, [595.0, 100.0])]
    assert "it lies on the FE side" in path.refused[0][3]
    assert len(path.initiations) == 1
    step, _, (a, b) = path.initiations[0]
    assert step == 4 and abs(a[0] - 1.5 * S) <= 2 * H and a[1] == pytest.approx(0.0, abs=1e-9)
    d = np.subtract(b, a)
    assert np.linalg.norm(d) == pytest.approx(4 * H, rel=1e-9)
    assert d[1] > 0 and abs(d[0]) <= np.tan(np.radians(1.0)) * d[1]
    assert len(bulk) == 1 and "its region of tension is left out" in str(bulk[0].message)


@pytest.mark.heavy(
    twin="tests/test_crack_initiation.py::test_a_refused_peak_leaves_other_regions_free"
)
def test_region_chooses_where_cracks_start():
    """Pure EFG, the second span's load 1.2 times the first's, cracks allowed only past x = 700
    mm (``CrackInitiation(region=...)``): the support's peak (1.14 f_t at step 4) starts
    nothing, and the warning says it lies outside the region; the second span's bottom starts
    its crack at step 4, as the coupled model whose patch leaves the support out (measured at
    x = 915 mm, 15 mm from the load)."""
    model, notch, cmod = two_span_beam(None, 1.2)
    region = mf.CrackInitiation(LAW, region=lambda x: x[:, 0] > 700.0)
    path, bulk = follow(model, notch, cmod, region)
    assert path.refused == [] and len(path.initiations) == 1
    step, _, (a, _) = path.initiations[0]
    assert step == 4 and abs(a[0] - 1.5 * S) <= 2 * H and a[1] == pytest.approx(0.0, abs=1e-9)
    assert len(bulk) == 1
    message = str(bulk[0].message)
    assert "at (595, 100)" in message and "it lies outside CrackInitiation.region" in message


@pytest.mark.parametrize("on_edge", [False, True])
def test_a_first_stretch_is_moved_off_the_particles(on_edge):
    """Particles at the vertices of 10 mm squares. Inside, a stretch at 45 degrees through a
    cell's midpoint (45, 45) meets the cell's corners; from the bottom edge's facet midpoint
    (45, 0) one along (1, 2) meets the vertex (50, 10). Each is moved by an eighth of a
    spacing (the first of SHIFTS that clears NEAR_ROW = 0.1 spacing), across the stretch
    inside, along the edge from the edge, keeping its direction and length: its nearest
    particle is then 0.125 spacing off inside and 0.25 / sqrt(5) = 0.112 from the edge (by
    hand). Unmoved, the stretch would be refused (a particle on a crack has no side)."""
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.array([100.0, 100.0])], [10, 10], dolfinx.mesh.CellType.quadrilateral
    )
    particles = mf.ParticleSet.from_vertices(msh)
    domain = CrackDomain.from_particles(particles)
    d = np.array([1.0, 2.0]) / np.sqrt(5.0) if on_edge else np.array([1.0, 1.0]) / np.sqrt(2.0)
    point = np.array([45.0, 0.0]) if on_edge else np.array([45.0, 45.0])
    site = InitiationSite(point, d, FT, 1.0, on_edge, None, 1.0, H)
    crack, why = first_stretch(mf.CrackInitiation(LAW), site, domain, [], False)
    assert why == "" and crack is not None
    a, b = crack.points
    slide = np.array([1.0, 0.0]) if on_edge else np.array([d[1], -d[0]])
    start = point + 0.125 * H * slide - (0.0 if on_edge else 4 * H) * d
    np.testing.assert_allclose(a, start, atol=1e-9)
    np.testing.assert_allclose(b - a, (4 if on_edge else 8) * H * d, atol=1e-9)
    near = point_segment_distance(particles.positions, a[None], b[None]).min()
    assert near == pytest.approx((0.25 / np.sqrt(5.0) if on_edge else 0.125) * H, rel=1e-9)


def test_a_first_stretch_that_does_not_fit_is_not_moved():
    """A site half a spacing below the top edge of the 10 mm grid, its stretch vertical: less
    than a spacing of it fits inside the body, and it is refused as such. The sideways shifts
    are for particles only: none is tried to make a stretch fit."""
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.array([100.0, 100.0])], [10, 10], dolfinx.mesh.CellType.quadrilateral
    )
    domain = CrackDomain.from_particles(mf.ParticleSet.from_vertices(msh))
    site = InitiationSite(np.array([45.0, 95.0]), np.array([0.0, 1.0]), FT, 1.0, False, None, 1, H)
    crack, why = first_stretch(mf.CrackInitiation(LAW), site, domain, [], False)
    assert crack is None and why.startswith("less than a particle spacing (10) of its first")


def test_regions_of_tension():
    """``bulk_stress_peaks``' exclusion by hand: on a line of candidates one spacing apart, two
    regions above the threshold (stresses 3, 4, 5 and 2, 6); excluding from the 4 leaves out
    3, 4, 5 (joined above the threshold), not the 6 beyond a candidate below it; a seed at a
    candidate below the threshold leaves out that candidate only."""
    x = np.column_stack([np.arange(8.0), np.zeros(8)])
    stress = np.array([0.5, 3.0, 4.0, 5.0, 0.5, 2.0, 6.0, 0.5])
    out = _regions(x, stress, [np.array([2.1, 0.2])], 1.0, 1.5)
    np.testing.assert_array_equal(np.flatnonzero(out), [1, 2, 3])
    out = _regions(x, stress, [np.array([4.0, 0.0])], 1.0, 1.5)
    np.testing.assert_array_equal(np.flatnonzero(out), [4])
    out = _regions(x, stress, [np.array([0.0, 0.0]), np.array([6.0, 0.0])], 1.0, 1.5)
    np.testing.assert_array_equal(np.flatnonzero(out), [0, 5, 6])


def test_bad_initiation():
    with pytest.raises(TypeError, match="region must be a callable on points"):
        mf.CrackInitiation(LAW, region=np.ones(3))
    model, notch, cmod = two_span_beam(lambda x: (x[0] > 150.0) & (x[0] < 450.0))
    wrong = mf.CrackInitiation(LAW, region=lambda x: x[0] > 700.0)  # DOLFINx's marker layout
    with pytest.raises(ValueError, match=r"CrackInitiation.region returned shape \(2,\)"):
        follow(model, notch, cmod, wrong, mf.PathOptions(increment=0.005, end=0.01))
    with pytest.raises(TypeError, match="law must be a LinearCohesive"):
        mf.CrackInitiation(mf.LinearElastic(1.0, 0.2))
    for kw, text in (
        ({"lead": 0.5}, r"lead=0.5 must be a number of particle spacings >= 1"),
        ({"gap": -1.0}, r"gap=-1.0 must be a number of particle spacings >= 0"),
        ({"max_cracks": 0}, r"max_cracks=0 must be an integer >= 1"),
        ({"lead": True}, r"lead=True must be"),
    ):
        with pytest.raises(ValueError, match=text):
            mf.CrackInitiation(LAW, **kw)
    model, _, cmod = two_span_beam()
    with pytest.raises(ValueError, match="initiation needs indirect displacement control"):
        mf.follow_path(model, mf.ArcLength(), OPTIONS, initiation=mf.CrackInitiation(LAW))
    with pytest.raises(TypeError, match="initiation must be a CrackInitiation"):
        mf.follow_path(model, cmod, OPTIONS, initiation=LAW)
    plain = mf.EFGElasticity(model.particles, model.material)  # no cohesive crack
    with pytest.raises(ValueError, match="and a crack with add_cohesive"):
        mf.follow_path(plain, cmod, OPTIONS, initiation=mf.CrackInitiation(LAW))
