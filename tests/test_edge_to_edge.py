"""Edge-to-edge FE–EFG coupling: multipliers collocated at the interface particles.

``CoupledElasticity(coupling="edge-to-edge")`` (Rabczuk et al. 2006, sec. 5.4) imposes
``u_FE(x_I) = u_P(x_I)`` at every particle ``x_I`` on the interface. Oracles: the linear patch
test, the Timoshenko cantilever (fitted rate and the pure-FE error at the same h, computed here),
the collocation constraint itself, and the same problem solved on COMM_SELF.
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
import scipy.sparse as sp
from conftest import (
    BEAM_L,
    beam_ends,
    beam_mesh,
    fe_errors,
    fitted_rate,
    solve_beam_fe,
)
from mpi4py import MPI

BEAM = mf.TimoshenkoBeam(mf.LinearElastic(3e7, 0.3))
#: With Gauss quadrature alone the linear patch test is NOT passed: at equilibrium the collocated
#: multipliers pass the interface force to particle ``J`` as ``sum_I phi_J(x_I) int t N_I``, the
#: integral of the FE interpolant of ``phi_J``, where the exact field needs ``int t phi_J``; MLS
#: shape functions are not linear between particles, so the two differ by a first-order
#: consistency error (measured max error 4.4e-2 on 6x6 quadrilaterals for u = (x, y)). With
#: consistent integration the VCI identity is written with that same interpolant on the interface
#: (CoupledElasticity._interface_interpolant), and the test passes to round-off (3e-15 here;
#: 1.2e-12 on the gmsh meshes of demos/patch_test.py).
PATCH_BOUND_GAUSS = 1.5e-2


def cells_right_of(msh, x0):
    n = msh.topology.index_map(2).size_local
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2]
    return np.flatnonzero(nodes[:, :, 0].mean(axis=1) > x0)


def solve_patch_test(comm, cell, exact, n=6, consistent=None):
    """The patch test at default options (``consistent=None``: VCI) or the given variant."""
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.full(2, 2.0)], [n, n], getattr(dolfinx.mesh.CellType, cell)
    )
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 1.0), 2.0 / n)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh),
        patch,
        mf.LinearElastic(1000.0, 0.3),
        coupling="edge-to-edge",
        consistent=consistent,
    )
    problem.add_dirichlet(mf.boundary_facets(msh), exact.displacement)
    return msh, problem, problem.solve()


def solve_beam(comm, h, consistent=False):
    msh = beam_mesh(comm, h)
    left, right = beam_ends(msh)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, BEAM_L / 2), h)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh),
        patch,
        BEAM.material,
        coupling="edge-to-edge",
        consistent=consistent,
    )
    problem.add_dirichlet(left, BEAM.displacement)
    problem.add_traction(right, BEAM.traction)
    sol = problem.solve()
    return msh, problem, sol, mf.error_norms(msh, sol.evaluate_at_quadrature, BEAM, BEAM.material)


def test_multipliers_sit_at_the_interface_particles():
    """Edge-to-edge collocates one multiplier per interface particle, Lagrange one per FE trace
    node: with particles at half the element size on the interface x = 24 of the h = 1.5 beam,
    17 particles against 9 nodes; and the two couplings give different solutions."""
    comm = MPI.COMM_WORLD
    msh = beam_mesh(comm, 1.5)
    left, right = beam_ends(msh)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, BEAM_L / 2), 0.75)
    sols = {}
    for coupling in ("edge-to-edge", "lagrange"):
        problem = mf.CoupledElasticity(
            _compat.vector_function_space(msh),
            patch,
            BEAM.material,
            coupling=coupling,
            consistent=False,
        )
        problem.add_dirichlet(left, BEAM.displacement)
        problem.add_traction(right, BEAM.traction)
        sols[coupling] = problem.solve()
        if coupling == "edge-to-edge":
            iface = problem.interface_particles()
            x = patch.particles.positions[iface]
            np.testing.assert_allclose(x[:, 0], BEAM_L / 2, atol=1e-12)
            np.testing.assert_allclose(np.sort(x[:, 1]), np.linspace(-6.0, 6.0, 17), atol=1e-12)
    assert sols["edge-to-edge"].sizes["multiplier_dofs"] == 2 * 17
    assert sols["lagrange"].sizes["multiplier_dofs"] == 2 * 9
    pts = np.array([[24.0, 6.0], [36.0, 0.0], [48.0, -6.0]])
    a, b = sols["edge-to-edge"].displacement(pts), sols["lagrange"].displacement(pts)
    assert np.abs(a - b).max() > 5e-5 * np.abs(b).max()  # measured 1.3e-4


def patch_test_error(cell, n, rng, consistent=None):
    exact = mf.LinearField(G=((0.3, -0.2), (0.5, 0.1)), c=(0.1, -0.4))
    _, _, sol = solve_patch_test(MPI.COMM_WORLD, cell, exact, n, consistent)
    x = np.vstack([rng.uniform(0.0, 2.0, (60, 2)), sol.patch.particles.positions])
    err = np.abs(sol.displacement(x) - exact.displacement(x)).max()
    return MPI.COMM_WORLD.allreduce(err, op=MPI.MAX)


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_patch_test_with_consistent_integration(cell, rank_rng):
    for n in (6, 12):
        assert patch_test_error(cell, n, rank_rng) <= 1e-10


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_patch_test_with_gauss_quadrature_is_first_order(cell, rank_rng):
    """The issue's Gauss target (1e-6) is not met: a consistency error that goes to zero at
    first order under refinement."""
    # measured 1.14e-2 / 1.05e-2 (quadrilaterals / triangles) at n = 6, 5.95e-3 / 5.49e-3 at 12:
    # halved by each refinement (ratio 1.91, 1.90; bounds 1.8 to 2.2, first order both sides)
    err = patch_test_error(cell, 6, rank_rng, consistent=False)
    assert 5e-3 < err <= PATCH_BOUND_GAUSS
    fine = patch_test_error(cell, 12, rank_rng, consistent=False)
    assert 1.8 <= err / fine <= 2.2


def test_cantilever_rate_and_error_against_pure_fe():
    """Gauss quadrature (``consistent=False``): error 0.923, 0.915, 0.916 x pure FE's at h = 3,
    1.5, 1, fitted rate 1.98; bounds: ratio in [0.8, 1.0], rate in [1.8, 2.2]. (With
    ``consistent=True`` the error is 0.17, 0.37, 0.45 x FE's and approaches it from below at
    rates 0.83, 1.50: demos/convergence.py holds that case.)"""
    hs = [3.0, 1.5, 1.0]
    errors = []
    for h in hs:
        _, _, _, e = solve_beam(MPI.COMM_WORLD, h, consistent=False)
        msh = beam_mesh(MPI.COMM_WORLD, h)
        fe = fe_errors(msh, solve_beam_fe(msh, BEAM), BEAM)["l2"]
        assert 0.8 <= e["l2"] / fe <= 1.0, (h, e["l2"], fe)
        errors.append(e["l2"])
    assert 1.8 <= fitted_rate(hs, errors) <= 2.2


def test_constraint_holds_at_the_interface_particles():
    _, problem, sol, _ = solve_beam(MPI.COMM_WORLD, 1.5)
    iface = problem.interface_particles()
    x = sol.patch.particles.positions[iface]
    assert iface.size == round(12 / 1.5) + 1  # particles on the nodes of x = 24
    np.testing.assert_allclose(x[:, 0], BEAM_L / 2, atol=1e-12)
    comm = MPI.COMM_WORLD
    # this rank evaluates its share of the interface particles: each side by its own basis
    mine = x[comm.rank :: comm.size]
    u_fe = mf.evaluate_fe_function(sol.u, mine)
    u_p = sol.mls.tabulate(mine, 0).values @ sol.coefficients
    residual = comm.allreduce(np.abs(u_fe - u_p).max(initial=0.0), op=MPI.MAX)
    scale = comm.allreduce(np.abs(sol.u.x.array).max(), op=MPI.MAX)
    assert residual <= 1e-10 * scale


def test_parallel_equals_serial(rank_rng):
    x = rank_rng.uniform([0.0, -6.0], [48.0, 6.0], (30, 2))
    _, _, world, _ = solve_beam(MPI.COMM_WORLD, 1.5, consistent=True)
    _, _, alone, _ = solve_beam(MPI.COMM_SELF, 1.5, consistent=True)
    a, b = world.displacement(x), alone.displacement(x)
    assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
    assert world.sizes == alone.sizes


def test_moment_corrections_carry_the_boundary_term_for_linear_stresses(rank_rng):
    """``moment_corrections``: for every node ``I``, component ``k`` and linear ``s(x)``,
    ``sum_q c_{I,k} N_I s w_q = sum_b D_I n_k s w_b`` (the moment conditions that make the
    edge-to-edge interface term exact for linear stresses), with the points split over the
    ranks (collective sums); nodes with ``D_I = 0`` get no correction."""
    from dolfinx_meshfree.physics.operators import moment_corrections

    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(7)  # the same data on every rank, each takes its share
    nq, nb, n = 400, 60, 12
    xq, xb = rng.uniform(0, 1, (nq, 2)), rng.uniform(0, 1, (nb, 2))
    wq, wb = rng.uniform(0.5, 1, nq), rng.uniform(0.5, 1, nb)
    centres = rng.uniform(0, 1, (n, 2))
    values = np.maximum(0.0, 1.0 - np.linalg.norm(xq[:, None] - centres[None], axis=2) / 0.6)
    mismatch = rng.normal(size=(nb, n)) * (rng.uniform(size=(nb, n)) < 0.4)
    mismatch[:, 0] = 0.0  # node 0: no boundary term
    normals = rng.normal(size=(nb, 2))
    q, b = slice(comm.rank, None, comm.size), slice(comm.rank, None, comm.size)
    corr = moment_corrections(
        sp.csr_matrix(values[q]), xq[q], wq[q], sp.csr_matrix(mismatch[b]), xb[b], wb[b],
        normals[b], comm,
    )  # fmt: skip
    for _ in range(3):
        a = rng.normal(size=3)
        sq, sb = a[0] + xq[q] @ a[1:], a[0] + xb[b] @ a[1:]
        for k in range(2):
            lhs = comm.allreduce(corr[k].T @ (wq[q] * sq), op=MPI.SUM)
            rhs = comm.allreduce(mismatch[b].T @ (wb[b] * normals[b, k] * sb), op=MPI.SUM)
            np.testing.assert_allclose(lhs, rhs, rtol=1e-10, atol=1e-12 * np.abs(rhs).max())
    assert all(np.abs(c.toarray()[:, 0]).max() == 0.0 for c in corr)


def test_operators_with_consistent_integration_match_the_static_system():
    """``CoupledElasticity.operators(consistent=True)`` (the dynamics' blocks) builds the same
    particle stiffness as the static solve: the VCI identity with the interface particles'
    interpolant and its first moments (before, the operators wrote it with ``phi_J`` on the
    interface, the variant whose linear patch test misses by about 4e-2)."""
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.full(2, 2.0)], [6, 6], dolfinx.mesh.CellType.quadrilateral
    )
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 1.0), 2.0 / 6)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh), patch, mf.LinearElastic(1000.0, 0.3),
        coupling="edge-to-edge",
    )  # fmt: skip
    K_ops = problem.operators(consistent=True).K_p
    K_sys = problem.family.system(problem)[0][1][1]
    x = K_ops.createVecRight()
    x.setRandom()
    y_ops, y_sys = K_ops.createVecLeft(), K_sys.createVecLeft()
    K_ops.mult(x, y_ops)
    K_sys.mult(x, y_sys)
    y_sys.axpy(-1.0, y_ops)
    assert y_sys.norm() <= 1e-12 * y_ops.norm()
