"""Smoothed particle hydrodynamics (SPH) approximation.

Standard SPH (Rabczuk et al. 2006, eq. 10): ``N_I(X) = dV_I W(X - X_I, h_0)`` with the
cubic-spline kernel of :func:`~dolfinx_meshfree.approx.kernels.sph_cubic_spline` (support ``2
h_0``), a
Lagrangian kernel (evaluated in the reference configuration).

Plain SPH reproduces neither constants nor linear fields near boundaries or on irregular particle
sets. Two corrections are offered:

* ``correction="gradient"``: corrected gradient (Bonet & Lok 1999, Randles & Libersky 1996),
  ``grad~ N_I = L(x) grad N_I`` with ``L = (sum_J grad N_J (x) (x_J - x))^-1``; gradients of linear
  fields are then exact.
* ``correction="shepard"``: Shepard-normalised values ``N_I / sum_J N_J`` (partition of unity), with
  the gradient corrected as above.

Two implementations (``backend``), as for :class:`~dolfinx_meshfree.approx.mls.MLS`: ``"numba"``
(the default when numba is importable: cell lists and a compiled per-point kernel,
:mod:`.sph_kernel`) and ``"numpy"`` (the reference, and the fallback without numba); they agree
to round-off (tested to 1e-12).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from scipy.spatial import cKDTree

from . import batched, jit
from .cell_lists import CellList
from .kernels import cubic_inner_piece, sph_cubic_spline
from .mls_kernel import count_pairs
from .neighbours import check_points, cut_pairs, pairs_within_support
from .sph_kernel import CORRECTION_IDS, fill_sph
from .tables import ShapeTable

if TYPE_CHECKING:  # annotations only
    from ..geometry.particles import ParticleSet

__all__ = ["BACKENDS", "DEFAULT_BACKEND", "SPH"]

_CORRECTIONS = (None, "gradient", "shepard")
#: The implementations of :meth:`SPH.tabulate`.
BACKENDS = ("numba", "numpy")
#: ``"numba"`` when numba is importable, else the numpy fallback; the environment variable
#: ``DOLFINX_MESHFREE_SPH_BACKEND`` (``numba`` or ``numpy``) overrides it.
DEFAULT_BACKEND = jit.default_backend("DOLFINX_MESHFREE_SPH_BACKEND")


class SPH:
    """SPH approximation on particles with volumes.

    Args:
        points: Particle positions (n, gdim), or a :class:`~dolfinx_meshfree.ParticleSet` (then
            ``volumes`` defaults to its volumes).
        volumes: Particle volumes ``dV_I`` (n,).
        smoothing_length: ``h_0``; the kernel support is ``2 h_0``. Default: 1.3 times the mean
            distance to the nearest neighbour.
        correction: ``None``, ``"gradient"`` or ``"shepard"``.
        backend: ``"numba"`` (compiled; the default when numba is importable) or ``"numpy"``
            (the reference implementation, and the fallback without numba).
    """

    def __init__(
        self,
        points: npt.ArrayLike | ParticleSet,
        volumes: npt.ArrayLike | None = None,
        smoothing_length: float | None = None,
        correction: str | None = "gradient",
        backend: str | None = None,
    ) -> None:
        backend = DEFAULT_BACKEND if backend is None else backend
        self.backend = jit.resolve_backend(backend, "DOLFINX_MESHFREE_SPH_BACKEND", BACKENDS)
        self._cells: CellList | None = None  # built on the first compiled tabulation
        positions = getattr(points, "positions", points)
        if volumes is None:
            volumes = getattr(points, "volumes", None)
        if volumes is None:
            raise ValueError("volumes are required for SPH (dV_I of Rabczuk et al. 2006, eq. 10)")
        x = np.asarray(positions, dtype=float)
        gdim = x.shape[1] if x.ndim == 2 else 0
        self.points = check_points(x, gdim if gdim in (1, 2, 3) else 2, "points")
        self.gdim = self.points.shape[1]
        v = np.asarray(volumes, dtype=float)
        if v.shape != (self.points.shape[0],) or not np.all(v > 0):
            raise ValueError(
                f"volumes should be positive with shape ({self.points.shape[0]},), got shape "
                f"{v.shape} (min {v.min() if v.size else 'n/a'})"
            )
        self.volumes = v
        if correction not in _CORRECTIONS:
            raise ValueError(f"correction={correction!r} is not known; use one of {_CORRECTIONS}")
        self.correction = correction
        self._tree = cKDTree(self.points)
        #: Pair cuts applied after the neighbour search, as :attr:`MLS.pair_cuts
        #: <dolfinx_meshfree.MLS.pair_cuts>` (``sides`` is ``None``), e.g. the bodies' cut of
        #: :mod:`~dolfinx_meshfree.approx.body_cuts`; with any, the numpy path tabulates (the
        #: compiled kernel fuses the search). Call :meth:`changed` after changing the list.
        self.pair_cuts: list = []
        if smoothing_length is None:
            d, _ = self._tree.query(self.points, k=2)
            smoothing_length = 1.3 * float(np.mean(d[:, 1]))
        if not (np.isfinite(smoothing_length) and smoothing_length > 0):
            raise ValueError(f"smoothing_length={smoothing_length} must be positive")
        self.h = float(smoothing_length)

    #: Changes whenever the shape functions do (see :meth:`changed`).
    version: int = 0

    def changed(self) -> None:
        """Mark the shape functions changed: the version increments (see
        :class:`~dolfinx_meshfree.approx.tables.Approximation`)."""
        self.version += 1
        self._cells = None

    def tabulate(self, x: npt.ArrayLike, derivatives: int = 1) -> ShapeTable:
        """Shape functions and first derivatives at ``x`` (m, gdim); local, no communication."""
        x = check_points(x, self.gdim, "x")
        if self.backend == "numba" and not self.pair_cuts:
            return self._tabulate_compiled(x, derivatives)
        m, n = x.shape[0], self.points.shape[0]
        radii = np.full(n, 2.0 * self.h)
        i, j, dx = pairs_within_support(x, self.points, radii, self._tree)
        dist = np.linalg.norm(dx, axis=1)
        if self.pair_cuts:  # (ddist: the kernel takes the direction from dx)
            ddist = np.zeros_like(dx)
            i, j, dx, dist, _ = cut_pairs(self.pair_cuts, x, i, j, dx, dist, ddist, None)
        self._check_counts(np.bincount(i, minlength=m), x)
        W, dWdq = sph_cubic_spline(dist / self.h, self.h, self.gdim)
        vol = self.volumes[j]
        N = vol * W
        if self.correction == "shepard":
            N = N / np.bincount(i, weights=N, minlength=m)[i]
        values = sp.csr_matrix((N, (i, j)), shape=(m, n))
        grads: list[sp.csr_matrix] = []
        if derivatives:
            with np.errstate(invalid="ignore", divide="ignore"):
                unit = np.where(dist[:, None] > 0.0, dx / dist[:, None], 0.0)
            dN = vol[:, None] * (dWdq / self.h)[:, None] * unit  # (npairs, gdim)
            if self.correction in ("gradient", "shepard"):
                dN = self._corrected_gradient(i, j, N, dN, x, m)
            for k in range(self.gdim):
                grads.append(sp.csr_matrix((dN[:, k], (i, j)), shape=(m, n)))
        return ShapeTable(points=x, values=values, gradients=grads, version=self.version)

    def _check_counts(self, counts: np.ndarray, x: np.ndarray) -> None:
        """A point with no particle within ``2h``: ValueError."""
        empty = np.flatnonzero(counts == 0)
        if empty.size:
            q = int(empty[0])
            raise ValueError(
                f"SPH: {empty.size} point(s) have no particle within 2h={2 * self.h:.3g}; first: "
                f"point {q} at {x[q]}; increase smoothing_length or add particles"
            )

    def _check_singular(self, bad: np.ndarray, x: np.ndarray) -> None:
        """Points where the gradient correction is singular (``bad``: their indices): ValueError."""
        if bad.size:
            q = int(bad[0])
            raise ValueError(
                f"SPH gradient correction is singular at {bad.size} point(s); first: point {q} at "
                f"{x[q]}, whose neighbours are collinear or too few: increase smoothing_length"
            )

    def _tabulate_compiled(self, x: np.ndarray, derivatives: int) -> ShapeTable:
        """The compiled path: grouped cell-list candidates, a count pass, then the kernel
        (:func:`.sph_kernel.fill_sph`) into exactly sized CSR arrays."""
        m, n, g = x.shape[0], self.points.shape[0], self.gdim
        if self._cells is None:
            self._cells = CellList(self.points, np.full(n, 2.0 * self.h))
        x3 = np.zeros((m, 3))
        x3[:, :g] = x
        cand = self._cells.candidates(x3)
        counts = np.empty(m, np.int64)
        count_pairs(x3, cand, counts)
        self._check_counts(counts, x)
        indptr = np.zeros(m + 1, np.int64)
        np.cumsum(counts, out=indptr[1:])
        k = int(indptr[-1])
        j, N = np.empty(k, np.int32), np.empty(k)
        dN = np.empty((g if derivatives else 0, k))
        singular = np.zeros(m, bool)
        # the kernel's factor 3/2 sigma_d / h^d, from W(0) = factor * w(0) of the reference
        scale = float(sph_cubic_spline(np.zeros(1), self.h, g)[0][0]) / cubic_inner_piece(0.0)[0]
        correction = CORRECTION_IDS[self.correction]
        fill_sph(x3, cand, indptr, self.volumes, self.h, scale, g, correction, bool(derivatives),
                 j, N, dN, singular)  # fmt: skip
        self._check_singular(np.flatnonzero(singular), x)
        mats = [sp.csr_matrix((data, j.copy(), indptr.copy()), shape=(m, n)) for data in [N, *dN]]
        for a in mats:
            a.has_sorted_indices = True
        grads = mats[1:] if derivatives else []
        return ShapeTable(points=x, values=mats[0], gradients=grads, version=self.version)

    def _corrected_gradient(
        self, i: np.ndarray, j: np.ndarray, N: np.ndarray, dN: np.ndarray, x: np.ndarray, m: int
    ) -> np.ndarray:
        """Corrected kernel gradients, exact for constant and linear fields.

        ``G_J = M^-1 (grad N_J - S Nhat_J)`` with ``S = sum_K grad N_K``, the Shepard values
        ``Nhat_J = N_J / sum_K N_K``, their mean ``xbar = sum_J Nhat_J x_J`` and
        ``M = sum_J grad N_J (x) (x_J - xbar)``. Then ``sum_J G_J = 0`` and
        ``sum_J G_J (x) x_J = I`` (the Bonet & Lok 1999 correction written for a table).
        """
        gdim = self.gdim
        total = np.bincount(i, weights=N, minlength=m)
        Nhat = N / total[i]
        S = np.stack([np.bincount(i, weights=dN[:, a], minlength=m) for a in range(gdim)], 1)
        xbar = np.stack(
            [np.bincount(i, weights=Nhat * self.points[j, b], minlength=m) for b in range(gdim)], 1
        )
        rel = self.points[j] - xbar[i]
        M = np.empty((m, gdim, gdim))
        for a in range(gdim):
            for b in range(gdim):
                M[:, a, b] = np.bincount(i, weights=dN[:, a] * rel[:, b], minlength=m)
        scale = np.abs(M).max(axis=(1, 2))
        det = np.linalg.det(M)
        self._check_singular(np.flatnonzero(~(np.abs(det) > 1e-10 * scale**gdim)), x)
        Minv = batched.inv(M)
        return np.einsum("pab,pb->pa", Minv[i], dN - S[i] * Nhat[:, None])
