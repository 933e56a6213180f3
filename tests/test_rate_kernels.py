"""The compiled HJC update (dolfinx_meshfree.physics.rate_kernels) against the numpy reference.

``tests/test_hjc.py`` checks the default backend (the compiled one, with numba) against the
closed forms of Holmquist, Johnson & Cook 1993; here the two implementations are driven
through the same paths at many points, which cross every region of the equation of state,
unload, reload, go into tension, shear, spin, damage and erode, in 3D, plane strain and
axisymmetry, and must agree to round-off at every step (the reference sums in other orders:
LAPACK's ``det``, numpy's stacked products). Both take their steps from their own states, so
a drift would grow; none does.
"""

from __future__ import annotations

import dataclasses

from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.physics import rate_kernels
from dolfinx_meshfree.physics.constitutive import DeformationError
from dolfinx_meshfree.physics.hjc import HolmquistJohnsonCook
from dolfinx_meshfree.physics.johnson_cook import JohnsonCook
from dolfinx_meshfree.physics.objective import nominal_stress

import numpy as np
import pytest

pytestmark = [
    pytest.mark.serial,  # a point-wise law: no parallel code path
    pytest.mark.skipif(not jit.AVAILABLE, reason="the compiled backend needs numba"),
]


def paths(m: int, d: int, steps: int, seed: int) -> np.ndarray:
    """``(steps + 1, m, d, d)`` gradients from ``I``: a compression and back, each point to
    its own depth (from region I to region III: ``mu_plock`` is 0.12), ending in a little
    tension, with a shear up to 0.03 and a spin up to 1.5 rad."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, steps + 1)[:, None]
    squeeze = 0.15 * rng.uniform(0.0, 1.0, m) ** 3 * np.sin(np.pi * t) ** 2
    stretch = 1.0 - squeeze + rng.uniform(0.0, 0.002, m) * t
    shear = rng.uniform(-0.03, 0.03, m) * t
    angle = rng.uniform(0.0, 1.5, m) * t
    U = np.zeros((steps + 1, m, 2, 2))
    U[..., 0, 0], U[..., 1, 1], U[..., 0, 1] = stretch, 1.0 - 0.3 * squeeze, shear
    R = np.stack([np.cos(angle), -np.sin(angle), np.sin(angle), np.cos(angle)], -1)
    F2 = R.reshape(steps + 1, m, 2, 2) @ U
    if d == 2:
        return F2
    F = np.zeros((steps + 1, m, 3, 3))
    F[..., :2, :2] = F2
    F[..., 2, 2] = 1.0 - 0.3 * squeeze
    F[..., 2, 0] = 0.5 * shear
    return F


def run(law: HolmquistJohnsonCook, F: np.ndarray, hoop: np.ndarray | None, dt: float) -> list:
    """The stresses and states of every step."""
    state, out = law.initial_state(F.shape[1]), []
    for k in range(1, len(F)):
        extra = {} if hoop is None else {"hoop": hoop[k]}
        sigma, state = law.update(F[k], dt, state, **extra)
        out.append((sigma, state))
    return out


def both_backends(base, seed: int) -> tuple:
    """``(compiled law, reference law, their steps, ...)``: ``base`` with each backend driven
    through the same 120-step :func:`paths` at 200 points (with a hoop stretch within 10 % of 1
    in axisymmetry), ``run``'s lists."""
    d = 3 if base.plane is None else 2
    F = paths(200, d, 120, seed=seed)
    hoop = None
    if base.plane == "axisymmetric":
        rng = np.random.default_rng(seed + 1)
        hoop = 1.0 + 0.1 * rng.uniform(-1, 1, 200) * np.linspace(0, 1, 121)[:, None]
    fast_law, slow_law = (dataclasses.replace(base, backend=b) for b in ("numba", "numpy"))
    return fast_law, slow_law, run(fast_law, F, hoop, 2e-6), run(slow_law, F, hoop, 2e-6)


#: The round-off of a dimensionless field computed from gradients of order 1 (``mu = 1 / J - 1``,
#: the plastic strain): a few units of 1's last place, whatever the field's own size. On this
#: machine's CPU the compiled plane-strain plastic strain at its first yielding steps (scale
#: 3.2e-5) differed from the reference by 7.8e-16 = 3.5 eps, 2.4e-11 of its scale; on the
#: machine of stop 60, within 7.3e-12. Fields in Pa or J/m^3 never come near this floor.
ROUND_OFF = 8 * np.finfo(float).eps


def assert_agree(s1: np.ndarray, a: dict, s2: np.ndarray, b: dict, tol: float) -> None:
    """One step's stresses and state fields within ``tol`` of each one's scale (the
    deviator's: the stress's), or within :data:`ROUND_OFF` of 1; the compiled fields
    C-contiguous."""
    assert np.abs(s1 - s2).max() <= tol * np.abs(s2).max()
    for name in a:
        scale = np.abs(s2 if name == "deviator" else b[name]).max()
        assert np.abs(a[name] - b[name]).max() <= max(tol * scale, ROUND_OFF), name
        assert a[name].flags.c_contiguous


@pytest.mark.parametrize(
    ("plane", "erosion"),
    [(None, None), (None, 0.05), ("strain", None), ("axisymmetric", 0.05)],
)
def test_compiled_update_meets_the_reference(plane, erosion):
    """Every step's stress and state fields agree within 2e-11 of each field's scale (the
    deviator's: the stress's) or :data:`ROUND_OFF`, measured up to 7.3e-12 (the plastic
    strain; ``mu = 1 / J - 1`` of a small compression takes the round-off of ``det F``
    relative to ``mu``), and on another CPU 7.8e-16 where the plastic strain's scale was
    3.2e-5 (3.5 eps: the floor). The paths
    end with points in region III, in tension, intact, fully damaged and (with erosion)
    eroded, so each branch is compared. The wave speed and the nominal stress of the same
    state agree within 1e-15 (measured 2.1e-16 and 3.5e-16)."""
    base = HolmquistJohnsonCook.concrete_48mpa(plane=plane, erosion=erosion)
    fast_law, slow_law, fast, slow = both_backends(base, seed=3)
    for (s1, a), (s2, b) in zip(fast, slow, strict=True):
        assert_agree(s1, a, s2, b, 2e-11)
        c1, c2 = fast_law.wave_speed(b), slow_law.wave_speed(b)  # the same state
        assert abs(c1 - c2) <= 1e-15 * c2
        F3 = b["F"].reshape(-1, 3, 3)
        P1, P2 = (nominal_stress(s2, F3, backend=k) for k in ("numba", "numpy"))
        assert np.abs(P1 - P2).max() <= 1e-15 * np.abs(P2).max()
        assert np.array_equal(P1 == 0.0, P2 == 0.0)  # the eroded: none
    last = slow[-1][1]
    assert (last["mu_max"] > base.mu_plock).any()  # region III
    assert (last["pressure"] < 0.0).any()  # tension
    assert (last["damage"] < 0.5).any() and (last["damage"] == 1.0).any()
    if erosion is not None:
        assert 0 < last["eroded"].sum() < 200


@pytest.mark.parametrize("plane", [None, "strain", "axisymmetric"])
def test_compiled_johnson_cook_meets_the_reference(plane):
    """Johnson–Cook's compiled step against its reference on the same paths (4340 steel: it
    yields at a shear of about 0.01, so most points flow): every step's stress and state within
    1e-11 of each field's scale (measured up to 1.8e-12); most points flow, some stay
    elastic."""
    _, _, fast, slow = both_backends(JohnsonCook.steel_4340(plane=plane), seed=5)
    for (s1, a), (s2, b) in zip(fast, slow, strict=True):
        assert_agree(s1, a, s2, b, 1e-11)
    assert (slow[-1][1]["plastic_strain"] > 0.0).mean() > 0.5
    assert (slow[-1][1]["plastic_strain"] == 0.0).any()


def test_compiled_update_hands_bad_points_to_the_reference():
    """An inverted or non-finite gradient without erosion, and a step whose mid-step gradient
    is singular, raise the reference's errors, which name the point (HJC and Johnson–Cook)."""
    law = HolmquistJohnsonCook.concrete_48mpa(backend="numba")
    state = law.initial_state(3)
    F = np.repeat(np.eye(3)[None], 3, axis=0)
    F[1, 0, 0] = -1.0
    with pytest.raises(DeformationError, match=r"det F = -1.000e\+00 <= 0 at 1 point"):
        law.update(F, 1e-6, state)
    F[1, 0, 0] = np.nan
    with pytest.raises(DeformationError, match="F is not finite at 1 point"):
        law.update(F, 1e-6, state)
    F[1] = np.eye(3)
    _, state = law.update(F, 1e-6, state)
    state["F"][2] = np.diag([-1.0, 1.0, -1.0]).ravel()  # det 1; the mid-step with I: singular
    with pytest.raises(
        ValueError, match="mid-step deformation gradient has det = 0 <= 0 at point 2"
    ):
        law.update(F, 1e-6, state)
    steel = JohnsonCook.steel_4340(backend="numba")
    F[1, 0, 0] = -1.0
    with pytest.raises(DeformationError, match=r"det F = -1.000e\+00 <= 0 at 1 point"):
        steel.update(F, 1e-6, steel.initial_state(3))


def test_backend_by_name():
    """An unknown backend is refused by name, with the ones known."""
    with pytest.raises(
        ValueError, match=r"backend='fortran' .* not known; use one of \('numba', 'numpy'\)"
    ):
        HolmquistJohnsonCook.concrete_48mpa(backend="fortran")
    assert rate_kernels.resolve_backend(None) == rate_kernels.DEFAULT_BACKEND


def test_smallest_stretch_meets_the_svd():
    """``smallest_stretches`` (Jacobi on ``F^T F``) against numpy's SVD: random gradients with
    stretches from 0.05 to 2 and any rotation, the identity, a rotation, a crushed cell (0.01)
    and a repeated stretch, within 5e-13 relative (measured 2.0e-13: ``C = F^T F`` squares the
    stretches' spread, 40 here, into its round-off); points not live read 1."""
    rng = np.random.default_rng(7)
    m = 2000
    Q1, _ = np.linalg.qr(rng.normal(size=(m, 3, 3)))
    Q2, _ = np.linalg.qr(rng.normal(size=(m, 3, 3)))
    S = rng.uniform(0.05, 2.0, (m, 3))
    F = Q1 * S[:, None, :] @ Q2
    F[0], F[1] = np.eye(3), Q1[1]
    F[2] = np.diag([1.0, 0.01, 1.0]) @ Q2[2]
    F[3] = Q1[3] @ np.diag([0.5, 0.5, 2.0])
    live = np.ones(m, dtype=bool)
    live[10] = False
    got = rate_kernels.smallest_stretches(F.reshape(m, 9), live)
    want = np.linalg.svd(F, compute_uv=False)[:, -1]
    assert got[10] == 1.0
    rel = np.abs(got - want)[live] / want[live]
    assert rel.max() < 5e-13
    assert got[0] == pytest.approx(1.0, rel=1e-15) and got[2] == pytest.approx(0.01, rel=1e-12)
