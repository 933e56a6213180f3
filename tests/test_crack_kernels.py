"""The compiled crossing test of a crack (``geometry/crack_kernels.py``) against the numpy
reference (:meth:`Crack.crosses_reference`), pair by pair: random polylines and segments, on a
coarse grid too so that ends touch, pass through tips and joints and lie on the crack (with and
without a side), open and closed ends; and against hand-made answers. Local (no MPI)."""

from __future__ import annotations

from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.geometry import crack_kernels
from dolfinx_meshfree.geometry.crack import Crack

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason="the compiled kernel needs numba")


def _cases(seed: int, grid: bool):
    """A polyline, 600 segments ``p q`` (a quarter of them starting on the crack) and sides."""
    rng = np.random.default_rng(seed)
    while True:
        k = int(rng.integers(2, 7))
        pts = np.cumsum(rng.uniform(-1.0, 1.0, (k, 2)), axis=0)
        if grid:
            pts = np.round(4.0 * pts) / 4.0
        try:
            crack = Crack(pts)
            break
        except ValueError:  # a zero-length segment or a fold-back: draw again
            continue
    n = 600
    p, q = rng.uniform(-3.0, 3.0, (2, n, 2))
    e = rng.integers(0, k - 1, n // 4)
    w = rng.uniform(0.0, 1.0, n // 4)
    if grid:
        p, q, w = np.round(4.0 * p) / 4.0, np.round(4.0 * q) / 4.0, np.round(4.0 * w) / 4.0
    p[: n // 4] = pts[e] + w[:, None] * (pts[e + 1] - pts[e])  # on the crack, joints and tips
    q[n // 4 : n // 2] = pts[rng.integers(0, k, n // 4)]  # ending on a tip or a joint
    return crack, p, q, rng.integers(-1, 2, n)


@pytest.mark.parametrize("grid", [False, True])
@pytest.mark.parametrize("ends", [(True, True), (False, True), (True, False), (False, False)])
def test_compiled_crossing_equals_the_reference(grid, ends):
    """Every pair gives the reference's answer, with and without sides, over 40 polylines per
    case (the grid case has touching and collinear configurations); the reference's answers
    hold both values, so the comparison can fail."""
    hits = 0
    for seed in range(40):
        crack, p, q, sides = _cases(seed, grid)
        crack.is_tip = list(ends)
        for s in (None, sides):
            expected = crack.crosses_reference(p, q, s)
            assert np.array_equal(crack.crosses(p, q, s), expected)
            i = np.arange(p.shape[0])[::-1]  # the indexed form, pairs in another order
            got = crack.crosses_pairs(p, i, q, i, None if s is None else s[i])
            assert np.array_equal(got, expected[i])
            hits += int(expected.sum())
    assert 0 < hits < 40 * 2 * 600


def test_crossing_by_hand():
    """A straight crack from (0, 0) to (2, 0), a tip at (2, 0): a segment across it crosses,
    one that passes beyond the tip or ends on the tip does not, one from a point on the crack
    crosses only when that point is given the other side."""
    crack = Crack(np.array([[0.0, 0.0], [2.0, 0.0]]))
    crack.is_tip = [False, True]  # a mouth at (0, 0), a tip at (2, 0)
    p = np.array([[1.0, 1.0], [3.0, 1.0], [2.0, 1.0], [0.0, 1.0], [1.0, 0.0], [1.0, 0.0]])
    q = np.array([[1.0, -1.0], [3.0, -1.0], [2.0, -1.0], [0.0, -1.0], [1.0, -1.0], [1.0, -1.0]])
    sides = np.array([0, 0, 0, 0, 1, -1])
    expected = [True, False, False, True, True, False]
    assert crack.crosses(p, q, sides).tolist() == expected
    assert crack.crosses_reference(p, q, sides).tolist() == expected


def test_bad_pairs_are_refused():
    """Index pairs beyond the points, unequal pair counts and a wrong number of sides."""
    a, b = np.array([[0.0, 0.0]]), np.array([[1.0, 0.0]])
    x = np.zeros((3, 2))
    ends = (np.ones(1, bool), np.ones(1, bool))
    fix = r"i \(2 entries\) and j \(2\) should be as many indices into x \(3 points\)"
    with pytest.raises(ValueError, match=fix):
        crack_kernels.crosses(x, x, a, b, *ends, 1e-12, None, np.array([0, 3]), np.array([0, 1]))
    with pytest.raises(ValueError, match=r"i \(2 entries\) and j \(1\)"):
        crack_kernels.crosses(x, x, a, b, *ends, 1e-12, None, np.array([0, 1]), np.array([0]))
    with pytest.raises(ValueError, match="sides has 2 entries for 3 pairs"):
        crack_kernels.crosses(x, x, a, b, *ends, 1e-12, np.array([1, 1]))
    crack = Crack(np.array([[0.0, 0.0], [1.0, 0.0]]))
    with pytest.raises(ValueError, match="the same shape"):
        crack.crosses(np.zeros((3, 2)), np.zeros((2, 2)))
