"""Intrinsic near-tip enrichment of the MLS basis (Fleming, Chu, Moran & Belytschko 1997).

Near a crack tip the displacement behaves as ``sqrt(r)`` times functions of the tip angle
``theta``; a linear MLS basis resolves it only by refinement (the SIF error of pure EFG falls
like ``h``: 3.7 % at 1,722 dofs on the edge crack, 0.6 % at 103k). Fleming et al. (1997) add
to the basis the four functions that span the first term of Williams' expansion,

.. math::
    p^T = \\left[1,\\ x,\\ y,\\ \\sqrt r\\cos\\tfrac\\theta2,\\ \\sqrt r\\sin\\tfrac\\theta2,\\
    \\sqrt r\\sin\\tfrac\\theta2\\sin\\theta,\\ \\sqrt r\\cos\\tfrac\\theta2\\sin\\theta\\right],

in the tip frame (``theta = +-pi`` on the crack faces), so that the K_I and K_II fields are
reproduced exactly. Far from the tip these functions are nearly linear over a support and the
moment matrix becomes singular (its eigenvalue ratio fell to 4e-19 with the whole plate
enriched at dilation 2.5), so the enriched approximation is used only near the tip and blended
into the linear one by a C1 cubic ramp ``R(r)`` (1 inside ``r1``, 0 beyond ``r2``), the blend
of two approximations of Belytschko et al. 1995, eq. (3.12), here of two MLS approximations:

.. math::
    N_I = R\\,N_I^{enr} + (1 - R)\\,N_I^{lin},\\qquad
    \\nabla N_I = R\\,\\nabla N_I^{enr} + (1 - R)\\,\\nabla N_I^{lin}
    + \\nabla R\\,(N_I^{enr} - N_I^{lin}).

Both reproduce linear fields, so the blend does (the linear patch test and VCI are unchanged).
The enriched MLS uses its own, larger supports (``dilation`` 4 by default: seven basis
functions) cut by the same cracks; in the general form ``phi_I = w_I p(x_I)^T A^{-1} p(x)``
(eq. 3.9 of Belytschko et al. 1995) with ``dphi_I = dw_I p_I^T A^{-1} p + w_I p_I^T A^{-1}
(dp - dA A^{-1} p)``. Defaults ``r1 = 2 h``, ``r2 = 4 h`` (``h`` the particle spacing at the
tip); ``r2`` is capped at 0.9 of the tip segment's length so that the branch cut of ``sqrt``
(behind the tip, along the last segment) stays on the crack.

Support size (issue 23, item 1). With dilation 3 (the earlier default) an edge crack passing
0.05 to 0.15 spacing from a particle row gave K_I off by -7 % to +70 % over the default domains
(a/W = 0.3, lagrange, spacings 0.0125 and 0.00625, the tip on or between particle columns; -12 %
over domains of 3 to 5 spacings), with a spread over large domains as low as 0.03 %: nothing
showed it. Cause: a point next to the crack face on the far side from that row sees, on its
side, the rows about 1 and 2 spacings away, the third at the edge of a support of 3 spacings
(weight ~0); the branch functions have terms quadratic across the face
(``sqrt(r) cos(theta/2) sin(theta)`` grows like ``y^2`` there), which two rows cannot determine,
so in the ramp ``2 h < r < 4 h`` the enriched moment matrices came near singular (eigenvalue
ratio 4.3e-10), the shape functions large and steep (``sum |phi_I|`` up to 54,
``h sum |grad phi_I|`` up to 754, against 5 and 35 at half a spacing's offset), and the
stiffness of that band under-integrated: one cut cell held 15x more energy at Gauss degree 30
than at the default 7, a spurious mode (raising the degree to 12 or 20 moved K_I from +71 % to
-2.3 % and +3.1 %: no convergence); a larger linear dilation (3) did not help, the visibility
criterion was worse. Dilation 4 puts the third row at 3/4 of the support: at offsets of 0.05
and 0.1 spacing the eigenvalue ratio is >= 1.4e-7, ``sum |phi_I|`` <= 5.4, ``h sum |grad
phi_I|`` <= 47, and K_I is within 0.83 % of Tada's value at every offset from 0.05 to 0.95
spacing and every tip position (66 cases over two spacings; ``tests/test_sif_reliability.py``,
``tests/test_tip_enrichment.py``); on a grid the enriched moment matrices' eigenvalue ratio
rose from 3.5e-9 to 2.3e-7 and the round-off of the reproduced linear gradients fell from
2.3e-8 to 1.4e-10. Where dilation 3 worked, K moves by 0.06 % to 0.14 % (below).

Measured on the single edge crack (a/W = 0.4, the crack half a spacing off the rows, pure EFG,
K_I against the converged P2 FE value), linear -> enriched: 1,722 dofs -4.07 % -> +0.29 %
(dilation 3: +0.23 %); 6,642 dofs -2.05 % -> +0.28 % (+0.14 %); 26,082 dofs -1.00 % ->
+0.18 % (+0.11 %); on the inclined centre crack (exact K, both tips, h = 0.1, 3,362 dofs) the
worst error falls from 9.9e-3 to 1.8e-3 (EFG; lagrange 1.9e-3, bridging 1.9e-3; 1.6e-3 to
1.7e-3 with dilation 3; ``tests/test_tip_enrichment.py``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..geometry.crack import Crack
from . import batched
from .crack_cuts import attach_cracks
from .mls import MLS, pair_distances
from .neighbours import cut_pairs, pairs_within_support
from .tables import ShapeTable

__all__ = ["TipEnrichment", "enrich_tips", "enriched_basis", "ramp"]

#: Basis functions of the enriched MLS (1, x, y and the four branch functions).
NUM_ENRICHED = 7


def ramp(r: np.ndarray, r1: float, r2: float) -> tuple[np.ndarray, np.ndarray]:
    """``R(r)``: 1 for ``r <= r1``, 0 for ``r >= r2``, ``1 - s^2 (3 - 2 s)`` between
    (``s = (r - r1)/(r2 - r1)``, C1); and ``dR/dr``."""
    s = np.clip((np.asarray(r, dtype=float) - r1) / (r2 - r1), 0.0, 1.0)
    return 1.0 - s * s * (3.0 - 2.0 * s), -6.0 * s * (1.0 - s) / (r2 - r1)


def enriched_basis(
    x: np.ndarray,
    tip: np.ndarray,
    direction: np.ndarray,
    scale: float,
    sides: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The basis above at points ``x`` (m, 2) and its gradient: ``p`` (m, 7), ``dp`` (2, m, 7).

    Coordinates are shifted to the tip and scaled by ``scale`` (conditioning only: MLS is
    invariant under a linear change of basis). Points on the crack line behind the tip with
    ``sides`` +1/-1 take the face on the left/right of the crack's direction of travel (the
    convention of :meth:`~dolfinx_meshfree.Crack.crosses` for a crack running to the tip).
    """
    t = np.asarray(direction, dtype=float)
    n = np.array([-t[1], t[0]])
    d = (np.asarray(x, dtype=float) - tip) / scale
    xl, yl = d @ t, d @ n
    z = xl + 1j * yl
    if np.any(z == 0):
        k = int(np.flatnonzero(z == 0)[0])
        raise ValueError(f"the tip enrichment is singular at the tip {np.asarray(x)[k].tolist()}")
    root = np.sqrt(z)  # branch cut along theta = +-pi, the crack behind the tip
    if sides is not None:
        on = (np.abs(yl) <= 1e-12 * np.abs(xl)) & (xl < 0) & (np.asarray(sides) != 0)
        face = np.where(np.asarray(sides) > 0, 1.0, -1.0)
        root = np.where(on, face * 1j * np.sqrt(np.abs(xl)), root)
        yl = np.where(on, 0.0, yl)
    r = np.abs(z)
    f1, f2 = root.real, root.imag
    half_inv = 0.5 / root  # d sqrt(z) / dz
    df1 = np.stack([half_inv.real, -half_inv.imag])  # d/dxl, d/dyl of Re sqrt(z)
    df2 = np.stack([half_inv.imag, half_inv.real])  # of Im sqrt(z)
    sin = yl / r
    dsin = np.stack([-xl * yl / r**3, xl * xl / r**3])
    m = xl.size
    p = np.empty((m, NUM_ENRICHED))
    dloc = np.zeros((2, m, NUM_ENRICHED))
    p[:, 0], p[:, 1], p[:, 2] = 1.0, xl, yl
    dloc[0, :, 1] = dloc[1, :, 2] = 1.0
    p[:, 3], p[:, 4], p[:, 5], p[:, 6] = f1, f2, f2 * sin, f1 * sin
    dloc[:, :, 3], dloc[:, :, 4] = df1, df2
    dloc[:, :, 5] = df2 * sin + f2 * dsin
    dloc[:, :, 6] = df1 * sin + f1 * dsin
    # back to global components: d/dx_k = (t_k d/dxl + n_k d/dyl) / scale
    dp = (t[:, None, None] * dloc[0] + n[:, None, None] * dloc[1]) / scale
    return p, dp


@dataclass
class TipEnrichment:
    """Blend of an enriched MLS into ``mls`` around the tips of ``cracks``; installed by
    :func:`enrich_tips` as one of ``mls.table_transforms``.

    Attributes:
        mls: The (linear) MLS whose tables are enriched.
        cracks: The cracks whose tips are enriched (their current tips at every tabulation).
        enriched: The private MLS of the enriched approximation (larger supports, same cuts).
        inner, outer: ``r1``, ``r2`` in particle spacings at the tip.
    """

    mls: MLS
    cracks: list[Crack]
    enriched: MLS
    inner: float = 2.0
    outer: float = 4.0

    def regions(self) -> list[tuple[np.ndarray, np.ndarray, float, float, float, int]]:
        """``(tip, direction, r1, r2, spacing, face)`` of every tip now; ``face`` maps the
        crack's ``sides`` (left/right of its segments' order) to the tip frame's (left/right of
        the direction of travel to the tip): -1 at a tip at the crack's start."""
        out = []
        for crack in self.cracks:
            a, b = crack.segments
            for end in crack.tip_ends:
                tip = crack.points[end]
                near = np.linalg.norm(self.mls.points - tip, axis=1)
                spacing = float(self.mls.radii[np.argmin(near)] / self.mls.dilation)
                seg = float(np.linalg.norm(b[0] - a[0] if end == 0 else b[-1] - a[-1]))
                r2 = min(self.outer * spacing, 0.9 * seg)
                r1 = r2 * self.inner / self.outer
                out.append((tip, crack.tip_direction(end), r1, r2, spacing, -1 if end == 0 else 1))
        return out

    def reach(self) -> float:
        """A bound on the outer ramp radius ``r2`` at any tip (``outer`` times the largest
        particle spacing): the rows a tip's move can change lie within it of the old and the
        new tip (:mod:`~dolfinx_meshfree.statics.growth_update`)."""
        return float(self.outer * self.mls.radii.max() / self.mls.dilation)

    def __call__(
        self, x: np.ndarray, table: ShapeTable, derivatives: int, sides: np.ndarray | None
    ) -> ShapeTable:
        for tip, direction, r1, r2, spacing, face in self.regions():
            d = x - tip
            r = np.linalg.norm(d, axis=1)
            near = np.flatnonzero(r < r2)
            if near.size == 0:
                continue
            s = None if sides is None else np.asarray(sides)[near]
            enr = self._tabulate(x[near], derivatives, s, face, tip, direction, spacing)
            R, dR = ramp(r[near], r1, r2)
            unit = d[near] / r[near, None]
            table = _blend(table, near, enr, R, dR[:, None] * unit)
        return table

    def _tabulate(
        self,
        x: np.ndarray,
        derivatives: int,
        sides: np.ndarray | None,
        face: int,
        tip: np.ndarray,
        direction: np.ndarray,
        spacing: float,
    ) -> ShapeTable:
        """The enriched MLS at ``x`` (general form, numpy: a few points around each tip);
        ``sides`` in the crack's convention, ``face * sides`` in the tip frame's."""
        e = self.enriched
        m, n = x.shape[0], e.num_particles
        i, j, dx = pairs_within_support(x, e.points, e.radii, e._tree)
        dist, ddist = pair_distances(dx)
        i, j, dx, dist, ddist = cut_pairs(e.pair_cuts, x, i, j, dx, dist, ddist, sides)
        rho = e.radii[j]
        w, dwdr = e._weight(dist / rho)
        pI = enriched_basis(e.points, tip, direction, spacing)[0][j]
        q, dq = enriched_basis(x, tip, direction, spacing, None if sides is None else face * sides)
        A = MLS._sum_outer(i, w, pI, pI, m)
        e._check_conditioning(A, np.bincount(i, minlength=m), x)  # the MLS's own check
        Ainv = batched.inv(A)
        g = np.einsum("qab,qb->qa", Ainv, q)  # A^-1 p(x)
        phi = w * np.einsum("pa,pa->p", pI, g[i])
        values = sp.csr_matrix((phi, (i, j)), shape=(m, n))
        grads = []
        if derivatives:
            for k in range(2):
                dw = dwdr / rho * ddist[:, k]
                dA = MLS._sum_outer(i, dw, pI, pI, m)
                dg = np.einsum("qab,qb->qa", Ainv, dq[k] - np.einsum("qab,qb->qa", dA, g))
                dphi = dw * np.einsum("pa,pa->p", pI, g[i]) + w * np.einsum("pa,pa->p", pI, dg[i])
                grads.append(sp.csr_matrix((dphi, (i, j)), shape=(m, n)))
        return ShapeTable(points=x, values=values, gradients=grads, version=self.mls.version)


def _blend(
    table: ShapeTable, near: np.ndarray, enr: ShapeTable, R: np.ndarray, dR: np.ndarray
) -> ShapeTable:
    """Rows ``near`` of ``table`` replaced by ``R enr + (1 - R) table`` (gradients with
    ``dR (enr - table)``, ``dR`` (k, gdim) the gradient of ``R``); the values and gradients of
    the result share one sparsity pattern, as the MLS tables do."""
    k = near.size
    base = [table.values[near].tocoo(), *(g[near].tocoo() for g in table.gradients)]
    extra = [enr.values.tocoo(), *(g.tocoo() for g in enr.gradients)]
    rows = np.concatenate([base[0].row, extra[0].row])
    cols = np.concatenate([base[0].col, extra[0].col])
    rb, re_ = base[0].row, extra[0].row
    vb, ve = base[0].data, extra[0].data

    def merged(db: np.ndarray, de: np.ndarray) -> sp.csr_matrix:
        out = sp.csr_matrix(
            (np.concatenate([db, de]), (rows, cols)), shape=(k, table.values.shape[1])
        )
        out.sum_duplicates()
        return out

    for b, e in zip(base, extra, strict=True):  # every table lists its pairs in the same order
        if not (np.array_equal(b.row, rb) and np.array_equal(e.row, re_)):
            raise RuntimeError("a table's values and gradients differ in sparsity")
    new = [merged((1.0 - R[rb]) * vb, R[re_] * ve)]
    for c in range(len(table.gradients)):
        gb, ge = base[c + 1].data, extra[c + 1].data
        new.append(merged((1.0 - R[rb]) * gb - dR[rb, c] * vb, R[re_] * ge + dR[re_, c] * ve))
    out = [
        _splice(old, near, rows_new)
        for old, rows_new in zip([table.values, *table.gradients], new, strict=True)
    ]
    return ShapeTable(points=table.points, values=out[0], gradients=out[1:], version=table.version)


def _splice(full: sp.csr_matrix, near: np.ndarray, rows: sp.csr_matrix) -> sp.csr_matrix:
    """``full`` with its rows ``near`` replaced by the rows of ``rows`` (CSR, vectorised)."""
    full = full.tocsr()
    m = full.shape[0]
    counts = np.diff(full.indptr)
    counts[near] = np.diff(rows.indptr)
    indptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    indices = np.empty(indptr[-1], dtype=full.indices.dtype)
    data = np.empty(indptr[-1])
    keep = np.ones(m, dtype=bool)
    keep[near] = False
    src_rows = np.repeat(np.arange(m), np.diff(full.indptr))
    sel = keep[src_rows]
    dest = indptr[src_rows[sel]] + (np.arange(full.indptr[-1])[sel] - full.indptr[src_rows[sel]])
    indices[dest], data[dest] = full.indices[sel], full.data[sel]
    new_rows = np.repeat(np.arange(near.size), np.diff(rows.indptr))
    dest = indptr[near[new_rows]] + (np.arange(rows.indptr[-1]) - rows.indptr[new_rows])
    indices[dest], data[dest] = rows.indices, rows.data
    out = sp.csr_matrix((data, indices, indptr.astype(full.indptr.dtype)), shape=full.shape)
    out.has_sorted_indices = True
    return out


def enrich_tips(
    mls: MLS,
    cracks: Sequence[Crack],
    method: str = "diffraction",
    dilation: float = 4.0,
    inner: float = 2.0,
    outer: float = 4.0,
) -> TipEnrichment:
    """Enrich ``mls`` around the tips of ``cracks`` (already attached to it by
    :func:`~dolfinx_meshfree.approx.crack_cuts.attach_cracks` with ``method``): appends a
    :class:`TipEnrichment` to ``mls.table_transforms`` and marks ``mls`` changed.

    Args:
        dilation: Support dilation of the enriched MLS (seven basis functions need more
            particles than three: 2.5 is singular, 3.0 near singular next to a crack face when
            the crack passes within 0.15 spacing of a particle row, 4.0 well conditioned at
            every offset; module docstring).
        inner, outer: Ramp radii ``r1 < r2`` in particle spacings at the tip.
    """
    if not (np.isfinite(dilation) and dilation > 0):
        raise ValueError(f"dilation={dilation!r} must be a positive number (4.0 is the default)")
    if not (0 < inner < outer and np.isfinite(outer)):
        raise ValueError(
            f"inner={inner!r}, outer={outer!r}: the ramp radii must satisfy 0 < inner < outer "
            f"(in particle spacings; the defaults are 2 and 4)"
        )
    enriched = MLS(mls.points, weight=mls.weight_name, dilation=dilation, backend="numpy")
    enriched.rcond = mls.rcond
    enriched._fix = (  # the fix its conditioning check names (MomentMatrixError)
        f"raise the enrichment's dilation (now {dilation}) or lower its outer radius "
        f"(now {outer} spacings around the tip)"
    )
    attach_cracks(enriched, cracks, method)
    transform = TipEnrichment(mls, list(cracks), enriched, float(inner), float(outer))
    mls.table_transforms.append(transform)
    mls.changed()
    return transform
