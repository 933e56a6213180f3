"""The compiled SPH path (numba: grouped cell lists + per-point kernel) against the numpy
reference, for every correction, with and without gradients, in 1D-3D.

Both evaluate the same sums (Rabczuk et al. 2006, eq. 10 and the corrections of
``approx/sph.py``) in different orders, so they agree to round-off: the values to a few eps,
the corrected gradients to eps times the condition number of the correction matrix ``M``
(1e1-1e2 here). ``TOL = 1e-12`` relative to the largest entry is that with a margin of 100 or
more (observed below 1e-14). The pair sets, their order and the CSR patterns are equal exactly.
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx import jit

import numpy as np
import pytest

# serial: no parallel code path here (tests/conftest.py, the tiers)
pytestmark = [
    pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not installed"),
    pytest.mark.serial,
]

TOL = 1e-12


def cloud(gdim, n_side, seed):
    """A jittered grid in [0, 1]^gdim shifted by 1, volumes of its cells, and evaluation points
    inside (some on particles, some on the boundary)."""
    rng = np.random.default_rng(seed)
    ax = np.linspace(0.0, 1.0, n_side + 1)
    P = np.stack(np.meshgrid(*[ax] * gdim, indexing="ij"), axis=-1).reshape(-1, gdim)
    inner = np.all((P > 0) & (P < 1), axis=1)
    P[inner] += rng.uniform(-0.3, 0.3, (inner.sum(), gdim)) / n_side
    x = np.vstack([rng.uniform(0, 1, (200, gdim)), P[::7], np.zeros((1, gdim))])
    return P + 1.0, np.full(P.shape[0], n_side**-gdim), x + 1.0


def assert_equal_tables(ta, tb):
    assert len(ta.gradients) == len(tb.gradients)
    for a, b in zip([ta.values, *ta.gradients], [tb.values, *tb.gradients], strict=True):
        assert b.has_sorted_indices
        a.sort_indices()
        np.testing.assert_array_equal(a.indptr, b.indptr)
        np.testing.assert_array_equal(a.indices, b.indices)
        assert np.abs(a.data - b.data).max() <= TOL * np.abs(a.data).max()


@pytest.mark.parametrize("correction", [None, "gradient", "shepard"])
@pytest.mark.parametrize("gdim, n_side", [(1, 40), (2, 12), (3, 5)])
def test_compiled_equals_numpy(gdim, n_side, correction):
    P, vol, x = cloud(gdim, n_side, seed=gdim)
    a = mf.SPH(P, vol, correction=correction, backend="numpy")
    b = mf.SPH(P, vol, correction=correction, backend="numba")
    assert a.h == b.h
    for derivatives in (1, 0):
        ta, tb = a.tabulate(x, derivatives), b.tabulate(x, derivatives)
        assert_equal_tables(ta, tb)


def test_compiled_refuses_what_numpy_refuses():
    P, vol, _ = cloud(2, 8, seed=0)
    for backend in ("numpy", "numba"):
        sph = mf.SPH(P, vol, backend=backend)
        with pytest.raises(ValueError, match=r"no particle within 2h=.*first: point 1 at"):
            sph.tabulate(np.array([[1.5, 1.5], [9.0, 9.0]]))
        # one particle in reach only: the correction matrix is singular
        lone = mf.SPH(P, vol, smoothing_length=0.3 * sph.h, backend=backend)
        with pytest.raises(ValueError, match="gradient correction is singular"):
            lone.tabulate(P[:3] + 1e-3)


def test_unknown_backend_is_refused():
    P, vol, _ = cloud(2, 4, seed=0)
    with pytest.raises(ValueError, match=r"backend='fortran' \(argument or DOLFINX_MESHFREE_SPH"):
        mf.SPH(P, vol, backend="fortran")
