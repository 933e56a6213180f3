"""Facet integrals of the unknown in a user's coupled model: elastic supports and follower loads.

A model written for DOLFINx may hold ``k (u.n)(v.n) ds`` in its bilinear form (an elastic
support) or ``p J inner(inv(F).T N, v) ds`` in its residual (a follower pressure). Before, the
linear problem refused the first and the nonlinear problem dropped the second silently (a
spring-supported bar came out as a free one). Oracles, both affine fields that every exact
coupling reproduces:

* a bar in plane stress on rollers at x = 0 and y = 0, pulled by ``p`` at x = L and held there
  by a normal spring ``k``: ``sigma_xx = p / (1 + k L / E)``, ``u = (sigma x / E, -nu sigma y /
  E)`` (here ``k L / E = 1``: the spring carries half the load);
* a block in plane strain (neo-Hookean, ``P = mu (F - F^-T) + lambda ln J F^-T``) on rollers,
  pressed at x = L by a follower pressure ``p`` on the current area: a uniform stretch
  ``diag(l1, l2)`` with ``P_11 = -p l2`` and ``P_22 = 0``, solved here by scipy from the closed
  form (a dead load ``P_11 = -p`` gives a stretch 1.3 % different, so the check tells them
  apart).

The patch lies inside the body, off the facets that carry the terms; terms on a patch cell's
facets (and a ramp's interface cells') are refused, as are ``dS`` terms of the unknown and a
``ds`` term beside a law with state.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from scipy.optimize import fsolve

pytestmark = pytest.mark.filterwarnings("ignore::dolfinx_meshfree.PartitionImbalanceWarning")

COMM = MPI.COMM_WORLD
E, NU, L, H = 1000.0, 0.25, 3.0, 1.0
K_SPRING = E / L  # k L / E = 1
P_PULL = 10.0
LINEAR_EXACT = ("lagrange", "edge-to-edge", "bridging", "ramp", "ramp-cubic")
TOL = 1e-12  # round-off: measured 8e-16 to 8e-15


def mesh(cell: str, n: int = 4):
    if cell == "hexahedron":
        return dolfinx.mesh.create_box(
            COMM, [[0.0, 0.0, 0.0], [L, H, H]], [12, 3, 3],
            dolfinx.mesh.CellType.hexahedron,
        )  # fmt: skip
    kind = getattr(dolfinx.mesh.CellType, cell)
    return dolfinx.mesh.create_rectangle(COMM, [[0.0, 0.0], [L, H]], [3 * n, n], kind)


def tagged_ds(msh):
    """ds with tag 1 on x = L and 2 on x = 0."""
    fdim = msh.topology.dim - 1
    right = dolfinx.mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], L))
    left = dolfinx.mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], 0.0))
    facets = np.concatenate([right, left])
    values = np.concatenate([np.full(right.size, 1), np.full(left.size, 2)]).astype(np.int32)
    order = np.argsort(facets)
    tags = dolfinx.mesh.meshtags(msh, fdim, facets[order].astype(np.int32), values[order])
    return ufl.Measure("ds", msh, subdomain_data=tags)


def rollers(V):
    """u_i = 0 on the plane x_i = 0, for every i."""
    msh = V.mesh
    fdim = msh.topology.dim - 1
    bcs = []
    for i in range(msh.geometry.dim):
        facets = dolfinx.mesh.locate_entities_boundary(
            msh, fdim, lambda x, i=i: np.isclose(x[i], 0)
        )
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(i), fdim, facets)
        bcs.append(dolfinx.fem.dirichletbc(0.0, dofs, V.sub(i)))
    return bcs


def middle_cells(msh, x0=1.0, x1=2.0):
    tdim = msh.topology.dim
    n = msh.topology.index_map(tdim).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n]].mean(axis=1)
    return np.flatnonzero((mid[:, 0] > x0) & (mid[:, 0] < x1)).astype(np.int32)


def probe(gdim):
    pts = np.array([[L, 0.7], [1.5, 0.4], [1.02, 0.9], [0.5, 0.5], [2.6, 0.1]])
    if gdim == 3:
        pts = np.column_stack([pts, np.full(len(pts), 0.3)])
    return pts


# -- a linear elastic support ---------------------------------------------------------------------


def support_problem(cell, coupling, cells=None, where=1):
    msh = mesh(cell)
    gdim = msh.geometry.dim
    plane = None if gdim == 3 else "stress"
    mat = mf.LinearElastic(E, NU, plane=plane)
    V = _compat.vector_function_space(msh, 1)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    ds = tagged_ds(msh)
    n = ufl.FacetNormal(msh)
    a = ufl.inner(mat.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    a += K_SPRING * ufl.dot(u, n) * ufl.dot(v, n) * ds(where)  # the elastic support
    L_form = P_PULL * ufl.dot(n, v) * ds(1)
    patch = mf.ParticlePatch(msh, middle_cells(msh) if cells is None else cells, spacing=0.25)
    return mf.CoupledLinearProblem(a, L_form, rollers(V), patch, mat, coupling=coupling), mat


def support_exact(x, mat):
    sigma = P_PULL / (1.0 + K_SPRING * L / E)
    u = np.zeros_like(x)
    u[:, 0] = sigma * x[:, 0] / E
    u[:, 1:] = -NU * sigma * x[:, 1:] / E
    return u


@pytest.mark.parametrize("coupling", LINEAR_EXACT)
def test_an_elastic_support_holds_a_coupled_bar(coupling):
    """The spring on the FE end carries half the load, every exact coupling to round-off (before:
    ``a has a exterior_facet integral`` refused the model)."""
    problem, mat = support_problem("quadrilateral", coupling)
    x = probe(2)
    u = problem.solve().displacement(x)
    exact = support_exact(x, mat)
    assert np.abs(u - exact).max() < TOL * np.abs(exact).max()


@pytest.mark.parametrize("cell, coupling", [("triangle", "lagrange"), ("hexahedron", "lagrange"),
                                            ("hexahedron", "bridging")])  # fmt: skip
def test_an_elastic_support_on_other_cells(cell, coupling):
    problem, mat = support_problem(cell, coupling)
    x = probe(problem.V.mesh.geometry.dim)
    u = problem.solve().displacement(x)
    exact = support_exact(x, mat)
    assert np.abs(u - exact).max() < TOL * np.abs(exact).max()


# -- a follower pressure at finite strain ---------------------------------------------------------

MAT_NH = mf.NeoHookean(E=E, nu=0.3, plane="strain")
NEWTON = 2e-10  # Newton's tolerance: measured 8.0e-11 of l1 - 1, every method
P_PRESS = 120.0


def stretches(follower: bool) -> np.ndarray:
    """``(l1, l2)`` of the pressed block from the closed-form nominal stress (plane strain)."""
    mu, lam = MAT_NH.mu, MAT_NH.lmbda

    def residual(s):
        l1, l2 = s
        lnJ = np.log(l1 * l2)
        p11 = mu * (l1 - 1 / l1) + lam * lnJ / l1
        p22 = mu * (l2 - 1 / l2) + lam * lnJ / l2
        return [p11 + P_PRESS * (l2 if follower else 1.0), p22]

    return np.asarray(fsolve(residual, [0.9, 1.05], xtol=1e-14))


def test_the_closed_forms_tell_follower_from_dead():
    follower, dead = stretches(True), stretches(False)
    assert abs(follower[0] - dead[0]) > 1e-3  # measured 1.7e-3 on l1 (1.3 % of l1 - 1)
    assert abs((follower[0] - 1) / (dead[0] - 1) - 1) > 0.01


def pressed_block(method, where=1, cells=None):
    msh = mesh("quadrilateral")
    V = _compat.vector_function_space(msh, 1)
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    ds = tagged_ds(msh)
    N = ufl.FacetNormal(msh)
    F = ufl.Identity(2) + ufl.grad(u)
    p = dolfinx.fem.Constant(msh, 0.0)
    R = ufl.inner(MAT_NH.ufl_first_piola(F), ufl.grad(v)) * ufl.dx
    R += p * ufl.det(F) * ufl.dot(ufl.inv(F).T * N, v) * ds(where)  # the follower pressure
    if method == "fe":
        return mf.FENonlinearProblem(R, u, rollers(V)), u, p
    patch = mf.ParticlePatch(msh, middle_cells(msh) if cells is None else cells, spacing=0.25)
    return mf.CoupledNonlinearProblem(R, u, rollers(V), patch, MAT_NH, coupling=method), u, p


@pytest.mark.parametrize("method", ["fe", "lagrange", "edge-to-edge", "bridging", "ramp"])
def test_a_follower_pressure_at_finite_strain(method):
    """The pressure ramped by the user's Constant over three calls of ``solve`` (facet terms of u
    are not scaled by ``load_steps``); the block's stretch meets the closed form. Before, pure FE
    refused the model and the couplings dropped the pressure (no deformation at all)."""
    problem, u, p = pressed_block(method)
    for value in (P_PRESS / 3, 2 * P_PRESS / 3, P_PRESS):
        p.value = value
        problem.solve()
    l1, l2 = stretches(True)
    x = probe(2)
    exact = np.column_stack([(l1 - 1) * x[:, 0], (l2 - 1) * x[:, 1]])
    if method == "fe":  # the nodal values of every rank's owned nodes
        owned = u.function_space.dofmap.index_map.size_local
        values = u.x.array.reshape(-1, 2)[:owned]
        dof_x = u.function_space.tabulate_dof_coordinates()[:owned, :2]
        fe_exact = np.column_stack([(l1 - 1) * dof_x[:, 0], (l2 - 1) * dof_x[:, 1]])
        assert np.abs(values - fe_exact).max() < NEWTON * abs(l1 - 1)
        return
    got = problem.solution.displacement(x)
    assert np.abs(got - exact).max() < NEWTON * abs(l1 - 1)


# -- refusals -------------------------------------------------------------------------------------


def test_a_support_on_the_patch_is_refused_by_its_facets():
    msh = mesh("quadrilateral")
    cells = middle_cells(msh, 2.0, L + 1)  # the patch reaches x = L
    with pytest.raises(ValueError, match=r"runs over .* facet\(s\) of a patch cell.*\[3\.0, "):
        support_problem("quadrilateral", "lagrange", cells=cells)


def test_a_ramp_refuses_a_support_on_its_interface_cells():
    msh = mesh("quadrilateral")
    cells = middle_cells(msh, 1.5, L - 0.25 - 1e-9)  # one FE column at x = L: ramp cells
    with pytest.raises(ValueError, match="interface cell"):
        support_problem("quadrilateral", "ramp", cells=cells)
    problem, mat = support_problem("quadrilateral", "lagrange", cells=cells)  # pure FE cells
    x = probe(2)
    exact = support_exact(x, mat)
    assert np.abs(problem.solve().displacement(x) - exact).max() < TOL * np.abs(exact).max()


def test_a_follower_pressure_on_the_patch_is_refused():
    msh = mesh("quadrilateral")
    with pytest.raises(ValueError, match="F's ds integral of the unknown"):
        pressed_block("lagrange", cells=middle_cells(msh, 2.0, L + 1))


def test_interior_facet_terms_and_laws_with_state_are_refused():
    msh = mesh("quadrilateral")
    V = _compat.vector_function_space(msh, 1)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    mat = mf.LinearElastic(E, NU, plane="stress")
    a = ufl.inner(mat.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    L_form = ufl.dot(ufl.as_vector([1.0, 0.0]), v) * tagged_ds(msh)(1)
    patch = mf.ParticlePatch(msh, middle_cells(msh), spacing=0.25)
    jump = ufl.inner(ufl.jump(u), ufl.jump(v)) * ufl.dS
    with pytest.raises(ValueError, match="interior_facet integral"):
        mf.CoupledLinearProblem(a + jump, L_form, rollers(V), patch, mat)
    law = mf.J2Plasticity(E, NU, 1.0, plane="stress")
    spring = K_SPRING * ufl.inner(u, v) * tagged_ds(msh)(1)
    with pytest.raises(ValueError, match="law with state"):
        mf.CoupledLinearProblem(a + spring, L_form, rollers(V), patch, law)
    problem = mf.CoupledLinearProblem(a + spring, L_form, rollers(V), patch, mat)
    with pytest.raises(ValueError, match="explicit dynamics does not carry them"):
        mf.ExplicitDynamics.coupled(problem.model)
