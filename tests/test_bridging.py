"""Bridging domain coupling (Belytschko & Xiao 2004; Rabczuk et al. 2006, sec. 5.3):
``coupling="bridging"``.

Oracles: the band's geometry and its linear weight alpha (eq. 47–48), the constraint itself
(``sum_L N_k(x_L) (u_FE(x_L) - u_P(x_L)) = 0`` for every band node k, eq. 57 and 79–80), the
augmented-Lagrangian penalty (eq. 54), the Timoshenko solution (rate and the pure-FE error at
the same h), the same problem solved on COMM_SELF, and the linear patch test.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.couplings.bridging import BridgingBand

import dolfinx
import numpy as np
import pytest
import ufl
from conftest import CELL_TYPES, load_demo, rectangle
from mpi4py import MPI
from test_coupled import beam_mesh, cells_right_of, fe_beam_error, square

EXACT = mf.LinearField(G=((0.3, -0.2), (0.5, 0.1)), c=(0.1, -0.4))


def patch_problem(comm, spacing=1 / 3, **options):
    """2 x 2 square, 6 x 6 quadrilaterals, particles on the cells with centroid x > 2/3."""
    msh = square(comm)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 2 / 3), spacing)
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(
        V, patch, mf.LinearElastic(1000, 0.3), coupling="bridging", **options
    )
    problem.add_dirichlet(mf.boundary_facets(msh), EXACT.displacement)
    return msh, problem


def patch_test_error(**options):
    msh, problem = patch_problem(MPI.COMM_WORLD, **options)
    sol = problem.solve()
    q = mf.cell_quadrature(msh, 7)
    u, _ = sol.evaluate_at_quadrature(q)
    err = np.abs(u - EXACT.displacement(q.points)).max(initial=0.0)
    return MPI.COMM_WORLD.allreduce(err, op=MPI.MAX)


def solve_beam(comm, h, spacing=None, **options):
    mat = mf.LinearElastic(3e7, 0.3)
    beam = mf.TimoshenkoBeam(mat)
    msh = beam_mesh(comm, h)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 24.0), h if spacing is None else spacing)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh), patch, mat, coupling="bridging", **options
    )
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0)), beam.displacement)
    problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48)), beam.traction)
    sol = problem.solve()
    return sol, mf.error_norms(msh, sol.evaluate_at_quadrature, beam, mat)


def test_band_and_weights():
    """Cantilever h = 1.5, patch x > 24, overlap 2: the band is 24 <= x <= 27 (2 x 8 cells) and
    alpha = (x - 24) / 3 at its nodes (0 on the FE side, 1 on the particle side)."""
    comm = MPI.COMM_WORLD
    mat = mf.LinearElastic(3e7, 0.3)
    msh = beam_mesh(comm, 1.5)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 24.0), 1.5)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh), patch, mat, coupling="bridging"
    )
    band = BridgingBand(problem, problem.overlap)
    assert comm.allreduce(band.cells.size) == 16
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[band.cells], 0].mean(axis=1)
    assert np.all((mid > 24.0) & (mid < 27.0))
    x = band.coordinates[band.in_band_node, 0]
    assert np.all((x > 24.0 - 1e-12) & (x < 27.0 + 1e-12))
    assert np.abs(band.alpha[band.in_band_node] - (x - 24.0) / 3.0).max(initial=0) <= 1e-12
    # particles of the closed band: 3 columns of 9
    assert band.particles.size == 27
    assert np.all(np.abs(patch.particles.positions[band.particles, 0] - 25.5) <= 1.5 + 1e-12)


@pytest.mark.xfail(
    strict=True,
    reason="the point constraints (eq. 57, 79-80) do not transmit the band's force "
    "-grad(alpha).sigma consistently to the particles: measured max error 1.1e-2 (quadrature "
    "degree 7 or 14, penalty 0 or E, dilation 2 or 3); not met",
)
def test_patch_test_with_gauss_quadrature():
    """The linear patch test of the published method (point constraints, plain Gauss): 2 x 2
    square, 6 x 6 quadrilaterals, particles on x > 2/3 (spacing 1/3), overlap 2, u linear on
    the whole boundary. Issue target: maximum error <= 1e-6."""
    assert patch_test_error(consistent=False, constraint="points") <= 1e-6


@pytest.mark.parametrize("constraint", ["integral", "points"])
def test_patch_test_at_default_options(constraint):
    """Default options (VCI under the alpha weight, eq. 46, alpha-weighted facet multipliers in
    the band; the integral constraint by default): the linear patch test to round-off (measured
    1e-15 and 4e-14), with either constraint: the VCI band term is the multiplier field that
    balances the FE side's grad(alpha) (``_band_multiplier_of_alpha``), which the multipliers
    carry. Without it (grad(alpha) itself) the point constraints missed by 1.1e-2 here and the
    integral one by 1.6e-3 on the gmsh meshes (tests/test_patch_demo.py covers those)."""
    _, problem = patch_problem(MPI.COMM_WORLD)
    assert problem.consistent and problem.constraint == "integral"
    assert patch_test_error(constraint=constraint) <= 1e-10


def test_patch_test_on_a_graded_unstructured_band():
    """A band whose alpha has a different gradient in every cell: the crossed triangles of a
    perturbed 6 x 6 mesh (interior vertices moved by up to 30 % of a cell, not those of the
    interface x = 2/3), jittered particles. Default options: exact to 1e-10 (measured 1e-14)."""
    comm = MPI.COMM_WORLD
    msh = square(comm, "triangle")
    x = msh.geometry.x
    inner = np.all((x[:, :2] > 1e-9) & (x[:, :2] < 2 - 1e-9), axis=1) & ~np.isclose(x[:, 0], 2 / 3)
    phase = np.sin(12.9898 * x[:, 0] + 78.233 * x[:, 1]) * 43758.5453
    shift = 0.1 * (2 * (phase - np.floor(phase)) - 1)
    x[inner, 0] += shift[inner]
    x[inner, 1] -= 0.5 * shift[inner]
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 2 / 3), 1 / 3, jitter=0.3)
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1000, 0.3), coupling="bridging")
    problem.add_dirichlet(mf.boundary_facets(msh), EXACT.displacement)
    sol = problem.solve()
    qb = mf.cell_quadrature(msh, 1, sol.band.cells)
    grads = np.concatenate(comm.allgather(sol.band.alpha_at(qb.points, qb.cells, 1)[1]))
    assert len(np.unique(np.round(grads, 9), axis=0)) > 10  # differs from cell to cell
    q = mf.cell_quadrature(msh, 7)
    u, _ = sol.evaluate_at_quadrature(q)
    err = np.abs(u - EXACT.displacement(q.points)).max(initial=0.0)
    assert comm.allreduce(err, op=MPI.MAX) <= 1e-10


def constraint_residual(sol, V):
    """``sum_L N_k(x_L) (u_FE(x_L) - u_P(x_L))`` for every node k (global numbering)."""
    x = sol.patch.particles.positions[sol.band.particles]
    u_fe = mf.evaluate_fe_function(sol.u, x)
    u_p = sol.mls.tabulate(x, 0).values @ sol.coefficients
    n = mf.tabulate_fe_basis(V, x, derivatives=0).values
    return n.T @ (u_fe - u_p), np.abs(u_p).max()


@pytest.mark.parametrize("spacing", [1.5, 0.75])
def test_constraint_holds(spacing):
    """The point constraints' equations hold to round-off, at particles on the FE nodes and
    between."""
    sol, _ = solve_beam(MPI.COMM_WORLD, 1.5, spacing=spacing, constraint="points")
    r, scale = constraint_residual(sol, sol.u.function_space)
    assert np.abs(r).max() <= 1e-10 * scale


def test_penalty():
    """With one particle per band node the weighted constraints force u_FE = u_P at every band
    particle, so the penalty p g^T g (eq. 54) leaves the solution unchanged; with two particles
    per cell side it changes it, and the constraint still holds (point constraints)."""
    pts = np.random.default_rng(3 + MPI.COMM_WORLD.rank).uniform([0.5, -5.5], [47.5, 5.5], (20, 2))
    a, _ = solve_beam(MPI.COMM_WORLD, 1.5, constraint="points")
    b, _ = solve_beam(MPI.COMM_WORLD, 1.5, penalty=3e7, constraint="points")
    ua, ub = a.displacement(pts), b.displacement(pts)
    assert np.abs(ua - ub).max() <= 1e-8 * np.abs(ua).max()
    c, _ = solve_beam(MPI.COMM_WORLD, 1.5, spacing=0.75, constraint="points")
    d, _ = solve_beam(MPI.COMM_WORLD, 1.5, spacing=0.75, penalty=3e7, constraint="points")
    uc, ud = c.displacement(pts), d.displacement(pts)
    assert np.abs(uc - ud).max() > 1e-8 * np.abs(uc).max()
    r, scale = constraint_residual(d, d.u.function_space)
    assert np.abs(r).max() <= 1e-10 * scale


def test_cantilever_rate_and_error_against_pure_fe():
    """Default options on the Timoshenko cantilever (patch x > 24, spacing h): L2 errors
    2.62e-2, 6.59e-3, 2.92e-3 at h = 3, 1.5, 1, rate 2.0, 0.91-0.93 times the plain FE error
    (the published variant, point constraints and plain Gauss: 0.93-0.96). Bounds: rate within
    0.2 of 2, ratio within [0.8, 1.0] (the band's particles must not make it worse than FE)."""
    hs = [3.0, 1.5, 1.0]
    errs = [solve_beam(MPI.COMM_WORLD, h)[1]["l2"] for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert 1.8 <= slope <= 2.2
    for h, e in zip(hs, errs, strict=True):
        assert 0.8 * fe_beam_error(h) <= e <= 1.0 * fe_beam_error(h)


def test_parallel_equals_serial(rank_rng):
    pts = rank_rng.uniform([0.5, -5.5], [47.5, 5.5], (20, 2))
    # and points in the band (24 < x < 27)
    pts = np.vstack([pts, rank_rng.uniform([24.1, -5.9], [26.9, 5.9], (10, 2))])
    world, _ = solve_beam(MPI.COMM_WORLD, 1.5, penalty=1e7)
    alone, _ = solve_beam(MPI.COMM_SELF, 1.5, penalty=1e7)
    a = world.displacement(pts)
    b = alone.displacement(pts)
    assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"overlap": 0}, "overlap must be a positive integer"),
        ({"overlap": -1}, "overlap must be a positive integer"),
        ({"overlap": 1.5}, "overlap must be a positive integer"),
        ({"overlap": True}, "overlap must be a positive integer"),
        ({"penalty": -1.0}, "penalty must be finite and >= 0"),
        ({"penalty": float("nan")}, "penalty must be finite and >= 0"),
        ({"penalty": "big"}, "penalty must be a real number"),
        ({"constraint": "nodes"}, "constraint='nodes' is not known"),
        ({"band_width": 0.0}, "band_width must be None .* or a positive length, got 0.0"),
        ({"band_width": float("inf")}, "band_width must be None"),
        ({"band_width": "wide"}, "band_width must be None"),
    ],
)
def test_bad_options(options, message):
    with pytest.raises(ValueError, match=message):
        patch_problem(MPI.COMM_WORLD, **options)


def test_band_wider_than_the_patch():
    """The patch is 4 cells wide: overlap 4 fills it (the band reaches the patch's far side,
    alpha < 1 on its Dirichlet facets; linear patch test exact at default options, measured
    9e-14, was only checked below 1.0), overlap 5 is refused on every rank."""
    assert patch_test_error(overlap=4) <= 1e-10
    _, problem = patch_problem(MPI.COMM_WORLD, overlap=5)
    with pytest.raises(ValueError, match=r"overlap=5 cell layers is wider than the patch: only 4"):
        problem.solve()


def cantilever_bands(comm):
    """``band_of(width)``: the bridging band (2 layers, or ``width``) of the cantilever (h = 1.5)
    with its patch right of x = 24, built afresh at each call on one mesh and patch."""
    msh = beam_mesh(comm, 1.5)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 24.0), 1.5)
    V = _compat.vector_function_space(msh)
    mat = mf.LinearElastic(3e7, 0.3)
    return lambda width: BridgingBand(
        mf.CoupledElasticity(V, patch, mat, coupling="bridging"), 2, width
    )


@pytest.mark.parametrize(("width", "nodes"), [(3.0, [0, 0.5, 1]), (2.25, [0, 1 / 1.5, 1])])
def test_band_of_a_physical_width(width, nodes):
    """``band_width``: the patch cells with a node closer than the width to the interface x = 24
    of the cantilever (h = 1.5), alpha = min((x - 24) / width, 1) at the nodes. A width of two
    cells gives the band of two cell layers exactly; 1.5 cells gives the same cells with alpha
    2/3 on the middle nodes."""
    comm = MPI.COMM_WORLD
    band_of = cantilever_bands(comm)
    layers, band = band_of(None), band_of(width)
    assert band.layer is None
    assert np.array_equal(band.cells, layers.cells)
    assert np.array_equal(band.in_band_node, layers.in_band_node)
    assert np.array_equal(band.particles, layers.particles)
    x = band.coordinates[band.in_band_node, 0]
    assert np.abs(band.alpha[band.in_band_node] - np.minimum((x - 24.0) / width, 1)).max() < 1e-12
    values = np.concatenate(comm.allgather(band.alpha[band.in_band_node]))
    assert np.allclose(np.unique(np.round(values, 12)), nodes)


def test_band_of_a_physical_width_decides_ties_under_round_off(monkeypatch):
    """A width of exactly two cells puts the third node layer at a tie (distance = width). With
    the distances perturbed by a few ulps, up or down at random per node and rank (what another
    machine's or rank's round-off does), the band is still the two cell layers (issue 23, item
    10: an extra layer of cells on 2 ranks of one machine)."""
    comm = MPI.COMM_WORLD
    band_of = cantilever_bands(comm)
    layers = band_of(None)
    exact = BridgingBand._interface_distance
    rng = np.random.default_rng(7 + comm.rank)

    def noisy(self, problem, on_interface):
        d = exact(self, problem, on_interface)
        return d * (1 + rng.choice([-4, 4], d.size) * np.finfo(float).eps)

    monkeypatch.setattr(BridgingBand, "_interface_distance", noisy)
    band = band_of(3.0)
    assert np.array_equal(band.cells, layers.cells)
    assert np.array_equal(band.in_band_node, layers.in_band_node)
    assert np.array_equal(band.particles, layers.particles)


def test_band_of_a_physical_width_on_a_curved_gmsh_patch():
    """Default options with ``band_width`` on the unstructured triangles of the patch-test demo,
    patch |c - (2, 1)| < 1.1 (an interface following a circle): the linear patch test to
    round-off (measured 2e-14); the band is the cells within the width of the interface."""
    demo = load_demo("patch_test")
    comm = MPI.COMM_WORLD
    args = demo.parse(["--mesh", "irregular", "--cell", "triangle"])
    msh, jitter = demo.make_mesh(comm, args)
    patch = mf.ParticlePatch(msh, demo.patch_cells(msh, "curved"), 1 / 3, jitter=jitter)
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(
        V, patch, mf.LinearElastic(1000, 0.3), coupling="bridging", band_width=0.45
    )
    problem.add_dirichlet(mf.boundary_facets(msh), EXACT.displacement)
    sol = problem.solve()
    assert 0 < comm.allreduce(sol.band.cells.size) < comm.allreduce(patch.cells.size)
    q = mf.cell_quadrature(msh, 7)
    u, _ = sol.evaluate_at_quadrature(q)
    err = np.abs(u - EXACT.displacement(q.points)).max(initial=0.0)
    assert comm.allreduce(err, op=MPI.MAX) <= 1e-10


def test_band_of_a_physical_width_keeps_the_rate_on_the_bushing():
    """The bushing of demos/plug_into_existing_model.py (gmsh triangles h = 0.2, 0.1, 0.05,
    curved interface r = 1.4, particles at the vertices), band_width = 0.2. The published
    variant (point constraints, plain Gauss) with the 2-layer band loses its rate as the band
    narrows (L2 rate 1.55, error 0.62 -> 1.21 x FE; FE: 2.03); with the band of a width it
    keeps it: rate 2.14, 0.84 -> 0.72 x FE (default options: 2.04, 0.70-0.72 x FE, run by the
    demo). Bounds: rate within 0.25 of the measured one, error <= FE's on every mesh."""
    demo = load_demo("plug_into_existing_model")
    args = demo.parse([])
    hs = [0.2, 0.1, 0.05]
    options = {"band_width": 0.2, "consistent": False, "constraint": "points"}
    demo.bridging_band = lambda _args: options
    fe, br = [], []
    for h in hs:
        records = demo.run(MPI.COMM_WORLD, args, h, ["bridging"])
        fe.append(records[0]["l2"])
        br.append(records[1]["l2"])
    rate = np.polyfit(np.log(hs), np.log(br), 1)[0]
    assert abs(rate - 2.14) <= 0.25, rate
    assert all(b <= f for b, f in zip(br, fe, strict=True)), (br, fe)


def test_integral_constraint():
    """With plain Gauss quadrature (``consistent=False``), ``constraint="integral"`` (eq. 52)
    against the point constraints (eq. 79-81): the cantilever keeps rate 2 with errors no larger
    than the point constraints' (measured 2.62e-2, 6.59e-3, 2.92e-3 against 2.69e-2, 6.81e-3,
    3.01e-3), and the linear patch test drops from 1.1e-2 to the Gauss quadrature level (exact
    with VCI, the default: test_patch_test_at_default_options)."""
    hs = [3.0, 1.5, 1.0]
    errs = [solve_beam(MPI.COMM_WORLD, h, consistent=False)[1]["l2"] for h in hs]
    assert np.polyfit(np.log(hs), np.log(errs), 1)[0] >= 1.9
    points = [
        solve_beam(MPI.COMM_WORLD, h, consistent=False, constraint="points")[1]["l2"] for h in hs
    ]
    assert all(e <= p for e, p in zip(errs, points, strict=True))
    plain = patch_test_error(consistent=False, constraint="points")
    assert patch_test_error(consistent=False) < 1e-4 < 1e-3 < plain


def test_too_few_band_particles_for_point_constraints():
    """Coarse jittered particles leave band nodes without enough band particles to determine the
    multipliers: a clear error on every rank (it was a singular or silently wrong solve). The
    integral constraint solves the same problem; here the band and facet constraints determine
    the few coarse particles on their own, so the linear field comes back to round-off (a check
    that the constraints are consistent, not a patch test of the coupling)."""
    msh = square(MPI.COMM_WORLD)
    # (the grid alone: the coarse particles that the constraints determine on their own)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 2 / 3), 0.5, jitter=0.3, placement="grid")
    V = _compat.vector_function_space(msh)
    for constraint in ("points", "integral"):
        problem = mf.CoupledElasticity(
            V, patch, mf.LinearElastic(1000, 0.3), coupling="bridging", constraint=constraint
        )
        problem.add_dirichlet(mf.boundary_facets(msh), EXACT.displacement)
        if constraint == "points":
            with pytest.raises(ValueError, match=r"cannot determine the band multipliers"):
                problem.solve()
        else:
            sol = problem.solve()
            q = mf.cell_quadrature(msh, 7)
            u, _ = sol.evaluate_at_quadrature(q)
            err = np.abs(u - EXACT.displacement(q.points)).max(initial=0.0)
            assert MPI.COMM_WORLD.allreduce(err, op=MPI.MAX) <= 1e-10


# --- stair steps of a slanted interface (issue 23, item 7) ---------------------------------------
#
# The reported model: [0, 2] x [0, 1], 32 x 16 cells (h = 1/16), the patch the cells whose centre
# has x - a y > 0.55, x + b y < 1.55, 0.12 < y < 0.88 (a slanted island, FE all round), particles
# at spacing h/2, default options, a constant body load, the whole boundary held. Its staircase
# interface has band cells whose nodes all lie on the interface (alpha = 0 throughout), and at
# slant (a, b) = (0.5, 0.4) the particles beside them ([0.625, 0.15625], [1.5, 0.15625]) reach
# the patch's quadrature only there: alpha-weighted integral exactly 0, refused by the VCI as
# "shape function 29 integrates to ~0" (the reported (0.3, 0.2) has no such particle and solved
# already). Oracle: the exact quadratic field of demos/robustness.py (LOADED, whose body force is
# constant) and the plain FE error of the same model on the same mesh.

robustness = load_demo("robustness")


def stair_model(comm, cell, slant, spacing, exact, body=True, material=None, **options):
    """The reported model on ``cell``s with the patch's slant ``(a, b)`` and particles at
    ``spacing * h``; ``exact`` on every exterior facet, its constant body force if ``body``."""
    msh = rectangle(comm, (0.0, 0.0), (2.0, 1.0), (32, 16), CELL_TYPES[cell])
    n = msh.topology.index_map(2).size_local
    c = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    a, b = slant
    x, y = c[:, 0], c[:, 1]
    cells = np.flatnonzero((x - a * y > 0.55) & (x + b * y < 1.55) & (y > 0.12) & (y < 0.88))
    patch = mf.ParticlePatch(msh, cells, spacing=spacing / 16)
    V = _compat.vector_function_space(msh)
    material = material or robustness.MATERIAL
    problem = mf.CoupledElasticity(V, patch, material, coupling="bridging", **options)
    if body:
        force = exact.body_force(material)
        problem.set_body_force(lambda p: np.tile(force, (p.shape[0], 1)))
    problem.add_dirichlet(mf.boundary_facets(msh), exact.displacement)
    return msh, problem


def max_error(comm, msh, sol, exact, rng=None):
    """Largest error at the degree-7 Gauss points of every cell and, with ``rng``, at random
    points (every rank)."""
    q = mf.cell_quadrature(msh, 7)
    u, _ = sol.evaluate_at_quadrature(q)
    err = comm.allreduce(np.abs(u - exact.displacement(q.points)).max(initial=0.0), op=MPI.MAX)
    if rng is not None:
        pts = rng.uniform([0.0, 0.0], [2.0, 1.0], (500, 2))
        err = max(err, np.abs(sol.displacement(pts) - exact.displacement(pts)).max())
    return comm.allreduce(err, op=MPI.MAX)


@pytest.mark.all_cases
@pytest.mark.parametrize(
    ("cell", "slant", "spacing", "held"),
    [
        ("quadrilateral", (0.3, 0.2), 0.5, []),  # as reported
        # refused before: "shape function 29", "49", "27 integrates to ~0"
        ("quadrilateral", (0.5, 0.4), 0.5, [[0.625, 0.15625], [1.5, 0.15625]]),
        ("quadrilateral", (0.7, 0.7), 0.5, [[1.4375, 0.15625], [1.03125, 0.6875]]),
        ("triangle", (0.5, 0.4), 0.5, [[1.46875, 0.125], [1.5, 0.125], [1.5, 0.15625]]),
        ("quadrilateral", (0.5, 0.4), 1.0, []),  # spacing h
        ("triangle", (0.7, 0.7), 1.0, []),
    ],
)
def test_stair_steps_at_default_options(cell, slant, spacing, held):
    """The reported model and variations (slant, triangles, spacing h) solve at default options
    with the L2 error within 1.2x the plain FE error (the issue's target; measured 0.918,
    0.950, 0.975, 0.972, 0.947, 0.990 in the order of the cases; lagrange 0.86-1.01 on the same
    models). The particles with alpha = 0 on their whole support are held (their number, on
    every rank), and the band's stair-step cells (alpha = 0 throughout) are left out of the
    constraint. ``held``: their coordinates (those the refusal named by index)."""
    comm = MPI.COMM_WORLD
    exact = robustness.LOADED
    msh, problem = stair_model(comm, cell, slant, spacing, exact)
    sol = problem.solve()
    band = sol.band
    positions = problem.patch.particles.positions[band.held]
    assert np.allclose(positions, np.reshape(held, (-1, 2)), atol=1e-12), positions
    if held:  # stair-step cells (alpha = 0 throughout) in the band, left out of the constraint
        assert comm.allreduce(band.tied_cells.size) < comm.allreduce(band.cells.size)
    coupled = mf.error_norms(msh, sol.evaluate_at_quadrature, exact, robustness.MATERIAL)["l2"]
    fe = robustness.solve_plain_fe(robustness.user_model(msh, "body"))["l2"]
    assert coupled <= 1.2 * fe, coupled / fe


@pytest.mark.parametrize(
    ("cell", "slant", "constraint"),
    [
        ("quadrilateral", (0.5, 0.4), "integral"),
        ("triangle", (0.7, 0.7), "points"),
        ("quadrilateral", (1.0, 0.5), "points"),
    ],
)
def test_stair_steps_keep_the_patch_test_exact(cell, slant, constraint, rank_rng):
    """The linear patch test on stair-step models with held particles (2, 6 and 3 of them):
    exact to round-off at the Gauss points and at random points (measured 1.3e-15, 6.6e-15,
    1.9e-15; bound 1e-10), with either constraint."""
    comm = MPI.COMM_WORLD
    msh, problem = stair_model(
        comm, cell, slant, 0.5, EXACT, body=False, material=mf.LinearElastic(1000, 0.3),
        constraint=constraint,
    )  # fmt: skip
    sol = problem.solve()
    assert sol.band.held.size > 0
    assert max_error(comm, msh, sol, EXACT, rank_rng) <= 1e-10


def test_stair_step_particle_that_a_constraint_sees_is_refused_by_coordinates():
    """A held particle that a band constraint point still reaches (``constraint="points"``,
    dilation 1.5: the band particles on the interface, where alpha = 0, are constraint points)
    would enter the constraint with no stiffness of its own: refused on every rank, naming the
    particle by its coordinates, the dilation and the two fixes; the integral constraint (one of
    them) solves the same model with the patch test exact (measured 1e-15). On 4 x 4 points:
    the default rule of these particles at h / 2, 8 x 8, has points of that particle's support
    where alpha > 0, and the point constraint passes the patch test (measured 2.2e-15)."""
    comm = MPI.COMM_WORLD
    options = {"body": False, "material": mf.LinearElastic(1000, 0.3), "dilation": 1.5}
    msh, problem = stair_model(comm, "quadrilateral", (0.5, 0.4), 0.5, EXACT, **options,
                               constraint="points")  # fmt: skip
    assert problem.quadrature_degree == 15
    assert max_error(comm, msh, problem.solve(), EXACT) <= 1e-10
    options["quadrature_degree"] = 7
    _, problem = stair_model(comm, "quadrilateral", (0.5, 0.4), 0.5, EXACT, **options,
                             constraint="points")  # fmt: skip
    with pytest.raises(ValueError) as info:
        problem.solve()
    message = str(info.value)
    assert "the particle at [0.625, 0.125]" in message
    assert "alpha = 0 at every quadrature point of its support" in message
    assert "a point of the band constraint reaches it" in message
    assert "increase the dilation (now 1.5)" in message
    assert "constraint='integral'" in message
    assert "shape function" not in message
    msh, problem = stair_model(comm, "quadrilateral", (0.5, 0.4), 0.5, EXACT, **options)
    assert max_error(comm, msh, problem.solve(), EXACT) <= 1e-10


@pytest.mark.filterwarnings("ignore::dolfinx_meshfree.StaticModelWarning")  # built only
def test_stair_steps_in_finite_strain_and_dynamics():
    """The held particles' identity rows stay in the Newton tangent: the neo-Hookean model of
    the reported kind (slant (0.5, 0.4), strains of 2e-4) converges and stays near the linear
    solution: measured relative difference 1.3e-3, at (0.7, 0.2) beside a stair step, and the
    same at a tenth of the load (a difference of the finite-strain path's tangent at u = 0 near
    stair steps that predates this change: 1.0e-2 before it, with dilation 2.5 where that code
    ran; 1.4e-4 on the slant (0.3, 0.2), falling with the load). Bound 5e-3. Explicit dynamics
    cannot hold a particle of zero mass yet: refused by its coordinates, and the fix it names
    (a larger dilation) builds the model."""
    comm = MPI.COMM_WORLD
    E, nu = 1000.0, 0.3
    zero = mf.LinearField(G=((0.0, 0.0), (0.0, 0.0)), c=(0.0, 0.0))
    linear = mf.LinearElastic(E, nu, plane="strain", rho=1.0)
    msh, problem = stair_model(comm, "quadrilateral", (0.5, 0.4), 0.5, zero, False, linear)
    force = np.array([1.0, -2.0])
    problem.set_body_force(lambda p: np.tile(force, (p.shape[0], 1)))
    pts = np.array([[1.0, 0.5], [0.7, 0.2], [1.3, 0.8]])
    u_lin = problem.solve().displacement(pts)

    V = problem.V
    law = mf.NeoHookean(E=E, nu=nu, plane="strain")
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    b = dolfinx.fem.Constant(msh, force)
    F = ufl.inner(law.ufl_first_piola(ufl.Identity(2) + ufl.grad(u)), ufl.grad(v)) * ufl.dx
    F -= ufl.dot(b, v) * ufl.dx
    g = dolfinx.fem.Function(V)
    g.x.array[:] = 0.0
    dofs = dolfinx.fem.locate_dofs_topological(V, 1, mf.boundary_facets(msh))
    nonlinear = mf.CoupledNonlinearProblem(
        F, u, [dolfinx.fem.dirichletbc(g, dofs)], problem.patch, law, coupling="bridging"
    )
    _, converged, _ = nonlinear.solve()
    assert converged
    u_nl = nonlinear.solution.displacement(pts)
    assert np.abs(u_nl - u_lin).max() <= 5e-3 * np.abs(u_lin).max()

    with pytest.raises(ValueError, match=r"the particle at \[0\.625, 0\.15625\] .*dilation"):
        mf.ExplicitDynamics.coupled(problem)
    _, wider = stair_model(comm, "quadrilateral", (0.5, 0.4), 0.5, zero, False, linear,
                           dilation=2.5)  # fmt: skip
    mf.ExplicitDynamics.coupled(wider)


@pytest.mark.serial
def test_vci_refusal_names_the_particle_by_coordinates():
    """The consistent integration's refusal (a support that misses the quadrature) names the
    particle by its coordinates when given them; nodes flagged inactive (the bridging's held
    particles) are neither refused nor corrected."""
    from dolfinx_meshfree.physics.operators import vci_constants

    vol = np.array([0.5, 0.0, 0.25])
    rhs = np.array([[1.0, 2.0], [3.0, 4.0], [0.5, 0.5]])
    positions = np.array([[0.0, 0.0], [0.625, 0.15625], [1.0, 1.0]])
    with pytest.raises(ValueError, match=r"the particle at \[0\.625, 0\.15625\] .*dilation"):
        vci_constants(vol, rhs, MPI.COMM_SELF, positions)
    xi = vci_constants(vol, rhs, MPI.COMM_SELF, positions, np.array([False, True, False]))
    assert np.array_equal(xi, [[2.0, 4.0], [0.0, 0.0], [2.0, 2.0]])
