"""The compiled MLS path (numba: cell lists + per-point kernel) against the numpy reference.

Both evaluate Belytschko et al. 1995, eq. (3.7)-(3.9) in the same shifted, scaled basis but with
different summation orders, inverses (Gauss-Jordan vs closed form / LU) and a different but
algebraically equal form of the moment derivatives (``D_k A`` instead of per-pair basis
derivatives), so they agree to round-off: about eps times the condition number of the scaled
moment matrix (1e1-1e3 here). ``TOL = 1e-12`` relative to the largest entry is that with a
margin of 10-100 (observed 1e-15-2e-14). The pair sets, their order and the CSR patterns are
equal exactly.
"""

import re

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.approx import mls as mls_module
from dolfinx_meshfree.approx.mls_kernel import derivative_matrices, monomial_exponents
from dolfinx_meshfree.approx.neighbours import pairs_within_support

import numpy as np
import pytest

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = [
    pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not installed"),
    pytest.mark.serial,
]

TOL = 1e-12
WEIGHTS = ["gaussian", "cubic", "quartic"]
CASES = [(1, "linear"), (2, "linear"), (2, "quadratic"), (3, "linear")]


def cloud(kind, gdim, n_side, seed):
    """Particles in [0, 1]^gdim shifted by 2: a jittered grid or a uniform random cloud (plus
    the corners of the box), and evaluation points inside."""
    rng = np.random.default_rng(seed)
    axes = [np.linspace(0.0, 1.0, n_side + 1)] * gdim
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, gdim)
    if kind == "grid":
        P = grid + rng.uniform(-0.3, 0.3, grid.shape) / n_side
    else:
        corners = grid[np.all((grid == 0) | (grid == 1), axis=1)]
        P = np.vstack([corners, rng.uniform(0, 1, (grid.shape[0], gdim))])
    x = np.vstack([rng.uniform(0, 1, (300, gdim)), P[::5]])  # includes points at particles
    return P + 2.0, x + 2.0


def both(P, cuts=(), **kw):
    a = mf.MLS(P, backend="numpy", **kw)
    b = mf.MLS(P, backend="numba", **kw)
    a.pair_cuts = list(cuts)
    b.pair_cuts = list(cuts)
    return a, b


def assert_tables_equal(ta, tb):
    va, vb = ta.values, tb.values
    assert vb.format == "csr" and vb.has_sorted_indices
    va.sort_indices()
    np.testing.assert_array_equal(va.indptr, vb.indptr)
    np.testing.assert_array_equal(va.indices, vb.indices)
    assert np.abs(va.data - vb.data).max() <= TOL * np.abs(va.data).max()
    assert len(ta.gradients) == len(tb.gradients)
    for ga, gb in zip(ta.gradients, tb.gradients, strict=True):
        ga.sort_indices()
        np.testing.assert_array_equal(ga.indices, gb.indices)
        assert np.abs(ga.data - gb.data).max() <= TOL * np.abs(ga.data).max()


@pytest.mark.parametrize("kind", ["grid", "random"])
@pytest.mark.parametrize("weight", WEIGHTS)
@pytest.mark.parametrize("gdim, basis", CASES)
def test_compiled_equals_numpy(gdim, basis, weight, kind):
    n_side = {1: 40, 2: 12, 3: 5}[gdim]
    P, x = cloud(kind, gdim, n_side, seed=gdim)
    dilation = {("grid", "linear"): 2.0, ("grid", "quadratic"): 2.8}.get((kind, basis), 3.5)
    a, b = both(P, weight=weight, dilation=dilation, basis=basis)
    assert_tables_equal(a.tabulate(x), b.tabulate(x))
    ta, tb = a.tabulate(x, derivatives=0), b.tabulate(x, derivatives=0)
    assert tb.gradients == []
    assert_tables_equal(ta, tb)


def crack_cut(x, i, j, dx, dist, ddist, sides=None):
    """Visibility across the segment y = 2.5, x < 2.5: drop the pairs whose line of sight
    crosses it (keeps the order of the others)."""
    xi, xj = x[i], x[i] - dx
    crosses = (xi[:, 1] - 2.5) * (xj[:, 1] - 2.5) < 0
    t = (2.5 - xi[:, 1]) / np.where(crosses, xj[:, 1] - xi[:, 1], 1.0)
    at = xi[:, 0] + t * (xj[:, 0] - xi[:, 0])
    keep = ~(crosses & (at < 2.5))
    return i[keep], j[keep], dx[keep], dist[keep], ddist[keep]


def stretch_cut(x, i, j, dx, dist, ddist, sides=None):
    """A distance changed by a term that depends on the particle only (its gradient is
    unchanged): ``dist + 0.05 |x_I - (2.5, 2.5)|``."""
    xj = x[i] - dx
    return i, j, dx, dist + 0.05 * np.linalg.norm(xj - 2.5, axis=1), ddist


def reversing_cut(x, i, j, dx, dist, ddist, sides=None):
    """Returns the pairs reversed: the compiled path must restore the CSR order."""
    return i[::-1], j[::-1], dx[::-1], dist[::-1], ddist[::-1]


@pytest.mark.parametrize("basis", ["linear", "quadratic"])
@pytest.mark.parametrize(
    "cuts", [[crack_cut], [stretch_cut], [crack_cut, stretch_cut], [reversing_cut]]
)
def test_compiled_equals_numpy_with_pair_cuts(cuts, basis):
    P, x = cloud("grid", 2, 16, seed=5)
    a, b = both(P, cuts, weight="quartic", dilation=3.0, basis=basis)
    ta, tb = a.tabulate(x), b.tabulate(x)
    assert_tables_equal(ta, tb)
    plain = mf.MLS(P, weight="quartic", dilation=3.0, basis=basis).tabulate(x)
    if crack_cut in cuts:  # the cut removed pairs
        assert tb.values.nnz < plain.values.nnz
    elif stretch_cut in cuts:  # the same pairs, other values
        assert tb.values.nnz == plain.values.nnz
        assert np.abs(tb.values - plain.values).max() > 1e-3
    else:  # the order of the pairs does not matter
        assert_tables_equal(plain, tb)


def identity_cut(x, i, j, dx, dist, ddist, sides=None):
    """Changes nothing (but the cut path runs: pairs to numpy and back)."""
    return i, j, dx, dist, ddist


def test_chunks_give_the_same_table(monkeypatch):
    """Points are tabulated chunk by chunk (bounded temporaries): any chunk size gives the same
    table to the last bit, with and without cuts."""
    P, x = cloud("grid", 2, 12, seed=9)
    whole = mf.MLS(P, backend="numba").tabulate(x)
    monkeypatch.setattr(mls_module, "CHUNK", 7)  # many chunks, the last one partial
    mls = mf.MLS(P, backend="numba")
    chunked = mls.tabulate(x)
    mls.pair_cuts = [identity_cut]
    cut = mls.tabulate(x)
    mats = zip(
        [whole.values, *whole.gradients, whole.values, *whole.gradients],
        [chunked.values, *chunked.gradients, cut.values, *cut.gradients],
        strict=True,
    )
    for a, b in mats:
        np.testing.assert_array_equal(a.indptr, b.indptr)
        np.testing.assert_array_equal(a.indices, b.indices)
        np.testing.assert_array_equal(a.data, b.data)


def test_cell_list_pairs_equal_tree_pairs():
    """The cell-list pairs are those of the kd-tree search, sorted by point then particle, with
    the distances of ``pair_distances`` to the last bit."""
    P, x = cloud("random", 2, 12, seed=3)
    mls = mf.MLS(P, dilation=3.0, backend="numba")
    mls.tabulate(x[:1])  # builds the cell list
    counts, j, dx, dist, ddist = mls._cells.pairs(x)
    i = np.repeat(np.arange(x.shape[0]), counts)
    assert np.all((np.diff(i) > 0) | ((np.diff(i) == 0) & (np.diff(j) > 0)))
    ti, tj, tdx = pairs_within_support(x, mls.points, mls.radii)
    o = np.lexsort((tj, ti))
    np.testing.assert_array_equal(i, ti[o])
    np.testing.assert_array_equal(j, tj[o])
    np.testing.assert_array_equal(dx, tdx[o])
    tdist, tddist = mf.approx.mls.pair_distances(tdx[o])
    np.testing.assert_array_equal(dist, tdist)
    np.testing.assert_array_equal(ddist, tddist)


def test_points_outside_the_particle_box_and_empty_input():
    P, _ = cloud("grid", 2, 8, seed=1)
    mls = mf.MLS(P, backend="numba")
    t = mls.tabulate(np.zeros((0, 2)))
    assert t.values.shape == (0, P.shape[0]) and len(t.gradients) == 2
    with pytest.raises(mf.MomentMatrixError, match="has 0 particle"):
        mls.tabulate(np.array([[2.5, 2.5], [-100.0, 1e6]]))


def masked(message):
    """The message without the eigenvalue ratio (round-off differs between the paths)."""
    return re.sub(r"ratio \S+", "ratio ?", message)


@pytest.mark.parametrize(
    "layout, expected",
    [("sparse", "has 2 particle"), ("collinear", "ill-conditioned")],
)
def test_errors_are_those_of_the_numpy_path(layout, expected):
    if layout == "sparse":  # one point sees only two particles
        P = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [5.0, 5.0], [5.5, 5.0], [9.0, 9.0]])
        x = np.array([[0.3, 0.3], [5.2, 5.0]])
        kw = {"radii": np.array([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])}
    else:  # a row of particles along y = 0 far from the others: A is singular on the row
        P = np.vstack([np.c_[np.arange(8.0), np.zeros(8)], [[0.0, 10.0], [7.0, 10.0]]])
        x = np.array([[3.2, 0.0], [3.7, 0.0]])
        kw = {"radii": np.full(10, 2.5)}
    msgs = []
    for backend in ("numpy", "numba"):
        with pytest.raises(mf.MomentMatrixError, match=expected) as err:
            mf.MLS(P, backend=backend, **kw).tabulate(x)
        msgs.append(masked(str(err.value)))
    assert msgs[0] == msgs[1]


@pytest.mark.parametrize("cuts", [[], [identity_cut]])
def test_points_near_rcond_are_checked_exactly(cuts):
    """With rcond just below the smallest eigenvalue ratio, the kernel's cheap bound
    ``1 / (tr A tr A^-1)`` (up to m^2 below the ratio) flags points that the exact check then
    accepts; the table is the numpy one. Slightly above it, both paths reject the same point."""
    P, x = cloud("random", 2, 10, seed=21)
    ref = mf.MLS(P, dilation=3.5, backend="numpy")
    A = ref._sum_outer(*_moment_inputs(ref, x))
    ratio = ref._eigenvalue_ratio(A)
    q = int(np.argmin(ratio))
    rcond = 0.99 * ratio[q]
    bound = 1.0 / (np.trace(A, axis1=1, axis2=2) * np.trace(np.linalg.inv(A), axis1=1, axis2=2))
    assert np.count_nonzero(bound < rcond) >= 1  # the exact check runs (measured: 2 points)
    a, b = both(P, cuts, dilation=3.5, rcond=rcond)
    assert_tables_equal(a.tabulate(x), b.tabulate(x))
    msgs = []
    for mls in both(P, cuts, dilation=3.5, rcond=1.01 * ratio[q]):
        with pytest.raises(mf.MomentMatrixError, match=f"first: point {q} ") as err:
            mls.tabulate(x)
        msgs.append(masked(str(err.value)))
    assert msgs[0] == msgs[1]


def _moment_inputs(mls, x):
    """``(i, w, p, p, m)`` of the numpy path's moment sum, eq. (3.7a)."""
    i, j, dx = pairs_within_support(x, mls.points, mls.radii)
    dist, _ = mf.approx.mls.pair_distances(dx)
    w, _ = mls._weight(dist / mls.radii[j])
    p, _ = mf.approx.mls.polynomial_basis(-dx / mls._scale, mls.order)
    return i, w, p, p, x.shape[0]


@pytest.mark.parametrize("gdim, basis", CASES)
def test_exponents_and_derivative_matrices_match_polynomial_basis(gdim, basis):
    order = 1 if basis == "linear" else 2
    xi = np.random.default_rng(0).uniform(-2, 2, (20, gdim))
    p, dp = mf.approx.mls.polynomial_basis(xi, order)
    E = monomial_exponents(gdim, order)
    # pow() of an integer exponent may round differently from x * x: equal to 2 ulp
    np.testing.assert_allclose(np.prod(xi[:, None, :] ** E[None], axis=2), p, rtol=5e-16, atol=0)
    D = derivative_matrices(E)
    for k in range(gdim):
        np.testing.assert_array_equal(p @ D[k].T, dp[k])


def test_backend_argument_is_checked(monkeypatch):
    P, _ = cloud("grid", 2, 4, seed=0)
    with pytest.raises(ValueError, match="backend='fortran'"):
        mf.MLS(P, backend="fortran")
    monkeypatch.setattr(jit, "AVAILABLE", False)
    with pytest.raises(ValueError, match="needs numba"):
        mf.MLS(P, backend="numba")
