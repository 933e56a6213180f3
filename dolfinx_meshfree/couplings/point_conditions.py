"""Essential conditions at points of the particle patch: a ``DirichletBC`` that holds single
nodes of patch cells (a pinned corner, the usual FEniCSx way of removing the rigid motions of a
body loaded by tractions alone).

A node that no FE cell carries and no held exterior facet contains has no FE dof to hold: only
the particle field lives there. Its condition ``u_P(x_k)_i = ubar_i(x_k)`` is collocated at the
node by one multiplier per point and held component, the rows ``s w phi_J(x_k)`` beside the
facet multipliers' ``s int_f phi_J`` (:func:`~dolfinx_meshfree.statics.efg.facet_multipliers`;
the constraint term ``lambda^T g`` with the gap taken at points of Rabczuk et al. 2006, sec. 5.4,
eq. 98-99, here for an essential condition).
``s w`` only scales the rows (``s``: the material's modulus, ``w``: the particle spacing, a
length as a facet's measure); the multiplier is the point force the condition carries.

Each row needs particles of its own: two held points closer than one particle spacing can make
the rows dependent (more points than particles about them) and are refused, naming them
(:func:`check_point_spacing`). A held node on a held exterior facet of the patch keeps the facet
multiplier, and a node of an FE cell is held strongly, as before; with the ramps a node of the
interface is also held as a point (their field there is the particles', ``R = 1``). The nodes of
a held stretch of fewer facets than dimensions are points too (its facet multipliers hold its
mean only): :func:`~dolfinx_meshfree.statics.problem.short_stretches`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.quadrature import QuadraturePoints

if TYPE_CHECKING:  # annotations only
    from mpi4py import MPI

__all__ = ["PinRows", "PointCondition", "check_point_spacing", "pin_rows"]


@dataclass(frozen=True)
class PointCondition:
    """``u_P(x_k)_i = values[k, i]`` for ``i`` in ``components`` at this rank's ``points``.

    Attributes:
        points: (m, gdim) held nodes owned by this rank (m may be 0 on some ranks).
        values: (m, gdim) their values (the components not held are ignored).
        cells: (m,) a local patch cell of each point.
        components: The held components, e.g. ``(0, 1)``, or ``(1,)`` for ``V.sub(1)``.
        weight: The rows' length scale ``w`` (the particle spacing).
        nodes: (m,) the points' local node indices of the FE space (for reactions).
    """

    points: np.ndarray
    values: np.ndarray
    cells: np.ndarray
    components: tuple[int, ...]
    weight: float
    nodes: np.ndarray

    def rule(self) -> QuadraturePoints:
        """The points as a one-point "facet" rule each, weight ``w``: the entities are
        ``-1, -2, ...`` (one multiplier per point; negative, so that the 3D facet check of
        :func:`~dolfinx_meshfree.statics.efg.check_multiplier_facets` leaves them out)."""
        m = len(self.points)
        return QuadraturePoints(
            points=np.asarray(self.points, dtype=float),
            weights=np.full(m, float(self.weight)),
            cells=np.asarray(self.cells, dtype=np.int32),
            normals=None,
            entities=-1 - np.arange(m, dtype=np.int64),
        )

    def value(self, x: np.ndarray) -> np.ndarray:
        """The values at ``x``, which must be :attr:`points` (the rule's points, in order)."""
        if len(x) != len(self.points) or not np.array_equal(x, self.points):
            raise ValueError("PointCondition.value is evaluated at its own points only")
        return np.asarray(self.values, dtype=float)


def check_point_spacing(comm: MPI.Comm, points: np.ndarray, spacing: float) -> None:
    """Refuse held points of the particle field closer than one particle ``spacing`` to each
    other (collective; every rank raises, naming the pair by its coordinates)."""
    every = np.concatenate(comm.allgather(np.asarray(points, dtype=float)))
    if len(every) < 2:
        return
    pairs = cKDTree(every).query_pairs(spacing * (1.0 - 1e-9), output_type="ndarray")
    if len(pairs):
        a, b = every[pairs[0, 0]], every[pairs[0, 1]]
        raise ValueError(
            f"bcs hold {len(every)} node(s) of the particle patch at points (single nodes, or "
            "the nodes of a held stretch of fewer facets than dimensions, whose facet "
            "multipliers would leave it free to rotate), two of them "
            f"{np.linalg.norm(a - b):.6g} apart (at {np.round(a, 6).tolist()} and "
            f"{np.round(b, 6).tolist()}), closer than the particle spacing {spacing:.6g}: the "
            "particle field cannot be held at points that its particles do not separate. Hold "
            "points at least a spacing apart (a pinned corner, a roller point), a whole exterior "
            "facet, or leave these cells out of the patch"
        )


@dataclass(frozen=True)
class PinRows:
    """Where the pins' multipliers lie in the block of a model's patch conditions, and how each
    becomes a force: ``F = -s w (sum_J phi_J(x_k)) lambda`` per point and held component, the
    force the pin exerts on the body (the particle equations read ``K u + G^T lambda = f``).

    Attributes:
        rows: Per point condition, (m, len(components)) local rows of the block.
        factors: Per point condition, (m,) ``s w sum_J phi_J(x_k)``: a row's sum over the
            particle columns.
        components: Per point condition, its held components.
        gdim: The geometric dimension.
    """

    rows: list[np.ndarray]
    factors: list[np.ndarray]
    components: list[tuple[int, ...]]
    gdim: int

    def forces(self, multipliers: np.ndarray) -> list[np.ndarray]:
        """Per point condition, (m, gdim) forces on the body at its points (0 in the
        components not held) from the block's local multipliers."""
        out = []
        for rows, factor, comps in zip(self.rows, self.factors, self.components, strict=True):
            f = np.zeros((len(factor), self.gdim))
            f[:, list(comps)] = -factor[:, None] * np.asarray(multipliers)[rows]
            out.append(f)
        return out


def pin_rows(
    conditions: list, quadratures: list[QuadraturePoints], tables: list, scale: float, gdim: int
) -> PinRows:
    """The :class:`PinRows` of the point conditions among a model's patch conditions (the
    rules without normals), numbered as
    :func:`~dolfinx_meshfree.statics.efg.facet_multipliers` numbers its rows (local)."""
    rows, factors, comps, offset = [], [], [], 0
    for cond, d, tab in zip(conditions, quadratures, tables, strict=True):
        cs = tuple(cond[2]) if len(cond) > 2 else tuple(range(gdim))
        entities, facet_id = np.unique(d.entities, return_inverse=True)
        if d.normals is None:  # a point condition: one "facet" per point
            rows.append(offset + len(cs) * facet_id[:, None] + np.arange(len(cs))[None, :])
            sums = np.asarray(tab.values.sum(axis=1)).ravel()
            factors.append(scale * d.weights * sums)
            comps.append(cs)
        offset += len(cs) * entities.size
    return PinRows(rows, factors, comps, gdim)
