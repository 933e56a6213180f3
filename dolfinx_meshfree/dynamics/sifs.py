"""Dynamic stress intensity factors of an explicit model at its current state: the domain
interaction integral with the inertia term (Moran & Shih 1987; Belytschko et al. 1995, sec.
5.2.2) at a stationary tip of a crack of the particles
(:func:`~dolfinx_meshfree.fracture.interaction.interaction_integral` with ``acceleration``).

The displacement is ``d_n`` and the acceleration the one of the equations of motion at ``t_n``,
``a_n = P M^{-1} (f^ext(t_n) - f^int(d_n))``, ``P`` the correction onto ``G a = 0`` in the mass
metric (Rabczuk et al. 2006, eq. 94–96; :mod:`~dolfinx_meshfree.dynamics.constraint`): the
acceleration central differences use between ``v_{n-1/2}`` and ``v_{n+1/2}``. Body forces
(``add_body_force``) enter as in statics: the balance is ``sigma_ij,j = rho (u_tt - b / rho)``,
so the inertia term takes ``a - amplitude(t) b / rho`` at its points
(:meth:`~dolfinx_meshfree.dynamics.loads.ExternalLoads.body_acceleration`). Both fields are
the crack-aware MLS approximations of their particle coefficients; the domain checks are those of
statics (:func:`~dolfinx_meshfree.statics.sifs.solution_sifs`: inside the particles, away from
the exterior boundary, the FE interface and other tips).

With crack-face contact (:class:`~dolfinx_meshfree.dynamics.crack_contact.ContactSystem`) K_I
includes the faces' term of the contact pressure
(:func:`~dolfinx_meshfree.dynamics.crack_contact.face_term`, on the probe domain too); J does
not (``J_comparable=False``: the J–K mismatch is not measured).

Reliability: the results carry the figures of
:class:`~dolfinx_meshfree.fracture.interaction.StressIntensityFactors` (domain dependence with the
near-tip probe, J–K mismatch) and the default domains of statics, but no warning is issued: K(t)
passes through zero (before the waves reach the tip, at load reversals), where figures relative
to ``|K|`` mean nothing; read ``sifs.reliable`` / ``sifs.summary()`` where K is established, or
call ``sifs.warn()``.

Left out: the crack-velocity terms of a moving tip (this is K at a stationary tip; a growing
crack's K would need them).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from petsc4py import PETSc

from ..fracture.interaction import StressIntensityFactors, interaction_rule
from ..geometry.crack import Crack, CrackDomain
from ..parallel import raise_on_all_ranks
from ..physics.materials import LinearElastic
from ..statics.sif_functional import SIFFunctional
from ..statics.sifs import sif_domains, solution_sifs
from .crack_contact import ContactSystem, FaceTerm, face_term

if TYPE_CHECKING:  # annotations only: the facade imports this module
    from .explicit import ExplicitDynamics

__all__ = [
    "SIFHistory",
    "current_acceleration",
    "dynamic_sifs",
    "model_cracks",
    "particle_state",
]


def current_acceleration(dyn: ExplicitDynamics) -> list[PETSc.Vec]:
    """``a_n = P M^{-1} (f^ext(t_n) - f^int(d_n))`` per field at the current state (new vectors
    the caller destroys; zero on dofs held at rest; collective). Inside an output of a run
    ``f^int(d_n)`` is the step's own (:meth:`CentralDifference.force_now
    <dolfinx_meshfree.dynamics.central_difference.CentralDifference.force_now>`): the same
    values, without a second product, unless the callback has changed the displacement."""
    stepper = dyn.stepper
    f_now = stepper.force_now()
    if f_now is not None:
        ku = [f.copy() for f in f_now]
    else:
        ku = dyn.system.internal_force(stepper.u)
    acc = [k.duplicate() for k in ku]
    for k, (f, a) in enumerate(zip(ku, acc, strict=True)):
        for vecs, amp in stepper.loads.at(dyn.time):
            if vecs[k] is not None and amp != 0.0:
                f.axpy(-amp, vecs[k])
        a.pointwiseMult(stepper.minv[k], f)
        a.scale(-1.0)
    if dyn.projection is not None:
        dyn.projection.correct(acc)
    for f in ku:
        f.destroy()
    return acc


def particle_state(dyn: ExplicitDynamics) -> tuple[np.ndarray, np.ndarray]:
    """The particle coefficients (n, gdim) of the displacement ``d_n`` and of the acceleration
    ``a_n`` (:func:`current_acceleration`), replicated on every rank (collective)."""
    acc = current_acceleration(dyn)
    try:
        u = dyn.evaluator.local_values(dyn.u, fe=False)[1]
        a = dyn.evaluator.local_values(acc, fe=False)[1]
    finally:
        for x in acc:
            x.destroy()
    return u, a


def model_cracks(dyn: ExplicitDynamics) -> tuple[list[Crack], object]:
    """The cracks cutting the model's MLS and where they lie (the patch, or the particles'
    :class:`~dolfinx_meshfree.geometry.crack.CrackDomain` of pure EFG)."""
    cracks = dyn.evaluator.disc.cracks
    if dyn.patch is not None:
        return cracks, dyn.patch
    if dyn.particles is None:
        return cracks, None
    kept = dyn.__dict__.get("_crack_domain")  # (particles, domain): made once per particle set
    if kept is None or kept[0] is not dyn.particles:
        kept = (dyn.particles, CrackDomain.from_particles(dyn.particles))
        dyn.__dict__["_crack_domain"] = kept
    return cracks, kept[1]


def dynamic_sifs(
    dyn: ExplicitDynamics,
    crack: Crack,
    tip: int | Sequence[float] | np.ndarray = 0,
    radius: float | Sequence | np.ndarray | None = None,
    probe: bool = True,
    j_integral: bool = True,
    **options,
) -> StressIntensityFactors:
    """K_I, K_II and J at a stationary tip of ``crack`` at the model's current state (module
    docstring; collective, the same on every rank).

    Args:
        dyn: A linear elastic explicit model with cracks (``ExplicitDynamics.efg(...,
            cracks=...)`` or ``.coupled`` of a cracked patch).
        crack: One of the model's cracks. tip: An index of ``crack.tips`` or its coordinates.
        radius: Outer domain radii (default 8, 10, 12, 14, 16 particle spacings, ``r1 = r2 / 2``,
            shrunk to fit: :func:`~dolfinx_meshfree.statics.sifs.default_domains`).
        options: ``inner``, ``weight``, ``points`` of
            :func:`~dolfinx_meshfree.interaction_integral` (``points`` default 16 x 64 in 4
            panels with the default domains).
        probe: Evaluate the near-tip probe of the reliability figures (``False`` for a caller
            that uses K only: :func:`~dolfinx_meshfree.statics.sifs.solution_sifs`).
        j_integral: Also compute J (and the J–K mismatch). ``False``: K only, by the linear
            functionals of :class:`~dolfinx_meshfree.statics.sif_functional.SIFFunctional`,
            kept on the model and rebuilt when the tip, the domains or the MLS change (its
            version: a crack grew, particles moved): a check is the acceleration and a few
            dot products (J is ``nan``, ``J_comparable=False``). The K's equal the full
            integral's to round-off.

    Raises:
        ValueError: on every rank: no cracks, a finite-strain material, a bad tip or radius.
    """
    cracks, domain = model_cracks(dyn)

    def check() -> None:
        if not cracks or domain is None:
            raise ValueError(
                "the model has no cracks: build it with ExplicitDynamics.efg(..., cracks=[crack]) "
                "or from a CoupledElasticity whose patch has cracks"
            )
        if not isinstance(dyn.material, LinearElastic):
            raise ValueError(
                f"material={dyn.material!r}: dynamic stress intensity factors need the small-"
                "strain LinearElastic law (the interaction integral is linear elastic)"
            )

    raise_on_all_ranks(dyn.comm, check)
    if not j_integral:
        return _functional_sifs(dyn, cracks, domain, crack, tip, radius, probe, options)
    u, a = particle_state(dyn)
    mls = dyn.mls

    def grad(x: np.ndarray) -> np.ndarray:
        return mls.tabulate(x).gradient(u)

    def acceleration(x: np.ndarray) -> np.ndarray:
        # the balance sigma_ij,j = rho (u_tt - b / rho): the body forces' term
        body = dyn.loads.body_acceleration(dyn.time, x)
        a_x = mls.tabulate(x, 0).values @ a
        return a_x if body is None else a_x - body

    sifs = solution_sifs(
        grad, dyn.material, cracks, domain, crack, tip, radius, check=False, probe=probe,
        acceleration=acceleration, **options,
    )  # fmt: skip
    if isinstance(dyn.system, ContactSystem):  # the faces' contact pressure (closed faces)
        weight = options.get("weight", "linear")

        def with_faces(s: StressIntensityFactors) -> StressIntensityFactors:
            dK = face_term(mls, u, dyn.material, crack, s, weight)
            return dataclasses.replace(s, K_I=s.K_I + dK, J_comparable=False)

        probe = None if sifs.probe is None else with_faces(sifs.probe)
        sifs = dataclasses.replace(with_faces(sifs), probe=probe)
    return sifs


def _exact(x: object) -> object:
    """A key for a tip or radius argument that tells any two different values apart (the
    bytes of arrays, not their printed digits)."""
    if x is None or isinstance(x, int | np.integer):
        return x
    a = np.asarray(x, dtype=float)
    return a.shape, a.tobytes()


def _kept(dyn: ExplicitDynamics, key: tuple, build: Callable[[], Any]) -> Any:
    """What ``build`` makes for ``key`` (the checked domains, a
    :class:`~dolfinx_meshfree.statics.sif_functional.SIFFunctional`, a
    :class:`~dolfinx_meshfree.dynamics.crack_contact.FaceTerm`), kept on the model with the MLS
    and its version at the time, rebuilt when missing or made for another MLS or an older
    version of it (a crack grew, the particles moved): never stale."""
    kept = dyn.__dict__.setdefault("_sif_tables", {})
    entry = kept.get(key)
    if entry is None or entry[0] is not dyn.mls or entry[1] != dyn.mls.version:
        # the same decision on every rank (replicated tips, domains and MLS versions)
        entry = (dyn.mls, dyn.mls.version, raise_on_all_ranks(dyn.comm, build))
        kept[key] = entry
    return entry[2]


def _functional_sifs(
    dyn: ExplicitDynamics,
    cracks: list[Crack],
    domain: object,
    crack: Crack,
    tip: int | Sequence[float] | np.ndarray,
    radius: float | Sequence | np.ndarray | None,
    probe: bool,
    options: dict,
) -> StressIntensityFactors:
    """:func:`dynamic_sifs` with ``j_integral=False``: K by kept linear functionals (and the
    crack faces' contact term by kept tables). Only the tables of this check are kept: those
    of a tip that moved are dropped."""
    material, mls = dyn.material, dyn.mls
    # the domains depend on this crack, the others (their points are kept out), the tip, the
    # radii and the options; the patch's boundary changes only with the MLS (a new model)
    where = (id(crack), *(c.points.tobytes() for c in cracks), _exact(tip), _exact(radius),
             repr(sorted(options.items())))  # fmt: skip
    plan = _kept(
        dyn, ("domains", *where),
        lambda: sif_domains(material, cracks, domain, crack, tip, radius, **options),
    )  # fmt: skip
    opts = plan.options
    contact = isinstance(dyn.system, ContactSystem)
    used = [("domains", *where)]

    def tables(pairs: np.ndarray) -> tuple[SIFFunctional, FaceTerm | None]:
        key = (id(crack), plan.tip.tobytes(), plan.direction.tobytes(), pairs.tobytes(),
               repr(sorted(opts.items())))  # fmt: skip

        def functional() -> SIFFunctional:
            rule = interaction_rule(
                material, plan.tip, plan.direction, pairs, keep_outside=plan.keep,
                dynamic=True, **opts,
            )  # fmt: skip
            return SIFFunctional(mls, rule)

        def faces() -> FaceTerm:
            w = opts.get("weight", "linear")
            return FaceTerm(mls, crack, plan.tip, plan.direction, pairs[:, 0], pairs[:, 1], w)

        used.extend([key, ("faces", *key)])
        f = _kept(dyn, key, functional)
        if not contact:
            return f, None
        return f, _kept(dyn, ("faces", *key), faces)

    main = tables(plan.pairs)
    near = tables(plan.near) if probe and len(plan.near) else None
    # the particles the tables read, gathered alone (not every particle) at each check; kept
    # with the tables themselves (held, so compared by identity), made again with new ones
    found = tuple(t for pair in (main, near) if pair is not None for t in pair if t is not None)
    kept = dyn.__dict__["_sif_tables"]
    window = kept.get("columns")
    if (
        window is None
        or len(window[0]) != len(found)
        or any(a is not b for a, b in zip(window[0], found, strict=False))
    ):
        window = (found, *_columns(found))
        kept["columns"] = window
    used.append("columns")
    columns, where = window[1], window[2]
    for key in [k for k in kept if k not in used]:
        del kept[key]
    acc = current_acceleration(dyn)
    try:
        u, a = dyn.evaluator.particle_rows([dyn.u, acc], columns)
    finally:
        for x in acc:
            x.destroy()

    def result(f: SIFFunctional, faces: FaceTerm | None) -> StressIntensityFactors:
        rows = where[id(f)]
        KI, KII = f.on_columns(u[rows], a[rows])
        body = dyn.loads.body_acceleration(dyn.time, f.rule.acceleration_points)
        if body is not None:  # u_tt - b / rho, as the full integral
            dKI, dKII = f.at_points(-body)
            KI, KII = KI + dKI, KII + dKII
        if faces is not None:  # the faces' contact pressure (closed faces); J has no such term
            KI = KI + faces.on_columns(u[where[id(faces)]], material)
        rule = f.rule
        return StressIntensityFactors(
            inner=rule.inner, outer=rule.outer, K_I=KI, K_II=KII, J=np.full(KI.size, np.nan),
            E_prime=rule.E_prime, tip=rule.tip, direction=rule.direction, J_comparable=False,
        )  # fmt: skip

    sifs = result(*main)
    if near is not None:
        sifs = dataclasses.replace(sifs, probe=result(*near))
    return sifs


def _columns(
    tables: Sequence[SIFFunctional | FaceTerm],
) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """The particles the ``tables`` read (sorted) and, per table (by ``id``: the caller holds
    the tables with the result), the rows of its own columns among them."""
    columns = np.unique(np.concatenate([t.columns for t in tables]))
    return columns, {id(t): np.searchsorted(columns, t.columns) for t in tables}


class SIFHistory:
    """An ``on_output`` callback of :meth:`ExplicitDynamics.run
    <dolfinx_meshfree.dynamics.explicit.ExplicitDynamics.run>` that records K_I(t), K_II(t) at a
    stationary tip (:func:`dynamic_sifs` at each output time; collective).

    Example::

        history = SIFHistory(crack, tip=0, radius=[0.1, 0.15])
        dyn.run(t_end, outputs=np.linspace(0, t_end, 50), on_output=history)
        history.KI_history()  # [[t, K_I], ...], K_I averaged over the radii

    Args:
        crack, tip, radius, options: As :func:`dynamic_sifs`.

    Attributes:
        records: ``(step, time, StressIntensityFactors)`` per output.
    """

    def __init__(
        self,
        crack: Crack,
        tip: int | Sequence[float] | np.ndarray = 0,
        radius: float | Sequence | np.ndarray | None = None,
        **options,
    ) -> None:
        self.crack, self.tip, self.radius, self.options = crack, tip, radius, options
        self.records: list[tuple[int, float, StressIntensityFactors]] = []

    def __call__(self, dyn: ExplicitDynamics, step: int, time: float) -> None:
        sifs = dynamic_sifs(dyn, self.crack, self.tip, self.radius, **self.options)
        self.records.append((step, time, sifs))

    def KI_history(self) -> list[list[float]]:
        """``[[t, K_I], ...]`` with K_I averaged over the domains."""
        return [[t, float(s.K_I.mean())] for _, t, s in self.records]

    def KII_history(self) -> list[list[float]]:
        """``[[t, K_II], ...]`` with K_II averaged over the domains."""
        return [[t, float(s.K_II.mean())] for _, t, s in self.records]
