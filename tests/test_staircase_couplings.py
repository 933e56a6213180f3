"""The Lagrange and edge-to-edge couplings on staircase interfaces.

A patch chosen by a slanted criterion meets the FE cells on a staircase of mesh facets, which
turns by 90 degrees at every node (``demos/robustness.py``, quadrilaterals, patch above
y = 0.7 + 0.4 x). Oracles: the plain FE error of the same model on the same mesh (DOLFINx's own
assembly), and the exact polynomial solution.

- Lagrange: the multipliers are the FE traces of the interface nodes (Rabczuk et al. 2006,
  eq. 109), continuous along the whole interface by default; the earlier default split them at
  every turn of more than 30 degrees (``corner_angle=30``), which doubles them on a staircase
  and over-constrains the particles.
- Edge-to-edge: consistent integration writes the interface term with the interpolant of the
  particle functions on the interface particles (``I_P``); with the FE interpolant (``I_h``,
  the earlier choice) particles between the FE nodes (spacing 0.5 h) spoiled the corrected
  gradients.
"""

from __future__ import annotations

import dolfinx_meshfree as mf

import dolfinx
import numpy as np
import pytest
from conftest import load_demo
from mpi4py import MPI

demo = load_demo("robustness")
LINEAR = demo.QuadraticField(demo.C0, demo.G0, np.zeros((2, 2, 2)))


def _errors(level, coupling="lagrange", patch="slanted", spacing="1", load="none", exact=None,
            **options) -> tuple[float, float]:  # fmt: skip
    """Coupled and plain FE relative L2 errors on quadrilaterals."""
    msh, h = demo.build_mesh(MPI.COMM_WORLD, "quadrilateral", level)
    model = demo.user_model(msh, load)
    if exact is not None:  # the same model with another exact field (no body load)
        model = _with_exact(model, exact, load)
    cells = demo.make_patch(msh, patch, spacing, h)
    problem = mf.CoupledLinearProblem(
        model.a, model.L, model.bcs, cells, material=demo.MATERIAL, coupling=coupling, **options
    )
    solution = problem.solve()
    coupled = mf.error_norms(msh, solution.evaluate_at_quadrature, model.exact, demo.MATERIAL)
    return coupled["l2"], demo.solve_plain_fe(model)["l2"]


def _with_exact(model, exact, load):
    import ufl

    V = model.V
    msh = V.mesh
    g = dolfinx.fem.Function(V)
    g.interpolate(lambda p: exact.displacement(p[:2].T).T)
    dofs = dolfinx.fem.locate_dofs_topological(V, 1, model.dirichlet_facets)
    v = ufl.TestFunction(V)
    L = ufl.dot(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.dx
    if load == "traction":
        facets = model.traction_facets
        tags = dolfinx.mesh.meshtags(msh, 1, facets, np.full(facets.size, 5, dtype=np.int32))
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        sigma = demo.MATERIAL.ufl_stress(exact.ufl(ufl.SpatialCoordinate(msh)))
        L = L + ufl.dot(sigma * ufl.FacetNormal(msh), v) * ds(5)
    bcs = [dolfinx.fem.dirichletbc(g, dofs)]
    return demo.Model(V, model.a, L, bcs, exact, None, model.traction_facets,
                      model.dirichlet_facets)  # fmt: skip


def test_lagrange_trace_multipliers_on_a_staircase_match_fe():
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


@pytest.mark.parametrize("corner_angle", [None, 30.0])
def test_lagrange_passes_the_linear_patch_test_on_a_staircase(corner_angle):
    """Consistent integration with the multipliers' projected normals: a linear field is
    reproduced to round-off with continuous multipliers on the staircase, where ``n`` jumps at
    every node, as with the split ones (measured 6e-16 and 8e-16 relative L2)."""
    e, _ = _errors(0, exact=LINEAR, corner_angle=corner_angle)
    assert e <= 1e-10, e


@pytest.mark.parametrize("load", ["none", "traction"])
def test_edge_to_edge_passes_the_linear_patch_test_with_particles_between_nodes(load):
    """Spacing 0.5 h puts interface particles between the FE nodes; with the interface
    particles' interpolant in consistent integration the linear patch test passes to round-off
    (measured 3e-16 to 3e-15 on quadrilateral, triangle and gmsh staircases)."""
    e, _ = _errors(0, "edge-to-edge", spacing="0.5", load=load, exact=LINEAR)
    assert e <= 1e-10, e


@pytest.mark.parametrize(
    "patch, load, measured",
    [("axis", "traction", 1.01), ("slanted", "none", 1.04)],
)
def test_edge_to_edge_with_particles_between_nodes_matches_fe(patch, load, measured):
    """Spacing 0.5 h: 1.01x (axis patch, traction) and 1.04x (staircase, no load) the FE error at
    h = 1/12, rates 2.02 and 1.99 (measured); with the FE interpolant in consistent integration
    they were 1.34x (rate 1.98) and 1.53x (rate 1.66). Bounds: the issue's target 1.2x, rate in
    [1.8, 2.5]."""
    e0, _ = _errors(0, "edge-to-edge", patch=patch, spacing="0.5", load=load)
    e1, f1 = _errors(1, "edge-to-edge", patch=patch, spacing="0.5", load=load)
    rate = np.log2(e0 / e1)
    assert e1 <= 1.2 * f1, (e1 / f1, measured)
    assert 1.8 <= rate <= 2.5, rate


@pytest.mark.parametrize(
    "patch, measured, before",
    [("axis", 0.86, 1.40), ("curved", 0.86, 1.46)],
)
def test_edge_to_edge_with_traction_matches_fe(patch, measured, before):
    """Traction on the right and top edges, spacing h: 0.86x the FE error at h = 1/12 on the
    axis patch (interface ending on the loaded top edge) and on the curved staircase, rates
    2.01 (measured). Before, consistent integration carried the interface interpolant's
    mismatch ``I_P phi_J - phi_J`` with one constant per particle, which samples the stress at
    the support's centroid instead of on the interface: 1.40x and 1.46x (rates 1.99, 1.95),
    the error largest where the interface meets the free edge. Bounds: the issue's target
    1.2x, rate in [1.8, 2.5]."""
    e0, _ = _errors(0, "edge-to-edge", patch=patch, load="traction")
    e1, f1 = _errors(1, "edge-to-edge", patch=patch, load="traction")
    rate = np.log2(e0 / e1)
    assert e1 <= 1.2 * f1, (e1 / f1, measured, before)
    assert 1.8 <= rate <= 2.5, rate


@pytest.mark.parametrize("angle", [0.0, 90.0, 120.0, "30"])
def test_bad_corner_angle_is_refused(angle):
    msh, h = demo.build_mesh(MPI.COMM_WORLD, "quadrilateral", 0)
    model = demo.user_model(msh, "none")
    patch = demo.make_patch(msh, "slanted", "1", h)
    with pytest.raises(ValueError, match="corner_angle="):
        mf.CoupledElasticity(model.V, patch, demo.MATERIAL, "lagrange", corner_angle=angle)
