"""Master–slave FE–EFG coupling (Rabczuk, Xiao & Sauer 2006, sec. 5.1.2, eq. 17–28):
``coupling="master-slave"``.

Oracles: the slave constraint itself, recomputed here from the solved FE field (the interfaces
are vertical lines, so the closest point and the edge rotation have closed forms); the first
layer, recomputed by sampling the interface densely (the nearest particle of each sample);
rigid-body motion (reproduced exactly); the linear patch test (not passed: measured); the
Timoshenko solution and a quadratic field with a constant body load on slanted, curved and gmsh
patches (rates, against plain FE on the same mesh); the same problem solved on COMM_SELF.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.couplings.master_slave import solve_master_slave

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from test_coupled import beam_mesh, cells_right_of, square
from test_problem import cells_where, plain_dolfinx

RIGID = mf.LinearField(G=((0.0, -2e-3), (2e-3, 0.0)), c=(0.1, -0.4))
LINEAR = mf.LinearField(G=((0.3, -0.2), (0.5, 0.1)), c=(0.1, -0.4))


def patch_problem(comm, field, spacing, cell="quadrilateral"):
    """2 x 2 square, 6 x 6 cells (h = 1/3), particles on x > 1, ``u = field`` on the boundary."""
    msh = square(comm, cell)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 1.0), spacing)
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1000, 0.3), coupling="master-slave")
    problem.add_dirichlet(mf.boundary_facets(msh), field.displacement)
    return msh, problem


def max_error(msh, sol, field):
    q = mf.cell_quadrature(msh, 7)
    u, _ = sol.evaluate_at_quadrature(q)
    err = np.abs(u - field.displacement(q.points)).max(initial=0.0)
    return MPI.COMM_WORLD.allreduce(err, op=MPI.MAX)


@pytest.mark.parametrize("tie", ["values", "coefficients"])
@pytest.mark.parametrize("spacing", [0.25, 1 / 6])
def test_slave_constraint_holds(spacing, tie):
    """u_P = u_C + theta x (P - C) for every slave, from the solved FE field: the interface is
    x = 1, so C = (1, y_P) and theta = -(u_x(b) - u_x(a)) / |b - a| on the edge [a, b] through
    C (the mean of the two edges when C is a node). Spacing 0.25 puts particles both at the
    nodes' heights (k/3) and between them. ``slaves="band"`` (the particles within 1.01 s of
    Gamma_I: here the interface column and the next one), so that links of nonzero length are
    checked; the default first layer is the interface column alone. ``tie="values"`` (the
    default) holds the MLS value ``u^h(x_P)`` there, ``tie="coefficients"`` the nodal
    parameter ``u_P``."""
    _, problem = patch_problem(MPI.COMM_WORLD, LINEAR, spacing)
    sol = solve_master_slave(problem, slaves="band", tie=tie)
    x = problem.patch.particles.positions
    slaves = sol.links.slaves
    assert np.array_equal(slaves, np.flatnonzero(x[:, 0] <= 1.0 + 1.01 * spacing + 1e-12))
    assert np.array_equal(problem.solve().links.slaves, np.flatnonzero(np.isclose(x[:, 0], 1.0)))
    assert np.any(np.isclose(x[slaves, 0], 1.0)) and np.any(x[slaves, 0] > 1.0 + 1e-12)
    h = 1 / 3
    y = x[slaves, 1]
    k = np.floor(y / h + 1e-9)
    at_node = np.abs(y - np.rint(y / h) * h) <= 1e-9
    # the edges [a, b] through C: one, or the two beside a node
    lower = np.where(at_node, np.rint(y / h) - 1, k)
    upper = np.where(at_node, np.rint(y / h), k)
    thetas = []
    for j in (lower, upper):
        j = np.clip(j, 0, 5)
        a = np.column_stack([np.ones_like(y), j * h])
        b = np.column_stack([np.ones_like(y), (j + 1) * h])
        ua = mf.evaluate_fe_function(sol.u, a)
        ub = mf.evaluate_fe_function(sol.u, b)
        thetas.append(-(ub[:, 0] - ua[:, 0]) / h)
    valid_lower = (~at_node | (np.rint(y / h) > 0)).astype(float)
    valid_upper = (~at_node | (np.rint(y / h) < 6)).astype(float)
    theta = (thetas[0] * valid_lower + thetas[1] * valid_upper) / (valid_lower + valid_upper)
    c = np.column_stack([np.ones_like(y), y])
    u_c = mf.evaluate_fe_function(sol.u, c)
    r = x[slaves] - c
    expected = u_c + theta[:, None] * np.column_stack([-r[:, 1], r[:, 0]])
    scale = np.abs(expected).max()
    tied = sol.coefficients[slaves]
    if tie == "values":
        tied = sol.mls.tabulate(x[slaves], 0).values @ sol.coefficients
        # the field is not its nodal parameters: the two ties differ
        assert np.abs(sol.coefficients[slaves] - expected).max() > 1e-4 * scale
    assert np.abs(tied - expected).max() <= 1e-12 * scale


@pytest.mark.parametrize("slaves", ["layer", "band"])
@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
@pytest.mark.parametrize("spacing", [1 / 3, 0.25])
def test_rigid_body_motion_is_reproduced(cell, spacing, slaves):
    """A rigid translation and a small rotation on the whole boundary: the links are rigid, so
    the motion is reproduced to round-off (measured 3e-14)."""
    msh, problem = patch_problem(MPI.COMM_WORLD, RIGID, spacing, cell)
    assert max_error(msh, solve_master_slave(problem, slaves=slaves), RIGID) <= 1e-10


@pytest.mark.parametrize(
    ("slaves", "tie", "measured"),
    [
        ("layer", "values", (1.12e-2, 1.54e-3, 4.51e-4)),
        ("layer", "coefficients", (2.07e-2, 3.59e-3, 5.85e-4)),
        ("band", "coefficients", (7.36e-2, 2.77e-2, 1.31e-2)),
    ],
)
def test_linear_patch_test_is_not_passed(slaves, tie, measured):
    """Master–slave is exempt from the linear patch test: the slaves match the FE trace at
    their points only (values, the default tie of the layer: the particles on Gamma_I here),
    and with the paper's coefficient tie the particle's *parameter*, not the MLS field; a
    slave off the interface (the band) moves with its edge's rotation, not with the field's
    strain. Maximum error at Gauss points, |G| ~ 0.5, spacing 1/3, 1/6, 1/12 (h = 1/3 on the
    FE side; the default rules of degree 7, 15, 31): each within [0.5, 2] x the measured value
    (VCI does not remove it: 1.12e-2, 1.53e-3, 4.55e-4 with the layer's value tie; on 4 x 4
    points the value tie's errors were 1.12e-2, 1.86e-3, 2.43e-3). Dirichlet facets of the
    patch inside the slave layer carry no multiplier (the slaves follow the strongly fixed FE
    boundary): with them, at spacing 1/3, the constraints over-determined the slaves and the
    error was 55 (1.9e2 for u = (x, y))."""
    errs = [max_error(*_solved(s, slaves, tie), LINEAR) for s in (1 / 3, 1 / 6, 1 / 12)]
    for e, m in zip(errs, measured, strict=True):
        assert 0.5 * m < e < 2.0 * m, (errs, measured)


def _solved(spacing, slaves="layer", tie=None):
    msh, problem = patch_problem(MPI.COMM_WORLD, LINEAR, spacing)
    return msh, solve_master_slave(problem, slaves=slaves, tie=tie)


def solve_beam(comm, h, slaves="layer"):
    mat = mf.LinearElastic(3e7, 0.3)
    beam = mf.TimoshenkoBeam(mat)
    msh = beam_mesh(comm, h)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 24.0), h)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh), patch, mat, coupling="master-slave"
    )
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0)), beam.displacement)
    problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48)), beam.traction)
    sol = solve_master_slave(problem, slaves=slaves)
    return sol, mf.error_norms(msh, sol.evaluate_at_quadrature, beam, mat)


@pytest.mark.parametrize(
    ("slaves", "rates", "first"),
    # measured: layer 2.60e-2, 6.60e-3, 2.95e-3, fitted rate 1.98 (coefficient ties: 2.19e-2,
    # 5.07e-3, 2.18e-3, 2.10); band 4.51e-2, 1.76e-2, 1.07e-2, fitted 1.31 (the paper:
    # 1.23/1.23/1.13, Table II)
    [("layer", (1.8, 2.4), 0.03), ("band", (1.1, 1.6), 0.06)],
)
def test_cantilever_rate(slaves, rates, first):
    """Timoshenko cantilever, patch x > 24, spacing h (pure Q1: 2.81e-2, 7.21e-3, 3.22e-3).

    ``"band"`` (the particles within 1.01 s of Gamma_I: the interface column and the next one)
    moves a layer of width s = h rigidly with the interface edges, which drops the field's
    strain across it: an O(h) kinematic error, first-order convergence, the paper's figure.
    The default layer is the interface column alone (links of length zero), its MLS values
    tied to the FE nodes: the error is 0.92x pure Q1's and converges at second order on this
    aligned grid."""
    hs = [3.0, 1.5, 1.0]
    errs = [solve_beam(MPI.COMM_WORLD, h, slaves)[1]["l2"] for h in hs]
    assert errs[0] > errs[1] > errs[2]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert rates[0] <= slope <= rates[1]
    assert errs[0] < first


def test_parallel_equals_serial(rank_rng):
    pts = rank_rng.uniform([0.5, -5.5], [47.5, 5.5], (20, 2))
    # and points in the slave layer (24 < x < 25.5)
    pts = np.vstack([pts, rank_rng.uniform([24.1, -5.9], [25.4, 5.9], (10, 2))])
    world, _ = solve_beam(MPI.COMM_WORLD, 1.5)
    alone, _ = solve_beam(MPI.COMM_SELF, 1.5)
    a = world.displacement(pts)
    b = alone.displacement(pts)
    assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
    assert np.array_equal(world.links.slaves, alone.links.slaves)


def test_fieldsplit_equals_mumps():
    """The reduced system with patch-side Dirichlet multipliers through the Schur fieldsplit."""
    _, problem = patch_problem(MPI.COMM_WORLD, LINEAR, 1 / 6)
    a = problem.solve("fieldsplit").coefficients
    b = problem.solve("mumps").coefficients
    assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()


# -- the first layer and convergence on slanted, curved and unstructured patches ----------------

MESHES = __import__("pathlib").Path(__file__).resolve().parent.parent / "meshes"
PLANE_STRESS = mf.LinearElastic(1000.0, 0.3, plane="stress")
#: u_i = Q[i] . (x^2, x y, y^2) + G[i] . (x, y): div sigma is constant (a constant body load)
Q = np.array([[0.3, -0.2, 0.25], [0.15, 0.35, -0.3]])
G = np.array([[0.1, 0.2], [-0.1, 0.05]])


class Quadratic:
    """The quadratic field above, for :func:`dolfinx_meshfree.error_norms` and as UFL."""

    def displacement(self, x):
        return np.stack([x[:, 0] ** 2, x[:, 0] * x[:, 1], x[:, 1] ** 2], 1) @ Q.T + x @ G.T

    def displacement_gradient(self, x):
        X, Y, Z = x[:, 0], x[:, 1], np.zeros(len(x))
        dm = np.stack([np.stack([2 * X, Z], 1), np.stack([Y, X], 1), np.stack([Z, 2 * Y], 1)], 1)
        return np.einsum("ik,qkj->qij", Q, dm) + G[None]

    def ufl(self, x):
        m = (x[0] ** 2, x[0] * x[1], x[1] ** 2)
        return ufl.as_vector(
            [
                sum(Q[i, k] * m[k] for k in range(3)) + G[i, 0] * x[0] + G[i, 1] * x[1]
                for i in (0, 1)
            ]
        )


QUADRATIC = Quadratic()


def mesh_of(kind, n, comm=MPI.COMM_WORLD):
    """Unit square with n x n cells, or the gmsh bushing annulus 1 <= r <= 2 of size n."""
    if kind != "gmsh":
        return dolfinx.mesh.create_unit_square(comm, n, n, getattr(dolfinx.mesh.CellType, kind))
    path = MESHES / f"bushing_triangle_h{n:g}.xdmf"
    with dolfinx.io.XDMFFile(
        comm, str(path), "r", encoding=dolfinx.io.XDMFFile.Encoding.ASCII
    ) as f:
        return f.read_mesh(name="mesh")


#: Patches by cell centroid: above a slanted line, in a disk (unit square: around the corner
#: (1, 1); bushing: the inner ring r < 1.4, a curved interface of the gmsh geometry).
PATCHES = {
    "slanted": lambda m: m[:, 1] > 0.4 * m[:, 0] + 0.2,
    "curved": lambda m: np.hypot(m[:, 0] - 1.0, m[:, 1] - 1.0) < 0.6,
    "ring": lambda m: np.hypot(m[:, 0], m[:, 1]) < 1.4,
}


def quadratic_model(msh):
    """Plane stress, u = QUADRATIC on the whole boundary, its constant body load -div sigma."""
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    f = -ufl.div(PLANE_STRESS.ufl_stress(QUADRATIC.ufl(ufl.SpatialCoordinate(msh))))
    a = ufl.inner(PLANE_STRESS.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    msh.topology.create_connectivity(1, 2)
    g = dolfinx.fem.Function(V)
    g.interpolate(lambda x: QUADRATIC.displacement(x[:2].T).T)
    dofs = dolfinx.fem.locate_dofs_topological(
        V, 1, dolfinx.mesh.exterior_facet_indices(msh.topology)
    )
    return V, a, ufl.dot(f, v) * ufl.dx, [dolfinx.fem.dirichletbc(g, dofs)]


def coupled_and_fe_errors(kind, patch, n, spacing, slaves="layer", placement="conforming"):
    """Relative L2 errors of master-slave and of plain FE on the same mesh."""
    msh = mesh_of(kind, n)
    V, a, L, bcs = quadratic_model(msh)
    uh = plain_dolfinx(V, a, L, bcs).x.array.reshape(-1, 2)

    def fe(q):
        t = mf.tabulate_in_cells(V, q.points, q.cells)
        return t.values @ uh, t.gradient(uh)

    cells = cells_where(msh, PATCHES[patch])
    if spacing == "vertices":
        p = mf.ParticlePatch(msh, cells, placement="vertices")
    else:
        p = mf.ParticlePatch(msh, cells, spacing / n, placement=placement)
    problem = mf.CoupledLinearProblem(a, L, bcs, p, PLANE_STRESS, coupling="master-slave")
    sol = solve_master_slave(problem.problem, slaves=slaves)
    return (
        mf.error_norms(msh, sol.evaluate_at_quadrature, QUADRATIC, PLANE_STRESS)["l2"],
        mf.error_norms(msh, fe, QUADRATIC, PLANE_STRESS)["l2"],
    )


def test_first_layer_is_the_nearest_particles_of_the_interface():
    """The first-layer slaves are the particles nearest to some stretch of Gamma_I (exact lower
    envelope of the distance along each edge), checked by sampling every interface edge at 400
    points: each sample's nearest particle is a slave, and every slave is the nearest particle
    of some sample. A slanted staircase interface and a plain grid (``placement="grid"``,
    spacing 0.75 h) that does not meet it, so the links have lengths between 0 and about one
    spacing."""
    msh = mesh_of("quadrilateral", 12)
    _, a, L, bcs = quadratic_model(msh)
    cells = cells_where(msh, PATCHES["slanted"])
    patch = mf.ParticlePatch(msh, cells, 0.75 / 12, placement="grid")
    problem = mf.CoupledLinearProblem(a, L, bcs, patch, PLANE_STRESS, coupling="master-slave")
    with pytest.raises(ValueError, match=r"carry no particle, first \["):
        problem.solve()  # refused by default: a layer off the interface
    problem.model.slaves = "first-layer"  # the paper's layer
    links = problem.solve().links
    x = patch.particles.positions
    tau = (np.arange(400) + 0.5) / 400
    samples = (links.edges[:, :1] + tau[None, :, None] * np.diff(links.edges, axis=1)).reshape(
        -1, 2
    )
    d = np.linalg.norm(samples[:, None, :] - x[None], axis=2)
    order = np.sort(d, axis=1)
    clear = order[:, 1] - order[:, 0] > 1e-9  # no tie between two particles
    nearest = np.unique(np.argmin(d, axis=1)[clear])
    assert np.array_equal(nearest, links.slaves)
    assert 0.0 < links.distance[links.slaves].max() < 1.2 * 0.75 / 12


@pytest.mark.parametrize(
    ("kind", "patch", "spacing", "sizes", "rates", "ratio"),
    [
        # measured (layer on Gamma_I, value ties): steps 2.00, 1.97, fitted 1.99; ratio to FE
        # 0.75, 0.75, 0.76 (coefficient ties: fitted 1.86, ratios 0.81-0.98)
        ("quadrilateral", "slanted", 0.5, (8, 16, 32), (1.7, 2.3), 1.5),
        # measured 1.37, 1.96, fitted 1.66; ratios 1.66, 2.57, 2.64 (coefficient ties: fitted
        # 1.50, ratios 4.1-8.3)
        ("triangle", "curved", "vertices", (8, 16, 32), (1.3, 2.3), 5.5),
        # gmsh bushing, inner ring: measured 1.99, 1.95, fitted 1.97; ratios 1.30, 1.29, 1.28
        # (coefficient ties: fitted 1.55, ratios 2.3-4.1)
        ("gmsh", "ring", "vertices", (0.2, 0.1, 0.05), (1.7, 2.3), 2.6),
    ],
)
def test_rate_on_slanted_and_curved_patches(kind, patch, spacing, sizes, rates, ratio):
    """Quadratic field with a constant body load (on FE cells and particles, the slaves' share
    reaching their masters through T^T, eq. 28), plane stress, exact values on the boundary:
    L2 rate two-sided about the measured one (the issue's target is 1.0: first order is the
    method's nature, the slaves matching the FE trace at points) and the error ratio to plain
    FE on the same mesh below about 2x the measured value. The ratio may grow
    at most like 1/h (a first-order method against FE's second order): ratio x h does not grow.
    The 1.01 s band of the paper (``slaves="band"``) measured rates 0.46-1.0 on the gmsh ring
    and ratios growing to 13-26 (see the module docstring of master_slave)."""
    e, f = np.array([coupled_and_fe_errors(kind, patch, n, spacing) for n in sizes]).T
    hs = np.array([1.0 / n for n in sizes]) if kind != "gmsh" else np.array(sizes)
    slope = np.polyfit(np.log(hs), np.log(e), 1)[0]
    assert rates[0] <= slope <= rates[1]
    assert np.all(e / f <= ratio)
    scaled = e / f * hs
    assert np.all(scaled[1:] <= scaled[:-1] * 1.05)


@pytest.mark.xfail(
    strict=True,
    reason="issue 8 item 5 target (rate >= 1.0 at every refinement) not met with grid particles "
    "off Gamma_I: measured L2 errors 8.40e-3, 4.27e-3, 2.35e-3 (n = 16, 32, 64), steps 0.98 and "
    "0.86, fitted 0.92 (n = 128: 1.02e-3, step 1.20, fitted over 16-128: 1.01); with particles "
    "on the patch border (a boundary-conforming placement) 1.36 and 1.45",
)
def test_rate_with_grid_particles_off_the_interface():
    """Slanted staircase interface on quadrilaterals, a plain grid (``placement="grid"``) of
    spacing 0.75 h, which puts no particle on Gamma_I: the first layer lies 0-0.7 h off it
    (mean 0.26 h at every size), each slave rigidly linked over that distance. The error is
    first order with a constant that changes with the way the grid meets the staircase at each
    size (steps 0.98, 0.86, 1.20 up to n = 128), so three sizes can fit below 1. It is the
    placement, not the links: the default placement gives 1.40 and 1.32 (next test)."""
    e, _ = np.array(
        [
            coupled_and_fe_errors(
                "quadrilateral", "slanted", n, 0.75, "first-layer", placement="grid"
            )
            for n in (16, 32, 64)
        ]
    ).T
    slope = np.polyfit(np.log([1 / 16, 1 / 32, 1 / 64]), np.log(e), 1)[0]
    assert 1.0 <= slope <= 2.5


def test_rate_with_the_default_placement_off_the_grid():
    """The same slanted patch and spacing at the default placement (``"conforming"``: particles
    on the patch border's vertices and edges, so the first layer sits on Gamma_I with links of
    length 0): every refinement step converges at rate >= 1.0 (two-sided: <= 2.5); measured
    errors 2.65e-3, 1.00e-3, 4.01e-4 (2.1-5.2x plain FE), steps 1.40 and 1.32."""
    e, f = np.array(
        [coupled_and_fe_errors("quadrilateral", "slanted", n, 0.75) for n in (16, 32, 64)]
    ).T
    steps = np.log(e[:-1] / e[1:]) / np.log(2.0)
    assert np.all((1.0 <= steps) & (steps <= 2.5)), (steps, e, e / f)


@pytest.mark.parametrize("particle_values", ["nodal", "collocation"])
def test_dynamics_initial_linear_field_on_every_particle(particle_values):
    """Explicit dynamics with the master–slave reduction (default layer, value ties):
    ``set_initial`` of a linear field keeps the masters' coefficients through the selection
    composed on ``S`` (with value ties the slaves' rows of ``S`` are ``-Phi_SS^{-1} Phi_SM``,
    so ``S^T`` is not the restriction), and the expansion ``u_P = T_PF u_FE + S u_M`` gives
    every particle, slaves included, the field's value: MLS reproduces a linear field with
    its values as coefficients, so the value tie holds exactly. Measured 5e-16 and 1.3e-15
    relative; with ``S^T`` instead of the selection, 1.9e-2."""
    msh = square(MPI.COMM_WORLD, "quadrilateral")
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 1.0), 1 / 6)
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1000, 0.3), coupling="master-slave")
    dyn = mf.ExplicitDynamics.coupled(problem)
    dyn.set_initial(displacement=LINEAR.displacement, particle_values=particle_values)
    _, coeffs = dyn._local_values(dyn.u)
    exact = LINEAR.displacement(patch.particles.positions)
    assert np.abs(coeffs - exact).max() <= 1e-12 * np.abs(exact).max()
    dyn.destroy()


def test_layer_off_the_interface_is_refused_and_why():
    """Why ``slaves="layer"`` refuses a first layer off Gamma_I: on a disc patch of triangles
    with a grid of spacing 1.5 h (no particle on the interface), the paper's layer
    (``"first-layer"``) misses a linear field held on the whole boundary by 16.8 % at n = 16
    (13.6 and 17.7 % at n = 8 and 32: no convergence), where the default placement, with
    particles on Gamma_I, misses by 1.2 % (checked within 2x of each)."""
    from test_problem import boundary_bc

    n = 16
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.array([2.0, 2.0])], [n, n], dolfinx.mesh.CellType.triangle
    )
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    law = mf.LinearElastic(3e7, 0.3, plane="strain")
    a = ufl.inner(law.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    L = ufl.dot(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.dx
    G = np.array([[2e-3, 5e-4], [5e-4, -1e-3]])
    bcs = [boundary_bc(V, mf.boundary_facets(msh), lambda x: x @ G.T)]
    cells = cells_where(msh, lambda m: np.hypot(m[:, 0] - 1.0, m[:, 1] - 1.0) < 0.6)
    grid = np.stack(np.meshgrid(np.linspace(0, 2, 17), np.linspace(0, 2, 17)), -1).reshape(-1, 2)
    errors = {}
    for placement in ("grid", "conforming"):
        patch = mf.ParticlePatch(msh, cells, 3.0 / n, placement=placement)
        problem = mf.CoupledLinearProblem(a, L, bcs, patch, law, coupling="master-slave")
        if placement == "grid":
            with pytest.raises(ValueError, match="not reliably convergent"):
                problem.solve()
            problem.model.slaves = "first-layer"
            # the choice goes with the model onto a rebuilt patch (crack growth, adapt)
            assert problem.with_patch(patch).model.slaves == "first-layer"
        sol = problem.solve()
        errors[placement] = np.abs(sol.displacement(grid) - grid @ G.T).max() / np.abs(G).max()
    assert 0.084 <= errors["grid"] <= 0.34, errors
    assert errors["conforming"] <= 0.024, errors


def test_dynamics_takes_the_models_slaves():
    """``ExplicitDynamics.coupled`` reads ``model.slaves``: a grid patch (no particle on the
    interface) is refused by default, in dynamics as in statics, and runs once the model takes
    ``"first-layer"`` (before, dynamics refused it whatever the model said)."""
    n = 8
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.array([2.0, 2.0])], [n, n], dolfinx.mesh.CellType.triangle
    )
    V = _compat.vector_function_space(msh)
    cells = cells_where(msh, lambda m: np.hypot(m[:, 0] - 1.0, m[:, 1] - 1.0) < 0.6)
    patch = mf.ParticlePatch(msh, cells, 3.0 / n, placement="grid")
    law = mf.LinearElastic(1000, 0.3, rho=1.0)
    problem = mf.CoupledElasticity(V, patch, law, coupling="master-slave")
    with pytest.raises(ValueError, match="first-layer"):
        mf.ExplicitDynamics.coupled(problem)
    problem.slaves = "first-layer"
    dyn = mf.ExplicitDynamics.coupled(problem)
    # a rigid translation is carried exactly by the links (first-layer or not)
    dyn.set_initial(displacement=lambda x: np.tile([1e-3, -2e-3], (len(x), 1)))
    dyn.run(5 * dyn.stable_time_step())
    pts = patch.particles.positions
    assert np.abs(dyn.displacement_at(pts) - [1e-3, -2e-3]).max() <= 1e-12
    dyn.destroy()
