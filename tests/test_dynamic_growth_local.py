"""The local update of a cracked explicit model after an extension (issue 11, item 2):
:class:`~dolfinx_meshfree.dynamics.growth_local.LocalModelUpdate` and
``DynamicCrackGrowth(update="local")``.

Oracle: a model built from scratch with the grown crack (the full rebuild, an independent
computation: every table, rule, mass and constraint row assembled again). After 1, 2 and 3
extensions the updated model equals it: the internal force ``K u`` of a random ``u``, the lumped
masses, the constraint blocks, the stable step, and the state after 6 more steps from the same
state (efg, lagrange, bridging; an edge crack whose mouth is on the boundary and an interior
crack; serial and 2 ranks). Measured: 1e-16 - 1e-15 relative (check 1e-12).

The model is the Freund plate of ``demos/dynamic_sif_freund.py`` (21 cells across 2H), the
couplings' patch 0.9 wide (the tip stays 4 spacings from the FE interface: no constraint row
changes, the update is local throughout).
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree.dynamics import CrackContact, DynamicCrackGrowth
from dolfinx_meshfree.dynamics.growth_local import LocalModelUpdate

import numpy as np
import pytest
from conftest import load_demo
from mpi4py import MPI

COMM = MPI.COMM_WORLD
CELLS = 21
FR = load_demo("dynamic_sif_freund")
H_SPACING = 2.0 * FR.H / CELLS
SEG = 1.5 * H_SPACING
#: Kink angles of the three extensions (radians, from the tip direction).
KINKS = (0.5, 0.5, -0.9)
#: An edge crack (its mouth on x = 0) and an interior crack (both ends inside the particles).
CRACKS = {"edge": [[0.0, 0.0], [0.8, 0.0]], "interior": [[0.3, 0.0], [0.8, 0.0]]}


def _max(values) -> float:
    return COMM.allreduce(max([0.0, *values]), op=MPI.MAX)


def _model(method: str, points, msh=None, quadrature=None, contact=None):
    kw = {} if method == "efg" else {"patch_width": 0.9}
    crack = mf.Crack(np.array(points, dtype=float))
    dyn = FR.build(
        method, CELLS, COMM, crack=crack, msh=msh, quadrature=quadrature, crack_contact=contact,
        **kw,
    )[0]  # fmt: skip
    return dyn, crack


def _differences(a, b) -> dict:
    """Relative differences of two models: K u (a random u, the same on both), masses,
    constraint blocks, stable step."""
    rng = np.random.default_rng(7 + COMM.rank)
    for x, y in zip(a.stepper.u, b.stepper.u, strict=True):
        x.array[:] = rng.standard_normal(x.getLocalSize())
        x.copy(y)
    fa, fb = a.system.internal_force(a.stepper.u), b.system.internal_force(b.stepper.u)
    out = {
        "force": _max(np.abs(x.array - y.array).max(initial=0) for x, y in zip(fa, fb, strict=True))
        / _max(np.abs(y.array).max(initial=0) for y in fb),
        "mass": _max(
            np.abs(f.mass.array - g.mass.array).max(initial=0)
            for f, g in zip(a.fields, b.fields, strict=True)
        )
        / _max(g.mass.array.max(initial=0) for g in b.fields),
        "dt": abs(a.stable_time_step() / b.stable_time_step() - 1.0),
        "G": 0.0,
    }
    for x in (*fa, *fb):
        x.destroy()
    for A, B in zip(a.G or [], b.G or [], strict=True):
        if A is not None:
            C = A.copy()
            C.axpy(-1.0, B)
            out["G"] = max(out["G"], C.norm() / B.norm())
            C.destroy()
    return out


@pytest.mark.parametrize("start", ["edge", "interior"])
@pytest.mark.parametrize("method", ["efg", "lagrange", "bridging"])
def test_local_update_equals_a_full_rebuild(method, start):
    """After each of three extensions: forces, masses, constraint rows, stable step and the
    state after 6 more steps equal a fresh model's (measured <= 2.1e-15; check 1e-12; the
    stable step drops by 22-29 % in efg, 0.05-0.2 % in the couplings); the
    update is local (no constraint row or load in reach) and touches only the cells near the
    new segment (fewer than a quarter of the particle cells)."""
    _extend_and_compare(method, start, None)


@pytest.mark.parametrize("method", ["efg", "lagrange"])
def test_local_update_with_crack_contact_equals_a_full_rebuild(method):
    """The same with the faces' contact (``CrackContact()``, the penalty's default): the local
    update rebuilds the faces' gap operator for the grown crack, so the forces, the stable
    step (which bounds the full contact stiffness), the masses and the state after 6 more
    steps equal a fresh model's (measured <= 4.8e-16, 2.2e-16, 1.3e-15, 2.4e-16; check
    1e-12). The random ``u`` closes faces: with the old operator kept the forces were 0.28
    apart and the stable steps 1.8e-3. Before, a model with contact was rebuilt in full at
    every extension."""
    _extend_and_compare(method, "edge", CrackContact())


def _extend_and_compare(method: str, start: str, contact: CrackContact | None) -> None:
    dyn, crack = _model(method, CRACKS[start], contact=contact)
    msh = dyn.mesh
    upd = LocalModelUpdate(dyn)
    assert (upd.contact is not None) == (contact is not None)
    dyn.set_initial(velocity=lambda x: np.stack([0.1 * x[:, 1], 0.05 * x[:, 0] ** 2], axis=1))
    dt = 0.5 * dyn.stable_time_step()
    dyn.run(4 * dt, dt=dt)
    ncells = COMM.allreduce(upd.cells.size, op=MPI.SUM)
    for kink in KINKS:
        trial = mf.Crack(crack.points.copy())
        trial.extend(kink, SEG, tip=-1)
        plan = upd.prepare(trial.points, crack)
        assert plan is not None, upd.last
        crack.extend(kink, SEG, tip=-1)
        upd.apply(plan)
        assert upd.last["mode"] == "local" and upd.last["cells"] < ncells / 4
        fresh, _ = _model(method, crack.points, msh, contact=contact)
        if contact is not None:
            assert dyn.system.num_points == fresh.system.num_points > 0
        # the same state (d_n, v_{n-1/2}), projected onto the fresh constraint
        u0 = [x.copy() for x in dyn.stepper.u]
        diff = _differences(dyn, fresh)
        for src, dst in (
            (u0, dyn.stepper.u),
            (u0, fresh.stepper.u),
            (dyn.stepper.v, fresh.stepper.v),
        ):
            for x, y in zip(src, dst, strict=True):
                x.copy(y)
        if fresh.projection is not None:
            fresh.projection.correct(fresh.stepper.u)
            fresh.projection.correct(fresh.stepper.v)
        fresh.stepper.step, fresh.stepper.time, fresh.stepper.dt_prev = (
            dyn.step, dyn.time, dyn.stepper.dt_prev
        )  # fmt: skip
        for m in (dyn, fresh):
            m.run(m.time + 6 * dt, dt=dt)
        du = _max(
            np.abs(x.array - y.array).max(initial=0)
            for x, y in zip(dyn.stepper.u, fresh.stepper.u, strict=True)
        )
        un = _max(np.abs(x.array).max(initial=0) for x in fresh.stepper.u)
        assert max(diff.values()) <= 1e-12, diff
        assert du <= 1e-12 * un
        fresh.destroy()
        for x in u0:
            x.destroy()
    dyn.destroy()


@pytest.mark.parametrize("method", ["efg", "lagrange"])
def test_local_update_with_an_adaptive_rule(method):
    """With an adaptive rule (dense within 3 spacings of the tip, 2x2 elsewhere) the dense
    zone moves with the tip: the update re-integrates the cells entering and leaving it
    (:func:`~dolfinx_meshfree.geometry.adaptive_quadrature.changed_cells`) and equals a fresh
    model with the same rule after each extension (check 1e-12); the same model updated as if
    its rule were uniform differs from the fresh one (the check can fail)."""
    rule = mf.AdaptiveQuadrature(3.0 * H_SPACING)
    dyn, crack = _model(method, CRACKS["interior"], quadrature=rule)
    assert dyn.quadrature is rule
    upd = LocalModelUpdate(dyn)
    blind, blind_crack = _model(method, CRACKS["interior"], dyn.mesh, quadrature=rule)
    blind_upd = LocalModelUpdate(blind)
    blind_upd.quadrature = None  # as if the rule did not move: only the cut cells change
    for kink in KINKS[:2]:
        for u, c in ((upd, crack), (blind_upd, blind_crack)):
            trial = mf.Crack(c.points.copy())
            trial.extend(kink, SEG, tip=-1)
            plan = u.prepare(trial.points, c)
            assert plan is not None, u.last
            c.extend(kink, SEG, tip=-1)
            u.apply(plan)
        fresh, _ = _model(method, crack.points, dyn.mesh, quadrature=rule)
        assert max(_differences(dyn, fresh).values()) <= 1e-12
        assert _differences(blind, fresh)["force"] > 1e-6
        fresh.destroy()
    dyn.destroy()
    blind.destroy()


def test_adaptive_rule_moving_over_bridging_band_constraints_falls_back():
    """Bridging ties the patch over its band cells with the cell rule: a dense zone moving onto
    band cells may change a constraint row, so the update declines (the caller rebuilds)."""
    rule = mf.AdaptiveQuadrature(3.0 * H_SPACING)
    dyn, crack = _model("bridging", CRACKS["interior"], quadrature=rule)
    upd = LocalModelUpdate(dyn)
    trial = mf.Crack(crack.points.copy())
    trial.extend(KINKS[0], SEG, tip=-1)
    assert upd.prepare(trial.points, crack) is None
    assert upd.last["reason"] == "a constraint row on a cell whose rule changes"
    dyn.destroy()


def test_extra_cells_and_the_fallback_near_a_constraint():
    """``extra_cells`` (the adaptive rule's hook) re-integrates more cells with the same result;
    an extension that reaches the rollers at x = W (a constraint row) is refused (``None``,
    the reason named) and the rebuild is the caller's."""
    dyn, crack = _model("efg", CRACKS["edge"])
    upd = LocalModelUpdate(dyn)
    trial = mf.Crack(crack.points.copy())
    trial.extend(0.0, SEG, tip=-1)
    plan = upd.prepare(trial.points, crack, extra_cells=upd.cells[::3])
    crack.extend(0.0, SEG, tip=-1)
    upd.apply(plan)
    fresh, _ = _model("efg", crack.points, dyn.mesh)
    assert max(_differences(dyn, fresh).values()) <= 1e-12
    fresh.destroy()
    trial = mf.Crack(crack.points.copy())
    trial.extend(0.0, 0.95 * (FR.W - crack.points[-1, 0]), tip=-1)  # toward the rollers
    assert upd.prepare(trial.points, crack) is None
    assert "constraint row" in upd.last["reason"]
    dyn.destroy()


def _growth(update: str, **kw) -> DynamicCrackGrowth:
    dyn, crack = _model("efg", CRACKS["edge"])
    msh = dyn.mesh
    dyn.destroy()

    def build(c: mf.Crack) -> mf.ExplicitDynamics:
        return FR.build("efg", CELLS, COMM, crack=c, msh=msh)[0]

    cs = float(np.sqrt(FR.MATERIAL.mu / FR.MATERIAL.rho))
    return DynamicCrackGrowth(
        build, crack, K_Ic=0.8, speed=0.8 * cs, segment=3.5 * H_SPACING, check_every=2,
        radius=np.array([2.0, 3.0]) * H_SPACING, update=update, **kw,
    )  # fmt: skip


def test_growth_local_equals_full():
    """The Freund plate's growth (one extension) with ``update="local"`` and ``"full"``: the
    same checks, K to 1e-12 relative (measured 3e-16), the same path, the same released
    energy; the local run updated in place (one local update, no rebuild)."""
    T = FR.H / FR.MATERIAL.wave_speed() + 2.0 * FR.H / FR.MATERIAL.wave_speed()
    runs = {}
    for update in ("full", "local"):
        g = _growth(update)
        g.run(T)
        runs[update] = g
    full, local = runs["full"], runs["local"]
    assert full.timings["full"] == 1 and local.timings["local"] == 1
    assert local.timings["full"] == 0
    KI, KJ = np.array(full.KI_history()), np.array(local.KI_history())
    assert KI.shape == KJ.shape
    assert np.abs(KI - KJ).max() <= 1e-12 * np.abs(KI).max()
    assert np.abs(full.path - local.path).max() <= 1e-14
    (ta, ea), (tb, eb) = full.released[0], local.released[0]
    assert ta == tb and eb == pytest.approx(ea, rel=1e-10) and eb > 0


def test_dt_above_the_updated_stable_step_is_refused():
    """A given ``dt`` equal to the first model's stable step: the local update lowers the
    stable step (the cut cells' masses; measured 0.99956x after the extension), and
    the next chunk is refused with the step, the time and the tip named."""
    g = _growth("local")
    dt0 = g.model.stable_time_step()
    g.model.destroy()
    g = _growth("local", dt=dt0)
    T = 3.0 * FR.H / FR.MATERIAL.wave_speed()
    with pytest.raises(ValueError, match=r"above the stable time step .* rebuilt or updated at"):
        g.run(T)
    assert g.timings["local"] == 1 and g.model.stable_time_step() < dt0 * (1 - 1e-12)


# --- bad input --------------------------------------------------------------------------------
def test_bad_update_options():
    with pytest.raises(ValueError, match="update='bogus' is not known"):
        _growth("bogus")
    with pytest.raises(ValueError, match="quadrature_degree=0 must be an integer"):
        _growth("local", quadrature_degree=0)
    with pytest.raises(ValueError, match="quadrature_degree=5"):
        _growth("local", quadrature_degree=5)
    dyn, crack = _model("efg", CRACKS["edge"])
    msh = dyn.mesh
    dyn.destroy()

    def copying(c: mf.Crack) -> mf.ExplicitDynamics:  # builds with a copy of the crack
        return FR.build("efg", CELLS, COMM, crack=mf.Crack(c.points.copy()), msh=msh)[0]

    with pytest.raises(ValueError, match="does not hold the crack it was given"):
        DynamicCrackGrowth(copying, crack, K_Ic=0.8, speed=0.1, segment=SEG, tip=-1, update="local")
