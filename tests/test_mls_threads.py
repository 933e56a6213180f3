"""The fused compiled MLS path (search and kernel in one pass, straight into the table's
buffers) in its three regimes: one thread with buffers sized right, one thread with buffers
grown mid-chunk, and several threads (a counting pass, then exactly sized buffers filled chunk
by chunk in parallel). They compute every point by the same code, so the tables are equal to
the last bit; against the numpy reference they agree to round-off (``TOL`` as in
``test_mls_compiled.py``: eps times the moment matrices' condition number, with a margin)."""

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.approx import mls as mls_module

import numpy as np
import pytest

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = [
    pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not installed"),
    pytest.mark.serial,
]

TOL = 1e-12


def cloud(gdim, n_side, seed):
    """A jittered grid with a few particles of large support (the coarse grid of the cell
    list is not empty), and evaluation points inside."""
    rng = np.random.default_rng(seed)
    ax = np.linspace(0.0, 1.0, n_side + 1)
    P = np.stack(np.meshgrid(*[ax] * gdim, indexing="ij"), axis=-1).reshape(-1, gdim)
    P = P + rng.uniform(-0.3, 0.3, P.shape) / n_side
    x = rng.uniform(0.0, 1.0, (500, gdim))
    return P, x


def tables(mls, x):
    t = mls.tabulate(x)
    return [t.values, *t.gradients]


@pytest.mark.parametrize(
    "gdim, basis, n_side", [(2, "linear", 14), (2, "quadratic", 10), (3, "linear", 5)]
)
def test_threads_and_growth_give_the_same_table(monkeypatch, gdim, basis, n_side):
    P, x = cloud(gdim, n_side, seed=gdim)
    dilation = 2.8 if basis == "quadratic" else 2.2
    radii = mf.MLS(P, dilation=dilation, basis=basis).radii.copy()
    radii[::17] *= 1.6  # a few large supports
    ref = tables(mf.MLS(P, radii=radii, basis=basis, backend="numpy"), x)
    monkeypatch.setattr(mls_module, "CHUNK", 64)  # several chunks, the last one partial
    mls = mf.MLS(P, radii=radii, basis=basis, backend="numba")
    one = tables(mls, x)
    assert mls._cells.grid[-1][1] < mls._cells.grid[-1][2]  # both grids hold particles
    assert mls._cells.grid[3][mls._cells.grid[-1][1]] < P.shape[0]
    mls._cells.pairs_per_point = 0.5  # the first guess far too small: the buffers grow
    grown = tables(mls, x)
    monkeypatch.setattr(jit, "num_threads", lambda: 2)
    threaded = tables(mls, x)
    for a, b, c, r in zip(one, grown, threaded, ref, strict=True):
        for other in (b, c):
            np.testing.assert_array_equal(a.indptr, other.indptr)
            np.testing.assert_array_equal(a.indices, other.indices)
            np.testing.assert_array_equal(a.data, other.data)
        r.sort_indices()
        np.testing.assert_array_equal(a.indices, r.indices)
        assert np.abs(a.data - r.data).max() <= TOL * np.abs(r.data).max()


def test_threads_check_conditioning_as_the_numpy_path(monkeypatch):
    """With several chunks in parallel the points flagged by the cheap bound are gathered in
    order: the first rejected point and the message are those of the numpy path."""
    rng = np.random.default_rng(4)
    P = rng.uniform(0, 1, (300, 2))
    x = rng.uniform(0, 1, (400, 2))
    ref = mf.MLS(P, dilation=3.5, backend="numpy")
    t = ref.tabulate(x)  # accepted at the default rcond
    assert t.values.shape == (400, 300)
    i, j, dx = mf.approx.neighbours.pairs_within_support(x, ref.points, ref.radii)
    dist, _ = mf.approx.mls.pair_distances(dx)
    w, _ = ref._weight(dist / ref.radii[j])
    p, _ = mf.approx.mls.polynomial_basis(-dx / ref._scale, ref.order)
    ratio = ref._eigenvalue_ratio(ref._sum_outer(i, w, p, p, x.shape[0]))
    rcond = float(np.sort(ratio)[3]) * 1.001  # four points below: in several chunks
    monkeypatch.setattr(mls_module, "CHUNK", 50)
    monkeypatch.setattr(jit, "num_threads", lambda: 2)
    msgs = []
    for backend in ("numpy", "numba"):
        with pytest.raises(mf.MomentMatrixError, match="at 4 point") as err:
            mf.MLS(P, dilation=3.5, rcond=rcond, backend=backend).tabulate(x)
        msgs.append(err.value.args[0].split("ratio ")[0] + err.value.args[0].split(")")[1])
    assert msgs[0] == msgs[1]


def test_thread_count_is_checked(monkeypatch):
    monkeypatch.setenv("DOLFINX_MESHFREE_THREADS", "two")
    with pytest.raises(ValueError, match="DOLFINX_MESHFREE_THREADS='two'"):
        jit.num_threads()
    monkeypatch.setenv("DOLFINX_MESHFREE_THREADS", "2")
    assert jit.num_threads() == 2
    monkeypatch.delenv("DOLFINX_MESHFREE_THREADS")
    assert jit.num_threads() == 1
