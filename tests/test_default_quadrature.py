"""The particle stiffness's default Gauss rule follows the particles: at least 15 points per
particle (``geometry.quadrature.particle_quadrature_degree``). The expected degrees are worked
out by hand from the rules' point counts: a square cell with a particle at each vertex has one
particle per cell, so 4 x 4 points (degree 7); with particles at ``h / 2`` it has four, so 60
points are needed and 8 x 8 (degree 15) is the first square rule with as many; a triangle (half
a square) with particles at ``h / 2`` has two, 30 points, and basix's triangle rules have 28 at
degree 11 and 37 at 13; a cube at ``h / 2`` has eight, 120 points, 5 x 5 x 5 (degree 9); a
tetrahedron (a sixth of a cube) at ``h / 2`` has 4/3, 20 points, fewer than the 64 of degree 7.
A model with cracks keeps 7. Why the default matters is checked in ``test_smoothing.py`` (VCI's
stall on 4 x 4 points)."""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import pytest
from conftest import beam_mesh
from mpi4py import MPI
from test_efg_3d import MATERIAL as MATERIAL3
from test_efg_3d import unit_cube

MATERIAL = mf.LinearElastic(3e7, 0.3)


@pytest.mark.parametrize(
    ("cell", "ratio", "degree"),
    [
        ("quadrilateral", None, 7),
        ("quadrilateral", 1.5, 11),
        ("quadrilateral", 2.0, 15),
        ("triangle", None, 7),
        ("triangle", 2.0, 13),
    ],
)
def test_efg_default_degree(cell, ratio, degree):
    """Particles at the vertices (``ratio`` None) or at ``h / ratio``; the same on 2 ranks."""
    msh = beam_mesh(MPI.COMM_WORLD, 2.0, cell)
    particles = (
        mf.ParticleSet.from_vertices(msh)
        if ratio is None
        else mf.ParticleSet.from_cells(msh, 2.0 / ratio)
    )
    assert mf.EFGElasticity(particles, MATERIAL).quadrature_degree == degree
    # a jittered grid counts as many particles per cell
    if ratio == 2.0:
        jittered = mf.ParticleSet.from_cells(msh, 2.0 / ratio, jitter=0.3)
        assert mf.EFGElasticity(jittered, MATERIAL).quadrature_degree == degree
    # a degree given is kept
    assert mf.EFGElasticity(particles, MATERIAL, quadrature_degree=5).quadrature_degree == 5


@pytest.mark.parametrize(("cell", "degree"), [("hexahedron", 9), ("tetrahedron", 7)])
def test_efg_default_degree_3d(cell, degree):
    msh = unit_cube(MPI.COMM_WORLD, 4, cell)
    particles = mf.ParticleSet.from_cells(msh, 0.125)
    assert mf.EFGElasticity(particles, MATERIAL3).quadrature_degree == degree


def test_coupled_default_degree():
    """The patch's particles and cells set it: at the vertices or at ``h`` 7, at ``h / 2`` 15."""
    msh = beam_mesh(MPI.COMM_WORLD, 2.0)
    V = _compat.vector_function_space(msh)
    cells = dolfinx.mesh.locate_entities(msh, 2, lambda x: x[0] > 24.0 - 1e-9)
    for options, degree in (
        ({"placement": "vertices"}, 7),
        ({"spacing": 2.0}, 7),
        ({"spacing": 1.0}, 15),
    ):
        patch = mf.ParticlePatch(msh, cells, **options)
        assert mf.CoupledElasticity(V, patch, MATERIAL).quadrature_degree == degree
    with pytest.raises(ValueError, match=r"quadrature_degree=0 must be an integer >= 1"):
        mf.CoupledElasticity(V, patch, MATERIAL, quadrature_degree=0)


def test_cracked_models_keep_degree_7():
    """With cracks the default stays 7 (a finer rule on the crack faces met one-sided supports
    too thin for the MLS beside an edge crack's mouth: the SIF reliability sweep)."""
    msh = beam_mesh(MPI.COMM_WORLD, 2.0)
    crack = mf.Crack([[0.0, 0.5], [10.0, 0.5]])
    particles = mf.ParticleSet.from_cells(msh, 1.0)
    assert mf.EFGElasticity(particles, MATERIAL, cracks=[crack]).quadrature_degree == 7
    assert mf.EFGElasticity(particles, MATERIAL).quadrature_degree == 15


@pytest.mark.parametrize("bad", [0, -3, True, 2.5, "7"])
def test_bad_degree(bad):
    msh = beam_mesh(MPI.COMM_WORLD, 4.0)
    with pytest.raises(ValueError, match=rf"quadrature_degree={bad!r} must be an integer >= 1"):
        mf.EFGElasticity(mf.ParticleSet.from_vertices(msh), MATERIAL, quadrature_degree=bad)
