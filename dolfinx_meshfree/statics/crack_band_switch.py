"""The paper's combined model: damage in the bulk, and a cohesive crack where the damage has
localised, with the band's softening handed to the crack's faces.

Rabczuk et al. 2006, sec. 6.1.2, model the concrete "with linear elastic material behaviour in
compression and with the Lemaitre model in tension. In the discontinuous region, a linear
traction–crack opening relation is applied" (after Rabczuk & Belytschko 2004, their ref. [48]).
Here the bulk is :class:`~dolfinx_meshfree.RankineDamage` (the crack band) and the discontinuity
a crack whose faces carry :class:`~dolfinx_meshfree.LinearCohesive` with the bulk's ``f_t`` and
``G_f``. :class:`CrackBandSwitch` names the switch from one to the other.

**When** (the switch). After every converged step of :func:`~dolfinx_meshfree.follow_path`, a
tip of the crack (a notch at first) is extended while its *front* is within ``ahead`` particle
spacings of it. The front is the nearer of

* a particle point in front of the tip (``(x - tip) . d > 0``, ``d`` the crack's direction at
  the tip) whose damage has reached ``damage``, the switch value ``D_s``: the band has
  localised there;
* the point nearest the tip where the crack's faces have softened (as
  :class:`~dolfinx_meshfree.CohesiveGrowth`'s).

So the first extensions run from the notch through the localised band and on, until the tip
is ``ahead`` spacings beyond it (a bonded lead, as a cohesive crack that finds its path keeps);
from then on the faces' softening front drives the growth, and the band's localisation ahead
of the tip, where it comes first. A local damage model localises into a band one point wide as
soon as it softens (its tangent's softening modulus is negative at once: ``-E eps0 / (eps_f -
eps0)`` in uniaxial tension), so the default ``D_s = 0.05`` switches at the onset of softening
(a softened fraction ``(kappa - eps0) / (eps_f - eps0)`` of 9e-4 at ``eps_f / eps0 = 60``).
Measured on a bar in tension split from a notch (``tests/test_crack_band_switch.py``, pure EFG):
the peak at h = 10 and 5 mm within 1.0e-4 of each other and 3.3e-4 of a cohesive crack grown
from a bonded lead in an elastic bulk (:class:`~dolfinx_meshfree.CohesiveGrowth`), the energy
balance within 1.1e-3. A later switch keeps the band's own peak, which is not objective at
these spacings (the band alone: 2.03 and 1.81, the cohesive crack 1.61), and the load must then
fall at the switch from the band's curve to the crack's at one control value: ``D_s = 0.9``
peaked at 1.73 at h = 5 mm with the energy balance off by 0.75 %, and at h = 10 mm found no
equilibrium after the switch (a :class:`~dolfinx_meshfree.PathError`). Switches from damage to
a cohesive crack at a critical damage: Simone, Wells & Sluys 2003 (CMAME 192, 4581-4607) and
Comi, Mariani & Perego 2007 (IJNAMG 31, 213-238).

**Where.** As :class:`~dolfinx_meshfree.CohesiveGrowth`'s extensions
(:func:`~dolfinx_meshfree.statics.cohesive_growth.extension`): one ``step`` normal to the
largest principal stress averaged about the front (the Gaussian average, the largest kink, the
turn off the particles, the run to a free edge), the particle field refitted across the new
segment. The average is taken about a localised point's foot on the tip's ray: about the point
itself, beside the ray, the symmetric notched beam's crack turned 6 degrees.

**The hand-over** (energy-consistent). The bulk points beside the new segment (within ``width``
spacings of it, about the old tip too, not beyond the new one) give their softening to its
faces and stay elastic from then on:

* the energy each point has dissipated, ``W_q w_q`` (:meth:`RankineDamage.dissipated_energy`
  times its quadrature weight, measured on the model before the crack grew: the carry of the
  states to the cut cells' new points, :mod:`~dolfinx_meshfree.statics.state_carry`, does not
  change it), goes to the nearest face point of the segment, whose history is set to the
  opening that has dissipated that energy per unit area, ``d_f = sum W_q w_q / w_f``:
  ``kappa_f = w_0 + (w_c - w_0) d_f / G_f`` (:meth:`LinearCohesive.opening_of_dissipation`;
  the faces' dissipation is linear in ``kappa`` past the peak, so the energy moves exactly, up
  to the faces' cap, beyond which it stays in the bulk);
* the points of the rebuilt model beside the segment give up the same share of their
  dissipation, and their history and damage are reset to the virgin ones and frozen (the
  ``frozen`` field of :class:`~dolfinx_meshfree.RankineDamage`: it never damages again).

In uniaxial tension a band point softened to the fraction ``r`` has dissipated ``G_f r`` per
unit crack area (its width ``h`` times ``(G_f / h) r``), has stretched inelastically by ``D
kappa h = (kappa - eps0 + eps0 r) h`` and carries ``f_t (1 - r)``; its faces take ``kappa_f``
at the same ``r``, so they carry the same traction and open by ``w_c r = (kappa - eps0 + eps0
r) h`` (with ``w_0 -> 0``): the crack takes over the band's opening and its dissipation
exactly, and dissipates the rest, ``G_f (1 - r)``, as it opens. Without the reset (the band
frozen damaged) the band's opening would be counted twice (a sudden softening of the whole
body at the switch); without the freeze, the band and the faces beside it, in series at the
same stress, would both soften (the fracture energy dissipated twice). The energy moved is
recorded per extension (:attr:`~dolfinx_meshfree.statics.path_following.PathResult.handovers`);
the bulk's and the faces' dissipation together do not change at the hand-over
(:attr:`~dolfinx_meshfree.statics.path_following.PathResult.carried` counts the faces' share).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from ..geometry.crack import Crack
from ..physics.cohesive import LinearCohesive
from ..physics.inelastic import RankineDamage
from .cohesive import CohesiveCrack
from .cohesive_growth import (
    CohesiveGrowth,
    _FieldFit,
    extension,
    nearest_over_ranks,
    softening_front,
)

if TYPE_CHECKING:  # annotations only
    from ..approx.mls import MLS
    from ..geometry.crack import CrackDomain
    from ..geometry.patch import ParticlePatch
    from ..physics.materials import LinearElastic
    from ..physics.state import PointState
    from .cohesive import CohesiveSide

__all__ = ["TIE", "BandEnergy", "CrackBandSwitch", "hand_over", "localised_front", "switch_once"]

#: Relative widening of the geometric bounds (a point's distance from a new segment, from a tip)
#: so that a point exactly on one, as grid points are, falls on the same side on every partition.
TIE = 1e-9


@dataclass(frozen=True)
class CrackBandSwitch(CohesiveGrowth):
    """Switch from the crack band of a :class:`~dolfinx_meshfree.RankineDamage` bulk to a
    cohesive crack where the damage has localised (module docstring), in
    :func:`~dolfinx_meshfree.follow_path` (``growth=``).

    The crack starts traction-free (a notch; give it ``through=True`` if it may split the
    body): the switch gives it faces with ``LinearCohesive(ft, Gf, shear)`` of the bulk's
    ``f_t`` and ``G_f`` as it grows (do not ``add_cohesive`` it).

    Args:
        crack: The crack (one of the model's), grown at each of its tips.
        damage: The switch value ``D_s`` in (0, 1): a particle point in front of a tip whose
            damage has reached it has localised (default: the onset of softening; module
            docstring for a later switch).
        ahead: Particle spacings kept between the front (a localised point, or where the
            faces have softened) and the tip (> ``step``).
        step, radius, max_extensions, clearance: As
            :class:`~dolfinx_meshfree.CohesiveGrowth`'s.
        lookahead: As :class:`~dolfinx_meshfree.CohesiveGrowth`'s, 0.5 here: a crack that
            follows the band in steps of one spacing drifted towards a particle column and
            passed beside it (a user's plate on triangles: a singular MLS at 0.045 spacing).
        width: Particle spacings each side of a new segment within which the bulk points hand
            their softening to its faces (the band's half-width and some).
        shear: ``beta`` of the faces' law (:class:`~dolfinx_meshfree.LinearCohesive`).
        points: Gauss points per piece of the faces.
    """

    damage: float = 0.05
    lookahead: float = 0.5
    width: float = 1.0
    shear: float = 1.0
    points: int = 3

    def __post_init__(self) -> None:
        super().__post_init__()
        D = self.damage
        if isinstance(D, bool) or not (isinstance(D, int | float) and 0.0 < D < 1.0):
            raise ValueError(
                f"damage={D!r} must lie in (0, 1): the damage at which the band hands over to "
                "the crack (the default 0.05: the onset of softening)"
            )
        w = self.width
        if isinstance(w, bool) or not (isinstance(w, int | float) and np.isfinite(w) and w > 0):
            raise ValueError(f"width={w!r} must be a positive number of particle spacings")
        LinearCohesive(ft=1.0, Gf=1.0, shear=self.shear)  # its checks, naming shear
        p = self.points
        if isinstance(p, bool) or not (isinstance(p, int) and p >= 1):
            raise ValueError(f"points={p!r} must be an integer >= 1 (Gauss points per piece)")

    def faces(self, bulk: object) -> CohesiveCrack:
        """The record of the crack's faces before they exist (no segment yet), with the
        ``LinearCohesive`` of the ``bulk`` law's ``f_t`` and ``G_f``; ValueError unless the bulk
        is a :class:`~dolfinx_meshfree.RankineDamage` (local)."""
        if not isinstance(bulk, RankineDamage):
            raise ValueError(
                f"CrackBandSwitch hands a RankineDamage bulk's crack band to a cohesive crack; "
                f"the model's law is {type(bulk).__name__}: give it mf.RankineDamage(...), or "
                "grow a cohesive crack in it with mf.CohesiveGrowth"
            )
        law = LinearCohesive(ft=bulk.ft, Gf=bulk.Gf, shear=self.shear)
        return CohesiveCrack(self.crack, law, segments=(), points=self.points)

    def check(self, cohesive: Sequence[CohesiveCrack], cracks: Sequence[Crack]) -> int:
        """The index in ``cohesive`` of this crack's faces (given by :meth:`faces`; -1 before);
        ValueError naming what is missing."""
        self._check_is_models(cracks)
        self._check_has_tip()
        return next((i for i, c in enumerate(cohesive) if c.crack is self.crack), -1)


def localised_front(
    switch: CrackBandSwitch,
    states: Sequence[PointState],
    tip: np.ndarray,
    along: np.ndarray,
    h: float,
    comm: MPI.Comm,
) -> np.ndarray | None:
    """The bulk point nearest ``tip`` in front of it (``(x - tip) . along > 0``) within
    ``switch.ahead`` spacings whose committed damage has reached ``switch.damage`` and that is
    not frozen, over the ranks, or ``None`` (collective, the same on every rank)."""
    hits = [np.zeros((0, 2))]
    for st in states:
        x = st.points[:, :2]
        c = st.committed
        hit = (  # ties with the bounds decided alike on every partition (TIE)
            (c["damage"][:, 0] >= switch.damage)
            & (c["frozen"][:, 0] <= 0.0)
            & ((x - tip) @ along > TIE * h)
            & (np.linalg.norm(x - tip, axis=1) <= switch.ahead * h * (1.0 + TIE))
        )
        hits.append(x[hit])
    return nearest_over_ranks(np.concatenate(hits), tip, comm)


def switch_once(
    switch: CrackBandSwitch,
    states: Sequence[PointState],
    side: CohesiveSide | None,
    mls: MLS,
    coefficients: Callable[[], np.ndarray],
    material: LinearElastic,
    domain: ParticlePatch | CrackDomain,
    h: float,
) -> tuple[int, np.ndarray, float, np.ndarray] | None:
    """Extend ``switch.crack`` by one step at the first tip whose front comes within
    ``switch.ahead`` spacings of it (collective), as
    :func:`~dolfinx_meshfree.statics.cohesive_growth.grow_once` does: the front is the nearer
    of a localised bulk point in front of the tip (:func:`localised_front`) and the faces'
    softening front (:func:`~dolfinx_meshfree.statics.cohesive_growth.softening_front`, once
    ``side``, the crack's faces, exists). Returns ``(end, refitted coefficients, turn,
    segment)`` (the new segment's end points (2, 2), the old tip first), or ``None`` when it
    did not grow."""
    crack = switch.crack
    comm = domain.comm
    for end in crack.tip_ends:
        tip = crack.points[end].copy()
        ahead = crack.tip_direction(end)
        band = localised_front(switch, states, tip, ahead, h, comm)
        # on the tip's ray at the point's distance ahead: the average about it is then that
        # of the material straight ahead (about a point of the band beside the ray the
        # averaged stress of the symmetric notched beam turned the crack 6 degrees)
        fronts = [None if band is None else tip + float((band - tip) @ ahead) * ahead]
        if side is not None:
            fronts.append(softening_front(side, tip))
        near = [f for f in fronts if f is not None and np.linalg.norm(f - tip) < switch.ahead * h]
        if not near:
            continue
        front = min(near, key=lambda f: float(np.linalg.norm(f - tip)))
        c = coefficients()
        d, length, turn = extension(switch, mls, c, material, domain, h, end, front)
        fit = _FieldFit(mls, c, crack, tip, tip + length * d, domain, h)
        crack.extend(d, length, tip=end)
        return end, fit.refit(domain.comm), turn, np.stack([tip, crack.points[end]])
    return None


def _gathered(comm: MPI.Comm, *arrays: np.ndarray) -> tuple[list[np.ndarray], int]:
    """The arrays concatenated over the ranks in rank order, and this rank's offset in them."""
    parts = comm.allgather(arrays)
    sizes = [len(p[0]) for p in parts]
    joined = [np.concatenate([p[i] for p in parts]) for i in range(len(arrays))]
    return joined, int(sum(sizes[: comm.rank]))


def _strip(
    switch: CrackBandSwitch, x: np.ndarray, segment: np.ndarray, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """The points of ``x`` (m, >= 2) beside ``segment`` (within ``width`` spacings of it, not
    beyond its end: the band ahead goes on), the old tip's end included (the cell the crack
    leaves, whose rule the new segment changes too): their indices and their positions ``s``
    along it, at most 1 (local)."""
    a, b = segment
    t = b - a
    s = (x[:, :2] - a) @ t / float(t @ t)
    foot = a + np.clip(s, 0.0, 1.0)[:, None] * t
    # the bounds widened by 1e-9: a grid point at exactly ``width`` spacings (or at the new
    # tip's normal) is in whatever the round-off of the partition (on 2 ranks one point of the
    # shear beam's strip at 1.0 h flipped, and the path went another way)
    dist = np.linalg.norm(x[:, :2] - foot, axis=1)
    near = (s <= 1.0 + TIE) & (dist <= switch.width * h * (1.0 + TIE))
    idx = np.flatnonzero(near)
    return idx, s[idx]


@dataclass(frozen=True)
class BandEnergy:
    """The energy the bulk has dissipated beside a new segment, measured on the model before
    the crack grew (the states the carry to the cut cells' new points has not touched):
    positions ``s`` along the segment and energies ``W_q w_q`` of the points, over the ranks in
    rank order (the same on every rank)."""

    segment: np.ndarray
    s: np.ndarray
    energy: np.ndarray

    @classmethod
    def of(
        cls,
        switch: CrackBandSwitch,
        bulk: Sequence[tuple[PointState, np.ndarray]],
        segment: np.ndarray,
        h: float,
        comm: MPI.Comm,
    ) -> BandEnergy:
        """Measure it on the sets of bulk points ``bulk`` (``(state, weights)`` each;
        collective)."""
        s_local, e_local = [np.zeros(0)], [np.zeros(0)]
        for st, w in bulk:
            idx, s = _strip(switch, st.points, segment, h)
            s_local.append(s)
            e_local.append(st.committed["dissipation"][idx, 0] * np.asarray(w, dtype=float)[idx])
        (s, e), _ = _gathered(comm, np.concatenate(s_local), np.concatenate(e_local))
        return cls(np.asarray(segment, dtype=float), s, e)


def _nearest(f_s: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The index of the nearest of the sorted positions ``f_s`` to each of ``s`` (ties: the
    lower one)."""
    if len(f_s) == 1:
        return np.zeros(len(s), dtype=np.int64)
    k = np.clip(np.searchsorted(f_s, s), 1, len(f_s) - 1)
    return np.where(s - f_s[k - 1] <= f_s[k] - s, k - 1, k)


def hand_over(
    switch: CrackBandSwitch,
    band: BandEnergy,
    bulk: Sequence[tuple[PointState, np.ndarray]],
    side: CohesiveSide,
    h: float,
) -> tuple[float, float, int]:
    """Hand the softening of the bulk beside the new segment to the face points of ``side`` on
    it (module docstring), in the committed (and trial) states of both, on the rebuilt model:
    ``band``, the energy measured before the crack grew, goes to the faces, each point's to the
    nearest face point (:meth:`LinearCohesive.opening_of_dissipation` of the sum per unit
    area, up to the faces' cap); the bulk points of the rebuilt model beside the segment
    (``bulk``: ``(state, weights)`` of each set) lose the same share of their dissipation, are
    reset to the virgin state and frozen. Returns the energy the faces took, the energy the
    bulk points gave up and the number frozen, summed over the ranks (collective; the same on
    every rank and for every partition: the face points are sorted along the segment). The two
    energies differ by what the carry to the cut cells' points changed (the points beside the
    segment are those of the cells it cut)."""
    comm = side.comm
    a, b = band.segment
    t = b - a
    fx = side.points
    fs = (fx - a) @ t / float(t @ t) if len(fx) else np.zeros(0)
    gap = np.linalg.norm(fx - (a + np.clip(fs, 0.0, 1.0)[:, None] * t), axis=1)
    mine = np.flatnonzero((gap <= 1e-9 * h) & (fs >= -1e-9) & (fs <= 1.0 + 1e-9))
    (f_s, f_w), offset = _gathered(comm, fs[mine], side.weights[mine])
    order = np.argsort(f_s, kind="stable")
    f_s, f_w = f_s[order], f_w[order]
    if not len(f_s):
        return 0.0, 0.0, 0
    law = side.law
    energy = np.bincount(_nearest(f_s, band.s), weights=band.energy, minlength=len(f_s))
    # beyond the faces' cap it stays; below 1e-12 G_f it is round-off (a face point given it
    # would count as softened, on one partition and not on another)
    take = np.minimum(energy / f_w, law.max_dissipation)
    take[take <= 1e-12 * law.Gf] = 0.0
    share = np.divide(take * f_w, energy, out=np.zeros_like(energy), where=energy > 0.0)
    where = np.empty(len(order), dtype=np.int64)
    where[order] = np.arange(len(order))
    kappa = law.opening_of_dissipation(take[where[offset : offset + len(mine)]])
    for state in (side.state.committed, side.state.trial):
        state["kappa"][mine, 0] = kappa
    side.state.version += 1
    given, frozen = 0.0, 0
    for st, w in bulk:
        idx, s = _strip(switch, st.points, band.segment, h)
        keep = 1.0 - share[_nearest(f_s, s)]
        keep[keep <= 1e-12] = 0.0  # all of it moved: no round-off left behind
        given += float(st.committed["dissipation"][idx, 0] * (1.0 - keep) @ np.asarray(w)[idx])
        virgin = st.law.initial_state(len(idx))
        for state in (st.committed, st.trial):
            state["dissipation"][idx, 0] *= keep
            state["kappa"][idx] = virgin["kappa"]
            state["damage"][idx] = 0.0
            state["frozen"][idx] = 1.0
        st.version += 1
        frozen += len(idx)
    return float((take * f_w).sum()), comm.allreduce(given), comm.allreduce(frozen)
