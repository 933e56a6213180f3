"""Cavity expansion in a rate-form material (``verification/cavity_expansion.py``): Hill's
closed form, the ogive integral's closed forms, mesh independence, the package's axisymmetric FE
model of the same cylinder (HJC concrete and Johnson–Cook steel, its cells at their mean
dilatation and at the full rule, which locks), bad input.

Serial: the 1D cavity is NumPy on each rank, with no parallel code path; the FE cylinder uses
the explicit dynamics, rate law and driven wall that their own tests run on 2 ranks."""

from __future__ import annotations

import dataclasses

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

#: An elastic–perfectly-plastic Mises steel: Johnson–Cook without hardening or rate.
STEEL_PLAIN = {"rho": 7830.0, "E": 200e9, "nu": 0.29, "A": 792e6, "B": 0.0, "n": 1.0, "C": 0.0}
STEEL = mf.JohnsonCook(**STEEL_PLAIN)


@pytest.mark.serial
def test_cavity_pressure_meets_hill():
    """A cavity expanded at 100 m/s in an elastic–perfectly-plastic Mises steel: its pressure
    less the inertial ``3/2 rho V^2`` (the incompressible plastic zone's) meets Hill's
    quasi-static closed form, 3,049 MPa, within 1 % (measured -0.50 % with 20 zones per radius;
    -0.13 % at 50 m/s, where the inertial term's share is smaller, with 40), and is steady
    over the last 30 % of the growth (the self-similar regime)."""
    cavity = mf.cavity_expansion(STEEL, 100.0, cells=20)
    hill = mf.hill_cavity_pressure(STEEL.E, STEEL.nu, STEEL.A)
    assert hill == pytest.approx(3.049e9, rel=1e-3)
    assert abs((cavity.pressure - 1.5 * STEEL.rho * 100.0**2) / hill - 1.0) < 0.01
    assert cavity.spread < 0.01 * cavity.pressure


@pytest.mark.serial
def test_hjc_cavity_pressure_is_independent_of_the_mesh():
    """The HJC concrete at 430 m/s (24.9 ``fc``, the strength at its SFMAX cap and D = 1 at the
    wall, measured): 20 and 60 zones per radius, and a growth from a tenth instead of a
    twentieth of the radius, agree within 0.5 % (measured 0.1 %)."""
    law = mf.HolmquistJohnsonCook.concrete_48mpa()
    coarse = mf.cavity_expansion(law, 430.0, cells=20)
    fine = mf.cavity_expansion(law, 430.0, cells=60)
    short = mf.cavity_expansion(law, 430.0, cells=20, growth=10.0)
    assert 20.0 < fine.pressure / law.fc < 30.0
    assert abs(coarse.pressure / fine.pressure - 1.0) < 5e-3
    assert abs(short.pressure / fine.pressure - 1.0) < 5e-3


@pytest.mark.serial
def test_ogive_force_closed_forms():
    """Forrestal's frictionless ogive integral: a constant normal stress ``sigma`` gives ``pi
    a^2 sigma`` (the shank's section), ``sigma = c V_n^2`` gives ``pi a^2 N* c V^2`` with the
    nose factor ``N* = (8 psi - 1) / (24 psi^2)``, for psi = 1, 3 and 4.5."""
    a, V = 0.0127, 700.0
    for psi in (1.0, 3.0, 4.5):
        const = mf.ogive_force(lambda w: np.full_like(w, 4e8), V, a, psi)
        assert const == pytest.approx(np.pi * a * a * 4e8, rel=1e-9)
        quad = mf.ogive_force(lambda w: 2440.0 * w * w, V, a, psi)
        nose = (8.0 * psi - 1.0) / (24.0 * psi * psi)
        assert quad == pytest.approx(np.pi * a * a * nose * 2440.0 * V * V, rel=1e-9)


@pytest.mark.serial
def test_hjc_resists_an_ogive_as_concrete_does():
    """The published 48 MPa HJC concrete's own cavity pressure (three cavities, 50, 240 and
    430 m/s; the curve passes through them and holds its end values beyond) on Hanchak's 25.4
    mm ogive of caliber-radius-head 3 at 430 m/s: 332 kN with 20 zones per radius (measured;
    325 kN from five cavities with 40), 1.24 times Forrestal, Altman, Cargile & Hanchak
    (1994)'s empirical force for 48 MPa concrete, ``pi a^2 (S fc + N* rho V^2)`` with ``S =
    82.6 * 48^-0.544`` (checked between 1.0 and 1.5): the material resists as concrete does."""
    law = mf.HolmquistJohnsonCook.concrete_48mpa()
    a, V = 0.0127, 430.0
    curve, cavities = mf.cavity_pressure_curve(law, np.linspace(50.0, V, 3), a, cells=20)
    p = np.array([c.pressure for c in cavities])
    assert np.allclose(curve(np.array([10.0, 50.0, 335.0, 430.0, 900.0])),
                       [p[0], p[0], 0.5 * (p[1] + p[2]), p[2], p[2]], rtol=1e-14)  # fmt: skip
    force = mf.ogive_force(curve, V, a, 3.0)
    empirical = np.pi * a * a * (82.6 * 48.0**-0.544 * law.fc + 23.0 / 216.0 * law.rho * V * V)
    assert 1.0 < force / empirical < 1.5


def fe_cylinder_pressure(
    cells: int, velocity: float = 430.0, law=None, dilatation: str | None = None
) -> float:
    """The cylindrical cavity of an axisymmetric rate-form ``law`` (default: the HJC concrete)
    in the package's axisymmetric FE model, its cells' volumetric strain by ``dilatation``
    (``ExplicitDynamics.fe``'s): a strip
    ``radius / cells`` high with its axial motion held (plane strain along the axis), its
    reference radii those of the 1D cavity (graded from the wall at the end, 20 radii out),
    the wall driven at ``velocity`` (ramped up over 2 % of the run, as the 1D one), to a
    twentieth of the radius from a twentieth; the pressure from the driven wall's reaction
    work, ``dW / dt / (2 pi a H V)``, over the last 30 % of the growth."""
    radius = 0.0127
    a0, h = radius / 20, radius / cells
    r = [radius]
    while r[-1] < 20 * radius:
        r.append(r[-1] + h)
        h *= 1.03
    R = np.sqrt(a0**2 + np.array(r) ** 2 - radius**2)
    R[0] = a0
    height = radius / cells
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.array([1.0, height])], [len(R) - 1, 1],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    x = msh.geometry.x
    x[:, 0] = np.interp(x[:, 0], np.linspace(0.0, 1.0, len(R)), R)
    t_end = (radius - a0) / velocity
    ramp = 0.02 * t_end
    held = [
        (mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], height)),
         (1,)),
        (mf.boundary_facets(msh, lambda x: np.isclose(x[0], a0)), (0,),
         lambda t: [velocity * min(1.0, t / ramp)]),
    ]  # fmt: skip
    law = law or mf.HolmquistJohnsonCook.concrete_48mpa(plane="axisymmetric")
    V = _compat.vector_function_space(msh)
    dyn = mf.ExplicitDynamics.fe(V, law, fixed_facets=held, dilatation=dilatation)
    times, work = [], []
    for k in range(1, 41):
        dyn.run(k * t_end / 40, energy_records=2)
        times.append(dyn.time)
        work.append(dyn.stepper.records[-1].external)
    times = np.array(times)
    a = a0 + velocity * (times - 0.5 * ramp)
    p = np.gradient(np.array(work), times) / (2 * np.pi * a * height * velocity)
    dyn.destroy()
    return float(p[a >= a0 + 0.7 * (radius - a0)].mean())


@pytest.mark.serial
def test_fe_cylinder_meets_the_1d_cavity():
    """The HJC concrete's cylindrical cavity at 430 m/s, expanded twentyfold (hoop stretches to
    20, the wall's concrete crushed and failed): the package's axisymmetric FE model
    (``ExplicitDynamics.fe`` with the rate law, a driven wall) against the 1D cavity, an
    independent discretisation of the same problem (28.9 ``fc``). Measured with 20 and 40
    cells per radius: -0.33 and -0.18 % at the cells' mean dilatation (the default, with the
    law's bulk viscosity); checked within 0.6 %. The full rule at every point gave -3.8 % at 20
    (before the bulk viscosity -4.1, -3.0 and -2.0 % with 20, 40 and 80: the failed concrete
    keeps only a pressure, and its volume change locked the cells); checked at 20: 2-8 % below.
    So the FE
    model and the axisymmetric law carry a crushing cavity as the 1D one does: the Hanchak
    slab's low tunnel force is not here."""
    law = mf.HolmquistJohnsonCook.concrete_48mpa()
    exact = mf.cavity_expansion(law, 430.0, shape="cylinder", extent=20.0, cells=40).pressure
    assert 28.0 < exact / law.fc < 30.0
    for cells in (20, 40):
        assert abs(fe_cylinder_pressure(cells) / exact - 1.0) < 6e-3
    assert -0.08 < fe_cylinder_pressure(20, dilatation="pointwise") / exact - 1.0 < -0.02


@pytest.mark.serial
def test_steel_cavity_does_not_lock():
    """The Johnson–Cook steel without hardening (elastic–perfectly plastic, isochoric flow)
    driven at 200 m/s in the same axisymmetric strip, against the 1D cavity (3,455 MPa). With
    10 and 20 cells per radius at the cells' mean dilatation (the default): -0.13 and -0.15 %
    (measured), checked within 0.3 %. The full rule at every point locks: +22 % at 10 cells
    and +6.7 % at 20 (+1.9 % at 40), measured; checked above +11 % at 10. Nothing in the locked
    run said so: this is the silent wrong answer the mean dilatation removes."""
    law = mf.JohnsonCook(**STEEL_PLAIN, plane="axisymmetric")
    exact = mf.cavity_expansion(STEEL, 200.0, shape="cylinder", extent=20.0, cells=40).pressure
    assert 3.3e9 < exact < 3.6e9
    for cells in (10, 20):
        assert abs(fe_cylinder_pressure(cells, 200.0, law) / exact - 1.0) < 3e-3
    assert fe_cylinder_pressure(10, 200.0, law, "pointwise") / exact - 1.0 > 0.11


@pytest.mark.serial
def test_cavity_expansion_bad_input():
    """Each refused by name: an unknown cavity, a wall that does not move, a growth too short
    to be self-similar, an axisymmetric (2D) law, Hill without a plastic zone, an ogive of CRH
    below 1/2, speeds that do not increase."""
    law = mf.HolmquistJohnsonCook.concrete_48mpa()
    with pytest.raises(ValueError, match="shape='cube' is out of range"):
        mf.cavity_expansion(law, 100.0, shape="cube")
    with pytest.raises(ValueError, match=r"velocity=0\.0 is out of range"):
        mf.cavity_expansion(law, 0.0)
    with pytest.raises(ValueError, match=r"growth=2\.0 is out of range"):
        mf.cavity_expansion(law, 100.0, growth=2.0)
    with pytest.raises(ValueError, match="plane='axisymmetric'; the cavity is 3D"):
        mf.cavity_expansion(dataclasses.replace(law, plane="axisymmetric"), 100.0)
    with pytest.raises(ValueError, match="a plastic zone larger than the cavity"):
        mf.hill_cavity_pressure(1e6, 0.3, 1e6)
    with pytest.raises(ValueError, match=r"crh >= 0\.5"):
        mf.ogive_force(lambda w: w, 100.0, 0.01, 0.4)
    with pytest.raises(ValueError, match="two or more increasing speeds"):
        mf.cavity_pressure_curve(law, np.array([300.0, 100.0]), 0.0127)
