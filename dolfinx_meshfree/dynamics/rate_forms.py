"""Rate-form laws (:class:`~dolfinx_meshfree.HolmquistJohnsonCook`,
:class:`~dolfinx_meshfree.JohnsonCook`) in explicit dynamics: their state at the quadrature
points, advanced once per step.

A rate-form law integrates its stress from one deformation gradient to the next over the time
between them (:mod:`~dolfinx_meshfree.physics.objective`), so the explicit loop (Rabczuk et al.
2006, eq. 86–92: one internal force ``f^int(d_n)`` per step) drives it: the stepper tells the
system the time ``t_n`` of each force evaluation (``set_time``), and the evaluation at ``d_n``
advances the state of every point from ``F_{n-1}`` over ``t_n - t_{n-1}`` to ``F_n``. An
evaluation at the same time and gradients (a run continued from where the last one stopped)
returns the stress it has; going back in time is refused (the state cannot be undone).

:class:`RateLaw` is the law as the force code sees it (the
:class:`~dolfinx_meshfree.physics.constitutive.Material` protocol): ``first_piola`` is the nominal
stress ``J sigma F^{-T}`` (in-plane part in 2D) of the advanced state, ``strain_energy_density``
the stress work per unit reference volume the state carries (the records' internal energy:
stored and dissipated together), ``tangent`` the elastic tangent of its stiffest linear twin
(the law's ``stiffest_bulk_modulus`` and its shear modulus; scaled up if the points' current
wave speed ever passes the twin's): the stable-step bound of
:mod:`~dolfinx_meshfree.dynamics.time_step` uses it, so the step is safe after the concrete
compacts (HJC's fully dense ``K1`` is 5.3 times its elastic ``K_e``: the step is 0.58 of the
virgin concrete's from the start), and ``wave_speed`` the larger of the twin's and the points'
current dilatational speed, which the run's re-bound check watches (so it re-bounds only when the
points outrun the twin). The FE cells evaluate it at their Gauss points
with :class:`PointFESide` (it has no UFL form; on quadrilaterals and hexahedra at their cells' mean
dilatation, :mod:`~dolfinx_meshfree.dynamics.rate_dilatation`), the particles through
:class:`~dolfinx_meshfree.statics.sides.ParticleSide` unchanged, and the ramps' interface cells
through :class:`~dolfinx_meshfree.statics.sides.BlendedSide` on their blended table (Belytschko
et al. 1995, eq. 3.12-3.16) with points of their own.

A law's artificial bulk viscosity (its ``viscosity``, on by default:
:mod:`~dolfinx_meshfree.physics.bulk_viscosity`) lives here, not in the law: each point's
viscous pressure ``q`` from the volume ratios of its last two updates and its reference length
(the side gives it: an FE cell's size, the local particle spacing, :meth:`RateLaw.attach`); the
forces see ``sigma - q I``, the state keeps the law's stress; ``q``'s work joins the internal
energy (the state's ``viscous_work``), and the stable step is divided by the largest of the
points' Wilkins factors (:meth:`RateLaw.viscous_factor`; the run checks it every step).

A model's law is a :class:`RateLaws`: one :class:`RateLaw` per side (the FE cells, the particles,
the ramps' blended cells; master–slave's particles, seen through its reduction, Rabczuk et al.
2006, eq. 27-28; the hybrid's particle energy, its SPH sums of the nominal stress at the points of
its rule, eq. 125-130, HA-F), one clock. Every method of explicit dynamics carries it
(:data:`RATE_METHODS`).
"""

from __future__ import annotations

from collections.abc import Callable

import dolfinx
import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc
from scipy.spatial import cKDTree

from .. import _compat
from ..approx.fe_dofs import fe_dof_layout
from ..approx.fe_points import tabulate_in_cells
from ..geometry.quadrature import QuadraturePoints, cell_quadrature, cell_sizes
from ..physics import rate_kernels
from ..physics.axisymmetry import revolved
from ..physics.bulk_viscosity import (
    current_lengths,
    viscous_pressure,
    volume_ratios,
    volumetric_rate,
)
from ..physics.constitutive import DeformationError, check_deformation_gradients
from ..physics.forces import InternalForces
from ..physics.materials import AXISYMMETRIC, LinearElastic, is_axisymmetric
from ..physics.objective import as_3d, nominal_stress
from ..physics.state import is_rate_law
from ..physics.zones import MaterialZones
from ..statics.petsc import create_aij, create_vector
from .rate_dilatation import MeanDilatationLaw
from .time_step import same_time

__all__ = [
    "RATE_METHODS",
    "VISCOUS_FIELDS",
    "PointFESide",
    "RateLaw",
    "RateLaws",
    "carry_state",
    "is_viscous",
    "nearest_in_cell",
    "with_viscous_fields",
    "zone_laws",
]

#: The methods of explicit dynamics that carry a rate-form law's state (all of them): each side
#: of theirs has its own points, the ramps' blended interface cells, master–slave's reduced
#: particles and the hybrid's SPH sums (HA-F) too.
RATE_METHODS = (
    "fe", "efg", "lagrange", "edge-to-edge", "bridging", "ramp", "ramp-cubic", "master-slave",
    "hybrid",
)  # fmt: skip


#: The state a law's artificial bulk viscosity adds to every point (its own state does not
#: carry it): the viscous pressure ``q`` of the last update and the work it did per unit
#: reference volume (:mod:`~dolfinx_meshfree.physics.bulk_viscosity`).
VISCOUS_FIELDS = ("viscous_pressure", "viscous_work")
#: The identity, row-major: the gradient given to dead points' lengths.
_EYE9 = np.eye(3).reshape(9)


def zone_laws(law: object) -> list:
    """The laws of a :class:`~dolfinx_meshfree.MaterialZones` (one per zone), else ``[law]``."""
    return list(law.laws) if isinstance(law, MaterialZones) else [law]


def is_viscous(law: object) -> bool:
    """Whether a rate-form law (any zone of it) carries an artificial bulk viscosity."""
    return any(getattr(z, "viscosity", None) is not None for z in zone_laws(law))


def with_viscous_fields(state: dict[str, np.ndarray], law: object) -> dict[str, np.ndarray]:
    """``state`` (a virgin one of ``m`` points) with :data:`VISCOUS_FIELDS` at zero where
    ``law`` carries a viscosity (in place; returned)."""
    if is_viscous(law):
        m = len(state["F"])
        state.update({name: np.zeros((m, 1)) for name in VISCOUS_FIELDS})
    return state


def stiffest_twin(law: object) -> LinearElastic:
    """The linear law of a rate-form ``law``'s ``stiffest_bulk_modulus`` and shear modulus, its
    density and plane: the masses, the linear stiffness and the stable-step bound."""
    K, G = float(law.stiffest_bulk_modulus), float(law.G)
    return LinearElastic(
        E=9.0 * K * G / (3.0 * K + G),
        nu=(3.0 * K - 2.0 * G) / (2.0 * (3.0 * K + G)),
        plane=(AXISYMMETRIC if is_axisymmetric(law) else "strain") if law.gdim == 2 else None,
        rho=float(law.rho),
    )


def elastic_tangent(twin: LinearElastic, m: int) -> np.ndarray:
    """The isotropic tangent ``C_iJkL = lambda d_iJ d_kL + mu (d_ik d_JL + d_iL d_Jk)`` (m, d,
    d, d, d) of a twin's Lamé constants, in its plane (the (r, z) block of an axisymmetric
    twin: its hoop terms are the force operator's, ``InternalForces._hoop_tangent``)."""
    eye = np.eye(twin.gdim)
    C = twin.lmbda * np.einsum("ij,kl->ijkl", eye, eye) + twin.mu * (
        np.einsum("ik,jl->ijkl", eye, eye) + np.einsum("il,jk->ijkl", eye, eye)
    )
    return np.broadcast_to(C, (m, *C.shape)).copy()


class RateLaw:
    """A rate-form law bound to the state of one set of points (one side of a model), as a
    :class:`~dolfinx_meshfree.physics.constitutive.Material` (module docstring).

    The points are the first ``first_piola`` call's (their number fixes the state's size).
    A :class:`~dolfinx_meshfree.MaterialZones` law takes ``cell_zone``, the zone of every local
    cell, and needs its points' cells (:meth:`attach`) before the first force.
    """

    def __init__(self, law: object, cell_zone: np.ndarray | None = None) -> None:
        if not is_rate_law(law):
            raise TypeError(f"law must be a rate-form law, got {type(law).__name__}")
        if isinstance(law, MaterialZones) and cell_zone is None:
            raise ValueError("a MaterialZones law needs the zone of every cell (cell_zone)")
        self.law = law
        self.cell_zone = None if cell_zone is None else np.asarray(cell_zone, dtype=np.int64)
        #: The zone of each point (m,) (a :class:`~dolfinx_meshfree.MaterialZones` law).
        self.zones: np.ndarray | None = None
        #: Per zone, its stiffest linear twin (one zone for a single law).
        self.twins = (
            [stiffest_twin(z) for z in zone_laws(law)] if isinstance(law, MaterialZones) else None
        )
        #: The stiffest linear twin (:func:`stiffest_twin`).
        self.twin = stiffest_twin(law)
        self.plane, self.rho, self.E, self.nu = (
            self.twin.plane,
            self.twin.rho,
            self.twin.E,
            self.twin.nu,
        )
        #: The state of the points (this rank's), their Cauchy stress (m, 3, 3) and reference
        #: coordinates (m, gdim): ``None`` until the first force.
        self.state: dict[str, np.ndarray] | None = None
        self.sigma: np.ndarray | None = None
        self.points: np.ndarray | None = None
        #: The local cell of each point (m,), given by the side that binds the law
        #: (:meth:`attach`): the state criteria and a conversion's transfer read it.
        self.cells: np.ndarray | None = None
        #: The time of the state, and the time of the next evaluation (``set_time``).
        self.time = 0.0
        self.clock = 0.0
        #: Set by a conversion (:func:`carry_state`): the next evaluation at the state's time
        #: takes its deformation gradient (the new field's) as the state's, the stress kept.
        self.rebase = False
        #: Whether the law carries an artificial bulk viscosity (:meth:`_viscous`), per zone its
        #: coefficients ``(c_q, c_l)`` (zeros: none), its twin's wave speed and its density.
        self.viscous = is_viscous(law)
        self._viscosity = np.array(
            [(z.viscosity.quadratic, z.viscosity.linear) if z.viscosity else (0.0, 0.0)
             for z in zone_laws(law)]
        )  # fmt: skip
        twins = self.twins if self.twins is not None else [self.twin]
        self._speeds = np.array([twin.wave_speed() for twin in twins])
        self._densities = np.array([twin.rho for twin in twins])
        #: The reference length of each point (m,) (:meth:`attach`): a viscosity's ``l_0``.
        self.lengths: np.ndarray | None = None
        #: Each point's step factor of the viscosity at the last update (``None``: 1).
        self.factor: np.ndarray | None = None

    def attach(
        self, points: np.ndarray, cells: np.ndarray, lengths: np.ndarray | None = None
    ) -> None:
        """The points (m, gdim, reference coordinates), their local cells (m,) and their
        reference lengths (m,: an FE cell's size, the local particle spacing; what a viscosity
        needs), known when the side is built (before any force)."""
        points, cells = np.asarray(points, dtype=float), np.asarray(cells, dtype=np.int64)
        if len(points) != len(cells):
            raise ValueError(f"{len(points)} points but {len(cells)} cells: one cell per point")
        self.points, self.cells = points.copy(), cells.copy()
        if lengths is not None:
            lengths = np.asarray(lengths, dtype=float)
            if lengths.shape != (len(points),) or not np.all(lengths > 0.0):
                raise ValueError(
                    f"lengths: {lengths.shape} values for {len(points)} points; one positive "
                    "length per point"
                )
            self.lengths = lengths.copy()
        if self.cell_zone is not None:
            if len(cells) and not (cells.min() >= 0 and cells.max() < len(self.cell_zone)):
                raise ValueError(
                    f"a point's cell lies outside the {len(self.cell_zone)} local cells whose "
                    "zones are known; the zones and the points must be of one mesh"
                )
            self.zones = self.cell_zone[cells]

    def initial_state(self, m: int) -> dict[str, np.ndarray]:
        """The virgin state of ``m`` points (a zoned law: of the attached points' zones), with
        :data:`VISCOUS_FIELDS` where the law carries a viscosity."""
        return with_viscous_fields(self._law_initial_state(m), self.law)

    def _law_initial_state(self, m: int) -> dict[str, np.ndarray]:
        if not isinstance(self.law, MaterialZones):
            return self.law.initial_state(m)
        if self.zones is None or len(self.zones) != m:
            raise ValueError(
                f"{self.law!r}: {m} points, but {0 if self.zones is None else len(self.zones)} "
                "were attached with their cells; a zoned law needs every point's cell (attach)"
            )
        return self.law.initial_state(m, self.zones)

    @property
    def gdim(self) -> int:
        return int(self.law.gdim)

    def set_time(self, t: float) -> None:
        """The time of the next evaluation (the stepper's ``t_n``)."""
        self.clock = float(t)

    def stress(
        self, F: np.ndarray, points: np.ndarray | None = None, hoop: np.ndarray | None = None
    ) -> np.ndarray:
        """The Cauchy stress (m, 3, 3) at ``F`` (m, d, d), the state advanced to the clock;
        ``points`` (m, gdim), the points' reference coordinates, are kept on the first call;
        ``hoop`` (m,): an axisymmetric law's hoop stretch ``r / R`` (its ``F_zz``)."""
        F = np.asarray(F, dtype=float)
        m = len(F)
        if self.state is None:
            self.state = self.initial_state(m)
            self.sigma = np.zeros((m, 3, 3))
            if self.points is None and points is not None:
                self.points = np.array(points, dtype=float)
        made_for = len(self.state["F"]) if self.points is None else len(self.points)
        if m != len(self.state["F"]) or m != made_for:
            raise ValueError(
                f"{type(self.law).__name__}: {m} points, but its state was made for "
                f"{made_for}: one RateLaw per set of points"
            )
        dt = 0.0 if same_time(self.clock, self.time) else self.clock - self.time
        if m == 0:  # a rank with none of this side's points
            self.time = self.clock
            return self.sigma
        if dt == 0.0:
            if self.rebase:  # the first force of a converted model: its field's gradients
                self.state["F"] = as_3d(F, hoop).reshape(m, 9).copy()
                self.rebase = False
            elif not np.array_equal(as_3d(F, hoop).reshape(m, 9), self.state["F"]):
                raise ValueError(
                    f"{type(self.law).__name__}: the deformation changed with no time passing "
                    f"(t = {self.clock:.6g}): a rate-form law starts from rest, undeformed; give "
                    "initial velocities, not an initial displacement"
                )
            return self._with_viscosity()
        if dt < 0.0:
            raise ValueError(
                f"{type(self.law).__name__}: asked for t = {self.clock:.6g} before its state's "
                f"t = {self.time:.6g}; a rate-form law's state cannot go back: build the model "
                "again to start over"
            )
        extra = {} if hoop is None else {"hoop": hoop}
        old = self.state
        own = {k: v for k, v in old.items() if k not in VISCOUS_FIELDS}
        try:  # the law sees its own state only
            self.sigma, new = self.law.update(F, dt, own, **extra)
        except DeformationError:  # again, naming the point by its reference coordinates
            check_deformation_gradients(as_3d(F, hoop), 3, self.points)
            raise
        self.state = self._viscous(old, new, dt) if self.viscous else new
        self.time = self.clock
        return self._with_viscosity()

    def _viscous(
        self, old: dict[str, np.ndarray], new: dict[str, np.ndarray], dt: float
    ) -> dict[str, np.ndarray]:
        """``new`` with the viscous pressure and work of the step from ``old`` (module
        :mod:`~dolfinx_meshfree.physics.bulk_viscosity`), and the points' step factors. Eroded
        and inverted points carry none."""
        if self.lengths is None:
            raise ValueError(
                f"{type(self.law).__name__}: its bulk viscosity needs each point's length, which "
                "the side binding the law gives (attach(points, cells, lengths)); or give the "
                "law viscosity=None"
            )
        m = len(new["F"])
        J_old, J_new = volume_ratios(old["F"]), volume_ratios(new["F"])
        live = np.isfinite(J_old) & np.isfinite(J_new) & (J_old > 0.0) & (J_new > 0.0)
        if "eroded" in new:
            live &= new["eroded"][:, 0] == 0
        zone = self.zones if self.zones is not None else np.zeros(m, dtype=np.int64)
        coeff, c = self._viscosity[zone], self._speeds[zone]
        J = np.where(live, J_new, 1.0)
        rate = np.where(live, volumetric_rate(np.where(live, J_old, 1.0), J, dt), 0.0)
        # dead points take the identity: their length stays l_0 (s_min(I) = 1 exactly)
        F_live = np.where(live[:, None], new["F"], _EYE9)
        backend = getattr(self.law, "backend", None)
        length = current_lengths(F_live, self.lengths, self.plane, backend)
        q, self.factor = viscous_pressure(
            rate, J, self._densities[zone], c, length, coeff[:, 0], coeff[:, 1]
        )
        q_old = old["viscous_pressure"][:, 0]
        work = np.where(live, -0.5 * (q_old + q) * (J_new - J_old), 0.0)
        return dict(
            new,
            viscous_pressure=q[:, None],
            viscous_work=old["viscous_work"] + work[:, None],
        )

    def _with_viscosity(self) -> np.ndarray:
        """The Cauchy stress the forces see: the law's, less the viscous pressure ``q I``."""
        if not self.viscous or self.state is None or not len(self.sigma):
            return self.sigma
        out = self.sigma.copy()
        q = self.state["viscous_pressure"][:, 0]
        for i in range(3):
            out[:, i, i] -= q
        return out

    def first_piola(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """``J sigma F^{-T}`` (m, d, d) of the advanced state."""
        if is_axisymmetric(self):
            raise ValueError(
                f"{type(self.law).__name__} is axisymmetric: its forces need the hoop stretch "
                "(axisymmetric_piola), which this path does not give"
            )
        d = self.gdim
        P = nominal_stress(self.stress(F, points), as_3d(np.asarray(F, dtype=float)))
        return P[:, :d, :d]

    def axisymmetric_piola(
        self, F: np.ndarray, points: np.ndarray, hoop: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``J sigma F^{-T}`` of an axisymmetric law at ``F`` (m, 2, 2) and the hoop stretch
        ``hoop`` (m,): its (r, z) block (m, 2, 2) and its hoop component ``P_tt`` (m,)."""
        F3 = as_3d(np.asarray(F, dtype=float), hoop)
        P = nominal_stress(self.stress(F, points, hoop), F3)
        return P[:, :2, :2], P[:, 2, 2]

    def tangent(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """The stiffest twin's elastic tangent (for the stable-step bound), scaled up by
        ``(c / c_twin)^2`` where the points' current wave speed ``c`` has passed the twin's
        (extreme compaction), and at each point by ``1 / s_min(F)^2`` (:meth:`stretches`: a
        crushed cell's frequencies in the reference configuration), so that a re-bound sees
        both. The stretch is each point's own, so the bound does not depend on the partition."""
        F = np.asarray(F, dtype=float)
        if self.twins is None:
            scale = max(1.0, (float(self.law.wave_speed(self.state)) / self.twin.wave_speed()) ** 2)
            out = scale * elastic_tangent(self.twin, len(F))
        else:
            d = self.gdim
            out = np.zeros((len(F), d, d, d, d))
            scale = self._zone_ratios() ** 2
            for k, twin in enumerate(self.twins):
                idx = np.flatnonzero(self.zones == k)
                if idx.size:
                    out[idx] = scale[k] * elastic_tangent(twin, idx.size)
        stretch = self.stretches()
        if stretch is not None and len(stretch) == len(out):
            out *= (1.0 / stretch**2)[:, None, None, None, None]
        return out

    def _zone_ratios(self) -> np.ndarray:
        """Per zone of a zoned law, its points' current wave speed over its own twin's, at
        least 1 (1 before the first force and for a zone without points)."""
        twin_speeds = np.array([twin.wave_speed() for twin in self.twins])
        if self.state is None:
            return np.ones(len(self.twins))
        return np.maximum(1.0, self.law.zone_wave_speeds(self.state) / twin_speeds)

    def stretches(self) -> np.ndarray | None:
        """Each point's smallest principal stretch ``s_min(F)``, at most 1 (eroded points: 1,
        as they carry nothing); ``None`` before the first force. In the reference
        configuration the discretisation's frequencies grow as the cells shrink, ``omega ~ c /
        (s_min h)``: the stable step must see the stretch as well as the current wave speed
        ``c`` (a cell crushed to half its height halves the step whatever ``c``)."""
        if self.state is None:
            return None
        F = self.state["F"].reshape(-1, 3, 3)
        s = np.ones(len(F))
        live = self.state["eroded"][:, 0] == 0 if "eroded" in self.state else np.ones(len(F), bool)
        if rate_kernels.resolve_backend(getattr(self.law, "backend", None)) == "numba":
            s = rate_kernels.smallest_stretches(self.state["F"], live)
        elif live.any():
            s[live] = np.linalg.svd(F[live], compute_uv=False)[:, -1]
        return np.clip(s, 1e-12, 1.0)

    def compression(self) -> float:
        """``1 / min_q s_min(F_q)`` over this rank's points (:meth:`stretches`; at least 1)."""
        s = self.stretches()
        return 1.0 / float(s.min(initial=1.0)) if s is not None else 1.0

    def strain_energy_density(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """The stress work per unit reference volume of the state (m,), the viscous work with
        it (the energy record's internal energy: stored and dissipated)."""
        if self.state is None:
            return np.zeros(len(F))
        work = self.state["work"][:, 0].copy()
        if self.viscous:
            work += self.state["viscous_work"][:, 0]
        return work

    def viscous_factor(self) -> float:
        """The largest step factor of the viscosity over this rank's points at their last
        update (1 without): the stable step's divisor
        (:meth:`~dolfinx_meshfree.dynamics.time_step.TimeStepBound.stable`)."""
        return float(self.factor.max(initial=1.0)) if self.factor is not None else 1.0

    def ufl_first_piola(self, F: object) -> object:
        raise TypeError(
            f"{type(self.law).__name__} is a rate-form law: it has no UFL expression (the FE cells "
            "evaluate it at their points, PointFESide)"
        )

    def points_wave_speed(self) -> float:
        """The largest current dilatational wave speed of the points, over their smallest
        principal stretch (:meth:`compression`): the speed at which waves cross the cells'
        reference lengths."""
        return float(self.law.wave_speed(self.state)) * self.compression()

    def wave_speed(self, F: np.ndarray | None = None) -> float:
        """The speed the stable step is bounded with: the stiffest twin's, or the points'
        current one where it is larger (``F`` is not used). The run re-bounds only when the
        points outrun the twin (a compaction past it), not as they stiffen below it. A zoned
        law: the stiffest twin's speed times the largest ratio of a zone's points' speed to its
        own twin's (at least 1), so that a soft zone outrunning its twin re-bounds the step
        even while it stays slower than the stiffest zone."""
        if self.twins is None:
            return max(self.points_wave_speed(), self.twin.wave_speed())
        return float(self._zone_ratios().max()) * self.twin.wave_speed()


class RateLaws:
    """A rate-form law over the sides of one model: a :class:`RateLaw` per side (:meth:`bind`),
    one clock (:meth:`set_time`); what the system and the user see.

    ``state``, ``sigma`` and ``points`` join the sides' (FE first), so that
    ``dyn.material.state["damage"]`` holds every point of this rank.
    """

    def __init__(self, law: object, cell_zone: np.ndarray | None = None) -> None:
        if not is_rate_law(law):
            raise TypeError(f"law must be a rate-form law, got {type(law).__name__}")
        self.law, self.twin = law, stiffest_twin(law)
        #: The zone of every local cell of the model's mesh (a
        #: :class:`~dolfinx_meshfree.MaterialZones` law), else ``None``.
        self.cell_zone = cell_zone
        self.members: list[RateLaw] = []
        self.plane, self.rho, self.E, self.nu = (
            self.twin.plane,
            self.twin.rho,
            self.twin.E,
            self.twin.nu,
        )
        if isinstance(law, MaterialZones):  # the contact penalty's modulus: the largest
            self.E = max(stiffest_twin(zone).E for zone in law.laws)
        self.clock = 0.0

    @property
    def gdim(self) -> int:
        return int(self.law.gdim)

    @property
    def zoned(self) -> bool:
        """Whether the law is a :class:`~dolfinx_meshfree.MaterialZones`."""
        return self.cell_zone is not None

    def density_at_cells(self, cells: np.ndarray) -> float | np.ndarray:
        """The density of points in the given local cells: the law's, or per point its cell's
        zone's (a zoned law)."""
        if self.cell_zone is None:
            return float(self.rho)
        return self.law.densities()[self.cell_zone[np.asarray(cells, dtype=np.int64)]]

    def density_at(self, x: np.ndarray) -> float | np.ndarray:
        """The density at points ``x`` (n, gdim): the law's, or per point its zone's by the
        markers (a zoned law: particles' ``rho V_I`` masses)."""
        if self.cell_zone is None:
            return float(self.rho)
        return self.law.densities()[self.law.zone_of(x)]

    def fe_density(self, V: dolfinx.fem.FunctionSpace) -> float | dolfinx.fem.Function:
        """The density of the FE lumped masses: the law's, or a DG0 field of the cells' zones'
        (a zoned law)."""
        if self.cell_zone is None:
            return float(self.rho)
        V0 = _compat.scalar_function_space(V.mesh, "DG", 0)
        rho = dolfinx.fem.Function(V0)
        dofs = _compat.dofmap_array(V0)[:, 0]
        rho.x.array[dofs] = self.density_at_cells(np.arange(len(dofs)))
        return rho

    def bind(self) -> RateLaw:
        """The law of one more side (its own points' state)."""
        member = RateLaw(self.law, self.cell_zone)
        member.set_time(self.clock)
        self.members.append(member)
        return member

    def set_time(self, t: float) -> None:
        """The time of the next internal force, for every side."""
        self.clock = float(t)
        for member in self.members:
            member.set_time(t)

    def wave_speed(self, F: np.ndarray | None = None) -> float:
        """The largest of the sides' (:meth:`RateLaw.wave_speed`; the twin's before any side;
        ``F`` is not used)."""
        return max((m.wave_speed() for m in self.members), default=self.twin.wave_speed())

    def viscous_factor(self) -> float:
        """The largest of the sides' :meth:`RateLaw.viscous_factor` (this rank's points)."""
        return max((m.viscous_factor() for m in self.members), default=1.0)

    def _joined(self, name: str) -> np.ndarray | None:
        parts = [getattr(m, name) for m in self.members if m.state is not None]
        return np.concatenate(parts) if parts else None

    @property
    def state(self) -> dict[str, np.ndarray] | None:
        """Every side's state fields, joined (this rank's points; ``None`` before a force)."""
        states = [m.state for m in self.members if m.state is not None]
        if not states:
            return None
        return {k: np.concatenate([s[k] for s in states]) for k in states[0]}

    @property
    def sigma(self) -> np.ndarray | None:
        """The points' Cauchy stress (m, 3, 3), joined."""
        return self._joined("sigma")

    @property
    def points(self) -> np.ndarray | None:
        """The points' reference coordinates (m, gdim), joined."""
        return self._joined("points")

    def _virgin(self) -> dict[str, np.ndarray]:
        """The virgin state of one point (with :data:`VISCOUS_FIELDS` for a viscous law)."""
        return with_viscous_fields(self.law.initial_state(1), self.law)

    @property
    def viscous(self) -> bool:
        """Whether the law carries an artificial bulk viscosity (a zone of it)."""
        return is_viscous(self.law)

    def scalar_names(self) -> list[str]:
        """The law's scalar state variables, in its order (``"damage"``, ...), then the
        viscosity's."""
        virgin = self._virgin()
        return [k for k, v in virgin.items() if np.asarray(v).reshape(1, -1).shape[1] == 1]

    def state_values(self, name: str) -> tuple[np.ndarray, np.ndarray, float]:
        """``(cells, values, virgin)``: a scalar state variable ``name`` at every point of this
        rank whose cell is known (:meth:`RateLaw.attach`; the virgin state before the first
        force), the points' local cells, and the variable's value in the virgin state.

        Raises:
            ValueError: ``name`` is not a scalar state variable of the law (the message lists
                them).
        """
        virgin = self._virgin()
        scalars = self.scalar_names()
        if name not in scalars:
            raise ValueError(
                f"{name!r} is not a scalar state variable of {type(self.law).__name__}; use one "
                f"of {scalars}"
            )
        cells, values = [np.zeros(0, dtype=np.int64)], [np.zeros(0)]
        for member in self.members:
            if member.cells is None:
                continue
            m = len(member.cells)
            state = member.state if member.state is not None else member.initial_state(m)
            cells.append(member.cells)
            values.append(np.asarray(state[name], dtype=float).reshape(m))
        return np.concatenate(cells), np.concatenate(values), float(virgin[name].ravel()[0])


def nearest_in_cell(
    src_points: np.ndarray, src_cells: np.ndarray, points: np.ndarray, cells: np.ndarray
) -> np.ndarray:
    """For each point (m, gdim) in its local cell (m,): the index of the nearest source point in
    the same cell, ``-1`` where that cell has none (a k-d tree on the coordinates and the cell
    index times a length larger than any distance between the points). Source points equally
    near (to round-off: a particle at a cell's centre and the cell's Gauss points) go to the one
    with the smallest coordinates, so the choice does not depend on the partition (the tree's
    order of equal distances does: on 2 ranks the hybrid's converted particles took other Gauss
    points' damage than serially, and the Hanchak shot's exit velocity differed by 2e-6)."""
    out = np.full(len(points), -1, dtype=np.int64)
    if not len(points) or not len(src_points):
        return out
    both = np.concatenate([src_points, points])
    extent = float(np.ptp(both, axis=0).max())
    far = 4.0 * (extent + 1.0)
    tree = cKDTree(np.column_stack([src_points, far * np.asarray(src_cells, dtype=float)]))
    k = min(8, len(src_points))
    dist, found = tree.query(np.column_stack([points, far * np.asarray(cells, dtype=float)]), k=k)
    dist, found = dist.reshape(len(points), k), found.reshape(len(points), k)
    rank = np.empty(len(src_points), dtype=np.int64)  # the coordinates' lexicographic order
    rank[np.lexsort(src_points.T[::-1])] = np.arange(len(src_points))
    tie = dist <= dist[:, :1] + 1e-12 * max(extent, 1e-300)
    key = np.where(tie, rank[np.minimum(found, len(src_points) - 1)], len(src_points))
    index = found[np.arange(len(points)), np.argmin(key, axis=1)]
    same = np.asarray(src_cells)[index] == cells
    out[same] = index[same]
    return out


def carry_state(old: RateLaws, new: RateLaws) -> None:
    """Carry the state of ``old`` (a model's law, advanced to its last force) into ``new`` (the
    law of its rebuild on another patch, before any force): every point of ``new`` takes the
    state and the stress of the nearest point of ``old`` in the same cell, of its own side
    (FE, particles) where that side had points in the cell, else of any side. Points of a
    patch cell whose rule is unchanged are the old points, so their state is theirs; a
    converted FE cell's particles take the state of its Gauss points (the nearest: damage and
    plastic strain are not smoothed away), a released cell's Gauss points the particles'. If
    the old model never ran a force, the new one starts virgin too.

    The state's deformation gradient is then the old field's, not the new one's at the point
    (the fit differs from the old field by what the new space cannot represent): each member
    is set to take, at its first force (the conversion's, at the same time), the new field's
    gradients as the state's, so that the next increment is the motion's and not the fit's
    difference. Local (this rank's points).

    Raises:
        ValueError: a new side gave no points (:meth:`RateLaw.attach`), or a new point's cell
            has no old point on this rank (named by its coordinates).
    """
    if any(member.cells is None for member in new.members):
        raise ValueError("carry_state: the new law's sides must give their points (attach)")
    new.clock = old.clock
    for member in new.members:
        member.time = member.clock = old.clock
    src = [m for m in old.members if m.state is not None and m.cells is not None]
    if not src:  # the old model never ran a force
        return
    offsets = np.cumsum([0] + [len(s.cells) for s in src])
    points = np.concatenate([s.points for s in src])
    cells = np.concatenate([s.cells for s in src])
    state = {key: np.concatenate([s.state[key] for s in src]) for key in src[0].state}
    sigma = np.concatenate([s.sigma for s in src])
    for k, member in enumerate(new.members):
        index = np.full(len(member.cells), -1, dtype=np.int64)
        if k < len(old.members) and old.members[k] in src:  # its own side first
            j = src.index(old.members[k])
            own = nearest_in_cell(src[j].points, src[j].cells, member.points, member.cells)
            index[own >= 0] = offsets[j] + own[own >= 0]
        rest = index < 0
        index[rest] = nearest_in_cell(points, cells, member.points[rest], member.cells[rest])
        if np.any(index < 0):
            x = member.points[np.flatnonzero(index < 0)[0]]
            raise ValueError(
                f"carry_state: the new point at {np.array2string(x, precision=6)} has no old "
                "point in its cell on this rank; a conversion keeps the cells' ownership"
            )
        member.state = {key: value[index] for key, value in state.items()}  # copies
        member.sigma = sigma[index]
        member.rebase = True


class PointFESide:
    """The FE field's internal force of a :class:`RateLaw` at the Gauss points of the owned cells
    (``f^int = sum_q B0^T P w_q`` by :class:`~dolfinx_meshfree.InternalForces` on the FE basis
    tabulated at the points), in the FE field's PETSc numbering; the interface of
    :class:`~dolfinx_meshfree.statics.sides.ParticleSide` (collective calls).

    Args:
        V: The vector P1/Q1 space. law: The bound law. cells: Flags of the local cells it acts on
            (``None``: every owned cell). weight_at: ``weight_at(q)`` (m,), a factor of the
            points' weights (the bridging band's ``beta_FE = 1 - alpha``), or ``None``.
        degree: The Gauss rule (2: the P1/Q1 stiffness exactly).
        dilatation: Whether the law runs at its cells' mean dilatation
            (:mod:`~dolfinx_meshfree.dynamics.rate_dilatation`: Q1 cells in plane strain,
            axisymmetry and 3D do not lock under plastic flow).
    """

    def __init__(
        self,
        V: dolfinx.fem.FunctionSpace,
        law: RateLaw,
        cells: np.ndarray | None = None,
        weight_at: Callable[[QuadraturePoints], np.ndarray] | None = None,
        degree: int = 2,
        dilatation: bool = False,
    ) -> None:
        msh = V.mesh
        self.comm = msh.comm
        self.V = V
        self.u = dolfinx.fem.Function(V)
        self.u.x.array[:] = 0.0
        self.layout, l2g = fe_dof_layout(V)
        #: The global node of each local node (owned and ghost), as FESide's.
        self.l2g = np.asarray(l2g)
        self.gdim = gdim = msh.geometry.dim
        self.n_owned = gdim * V.dofmap.index_map.size_local
        self.dofs = (gdim * np.asarray(l2g)[:, None] + np.arange(gdim)).ravel().astype(np.int64)
        n_owned = msh.topology.index_map(msh.topology.dim).size_local
        owned = np.arange(n_owned) if cells is None else np.flatnonzero(cells[:n_owned])
        q = cell_quadrature(msh, degree, owned.astype(np.int32))
        if is_axisymmetric(law):  # 2 pi R w (the hoop terms: InternalForces)
            q = revolved(q)
        table = tabulate_in_cells(V, q.points, q.cells, derivatives=1)
        w = q.weights if weight_at is None else q.weights * weight_at(q)
        law.attach(q.points, q.cells, cell_sizes(msh, q.cells))
        #: The law as the force sum reads it: at the cells' mean dilatation, or pointwise.
        self.material = MeanDilatationLaw(law, q.cells, w) if dilatation else law
        self.forces = InternalForces(table, w, self.material, comm=self.comm)

    def coefficients(self, x: PETSc.Vec) -> np.ndarray:
        """The local FE values (owned and ghost nodes, interleaved) of ``x``."""
        self.u.x.array[: self.n_owned] = x.getArray(readonly=True)
        self.u.x.scatter_forward()
        return self.u.x.array

    def set_state(self, x: PETSc.Vec) -> None:
        """``u`` (owned and ghost values) from ``x``: the FE half of a blended side's
        coefficients (:class:`~dolfinx_meshfree.statics.sides.BlendedSide`, the ramps'
        interface cells)."""
        self.coefficients(x)

    def held_everywhere(self) -> np.ndarray:
        """No held dof: this side's rows are all kept (explicit dynamics holds its fixed dofs
        in the stepper), and so are a blended side's."""
        return np.zeros(0, dtype=np.int64)

    def internal_force(self, x: PETSc.Vec) -> PETSc.Vec:
        f = self.forces.internal_force(self.coefficients(x))
        return create_vector(self.comm, self.layout, self.dofs, f)

    def tangent(self, x: PETSc.Vec) -> PETSc.Mat:
        K = self.forces.tangent(self.coefficients(x)).tocoo()
        n = self.layout.size_global
        Kg = sp.csr_matrix((K.data, (self.dofs[K.row], self.dofs[K.col])), shape=(n, n))
        return create_aij(self.comm, Kg, self.layout, self.layout)
