"""Fracture mechanics on given fields (issue 10, items 4 and 5): the Williams near-tip fields,
the domain interaction integral, the maximum hoop stress criterion and the exact fields of the
SIF demos (inclined centre crack in an infinite plate, Tada's edge-crack factor).

Oracles, none taken from the code under test:

* the Williams field against the textbook trigonometric formulas of modes I and II (Anderson,
  Fracture Mechanics, table 2.1/2.2), its gradient against central differences of its
  displacement, its stress against Hooke's law written out here;
* the interaction integral on those exact fields with K_I, K_II chosen here, a shifted tip, a
  rotated crack, and higher Williams terms (T-stress, r^(1/2) stresses, ...) that carry no K;
* the centre crack: traction-free faces, the remote field, equilibrium and compatibility by
  differences, and K from the near-tip limit ``sqrt(2 pi r) sigma`` ahead of the tip, independent
  of the interaction integral;
* the kink angle and K_eq against Erdogan & Sih's values and a brute-force maximum of the hoop
  stress of the Williams stress tensor.

Everything is local numpy: serial and ``mpirun -n 2`` run the same computation on every rank.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree.fracture.criteria import (
    advance,
    equivalent_sif,
    grows,
    hoop_stress_factor,
    kink_angle,
    kinked_direction,
)
from dolfinx_meshfree.fracture.interaction import interaction_integral
from dolfinx_meshfree.fracture.williams import WilliamsField
from dolfinx_meshfree.verification.crack_fields import InclinedCentreCrack, edge_crack_factor

import numpy as np
import pytest

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial

RNG = np.random.default_rng(20261130)
PLANES = ("stress", "strain")


def _material(plane: str) -> mf.LinearElastic:
    return mf.LinearElastic(210.0, 0.3, plane=plane)


def _hooke(material: mf.LinearElastic, grad: np.ndarray) -> np.ndarray:
    """Plane stress / plane strain Hooke's law written out (independent of LinearElastic)."""
    E, nu = material.E, material.nu
    exx, eyy = grad[:, 0, 0], grad[:, 1, 1]
    exy = 0.5 * (grad[:, 0, 1] + grad[:, 1, 0])
    if material.plane == "stress":
        c = E / (1 - nu**2)
        sxx, syy = c * (exx + nu * eyy), c * (eyy + nu * exx)
    else:
        c = E / ((1 + nu) * (1 - 2 * nu))
        sxx, syy = c * ((1 - nu) * exx + nu * eyy), c * ((1 - nu) * eyy + nu * exx)
    sxy = E / (1 + nu) * exy
    return np.stack([np.stack([sxx, sxy], -1), np.stack([sxy, syy], -1)], -2)


def _central_gradient(fn, x: np.ndarray, d: float) -> np.ndarray:
    """d fn_i / d x_j (m, ..., 2) by central differences of step d."""
    cols = []
    for j in range(2):
        e = np.zeros(2)
        e[j] = d
        cols.append((fn(x + e) - fn(x - e)) / (2 * d))
    return np.stack(cols, axis=-1)


def _polar_points(m: int, r_min: float, r_max: float, tip=(0.0, 0.0), angle: float = 0.0):
    r = RNG.uniform(r_min, r_max, m)
    th = RNG.uniform(-0.99 * np.pi, 0.99 * np.pi, m)
    local = np.stack([r * np.cos(th), r * np.sin(th)], axis=1)
    c, s = np.cos(angle), np.sin(angle)
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(tip), r, th


# --- Williams fields ---------------------------------------------------------------------------


@pytest.mark.parametrize("plane", PLANES)
def test_williams_against_textbook_formulas(plane):
    """Modes I + II from the complex potentials equal the trigonometric formulas (to round-off)."""
    mat = _material(plane)
    KI, KII = 1.3, -0.7
    x, r, th = _polar_points(200, 0.01, 3.0)
    u, grad, sigma = WilliamsField(mat, KI, KII).fields(x)
    nu, mu = mat.nu, mat.mu
    kappa = 3 - 4 * nu if plane == "strain" else (3 - nu) / (1 + nu)
    c, s, c3, s3 = np.cos(th / 2), np.sin(th / 2), np.cos(1.5 * th), np.sin(1.5 * th)
    f = 1 / np.sqrt(2 * np.pi * r)
    sxx = KI * f * c * (1 - s * s3) - KII * f * s * (2 + c * c3)
    syy = KI * f * c * (1 + s * s3) + KII * f * s * c * c3
    sxy = KI * f * s * c * c3 + KII * f * c * (1 - s * s3)
    g = np.sqrt(r / (2 * np.pi)) / (2 * mu)
    ux = KI * g * c * (kappa - 1 + 2 * s**2) + KII * g * s * (kappa + 1 + 2 * c**2)
    uy = KI * g * s * (kappa + 1 - 2 * c**2) - KII * g * c * (kappa - 1 - 2 * s**2)
    scale = np.abs(f).max() * (abs(KI) + abs(KII))
    assert np.abs(sigma[:, 0, 0] - sxx).max() < 1e-13 * scale
    assert np.abs(sigma[:, 1, 1] - syy).max() < 1e-13 * scale
    assert np.abs(sigma[:, 0, 1] - sxy).max() < 1e-13 * scale
    assert np.allclose(sigma[:, 0, 1], sigma[:, 1, 0], rtol=0, atol=0)
    assert np.abs(u[:, 0] - ux).max() < 1e-13 * np.abs(ux).max()
    assert np.abs(u[:, 1] - uy).max() < 1e-13 * np.abs(uy).max()
    # stress of the gradient by Hooke's law (compatibility of kappa and mu with the plane law)
    assert np.abs(_hooke(mat, grad) - sigma).max() < 1e-12 * scale


@pytest.mark.parametrize("plane", PLANES)
def test_williams_higher_terms_gradient_and_free_faces(plane):
    """A field with T-stress and higher terms at a shifted, rotated tip: gradient = central
    differences of the displacement, stress = Hooke's law of the gradient, equilibrium, and
    traction-free faces just above and below the crack behind the tip."""
    mat = _material(plane)
    tip, angle = np.array([0.4, -1.1]), 2.0
    w = WilliamsField(
        mat,
        0.8,
        0.5,
        T=-1.7,
        higher=(0.3 + 0.2j, -0.5 + 0.1j, 0.2 - 0.4j),
        tip=tuple(tip),
        direction=(np.cos(angle), np.sin(angle)),
    )
    x, _, _ = _polar_points(100, 0.2, 2.0, tip, angle)
    _, grad, sigma = w.fields(x)
    d = 1e-5
    fd = _central_gradient(w.displacement, x, d)
    # truncation d^2/6 |u'''| with |u'''| ~ r^(-5/2)/(2 mu) <= 18/mu at r >= 0.2: ~2e-10/mu
    assert np.abs(fd - grad).max() < 1e-8 / mat.mu
    assert np.abs(_hooke(mat, grad) - sigma).max() < 1e-12 * np.abs(sigma).max()
    ds = _central_gradient(w.stress, x, d)  # (m, 2, 2, 2): d sigma_ij / d x_k
    div = ds[:, :, 0, 0] + ds[:, :, 1, 1]
    assert np.abs(div).max() < 1e-6  # d^2/6 |sigma'''| ~ 1e-10 * 90: round-off 1e-16/1e-5 rules
    # crack faces behind the tip: theta = +-(pi - 1e-13), normal e2 of the tip frame
    e1 = np.array([np.cos(angle), np.sin(angle)])
    e2 = np.array([-e1[1], e1[0]])
    rr = np.linspace(0.05, 2.0, 40)
    for side in (1.0, -1.0):
        pts = tip - rr[:, None] * e1 + side * 1e-13 * rr[:, None] * e2
        t = w.stress(pts) @ e2
        assert np.abs(t).max() < 1e-10 * np.abs(sigma).max()


# --- interaction integral on exact Williams fields ----------------------------------------------

RADII = [0.05, 0.3, 1.0, 4.0]


@pytest.mark.parametrize("plane", PLANES)
@pytest.mark.parametrize("weight", ["linear", "smooth"])
@pytest.mark.parametrize("higher", [False, True], ids=["K-field", "higher-terms"])
def test_interaction_integral_recovers_K(plane, weight, higher):
    """Mixed mode at a shifted tip with a rotated crack: K_I, K_II to 1e-8 on every radius
    (measured <= 3e-14), J = (K_I^2 + K_II^2)/E' to 1e-8 relative (measured <= 3e-13); the
    T-stress and the higher terms leave K unchanged (the domain form at work)."""
    mat = _material(plane)
    KI, KII = 2.3, -1.1
    tip, angle = (3.0, -2.0), np.radians(130.0)
    direction = (np.cos(angle), np.sin(angle))
    extra = {"T": 4.0, "higher": (0.7 - 0.3j, -1.2 + 0.4j, 0.5 + 0.5j)} if higher else {}
    w = WilliamsField(mat, KI, KII, tip=tip, direction=direction, **extra)
    res = interaction_integral(w.displacement_gradient, mat, tip, direction, RADII, weight=weight)
    assert res.K_I.shape == (len(RADII),)
    np.testing.assert_allclose(res.outer, RADII)
    np.testing.assert_allclose(res.inner, 0.5 * np.array(RADII))
    assert np.abs(res.K_I - KI).max() < 1e-8
    assert np.abs(res.K_II - KII).max() < 1e-8
    J = (KI**2 + KII**2) / res.E_prime
    assert np.abs(res.J - J).max() < 1e-8 * J
    assert res.path_dependence < 1e-8
    E, nu = mat.E, mat.nu
    assert res.E_prime == pytest.approx(E if plane == "stress" else E / (1 - nu**2), rel=1e-15)


def test_interaction_integral_options_and_single_call():
    """A disc domain (r1 = 0), explicit (r1, r2) pairs and a coarse rule; pure mode I gives
    K_II = 0 and pure mode II gives K_I = 0; grad_u is called once with all the points."""
    mat = _material("strain")
    calls = []

    def grad(x, w):
        calls.append(len(x))
        return w.displacement_gradient(x)

    for KI, KII in ((1.0, 0.0), (0.0, 1.0)):
        w = WilliamsField(mat, KI, KII, T=0.5)
        calls.clear()
        res = interaction_integral(
            lambda x, w=w: grad(x, w),
            mat,
            (0, 0),
            (1, 0),
            [[0.0, 1.0], [0.2, 0.3]],
            points=(4, 16),
        )
        assert calls == [2 * 4 * 16]
        np.testing.assert_allclose(res.inner, [0.0, 0.2])
        assert np.abs(res.K_I - KI).max() < 1e-12
        assert np.abs(res.K_II - KII).max() < 1e-12


def test_interaction_integral_detects_a_wrong_field():
    """The integral is not blind: a field whose faces are loaded (a uniform sigma_22 added to a
    mode I field) or the wrong material (plane stress data read as plane strain) gives a
    different, path-dependent answer."""
    stress, strain = _material("stress"), _material("strain")
    w = WilliamsField(stress, 1.0, 0.0)
    ok = interaction_integral(w.displacement_gradient, stress, (0, 0), (1, 0), RADII)
    assert np.abs(ok.K_I - 1.0).max() < 1e-12
    wrong = interaction_integral(w.displacement_gradient, strain, (0, 0), (1, 0), RADII)
    assert np.abs(wrong.K_I - 1.0).max() > 1e-2
    # uniform sigma_22 = 1 (plane stress): eps_22 = 1/E, eps_11 = -nu/E; faces now carry traction
    H = np.diag([-stress.nu / stress.E, 1.0 / stress.E])
    loaded = interaction_integral(
        lambda x: w.displacement_gradient(x) + H, stress, (0, 0), (1, 0), RADII
    )
    assert loaded.path_dependence > 1e-2


# --- the inclined centre crack -----------------------------------------------------------------

ALPHAS = [0.0, 30.0, 45.0, 60.0, 90.0]


def _crack(alpha_deg: float, plane: str = "strain") -> InclinedCentreCrack:
    return InclinedCentreCrack(
        _material(plane), a=2.0, alpha=np.radians(alpha_deg), sigma=3.0, center=(0.5, -0.3)
    )


@pytest.mark.parametrize("alpha", [0.0, 30.0, 60.0])
def test_centre_crack_faces_remote_field_equilibrium(alpha):
    """Traction-free faces (to 1e-10 sigma), the remote field sigma e_y e_y, equilibrium and
    compatibility by differences, Hooke's law of the gradient equal to the potentials' stress."""
    c = _crack(alpha)
    t, n = c.tip_directions[0], np.array([-c.tip_directions[0][1], c.tip_directions[0][0]])
    xs = np.linspace(-0.9, 0.9, 37) * c.a
    for side in (1.0, -1.0):
        pts = np.asarray(c.center) + xs[:, None] * t + side * 1e-13 * c.a * n
        assert np.abs(c.stress(pts) @ n).max() < 1e-10 * c.sigma
    # remote: the perturbation decays as (a/r)^2; at r = 1e4 a it is ~1e-8 sigma
    far, _, _ = _polar_points(20, 1e4 * c.a, 2e4 * c.a, c.center)
    remote = np.array([[0.0, 0.0], [0.0, c.sigma]])
    assert np.abs(c.stress(far) - remote).max() < 1e-7 * c.sigma
    # equilibrium and compatibility at points off the crack (r >= 0.3 a from both tips)
    pts, _, _ = _polar_points(200, 0.1, 3.0 * c.a, c.center)
    pts = pts[np.min(np.linalg.norm(pts[:, None] - c.tips[None], axis=2), axis=1) > 0.3 * c.a]
    pts = pts[np.abs((pts - c.center) @ n) > 1e-3]  # keep the differences off the crack line
    _, grad, sigma = c.fields(pts)
    d = 1e-6 * c.a
    fd = _central_gradient(c.displacement, pts, d)
    assert np.abs(fd - grad).max() < 1e-7 * c.sigma / c.material.mu
    assert np.abs(_hooke(c.material, grad) - sigma).max() < 1e-12 * c.sigma * 1e2
    ds = _central_gradient(c.stress, pts, d)
    assert np.abs(ds[:, :, 0, 0] + ds[:, :, 1, 1]).max() < 1e-6 * c.sigma / c.a


@pytest.mark.parametrize("alpha", ALPHAS)
def test_centre_crack_near_tip_limit(alpha):
    """K of the exact field from its near-tip stress ahead of each tip: sqrt(2 pi r) sigma_22 ->
    K_I, sqrt(2 pi r) sigma_12 -> K_II as r -> 0 (error O(r/a): 1e-5 at r = 1e-6 a), and the
    values cos^2 alpha, sin alpha cos alpha (independent of the interaction integral)."""
    c = _crack(alpha)
    nI, nII = c.normalized
    assert nI == pytest.approx(np.cos(np.radians(alpha)) ** 2, abs=1e-15)
    assert nII == pytest.approx(np.sin(np.radians(alpha)) * np.cos(np.radians(alpha)), abs=1e-15)
    ref = c.sigma * np.sqrt(np.pi * c.a)
    r = 1e-6 * c.a
    for tip, e1 in zip(c.tips, c.tip_directions, strict=True):
        e2 = np.array([-e1[1], e1[0]])
        s = c.stress((tip + r * e1)[None])[0]
        assert np.sqrt(2 * np.pi * r) * (e2 @ s @ e2) / ref == pytest.approx(nI, abs=1e-5)
        assert np.sqrt(2 * np.pi * r) * (e1 @ s @ e2) / ref == pytest.approx(nII, abs=1e-5)


@pytest.mark.parametrize("plane", PLANES)
@pytest.mark.parametrize("alpha", ALPHAS)
def test_centre_crack_interaction_integral(alpha, plane):
    """The interaction integral on the exact field at each tip: K / (sigma sqrt(pi a)) =
    cos^2 alpha, sin alpha cos alpha to 1e-6 over radii 0.1a .. 1.5a (measured <= 2e-10; the
    largest domain reaches within 0.5a of the other tip)."""
    c = _crack(alpha, plane)
    ref = c.sigma * np.sqrt(np.pi * c.a)
    nI, nII = c.normalized
    for tip, direction in zip(c.tips, c.tip_directions, strict=True):
        res = interaction_integral(
            c.displacement_gradient,
            c.material,
            tip,
            direction,
            np.array([0.1, 0.5, 1.5]) * c.a,
            keep_outside=c.tips[np.linalg.norm(c.tips - tip, axis=1) > 0],
        )
        assert np.abs(res.K_I / ref - nI).max() < 1e-6
        assert np.abs(res.K_II / ref - nII).max() < 1e-6
        J = (c.K_I**2 + c.K_II**2) / res.E_prime
        assert np.abs(res.J - J).max() < 1e-6 * c.sigma**2 * np.pi * c.a / res.E_prime


def test_edge_crack_factor():
    """Tada's fit, evaluated by hand at a/W = 0.2, 0.4, 0.6, and its a/W -> 0 limit against the
    edge crack in a half-plane, K_I = 1.1215 sigma sqrt(pi a) (Koiter; Tada's handbook), to the
    fit's 0.5 %."""
    F = edge_crack_factor(np.array([0.2, 0.4, 0.6]))
    np.testing.assert_allclose(F, [1.370664, 2.103504, 4.026424], rtol=0, atol=1e-12)
    assert edge_crack_factor(1e-9) == pytest.approx(1.1215, rel=5e-3)


# --- maximum hoop stress ------------------------------------------------------------------------


def test_kink_angle_published_values():
    """Erdogan & Sih 1963: pure mode II kinks by -70.5 deg with K_eq = 2/sqrt(3) K_II (i.e.
    K_IIc = sqrt(3)/2 K_Ic); K_II = K_I kinks by -53.1 deg with K_eq = 4/sqrt(5) K_I."""
    assert np.degrees(kink_angle(0.0, 1.0)) == pytest.approx(-70.5288, abs=1e-4)
    assert kink_angle(0.0, 1.0) == pytest.approx(-2 * np.arctan(1 / np.sqrt(2)), abs=1e-15)
    assert np.degrees(kink_angle(0.0, -1.0)) == pytest.approx(70.5288, abs=1e-4)
    assert np.degrees(kink_angle(1.0, 1.0)) == pytest.approx(-53.1301, abs=1e-4)
    assert kink_angle(1.0, 1.0) == pytest.approx(-2 * np.arctan(0.5), abs=1e-15)
    assert equivalent_sif(0.0, 1.0) == pytest.approx(2 / np.sqrt(3), abs=1e-14)
    assert equivalent_sif(1.0, 1.0) == pytest.approx(4 / np.sqrt(5), abs=1e-14)
    assert kink_angle(2.0, 0.0) == 0.0 and equivalent_sif(2.0, 0.0) == pytest.approx(2.0)
    # small K_II: no cancellation, theta ~ -2 K_II / K_I
    assert kink_angle(1.0, 1e-12) == pytest.approx(-2e-12, rel=1e-9)
    # vectorised, and the formula of the issue where it is free of cancellation
    KI, KII = RNG.uniform(0.1, 2, 50), RNG.uniform(-2, 2, 50)
    theta = kink_angle(KI, KII)
    formula = 2 * np.arctan((KI - np.sqrt(KI**2 + 8 * KII**2)) / (4 * KII))
    assert np.abs(theta - formula).max() < 1e-12
    assert np.all(np.sign(theta) == -np.sign(KII))


@pytest.mark.parametrize("KI, KII", [(1.0, 0.0), (1.0, 0.3), (1.0, 1.0), (0.2, -1.0), (0.0, 1.0)])
def test_kink_angle_is_the_hoop_stress_maximum(KI, KII):
    """theta_c and K_eq against a brute-force maximum of sigma_theta_theta of the Williams stress
    tensor (rotated to polar components here) at r = 1e-4, and tau_r_theta = 0 there."""
    mat = _material("strain")
    r = 1e-4
    w = WilliamsField(mat, KI, KII)

    def hoop_of(th):
        s = w.stress(r * np.stack([np.cos(th), np.sin(th)], axis=1))
        et = np.stack([-np.sin(th), np.cos(th)], axis=1)
        return np.einsum("qi,qij,qj->q", et, s, et) * np.sqrt(2 * np.pi * r)

    th = np.linspace(-np.pi + 1e-9, np.pi - 1e-9, 4001)  # coarse grid, then a fine one around
    th = np.linspace(th[np.argmax(hoop_of(th))] - 2e-3, th[np.argmax(hoop_of(th))] + 2e-3, 4001)
    hoop = hoop_of(th)
    k = np.argmax(hoop)
    tc = kink_angle(KI, KII)
    assert th[k] == pytest.approx(tc, abs=2e-6)  # fine grid step 1e-6
    assert hoop[k] == pytest.approx(equivalent_sif(KI, KII), rel=1e-8)
    assert hoop_stress_factor(th, KI, KII) == pytest.approx(hoop, abs=1e-10)
    xc = r * np.array([[np.cos(tc), np.sin(tc)]])
    sc = WilliamsField(mat, KI, KII).stress(xc)[0]
    tau = np.array([np.cos(tc), np.sin(tc)]) @ sc @ np.array([-np.sin(tc), np.cos(tc)])
    assert abs(tau) * np.sqrt(2 * np.pi * r) < 1e-12


def test_growth_decision_and_direction():
    """Growth iff K_eq >= K_Ic: pure mode II grows at K_II = sqrt(3)/2 K_Ic; the new direction
    is the old one turned by theta_c counterclockwise."""
    K_Ic = 2.0
    k2 = np.sqrt(3) / 2 * K_Ic
    assert grows(0.0, k2 * (1 + 1e-12), K_Ic) and not grows(0.0, k2 * (1 - 1e-12), K_Ic)
    np.testing.assert_array_equal(grows([1.0, 2.0, 3.0], 0.0, K_Ic), [False, True, True])
    d = kinked_direction(np.array([0.0, 2.0]), np.radians(-90.0))
    np.testing.assert_allclose(d, [1.0, 0.0], atol=1e-15)
    # pure mode II, crack pointing along +y: it turns clockwise by 70.53 deg (towards +x)
    tip, d, theta = advance((1.0, 2.0), (0.0, 3.0), 0.0, 1.0, 0.1)
    np.testing.assert_allclose(d, [2 * np.sqrt(2) / 3, 1 / 3], atol=1e-15)
    np.testing.assert_allclose(tip, [1.0 + 0.1 * 2 * np.sqrt(2) / 3, 2.0 + 0.1 / 3], atol=1e-15)
    assert theta == pytest.approx(-2 * np.arctan(1 / np.sqrt(2)), abs=1e-15)


# --- bad input ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"radius": 0.0}, "radius=.*positive"),
        ({"radius": [1.0, -2.0]}, "radius=.*positive"),
        ({"radius": [[0.5, 0.5]]}, "need 0 <= r1 < r2"),
        ({"radius": [[0.6, 0.5]]}, "need 0 <= r1 < r2"),
        ({"radius": []}, "radius is empty"),
        ({"inner": 1.0}, "inner=1.0"),
        ({"direction": (0.0, 0.0)}, "zero length"),
        ({"direction": (np.nan, 1.0)}, "direction"),
        ({"tip": (1.0, 2.0, 3.0)}, "tip should be"),
        ({"weight": "cubic"}, "weight='cubic'"),
        ({"points": (0, 8)}, "points="),
        ({"material": mf.LinearElastic(1.0, 0.3, plane=None)}, "plane=None"),
        ({"keep_outside": [[5.0, 5.0], [0.9, 0.1]]}, r"contains \[0\.9, 0\.1\]"),
        ({"grad_u": lambda x: np.zeros((len(x), 2))}, r"shape \(\d+, 2, 2\)"),
        ({"grad_u": lambda x: np.full((len(x), 2, 2), np.nan)}, "non-finite"),
    ],
)
def test_interaction_integral_bad_input(kwargs, match):
    mat = _material("stress")
    args = {
        "grad_u": WilliamsField(mat, 1.0).displacement_gradient,
        "material": mat,
        "tip": (0.0, 0.0),
        "direction": (1.0, 0.0),
        "radius": 1.0,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        interaction_integral(**args)


def test_bad_input_fields_and_criteria():
    mat = _material("stress")
    with pytest.raises(ValueError, match=r"a=0\.0"):
        InclinedCentreCrack(mat, a=0.0)
    with pytest.raises(ValueError, match="singular at the tips"):
        InclinedCentreCrack(mat, a=1.0).stress(np.array([[1.0, 0.0]]))
    with pytest.raises(ValueError, match="singular at the tip"):
        WilliamsField(mat, 1.0).stress(np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r"a_over_w=0\.7"):
        edge_crack_factor(0.7)
    with pytest.raises(ValueError, match="K_Ic=0"):
        grows(1.0, 0.0, 0)
    with pytest.raises(ValueError, match="must be finite"):
        kink_angle(np.inf, 1.0)
    with pytest.raises(ValueError, match="nonzero 2-vector"):
        kinked_direction(np.zeros(2), 0.1)
    with pytest.raises(ValueError, match="increment=0"):
        advance((0, 0), (1, 0), 1.0, 0.0, 0)
