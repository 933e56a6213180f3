"""Axisymmetric (r, z) models: the hoop strain and the 2 pi r weights
(``physics/axisymmetry.py``; issue 27, item 1).

Oracles: the axisymmetric patch test ``u = (a r, b z)`` (constant stress with ``s_rr = s_tt``,
reproduced exactly by the linear MLS basis: VCI must give it to round-off, the axis included);
Lamé's thick cylinder under internal pressure; the radial mode of a solid cylinder (Bessel
``J1``) and the breathing mode of a solid sphere (spherical Bessel ``j1``) in explicit dynamics,
each with its closed-form frequency (``demos/axisymmetric.py``). The same runs with
``plane="strain"`` miss the modes by about 200 %, so the checks can fail. Serial = 2 ranks: the
same figures on both (the suite runs both ways).
"""

from __future__ import annotations

import dataclasses

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.dynamics.rate_forms import RateLaw, stiffest_twin
from dolfinx_meshfree.geometry.quadrature import cell_quadrature
from dolfinx_meshfree.physics import axisymmetry
from dolfinx_meshfree.physics.forces import InternalForces

import dolfinx
import numpy as np
import pytest
import ufl
from conftest import conversion_balance, load_demo
from mpi4py import MPI
from scipy.special import j1

COMM = MPI.COMM_WORLD
demo = load_demo("axisymmetric")
MATERIAL = mf.LinearElastic(E=100.0, nu=0.3, plane="axisymmetric")


def section(r0, r1, h, nr, nz, cell):
    return dolfinx.mesh.create_rectangle(
        COMM, [np.array([r0, 0.0]), np.array([r1, h])], [nr, nz],
        getattr(dolfinx.mesh.CellType, cell),
    )  # fmt: skip


def patch_problem(cell, spacing, integration=None):
    """The solid cylinder ``0 <= r <= 1``, ``0 <= z <= 2`` loaded by the tractions of
    ``u = (a r, b z)``: held radially on the axis and axially on ``z = 0``."""
    msh = section(0.0, 1.0, 2.0, 5, 9, cell)
    prob = mf.EFGElasticity(mf.ParticleSet.from_cells(msh, spacing=spacing), MATERIAL,
                            integration=integration)  # fmt: skip
    return prob, patch_conditions(prob, msh)


def patch_conditions(prob, msh) -> tuple[float, float, float, float]:
    """The conditions of ``u = (a r, b z)`` on the section ``[0, 1] x [0, 2]``: the axis and
    ``z = 0`` held by component, the constant stress's tractions on ``r = 1`` and ``z = 2``.
    Returns ``(a, b, sigma_rr, sigma_zz)``."""
    a, b = 1e-3, -2e-3
    lam, mu = MATERIAL.lmbda, MATERIAL.mu
    srr, szz = lam * (2 * a + b) + 2 * mu * a, lam * (2 * a + b) + 2 * mu * b
    zero = lambda x: np.zeros_like(x)  # noqa: E731
    prob.add_dirichlet(demo.facets(msh, lambda x: np.isclose(x[0], 0.0)), zero, components=(0,))
    prob.add_dirichlet(demo.facets(msh, lambda x: np.isclose(x[1], 0.0)), zero, components=(1,))
    prob.add_traction(demo.facets(msh, lambda x: np.isclose(x[0], 1.0)),
                      lambda x, n: np.tile([srr, 0.0], (len(x), 1)))  # fmt: skip
    prob.add_traction(demo.facets(msh, lambda x: np.isclose(x[1], 2.0)),
                      lambda x, n: np.tile([0.0, szz], (len(x), 1)))  # fmt: skip
    return a, b, srr, szz


@pytest.mark.parametrize("cell, spacing", [("quadrilateral", 0.2), ("triangle", 0.13)])
def test_patch_test_is_exact_to_the_axis(cell, spacing):
    """VCI reproduces ``u = (a r, b z)`` to round-off, on the axis too (the stress there by the
    limit ``u_r / r -> du_r/dr``); plain Gauss misses it by about 6e-5 (so the check can fail)."""
    prob, (a, b, srr, szz) = patch_problem(cell, spacing)
    sol = prob.solve()
    x = np.vstack([np.random.default_rng(1).uniform([0, 0], [1, 2], (100, 2)),
                   [[0.0, 0.3], [0.0, 1.9]]])  # fmt: skip
    u, g = sol.evaluate(x)
    exact = np.column_stack([a * x[:, 0], b * x[:, 1]])
    assert np.abs(u - exact).max() < 1e-12 * abs(b) * 2 / 1e-3  # 2e-15 measured
    s = axisymmetry.stress(MATERIAL, x, u, g)
    assert np.allclose(s[:, 0, 0], srr, rtol=0, atol=1e-10 * abs(srr))
    assert np.allclose(s[:, 2, 2], srr, rtol=0, atol=1e-10 * abs(srr))  # s_tt = s_rr
    assert np.allclose(s[:, 1, 1], szz, rtol=0, atol=1e-10 * abs(szz))
    gauss, _ = patch_problem(cell, spacing, integration="gauss")
    miss = np.abs(gauss.solve().evaluate(x)[0] - exact).max() / abs(2 * b)
    assert miss > 1e-5  # 6.1e-5 (triangles), not exact: the consistency is VCI's doing


@pytest.mark.parametrize("method", demo.METHODS)
def test_lame_cylinder_converges(method):
    """Lamé's thick cylinder: the relative L2 error at 16 cells and the rate from 8 (FE, the
    user's own form with the helpers: 3.25e-4, rate 1.99; EFG: 5.0e-5, rate 2.24; lagrange,
    particles at the bore: 1.16e-4, rate 2.06; edge-to-edge: 1.61e-4, rate 2.12; bridging:
    1.19e-4, rate 2.12; ramp: 9.7e-5, rate 2.01; master-slave: 1.42e-4, rate 2.02; hybrid
    (smoothed strains): 3.7e-4, rate 2.64)."""
    coarse, fine = (demo.lame_cylinder(method, n)["l2"] for n in (8, 16))
    margin, (lo, hi) = demo.TARGETS[("lame", method)]
    assert fine < margin
    assert lo <= demo.rate(coarse, fine) <= hi


@pytest.mark.parametrize("method", demo.METHODS)
def test_spherical_shell_converges(method):
    """The thick spherical shell under internal pressure, its particles reaching the axis where
    the stress varies: the relative L2 error at 16 cells and the rate from 8 (measured FE
    1.52e-3 / 1.99, EFG 5.6e-4 / 2.14, lagrange 8.3e-4 / 2.09, edge-to-edge 4.4e-4 / 2.48,
    bridging 8.7e-4 / 2.15, ramp 7.6e-4 / 1.92, master-slave 7.2e-4 / 2.14, hybrid 1.4e-3 /
    2.51). With the axis
    offset taken off the test functions' hoop under VCI too (the first version), EFG gave 9.7e-3,
    lagrange 3.1e-2 (rate 0.72) and edge-to-edge 4.2e-2 (rate 0.17), while the patch tests held."""
    coarse, fine = (demo.spherical_shell(method, n)["l2"] for n in (8, 16))
    margin, (lo, hi) = demo.TARGETS[("shell", method)]
    assert fine < margin
    assert lo <= demo.rate(coarse, fine) <= hi


@pytest.mark.parametrize("shape", ["cylinder", "sphere"])
@pytest.mark.parametrize("method", demo.METHODS)
def test_breathing_modes_against_bessel(shape, method):
    """The radial mode of a solid cylinder and the breathing mode of a sphere over two periods:
    the error at 16 cells and the rate from 8 (measured: cylinder FE 6.5e-3 / 2.09, EFG 2.6e-3 /
    1.85, lagrange 3.3e-3 / 1.71 (its probe on the interface); sphere FE 1.24e-2 / 1.86, EFG
    1.43e-2 / 1.50, lagrange 4.5e-3 / 2.00; master-slave cylinder 9.8e-3 / 2.77, sphere 9.3e-3 /
    2.28; edge-to-edge cylinder 1.9e-2 / 2.32, sphere 1.8e-2 / 1.32, at 32 cells 4.3e-3 and
    3.5e-3; bridging 3.8e-3 / 1.96 and 5.3e-3 / 2.39: its band on the cylinder is cut by the
    rollers, whose redundant rows the velocity projection deflates; ramp (not VCI-corrected in
    dynamics) 2.0e-3 / 2.78 and 6.3e-3 / 1.99; hybrid 9.7e-3 / 1.27 and 2.3e-2 / 1.86, at 32
    cells 1.9e-3 and 4.7e-3), the discrete energy kept to round-off (1e-15)."""
    coarse, fine = (demo.breathing(shape, method, n) for n in (8, 16))
    margin, (lo, hi) = demo.TARGETS[(shape, method)]
    assert fine["error"] < margin
    assert lo <= demo.rate(coarse["error"], fine["error"]) <= hi
    assert max(coarse["drift"], fine["drift"]) < demo.DRIFT


@pytest.mark.parametrize(
    "coupling, options",
    [("lagrange", {}), ("edge-to-edge", {}), ("bridging", {}),
     ("bridging", {"constraint": "points", "penalty": 100.0}), ("ramp", {}), ("ramp-cubic", {})],
    ids=["lagrange", "edge-to-edge", "bridging", "bridging-points-penalty", "ramp", "ramp-cubic"],
)  # fmt: skip
@pytest.mark.parametrize(
    "cell, where",
    [("quadrilateral", lambda x: x[0] < 0.51), ("triangle", lambda x: (x[0] < 0.67) & (x[1] > 0.6)
     & (x[1] < 1.4))],
    ids=["axis", "inner"],
)  # fmt: skip
def test_interface_patch_test_is_exact(cell, where, coupling, options):
    """The lagrange coupling in axisymmetry (revolved interface multipliers, their projected
    normals in VCI, revolved loads and conditions): ``u = (a r, b z)`` to round-off with a patch
    on the axis (quadrilaterals) and one inside the section (triangles): 1.0e-14 and 6.2e-15
    measured; edge-to-edge (collocated multipliers, the particles' interpolant and its moment
    corrections under revolved weights) 3.9e-15 and 6.0e-15; bridging (the band's energies,
    its ``int N_k grad(alpha) 2 pi r`` in VCI, its constraint) 5.3e-15 and 4.1e-15, with point
    constraints and the penalty 5.5e-15 and 4.6e-15 serial, 1.2e-12 on 2 ranks (the penalty's
    conditioning under MUMPS's parallel ordering; the band term not revolved: 2.7e-2); the
    ramps (revolved blended cells with their hoop rows, VCI over patch and interface cells, the
    rollers held by component on their interface cells) 8.8e-15 / 5.2e-15 (ramp) and 4.8e-15 /
    1.1e-14 (cubic)."""
    msh = section(0.0, 1.0, 2.0, 6, 12, cell)
    patch = demo.patch_of(msh, where)
    V = _compat.vector_function_space(msh, 1)
    prob = mf.CoupledElasticity(V, patch, MATERIAL, coupling=coupling, **options)
    a, b, _, _ = patch_conditions(prob, msh)
    x = np.random.default_rng(0).uniform([0, 0], [1, 2], (200, 2))
    u = prob.solve().displacement(x)
    exact = np.column_stack([a * x[:, 0], b * x[:, 1]])
    bound = 2.5e-12 if options.get("penalty") else 5e-14
    assert np.abs(u - exact).max() < bound * abs(2 * b)


@pytest.mark.parametrize(
    "integration, where",
    [("smoothed", "axis"), ("smoothed", "rollers"), ("cells", "axis"), ("smoothed", "inner")],
)
def test_hybrid_patch_test_is_exact(integration, where):
    """The hybrid SPH–FE coupling in axisymmetry: its smoothed strains over revolved sub-cells
    (the edges carry ``r u``, the hoop ``N(x_k) / r_k``), or Gauss points with VCI, and the
    patch facets held by component (Nitsche's terms revolved, the axis by its penalty): ``u =
    (a r, b z)`` to round-off with a patch on the axis and the rollers, on the rollers only, and
    inside the section (measured 2.3e-15, 3.9e-15, 4.2e-15, 1.5e-15; with the rollers held by
    the multipliers instead of the smoothing edges' rule the test missed by 5.1e-5)."""
    cell = "triangle" if where == "inner" else "quadrilateral"
    msh = section(0.0, 1.0, 2.0, 6, 12, cell)
    marker = {
        "axis": lambda x: x[0] < 0.51,
        "rollers": lambda x: (x[0] > 0.3) & (x[0] < 0.7) & (x[1] < 0.7),
        "inner": lambda x: (x[0] < 0.67) & (x[1] > 0.6) & (x[1] < 1.4),
    }[where]
    V = _compat.vector_function_space(msh, 1)
    prob = mf.HybridElasticity(V, demo.patch_of(msh, marker), MATERIAL, integration=integration)
    a, b, _, _ = patch_conditions(prob, msh)
    x = np.random.default_rng(0).uniform([0, 0], [1, 2], (200, 2))
    u = prob.solve().displacement(x)
    exact = np.column_stack([a * x[:, 0], b * x[:, 1]])
    assert np.abs(u - exact).max() < 5e-14 * abs(2 * b)


@pytest.mark.parametrize("method", ["fe", "efg", "lagrange", "master-slave"])
def test_plane_strain_misses_the_mode(method):
    """Without the hoop strain the cylinder's mode is missed (1.99, 1.97, 1.98, 1.97 measured):
    the axisymmetric checks above can fail."""
    assert demo.breathing("cylinder", method, 16, plane="strain")["error"] > 0.5


def test_fe_forms_and_weights():
    """The helpers' form is the revolved strain energy: ``u = (r, 0)`` has the strain
    ``diag(1, 0, 1)`` in (r, z, theta), so ``sigma : eps = 4 lambda + 4 mu`` and the integral
    over the section ``1 <= r <= 2``, ``0 <= z <= 1`` with ``2 pi r dA`` is that times the
    revolved volume ``pi (2^2 - 1^2)``; the explicit FE model's lumped masses sum to
    ``rho`` times that volume."""
    msh = section(1.0, 2.0, 1.0, 4, 3, "triangle")
    V = _compat.vector_function_space(msh, 1)
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.vstack([x[0], 0.0 * x[0]]))
    energy = ufl.inner(axisymmetry.ufl_stress(u, MATERIAL), axisymmetry.ufl_strain(u))
    weight = 2 * ufl.pi * axisymmetry.radius(msh)
    value = COMM.allreduce(
        dolfinx.fem.assemble_scalar(_compat.create_form(energy * weight * ufl.dx)), op=MPI.SUM
    )
    volume = np.pi * (2.0**2 - 1.0**2)
    assert value == pytest.approx(4 * (MATERIAL.lmbda + MATERIAL.mu) * volume, rel=1e-12)
    rho = 3.0
    dyn = mf.ExplicitDynamics.fe(V, mf.LinearElastic(E=1.0, nu=0.3, rho=rho, plane="axisymmetric"))
    assert dyn.fields[0].mass.sum() / 2 == pytest.approx(rho * volume, rel=1e-12)  # 2 components


def test_refusals():
    """Every path without the hoop strain refuses an axisymmetric law by name; so do a
    section outside r >= 0 (named by coordinates), particles on an axis left free (named by a
    facet: measured, the radial mode then missed by 22 %) and a negative row-sum mass (named by
    the particle)."""
    msh = section(0.0, 2.0, 1.0, 8, 4, "quadrilateral")
    V = _compat.vector_function_space(msh, 1)
    cells = dolfinx.mesh.locate_entities(msh, 2, lambda x: x[0] > 0.99)
    patch = mf.ParticlePatch(msh, cells, placement="vertices")
    with pytest.raises(ValueError, match=r"axisymmetric.*no hoop strain"):
        MATERIAL.voigt()
    for options in ({"variant": "HA-S"}, {"integration": "particles"}):
        with pytest.raises(ValueError, match=r"axisymmetric hybrid is HA-F"):
            mf.HybridElasticity(V, patch, MATERIAL, **options)
    with pytest.raises(ValueError, match="ufl_stress"):
        mf.solve_fe_elasticity(V, MATERIAL)
    P = mf.ParticleSet.from_cells(msh, spacing=0.25)
    with pytest.raises(ValueError, match="integration='smoothed'"):
        mf.EFGElasticity(P, MATERIAL, integration="smoothed")
    steel = mf.LinearElastic(E=1.0, nu=0.3, rho=1.0, plane="axisymmetric")
    with pytest.raises(ValueError, match="particle_mass='volume'"):
        mf.ExplicitDynamics.efg(P, steel, particle_mass="volume")
    axis_free = r"on the axis r = 0 \(e\.g\. at \[0\.0, [0-9.]+\]\) have particles but"
    free = mf.EFGElasticity(P, MATERIAL)  # the axis left free: refused at the assembly
    with pytest.raises(ValueError, match=axis_free):
        free.solve()
    with pytest.raises(ValueError, match=axis_free):
        mf.ExplicitDynamics.efg(P, steel)
    on_axis = demo.patch_of(msh, lambda x: x[0] < 0.6)
    with pytest.raises(ValueError, match=axis_free):
        mf.ExplicitDynamics.coupled(mf.CoupledElasticity(V, on_axis, steel, coupling="lagrange"))
    left = section(-1.0, 1.0, 1.0, 4, 2, "triangle")
    with pytest.raises(ValueError, match=r"the point \[-[0-9.]+, [0-9.]+\] has r = x\[0\] < 0"):
        mf.EFGElasticity(mf.ParticleSet.from_cells(left, spacing=0.25), MATERIAL)
    with pytest.raises(ValueError, match=r"the particle at \[0.0, 0.9375\]"):
        demo.breathing("sphere", "efg", 16, dilation=2.0)


@pytest.mark.parametrize("name", ["hjc", "johnson-cook"])
def test_rate_law_point_is_the_3d_law_with_the_hoop_stretch(name):
    """An axisymmetric rate-form law at ``F`` (m, 2, 2) and the hoop stretch gives the 3D law's
    stress and state at the block-diagonal ``F`` (the independent computation); without the
    hoop stretch it refuses."""
    if name == "hjc":
        law3 = mf.HolmquistJohnsonCook.concrete_48mpa()
    else:
        law3 = mf.JohnsonCook.steel_4340()
    law = dataclasses.replace(law3, plane="axisymmetric")
    rng = np.random.default_rng(3)
    m = 40
    F = np.eye(2) + 3e-3 * rng.standard_normal((m, 2, 2))
    hoop = 1.0 + 3e-3 * rng.standard_normal(m)
    F3 = np.zeros((m, 3, 3))
    F3[:, :2, :2], F3[:, 2, 2] = F, hoop
    s3, state3 = law3.update(F3, 1e-6, law3.initial_state(m))
    s, state = law.update(F, 1e-6, law.initial_state(m), hoop=hoop)
    assert np.abs(s - s3).max() <= 1e-12 * np.abs(s3).max()
    for key in state3:
        np.testing.assert_allclose(state[key], state3[key], rtol=1e-12, atol=1e-300)
    with pytest.raises(ValueError, match="takes the hoop stretch"):
        law.update(F, 1e-6, law.initial_state(m))


#: Johnson–Cook steel kept elastic (a yield stress far above the mode's stress): the radial mode
#: of the cylinder from its velocity shape, as the linear run but through the rate-form law.
ELASTIC_JC = mf.JohnsonCook(rho=1.0, E=1.0, nu=0.3, A=1e6, B=0.0, n=1.0, C=0.0)


@pytest.mark.parametrize(
    "method, margin", [("fe", 1.5e-2), ("efg", 6e-3), ("lagrange", 8e-3), ("hybrid", 1.3e-2)]
)
def test_rate_law_radial_mode(method, margin):
    """A rate-form law in axisymmetry (``InternalForces``' hoop terms, the law's hoop stretch):
    the cylinder's radial mode started from its velocity (a rate law starts undeformed) follows
    ``J1(k r) sin(omega t)`` (measured at 16 cells: FE 7.3e-3, EFG 2.9e-3, a lagrange patch
    near the axis 4.0e-3, a hybrid one 6.3e-3 (its rate-law side takes the hoop of its smoothed
    strains); plane strain misses it by 223 %), the energy balance to 2.8e-6 (hypo-elastic at
    strain 1e-3)."""
    law = dataclasses.replace(ELASTIC_JC, plane="axisymmetric", viscosity=None)  # an elastic mode
    ka = demo.cylinder_wavenumber()
    msh = demo.rectangle(COMM, 0.0, 1.0, demo.SLICE, 16, 4)
    ends = demo.facets(msh, lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], demo.SLICE))
    axis = demo.facets(msh, lambda x: np.isclose(x[0], 0.0))
    fixed = [(ends, (1,)), (axis, (0,))]
    if method == "fe":
        dyn = mf.ExplicitDynamics.fe(_compat.vector_function_space(msh, 1), law,
                                     fixed_facets=fixed)  # fmt: skip
    elif method == "efg":
        P = mf.ParticleSet.from_cells(msh, spacing=1.0 / 16)
        dyn = mf.ExplicitDynamics.efg(P, law, fixed_facets=fixed)
    else:  # particles near the axis (r < 0.5), the probe on the interface
        V = _compat.vector_function_space(msh, 1)
        patch = demo.patch_of(msh, lambda x: x[0] < 0.5)
        problem = demo.coupled(V, patch, stiffest_twin(law), method)
        dyn = mf.ExplicitDynamics.coupled(problem, material=law, fixed_facets=fixed)
    omega = ka * stiffest_twin(law).wave_speed()
    amp = 1e-3
    dyn.set_initial(velocity=lambda x: np.column_stack([amp * omega * j1(ka * x[:, 0]),
                                                        0.0 * x[:, 0]]))  # fmt: skip
    probe = np.array([[0.5, 0.5 * demo.SLICE]])
    period = 2 * np.pi / omega
    seen = []

    def record(d, step, t):
        seen.append((t, d.displacement_at(probe)[0, 0]))

    res = dyn.run(2 * period, outputs=np.linspace(0, 2 * period, 41)[1:], on_output=record)
    t, u = np.array(seen).T
    exact = amp * j1(ka * 0.5) * np.sin(omega * t)
    assert np.abs(u - exact).max() / (amp * j1(ka * 0.5)) < margin
    assert res.energy_drift < 1e-5


@pytest.mark.parametrize("method", demo.METHODS)
def test_rods_meet_head_on(method):
    """Contact between bodies in axisymmetry: two rods on the axis (``nu = 0``) meet at +-10
    m/s. The force holds ``rho c v0 pi R^2`` for ``2 L / c`` and the faces overlap by about
    ``h rho c v0 / E`` (the penalty's closed form), within the demo's margins (about 2x the
    figures measured at 20 cells). FE's overlap checks the revolved tributary areas: with the
    plane lengths it was 59 times the closed form and the force +1275 % (measured by swapping
    them in)."""
    r = demo.rods(method, 20)
    for key, margin in demo.ROD_MARGINS[method].items():
        assert abs(r[key]) < margin, (key, r[key])
    assert r["parted"]


#: The concrete cylinders' section: radius, length (z along the axis, the wall at z = 0).
CYL_RADIUS, CYL_LENGTH = 0.02, 0.1


def concrete_cylinder(rollers: bool = True):
    """The cylinder's section (4 x 20 quadrilaterals) and its held facets: the wall, the axis
    held radially, and with ``rollers`` its side (``u_r = 0``: uniaxial strain)."""
    msh = section(0.0, CYL_RADIUS, CYL_LENGTH, 4, 20, "quadrilateral")
    fixed = [
        (demo.facets(msh, lambda x: np.isclose(x[1], 0.0)), (0, 1)),
        (demo.facets(msh, lambda x: np.isclose(x[0], 0.0)), (0,)),
    ]
    if rollers:
        fixed.append((demo.facets(msh, lambda x: np.isclose(x[0], CYL_RADIUS)), (0,)))
    return msh, fixed


def thrown(method, law, msh, fixed, v0, patch_cells=None):
    """The cylinder by ``method`` (fe, efg or a coupling with particles on ``patch_cells``, by
    default the quarter at the wall), thrown at the wall at ``v0``."""
    if method == "fe":
        dyn = mf.ExplicitDynamics.fe(_compat.vector_function_space(msh), law, fixed_facets=fixed)
    elif method == "efg":
        P = mf.ParticleSet.from_cells(msh, CYL_LENGTH / 20)
        dyn = mf.ExplicitDynamics.efg(P, law, fixed_facets=fixed)
    else:
        if patch_cells is None:
            patch = demo.patch_of(msh, lambda x: x[1] < CYL_LENGTH / 4)
        else:
            patch = mf.ParticlePatch(msh, patch_cells, CYL_LENGTH / 20)
        masses = mf.LinearElastic(30e9, 0.2, "axisymmetric", rho=law.rho)
        V = _compat.vector_function_space(msh)
        problem = demo.coupled(V, patch, masses, method, **demo.DYNAMIC_OPTIONS.get(method, {}))
        dyn = mf.ExplicitDynamics.coupled(problem, material=law, fixed_facets=fixed)
    dyn.set_initial(velocity=lambda x: np.column_stack([0.0 * x[:, 0], np.full(len(x), -v0)]))
    return dyn


def stress_behind(dyn, concrete, v0, depth):
    """The mean axial stress of the points with ``z < depth`` over the 1D ``-rho c v0``."""
    law = dyn.material
    behind = law.points[:, 1] < depth
    total = COMM.allreduce(np.array([law.sigma[behind, 1, 1].sum(), behind.sum()]))
    return total[0] / total[1] / (-concrete.rho * wave_speed(concrete) * v0)


def wave_speed(concrete) -> float:
    """HJC's elastic dilatational speed (region I)."""
    return float(np.sqrt((concrete.K_elastic + 4 * concrete.G / 3) / concrete.rho))


@pytest.mark.parametrize(
    "method, margin",
    [("fe", 0.012), ("efg", 0.03), ("lagrange", 0.016), ("master-slave", 2.2e-3),
     ("edge-to-edge", 0.004), ("bridging", 0.025), ("ramp", 0.05), ("hybrid", 0.025)],
)  # fmt: skip
def test_concrete_cylinder_elastic_wave(method, margin):
    """A cylinder of HJC concrete (radius 2 cm, length 10 cm, 20 cells along) on rollers
    (``u_r = 0`` on its side: uniaxial strain) thrown at a wall at 0.5 m/s: the stress behind
    the front at ``t = L / 2c`` is the 1D ``-rho c v0`` (measured 0.62 %, 1.56 %, 0.77 %,
    0.11 %, 0.19 %, 1.26 %, 2.37 % and 1.25 % off, the FE cells at their mean dilatation: with
    the full rule master-slave's was 0.025 % and edge-to-edge's 0.13 %) and the concrete stays
    undamaged. The
    rate-form law with the hoop stretch, in FE, EFG and a lagrange, master–slave, edge-to-edge,
    bridging, ramp or hybrid patch on the quarter at the wall (the ramp not VCI-corrected in
    dynamics)."""
    law = mf.HolmquistJohnsonCook.concrete_48mpa(plane="axisymmetric")
    v0 = 0.5
    dyn = thrown(method, law, *concrete_cylinder(), v0)
    dyn.run(0.5 * CYL_LENGTH / wave_speed(law))
    assert abs(stress_behind(dyn, law, v0, 0.3 * CYL_LENGTH) - 1.0) < margin
    state = dyn.material
    assert COMM.allreduce(float(state.state["damage"].max(initial=0.0)), op=MPI.MAX) == 0.0


def test_conversions_in_axisymmetry():
    """Failing FE cells become lagrange particles in an axisymmetric model
    (``dynamics.AdaptiveRun``): the concrete cylinder at 300 m/s with a free side, one row of
    particle cells at the wall to start. Every conversion keeps the revolved mass exactly and
    the momentum to round-off (measured: 7 conversions, mass error 0, momentum correction
    1.6e-16, the same on 2 ranks), and the balance with the conversions counted closes
    (measured -1.6e-3)."""
    law = mf.HolmquistJohnsonCook.concrete_48mpa(plane="axisymmetric")
    msh, fixed = concrete_cylinder(rollers=False)
    n = msh.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(msh, 2, np.arange(n, dtype=np.int32))
    first_row = np.flatnonzero(mid[:, 1] < CYL_LENGTH / 20)

    def build(cells=None):
        cells = first_row if cells is None else cells
        return thrown("lagrange", law, msh, fixed, 300.0, patch_cells=cells)

    run = mf.dynamics.AdaptiveRun(build, mf.StateAbove("damage", 0.1), check_every=5)
    dyn = run.run(20e-6)
    conversions = run.conversions
    assert len(conversions) >= 3
    assert max(c.mass_error for c in conversions) < 1e-14
    assert max(c.momentum_correction for c in conversions) < 1e-12
    assert abs(conversion_balance(dyn.stepper.records, conversions)) < 3e-3


@pytest.mark.parametrize("coupling", ["lagrange", "edge-to-edge", "bridging", "ramp"])
def test_user_forms_with_a_patch(coupling):
    """A user's own axisymmetric model (``a`` and ``L`` written with ``2 pi r dx`` and
    ``2 pi r ds``, ``DirichletBC`` on ``V.sub(i)``) gets a patch through
    ``CoupledLinearProblem``: the patch test ``u = (a r, b z)`` holds to round-off (the
    tractions' ``2 pi r`` is not counted twice), and a body force written in ``L`` gives the
    displacement of ``CoupledElasticity.set_body_force`` with the same load to round-off (the
    two load paths are independent: the form's integrand evaluated by DOLFINx against a
    callable). Measured: lagrange 6.3e-15 and 2.0e-15 (1.2e-14 and 2.6e-15 on 2 ranks),
    edge-to-edge 5.2e-15 and 2.0e-15 (1.7e-14, 2.4e-15), bridging 3.7e-15 and 4.5e-15 (1.4e-15,
    5.2e-15)."""
    msh = section(0.0, 1.0, 2.0, 6, 12, "triangle")
    a_, b_ = 1e-3, -2e-3
    lam, mu = MATERIAL.lmbda, MATERIAL.mu
    srr, szz = lam * (2 * a_ + b_) + 2 * mu * a_, lam * (2 * a_ + b_) + 2 * mu * b_
    V = _compat.vector_function_space(msh, 1)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    rev, dx = axisymmetry.measure(msh), ufl.dx(domain=msh)
    a = ufl.inner(axisymmetry.ufl_stress(u, MATERIAL), axisymmetry.ufl_strain(v)) * rev * dx
    outer = demo.facets(msh, lambda x: np.isclose(x[0], 1.0))
    top = demo.facets(msh, lambda x: np.isclose(x[1], 2.0))
    facets = np.concatenate([outer, top])
    order = np.argsort(facets)
    marks = np.concatenate([np.full(outer.size, 1), np.full(top.size, 2)]).astype(np.int32)
    tags = dolfinx.mesh.meshtags(msh, 1, facets[order], marks[order])
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    t_outer = dolfinx.fem.Constant(msh, np.array([srr, 0.0]))
    t_top = dolfinx.fem.Constant(msh, np.array([0.0, szz]))
    L = ufl.dot(t_outer, v) * rev * ds(1) + ufl.dot(t_top, v) * rev * ds(2)
    bcs = []
    for comp, marker in (
        (0, lambda x: np.isclose(x[0], 0.0)),
        (1, lambda x: np.isclose(x[1], 0.0)),
    ):
        Vi = V.sub(comp)
        dofs = dolfinx.fem.locate_dofs_topological(Vi, 1, demo.facets(msh, marker))
        bcs.append(dolfinx.fem.dirichletbc(np.float64(0.0), dofs, Vi))
    patch = demo.patch_of(msh, lambda x: (x[0] < 0.67) & (x[1] > 0.6) & (x[1] < 1.4))
    x = np.random.default_rng(2).uniform([0, 0], [1, 2], (200, 2))
    u_h = mf.CoupledLinearProblem(a, L, bcs, patch, MATERIAL, coupling).solve().displacement(x)
    exact = np.column_stack([a_ * x[:, 0], b_ * x[:, 1]])
    assert np.abs(u_h - exact).max() < 5e-14 * abs(2 * b_)
    # a body force in L against the same force given as a callable
    force = np.array([3.0, -2.0])
    f = dolfinx.fem.Constant(msh, force)
    body = ufl.dot(f, v) * rev * dx
    forms = mf.CoupledLinearProblem(a, body, bcs, patch, MATERIAL, coupling).solve()
    model = mf.CoupledElasticity(V, patch, MATERIAL, coupling=coupling)
    zero = lambda y: np.zeros_like(y)  # noqa: E731
    model.add_dirichlet(demo.facets(msh, lambda y: np.isclose(y[0], 0.0)), zero, components=(0,))
    model.add_dirichlet(demo.facets(msh, lambda y: np.isclose(y[1], 0.0)), zero, components=(1,))
    model.set_body_force(lambda y: np.tile(force, (len(y), 1)))
    u_f, u_c = forms.displacement(x), model.solve().displacement(x)
    assert np.abs(u_f - u_c).max() < 1e-10 * np.abs(u_c).max()


@pytest.mark.parametrize("method, margin", [("fe", 0.018), ("efg", 0.055)])
def test_zoned_cylinder(method, margin):
    """``MaterialZones`` of axisymmetric laws: a cylinder of HJC concrete (at the wall, z < L/2)
    under Johnson–Cook steel, on rollers, at 0.5 m/s. The lumped masses sum to the revolved
    zones' ``pi R^2 L / 2 (rho_c + rho_s)`` to round-off (measured 2e-16 FE, 1.8e-15 EFG), and
    behind the front, before it reaches the steel (``t = 0.45 L / c``), the concrete carries the
    1D ``-rho c v0`` (measured -0.86 % FE, +2.9 % EFG: the front's smear at that time)."""
    steel = mf.JohnsonCook.steel_4340(plane="axisymmetric")
    hjc = mf.HolmquistJohnsonCook.concrete_48mpa(plane="axisymmetric")
    v0 = 0.5
    zones = mf.MaterialZones(
        [(hjc, lambda x: x[1] < CYL_LENGTH / 2), (steel, lambda x: x[1] >= CYL_LENGTH / 2)]
    )
    dyn = thrown(method, zones, *concrete_cylinder(), v0)
    mass = dyn.fields[0].mass.sum() / 2  # two components per node or particle
    exact = np.pi * CYL_RADIUS**2 * CYL_LENGTH / 2 * (hjc.rho + steel.rho)
    assert mass == pytest.approx(exact, rel=1e-12)
    dyn.run(0.45 * CYL_LENGTH / wave_speed(hjc))
    assert abs(stress_behind(dyn, hjc, v0, 0.27 * CYL_LENGTH) - 1.0) < margin


@pytest.mark.parametrize("backend", ["scipy", "numba"])
def test_rate_law_tangent_has_the_hoop_rows(backend):
    """The tangent of an axisymmetric rate-form law (what the stable step is bounded with) is
    its twin's axisymmetric stiffness at rest, hoop rows included, on both assembly backends:
    against :func:`axisymmetric_stiffness` on the same table (an independent assembly), to
    round-off. The compiled backend returned the plane block alone (13 % of the stiffness
    missing) until the review of this stop."""
    if backend == "numba" and not jit.AVAILABLE:
        pytest.skip("numba is not installed")
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_SELF, [np.array([0.1, 0.0]), np.array([1.0, 1.0])], [4, 4],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    mls = mf.MLS(mf.ParticleSet.from_cells(msh, 0.25))
    law = RateLaw(mf.JohnsonCook.steel_4340(plane="axisymmetric"))
    q = axisymmetry.revolved(cell_quadrature(msh, 4))
    table = mls.tabulate(q.points)
    hoop = axisymmetry.hoop_table(table.values, q.points)
    expected = axisymmetry.axisymmetric_stiffness(
        table.gradients, hoop, q.weights, stiffest_twin(law.law)
    )
    forces = InternalForces(table, q.weights, law)
    K = forces.tangent(np.zeros(forces.num_dofs), backend=backend)
    assert abs(K - expected).max() <= 1e-12 * abs(expected).max()


#: Patches of the cylinder ``r < R = 0.1``, ``0 < z < 1`` (4 x 20 cells): marker of the patch
#: cells' midpoints, and the patch's revolved volume over ``pi R^2``.
HYBRID_PATCHES = {
    "top": (lambda x: x[1] > 0.7, 0.3),
    # one column on the axis: its centred particles are collinear, so particles are added
    # between them and the corners (hybrid_sph.centred_particles), off the cells' centres
    "axis column": (lambda x: x[0] < 0.025, 0.25**2),
    "staircase": (
        lambda x: (x[0] < 0.025) | ((x[0] < 0.05) & (x[1] > 0.5)),
        0.25**2 + (0.5**2 - 0.25**2) / 2,
    ),
}


@pytest.mark.parametrize(
    "particle_mass, shape",
    [("row-sum", "top"), ("volume", "top"), ("volume", "axis column"), ("volume", "staircase")],
)
def test_hybrid_masses_are_revolved(particle_mass, shape):
    """The axisymmetric hybrid's lumped masses (FE and SPH particles) sum to the revolved mass
    ``rho pi R^2 L`` of a cylinder, with either particle mass. ``"volume"``, the SPH mass
    ``rho V_I``, takes each particle's region revolved
    (``ParticleSet.revolved_volumes``), so the patch weighs its revolved volume to
    round-off whatever its shape. Before: the plane area (stop 48: the patch's particles were
    3.2x too heavy here and a rigid projectile struck it 24 % off the closed form,
    tests/test_rigid_projectile.py); then the area revolved at the particle's radius (stop 49),
    exact for the top patch only. The particles added off the cells' centres broke it: here
    one lands on the axis, and the axis column and the staircase were refused (a zero mass);
    on the Hanchak slab's one-column patch on the axis (24 cells) they sat off it, and the
    patch weighed 23 % too little, silently (a conversion changed the total by 2.7e-6)."""
    radius, length, rho = 0.1, 1.0, 7.0
    marker, fraction = HYBRID_PATCHES[shape]
    msh = section(0.0, radius, length, 4, 20, "quadrilateral")
    law = mf.LinearElastic(1e3, 0.25, "axisymmetric", rho=rho)
    axis = [(demo.facets(msh, lambda x: np.isclose(x[0], 0.0)), (0,))]
    patch = demo.patch_of(msh, marker)
    problem = mf.HybridElasticity(_compat.vector_function_space(msh), patch, law, variant="HA-F")
    dyn = mf.ExplicitDynamics.coupled(problem, particle_mass=particle_mass, fixed_facets=axis)
    total = sum(f.mass.sum() for f in dyn.fields) / 2  # two components per node or particle
    patch_mass = dyn.fields[1].mass.sum() / 2
    dyn.destroy()
    assert total == pytest.approx(rho * np.pi * radius**2 * length, rel=1e-12)
    exact = rho * np.pi * radius**2 * fraction * length
    # "row-sum": the SPH interpolant's row sums, not the regions (measured 0.2 %)
    assert patch_mass == pytest.approx(exact, rel=0.05 if particle_mass == "row-sum" else 1e-12)
