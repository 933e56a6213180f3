"""The multiplier space of the Lagrange (compatibility) coupling on staircase interfaces.

A patch chosen by a slanted criterion meets the FE cells on a staircase of mesh facets, which
turns by 90 degrees at every node. The multipliers are the FE traces of the interface nodes
(Rabczuk et al. 2006, eq. 109), continuous along the whole interface by default; the earlier
default split them at every turn of more than 30 degrees (``corner_angle=30``), which doubles
them on a staircase and over-constrains the particles. Oracles: the plain FE error of the same
model on the same mesh (DOLFINx's own assembly), and the exact polynomial solution.
"""

from __future__ import annotations

import dolfinx_meshfree as mf

import numpy as np
import pytest
from conftest import load_demo
from mpi4py import MPI

demo = load_demo("robustness")


def _errors(level: int, load: str = "none", exact=None, **options) -> tuple[float, float]:
    """Coupled and plain FE L2 errors, quadrilaterals, slanted patch, spacing h."""
    msh, h = demo.build_mesh(MPI.COMM_WORLD, "quadrilateral", level)
    model = demo.user_model(msh, load)
    if exact is not None:
        model = demo.Model(model.V, model.a, model.L, _bcs(model, exact), exact, None,
                           model.traction_facets, model.dirichlet_facets)  # fmt: skip
    patch = demo.make_patch(msh, "slanted", "1", h)
    problem = mf.CoupledLinearProblem(
        model.a, model.L, model.bcs, patch, material=demo.MATERIAL, coupling="lagrange", **options
    )
    solution = problem.solve()
    coupled = mf.error_norms(msh, solution.evaluate_at_quadrature, model.exact, demo.MATERIAL)
    return coupled["l2"], demo.solve_plain_fe(model)["l2"]


def _bcs(model, exact):
    import dolfinx

    g = dolfinx.fem.Function(model.V)
    g.interpolate(lambda p: exact.displacement(p[:2].T).T)
    dofs = dolfinx.fem.locate_dofs_topological(model.V, 1, model.dirichlet_facets)
    return [dolfinx.fem.dirichletbc(g, dofs)]


def test_trace_multipliers_on_a_staircase_match_fe():
    """Default (continuous trace multipliers): 1.10x the FE error at h = 1/12, rate 2.80
    (measured); with the split at corners (``corner_angle=30``, the earlier default) 2.23x,
    rate 2.52. Bounds: the issue's target 1.2x and rate >= 1.8 (rate <= 3.5: an error that
    falls much faster than FE's is large on the coarse mesh); the split kept above 1.6x so that
    the comparison shows what the default fixes."""
    e0, _ = _errors(0)
    e1, f1 = _errors(1)
    rate = np.log2(e0 / e1)
    assert e1 <= 1.2 * f1, e1 / f1
    assert 1.8 <= rate <= 3.5, rate
    s1, _ = _errors(1, corner_angle=30.0)
    assert s1 >= 1.6 * f1, s1 / f1  # measured 2.23


def test_trace_multipliers_pass_the_linear_patch_test_on_a_staircase():
    """Consistent integration with the multipliers' projected normals: a linear field is
    reproduced to round-off with continuous multipliers on the staircase, where ``n`` jumps at
    every node (measured 6e-16 relative L2; the plain FE 5e-16)."""
    linear = demo.QuadraticField(demo.C0, demo.G0, np.zeros((2, 2, 2)))
    e, _ = _errors(0, exact=linear)
    assert e <= 1e-10, e


@pytest.mark.parametrize("angle", [0.0, 90.0, 120.0, "30"])
def test_bad_corner_angle_is_refused(angle):
    msh, h = demo.build_mesh(MPI.COMM_WORLD, "quadrilateral", 0)
    model = demo.user_model(msh, "none")
    patch = demo.make_patch(msh, "slanted", "1", h)
    with pytest.raises(ValueError, match="corner_angle="):
        mf.CoupledElasticity(model.V, patch, demo.MATERIAL, "lagrange", corner_angle=angle)
