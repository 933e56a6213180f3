"""Points on the faces of a crack: sampled along its polyline, and those each rank owns.

The face machinery shared by crack-face contact in explicit dynamics
(:mod:`~dolfinx_meshfree.dynamics.crack_contact`) and cohesive cracks in statics
(:mod:`~dolfinx_meshfree.statics.cohesive`): Gauss–Legendre points on pieces of at most one
particle spacing, their unit left normals and length weights, and the points whose integration
cell this rank owns.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from .. import _compat

if TYPE_CHECKING:  # annotations only
    from .crack import Crack
    from .particles import ParticleSet

__all__ = ["contact_points", "owned_points"]


def contact_points(
    crack: Crack,
    h: float,
    points: int = 2,
    tip_gap: float = 0.0,
    segments: Sequence[int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample points along a crack polyline (the same on every rank: no communication).

    Each segment (of ``segments``, by index; ``None``: all) is cut into ``ceil(length / h)``
    equal pieces, each with ``points`` Gauss–Legendre points; points within ``tip_gap * h`` of a
    tip are dropped.

    Returns:
        ``(x, n, w)``: points (m, 2), unit left normals (m, 2) (towards the ``+1`` side of
        :meth:`Crack.side`) and length weights (m,).
    """
    xi, wi = np.polynomial.legendre.leggauss(points)
    xi, wi = 0.5 * (xi + 1.0), 0.5 * wi
    xs, ns, ws = [], [], []
    for k, (a, b) in enumerate(zip(*crack.segments, strict=True)):
        if segments is not None and k not in segments:
            continue
        t = b - a
        length = float(np.linalg.norm(t))
        pieces = max(1, int(np.ceil(length / h - 1e-9)))
        s = ((np.arange(pieces)[:, None] + xi[None, :]) / pieces).ravel()
        xs.append(a[None, :] + s[:, None] * t[None, :])
        ns.append(np.tile(np.array([-t[1], t[0]]) / length, (s.size, 1)))
        ws.append(np.tile(wi * length / pieces, pieces))
    if not xs:  # no segment carries points (a cohesive record whose faces are still to come)
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    x, n, w = np.concatenate(xs), np.concatenate(ns), np.concatenate(ws)
    keep = np.ones(len(x), dtype=bool)
    for tip in crack.tips:
        keep &= np.linalg.norm(x - tip[None, :], axis=1) >= tip_gap * h
    return x[keep], n[keep], w[keep]


def owned_points(particles: ParticleSet, x: np.ndarray) -> np.ndarray:
    """bool (m,): the points ``x`` this rank owns: in one of its integration cells, a point
    on a cell boundary shared by ranks going to the lowest rank (collective)."""
    msh = particles.mesh
    comm = particles.comm
    cells = particles.integration_cells()
    imap = msh.topology.index_map(msh.topology.dim)
    mine = np.zeros(imap.size_local + imap.num_ghosts, dtype=bool)
    mine[cells] = True
    p3 = np.zeros((len(x), 3))
    p3[:, :2] = x
    offsets, arr = _compat.colliding_cells(msh, _compat.bb_tree(msh, msh.topology.dim), p3)
    hit = np.zeros(len(x), dtype=bool)
    np.logical_or.at(hit, np.repeat(np.arange(len(x)), np.diff(offsets)), mine[arr])
    size = comm.size
    claim = np.where(hit, comm.rank, size).astype(np.int32)
    owner = np.empty_like(claim)
    comm.Allreduce(claim, owner, op=MPI.MIN)
    return owner == comm.rank
