"""Pure FE with a law with state (``mf.FEElasticity``): the FE reference of the softening and
plasticity models, with the calls of the coupled ones (``add_dirichlet``, ``add_traction``,
``solve``, ``mf.follow_path``).

The checks are closed forms and exact properties (the ring's limit pressure is in
``tests/test_plastic_ring.py``):

- a bar in uniaxial tension (plane stress, nu = 0; quadrilaterals, triangles, hexahedra) carries
  a uniform strain, so its load-elongation curve is the law's bilinear softening curve (Bazant
  & Oh 1983) with the crack band of the cell size, and the energy it dissipates is ``G_f / h``
  per unit volume, written out in ``tests/test_softening.py``'s helpers;
- a bar with a notch (a column of cells narrower, top and bottom) localises in that column: the
  energy it dissipates is ``G_f`` times the notch's section whatever the mesh (the crack band's
  objectivity, issue 24's "two FE meshes"), and its peak is the same on both meshes;
- the same bar on coarse meshes localises too (a step that jumps onto a branch where columns
  outside the control's gauge soften is cut: ``follow_path``'s ``LEVER_JUMP``);
- the control quantity's functional equals the FE field's point values;
- what has no answer says why: a control quantity that turns (its maximum along the path), a
  load above the limit load, and what an FE model does not carry.

Serial and 2 ranks.
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.statics import path_following as pf
from dolfinx_meshfree.statics.fe_model import fe_point_functional

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI
from test_softening import _capped_dissipation, _closed_form

E, FT, GF = 1000.0, 1.0, 0.02
L, W = 2.0, 1.0


def _bar(msh, law, gdim: int = 2):
    """The model: held at x = 0, a unit traction along x at x = L."""
    model = mf.FEElasticity(_compat.vector_function_space(msh), law)
    model.add_dirichlet(mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0)), np.zeros_like)
    load = np.eye(gdim)[0]
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    model.add_traction(right, lambda p, nrm: np.tile(load, (len(p), 1)))
    return model


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle", "hexahedron"])
def test_fe_bar_follows_the_closed_form_through_the_peak(cell):
    """The load factor on the closed-form curve at every step (measured 8e-15 f_t quadrilaterals,
    1.2e-14 triangles; checked 1e-9), the dissipated energy the closed form's (1e-9), the energy
    balance (external work - stored) to the trapezoidal rule's 2e-3 (measured 1.4e-4), Newton in
    at most 6 iterations a step (measured 2)."""
    n = 4 if cell != "hexahedron" else 2
    if cell == "hexahedron":
        msh = dolfinx.mesh.create_box(
            MPI.COMM_WORLD, [np.zeros(3), np.array([L, W, W])], [2 * n, n, n],
            dolfinx.mesh.CellType.hexahedron,
        )  # fmt: skip
        law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane=None)
        point, direction = [L, 0.5, 0.5], [1.0, 0.0, 0.0]
    else:
        msh = dolfinx.mesh.create_rectangle(
            MPI.COMM_WORLD, [[0, 0], [L, W]], [2 * n, n], getattr(dolfinx.mesh.CellType, cell)
        )
        law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")
        point, direction = [L, 0.5], [1.0, 0.0]
    model = _bar(msh, law, msh.geometry.dim)
    h = W / n  # the band: the cells' size (squares and cubes, or halves of squares)
    eps_f = 2.0 * GF / (FT * h)
    end = 1.25 * eps_f * L  # past full softening
    control = mf.DisplacementControl([point], [direction])
    res = mf.follow_path(model, control, mf.PathOptions(5e-4, end, max_increment=end / 20))
    eps = np.array(res.control) / L
    t = np.array(res.load_factor)
    assert eps.min() < FT / E < eps.max()  # through the peak
    assert t[-1] < 0.05 * FT  # softened to the residual stiffness
    assert np.abs(t - _closed_form(eps, h, law.max_damage)).max() < 1e-9 * FT
    volume = L * W * (W if cell == "hexahedron" else 1.0)
    expected = _capped_dissipation(h, law.max_damage) * volume
    assert res.dissipated_energy[-1] == pytest.approx(expected, rel=1e-9)
    balance = res.external_work[-1] - res.stored_energy[-1]
    assert balance == pytest.approx(res.dissipated_energy[-1], rel=2e-3)
    assert max(res.iterations) <= 6
    (state,) = res.solution.states  # the FE cells' points, every one damaged alike
    assert np.ptp(state.committed["damage"]) < 1e-12


def test_load_steps_commit_the_state():
    """``solve(load_steps=)`` below the peak: the elongation of ``0.9 f_t / E`` exactly
    (1e-10), no damage committed, one state store."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [6, 3], dolfinx.mesh.CellType.quadrilateral
    )
    law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")
    model = mf.FEElasticity(_compat.vector_function_space(msh), law)
    model.add_dirichlet(mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0)), np.zeros_like)
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    model.add_traction(right, lambda p, nrm: np.tile([0.9 * FT, 0.0], (len(p), 1)))
    sol = model.solve(load_steps=3)
    (state,) = sol.states
    assert np.all(state.committed["damage"] == 0.0)
    assert len(sol.newton.steps) == 3
    u = sol.displacement(np.array([[L, 0.5]]))
    assert u[0, 0] == pytest.approx(0.9 * FT / E * L, rel=1e-10)


def _notched(n: int, method: str = "fe", cell: str = "quadrilateral", options=None):
    """The bar with the column of cells ``1 <= x <= 1 + 1 / n`` 0.9 W high (centred): a
    rectangle of the weakest section, and the elongation across it controlled; ``method``:
    plain FE, or a coupling with its patch on ``0.5 <= x <= 1.5``; ``options``: the path's, by
    default to an opening of ``2 w_c``."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [2 * n, n], getattr(dolfinx.mesh.CellType, cell)
    )
    x = msh.geometry.x
    column = (x[:, 0] > 1.0 - 1e-9) & (x[:, 0] < 1.0 + 1.0 / n + 1e-9)
    x[column, 1] = 0.5 + (x[column, 1] - 0.5) * 0.9
    law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")
    if method == "fe":
        model = _bar(msh, law)
    else:
        mid = dolfinx.mesh.locate_entities(
            msh, 2, lambda p: (p[0] > 0.5 - 1e-9) & (p[0] < 1.5 + 1e-9)
        )
        patch = mf.ParticlePatch(msh, mid, placement="vertices")
        model = mf.CoupledElasticity(
            _compat.vector_function_space(msh), patch, law, coupling=method
        )
        model.add_dirichlet(mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0)), np.zeros_like)
        right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
        model.add_traction(right, lambda p, nrm: np.tile([1.0, 0.0], (len(p), 1)))
    control = mf.DisplacementControl([[0.5, 0.5], [1.5, 0.5]], [[-1, 0], [1, 0]])
    options = options or mf.PathOptions(increment=2e-4, end=0.08, max_increment=4e-3)
    return mf.follow_path(model, control, options)


def test_fe_crack_band_is_objective_in_the_mesh():
    """The notched bar at 8 and 12 cells across: the energy dissipated once the band is open
    (an opening of twice ``w_c = 2 G_f / f_t``) is ``G_f`` times the notch's section (measured
    1.020 and 1.003 of it; checked 4 %), the same on both meshes (1.6 %; the issue's target 3 %),
    and the peaks agree: 0.035 % (checked 0.07 %) on paths that step by 2.5e-5 to just past
    the peak (1.25e-5: 0.033 %). The default paths step by 1.7e-4 and 1.1e-4 near the peak,
    and their largest steps differ by 0.12 %: the peak falls between steps, differently on each
    mesh (0.034 % before the first step's convergence test was fixed, by how they fell)."""
    runs = [_notched(n) for n in (8, 12)]
    area = 0.9 * W
    ratios = [r.dissipated_energy[-1] / (GF * area) for r in runs]
    fine = mf.PathOptions(increment=2.5e-5, end=1.6e-3, grow=1.0)  # the peak at about 1.1e-3
    peaks = []
    for n in (8, 12):
        load = _notched(n, options=fine).load_factor
        assert load[-1] < max(load)  # past the peak
        peaks.append(max(load))
    print(f"energy / (G_f area) {ratios}, peaks {peaks}")
    for r, ratio in zip(runs, ratios, strict=True):
        assert abs(ratio - 1.0) < 0.04
        assert r.control[-1] == pytest.approx(0.08)
        assert r.load_factor[-1] < 0.1 * r.peak[0]  # the band is open
    assert abs(ratios[1] - ratios[0]) < 0.03 * ratios[0]
    assert abs(peaks[1] - peaks[0]) < 7e-4 * peaks[0]
    assert 0.85 * FT < peaks[0] < 0.9 * FT  # the notch's section carries f_t at most


@pytest.mark.parametrize(
    "method, cell, n, bound",
    [
        ("fe", "quadrilateral", 4, 0.05),
        ("fe", "triangle", 6, 0.05),
        ("lagrange", "quadrilateral", 4, 0.3),
    ],
)
def test_a_coarse_bar_localises(method, cell, n, bound):
    """The notched bar on coarse meshes. At the peak Newton's predictor overshot it (load factor
    1.107 against 0.886, above every column's strength) and the step converged where columns
    outside the controlled gauge had softened too: 3.8 to 5.2 times ``G_f`` times the notch's
    section dissipated, silently (FE at 4 and 6 cells across, lagrange at 4). The load's work
    per unit of control jumped 18.5-24.8-fold in that step; such a step is now cut. Measured
    now: 1.037 (FE quadrilaterals, 4), 1.028 (FE triangles, 6) and 1.145 (lagrange, 4: its MLS
    band spreads wider than a cell) of ``G_f`` times the section; checked within 5 % (FE) and
    30 % (lagrange)."""
    res = _notched(n, method, cell)
    ratio = res.dissipated_energy[-1] / (GF * 0.9 * W)
    assert 1.0 - 0.05 < ratio < 1.0 + bound
    assert res.load_factor[-1] < 0.1 * res.peak[0]


def test_a_lever_through_zero_is_not_a_jump():
    """The branch guard measures a step's lever from the last step's or from ``LEVER_FLOOR``
    times the path's first, if larger. The unnotched concrete beam under CMOD control
    (``demos/concrete_beam.py --notch-depth 0 --path found``, lane B) had its lever 135.8 at the
    first step, and 0.024 where the deflection turned forward again past its snap-back: the
    next step's 0.82 was a 33-fold "jump", every cut's 0.49 20.3-fold, and the path stopped at
    step 22. Measured from the floor it is 0.06. A lever below zero (past a snap-back) is measured
    from the floor too; a branch jump of the coarse bars (from 0.97 of the first lever to 20
    times it) stays a jump; no lever measured, no jump."""
    assert pf._lever_jump(0.02437, 135.75, 0.8202) == pytest.approx(0.8202 / 13.575, rel=1e-12)
    assert pf._lever_jump(0.02437, 135.75, 0.8202) < pf.LEVER_JUMP < 0.8202 / 0.02437
    assert pf._lever_jump(-0.19, 135.75, 0.75) == pytest.approx(0.75 / 13.575, rel=1e-12)
    assert pf._lever_jump(-0.19, 135.75, 100.0) > pf.LEVER_JUMP
    assert pf._lever_jump(0.97, 1.0, 20.0) == pytest.approx(20.0 / 0.97, rel=1e-12)
    assert pf._lever_jump(None, 1.0, 20.0) == pf._lever_jump(0.97, 1.0, None) == 0.0
    assert pf._lever_jump(-1.0, 0.0, 20.0) == 0.0


def test_the_control_functional_is_the_point_values():
    """``fe_point_functional`` against DOLFINx-style evaluation of a random field at points
    inside cells, on a vertex and on the boundary (1e-13)."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [5, 3], dolfinx.mesh.CellType.triangle
    )
    V = _compat.vector_function_space(msh)
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.vstack([np.sin(3 * x[0]) + x[1], np.cos(2 * x[1]) * x[0]]))
    points = np.array([[0.31, 0.27], [0.8, 1.0 / 3.0], [L, 0.5], [1.234, 0.99]])
    directions = np.array([[1.0, -2.0], [0.5, 0.0], [0.0, 1.0], [-1.0, 1.0]])
    w = fe_point_functional(V, points, directions)
    n = V.dofmap.index_map.size_local * 2
    value = msh.comm.allreduce(float(w @ u.x.array[:n]))
    expected = float(np.sum(mf.evaluate_fe_function(u, points) * directions))
    assert value == pytest.approx(expected, abs=1e-13)


def test_bad_input_is_refused():
    """A finite-strain law, a P2 space, a law of the wrong dimension, cracks or a patch to grow
    along the path, and an elastic path are refused by name, on every rank."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [4, 2], dolfinx.mesh.CellType.quadrilateral
    )
    V = _compat.vector_function_space(msh)
    law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")
    with pytest.raises(TypeError, match="FENonlinearProblem"):
        mf.FEElasticity(V, mf.NeoHookean(E, 0.3, plane="strain"))
    with pytest.raises(ValueError, match="degree-1 Lagrange"):
        mf.FEElasticity(_compat.vector_function_space(msh, 2), law)
    with pytest.raises(ValueError, match="plane=None on a 3D"):
        mf.FEElasticity(V, mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane=None))
    model = _bar(msh, law)
    control = mf.DisplacementControl([[L, 0.5]], [[1.0, 0.0]])
    options = mf.PathOptions(1e-4, 1e-3)
    with pytest.raises(ValueError, match="FE cells carry no crack"):
        mf.follow_path(model, control, options, adapt=mf.NearTips())
    left = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0))
    with pytest.raises(ValueError, match="components=\\(2,\\)"):
        model.add_dirichlet(left, np.zeros_like, (2,))
    elastic = _bar(msh, mf.LinearElastic(E, 0.0, plane="stress"))
    with pytest.raises(ValueError, match="straight path; solve it"):
        mf.follow_path(elastic, control, options)
    # its elastic solve: the uniform strain 1 / E of the unit traction
    u = elastic.solve().displacement(np.array([[L, 0.5]]))
    assert u[0, 0] == pytest.approx(L / E, rel=1e-10)


def test_a_load_above_the_limit_load_says_so():
    """``solve(load_steps=)`` with a traction of 1.2 sigma_y on a J2 strip (plane stress, held
    at one end): no equilibrium beyond the limit load ``sigma_y W``. Before, the plane-stress
    return map's failure at Newton's overshooting iterate escaped as an ``ArithmeticError``
    advising smaller load steps (and, raised on some ranks only, could hang the others); now
    Newton's line search shortens such a step, the load step is cut, and the error names the
    last converged load factor (0.832 of 1.2, 0.998 sigma_y: below the limit) and
    ``follow_path``."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [8, 4], dolfinx.mesh.CellType.quadrilateral
    )
    law = mf.J2Plasticity(E=E, nu=0.3, sigma_y=FT, H=0.0, plane="stress")
    model = mf.FEElasticity(_compat.vector_function_space(msh), law)
    model.add_dirichlet(mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0)), np.zeros_like)
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    model.add_traction(right, lambda p, nrm: np.tile([1.2 * FT, 0.0], (len(p), 1)))
    with pytest.raises(mf.NewtonError, match="No equilibrium was found from load factor") as e:
        model.solve(load_steps=4)
    last = float(str(e.value).split("from load factor ")[1].split(" ")[0])
    assert 0.75 < 1.2 * last <= 1.0  # converged up to near the limit, not past it
    assert "follow_path" in str(e.value)


def test_a_control_that_turns_is_named():
    """A bar notched on its top edge only, controlled by the elongation of its bottom edge: as
    the notch's corners soften the bar bends and that edge stops lengthening (a maximum of the
    control along the path), so no increment has a solution. The error says that the
    control's growth per unit load fell (measured 0.23 of the first step's) and asks for
    another control, not a smaller increment."""
    n = 4
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [2 * n, n], dolfinx.mesh.CellType.quadrilateral
    )
    x = msh.geometry.x
    x[(x[:, 0] > 1.0 - 1e-9) & (x[:, 0] < 1.0 + 1.0 / n + 1e-9), 1] *= 0.9  # the top notch
    model = _bar(msh, mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress"))
    bottom = mf.DisplacementControl([[0.5, 0.0], [1.5, 0.0]], [[-1, 0], [1, 0]])
    with pytest.raises(mf.PathError, match="the control quantity's growth per unit load fell"):
        mf.follow_path(model, bottom, mf.PathOptions(2e-4, 0.05, max_increment=8e-3))
