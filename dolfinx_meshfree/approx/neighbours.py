"""Neighbour search between evaluation points and particles with per-particle support radii."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

__all__ = ["check_points", "pairs_within_support", "support_radii"]


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


def support_radii(points: np.ndarray, dilation: float, num_neighbours: int) -> np.ndarray:
    """Support radii ``d_mI = d_max * c_I`` (Belytschko et al. 1995, eq. 3.11).

    ``c_I`` is the distance from particle ``I`` to its ``num_neighbours``-th nearest other particle,
    i.e. the radius that holds enough neighbours to satisfy the basis; on a regular grid and a
    linear basis it is the grid spacing, as in the paper.
    """
    n = points.shape[0]
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
