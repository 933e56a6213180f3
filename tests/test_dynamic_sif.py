"""Dynamic stress intensity factors (issue 11, item 1): the interaction integral with the inertia
term at a stationary tip, and K_I(t) of explicit models against Freund's solution.

Oracles: (1) an exact field: a Williams field plus a smooth field ``w`` that is not in
equilibrium, with the acceleration ``div sigma(w) / rho`` that makes the pair satisfy the
momentum balance; ``w`` is free on the crack faces (its gradient vanishes there) and has no
singularity, so K is the Williams field's exactly, on every domain, in plane strain and plane
stress; without the inertia term the result is off (the check can fail). (2) Freund's K_I(t) of
a semi-infinite crack under a suddenly applied crack-face pressure (equivalently a plane step
wave reaching the crack plane; plane strain) before waves from elsewhere reach the tip
(``demos/dynamic_sif_freund.py``). (3) Serial equals 2 ranks: under mpirun the model is also run
on each rank alone (``COMM_SELF``) and compared.
"""

from __future__ import annotations

import json

import dolfinx_meshfree as mf
from dolfinx_meshfree.fracture.frame import TipFrame
from dolfinx_meshfree.fracture.interaction import interaction_integral
from dolfinx_meshfree.fracture.williams import WilliamsField

import numpy as np
import pytest
from conftest import load_demo
from mpi4py import MPI

COMM = MPI.COMM_WORLD
TIP, ANGLE = np.array([0.3, -0.2]), 0.4
DIRECTION = np.array([np.cos(ANGLE), np.sin(ANGLE)])
FRAME = TipFrame(TIP, DIRECTION)
KI, KII = 1.3, -0.7
#: ``w = (y^2 (c00 + c01 x), y^2 (c10 + c11 x))`` in the tip frame: zero gradient on y = 0.
CW = np.array([[0.4, -0.3], [0.25, 0.6]])


def _grad_w_local(x: np.ndarray) -> np.ndarray:
    g = np.zeros((len(x), 2, 2))
    for i in range(2):
        g[:, i, 0] = x[:, 1] ** 2 * CW[i, 1]
        g[:, i, 1] = 2.0 * x[:, 1] * (CW[i, 0] + CW[i, 1] * x[:, 0])
    return g


def exact_fields(mat: mf.LinearElastic):
    """``grad u`` of Williams (K_I, K_II, T) + w, and ``u_tt = div sigma(w) / rho`` (central
    differences of the quadratic stress: exact to round-off)."""
    williams = WilliamsField(mat, KI, KII, T=0.5, tip=tuple(TIP), direction=tuple(DIRECTION))

    def grad_u(x):
        return williams.fields(x)[1] + FRAME.tensors_to_global(_grad_w_local(FRAME.to_local(x)))

    def acceleration(x):
        xl, h = FRAME.to_local(x), 1e-3
        div = np.zeros((len(xl), 2))
        for j in range(2):
            e = np.zeros(2)
            e[j] = h
            s_p, s_m = mat.stress(_grad_w_local(xl + e)), mat.stress(_grad_w_local(xl - e))
            div += (s_p[:, :, j] - s_m[:, :, j]) / (2.0 * h)
        return FRAME.vectors_to_global(div / mat.rho)

    return grad_u, acceleration


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_inertia_term_on_an_exact_field(plane):
    """Measured: K_I, K_II, J to 1.6e-15 on three domains; without the inertia term off by
    3e-3 to 0.16 (checks 1e-12 and > 1e-3)."""
    mat = mf.LinearElastic(2.0, 0.3, plane=plane, rho=3.0)
    grad_u, acc = exact_fields(mat)
    radii = [0.1, 0.2, 0.4]
    s = interaction_integral(grad_u, mat, TIP, DIRECTION, radii, acceleration=acc)
    J = (KI**2 + KII**2) / s.E_prime
    assert np.abs(s.K_I - KI).max() <= 1e-12 and np.abs(s.K_II - KII).max() <= 1e-12
    assert np.abs(s.J - J).max() <= 1e-12
    static = interaction_integral(grad_u, mat, TIP, DIRECTION, radii)
    assert np.abs(static.K_I - KI).min() > 1e-3 and np.abs(static.K_II - KII).min() > 1e-3


def test_zero_acceleration_is_the_static_integral():
    """With ``u_tt = 0`` the dynamic integral is the static one, bit for bit."""
    mat = mf.LinearElastic(2.0, 0.3, plane="strain", rho=3.0)
    grad_u, _ = exact_fields(mat)
    static = interaction_integral(grad_u, mat, TIP, DIRECTION, [0.1, 0.3])
    zero = interaction_integral(
        grad_u, mat, TIP, DIRECTION, [0.1, 0.3], acceleration=lambda x: np.zeros((len(x), 2))
    )
    for name in ("K_I", "K_II", "J"):
        assert np.array_equal(getattr(static, name), getattr(zero, name))


def test_bad_acceleration():
    mat = mf.LinearElastic(2.0, 0.3, plane="strain")
    grad_u, _ = exact_fields(mat)
    with pytest.raises(ValueError, match="acceleration must return finite values of shape"):
        interaction_integral(
            grad_u, mat, TIP, DIRECTION, 0.2, acceleration=lambda x: np.zeros((len(x), 3))
        )


# --- Freund -----------------------------------------------------------------------------------
#: Measured (81 cells across 2H, h = 0.0247, 8 samples over the window, radii 4 h and 6 h,
#: compared after the first tenth of the window: all 8 samples, from (t - t0) c_d = 0.24):
#: largest |error| efg 2.4 %, lagrange 1.7 %: checked against the issue's 5 %. |K_II| / max K_I
#: <= 3.7e-4 (symmetric problem; check 1e-3). Spread between the radii 0.24 % / 0.59 % of max
#: K_I (check 1.2 %).
FREUND_CELLS = 81


@pytest.mark.parametrize("method", ["efg", "lagrange"])
def test_freund_step_wave(method):
    demo = load_demo("dynamic_sif_freund")
    rec = demo.run(method, FREUND_CELLS, samples=8)
    err = np.asarray(rec["error"])
    compared = np.asarray(rec["compared"])
    assert compared.all()
    assert np.abs(err[compared]).max() <= 0.05
    assert np.abs(rec["KII"]).max() <= 1e-3 * max(rec["K_freund"])
    assert rec["energy_drift"] <= 1e-12  # measured 5e-15 - 9e-15
    KI = np.asarray(rec["KI"])
    assert np.abs(KI[:, 0] - KI[:, 1]).max() <= 0.012 * KI.max()  # path independence
    if COMM.size > 1:  # the same model on one rank
        alone = demo.run(method, FREUND_CELLS, samples=8, comm=MPI.COMM_SELF)
        assert np.abs(np.asarray(alone["KI"]) - rec["KI"]).max() <= 1e-8 * KI.max()


def test_freund_demo_main(shared_dir):
    """The demo's command line: its own 5 % check passes (exit 0) and the JSON holds the
    history (bridging at 41 cells: measured 2.6 %)."""
    demo = load_demo("dynamic_sif_freund")
    out = shared_dir / "freund.json"
    args = ["--method", "bridging", "--cells", "41", "--samples", "6", "--json", str(out)]
    assert demo.main(args) == 0
    COMM.Barrier()
    (rec,) = json.loads(out.read_text())
    assert rec["method"] == "bridging" and len(rec["t"]) == 6 and len(rec["KI"][0]) == 2
    assert rec["max_error"] <= 0.05
