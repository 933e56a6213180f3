"""A cohesive crack that finds its path: its bonded tip kept ahead of the softening zone, each new
segment normal to the largest principal stress at the front.

The faces of :class:`~dolfinx_meshfree.LinearCohesive` are intrinsic: bonded by the penalty
``K_0`` until the normal traction reaches ``f_t``. A bonded stretch of crack is therefore (up to
the penalty's few per cent of stiffening, :mod:`~dolfinx_meshfree.statics.cohesive`) the uncut
body, and its faces carry no state while they stay on the elastic branch. The crack is grown
ahead of where the material fails, not where it has failed:

* **when:** after every converged step of :func:`~dolfinx_meshfree.follow_path`, the *front* is
  the face point nearest the tip whose faces have softened (``kappa > w_0``: the normal traction
  has reached ``f_t``, a stress criterion at the faces, not averaged); when it comes within
  ``ahead`` particle spacings of the tip, the crack grows by ``step`` spacings;
* **where:** normal to the largest principal stress averaged about the front with the Gaussian
  weight ``exp(-r^2 / (2 l^2))``, ``l = radius`` spacings, over the disc ``r <= 3 l`` (the
  nonlocal direction of Wells & Sluys 2001, "A new method for modelling cohesive cracks using
  finite elements", IJNME 50, sec. 4.1, there with ``l = 3`` element sizes), leaving out the
  points within ``clearance`` spacings of the crack: beside the cut the one-sided fields carry a
  stress parallel to the crack that is not there (in the notched beam at its peak, 1.3 mm from
  the crack, ``sigma_yy`` 4.15 MPa against ``sigma_xx`` 3.03, falling to 0.3 against 1.85 at
  25 mm: with it the averaged direction turned a mode I crack sideways). At the front, not at
  the tip: ahead of a bending beam's process zone the bulk is in compression. A turn of more
  than 70.5 degrees in one extension (beyond the largest kink of any mixed-mode tip field, pure
  mode II by the maximum hoop stress criterion) is no tip field's: the crack goes straight on
  (:data:`_COS_MAX_KINK`);
* **to the boundary:** an extension that would end within one spacing of the exterior boundary
  (a tip must stay a spacing inside; along the ray or across it) runs to the edge's nearest point
  ahead, meeting the traction-free edge at a right angle as a crack normal to the principal
  stress does there (:func:`_to_free_edge`). The crack then splits the body (it must be
  ``Crack(..., through=True)``) and stops growing.
* **out of a notch:** :func:`initiation_direction` gives the first (bonded) segment's direction
  from the linear-elastic solution, by the same average about the notch's tip.

So new faces are inserted where the bulk is still below ``f_t`` (the tip ``ahead`` spacings in
front of the softening zone; an extension at the front itself inserts faces already past ``w_0``,
and the crack runs through the body in one step), the bulk stays elastic, and the faces already
there keep their state: the model is rebuilt on the longer crack, the faces' states carried
point by point (their positions do not change; the new ones start bonded), the coefficients of
the particles whose supports the new segment cuts refitted to the field before it grew
(:class:`_FieldFit`), and the model brought back to equilibrium at the same control value. A
bulk law with state (``RankineDamage``, ``J2Plasticity``) has its committed state carried to the
new cut cells' points (:mod:`~dolfinx_meshfree.statics.state_carry`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from ..approx.crack_cuts import support_radius_at
from ..approx.mls import MomentMatrixError
from ..geometry.crack import (
    NEAR_ROW,
    Crack,
    _turn,
    gathered_segments,
    particle_spacing,
    point_segment_distance,
)
from ..geometry.particles import _points_in_cells
from ..parallel import raise_on_all_ranks
from .cohesive import CohesiveCrack, CohesiveSide
from .sifs import resolve_tip

if TYPE_CHECKING:  # annotations only
    import numpy.typing as npt

    from ..approx.mls import MLS
    from ..couplings.base import CoupledSolution
    from ..geometry.crack import CrackDomain
    from ..geometry.patch import ParticlePatch
    from ..physics.materials import LinearElastic
    from ..physics.state import PointState
    from .efg import EFGSolution

__all__ = [
    "TURNS",
    "CohesiveGrowth",
    "direction_at",
    "extension",
    "grow_once",
    "initiation_direction",
    "nearest_over_ranks",
    "nearest_softened",
    "principal_direction",
    "ray_to_boundary",
    "softening_front",
]


@dataclass(frozen=True)
class CohesiveGrowth:
    """Let a cohesive crack find its path in :func:`~dolfinx_meshfree.follow_path` (module
    docstring). The crack's faces must carry a law (``add_cohesive``) on the segment that ends at
    its tip; the segments added are cohesive too.

    Args:
        crack: The crack (one of the model's): an edge crack (one tip), or a crack inside the
            body (two tips, each grown when the softening front nears it; from
            :meth:`~dolfinx_meshfree.InitiationSite.crack`).
        ahead: Particle spacings kept between the softening front and the tip (> ``step``).
        step: The length of one extension, in particle spacings.
        radius: The Gaussian averaging length ``l`` of the direction, in particle spacings.
        max_extensions: Extensions allowed after one step of the path (a crack that would run
            further at one control value is a snap-back the control cannot follow: PathError).
        clearance: Particle spacings about the crack left out of the average (its faces' near
            field, module docstring); 0 keeps every point.
        lookahead: The share of a further step, beyond the new segment's end, that must keep
            off the particles too (:func:`_off_the_particles`): 0 checks the far half of the
            new segment only, so that a crack can end a segment just short of a particle on its
            line, and pass beside it in the next one. :class:`~dolfinx_meshfree.CrackBandSwitch`
            takes 0.5.
    """

    crack: Crack
    ahead: float = 3.0
    step: float = 1.0
    radius: float = 1.0
    max_extensions: int = 20
    clearance: float = 1.5
    lookahead: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.crack, Crack):
            raise TypeError(f"crack must be a Crack, got {type(self.crack).__name__}")
        for name in ("ahead", "step", "radius"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v!r} must be a positive number of particle spacings")
        if self.ahead <= self.step:
            raise ValueError(
                f"ahead={self.ahead!r} must exceed step={self.step!r}: after an extension the "
                "tip must still be ahead of the softening front"
            )
        for name in ("clearance", "lookahead"):
            c = getattr(self, name)
            if isinstance(c, bool) or not (
                isinstance(c, int | float) and np.isfinite(c) and c >= 0
            ):
                raise ValueError(f"{name}={c!r} must be a number of particle spacings >= 0")
        n = self.max_extensions
        if isinstance(n, bool) or not (isinstance(n, int) and n >= 1):
            raise ValueError(f"max_extensions={n!r} must be an integer >= 1")

    def check(self, cohesive: Sequence[CohesiveCrack], cracks: Sequence[Crack]) -> int:
        """The index in ``cohesive`` of this crack's faces; ValueError naming what is missing."""
        self._check_is_models(cracks)
        k = next((i for i, c in enumerate(cohesive) if c.crack is self.crack), None)
        if k is None:
            raise ValueError(
                f"CohesiveGrowth: {self.crack!r} carries no traction-separation law; add one with "
                "model.add_cohesive(crack, LinearCohesive(...)) before following the path"
            )
        self._check_has_tip()
        segs = cohesive[k].segments
        for end in self.crack.tip_ends:
            last = 0 if end == 0 else len(self.crack.points) - 2
            if segs is not None and last not in segs:
                raise ValueError(
                    f"CohesiveGrowth: the segment {last} of {self.crack!r} at its tip "
                    f"{self.crack.points[end].tolist()} is not cohesive (segments={segs}); the "
                    "crack grows from faces that carry the law"
                )
        return k

    def _check_is_models(self, cracks: Sequence[Crack]) -> None:
        """ValueError unless the crack is one of the model's ``cracks``."""
        if not any(self.crack is c for c in cracks):
            raise ValueError(
                f"{type(self).__name__}: {self.crack!r} is not one of the model's cracks; pass "
                "the Crack object given to the ParticlePatch (or EFGElasticity)"
            )

    def _check_has_tip(self) -> None:
        """ValueError unless the crack has a tip to grow."""
        if not self.crack.tip_ends:
            raise ValueError(
                f"{type(self).__name__}: {self.crack!r} has no tip (it splits the body "
                "already); nothing can grow"
            )

    def extended(self, cohesive: CohesiveCrack, end: int) -> CohesiveCrack:
        """``cohesive`` after the crack grew by one segment at ``end`` (0: a segment prepended,
        -1: appended), which carries the law too."""
        if cohesive.segments is None:
            return cohesive
        if end == 0:
            segs = (0, *(s + 1 for s in cohesive.segments))
        else:
            segs = (*cohesive.segments, len(self.crack.points) - 2)
        return replace(cohesive, segments=tuple(sorted(set(segs))))


#: The largest kink of a crack under any mixed-mode tip field: pure mode II, 70.5 degrees by the
#: maximum hoop stress criterion (Erdogan & Sih 1963: cos(theta) = 1/3). An averaged principal
#: stress that turns a crack further in one extension is no tip field: nearly isotropic (its
#: eigenvectors set by the round-off: the unnotched beam's crack turned 90 degrees at 3/4 of the
#: depth, sigma_xx 0.386 against sigma_yy 0.406, averaged over 20 mm at h = 10 mm) or the flanks'
#: stress parallel to the crack; the crack then goes straight on.
_COS_MAX_KINK = 1.0 / 3.0


def softening_front(side: CohesiveSide, tip: np.ndarray) -> np.ndarray | None:
    """The face point of ``side`` nearest ``tip`` whose faces have softened (committed ``kappa >
    w_0``: the normal traction reached ``f_t``), or ``None`` (collective, the same on every
    rank)."""
    return nearest_softened(side.state, side.law.w_0, tip, side.comm)


def nearest_softened(
    state: PointState, w_0: float, tip: np.ndarray, comm: MPI.Comm
) -> np.ndarray | None:
    """The point of the face points' ``state`` nearest ``tip`` whose committed ``kappa`` is past
    ``w_0``, over the ranks, or ``None`` (collective): :func:`softening_front`, and the dynamic
    growth's (:class:`~dolfinx_meshfree.dynamics.CohesiveDynamicGrowth`)."""
    return nearest_over_ranks(state.points[state.committed["kappa"][:, 0] > w_0], tip, comm)


def nearest_over_ranks(points: np.ndarray, tip: np.ndarray, comm: MPI.Comm) -> np.ndarray | None:
    """The point of ``points`` (this rank's, (m, 2)) nearest ``tip`` over the ranks, ties by
    coordinates so that it is the same on every rank and for every partition, or ``None``
    (collective)."""
    mine = None
    if len(points):
        r = np.linalg.norm(points - tip, axis=1)
        k = np.lexsort((points[:, 1], points[:, 0], r))[0]
        mine = (float(r[k]), points[k].copy())
    found = [m for m in comm.allgather(mine) if m is not None]
    if not found:
        return None
    return min(found, key=lambda m: (m[0], m[1][0], m[1][1]))[1]


def direction_at(crack: Crack, x: np.ndarray, end: int) -> np.ndarray:
    """The unit direction (2,) of the crack's segment nearest the point ``x``, pointing towards
    its end ``end`` (0 or -1: the tip) (local)."""
    pts = crack.points if end == -1 else crack.points[::-1]
    a, b = pts[:-1], pts[1:]
    k = int(point_segment_distance(x[None], a, b)[0].argmin())
    t = b[k] - a[k]
    return t / np.linalg.norm(t)


def _inside(domain: ParticlePatch | CrackDomain, x: np.ndarray) -> np.ndarray:
    """Whether each of ``x`` lies in a cell of ``domain`` on some rank (collective)."""
    inside = _points_in_cells(domain.mesh, x, domain.cells).astype(np.int32)
    domain.comm.Allreduce(MPI.IN_PLACE, inside, op=MPI.MAX)
    return inside > 0


def _polar_rule(centre: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Points (192, 2) and weights (192,) of the Gaussian average of length ``length`` about
    ``centre`` over the disc of radius ``3 length``: 8 rings x 24 rays, weight ``exp(-r^2 /
    (2 l^2)) r`` (local)."""
    r = (np.arange(8) + 0.5) / 8 * 3.0 * length
    a = (np.arange(24) + 0.5) / 24 * 2.0 * np.pi  # symmetric under reflections in x and y
    R, A = np.meshgrid(r, a, indexing="ij")
    x = centre + np.stack([R * np.cos(A), R * np.sin(A)], axis=-1).reshape(-1, 2)
    w = (np.exp(-0.5 * (R / length) ** 2) * R).ravel()
    return x, w


def principal_direction(
    mls: MLS,
    coefficients: np.ndarray,
    material: LinearElastic,
    centre: np.ndarray,
    length: float,
    along: np.ndarray,
    domain: ParticlePatch | CrackDomain | None = None,
    crack: Crack | None = None,
    clearance: float = 0.0,
) -> np.ndarray:
    """The unit direction normal to the largest principal stress averaged about ``centre``
    (Gaussian weight of length ``length`` over the disc of radius ``3 length``; polar rule of 8
    rings x 24 rays), oriented with ``along``; ``along`` itself where the averaged stress is
    compressive all round (a front next to a beam's compression zone: no tension to turn to).
    The points within ``clearance`` of ``crack`` are left out; with ``domain`` (collective), so
    are those outside its cells (beyond the body's edge, or on the FE side); without, local. The
    same on every rank for replicated coefficients.
    """
    x, w = _polar_rule(centre, length)
    if crack is not None:  # the faces' near field (a spurious parallel stress) left out
        far = crack.distance(x) >= clearance
        x, w = x[far], w[far]
    if domain is not None:
        inside = _inside(domain, x)
        x, w = x[inside], w[inside]
    grad = mls.tabulate(x).gradient(coefficients)
    sigma = np.einsum("q,qij->ij", w, material.stress(grad)) / w.sum()
    vals, vecs = np.linalg.eigh(0.5 * (sigma + sigma.T))
    if vals.max() <= 0.0:  # compressed all round: no tension to turn to; straight on
        return along / np.linalg.norm(along)
    n = vecs[:, np.argmax(vals)]
    d = np.array([-n[1], n[0]])
    return d if d @ along >= 0 else -d


def initiation_direction(
    solution: EFGSolution | CoupledSolution,
    crack: Crack,
    tip: int | npt.ArrayLike = 0,
    radius: float | None = None,
    clearance: float | None = None,
) -> np.ndarray:
    """The direction of a cohesive crack's first segment out of a notch: normal to the largest
    principal stress of a linear-elastic ``solution`` averaged about the notch's tip with the
    Gaussian weight of :class:`CohesiveGrowth`'s extensions (:func:`principal_direction`; the
    faces' near field left out), oriented away from the notch (collective).

    Under proportional loading the linear-elastic field is the cohesive model's before anything
    softens, so this is where the stress criterion first sends the crack. Build the crack from it
    before following the path: ``notch + [tip + lead * d]`` with the bonded lead of
    ``CohesiveGrowth.ahead + 1`` spacings (``demos/concrete_beam.py --setup arrea-ingraffea``).

    Args:
        solution: a linear-elastic solve (``model.solve()``) of the model with ``crack`` the notch
            alone (pure EFG or coupled; the tip in the particles).
        crack: the notch (one of the solved model's cracks).
        tip: an index of ``crack.tips`` or its coordinates.
        radius: the Gaussian averaging length (default: :class:`CohesiveGrowth`'s, 1 spacing).
        clearance: the distance about the notch left out (default: 1.5 spacings).

    Returns:
        The unit direction (2,).
    """
    domain = solution.patch if hasattr(solution, "patch") else solution.domain
    cracks = solution.patch.cracks if hasattr(solution, "patch") else solution.cracks
    if not any(crack is c for c in cracks):
        raise ValueError(
            f"initiation_direction: {crack!r} is not one of the solved model's cracks; pass the "
            "Crack object the model was built with"
        )
    h = particle_spacing(domain)
    k = resolve_tip(crack, tip, h)
    x, end = crack.tips[k], crack.tip_ends[k]
    l_avg = CohesiveGrowth.radius * h if radius is None else float(radius)
    clear = CohesiveGrowth.clearance * h if clearance is None else float(clearance)
    along = direction_at(crack, x, end)
    return raise_on_all_ranks(
        domain.comm,
        lambda: principal_direction(
            solution.mls, solution.coefficients, solution.material, x, l_avg, along, domain,
            crack, clear,
        ),
    )  # fmt: skip


def ray_to_boundary(
    domain: ParticlePatch | CrackDomain, start: np.ndarray, direction: np.ndarray
) -> float:
    """Distance from ``start`` along ``direction`` to the nearest exterior facet it meets
    (``inf`` if none; collective)."""
    return _ray(gathered_segments(domain, domain.exterior_facets), start, direction)


def _ray(seg: np.ndarray, start: np.ndarray, direction: np.ndarray) -> float:
    """:func:`ray_to_boundary` on gathered exterior segments ``seg`` (k, 2, 2) (local)."""
    a, b = seg[:, 0], seg[:, 1]
    t = b - a
    # start + s d = a + u t: [d, -t] (s, u) = a - start, by Cramer's rule
    det = direction[1] * t[:, 0] - direction[0] * t[:, 1]
    rhs = a - start
    ok = np.abs(det) > 1e-14 * np.linalg.norm(t, axis=1)
    safe = np.where(ok, det, 1.0)
    s = np.where(ok, (rhs[:, 1] * t[:, 0] - rhs[:, 0] * t[:, 1]) / safe, -1.0)
    u = np.where(ok, (direction[0] * rhs[:, 1] - direction[1] * rhs[:, 0]) / safe, -1.0)
    hit = ok & (s > 0) & (u >= -1e-12) & (u <= 1 + 1e-12)
    return float(s[hit].min()) if hit.any() else np.inf


def grow_once(
    growth: CohesiveGrowth,
    side: CohesiveSide,
    mls: MLS,
    coefficients: Callable[[], np.ndarray],
    material: LinearElastic,
    domain: ParticlePatch | CrackDomain,
    h: float,
) -> tuple[int, np.ndarray, float] | None:
    """Extend ``growth.crack`` by one step when its softening front is within ``ahead`` spacings
    of the tip (collective): the particle coefficients refitted to the field before it grew
    (:class:`_FieldFit`), or ``None`` when it did not grow. ``coefficients()`` gives the current
    ones, replicated (called only when the crack grows). A crack that would leave the patch
    raises the validator's ValueError (every rank). Of two tips, the first whose front is near
    grows; returns ``(end, coefficients, turn)`` (``end`` 0 or -1: the crack's end that grew;
    ``turn``: the degrees its new segment was turned off the particles, :func:`extension`)."""
    crack = growth.crack
    for end in crack.tip_ends:
        tip = crack.points[end]
        front = softening_front(side, tip)
        if front is not None and np.linalg.norm(front - tip) < growth.ahead * h:
            c = coefficients()
            d, length, turn = extension(growth, mls, c, material, domain, h, end, front)
            fit = _FieldFit(mls, c, crack, tip, tip + length * d, domain, h)
            crack.extend(d, length, tip=end)  # through: the end is a mouth
            return end, fit.refit(domain.comm), turn
    return None


def extension(
    growth: CohesiveGrowth,
    mls: MLS,
    c: np.ndarray,
    material: LinearElastic,
    domain: ParticlePatch | CrackDomain,
    h: float,
    end: int,
    front: np.ndarray,
) -> tuple[np.ndarray, float, float]:
    """The next segment of the crack's ``end`` whose softening front is ``front``: its unit
    direction, its length and the degrees it was turned off the particles (collective; the
    crack is not changed). Normal to the principal stress averaged about the front (of the
    particle coefficients ``c``), straight on past the largest kink of any tip field, turned by
    up to 15 degrees where its far half would pass within ``NEAR_ROW`` spacing of a particle
    (:func:`_off_the_particles`); to the edge ahead at a right angle when the new tip would end
    within a spacing of it (refused without ``through=True``); a tip that would come within a
    support radius of the FE interface is refused."""
    crack = growth.crack
    tip = crack.points[end]
    comm = domain.comm
    along = direction_at(crack, front, end)  # the crack's direction at the front
    d = raise_on_all_ranks(
        comm,
        lambda: principal_direction(
            mls, c, material, front, growth.radius * h, along, domain, crack,
            growth.clearance * h,
        ),
    )  # fmt: skip
    ahead = crack.tip_direction(end)
    if d @ ahead < _COS_MAX_KINK:  # no tip field turns a crack this far: straight on
        d = ahead
    length = growth.step * h
    seg = gathered_segments(domain, domain.exterior_facets)
    to_edge = _ray(seg, tip, d)
    # run to the boundary when the new tip would end within h of it (a tip stays h inside),
    # along the ray or across it (a ray that meets the edge at a slant): the crack splits the body
    gap = point_segment_distance((tip + length * d)[None], seg[:, 0], seg[:, 1]).min()
    through = to_edge <= length + h or gap < h

    def check() -> None:
        if through and not crack.through:
            raise ValueError(
                f"the growing crack {crack!r} reaches the exterior boundary at "
                f"{(tip + to_edge * d).round(6).tolist()}: it would split the body; give "
                "Crack(..., through=True) so that its cohesive faces hold the parts together"
            )

    raise_on_all_ranks(comm, check)
    if through:  # to the nearest point of the edge ahead: the crack meets it at a right angle
        return (*_to_free_edge(tip, d, to_edge, seg), 0.0)
    d, turn = _off_the_particles(
        domain.particles.positions[:, :2], tip, d, length, h, seg, growth.lookahead
    )
    _check_interface_clearance(mls, domain, tip + length * d)
    return d, length, turn


#: The turns, in degrees, tried in turn for a grown segment whose far half would pass within
#: ``NEAR_ROW`` spacing of a particle (:func:`_off_the_particles`).
TURNS = (0.0, 5.0, -5.0, 10.0, -10.0, 15.0, -15.0)


def _off_the_particles(
    particles: np.ndarray,
    tip: np.ndarray,
    d: np.ndarray,
    length: float,
    h: float,
    edge: np.ndarray,
    lookahead: float = 0.0,
) -> tuple[np.ndarray, float]:
    """The direction of the next segment and its turn in degrees: ``d`` turned by the first of
    :data:`TURNS` whose far half (and ``lookahead`` of a further segment straight on) keeps
    ``NEAR_ROW`` spacing off every particle and whose end stays a spacing inside the exterior
    segments ``edge`` ((k, 2, 2), as the unturned one does); ``d`` and 0 when none does. A
    segment that runs beside a row of particles leaves the points between them with only that
    row on their side of the cut: four collinear particles, a singular moment matrix (a crack on
    quadrilaterals that turned vertical 0.044 spacing beside a column). The first half may stay
    close: it starts at the tip the crack already has. A crack that ends a segment just short of
    a particle on its line passes beside it in the next one: a user's plate on triangles whose
    :class:`~dolfinx_meshfree.CrackBandSwitch` crack drifted to 0.045 spacing of a column
    (``lookahead`` 0.5 kept it 0.11 spacing off). The same on every rank (replicated
    particles)."""
    for turn in TURNS:
        e = _turn(d, np.deg2rad(turn))
        a, b = tip + 0.5 * length * e, tip + (1.0 + lookahead) * length * e
        if point_segment_distance(particles, a[None], b[None]).min() < NEAR_ROW * h:
            continue
        b = tip + length * e
        if turn and point_segment_distance(b[None], edge[:, 0], edge[:, 1]).min() < h:
            continue
        return e, float(turn)
    return d, 0.0


def _to_free_edge(
    tip: np.ndarray, d: np.ndarray, to_edge: float, seg: np.ndarray
) -> tuple[np.ndarray, float]:
    """The last stretch of a crack that runs through to the exterior boundary ``seg`` (k, 2, 2):
    to the boundary point nearest ``tip`` if it lies ahead (``d``), else along ``d`` for
    ``to_edge``. A traction-free edge is a principal plane whose normal stress vanishes, so the
    largest principal stress next to it is tangential and a crack normal to it meets the edge at
    a right angle. Along the ray, a slanted meeting left a wedge between the crack and the edge
    whose points saw too few particles for the MLS (the shear beam's curved path at h = 20 mm,
    60 degrees from the normal: a singular moment matrix at the mouth). Returns the unit
    direction and the length (local)."""
    a, b = seg[:, 0], seg[:, 1]
    t = b - a
    xi = np.clip(np.einsum("kd,kd->k", tip - a, t) / np.einsum("kd,kd->k", t, t), 0.0, 1.0)
    p = a + xi[:, None] * t
    dist = np.linalg.norm(p - tip, axis=1)
    k = int(dist.argmin())
    if dist[k] == 0.0 or (p[k] - tip) @ d <= 0.0:  # the nearest edge is behind: along the ray
        return d, to_edge
    return (p[k] - tip) / dist[k], float(dist[k])


class _FieldFit:
    """The particle coefficients after a crack grew, fitted to the field before it grew.

    The new segment cuts the supports of the particles around it: with the same coefficients the
    one-sided fields on its two sides differ, a jump the new bonded faces (penalty ``K_0 = 30 E /
    h``) would turn into large forces, and Newton, started there, lost the path when the crack
    split a plate. The coefficients of the particles whose supports meet the new segment ``a b``
    are instead refitted, by least squares at points of their supports off the crack, to the
    field before it grew, which is continuous there: the new faces start bonded with (nearly) no
    jump. Built before :meth:`Crack.extend` (collective: the points in the domain; the old field
    there, local), :meth:`refit` after it.
    """

    def __init__(
        self,
        mls: MLS,
        coefficients: np.ndarray,
        crack: Crack,
        a: np.ndarray,
        b: np.ndarray,
        domain: ParticlePatch | CrackDomain,
        h: float,
    ) -> None:
        self.mls = mls
        self.c = np.asarray(coefficients, dtype=float).reshape(mls.num_particles, -1)
        self.affected = np.flatnonzero(
            point_segment_distance(mls.points[:, :2], a[None], b[None])[:, 0] < mls.radii
        )
        # a grid of h / 2 over the new segment's neighbourhood: the points in the supports of
        # the affected particles, off the crack and its new segment, in the domain
        pad = 2.0 * mls.radii.max()
        lo, hi = np.minimum(a, b) - pad, np.maximum(a, b) + pad
        n = np.maximum(2, np.ceil((hi - lo) / (0.5 * h)).astype(int) + 1)
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n[0]), np.linspace(lo[1], hi[1], n[1]))
        x = np.stack([gx.ravel(), gy.ravel()], axis=1)
        pa, ra = mls.points[self.affected, :2], mls.radii[self.affected]
        near = (np.linalg.norm(x[:, None, :] - pa[None], axis=2) < ra[None]).any(axis=1)
        off = point_segment_distance(x, a[None], b[None])[:, 0] > 0.05 * h
        x = x[near & off & (crack.distance(x) > 0.05 * h)]
        self.x = x[_inside(domain, x)]
        # the field before the crack grows; where the MLS cannot be evaluated, nothing is
        # refitted (the same on every rank)
        self.u_old = None
        if len(self.x):
            try:
                self.u_old = mls.tabulate(self.x, 0).values @ self.c
            except MomentMatrixError:
                self.x = self.x[:0]

    def refit(self, comm: MPI.Comm) -> np.ndarray:
        """The coefficients (interleaved, original order, the same on every rank) after the
        crack grew: those of the affected particles refitted on rank 0 and broadcast
        (collective). Where the MLS cannot be evaluated at a fitting point (a moment matrix
        too ill-conditioned beside a kink of the crack) the coefficients are left as they were:
        the re-equilibration then starts from them, and fails with a PathError if it must."""
        c = self.c.copy()
        if comm.rank == 0 and self.affected.size and len(self.x) >= self.affected.size:
            try:
                phi = self.mls.tabulate(self.x, 0).values.tocsc()
            except MomentMatrixError:
                phi = None
            if phi is not None:
                rest = np.setdiff1d(np.arange(self.c.shape[0]), self.affected)
                rhs = self.u_old - phi[:, rest] @ self.c[rest]
                A = phi[:, self.affected].toarray()
                c[self.affected] = np.linalg.lstsq(A, rhs, rcond=None)[0]
        return comm.bcast(c.ravel(), root=0)


def _check_interface_clearance(
    mls: MLS, domain: ParticlePatch | CrackDomain, tip: np.ndarray
) -> None:
    """Refuse a new tip closer to the FE interface than the largest support radius of the
    particles around it (as :func:`~dolfinx_meshfree.attach_cracks` does for the given tips: the
    cut would change shape functions the FE side cannot follow). Collective."""
    iface = gathered_segments(domain, domain.interface_facets)
    if not iface.size:
        return
    r = support_radius_at(mls, tip)
    d = float(point_segment_distance(tip[None], iface[:, 0], iface[:, 1]).min())

    def check() -> None:
        if d < r:
            raise ValueError(
                f"the growing crack's next tip {tip.round(6).tolist()} would be {d:.3g} from the "
                f"FE interface, less than the support radius {r:.3g} there: the crack would leave "
                "what the particle patch can carry; enlarge the patch along the crack's path"
            )

    raise_on_all_ranks(domain.comm, check)
