"""Dynamic crack growth in explicit dynamics (issue 11, item 2; Belytschko et al. 1995, sec.
5.2.2).

Every ``check_every`` steps K_I and K_II at the tip are computed by the dynamic interaction
integral (:func:`~dolfinx_meshfree.dynamics.sifs.dynamic_sifs`: the inertia term; the
crack-velocity terms of a moving tip are left out, K is that of a stationary tip at the current
state). The crack initiates when the maximum hoop stress reaches its critical value,
``K_eq >= K_Ic`` (:func:`~dolfinx_meshfree.fracture.criteria.equivalent_sif`); the tip then
travels at the prescribed ``speed`` (the paper: 0.15 c_s; at most the Rayleigh speed) and the
crack is extended by one straight segment of length ``segment`` each time the tip has travelled
one segment (the paper's remark: every ``segment / speed`` seconds), in the direction of the
maximum hoop stress (:func:`~dolfinx_meshfree.fracture.criteria.kink_angle`) at that moment;
the tip arrests (the partial segment is dropped) at a check where ``K_eq < K_Ic``, and may
initiate again later.

After each extension the model is updated in place (``update="local"``, the default:
:mod:`~dolfinx_meshfree.dynamics.growth_local`: the particle stiffness and row-sum masses of the
cells whose table rows or rule change near the new segment, then ``M^{-1}``, the multiplier
projection and the stable step; equal to a full rebuild to round-off). Where the change reaches
a constraint row or a particle load, and with ``update="full"``, the model is rebuilt from
scratch by the user's ``build(crack)`` with the grown crack (both sides: tables, cut cells,
masses, constraint rows, the stable step) and the state is carried over unchanged: the FE dofs
and the particle coefficients of ``d_n`` and ``v_{n-1/2}`` (the particles do not move, only
their shape functions change: the remark after eq. 3.11), projected onto the new constraint
``G d = 0``, ``G v = 0`` in the mass metric (a no-op when the constraint rows did not change),
with the step, time and work accounts. The cost of either is measured in
:attr:`DynamicCrackGrowth.timings`. The energy an extension removes (the strain energy of the
old minus the new stiffness at the same ``d_n``: the energy released by the new crack faces)
is recorded per extension.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.optimize import brentq

from ..couplings.ramp import RampInterface
from ..fracture.criteria import equivalent_sif, kink_angle
from ..fracture.interaction import StressIntensityFactors
from ..geometry.crack import (
    Crack,
    gathered_segments,
    particle_spacing,
    point_segment_distance,
    segments_intersect,
)
from ..io import ProgressBar
from ..parallel import raise_on_all_ranks
from ..physics.materials import LinearElastic
from ..statics.growth import GrowthStopped
from ..statics.sifs import CLEARANCE, MIN_OUTER
from .central_difference import advance_to
from .cohesive_faces import CohesiveFacesSystem
from .energy import strain_energy
from .explicit import ExplicitDynamics
from .growth_local import LocalModelUpdate
from .growth_probe import turn_to_fit
from .patch_conversion import ConvertingPatch, carry_clock
from .sifs import dynamic_sifs, model_cracks
from .system import wrapped

__all__ = ["DYNAMIC_UPDATES", "DynamicCrackGrowth", "GrowthCheck", "rayleigh_speed"]

#: How an extension updates the model.
DYNAMIC_UPDATES = ("local", "full")

Build = Callable[[Crack], ExplicitDynamics]


def rayleigh_speed(material: LinearElastic) -> float:
    """The Rayleigh wave speed ``c_R`` of ``material`` (root of ``(2 - x)^2 = 4 sqrt(1 - k x)
    sqrt(1 - x)``, ``x = c_R^2 / c_s^2``, ``k = c_s^2 / c_d^2`` of the plane law)."""
    cs = float(np.sqrt(material.mu / material.rho))
    k = (cs / material.wave_speed()) ** 2

    def f(x: float) -> float:
        return (2.0 - x) ** 2 - 4.0 * np.sqrt(1.0 - k * x) * np.sqrt(1.0 - x)

    return cs * float(np.sqrt(brentq(f, 1e-6, 1.0 - 1e-14, xtol=1e-15)))


@dataclass
class GrowthCheck:
    """One check of :class:`DynamicCrackGrowth`.

    Attributes:
        step: The model's step.
        time: The model's time.
        tip: The tip (2,) at which K was computed.
        K_I: Mean over the domain radii.
        K_II: Mean over the domain radii.
        theta: Kink angle (radians, counterclockwise from the tip direction).
        K_eq: The equivalent SIF.
        state: ``"below"`` (K_eq < K_Ic, not growing), ``"initiated"``, ``"growing"``,
            ``"arrested"``.
        extended: A segment was added at this check (the model rebuilt).
        new_tip: The tip after it.
        turn: Degrees the segment was turned off ``theta`` so that the crack-aware MLS can
            carry it (:func:`~dolfinx_meshfree.dynamics.growth_probe.turn_to_fit`; 0 for the
            criterion's segment, or when nothing grew).
    """

    step: int
    time: float
    tip: np.ndarray
    K_I: float
    K_II: float
    theta: float
    K_eq: float
    state: str
    extended: bool
    new_tip: np.ndarray
    turn: float = 0.0

    def as_dict(self) -> dict:
        """Plain lists and floats (for JSON)."""
        d = asdict(self)
        d["tip"], d["new_tip"] = self.tip.tolist(), self.new_tip.tolist()
        return d


def _at_edge(model: ExplicitDynamics, crack: Crack, end: int, theta: float, length: float,
             exterior: np.ndarray, room: float) -> str | None:  # fmt: skip
    """Why the segment of ``length`` at ``theta`` from the tip ``end`` is not grown: it
    crosses the body's exterior boundary (``exterior``, (k, 2, 2) segments; the crack would
    split the body), or it ends nearer to it than ``room`` (the SIF domains' outer radius: K
    could not be taken at the new tip); ``None`` otherwise."""
    tip = crack.points[end]
    new = crack.extension_tip(theta, length, end)
    if not len(exterior):
        return None
    a, b = exterior[:, 0], exterior[:, 1]
    if segments_intersect(tip[None], new[None], a, b).any():
        why = "across the body's exterior boundary: the crack would split the body"
    elif (d := float(point_segment_distance(new[None], a, b).min())) <= room:
        why = (f"{d:.6g} from the body's exterior boundary, within the SIF domains' outer "
               f"radius {room:.6g}: K could not be taken there")  # fmt: skip
    else:
        return None
    return (
        f"DynamicCrackGrowth: at step {model.step}, t = {model.time:.6g}, the tip at "
        f"{np.round(tip, 12).tolist()} would grow by {length:.6g} at {np.degrees(theta):.4g} "
        f"deg to {np.round(new, 12).tolist()}, {why}. The crack has reached the edge at this "
        "resolution, and the growth does not follow it further: the run stops here with the "
        "crack as it is (the model is growth.model, at this time); refine the particles near "
        "the edge, or give smaller radius=, to follow it closer"
    )


def _edge_stop(growth: DynamicCrackGrowth, theta: float) -> str | None:
    """Why ``growth``'s next segment (at ``theta``) is not grown (:func:`_at_edge`: it would
    cross the body's exterior boundary, or end within the SIF domains' outer radius of it:
    ``radius``, or the default domains' least room), else ``None``. :meth:`DynamicCrackGrowth.run
    <dolfinx_meshfree.dynamics.DynamicCrackGrowth.run>` then stops at that check with a
    :class:`~dolfinx_meshfree.GrowthStopped` warning, the reason in ``growth.stopped``.
    Collective (the boundary is gathered once per model's domain)."""
    dyn = growth.model
    domain = model_cracks(dyn)[1]
    if growth._exterior is None or growth._exterior[0] is not domain:
        growth._exterior = (domain, gathered_segments(domain, domain.exterior_facets))
    room = (MIN_OUTER + CLEARANCE) * particle_spacing(domain)
    if growth.radius is not None:
        room = float(np.max(growth.radius))
    return _at_edge(dyn, growth.crack, growth.end, theta, growth.segment, growth._exterior[1], room)


def _positive(name: str, value: object, what: str) -> float:
    if isinstance(value, bool) or not (
        isinstance(value, int | float | np.floating) and np.isfinite(value) and value > 0
    ):
        raise ValueError(f"{name}={value!r} must be a positive number ({what})")
    return float(value)


class DynamicCrackGrowth:
    """Dynamic growth of one tip of ``crack`` in an explicit model (module docstring).

    Args:
        build: ``build(crack) -> ExplicitDynamics``: the model with ``crack`` among its cracks,
            its loads and conditions (called once at the start and after every extension with
            a fresh copy of the grown crack; the same mesh and particles every time).
        crack: The initial crack (copied: the caller's object is not changed).
        K_Ic: The fracture toughness (> 0).
        speed: The prescribed tip speed (> 0, at most the Rayleigh speed
            :func:`rayleigh_speed`; the paper: ``0.15 c_s``).
        segment: The length of a straight crack segment (> 0; a few particle spacings, larger
            than the outer domain radius).
        check_every: Steps between two evaluations of K (>= 1); ``check_every * dt * speed``
            must not exceed ``segment``.
        tip: The end to grow, 0 or -1 (default: the only tip).
        radius: Outer domain radii of the interaction integral (default that of
            :func:`~dolfinx_meshfree.dynamics.sifs.dynamic_sifs`).
        dt: The time step; ``None``: the stable step of each (re)built model. A given ``dt``
            above the stable step of a rebuilt model is refused (a ``ValueError``).
        update: ``"local"`` (default): update the model in place near the new segment
            (:class:`~dolfinx_meshfree.dynamics.growth_local.LocalModelUpdate`; ``build`` must
            put the crack it is given in the model, which is then extended in place), falling
            back to a rebuild where the change reaches a constraint row or a particle load,
            and for the ramps (their blended interface cells) and master-slave (its particle
            field is expanded from FE dofs and masters; ``timings["full"]`` counts the
            rebuilds); crack-face contact's gap operator is rebuilt for the grown faces;
            ``"full"``: call ``build`` after every extension.
        quadrature_degree: The degree of the model's cell rule (``update="local"``; the
            builders' default 7; checked on the masses around the tip).
        adapt: A patch that grows during the run (issue 25): ``mf.NearTips(spacings=k)`` (or
            ``mf.FieldAbove`` on the current displacement, ``mf.CellsWhere``, or a list), asked
            before the first step and before each
            extension with the tip the extension will make. The FE cells it names become
            particles: ``build(crack, cells=cells)`` rebuilds the model on the larger patch
            (``cells``: this rank's patch cells, for ``mf.ParticlePatch(mesh, cells, ...)``)
            and the state is carried over by
            :func:`~dolfinx_meshfree.dynamics.patch_conversion.convert` (mass and momentum
            conserved, the energy change recorded in :attr:`conversions` and counted in
            :attr:`released`). Every coupling (master-slave at finite strain only with links of
            length zero). Default ``None``: the patch is fixed.
        fit_segments: Turn a segment that the crack-aware MLS could not carry by up to 15
            degrees (:func:`~dolfinx_meshfree.dynamics.growth_probe.turn_to_fit`; each turn in
            ``GrowthCheck.turn``). ``False``: every segment in the criterion's direction (the
            paper's), and a model that cannot be built on it stops the run.
        sif_options: More keywords of :func:`~dolfinx_meshfree.dynamics.sifs.dynamic_sifs`.

    Example::

        growth = DynamicCrackGrowth(build, crack, K_Ic=68e6, speed=0.15 * cs, segment=4 * h)
        growth.run(80e-6)
        growth.path                  # the crack tip after each extension
        growth.KI_history()          # [[t, K_I], ...]

    Attributes:
        model: The current :class:`ExplicitDynamics`. crack: The current crack (the model's).
        history: One :class:`GrowthCheck` per check. released: ``(time, energy)`` per extension.
        timings: Seconds in ``steps``, ``sifs``, ``rebuild`` (total of the extensions,
            local or full), ``rebuilds`` (count of extensions), ``local`` and ``full`` (counts
            by kind), ``per_step``.
        local: The :class:`~dolfinx_meshfree.dynamics.growth_local.LocalModelUpdate` of the
            current model (``None`` with ``update="full"``).
    """

    def __init__(
        self,
        build: Build,
        crack: Crack,
        K_Ic: float,
        speed: float,
        segment: float,
        check_every: int = 10,
        tip: int | None = None,
        radius: float | Sequence[float] | None = None,
        dt: float | None = None,
        update: str = "local",
        quadrature_degree: int = 7,
        adapt: Any = None,
        fit_segments: bool = True,
        **sif_options,
    ) -> None:
        if not callable(build):
            raise ValueError(f"build={build!r:.80} must be a callable build(crack) -> model")
        if not isinstance(crack, Crack):
            raise ValueError(f"crack={crack!r:.80} should be a dolfinx_meshfree.Crack")
        self.K_Ic = _positive("K_Ic", K_Ic, "the fracture toughness")
        self.speed = _positive("speed", speed, "the prescribed crack tip speed")
        self.segment = _positive("segment", segment, "the length of a crack segment")
        if isinstance(check_every, bool) or not isinstance(check_every, int) or check_every < 1:
            raise ValueError(f"check_every={check_every!r} must be an integer >= 1 (steps)")
        self.dt = None if dt is None else _positive("dt", dt, "the time step")
        if update not in DYNAMIC_UPDATES:
            raise ValueError(f"update={update!r} is not known; use one of {DYNAMIC_UPDATES}")
        deg = quadrature_degree
        if isinstance(deg, bool) or not isinstance(deg, int | np.integer) or deg < 1:
            raise ValueError(
                f"quadrature_degree={deg!r} must be an integer >= 1 (the degree of the model's "
                "cell rule; the builders' default is 7)"
            )
        self.update, self.quadrature_degree = update, int(deg)
        if not isinstance(fit_segments, bool | np.bool_):
            raise ValueError(f"fit_segments={fit_segments!r} must be True or False")
        self.fit_segments = bool(fit_segments)
        self.check_every, self.radius, self.sif_options = check_every, radius, sif_options
        self.build = build
        self.timings = {"steps": 0.0, "sifs": 0.0, "rebuild": 0.0, "rebuilds": 0, "setup": 0.0,
                        "local": 0, "full": 0}  # fmt: skip
        #: ``(step, K's)`` taken at the last step of :meth:`_advance`, for the check there
        self._sifs_at: tuple[int, StressIntensityFactors] | None = None
        tic = time.perf_counter()
        self.crack = Crack(crack.points.copy())
        self.model = build(self.crack)
        self.timings["setup"] = time.perf_counter() - tic
        comm = self.model.comm

        def check() -> int:
            if not isinstance(self.model, ExplicitDynamics):
                raise ValueError(f"build(crack) returned {self.model!r:.80}, not ExplicitDynamics")
            mat = self.model.material
            if not isinstance(mat, LinearElastic):
                raise ValueError(f"material={mat!r}: dynamic growth needs LinearElastic")
            if wrapped(self.model.system, CohesiveFacesSystem):
                raise ValueError(
                    "DynamicCrackGrowth grows a traction-free crack by K_Ic; the model's cracks "
                    "carry cohesive faces (add_cohesive), whose operators its local updates do "
                    "not follow: build the problem without add_cohesive"
                )
            cr = rayleigh_speed(mat)
            if self.speed > cr:
                raise ValueError(
                    f"speed={self.speed!r} is above the Rayleigh speed c_R={cr:.6g} (c_s="
                    f"{np.sqrt(mat.mu / mat.rho):.6g}): a mode-I crack cannot run faster; "
                    f"the paper uses 0.15 c_s"
                )
            ends = self.crack.tip_ends
            if tip is None:
                if len(ends) != 1:
                    raise ValueError(f"the crack has tips at ends {ends}: give tip=0 or tip=-1")
                return ends[0]
            if isinstance(tip, bool) or tip not in ends:
                raise ValueError(f"tip={tip!r} is not a tip end of the crack (ends {ends})")
            return int(tip)

        self.end = raise_on_all_ranks(comm, check)
        #: The :class:`~dolfinx_meshfree.dynamics.patch_conversion.ConvertingPatch` (``adapt``).
        self.adaptive = None
        if adapt is not None:
            r = None if radius is None else float(np.max(radius))
            self.adaptive = ConvertingPatch(adapt, self.model, build, r, self.segment)
        self.timings["conversions"] = 0
        self.local: LocalModelUpdate | None = None
        self._start_local()
        if radius is None:  # after the model's own refusals
            _check_default_domains(self.model, self.segment)
        self.history: list[GrowthCheck] = []
        self.released: list[tuple[float, float]] = []
        self.path_points: list[np.ndarray] = [self.crack.points[self.end].copy()]
        self._growing, self._travelled = False, 0.0
        #: Why :meth:`run` stopped before ``t_end`` (the crack reached the edge), else ``None``.
        self.stopped: str | None = None
        self._exterior: tuple[Any, np.ndarray] | None = None  # (domain, its boundary segments)

    def _start_local(self) -> None:
        """The local update of the current model (``update="local"``; collective)."""
        if self.update != "local":
            return
        # the ramps' blended cells and master-slave's expanded particle field have no local
        # update (LocalModelUpdate refuses them): their models are rebuilt in full
        if isinstance(self.model.interface, RampInterface) or self.model.reduction is not None:
            self.local = None
            return
        ours = any(c is self.crack for c in model_cracks(self.model)[0])

        def check() -> None:
            if not ours:
                raise ValueError(
                    "update='local': the model built by build(crack) does not hold the crack it "
                    "was given (the local update extends it in place); put that Crack object in "
                    "the model, or pass update='full'"
                )

        raise_on_all_ranks(self.model.comm, check)
        self.local = LocalModelUpdate(self.model, self.quadrature_degree)

    # --- results ------------------------------------------------------------------------------
    @property
    def path(self) -> np.ndarray:
        """The tip positions (m, 2), the initial tip and the tip after each extension."""
        return np.array(self.path_points)

    def KI_history(self) -> list[list[float]]:
        """``[[t, K_I], ...]`` at every check."""
        return [[c.time, c.K_I] for c in self.history]

    def KII_history(self) -> list[list[float]]:
        """``[[t, K_II], ...]`` at every check."""
        return [[c.time, c.K_II] for c in self.history]

    @property
    def initiation(self) -> GrowthCheck | None:
        """The first check at which the crack initiated, or ``None``."""
        return next((c for c in self.history if c.state == "initiated"), None)

    # --- the loop -----------------------------------------------------------------------------
    def _time_step(self) -> float:
        """The step of the current model: ``dt`` (refused above the stable step) or the stable
        one; ``check_every * dt * speed <= segment`` (collective)."""
        dyn = self.model
        stable = dyn.stable_time_step()

        def check() -> float:
            dt = stable if self.dt is None else self.dt
            if dt > stable * (1.0 + 1e-12):
                tipx = np.round(self.crack.points[self.end], 12).tolist()
                raise ValueError(
                    f"dt={dt:.6g} is above the stable time step {stable:.6g} of the model rebuilt "
                    f"or updated at step {dyn.step}, t = {dyn.time:.6g} (tip {tipx}): the masses "
                    f"changed; pass dt <= {stable:.6g} or dt=None (the stable step of each model)"
                )
            if self.check_every * dt * self.speed > self.segment * (1.0 + 1e-12):
                raise ValueError(
                    f"check_every={self.check_every} steps of dt={dt:.6g} at speed={self.speed:.6g}"
                    f" cover {self.check_every * dt * self.speed:.6g}, more than segment="
                    f"{self.segment:.6g}: lower check_every or lengthen the segment"
                )
            return dt

        return raise_on_all_ranks(dyn.comm, check)

    def _advance(self, nsteps: int, dt: float) -> None:
        """``nsteps`` steps of ``dt``; the K's of the next check are taken at the last step,
        inside the run, where the step's own internal force serves their acceleration
        (:meth:`~dolfinx_meshfree.dynamics.central_difference.CentralDifference.force_now`: the
        same K's without a second product; kept for :meth:`check` at that step only)."""
        dyn = self.model
        spent = [0.0]

        def at_end(step: int, t: float) -> None:
            tic = time.perf_counter()
            self._sifs_at = (step, self._sifs())
            spent[0] += time.perf_counter() - tic

        tic = time.perf_counter()
        t_end = dyn.time + nsteps * dt
        advance_to(
            dyn.stepper, dyn.bound, t_end, nsteps, dt, (t_end,), 1, at_end,
            lambda n: ProgressBar(n, dyn.comm, False),
        )  # fmt: skip
        self.timings["steps"] += time.perf_counter() - tic - spent[0]
        self.timings["sifs"] += spent[0]

    def _sifs(self) -> StressIntensityFactors:
        """K at the running tip at the model's current state (collective)."""
        # the criterion uses K only: no near-tip probe (the reliability figures' extra annuli)
        return dynamic_sifs(
            self.model, self.crack, self.crack.points[self.end].copy(), self.radius,
            probe=False, j_integral=False, **self.sif_options,
        )  # fmt: skip

    def check(self) -> GrowthCheck:
        """K at the tip at the current state, the criterion, and an extension when the tip
        has travelled one segment (collective)."""
        dyn, crack, end = self.model, self.crack, self.end
        tip = crack.points[end].copy()
        kept, self._sifs_at = self._sifs_at, None
        if kept is not None and kept[0] == dyn.step:  # taken at the end of the last advance
            sif = kept[1]
        else:
            tic = time.perf_counter()
            sif = self._sifs()
            self.timings["sifs"] += time.perf_counter() - tic
        KI, KII = float(sif.K_I.mean()), float(sif.K_II.mean())
        theta, keq = float(kink_angle(KI, KII)), float(equivalent_sif(KI, KII))
        grows = keq >= self.K_Ic
        last = self.history[-1].time if self.history else dyn.time
        if grows and not self._growing:
            state, self._travelled = "initiated", 0.0
        elif grows:
            state = "growing"
            self._travelled += self.speed * (dyn.time - last)
        else:
            state = "arrested" if self._growing else "below"
        self._growing = grows
        extended = grows and self._travelled >= self.segment * (1.0 - 1e-9)
        turn = 0.0
        if extended and self.fit_segments:  # a segment the MLS could not carry: turned a little
            turn = turn_to_fit(dyn, self.crack, self.end, theta, self.segment,
                               self.quadrature_degree)  # fmt: skip
        if extended:  # the segment as grown, not across the body's edge (else the run stops)
            self.stopped = _edge_stop(self, theta + np.deg2rad(turn))
            extended = self.stopped is None
            turn = turn if extended else 0.0
        if extended:
            self._travelled -= self.segment
            self._extend(theta + np.deg2rad(turn))
        rec = GrowthCheck(
            step=dyn.step, time=dyn.time, tip=tip, K_I=KI, K_II=KII, theta=theta, K_eq=keq,
            state=state, extended=extended, new_tip=self.crack.points[self.end].copy(),
            turn=turn,
        )  # fmt: skip
        self.history.append(rec)
        return rec

    def _extend(self, theta: float) -> None:
        """Extend the crack by one segment at ``theta`` and rebuild the model, carrying the
        state over (collective)."""
        tic = time.perf_counter()
        if self.adaptive is not None and self._convert(theta):  # grown and extended at once
            self.path_points.append(self.crack.points[self.end].copy())
            self.timings["rebuild"] += time.perf_counter() - tic
            self.timings["rebuilds"] += 1
            return
        old, crack, end = self.model, self.crack, self.end
        plan = None
        if self.local is not None:
            trial = Crack(crack.points.copy())
            self._grow(trial, theta)
            plan = self.local.prepare(trial.points, crack)
        self._grow(crack, theta)  # validated in the patch on every rank
        if plan is not None:
            self.released.append((old.time, self.local.apply(plan)))
            self.timings["local"] += 1
        else:
            grown = Crack(crack.points.copy())
            if self.adaptive is None:
                new = self.build(grown)
            else:  # the grown patch's cells
                new = self.build(grown, cells=old.patch.cells)
            self.released.append((old.time, carry_state(old, new)))
            old.destroy()
            self.model, self.crack = new, grown
            self.timings["full"] += 1
            self._start_local()
        self.path_points.append(self.crack.points[end].copy())
        self.timings["rebuild"] += time.perf_counter() - tic
        self.timings["rebuilds"] += 1

    def _convert(self, theta: float | None) -> bool:
        """``adapt``: grow the patch where the criteria say (about the tips and, with ``theta``,
        the tip that the coming extension will make), rebuild the model on it (with that
        extension: one rebuild for both) and carry the state
        (:func:`~dolfinx_meshfree.dynamics.patch_conversion.convert`). The energy the event
        changes (the extension's release and the conversion's) joins :attr:`released`.
        Returns whether it happened (collective)."""
        crack, end = self.crack, self.end
        new_tip = None
        if theta is not None:
            new_tip = crack.extension_tip(theta, self.segment, end)
        grown = Crack(crack.points.copy(), through=crack.through)

        def rebuild(cells: np.ndarray) -> ExplicitDynamics:
            if theta is not None:  # the extension that asked for the growth, in one rebuild
                self._grow(grown, theta)
            return self.build(grown, cells=cells)

        new = self.adaptive.grow(self.model, rebuild, new_tip)
        if new is None:
            return False
        old = self.model
        self.model, self.crack = new, grown
        self.released.append((old.time, -self.adaptive.conversions[-1].energy_change))
        old.destroy()
        self.timings["conversions"] += 1
        self._start_local()
        return True

    @property
    def conversions(self) -> list:
        """The :class:`~dolfinx_meshfree.dynamics.patch_conversion.Conversion` records
        (``adapt``; empty for a fixed patch)."""
        return [] if self.adaptive is None else self.adaptive.conversions

    def _grow(self, crack: Crack, theta: float) -> None:
        """``crack.extend`` by one segment at ``theta``, its refusal naming the step, the time
        and the tip."""
        tip = crack.points[self.end].copy()
        try:
            crack.extend(theta, self.segment, tip=self.end)
        except ValueError as e:
            raise ValueError(
                f"dynamic crack growth stopped at step {self.model.step}, t = "
                f"{self.model.time:.6g}: the tip at {np.round(tip, 12).tolist()} cannot advance "
                f"by {self.segment:.6g} at {np.degrees(theta):.4g} deg: {e}"
            ) from e

    def run(self, t_end: float) -> list[GrowthCheck]:
        """Run to ``t_end``, checking every ``check_every`` steps (the last chunk may be
        shorter; a check at the start too). Returns :attr:`history` (collective). With
        ``adapt``, a :class:`~dolfinx_meshfree.PatchCriterionWarning` (once) if the criteria
        have named no cell by then.

        A segment that would reach the body's edge stops the run (:attr:`stopped`).

        Raises:
            ValueError: on every rank: ``t_end`` not a positive number; ``dt`` above the stable
                step of a (rebuilt) model; ``check_every * dt * speed > segment``; a segment
                that would leave the particles for FE cells (naming the step, the time and the
                tip).
        """
        t_end = _positive("t_end", t_end, "the final time")
        self.stopped = None  # a check that would cross the edge says so again
        if not self.history:
            if self.adaptive is not None:  # the patch about the initial tip
                tic = time.perf_counter()
                self._convert(None)
                self.timings["rebuild"] += time.perf_counter() - tic
            self.check()
        while self.stopped is None and self.model.time < t_end * (1.0 - 1e-12):
            dt = self._time_step()
            left = int(np.ceil((t_end - self.model.time) / dt - 1e-9))
            n = min(self.check_every, left)
            self._advance(n, min(dt, (t_end - self.model.time) / n) if n == left else dt)
            self.check()
        if self.stopped is not None:  # the same on every rank (the boundary is gathered)
            warnings.warn(self.stopped, GrowthStopped, stacklevel=2)
        steps = max(1, self.model.step)
        self.timings["per_step"] = self.timings["steps"] / steps
        if self.adaptive is not None:
            self.adaptive.finish("DynamicCrackGrowth", f"{len(self.history)} check(s)")
        return self.history


def _check_default_domains(model: ExplicitDynamics, segment: float) -> None:
    """The default SIF domains (``radius=None``) must fit behind a tip after a kink: a
    ``ValueError`` on every rank for a ``segment`` shorter than they need (collective)."""
    domain = model_cracks(model)[1]
    if domain is None:  # no cracks: the first check says so
        return

    def fits() -> None:
        h = particle_spacing(domain)
        need = MIN_OUTER + CLEARANCE
        if segment < need * h * (1.0 - 1e-9):
            raise ValueError(
                f"segment={segment:.6g} is {segment / h:.3g} particle spacings (h = {h:.6g}): "
                "after an extension the crack kinks that far behind the tip, and the default "
                f"SIF domains need {need:g} spacings of straight crack there (statics' "
                "sif_domains); give radius= with outer radii below the segment (e.g. radius="
                f"[{2 * h:.6g}, {3 * h:.6g}], 2 and 3 spacings, as demos/kalthoff_winkler.py with "
                f"its 3.5-spacing segments) or a segment of at least {need * h:.6g}"
            )

    raise_on_all_ranks(model.comm, fits)


def carry_state(old: ExplicitDynamics, new: ExplicitDynamics) -> float:
    """Copy ``d_n``, ``v_{n-1/2}`` (FE dofs and particle coefficients), the step, time and the
    work accounts of ``old`` into ``new`` (the same mesh and particles), projected onto the new
    constraint. Returns the strain energy the new stiffness releases at ``d_n`` (collective)."""
    so, sn = old.stepper, new.stepper

    def check() -> None:
        for a, b in zip(so.u, sn.u, strict=True):
            if a.getSize() != b.getSize() or a.getLocalSize() != b.getLocalSize():
                raise ValueError(
                    f"the rebuilt model has {b.getSize()} dofs in a field where the old one had "
                    f"{a.getSize()}: build(crack) must keep the mesh and the particles"
                )

    raise_on_all_ranks(old.comm, check)
    for src, dst in ((so.u, sn.u), (so.v, sn.v)):
        for a, b in zip(src, dst, strict=True):
            a.copy(b)
    carry_clock(old, new)
    return strain_energy(old.system, so.u) - strain_energy(new.system, sn.u)
