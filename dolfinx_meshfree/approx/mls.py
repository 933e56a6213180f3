"""Moving least squares (MLS) / element-free Galerkin shape functions.

Implements Belytschko et al. 1995, eq. (3.4)–(3.9): for an evaluation point ``x``

.. math::
    A(x) = \\sum_I w_I(x) p(x_I) p^T(x_I), \\qquad
    \\phi_I(x) = p^T(x) A^{-1}(x) w_I(x) p(x_I),

with derivatives that include the derivative of ``A^{-1}`` (``d(A^-1) = -A^-1 dA A^-1``, Belytschko,
Lu & Gu 1994), as the paper requires below eq. (4.3). For conditioning the basis is shifted to ``x``
and scaled by a length ``s``: ``p_I = p((x_I - x)/s)``; MLS is invariant under this change of basis,
and then ``p(x) = e_1``, so ``phi_I = w_I p_I^T gamma`` with ``A gamma = e_1``.

Two implementations (``backend``): ``"numba"`` (the default when numba is importable) searches
neighbours by cell lists (:mod:`.cell_lists`) and runs a compiled per-point kernel
(:mod:`.mls_kernel`) over chunks of points, writing the CSR arrays directly; ``"numpy"`` (the
reference, and the fallback without numba) is batched over all points at once (sparse pair lists,
``bincount`` moment sums, batched inverses). Both give the same tables to round-off (tested to
1e-12) and the same errors.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from scipy.spatial import cKDTree

from . import batched, jit
from .cell_lists import CellList
from .kernels import get_weight
from .mls_kernel import (
    WEIGHT_IDS,
    derivative_matrices,
    mls_shape_functions,
    monomial_exponents,
    tabulate_cells,
)
from .neighbours import check_points, cut_pairs, pairs_within_support, support_radii
from .tables import ShapeTable

if TYPE_CHECKING:  # annotations only
    from ..geometry.particles import ParticleSet

__all__ = [
    "BACKENDS",
    "DEFAULT_BACKEND",
    "MLS",
    "MomentMatrixError",
    "PairCut",
    "TableTransform",
    "pair_distances",
    "polynomial_basis",
]

#: The implementations of :meth:`MLS.tabulate`.
BACKENDS = ("numba", "numpy")
#: ``"numba"`` when numba is importable, else the numpy fallback; the environment variable
#: ``DOLFINX_MESHFREE_MLS_BACKEND`` (``numba`` or ``numpy``) overrides it, e.g. to run a test
#: suite on the reference path.
DEFAULT_BACKEND = jit.default_backend("DOLFINX_MESHFREE_MLS_BACKEND")
#: Evaluation points per chunk of the compiled path (bounds its temporaries).
CHUNK = 8192

#: A pair cut ``(x, i, j, dx, dist, ddist, sides) -> (i, j, dx, dist, ddist)``: see
#: :attr:`MLS.pair_cuts`.
PairCut = Callable[
    [np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None],
    tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
]


def pair_distances(dx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances ``|x - x_I|`` of the pairs and their gradients with respect to ``x``.

    Args:
        dx: ``x_i - x_j`` per pair (npairs, gdim).

    Returns:
        ``(dist, ddist)``: (npairs,) and (npairs, gdim); the gradient is the unit vector, zero
        where the point coincides with the particle (where every weight is flat).
    """
    dist = np.linalg.norm(dx, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        ddist = np.where(dist[:, None] > 0.0, dx / dist[:, None], 0.0)
    return dist, ddist


_BASES = {"linear": 1, "quadratic": 2}

#: A table transform ``(x, table, derivatives, sides) -> table``: see :attr:`MLS.table_transforms`.
TableTransform = Callable[[np.ndarray, ShapeTable, int, np.ndarray | None], ShapeTable]


class MomentMatrixError(ValueError):
    """The MLS moment matrix A(x) is singular or ill-conditioned at some evaluation point."""


def polynomial_basis(xi: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Complete polynomial basis and its derivatives in 1D/2D/3D (linear) or 2D (quadratic).

    Args:
        xi: Scaled, shifted coordinates (n, gdim).
        order: 1 (linear) or 2 (quadratic, 2D only).

    Returns:
        ``(p, dp)`` with ``p`` (n, m) and ``dp`` (gdim, n, m) = d p / d xi_k.
    """
    n, gdim = xi.shape
    one = np.ones((n, 1))
    zero = np.zeros((n, 1))
    if order == 1:
        p = np.hstack([one, xi])
        dp = np.zeros((gdim, n, gdim + 1))
        for k in range(gdim):
            dp[k, :, k + 1] = 1.0
        return p, dp
    if order == 2 and gdim == 2:
        x, y = xi[:, :1], xi[:, 1:2]
        p = np.hstack([one, x, y, x * x, x * y, y * y])
        dpx = np.hstack([zero, one, zero, 2 * x, y, zero])
        dpy = np.hstack([zero, zero, one, zero, x, 2 * y])
        return p, np.stack([dpx, dpy])
    raise ValueError(
        f"basis of order {order} in {gdim}D is not supported; use linear or 2D quadratic"
    )


class MLS:
    """MLS/EFG approximation on a fixed set of particles.

    Args:
        points: Particle positions (n, gdim), or a :class:`~dolfinx_meshfree.ParticleSet`.
        weight: ``"quartic"`` (default, eq. 3.10c), ``"cubic"`` (3.10b) or ``"gaussian"`` (3.10a).
        dilation: ``d_max`` of eq. (3.11); the support of particle ``I`` is ``d_max * c_I``.
        basis: ``"linear"`` or ``"quadratic"`` (2D).
        radii: Optional explicit support radii (n,), overriding ``dilation``.
        rcond: Smallest acceptable ratio of the extreme eigenvalues of the scaled moment matrix;
            below it an evaluation point is rejected with :class:`MomentMatrixError`.
        backend: ``"numba"`` (compiled, chunked; the default when numba is importable) or
            ``"numpy"`` (the reference implementation, and the fallback without numba).

    Example:
        >>> mls = MLS(points, weight="quartic", dilation=2.0)
        >>> table = mls.tabulate(x)          # table.values: (m x n) CSR
        >>> ux = table.values @ u_particles
    """

    def __init__(
        self,
        points: npt.ArrayLike | ParticleSet,
        weight: str = "quartic",
        dilation: float = 2.0,
        basis: str = "linear",
        radii: npt.ArrayLike | None = None,
        rcond: float = 1e-10,
        backend: str | None = None,
    ) -> None:
        backend = DEFAULT_BACKEND if backend is None else backend
        self.backend = jit.resolve_backend(backend, "DOLFINX_MESHFREE_MLS_BACKEND", BACKENDS)
        positions = getattr(points, "positions", points)
        self.weight_name = weight
        self._weight = get_weight(weight)
        if basis not in _BASES:
            raise ValueError(f"basis={basis!r} is not known; use one of {sorted(_BASES)}")
        if not (isinstance(dilation, int | float) and np.isfinite(dilation) and dilation > 1.0):
            raise ValueError(
                f"dilation={dilation!r} must be a number > 1 (typically 2-4 for statics, "
                "Belytschko et al. 1995 eq. 3.11)"
            )
        x = np.asarray(positions, dtype=float)
        gdim = x.shape[1] if x.ndim == 2 else 0
        self.points = check_points(x, gdim if gdim in (1, 2, 3) else 2, "points")
        self.gdim = self.points.shape[1]
        self.order = _BASES[basis]
        self.basis = basis
        self.num_basis = polynomial_basis(np.zeros((1, self.gdim)), self.order)[0].shape[1]
        self.dilation = float(dilation)
        self._fix = f"increase dilation (now {self.dilation})"
        if radii is None:
            self.radii = support_radii(self.points, self.dilation, self.num_basis, self._weight)
        else:
            r = np.asarray(radii, dtype=float)
            if r.shape != (self.points.shape[0],) or not np.all(r > 0):
                raise ValueError(
                    f"radii should be positive with shape ({self.points.shape[0]},), got {r.shape}"
                )
            self.radii = r
            self._fix = "increase radii (given explicitly; dilation is not used)"
        self.rcond = float(rcond)
        self._scale = float(np.median(self.radii))
        self._tree = cKDTree(self.points)
        self._cells: CellList | None = None  # built on the first compiled tabulation
        #: Pair cuts applied in order after the neighbour search, each
        #: ``cut(x, i, j, dx, dist, ddist, sides) -> (i, j, dx, dist, ddist)``: it may drop pairs
        #: or change the distance that enters the weight and its gradient ``d dist / dx`` (a
        #: crack's visibility or diffraction criterion); ``sides`` is the argument of
        #: :meth:`tabulate`. Call :meth:`changed` after changing the list.
        self.pair_cuts: list[PairCut] = []
        #: Applied in order to every table :meth:`tabulate` returns,
        #: ``transform(x, table, derivatives, sides) -> table`` (e.g. the near-tip enrichment of
        #: :mod:`.tip_enrichment`). Call :meth:`changed` after changing the list.
        self.table_transforms: list[TableTransform] = []
        #: Changes whenever the shape functions do (:meth:`changed`); tables carry the version
        #: they were built at (:attr:`ShapeTable.version`).
        self.version = 0
        #: Supports widened after construction, each with its reason (e.g. at a crack's mouth:
        #: :class:`~dolfinx_meshfree.approx.mouth_supports.WidenedSupports`).
        self.widened: list = []

    @property
    def scale(self) -> float:
        """The length ``s`` that scales the basis ``p((x_I - x) / s)`` of the moment matrices
        (the median support radius at construction; fixed, so tables are comparable)."""
        return self._scale

    def weight_function(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The weight ``w(q)`` and ``dw/dq`` at normalised distances ``q = |x - x_I| / d_I``
        (eq. 3.10 of Belytschko et al. 1995; zero for ``q >= 1``)."""
        return self._weight(np.asarray(q, dtype=float))

    def changed(self) -> None:
        """Mark the shape functions changed (the caller moved particles, changed supports or
        cut them): the version increments, and consumers holding older tables must rebuild."""
        self.version += 1
        self._cells = None  # rebuilt from the current points and radii

    @property
    def num_particles(self) -> int:
        """Number of particles (columns of every table)."""
        return self.points.shape[0]

    def subset(self, indices: npt.ArrayLike) -> MLS:
        """The MLS of the particles ``indices`` (increasing) with their support radii and this
        MLS's weight, basis, scaling length, ``rcond`` and backend (local).

        At a point whose supports (``|x - x_I| < d_I``) all belong to the subset its tables are
        this MLS's columns ``indices``, to the last bit: the same pairs in the same order, the
        same sums (eq. (3.7a)-(3.9)). A rank's particles within reach of its evaluation points
        (a halo) so stand for the whole set (:mod:`~dolfinx_meshfree.statics.large`). Pair cuts
        that have a ``subset(indices)`` of their own (the bodies' cut) are carried over; a subset
        of an MLS with any other cut (a crack's) or a table transform is refused.
        """
        idx = np.asarray(indices, dtype=np.int64)
        n = self.num_particles
        if (
            idx.ndim != 1
            or idx.size == 0
            or idx[0] < 0
            or idx[-1] >= n
            or np.any(np.diff(idx) <= 0)
        ):
            raise ValueError(
                f"indices must be increasing particle indices in [0, {n}), at least one; got "
                f"shape {idx.shape}" + (f", {idx[0]}..{idx[-1]}" if idx.size else "")
            )
        if self.table_transforms or not all(hasattr(c, "subset") for c in self.pair_cuts):
            raise ValueError(
                "subset() of an MLS with pair cuts that have no subset of their own (a crack's) "
                "or table transforms (enrichment) is not supported: tabulate the whole MLS"
            )
        sub = MLS(
            self.points[idx], weight=self.weight_name, dilation=self.dilation, basis=self.basis,
            radii=self.radii[idx], rcond=self.rcond, backend=self.backend,
        )  # fmt: skip
        sub._scale, sub._fix = self._scale, self._fix
        sub.pair_cuts = [cut.subset(idx) for cut in self.pair_cuts]
        return sub

    def tabulate(
        self, x: npt.ArrayLike, derivatives: int = 1, sides: npt.ArrayLike | None = None
    ) -> ShapeTable:
        """Shape functions (and first derivatives) at the points ``x`` (m, gdim).

        ``sides`` (m,) of ``+1``/``-1``/``0``, passed to the :attr:`pair_cuts`: the face of a
        crack on which a point lying on the crack is taken (the one-sided limit; 0: none).

        Local: no MPI communication. Raises :class:`MomentMatrixError` naming the first bad point,
        its neighbour count and the fix when ``A(x)`` is singular or ill-conditioned.
        """
        if derivatives not in (0, 1):
            raise ValueError(f"derivatives={derivatives} not supported; use 0 or 1")
        x = check_points(x, self.gdim, "x")
        m = x.shape[0]
        if sides is not None:
            if np.shape(sides) != (m,):
                raise ValueError(
                    f"sides should have shape ({m},) (one per point), got {np.shape(sides)}"
                )
            sides = np.asarray(sides)
        if self.backend == "numba":
            table = self._tabulate_compiled(x, derivatives, sides)
        else:
            table = self._tabulate_numpy(x, derivatives, sides)
        for transform in self.table_transforms:
            table = transform(x, table, derivatives, sides)
        return table

    def support_quality(
        self, x: npt.ArrayLike, sides: npt.ArrayLike | None = None, matrices: bool = False
    ) -> tuple[np.ndarray, ...]:
        """Per point of ``x`` (m, gdim): the number of particles in its support after the pair
        cuts, and the smallest over the largest eigenvalue of its moment matrix ``A(x)`` (eq.
        3.7a of Belytschko et al. 1995; 0 with fewer particles than the basis needs), without
        raising: where :meth:`tabulate` would refuse (a ratio not above ``rcond``) and how far
        from it a point is; with ``matrices``, the moment matrices (m, nb, nb) too, in the
        basis ``p((x_I - x) / s)``. The reference path; local. A cut with an ``unchecked``
        variant (:meth:`~dolfinx_meshfree.approx.crack_cuts.CrackCut.unchecked`) is applied by
        it."""
        x = check_points(x, self.gdim, "x")
        m = x.shape[0]
        i, j, dx = pairs_within_support(x, self.points, self.radii, self._tree)
        dist, ddist = pair_distances(dx)
        cuts = [getattr(c, "unchecked", c) for c in self.pair_cuts]
        i, j, dx, dist, ddist = cut_pairs(cuts, x, i, j, dx, dist, ddist, sides)
        counts = np.bincount(i, minlength=m)
        w, _ = self._weight(dist / self.radii[j])
        p, _ = polynomial_basis(-dx / self._scale, self.order)
        A = self._sum_outer(i, w, p, p, m)
        ratio = np.zeros(m)
        ok = counts >= self.num_basis
        if ok.any():
            ratio[ok] = self._eigenvalue_ratio(A[ok])
        return (counts, ratio, A) if matrices else (counts, ratio)

    def _check_counts(self, counts: np.ndarray, x: np.ndarray) -> None:
        """Too few particles in the support of a point: :class:`MomentMatrixError`."""
        nb = self.num_basis
        too_few = np.flatnonzero(counts < nb)
        if too_few.size:
            q = int(too_few[0])
            raise MomentMatrixError(
                f"MLS moment matrix is singular at {too_few.size} point(s); first: point {q} at "
                f"{x[q]} has {counts[q]} particle(s) in support but the {self.basis} basis needs "
                f"at least {nb}: {self._fix} or add particles"
            )

    def _prepare_compiled(self) -> None:
        """Cell list and basis tables of the compiled path (once per version)."""
        if self._cells is None:
            self._cells = CellList(self.points, self.radii)
            exponents = monomial_exponents(self.gdim, self.order)
            self._exponents = tuple(map(tuple, exponents.tolist()))
            self._dmat = derivative_matrices(exponents)

    def _tabulate_compiled(
        self, x: np.ndarray, derivatives: int, sides: np.ndarray | None = None
    ) -> ShapeTable:
        """The compiled path: cell-list pairs, cuts, compiled kernel, chunk by chunk."""
        m, g = x.shape
        self._prepare_compiled()
        if not self.pair_cuts:  # search and kernel fused, straight into the table
            counts, j, columns, sus, sus_A = tabulate_cells(
                self._cells, x, WEIGHT_IDS[self.weight_name], self._exponents, self._dmat,
                self._scale, bool(derivatives), self.rcond, CHUNK,
            )  # fmt: skip
            return self._checked_table(x, counts, sus, sus_A, j, columns, derivatives)
        counts = np.empty(m, np.int64)
        out = _GrowingColumns(1 + (g if derivatives else 0), m)
        suspects: list[np.ndarray] = [np.zeros(0, np.int64)]
        suspect_A: list[np.ndarray] = [np.zeros((0, self.num_basis, self.num_basis))]
        for start in range(0, m, CHUNK):
            stop = min(start + CHUNK, m)
            c, j, dx, dist, ddist = self._cells.pairs(x[start:stop])
            if self.pair_cuts:
                i = np.repeat(np.arange(start, stop), c)
                i, j, dx, dist, ddist = cut_pairs(self.pair_cuts, x, i, j, dx, dist, ddist, sides)
                c = np.bincount(i - start, minlength=stop - start)
                j = np.ascontiguousarray(j, dtype=np.int32)
                dx, ddist = np.ascontiguousarray(dx, float), np.ascontiguousarray(ddist, float)
                dist = np.ascontiguousarray(dist, float)
            counts[start:stop] = c
            indptr = np.zeros(stop - start + 1, np.int64)
            np.cumsum(c, out=indptr[1:])
            phi, dphi, bound, A = mls_shape_functions(
                indptr, j, dx, dist, ddist, self.radii, WEIGHT_IDS[self.weight_name],
                self._exponents, self._dmat, self._scale, bool(derivatives),
            )  # fmt: skip
            sus = np.flatnonzero(~(bound > self.rcond))
            suspects.append(sus + start)
            suspect_A.append(A[sus])
            out.append(j, [phi, *dphi], stop - start)
        sus, sus_A = np.concatenate(suspects), np.concatenate(suspect_A)
        return self._checked_table(x, counts, sus, sus_A, *out.result(), derivatives)

    def _checked_table(
        self, x: np.ndarray, counts: np.ndarray, sus: np.ndarray, sus_A: np.ndarray,
        j: np.ndarray, columns: list[np.ndarray], derivatives: int,
    ) -> ShapeTable:  # fmt: skip
        """The compiled path's table after its checks: the pair counts, then the exact
        eigenvalue ratio of the moment matrices ``sus_A`` of the points ``sus`` whose cheap
        bound was not above ``rcond``."""
        self._check_counts(counts, x)
        if sus.size:
            ratio = np.full(x.shape[0], np.inf)
            ratio[sus] = self._eigenvalue_ratio(sus_A)
            self._check_ratio(ratio, counts, x)
        return self._table(x, counts, j, columns, derivatives)

    def _table(
        self, x: np.ndarray, counts: np.ndarray, j: np.ndarray, columns: list[np.ndarray],
        derivatives: int,
    ) -> ShapeTable:  # fmt: skip
        """CSR tables from pairs sorted by point and particle (each matrix owns its indices)."""
        m, n = x.shape[0], self.num_particles
        idx = np.int32 if j.size < np.iinfo(np.int32).max else np.int64
        indptr = np.zeros(m + 1, idx)
        np.cumsum(counts, out=indptr[1:])
        mats = []
        for c, data in enumerate(columns):
            cols = j.astype(idx, copy=c > 0)
            a = sp.csr_matrix((data, cols, indptr if c == 0 else indptr.copy()), shape=(m, n))
            a.has_sorted_indices = True
            mats.append(a)
        grads = mats[1:] if derivatives else []
        return ShapeTable(points=x, values=mats[0], gradients=grads, version=self.version)

    def _tabulate_numpy(
        self, x: np.ndarray, derivatives: int, sides: np.ndarray | None = None
    ) -> ShapeTable:
        """The reference path: all points at once, batched numpy."""
        m = x.shape[0]
        n = self.num_particles
        i, j, dx = pairs_within_support(x, self.points, self.radii, self._tree)
        dist, ddist = pair_distances(dx)
        i, j, dx, dist, ddist = cut_pairs(self.pair_cuts, x, i, j, dx, dist, ddist, sides)
        counts = np.bincount(i, minlength=m)
        self._check_counts(counts, x)
        s = self._scale
        rho = self.radii[j]
        w, dwdr = self._weight(dist / rho)
        # p_I = p((x_I - x)/s); d p_I / dx_k = -(1/s) dp/dxi_k
        p, dpdxi = polynomial_basis(-dx / s, self.order)
        # moment matrix, eq. (3.7a), summed per point with bincount (vectorised)
        A = self._sum_outer(i, w, p, p, m)
        self._check_conditioning(A, counts, x)
        Ainv = batched.inv(A)
        gamma = Ainv[:, :, 0]  # A^-1 e_1 (A symmetric)
        g_pair = gamma[i]
        phi = w * np.einsum("pa,pa->p", p, g_pair)  # eq. (3.9)
        values = sp.csr_matrix((phi, (i, j)), shape=(m, n))
        grads: list[sp.csr_matrix] = []
        if derivatives:
            for k in range(self.gdim):
                dw = dwdr / rho * ddist[:, k]
                dp = -dpdxi[k] / s
                dA = self._sum_outer(i, dw, p, p, m) + self._sum_outer(i, w, dp, p, m)
                dA += np.transpose(self._sum_outer(i, w, dp, p, m), (0, 2, 1))
                dgamma = -np.einsum("qab,qbc,qc->qa", Ainv, dA, gamma)
                dphi = (
                    w * np.einsum("pa,pa->p", p, dgamma[i])
                    + dw * np.einsum("pa,pa->p", p, g_pair)
                    + w * np.einsum("pa,pa->p", dp, g_pair)
                )
                grads.append(sp.csr_matrix((dphi, (i, j)), shape=(m, n)))
        return ShapeTable(points=x, values=values, gradients=grads, version=self.version)

    @staticmethod
    def _sum_outer(
        i: np.ndarray, w: np.ndarray, a: np.ndarray, b: np.ndarray, m: int
    ) -> np.ndarray:
        """``out[q] = sum_{pairs of q} w a b^T``, shape (m, na, nb), by bincount per entry."""
        na, nb = a.shape[1], b.shape[1]
        out = np.empty((m, na, nb))
        for r in range(na):
            wa = w * a[:, r]
            for c in range(nb):
                out[:, r, c] = np.bincount(i, weights=wa * b[:, c], minlength=m)
        return out

    @staticmethod
    def _eigenvalue_ratio(A: np.ndarray) -> np.ndarray:
        """Smallest over largest eigenvalue of each symmetric matrix of ``A`` (k, nb, nb)."""
        ev = np.linalg.eigvalsh(A)
        return ev[:, 0] / np.maximum(ev[:, -1], np.finfo(float).tiny)

    def _check_conditioning(self, A: np.ndarray, counts: np.ndarray, x: np.ndarray) -> None:
        self._check_ratio(self._eigenvalue_ratio(A), counts, x)

    def _check_ratio(self, ratio: np.ndarray, counts: np.ndarray, x: np.ndarray) -> None:
        """Eigenvalue ratio below ``rcond`` at a point: :class:`MomentMatrixError`."""
        bad = np.flatnonzero(~(ratio > self.rcond))
        if bad.size:
            q = int(bad[0])
            # a cut that knows why (a crack beside the point) says so
            hints = [h(x[q]) for c in self.pair_cuts if (h := getattr(c, "hint", None))]
            why = "".join(f"; {h}" for h in hints if h)
            raise MomentMatrixError(
                f"MLS moment matrix is ill-conditioned at {bad.size} point(s) (eigenvalue ratio "
                f"{ratio[q]:.2e} < rcond={self.rcond:.0e}); first: point {q} at {x[q]} with "
                f"{counts[q]} particle(s) in support, which are (nearly) collinear or too few: "
                f"{self._fix} or add particles off the line{why}"
            )


class _GrowingColumns:
    """Pair columns (int32 indices + float columns) appended chunk by chunk into buffers that
    grow geometrically and are trimmed in place at the end (no concatenation of the chunks)."""

    def __init__(self, ncols: int, num_points: int) -> None:
        self._n = 0
        self._points = 0
        self._num_points = num_points
        self._j = np.empty(0, np.int32)
        self._cols = [np.empty(0) for _ in range(ncols)]

    def append(self, j: np.ndarray, cols: list[np.ndarray], points: int) -> None:
        """Append the pairs of the next ``points`` points."""
        k = j.size
        self._points += points
        if self._n + k > self._j.size:
            # room for all points at the pair density seen so far (+10 %), at least 1.5x
            need = self._n + k
            estimate = int(1.1 * need * self._num_points / self._points) + 1024
            cap = max(need, estimate, int(1.5 * self._j.size))
            self._j = _grown(self._j, self._n, cap)
            self._cols = [_grown(c, self._n, cap) for c in self._cols]
        self._j[self._n : self._n + k] = j
        for buf, c in zip(self._cols, cols, strict=True):
            buf[self._n : self._n + k] = c
        self._n += k

    def result(self) -> tuple[np.ndarray, list[np.ndarray]]:
        for a in (self._j, *self._cols):
            a.resize(self._n, refcheck=False)
        return self._j, self._cols


def _grown(a: np.ndarray, n: int, cap: int) -> np.ndarray:
    """A buffer of ``cap`` entries holding the first ``n`` of ``a``."""
    b = np.empty(cap, a.dtype)
    b[:n] = a[:n]
    return b
