"""Body loads for every coupling, in statics and in explicit dynamics.

Oracles:

* a quadratic displacement field with the constant body force that equilibrates it (plane
  stress, ``f = -div sigma(u)``), Dirichlet data from the exact field: every coupling against the
  plain DOLFINx solution on the same mesh (error ratio) and under refinement (fitted L2 rate), on
  an axis-aligned patch (quadrilaterals, triangles) and on a slanted band of cells;
* the shares of the load vectors computed independently: the blended functions of the ramp's
  interface cells (``int R``, Belytschko et al. 1995, eq. 3.13-3.15; the cubic ramp of Rabczuk
  et al. 2006, eq. 38-42) and the bridging weights ``alpha`` (eq. 49) from nodal layer values,
  and every coupling's total load against ``int f``;
* the UFL path (``CoupledLinearProblem``, DOLFINx assembly on the FE side) against the callable
  path (``CoupledElasticity.set_body_force``, Gauss quadrature on the FE side);
* the zero load ``inner(Constant((0, 0)), v) * dx`` leaves the linear patch test as it is;
* dynamics: a free body under a constant body force moves rigidly, ``u = b t^2 / (2 rho)``, to
  round-off (the loads use the functions and weights of the row-sum masses), and the total
  momentum of any body force grows as ``t int b`` exactly.
"""

from __future__ import annotations

import functools

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import ExplicitDynamics

import dolfinx
import numpy as np
import pytest
import ufl
from conftest import fitted_rate
from mpi4py import MPI

COMM = MPI.COMM_WORLD
MAT = mf.LinearElastic(1.0, 0.3, plane="stress")
COEFFS = (0.3, -0.2, 0.4, 0.25, 0.1, -0.35)

#: Options at which the couplings' own interface errors are O(h^2) without any body load
#: (measured with f = 0: edge-to-edge at default options 1.13-1.23x FE, bridging with point
#: constraints rate 1.5; issue 8, item 3 makes these the defaults).
OPTIONS = {"edge-to-edge": {"consistent": True}, "bridging": {"constraint": "integral"}}

#: Patches: an axis-aligned box and a slanted band of cells, inside the unit square.
SHAPES = {
    "box": lambda m: (np.abs(m[:, 0] - 0.5) < 0.25) & (np.abs(m[:, 1] - 0.5) < 0.25),
    "slant": lambda m: (
        (np.abs(m[:, 0] + 0.5 * m[:, 1] - 0.75) < 0.3) & (np.abs(m[:, 1] - 0.5) < 0.35)
    ),
}

#: (cell type, patch, refinements): n x n cells on the unit square, particle spacing 1/n.
CASES = {
    "quadrilateral-box": ("quadrilateral", "box", (8, 16, 32)),
    "quadrilateral-slant": ("quadrilateral", "slant", (12, 24, 48)),
    "triangle-box": ("triangle", "box", (8, 16, 32)),
}


class Quadratic:
    """``u = (a x^2 + b x y + c y^2, d x^2 + e x y + f y^2)`` and its equilibrating force."""

    def __init__(self, coeffs=COEFFS, material=MAT):
        self.c, self.material = coeffs, material

    def displacement(self, x):
        a, b, c, d, e, f = self.c
        X, Y = x[:, 0], x[:, 1]
        return np.stack([a * X**2 + b * X * Y + c * Y**2, d * X**2 + e * X * Y + f * Y**2], 1)

    def displacement_gradient(self, x):
        a, b, c, d, e, f = self.c
        X, Y = x[:, 0], x[:, 1]
        row0 = np.stack([2 * a * X + b * Y, b * X + 2 * c * Y], -1)
        row1 = np.stack([2 * d * X + e * Y, e * X + 2 * f * Y], -1)
        return np.stack([row0, row1], 1)

    def body_force(self) -> np.ndarray:
        """``-div sigma(u)`` (constant), plane stress."""
        a, b, c, d, e, f = self.c
        E, nu = self.material.E, self.material.nu
        C, G = E / (1 - nu**2), E / (2 * (1 + nu))
        return -np.array(
            [C * (2 * a + nu * e) + G * (2 * c + e), G * (b + 2 * d) + C * (2 * f + nu * b)]
        )


EXACT = Quadratic()


def cells_where(msh, predicate):
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    return np.flatnonzero(predicate(mid))


def model(n, cell, force=None, exact=EXACT):
    """Unit square, the elasticity form, ``L = f . v dx`` and the exact field on the boundary."""
    msh = dolfinx.mesh.create_unit_square(COMM, n, n, getattr(dolfinx.mesh.CellType, cell))
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(MAT.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    f = exact.body_force() if force is None else force
    L = ufl.inner(dolfinx.fem.Constant(msh, np.asarray(f, dtype=float)), v) * ufl.dx
    g = dolfinx.fem.Function(V)
    g.interpolate(lambda x: exact.displacement(x[:2].T).T)
    facets = mf.boundary_facets(msh)
    bcs = [dolfinx.fem.dirichletbc(g, dolfinx.fem.locate_dofs_topological(V, 1, facets))]
    return msh, V, a, L, bcs


def l2_error(msh, evaluate, exact=EXACT) -> float:
    return mf.error_norms(msh, evaluate, exact, MAT, degree=4)["l2"]


@functools.cache
def fe_errors(case: str) -> tuple[float, ...]:
    """Plain DOLFINx (LU) on the same meshes."""

    cell, _, ns = CASES[case]
    return tuple(plain_fe_error(*model(n, cell)) for n in ns)


def plain_fe_error(msh, V, a, L, bcs) -> float:
    """The L2 error of the model solved as written (DOLFINx assembly, LU)."""
    local = mf.solve_forms(a, L, bcs).u.x.array.reshape(-1, 2)

    def evaluate(q):
        t = mf.tabulate_in_cells(V, q.points, q.cells)
        return t.values @ local, t.gradient(local)

    return l2_error(msh, evaluate)


def coupled_errors(case: str, coupling: str) -> np.ndarray:
    cell, shape, ns = CASES[case]
    out = []
    for n in ns:
        msh, _, a, L, bcs = model(n, cell)
        patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES[shape]), 1.0 / n)
        options = OPTIONS.get(coupling, {})
        problem = mf.CoupledLinearProblem(
            a, L, bcs, patch, material=MAT, coupling=coupling, **options
        )
        out.append(l2_error(msh, problem.solve().evaluate_at_quadrature))
    return np.array(out)


# -- statics: the quadratic field with its body force ---------------------------------------------

#: Measured (serial and 2 ranks) error ratios to FE and fitted L2 rates (lagrange on the slanted
#: band: 1.34 1.21 1.09, rate 2.15, a strict xfail, while its multipliers were split at every
#: turn of the staircase interface; continuous trace multipliers since, see
#: tests/test_staircase_couplings.py):
#:
#: | case                | coupling      | ratio to FE       | rate  |
#: |---------------------|---------------|-------------------|-------|
#: | quadrilateral-box   | lagrange      | 0.91 0.91 0.91    | 2.00  |
#: |                     | edge-to-edge  | 0.93 0.91 0.91    | 2.03  |
#: |                     | ramp          | 0.81 0.86 0.88    | 1.93  |
#: |                     | ramp-cubic    | 0.82 0.86 0.88    | 1.95  |
#: |                     | bridging      | 0.96 0.94 0.92    | 2.03  |
#: | quadrilateral-slant | lagrange      | 0.86 0.86 0.84    | 2.02  |
#: |                     | edge-to-edge  | 0.91 0.93 0.93    | 1.98  |
#: |                     | ramp          | 0.79 0.81 0.81    | 1.98  |
#: |                     | ramp-cubic    | 0.78 0.81 0.81    | 1.97  |
#: |                     | bridging      | 0.92 0.90 0.88    | 2.04  |
#: | triangle-box        | lagrange      | 0.93 0.93 0.93    | 2.00  |
#: |                     | edge-to-edge  | 0.93 0.92 0.92    | 2.01  |
#: |                     | ramp          | 0.90 0.89 0.91    | 1.99  |
#: |                     | ramp-cubic    | 0.91 0.89 0.91    | 2.00  |
#: |                     | bridging      | 0.97 0.96 0.95    | 2.02  |
VARIATIONAL = ["lagrange", "edge-to-edge", "ramp", "ramp-cubic", "bridging"]


def _case_params():
    for case in CASES:
        for coupling in VARIATIONAL:
            yield pytest.param(case, coupling, id=f"{case}-{coupling}")


@pytest.mark.parametrize("case, coupling", list(_case_params()))
def test_quadratic_field_with_body_force(case, coupling):
    """Error <= 1.2 x the plain FE error at every level, fitted L2 rate in [1.8, 2.4] (measured
    1.93-2.04, table above; FE: 2.00)."""
    fe = np.array(fe_errors(case))
    errors = coupled_errors(case, coupling)
    ns = np.array(CASES[case][2], dtype=float)
    rate = fitted_rate(1.0 / ns, errors)
    assert 1.8 <= rate <= 2.4, (rate, errors)
    assert np.all(errors <= 1.2 * fe), errors / fe


@pytest.mark.parametrize("coupling", ["ramp", "ramp-cubic"])
def test_ramp_patch_reaching_the_dirichlet_boundary(coupling):
    """The patch x > 0.5 reaches the boundary, where a DirichletBC holds the exact field: the
    ramp's interface cells there constrain the particle part of their blended functions too.
    Error <= 1.2 x FE at n = 8 and 16 (measured 0.76 and 0.77; 2.48 and 2.76 when
    CoupledLinearProblem passed only the patch's own facets to the particles)."""
    for n in (8, 16):
        msh, V, a, L, bcs = model(n, "quadrilateral")
        fe = plain_fe_error(msh, V, a, L, bcs)
        patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 0.5), 1.0 / n)
        problem = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, coupling=coupling)
        ratio = l2_error(msh, problem.solve().evaluate_at_quadrature) / fe
        assert ratio <= 1.2, (n, ratio)


def test_master_slave_with_body_force_converges():
    """Master-slave is first order (its rigid slave layer; the body load is not the limit):
    fitted rate measured 0.78 (quadrilateral box; 0.87 on the slanted band), checked in
    [0.5, 2.2]; the error decreases at every refinement."""
    errors = coupled_errors("quadrilateral-box", "master-slave")
    rate = fitted_rate(1.0 / np.array(CASES["quadrilateral-box"][2], float), errors)
    assert 0.5 <= rate <= 2.2, (rate, errors)
    assert np.all(np.diff(errors) < 0.0), errors


# -- the shares of the load vectors ---------------------------------------------------------------


def _f(x):
    """A non-constant body force; its integral over the unit square is (1.5, 0.5)."""
    return np.stack([1.0 + x[:, 0], 2.0 * x[:, 0] * x[:, 1]], axis=1)


def _shares(problem):
    """(FE total, particle total) of a CoupledElasticity's body loads, summed over the ranks,
    through the coupling's own load function."""
    from dolfinx_meshfree.couplings import bridging, ramp
    from dolfinx_meshfree.couplings.assembly import body_loads
    from dolfinx_meshfree.geometry.quadrature import cell_quadrature

    coupling = problem.coupling
    if coupling in ("ramp", "ramp-cubic"):
        blend = ramp.RampInterface(problem, cubic=ramp.RAMPS[coupling])
        q = cell_quadrature(problem.V.mesh, problem.quadrature_degree, blend.cells)
        fe, fp = ramp._body_loads(problem, blend, q, blend.table(q.points, q.cells))
    elif coupling == "bridging":
        fe, fp = bridging._body_loads(problem, bridging.BridgingBand(problem, problem.overlap))
    else:
        fe, fp = body_loads(problem, problem.cell_indicator(~problem.patch.in_patch))
    return COMM.allreduce(fe.reshape(-1, 2).sum(axis=0)), COMM.allreduce(fp.reshape(-1, 2).sum(0))


@pytest.mark.parametrize("coupling", mf.COUPLINGS)
def test_loads_sum_to_the_integral_of_the_force(coupling):
    """FE + particle loads = int f over the square, to round-off (partition of unity of every
    coupling's functions and weights, eq. 3.17 and eq. 49)."""
    msh = dolfinx.mesh.create_unit_square(COMM, 8, 8, dolfinx.mesh.CellType.quadrilateral)
    V = _compat.vector_function_space(msh)
    patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES["box"]), 1.0 / 8)
    problem = mf.CoupledElasticity(V, patch, MAT, coupling=coupling)
    problem.set_body_force(_f)
    fe, fp = _shares(problem)
    assert np.allclose(fe + fp, [1.5, 0.5], rtol=0.0, atol=1e-13)


@pytest.mark.parametrize("coupling", mf.COUPLINGS)
def test_tagged_form_load_covers_its_cells_only(coupling):
    """L = f . v dx(FE_TAG) with the patch's cell tags: the loads sum to f times the area of the
    FE cells (the ramp's interface cells included, with their blended functions), nothing on
    the patch cells; the particles' share is the ramp's (:data:`RAMP_SHARES`) or zero."""
    n, h = 8, 1.0 / 8
    msh, V, a, _, bcs = model(n, "quadrilateral")
    patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES["box"]), h)
    f = np.array([0.7, -0.4])
    dx = ufl.Measure("dx", domain=msh, subdomain_data=patch.cell_tags)
    v = ufl.TestFunction(V)
    L = ufl.inner(dolfinx.fem.Constant(msh, f), v) * dx(mf.geometry.patch.FE_TAG)
    problem = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, coupling=coupling)
    fe, fp = _shares(problem.problem)
    assert np.allclose(fe + fp, 0.75 * f, rtol=1e-12, atol=0.0)  # the square minus the box
    particle = 0.0
    if coupling in RAMP_SHARES:  # 16 cells beside the box's edges, 4 at its corners
        on_edge, at_corner = RAMP_SHARES[coupling]
        particle = h * h * (16 * on_edge + 4 * at_corner)
    assert np.allclose(fp, particle * f, rtol=1e-12, atol=1e-15)


def _nodal_integral(msh, cells, nodal):
    """int over ``cells`` (owned, axis-aligned squares) of the Q1 interpolant of ``nodal(x)``:
    the cell area times the mean of the four vertex values (exact for bilinear functions)."""
    x = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :2]
    area = np.ptp(x[:, :, 0], axis=1) * np.ptp(x[:, :, 1], axis=1)
    return float(np.sum(area * nodal(x.reshape(-1, 2)).reshape(x.shape[:2]).mean(axis=1)))


#: int over a unit interface cell of R + (1 - R) R_1, the particles' share of the blended
#: functions: the ramp R (linear R_1 = sum of N_a over the interface nodes, eq. 3.13; cubic
#: 3 R_1^2 - 2 R_1^3) and the interface nodes' own (1 - R) N_a, which belong to the particles at
#: the nodes. Cells beside an edge of the box (R_1 = 1 - s) and at a corner (R_1 = s t):
#: linear 2/3 and 7/18; cubic 1/2 + 1/2 - 7/20 = 13/20 and 5/24 + 1/4 - 43/400 = 421/1200.
RAMP_SHARES = {"ramp": (2.0 / 3.0, 7.0 / 18.0), "ramp-cubic": (13.0 / 20.0, 421.0 / 1200.0)}


@pytest.mark.parametrize("coupling", ["ramp", "ramp-cubic", "bridging"])
def test_blended_and_weighted_shares(coupling):
    """A constant body force b: the particles' share is b times the patch area plus the
    particles' share of the ramp's interface cells (:data:`RAMP_SHARES`), or b times the
    integral over the patch of the bridging weight alpha (layer / overlap at the nodes,
    bilinear in the cells, eq. 49); the FE share is the rest, to round-off."""
    n, h = 8, 1.0 / 8
    msh = dolfinx.mesh.create_unit_square(COMM, n, n, dolfinx.mesh.CellType.quadrilateral)
    V = _compat.vector_function_space(msh)
    patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES["box"]), h)
    problem = mf.CoupledElasticity(V, patch, MAT, coupling=coupling)
    b = np.array([0.7, -0.4])
    problem.set_body_force(lambda x: np.tile(b, (len(x), 1)))
    fe, fp = _shares(problem)
    owned = np.arange(msh.topology.index_map(2).size_local)
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[owned], :2].mean(axis=1)
    # Chebyshev distance of the cell midpoints to the centre of the box [0.25, 0.75]^2
    cheb = np.abs(mid - 0.5).max(axis=1)
    patch_cells = owned[cheb < 0.25]
    if coupling == "bridging":

        def alpha(x):
            depth = (0.25 - np.abs(x - 0.5).max(axis=1)) / h  # node layer inside the box
            return np.clip(depth / 2.0, 0.0, 1.0)  # overlap = 2

        particle = _nodal_integral(msh, patch_cells, alpha)
    else:
        ring = owned[(cheb > 0.25) & (cheb < 0.25 + h)]
        edge = ring[np.abs(mid[ring] - 0.5).min(axis=1) < 0.25]
        corner = np.setdiff1d(ring, edge)
        on_edge, at_corner = RAMP_SHARES[coupling]
        particle = h * h * (patch_cells.size + on_edge * edge.size + at_corner * corner.size)
    particle = COMM.allreduce(particle)
    assert np.allclose(fp, particle * b, rtol=1e-12, atol=0.0)
    assert np.allclose(fe, (1.0 - particle) * b, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("coupling", mf.COUPLINGS)
def test_form_and_callable_agree(coupling):
    """L = f . v dx (DOLFINx on the FE side) and set_body_force (Gauss quadrature there) with the
    same exact boundary values: the same solution to round-off."""
    n = 8
    msh, V, a, L, bcs = model(n, "quadrilateral")
    patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES["box"]), 1.0 / n)
    options = OPTIONS.get(coupling, {})
    forms = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, coupling=coupling, **options)
    s1 = forms.solve()
    callables = mf.CoupledElasticity(V, patch, MAT, coupling=coupling, **options)
    callables.add_dirichlet(mf.boundary_facets(msh), EXACT.displacement)
    f = EXACT.body_force()
    callables.set_body_force(lambda x: np.tile(f, (len(x), 1)))
    s2 = callables.solve()
    pts = np.array([[0.1, 0.2], [0.5, 0.5], [0.3, 0.7], [0.74, 0.26], [0.9, 0.95]])
    u1, u2 = s1.displacement(pts), s2.displacement(pts)
    assert np.abs(u1 - u2).max() <= 1e-10 * np.abs(u2).max()


# -- bad input ------------------------------------------------------------------------------------


def test_body_force_bad_input():
    """A body force that is not callable, or returns the wrong shape: errors naming it, on
    every rank (the shape error is raised by a collective evaluation)."""
    msh = dolfinx.mesh.create_unit_square(COMM, 8, 8, dolfinx.mesh.CellType.quadrilateral)
    V = _compat.vector_function_space(msh)
    patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES["box"]), 1.0 / 8)
    problem = mf.CoupledElasticity(V, patch, MAT, coupling="ramp")
    with pytest.raises(TypeError, match=r"body force must be a callable b\(x\)"):
        problem.set_body_force(np.array([0.0, -1.0]))
    problem.add_dirichlet(mf.boundary_facets(msh), EXACT.displacement)
    problem.set_body_force(lambda x: np.zeros(len(x)))
    with pytest.raises(ValueError, match=r"the body force must return an array of shape"):
        problem.solve()
    dyn = _dynamics("fe")
    with pytest.raises(ValueError, match=r"must return an array of shape"):
        dyn.add_body_force(lambda x: np.zeros((len(x), 3)))


# -- the zero load and the linear patch test ------------------------------------------------------


class Linear:
    """``u = 1e-3 + G x``: no body force equilibrates it but zero."""

    grad = np.array([[2e-3, -1e-3], [3e-3, 1e-3]])

    def displacement(self, x):
        return 1e-3 + x @ self.grad.T


#: Options with which each coupling passes the linear patch test exactly (consistent
#: integration; bridging with the integral constraint); master-slave passes it to its rigid
#: layer's level.
PATCH_OPTIONS = {
    "lagrange": {"consistent": True},
    "edge-to-edge": {"consistent": True},
    "ramp": {"consistent": True},
    "ramp-cubic": {"consistent": True},
    "bridging": {"consistent": True, "constraint": "integral"},
    "master-slave": {},
}

#: The patch-test level (relative max error) of each coupling here, with or without the zero
#: load: 1e-10 with consistent integration; bridging measured 2.1e-4 (the box's corners: there
#: grad alpha leaves the multipliers' space), master-slave 2.1e-2 (its rigid slave layer).
PATCH_LEVEL = {
    "lagrange": 1e-10,
    "edge-to-edge": 1e-10,
    "ramp": 1e-10,
    "ramp-cubic": 1e-10,
    "bridging": 5e-4,
    "master-slave": 5e-2,
}


@pytest.mark.parametrize("coupling", mf.COUPLINGS)
def test_zero_body_load_keeps_the_patch_test(coupling):
    """``inner(Constant((0, 0)), v) * dx`` (the usual DOLFINx idiom) is accepted by every
    coupling and changes nothing: the same solution as a zero ``ds`` term, to round-off, and
    the linear field to the coupling's patch-test level (1e-10 with consistent integration)."""
    linear = Linear()
    n = 8
    msh, _, a, L, bcs = model(n, "quadrilateral", force=np.zeros(2), exact=linear)
    v = L.arguments()[0]
    L_ds = ufl.inner(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.ds
    patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES["box"]), 1.0 / n)
    options = PATCH_OPTIONS[coupling]
    pts = np.stack(np.meshgrid(np.linspace(0, 1, 9), np.linspace(0, 1, 9)), -1).reshape(-1, 2)
    u = []
    for form in (L, L_ds):
        problem = mf.CoupledLinearProblem(
            a, form, bcs, patch, material=MAT, coupling=coupling, **options
        )
        u.append(problem.solve().displacement(pts))
    scale = np.abs(linear.displacement(pts)).max()
    assert np.abs(u[0] - u[1]).max() <= 1e-13 * scale
    assert np.abs(u[0] - linear.displacement(pts)).max() <= PATCH_LEVEL[coupling] * scale


# -- dynamics -------------------------------------------------------------------------------------

STEEL = mf.LinearElastic(200.0, 0.25, "strain", rho=2.0)
#: Every model of ExplicitDynamics; "-sp": the particles integrated at the particles and
#: stress points (Rabczuk, Belytschko & Xiao 2004) instead of the cells' Gauss rule.
DYNAMIC = ["fe", "efg", "efg-sp", *mf.COUPLINGS, "lagrange-sp", "master-slave-sp", "hybrid"]
#: master-slave with the paper's slave band (links of nonzero length): see _rigid_params
BAND = "master-slave-band"


def _dynamics(method: str) -> ExplicitDynamics:
    """A free 2 x 1 body, 8 x 4 quadrilaterals, particles (spacing h) on x > 1."""
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.array([2.0, 1.0])], [8, 4], dolfinx.mesh.CellType.quadrilateral
    )
    V = _compat.vector_function_space(msh)
    stress_points = method.endswith("-sp")
    method = method.removesuffix("-sp")
    integration = {"integration": "stress-points"} if stress_points else {}
    if method == BAND:
        method, integration = "master-slave", {"slaves": "band"}
    if method == "fe":
        return ExplicitDynamics.fe(V, STEEL)
    if method == "efg":
        return ExplicitDynamics.efg(mf.ParticleSet.from_cells(msh, 0.125), STEEL, **integration)
    patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 1.0), 0.25)
    if method == "hybrid":
        return ExplicitDynamics.coupled(mf.HybridElasticity(V, patch, STEEL))
    options = {"overlap": 1} if method == "bridging" else {}
    return ExplicitDynamics.coupled(
        mf.CoupledElasticity(V, patch, STEEL, coupling=method, **options), **integration
    )


def _momentum(dyn: ExplicitDynamics) -> np.ndarray:
    local = sum(
        (f.mass.array_r * v.array_r).reshape(-1, 2).sum(axis=0)
        for f, v in zip(dyn.fields, dyn._current(), strict=True)
    )
    return COMM.allreduce(local)


def _rigid_params():
    for method in [*DYNAMIC, BAND]:
        marks = ()
        if method == BAND:
            # the loads T^T f are the consistent ones (the momentum below is exact), but the
            # lumped masses are row sums of T^T M T over both components, which rigid links of
            # nonzero length (eq. 27) couple: M_red b / rho != T^T f. The default first layer
            # sits on the interface here (links of length 0) and moves rigidly to round-off.
            marks = pytest.mark.xfail(
                strict=True, reason="master-slave band: lumped masses 8 % off the rigid motion"
            )
        yield pytest.param(method, marks=marks)


@pytest.mark.parametrize("method", list(_rigid_params()))
def test_free_body_under_gravity_moves_rigidly(method):
    """Constant b on a free body: the exact solution is the rigid motion u = b t^2 / (2 rho) with
    zero stress. The consistent loads use the functions and weights of the row-sum masses
    (blended on the ramp's interface cells, alpha-weighted in the bridging band, reduced by T^T
    for master-slave; hybrid: the lumped load M b / rho), so f = M b / rho and central
    differences reproduce it to round-off; the momentum is t int b."""
    dyn = _dynamics(method)
    b = np.array([0.3, -0.7])
    dyn.add_body_force(lambda x: np.tile(b, (len(x), 1)))
    result = dyn.run(20 * dyn.stable_time_step())
    t = result.time
    pts = np.array([[0.1, 0.1], [0.9, 0.6], [1.05, 0.5], [1.6, 0.9], [1.95, 0.05]])
    u = dyn.displacement_at(pts)
    exact = 0.5 * b / STEEL.rho * t**2
    assert np.abs(u - exact).max() <= 1e-10 * np.abs(exact).max()
    assert np.allclose(_momentum(dyn), 2.0 * b * t, rtol=1e-10, atol=0.0)


@pytest.mark.parametrize("method", [m for m in DYNAMIC if m != "hybrid"])
def test_momentum_of_a_varying_body_force(method):
    """b(x) = (1 + x, 2 x y): the body deforms, but the stiffness and the constraints exchange
    no momentum, so the total momentum is t int b = t (4, 2) exactly (the loads integrate b with
    functions that sum to one: not the lumped M b(x_I) / rho)."""
    dyn = _dynamics(method)
    dyn.add_body_force(_f)
    result = dyn.run(20 * dyn.stable_time_step())
    assert np.allclose(_momentum(dyn), np.array([4.0, 2.0]) * result.time, rtol=1e-10, atol=0.0)


# -- hybrid SPH-FE ---------------------------------------------------------------------------------


@pytest.mark.parametrize("variant", mf.HYBRID_VARIANTS)
def test_hybrid_loads_sum_to_the_integral_of_the_force(variant):
    """HybridElasticity.set_body_force: FE loads (N_a on the FE cells) + particle loads (the
    particles' corrected SPH interpolant on the patch cells, which reproduces constants) =
    int f over the square, to round-off."""
    msh = dolfinx.mesh.create_unit_square(COMM, 8, 8, dolfinx.mesh.CellType.quadrilateral)
    V = _compat.vector_function_space(msh)
    patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES["box"]), 1.0 / 8)
    problem = mf.HybridElasticity(V, patch, MAT, variant=variant)
    problem.set_body_force(_f)
    b_fe, b_p = problem._loads()
    total = COMM.allreduce(b_fe.array.reshape(-1, 2).sum(axis=0)) + COMM.allreduce(
        b_p.array.reshape(-1, 2).sum(axis=0)
    )
    assert np.allclose(total, [1.5, 0.5], rtol=0.0, atol=1e-13), total


@pytest.mark.parametrize("variant", mf.HYBRID_VARIANTS)
def test_hybrid_with_body_force_converges(variant):
    """The quadratic field with its equilibrating body force through HybridElasticity: fitted
    L2 rate over n = 8, 16, 32 measured 1.90 (HA-S) and 2.42 (HA-F), checked in [1.0, 2.8];
    errors at n = 32 7.5e-2 (HA-S: 150x plain FE's 5.0e-4, which its interface tractions leave
    far above FE with or without a body load) and 1.5e-3 (HA-F, 3.1x FE), checked <= 2x."""
    errors = []
    for n in (8, 16, 32):
        msh, V, _, _, _ = model(n, "quadrilateral")
        patch = mf.ParticlePatch(msh, cells_where(msh, SHAPES["box"]), 1.0 / n)
        problem = mf.HybridElasticity(V, patch, MAT, variant=variant)
        problem.add_dirichlet(mf.boundary_facets(msh), EXACT.displacement)
        b = EXACT.body_force()
        problem.set_body_force(lambda x, b=b: np.tile(b, (x.shape[0], 1)))
        errors.append(l2_error(msh, problem.solve().evaluate_at_quadrature))
    rate = fitted_rate(1.0 / np.array([8.0, 16.0, 32.0]), np.array(errors))
    assert 1.0 <= rate <= 2.8, (rate, errors)
    assert errors[-1] <= 2 * {"HA-S": 7.5e-2, "HA-F": 1.5e-3}[variant], errors
