"""Particle sets generated in mesh cells: positions, jitter, patches, volumes, ownership."""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import numpy as np
import pytest
from conftest import CELL_TYPES, rectangle
from mpi4py import MPI

COMM = MPI.COMM_WORLD


@pytest.fixture(params=sorted(CELL_TYPES))
def msh(request):
    return rectangle(COMM, [1.0, -1.0], [4.0, 1.0], [6, 4], CELL_TYPES[request.param])


def test_regular_grid_fills_the_cells(msh):
    P = mf.ParticleSet.from_cells(msh, 0.25)
    # round(3 / 0.25) + 1 by round(2 / 0.25) + 1 grid points, corners on the box's corners
    xs, ys = np.linspace(1.0, 4.0, 13), np.linspace(-1.0, 1.0, 9)
    expected = np.stack(np.meshgrid(xs, ys, indexing="xy"), axis=-1).reshape(-1, 2)
    np.testing.assert_allclose(P.positions, expected, rtol=0, atol=1e-14)
    assert P.num_particles == 117 and P.gdim == 2
    # the volumes (nearest-particle share of the cells' quadrature weights) sum to the area
    assert np.all(P.volumes > 0)
    assert abs(P.volumes.sum() - 6.0) <= 1e-12


def test_particles_at_the_nodes_get_their_voronoi_areas(msh):
    """Particles at the mesh nodes (spacing = cell size): by symmetry the nearest-particle shares
    of the cell quadrature are exactly the Voronoi areas, spacing^2 inside, half on an edge,
    a quarter at a corner. On quadrilaterals the 3 x 3 Gauss points on a cell's midlines lie on
    Voronoi edges and must be shared. On triangles the symmetry holds for every particle
    except the two box corners whose corner square is cut by a diagonal (there the coarse-rule
    limitation of the xfail test below applies)."""
    h = 0.5
    P = mf.ParticleSet.from_cells(msh, h)
    x = P.positions
    on_x = np.isclose(x[:, 0], 1.0) | np.isclose(x[:, 0], 4.0)
    on_y = np.isclose(x[:, 1], -1.0) | np.isclose(x[:, 1], 1.0)
    expected = h * h * np.where(on_x, 0.5, 1.0) * np.where(on_y, 0.5, 1.0)
    check = np.ones(P.num_particles, bool)
    if msh.topology.cell_type.name == "triangle":
        check = ~(on_x & on_y)
    np.testing.assert_allclose(P.volumes[check], expected[check], rtol=1e-12)


@pytest.mark.xfail(
    strict=True,
    reason="known limitation: volumes come from the cells' degree-4 quadrature points; with "
    "particle spacing 0.25 in 0.5 cells that is ~2 points per particle, so interior volumes "
    "of a regular grid are off by up to 30 % from the Voronoi area spacing^2",
)
def test_finer_particle_grid_volumes_are_voronoi_areas(msh):
    P = mf.ParticleSet.from_cells(msh, 0.25)
    interior = np.all((P.positions > [1.0, -1.0]) & (P.positions < [4.0, 1.0]), axis=1)
    np.testing.assert_allclose(P.volumes[interior], 0.0625, rtol=0.05)


def test_jitter_moves_interior_points_only(msh):
    spacing = 0.25
    regular = mf.ParticleSet.from_cells(msh, spacing)
    jittered = mf.ParticleSet.from_cells(msh, spacing, jitter=0.3, seed=4)
    moved = jittered.positions - regular.positions
    on_box = np.any(
        np.isclose(regular.positions, [1.0, -1.0]) | np.isclose(regular.positions, [4.0, 1.0]),
        axis=1,
    )
    assert np.all(moved[on_box] == 0.0)
    assert np.all(np.abs(moved) <= 0.3 * spacing + 1e-14)
    assert np.abs(moved[~on_box]).max() > 0.2 * spacing
    # same seed, same set; the set is replicated, so identical on every rank
    again = mf.ParticleSet.from_cells(msh, spacing, jitter=0.3, seed=4)
    np.testing.assert_array_equal(again.positions, jittered.positions)
    sums = COMM.allgather(float(np.sum(jittered.positions)))
    assert len(set(sums)) == 1
    assert abs(jittered.volumes.sum() - 6.0) <= 1e-12


def test_patch_of_cells(msh):
    """Particles filling the cells left of x = 2.5: they stay in the patch's closure and their
    volumes add up to the patch area."""
    num_owned = msh.topology.index_map(msh.topology.dim).size_local
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[:num_owned], :2]
    cells = np.flatnonzero(nodes[:, :, 0].max(axis=1) <= 2.5 + 1e-12)
    P = mf.ParticleSet.from_cells(msh, 0.25, cells=cells)
    assert P.positions[:, 0].max() <= 2.5 + 1e-12
    assert P.num_particles == 7 * 9
    assert abs(P.volumes.sum() - 1.5 * 2.0) <= 1e-12
    np.testing.assert_array_equal(P.cells, cells)


def test_ownership_follows_the_cells(msh):
    P = mf.ParticleSet.from_cells(msh, 0.5, jitter=0.2)
    from dolfinx_meshfree.approx.fe_points import locate_points

    here = locate_points(msh, P.positions) >= 0
    counts = COMM.allgather(P.owned.size)
    mine = np.zeros(P.num_particles, dtype=bool)
    mine[P.owned] = True
    # a particle this rank owns lies in one of its cells; particles in no cell of this rank
    # are owned elsewhere (shared boundaries go to the lowest rank)
    assert np.all(here[mine])
    assert np.all(P.owner[here] <= COMM.rank)
    assert sum(counts) == P.num_particles
    dofs = P.petsc_dofs(2)
    assert dofs.shape == (P.num_particles, 2)
    assert np.array_equal(np.sort(dofs.ravel()), np.arange(2 * P.num_particles))


def test_sph_takes_volumes_from_a_particle_set(msh):
    P = mf.ParticleSet.from_cells(msh, 0.25, jitter=0.2)
    sph = mf.SPH(P, correction="shepard")
    np.testing.assert_array_equal(sph.volumes, P.volumes)
    x = np.random.default_rng(COMM.rank).uniform([1.0, -1.0], [4.0, 1.0], (50, 2))
    table = sph.tabulate(x)
    assert np.abs(table.values.sum(axis=1) - 1.0).max() <= 1e-12
    grads = table.gradient(P.positions)
    assert np.abs(grads - np.eye(2)[None]).max() <= 1e-10 * 4.0 / 0.25
