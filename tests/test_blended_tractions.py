"""Tractions of explicit dynamics on the ramps' interface cells and on bridging's band: the
blended functions (Belytschko et al. 1995, eq. 3.15; Rabczuk et al. 2006, eq. 49), so that a
patch may reach a loaded edge (as an adaptive patch does when it grows to it).

Oracle: the blended functions are a partition of unity and reproduce linear fields, so the
load vector's resultant ``sum_I f_I`` and first moment ``sum_I f_I y_I`` (nodes and particles at
their positions) are the exact integrals ``int t ds`` and ``int t y ds`` of the traction, here
in closed form. A misrouted or dropped share (an FE node on the interface, a particle column)
changes them.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

COMM = MPI.COMM_WORLD
MATERIAL = mf.LinearElastic(1000.0, 0.3, plane="strain", rho=1.0)


def traction(x, n):
    """``t(y) = (1 + y, 2 y)`` on the edge x = 1."""
    return np.stack([1.0 + x[:, 1], 2.0 * x[:, 1]], axis=1)


#: ``int_0^1 t dy`` and ``int_0^1 t y dy``.
RESULTANT = np.array([1.5, 1.0])
MOMENT = np.array([1.0 / 2.0 + 1.0 / 3.0, 2.0 / 3.0])


@pytest.mark.parametrize(
    "coupling, cell_type",
    [
        ("ramp", dolfinx.mesh.CellType.quadrilateral),
        ("ramp-cubic", dolfinx.mesh.CellType.triangle),
        ("bridging", dolfinx.mesh.CellType.quadrilateral),
        ("lagrange", dolfinx.mesh.CellType.triangle),
    ],
)
def test_traction_across_the_interface(coupling, cell_type):
    """The patch (cells within 0.3 of (1, 0.5)) meets the loaded edge x = 1, whose facets lie
    on FE cells, particle cells and interface or band cells: resultant and first moment to
    1e-12 (measured at most 4.4e-16); dropping the blended share misses them by 0.1 to 0.5."""
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.array([0.0, 0.0]), np.array([1.0, 1.0])], [12, 12], cell_type
    )
    cells = mf.cells_near(msh, np.array([[1.0, 0.5]]), 0.3)
    patch = mf.ParticlePatch(msh, cells, 0.7 / 12)
    problem = mf.CoupledElasticity(_compat.vector_function_space(msh), patch, MATERIAL, coupling)
    dyn = mf.ExplicitDynamics.coupled(problem)
    right = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 1.0))
    blended = dyn.evaluator.disc.blended_cells()
    if blended is not None:  # the edge does cross blended cells
        msh.topology.create_connectivity(1, 2)
        f2c = msh.topology.connectivity(1, 2)
        first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[right]]
        assert COMM.allreduce(int(blended[first].sum())) >= 2
    dyn.add_traction(right, traction)
    vecs, _ = dyn.loads.loads[-1]
    force, moment = np.zeros(2), np.zeros(2)
    for k, b in enumerate(vecs):
        f = b.array_r.reshape(-1, 2)
        y = dyn.evaluator.disc.owned_points(k)[:, 1]
        force += f.sum(axis=0)
        moment += (f * y[:, None]).sum(axis=0)
    force, moment = COMM.allreduce(force), COMM.allreduce(moment)
    assert np.abs(force - RESULTANT).max() <= 1e-12
    assert np.abs(moment - MOMENT).max() <= 1e-12
