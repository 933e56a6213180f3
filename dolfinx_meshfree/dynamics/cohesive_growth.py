"""Cohesive cracks that find their path in explicit dynamics (issue 24: "cohesive cracks in
dynamics"; the dynamic counterpart of :class:`~dolfinx_meshfree.CohesiveGrowth`).

:class:`CohesiveDynamicGrowth` runs a model whose crack carries cohesive faces
(:mod:`~dolfinx_meshfree.dynamics.cohesive_faces`) ``check_every`` steps at a time. Between
chunks, a tip whose softening front (the nearest face point past ``f_t``) has come within
``ahead`` particle spacings of it grows by one step, by the rule of statics
(:func:`~dolfinx_meshfree.statics.cohesive_growth.extension`): normal to the principal stress
averaged about the front, to the edge at a right angle when it gets there. The model is then
rebuilt by the user's ``build(crack)`` on the longer crack, and the state carried over:
- the FE dofs and the particle coefficients of displacement and velocity are copied;
- the coefficients of the particles whose supports the new segment cuts are refitted, by
  least squares off the crack, to the fields before it grew (both fields; statics'
  ``_FieldFit``). With the old coefficients the one-sided fields would differ across the new
  bonded faces, a jump the penalty turns into a spurious force and energy;
- the faces' states are carried where their points lie
  (:func:`~dolfinx_meshfree.dynamics.cohesive_faces.carry_faces`);
- the strain energy the rebuild changes is recorded (:attr:`CohesiveDynamicGrowth.released`).

The tips keep ``ahead`` spacings of bonded faces ahead of the softening front, so the faces
soften before the tip arrives, as in statics.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..approx.mls import MomentMatrixError
from ..geometry.crack import Crack, CrackDomain, particle_spacing
from ..parallel import raise_on_all_ranks
from ..physics.materials import LinearElastic
from ..statics.cohesive_growth import CohesiveGrowth, _FieldFit, extension, nearest_softened
from ..statics.sides import particle_coefficients
from .cohesive_faces import CohesiveFacesSystem, carry_faces
from .energy import strain_energy
from .explicit import ExplicitDynamics
from .patch_conversion import carry_clock
from .system import wrapped

if TYPE_CHECKING:  # annotations only
    from collections.abc import Callable

    from petsc4py import PETSc

__all__ = ["CohesiveDynamicGrowth"]


def _scatter(model: ExplicitDynamics, vec: PETSc.Vec, coefficients: np.ndarray) -> None:
    """Set this rank's part of a particle-field vector from replicated coefficients (N, gdim)."""
    P = model.particles
    gdim = P.gdim
    by_petsc = np.empty_like(coefficients)
    by_petsc[P.petsc_index] = coefficients
    lo, hi = vec.getOwnershipRange()
    vec.array[:] = by_petsc.reshape(-1, gdim).ravel()[lo:hi]


class CohesiveDynamicGrowth:
    """A cohesive crack that finds its path in explicit dynamics (module docstring).

    Args:
        build: ``build(crack) -> ExplicitDynamics``: the model with its loads and conditions,
            ``crack`` among its cracks with cohesive faces on the segment at each tip (a
            ``CoupledElasticity`` with ``add_cohesive``, or ``ExplicitDynamics.efg(...,
            cohesive=...)``). Called again on each longer crack: it must keep the mesh and the
            particles.
        crack: The starting crack (copied; the model's is :attr:`crack`).
        growth: The rule's lengths (``ahead``, ``step``, ``radius``, ``clearance`` in particle
            spacings; ``max_extensions`` per check), as :class:`~dolfinx_meshfree.CohesiveGrowth`
            (its ``crack`` is ignored). Default: its defaults.
        check_every: Steps between two checks (>= 1).

    Attributes:
        model: The current :class:`~dolfinx_meshfree.ExplicitDynamics` (a new object after each
            extension; the old one is destroyed). crack: Its crack.
        extensions: ``(time, new tip)`` per extension.
        turns: Per extension, the degrees its segment was turned off the stress criterion's
            direction to keep its far half ``NEAR_ROW`` spacing off every particle
            (:data:`~dolfinx_meshfree.statics.cohesive_growth.TURNS`; 0 where it passes clear).
        released: ``(time, energy)`` per extension: the strain energy the rebuild and the refit
            changed (the old model's at its state minus the new one's at the carried state).
    """

    def __init__(
        self,
        build: Callable[[Crack], ExplicitDynamics],
        crack: Crack,
        growth: CohesiveGrowth | None = None,
        check_every: int = 10,
    ) -> None:
        if not callable(build):
            raise ValueError(f"build={build!r:.80} must be a callable build(crack) -> model")
        if not isinstance(crack, Crack):
            raise TypeError(f"crack must be a Crack, got {type(crack).__name__}")
        if isinstance(check_every, bool) or not isinstance(check_every, int) or check_every < 1:
            raise ValueError(f"check_every={check_every!r} must be an integer >= 1 (steps)")
        if growth is not None and not isinstance(growth, CohesiveGrowth):
            raise TypeError(f"growth must be a CohesiveGrowth or None, got {type(growth).__name__}")
        self.build, self.check_every = build, check_every
        self.crack = Crack(crack.points.copy(), through=crack.through)
        self.rule = replace(growth or CohesiveGrowth(self.crack), crack=self.crack)
        self.model = build(self.crack)
        raise_on_all_ranks(self.model.comm, self._check)
        self.extensions: list[tuple[float, list[float]]] = []
        self.turns: list[float] = []
        self.released: list[tuple[float, float]] = []

    def _faces(self) -> tuple[CohesiveFacesSystem, int]:
        """The model's cohesive faces and the index of the crack's among them."""
        found = wrapped(self.model.system, CohesiveFacesSystem)
        k = next((i for i, c in enumerate(found[0].cracks) if c is self.crack), -1) if found else -1
        return (found[0] if found else None), k

    def _check(self) -> None:
        if not isinstance(self.model, ExplicitDynamics):
            raise ValueError(f"build(crack) returned {self.model!r:.80}, not ExplicitDynamics")
        if not isinstance(self.model.material, LinearElastic):
            raise ValueError(
                f"material={type(self.model.material).__name__}: cohesive growth in dynamics is "
                "small strain (LinearElastic)"
            )
        _, k = self._faces()
        if k < 0:
            raise ValueError(
                f"the model built by build(crack) carries no cohesive faces on {self.crack!r}: "
                "put that Crack object in the model with its law (add_cohesive, or "
                "ExplicitDynamics.efg(..., cohesive=[(crack, law)]))"
            )
        if not self.crack.tip_ends:
            raise ValueError(f"{self.crack!r} has no tip (it splits the body already)")

    @property
    def _domain(self) -> object:
        m = self.model
        return m.patch if m.patch is not None else CrackDomain.from_particles(m.particles)

    def _front(self, tip: np.ndarray) -> np.ndarray | None:
        """The face point nearest ``tip`` past ``f_t`` (committed), or ``None`` (collective)."""
        faces, k = self._faces()
        return nearest_softened(faces.states[k], faces.faces[k][1].w_0, tip, self.model.comm)

    def _grow(self) -> bool:
        """Extend a tip whose softening front is near, rebuild and carry (collective); whether
        it grew."""
        old = self.model
        domain = self._domain
        h = particle_spacing(domain)
        for end in self.crack.tip_ends:
            tip = self.crack.points[end].copy()
            front = self._front(tip)
            if front is None or np.linalg.norm(front - tip) >= self.rule.ahead * h:
                continue
            faces, _ = self._faces()
            field = faces.field
            P = old.particles  # the coefficients, replicated, by particle (collective)
            u, v = (particle_coefficients(P, x[field]).reshape(-1, P.gdim) for x in (old.u, old.v))
            d, length, turn = extension(self.rule, old.mls, u, old.material, domain, h, end, front)
            b = tip + length * d
            fits = [_FieldFit(old.mls, c, self.crack, tip, b, domain, h) for c in (u, v)]
            energy_old = strain_energy(old.system, old.stepper.u)
            self.crack.extend(d, length, tip=end)
            u, v = (fit.refit(old.comm).reshape(u.shape) for fit in fits)
            grown = Crack(self.crack.points.copy(), through=self.crack.through)
            try:
                new = self.build(grown)
            except MomentMatrixError as err:  # raised on every rank
                raise RuntimeError(
                    f"at t = {old.time:.6g} the crack grew to {grown.points[end].round(6).tolist()}"
                    f" and the MLS cannot be evaluated beside it ({err}); choose a finer particle "
                    "spacing or a larger dilation"
                ) from None
            for src, dst in ((old.stepper.u, new.stepper.u), (old.stepper.v, new.stepper.v)):
                for a, b in zip(src, dst, strict=True):  # the same mesh and particles
                    a.copy(b)
            carry_clock(old, new)  # the step, the time and the work accounts
            _scatter(new, new.stepper.u[field], u)
            _scatter(new, new.stepper.v[field], v)
            carry_faces(old.system, new.system)
            self.released.append((old.time, energy_old - strain_energy(new.system, new.stepper.u)))
            old.destroy()
            self.model, self.crack = new, grown
            self.rule = replace(self.rule, crack=grown)
            raise_on_all_ranks(new.comm, self._check_faces)
            self.extensions.append((new.time, grown.points[end].tolist()))
            self.turns.append(turn)
            return True
        return False

    def _check_faces(self) -> None:
        _, k = self._faces()
        if k < 0:
            raise ValueError("build(crack) did not put the grown crack's faces in the model")

    def run(self, t_end: float) -> ExplicitDynamics:
        """Run to ``t_end`` (collective), checking every ``check_every`` steps; returns the
        final model. RuntimeError when a tip grows ``max_extensions`` times at one check (the
        crack would run faster than the checks: lower ``check_every``)."""
        while self.model.time < t_end * (1.0 - 1e-12):
            dt = self.model.stable_time_step()
            n = min(self.check_every, max(1, math.ceil((t_end - self.model.time) / dt - 1e-9)))
            self.model.run(min(t_end, self.model.time + n * dt), dt=dt, energy_records=1)
            if not self.crack.tip_ends:
                continue
            for _ in range(self.rule.max_extensions):
                if not self._grow() or not self.crack.tip_ends:
                    break
            else:
                raise RuntimeError(
                    f"at t = {self.model.time:.6g} the crack grew {self.rule.max_extensions} "
                    "times at one check and its softening front is still near the tip: it runs "
                    "faster than the checks; lower check_every"
                )
        return self.model
