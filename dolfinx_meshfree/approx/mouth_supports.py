"""Particle supports widened at a crack's mouth, where the crack meets the exterior boundary at
a sharp angle.

Belytschko et al. (1995) size each support by eq. (3.11), ``d_mI = d_max c_I``, with ``c_I``
"determined by searching for enough adjacent nodes to satisfy the basis", and cut the weights
"across boundaries" (eq. 3.10). A crack is such a boundary. Where it leaves the body, the crack
and the exterior boundary enclose a wedge of material on each side. Diffraction bends the
weights round a tip, but nothing bends them round a mouth, so a point in a narrow wedge sees
only the particles inside it. With the crack meeting the boundary at less than about 45 degrees,
points near the mouth saw two particles on the boundary's line, a singular moment matrix, and
the model was refused (a user's random inclined edge cracks: 3 of 12 draws, at 48 to 58 degrees
from the edge's normal).

:func:`widen_at_mouths` redoes the search of eq. (3.11) there, with the crack as a boundary. It
looks at the mouths where the crack meets the boundary at less than :data:`WEDGE_MAX` degrees,
samples points about each inside the particles' region (a polar grid, :data:`SAMPLE_RADII`
spacings by :data:`SAMPLE_ANGLES` directions) and reads their moment matrices under the cut
(:meth:`~dolfinx_meshfree.MLS.support_quality`). A mouth where a sample sees fewer particles
than the basis needs, or has an eigenvalue ratio below :data:`TRIGGER`, is widened: while a
sample falls short of that count or of :data:`RATIO_MIN`, the worst such sample widens one
support a round (at most :data:`MAX_ROUNDS`): that of a particle it can see (a straight line
crossing no crack and no part of the boundary) whose support does not yet reach it at
:data:`REACH` of its radius, the nearest whose widening lifts the sample's ratio to
:data:`FIXED` times :data:`RATIO_MIN`, else the one that lifts it most. A mouth whose samples
all stay above :data:`TRIGGER`, and a right-angled one (even with the crack a hair off a
particle row, a case of :class:`~dolfinx_meshfree.geometry.crack.CrackPlacementWarning`),
change nothing, to the bit; the widened supports change the shape functions within their reach
of the mouth only.

Every rank holds every particle and the gathered boundary, so each rank makes the same choice.
The record of what changed is :attr:`MLS.widened <dolfinx_meshfree.MLS.widened>`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..geometry.crack import (
    Crack,
    gathered_segments,
    particle_spacing,
    point_segment_distance,
    segments_intersect,
)
from .mls import MLS, polynomial_basis

if TYPE_CHECKING:  # annotations only
    from ..geometry.crack import CrackDomain
    from ..geometry.patch import ParticlePatch

__all__ = [
    "FIXED",
    "MAX_ROUNDS",
    "RATIO_MIN",
    "REACH",
    "SAMPLE_ANGLES",
    "SAMPLE_RADII",
    "TRIGGER",
    "WEDGE_MAX",
    "WidenedSupports",
    "inside_polygons",
    "mouth_points",
    "wedge_angle",
    "widen_at_mouths",
]

#: Distances of the samples from a mouth, in particle spacings: down to a hundredth of a
#: spacing, where a wedge holds the fewest particles, and out to where it is two or more
#: spacings wide at 20 degrees.
SAMPLE_RADII = (0.01, 0.03, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0)
#: Directions of the samples about a mouth (every 2 degrees).
SAMPLE_ANGLES = 180
#: Only a mouth whose crack meets the boundary at less than this many degrees (the sharper
#: wedge; 90 for a crack normal to a straight edge) is looked at: the user's refused cracks
#: met it at 31-42 degrees, and one at 53 was carried.
WEDGE_MAX = 75.0
#: A mouth is widened when a sample's eigenvalue ratio is below this (100 times the refusal
#: threshold ``rcond``, 1e-10) or a sample sees too few particles: a mouth the model's points
#: could be refused at. Above it nothing changes: an edge crack a tenth of a spacing off a
#: particle row has 2.4e-5 at worst, and its model has always been accepted.
TRIGGER = 1e-8
#: Once widened, every sample's eigenvalue ratio is brought to at least this (1e6 times
#: ``rcond``), so that the points between the samples keep a margin (a right-angled mouth has
#: 1e-2, a crack 0.02 spacing off a row -5e-17).
RATIO_MIN = 1e-4
#: A widened support reaches its sample at this fraction of its radius (the quartic weight is
#: 0.18 there: the particle counts in the sample's fit, not just at its edge).
REACH = 0.6
#: A widening that lifts a sample's ratio to this multiple of :data:`RATIO_MIN` is enough: the
#: nearest such particle is taken (the smallest change of the shape functions).
FIXED = 10.0
#: Rounds of widening before the search gives up (the model's own check then refuses, naming
#: the point).
MAX_ROUNDS = 40


@dataclasses.dataclass(frozen=True)
class WidenedSupports:
    """The supports widened at one mouth.

    Attributes:
        reason: ``"crack mouth"``.
        mouth: Where the crack meets the boundary (2,).
        particles: The particles whose supports grew (k,).
        old, new: Their radii before and after (k,).
    """

    reason: str
    mouth: np.ndarray
    particles: np.ndarray
    old: np.ndarray
    new: np.ndarray

    def __str__(self) -> str:
        grow = float((self.new / self.old).max()) if len(self.new) else 1.0
        return (
            f"{self.reason} at {np.round(self.mouth, 6).tolist()}: {len(self.particles)} "
            f"support(s) widened, up to {grow:.3g}x"
        )


def inside_polygons(x: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Whether each point of ``x`` (m, 2) lies inside the closed boundary made of ``segments``
    (k, 2, 2) in any order (even-odd rule: a ray towards +x crosses it an odd number of
    times)."""
    a, b = segments[None, :, 0, :], segments[None, :, 1, :]
    px, py = x[:, None, 0], x[:, None, 1]
    straddle = (a[..., 1] > py) != (b[..., 1] > py)
    with np.errstate(invalid="ignore", divide="ignore"):
        xc = a[..., 0] + (py - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
    return (np.count_nonzero(straddle & (px < xc), axis=1) % 2) == 1


def _crosses(p: np.ndarray, q: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Whether each segment ``p q`` (n, 2) crosses one of ``segments`` (k, 2, 2) properly
    (:func:`~dolfinx_meshfree.geometry.crack.segments_intersect` with ``proper``): (n,) bool. A
    line that ends on the boundary (a particle on it) or runs along it does not cross."""
    if not len(segments) or not len(p):
        return np.zeros(len(p), dtype=bool)
    return segments_intersect(p, q, segments[:, 0], segments[:, 1], proper=True).any(axis=1)


def mouth_points(crack: Crack) -> list[tuple[int, np.ndarray]]:
    """``(end, point)`` per mouth of ``crack``: an end (0 or -1) that is not a tip, which
    placing the crack found on the exterior boundary (within ``1e-8 h``,
    :func:`~dolfinx_meshfree.geometry.crack.validate_in_patch`)."""
    return [
        (end, crack.points[end].copy())
        for end, tip in zip((0, -1), crack.is_tip, strict=True)
        if not tip
    ]


def wedge_angle(crack: Crack, end: int, mouth: np.ndarray, segments: np.ndarray) -> float:
    """The smallest angle (radians) between the crack, leaving its mouth at ``end`` (0 or -1),
    and the boundary ``segments`` (k, 2, 2) that pass through the mouth (the nearest to it: a
    mouth lies on the boundary to round-off): the sharper of the two wedges it cuts off (pi/2
    for a crack normal to a straight edge); pi without segments."""
    pts = crack.points
    d = (pts[1] - pts[0]) if end == 0 else (pts[-2] - pts[-1])
    d = d / np.linalg.norm(d)
    a, b = segments[:, 0], segments[:, 1]
    size = float(np.linalg.norm(b - a, axis=1).max(initial=1.0))
    dist = point_segment_distance(mouth[None], a, b)[0]
    on = dist <= dist.min(initial=np.inf) + 1e-9 * size
    best = np.pi
    for p, q in zip(a[on], b[on], strict=True):
        for far in (p, q):  # the boundary's directions away from the mouth
            t = far - mouth
            n = float(np.linalg.norm(t))
            if n > 1e-9 * size:
                best = min(best, float(np.arccos(np.clip(np.dot(t / n, d), -1.0, 1.0))))
    return best


def _samples(mouth: np.ndarray, h: float) -> np.ndarray:
    rho = np.asarray(SAMPLE_RADII, dtype=float) * h
    phi = 2.0 * np.pi * (np.arange(SAMPLE_ANGLES) + 0.5) / SAMPLE_ANGLES
    ring = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    return (mouth[None, None, :] + rho[:, None, None] * ring[None, :, :]).reshape(-1, 2)


def widen_at_mouths(
    mls: MLS, cracks: Sequence[Crack], domain: ParticlePatch | CrackDomain
) -> list[WidenedSupports]:
    """Widen the supports of ``mls`` at the mouths of ``cracks`` (already cut into its
    weights) until the moment matrices about each mouth are sound (module docstring).
    Appends the records to ``mls.widened`` and marks ``mls`` changed when a radius grew, and
    returns them. Collective: the boundary of ``domain`` (its exterior and FE interface
    facets: the particles' region) is gathered; the result is the same on every rank."""
    segments = np.concatenate(
        [
            gathered_segments(domain, domain.exterior_facets),
            gathered_segments(domain, domain.interface_facets),
        ]
    )
    if not len(segments):
        return []
    # the sharp mouths only: at a right-angled one (a crack a hair off a particle row too)
    # every model so far was accepted, and it stays as it was
    mouths = [
        m
        for crack in cracks
        for end, m in mouth_points(crack)
        if wedge_angle(crack, end, m, segments) < np.radians(WEDGE_MAX)
    ]
    if not mouths:
        return []
    h = particle_spacing(domain)
    lines = np.concatenate([np.stack(c.segments, axis=1) for c in cracks] + [np.zeros((0, 2, 2))])
    records = []
    for mouth in mouths:
        x = _samples(mouth, h)
        near_crack = np.zeros(len(x), dtype=bool)
        for crack in cracks:
            near_crack |= crack.distance(x) < 1e-6 * h
        x = x[inside_polygons(x, segments) & ~near_crack]
        old = mls.radii.copy()
        counts, ratio = mls.support_quality(x)
        if not np.any((counts < mls.num_basis) | (ratio < TRIGGER)):
            continue  # a sound mouth (or one near a particle row that holds): left as it is
        for _ in range(MAX_ROUNDS):
            counts, ratio, A = mls.support_quality(x, matrices=True)
            bad = np.flatnonzero((counts < mls.num_basis) | (ratio < RATIO_MIN))
            if not bad.size:
                break
            # one support a round, for the worst sample that can widen one (the first of
            # equals): the others' moment matrices change with it, and most need nothing more
            radii = mls.radii.copy()
            for q in bad[np.lexsort((counts[bad] >= mls.num_basis, ratio[bad]))]:
                if _widen_one(mls, x[q], A[q], radii, segments, lines):
                    break
            else:
                break  # nothing left to see: the model's own check refuses, naming the point
            mls.radii = radii
            mls.changed()
        grown = np.flatnonzero(mls.radii > old)
        if grown.size:
            rec = WidenedSupports("crack mouth", mouth, grown, old[grown], mls.radii[grown])
            mls.widened.append(rec)
            records.append(rec)
    return records


def _widen_one(
    mls: MLS,
    x: np.ndarray,
    A: np.ndarray,
    radii: np.ndarray,
    boundary: np.ndarray,
    cracks: np.ndarray,
) -> bool:
    """Grow, in ``radii``, the support of one particle that ``x`` sees (a straight line
    crossing no crack and no boundary) and that its support does not yet reach at
    :data:`REACH`, among the nearest few: the nearest that lifts the eigenvalue ratio of
    ``x``'s moment matrix ``A`` (in the basis of :meth:`~dolfinx_meshfree.MLS.support_quality`)
    to :data:`FIXED` times :data:`RATIO_MIN`, else the one that lifts it most. Returns whether
    a support grew."""
    d = np.linalg.norm(mls.points - x, axis=1)
    order = np.argsort(d, kind="stable")
    cand = order[d[order] >= REACH * radii[order]][: 8 * mls.num_basis]
    if not cand.size:
        return False
    p = np.broadcast_to(x, (cand.size, 2))
    seen = ~_crosses(p, mls.points[cand], boundary)
    seen &= ~_crosses(p, mls.points[cand], cracks)
    cand = cand[seen]
    if not cand.size:
        return False
    # each candidate's weight at the sample after widening (REACH of its radius) replaces the
    # one it has there now (zero outside its support; a crack cut is not undone: the candidate
    # is in sight)
    basis, _ = polynomial_basis(-(x - mls.points[cand]) / mls.scale, mls.order)
    w_new, _ = mls.weight_function(np.full(cand.size, REACH))
    w_now, _ = mls.weight_function(np.minimum(d[cand] / radii[cand], 1.0))
    trial = A[None] + (w_new - w_now)[:, None, None] * np.einsum("ka,kb->kab", basis, basis)
    ev = np.linalg.eigvalsh(trial)
    gain = ev[:, 0] / np.maximum(ev[:, -1], np.finfo(float).tiny)
    # the nearest that passes with a margin (the smallest widening), else the largest gain
    enough = np.flatnonzero(gain >= FIXED * RATIO_MIN)
    k = cand[int(enough[0]) if enough.size else int(np.argmax(gain))]
    radii[k] = max(radii[k], d[k] / REACH)
    return True
