"""Further cohesive cracks that start during a followed path: multiple cracking (issue 24).

:func:`~dolfinx_meshfree.follow_path` watches, at every converged step with cohesive cracks in an
elastic bulk, the bulk's largest averaged principal stress three spacings or more from every crack
(:func:`~dolfinx_meshfree.statics.cohesive_initiation.bulk_stress_peak`). Given a
:class:`CrackInitiation`, a step at which it passes the law's ``f_t`` starts a crack there, by the
rule that started the first (the stress criterion of :func:`~dolfinx_meshfree.initiation_site`,
here on the current field: :func:`~dolfinx_meshfree.statics.cohesive_initiation.site_at`):

* **where:** at the bulk's peak, normal to the averaged largest principal stress there: an edge
  crack from an exterior edge, a crack with two tips inside the body;
* **its first stretch** is bonded (``Crack(..., through=True)``, the law on every face), ``lead``
  spacings long each way (or inwards from an edge), shortened to stay one spacing inside the
  body and ``gap`` spacings from every other crack, and moved sideways by up to half a spacing
  where it would pass within ``NEAR_ROW`` spacing of a particle (:func:`first_stretch`); one
  shorter than a spacing is not started, and a :class:`~dolfinx_meshfree.BulkStrengthWarning`
  says why;
* **into the built model** (:func:`insert_crack`): checked as any crack
  (:func:`~dolfinx_meshfree.geometry.crack.place_crack`; in a coupled model, its tips a support
  radius from the FE interface as :func:`~dolfinx_meshfree.approx.crack_cuts.attach_cracks`
  asks), added to the MLS's cut (a pair that crosses two cracks drops out, as between the cracks
  given at build time), the law on its faces; the coefficients of the particles whose supports it
  cuts refitted to the field before it (the growing crack's
  :class:`~dolfinx_meshfree.statics.cohesive_growth._FieldFit`), so that its bonded faces start
  with no jump;
* then the model is rebuilt (the other faces' states carried), brought back to equilibrium at the
  same control value, and the new crack grows by a
  :class:`~dolfinx_meshfree.CohesiveGrowth` with the parameters of the first one given (or the
  defaults).

Several cracks may start in one step, one at a time, each from the field the last left, up to
``max_cracks`` in the path. A peak on the FE side of a coupled model, or in a patch cell too close
to the interface, cannot start a crack there: the warning names the point (enlarge the patch),
:attr:`~dolfinx_meshfree.PathResult.refused` lists it, and its region of tension (the candidates
above ``f_t`` joined to it) is left out from then on, so that the peaks of other regions still
start cracks (``follow_path`` tries at most ``MAX_REFUSED_PER_STEP`` sites a step). A crack is
never started beside a refused site, in its region, where it would stand for the refused one
displaced.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..approx.crack_cuts import CrackCut, support_radius_at
from ..geometry.crack import (
    NEAR_ROW,
    Crack,
    gathered_segments,
    place_crack,
    point_segment_distance,
    validate_in_patch,
)
from ..geometry.quadrature import boundary_facets
from ..physics.cohesive import LinearCohesive
from .cohesive_growth import CohesiveGrowth, _FieldFit, _ray
from .cohesive_initiation import InitiationSite

if TYPE_CHECKING:  # annotations only
    from collections.abc import Callable

    from ..geometry.crack import CrackDomain
    from ..geometry.patch import ParticlePatch
    from .coupled import CoupledElasticity
    from .efg import EFGElasticity

__all__ = ["SHIFTS", "CrackInitiation", "first_stretch", "insert_crack"]

#: The sideways shifts, in particle spacings, tried in turn for a first stretch that passes within
#: ``NEAR_ROW`` spacing of a particle (:func:`first_stretch`): across the stretch inside the
#: body, along the edge from an edge site. An eighth of a spacing clears a particle that a
#: 45-degree stretch through a cell's midpoint meets (at least ``NEAR_ROW`` = 0.1 off it); half a
#: spacing is the most, a shift within the stress's averaging length (one spacing).
SHIFTS = (0.0, 0.125, -0.125, 0.25, -0.25, 0.375, -0.375, 0.5, -0.5)


@dataclass(frozen=True)
class CrackInitiation:
    """Start further cohesive cracks in :func:`~dolfinx_meshfree.follow_path` where the bulk's
    averaged largest principal stress passes ``law.ft`` (module docstring).

    Args:
        law: The traction-separation law of the new cracks' faces.
        lead: The bonded first stretch, in particle spacings, each way from a site inside the
            body or inwards from an edge (default: ``CohesiveGrowth.ahead + 1``, as
            :meth:`~dolfinx_meshfree.InitiationSite.crack`).
        gap: Particle spacings kept between a new crack and every other.
        max_cracks: The most cracks started in one path.
        region: ``region(x)`` (m, 2) -> (m,) bool: where cracks may start (default: anywhere).
            A peak outside it starts nothing and the warning says so; the largest averaged
            stress inside it above ``f_t`` starts a crack (as ``initiation_site``'s
            ``region`` chooses the first crack's site).
    """

    law: LinearCohesive
    lead: float = CohesiveGrowth.ahead + 1.0
    gap: float = 1.5
    max_cracks: int = 8
    region: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.law, LinearCohesive):
            raise TypeError(
                f"law must be a LinearCohesive (the new cracks' faces), got "
                f"{type(self.law).__name__}"
            )
        for name, low in (("lead", 1.0), ("gap", 0.0)):
            v = getattr(self, name)
            number = isinstance(v, int | float) and not isinstance(v, bool)
            if not (number and np.isfinite(v) and v >= low):
                raise ValueError(f"{name}={v!r} must be a number of particle spacings >= {low:g}")
        n = self.max_cracks
        if isinstance(n, bool) or not (isinstance(n, int) and n >= 1):
            raise ValueError(f"max_cracks={n!r} must be an integer >= 1")
        if self.region is not None and not callable(self.region):
            raise TypeError(
                f"region must be a callable on points (m, 2) -> (m,) bool, got {self.region!r}"
            )


def first_stretch(
    init: CrackInitiation,
    site: InitiationSite,
    domain: ParticlePatch | CrackDomain,
    cracks: list[Crack],
    coupled: bool,
    interface_clearance: float = 0.0,
) -> tuple[Crack | None, str]:
    """The bonded first stretch of the crack that starts at ``site`` (collective): ``(crack,
    "")``, or ``(None, why)`` when less than a spacing of it fits (module docstring); in a
    coupled model it also keeps ``interface_clearance`` (the particles' largest support radius)
    from the FE interface. A stretch that passes within ``NEAR_ROW`` spacing of a particle (a
    45-degree stretch through a cell's midpoint meets its corners) is moved sideways by the
    first of :data:`SHIFTS` that clears it, across the stretch or, from an edge site, along the
    edge; a particle on a crack has no side, and one beside it biases the faces' one-sided
    functions."""
    h, p = site.spacing, site.point
    facets = boundary_facets(domain.mesh) if coupled else domain.exterior_facets
    edge = gathered_segments(domain, facets)
    iface = gathered_segments(domain, domain.interface_facets) if coupled else edge[:0]
    others = [np.stack([c.points[:-1], c.points[1:]], axis=1) for c in cracks]
    other = np.concatenate(others) if others else np.zeros((0, 2, 2))
    gap = init.gap * h

    def far(x: np.ndarray, seg: np.ndarray, distance: float) -> bool:
        """Whether every point of ``x`` (m, 2) is ``distance`` or more from the segments."""
        if not len(seg):
            return True
        return bool(point_segment_distance(x, seg[:, 0], seg[:, 1]).min() >= distance)

    def clear(x: np.ndarray) -> bool:
        """Whether the points ``x`` (m, 2) keep a spacing from the body's edges, ``gap`` from
        the other cracks and ``interface_clearance`` from the FE interface."""
        return far(x, edge, h) and far(x, other, gap) and far(x, iface, interface_clearance)

    def reach(d: np.ndarray) -> float:
        """How far the stretch runs along ``d``: ``lead``, shortened by half spacings until
        its points from 1.5 spacings on keep their distances (a stretch beside an edge would
        leave a strip of particles in a row, beside another crack one too thin to fit)."""
        start = p + 1e-9 * h * d  # off the edge an edge site lies on
        length = min(init.lead * h, _ray(edge, start, d) - h)
        if len(other):
            length = min(length, _ray(other, start, d) - gap)
        if len(iface):
            length = min(length, _ray(iface, start, d) - interface_clearance)
        while length >= h:
            probe = np.arange(min(1.5 * h, length), length + 1e-12 * h, 0.25 * h)
            if clear(p + probe[:, None] * d):
                break
            length -= 0.5 * h
        return float(length)

    d = site.direction
    particles = domain.particles.positions[:, :2]
    slide = _edge_tangent(edge, p) if site.on_edge else np.array([d[1], -d[0]])
    for shift in SHIFTS:  # the first whose stretch fits and keeps off the particles
        p = site.point + shift * h * slide
        if site.on_edge and point_segment_distance(p[None], edge[:, 0], edge[:, 1]).min() > (
            1e-9 * h
        ):
            continue  # slid off the edge's straight piece
        ahead = reach(d)
        behind = 0.0 if site.on_edge else reach(-d)
        if ahead < h or (not site.on_edge and behind < h):
            if shift == 0.0:  # the site's own stretch does not fit: no shift is looked for
                return None, (
                    f"less than a particle spacing ({h:.3g}) of its first stretch (from "
                    f"{np.round(site.point, 6).tolist()} along {np.round(d, 6).tolist()}) fits "
                    f"a spacing inside the body's edges, {init.gap:g} spacings from the other "
                    "cracks and, in a coupled model, a support radius from the FE interface "
                    "(enlarge the patch there)"
                )
            continue
        a, b = p - behind * d, p + ahead * d
        if point_segment_distance(particles, a[None], b[None]).min() >= NEAR_ROW * h:
            return Crack([a, b], through=True), ""
    return None, (
        f"its first stretch from {np.round(site.point, 6).tolist()} along "
        f"{np.round(d, 6).tolist()} passes within {NEAR_ROW:g} spacing of a particle however "
        f"it is moved sideways (up to {max(SHIFTS):g} spacing): a particle on a crack has no "
        "side"
    )


def _edge_tangent(edge: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The unit tangent (2,) of the exterior segment (of ``edge``, (m, 2, 2)) nearest ``p``."""
    k = int(np.argmin(point_segment_distance(p[None], edge[:, 0], edge[:, 1])[0]))
    t = edge[k, 1] - edge[k, 0]
    return t / np.linalg.norm(t)


def insert_crack(
    model: CoupledElasticity | EFGElasticity,
    efg: bool,
    crack: Crack,
    law: LinearCohesive,
    coefficients: np.ndarray,
    h: float,
) -> np.ndarray:
    """Add ``crack`` to the built ``model``'s particles, its MLS cut and its cohesive faces
    (collective; a crack the checks refuse raises their ValueError on every rank, and the model
    is left as it was). Returns the particle coefficients (interleaved, replicated) refitted to
    the field ``coefficients`` across it (``h``: the particle spacing)."""
    domain = model._domain if efg else model.patch
    mls = model.mls
    a, b = crack.points[0], crack.points[-1]
    fit = _FieldFit(mls, coefficients, crack, a, b, domain, h)
    if efg:
        place_crack(crack, domain)
        model.cracks.append(crack)
    else:
        r = max((support_radius_at(mls, t) for t in crack.tips), default=0.0)
        validate_in_patch(crack, domain, clearance=max(r, h))
        domain.add_crack(crack)
    cut = next(c for c in mls.pair_cuts if isinstance(c, CrackCut))
    cut.cracks.append(crack)
    crack.add_listener(mls.changed)
    mls.changed()
    model.add_cohesive(crack, law)
    return fit.refit(domain.comm)
