"""Compiled SPH sums: kernel values, gradients and their corrections, one point at a time.

The same quantities as the numpy reference :meth:`~dolfinx_meshfree.approx.sph.SPH.tabulate`
(Rabczuk et al. 2006, eq. 10; the corrections of :mod:`.sph`), per point from its pairs:

* ``N_I = dV_I W(|x - x_I|, h)`` and ``grad N_I = dV_I W'(q)/h (x - x_I)/|x - x_I|``, with the
  cubic spline of :func:`~dolfinx_meshfree.approx.kernels.sph_cubic_spline` (the EFG cubic
  (3.10b) of ``q/2``, compiled once in :mod:`.mls_kernel`);
* Shepard values ``N_I / sum_J N_J``;
* corrected gradients ``G_I = M^-1 (grad N_I - S Nhat_I)`` with ``S = sum_J grad N_J``,
  ``Nhat_I = N_I / sum_J N_J``, ``xbar = sum_J Nhat_J x_J`` and
  ``M = sum_J grad N_J (x) (x_J - xbar)``, inverted in closed form as :func:`.batched.inv`.

The pairs come from the grouped candidate lists of
:meth:`~dolfinx_meshfree.approx.cell_lists.CellList.candidates` (every particle has the
support ``2h``), sorted by particle index: a count pass sizes the CSR arrays exactly, a fill
pass writes them.
"""

from __future__ import annotations

import numpy as np

from . import jit
from .mls_kernel import _weight

__all__ = ["CORRECTION_IDS", "fill_sph"]

#: The corrections of :class:`~dolfinx_meshfree.approx.sph.SPH` by code.
CORRECTION_IDS = {None: 0, "gradient": 1, "shepard": 2}


@jit.jit
def _inverse_small(M: np.ndarray, out: np.ndarray, g: int) -> float:
    """``out = M^-1`` (g x g, g <= 3) by the adjugate, as :func:`.batched.inv`; returns det."""
    if g == 1:
        out[0, 0] = 1.0 / M[0, 0]
        return M[0, 0]
    if g == 2:
        det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
        out[0, 0], out[0, 1] = M[1, 1] / det, -M[0, 1] / det
        out[1, 0], out[1, 1] = -M[1, 0] / det, M[0, 0] / det
        return det
    c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
    c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
    c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
    det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
    out[0, 0], out[1, 0], out[2, 0] = c00 / det, c01 / det, c02 / det
    out[0, 1] = (M[0, 2] * M[2, 1] - M[0, 1] * M[2, 2]) / det
    out[1, 1] = (M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]) / det
    out[2, 1] = (M[0, 1] * M[2, 0] - M[0, 0] * M[2, 1]) / det
    out[0, 2] = (M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1]) / det
    out[1, 2] = (M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2]) / det
    out[2, 2] = (M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]) / det
    return det


@jit.jit
def fill_sph(
    x: np.ndarray,
    candidates: tuple,
    indptr: np.ndarray,
    volumes: np.ndarray,
    h: float,
    scale: float,
    g: int,
    correction: int,
    derivatives: bool,
    j: np.ndarray,
    N: np.ndarray,
    dN: np.ndarray,
    singular: np.ndarray,
) -> None:
    """SPH shape functions of the points ``x`` (m, 3; zero-padded) into CSR arrays.

    Args:
        x: The points.
        candidates: :meth:`~.cell_lists.CellList.candidates` of these points, radii ``2h``.
        indptr: Pair offsets per point (m + 1,), from :func:`.mls_kernel.count_pairs`.
        volumes: ``dV_I`` of every particle (n,).
        h: Smoothing length; ``scale``: ``3/2 sigma_d / h^d`` of the kernel.
        g: Spatial dimension.
        correction: :data:`CORRECTION_IDS`.
        derivatives: Whether to compute the gradients.
        j, N, dN: Outputs per pair (npairs,), (npairs,), (g, npairs): particle index, value and
            gradient (no rows without derivatives).
        singular: Output per point (m,): whether the gradient correction's ``M`` is singular
            (``|det M| <= 1e-10 max|M|^g``, the numpy path's test).
    """
    group, cstart, cpacked, cradii, ckey = candidates
    kmax = 1
    for gr in range(cstart.size - 1):
        kmax = max(kmax, cstart[gr + 1] - cstart[gr])
    pos = np.empty((kmax, 3))  # x_J of the pairs
    M = jit.carray(jit.stack_pointer(9), (3, 3))
    Minv = jit.carray(jit.stack_pointer(9), (3, 3))
    S = jit.carray(jit.stack_pointer(3), (3,))
    xbar = jit.carray(jit.stack_pointer(3), (3,))
    v = jit.carray(jit.stack_pointer(3), (3,))
    for q in range(x.shape[0]):
        gr = group[q]
        k = indptr[q]
        cnt = 0
        for c in range(cstart[gr], cstart[gr + 1]):  # the pairs, by particle index
            r2 = 0.0
            for d in range(3):
                pos[cnt, d] = cpacked[c, d]
                r2 += (x[q, d] - pos[cnt, d]) ** 2
            if r2 <= cpacked[c, 3] and np.sqrt(r2) < cradii[c]:
                r = np.sqrt(r2)
                w, dw = _weight(1, 0.5 * r / h)  # sph_cubic_spline: the cubic of q / 2
                vol = volumes[ckey[c]]
                j[k + cnt] = ckey[c]
                N[k + cnt] = vol * scale * w
                if derivatives:
                    f = vol * 0.5 * scale * dw / h / r if r > 0.0 else 0.0
                    for d in range(g):
                        dN[d, k + cnt] = f * (x[q, d] - pos[cnt, d])
                cnt += 1
        singular[q] = False
        if correction == 2:  # Shepard values
            total = 0.0
            for t in range(cnt):
                total += N[k + t]
            for t in range(cnt):
                N[k + t] = N[k + t] / total
        if not derivatives or correction == 0:
            continue
        total = 0.0
        for t in range(cnt):
            total += N[k + t]
        for a in range(g):
            S[a] = 0.0
            xbar[a] = 0.0
            for b in range(g):
                M[a, b] = 0.0
        for t in range(cnt):
            nhat = N[k + t] / total
            for a in range(g):
                S[a] += dN[a, k + t]
                xbar[a] += nhat * pos[t, a]
        for t in range(cnt):
            for a in range(g):
                for b in range(g):
                    M[a, b] += dN[a, k + t] * (pos[t, b] - xbar[b])
        mmax = 0.0
        for a in range(g):
            for b in range(g):
                mmax = max(mmax, abs(M[a, b]))
        det = _inverse_small(M, Minv, g)
        if not abs(det) > 1e-10 * mmax**g:
            singular[q] = True
            continue
        for t in range(cnt):
            nhat = N[k + t] / total
            for a in range(g):
                v[a] = dN[a, k + t] - S[a] * nhat
            for a in range(g):
                acc = 0.0
                for b in range(g):
                    acc += Minv[a, b] * v[b]
                dN[a, k + t] = acc
