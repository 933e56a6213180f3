"""Multipliers of essential conditions on groups of facets, not one per facet.

The essential condition ``u = ubar`` on exterior facets of a particle patch is enforced by
piecewise-constant Lagrange multipliers (Belytschko, Lu & Gu 1994, with the multiplier field
constant on pieces of the boundary): ``int_g lambda . (u^h - ubar) = 0`` for every piece ``g``.
One multiplier per facet and component (:func:`~dolfinx_meshfree.statics.efg.facet_multipliers` on
the
facets themselves) is only well posed while the particles are denser than the facets. When the
particle spacing is about the element size or larger, the facets' multipliers outnumber the
particles that the boundary sees: the constraint block ``G`` (``int_f phi_J``) loses rank and the
saddle-point system is singular (measured: the hybrid SPH–FE coupling on the gmsh square, patch
``x > 1``, spacing 1.5 h: 52 multipliers on 64 particle dofs, rank 48, condition number 4e18 and
an L2 error 3,700 x the plain FE error; on a regular mesh at spacing h the block has full rank
but locks the particles, 120 x FE). Like the inf-sup condition of mortar methods, the multiplier
space must be coarser than the trace of the primal one.

:func:`grouped_facet_quadrature` cuts the Dirichlet boundary into pieces of at least a given
length (two particle spacings by default in :class:`~dolfinx_meshfree.HybridElasticity`): the
facets are joined into chains (along shared vertices, corners included), and each chain of
length ``L`` into ``max(1, floor(L / length))`` pieces of equal length, a facet going to the piece
that holds its midpoint. The pieces are found from the facets' coordinates gathered on every
rank, so they do not depend on the partition: serial and parallel runs impose the same
conditions. :func:`constraint_rank_check` is the safety net: it refuses a constraint block whose
rows are (nearly) dependent instead of returning the garbage of a singular solve.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from .. import _compat
from .quadrature import QuadraturePoints

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = ["FacetGroups", "constraint_rank_check", "grouped_facet_quadrature"]

#: Relative singular value of the (row-normalised) constraint block below which its rows count
#: as dependent.
RANK_TOLERANCE = 1e-8


class FacetGroups:
    """Pieces of a boundary made of facets, the same on every rank.

    Attributes:
        ends: (nf, 2, gdim) end points of every facet (all ranks), in a partition-independent
            order. group: (nf,) the piece of each facet. owner: (nf,) the rank that gave the
            facet. num_groups: number of pieces. group_owner: (num_groups,) the rank that
            assembles each piece's multipliers (the owner of its first facet).
    """

    def __init__(self, ends: np.ndarray, group: np.ndarray, owner: np.ndarray) -> None:
        self.ends, self.group, self.owner = ends, group, owner
        self.num_groups = int(group.max()) + 1 if group.size else 0
        first = np.full(self.num_groups, np.iinfo(np.int64).max, dtype=np.int64)
        np.minimum.at(first, group, np.arange(group.size))
        self.group_owner = owner[first] if group.size else np.zeros(0, np.int64)

    def quadrature(self, degree: int, rank: int | None = None) -> QuadraturePoints:
        """Gauss–Legendre points of the facets (of the pieces that ``rank`` assembles, or of all
        pieces with ``rank=None``); ``entities`` is the piece of each point."""
        sel = np.arange(self.group.size)
        if rank is not None:
            sel = sel[self.group_owner[self.group] == rank]
        npts = max(1, (degree + 2) // 2)
        s, ws = np.polynomial.legendre.leggauss(npts)
        s, ws = 0.5 * (s + 1.0), 0.5 * ws
        a, b = self.ends[sel, 0], self.ends[sel, 1]
        length = np.linalg.norm(b - a, axis=1)
        x = a[:, None, :] + s[None, :, None] * (b - a)[:, None, :]
        gdim = self.ends.shape[2]
        return QuadraturePoints(
            points=x.reshape(-1, gdim),
            weights=(length[:, None] * ws[None, :]).ravel(),
            cells=np.full(sel.size * npts, -1, dtype=np.int64),
            entities=np.repeat(self.group[sel], npts),
        )


def _chains(ends: np.ndarray) -> list[np.ndarray]:
    """Facets (given by their end points, in a fixed order) joined into chains along shared
    vertices: each chain starts at a free end (the lexicographically smallest) or, for closed
    loops, at the smallest vertex, and takes the first unused facet at each vertex."""
    gdim = ends.shape[2]
    _, vid = np.unique(ends.reshape(-1, gdim), axis=0, return_inverse=True)
    vid = vid.reshape(-1, 2)
    nv = int(vid.max()) + 1 if vid.size else 0
    at: list[list[int]] = [[] for _ in range(nv)]
    for f, (a, b) in enumerate(vid):
        at[a].append(f)
        at[b].append(f)
    used = np.zeros(vid.shape[0], dtype=bool)
    chains = []
    while not used.all():
        left = np.zeros(nv, dtype=np.int64)
        np.add.at(left, vid[~used].ravel(), 1)
        odd = np.flatnonzero(left % 2 == 1)
        # unique() sorted the vertices lexicographically: the smallest index is the smallest point
        start = int(odd[0]) if odd.size else int(np.flatnonzero(left > 0)[0])
        chain, v = [], start
        while True:
            nxt = [f for f in at[v] if not used[f]]
            if not nxt:
                break
            f = nxt[0]
            used[f] = True
            chain.append(f)
            v = int(vid[f, 1] if vid[f, 0] == v else vid[f, 0])
        chains.append(np.asarray(chain, dtype=np.int64))
    return chains


def grouped_facet_quadrature(
    msh: dolfinx.mesh.Mesh, facets: np.ndarray, length: float
) -> FacetGroups:
    """Pieces of at least ``length`` (if a chain is that long) of the given facets (collective).

    Args:
        msh: Degree-1 2D mesh.
        facets: This rank's facets (local indices; each facet given by one rank only).
        length: Minimum length of a piece (a chain shorter than this is one piece); 0: one
            piece per facet.

    Returns:
        :class:`FacetGroups`, identical on every rank and independent of the partition.
    """
    comm = msh.comm
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    facets = np.asarray(facets, dtype=np.int32)
    if facets.size:
        local = msh.geometry.x[_compat.entities_to_geometry(msh, tdim - 1, facets), :gdim]
    else:
        local = np.zeros((0, 2, gdim))
    parts = comm.allgather(local)
    ends = np.concatenate(parts).reshape(-1, 2, gdim)
    owner = np.concatenate([np.full(p.shape[0], r, dtype=np.int64) for r, p in enumerate(parts)])
    # a partition-independent order: each facet's ends sorted, then the facets by their ends
    a, b = ends[:, 0], ends[:, 1]
    swap = (a[:, 0] > b[:, 0]) | ((a[:, 0] == b[:, 0]) & (a[:, 1] > b[:, 1]))
    ends = np.where(swap[:, None, None], ends[:, ::-1], ends)
    order = np.lexsort((ends[:, 1, 1], ends[:, 1, 0], ends[:, 0, 1], ends[:, 0, 0]))
    ends, owner = ends[order], owner[order]
    group = np.zeros(ends.shape[0], dtype=np.int64)
    flen = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    next_group = 0
    for chain in _chains(ends) if length > 0 else []:
        total = float(flen[chain].sum())
        pieces = max(1, int(np.floor(total / length + 1e-9)))
        mid = np.cumsum(flen[chain]) - 0.5 * flen[chain]
        group[chain] = next_group + np.minimum(pieces - 1, (mid / (total / pieces)).astype(int))
        next_group += pieces
    if length <= 0:  # one piece per facet
        group = np.arange(ends.shape[0], dtype=np.int64)
    # renumber the pieces that hold a facet (a piece may be empty on a chain of few long facets)
    _, group = np.unique(group, return_inverse=True)
    return FacetGroups(ends, group.reshape(-1), owner)


def constraint_rank_check(rows: sp.csr_matrix, where: np.ndarray, what: str) -> None:
    """Raise ``ValueError`` if the constraint rows ``rows`` (one per piece, over the particles;
    the same on every rank) are (nearly) linearly dependent: the smallest singular value of the
    row-normalised block below :data:`RANK_TOLERANCE` of the largest. ``where`` (pieces, gdim)
    names a point of each piece for the message."""
    if rows.shape[0] == 0:
        return
    dense = rows.toarray()
    norm = np.linalg.norm(dense, axis=1)
    if np.any(norm == 0.0):
        k = int(np.flatnonzero(norm == 0.0)[0])
        raise ValueError(
            f"{what}: the boundary piece at {where[k]} sees no particle; add particles near it "
            "(a finer spacing or placement='vertices')"
        )
    u, s, _ = np.linalg.svd(dense / norm[:, None], full_matrices=False)
    if s[-1] < RANK_TOLERANCE * s[0]:
        k = int(np.argmax(np.abs(u[:, -1])))
        raise ValueError(
            f"{what}: the multipliers of the essential condition are linearly dependent "
            f"(smallest relative singular value {s[-1] / s[0]:.1e}), near {where[k]}: too few "
            "particles for the boundary pieces; use longer pieces (multiplier_length) or a "
            "finer particle spacing"
        )
