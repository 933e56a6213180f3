"""Johnson–Cook plasticity at finite strain (dolfinx_meshfree.physics.johnson_cook) against closed
forms: the pressure ``-K ln J``, the flow curve and its rate term along a pure-shear stretch
(the plastic strain from the log strain less the elastic ``q / 3G``), the work of that path by
quadrature of the flow curve, the spinning-plate check of a hardened point, and bad input.
"""

from __future__ import annotations

import dataclasses

from dolfinx_meshfree.physics.johnson_cook import JohnsonCook

import numpy as np
import pytest

# serial: pure numpy point-wise law, no parallel code path (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial

LAW = JohnsonCook.steel_4340()
E, NU, A, B, N, C = 200e9, 0.29, 792e6, 510e6, 0.26, 0.014
G, K = E / (2 * (1 + NU)), E / (3 * (1 - 2 * NU))


def shear_path(total: float, steps: int) -> list[np.ndarray]:
    """Pure shear F = diag(e^x, e^-x, 1): J = 1, no rotation, equivalent log strain 2x/sqrt 3."""
    return [
        np.diag([np.exp(x), np.exp(-x), 1.0])[None] for x in np.linspace(0, total, steps + 1)[1:]
    ]


def drive(law, path, state=None, dt=1e-3):
    state = law.initial_state(1) if state is None else state
    sigmas = []
    for F in path:
        sigma, state = law.update(F, dt, state)
        sigmas.append(sigma[0])
    return np.array(sigmas), state


def von_mises(sigma):
    s = sigma - np.trace(sigma) / 3 * np.eye(3)
    return float(np.sqrt(1.5 * np.sum(s * s)))


def test_pressure_is_minus_k_log_j():
    path = [np.eye(3)[None] * s for s in (0.99, 0.98, 1.01)]
    sigma, state = drive(LAW, path)
    assert -np.trace(sigma[-1]) / 3 == pytest.approx(-K * np.log(1.01**3), rel=1e-12)
    assert von_mises(sigma[-1]) < 1e-6
    assert state["plastic_strain"][0, 0] == 0.0


@pytest.mark.parametrize("rate", [1e-2, 1e3])
def test_flow_curve_in_pure_shear(rate):
    """q = (A + B eps_p^n)(1 + C ln rate) with eps_p = 2x/sqrt3 - q / 3G, quasi-static and at
    1000/s (dt from the step's deviatoric strain rate)."""
    total, steps = 0.05, 500
    dx = total / steps
    dt = 2.0 / np.sqrt(3.0) * dx / rate
    sigma, state = drive(LAW, shear_path(total, steps), dt=dt)
    q = von_mises(sigma[-1])
    eps_p = 2.0 / np.sqrt(3.0) * total - q / (3.0 * G)
    assert state["plastic_strain"][0, 0] == pytest.approx(eps_p, rel=1e-9)
    factor = 1.0 + C * np.log(max(rate, 1.0))
    assert q == pytest.approx((A + B * eps_p**N) * factor, rel=1e-9)


def test_work_of_pure_shear_by_the_flow_curve():
    """Quasi-static, the work per unit volume of the path is the integral of q d eps_eq along
    the elastic-plastic curve (eps_eq = eps_p + sigma_y / 3G past yield), in closed form::

        W = A eps_p + B eps_p^(n+1) / (n+1) + sigma_y(eps_p)^2 / 6G

    (the plastic work plus the stored q^2 / 6G); the trapezoidal work converges at second order
    in the step."""
    errors = []
    for steps in (200, 400):
        _, state = drive(LAW, shear_path(0.02, steps))
        e = state["plastic_strain"][0, 0]
        expected = A * e + B * e ** (N + 1) / (N + 1) + (A + B * e**N) ** 2 / (6 * G)
        errors.append(abs(state["work"][0, 0] / expected - 1))
    assert errors[1] < 6.5e-6  # measured 3.2e-6
    assert 3.6 < errors[0] / errors[1] < 4.4


def _rotation(angle: float) -> np.ndarray:
    a = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    Kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx


def test_spinning_hardened_point():
    F0 = np.array([[[1.02, 0.03, 0.0], [0.0, 0.985, 0.0], [0.0, 0.01, 0.998]]])
    path = [np.eye(3)[None] + s * (F0 - np.eye(3)) for s in np.linspace(0, 1, 51)[1:]]
    sigma, state0 = drive(LAW, path)
    assert state0["plastic_strain"][0, 0] > 0.005
    angles = np.radians(np.arange(20.0, 381.0, 20.0))
    spun, state = drive(LAW, [_rotation(a) @ F0 for a in angles], state0)
    for a, s in zip(angles, spun, strict=True):
        R = _rotation(a)
        assert np.abs(s - R @ sigma[-1] @ R.T).max() < 1e-12 * np.abs(sigma[-1]).max()
    assert state["plastic_strain"][0, 0] == pytest.approx(state0["plastic_strain"][0, 0], rel=1e-12)
    assert state["work"][0, 0] == pytest.approx(state0["work"][0, 0], rel=1e-12)


def test_plane_strain_is_3d_with_unit_fzz():
    F2 = np.array([[[1.01, 0.02], [0.0, 0.99]]])
    s2, _ = drive(dataclasses.replace(LAW, plane="strain"), [F2])
    F3 = np.eye(3)[None].copy()
    F3[0, :2, :2] = F2[0]
    s3, _ = drive(LAW, [F3])
    assert np.array_equal(s2, s3)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"A": 0.0}, r"A=0.0 must be a positive finite number"),
        ({"n": 1.5}, r"n=1.5 must lie in \(0, 1\]"),
        ({"nu": 0.5}, r"nu=0.5 must lie in \(-1, 0.5\)"),
        ({"C": -0.1}, r"C=-0.1 must be a finite number >= 0"),
        ({"plane": "stress"}, r"plane='stress' is not None"),
    ],
)
def test_bad_parameters(change, match):
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(LAW, **change)


def test_bad_update_input():
    with pytest.raises(ValueError, match=r"dt=-1.0 must be a positive time step"):
        LAW.update(np.eye(3)[None], -1.0, LAW.initial_state(1))
    with pytest.raises(ValueError, match=r"state\['F'\] should have shape \(1, 9\), got nothing"):
        LAW.update(
            np.eye(3)[None], 1e-6, {k: v for k, v in LAW.initial_state(1).items() if k != "F"}
        )
