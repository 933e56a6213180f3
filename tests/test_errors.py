"""Bad input gives a clear error that names the argument or the fix, on every rank, without hangs.

Collective functions are called with input that is bad on one rank only, so that the test checks
that the other ranks raise as well (a rank that went on into a collective call would hang the
run; the CI wraps MPI runs in a timeout).
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.physics.user_functions import check_arguments

import dolfinx
import numpy as np
import pytest
from conftest import BEAM_L, beam_ends, beam_mesh, rectangle
from mpi4py import MPI

COMM = MPI.COMM_WORLD
LAST = COMM.size - 1  # the rank that passes the bad input


def grid(n=6, spacing=1.0):
    xs = np.arange(n + 1) * spacing
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    return np.stack([X.ravel(), Y.ravel()], axis=1)


# --- MLS: supports, collinear particles ----------------------------------------------------


def test_tiny_explicit_radii_leave_points_without_support():
    P = grid()
    mls = mf.MLS(P, radii=np.full(P.shape[0], 0.3))
    with pytest.raises(mf.MomentMatrixError, match=r"particle\(s\) in support.*increase radii"):
        mls.tabulate(np.array([[2.5, 2.5]]))


def test_dilation_too_small_for_a_gap_in_the_particles():
    P = grid(8)
    keep = np.linalg.norm(P - 4.0, axis=1) > 2.5  # a hole of radius 2.5 around (4, 4)
    mls = mf.MLS(P[keep], dilation=1.2)
    x = np.array([[1.5, 1.5], [4.0, 4.0]])
    with pytest.raises(
        mf.MomentMatrixError,
        match=r"1 point\(s\); first: point 1 at \[4\. 4\.\] has 0 particle\(s\).*"
        r"increase dilation \(now 1.2\)",
    ):
        mls.tabulate(x)
    # with a large enough dilation the same points are fine (partition of unity holds)
    table = mf.MLS(P[keep], dilation=3.0).tabulate(x)
    assert np.abs(table.values.sum(axis=1) - 1.0).max() < 1e-12


def test_collinear_particles_are_reported():
    t = np.linspace(0.0, 1.0, 12)
    P = np.stack([t, 0.5 * t + 1.0], axis=1)
    with pytest.raises(mf.MomentMatrixError, match="collinear"):
        mf.MLS(P, dilation=3.0).tabulate(P[3:5] + np.array([0.0, 0.01]))
    with pytest.raises(ValueError, match=r"collinear.*increase smoothing_length"):
        mf.SPH(P, volumes=np.full(12, 0.1), correction="gradient").tabulate(P[3:5])


def test_sph_point_without_particles():
    P = grid()
    with pytest.raises(ValueError, match=r"no particle within 2h.*increase smoothing_length"):
        mf.SPH(P, volumes=np.ones(P.shape[0])).tabulate(np.array([[20.0, 20.0]]))


# --- shapes, NaN, names, numbers -------------------------------------------------------------


@pytest.mark.parametrize(
    "make",
    [
        lambda: mf.MLS(np.zeros((5, 4))),
        lambda: mf.MLS(np.zeros(7)),
        lambda: mf.MLS(grid()).tabulate(np.zeros((3, 5))),
        lambda: mf.MLS(grid()).tabulate(np.zeros((2, 2, 2))),
        lambda: mf.SPH(np.zeros((5, 4)) + np.arange(5)[:, None], volumes=np.ones(5)),
    ],
)
def test_wrong_array_shapes(make):
    with pytest.raises(ValueError, match=r"should have shape \(num_points, \d\), got \("):
        make()


def test_wrong_shapes_of_radii_volumes_and_third_coordinate():
    P = grid()
    with pytest.raises(ValueError, match=r"radii should be positive with shape \(49,\)"):
        mf.MLS(P, radii=np.ones(3))
    with pytest.raises(ValueError, match=r"radii should be positive"):
        mf.MLS(P, radii=-np.ones(P.shape[0]))
    with pytest.raises(ValueError, match=r"volumes should be positive with shape \(49,\)"):
        mf.SPH(P, volumes=np.ones(3))
    with pytest.raises(ValueError, match="volumes are required"):
        mf.SPH(P)
    with pytest.raises(ValueError, match="non-zero coordinates beyond gdim=2"):
        mf.MLS(P).tabulate(np.array([[1.0, 1.0, 0.5]]))


def test_nan_coordinates():
    P = grid()
    bad = P.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"points has 1 point\(s\) with NaN.*row 5"):
        mf.MLS(bad)
    with pytest.raises(ValueError, match=r"x has 1 point\(s\) with NaN or infinite.*row 1"):
        mf.MLS(P).tabulate(np.array([[1.0, 1.0], [np.inf, 0.0]]))
    with pytest.raises(ValueError, match="NaN"):
        mf.SPH(bad, volumes=np.ones(P.shape[0]))


@pytest.mark.parametrize("name", ["gauss", "Quartic", "", None, 3])
def test_unknown_weight_names(name):
    with pytest.raises(ValueError, match=r"weight=.* is not a known weight.*'cubic'"):
        mf.MLS(grid(), weight=name)


def test_unknown_basis_and_correction():
    with pytest.raises(ValueError, match="basis='cubic'"):
        mf.MLS(grid(), basis="cubic")
    with pytest.raises(ValueError, match="correction='kernel'"):
        mf.SPH(grid(), volumes=np.ones(49), correction="kernel")
    with pytest.raises(ValueError, match="derivatives=2"):
        mf.MLS(grid()).tabulate(np.array([[1.0, 1.0]]), derivatives=2)


@pytest.mark.parametrize("dilation", [1.0, 0.5, -2.0, 0.0, np.nan, np.inf, "2", None])
def test_bad_dilation(dilation):
    with pytest.raises(ValueError, match=r"dilation=.* must be a number > 1"):
        mf.MLS(grid(), dilation=dilation)


@pytest.mark.parametrize(
    "kwargs, phrase",
    [
        ({"E": 3e7, "nu": 0.5}, "nu=0.5"),
        ({"E": 3e7, "nu": 0.7}, "nu=0.7"),
        ({"E": 3e7, "nu": -1.0}, "nu=-1.0"),
        ({"E": -1.0, "nu": 0.3}, "E=-1.0"),
        ({"E": 0.0, "nu": 0.3}, "E=0.0"),
        ({"E": np.nan, "nu": 0.3}, "E=nan"),
        ({"E": 3e7, "nu": 0.3, "rho": 0.0}, "rho=0.0"),
        ({"E": 3e7, "nu": 0.3, "rho": -7800.0}, "rho=-7800.0"),
        ({"E": 3e7, "nu": 0.3, "plane": "axisym"}, "plane='axisym'"),
    ],
)
def test_bad_material(kwargs, phrase):
    with pytest.raises(ValueError, match=phrase.replace(".", r"\.").replace("+", r"\+")):
        mf.LinearElastic(**kwargs)


def test_bad_beam_geometry():
    mat = mf.LinearElastic(3e7, 0.3)
    with pytest.raises(ValueError, match=r"L=0\.0 must be a positive length"):
        mf.TimoshenkoBeam(mat, L=0.0)
    with pytest.raises(ValueError, match=r"D=-12\.0 must be a positive length"):
        mf.TimoshenkoBeam(mat, D=-12.0)


# --- collective: particle sets ---------------------------------------------------------------


@pytest.fixture
def square():
    return rectangle(COMM, [0.0, 0.0], [2.0, 2.0], [4, 4], dolfinx.mesh.CellType.quadrilateral)


@pytest.mark.parametrize("spacing", [0.0, -0.5, np.nan, np.inf, "0.5", None])
def test_from_cells_bad_spacing_on_every_rank(square, spacing):
    with pytest.raises(ValueError, match=r"spacing=.* must be a positive number"):
        mf.ParticleSet.from_cells(square, spacing)


def test_from_cells_bad_spacing_on_one_rank_only(square):
    spacing = -0.5 if COMM.rank == LAST else 0.5
    with pytest.raises(ValueError, match=r"spacing=-0.5 must be a positive number"):
        mf.ParticleSet.from_cells(square, spacing)


def test_spacing_that_differs_between_ranks(square):
    """A spacing computed from a rank's own cells (valid on each rank, different between them):
    refused on every rank, with each rank's value (before: the ranks built different grids and
    hung in a collective call, MPI_ERR_TRUNCATE, with a ParticlePatch). Serially it is one
    value and builds."""
    spacing = 0.5 + 0.25 * COMM.rank
    if COMM.size == 1:
        assert mf.ParticleSet.from_cells(square, spacing).num_particles > 0
        return
    with pytest.raises(ValueError, match=r"must be the same on every rank .* \[\(0\.5, 0\.0, 0\)"):
        mf.ParticlePatch(square, np.arange(2, dtype=np.int32), spacing=spacing)


@pytest.mark.parametrize("jitter", [0.5, -0.1])
def test_from_cells_bad_jitter(square, jitter):
    with pytest.raises(ValueError, match=rf"jitter={jitter} must lie in \[0, 0.5\)"):
        mf.ParticleSet.from_cells(square, 0.5, jitter=jitter)


def test_particle_set_positions_must_agree_and_lie_in_the_mesh(square):
    P = grid(4, 0.5)
    mine = P + (1e-3 if COMM.rank == LAST and COMM.size > 1 else 0.0)
    if COMM.size > 1:
        with pytest.raises(ValueError, match="identical on every rank"):
            mf.ParticleSet(mine, mesh=square)
    outside = np.vstack([P, [[2.5, 1.0]]])
    message = r"1 particle\(s\) lie outside the mesh, first \[2\.5 1\. \]"
    with pytest.raises(ValueError, match=message):
        mf.ParticleSet(outside, mesh=square)
    bad = P.copy()
    if COMM.rank == LAST:
        bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        mf.ParticleSet(bad, mesh=square)


# --- collective: FE basis at points ----------------------------------------------------------


def space(msh):
    V = _compat.vector_function_space(msh)
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.vstack([x[0], x[1]]))
    u.x.scatter_forward()
    return V, u


OUTSIDE = np.array([2.75, 0.5])


def points_one_outside(rank_rng):
    pts = rank_rng.uniform(0.0, 2.0, (5, 2))
    if COMM.rank == LAST:
        pts[3] = OUTSIDE
    return pts


OUTSIDE_MESSAGE = (
    rf"^1 point\(s\) lie outside the mesh: rank {LAST} point 3 \[2\.75 +0\.5 *\]\. "
    r"Move them into the domain\.$"
)


def test_tabulate_fe_basis_outside_point_raises_on_every_rank(square, rank_rng):
    V, _ = space(square)
    with pytest.raises(mf.PointsOutsideMeshError, match=OUTSIDE_MESSAGE):
        mf.tabulate_fe_basis(V, points_one_outside(rank_rng))


def test_evaluate_fe_function_outside_point_raises_on_every_rank(square, rank_rng):
    _, u = space(square)
    with pytest.raises(mf.PointsOutsideMeshError, match=OUTSIDE_MESSAGE):
        mf.evaluate_fe_function(u, points_one_outside(rank_rng))
    with pytest.raises(mf.PointsOutsideMeshError, match=OUTSIDE_MESSAGE):
        mf.ensure_points_in_mesh(square, points_one_outside(rank_rng))
    # several outside points on several ranks: the count covers all of them
    pts = np.array([[-1.0, 0.5], [1.0, 1.0], [3.0, 3.0]])
    with pytest.raises(mf.PointsOutsideMeshError, match=rf"^{2 * COMM.size} point\(s\)"):
        mf.evaluate_fe_function(u, pts)
    # and the function still works afterwards on every rank (no rank is left behind)
    ok = rank_rng.uniform(0.0, 2.0, (4, 2))
    np.testing.assert_allclose(mf.evaluate_fe_function(u, ok), ok, atol=1e-13)


@pytest.mark.parametrize(
    "bad, phrase",
    [
        (np.zeros((3, 4)), r"should have shape \(num_points, 2\), got \(3, 4\)"),
        (np.array([[0.5, np.nan]]), "NaN"),
    ],
)
def test_fe_points_bad_array_on_one_rank_raises_on_every_rank(square, bad, phrase):
    V, u = space(square)
    pts = bad if COMM.rank == LAST else np.array([[0.5, 0.5]])
    with pytest.raises(ValueError, match=phrase):
        mf.tabulate_fe_basis(V, pts)
    with pytest.raises(ValueError, match=phrase):
        mf.evaluate_fe_function(u, pts)


# --- collective: EFG solver ------------------------------------------------------------------


def test_efg_rejects_bad_options_on_every_rank():
    msh = beam_mesh(COMM, 3.0)
    particles = mf.ParticleSet.from_cells(msh, 3.0)
    mat = mf.LinearElastic(3e7, 0.3)
    with pytest.raises(ValueError, match=r"dilation=0.9 must be a number > 1"):
        mf.EFGElasticity(particles, mat, dilation=0.9)
    with pytest.raises(ValueError, match="weight='gauss'"):
        mf.EFGElasticity(particles, mat, weight="gauss")
    with pytest.raises(
        TypeError, match=r"material must be a LinearElastic, a finite-strain .*got dict"
    ):
        mf.EFGElasticity(particles, {"E": 3e7, "nu": 0.3})
    with pytest.raises(ValueError, match="quadrature_degree=0"):
        mf.EFGElasticity(particles, mat, quadrature_degree=0)
    no_mesh = mf.ParticleSet(particles.positions, comm=COMM)
    with pytest.raises(ValueError, match="needs particles with a background mesh"):
        mf.EFGElasticity(no_mesh, mat)


def test_efg_solve_with_uncovered_quadrature_points_raises_on_every_rank():
    """A hole in the particles inside one cell owned by rank 0: MLS fails at that cell's
    quadrature points on rank 0 only; every other rank must raise too instead of entering the
    assembly (which would hang)."""
    h = 3.0
    msh = beam_mesh(COMM, h)
    tdim = msh.topology.dim
    num_owned = msh.topology.index_map(tdim).size_local
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[:num_owned], :2]
    centroids = nodes.mean(axis=1)
    others = np.vstack([c for r, c in enumerate(COMM.allgather(centroids)) if r != 0] or [[]])
    others = others.reshape(-1, 2)
    if COMM.rank == 0:
        # an interior cell of rank 0, at least two cells away from any other rank's cells
        interior = (np.abs(centroids[:, 0] - BEAM_L / 2) < BEAM_L / 2 - 2 * h) & (
            np.abs(centroids[:, 1]) < h
        )
        far = np.array(
            [others.size == 0 or np.linalg.norm(others - c, axis=1).min() > 2.5 * h
             for c in centroids]
        )  # fmt: skip
        candidates = np.flatnonzero(interior & far)
        centre = centroids[candidates[0]] if candidates.size else None
    else:
        centre = None
    centre = COMM.bcast(centre, root=0)
    assert centre is not None, "no interior cell of rank 0 far from the other ranks' cells"
    spacing = 1.5
    xs = np.linspace(0.0, BEAM_L, round(BEAM_L / spacing) + 1)
    ys = np.linspace(-6.0, 6.0, round(12.0 / spacing) + 1)
    grid_pts = np.stack(np.meshgrid(xs, ys, indexing="xy"), axis=-1).reshape(-1, 2)
    keep = np.linalg.norm(grid_pts - centre, axis=1) > 3.0
    particles = mf.ParticleSet(grid_pts[keep], mesh=msh)
    beam = mf.TimoshenkoBeam(mf.LinearElastic(3e7, 0.3))
    left, right = beam_ends(msh)
    problem = mf.EFGElasticity(particles, beam.material, dilation=1.1)
    problem.add_dirichlet(left, beam.displacement)
    problem.add_traction(right, beam.traction)
    if COMM.rank == 0:
        with pytest.raises(mf.MomentMatrixError, match=r"increase dilation \(now 1.1\)"):
            problem.solve()
    else:
        with pytest.raises(ValueError, match=r"on rank 0: MomentMatrixError: .*increase dilation"):
            problem.solve()
    # with a dilation that bridges the hole the same problem solves
    problem = mf.EFGElasticity(particles, beam.material, dilation=3.0)
    problem.add_dirichlet(left, beam.displacement)
    problem.add_traction(right, beam.traction)
    sol = problem.solve()
    assert np.all(np.isfinite(sol.coefficients))


def test_user_functions_with_the_wrong_arguments_are_refused_by_name():
    """A traction of the points alone (the README's snippet does not show ``n``) raised
    Python's bare "takes 1 positional argument but 2 were given" from inside the assembly; a
    Dirichlet value of ``(x, n)`` likewise. Both are now refused where they are given (no
    collective call), by name, with the call they must accept and the fix; a builtin whose
    signature Python cannot read passes that check."""
    msh = beam_mesh(COMM, 3.0)
    left, right = beam_ends(msh)
    particles = mf.ParticleSet.from_cells(msh, 3.0)
    efg = mf.EFGElasticity(particles, mf.LinearElastic(3e7, 0.3))
    with pytest.raises(TypeError, match=r"traction is called with \(x, n\).*lambda x, n: \.\.\."):
        efg.add_traction(right, lambda x: np.zeros_like(x))
    with pytest.raises(TypeError, match=r"the Dirichlet value is called with \(x\) .*lambda x:"):
        efg.add_dirichlet(left, lambda x, n: np.zeros_like(x))
    with pytest.raises(TypeError, match=r"traction must be a callable of \(x, n\).*got 3.0"):
        efg.add_traction(right, 3.0)
    V = _compat.vector_function_space(msh)
    cells = np.arange(msh.topology.index_map(2).size_local, dtype=np.int32)[:4]
    coupled = mf.CoupledElasticity(V, mf.ParticlePatch(msh, cells, 1.5), mf.LinearElastic(3e7, 0.3))
    with pytest.raises(TypeError, match=r"traction is called with \(x, n\)"):
        coupled.add_traction(right, lambda x: np.zeros_like(x))
    dyn = mf.ExplicitDynamics.fe(V, mf.LinearElastic(3e7, 0.3, rho=2.5e-3))
    with pytest.raises(TypeError, match=r"traction is called with \(x, n\)"):
        dyn.add_traction(right, lambda x: np.zeros_like(x))
    check_arguments(np.zeros_like, 1, "the Dirichlet value")  # a builtin: not refused
    check_arguments(lambda x, n=None: x, 1, "the Dirichlet value")  # a default is fine


def test_facets_that_select_nothing_or_are_not_facets_are_refused_by_name():
    """A load or a condition on no facet acted nowhere, silently: a marker of a curved
    boundary tested at the straight facets' midpoints selected none, and the thick ring of
    ``tests/test_plastic_ring.py`` solved to zero displacements. Facets empty on every rank are
    refused, naming the call and the fix; facets on one rank only are fine; indices that are not
    facets of the mesh, on one rank only, are refused on every rank."""
    msh = beam_mesh(COMM, 3.0)
    _, right = beam_ends(msh)
    none = np.zeros(0, dtype=np.int32)
    mat = mf.LinearElastic(3e7, 0.3, rho=2.5e-3)
    efg = mf.EFGElasticity(mf.ParticleSet.from_cells(msh, 3.0), mat)
    V = _compat.vector_function_space(msh)
    cells = np.arange(msh.topology.index_map(2).size_local, dtype=np.int32)[:4]
    coupled = mf.CoupledElasticity(V, mf.ParticlePatch(msh, cells, 1.5), mat)
    dyn = mf.ExplicitDynamics.fe(V, mat)
    traction = lambda x, n: np.zeros_like(x)  # noqa: E731
    calls = [
        ("add_traction", efg.add_traction, traction),
        ("add_dirichlet", efg.add_dirichlet, np.zeros_like),
        ("add_traction", coupled.add_traction, traction),
        ("add_dirichlet", coupled.add_dirichlet, np.zeros_like),
        ("add_traction", dyn.add_traction, traction),
    ]
    for name, call, fn in calls:
        with pytest.raises(ValueError, match=rf"{name}: facets holds no facet on any rank.*atol"):
            call(none, fn)
        bad = np.array([10**7], dtype=np.int32) if COMM.rank == LAST else right
        with pytest.raises(ValueError, match=r"names facets that are not owned here"):
            call(bad, fn)
        with pytest.raises(ValueError, match=r"must be a 1D array of facet indices"):
            call(right.astype(float) + 0.5, fn)
    # facets on the last rank only: accepted
    coupled.add_traction(right if COMM.rank == LAST else none, traction)
    hybrid = mf.HybridElasticity(V, mf.ParticlePatch(msh, cells, 1.5), mat)
    with pytest.raises(ValueError, match=r"add_dirichlet: facets holds no facet on any rank"):
        hybrid.add_dirichlet(none, np.zeros_like)
    with pytest.raises(ValueError, match=r"fixed_facets holds no facet on any rank"):
        mf.ExplicitDynamics.fe(V, mat, fixed_facets=none)
    with pytest.raises(ValueError, match=r"fixed_facets holds no facet on any rank"):
        mf.ExplicitDynamics.fe(V, mat, fixed_facets=[(right, (0,)), (none, (1,))])


def _second_order_mesh():
    """Two 6-node triangles of the unit square, the mid-edge nodes of its right edge bowed
    out (a curved boundary, as gmsh writes second-order meshes); on rank 0."""
    x = np.array(
        [[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0], [1.1, 0.5], [0.5, 1], [0, 0.5], [0.5, 0.5]],
        dtype=float,
    )
    # DOLFINx's P2 triangle: the vertices, then the nodes on the edges opposite them
    cells = np.array([[0, 1, 2, 5, 8, 4], [0, 2, 3, 6, 7, 8]], dtype=np.int64)
    if COMM.rank:
        x, cells = x[:0], cells[:0]
    if _compat.MODERN:
        import basix.ufl
        import ufl

        domain = ufl.Mesh(basix.ufl.element("Lagrange", "triangle", 2, shape=(2,)))
        return dolfinx.mesh.create_mesh(COMM, cells, domain, x)
    import ufl

    domain = ufl.Mesh(ufl.VectorElement("Lagrange", "triangle", 2))
    return dolfinx.mesh.create_mesh(COMM, cells, x, domain)


def test_curved_cells_are_refused_by_name():
    """A mesh of second-order geometry (gmsh's curved cells) failed deep in the quadrature with
    numpy's "matmul: Input operand 1 has a mismatch in its core dimension"; FE values at points
    said the P1 space had "3 nodes per cell where the cell has 6 vertices". Now each entry point
    names the mesh's degree and the fix, on every rank."""
    msh = _second_order_mesh()
    assert _compat.coordinate_degree(msh) == 2
    fix = r"degree-2 coordinate element \(curved cells\).*first-order geometry"
    with pytest.raises(ValueError, match=r"ParticleSet: the mesh has a " + fix):
        mf.ParticleSet.from_cells(msh, 0.25)
    cells = np.arange(msh.topology.index_map(2).size_local, dtype=np.int32)
    with pytest.raises(ValueError, match=r"ParticlePatch: the mesh has a " + fix):
        mf.ParticlePatch(msh, cells, 0.25)
    V = _compat.vector_function_space(msh)
    with pytest.raises(ValueError, match=r"FE values at points: the mesh has a " + fix):
        mf.tabulate_fe_basis(V, np.array([[0.5, 0.5]]))
    # the curved boundary's facet is found by its vertices (x = 1), not its bowed midpoint
    right = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 1.0))
    assert COMM.allreduce(right.size) == 1
