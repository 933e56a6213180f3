"""MLS / EFG shape functions (Belytschko et al. 1995, eq. 3.4–3.9).

Exact properties (partition of unity, linear and quadratic reproduction of values and gradients)
are checked on irregular particle sets for the three weights of eq. (3.10); the shape functions
themselves against an independent, point-by-point implementation of eq. (3.7)–(3.9) in the
unshifted, unscaled monomial basis; derivatives against central differences.

Tolerances. The reproduction properties hold exactly in exact arithmetic, so the discrepancy is
round-off: about eps times the condition number of the (shifted, scaled) moment matrix (1e1–1e3
for these particle sets) times the size of the terms that cancel (``sum_I |phi_I| |f(x_I)|``,
a few times the field's magnitude, 1/h times that for gradients). ``TOL = 1e6 eps`` (2.2e-10)
relative to the field's magnitude (over the particle spacing for gradients) is that bound with a
margin of ~100; observed: 1e-15–1e-12. An error in the formulas shows up at 1e-3 or more.
Central differences use the optimal step ``eps^(1/3) h``: their error is ``O(eps^(2/3))`` times
ratios of derivatives, bounded here by ``10 sqrt(eps)`` relative (observed <= 3e-9).
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx.kernels import WEIGHTS

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import EPS, SQRT_EPS

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = pytest.mark.serial

TOL = 1e6 * EPS
WEIGHT_NAMES = ["gaussian", "cubic", "quartic"]
ORIGIN = np.array([3.0, -1.0])  # away from 0 so that the basis shift matters
SIZE = np.array([2.0, 1.0])


def jittered_grid(n, jitter, seed):
    """(n[0]+1) x (n[1]+1) grid on ORIGIN + [0,2]x[0,1], interior points moved at random."""
    rng = np.random.default_rng(seed)
    xs, ys = (np.linspace(0.0, SIZE[k], n[k] + 1) for k in range(2))
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    P = np.stack([X.ravel(), Y.ravel()], axis=1)
    h = SIZE / np.asarray(n)
    inner = np.all((P > 0) & (P < SIZE), axis=1)
    P[inner] += rng.uniform(-jitter, jitter, (inner.sum(), 2)) * h
    return P + ORIGIN, float(h.min())


def random_cloud(n, seed):
    """Uniformly random particles in the box plus its 4 corners (a very irregular set)."""
    rng = np.random.default_rng(seed)
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=float) * SIZE
    P = np.vstack([corners, rng.uniform(0, 1, (n, 2)) * SIZE])
    return P + ORIGIN, float(np.sqrt(SIZE.prod() / n))


def eval_points(m, seed, margin=0.0):
    rng = np.random.default_rng(seed)
    return ORIGIN + margin * SIZE + rng.uniform(0, 1, (m, 2)) * SIZE * (1 - 2 * margin)


PARTICLE_SETS = {
    "jittered": lambda: jittered_grid((16, 8), 0.4, seed=3),
    "random": lambda: random_cloud(150, seed=5),
}


def monomials(x, order):
    """Monomials of total degree <= order at points (m, 2), and their gradients (m, k, 2)."""
    X, Y = x[:, 0], x[:, 1]
    one, zero = np.ones_like(X), np.zeros_like(X)
    if order == 1:
        f = [one, X, Y]
        g = [[zero, zero], [one, zero], [zero, one]]
    else:
        f = [one, X, Y, X * X, X * Y, Y * Y]
        g = [
            [zero, zero],
            [one, zero],
            [zero, one],
            [2 * X, zero],
            [Y, X],
            [zero, 2 * Y],
        ]
    return np.stack(f, axis=1), np.stack([np.stack(gi, axis=1) for gi in g], axis=1)


@pytest.mark.parametrize("basis, order", [("linear", 1), ("quadratic", 2)])
@pytest.mark.parametrize("weight", WEIGHT_NAMES)
@pytest.mark.parametrize("particles", sorted(PARTICLE_SETS))
def test_reproduction_of_polynomials_and_their_gradients(particles, weight, basis, order):
    P, h = PARTICLE_SETS[particles]()
    mls = mf.MLS(P, weight=weight, dilation=2.5 if order == 1 else 3.0, basis=basis)
    x = eval_points(400, seed=11)
    table = mls.tabulate(x)
    f_nodes, _ = monomials(P, order)  # (n, k): includes the constant (partition of unity)
    f_exact, g_exact = monomials(x, order)
    scale = np.abs(f_nodes).max()
    values = table.values @ f_nodes
    assert np.abs(values - f_exact).max() <= TOL * scale
    grads = table.gradient(f_nodes)  # (m, k, 2)
    assert grads.shape == g_exact.shape
    assert np.abs(grads - g_exact).max() <= TOL * scale / h
    # a quadratic field is *not* reproduced by a linear basis: the check above can fail
    if order == 1:
        q_nodes, _ = monomials(P, 2)
        q_exact, _ = monomials(x, 2)
        assert np.abs(table.values @ q_nodes[:, 3] - q_exact[:, 3]).max() > 1e-4


@pytest.mark.parametrize("dim", [1, 3])
def test_linear_reproduction_in_1d_and_3d(dim):
    rng = np.random.default_rng(dim)
    n_side = 40 if dim == 1 else 5
    axes = [np.linspace(0.0, 1.0, n_side + 1)] * dim
    P = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    inner = np.all((P > 0) & (P < 1), axis=1)
    P[inner] += rng.uniform(-0.3, 0.3, (inner.sum(), dim)) / n_side
    P += 2.0
    x = 2.0 + rng.uniform(0, 1, (100, dim))
    table = mf.MLS(P, weight="cubic", dilation=2.5).tabulate(x)
    f = np.hstack([np.ones((P.shape[0], 1)), P])
    scale = np.abs(f).max()
    assert np.abs(table.values @ f - np.hstack([np.ones((100, 1)), x])).max() <= TOL * scale
    for k in range(dim):
        expected = np.zeros(dim + 1)
        expected[k + 1] = 1.0
        assert np.abs(table.gradients[k] @ f - expected).max() <= TOL * scale * n_side


def reference_mls(P, x, radii, weight, order):
    """Eq. (3.7)–(3.9) of Belytschko et al. 1995 point by point in the raw monomial basis.

    Returns phi (m, n) and its gradient (2, m, n) by the product rule on
    ``phi_I = p(x)^T A(x)^-1 w_I(x) p(x_I)`` with ``(A^-1)_,k = -A^-1 A_,k A^-1``.
    """
    wfun = WEIGHTS[weight]
    m, n = x.shape[0], P.shape[0]
    pI, _ = monomials(P, order)  # (n, k)
    phi = np.zeros((m, n))
    dphi = np.zeros((2, m, n))
    for q in range(m):
        d = x[q] - P
        dist = np.sqrt(np.sum(d * d, axis=1))
        w, dwdr = wfun(dist / radii)
        w = np.where(dist < radii, w, 0.0)
        dwdr = np.where(dist < radii, dwdr, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            dw = np.where(dist[:, None] > 0, dwdr[:, None] * d / (dist * radii)[:, None], 0.0)
        A = (pI * w[:, None]).T @ pI
        Ainv = np.linalg.inv(A)
        px, gpx = monomials(x[q : q + 1], order)
        B = pI.T * w  # C(x) of eq. (3.7b): columns w_I p(x_I)
        phi[q] = px[0] @ Ainv @ B
        for k in range(2):
            dA = (pI * dw[:, k : k + 1]).T @ pI
            dphi[k, q] = (
                gpx[0, :, k] @ Ainv @ B
                - px[0] @ Ainv @ dA @ Ainv @ B
                + px[0] @ Ainv @ (pI.T * dw[:, k])
            )
    return phi, dphi


@pytest.mark.parametrize("basis, order", [("linear", 1), ("quadratic", 2)])
@pytest.mark.parametrize("weight", WEIGHT_NAMES)
def test_shape_functions_equal_independent_eq_3_9(weight, basis, order):
    P, _ = jittered_grid((10, 5), 0.3, seed=7)
    dilation = 2.0 if order == 1 else 2.8
    mls = mf.MLS(P, weight=weight, dilation=dilation, basis=basis)
    # support radii d_mI = d_max c_I, eq. (3.11): c_I the distance to the k-th nearest other
    # particle, k = number of basis functions ("enough adjacent nodes to satisfy the basis")
    k = 3 if order == 1 else 6
    all_d = np.sort(np.linalg.norm(P[:, None, :] - P[None, :, :], axis=2), axis=1)
    radii = dilation * all_d[:, k]
    np.testing.assert_allclose(mls.radii, radii, rtol=1e-14)
    x = np.vstack([eval_points(40, seed=13), P[::7]])  # includes points at particles
    table = mls.tabulate(x)
    # the monomials are taken about the box's centre, a fixed translation of the global basis
    # (MLS is invariant under it) that keeps the raw quadratic moment matrix well conditioned
    centre = ORIGIN + SIZE / 2
    phi, dphi = reference_mls(P - centre, x - centre, radii, weight, order)
    np.testing.assert_allclose(table.values.toarray(), phi, rtol=0, atol=1e-10 * np.abs(phi).max())
    for kk in range(2):
        g = table.gradients[kk].toarray()
        np.testing.assert_allclose(g, dphi[kk], rtol=0, atol=1e-9 * np.abs(dphi[kk]).max())


@pytest.mark.parametrize("basis", ["linear", "quadratic"])
@pytest.mark.parametrize("weight", WEIGHT_NAMES)
def test_derivatives_match_central_differences(weight, basis):
    P, h = jittered_grid((12, 6), 0.35, seed=17)
    mls = mf.MLS(P, weight=weight, dilation=2.5 if basis == "linear" else 3.0, basis=basis)
    x = eval_points(60, seed=19, margin=0.01)
    grads = mls.tabulate(x).gradients
    delta = EPS ** (1 / 3) * h
    for k in range(2):
        e = np.zeros(2)
        e[k] = delta
        fd = (
            mls.tabulate(x + e, derivatives=0).values - mls.tabulate(x - e, derivatives=0).values
        ) / (2 * delta)
        err = np.abs((grads[k] - fd).toarray()).max()
        assert err <= 10 * SQRT_EPS * np.abs(grads[k].toarray()).max()


def test_tabulate_returns_csr_tables_of_the_right_shape():
    P, _ = random_cloud(60, seed=23)
    x = eval_points(17, seed=29)
    mls = mf.MLS(P, weight="quartic", dilation=2.0, basis="linear")
    table = mls.tabulate(x)
    m, n = x.shape[0], P.shape[0]
    assert sp.issparse(table.values) and table.values.format == "csr"
    assert table.values.shape == (m, n) and table.shape == (m, n)
    assert isinstance(table.gradients, list) and len(table.gradients) == 2
    for g in table.gradients:
        assert sp.issparse(g) and g.format == "csr" and g.shape == (m, n)
    # the stored pattern is exactly the pairs with |x - x_I| < d_I (compact support, eq. 3.10)
    dist = np.linalg.norm(x[:, None, :] - P[None, :, :], axis=2)
    inside = dist < mls.radii[None, :]
    pattern = np.zeros((m, n), dtype=bool)
    coo = table.values.tocoo()
    pattern[coo.row, coo.col] = True
    np.testing.assert_array_equal(pattern, inside)
    np.testing.assert_array_equal(table.points, x)
    assert mf.MLS(P).tabulate(x, derivatives=0).gradients == []


def test_particle_set_input_and_shifted_origin_give_the_same_shape_functions():
    # MLS is invariant under translation of particles and points together
    P, _ = jittered_grid((8, 4), 0.3, seed=31)
    x = eval_points(30, seed=37)
    shift = np.array([-1234.5, 678.25])
    a = mf.MLS(P, weight="cubic", dilation=2.2).tabulate(x)
    b = mf.MLS(P + shift, weight="cubic", dilation=2.2).tabulate(x + shift)
    np.testing.assert_allclose(a.values.toarray(), b.values.toarray(), rtol=0, atol=1e-9)
    for ga, gb in zip(a.gradients, b.gradients, strict=True):
        np.testing.assert_allclose(ga.toarray(), gb.toarray(), rtol=0, atol=1e-8)
