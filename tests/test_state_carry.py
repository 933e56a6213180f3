"""A law's state carried to a changed quadrature (dolfinx_meshfree.statics.state_carry).

Oracles: the side of the crack of every point, from its coordinates (a state that is +1 on one
side of a crack and -1 on the other must arrive on the side it was on); positions that did not
change keep their state bit for bit; a sliver with no old point on its side is counted, never
silent; bad input.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree.physics.state import PointState
from dolfinx_meshfree.statics.state_carry import carry_states

import numpy as np
import pytest

LAW = mf.J2Plasticity(E=200e3, nu=0.3, sigma_y=250.0, H=1000.0, plane="strain")


def _gauss(x0: float, cell: int, n: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """The n x n Gauss points of the unit square [x0, x0 + 1] x [0, 1], and their cell."""
    g, _ = np.polynomial.legendre.leggauss(n)
    g = 0.5 * (g + 1.0)
    X, Y = np.meshgrid(x0 + g, g, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel()])
    return pts, np.full(len(pts), cell)


def _state(points: np.ndarray, cells: np.ndarray, alpha: np.ndarray | None = None) -> PointState:
    st = PointState(LAW, points, cells=cells)
    if alpha is not None:
        st.committed["alpha"][:, 0] = alpha
        st.committed["plastic_strain"][:] = alpha[:, None]
        st.restore()
    return st


def _old(alpha_of):
    p0, c0 = _gauss(0.0, 0)
    p1, c1 = _gauss(1.0, 1)
    pts, cells = np.concatenate([p0, p1]), np.concatenate([c0, c1])
    return _state(pts, cells, alpha_of(pts)), pts, cells


def test_a_state_stays_on_its_side_of_the_crack():
    """Cell 0 newly cut by a vertical crack at x = 0.45 (its rule replaced by 200 random
    points), cell 1 unchanged: every new point of cell 0 takes a state from its own side (+1
    left, -1 right), and cell 1's points keep theirs exactly, trial state included."""
    crack = mf.Crack([[0.45, -1.0], [0.45, 2.0]])
    old, pts, cells = _old(lambda p: np.where(p[:, 0] < 0.45, 1.0, -1.0) * (1.0 + p[:, 1]))
    rng = np.random.default_rng(3)
    cut = rng.uniform(0.0, 1.0, (200, 2))
    new_pts = np.concatenate([cut, pts[cells == 1]])
    new = _state(new_pts, np.concatenate([np.zeros(200, int), np.ones(9, int)]))
    new.trial["alpha"][:] = 7.0  # dropped: the trial state becomes the carried one
    counts = carry_states([old], [new], [crack], h=1.0)
    alpha = new.committed["alpha"][:, 0]
    left = cut[:, 0] < 0.45
    assert np.all(alpha[:200][left] > 0) and np.all(alpha[:200][~left] < 0)
    # each from the nearest old point of its side
    for i in (np.argmin(cut[:, 0]), np.argmax(cut[:, 0])):
        side = (pts[:, 0] < 0.45) == left[i]
        mine = np.flatnonzero(side & (cells == 0))
        j = mine[np.argmin(np.linalg.norm(pts[mine] - cut[i], axis=1))]
        assert alpha[i] == old.committed["alpha"][j, 0]
    assert np.array_equal(alpha[200:], old.committed["alpha"][cells == 1, 0])
    assert np.array_equal(new.trial["alpha"], new.committed["alpha"])
    assert np.array_equal(new.committed["plastic_strain"][:, 0], alpha)
    assert (counts.copied, counts.moved, counts.crossed) == (9, 200, 0)


def test_a_sliver_without_an_old_point_is_counted():
    """A crack at x = 0.95 leaves no old Gauss point (the last at 0.887) on its right in cell
    0: the new points there take the nearest across the crack, and are counted."""
    crack = mf.Crack([[0.95, -1.0], [0.95, 2.0]])
    old, pts, cells = _old(lambda p: p[:, 0])
    new_pts = np.array([[0.97, 0.5], [0.99, 0.1], [0.55, 0.45]])
    new = _state(new_pts, np.zeros(3, int))
    counts = carry_states([old], [new], [crack], h=1.0)
    assert counts.crossed == 2 and counts.moved == 3
    near = pts[cells == 0]
    for i in range(3):
        j = np.argmin(np.linalg.norm(near - new_pts[i], axis=1))
        assert new.committed["alpha"][i, 0] == near[j, 0]


def test_a_crack_tip_inside_the_cell_does_not_separate_what_lies_beyond_it():
    """A crack from the bottom ending at y = 0.3 in cell 0: a point above the tip, left of the
    crack's line, takes the nearest old point, which lies right of it."""
    crack = mf.Crack([[0.45, -1.0], [0.45, 0.3]])
    old, pts, cells = _old(lambda p: np.arange(len(p), dtype=float))
    new = _state(np.array([[0.44, 0.85]]), np.zeros(1, int))
    counts = carry_states([old], [new], [crack], h=1.0)
    near = np.flatnonzero(cells == 0)
    j = near[np.argmin(np.linalg.norm(pts[near] - [0.44, 0.85], axis=1))]
    assert pts[j, 0] > 0.45  # the nearest lies across the crack's line, beyond its tip
    assert new.committed["alpha"][0, 0] == j and counts.crossed == 0


def test_bad_input():
    old, pts, _ = _old(lambda p: p[:, 0])
    with pytest.raises(ValueError, match=r"cells should have shape \(18,\), got \(3,\)"):
        PointState(LAW, pts, cells=np.zeros(3, int))
    new = _state(np.array([[2.5, 0.5]]), np.array([2]))
    with pytest.raises(RuntimeError, match=r"point \(2\.5, 0\.5\): its cell had no points"):
        carry_states([old], [new], [], h=1.0)
    with pytest.raises(RuntimeError, match="the rebuilt model has 0 sets of points"):
        carry_states([old], [], [], h=1.0)
    with pytest.raises(RuntimeError, match="needs the points' cells"):
        carry_states([old], [PointState(LAW, pts)], [], h=1.0)
