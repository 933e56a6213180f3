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
from dolfinx_meshfree.bridging import BridgingBand

import numpy as np
import pytest
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
    """The linear patch test: 2 x 2 square, 6 x 6 quadrilaterals, particles on x > 2/3 (spacing
    1/3), overlap 2, u linear on the whole boundary. Issue target: maximum error <= 1e-6."""
    assert patch_test_error() <= 1e-6


def test_patch_test_with_consistent_integration():
    """``constraint="integral"`` with VCI under the alpha weight (eq. 46) and alpha-weighted
    facet multipliers in the band: the linear patch test to round-off on this band of uniform
    straight layers (grad alpha constant, in the multiplier space; measured 3e-15). The point
    constraints stay first order (3.6e-2 in demos/patch_test.py), and on unstructured meshes
    grad alpha is only piecewise constant (1.6e-3 on the gmsh meshes)."""
    assert patch_test_error(consistent=True, constraint="integral") <= 1e-10
    assert patch_test_error(consistent=True) > 1e-3


def constraint_residual(sol, V):
    """``sum_L N_k(x_L) (u_FE(x_L) - u_P(x_L))`` for every node k (global numbering)."""
    x = sol.patch.particles.positions[sol.band.particles]
    u_fe = mf.evaluate_fe_function(sol.u, x)
    u_p = sol.mls.tabulate(x, 0).values @ sol.coefficients
    n = mf.tabulate_fe_basis(V, x, derivatives=0).values
    return n.T @ (u_fe - u_p), np.abs(u_p).max()


@pytest.mark.parametrize("spacing", [1.5, 0.75])
def test_constraint_holds(spacing):
    """The multiplier equations hold to round-off, at particles on the FE nodes and between."""
    sol, _ = solve_beam(MPI.COMM_WORLD, 1.5, spacing=spacing)
    r, scale = constraint_residual(sol, sol.u.function_space)
    assert np.abs(r).max() <= 1e-10 * scale


def test_penalty():
    """With one particle per band node the weighted constraints force u_FE = u_P at every band
    particle, so the penalty p g^T g (eq. 54) leaves the solution unchanged; with two particles
    per cell side it changes it, and the constraint still holds."""
    pts = np.random.default_rng(3 + MPI.COMM_WORLD.rank).uniform([0.5, -5.5], [47.5, 5.5], (20, 2))
    a, _ = solve_beam(MPI.COMM_WORLD, 1.5)
    b, _ = solve_beam(MPI.COMM_WORLD, 1.5, penalty=3e7)
    ua, ub = a.displacement(pts), b.displacement(pts)
    assert np.abs(ua - ub).max() <= 1e-8 * np.abs(ua).max()
    c, _ = solve_beam(MPI.COMM_WORLD, 1.5, spacing=0.75)
    d, _ = solve_beam(MPI.COMM_WORLD, 1.5, spacing=0.75, penalty=3e7)
    uc, ud = c.displacement(pts), d.displacement(pts)
    assert np.abs(uc - ud).max() > 1e-8 * np.abs(uc).max()
    r, scale = constraint_residual(d, d.u.function_space)
    assert np.abs(r).max() <= 1e-10 * scale


def test_cantilever_rate_and_error_against_pure_fe():
    hs = [3.0, 1.5, 1.0]
    errs = [solve_beam(MPI.COMM_WORLD, h)[1]["l2"] for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert slope >= 1.8
    for h, e in zip(hs, errs, strict=True):
        assert e <= 1.5 * fe_beam_error(h)


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
    ],
)
def test_bad_options(options, message):
    with pytest.raises(ValueError, match=message):
        patch_problem(MPI.COMM_WORLD, **options)


def test_band_wider_than_the_patch():
    """The patch is 4 cells wide: overlap 4 fills it, overlap 5 is refused on every rank."""
    assert patch_test_error(overlap=4) < 1.0
    _, problem = patch_problem(MPI.COMM_WORLD, overlap=5)
    with pytest.raises(ValueError, match=r"overlap=5 cell layers is wider than the patch: only 4"):
        problem.solve()


def test_integral_constraint():
    """``constraint="integral"`` ties the band by Gauss quadrature over its cells (eq. 52): the
    cantilever keeps rate 2 with errors no larger than the point constraints' (measured 2.62e-2,
    6.59e-3, 2.92e-3 against 2.69e-2, 6.81e-3, 3.01e-3), and the linear patch test drops from
    1.1e-2 to the Gauss quadrature level (exact with VCI: previous test)."""
    hs = [3.0, 1.5, 1.0]
    errs = [solve_beam(MPI.COMM_WORLD, h, constraint="integral")[1]["l2"] for h in hs]
    assert np.polyfit(np.log(hs), np.log(errs), 1)[0] >= 1.9
    points = [solve_beam(MPI.COMM_WORLD, h)[1]["l2"] for h in hs]
    assert all(e <= p for e, p in zip(errs, points, strict=True))
    assert patch_test_error(constraint="integral") < 1e-4 < 1e-3 < patch_test_error()


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
