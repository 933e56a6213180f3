"""Neighbour search between evaluation points and particles with per-particle support radii."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from .kernels import WeightFunction, quartic

__all__ = ["check_points", "cut_pairs", "pairs_within_support", "support_radii"]


def check_points(x: npt.ArrayLike, gdim: int, name: str = "x") -> np.ndarray:
    """Validate an (m, gdim) array of finite coordinates; (m, 3) with a zero z is accepted too."""
    a = np.asarray(x, dtype=float)
    if a.ndim == 1 and a.size == gdim:
        a = a.reshape(1, gdim)
    if a.ndim != 2 or a.shape[1] not in (gdim, 3):
        raise ValueError(f"{name} should have shape (num_points, {gdim}), got {a.shape}")
    if a.shape[1] == 3 and gdim < 3:
        if a.size and np.any(a[:, gdim:] != 0.0):
            raise ValueError(f"{name} has non-zero coordinates beyond gdim={gdim}")
        a = a[:, :gdim]
    bad = ~np.isfinite(a).all(axis=1)
    if np.any(bad):
        idx = np.flatnonzero(bad)
        raise ValueError(
            f"{name} has {idx.size} point(s) with NaN or infinite coordinates, first at row "
            f"{idx[0]}: {a[idx[0]]}; remove or fix them"
        )
    return np.ascontiguousarray(a)


#: Smallest eigenvalue of the weighted directions ``sum_J w(r_J) / w(1 / d_max) n_J n_J^T`` of
#: the neighbours within a particle's support (unit vectors ``n_J``; the weights relative to
#: the weight at the nodal spacing ``c_I``, ``r = 1 / d_max``) for the neighbours to count as
#: spread in every direction (see :func:`support_radii`): about a third of one neighbour
#: straight across at the nodal spacing. At dilation 2 (quartic weight) a regular 2D grid gives
#: 2.5 inside, 1.25 on its border and 1.0 at a corner, a 3D grid 3.0 inside; a row of
#: particles whose supports reach the next row only with the weight's tail about 3e-3.
SPREAD = 0.3

#: Neighbour distances per batch of :func:`support_radii` (points x neighbours; some 100 MB).
_BATCH = 4_000_000


def _smallest_eigenvalue(s: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of symmetric (..., g, g) matrices, g = 1, 2 or 3."""
    if s.shape[-1] == 1:
        return s[..., 0, 0]
    if s.shape[-1] == 2:
        half = 0.5 * (s[..., 0, 0] + s[..., 1, 1])
        return half - np.hypot(0.5 * (s[..., 0, 0] - s[..., 1, 1]), s[..., 0, 1])
    return np.linalg.eigvalsh(s)[..., 0]


def _spread_radii(
    points: np.ndarray,
    tree: cKDTree,
    rows: np.ndarray,
    k: int,
    num_neighbours: int,
    c: np.ndarray,
    dilation: float,
    weight: WeightFunction,
    w0: float,
) -> np.ndarray:
    """Set ``c[rows]`` to the first spread candidate among the ``k`` nearest neighbours (see
    :func:`support_radii`), candidate by candidate for the rows still open; returns the rows
    (a mask of ``rows``) that need more neighbours."""
    n, gdim = points.shape
    d, idx = tree.query(points[rows], k=k + 1)
    d, idx = d[:, 1:], idx[:, 1:]  # the particle itself first
    unit = (points[idx] - points[rows, None, :]) / d[..., None]
    outer = np.einsum("mki,mkj->mkij", unit, unit).reshape(rows.size, k, gdim * gdim)
    after = np.append(d[:, 1:], np.full((d.shape[0], 1), np.inf), axis=1)
    open_ = np.ones(rows.size, dtype=bool)
    more = np.zeros(rows.size, dtype=bool)
    for j in range(num_neighbours - 1, k):
        o = np.flatnonzero(open_)
        if o.size == 0:
            break
        reach = dilation * d[o, j]
        known = (d[o, -1] >= reach) | (k == n - 1)  # every neighbour in the support listed
        more[o[~known]] = True
        open_[o[~known]] = False
        o, reach = o[known], reach[known]
        if j < k - 1 or k == n - 1:
            tie_end = after[o, j] > d[o, j] * (1.0 + 1e-10)
        else:
            tie_end = np.zeros(o.size, dtype=bool)  # a tie may go on past the k-th neighbour
        inside = int((d[o] < reach[:, None]).sum(axis=1).max(initial=0))
        w = weight(d[o, :inside] / reach[:, None])[0] / w0
        s = np.einsum("mk,mkp->mp", w, outer[o, :inside]).reshape(o.size, gdim, gdim)
        done = o[tie_end & (_smallest_eigenvalue(s) >= SPREAD)]
        c[rows[done]] = d[done, j]
        open_[done] = False
    more |= open_ & (k < n - 1)
    return more


def support_radii(
    points: np.ndarray,
    dilation: float,
    num_neighbours: int,
    weight: WeightFunction = quartic,
) -> np.ndarray:
    """Support radii ``d_mI = d_max * c_I`` (Belytschko et al. 1995, eq. 3.11).

    ``c_I`` is the distance from particle ``I`` to its ``num_neighbours``-th nearest other
    particle, the radius that holds enough neighbours for the basis (on a regular grid and a
    linear basis, the grid spacing, as in the paper), or farther: the smallest such neighbour
    distance at which the neighbours within the support ``d_max c_I`` are spread in every
    direction, with weights:
    ``lambda_min(sum_J w(|x_J - x_I| / d_mI) / w(1 / d_max) n_J n_J^T) >= SPREAD``
    (:data:`SPREAD`; ``n_J`` the unit vector to ``J``, ``w`` the MLS weight). The weights are
    relative to the weight at the nodal spacing, so that a small dilation keeps its meaning
    (supports just past the nearest neighbours, refused by the MLS where too small).

    The spread condition matters where the particles lie in rows much closer than the rows are
    apart (the vertices of stretched cells, e.g. a mapped mesh around a hole, aspect ratio 4):
    the nearest neighbours are then all in the particle's own row, and the supports reached
    the next row only with the weight's tail, an ill-conditioned moment matrix that passed
    ``rcond`` and gave 12-18x the FE error on the Kirsch plate (1.2x with the condition). On a
    regular grid, and on the 2D boundary-conforming placement, no radius changes (in 3D, some
    border particles of the conforming placement at 0.5 h: 106 of 603, by at most 1.26x).
    Ties in distance are decided together (the condition is tested after the last of equally
    distant neighbours), so the radii do not depend on the order of the points. Where no
    neighbourhood is spread (all particles on a line), ``c_I`` is the distance to the
    ``num_neighbours``-th neighbour.
    """
    n, gdim = points.shape
    if n <= num_neighbours:
        raise ValueError(
            f"{n} particle(s) cannot support a basis that needs {num_neighbours + 1}; "
            "add particles or lower the basis order"
        )
    tree = cKDTree(points)
    dist, _ = tree.query(points, k=num_neighbours + 1)
    c = dist[:, -1]
    if np.any(c <= 0.0):
        i = int(np.flatnonzero(c <= 0.0)[0])
        raise ValueError(
            f"particle {i} at {points[i]} coincides with {num_neighbours} others; remove duplicates"
        )
    w0 = float(weight(np.array([1.0 / dilation]))[0][0])  # the weight at the nodal spacing
    todo = np.arange(n)
    k = min(n - 1, int(np.ceil(1.5 * num_neighbours * dilation**gdim)))
    while todo.size:
        batch = max(1, _BATCH // k)
        retry = [
            rows[_spread_radii(points, tree, rows, k, num_neighbours, c, dilation, weight, w0)]
            for rows in (todo[lo : lo + batch] for lo in range(0, todo.size, batch))
        ]
        todo = np.concatenate(retry)
        if k == n - 1:
            break  # no spread neighbourhood (all on a line): eq. 3.11's distance stays
        k = min(n - 1, 4 * k)
    return dilation * c


def pairs_within_support(
    x: np.ndarray, particles: np.ndarray, radii: np.ndarray, tree: cKDTree | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All (point, particle) pairs with ``|x - x_I| < d_I`` (in no particular order).

    Returns:
        ``(i, j, dx)``: point indices, particle indices and ``x_i - x_j`` (npairs, gdim).
    """
    if tree is None:
        tree = cKDTree(particles)
    rmax = float(radii.max())
    if x.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, x.shape[1]))
    sdm = cKDTree(x).sparse_distance_matrix(tree, rmax, output_type="ndarray")
    i = sdm["i"].astype(np.int64)
    j = sdm["j"].astype(np.int64)
    keep = sdm["v"] < radii[j]
    i, j = i[keep], j[keep]
    return i, j, x[i] - particles[j]


def cut_pairs(
    cuts: list, x: np.ndarray, i: np.ndarray, j: np.ndarray, dx: np.ndarray, dist: np.ndarray,
    ddist: np.ndarray, sides: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The (point, particle) pairs after the pair ``cuts`` in turn (``cut(x, i, j, dx, dist,
    ddist, sides) -> (i, j, dx, dist, ddist)``: :attr:`~dolfinx_meshfree.MLS.pair_cuts`), put
    back in the order by point then particle if a cut reordered them."""
    for cut in cuts:
        i, j, dx, dist, ddist = cut(x, i, j, dx, dist, ddist, sides)
    if np.any(np.diff(i) < 0):
        o = np.lexsort((j, i))
        i, j, dx, dist, ddist = i[o], j[o], dx[o], dist[o], ddist[o]
    return i, j, dx, dist, ddist
