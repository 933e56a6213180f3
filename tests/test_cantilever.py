"""Convergence on the Timoshenko cantilever (Belytschko et al. 1995, sec. 5.1.2, eq. 5.2–5.3).

L = 48, D = 12, E = 3e7, nu = 0.3, P = 1000: exact displacement on x = 0, parabolic shear on
x = L. The rates are fitted with ``np.polyfit`` over h = 3, 1.5, 1 (16 x 4 to 48 x 12 cells):
P1/Q1 finite elements converge at 2 in L2 and 1 in energy; EFG with a linear basis converges at
(at least) 2 in L2 with a smaller error constant than FE on the same grid.
"""

import dolfinx_meshfree as mf

import numpy as np
import pytest
from conftest import (
    beam_mesh,
    efg_errors,
    fe_errors,
    fitted_rate,
    solve_beam_efg,
    solve_beam_fe,
)
from mpi4py import MPI

H = np.array([3.0, 1.5, 1.0])


def beam(plane):
    return mf.TimoshenkoBeam(mf.LinearElastic(3e7, 0.3, plane))


#: (plane, background cell type) of the EFG runs; FE always runs on the same mesh
CASES = [("stress", "quadrilateral"), ("strain", "quadrilateral"), ("stress", "triangle")]


@pytest.fixture(scope="module")
def series():
    """FE and EFG errors over the refinement series, computed once for the module."""
    out = {}
    for plane, cell_name in CASES:
        b = beam(plane)
        fe, efg = [], []
        for h in H:
            msh = beam_mesh(MPI.COMM_WORLD, h, cell_name)
            fe.append(fe_errors(msh, solve_beam_fe(msh, b), b))
            efg.append(efg_errors(msh, solve_beam_efg(msh, b, h), b))
        out[plane, cell_name] = (fe, efg)
    return out


@pytest.mark.parametrize("plane", ["stress", "strain"])
def test_fe_cantilever_converges_at_the_optimal_rates(series, plane):
    # Q1 elements; (P1 triangles lock in bending and are still pre-asymptotic on this series)
    fe, _ = series[plane, "quadrilateral"]
    l2 = [e["l2"] for e in fe]
    energy = [e["energy"] for e in fe]
    assert np.all(np.diff(l2) < 0) and np.all(np.diff(energy) < 0)
    # measured (stress / strain): L2 rate 1.97 / 1.96, energy 0.99 / 0.99; errors at h = 1: L2
    # 3.2e-3 / 3.8e-3, energy 5.9e-2 / 6.4e-2 (converges to the right solution)
    assert 1.9 <= fitted_rate(H, l2) <= 2.1
    assert 0.9 <= fitted_rate(H, energy) <= 1.1
    assert l2[-1] < 8e-3 and energy[-1] < 0.1


@pytest.mark.parametrize("plane, cell_name", CASES)
def test_efg_cantilever_converges_and_beats_fe(series, plane, cell_name):
    fe, efg = series[plane, cell_name]
    l2 = np.array([e["l2"] for e in efg])
    energy = np.array([e["energy"] for e in efg])
    # measured over the three cases: L2 rate 2.70-2.90, energy 1.37-1.39; L2 error at h = 1
    # 8.2e-5 to 1.1e-4 (bounds: two-sided rates, twice the largest error)
    assert 2.4 <= fitted_rate(H, l2) <= 3.2
    assert 1.2 <= fitted_rate(H, energy) <= 1.6
    assert l2[-1] < 2.5e-4
    # EFG (linear basis, quartic weight, d_max = 2) is more accurate than FE on the same grid:
    # L2 0.005-0.067 x FE's, energy 0.05-0.20 x (bounds: about twice the largest ratio)
    assert np.all(l2 <= 0.15 * np.array([e["l2"] for e in fe]))
    assert np.all(energy <= 0.4 * np.array([e["energy"] for e in fe]))


def test_plane_strain_solution_differs_from_plane_stress(series):
    """The plane-strain runs solve a different problem (E' = E/(1-nu^2), nu' = nu/(1-nu))."""
    x = np.array([[48.0, 0.0], [24.0, 3.0]])
    stress, strain = beam("stress"), beam("strain")
    ratio = strain.displacement(x)[0, 1] / stress.displacement(x)[0, 1]
    assert 0.85 < ratio < 0.95  # tip deflection about (1 - nu^2) times smaller
    assert series["strain", "quadrilateral"][1][-1]["l2"] < 1e-3


def test_error_norms_of_the_exact_solution_vanish():
    """The error functional itself: zero for the exact field, nonzero for a perturbed one."""
    b = beam("stress")
    msh = beam_mesh(MPI.COMM_WORLD, 3.0)
    exact = mf.error_norms(
        msh, lambda q: (b.displacement(q.points), b.displacement_gradient(q.points)), b, b.material
    )
    assert exact["l2"] == 0.0 and exact["energy"] == 0.0

    def scaled(q):
        return 1.01 * b.displacement(q.points), 1.01 * b.displacement_gradient(q.points)

    off = mf.error_norms(msh, scaled, b, b.material)
    assert abs(off["l2"] - 0.01) <= 1e-12 and abs(off["energy"] - 0.01) <= 1e-12
