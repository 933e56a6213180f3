"""Local update of the particle side after a crack grows (issue 10, item 5).

Belytschko et al. (1995), remark after eq. (3.11): the MLS shape functions change as the crack
grows, but only near the new segment. After ``crack.extend`` this module re-tabulates only the
table rows, re-integrates only the cells, and replaces only the stiffness contributions that the
extension changes; the result equals a full rebuild to round-off (the tests check 1e-10).

**Where the weights change** (Organ, Fleming & Belytschko 1996; :mod:`~dolfinx_meshfree.approx.
crack_cuts`). Let ``S`` be the new segment(s), from the old tip ``t_0`` to the new tip ``t_1``.
The weight of a pair ``(x, x_I)`` (evaluation point, particle with support radius ``r_I``) is
the plain ``w(|x - x_I|)`` unless the segment ``x x_I`` crosses the crack; then it is dropped
(visibility) or uses the bent distance ``d = ((s_1 + s_2)/s_0)^lambda s_0 >= s_1 + s_2`` around a
tip whose legs do not cross the crack, kept only if ``d < r_I`` (diffraction). The pair can
change only if (a) ``x x_I`` crosses ``S`` (it crosses the crack now, or twice), (b) it crossed
the old crack and is bent around ``t_0`` (now a joint) or, now, around ``t_1``, or (c) a leg to
another tip crosses ``S`` (no longer admissible). In (a) ``|x - x_I| < r_I`` (in the support);
in (b) ``|x - t| + |x_I - t| <= d < r_I`` for ``t = t_0`` or ``t_1`` on ``S``; in (c) the leg
meets ``S`` at ``c`` and ``|x - c|, |x_I - c| <= s_1 + s_2 < r_I``. In every case

    dist(x, S) < r_I  and  dist(x_I, S) < r_I.

So with ``P_1 = {I : dist(x_I, S) < r_I}`` and ``R_1 = max_{I in P_1} r_I``, the rows of a table
(at points ``x``) that change are within ``R_1`` of ``S``; every other row is the same function
of the same weights, bit for bit. Crack-face points (one-sided values) follow the same rule.

**Cells.** The cells :func:`~dolfinx_meshfree.geometry.cut_cells.cells_cut_by` ``S`` get new
points (:func:`~dolfinx_meshfree.geometry.cut_cells.replace_cells`), and the crack faces of ``S``
are added to the VCI boundary; no other point changes.

**Consistent integration** (Chen, Hillman & Rüter 2013): ``xi_I = (sum_b N_I n w_b - sum_q
grad N_I w_q) / sum_q N_I w_q`` is a sum over the support of ``I`` only, so it changes only for
the particles ``X`` that are non-zero at a changed row (cell or boundary, old or new). Their sums
are recomputed over their whole supports (the rows where any of them is non-zero; collective),
and the corrected test gradients ``grad N + N xi`` change only on those rows ``Q'``.

**Stiffness.** ``K = sum_q B_test(x_q)^T D B(x_q) w_q`` (Belytschko et al. 1995, eq. 4.3):
``K_new = K_old - sum_{q in Q'_old} (...)_old + sum_{q in Q'_new} (...)_new``, formed by
:func:`~dolfinx_meshfree.physics.operators.stiffness_matrix` on the rows ``Q'`` only. The cost
of a step grows with the particles within about three support radii of ``S``: the tables are
kept in chunks (the changed rows are appended, the unchanged ones never copied) and stacked only
when a caller reads them. What still grows with the patch: the sparse sum ``K_old + dK`` and the
PETSc matrix built from it, the rules' point arrays (memory copies), the facet tables of the
loads and conditions (on the boundary), and the direct solve (``benchmarks/bench_growth.py``).

Not local (a full rebuild is done instead, silently equal): the edge-to-edge coupling's boundary
values and moment corrections (``boundary_values``/``boundary_moments`` of
:func:`~dolfinx_meshfree.statics.efg.particle_stiffness`), and any change of the crack other than
an extension at its ends.
"""

from __future__ import annotations

import dataclasses
import time
import weakref
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from .. import _compat
from ..approx.tables import ShapeTable
from ..geometry.crack import Crack, point_segment_distance
from ..geometry.cut_cells import (
    cells_cut_by,
    crack_face_quadrature,
    cut_cell_quadrature,
    join_quadrature,
    replace_cells,
)
from ..geometry.quadrature import QuadraturePoints
from ..parallel import raise_on_all_ranks
from ..physics.operators import stiffness_matrix

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

    from ..approx.mls import MLS
    from ..geometry.particles import ParticleSet
    from ..physics.materials import LinearElastic

__all__ = [
    "LocalUpdate",
    "change_radius",
    "changed_rows",
    "enable_local_update",
    "local_update_for",
    "new_segments",
]

#: MLS or Crack -> its LocalUpdate (weakly held: the update lives as long as the MLS).
_REGISTRY: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def local_update_for(obj: Any) -> LocalUpdate | None:
    """The :class:`LocalUpdate` registered for an MLS or a Crack, or None."""
    try:
        return _REGISTRY.get(obj)
    except TypeError:
        return None


def enable_local_update(mls: MLS, cracks: Sequence[Crack]) -> LocalUpdate:
    """Register a :class:`LocalUpdate` for ``mls`` and its ``cracks`` (replaces an earlier one):
    from then on :func:`~dolfinx_meshfree.statics.efg.crack_rules` and
    :func:`~dolfinx_meshfree.statics.efg.particle_stiffness` update their previous result
    locally after the cracks grow."""
    upd = LocalUpdate(mls, cracks)
    _REGISTRY[mls] = upd
    for c in upd.cracks:
        _REGISTRY[c] = upd
    return upd


def disable_local_update(mls: MLS) -> None:
    """Remove the :class:`LocalUpdate` of ``mls`` (and of its cracks): full rebuilds again."""
    upd = _REGISTRY.pop(mls, None)
    if upd is not None:
        for c in upd.cracks:
            if _REGISTRY.get(c) is upd:
                del _REGISTRY[c]


def new_segments(old: np.ndarray, new: np.ndarray) -> np.ndarray | None:
    """The segments (k, 2, 2) that ``new`` adds to the polyline ``old`` at its ends (each from
    the old tip outwards), or None when ``new`` is not ``old`` extended."""
    m = old.shape[0]
    if new.shape[0] < m:
        return None
    segs = []
    for start in range(new.shape[0] - m + 1):
        if np.array_equal(new[start : start + m], old):
            if start > 0:  # grown at the start: points new[0 .. start] lead to old[0]
                p = new[: start + 1][::-1]
                segs += [p[i : i + 2] for i in range(start)]
            tail = new[start + m - 1 :]
            segs += [tail[i : i + 2] for i in range(tail.shape[0] - 1)]
            return np.array(segs, dtype=float).reshape(-1, 2, 2)
    return None


def changed_rows(points: np.ndarray, segments: np.ndarray, radius: float) -> np.ndarray:
    """Indices of ``points`` (m, 2) within ``radius`` of any of ``segments`` (k, 2, 2)."""
    if segments.shape[0] == 0 or points.shape[0] == 0 or radius <= 0:
        return np.zeros(0, dtype=np.int64)
    lo = segments.reshape(-1, 2).min(axis=0) - radius
    hi = segments.reshape(-1, 2).max(axis=0) + radius
    cand = np.flatnonzero(np.all((points[:, :2] >= lo) & (points[:, :2] <= hi), axis=1))
    d = point_segment_distance(points[cand, :2], segments[:, 0], segments[:, 1]).min(axis=1)
    return cand[d < radius]


def change_radius(mls: MLS, segments: np.ndarray) -> float:
    """``R_1``: the largest support radius of the particles of ``mls`` whose support reaches
    ``segments`` (k, 2, 2) (0 when none), times ``1 + 1e-12``: every table row that the new
    segments change lies within ``R_1`` of them (the module's docstring)."""
    x, r = mls.points[:, :2], mls.radii
    ids = changed_rows(x, segments, float(r.max()))
    d = point_segment_distance(x[ids], segments[:, 0], segments[:, 1]).min(axis=1)
    near = ids[d < r[ids]]
    R = float(r[near].max()) if near.size else 0.0
    # a table transform with a reach (the near-tip enrichment's ramp, which moves with the
    # tip) changes every row within that reach of the old and the new tip: ends of S
    if segments.shape[0]:
        R = max([R, *(t.reach() for t in mls.table_transforms if hasattr(t, "reach"))])
    return R * (1 + 1e-12)


def _rows(A: sp.csr_matrix, rows: np.ndarray) -> sp.csr_matrix:
    return A[rows] if rows.size else sp.csr_matrix((0, A.shape[1]))


class _Rows:
    """The rows of a sparse table kept in chunks: row ``i`` of the table is row ``where[i]`` of
    the chunks stacked. An update appends the changed and added rows as a new chunk and points
    the table's rows to it: the unchanged rows are never copied (a growth step costs what it
    changes). ``touching`` finds the rows with entries in given columns through each chunk's
    transpose (built once per chunk)."""

    def __init__(self, chunks: list, offsets: np.ndarray, where: np.ndarray, csc: list | None):
        self.chunks, self.offsets, self.where, self.csc = chunks, offsets, where, csc
        self.ncols = chunks[0].shape[1]

    @classmethod
    def of(cls, A: sp.csr_matrix, transpose: bool = False) -> _Rows:
        A = A.tocsr()
        return cls([A], np.array([0, A.shape[0]]), np.arange(A.shape[0]),
                   [A.tocsc()] if transpose else None)  # fmt: skip

    def __len__(self) -> int:
        return self.where.size

    def rows(self, idx: np.ndarray) -> sp.csr_matrix:
        """The table's rows ``idx`` (CSR, in that order)."""
        idx = np.asarray(idx, dtype=np.int64)
        if idx.size == 0:
            return sp.csr_matrix((0, self.ncols))
        g = self.where[idx]
        c = np.searchsorted(self.offsets, g, side="right") - 1
        parts, order = [], []
        for k in np.unique(c):
            sel = np.flatnonzero(c == k)
            parts.append(self.chunks[k][g[sel] - self.offsets[k]])
            order.append(sel)
        M = sp.vstack(parts, format="csr")
        inv = np.empty(idx.size, dtype=np.int64)
        inv[np.concatenate(order)] = np.arange(idx.size)
        return M[inv]

    def full(self) -> sp.csr_matrix:
        """The whole table (a copy)."""
        return self.rows(np.arange(len(self)))

    def update(
        self, kept: np.ndarray, at: np.ndarray, replaced: sp.csr_matrix, added: sp.csr_matrix
    ) -> _Rows:
        """The table of rows ``kept``, those at positions ``at`` replaced by ``replaced``, then
        ``added`` (a new object sharing the chunks)."""
        new = sp.vstack([replaced, added], format="csr")
        start = int(self.offsets[-1])
        where = np.concatenate([self.where[kept], start + at.size + np.arange(added.shape[0])])
        where[at] = start + np.arange(at.size)
        return _Rows(
            [*self.chunks, new], np.append(self.offsets, start + new.shape[0]), where,
            None if self.csc is None else [*self.csc, new.tocsc()],
        )  # fmt: skip

    def touching(self, cols: np.ndarray) -> np.ndarray:
        """The table's rows (sorted) with a stored entry in ``cols``."""
        hit = [self.offsets[k] + np.unique(t[:, cols].indices) for k, t in enumerate(self.csc)]
        g = np.concatenate(hit) if hit else np.zeros(0, dtype=np.int64)
        inv = np.full(int(self.offsets[-1]), -1, dtype=np.int64)
        inv[self.where] = np.arange(len(self))
        r = inv[g]
        return np.unique(r[r >= 0])


class _LazyTable(ShapeTable):
    """A :class:`ShapeTable` whose values and gradients are stacked from their chunks when
    first read."""

    def __init__(self, points: np.ndarray, values: _Rows, grads: list[_Rows], version: int):
        self.points, self.version = points, version
        self._rows = (values, grads)
        self._built: dict = {}

    @property
    def values(self) -> sp.csr_matrix:  # type: ignore[override]
        if "v" not in self._built:
            self._built["v"] = self._rows[0].full()
        return self._built["v"]

    @property
    def gradients(self) -> list[sp.csr_matrix]:  # type: ignore[override]
        if "g" not in self._built:
            self._built["g"] = [g.full() for g in self._rows[1]]
        return self._built["g"]


def _columns(*mats: sp.csr_matrix) -> np.ndarray:
    """The columns with a stored entry in any of ``mats``."""
    cols = [m.tocsr().indices for m in mats if m.shape[0]]
    return np.unique(np.concatenate(cols)) if cols else np.zeros(0, dtype=np.int64)


def _vci_sums(values, grads, w, bvalues, bw, normals) -> tuple[np.ndarray, np.ndarray]:
    """This rank's ``sum_q N_I w_q`` and ``sum_b N_I n w_b - sum_q grad N_I w_q`` (n,), (n, d):
    the numerator and denominator of the VCI constant (Chen, Hillman & Rüter 2013; the sums of
    :func:`~dolfinx_meshfree.physics.operators.consistent_gradients`)."""
    vol = values.T @ w
    rhs = np.stack(
        [bvalues.T @ (bw * normals[:, k]) - g.T @ w for k, g in enumerate(grads)], axis=1
    )
    return vol, rhs


@dataclasses.dataclass
class _Rules:
    """A crack rule built before (the key's arguments) and the crack points it saw."""

    q: QuadraturePoints | None
    bq: QuadraturePoints | None
    seen: int  # position in the change log


@dataclasses.dataclass
class _Stiffness:
    """The pieces of the last stiffness, to update."""

    key: tuple
    q: QuadraturePoints
    bq: QuadraturePoints | None
    values: _Rows
    grads: list[_Rows]
    bvalues: _Rows | None
    normals: np.ndarray | None
    test: list[_Rows]
    xi: np.ndarray | None
    Kg: sp.csr_matrix
    seen: int


class LocalUpdate:
    """Local rebuild of the crack rules and the particle stiffness of one MLS after its cracks
    grow (see the module's docstring for the region that changes). Created by
    :func:`enable_local_update`; used by :func:`~dolfinx_meshfree.statics.efg.crack_rules` and
    :func:`~dolfinx_meshfree.statics.efg.particle_stiffness` through :func:`local_update_for`.

    Attributes:
        log: One entry per crack change: the added segments (k, 2, 2), or None (not an
            extension: everything built before is rebuilt in full).
        last: What the last call did: ``"full"`` or ``"local"`` with row counts (for tests and
            the benchmark).
    """

    def __init__(self, mls: MLS, cracks: Sequence[Crack]) -> None:
        self.mls = mls
        self.cracks = list(cracks)
        self._points = [c.points.copy() for c in self.cracks]
        self.log: list[np.ndarray | None] = []
        self._rules: dict[tuple, _Rules] = {}
        self._derived: dict[int, tuple[QuadraturePoints, QuadraturePoints, np.ndarray]] = {}
        self._stiff: _Stiffness | None = None
        self.last: dict = {}
        for c in self.cracks:
            c.add_listener(self._crack_changed)

    # -- the change log ------------------------------------------------------------------------
    def _crack_changed(self) -> None:
        segs = []
        for k, c in enumerate(self.cracks):
            s = new_segments(self._points[k], c.points)
            if s is None:
                self.log.append(None)
                self._points[k] = c.points.copy()
                return
            segs.append(s)
            self._points[k] = c.points.copy()
        self.log.append(np.concatenate(segs) if segs else np.zeros((0, 2, 2)))

    def _since(self, seen: int) -> np.ndarray | None:
        """The segments added since log position ``seen`` (None: rebuild in full)."""
        entries = self.log[seen:]
        if any(e is None for e in entries):
            return None
        return np.concatenate(entries) if entries else np.zeros((0, 2, 2))

    def radius(self, segments: np.ndarray) -> float:
        """``R_1`` of :func:`change_radius` for this update's MLS."""
        return change_radius(self.mls, segments)

    # -- crack rules ---------------------------------------------------------------------------
    def rules(
        self,
        msh: dolfinx.mesh.Mesh,
        cells: np.ndarray,
        cracks: list[Crack],
        degree: int,
        boundary: tuple | None,
        cell_rule: bool,
        full: Callable[[], tuple],
    ) -> tuple:
        """:func:`~dolfinx_meshfree.statics.efg.crack_rules`'s result: ``full()`` the first time
        (per set of arguments), then the previous rules with the cells the new segments cut
        re-integrated and their crack faces appended."""
        if [id(c) for c in cracks] != [id(c) for c in self.cracks]:
            return full()
        key = (
            id(msh), np.asarray(cells).tobytes(), degree, bool(cell_rule),
            None if boundary is None else tuple(
                None if b is None else np.asarray(b).tobytes() for b in boundary
            ),
        )  # fmt: skip
        prev = self._rules.get(key)
        segs = None if prev is None else self._since(prev.seen)
        if segs is None:
            q, bq = full()
            self._rules[key] = _Rules(q, bq, len(self.log))
            return q, bq
        q, bq = prev.q, prev.bq
        if segs.shape[0]:
            cells = np.asarray(cells, dtype=np.int64)
            polylines = [s for s in segs]
            if q is not None:
                cut = cells_cut_by(msh, self._near_cells(msh, cells, segs), polylines)
                q_new = replace_cells(q, cut, cut_cell_quadrature(msh, cut, cracks, degree))
                keep = ~np.isin(q.cells, cut)
                self._derived[id(q_new)] = (q_new, q, keep)
                q = q_new
            if bq is not None:
                faces = crack_face_quadrature(
                    msh, self._near_cells(msh, cells, segs), polylines, degree
                )
                faces = dataclasses.replace(faces, entities=np.full(len(faces), -1))
                bq_new = join_quadrature(bq, faces)
                self._derived[id(bq_new)] = (bq_new, bq, np.ones(len(bq), dtype=bool))
                bq = bq_new
        self._rules[key] = _Rules(q, bq, len(self.log))
        return q, bq

    def _near_cells(self, msh, cells: np.ndarray, segs: np.ndarray) -> np.ndarray:
        """The cells among ``cells`` whose vertices' bounding box meets that of ``segs``."""
        geo = msh.geometry.x[_compat.entities_to_geometry(msh, 2, cells), :2]
        lo, hi = segs.reshape(-1, 2).min(axis=0), segs.reshape(-1, 2).max(axis=0)
        ok = np.all((geo.min(axis=1) <= hi) & (geo.max(axis=1) >= lo), axis=1)
        return cells[ok]

    def _origin(self, new: QuadraturePoints | None, old: QuadraturePoints | None):
        """The kept-row mask of ``old`` in ``new`` (``new`` = kept rows, then appended ones),
        or None when ``new`` is not derived from ``old`` by :meth:`rules`."""
        if new is None or old is None:
            return None if (new is None) != (old is None) else np.zeros(0, dtype=bool)
        if new is old:
            return np.ones(len(old), dtype=bool)
        entry = self._derived.get(id(new))
        if entry is None or entry[0] is not new:
            return None
        mask, cur = entry[2], entry[1]
        while cur is not old:  # several rule updates between two stiffnesses
            e = self._derived.get(id(cur))
            if e is None or e[0] is not cur:
                return None
            m = np.zeros(len(e[1]), dtype=bool)
            m[np.flatnonzero(e[2])[mask[: int(e[2].sum())]]] = True
            mask, cur = m, e[1]
        return mask

    # -- stiffness -----------------------------------------------------------------------------
    def stiffness(
        self,
        particles: ParticleSet,
        material: LinearElastic,
        q: QuadraturePoints,
        bq: QuadraturePoints | None,
        normals_fn: Callable | None,
        key: tuple,
        comm: MPI.Comm,
    ) -> tuple[sp.csr_matrix, ShapeTable, Callable[[], list[sp.csr_matrix]], dict] | None:
        """The updated ``(Kg, table, test gradients (a function stacking them), timings)`` of
        :func:`~dolfinx_meshfree.statics.efg.particle_stiffness`, or None when a full build is
        needed (the first call, other arguments, a change that is not an extension). Collective
        (every rank takes the same branch; a tabulation error is raised on every rank)."""
        st = self._stiff
        ok = st is not None and st.key == key
        segs = self._since(st.seen) if ok else None
        kq = self._origin(q, st.q) if ok else None
        kb = self._origin(bq, st.bq) if ok else None
        mine = segs is not None and kq is not None and kb is not None
        if not comm.allreduce(mine, op=MPI.LAND):
            return None
        t0 = time.perf_counter()
        mls, gdim = self.mls, particles.gdim
        R = self.radius(segs) if segs.shape[0] else 0.0
        # cell rows: kept (changed near S) and added
        kept = np.flatnonzero(kq)
        nk = kept.size
        near = changed_rows(q.points[:nk], segs, R)
        added = np.arange(nk, len(q))
        redo = np.concatenate([near, added])
        tab = raise_on_all_ranks(comm, lambda: mls.tabulate(q.points[redo]) if redo.size else None)
        removed = np.flatnonzero(~kq)
        ni = near.size
        tv = tab.values if tab is not None else sp.csr_matrix((0, mls.num_particles))
        tg = tab.gradients if tab is not None else [tv] * gdim
        values = st.values.update(kept, near, tv[:ni], tv[ni:])
        grads = [g0.update(kept, near, g[:ni], g[ni:]) for g0, g in zip(st.grads, tg, strict=True)]
        # boundary rows
        xi = st.xi
        if bq is not None:
            bk = np.flatnonzero(kb)
            nbk = bk.size
            bnear = changed_rows(bq.points[:nbk], segs, R)
            badd = np.arange(nbk, len(bq))
            bredo = np.concatenate([bnear, badd])
            sides = getattr(bq, "sides", None)
            btab = raise_on_all_ranks(
                comm,
                lambda: (
                    mls.tabulate(
                        bq.points[bredo], 0, None if sides is None else sides[bredo]
                    ).values
                    if bredo.size
                    else sp.csr_matrix((0, mls.num_particles))
                ),
            )
            bvalues = st.bvalues.update(bk, bnear, btab[: bnear.size], btab[bnear.size :])
            if normals_fn is None:
                normals = bq.normals
            else:  # the hook changes the normals on mesh facets only: keep them, add the faces'
                normals = np.concatenate([st.normals[bk], bq.normals[nbk:]])
            t1 = time.perf_counter()
            # particles whose VCI constant can change: non-zero on a changed row, old or new
            X = _columns(
                st.values.rows(np.concatenate([removed, kept[near]])), tv,
                st.bvalues.rows(bk[bnear]), btab,
            )  # fmt: skip
            X = np.unique(np.concatenate(comm.allgather(X)))
            rows_new = np.union1d(values.touching(X), redo)
            brows = bvalues.touching(X)
            vol, rhs = _vci_sums(
                values.rows(rows_new), [g.rows(rows_new) for g in grads], q.weights[rows_new],
                bvalues.rows(brows), bq.weights[brows], normals[brows],
            )  # fmt: skip
            vol = comm.allreduce(vol[X], op=MPI.SUM)
            rhs = comm.allreduce(rhs[X], op=MPI.SUM)
            xi = st.xi.copy()
            xi[X] = rhs / vol[:, None]
        else:
            bvalues, normals = None, None
            t1 = time.perf_counter()
            X = np.zeros(0, dtype=np.int64)
            rows_new = redo
        # old rows whose contribution goes: removed, and kept rows that change (new numbering ->
        # old numbering through ``kept``)
        rows_old = np.concatenate([removed, kept[rows_new[rows_new < nk]]])
        vals_new = values.rows(rows_new)
        grads_new = [g.rows(rows_new) for g in grads]
        test_new = [
            sp.csr_matrix(g + (vals_new @ sp.diags(xi[:, k]) if xi is not None else 0))
            for k, g in enumerate(grads_new)
        ]
        test_old = [t.rows(rows_old) for t in st.test]
        dK = stiffness_matrix(
            test_new, q.weights[rows_new], material, grads_new
        ) - stiffness_matrix(
            test_old, st.q.weights[rows_old], material, [g.rows(rows_old) for g in st.grads]
        )
        dK = dK.tocoo()
        dof_map = particles.petsc_dofs(gdim).ravel()
        n = gdim * particles.num_particles
        Kg = st.Kg + sp.csr_matrix((dK.data, (dof_map[dK.row], dof_map[dK.col])), shape=(n, n))
        # the test gradients on every row: kept rows, with the changed ones replaced
        at = rows_new[rows_new < nk]  # rows_new is sorted: the kept ones, then all added
        test = [
            t.update(kept, at, tn[: at.size], tn[at.size :])
            for t, tn in zip(st.test, test_new, strict=True)
        ]
        t2 = time.perf_counter()
        table = _LazyTable(q.points, values, grads, mls.version)
        self._stiff = _Stiffness(
            key, q, bq, values, grads, bvalues, normals, test, xi, Kg, len(self.log)
        )
        # the rules derived before these are no longer needed (they hold whole quadratures)
        self._derived = {k: v for k, v in self._derived.items() if v[0] is q or v[0] is bq}
        self.last = {
            "mode": "local", "rows": int(redo.size), "boundary_rows": 0 if bq is None else
            int(bredo.size), "particles": int(X.size), "stiffness_rows": int(rows_new.size),
            "cell_rows": len(q), "stiffness_dofs": int(np.unique(dK.row).size),
        }  # fmt: skip
        return Kg, table, lambda: [t.full() for t in test], {"setup": t1 - t0, "assemble": t2 - t1}

    def record(
        self,
        key: tuple,
        q: QuadraturePoints,
        bq: QuadraturePoints | None,
        table: ShapeTable,
        bvalues: sp.csr_matrix | None,
        normals: np.ndarray | None,
        test: list[sp.csr_matrix],
        Kg: sp.csr_matrix,
        comm: MPI.Comm,
    ) -> None:
        """Keep a full build's pieces (collective when consistent: the VCI constants)."""
        xi = None
        if bq is not None:
            vol, rhs = _vci_sums(
                table.values, table.gradients, q.weights, bvalues, bq.weights, normals
            )
            vol = comm.allreduce(vol, op=MPI.SUM)
            rhs = comm.allreduce(rhs, op=MPI.SUM)
            with np.errstate(divide="ignore", invalid="ignore"):
                xi = np.where(vol[:, None] != 0, rhs / vol[:, None], 0.0)
        self._stiff = _Stiffness(
            key, q, bq, _Rows.of(table.values, True), [_Rows.of(g) for g in table.gradients],
            None if bvalues is None else _Rows.of(bvalues, True), normals,
            [_Rows.of(t) for t in test], xi, Kg.tocsr(), len(self.log),
        )  # fmt: skip
        self.last = {"mode": "full", "cell_rows": len(q)}
