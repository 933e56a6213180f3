"""A rigid projectile in explicit dynamics: an ogive- or flat-nosed body of revolution that
strikes the model, with a penalty on every material point it covers (issue 27, items 2 and 5).

A hard projectile that perforates a target passes through the material: no surface of the
target stays in front of it, so the node-to-facet contact of
:mod:`~dolfinx_meshfree.dynamics.body_contact` (two surfaces of one mesh) cannot carry it. Here
the projectile is a rigid body of revolution about the model's axis, and **every material
point** of the target (the mesh's vertices and the particles, at their current positions ``y =
X + A d``, ``A`` the model's evaluation operator: FE on FE cells, MLS on particle cells, the
blended functions on the ramps' and bridging's cells, the SPH interpolant in the hybrid's
patch) is pushed out of it. This is the contact acting on the particles, not only at the
surface's vertices, that :mod:`~dolfinx_meshfree.dynamics.body_contact` names as its limit at
high speed.

**The body.** In the coordinates ``(rho, s)`` of a point, ``rho`` its distance to the axis and
``s = heading (z_tip - z)`` its distance behind the nose's tip along the flight (``z`` the last
coordinate: the axis ``r = 0`` of an axisymmetric ``(r, z)`` model, the line ``x = 0`` of a
plane model, the ``z`` axis in 3D), the projectile of shank radius ``a``, length ``L`` and
caliber-radius-head ``psi`` is

.. math::
    0 \\le s \\le L, \\qquad \\rho \\le R(s) = \\begin{cases}
    \\sqrt{S^2 - (l - s)^2} - (S - a), & s \\le l, \\\\ a, & s > l, \\end{cases}
    \\qquad S = 2 \\psi a, \\quad l = a \\sqrt{4 \\psi - 1},

the tangent ogive of radius ``S`` (Forrestal & Luk's notation, *Int. J. Impact Eng.* 12, 1992;
``psi = 3`` for Hanchak's projectile), or a cylinder with a flat nose (``crh=None``). Its
section is convex, so a point inside has one nearest boundary point among the arc, the shank
and the back face: its depth ``g > 0`` and the outward normal ``n`` there.

**The penalty.** With ``k_s`` per point,

.. math::
    E_c = \\tfrac12 \\sum_s k_s g_s^2, \\qquad f_s = -k_s g_s n_s, \\qquad
    F_z = -\\sum_s k_s g_s (n_s \\cdot e_z),

``f_s`` the point's share of the internal force (then ``A^T f``) and ``F_z`` the axial force on
the projectile (``g`` falls by ``n . dy`` when the point moves by ``dy`` and grows by ``n_z dz``
when the projectile moves by ``dz``: both are the gradients of ``E_c``, so the pair conserves
``kinetic + strain + E_c + M v^2 / 2`` in central differences up to the non-smoothness of a
contact's start and end). ``k_s = factor * m_s * omega_0^2``, ``m_s = sum_j |A_sj| m_j`` the
point's share of the lumped masses and ``omega_0`` the bound of the model's largest frequency
without the projectile: a covered point oscillates at ``sqrt(factor) omega_0`` at most, so the
stable step falls by ``1 / sqrt(1 + factor)`` at most (the tangent the step is bounded with
adds ``A^T diag(k) A``, :meth:`ProjectileContactSystem.tangent`), and a point struck at speed
``v`` enters by about ``v / (sqrt(factor) omega_0)``, a fraction of the spacing (reported as
:attr:`ProjectileState.depth`). In an axisymmetric model the masses, hence ``k_s``, ``E_c``
and ``F_z``, are the revolved ones, and ``M`` is the projectile's mass; in a plane model all
are per unit thickness.

**The projectile's motion** is its own central-difference step, taken when the model's step
reaches a new time (``set_time(t_n)``, before the internal force at ``t_n``): ``v_{n-1/2} =
v_{n-3/2} + (dt_{n-1} + dt_n) / 2 * F_{n-1} / M`` and ``z_n = z_{n-1} + dt_n v_{n-1/2}``,
the same scheme as the model's (eq. 93 of Rabczuk et al. 2006, Table I). The step ``dt`` must
also hold the projectile's own frequency ``sqrt(sum_s k_s n_z^2 / M)``; a step above it is
refused by name (:class:`ProjectileState`).

**The axis is not struck** in an axisymmetric model: a point on it cannot move radially, so
the nose would push it ahead through the whole target (and a particle's MLS point there, held
only where the axis condition's multipliers act, leaks the radial penalty into its
neighbours: a measured blow-up of the Hanchak slab at 150 microseconds). In the solid of
revolution the material on the axis parts symmetrically, which the section cannot carry; its
neighbours off the axis are struck.

**Coulomb friction** (``RigidProjectile(friction=mu)``; frictionless by default): the penalty
regularisation of Coulomb's law with a return map, as the contact between bodies has it
(:mod:`~dolfinx_meshfree.dynamics.body_contact`; Wriggers, *Computational Contact Mechanics*,
2006). Each covered point carries a tangential spring of its normal stiffness ``k_s``: its
force on the point moves by ``-k_s`` times the point's tangential slip relative to the
projectile (the point's motion less the projectile's since the last evaluation), from its
previous value turned into the current tangent plane, and is limited to ``mu k_s g``; the
excess is slip, whose work (the limit times the slip) :attr:`ProjectileContactSystem.dissipated`
accumulates. The projectile takes the opposite axial force. A point that leaves contact forgets
its spring. The energy records' ``internal`` holds the springs' energy and the dissipated work,
so the balance still closes. The springs' stiffness is the normal one, so the stable step's
bound holds (``k_s (n n^T + t t^T) <= k_s I``).

The projectile does not rotate and keeps to its axis (normal impact, which the axisymmetric
model imposes anyway).
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from ..approx.fe_points import locate_points
from ..parallel import raise_on_all_ranks
from .body_contact import (
    ContactSurfaces,
    PointPenaltySystem,
    check_friction,
    coulomb_return,
    evaluation_operators,
    point_masses,
    vertex_coordinates,
)
from .system import wrapped
from .time_step import same_time

if TYPE_CHECKING:  # annotations only
    from .evaluation import FieldEvaluator
    from .system import SemiDiscreteSystem

__all__ = [
    "ProjectileContactSystem",
    "ProjectileState",
    "RigidProjectile",
    "carry_projectiles",
    "contact_nodes",
    "contact_points",
    "projectiles",
    "radial_distance",
    "with_projectile",
]


def _positive(name: str, value: object) -> None:
    if isinstance(value, bool) or not (
        isinstance(value, int | float) and np.isfinite(value) and value > 0.0
    ):
        raise ValueError(f"RigidProjectile({name}={value!r}): {name} must be a positive number")


def radial_distance(points: np.ndarray, radial: str) -> np.ndarray:
    """The distance ``rho`` (m,) of each point (m, gdim) to the model's axis: ``r`` (the first
    coordinate, ``"axisymmetric"``), ``|x|`` (``"plane"``) or ``sqrt(x^2 + y^2)`` (``"3d"``)."""
    if radial == "3d":
        return np.linalg.norm(points[:, :2], axis=1)
    if radial == "plane":
        return np.abs(points[:, 0])
    return np.maximum(points[:, 0], 0.0)


@dataclasses.dataclass(frozen=True)
class RigidProjectile:
    """A rigid body of revolution about the model's axis (module docstring), flying along it.

    Attributes:
        radius: The shank's radius ``a`` (m).
        length: Its length from the nose's tip to the back face (m), longer than the nose.
        mass: Its mass ``M`` (kg; per unit thickness in a plane model).
        velocity: Its initial speed along ``heading`` (m/s, >= 0).
        tip: The axial coordinate ``z`` of the nose's tip at ``t = 0``.
        crh: The ogive's caliber-radius-head ``psi >= 0.5`` (its arc's radius over the
            diameter; 0.5: a hemispherical nose), or ``None``: a flat nose.
        heading: ``-1``: it flies towards ``-z`` (default), ``+1``: towards ``+z``.
        factor: The penalty's ``k_s = factor m_s omega_0^2`` (module docstring). The default
            0.3 lowers the stable step to 0.88x (FE) and keeps the energy of a bar struck by a
            rigid mass to round-off (``tests/test_rigid_projectile.py``); 1 follows the
            closed form more closely (the penalty's lag is shorter) but each point's entry
            into contact then costs energy (0.7 % on that bar, FE; 5.6 % EFG).
        depth: The deepest penetration still taken for contact (m); ``None``: a quarter of
            the radius. A point found deeper is taken to have passed (no force; counted in
            :attr:`ProjectileState.released`): the penalty holds a struck point within a small
            fraction of the spacing, so a deep one has not been struck but has arrived there,
            and pushing it out through the nearest face (the back face, from inside the shank)
            would release ``k g^2 / 2`` at once.
        friction: Coulomb's coefficient ``mu`` between the projectile and the model (default
            0: frictionless; module docstring).
    """

    radius: float
    length: float
    mass: float
    velocity: float
    tip: float
    crh: float | None = 3.0
    heading: int = -1
    factor: float = 0.3
    depth: float | None = None
    friction: float = 0.0

    def __post_init__(self) -> None:
        for name in ("radius", "length", "mass", "factor"):
            _positive(name, getattr(self, name))
        check_friction("RigidProjectile", self.friction)
        if self.depth is not None:
            _positive("depth", self.depth)
        if isinstance(self.velocity, bool) or not (
            isinstance(self.velocity, int | float)
            and np.isfinite(self.velocity)
            and self.velocity >= 0.0
        ):
            raise ValueError(
                f"RigidProjectile(velocity={self.velocity!r}): the speed along heading must be "
                "a number >= 0 (the direction is heading's)"
            )
        if not (isinstance(self.tip, int | float) and np.isfinite(self.tip)):
            raise ValueError(f"RigidProjectile(tip={self.tip!r}) must be a finite number")
        if self.crh is not None:
            if isinstance(self.crh, bool) or not (
                isinstance(self.crh, int | float) and np.isfinite(self.crh) and self.crh >= 0.5
            ):
                raise ValueError(
                    f"RigidProjectile(crh={self.crh!r}): the caliber-radius-head must be >= 0.5 "
                    "(0.5: a hemispherical nose; 3: Hanchak's ogive) or None (a flat nose)"
                )
        if self.heading not in (-1, 1) or isinstance(self.heading, bool):
            raise ValueError(
                f"RigidProjectile(heading={self.heading!r}) must be -1 (flying towards -z) or "
                "+1 (towards +z)"
            )
        if self.length <= self.nose_length:
            raise ValueError(
                f"RigidProjectile(length={self.length!r}) must exceed the nose's length "
                f"{self.nose_length:.6g} (radius {self.radius!r}, crh {self.crh!r})"
            )

    @property
    def deepest(self) -> float:
        """The deepest penetration taken for contact (``depth``, default ``radius / 4``)."""
        return float(self.depth) if self.depth is not None else 0.25 * self.radius

    @property
    def nose_length(self) -> float:
        """The ogive's length ``l = a sqrt(4 psi - 1)`` (0 for a flat nose)."""
        if self.crh is None:
            return 0.0
        return float(self.radius * np.sqrt(4.0 * self.crh - 1.0))

    def profile(self, s: npt.ArrayLike) -> np.ndarray:
        """``R(s)``: the body's radius at the distance ``s`` behind the tip (0 outside)."""
        s = np.asarray(s, dtype=float)
        a, nose = self.radius, self.nose_length
        R = np.where((s >= 0.0) & (s <= self.length), a, 0.0)
        if nose > 0.0:
            S = 2.0 * self.crh * a
            arc = np.sqrt(np.maximum(S * S - (nose - s) ** 2, 0.0)) - (S - a)
            R = np.where((s >= 0.0) & (s < nose), np.maximum(arc, 0.0), R)
        return R

    def volume(self) -> float:
        """The body's volume (m^3), by the profile's revolution (a check of :meth:`profile`)."""
        s = np.linspace(0.0, self.length, 200_001)
        area = self.profile(s) ** 2
        return float(np.pi * np.sum(0.5 * (area[1:] + area[:-1]) * np.diff(s)))

    def penetration(
        self, points: np.ndarray, tip: float, radial: str
    ) -> tuple[np.ndarray, np.ndarray]:
        """The depth ``g >= 0`` (0 outside) of each point (m, gdim) in the body with its tip at
        ``z = tip``, and the outward normal (m, gdim) at its nearest boundary point (zero
        outside). ``radial``: ``"axisymmetric"`` (``rho = r``, the first coordinate),
        ``"plane"`` (``rho = |x|``) or ``"3d"`` (``rho = sqrt(x^2 + y^2)``)."""
        points = np.asarray(points, dtype=float)
        m, gdim = points.shape
        rho = radial_distance(points, radial)
        s = self.heading * (tip - points[:, -1])
        inside = (s > 0.0) & (s < self.length) & (rho < self.profile(s))
        depth, nrm = np.zeros(m), np.zeros((m, 2))  # (rho, s) components
        i = np.flatnonzero(inside)
        if i.size:
            r, t = rho[i], s[i]
            a, L, nose = self.radius, self.length, self.nose_length
            # candidate nearest points: (distance, normal in (rho, s))
            cands = []
            # the back face s = L (rho <= a): normal +s
            cands.append((L - t, np.tile([0.0, 1.0], (i.size, 1))))
            # the shank rho = a for s in [nose, L]: normal +rho (behind the nose's end,
            # the distance to its end point)
            ds = np.maximum(nose - t, 0.0)
            d_shank = np.hypot(a - r, ds)
            n_shank = np.column_stack([a - r, -ds]) / np.maximum(d_shank, 1e-300)[:, None]
            cands.append((d_shank, n_shank))
            if nose > 0.0:  # the arc: centre (-(S - a), nose), radius S; for the points of
                # the nose only (behind it the arc's circle is no part of the boundary: a
                # point of the shank may lie outside it, at a negative "distance")
                S = 2.0 * self.crh * a
                cx, cs = -(S - a), nose
                v = np.column_stack([r - cx, t - cs])
                dist = np.linalg.norm(v, axis=1)
                cands.append((np.where(t <= nose, S - dist, np.inf), v / dist[:, None]))
            else:  # the flat nose s = 0: normal -s
                cands.append((t.copy(), np.tile([0.0, -1.0], (i.size, 1))))
            d = np.stack([c[0] for c in cands])
            best = np.argmin(d, axis=0)
            depth[i] = d[best, np.arange(i.size)]
            nrm[i] = np.stack([c[1] for c in cands])[best, np.arange(i.size)]
        normal = np.zeros((m, gdim))
        normal[:, -1] = -self.heading * nrm[:, 1]  # s grows against heading
        if radial == "3d":
            safe = np.where(rho > 0.0, rho, 1.0)
            normal[:, 0] = nrm[:, 0] * np.where(rho > 0.0, points[:, 0] / safe, 0.0)
            normal[:, 1] = nrm[:, 0] * np.where(rho > 0.0, points[:, 1] / safe, 0.0)
        elif radial == "plane":
            normal[:, 0] = nrm[:, 0] * np.sign(points[:, 0])
        else:
            normal[:, 0] = nrm[:, 0]
        return depth, normal


@dataclasses.dataclass
class ProjectileState:
    """The projectile's state and history (the same on every rank).

    Attributes:
        time: ``t_n`` of the last step. tip: ``z`` of the nose's tip at ``t_n``.
        velocity: ``v_{n-1/2}`` along ``z`` (signed). force: ``F_z`` at ``t_n`` (N).
        pairs: Points covered at ``t_n``. depth: The deepest penetration since the start (m).
        released: The most points found deeper than :attr:`RigidProjectile.deepest` at one
            step (taken to have passed: no force), since the start.
        history: ``(t_n, tip, v_n, F_z, E_c, v_{n-1/2})`` per step, ``v_n = v_{n-1/2} + dt / 2
            F_z / M``.
    """

    time: float | None
    tip: float
    velocity: float
    force: float = 0.0
    dt_prev: float = 0.0
    pairs: int = 0
    depth: float = 0.0
    released: int = 0
    history: list = dataclasses.field(default_factory=list)

    def speed(self, mass: float, dt: float) -> float:
        """``v_n`` (signed) from ``v_{n-1/2}`` and ``F_z`` at ``t_n``, for the step ``dt``."""
        return self.velocity + 0.5 * dt * self.force / mass


class ProjectileContactSystem(PointPenaltySystem):
    """A :class:`~dolfinx_meshfree.dynamics.system.SemiDiscreteSystem` struck by a
    :class:`RigidProjectile` (module docstring): the inner internal force plus ``A^T f``, the
    strain energy plus ``E_c``, the tangent plus ``A^T diag(k) A``; the projectile's step is
    taken in :meth:`set_time`.

    Args:
        inner: The system without the projectile.
        projectile: The body.
        points: This rank's contact points (reference positions, owned rows of ``A``).
        operators: ``A_k`` per field (``None`` for a field that does not reach the points).
        stiffness: ``k_s`` of this rank's points.
        radial: As :meth:`RigidProjectile.penetration`.
    """

    def __init__(
        self,
        inner: SemiDiscreteSystem,
        projectile: RigidProjectile,
        points: np.ndarray,
        operators: Sequence[PETSc.Mat | None],
        stiffness: np.ndarray,
        radial: str,
    ) -> None:
        super().__init__(inner, operators, points.shape[1])
        self.projectile, self.points = projectile, points
        self.k, self.radial = stiffness, radial
        p = projectile
        #: The projectile's :class:`ProjectileState`.
        self.state = ProjectileState(None, float(p.tip), float(p.heading * p.velocity))
        #: The largest ``sqrt(sum k n_z^2 / M)`` met (the projectile's own frequency; with
        #: friction ``sqrt(sum k / M)`` over the covered points).
        self.omega = 0.0
        #: Friction's slips' work since the start (J; carried over a conversion).
        self.dissipated = 0.0
        m = len(points)
        #: Friction's springs per point: in contact at the last evaluation, their force on the
        #: point, the point's position relative to the tip there.
        self._stuck = np.zeros(m, dtype=bool)
        self._traction, self._relative = np.zeros((m, self.gdim)), np.zeros((m, self.gdim))

    def set_time(self, t: float) -> None:
        """Take the projectile's step to ``t`` (when ``t`` is new), then the inner system's."""
        st, M = self.state, self.projectile.mass
        if st.time is None:
            st.time = float(t)
        elif same_time(t, st.time):
            pass  # a next run's first t_n: the step to it is taken
        elif t > st.time:
            dt = float(t) - st.time
            if dt * self.omega > 2.0:  # the same on every rank (allreduced forces)
                sums = "sum k" if self.projectile.friction > 0 else "sum k n_z^2"
                raise ValueError(
                    f"the step dt = {dt:.4g} exceeds the projectile's stable step "
                    f"{2.0 / self.omega:.4g} (its contact frequency sqrt({sums} / M) = "
                    f"{self.omega:.4g} at t = {st.time:.6g}): make the projectile heavier than "
                    "the material it covers or lower RigidProjectile(factor=...)"
                )
            st.velocity += 0.5 * (st.dt_prev + dt) * st.force / M
            st.tip += dt * st.velocity
            st.dt_prev, st.time = dt, float(t)
        else:
            raise ValueError(
                f"the projectile's time {st.time:.6g} is past the model's t = {t:.6g}: a "
                "model struck by a projectile runs forward only (set_initial resets the model, "
                "not the projectile: build the model again)"
            )
        inner = getattr(self.inner, "set_time", None)
        if inner is not None:
            inner(t)

    def _evaluate(self, u: Sequence[PETSc.Vec]) -> float:
        """The points' forces into the row vector, ``F_z`` and ``E_c`` (collective)."""
        self._y.set(0.0)
        for A, x in zip(self.A, u, strict=True):
            if A is not None:
                A.multAdd(x, self._y, self._y)
        y = self.points + self._y.array_r.reshape(-1, self.gdim)
        g, n = self.projectile.penetration(y, self.state.tip, self.radial)
        passed = g > self.projectile.deepest
        g[passed], n[passed] = 0.0, 0.0
        on = g > 0.0
        kg = self.k * g
        force = kg[:, None] * n  # on the points (outwards)
        stored, slipped = 0.0, 0.0
        if self.projectile.friction > 0.0:
            friction, stored, slipped = self._friction(y, n, g, on)
            force += friction
        self._f.array[:] = (-force).ravel()  # the points' share of the internal force
        stiff = self.k[on] if self.projectile.friction > 0.0 else self.k[on] * n[on, -1] ** 2
        local = np.array(
            [
                -float(force[on, -1].sum()),
                0.5 * float(np.dot(kg[on], g[on])) + stored,
                float(np.count_nonzero(on)),
                float(stiff.sum()),
                float(np.count_nonzero(passed)),
                slipped,
            ]
        )
        total = self.comm.allreduce(local, op=MPI.SUM)
        self.dissipated += float(total[5])
        deepest = self.comm.allreduce(float(g.max(initial=0.0)), op=MPI.MAX)
        st = self.state
        st.force, st.pairs = float(total[0]), int(total[2])
        st.released = max(st.released, int(total[4]))
        st.depth = max(st.depth, deepest)
        self.omega = max(self.omega, float(np.sqrt(total[3] / self.projectile.mass)))
        energy = float(total[1])
        if not st.history or st.history[-1][0] != st.time:
            v_n = st.speed(self.projectile.mass, st.dt_prev)
            st.history.append((st.time, st.tip, v_n, st.force, energy, st.velocity))
        return energy

    def _friction(
        self, y: np.ndarray, n: np.ndarray, g: np.ndarray, on: np.ndarray
    ) -> tuple[np.ndarray, float, float]:
        """Coulomb friction at the points (module docstring): the tangential forces on them
        (m, gdim), the springs' stored energy and this evaluation's slip work (this rank's);
        the springs move to ``y`` (a second evaluation at the same state changes nothing)."""
        tip = np.zeros(self.gdim)
        tip[-1] = self.state.tip
        rel = y - tip  # the point relative to the projectile (which only translates along z)
        force = np.zeros_like(y)
        slip = np.where(self._stuck[on, None], rel[on] - self._relative[on], 0.0)
        prev = np.where(self._stuck[on, None], self._traction[on], 0.0)
        limit = self.projectile.friction * self.k[on] * g[on]
        force[on], slipped = coulomb_return(prev, slip, n[on], self.k[on], limit)
        self._stuck[:] = on
        self._traction[:] = force
        self._relative[:] = rel
        stored = 0.5 * float(np.sum(np.einsum("mk,mk->m", force[on], force[on]) / self.k[on]))
        return force, stored, slipped

    def _dissipated(self) -> float:
        """Friction's slips' work since the start (:attr:`dissipated`)."""
        return self.dissipated

    def kinetic_energy(self) -> float:
        """``M v_n^2 / 2`` at the last step."""
        v = self.state.speed(self.projectile.mass, self.state.dt_prev)
        return 0.5 * self.projectile.mass * v * v

    def _bound(self) -> np.ndarray:
        """``k_s`` of this rank's points: ``k_s n n^T <= k_s I`` in any contact state."""
        return self.k


def projectiles(system: object) -> list[ProjectileContactSystem]:
    """The projectiles' systems in a model's chain of wrapped systems (``system``, its
    ``inner``, ...), outermost first: one per
    :meth:`~dolfinx_meshfree.ExplicitDynamics.add_projectile`."""
    return wrapped(system, ProjectileContactSystem)


def carry_projectiles(old: object, new: object) -> int:
    """Carry the projectiles' states from the model ``old`` (its system) into ``new``, the
    same model rebuilt on a changed patch (a conversion of failing cells into particles,
    :mod:`~dolfinx_meshfree.dynamics.patch_conversion`): each projectile of the new model,
    added by the user's ``build`` as in the first model (the same :class:`RigidProjectile`),
    continues from the old one's tip, velocity, force, last step, history and friction's
    dissipated work; its penalty acts on the new model's points (the new particles join the
    contact) with the new model's ``k_s``, and friction's springs start afresh there (their
    stored energy is in the conversion's ``strain_change``). Returns the number carried.
    Raises ``ValueError`` (the same on every rank) when the rebuilt model's projectiles are
    not the old one's."""
    before, after = projectiles(old), projectiles(new)
    if [s.projectile for s in before] != [s.projectile for s in after]:
        raise ValueError(
            f"the rebuilt model is struck by {len(after)} projectile(s), the old one by "
            f"{len(before)}{' (not the same RigidProjectile)' if len(after) == len(before) else ''}"
            ": build(cells=...) must add the first model's projectiles again, with the same "
            "RigidProjectile (dyn.add_projectile(projectile) in build); their state is carried "
            "over"
        )
    for s0, s1 in zip(before, after, strict=True):
        s1.state = copy.deepcopy(s0.state)
        s1.omega = max(s1.omega, s0.omega)
        s1.dissipated = s0.dissipated  # friction's springs start afresh on the new points
    return len(after)


def contact_points(
    evaluator: FieldEvaluator, where: Callable[[np.ndarray], np.ndarray] | None
) -> tuple[np.ndarray, np.ndarray]:
    """This rank's contact points (reference positions) and a local cell of each: the model's
    own nodes, that is its owned vertices of FE cells (and of the ramps' and bridging's blended
    cells), and its particles that sit at no such vertex, kept where ``where(x)`` holds. A
    vertex of particle cells only is not a node of the model (the hybrid's particles sit at the
    cells' centres; pure EFG's at the vertices, as particles)."""
    points, cells, _ = contact_nodes(evaluator, where)
    return points, cells


def contact_nodes(
    evaluator: FieldEvaluator, where: Callable[[np.ndarray], np.ndarray] | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`contact_points`, and the local index of each point's particle (``-1``: a
    vertex)."""
    d = evaluator.disc
    msh = d.mesh
    tdim = msh.topology.dim
    n_cells = msh.topology.index_map(tdim).size_local + msh.topology.index_map(tdim).num_ghosts
    all_cells = np.arange(n_cells, dtype=np.int32)
    nodal = ~d.on_particles(all_cells)
    blended = d.blended_cells()
    if blended is not None:
        nodal |= blended[:n_cells]
    vx = vertex_coordinates(msh)
    # a nodal cell of each vertex: the first in cell order that holds it
    msh.topology.create_connectivity(tdim, 0)
    c2v = msh.topology.connectivity(tdim, 0)
    per_cell = int(np.diff(np.asarray(c2v.offsets))[0]) if n_cells else 1
    verts = np.asarray(c2v.array).reshape(-1, per_cell)[:n_cells]
    nodal_cells = np.flatnonzero(nodal).astype(np.int32)
    held, first = np.unique(verts[nodal_cells].ravel(), return_index=True)
    cell_of = np.full(len(vx), -1, dtype=np.int32)
    cell_of[held] = np.repeat(nodal_cells, per_cell)[first]
    owned = np.flatnonzero(cell_of[: msh.topology.index_map(0).size_local] >= 0)
    points, cells = vx[owned], cell_of[owned]
    index = np.full(len(points), -1, dtype=np.int64)
    if d.particles is not None:
        P = d.particles
        ip = np.flatnonzero(P.owner == evaluator.comm.rank)
        xp = P.positions[ip]
        if len(points) and len(xp):  # a particle at a vertex is struck there once
            extent = float(np.min(np.ptp(vx, axis=0)))
            dist, _ = cKDTree(points).query(xp)
            apart = dist > 1e-9 * max(extent, 1e-300)
            xp, ip = xp[apart], ip[apart]
        cp = locate_points(msh, xp)
        keep = cp >= 0
        points = np.concatenate([points, xp[keep]])
        cells = np.concatenate([cells, cp[keep].astype(np.int32)])
        index = np.concatenate([index, ip[keep]])
    if where is not None:
        mask = np.asarray(where(points), dtype=bool).reshape(-1)
        points, cells, index = points[mask], cells[mask], index[mask]
    return points, cells, index


def with_projectile(
    system: SemiDiscreteSystem,
    evaluator: FieldEvaluator,
    omega_0: float,
    projectile: RigidProjectile,
    where: Callable[[np.ndarray], np.ndarray] | None = None,
) -> ProjectileContactSystem:
    """``system`` struck by ``projectile`` at every point of the model (or where ``where(x)``
    holds), ``omega_0`` the bound of the model's largest frequency (collective)."""
    if not isinstance(projectile, RigidProjectile):  # the same on every rank
        raise TypeError(
            f"projectile must be a RigidProjectile, got {type(projectile).__name__}: use "
            "dolfinx_meshfree.dynamics.RigidProjectile(radius, length, mass, velocity, tip)"
        )
    d = evaluator.disc
    comm = evaluator.comm

    def check() -> None:
        if d.mesh is None:
            raise ValueError("a projectile needs the model's mesh (its vertices are struck)")
        if evaluator.expand is not None:
            raise ValueError(
                "a projectile is not available with master-slave's rotating links (finite "
                "strain, slaves='band'): use slaves='layer' or another coupling"
            )

    raise_on_all_ranks(comm, check)
    gdim = d.gdim
    radial = "axisymmetric" if d.axisymmetric else ("3d" if gdim == 3 else "plane")
    points, cells = contact_points(evaluator, where)
    if radial == "axisymmetric":  # the axis is not struck (module docstring)
        size = float(np.ptp(points, axis=0).max(initial=0.0)) if len(points) else 0.0
        off = points[:, 0] > 1e-12 * max(size, 1e-300)
        points, cells = points[off], cells[off]
    count = comm.allreduce(len(points))
    if count == 0:
        raise_on_all_ranks(comm, _nothing_struck)
    rho = radial_distance(points, radial)
    near = comm.allreduce(float(rho.min(initial=np.inf)), op=MPI.MIN)
    if not near < projectile.radius:  # the same on every rank
        raise_on_all_ranks(comm, lambda: _passes_through(near, projectile.radius))
    counts = comm.allgather(len(points))
    start = int(sum(counts[: comm.rank]))
    nv = int(sum(counts))
    rows = ContactSurfaces(
        np.zeros((nv, gdim)), np.zeros((0, gdim), dtype=np.int64), np.zeros(0, dtype=np.int8),
        np.zeros(nv, dtype=np.int8), (start, start + len(points)),
    )  # fmt: skip
    tables = evaluator.point_tables(points, cells)
    masses = system.mass()
    A = evaluation_operators(evaluator, rows, tables, masses)
    m_s = point_masses(A, masses, gdim)
    k = projectile.factor * m_s * omega_0**2
    return ProjectileContactSystem(system, projectile, points, A, k, radial)


def _passes_through(near: float, radius: float) -> None:
    raise ValueError(
        f"no struck point lies within the projectile's radius {radius:.6g} of its axis (the "
        f"nearest at {near:.6g}{', the axis left out' if near > 0 else ''}): it would pass "
        "through the model untouched; refine the mesh or the particles along its path (a "
        "spacing well below the radius)"
    )


def _nothing_struck() -> None:
    raise ValueError(
        "where(x) holds at no vertex or particle of the model: the projectile would strike "
        "nothing; widen where, or pass where=None (every point)"
    )
