"""CoupledLinearProblem: a particle patch in a model written as UFL forms and DirichletBCs.

Oracles: the same cantilever through CoupledElasticity's callables (an independent load and
boundary path), exact linear patch tests with constrained patch facets and with FacetNormal
tractions on patch facets (consistent integration), partition of unity for body loads (the
particle loads sum to the integral of the body force), and the errors raised for bad input.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.couplings.assembly import body_loads

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

COMM = MPI.COMM_WORLD
MAT = mf.LinearElastic(3e7, 0.3, plane="stress")


def rectangle(p1, n, cell="quadrilateral"):
    return dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.asarray(p1, dtype=float)], n, getattr(dolfinx.mesh.CellType, cell)
    )


def cells_where(msh, predicate):
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    return np.flatnonzero(predicate(mid))


def elasticity(V, material=MAT):
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    return ufl.inner(material.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx, v


def boundary_bc(V, facets, fn):
    g = dolfinx.fem.Function(V)
    g.interpolate(lambda x: fn(x[:2].T).T)
    return dolfinx.fem.dirichletbc(g, dolfinx.fem.locate_dofs_topological(V, 1, facets))


# -- the cantilever through two paths ----------------------------------------------------------


@pytest.mark.parametrize("coupling", mf.COUPLINGS)
def test_forms_match_callables_on_the_cantilever(coupling):
    """UFL traction (ds with tags) and a DirichletBC give the solution of the callable API."""
    beam = mf.TimoshenkoBeam(MAT)
    msh = dolfinx.mesh.create_rectangle(
        COMM,
        [np.array([0.0, -6.0]), np.array([48.0, 6.0])],
        [16, 4],
        dolfinx.mesh.CellType.quadrilateral,
    )
    V = _compat.vector_function_space(msh)
    left = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0))
    right = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48))
    tags = dolfinx.mesh.meshtags(msh, 1, right, np.full(right.size, 7, dtype=np.int32))
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    x = ufl.SpatialCoordinate(msh)
    a, v = elasticity(V)
    ty = beam.P / (2 * beam.inertia) * (beam.D**2 / 4 - x[1] ** 2)
    L = ufl.dot(ufl.as_vector((0.0, ty)), v) * ds(7)
    bcs = [boundary_bc(V, left, beam.displacement)]
    patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 24), 3.0)

    forms = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, coupling=coupling).solve()
    reference = mf.CoupledElasticity(V, patch, MAT, coupling=coupling)
    reference.add_dirichlet(left, beam.displacement)
    reference.add_traction(right, beam.traction)
    expected = reference.solve()

    pts = np.array([[6.0, 1.0], [23.0, -5.0], [30.0, 3.0], [47.5, 5.5]])
    u1, u2 = forms.displacement(pts), expected.displacement(pts)
    assert np.abs(u1 - u2).max() <= 1e-10 * np.abs(u2).max()
    # and both are the Timoshenko beam to the discretisation error at h = 3
    assert np.abs(u1 - beam.displacement(pts)).max() <= 0.06 * np.abs(beam.displacement(pts)).max()


# -- exact linear patch tests ------------------------------------------------------------------


def linear_field(x):
    return np.stack([1e-3 * (1 + 2 * x[:, 0] - x[:, 1]), 1e-3 * (3 * x[:, 0] + x[:, 1])], axis=1)


@pytest.mark.parametrize(
    "cell, corner",
    [("quadrilateral", False), ("triangle", False), ("quadrilateral", True), ("triangle", True)],
)
def test_patch_facets_constrained_by_dirichletbc(cell, corner):
    """A DirichletBC on the whole boundary reaches the patch's exterior facets; with ``corner``
    the patch is the quarter x, y > 1, whose interface turns by 90 degrees at (1, 1) (one
    multiplier per side there: with continuous trace multipliers this missed by 6.8e-6)."""
    msh = rectangle([2.0, 2.0], [6, 6], cell)
    V = _compat.vector_function_space(msh)
    a, v = elasticity(V)
    L = ufl.dot(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.dx
    bcs = [boundary_bc(V, mf.boundary_facets(msh), linear_field)]
    cells = cells_where(msh, lambda m: (m[:, 0] > 1.0) & ((m[:, 1] > 1.0) | (not corner)))
    patch = mf.ParticlePatch(msh, cells, 1.0 / 3.0)
    assert COMM.allreduce(patch.exterior_facets.size) > 0
    problem = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, consistent=True)
    sol = problem.solve()
    grid = np.stack(np.meshgrid(np.linspace(0, 2, 9), np.linspace(0, 2, 9)), -1).reshape(-1, 2)
    assert np.abs(sol.displacement(grid) - linear_field(grid)).max() <= 1e-10


def test_facet_normal_traction_reaches_particles():
    """sigma0 n on every facet but x = 0 (FacetNormal in L): exact with consistent integration."""
    msh = rectangle([2.0, 1.0], [8, 4])
    V = _compat.vector_function_space(msh)
    a, v = elasticity(V)
    grad = np.array([[2e-3, -1e-3], [3e-3, 1e-3]])  # of the linear field
    sigma0 = MAT.stress(grad[None])[0]
    n = ufl.FacetNormal(msh)
    L = ufl.dot(ufl.dot(ufl.as_matrix(sigma0.tolist()), n), v) * ufl.ds

    def exact(x):
        return 1e-3 + x @ grad.T

    bcs = [boundary_bc(V, mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0)), exact)]
    patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 1.0), 0.25)
    sol = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, consistent=True).solve()
    grid = np.stack(np.meshgrid(np.linspace(0, 2, 9), np.linspace(0, 1, 5)), -1).reshape(-1, 2)
    assert np.abs(sol.displacement(grid) - exact(grid)).max() <= 1e-10 * np.abs(exact(grid)).max()


def test_body_loads_partition_of_unity():
    """The particle loads of f dx sum to the integral of f over the patch; FE loads over the
    rest (the load vectors sum to the integral of f over the whole rectangle)."""
    msh = rectangle([2.0, 1.0], [8, 4])
    V = _compat.vector_function_space(msh)
    a, v = elasticity(V)
    x = ufl.SpatialCoordinate(msh)
    L = ufl.dot(ufl.as_vector((1.0 + x[0], 2.0 * x[1] * x[0])), v) * ufl.dx
    patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 1.5), 0.25)
    coupled = mf.CoupledLinearProblem(a, L, [], patch, material=MAT).problem
    fe, particle = body_loads(coupled, coupled.cell_indicator(~patch.in_patch))
    # int over [1.5, 2] x [0, 1] of (1 + x, 2 x y) = (0.5 + 0.875, 0.875)
    total = COMM.allreduce(particle.reshape(-1, 2).sum(axis=0))
    assert np.allclose(total, [1.375, 0.875], rtol=1e-12)
    # int over [0, 1.5] x [0, 1] of (1 + x, 2 x y) = (1.5 + 1.125, 1.125)
    assert np.allclose(COMM.allreduce(fe.reshape(-1, 2).sum(axis=0)), [2.625, 1.125], rtol=1e-12)


def plain_dolfinx(V, a, L, bcs):
    """The model (``V`` the space of ``a``) solved as written: DOLFINx assembly and LU."""
    return mf.solve_forms(a, L, bcs).u


def test_gravity_against_fine_fe():
    """A body load solved with a patch agrees with plain DOLFINx on the same mesh to within the
    discretisation error (both against a 4x finer FE solution)."""
    E, nu, rho_g = 1e3, 0.3, 1.0
    mat = mf.LinearElastic(E, nu, plane="strain")

    def model(n):
        msh = rectangle([4.0, 1.0], [4 * n, n])
        V = _compat.vector_function_space(msh)
        a, v = elasticity(V, mat)
        L = ufl.dot(dolfinx.fem.Constant(msh, np.array([0.0, -rho_g])), v) * ufl.dx
        left = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0))
        bcs = [boundary_bc(V, left, lambda x: np.zeros_like(x))]
        return msh, V, a, L, bcs

    pts = np.array([[4.0, 0.5], [3.0, 0.0], [2.0, 1.0]])
    u_ref = mf.evaluate_fe_function(plain_dolfinx(*model(16)[1:]), pts)
    msh, V, a, L, bcs = model(4)
    e_fe = np.abs(mf.evaluate_fe_function(plain_dolfinx(V, a, L, bcs), pts) - u_ref).max()
    patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 2.0), 0.25)
    sol = mf.CoupledLinearProblem(a, L, bcs, patch, material=mat).solve()
    e_coupled = np.abs(sol.displacement(pts) - u_ref).max()
    assert e_coupled <= 1.5 * e_fe


# -- bad input -----------------------------------------------------------------------------------


@pytest.fixture
def model():
    msh = rectangle([2.0, 1.0], [4, 2])
    V = _compat.vector_function_space(msh)
    a, v = elasticity(V)
    L = ufl.dot(dolfinx.fem.Constant(msh, np.array([0.0, -1.0])), v) * ufl.ds
    left = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0))
    bcs = [boundary_bc(V, left, lambda x: np.zeros_like(x))]
    patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 1.0), 0.5)
    return msh, V, a, L, v, bcs, patch


def test_plane_strain_form_with_plane_stress_material(model):
    _msh, V, _, L, _v, bcs, patch = model
    strain = mf.LinearElastic(3e7, 0.3, plane="strain")
    a, _ = elasticity(V, strain)
    with pytest.raises(ValueError, match=r"disagrees with the bilinear form.*plane='strain'"):
        mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT)


def test_scaled_modulus_is_reported(model):
    _msh, _V, a, L, _v, bcs, patch = model
    with pytest.raises(ValueError, match=r"times the material's: E=3e\+07"):
        mf.CoupledLinearProblem(
            a, L, bcs, patch, material=mf.LinearElastic(3e6, 0.3, plane="stress")
        )


def test_material_differing_only_off_the_patch_is_accepted():
    """The FE side may use another law: only the patch cells are compared, and the solution is
    the bimaterial one. Oracle: a stiff patch (x > 1, the material's law) beside a soft FE part,
    u = (f(x), 0) on the whole boundary with f piecewise linear, kink at the material interface
    x = 1 where the normal stress (lambda + 2 mu) f' is continuous: the exact solution, which a
    linear patch test reproduces (consistent integration: measured 1e-17, bound 1e-12; the same
    check with the material's law on the FE side too misses by 2.8e-3)."""
    msh = rectangle([2.0, 1.0], [8, 4])
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 1.0), 0.25)
    soft = mf.LinearElastic(1e6, 0.2, plane="stress")
    chi = dolfinx.fem.Function(_compat.scalar_function_space(msh, "DG", 0))
    chi.x.array[:] = 0.0
    dof_of_cell = _compat.dofmap_array(chi.function_space)[:, 0]
    chi.x.array[dof_of_cell[: patch.in_patch.size]] = patch.in_patch.astype(float)
    eps = ufl.sym(ufl.grad(v))
    a = (
        chi * ufl.inner(MAT.ufl_stress(u), eps) + (1 - chi) * ufl.inner(soft.ufl_stress(u), eps)
    ) * (ufl.dx)
    # f(0) = 0, f(2) = 0.01, slopes g_soft on [0, 1] and g_stiff on [1, 2] with M g continuous
    m_soft, m_stiff = soft.E / (1 - soft.nu**2), MAT.E / (1 - MAT.nu**2)  # lambda + 2 mu
    g_soft = 0.01 * m_stiff / (m_soft + m_stiff)
    g_stiff = 0.01 - g_soft

    def exact(x):
        f = np.where(x[:, 0] <= 1.0, g_soft * x[:, 0], g_soft + g_stiff * (x[:, 0] - 1.0))
        return np.column_stack([f, np.zeros_like(f)])

    bcs = [boundary_bc(V, mf.boundary_facets(msh), exact)]
    L = ufl.dot(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.ds
    sol = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, consistent=True).solve()
    pts = np.column_stack([np.linspace(0.0, 2.0, 41), np.tile([0.1, 0.5, 0.9], 14)[:41]])
    err = np.abs(sol.displacement(pts) - exact(pts)).max()
    assert err <= 1e-10 * 0.01
    # the oracle is not the uniform field of a single law: the kink is large
    straight = np.column_stack([0.005 * pts[:, 0], np.zeros(41)])
    assert np.abs(exact(pts) - straight).max() >= 0.4 * 0.01


@pytest.mark.parametrize(
    "case, match",
    [
        ("interior", r"only dx and ds integrals"),
        ("derivative", r"differentiates the test function"),
        ("coupling", r"coupling='glue' is not available"),
        ("not-affine", r"not affine in the FacetNormal"),
        ("close-pins", r"two of them 0\.5 apart \(at \[1\.5, 0\.5\] and \[2\.0, 0\.5\]\)"),
        ("facet-a", r"exterior facet\(s\) of a patch cell, e\.g\. the facets at"),
        ("interior-a", r"a has a interior_facet integral"),
        ("material", r"material must be a LinearElastic"),
    ],
)
def test_bad_input(model, case, match):
    msh, V, a, L, v, bcs, patch = model
    coupling, material = "lagrange", MAT
    if case == "interior":
        L = L + ufl.avg(v[0]) * ufl.dS
    elif case == "derivative":
        L = L + ufl.div(v) * ufl.ds  # in dx: an initial stress (tests/test_initial_stress.py)
    elif case == "coupling":
        coupling = "glue"
    elif case == "not-affine":
        n = ufl.FacetNormal(msh)
        L = n[0] * n[0] * v[0] * ufl.ds
    elif case == "close-pins":  # single nodes of patch cells held (a pin each): held by the
        # particle field at points, which need a particle spacing between them (here 1.0)
        dofs = dolfinx.fem.locate_dofs_geometrical(
            V, lambda x: np.isclose(x[0], 1.5) & np.isclose(x[1], 0.5)
        )
        far = dolfinx.fem.locate_dofs_geometrical(
            V, lambda x: np.isclose(x[0], 2.0) & np.isclose(x[1], 0.5)
        )
        bcs = [*bcs, *(dolfinx.fem.dirichletbc(np.zeros(2), d, V) for d in (dofs, far))]
        patch = mf.ParticlePatch(msh, cells_where(msh, lambda m: m[:, 0] > 1.0), 1.0)
    elif case == "facet-a":  # an elastic support on the patch's facets (on FE facets: taken)
        u = ufl.TrialFunction(V)
        a = a + ufl.dot(u, v) * ufl.ds
    elif case == "interior-a":
        u = ufl.TrialFunction(V)
        a = a + ufl.inner(ufl.jump(u), ufl.jump(v)) * ufl.dS
    elif case == "material":
        material = {"E": 3e7}
    with pytest.raises((ValueError, TypeError), match=match):
        mf.CoupledLinearProblem(a, L, bcs, patch, material=material, coupling=coupling)
