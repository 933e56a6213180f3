"""Quasi-static crack growth (issue 10, item 5): solve, K_I and K_II at the tip by the domain
interaction integral, kink by the maximum hoop stress criterion (Erdogan & Sih 1963;
:mod:`~dolfinx_meshfree.fracture.criteria`), extend the crack by ``da`` and solve again.

Belytschko et al. (1995), remark after eq. (3.11): the MLS shape functions change as the crack
grows; the crack's :meth:`~dolfinx_meshfree.Crack.extend` bumps the MLS version and the next
``problem.solve()`` rebuilds the particle side. ``update="local"`` (the default) rebuilds only
what the extension changes (:mod:`~dolfinx_meshfree.statics.growth_update`: the table rows within
a support radius of the new segment, the cells it cuts, the VCI constants and stiffness rows of
the particles there; equal to a full rebuild to round-off); ``update="full"`` rebuilds
everything (the cost of a step then grows with the patch; ``benchmarks/bench_growth.py`` measures
both).

Works with any problem whose ``solve()`` returns a solution with ``stress_intensity_factors``:
:class:`~dolfinx_meshfree.EFGElasticity`, :class:`~dolfinx_meshfree.CoupledElasticity` and
:class:`~dolfinx_meshfree.CoupledLinearProblem` (a coupling of ``CRACK_COUPLINGS``).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..fracture.criteria import equivalent_sif, kink_angle
from ..geometry.crack import Crack, gathered_segments, particle_spacing, point_segment_distance
from ..geometry.patch_criteria import GrowthContext, NearTips, warn_unused
from ..physics.state import check_stateless
from .growth_update import disable_local_update, enable_local_update
from .patch_growth import PatchEvent, PatchGrowth
from .sifs import CLEARANCE, DEFAULT_RADII

__all__ = [
    "GROWTH_UPDATES",
    "MIN_GROWTH_OUTER",
    "GrowthStep",
    "GrowthStopped",
    "QuasiStaticCrackGrowth",
    "TipAtBoundary",
]


#: How a growth step rebuilds the particle side.
GROWTH_UPDATES = ("local", "full")


class TipAtBoundary(ValueError):
    """A growing tip has come within the SIF domains' least room of the body's exterior
    boundary (:data:`MIN_GROWTH_OUTER` plus one spacing): the crack has reached the edge at
    this resolution. :meth:`QuasiStaticCrackGrowth.run` stops there (a
    :class:`GrowthStopped` warning); :meth:`QuasiStaticCrackGrowth.step` raises it."""


class GrowthStopped(UserWarning):
    """:meth:`QuasiStaticCrackGrowth.run` stopped before its steps: the reason is in the
    message and in :attr:`QuasiStaticCrackGrowth.stopped`."""


#: The smallest outer radius, in spacings, the default domains of a growth step shrink to near
#: the body's exterior boundary (``CLEARANCE`` spacings inside it); a tip nearer is refused.
MIN_GROWTH_OUTER = 2.0


@dataclass
class GrowthStep:
    """One step of :class:`QuasiStaticCrackGrowth`.

    Attributes:
        step: 0, 1, ...
        tip: The tip (2,) at which K was computed (before the extension).
        direction: The crack direction there.
        K_I: Mean over the integration domains.
        K_II: Mean over the integration domains.
        radius: The outer domain radii used.
        path_dependence: The spread of K over them
            (``StressIntensityFactors.path_dependence``).
        theta: Kink angle (radians, counterclockwise from ``direction``).
        K_eq: The equivalent SIF.
        grown: Whether the crack was extended after this step.
        new_tip: The tip after it.
        time_solve: Seconds of ``problem.solve()`` (rebuild of the tables, cut cells and
            operator, assembly, solve).
        time_sifs: Seconds of the interaction integral.
        timings: The solution's own split of ``time_solve`` (e.g. setup, assemble, solve).
        particles: The number of particles of the model solved (grows with ``adapt``).
    """

    step: int
    tip: np.ndarray
    direction: np.ndarray
    K_I: float
    K_II: float
    radius: np.ndarray
    path_dependence: float
    theta: float
    K_eq: float
    grown: bool
    new_tip: np.ndarray
    time_solve: float
    time_sifs: float
    timings: dict
    particles: int = 0

    def as_dict(self) -> dict:
        """Plain lists and floats (for JSON)."""
        d = asdict(self)
        for k in ("tip", "direction", "new_tip", "radius"):
            d[k] = np.asarray(d[k]).tolist()
        return d


def _check(crack: Crack, increment: float, steps: int, K_Ic: float | None, tip: int | None) -> int:
    """Validate the arguments (local, the same on every rank). Returns the end index to grow."""
    if not isinstance(crack, Crack):
        raise ValueError(f"crack={crack!r:.80} should be a dolfinx_meshfree.Crack")
    if isinstance(increment, bool) or not (
        isinstance(increment, int | float) and np.isfinite(increment) and increment > 0
    ):
        raise ValueError(
            f"increment={increment!r} must be a positive crack extension da per step "
            "(e.g. one to two particle spacings)"
        )
    if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 1:
        raise ValueError(f"steps={steps!r} must be an integer >= 1 (the number of growth steps)")
    if K_Ic is not None and not (np.isfinite(K_Ic) and K_Ic > 0):
        raise ValueError(
            f"K_Ic={K_Ic!r} must be a positive fracture toughness, or None (grow every step)"
        )
    ends = crack.tip_ends
    tips = {e: np.round(crack.points[e], 12).tolist() for e in ends}
    if tip is None:
        if len(ends) != 1:
            raise ValueError(
                f"the crack has tips at {list(tips.values())}: give tip=0 (start) or tip=-1 (end)"
            )
        return ends[0]
    if isinstance(tip, bool) or tip not in ends:
        raise ValueError(
            f"tip={tip!r} is not a tip of the crack; its tips are the ends {tips} "
            "(0: the start point, -1: the end point; a mouth on the boundary does not grow)"
        )
    return int(tip)


class QuasiStaticCrackGrowth:
    """Quasi-static growth of one tip of ``crack`` under the problem's fixed loads.

    Each step: ``problem.solve()``; ``K_I``, ``K_II`` at the tip (mean over the domain radii
    ``radius``); kink angle ``theta_c = 2 atan[(K_I - sqrt(K_I^2 + 8 K_II^2)) / (4 K_II)]``;
    if ``K_eq >= K_Ic`` (always when ``K_Ic`` is None: a prescribed-increment path) the crack is
    extended by ``increment`` in the kinked direction (``crack.extend``), else growth stops.

    Args:
        problem: an ``EFGElasticity``, ``CoupledElasticity`` or ``CoupledLinearProblem`` whose
            cracks include ``crack`` (with its loads and conditions set).
        crack: the growing crack. increment: ``da`` (> 0). steps: the number of steps (>= 1).
        K_Ic: fracture toughness, or None. tip: the end to grow, 0 or -1 (default: the only
            tip). radius: outer domain radii of the interaction integral (default: 3, 4, 5
            particle spacings, scaled down to 0.9 of the tip segment's length when the
            increment is shorter: the previous kink must stay outside the domains; and to keep
            one spacing from the body's exterior boundary, down to an outer radius of
            :data:`MIN_GROWTH_OUTER` spacings). A tip with less room, or nearer the exterior
            boundary than a given outer radius, has reached the edge: :meth:`run` stops there.
            update: ``"local"`` (default): after each extension re-tabulate, re-integrate and
            re-assemble only what it changes; ``"full"``: rebuild the particle side (equal to
            round-off, 1e-10 checked).
            adapt: A patch that grows during the run (issue 25): a criterion
            (:class:`~dolfinx_meshfree.NearTips`, :class:`~dolfinx_meshfree.FieldAbove`,
            :class:`~dolfinx_meshfree.CellsWhere`) or a list of them, asked before the first
            solve and before each extension (with the tip the extension will make);
            the FE cells they name become particles and the model is rebuilt on the larger
            patch (:class:`~dolfinx_meshfree.statics.patch_growth.PatchGrowth`; records in
            :attr:`events`, the current model in :attr:`problem`). ``problem`` must then be
            a :class:`~dolfinx_meshfree.CoupledLinearProblem`. ``NearTips(spacings=k)``
            must keep the SIF domains and their one-spacing clearance inside the patch
            (refused otherwise, naming the tip); ``NearTips()`` picks that radius. Default
            ``None``: the patch is fixed.
            sif_options: more keywords of ``stress_intensity_factors``.

    Example:
        >>> growth = mf.QuasiStaticCrackGrowth(problem, crack, increment=0.02, steps=5)
        >>> history = growth.run()       # list of GrowthStep
        >>> growth.path                  # the tip positions, (steps + 1, 2)
    """

    def __init__(
        self,
        problem: Any,
        crack: Crack,
        increment: float,
        steps: int,
        K_Ic: float | None = None,
        tip: int | None = None,
        radius: float | np.ndarray | None = None,
        update: str = "local",
        adapt: Any = None,
        **sif_options,
    ) -> None:
        self.end = _check(crack, increment, steps, K_Ic, tip)
        if not hasattr(problem, "solve"):
            raise ValueError(f"problem={problem!r:.80} has no solve()")
        if update not in GROWTH_UPDATES:
            raise ValueError(f"update={update!r} is not known; use one of {GROWTH_UPDATES}")
        self.update = update
        inner = getattr(problem, "problem", problem)  # CoupledLinearProblem -> CoupledElasticity
        check_stateless(
            getattr(inner, "law", getattr(inner, "material", None)),
            "QuasiStaticCrackGrowth (it re-solves from the unloaded state at every crack length)",
        )
        if getattr(inner, "cohesive", None):
            raise ValueError(
                "QuasiStaticCrackGrowth grows traction-free cracks by K_Ic and re-solves from the "
                "unloaded state: the model's cohesive faces (add_cohesive) would lose their "
                "state; follow a cohesive crack with follow_path"
            )
        mls = getattr(inner, "mls", None)
        cracks = getattr(inner, "cracks", None) or getattr(
            getattr(inner, "patch", None), "cracks", []
        )
        #: The :class:`~dolfinx_meshfree.statics.growth_update.LocalUpdate` (``update="local"``).
        self.local = None
        if mls is not None:
            if update == "local":
                self.local = enable_local_update(mls, cracks)
            else:
                disable_local_update(mls)
        self.problem, self.crack = problem, crack
        #: The :class:`~dolfinx_meshfree.statics.patch_growth.PatchGrowth` (``adapt``), or None.
        self.adaptive = None
        if adapt is not None:
            self.adaptive = PatchGrowth(problem, adapt, "QuasiStaticCrackGrowth")
            if all(c is not crack for c in problem.patch.cracks):
                raise ValueError(
                    "the crack is not one of the patch's cracks (ParticlePatch(..., cracks=[...]) "
                    "or patch.add_crack): the grown patch could not carry it"
                )
        self.increment, self.steps, self.K_Ic = float(increment), int(steps), K_Ic
        self.radius, self.sif_options = radius, sif_options
        #: The record, one :class:`GrowthStep` per step run.
        self.history: list[GrowthStep] = []
        #: The last solution.
        self.solution = None
        self._exterior: tuple[Any, np.ndarray] | None = None  # (domain, its boundary segments)
        #: Why :meth:`run` stopped before its steps (a tip at the boundary), else ``None``.
        self.stopped: str | None = None

    @property
    def path(self) -> np.ndarray:
        """The tip positions (m, 2), the initial tip and the tip after each extension."""
        if not self.history:
            return self.crack.points[self.end][None].copy()
        pts = [self.history[0].tip] + [s.new_tip for s in self.history if s.grown]
        return np.array(pts)

    @property
    def events(self) -> list[PatchEvent]:
        """The patch's growth events (``adapt``; empty for a fixed patch)."""
        return [] if self.adaptive is None else self.adaptive.events

    def _radii(self, domain: Any) -> Any:
        """The domains' radii at the current tip: ``radius`` as given, else the default radii
        (``DEFAULT_RADII`` x h) scaled down to fit within 0.9 of the tip segment (the
        interaction integral assumes a straight crack in its domain, so a kink, the previous
        tip, must stay outside it; an increment ``da >= 5.6 h`` keeps them) and to keep
        ``CLEARANCE`` spacings from the body's exterior boundary, down to an outer radius of
        ``MIN_GROWTH_OUTER`` spacings. A tip with less room than that, or than a given outer
        radius, has reached the edge at this resolution: :class:`TipAtBoundary`, naming it.
        Collective (the boundary is gathered once per domain)."""
        h = particle_spacing(domain)
        tip = self.crack.points[self.end]
        if self._exterior is None or self._exterior[0] is not domain:
            self._exterior = (domain, gathered_segments(domain, domain.exterior_facets))
        segments = self._exterior[1]
        d = np.inf
        if len(segments):
            d = float(point_segment_distance(tip[None], segments[:, 0], segments[:, 1]).min())
        if self.radius is not None:  # as given, inside the body (sif_domains' own check)
            r, need, room = self.radius, float(np.max(self.radius)), d
        else:
            b = self.crack.points[1 if self.end == 0 else -2]
            r = np.asarray(DEFAULT_RADII, float) * h
            r = r * min(1.0, 0.9 * float(np.linalg.norm(tip - b)) / r.max())
            need, room = MIN_GROWTH_OUTER * h, d - CLEARANCE * h
            r = r * min(1.0, room / r.max())
        if room < need or (self.radius is not None and room == need):
            raise TipAtBoundary(
                f"QuasiStaticCrackGrowth: the tip at {np.round(tip, 6).tolist()} is {d:.4g} "
                f"({d / h:.3g} spacings) from the body's exterior boundary: the SIF domains "
                f"need {need + d - room:.4g} there (h = {h:.4g}): the crack has reached the "
                "edge at this resolution; refine the particles to follow it further"
                + ("" if self.radius is None else ", or give smaller radius=")
            )
        return r

    def _outer_radius(self) -> float:
        """The SIF domains' outer radius at the current tip."""
        r = self._radii(self.problem.patch)
        return float(np.max(r))

    def _grow_patch(self, step: int, extra_tip: np.ndarray | None) -> None:
        """Ask the criteria with every tip (and the tip the coming extension makes); on an
        event, the model is the rebuilt one from now on (collective)."""
        patch = self.problem.patch
        tips = [c.tips for c in patch.cracks if len(c.tips)]
        if extra_tip is not None:
            tips.append(extra_tip[None])
        tips = np.concatenate(tips) if tips else np.zeros((0, 2))
        sif_radius = self._outer_radius()
        h = particle_spacing(patch)
        for c in self.adaptive.criteria:
            if isinstance(c, NearTips) and c.radius(h, sif_radius) < sif_radius + h:
                k = int(np.ceil(sif_radius / h + 1.0))
                raise ValueError(
                    f"{c!r} keeps the FE interface {c.radius(h, sif_radius):.4g} from the tip "
                    f"at {np.round(tips[-1], 6).tolist()}: inside the SIF domains' outer "
                    f"radius {sif_radius:.4g} plus one spacing (h = {h:.4g}); give spacings "
                    f">= {k}, or NearTips() (the domains plus 2 spacings)"
                )
        ctx = GrowthContext(step, tips, self.solution, sif_radius, self.increment)
        if self.adaptive.grow(ctx, self.local) is not None:
            self.problem = self.adaptive.problem
            if self.update == "local":
                self.local = self.adaptive.local_update(self.problem.patch.cracks)

    def step(self) -> GrowthStep:
        """Solve, compute K at the tip, and grow (if the criterion says so). Collective."""
        crack, end = self.crack, self.end
        if self.adaptive is not None and not self.history:
            self._grow_patch(-1, None)
        tip = crack.points[end].copy()
        direction = crack.tip_direction(end)
        t0 = time.perf_counter()
        sol = self.problem.solve()
        t1 = time.perf_counter()
        domain = getattr(sol, "domain", None) or sol.patch
        radius = self._radii(domain)
        sif = sol.stress_intensity_factors(crack, tip=tip, radius=radius, **self.sif_options)
        t2 = time.perf_counter()
        self.solution = sol
        KI, KII = float(sif.K_I.mean()), float(sif.K_II.mean())
        theta = float(kink_angle(KI, KII))
        keq = float(equivalent_sif(KI, KII))
        grown = self.K_Ic is None or keq >= self.K_Ic
        if grown:
            if self.adaptive is not None:  # the patch carries the new tip before it is made
                new_tip = crack.extension_tip(theta, self.increment, end)
                self._grow_patch(len(self.history), new_tip)
            crack.extend(theta, self.increment, tip=end)
        rec = GrowthStep(
            step=len(self.history), tip=tip, direction=direction, K_I=KI, K_II=KII,
            radius=np.atleast_1d(np.asarray(radius, float)),
            path_dependence=sif.path_dependence, theta=theta, K_eq=keq, grown=grown,
            new_tip=crack.points[end].copy(), time_solve=t1 - t0, time_sifs=t2 - t1,
            timings=dict(getattr(sol, "timings", None) or {}),
            particles=int(domain.particles.num_particles),
        )  # fmt: skip
        self.history.append(rec)
        return rec

    def run(self) -> list[GrowthStep]:
        """Run up to ``steps`` steps; stops early at the first step that does not grow
        (``K_eq < K_Ic``: under fixed loads the crack is stable), or when the tip has reached
        the body's boundary (:class:`TipAtBoundary`: a :class:`GrowthStopped` warning, the
        reason in :attr:`stopped`). Returns :attr:`history`.
        With ``adapt``, a :class:`~dolfinx_meshfree.PatchCriterionWarning` when no criterion
        named any cell in the whole run (the patch never needed growing: is the criterion the
        intended one?)."""
        for _ in range(self.steps):
            try:
                if not self.step().grown:
                    break
            except TipAtBoundary as e:  # on every rank: the boundary is gathered
                self.stopped = str(e)
                warnings.warn(
                    f"the growth stopped after {len(self.history)} step(s): {e}",
                    GrowthStopped,
                    stacklevel=2,
                )
                break
        if self.adaptive is not None and not self.adaptive.selected:
            warn_unused(
                self.adaptive.criteria, "QuasiStaticCrackGrowth", f"{len(self.history)} step(s)"
            )
        return self.history
