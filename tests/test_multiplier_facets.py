"""3D Dirichlet conditions on particle facets need particles on the facets
(:func:`~dolfinx_meshfree.statics.efg.check_multiplier_facets`): with particles only at the
facets' vertices (pure EFG at the vertices, the couplings' default placement at a spacing of
the element size) the piecewise-constant multipliers make a singular or nearly singular saddle
point, and the solution was wrong without an error.

The model: the unit cube, 4 cells per side, the half x > 1/2 a particle patch (or pure EFG on
the whole cube), a quadratic field with its body force and its values on the whole boundary
(``tests/test_couplings_3d.py``'s problem). Measured relative L2 errors at a spacing of the
element size, with the check bypassed: tetrahedra lagrange 4.4e-2, edge-to-edge 0.52 (lane A)
and 8.6e-2 (lane B), bridging 96; at 0.75 h: 1.6e-2 to 1.9e-2 (hexahedra 1.3e-2 to 1.5e-2).
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree.couplings import assembly

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI
from test_couplings_3d import coupled
from test_efg_3d import MATERIAL, QUADRATIC, particles_for, unit_cube

N = 4


def quadratic_error(cell_name: str, coupling: str, spacing: float) -> float:
    msh = unit_cube(MPI.COMM_WORLD, N, cell_name)
    num = msh.topology.index_map(3).size_local
    mid = dolfinx.mesh.compute_midpoints(msh, 3, np.arange(num, dtype=np.int32))
    patch = mf.ParticlePatch(msh, np.flatnonzero(mid[:, 0] > 0.5), spacing=spacing / N)
    problem = coupled(msh, patch, coupling)
    problem.add_dirichlet(mf.boundary_facets(msh), QUADRATIC.displacement)
    b = QUADRATIC.body_force
    problem.set_body_force(lambda x: np.tile(b, (x.shape[0], 1)))
    sol = problem.solve()
    return mf.error_norms(msh, sol.evaluate_at_quadrature, QUADRATIC, MATERIAL, degree=6)["l2"]


@pytest.mark.parametrize("cell_name", ["tetrahedron", "hexahedron"])
@pytest.mark.parametrize("coupling", ["lagrange", "edge-to-edge", "bridging"])
def test_particles_only_at_the_vertices_are_refused(cell_name, coupling):
    """At a spacing of the element size: refused on every rank, naming a facet and the fix."""
    with pytest.raises(ValueError, match=r"median share of .* spacing below the element size"):
        quadratic_error(cell_name, coupling, 1.0)


@pytest.mark.parametrize("cell_name", ["tetrahedron", "hexahedron"])
def test_finer_particles_pass(cell_name):
    """At 0.75 h the check passes and the error is that of the coupled method (measured 1.64e-2
    tetrahedra, 1.33e-2 hexahedra, lagrange; bound 2x)."""
    measured = {"tetrahedron": 1.64e-2, "hexahedron": 1.33e-2}[cell_name]
    assert quadratic_error(cell_name, "lagrange", 0.75) <= 2.0 * measured


def test_the_check_guards_a_wrong_answer(monkeypatch):
    """Bypassed, the tetrahedral bridging model at spacing h solves without an error and is
    wrong: measured 96 relative L2 error against 1.9e-2 at 0.75 h (5100x) in both lanes;
    bound 2000x. (Edge-to-edge is wrong too, by an amount that depends on the round-off: 30x
    in lane A, 5.0x in lane B.)"""
    good = quadratic_error("tetrahedron", "bridging", 0.75)
    monkeypatch.setattr(assembly, "check_multiplier_facets", lambda *args: None)
    assert quadratic_error("tetrahedron", "bridging", 1.0) > 2000.0 * good


def test_pure_efg_at_the_vertices_is_refused():
    """Pure EFG with particles at the hexahedra's vertices (measured 0.52 relative L2 error
    at n = 3 with the check bypassed, 8.7e-3 at h / 2): refused; at h / 2 it passes."""
    for placement in ("vertices", "half"):
        msh = unit_cube(MPI.COMM_WORLD, 3, "hexahedron")
        problem = mf.EFGElasticity(particles_for(msh, 3, placement), MATERIAL)
        problem.add_dirichlet(mf.boundary_facets(msh), QUADRATIC.displacement)
        if placement == "vertices":
            with pytest.raises(ValueError, match="carry a median share"):
                problem.solve()
        else:
            problem.solve()
