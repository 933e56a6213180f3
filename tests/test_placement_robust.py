"""Particle placement that always works (issue 8, item 2).

Every coupling on quadrilaterals and triangles, with a patch chosen by an axis-aligned, a slanted
and a curved criterion (its border a staircase off the grid lines), particles at 0.5 h, 0.75 h,
h, 1.5 h (the default ``placement="conforming"``) or on the vertices: the patch builds, the
coupled linear patch test runs and passes to the coupling's level, and the MLS moment matrices
are well conditioned at the quadrature points of the patch cells (and of the ramp's interface
cells). The old grid placement fails these (kept as ``placement="grid"``).
"""

from __future__ import annotations

import dolfinx_meshfree as mf  # (first: lane B's MPI)
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx.mls import MLS
from dolfinx_meshfree.couplings.ramp import RampInterface
from dolfinx_meshfree.parallel import raise_on_all_ranks

import dolfinx
import numpy as np
import pytest
from conftest import CELL_TYPES, load_demo
from mpi4py import MPI

N = 8  # cells per side of the unit square
H = 1.0 / N

#: Patch criteria on the cell centroids: on grid lines, slanted, and a quarter disc (curved).
PATCHES = {
    "axis-aligned": lambda c: c[:, 0] > 0.5,
    "slanted": lambda c: c[:, 1] > 0.4 * c[:, 0] + 0.2,
    "curved": lambda c: np.hypot(c[:, 0] - 1.0, c[:, 1]) < 0.6,
}
#: Particle spacings in element sizes; "vertices": placement="vertices".
SPACINGS = (0.5, 0.75, 1.0, 1.5, "vertices")

#: Largest nodal error of the linear patch test (consistent=True) per coupling. The variational
#: couplings reproduce linear fields (measured <= 5e-12 over the matrix, serial and 2 ranks);
#: bridging (integral constraint) is exact on the axis-aligned patches and reaches 1.4e-3 on the
#: staircase bands (alpha's gradient off the multiplier space; issue 8, item 3), master-slave's
#: rigid layer 7.8e-2 (first order): bounds about 2x those figures.
LEVEL = {
    "lagrange": 1e-10,
    "edge-to-edge": 1e-10,
    "ramp": 1e-10,
    "ramp-cubic": 1e-10,
    "bridging": 3e-3,
    "master-slave": 0.15,
}

#: Smallest eigenvalue ratio of the scaled moment matrix at the Gauss points: patch cells
#: (dilation 2; measured >= 1.9e-2 with the conforming placement, down to 1.5e-3 with the grid
#: on the slanted patch at 0.75 h) and the ramp's patch and interface cells (measured >= 9.5e-4,
#: on the vertices of the curved quadrilateral patch, the paper's radii; >= 3.7e-3 otherwise):
#: bounds about half the measured minima.
RCOND_PATCH, RCOND_RAMP = 1e-2, 5e-4

_MESHES: dict = {}


def mesh(cell: str):
    if cell not in _MESHES:
        msh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, N, N, CELL_TYPES[cell])
        n = msh.topology.index_map(2).size_local
        centroids = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
        _MESHES[cell] = (msh, centroids)
    return _MESHES[cell]


def make_patch(cell: str, shape: str, spacing, placement: str = "conforming"):
    msh, centroids = mesh(cell)
    cells = np.flatnonzero(PATCHES[shape](centroids))
    if spacing == "vertices":
        return msh, mf.ParticlePatch(msh, cells, placement="vertices")
    return msh, mf.ParticlePatch(msh, cells, spacing * H, placement=placement)


def patch_test_error(msh, patch, coupling: str) -> float:
    """Largest error of the coupled solution of u = c + G x (Dirichlet on the whole boundary)
    at the particles and at 200 random points (every rank evaluates its share)."""
    exact = mf.LinearField(G=((0.3, -0.2), (0.5, 0.1)), c=(0.1, -0.4))
    options = {"constraint": "integral"} if coupling == "bridging" else {}
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh),
        patch,
        mf.LinearElastic(1000.0, 0.3),
        coupling=coupling,
        consistent=True,
        **options,
    )
    problem.add_dirichlet(mf.boundary_facets(msh), exact.displacement)
    sol = problem.solve()
    comm = msh.comm
    pts = np.vstack([patch.particles.positions, np.random.default_rng(7).uniform(0, 1, (200, 2))])
    mine = pts[comm.rank :: comm.size]
    err = np.abs(sol.displacement(mine) - exact.displacement(mine)).max(initial=0.0)
    return comm.allreduce(float(err), op=MPI.MAX)


@pytest.mark.parametrize("spacing", SPACINGS)
@pytest.mark.parametrize("shape", PATCHES)
@pytest.mark.parametrize("cell", CELL_TYPES)
@pytest.mark.parametrize("coupling", mf.COUPLINGS)
def test_every_coupling_passes_the_patch_test_whatever_the_patch(coupling, cell, shape, spacing):
    msh, patch = make_patch(cell, shape, spacing)
    assert patch_test_error(msh, patch, coupling) <= LEVEL[coupling]


def moment_matrices_are_well_conditioned(comm, mls: MLS, points: np.ndarray, rcond: float) -> None:
    """Raises MomentMatrixError (on every rank) where the scaled moment matrix's eigenvalue
    ratio at this rank's ``points`` is below ``rcond``."""
    strict = MLS(mls.points, mls.weight_name, mls.dilation, mls.basis, radii=mls.radii, rcond=rcond)
    raise_on_all_ranks(comm, lambda: strict.tabulate(points, 0))


@pytest.mark.parametrize("spacing", SPACINGS)
@pytest.mark.parametrize("shape", PATCHES)
@pytest.mark.parametrize("cell", CELL_TYPES)
def test_moment_matrices_are_well_conditioned_in_patch_and_interface_cells(cell, shape, spacing):
    msh, patch = make_patch(cell, shape, spacing)
    V = _compat.vector_function_space(msh)
    material = mf.LinearElastic(1000.0, 0.3)
    q = mf.cell_quadrature(msh, 7, patch.cells)
    lagrange = mf.CoupledElasticity(V, patch, material, coupling="lagrange")
    moment_matrices_are_well_conditioned(msh.comm, lagrange.mls, q.points, RCOND_PATCH)
    ramp = mf.CoupledElasticity(V, patch, material, coupling="ramp")
    qi = mf.cell_quadrature(msh, 7, RampInterface(ramp).cells)
    points = np.vstack([q.points, qi.points])
    moment_matrices_are_well_conditioned(msh.comm, ramp.mls, points, RCOND_RAMP)


def test_the_grid_placement_is_ill_conditioned_on_a_slanted_patch():
    """The check above can fail: the clipped grid leaves the slanted border thin."""
    msh, patch = make_patch("quadrilateral", "slanted", 0.75, placement="grid")
    mls = mf.CoupledElasticity(
        _compat.vector_function_space(msh), patch, mf.LinearElastic(1000.0, 0.3)
    ).mls
    with pytest.raises(ValueError, match="ill-conditioned"):  # (MomentMatrixError on its rank)
        moment_matrices_are_well_conditioned(
            msh.comm, mls, mf.cell_quadrature(msh, 7, patch.cells).points, RCOND_PATCH
        )


@pytest.mark.parametrize("spacing", [0.5, 0.75, 1.0, 1.5])
@pytest.mark.parametrize("shape", PATCHES)
def test_conforming_placement_puts_particles_on_every_border_vertex(shape, spacing):
    msh, patch = make_patch("triangle", shape, spacing)
    facets = patch.boundary()[0]
    ends = msh.geometry.x[_compat.entities_to_geometry(msh, 1, facets), :2].reshape(-1, 2)
    ends = np.concatenate(msh.comm.allgather(ends))
    x = patch.particles.positions
    dist = np.min(np.linalg.norm(ends[:, None, :] - x[None, :, :], axis=2), axis=1)
    assert dist.max() <= 1e-12
    # and no two particles closer than a quarter of the finer of spacing and element size
    gap = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2) + np.eye(len(x))
    assert gap.min() >= 0.25 * min(spacing, 1.0) * H


@pytest.mark.parametrize("cell", CELL_TYPES)
def test_conforming_placement_is_the_grid_where_the_grid_conforms(cell):
    """Axis-aligned patch, spacing dividing h: the same particles in the same order."""
    for spacing in (0.5, 1.0):
        grid = make_patch(cell, "axis-aligned", spacing, placement="grid")[1].particles
        conforming = make_patch(cell, "axis-aligned", spacing)[1].particles
        assert np.array_equal(grid.positions, conforming.positions)


def test_ramp_refusals_name_the_fix():
    msh, patch = make_patch("quadrilateral", "slanted", 0.75, placement="grid")
    V = _compat.vector_function_space(msh)
    material = mf.LinearElastic(1000.0, 0.3)
    problem = mf.CoupledElasticity(V, patch, material, coupling="ramp")
    with pytest.raises(ValueError, match=r"placement='grid'.*placement='vertices'") as e:
        problem.solve()
    assert "the node at [" in str(e.value)  # by coordinates
    msh, patch = make_patch("quadrilateral", "axis-aligned", 0.5)
    problem = mf.CoupledElasticity(V, patch, material, coupling="ramp", dilation=1.2)
    with pytest.raises(ValueError, match=r"dilation d_max = 1.2: increase dilation"):
        problem.solve()


def test_bridging_point_constraints_with_coarse_particles_name_the_fix():
    msh, patch = make_patch("quadrilateral", "axis-aligned", 1.5)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh),
        patch,
        mf.LinearElastic(1000.0, 0.3),
        "bridging",
        constraint="points",
    )
    problem.add_dirichlet(mf.boundary_facets(msh), lambda x: np.zeros_like(x))
    with pytest.raises(ValueError, match="use constraint='integral'"):
        problem.solve()


def test_cantilever_demo_runs_at_every_patch_fraction():
    """The warm-up used a two-cell mesh where a fraction below 1/4 selected no cell."""
    cantilever = load_demo("cantilever")
    for fraction in (0.05, 0.25):
        records = cantilever.main(
            ["--method", "lagrange", "--h", "3", "--patch-fraction", str(fraction), "--no-check"]
        )
        assert records[0]["particle_dofs"] > 0
    with pytest.raises(SystemExit):  # at h = 3 the last cells' centroids lie at x = 46.5
        cantilever.parse(["--method", "lagrange", "--h", "3", "--patch-fraction", "0.03"])
