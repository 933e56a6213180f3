"""EFG patch test (Belytschko et al. 1995, sec. 5.1.1, eq. 5.1).

An affine displacement ``u = c + G x`` prescribed on the whole boundary of [0, 2]^2 (Lagrange
multipliers) is the exact solution without body force. MLS with a linear basis contains it, so
with variationally consistent integration (``consistent=True``) the EFG solution must reproduce it
to round-off, on regular and on jittered particles, on triangle and quadrilateral integration
cells. Plain Gauss quadrature of the rational MLS functions leaves an integration error (the
paper reports 1e-6), which the last assertion requires: it shows that this test can fail.

Tolerance: ``1e-10`` on displacements of size ~2 (the brief's value). Observed errors are
1e-14–1e-11: round-off amplified by the condition number of the saddle-point system (largest on
the regular triangle grid).
"""

import dolfinx_meshfree as mf

import numpy as np
import pytest
from conftest import CELL_TYPES, rectangle
from mpi4py import MPI

FIELD = mf.LinearField(G=((1.0, 0.2), (-0.3, 0.5)), c=(0.1, -0.2))
MATERIAL = mf.LinearElastic(1000.0, 0.3)
N = 6


def solve_patch(cell_name, jitter, consistent=None):
    """EFG on the patch; ``consistent=None``: the default options (VCI)."""
    msh = rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, 2.0], [N, N], CELL_TYPES[cell_name])
    particles = mf.ParticleSet.from_cells(msh, 2.0 / N, jitter=jitter)
    options = {} if consistent is None else {"consistent": consistent}
    problem = mf.EFGElasticity(particles, MATERIAL, **options)
    facets = mf.boundary_facets(msh)
    problem.add_dirichlet(facets, FIELD.displacement)
    return msh, facets, particles, problem.solve()


@pytest.mark.parametrize("jitter", [0.0, 0.3])
@pytest.mark.parametrize("cell_name", sorted(CELL_TYPES))
def test_patch_test_passes_with_consistent_integration(cell_name, jitter):
    msh, facets, particles, sol = solve_patch(cell_name, jitter)  # default options
    num_facets = msh.comm.allreduce(facets.size)
    x = np.random.default_rng(1).uniform(0.0, 2.0, (400, 2))
    u, grad = sol.evaluate(x)
    assert np.abs(u - FIELD.displacement(x)).max() <= 1e-10
    assert np.abs(grad - np.asarray(FIELD.G)).max() <= 1e-9
    # MLS reproduces the field, so its exact nodal parameters are the field at the particles
    assert np.abs(sol.coefficients - FIELD.displacement(particles.positions)).max() <= 1e-9
    # the multipliers are the reactions -sigma n, constant on each facet (one per owned facet,
    # in increasing facet order)
    q = mf.facet_quadrature(msh, facets, 7)
    _, first = np.unique(q.entities, return_index=True)
    sigma = MATERIAL.stress(np.asarray(FIELD.G)[None])[0]
    traction = q.normals[first] @ sigma.T
    lam = sol.multipliers.reshape(-1, 2)
    assert lam.shape == traction.shape
    assert sol.num_multipliers == 2 * num_facets
    assert np.abs(lam + traction).max(initial=0.0) <= 1e-8 * np.abs(sigma).max()
    # the jittered set is irregular (the test is not only on a grid)
    if jitter:
        spacing = 2.0 / N
        offsets = particles.positions / spacing - np.round(particles.positions / spacing)
        assert np.abs(offsets).max() > 0.1


@pytest.mark.parametrize("jitter", [0.0, 0.3])
@pytest.mark.parametrize("cell_name", sorted(CELL_TYPES))
def test_patch_test_fails_without_consistent_integration(cell_name, jitter):
    _, _, _, sol = solve_patch(cell_name, jitter, consistent=False)
    x = np.random.default_rng(1).uniform(0.0, 2.0, (400, 2))
    err = np.abs(sol.displacement(x) - FIELD.displacement(x)).max()
    # Gauss quadrature of rational shape functions is not exact, but it is still an
    # approximation of the right field: measured 1.1e-4 to 4.9e-4 (quadrilaterals, triangles,
    # jittered or not); bounds half the smallest and twice the largest
    assert 5e-5 < err < 1e-3
