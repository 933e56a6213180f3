"""The linear traction-separation law of a cohesive crack (dolfinx_meshfree.physics.cohesive).

Every check is against a closed form or an independent computation written here, not against
the module's own formulas: the bilinear envelope (peak ft at w_0 = ft / K0, zero at
w_c = 2 Gf / ft) with the residual secant residual ft / w_c once it caps the damage; the
secant unloading to the origin and the reloading along it; the penalty contact in compression;
the fracture energy, by a trapezoidal sum of the traction's work along monotonic mode-I, shear
and mixed paths (the kinks of the envelope are on the step grid, so the sum is exact on each
linear piece), against Gf less the cap's closed-form share, and work = stored + dissipated at
every step; the consistent tangent against central finite differences of the traction (and a
one-sided difference on the loading surface); one step against many along a proportional path.
The effective opening, the secant and the dissipated energy are re-derived below from the
specification (Camacho & Ortiz 1996 effective opening, intrinsic damage law).
"""

from __future__ import annotations

import copy
import dataclasses
import re

from dolfinx_meshfree.physics.cohesive import LinearCohesive

import numpy as np
import pytest

# serial: a pure numpy point-wise law, no parallel code path (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial

# concrete-like parameters (N, mm): w_0 = 3e-3 mm, w_c = 0.0667 mm (w_c / w_0 = 22.2)
FT, GF, K0 = 3.0, 0.1, 1e3
W0, WC = FT / K0, 2 * GF / FT
RES = 1e-4  # the default residual


# --- the law re-derived from the specification ---------------------------------------------


def _law(shear: float = 1.0, residual: float = RES, stiffness: float = K0):
    return LinearCohesive(FT, GF, shear=shear, stiffness=stiffness, residual=residual)


def _floor(residual: float) -> float:
    """The floor of the secant, residual ft / w_c (the residual stiffness once capped)."""
    return residual * FT / WC


def _envelope(k) -> np.ndarray:
    """T(k): K0 k up to w_0, linear softening to zero at w_c, zero beyond (no cap)."""
    k = np.asarray(k, dtype=float)
    soft = FT * (WC - k) / (WC - W0)
    return np.where(k <= W0, K0 * k, np.where(k < WC, soft, 0.0))


def _kappa_cap(residual: float) -> float:
    """Where T(k) / k = residual ft / w_c on the softening branch: ft (w_c - k)/(w_c - w_0)
    = c k, c = residual ft / w_c."""
    c = _floor(residual)
    return FT * WC / (FT + c * (WC - W0))


def _secant(k, residual: float) -> np.ndarray:
    """s(k) = K0 up to w_0, else max(T(k) / k, residual ft / w_c)."""
    k = np.asarray(k, dtype=float)
    ratio = _envelope(k) / np.where(k > 0, k, 1.0)
    return np.where(k <= W0, K0, np.maximum(ratio, _floor(residual)))


def _w_eff(jump: np.ndarray, beta: float) -> np.ndarray:
    """Effective opening sqrt(<w_n>^2 + beta^2 |w_s|^2) (m,)."""
    wn = np.maximum(jump[:, 0], 0.0)
    return np.sqrt(wn**2 + beta**2 * np.sum(jump[:, 1:] ** 2, axis=1))


def _expected(jump: np.ndarray, kappa_old: np.ndarray, beta: float, residual: float):
    """Traction (m, d) and the new kappa (m,) of the specification's law."""
    kappa = np.maximum(kappa_old, _w_eff(jump, beta))
    s = _secant(kappa, residual)
    t = np.empty_like(jump, dtype=float)
    t[:, 0] = np.where(jump[:, 0] >= 0, s * jump[:, 0], K0 * jump[:, 0])
    t[:, 1:] = beta**2 * s[:, None] * jump[:, 1:]
    return t, kappa


def _work_integral(k: float) -> float:
    """G(k) = integral of T from 0 to k (closed form)."""
    if k <= W0:
        return 0.5 * K0 * k**2
    k = min(k, WC)
    return 0.5 * FT * W0 + FT / (2 * (WC - W0)) * ((WC - W0) ** 2 - (WC - k) ** 2)


def _dissipated(k: float, residual: float) -> float:
    """G(k) - T(k) k / 2, frozen beyond kappa_cap."""
    k = min(k, _kappa_cap(residual))
    return _work_integral(k) - 0.5 * float(_envelope(k)) * k


def _state(kappa) -> dict:
    return {"kappa": np.asarray(kappa, dtype=float).reshape(-1, 1).copy()}


def _fd_tangent(law, jump: np.ndarray, state: dict, rel: float = 1e-6) -> np.ndarray:
    """Central finite differences of update(...)[0] w.r.t. each jump component (m, d, d)."""
    m, d = jump.shape
    h = rel * np.linalg.norm(jump, axis=1)
    out = np.empty((m, d, d))
    for j in range(d):
        dp = np.zeros_like(jump)
        dp[:, j] = h
        tp = law.update(jump + dp, state)[0]
        tm = law.update(jump - dp, state)[0]
        out[:, :, j] = (tp - tm) / (2 * h[:, None])
    return out


def _rel_err(A: np.ndarray, B: np.ndarray) -> float:
    """Largest relative error of a row (one traction component), so that the small shear rows
    are not hidden behind a large normal (contact) row."""
    num = np.linalg.norm(A - B, axis=2)
    return float((num / np.linalg.norm(B, axis=2)).max())


def _directions(d: int, m: int, rng, wn_sign: float | None = 1.0, min_frac: float = 0.2):
    """m random unit jumps in d; |w_n| >= min_frac and each |w_s_i| >= 0.1 (away from the kinks
    at w_n = 0 and at w_s = 0 of |w_s|), w_n of the given sign."""
    out = []
    while len(out) < m:
        v = rng.normal(size=d)
        v /= np.linalg.norm(v)
        if abs(v[0]) < min_frac or (np.abs(v[1:]) < 0.1).any():
            continue
        if wn_sign is not None:
            v[0] = wn_sign * abs(v[0])
        out.append(v)
    return np.array(out)


# --- 1. mode I envelope, mixed-mode closed form ---------------------------------------------


@pytest.mark.parametrize("d", [2, 3])
def test_mode_one_opening_follows_the_bilinear_envelope(d):
    law = _law()
    np.testing.assert_allclose(law.w_c, WC, rtol=1e-15)
    np.testing.assert_allclose(law.w_0, W0, rtol=1e-15)
    kcap = _kappa_cap(RES)
    assert W0 < kcap < WC
    # openings on the elastic and softening branches, the peak, w_c and beyond
    w = np.unique(np.concatenate([np.linspace(0, 1.5 * WC, 301), [W0, kcap, WC, 3 * WC]]))
    jump = np.zeros((w.size, d))
    jump[:, 0] = w
    t, T, new = law.update(jump, law.initial_state(w.size))
    expected = np.where(w <= W0, K0 * w, np.maximum(_envelope(w), _floor(RES) * w))
    np.testing.assert_allclose(t[:, 0], expected, rtol=1e-12, atol=1e-15 * FT)
    np.testing.assert_array_equal(t[:, 1:], 0.0)
    np.testing.assert_allclose(new["kappa"][:, 0], w, rtol=1e-15)
    # the peak ft at w_0; beyond w_c only the residual (residual ft / w_c) w
    np.testing.assert_allclose(t[w == W0, 0], FT, rtol=1e-12)
    assert t[:, 0].max() <= FT * (1 + 1e-12)
    beyond = w >= WC
    np.testing.assert_allclose(t[beyond, 0], _floor(RES) * w[beyond], rtol=1e-12)
    assert (t[beyond, 0] < 1e-2 * FT).all()
    # the envelope itself (no cap): traction_curve
    np.testing.assert_allclose(law.traction_curve(w), _envelope(w), rtol=1e-12, atol=1e-15 * FT)
    grid = np.array([[0.0, 0.5 * W0, W0], [0.5 * WC, WC, 2 * WC]])
    np.testing.assert_allclose(law.traction_curve(grid), _envelope(grid), rtol=1e-12, atol=0)
    # mode-I loading tangent in closed form on the softening branch (w_s = 0):
    # dt_n/dw_n = T'(w) = -ft/(w_c - w_0); dt_s/dw_s = beta^2 T(w)/w; no coupling
    soft = (w > 1.05 * W0) & (w < 0.95 * kcap)
    expected_T = np.zeros((soft.sum(), d, d))
    expected_T[:, 0, 0] = -FT / (WC - W0)
    for i in range(1, d):
        expected_T[:, i, i] = _envelope(w[soft]) / w[soft]
    np.testing.assert_allclose(T[soft], expected_T, rtol=1e-10, atol=1e-12 * K0)
    # virgin elastic: K0 I
    el = (w > 0) & (w < 0.95 * W0)
    np.testing.assert_allclose(T[el], np.broadcast_to(K0 * np.eye(d), T[el].shape), rtol=1e-14)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0])
def test_mixed_mode_traction_closed_form(d, beta):
    """Random jumps (openings, compression, sliding) from random committed kappa."""
    law = _law(shear=beta)
    rng = np.random.default_rng(17)
    m = 400
    jump = rng.normal(size=(m, d)) * rng.choice([0.3 * W0, 3 * W0, 0.5 * WC, 2 * WC], (m, 1))
    kappa_old = rng.choice([0.0, 0.5 * W0, 2 * W0, 0.4 * WC, 0.9 * WC, 1.5 * WC], m)
    t, _, new = law.update(jump, _state(kappa_old))
    t_cf, kappa_cf = _expected(jump, kappa_old, beta, RES)
    np.testing.assert_allclose(t, t_cf, rtol=1e-12, atol=1e-14 * FT)
    np.testing.assert_allclose(new["kappa"][:, 0], kappa_cf, rtol=1e-14)
    assert new["kappa"].shape == (m, 1)
    if beta == 0.0:  # sliding neither transmits traction nor damages
        np.testing.assert_array_equal(t[:, 1:], 0.0)
        np.testing.assert_allclose(
            new["kappa"][:, 0], np.maximum(kappa_old, np.maximum(jump[:, 0], 0)), rtol=1e-15
        )
    # stored energy with kappa from the (new) state, and the dissipated energy
    wn, ws2 = jump[:, 0], np.sum(jump[:, 1:] ** 2, axis=1)
    stored = 0.5 * _secant(kappa_cf, RES) * (np.maximum(wn, 0) ** 2 + beta**2 * ws2)
    stored += 0.5 * K0 * np.minimum(wn, 0) ** 2
    np.testing.assert_allclose(law.stored_energy(jump, new), stored, rtol=1e-12)
    diss = np.array([_dissipated(k, RES) for k in kappa_cf])
    np.testing.assert_allclose(law.dissipated_energy(new), diss, rtol=1e-10, atol=1e-14 * GF)


def test_dissipated_energy_closed_form():
    for md in (RES, 0.05):
        law = _law(residual=md)
        kcap = _kappa_cap(md)
        k = np.array([0.0, 0.5 * W0, W0, 1.5 * W0, 0.3 * WC, 0.8 * WC, kcap, 0.5 * (kcap + WC)])
        k = np.concatenate([k, [WC, 2 * WC]])
        D = law.dissipated_energy(_state(k))
        assert D.shape == k.shape
        np.testing.assert_allclose(D[:3], 0.0, rtol=0, atol=1e-15 * GF)  # none before the peak
        np.testing.assert_allclose(D, [_dissipated(x, md) for x in k], rtol=1e-10, atol=1e-16)
        # frozen beyond kappa_cap at Gf - T(kappa_cap) w_c / 2 (the triangle left beyond)
        frozen = GF - 0.5 * _floor(md) * kcap * WC
        np.testing.assert_allclose(D[6:], frozen, rtol=1e-10)
    # without a noticeable cap the full Gf at w_c
    law = _law(residual=1e-12)
    np.testing.assert_allclose(law.dissipated_energy(_state([WC])), GF, rtol=1e-9)


# --- 2. fracture energy by integration along monotonic paths --------------------------------


@pytest.mark.parametrize(
    "d,beta,residual", [(2, 1.0, 1e-6), (2, 0.5, 1e-6), (3, 0.5, 1e-6), (3, 0.8, RES)]
)
def test_fracture_energy_by_integration(d, beta, residual):
    """Points along rays: mode I, pure shear, mixed. On a ray w = lambda d the work
    t . dw = s(w_eff) w_eff dw_eff = T(w_eff) dw_eff, so each dissipates Gf (less the cap)."""
    law = _law(shear=beta, residual=residual)
    dirs = [np.eye(d)[0], np.eye(d)[1], np.r_[0.0, np.ones(d - 1)], np.r_[1.0, 0.5, -0.3][:d]]
    dirs = np.array(dirs)
    dirs = dirs / _w_eff(dirs, beta)[:, None]  # unit effective opening
    m = dirs.shape[0]
    kcap = _kappa_cap(residual)
    # effective-opening grid with the kinks w_0 and kappa_cap on it: the traction is linear in the
    # opening between them and the trapezoidal sum is exact
    weff = np.concatenate(
        [
            np.linspace(0, W0, 51),
            np.linspace(W0, kcap, 1501)[1:],
            np.linspace(kcap, 1.2 * WC, 51)[1:],
        ]
    )
    state = law.initial_state(m)
    work = np.zeros(m)
    t_old, jump_old = np.zeros((m, d)), np.zeros((m, d))
    for i, we in enumerate(weff[1:], start=1):
        jump = we * dirs
        t, _, state = law.update(jump, state)
        work += np.sum(0.5 * (t + t_old) * (jump - jump_old), axis=1)
        t_old, jump_old = t, jump
        if i % 50 == 0 or i == weff.size - 1:
            t_cf = _expected(jump, np.zeros(m), beta, residual)[0]
            np.testing.assert_allclose(t, t_cf, rtol=1e-12, atol=1e-15 * FT)
            np.testing.assert_allclose(state["kappa"][:, 0], we, rtol=1e-13)
            balance = work - law.stored_energy(jump, state)
            np.testing.assert_allclose(
                balance, law.dissipated_energy(state), rtol=1e-6, atol=1e-9 * GF
            )
    # the dissipated energy: Gf less the cap's share T(kappa_cap) w_c / 2, all directions alike
    D = law.dissipated_energy(state)
    D_cf = GF - 0.5 * _floor(residual) * kcap * WC
    np.testing.assert_allclose(D, D_cf, rtol=1e-9)
    np.testing.assert_allclose(work - law.stored_energy(jump, state), D_cf, rtol=1e-8)
    # the total work: D + the residual secant's stored energy c w_eff^2 / 2
    c = _floor(residual)
    np.testing.assert_allclose(work, D_cf + 0.5 * c * weff[-1] ** 2, rtol=1e-8)
    if residual <= 1e-6:
        np.testing.assert_allclose(D, GF, rtol=1e-3)
        np.testing.assert_allclose(work, GF, rtol=1e-3)


# --- 3. unloading to the origin and reloading -------------------------------------------------


@pytest.mark.parametrize("beta", [1.0, 0.5])
def test_unloading_is_secant_and_reloading_follows_it(beta):
    law = _law(shear=beta)
    direction = np.array([[1.0, 0.4]])  # mixed mode, w_n > 0
    direction /= _w_eff(direction, beta)[:, None]
    k1 = 0.4 * WC
    state = law.initial_state(1)
    for we in np.linspace(0, k1, 9)[1:]:
        _, _, state = law.update(we * direction, state)
    np.testing.assert_allclose(state["kappa"][0, 0], k1, rtol=1e-14)
    s1 = float(_envelope(k1)) / k1
    secant = s1 * np.diag([1.0, beta**2])
    committed = state
    # unloading: traction linear in the jump through the origin, slope s(kappa_max)
    for f in (0.9, 0.6, 0.25, 1e-3, 0.0):
        jump = f * k1 * direction
        t, T, new = law.update(jump, committed)
        np.testing.assert_allclose(t[0], secant @ jump[0], rtol=1e-12, atol=1e-16 * FT)
        np.testing.assert_allclose(T[0], secant, rtol=1e-12)
        np.testing.assert_array_equal(new["kappa"], committed["kappa"])
        np.testing.assert_allclose(
            law.stored_energy(jump, new), 0.5 * jump[0] @ secant @ jump[0], rtol=1e-12, atol=0
        )
        np.testing.assert_allclose(law.dissipated_energy(new), _dissipated(k1, RES), rtol=1e-12)
    # reloading from the origin along the same line up to kappa_max, then the envelope again
    state = committed
    for f in (0.0, 0.3, 0.7, 1.0):
        t, _, state = law.update(f * k1 * direction, state)
        np.testing.assert_allclose(t[0], f * k1 * (secant @ direction[0]), rtol=1e-12, atol=0)
        np.testing.assert_allclose(state["kappa"][0, 0], k1, rtol=1e-14)
    for we in (0.45 * WC, 0.6 * WC):
        jump = we * direction
        t, _, state = law.update(jump, state)
        s = float(_envelope(we)) / we
        np.testing.assert_allclose(t[0], s * np.diag([1.0, beta**2]) @ jump[0], rtol=1e-12)
        np.testing.assert_allclose(state["kappa"][0, 0], we, rtol=1e-14)
        # on the envelope: the effective traction is T(w_eff)
        t_eff = np.hypot(t[0, 0], t[0, 1] / beta)
        np.testing.assert_allclose(t_eff, _envelope(we), rtol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_secant_stiffness_maps_the_jump_to_the_traction(d):
    """The secant stiffness (path following's fallback tangent) times the jump is the traction,
    at points bonded, softening, unloading, past w_c and closed, from committed states of every
    kind: diag(s, beta^2 s) with s = T(kappa) / kappa of the envelope re-derived here (K_0 in
    compression); symmetric and positive definite."""
    beta = 0.7
    law = _law(shear=beta)
    rng = np.random.default_rng(3)
    m = 40
    committed = {"kappa": rng.choice([0.0, 0.5 * W0, 2 * W0, 0.3 * WC, 1.5 * WC], m)[:, None]}
    jump = rng.normal(size=(m, d)) * rng.choice([0.2 * W0, 0.1 * WC, 0.5 * WC], m)[:, None]
    t, _, trial = law.update(jump, committed)
    S = law.secant_stiffness(jump, committed)
    np.testing.assert_allclose(np.einsum("mij,mj->mi", S, jump), t, rtol=1e-12, atol=1e-14 * FT)
    kappa = trial["kappa"][:, 0]
    s = np.where(kappa > 0, _envelope(kappa) / np.where(kappa > 0, kappa, 1.0), K0)
    s = np.maximum(s, RES * FT / WC)
    np.testing.assert_allclose(S[:, 1, 1], beta**2 * s, rtol=1e-12)
    np.testing.assert_allclose(S[:, 0, 0], np.where(jump[:, 0] >= 0, s, K0), rtol=1e-12)
    assert np.all(np.linalg.eigvalsh(S) > 0) and np.allclose(S, S.transpose(0, 2, 1))


# --- 4. compression: penalty contact, no damage from it ---------------------------------------


@pytest.mark.parametrize("d", [2, 3])
def test_compression_is_penalty_contact_and_does_not_damage(d):
    law = _law(shear=0.5)
    wn = -np.array([0.1, 1.0, 10.0, 100.0]) * WC  # far beyond any opening scale
    for kappa0 in (0.0, 2 * W0, 0.5 * WC, 2 * WC):  # virgin, softened, fully softened
        state = _state(np.full(wn.size, kappa0))
        jump = np.zeros((wn.size, d))
        jump[:, 0] = wn
        t, T, new = law.update(jump, state)
        np.testing.assert_allclose(t[:, 0], K0 * wn, rtol=1e-14)  # not the secant
        np.testing.assert_array_equal(t[:, 1:], 0.0)
        np.testing.assert_array_equal(new["kappa"], state["kappa"])
        np.testing.assert_allclose(T[:, 0, 0], K0, rtol=1e-14)
        np.testing.assert_allclose(
            law.stored_energy(jump, new), 0.5 * K0 * wn**2, rtol=1e-14, atol=0
        )
    # compression + sliding: kappa grows through the sliding only, the normal part stays K0 w_n
    beta = 0.5
    ws = np.array([0.5 * W0, 3 * W0, 0.5 * WC, 2 * WC]) / beta  # w_eff = beta |w_s|
    jump = np.zeros((ws.size, d))
    jump[:, 0] = -5 * WC
    jump[:, 1] = ws
    t, _, new = law.update(jump, law.initial_state(ws.size))
    np.testing.assert_allclose(new["kappa"][:, 0], beta * ws, rtol=1e-14)
    np.testing.assert_allclose(t[:, 0], -5 * WC * K0, rtol=1e-14)
    np.testing.assert_allclose(t[:, 1], beta**2 * _secant(beta * ws, RES) * ws, rtol=1e-12)
    # the same sliding without the compression: the same damage and shear traction
    jump0 = jump.copy()
    jump0[:, 0] = 0.0
    t0, _, new0 = law.update(jump0, law.initial_state(ws.size))
    np.testing.assert_array_equal(new0["kappa"], new["kappa"])
    np.testing.assert_allclose(t0[:, 1:], t[:, 1:], rtol=1e-14)
    np.testing.assert_array_equal(t0[:, 0], 0.0)


# --- 5. the consistent tangent -----------------------------------------------------------------


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("beta", [1.0, 0.5])
def test_tangent_matches_finite_differences(d, beta):
    law = _law(shear=beta)
    rng = np.random.default_rng(23)
    m = 25
    kcap = _kappa_cap(RES)
    # (w_n sign, target w_eff range, committed kappa: "rel" x w_eff or "abs" value, grows)
    cases = {
        "loading": (1.0, (1.2 * W0, 0.9 * kcap), ("rel", 1 / 1.05), True),
        "loading_from_elastic": (1.0, (1.2 * W0, 0.9 * kcap), ("abs", 0.5 * W0), True),
        "unloading": (1.0, (0.5 * W0, 0.8 * kcap), ("rel", 1.1), False),
        "unloading_capped": (1.0, (0.5 * W0, 0.8 * kcap), ("abs", 3 * WC), False),
        "loading_capped": (1.0, (1.1 * WC, 3 * WC), ("rel", 1 / 1.05), True),
        "virgin_elastic": (1.0, (0.05 * W0, 0.8 * W0), ("abs", 0.0), True),
        "elastic_below_kappa": (1.0, (0.05 * W0, 0.8 * W0), ("abs", 0.9 * W0), False),
        "compression_shear_loading": (-1.0, (1.2 * W0, 0.9 * kcap), ("rel", 1 / 1.05), True),
        "compression_shear_unloading": (-1.0, (1.2 * W0, 0.8 * kcap), ("rel", 1.1), False),
        "compression_virgin": (-1.0, (0.05 * W0, 0.8 * W0), ("abs", 0.0), True),
    }
    for name, (sign, (lo, hi), (kind, k), grows) in cases.items():
        dirs = _directions(d, m, rng, wn_sign=sign)
        target = rng.uniform(lo, hi, m)
        jump = dirs * (target / _w_eff(dirs, beta))[:, None]
        kappa_old = k * target if kind == "rel" else np.full(m, k)
        state = _state(kappa_old)
        t, T, new = law.update(jump, state)
        np.testing.assert_allclose(t, _expected(jump, kappa_old, beta, RES)[0], rtol=1e-12)
        grew = new["kappa"][:, 0] > kappa_old
        assert grew.all() if grows else not grew.any(), name
        assert _rel_err(_fd_tangent(law, jump, state), T) <= 1e-6, name
        if name in ("virgin_elastic", "elastic_below_kappa"):
            Tel = K0 * np.diag([1.0] + [beta**2] * (d - 1))
            np.testing.assert_allclose(T, np.broadcast_to(Tel, T.shape), rtol=1e-13)
        if name.startswith("unloading") or name == "elastic_below_kappa":
            # the secant: s(kappa_old) diag(1, beta^2, ...), symmetric
            s = _secant(kappa_old, RES)
            Tsec = s[:, None, None] * np.diag([1.0] + [beta**2] * (d - 1))
            np.testing.assert_allclose(T, Tsec, rtol=1e-12)


def test_tangent_on_the_loading_surface_is_the_loading_one():
    """w_eff == kappa_old > w_0 exactly (kappa_old taken from the law's own trial state): the
    returned tangent is the one-sided forward derivative (opening further loads), not the
    backward one (which unloads along the secant)."""
    law = _law(shear=0.7)
    rng = np.random.default_rng(5)
    kcap = _kappa_cap(RES)
    dirs = np.abs(_directions(3, 12, rng))  # every component > 0: a forward step loads
    target = rng.uniform(1.2 * W0, 0.9 * kcap, 12)
    jump = dirs * (target / _w_eff(dirs, 0.7))[:, None]
    _, _, on = law.update(jump, law.initial_state(12))
    np.testing.assert_allclose(on["kappa"][:, 0], target, rtol=1e-13)
    t0, T, new = law.update(jump, on)
    np.testing.assert_array_equal(new["kappa"], on["kappa"])
    h = 1e-6 * np.linalg.norm(jump, axis=1)
    fwd, bwd = np.empty_like(T), np.empty_like(T)
    for j in range(3):
        dp = np.zeros_like(jump)
        dp[:, j] = h
        # second-order one-sided differences (-3 f0 + 4 f1 - f2) / (2 h), each side
        t1, t2 = law.update(jump + dp, on)[0], law.update(jump + 2 * dp, on)[0]
        fwd[:, :, j] = (-3 * t0 + 4 * t1 - t2) / (2 * h[:, None])
        t1, t2 = law.update(jump - dp, on)[0], law.update(jump - 2 * dp, on)[0]
        bwd[:, :, j] = (3 * t0 - 4 * t1 + t2) / (2 * h[:, None])
    assert _rel_err(fwd, T) <= 1e-6
    assert _rel_err(bwd, T) > 1e-2  # the two sides differ: the check discriminates
    s = _secant(target, RES)
    assert _rel_err(bwd, s[:, None, None] * np.diag([1.0, 0.49, 0.49])) <= 1e-6


# --- 6. one step equals many along a proportional path ---------------------------------------


@pytest.mark.parametrize("d", [2, 3])
def test_one_step_equals_many_for_proportional_paths(d):
    law = _law(shear=0.6)
    rng = np.random.default_rng(3)
    m = 24
    dirs = rng.normal(size=(m, d))
    dirs[: m // 4, 0] = np.abs(dirs[: m // 4, 0])
    dirs[: m // 4, 1:] = 0.0  # some pure mode I
    dirs[m // 4 : m // 2, 0] = -np.abs(dirs[m // 4 : m // 2, 0])  # some compression + shear
    weff = _w_eff(dirs, 0.6)
    final = dirs * (rng.choice([0.5 * W0, 5 * W0, 0.5 * WC, 0.99 * WC, 2 * WC], m) / weff)[:, None]
    t_big, _, big = law.update(final, law.initial_state(m))
    state = law.initial_state(m)
    for t in np.linspace(0, 1, 101)[1:]:
        t_small, _, state = law.update(t * final, state)
    np.testing.assert_allclose(t_small, t_big, rtol=1e-12, atol=1e-15 * FT)
    np.testing.assert_allclose(state["kappa"], big["kappa"], rtol=1e-12, atol=0)
    np.testing.assert_allclose(big["kappa"][:, 0], _w_eff(final, 0.6), rtol=1e-14)


# --- 7. the committed state is never touched; the interface ------------------------------------


def test_update_keeps_the_committed_state():
    law = _law(shear=0.5)
    assert law.state_fields == {"kappa": 1}
    init = law.initial_state(8)
    assert set(init) == {"kappa"} and init["kappa"].shape == (8, 1)
    np.testing.assert_array_equal(init["kappa"], 0.0)
    rng = np.random.default_rng(9)
    _, _, state = law.update(0.3 * WC * rng.normal(size=(8, 3)), init)
    np.testing.assert_array_equal(init["kappa"], 0.0)
    committed = copy.deepcopy(state)
    jump = 0.6 * WC * rng.normal(size=(8, 3))
    jump_copy = jump.copy()
    law.update(1.5 * jump, state)  # a trial that is then discarded
    t2, T2, new2 = law.update(jump, state)
    np.testing.assert_array_equal(state["kappa"], committed["kappa"])
    np.testing.assert_array_equal(jump, jump_copy)
    assert not np.shares_memory(new2["kappa"], state["kappa"])
    assert (new2["kappa"] > state["kappa"]).any()
    assert t2.shape == (8, 3) and T2.shape == (8, 3, 3) and new2["kappa"].shape == (8, 1)
    # the same step from the same committed state gives the same result (no hidden history)
    t3, T3, new3 = law.update(jump, committed)
    np.testing.assert_array_equal(t3, t2)
    np.testing.assert_array_equal(T3, T2)
    np.testing.assert_array_equal(new3["kappa"], new2["kappa"])
    # unloading trial (nothing grows) still returns new arrays
    _, _, new4 = law.update(np.zeros((8, 3)), state)
    assert not np.shares_memory(new4["kappa"], state["kappa"])
    np.testing.assert_array_equal(new4["kappa"], committed["kappa"])
    new4["kappa"][:] = -1.0
    np.testing.assert_array_equal(state["kappa"], committed["kappa"])


# --- 8. bad input ----------------------------------------------------------------------------

NAN = float("nan")


@pytest.mark.parametrize(
    "kwargs,text",
    [
        ({"ft": 0}, "ft=0"),
        ({"ft": -1}, "ft=-1"),
        ({"Gf": 0}, "Gf=0"),
        ({"Gf": -0.5}, "Gf=-0.5"),
        ({"shear": -0.5}, "shear=-0.5"),
        ({"stiffness": 0}, "stiffness=0"),
        ({"stiffness": -5}, "stiffness=-5"),
        ({"factor": 0}, "factor=0"),
        ({"factor": -2}, "factor=-2"),
        ({"residual": 0}, "residual=0"),
        ({"residual": 1}, "residual=1"),
        ({"residual": 1.5}, "residual=1.5"),
        ({"residual": -0.1}, "residual=-0.1"),
        ({"ft": NAN}, "ft=nan"),
        ({"Gf": NAN}, "Gf=nan"),
        ({"shear": NAN}, "shear=nan"),
        ({"stiffness": NAN}, "stiffness=nan"),
        ({"factor": NAN}, "factor=nan"),
        ({"residual": NAN}, "residual=nan"),
    ],
)
def test_bad_parameters_are_named(kwargs, text):
    args = {"ft": FT, "Gf": GF, "shear": 1.0, "stiffness": K0} | kwargs
    with pytest.raises(ValueError, match="(?i)" + re.escape(text)):
        LinearCohesive(**args)


def test_too_low_stiffness_and_missing_stiffness():
    # ft = 2, Gf = 1: w_c = 1 and K0 = ft^2 / (2 Gf) = 2 gives w_0 = 1 exactly
    LinearCohesive(2.0, 1.0, stiffness=2.5)  # w_0 = 0.8 < w_c: fine
    for k in (2.0, 1.0, 1e-3):
        with pytest.raises(ValueError, match="stiffness"):
            LinearCohesive(2.0, 1.0, stiffness=k)
    # by with_stiffness: factor E / h = 100 * 1 / 100 = 1 <= 2
    with pytest.raises(ValueError, match="stiffness"):
        LinearCohesive(2.0, 1.0).with_stiffness(1.0, 100.0)
    # update before the stiffness is set
    law = LinearCohesive(FT, GF)
    assert law.stiffness is None
    with pytest.raises(ValueError, match="with_stiffness"):
        law.update(np.zeros((2, 2)), law.initial_state(2))


# --- 9. with_stiffness ---------------------------------------------------------------------


def test_with_stiffness():
    E, h = 30e3, 2.5
    law = LinearCohesive(FT, GF, shear=0.4, factor=50.0)
    set_ = law.with_stiffness(E, h)
    assert isinstance(set_, LinearCohesive)
    np.testing.assert_allclose(set_.stiffness, 50.0 * E / h, rtol=1e-15)
    assert law.stiffness is None  # a copy: the original is unchanged
    assert (set_.ft, set_.Gf, set_.shear, set_.factor) == (FT, GF, 0.4, 50.0)
    np.testing.assert_allclose(set_.w_0, FT * h / (50.0 * E), rtol=1e-15)
    # a given stiffness is kept
    given = LinearCohesive(FT, GF, stiffness=K0, factor=50.0)
    assert given.with_stiffness(E, h).stiffness == K0
    # the law with the stiffness works: elastic tangent K0 diag(1, beta^2)
    _, T, _ = set_.update(np.array([[1e-9, 1e-9]]), set_.initial_state(1))
    np.testing.assert_allclose(T[0], 50.0 * E / h * np.diag([1.0, 0.16]), rtol=1e-14)
    # frozen
    with pytest.raises(dataclasses.FrozenInstanceError):
        set_.ft = 1.0


def test_with_stiffness_keeps_residual_and_the_defaults():
    law = LinearCohesive(FT, GF, residual=0.001).with_stiffness(30e3, 2.5)
    assert law.residual == 0.001
    default = LinearCohesive(FT, GF)
    assert (default.shear, default.stiffness, default.factor, default.residual) == (
        1.0,
        None,
        30.0,
        RES,
    )
    # default factor 30: K0 = 30 E / h
    np.testing.assert_allclose(default.with_stiffness(30e3, 2.5).stiffness, 30 * 30e3 / 2.5)
