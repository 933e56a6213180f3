"""A law's state carried to the quadrature of a model rebuilt on a longer crack (issue 24,
item 1: the state is "carried over when a crack ... changes the quadrature (say how)").

How. A cohesive crack that grows (:class:`~dolfinx_meshfree.CohesiveGrowth`) changes the rule of
the cells it newly cuts (sub-cells on each side: :mod:`~dolfinx_meshfree.geometry.cut_cells`),
and of no other cell. So:

* a new point that lies where an old point of its cell lay (within ``1e-9`` spacing) takes that
  point's committed state, copied exactly: every point of an unchanged cell, every FE point;
* a point of a changed cell takes the committed state of the nearest old point *of its own
  cell* that the cracks do not separate from it (:meth:`~dolfinx_meshfree.Crack.crosses`):
  the state of the material on its side. Where no old point of the cell lies on its side (a
  sliver the old rule had no point in), it takes the nearest old point's of the cell, and is
  counted (``crossed``).

This is the closest-point transfer of Perić, Hochard, Dutko & Owen (1996, CMAME 137, 331-344,
sec. 3). Whole states are copied, never averaged: a copied state is one the law reached, so a
plastic state stays on its yield surface and a damage is never below its history's (an average
of two plastic states need not be admissible). The cell, and not the nearest point anywhere,
keeps the result independent of the partition (a cell's points are on its owner's rank).

What it does not conserve: the dissipated energy integrated over a changed cell, whose weights
move between sides. :func:`~dolfinx_meshfree.follow_path` records the bulk's dissipated energy
before and after every rebuild (:attr:`~dolfinx_meshfree.statics.path_following.PathResult.
carried`); the difference is what the transfer changed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

if TYPE_CHECKING:  # annotations only
    from collections.abc import Sequence

    from mpi4py import MPI

    from ..geometry.crack import Crack
    from ..physics.state import PointState

__all__ = ["CarryCounts", "carry_at_points", "carry_pooled", "carry_states"]

#: A new point within this many particle spacings of an old point of its cell is the same point.
SAME_POINT = 1e-9


@dataclass
class CarryCounts:
    """What :func:`carry_states` did on this rank: points whose state was copied from the same
    position, points of changed cells given their cell's nearest old point on their side, and
    those of them that had none on their side (given the nearest across a crack)."""

    copied: int = 0
    moved: int = 0
    crossed: int = 0

    def __iadd__(self, other: CarryCounts) -> CarryCounts:
        self.copied += other.copied
        self.moved += other.moved
        self.crossed += other.crossed
        return self


def _carry(old: PointState, new: PointState, cracks: Sequence[Crack], h: float) -> CarryCounts:
    """Set ``new.committed`` from ``old.committed`` (module docstring); local."""
    if old.cells is None or new.cells is None:
        raise RuntimeError("a state carried to a changed quadrature needs the points' cells")
    counts = CarryCounts()
    m = len(new)
    source = np.full(m, -1, dtype=np.int64)
    if len(old) and m:
        dist, k = cKDTree(old.points).query(new.points)
        same = (dist <= SAME_POINT * h) & (old.cells[k] == new.cells)
        source[same] = k[same]
        counts.copied = int(same.sum())
    rest = np.flatnonzero(source < 0)
    if rest.size:
        order = np.argsort(old.cells, kind="stable")
        sorted_cells = old.cells[order]
        for c in np.unique(new.cells[rest]):
            mine = rest[new.cells[rest] == c]
            lo, hi = np.searchsorted(sorted_cells, [c, c + 1])
            pool = order[lo:hi]
            if pool.size == 0:
                x = new.points[mine[0]]
                raise RuntimeError(
                    f"no state to carry to the point ({', '.join(f'{v:.6g}' for v in x)}): its "
                    "cell had no points with state before"
                )
            # the cell's new points against its old ones at once: the nearest old point each
            # that no crack separates from it, else the nearest (ties to the first in ``pool``)
            x, y = new.points[mine], old.points[pool]
            d = np.linalg.norm(y[None, :, :] - x[:, None, :], axis=2)  # (mine, pool)
            apart = np.zeros(d.shape, dtype=bool)
            if cracks:
                p, q = np.repeat(x, pool.size, axis=0), np.tile(y, (mine.size, 1))
                for crack in cracks:
                    apart |= crack.crosses(p, q).reshape(d.shape)
            alone = apart.all(axis=1)  # no old point of the cell on its side
            nearest = np.argmin(np.where(apart, np.inf, d), axis=1)
            nearest[alone] = np.argmin(d[alone], axis=1)
            source[mine] = pool[nearest]
            counts.crossed += int(alone.sum())
        counts.moved = int(rest.size)
    for key, value in old.committed.items():
        new.committed[key] = value[source].copy()
    new.restore()
    return counts


def carry_states(
    old: Sequence[PointState], new: Sequence[PointState], cracks: Sequence[Crack], h: float
) -> CarryCounts:
    """Give each state of ``new`` (a rebuilt model's, in the order of ``old``: the same sides)
    the committed state of ``old`` at its points (module docstring), and drop its trial state.
    Local (each rank its own points); ``h`` is the particle spacing, ``cracks`` the model's
    cracks after the change. Returns this rank's counts."""
    if len(old) != len(new):
        raise RuntimeError(
            f"the rebuilt model has {len(new)} sets of points with state, the old one {len(old)}"
        )
    counts = CarryCounts()
    for a, b in zip(old, new, strict=True):
        if a.law is not b.law:
            raise RuntimeError("a state is carried between points of the same law only")
        counts += _carry(a, b, cracks, h)
    return counts


@dataclass
class _Pool:
    """The points with state of several sides as one set (:func:`carry_pooled`)."""

    law: object
    points: np.ndarray
    cells: np.ndarray | None
    committed: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.points)


def carry_pooled(
    old: Sequence[PointState], new: Sequence[PointState], cracks: Sequence[Crack], h: float
) -> CarryCounts:
    """As :func:`carry_states`, each new point drawing from the points of every old side: the
    model rebuilt on a grown patch, whose converted cells' particle points take the states of
    the FE points of their cells (the cells are the mesh's, the same on both sides). Every side
    must have the same law. Local; returns this rank's counts."""
    laws = {id(s.law) for s in (*old, *new)}
    if len(laws) > 1:
        raise RuntimeError("states are carried between points of one law only")
    if not old:
        raise RuntimeError("the old model has no points with state to carry")
    cells = [s.cells for s in old]
    if any(c is None for c in cells):
        raise RuntimeError("a state carried to a changed quadrature needs the points' cells")
    pool = _Pool(
        old[0].law,
        np.concatenate([s.points for s in old]),
        np.concatenate(cells),
        {k: np.concatenate([s.committed[k] for s in old]) for k in old[0].committed},
    )
    counts = CarryCounts()
    for b in new:
        counts += _carry(pool, b, cracks, h)
    return counts


def carry_at_points(old: PointState, new: PointState, comm: MPI.Comm, tol: float) -> None:
    """Give each point of ``new`` that lies within ``tol`` of a point of ``old`` (gathered over
    the ranks) that point's committed state, and drop ``new``'s trial state (collective). The
    faces of a crack rebuilt on more segments, or on a grown patch: their old points keep their
    positions, the new ones keep their initial state."""
    pts = np.concatenate(comm.allgather(old.points))
    fields = {k: np.concatenate(comm.allgather(v)) for k, v in old.committed.items()}
    if len(new) and len(pts):
        dist, k = cKDTree(pts).query(new.points)
        same = dist <= tol
        for key, values in fields.items():
            new.committed[key][same] = values[k[same]]
    new.restore()
