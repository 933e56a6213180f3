"""Particle placement in a ParticlePatch: on a grid of given spacing, or on the cells' vertices
(the choice for unstructured meshes and curved interfaces)."""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI


def test_vertex_placement_puts_one_particle_on_every_patch_vertex():
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_unit_square(comm, 5, 4, dolfinx.mesh.CellType.triangle)
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(mid[:, 0] > 0.6), placement="vertices")
    x = patch.particles.positions
    # columns x = 0.6, 0.8, 1.0 of the 6 x 5 vertex grid
    expected = np.array([[i / 5, j / 4] for i in (3, 4, 5) for j in range(5)])
    assert x.shape == expected.shape
    assert np.allclose(
        np.sort(x.view("f8,f8"), axis=0).view(float),
        np.sort(expected.view("f8,f8"), axis=0).view(float),
    )
    assert len({(len(p), float(p.sum())) for p in comm.allgather(x)}) == 1


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"placement": "random"}, r"placement='random' is not known"),
        ({}, r"spacing=None: give the particle spacing"),
        ({"placement": "vertices", "spacing": 0.1}, r"spacing=0.1 and jitter=0.0 must be left out"),
    ],
)
def test_placement_errors(kwargs, match):
    msh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    with pytest.raises(ValueError, match=match):
        mf.ParticlePatch(msh, np.arange(1), **kwargs)
