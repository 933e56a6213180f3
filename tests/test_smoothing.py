"""Smoothed (symmetric, consistent) particle integration (issue 26, item 1).

:mod:`dolfinx_meshfree.geometry.smoothing`: strains smoothed over each integration cell by the
divergence theorem (Chen et al. 2001; Liu, Dai & Nguyen-Thoi 2007) and stabilised by the Gauss
points' strains (Puso et al. 2008, eq. 36). The checks are exact properties (the divergence
identity, symmetry, the linear patch test in statics and dynamics, serial = 2 ranks) and
analytic solutions (the Timoshenko cantilever), each against a case that shows it can fail.
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.geometry.smoothing import smoothed_table, smoothing_rule, stiffness_rows
from dolfinx_meshfree.physics.operators import stiffness_matrix

import dolfinx
import numpy as np
import pytest
from conftest import CELL_TYPES, beam_mesh, fitted_rate, rectangle
from mpi4py import MPI
from test_efg_3d import MATERIAL as MATERIAL3
from test_efg_3d import G as G3
from test_efg_3d import affine, particles_for, unit_cube

FIELD = mf.LinearField(G=((1.0, 0.2), (-0.3, 0.5)), c=(0.1, -0.2))
MATERIAL = mf.LinearElastic(1000.0, 0.3)


def _owned(msh):
    return np.arange(msh.topology.index_map(msh.topology.dim).size_local)


# --- the rule -------------------------------------------------------------------------------


@pytest.mark.parametrize("beta", [1.0, 0.0])
@pytest.mark.parametrize("cell", ["quadrilateral", "triangle", "hexahedron", "tetrahedron"])
def test_smoothed_gradients_of_linear_functions_are_exact(cell, beta):
    """The divergence theorem on each smoothing domain: the smoothed gradient of ``x_i`` is
    ``e_i`` and the domains' volumes add up to the cells' (distorted cells; measured 1e-15).
    With one domain's boundary left open the identity fails: the check can fail."""
    if cell in ("hexahedron", "tetrahedron"):
        msh = unit_cube(MPI.COMM_WORLD, 2, cell, perturbed=True)
    else:
        msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, 1.0], [4, 3], CELL_TYPES[cell])
        x = msh.geometry.x
        inner = (x[:, 0] > 1e-9) & (x[:, 0] < 2 - 1e-9) & (x[:, 1] > 1e-9) & (x[:, 1] < 1 - 1e-9)
        x[inner, :2] += 0.08 * np.sin(7.1 * x[inner, :2] + 1.3)  # distorted, still convex
    gdim = msh.geometry.dim
    cells = _owned(msh)
    rule = smoothing_rule(msh, cells, 4, beta)
    whole = mf.cell_quadrature(msh, 2, cells).weights.sum()
    assert abs(rule.weights.sum() - whole) <= 1e-13 * whole
    xb = rule.boundary_points
    grads = np.stack([B @ xb for B in rule.boundary], axis=1)  # (nk, gdim, gdim): d x_i / d x_j
    assert np.abs(grads - np.eye(gdim)[None]).max() <= 1e-12
    # a facet's points left out (one smoothing domain open): no longer exact
    cut = rule.boundary[0].copy()
    cut.data[cut.indptr[0] : cut.indptr[1]] = 0.0
    assert abs((cut @ xb)[0, 0] - 1.0) > 1e-3


def test_a_cell_not_star_shaped_from_its_centre_is_refused():
    """A quadrilateral folded beyond its centre has a sub-cell of negative volume: refused,
    naming the cell by its vertices' coordinates."""
    msh = rectangle(MPI.COMM_SELF, [0.0, 0.0], [1.0, 1.0], [1, 1], CELL_TYPES["quadrilateral"])
    x = msh.geometry.x
    corner = np.flatnonzero(np.all(np.isclose(x[:, :2], [1.0, 1.0]), axis=1))
    x[corner, :2] = [0.3, 0.35]  # a dart: concave at this vertex, beyond the vertex mean
    with pytest.raises(ValueError, match=r"not star-shaped.*vertices"):
        smoothing_rule(msh, _owned(msh), 4, 0.0)


# --- statics --------------------------------------------------------------------------------


def _patch_solve(cell, jitter, integration):
    msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, 2.0], [6, 6], CELL_TYPES[cell])
    particles = mf.ParticleSet.from_cells(msh, 2.0 / 6, jitter=jitter)
    problem = mf.EFGElasticity(particles, MATERIAL, integration=integration)
    problem.add_dirichlet(mf.boundary_facets(msh), FIELD.displacement)
    return problem.solve()


@pytest.mark.parametrize("integration", ["smoothed", "smoothed-subcells"])
@pytest.mark.parametrize("jitter", [0.0, 0.3])
@pytest.mark.parametrize("cell", sorted(CELL_TYPES))
def test_patch_test_2d(cell, jitter, integration):
    """Measured 1e-15 (displacement) and 4e-14 (gradient); plain Gauss misses by 1e-4
    (tests/test_patch.py)."""
    sol = _patch_solve(cell, jitter, integration)
    x = np.random.default_rng(1).uniform(0.0, 2.0, (300, 2))
    u, grad = sol.evaluate(x)
    assert np.abs(u - FIELD.displacement(x)).max() <= 1e-10
    assert np.abs(grad - np.asarray(FIELD.G)).max() <= 1e-9


@pytest.mark.parametrize("traction", [False, True])
@pytest.mark.parametrize("cell, perturbed", [("hexahedron", True), ("tetrahedron", False)])
def test_patch_test_3d(cell, perturbed, traction):
    """Particles at h / 2 (8 per hexahedron): without the stabilisation the regular grid had 57
    zero-energy modes past the rigid ones (6 smoothed strains per sub-cell); with it, 1e-15
    (measured 2e-15 displacement, 1e-13 gradient), tractions on two faces included."""
    msh = unit_cube(MPI.COMM_WORLD, 3, cell, perturbed)
    problem = mf.EFGElasticity(particles_for(msh, 3, "half", perturbed), MATERIAL3,
                               integration="smoothed")  # fmt: skip
    sigma = MATERIAL3.stress(G3[None])[0]
    facets = mf.boundary_facets(msh)
    if traction:
        loaded = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 1.0) | np.isclose(x[2], 1.0))
        facets = np.setdiff1d(facets, loaded)
        problem.add_traction(loaded, lambda x, n: n @ sigma.T)
    problem.add_dirichlet(facets, affine)
    sol = problem.solve()
    x = np.random.default_rng(1).uniform(0.0, 1.0, (200, 3))
    u, grad = sol.evaluate(x)
    assert np.abs(u - affine(x)).max() <= 1e-10
    assert np.abs(grad - G3).max() <= 1e-9


def test_stiffness_is_symmetric_and_factorised_by_ldlt():
    """``K`` symmetric to round-off (measured 1e-16 relative) where VCI's is not (1e-2), so the
    default ``solver="mumps"`` factorises the saddle point by LDL^T."""
    msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, 1.0], [8, 4], CELL_TYPES["quadrilateral"])
    particles = mf.ParticleSet.from_cells(msh, 0.25, jitter=0.2)
    mls = mf.MLS(particles)
    rule = smoothing_rule(msh, _owned(msh), 7)
    rows, weights = stiffness_rows(mls, rule, smoothed_table(mls, rule))
    K = stiffness_matrix(rows, weights, MATERIAL)
    assert abs(K - K.T).max() <= 1e-14 * abs(K).max()
    factorisations = {}
    for integration in ("smoothed", "vci"):
        problem = mf.EFGElasticity(particles, MATERIAL, integration=integration)
        problem.add_dirichlet(mf.boundary_facets(msh), FIELD.displacement)
        system, objects, _ = problem.system()
        system.solve("mumps")
        factorisations[integration] = system.stats["factorisation"]
        for obj in (system, *objects):
            obj.destroy()
    assert factorisations == {"smoothed": "ldlt", "vci": "lu"}


def _cantilever(h, integration, comm=MPI.COMM_WORLD):
    beam = mf.TimoshenkoBeam(mf.LinearElastic(3e7, 0.3))
    msh = beam_mesh(comm, h)
    problem = mf.EFGElasticity(mf.ParticleSet.from_cells(msh, h), beam.material,
                               integration=integration)  # fmt: skip
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0)),
                          beam.displacement)  # fmt: skip
    problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48.0)), beam.traction)
    sol = problem.solve()
    return msh, sol, mf.error_norms(msh, lambda q: sol.evaluate(q.points), beam, beam.material)


def test_cantilever_accuracy_against_vci():
    """The Timoshenko cantilever (analytic): relative L2 errors at h = 2, 1, 0.5, measured
    5.72e-4, 8.56e-5, 1.47e-5 (VCI 5.42e-4, 8.08e-5, 1.54e-5; 0.95-1.06x), L2 rate 2.64 (VCI
    2.56), energy errors within 0.1 % of VCI's. Checked: each L2 error within 1.25x VCI's and
    below 2x the measured figure, the rate in [2.2, 3.2], the energy within 1 %. The plain
    sub-cell variant is far less accurate (measured 29x VCI at h = 1, constant strains per
    sub-cell): it stays an option, not a default."""
    hs = [2.0, 1.0, 0.5]
    measured = [5.72e-4, 8.56e-5, 1.47e-5]
    errors = {"smoothed": [], "vci": []}
    for h in hs:
        for integration in errors:
            errors[integration].append(_cantilever(h, integration)[2])
    for k in range(len(hs)):
        s, v = errors["smoothed"][k], errors["vci"][k]
        assert s["l2"] <= 1.25 * v["l2"], (hs[k], s["l2"], v["l2"])
        assert s["l2"] <= 2.0 * measured[k]
        assert abs(s["energy"] / v["energy"] - 1.0) <= 0.01
    rate = fitted_rate(hs, [e["l2"] for e in errors["smoothed"]])
    assert 2.2 <= rate <= 3.2, rate
    plain = _cantilever(1.0, "smoothed-subcells")[2]["l2"]
    assert plain >= 10.0 * errors["vci"][1]["l2"]  # measured 29x


def test_two_ranks_equal_serial():
    """The smoothed EFG cantilever on every rank of COMM_WORLD against each rank alone."""
    comm = MPI.COMM_WORLD
    x = np.random.default_rng(5).uniform([0.5, -5.5], [47.5, 5.5], (50, 2))
    u = [_cantilever(2.0, "smoothed", c)[1].displacement(x) for c in (comm, MPI.COMM_SELF)]
    assert np.abs(u[0] - u[1]).max() <= 1e-12 * np.abs(u[1]).max()


# --- dynamics -------------------------------------------------------------------------------


@pytest.mark.parametrize("cell", sorted(CELL_TYPES))
def test_dynamic_patch_test_is_exact(cell):
    """A body in a uniform stress (``sigma n`` on its whole boundary) moving at a uniform
    velocity stays on the linear field: after 1,000 central-difference steps measured 3.6e-11
    (quadrilaterals) and 3.9e-11 (triangles) relative, round-off growing with the steps, checked
    at the issue's 1e-10; with Gauss points 2.9e-5 and 2.3e-5 after only 100 steps, checked in
    [1e-5, 6e-5]. Energy drift measured 7e-12 (the tractions' work included), checked 1.5e-11."""
    G = np.array([[1.0, 0.2], [-0.3, 0.5]]) * 1e-3
    velocity = np.array([0.01, -0.02])
    material = mf.LinearElastic(1000.0, 0.3, rho=1.0)
    sigma = material.stress(G[None])[0]
    errors = {}
    for integration, steps in (("smoothed", 1000), ("cells", 100)):
        msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, 1.0], [8, 4], CELL_TYPES[cell])
        particles = mf.ParticleSet.from_cells(msh, 0.25, jitter=0.2)
        dyn = mf.ExplicitDynamics.efg(particles, material, integration=integration)
        dyn.add_traction(mf.boundary_facets(msh), lambda x, n: n @ sigma.T)
        dyn.set_initial(displacement=lambda x: x @ G.T,
                        velocity=lambda x: np.tile(velocity, (len(x), 1)))  # fmt: skip
        t_end = steps * dyn.stable_time_step()
        result = dyn.run(t_end)
        x = np.random.default_rng(0).uniform([0.0, 0.0], [2.0, 1.0], (100, 2))
        exact = x @ G.T + t_end * velocity
        errors[integration] = np.abs(dyn.displacement_at(x) - exact).max() / np.abs(exact).max()
        if integration == "smoothed":
            assert result.energy_drift <= 1.5e-11
        dyn.destroy()
    assert errors["smoothed"] <= 1e-10
    assert 1e-5 <= errors["cells"] <= 6e-5  # the Gauss points miss: the check can fail


# --- couplings and refusals -----------------------------------------------------------------


def _square_with_patch(cell: str, inside):
    """[0, 2]^2 in 6 x 6 cells, the patch the cells whose centroids satisfy ``inside``."""
    msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, 2.0], [6, 6], CELL_TYPES[cell])
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(inside(xc)), 1 / 3)
    return msh, patch, _compat.vector_function_space(msh)


def _field_error(sol, field) -> float:
    x = np.random.default_rng(2).uniform(0.0, 2.0, (200, 2))
    err = np.abs(sol.displacement(x) - field.displacement(x)).max()
    return MPI.COMM_WORLD.allreduce(err, op=MPI.MAX)


@pytest.mark.parametrize("coupling", ["lagrange", "master-slave"])
def test_couplings_take_the_smoothed_integration(coupling):
    """Lagrange on a straight interface passes the linear patch test to round-off (measured
    2e-15; Gauss 6e-5); master-slave is first order by its links but keeps the rigid motion."""
    msh, patch, V = _square_with_patch("quadrilateral", lambda xc: xc[:, 0] > 1.0)
    field = FIELD if coupling == "lagrange" else mf.LinearField(G=((0.0, -0.2), (0.2, 0.0)))
    problem = mf.CoupledElasticity(V, patch, MATERIAL, coupling=coupling, integration="smoothed")
    problem.add_dirichlet(mf.boundary_facets(msh), field.displacement)
    assert _field_error(problem.solve(), field) <= 1e-10


def test_lagrange_on_a_turning_interface_is_refused_unless_split():
    """A patch in the middle of the square: the interface turns at its corners, where the
    continuous multipliers pass ``sigma Pi n``; refused, naming the point and the fixes. With
    ``corner_angle`` the multipliers are split there and the patch test passes (measured 8e-14
    in lane A; lane B's MUMPS calls this saddle point structurally singular in LDL^T, the
    solve falls back to LU: 3e-13; 9e-4 on a staircase before the refusal)."""
    msh, patch, V = _square_with_patch("triangle", lambda xc: np.all(np.abs(xc - 1.0) < 0.5, 1))
    problem = mf.CoupledElasticity(V, patch, MATERIAL, integration="smoothed")
    problem.add_dirichlet(mf.boundary_facets(msh), FIELD.displacement)
    with pytest.raises(ValueError, match=r"interface turns \(near \[.*corner_angle=30"):
        problem.solve()
    problem = mf.CoupledElasticity(V, patch, MATERIAL, integration="smoothed", corner_angle=30.0)
    problem.add_dirichlet(mf.boundary_facets(msh), FIELD.displacement)
    assert _field_error(problem.solve(), FIELD) <= 1e-10


def test_bad_options_are_refused():
    comm = MPI.COMM_WORLD
    msh = rectangle(comm, [0.0, 0.0], [2.0, 2.0], [4, 4], CELL_TYPES["quadrilateral"])
    particles = mf.ParticleSet.from_cells(msh, 0.5)
    with pytest.raises(ValueError, match=r"integration='simpson': choose one of 'vci'"):
        mf.EFGElasticity(particles, MATERIAL, integration="simpson")
    with pytest.raises(ValueError, match=r"consistent=False contradicts integration='smoothed'"):
        mf.EFGElasticity(particles, MATERIAL, consistent=False, integration="smoothed")
    crack = mf.Crack([[0.0, 1.0], [0.9, 1.0]])
    with pytest.raises(ValueError, match=r"does not integrate cut cells yet"):
        mf.EFGElasticity(particles, MATERIAL, integration="smoothed", cracks=[crack])
    hyper = mf.NeoHookean(1000.0, 0.3)
    problem = mf.EFGElasticity(particles, hyper, integration="smoothed")
    problem.add_dirichlet(mf.boundary_facets(msh), FIELD.displacement)
    with pytest.raises(ValueError, match=r"stabilised by a linear elastic term"):
        problem.solve()
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 1.0), 0.5)
    V = _compat.vector_function_space(msh)
    for coupling in ("edge-to-edge", "bridging", "ramp"):
        with pytest.raises(ValueError, match=rf"coupling='{coupling}': the smoothing does not"):
            mf.CoupledElasticity(V, patch, MATERIAL, coupling=coupling, integration="smoothed")
    with pytest.raises(ValueError, match=r"small-strain"):
        mf.ExplicitDynamics.efg(particles, mf.NeoHookean(1000.0, 0.3, rho=1.0),
                                integration="smoothed")  # fmt: skip


def test_user_model_from_the_readme():
    """A user's own model, written as the README shows it: ``CoupledLinearProblem`` with
    ``integration="smoothed"`` on a plate whose right half is particles, against the same
    model on plain FE (the FE solution is exact for the affine field: both to round-off)."""
    import ufl

    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_rectangle(comm, [np.zeros(2), np.array([2.0, 1.0])], [8, 4],
                                        dolfinx.mesh.CellType.quadrilateral)  # fmt: skip
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(MATERIAL.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    L = ufl.inner(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.dx
    g = dolfinx.fem.Function(V)
    g.interpolate(lambda x: FIELD.displacement(x[:2].T).T)
    facets = mf.boundary_facets(msh)
    bc = dolfinx.fem.dirichletbc(g, dolfinx.fem.locate_dofs_topological(V, 1, facets))
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 1.0), 0.25)
    problem = mf.CoupledLinearProblem(a, L, [bc], patch, material=MATERIAL,
                                      integration="smoothed")  # fmt: skip
    sol = problem.solve()
    x = np.random.default_rng(4).uniform([0.0, 0.0], [2.0, 1.0], (100, 2))
    err = comm.allreduce(np.abs(sol.displacement(x) - FIELD.displacement(x)).max(), op=MPI.MAX)
    assert err <= 1e-10


def test_finite_strain_with_smoothed_subcells():
    """The plain variant integrates point by point (one smoothed ``F`` per sub-cell), so
    Newton's internal force carries it: a homogeneous deformation of a Neo-Hookean plate is
    reproduced (measured 1e-16; the stabilised variant is refused at finite strain)."""
    F = np.array([[1.1, 0.05], [-0.04, 0.95]])
    msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, 2.0], [6, 6], CELL_TYPES["quadrilateral"])
    particles = mf.ParticleSet.from_cells(msh, 1 / 3, jitter=0.2)
    problem = mf.EFGElasticity(particles, mf.NeoHookean(1000.0, 0.3),
                               integration="smoothed-subcells")  # fmt: skip
    problem.add_dirichlet(mf.boundary_facets(msh), lambda x: x @ (F - np.eye(2)).T)
    sol = problem.solve(load_steps=2)
    x = np.random.default_rng(1).uniform(0.0, 2.0, (100, 2))
    assert np.abs(sol.displacement(x) - x @ (F - np.eye(2)).T).max() <= 1e-10


def test_lagrange_in_dynamics():
    """The smoothed Lagrange coupling in explicit dynamics: energy conserved (drift measured
    4e-13) and the uniform-stress motion of the dynamic patch test kept to 4.4e-6 after 300
    steps (VCI 1.2e-5): not round-off, because the multipliers act on the velocities (Rabczuk
    et al. 2006, Table I), whose projection in the lumped-mass metric does not reproduce the
    static interface force. Checked at 2x."""
    G = np.array([[1.0, 0.2], [-0.3, 0.5]]) * 1e-3
    velocity = np.array([0.01, -0.02])
    material = mf.LinearElastic(1000.0, 0.3, rho=1.0)
    sigma = material.stress(G[None])[0]
    msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, 1.0], [8, 4], CELL_TYPES["quadrilateral"])
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 1.0), 0.25)
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, material, integration="smoothed")
    dyn = mf.ExplicitDynamics.coupled(problem)
    dyn.add_traction(mf.boundary_facets(msh), lambda x, n: n @ sigma.T)
    dyn.set_initial(displacement=lambda x: x @ G.T,
                    velocity=lambda x: np.tile(velocity, (len(x), 1)))  # fmt: skip
    t_end = 300 * dyn.stable_time_step()
    result = dyn.run(t_end)
    x = np.random.default_rng(0).uniform([0.0, 0.0], [2.0, 1.0], (100, 2))
    exact = x @ G.T + t_end * velocity
    err = np.abs(dyn.displacement_at(x) - exact).max() / np.abs(exact).max()
    assert err <= 9e-6
    assert result.energy_drift <= 1e-11
    dyn.destroy()


# --- the large solve: Nitsche and CG --------------------------------------------------------


@pytest.mark.parametrize("chunk", [40, 1 << 30])
def test_large_solve_patch_test_with_cg(chunk):
    """``mf.solve_large`` with the smoothed integration: chunks of whole cells (40 points: 2
    cells of 16 Gauss points), Nitsche's condition on one side, the constant stress as traction
    on the others, CG + GAMG (symmetric): the linear field to the solver's tolerance (measured
    1.1e-11 at rtol 1e-12, 35 iterations; checked 1e-9), and MUMPS on the same matrix to
    round-off (3e-15). Plain Gauss points miss the same field by 8.5e-3."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([0.0, 0.0]), np.array([4.0, 3.0])], [4, 3],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    material = mf.LinearElastic(200.0, 0.25, "stress")
    grad = np.array([[1e-3, 2e-3], [-5e-4, 3e-3]])
    sigma = material.stress(grad[None])[0]
    problem = mf.EFGElasticity(mf.ParticleSet.from_cells(msh, 0.5, jitter=0.2), material,
                               integration="smoothed")  # fmt: skip
    exact = lambda x: x[:, :2] @ grad.T  # noqa: E731
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0)), exact)
    rest = mf.boundary_facets(msh, lambda x: ~np.isclose(x[0], 0.0))
    problem.add_traction(rest, lambda x, n: n[:, :2] @ sigma.T)
    pts = np.random.default_rng(6).uniform([0.0, 0.0], [4.0, 3.0], (50, 2))
    scale = np.abs(exact(pts)).max()
    for direct, tol in ((True, 1e-10), (False, 1e-9)):
        options = mf.IterativeOptions(direct=direct, rtol=1e-12, chunk_points=chunk)
        sol = mf.solve_large(problem, options)
        assert np.abs(sol.displacement(pts) - exact(pts)).max() <= tol * scale
        assert (sol.timings["iterations"] > 0) != direct


@pytest.mark.parametrize("cell", ["hexahedron", "tetrahedron"])
def test_lagrange_3d(cell):
    """A planar interface (the half x > 1/2 of the cube): the 3D patch test to round-off
    (measured 1.4e-15 and 2.4e-15); the perturbed cube's interface is not planar, so its
    continuous multipliers are refused with the 3D fix (no corner_angle in 3D)."""
    from test_couplings_3d import coupled, half_patch, impose_affine

    msh = unit_cube(MPI.COMM_WORLD, 4, cell)
    patch = half_patch(msh, 4)
    problem = coupled(msh, patch, "lagrange", integration="smoothed")
    impose_affine(msh, patch, problem, fe_side=False)
    u, _ = problem.solve().evaluate_at_quadrature(mf.cell_quadrature(msh, 2))
    points = mf.cell_quadrature(msh, 2).points
    err = msh.comm.allreduce(np.abs(u - affine(points)).max(initial=0.0), op=MPI.MAX)
    assert err <= 1e-10
    if cell == "hexahedron":
        msh = unit_cube(MPI.COMM_WORLD, 4, cell, perturbed=True)
        patch = half_patch(msh, 4, jitter=0.3)
        problem = coupled(msh, patch, "lagrange", integration="smoothed")
        impose_affine(msh, patch, problem, fe_side=True)
        with pytest.raises(ValueError, match=r"interface turns .*3D interface that is not planar"):
            problem.solve()


def _fine_particles_errors(integration: str, degree: int | None = None) -> list[float]:
    """L2 errors of the EFG cantilever at h = 2 and 1 with particles at h / 2 (four per
    cell), on the default rule (8 x 8 Gauss points per cell) or ``degree``'s."""
    errors = []
    for h in (2.0, 1.0):
        beam = mf.TimoshenkoBeam(mf.LinearElastic(3e7, 0.3))
        msh = beam_mesh(MPI.COMM_WORLD, h)
        problem = mf.EFGElasticity(mf.ParticleSet.from_cells(msh, h / 2), beam.material,
                                   integration=integration, quadrature_degree=degree)  # fmt: skip
        problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0)),
                              beam.displacement)  # fmt: skip
        problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48.0)),
                             beam.traction)  # fmt: skip
        sol = problem.solve()
        errors.append(mf.error_norms(msh, lambda q, s=sol: s.evaluate(q.points), beam,
                                     beam.material)["l2"])  # fmt: skip
    return errors


def test_smoothed_converges_with_particles_finer_than_the_cells():
    """Particles at h / 2: the smoothed integration keeps its rate (measured 7.71e-4, 1.01e-4:
    rate 2.94; 1.41e-5 at h = 0.5), checked in [2.4, 3.5] with the h = 1 error below 2x the
    measured one."""
    e = _fine_particles_errors("smoothed")
    rate = np.log2(e[0] / e[1])
    assert 2.4 <= rate <= 3.5, rate
    assert e[1] <= 2.0 * 1.01e-4


def test_vci_converges_with_particles_finer_than_the_cells():
    """Particles at h / 2 on the default rule, 4 Gauss points per particle spacing (8 x 8 per
    cell, :func:`~dolfinx_meshfree.geometry.quadrature.particle_quadrature_degree`): VCI
    converges (measured 7.78e-4, 1.01e-4: rate 2.94; 1.33e-5 at h = 0.5), checked in [2.4, 3.5]
    with the h = 1 error below 2x the measured one. On the 4 x 4 points that were the default
    it stalls (6.69e-4, 3.18e-4, 2.05e-4: rates 1.07, 0.63; its error grows along the beam from
    the free edges): checked below 1.8, so that this test fails if the default loses the
    points."""
    e = _fine_particles_errors("vci")
    rate = np.log2(e[0] / e[1])
    assert 2.4 <= rate <= 3.5, rate
    assert e[1] <= 2.0 * 1.01e-4
    coarse = _fine_particles_errors("vci", degree=7)
    assert np.log2(coarse[0] / coarse[1]) <= 1.8
