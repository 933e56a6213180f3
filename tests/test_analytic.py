"""The exact solutions themselves (``analytic.py``, ``waves.py``), checked by finite differences.

Every demo and convergence test measures its error against these fields, so a wrong exact field
would make every error figure wrong together. Each field is checked here independently of the
code's own derivatives and laws:

* the gradient a class returns against central differences of its displacement;
* the stress by Hooke's law written out here (not ``LinearElastic.stress``), and for the beam
  against the stress formula of Belytschko et al. 1995, eq. (5.3);
* equilibrium ``div sigma = 0`` by central differences of that stress;
* the boundary conditions (traction-free faces, the end shear and its resultant ``P``, the
  pressure and the fixed housing of the bushing);
* for the rods, the wave equation ``u_tt = c^2 u_xx`` and ``v = u_t`` by differences in x and t,
  the initial conditions and the end conditions; for the step wave, d'Alembert's parallelogram
  rule, the end velocities read off the characteristics, and the momentum balance.

Tolerances: a central difference of step ``d`` errs by ``d^2 / 6 |f'''|``; each bound below is
that truncation estimate (or ``1e-9`` relative where the field is a polynomial of degree <= 2 and
the difference is exact up to round-off), stated beside it.
"""

from __future__ import annotations

import dolfinx_meshfree as mf

import numpy as np
import pytest

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial

RNG = np.random.default_rng(20261130)


def hooke(material: mf.LinearElastic, grad: np.ndarray) -> np.ndarray:
    """Stress (m, 2, 2) from displacement gradients by the textbook plane laws, written out
    from E and nu (independent of ``LinearElastic.lmbda`` / ``stress``)."""
    E, nu = material.E, material.nu
    exx, eyy = grad[:, 0, 0], grad[:, 1, 1]
    exy = 0.5 * (grad[:, 0, 1] + grad[:, 1, 0])
    s = np.empty_like(grad)
    if material.plane == "stress":
        k = E / (1.0 - nu**2)
        s[:, 0, 0], s[:, 1, 1] = k * (exx + nu * eyy), k * (eyy + nu * exx)
    else:
        k = E / ((1.0 + nu) * (1.0 - 2.0 * nu))
        s[:, 0, 0] = k * ((1.0 - nu) * exx + nu * eyy)
        s[:, 1, 1] = k * ((1.0 - nu) * eyy + nu * exx)
    s[:, 0, 1] = s[:, 1, 0] = E / (1.0 + nu) * exy
    return s


def fd_gradient(f, x: np.ndarray, d: float) -> np.ndarray:
    """Central differences ``df_i/dx_j`` (m, k, 2) of a field f: (m, 2) -> (m, k)."""
    cols = []
    for j in range(2):
        e = np.zeros(2)
        e[j] = d
        cols.append((f(x + e) - f(x - e)) / (2 * d))
    return np.stack(cols, axis=-1)


def fd_divergence(stress, x: np.ndarray, d: float) -> np.ndarray:
    """``div sigma`` (m, 2) by central differences of a stress field (m, 2, 2)."""
    ex, ey = np.array([d, 0.0]), np.array([0.0, d])
    dsx = (stress(x + ex) - stress(x - ex)) / (2 * d)
    dsy = (stress(x + ey) - stress(x - ey)) / (2 * d)
    return dsx[:, :, 0] + dsy[:, :, 1]


# -- Timoshenko cantilever (Belytschko et al. 1995, eq. 5.2-5.3) --------------------------------

BEAMS = [
    mf.TimoshenkoBeam(mf.LinearElastic(3e7, 0.3, "stress")),
    mf.TimoshenkoBeam(mf.LinearElastic(3e7, 0.3, "strain")),
    mf.TimoshenkoBeam(mf.LinearElastic(1000.0, 0.25, "stress"), L=8.0, D=1.0, P=-3.0),
]


def beam_points(beam, m=200):
    return RNG.uniform([0.0, -beam.D / 2], [beam.L, beam.D / 2], (m, 2))


@pytest.mark.parametrize("beam", BEAMS, ids=["stress", "strain", "belytschko"])
def test_beam_gradient_stress_and_equilibrium(beam):
    x = beam_points(beam)
    grad = beam.displacement_gradient(x)
    scale = np.abs(grad).max()
    # u is a cubic: the central difference errs by d^2/6 |u'''| <= d^2 P/(E I) (|u'''| <= 6 c
    # with c = P/(6 E' I), E' >= E); d = 1e-3 L gives ~1e-7 relative; bound 1e-6 relative
    d = 1e-3 * beam.L
    fd = fd_gradient(beam.displacement, x, d)
    assert np.abs(fd - grad).max() <= 1e-6 * scale
    # eq. (5.3) against Hooke's law applied to the gradient (plane strain: the same stress, as
    # the plane-strain moduli are substituted into the plane-stress formulas); exact up to
    # round-off (1e-9 relative)
    sigma = beam.stress(x)
    assert np.abs(hooke(beam.material, grad) - sigma).max() <= 1e-9 * np.abs(sigma).max()
    # equilibrium without body force: the stress is quadratic, central differences are exact up
    # to round-off: |div sigma| <= 1e-9 |sigma| / L
    div = fd_divergence(beam.stress, x, d)
    assert np.abs(div).max() <= 1e-9 * np.abs(sigma).max() / d


@pytest.mark.parametrize("beam", BEAMS, ids=["stress", "strain", "belytschko"])
def test_beam_boundary_conditions(beam):
    L, D, P = beam.L, beam.D, beam.P
    y = np.linspace(-D / 2, D / 2, 41)
    s0 = abs(P) / beam.inertia * L * D / 2  # the largest bending stress, the scale
    # lateral faces y = +-D/2 are traction-free
    for side in (-1.0, 1.0):
        xs = np.column_stack([np.linspace(0.0, L, 41), np.full(41, side * D / 2)])
        t = beam.traction(xs, np.tile([0.0, side], (41, 1)))
        assert np.abs(t).max() <= 1e-12 * s0
    # x = L: no normal stress, the parabolic shear t_y = P/(2I) (D^2/4 - y^2) ...
    end = np.column_stack([np.full(41, L), y])
    t = beam.traction(end, np.tile([1.0, 0.0], (41, 1)))
    assert np.abs(t[:, 0]).max() <= 1e-12 * s0
    np.testing.assert_allclose(t[:, 1], P / (2 * beam.inertia) * (D**2 / 4 - y**2), rtol=1e-12)
    # ... whose resultant is the end load P (Simpson's rule is exact on the parabola)
    w = np.ones(41)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    resultant = (y[1] - y[0]) / 3 * np.sum(w * t[:, 1])
    assert resultant == pytest.approx(P, rel=1e-12)
    # the clamped end: the centre of x = 0 does not move, nor does it rotate (du_y/dx = ... at
    # the centre, Belytschko eq. 5.2: u_x(0, y) is odd in y and u_y(0, 0) = 0)
    u0 = beam.displacement(np.column_stack([np.zeros(41), y]))
    assert np.abs(u0[20]).max() == 0.0
    np.testing.assert_allclose(u0[:, 0], -u0[::-1, 0], atol=1e-15 * np.abs(u0).max())
    # Euler-Bernoulli tip deflection P L^3 / (3 E' I) plus the shear term (4 + 5 nu') P L D^2
    # / (24 E' I) of eq. (5.2b) at (L, 0)
    E, nu = beam._moduli()
    tip = beam.displacement(np.array([[L, 0.0]]))[0, 1]
    EI = E * beam.inertia
    expect = P * L**3 / (3 * EI) + (4 + 5 * nu) * P * L * D**2 / (24 * EI)
    assert tip == pytest.approx(expect, rel=1e-12)


def test_beam_plane_strain_uses_the_plane_strain_moduli():
    """Plane strain: the same stress, and the deflection of E' = E/(1-nu^2), nu' = nu/(1-nu)."""
    stress, strain = BEAMS[0], BEAMS[1]
    x = beam_points(stress, 20)
    np.testing.assert_allclose(strain.stress(x), stress.stress(x), rtol=0, atol=1e-9)
    E, nu = 3e7, 0.3
    as_stress = mf.TimoshenkoBeam(mf.LinearElastic(E / (1 - nu**2), nu / (1 - nu), "stress"))
    np.testing.assert_allclose(strain.displacement(x), as_stress.displacement(x), rtol=1e-12)


# -- the affine field of the patch test --------------------------------------------------------


def test_linear_field():
    f = mf.LinearField(G=((0.3, -0.2), (0.5, 0.1)), c=(0.1, -0.4))
    x = RNG.uniform(-2.0, 2.0, (50, 2))
    G = np.array([[0.3, -0.2], [0.5, 0.1]])
    # the displacement: c + G x, written out
    np.testing.assert_allclose(f.displacement(x), x @ G.T + [0.1, -0.4], rtol=0, atol=1e-15)
    # affine: central differences exact up to round-off
    np.testing.assert_allclose(fd_gradient(f.displacement, x, 0.1), f.displacement_gradient(x),
                               rtol=0, atol=1e-13)  # fmt: skip
    assert f.displacement_gradient(x).shape == (50, 2, 2)
    # Belytschko's patch test field (defaults): u = x
    np.testing.assert_array_equal(mf.LinearField().displacement(x), x)


# -- Lamé's pressurized bushing ----------------------------------------------------------------

BUSHINGS = [
    mf.PressurizedBushing(mf.LinearElastic(1000.0, 0.3, "strain")),
    mf.PressurizedBushing(mf.LinearElastic(1000.0, 0.3, "stress")),
    mf.PressurizedBushing(mf.LinearElastic(2.0e5, 0.45, "strain"), a=0.5, b=3.0, p=-7.0),
]


def annulus_points(bushing, m=200, r=None):
    r = RNG.uniform(bushing.a, bushing.b, m) if r is None else np.full(m, float(r))
    theta = RNG.uniform(0.0, 2 * np.pi, m)
    return np.column_stack([r * np.cos(theta), r * np.sin(theta)])


def polar_frame(x):
    r = np.linalg.norm(x, axis=1)
    e_r = x / r[:, None]
    return e_r, np.column_stack([-e_r[:, 1], e_r[:, 0]])


@pytest.mark.parametrize("bushing", BUSHINGS, ids=["strain", "stress", "thick"])
def test_bushing_gradient_and_equilibrium(bushing):
    x = annulus_points(bushing)
    grad = bushing.displacement_gradient(x)
    # u_r = C1 r + C2/r: |u'''| ~ 6 C2 / a^4; the central difference with d = 1e-4 a errs by
    # d^2 C2 / a^4 ~ 1e-8 |grad|; bound 1e-6 relative
    d = 1e-4 * bushing.a
    fd = fd_gradient(bushing.displacement, x, d)
    assert np.abs(fd - grad).max() <= 1e-6 * np.abs(grad).max()

    # equilibrium: div sigma = 0 by differences of Hooke's stress (truncation d^2 |sigma'''| ~
    # 24 d^2 |sigma| / a^3, plus round-off eps |sigma| / d); bound 1e-5 |sigma| / a
    def sigma(y):
        return hooke(bushing.material, bushing.displacement_gradient(y))

    s = sigma(x)
    div = fd_divergence(sigma, x, d)
    assert np.abs(div).max() <= 1e-5 * np.abs(s).max() / bushing.a


@pytest.mark.parametrize("bushing", BUSHINGS, ids=["strain", "stress", "thick"])
def test_bushing_boundary_conditions_and_hoop_stress(bushing):
    p, a, b = bushing.p, bushing.a, bushing.b
    # the housing r = b holds the bushing fixed
    outer = annulus_points(bushing, 60, r=b)
    u_bore = abs(bushing.radial(np.array([a]))[0])
    assert np.abs(bushing.displacement(outer)).max() <= 1e-14 * u_bore
    # r = a: the pressure, traction sigma n = -p n with the outward normal n = -e_r
    inner = annulus_points(bushing, 60, r=a)
    e_r, e_t = polar_frame(inner)
    s = hooke(bushing.material, bushing.displacement_gradient(inner))
    traction = np.einsum("mij,mj->mi", s, -e_r)
    np.testing.assert_allclose(traction, p * e_r, rtol=0, atol=1e-12 * abs(p))
    # hoop stress (the demo's measure at the inner surface) and no shear in polar axes, at all r
    x = annulus_points(bushing)
    e_r, e_t = polar_frame(x)
    s = hooke(bushing.material, bushing.displacement_gradient(x))
    hoop = np.einsum("mi,mij,mj->m", e_t, s, e_t)
    scale = np.abs(hoop).max()
    np.testing.assert_allclose(bushing.hoop_stress(np.linalg.norm(x, axis=1)), hoop, rtol=0,
                               atol=1e-12 * scale)  # fmt: skip
    assert np.abs(np.einsum("mi,mij,mj->m", e_r, s, e_t)).max() <= 1e-12 * scale
    # u_r = C1 r + C2 / r with u_r(b) = 0 is C (r - b^2 / r) for one constant C
    r = np.linspace(a, b, 7)
    ur = bushing.radial(r)
    c = ur[0] / (a - b**2 / a)
    np.testing.assert_allclose(ur, c * (r - b**2 / r), rtol=1e-12, atol=1e-15 * abs(ur[0]))
    assert np.sign(ur[0]) == np.sign(p)  # an internal pressure pushes the bore outwards


# -- the heated bushing: radial conduction, outer surface held ------------------------------------

HEATED = [
    mf.HeatedBushing(mf.LinearElastic(1000.0, 0.3, "strain"), beta=2.0, Ta=50.0),
    mf.HeatedBushing(mf.LinearElastic(2.0e5, 0.25, "stress"), beta=-3.0, Ta=7.0, a=0.5, b=3.0),
]


def thermal_stress(bushing, x):
    """Hooke's stress of the closed-form gradient minus ``beta T I``, by finite differences'
    own inputs (independent of the class's stress formulas)."""
    r = np.linalg.norm(x, axis=1)
    s = hooke(bushing.material, bushing.displacement_gradient(x))
    return s - (bushing.beta * bushing.temperature(r))[:, None, None] * np.eye(2)


@pytest.mark.parametrize("bushing", HEATED, ids=["strain", "stress"])
def test_heated_bushing_gradient_equilibrium_and_boundaries(bushing):
    x = annulus_points(bushing)
    grad = bushing.displacement_gradient(x)
    d = 1e-4 * bushing.a
    assert np.abs(fd_gradient(bushing.displacement, x, d) - grad).max() <= 1e-6 * np.abs(grad).max()
    s = thermal_stress(bushing, x)
    div = fd_divergence(lambda y: thermal_stress(bushing, y), x, d)
    assert np.abs(div).max() <= 1e-5 * np.abs(s).max() / bushing.a
    # the housing holds r = b; the bore r = a is free (sigma n = 0)
    outer = annulus_points(bushing, 60, r=bushing.b)
    u_bore = abs(bushing.radial(np.array([bushing.a]))[0])
    assert np.abs(bushing.displacement(outer)).max() <= 1e-13 * u_bore
    inner = annulus_points(bushing, 60, r=bushing.a)
    e_r, e_t = polar_frame(inner)
    traction = np.einsum("mij,mj->mi", thermal_stress(bushing, inner), -e_r)
    assert np.abs(traction).max() <= 1e-10 * np.abs(s).max()
    # the class's stresses are the thermal Hooke stress in polar axes, at all r
    e_r, e_t = polar_frame(x)
    r = np.linalg.norm(x, axis=1)
    scale = np.abs(s).max()
    hoop = np.einsum("mi,mij,mj->m", e_t, s, e_t)
    radial = np.einsum("mi,mij,mj->m", e_r, s, e_r)
    assert np.abs(bushing.hoop_stress(r) - hoop).max() <= 1e-10 * scale
    assert np.abs(bushing.radial_stress(r) - radial).max() <= 1e-10 * scale
    # heated from inside (beta Ta > 0): the bore's hoop stress is compressive
    assert np.sign(bushing.hoop_stress(np.array([bushing.a]))[0]) == -np.sign(
        bushing.beta * bushing.Ta
    )


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_heated_bushing_thermal_modulus(plane):
    """beta_of: the in-plane stress that free expansion relieves: Hooke's stress of the in-plane
    free thermal strain (alpha T, and (1 + nu) alpha T in plane strain, where eps_zz = 0)."""
    law = mf.LinearElastic(1000.0, 0.3, plane)
    alpha, T = 1e-5, 40.0
    free = alpha * T * (1.0 + law.nu if plane == "strain" else 1.0)
    s = hooke(law, free * np.eye(2)[None])[0]
    np.testing.assert_allclose(s, mf.HeatedBushing.beta_of(law, alpha) * T * np.eye(2), rtol=1e-12)


# -- Kirsch plate: a circular hole under remote uniaxial tension ---------------------------------

KIRSCH = [
    mf.KirschPlate(mf.LinearElastic(1000.0, 0.3, "strain")),
    mf.KirschPlate(mf.LinearElastic(210.0, 0.25, "stress"), a=1.5, sigma=-2.0),
]


def kirsch_points(plate, m=200, r=None):
    t = RNG.uniform(0.0, 2.0 * np.pi, m)
    rr = RNG.uniform(1.05 * plate.a, 4.0 * plate.a, m) if r is None else np.full(m, r)
    return rr[:, None] * np.column_stack([np.cos(t), np.sin(t)])


@pytest.mark.parametrize("plate", KIRSCH, ids=["strain", "stress"])
def test_kirsch_gradient_and_equilibrium(plate):
    x = kirsch_points(plate)
    grad = plate.displacement_gradient(x)
    # the a^4 / r^3 terms: third derivatives about 60 |u| / a^2 near the hole; d = 1e-4 a errs
    # by some 1e-7 |grad|; bound 1e-6 relative
    d = 1e-4 * plate.a
    assert np.abs(fd_gradient(plate.displacement, x, d) - grad).max() <= 1e-6 * np.abs(grad).max()
    np.testing.assert_allclose(plate.stress(x), hooke(plate.material, grad), rtol=1e-12,
                               atol=1e-12 * abs(plate.sigma))  # fmt: skip

    def sigma(y):
        return hooke(plate.material, plate.displacement_gradient(y))

    # truncation ~ d^2 |sigma'''| ~ 120 d^2 |sigma| / a^3 plus round-off; bound 1e-5 |sigma| / a
    div = fd_divergence(sigma, x, d)
    assert np.abs(div).max() <= 1e-5 * abs(plate.sigma) / plate.a


@pytest.mark.parametrize("plate", KIRSCH, ids=["strain", "stress"])
def test_kirsch_hole_far_field_and_symmetry(plate):
    a, s0 = plate.a, plate.sigma
    # the hole is free of traction (outward normal of the plate there: -e_r)
    x = kirsch_points(plate, 60, r=a)
    e_r, e_t = polar_frame(x)
    s = hooke(plate.material, plate.displacement_gradient(x))
    assert np.abs(np.einsum("mij,mj->mi", s, -e_r)).max() <= 1e-12 * abs(s0)
    # hoop stress on the hole: sigma (1 - 2 cos 2t); 3 sigma at the top (0, a), -sigma at (a, 0)
    t = np.arctan2(x[:, 1], x[:, 0])
    hoop = np.einsum("mi,mij,mj->m", e_t, s, e_t)
    np.testing.assert_allclose(hoop, s0 * (1 - 2 * np.cos(2 * t)), rtol=0, atol=1e-12 * abs(s0))
    top = hooke(plate.material, plate.displacement_gradient(np.array([[0.0, a]])))[0]
    np.testing.assert_allclose(top, [[3 * s0, 0], [0, 0]], rtol=0, atol=1e-12 * abs(s0))
    # far away the stress tends to the remote one: the disturbance decays like (a / r)^2
    far = kirsch_points(plate, 60, r=1e3 * a)
    s_far = hooke(plate.material, plate.displacement_gradient(far))
    np.testing.assert_allclose(s_far, np.broadcast_to([[s0, 0], [0, 0]], s_far.shape), rtol=0,
                               atol=1e-5 * abs(s0))  # fmt: skip
    # symmetric about both axes: u_y = 0 on y = 0, u_x = 0 on x = 0, mirrored elsewhere
    r = RNG.uniform(a, 4 * a, 20)
    u_scale = np.abs(plate.displacement(kirsch_points(plate, 30))).max()
    assert np.abs(plate.displacement(np.column_stack([r, 0 * r]))[:, 1]).max() <= 1e-14 * u_scale
    assert np.abs(plate.displacement(np.column_stack([0 * r, r]))[:, 0]).max() <= 1e-14 * u_scale
    x = kirsch_points(plate, 30)
    np.testing.assert_allclose(plate.displacement(x * [-1, 1]), plate.displacement(x) * [-1, 1],
                               rtol=0, atol=1e-14 * u_scale)  # fmt: skip


# -- rods: Gaussian pulse (Rabczuk et al. 2006, sec. 6.2.1) and step wave (Belytschko 1995) -----

RODS = [
    mf.GaussianPulseRod(),  # the paper's rod, pulse in the middle
    mf.GaussianPulseRod(E=3.0, rho=2.0, length=10.0, center=2.5, alpha=1.5, x0=-3.0, amplitude=2.0),
]


@pytest.mark.parametrize("rod", RODS, ids=["paper", "offset"])
def test_gaussian_rod_wave_equation_and_velocity(rod):
    c, L = rod.wave_speed, rod.length
    assert c == pytest.approx(np.sqrt(rod.E / rod.rho), rel=1e-15)
    width = 1.0 / np.sqrt(rod.alpha)
    dx = 2e-3 * width
    dt = dx / c
    T = rod.transit_time
    x = np.column_stack([rod.x0 + RNG.uniform(0.0, L, 80), np.zeros(80)])
    # the scale of c^2 u_xx = c v_x: c A sqrt(alpha) (at t = L/c the pulses overlap again and
    # u is uniform, u_xx = 0: the residual is then measured against this scale)
    scale = c * rod.amplitude * np.sqrt(rod.alpha)
    for t in (0.37 * T, 1.0 * T, 2.6 * T):  # (t = 0: see the initial conditions below)

        def u(shift_x=0.0, shift_t=0.0, t=t):
            return rod.displacement(x + np.array([shift_x, 0.0]), t + shift_t)[:, 0]

        u0 = u()
        uxx = (u(dx) - 2 * u0 + u(-dx)) / dx**2
        utt = (u(0.0, dt) - 2 * u0 + u(0.0, -dt)) / dt**2
        # u_tt = c^2 u_xx. With c dt = dx the two second differences of any d'Alembert field
        # f(x - ct) + g(x + ct) agree exactly (a wrong c, or a field that is not one, leaves the
        # truncation error dx^2 alpha ~ 1e-6 of the scale): round-off only, measured 1e-9 of
        # the scale; bound 1e-8
        assert np.abs(utt - c**2 * uxx).max() <= 1e-8 * scale
        # v = u_t (truncation dt^2/6 |u'''|: measured 1.3e-6 of the amplitude; bound 1e-5)
        v = rod.velocity(x, t)
        assert np.abs(v[:, 1]).max() == 0.0
        ut = (u(0.0, dt) - u(0.0, -dt)) / (2 * dt)
        assert np.abs(ut - v[:, 0]).max() <= 1e-5 * rod.amplitude


@pytest.mark.parametrize("rod", RODS, ids=["paper", "offset"])
def test_gaussian_rod_initial_and_end_conditions(rod):
    c, L, T = rod.wave_speed, rod.length, rod.transit_time
    x = np.column_stack([np.linspace(rod.x0, rod.x0 + L, 301), np.zeros(301)])
    # t = 0: at rest in place, the Gaussian velocity (the images add exp(-alpha (distance to
    # the nearer end)^2) at most, times 2 for the two nearest images)
    assert np.abs(rod.displacement(x, 0.0)).max() == 0.0
    gauss = rod.amplitude * np.exp(-rod.alpha * (x[:, 0] - rod.center) ** 2)
    gap = min(rod.center - rod.x0, rod.x0 + L - rod.center)
    image = 2 * rod.amplitude * np.exp(-rod.alpha * gap**2)
    assert np.abs(rod.initial_velocity(x)[:, 0] - gauss).max() <= image + 1e-15
    np.testing.assert_array_equal(rod.initial_velocity(x), rod.velocity(x, 0.0))
    # free ends: sigma = E u_x = 0, by a one-sided second-order difference into the rod
    # (truncation dx^2/3 |u'''|, bound 1e-4 of the largest strain v0 / c)
    dx = 2e-3 / np.sqrt(rod.alpha)
    for t in (0.21 * T, 0.8 * T, 1.55 * T):
        for end, sign in ((rod.x0, 1.0), (rod.x0 + L, -1.0)):
            pts = np.array([[end, 0.0], [end + sign * dx, 0.0], [end + 2 * sign * dx, 0.0]])
            u = rod.displacement(pts, t)[:, 0]
            ux = sign * (-3 * u[0] + 4 * u[1] - u[2]) / (2 * dx)
            assert abs(ux) <= 1e-4 * rod.amplitude / c
    # a free-free rod returns its pulse mirrored after L / c: v(x, L/c) = v0(x0 + L - (x - x0))
    mirrored = np.column_stack([2 * rod.x0 + L - x[:, 0], x[:, 1]])
    np.testing.assert_allclose(rod.velocity(x, T), rod.initial_velocity(mirrored), rtol=0,
                               atol=1e-12 * rod.amplitude)  # fmt: skip
    # and after 2 L / c the whole field repeats
    np.testing.assert_allclose(rod.velocity(x, 2 * T + 0.3 * T), rod.velocity(x, 0.3 * T),
                               rtol=0, atol=1e-12 * rod.amplitude)  # fmt: skip
    # momentum is conserved (free ends): the integral of v is that of v0 (trapezoid, 301 pts)
    w = np.full(301, L / 300)
    w[[0, -1]] /= 2
    m0 = w @ rod.initial_velocity(x)[:, 0]
    m1 = w @ rod.velocity(x, 0.43 * T)[:, 0]
    assert m1 == pytest.approx(m0, rel=1e-6)


def test_paper_rod_times():
    """Rabczuk's t1 = 0.011563 ms is one transit L / c of the 60 mm rod (c = 5189 mm/ms)."""
    rod = mf.GaussianPulseRod()
    assert rod.wave_speed == pytest.approx(5189, abs=0.5)
    assert rod.transit_time == pytest.approx(0.011563, rel=1e-4)


STEPS = [mf.StepLoadedRod(), mf.StepLoadedRod(E=4.0, rho=0.25, length=2.0, sigma0=-3.0, x0=1.0)]


@pytest.mark.parametrize("rod", STEPS, ids=["belytschko", "scaled"])
def test_step_rod_characteristics(rod):
    c, L, v0 = rod.wave_speed, rod.length, rod.front_velocity
    assert v0 == pytest.approx(rod.sigma0 / (rod.rho * c), rel=1e-15)
    period = 4 * L / c
    # at rest at t = 0; the fixed end x0 + L never moves
    x = np.column_stack([rod.x0 + np.linspace(0.0, L, 101), np.zeros(101)])
    assert np.abs(rod.velocity(x, 0.0)).max() == 0.0
    ts = RNG.uniform(0.0, 3 * period, 50)
    fixed = np.array([[rod.x0 + L, 0.0]])
    assert max(abs(rod.velocity(fixed, t)[0, 0]) for t in ts) == 0.0
    # before the front reaches the fixed end: v0 behind the front x0 + c t, rest ahead
    for t in (0.3 * L / c, 0.9 * L / c):
        xi = x[:, 0] - rod.x0
        v = rod.velocity(x, t)[:, 0]
        away = np.abs(xi - c * t) > 1e-9
        np.testing.assert_array_equal(v[away], np.where(xi < c * t, v0, 0.0)[away])
    # the loaded end: the traction fixes the outgoing characteristic f = g + v0 (sigma =
    # -rho c (f - g) = -sigma0), the incoming one g is the fixed end's reflection -f of the
    # wave sent 2L/c earlier: v = f + g = v0 on (0, 2L/c), -v0 on (2L/c, 4L/c), period 4L/c
    loaded = np.array([[rod.x0, 0.0]])
    for t in ts:
        phase = (t % period) / (2 * L / c)
        if min(abs(phase - 1.0), phase, 2.0 - phase) < 1e-6:
            continue
        assert rod.velocity(loaded, t)[0, 0] == (v0 if phase < 1.0 else -v0)
    # d'Alembert: v = f(x - ct) + g(x + ct) satisfies the parallelogram rule on characteristic
    # parallelograms inside the rod (fronts are hit with probability zero)
    for _ in range(200):
        s, r = RNG.uniform(0.0, 0.3 * L / c, 2)
        xa = rod.x0 + RNG.uniform(c * r, L - c * s)
        t = RNG.uniform(0.0, 2 * period)

        def v(xx, tt):
            return rod.velocity(np.array([[xx, 0.0]]), tt)[0, 0]

        lhs = v(xa, t) + v(xa + c * (s - r), t + s + r)
        rhs = v(xa + c * s, t + s) + v(xa - c * r, t + r)
        assert lhs == pytest.approx(rhs, abs=1e-12 * abs(v0))
    # momentum balance: the load's impulse sigma0 t until the front reaches the fixed end, then
    # the wall's reaction -2 sigma0 on top: P(t) = sigma0 min(t, 2L/c - t) on [0, 2L/c]
    n = 200000
    xm = rod.x0 + (np.arange(n) + 0.5) * (L / n)
    pts = np.column_stack([xm, np.zeros(n)])
    for t in (0.25 * L / c, 0.8 * L / c, 1.3 * L / c, 1.9 * L / c):
        momentum = rod.rho * np.sum(rod.velocity(pts, t)[:, 0]) * (L / n)
        # midpoint rule on a step: at most one cell straddles each front, 2 fronts
        assert momentum == pytest.approx(rod.sigma0 * min(t, 2 * L / c - t),
                                         abs=2 * rod.rho * abs(v0) * L / n)  # fmt: skip


@pytest.mark.parametrize("rod", STEPS, ids=["belytschko", "scaled"])
def test_step_rod_arrivals(rod):
    """The velocity jumps exactly at the arrival times, and only there."""
    c, L = rod.wave_speed, rod.length
    xq = rod.x0 + 0.3 * L
    t_end = 5 * L / c
    arrivals = rod.arrivals(xq, t_end)
    expect = np.sort(np.r_[[(2 * k * L + 0.3 * L) / c for k in range(3)],
                          [(2 * (k + 1) * L - 0.3 * L) / c for k in range(3)]])  # fmt: skip
    np.testing.assert_allclose(arrivals, expect[expect <= t_end], rtol=1e-14)
    pt = np.array([[xq, 0.0]])
    eps = 1e-9 * L / c
    for ta in arrivals:
        jump = rod.velocity(pt, ta + eps)[0, 0] - rod.velocity(pt, ta - eps)[0, 0]
        assert abs(abs(jump) - abs(rod.front_velocity)) <= 1e-12 * abs(rod.front_velocity)
    mids = 0.5 * (np.r_[0.0, arrivals] + np.r_[arrivals, t_end])
    for a0, a1 in zip(np.r_[0.0, arrivals], np.r_[arrivals, t_end], strict=True):
        ts = np.linspace(a0, a1, 7)[1:-1]
        vs = [rod.velocity(pt, t)[0, 0] for t in ts]
        assert max(vs) == min(vs)  # constant between fronts
    assert mids.size == arrivals.size + 1
