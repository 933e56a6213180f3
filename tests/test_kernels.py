"""Weight functions of Belytschko et al. 1995, eq. (3.10a–c), and the SPH cubic-spline kernel.

The reference values are written out here by hand (fractions of the paper's polynomials), not
computed with the library's formulas.
"""

import math

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx.kernels import WEIGHTS, get_weight

import numpy as np
import pytest
from conftest import EPS, SQRT_EPS
from scipy import integrate

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial

R = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 1.2, 3.0])

# eq. (3.10a): exp(-(r/0.4)^2) for r <= 1
GAUSSIAN = [
    1.0,
    math.exp(-0.390625),  # (0.25/0.4)^2 = 0.390625
    math.exp(-1.5625),
    math.exp(-3.515625),
    math.exp(-6.25),  # the truncated Gaussian is discontinuous at r = 1
    0.0,
    0.0,
]
# eq. (3.10b): 2/3 - 4r^2 + 4r^3 (r <= 1/2); 4/3 - 4r + 4r^2 - 4/3 r^3 (1/2 < r <= 1)
CUBIC = [2.0 / 3.0, 23.0 / 48.0, 1.0 / 6.0, 1.0 / 48.0, 0.0, 0.0, 0.0]
# eq. (3.10c): 1 - 6r^2 + 8r^3 - 3r^4
QUARTIC = [1.0, 189.0 / 256.0, 5.0 / 16.0, 13.0 / 256.0, 0.0, 0.0, 0.0]

CASES = [(mf.gaussian, GAUSSIAN), (mf.cubic_spline, CUBIC), (mf.quartic, QUARTIC)]


@pytest.mark.parametrize("weight, expected", CASES, ids=["gaussian", "cubic", "quartic"])
def test_weights_equal_eq_3_10(weight, expected):
    w, dw = weight(R)
    assert w.shape == R.shape and dw.shape == R.shape
    np.testing.assert_allclose(w, expected, rtol=4 * EPS, atol=4 * EPS)
    # zero outside the support r > 1, value and derivative
    outside = np.array([1.0 + 1e-12, 1.5, 2.0, 10.0])
    w_out, dw_out = weight(outside)
    assert np.all(w_out == 0.0) and np.all(dw_out == 0.0)


@pytest.mark.parametrize("weight", [mf.gaussian, mf.cubic_spline, mf.quartic])
def test_weight_derivative_matches_central_differences(weight):
    # away from the points where the piecewise definitions switch (1/2 for the cubic spline,
    # 1 for all) so that the difference quotient sees one smooth piece
    r = np.concatenate([np.linspace(0.01, 0.49, 25), np.linspace(0.51, 0.99, 25)])
    delta = EPS ** (1 / 3)  # the optimal step of central differences
    fd = (weight(r + delta)[0] - weight(r - delta)[0]) / (2 * delta)
    # truncation delta^2 |w'''| / 6 plus round-off eps / delta: O(eps^(2/3)) |w'''| ~ 1e-9
    np.testing.assert_allclose(weight(r)[1], fd, rtol=0, atol=SQRT_EPS)


def test_cubic_and_quartic_are_c1_at_the_support_edge_and_cubic_at_one_half():
    # values and slopes of the two cubic-spline pieces agree at r = 1/2 and vanish at r = 1;
    # this and the table above pin down which branch is used where
    for weight in (mf.cubic_spline, mf.quartic):
        w, dw = weight(np.array([1.0 - 1e-9]))
        assert abs(w[0]) < 1e-12 and abs(dw[0]) < 1e-7
    left = mf.cubic_spline(np.array([0.5 - 1e-12]))
    right = mf.cubic_spline(np.array([0.5 + 1e-12]))
    assert abs(left[0][0] - right[0][0]) < 1e-10
    assert abs(left[1][0] - right[1][0]) < 1e-10
    assert abs(mf.cubic_spline(np.array([0.5]))[1][0] - (-1.0)) < 4 * EPS  # -8r + 12r^2 at 1/2


def test_weight_registry_names():
    assert WEIGHTS["gaussian"] is mf.gaussian
    assert WEIGHTS["cubic"] is mf.cubic_spline
    assert WEIGHTS["quartic"] is mf.quartic
    with pytest.raises(ValueError, match=r"weight='spline'.*cubic.*gaussian.*quartic"):
        get_weight("spline")


# --- SPH kernel (Rabczuk et al. 2006, eq. 10, with Monaghan's cubic spline) -------------------

SIGMA = {1: 2.0 / 3.0, 2: 10.0 / (7.0 * math.pi), 3: 1.0 / math.pi}


def monaghan(q, h, dim):
    """Monaghan's normalised cubic spline, written out independently of the library."""
    q = np.asarray(q, dtype=float)
    c = SIGMA[dim] / h**dim
    w = np.where(q < 1.0, 1.0 - 1.5 * q**2 + 0.75 * q**3, 0.0)
    w = np.where((q >= 1.0) & (q < 2.0), 0.25 * (2.0 - q) ** 3, w)
    return c * w


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("h", [0.37, 1.0, 2.5])
def test_sph_kernel_is_monaghan_and_rescaled_cubic_spline(dim, h):
    q = np.linspace(0.0, 2.5, 101)
    W, dW = mf.sph_cubic_spline(q, h, dim)
    np.testing.assert_allclose(W, monaghan(q, h, dim), rtol=1e-14, atol=1e-14 / h**dim)
    c = SIGMA[dim] / h**dim
    dW_exact = c * np.where(q < 1, -3 * q + 2.25 * q**2, np.where(q < 2, -0.75 * (2 - q) ** 2, 0))
    np.testing.assert_allclose(dW, dW_exact, rtol=1e-14, atol=1e-14 * c)
    # W = 3/2 sigma_d / h^d w(q/2) with w the EFG cubic spline (3.10b)
    np.testing.assert_allclose(
        W, 1.5 * SIGMA[dim] / h**dim * mf.cubic_spline(q / 2)[0], rtol=1e-14, atol=1e-14
    )
    assert np.all(W[q > 2.0] == 0.0)
    # at q = 2 the polynomial 4/3 - 4r + 4r^2 - 4/3 r^3 of (3.10b) vanishes up to round-off
    assert np.all(np.abs(W[q == 2.0]) <= 4 * EPS / h**dim)
    # dW/dq against central differences of the independent formula (away from q = 1, 2)
    qs = q[(np.abs(q - 1.0) > 0.05) & (q < 1.95) & (q > 0.0)]
    delta = 1e-6
    fd = (monaghan(qs + delta, h, dim) - monaghan(qs - delta, h, dim)) / (2 * delta)
    dWs = mf.sph_cubic_spline(qs, h, dim)[1]
    np.testing.assert_allclose(dWs, fd, rtol=0, atol=1e-8 * SIGMA[dim] / h**dim)


def test_sph_kernel_integrates_to_one_over_the_plane():
    h = 0.7
    # radial quadrature: int_0^{2h} W(r/h) 2 pi r dr, split at the kink r = h
    radial, _ = integrate.quad(
        lambda r: mf.sph_cubic_spline(r / h, h, 2)[0] * 2 * math.pi * r,
        0.0,
        2 * h,
        points=[h],
        epsabs=1e-14,
        epsrel=1e-13,
    )
    assert abs(radial - 1.0) < 1e-12
    # an independent Cartesian rule: tensor Gauss-Legendre on a 40 x 40 grid of sub-squares of
    # [-2h, 2h]^2; the kernel is C^2 with kinks on two circles, so the rule converges
    # algebraically, to ~1e-6 here
    s, ws = np.polynomial.legendre.leggauss(4)
    edges = np.linspace(-2 * h, 2 * h, 41)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
    x1 = (mid[:, None] + half[:, None] * s[None, :]).ravel()
    w1 = (half[:, None] * ws[None, :]).ravel()
    X, Y = np.meshgrid(x1, x1, indexing="ij")
    W = mf.sph_cubic_spline(np.hypot(X, Y) / h, h, 2)[0]
    cartesian = float(np.einsum("i,j,ij->", w1, w1, W))
    assert abs(cartesian - 1.0) < 1e-5


@pytest.mark.parametrize("dim, measure", [(1, lambda r: 2.0), (3, lambda r: 4 * math.pi * r**2)])
def test_sph_kernel_integrates_to_one_in_1d_and_3d(dim, measure):
    h = 1.3
    total, _ = integrate.quad(
        lambda r: mf.sph_cubic_spline(r / h, h, dim)[0] * measure(r),
        0.0,
        2 * h,
        points=[h],
        epsabs=1e-14,
        epsrel=1e-13,
    )
    assert abs(total - 1.0) < 1e-12


def test_sph_kernel_rejects_bad_arguments():
    with pytest.raises(ValueError, match="dim=4"):
        mf.sph_cubic_spline(np.array([0.5]), 1.0, 4)
    with pytest.raises(ValueError, match="smoothing length h=0"):
        mf.sph_cubic_spline(np.array([0.5]), 0.0, 2)
