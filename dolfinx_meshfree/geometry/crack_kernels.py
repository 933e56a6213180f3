"""The crossing test of a crack, compiled: which of ``n`` segments ``p q`` cross a polyline.

:meth:`~dolfinx_meshfree.geometry.crack.Crack.crosses` decides, for every pair of an evaluation
point ``p`` and a particle ``q`` in a crack's bounding box, whether the MLS weight between them is
cut (the visibility and diffraction criteria of Belytschko et al. 1995, sec. 3;
``approx/crack_cuts.py``). Its numpy form builds a dozen ``(pairs x segments)`` arrays per call
and took 9 % of an adaptive Kalthoff–Winkler run (0.44 s of 4.8 s; MLS tables at every
extension, conversion and SIF check). :func:`crosses` makes one pass over the pairs with the
same arithmetic (the signed areas in the same operand order, IEEE semantics, no fused
operations), so that it gives the numpy form's answer pair by pair
(``tests/test_crack_kernels.py``); the numpy form stays the reference and the fallback without
numba.
"""

from __future__ import annotations

import math

import numpy as np

from ..approx import jit

__all__ = ["crosses"]


@jit.jit
def _sign(x):  # pragma: no cover - compiled
    """``np.sign``: -1, 0, 1, and NaN for NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    if x == 0.0:
        return 0.0
    return math.nan


@jit.jit
def _crosses(x, i, y, j, a, b, open_a, open_b, len2, tol, lo, hi, sides, out):  # pragma: no cover
    """``out[m]``: whether ``x[i[m]] y[j[m]]`` crosses a segment ``a[e] b[e]`` properly (see
    :meth:`Crack.crosses`); ``sides`` empty, or a side per pair for points on the crack."""
    has_sides = sides.size > 0
    for m in range(i.shape[0]):
        p0, p1, q0, q1 = x[i[m], 0], x[i[m], 1], y[j[m], 0], y[j[m], 1]
        inside = (
            min(p0, q0) <= hi[0]
            and min(p1, q1) <= hi[1]
            and max(p0, q0) >= lo[0]
            and max(p1, q1) >= lo[1]
        )
        out[m] = False
        if not inside:
            continue
        s = sides[m] if has_sides else 0
        for e in range(a.shape[0]):
            a0, a1, b0, b1 = a[e, 0], a[e, 1], b[e, 0], b[e, 1]
            op = (b0 - a0) * (p1 - a1) - (b1 - a1) * (p0 - a0)
            if has_sides and s != 0:
                t0, t1 = b0 - a0, b1 - a1
                xi = ((p0 - a0) * t0 + (p1 - a1) * t1) / len2[e]
                if abs(op) <= tol * math.sqrt(len2[e]) and xi >= 0.0 and xi <= 1.0:
                    op = float(s)
            oq = (b0 - a0) * (q1 - a1) - (b1 - a1) * (q0 - a0)
            oa = _sign((q0 - p0) * (a1 - p1) - (q1 - p1) * (a0 - p0))
            ob = _sign((q0 - p0) * (b1 - p1) - (q1 - p1) * (b0 - p0))
            apart = oa * ob < 0.0 or (oa == 0.0 and not open_a[e]) or (ob == 0.0 and not open_b[e])
            if op * oq < 0.0 and apart:
                out[m] = True
                break


def crosses(
    x: np.ndarray,
    y: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    open_a: np.ndarray,
    open_b: np.ndarray,
    tol: float,
    sides: np.ndarray | None,
    i: np.ndarray | None = None,
    j: np.ndarray | None = None,
) -> np.ndarray:
    """Whether each segment ``p q`` crosses the polyline of segments ``a[e] b[e]`` (k, 2), whose
    ends ``open_a``/``open_b`` (k,) are crack tips: (n,) bool, as
    :meth:`~dolfinx_meshfree.geometry.crack.Crack.crosses` defines it (``tol``: the distance
    within which a point with a ``sides`` entry counts as on a segment, per unit length).

    The pairs are ``p = x[i[m]]``, ``q = y[j[m]]`` (``i``, ``j`` default to ``0..n-1``: then
    ``x`` and ``y`` are the ``n`` pairs' points), so that a caller with index pairs does not
    gather the points first."""
    x = np.ascontiguousarray(x, dtype=float).reshape(-1, 2)
    y = np.ascontiguousarray(y, dtype=float).reshape(-1, 2)
    i = np.arange(x.shape[0]) if i is None else np.asarray(i)
    j = np.arange(y.shape[0]) if j is None else np.asarray(j)
    if i.shape != j.shape or (i.size and (i.max() >= x.shape[0] or j.max() >= y.shape[0])):
        raise ValueError(
            f"i ({i.size} entries) and j ({j.size}) should be as many indices into x "
            f"({len(x)} points) and y ({len(y)})"
        )
    t = b - a
    len2 = t[:, 0] * t[:, 0] + t[:, 1] * t[:, 1]
    pts = np.concatenate([a, b[-1:]])
    out = np.empty(i.size, dtype=bool)
    s = np.zeros(0, np.int64) if sides is None else np.asarray(sides, np.int64).reshape(-1)
    if s.size not in (0, i.size):
        raise ValueError(f"sides has {s.size} entries for {i.size} pairs")
    _crosses(
        x, i, y, j,
        np.ascontiguousarray(a, dtype=float),
        np.ascontiguousarray(b, dtype=float),
        np.asarray(open_a, bool),
        np.asarray(open_b, bool),
        len2,
        float(tol),
        pts.min(axis=0),
        pts.max(axis=0),
        s,
        out,
    )  # fmt: skip
    return out
