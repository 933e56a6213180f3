"""Path following by indirect displacement control: through the peak of a softening response.

Load control cannot pass a limit point, and the displacement of the loaded point cannot pass a
snap-back. Indirect displacement control (de Borst 1987, "Computation of post-bifurcation and
post-failure behavior of strain-softening solids", Comput. Struct. 25; Crisfield 1991,
*Non-linear Finite Element Analysis of Solids and Structures*, vol. 1, sec. 9.3) makes the load
factor ``t`` an unknown and prescribes instead a quantity that grows monotonically through the
failure: a crack mouth opening (CMOD), a crack mouth sliding (CMSD), an elongation across the band
where the material softens:

.. math::
    R(x, t) = f_{int}(x) - t\\, q = 0, \\qquad g(x) = \\tau_k,

with ``g`` linear in the displacements (:class:`DisplacementControl`: ``sum_k c_k . u(X_k)``)
and ``q = -dR/dt`` (external loads, prescribed values of held dofs, constraint right-hand
sides: ``R`` is affine in ``t``). Each Newton iteration solves ``J da = -R`` and ``J db = q``
with one factorisation and takes ``dt = (tau_k - g(x) - g(da)) / g(db)``, ``x += da + dt db``
(the bordered update), with a line search that keeps the constraint. :class:`ArcLength` replaces
the constraint by Crisfield's cylindrical arc length ``|Dx| = dl`` (a quadratic in ``dt``).

The control increment adapts (:class:`PathOptions`): it grows after a step that converged in few
iterations and is halved, from the last converged state (laws' state included), when a step
does not converge; after ``max_cuts`` halvings the path cannot be followed and
:class:`PathError` names the step, the control value and the load factor.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from ..approx.mls import MomentMatrixError
from ..couplings.base import CoupledSolution
from ..geometry.crack import particle_spacing
from ..geometry.patch_criteria import warn_unused
from ..parallel import raise_on_all_ranks
from ..physics.inelastic import RankineDamage
from ..physics.materials import LinearElastic
from ..physics.state import is_stateful, voigt_strain
from .band_reach import BandCutWarning, band_at_interface
from .bifurcation import StabilityWatch, bordered_sign
from .cohesive import CohesiveSide, check_through
from .cohesive_growth import CohesiveGrowth, _inside, grow_once
from .cohesive_initiation import BulkStrengthWarning, bulk_stress_peaks, site_at
from .coupled_newton import BlockModel, build_block_problem, law_internal_force
from .crack_band_switch import BandEnergy, CrackBandSwitch, hand_over, switch_once
from .crack_initiation import CrackInitiation, first_stretch, insert_crack
from .efg import EFGBlockModel, EFGElasticity
from .fe_model import FEBlockModel, FEElasticity, fe_point_functional
from .patch_growth import PatchEvent
from .path_patch import check_adapt, fit_particles, grow_patch, path_context, site_context
from .petsc import BlockSystem, SolverOptions, solver_options
from .sides import BlockProblem, restore_step
from .state_carry import carry_at_points, carry_pooled, carry_states

if TYPE_CHECKING:  # annotations only
    from ..geometry.crack import Crack
    from ..geometry.patch_criteria import GrowthContext
    from ..physics.state import PointState
    from .coupled import CoupledElasticity

__all__ = [
    "CARRY_TOLERANCE",
    "ENERGY_TOLERANCE",
    "ArcLength",
    "DisplacementControl",
    "DoubleSofteningWarning",
    "EnergyBalanceWarning",
    "PathError",
    "PathOptions",
    "PathResult",
    "PathShortWarning",
    "StateCarryWarning",
    "follow_path",
]


class PathError(RuntimeError):
    """The equilibrium path could not be followed (the step, control value and load factor are
    in the message); ``result`` holds the path up to the last converged step."""

    def __init__(self, message: str, result: PathResult):
        super().__init__(message)
        self.result = result


class PathShortWarning(UserWarning):
    """:func:`follow_path` stopped at ``PathOptions.max_steps`` converged steps before the
    control reached ``end``: the result is the path up to there, shorter than asked (the
    message gives where it stopped and the last increments)."""


@dataclass(frozen=True)
class DisplacementControl:
    """The controlled quantity ``g = sum_k c_k . u(X_k)``: a weighted sum of displacement
    components at points of the body (FE or particle side; a point on the interface is taken on
    the FE side).

    Args:
        points: (k, gdim) reference coordinates.
        directions: (k, gdim) the vectors ``c_k``.

    Example: the opening of a crack mouth between ``(a, 0)`` and ``(b, 0)`` across a vertical
    crack, ``u_x(b) - u_x(a)``: ``DisplacementControl([[a, 0], [b, 0]], [[-1, 0], [1, 0]])``.
    """

    points: npt.ArrayLike
    directions: npt.ArrayLike

    def check(self, gdim: int) -> tuple[np.ndarray, np.ndarray]:
        """The points and directions as (k, gdim) arrays; ValueError on bad input."""
        p = np.atleast_2d(np.asarray(self.points, dtype=float))
        c = np.atleast_2d(np.asarray(self.directions, dtype=float))
        if p.ndim != 2 or p.shape[1] != gdim or p.shape[0] == 0:
            raise ValueError(
                f"DisplacementControl points={self.points!r} must be a (k, {gdim}) array of "
                "points of the body"
            )
        if c.shape != p.shape:
            raise ValueError(
                f"DisplacementControl directions={self.directions!r} must have the shape of "
                f"its points {p.shape}: one vector c_k per point"
            )
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(c))) or not np.any(c):
            raise ValueError(
                f"DisplacementControl directions={self.directions!r} must be finite and not all "
                "zero"
            )
        return p, c


@dataclass(frozen=True)
class ArcLength:
    """Crisfield's cylindrical arc length (Crisfield 1981, "A fast incremental/iterative solution
    procedure that handles snap-through", Comput. Struct. 13; Crisfield 1991, sec. 9.3.1): every
    step moves the displacement fields by ``|dx| = dl`` (the Euclidean norm over the FE and
    particle unknowns), the load factor free; ``PathOptions.increment`` is ``dl`` and ``end`` the
    total arc length. It follows snap-backs of any quantity, with no control quantity to choose;
    its arc length is not a physical quantity (record one with ``monitors``)."""


class DoubleSofteningWarning(UserWarning):
    """A :class:`~dolfinx_meshfree.RankineDamage` bulk whose ``f_t`` is not above the faces' of
    a growing cohesive crack: ahead of the tip the bulk reaches ``f_t`` where the bonded faces
    do, both soften, and the fracture energy is dissipated twice there (the plate of
    ``tests/test_cohesive_growth.py`` with equal strengths: the energy balance off by 7.4 %)."""


class StateCarryWarning(UserWarning):
    """Carrying the bulk's states to a rebuilt model's points changed its dissipated energy by
    more than :data:`CARRY_TOLERANCE` of itself (:attr:`PathResult.carried`): the cells the
    crack newly cut held strongly varying states, which the closest-point transfer does not
    keep; a finer particle spacing there keeps them better."""


class EnergyBalanceWarning(UserWarning):
    """The path's energy record does not balance at its end: the work of the load minus the
    stored energy misses the dissipated energy by more than :data:`ENERGY_TOLERANCE` of the
    work (:attr:`PathResult.energy_error`). Energy changed where no step followed it (a crack
    extension re-equilibrated at a fixed control, a step past a failure), so the curve is not
    resolved there: the same path with smaller increments tells how far it moves."""


#: The share of the load's work by which the energy record may miss at the path's end before
#: :class:`EnergyBalanceWarning` is raised. Measured over the 119 paths of the test suite: at
#: most 1.26 % (a grown patch; the J2 rings 0.5 to 1.15 %, VCI's Petrov-Galerkin share 1.1 % in
#: elastic steps); the slanted-notch beam of ``tests/test_cohesive_growth.py`` 0.10 % at its
#: increments of 0.002 mm, 9.1 % at 0.003 mm (its crack re-equilibrated at fixed openings).
ENERGY_TOLERANCE = 3e-2


#: The relative change of the bulk's dissipated energy at a rebuild above which
#: :class:`StateCarryWarning` is raised (measured: 6.4e-5 in the plastic plate of the tests).
CARRY_TOLERANCE = 1e-2


#: :class:`PathOptions`' default ``xtol``. Petersson's notched beam (``demos/concrete_beam.py``, h =
#: 25 mm, lagrange) has a residual floor of about 1e-9 N whatever the load, above ``rtol |t q|``
#: = 4.4e-10 in its first step: Newton reached the floor in one iteration, then wandered on it
#: (corrections of 4e-13 to 7e-15 of the fields) until no step length decreased ``|R|`` and the
#: stall test took it: 9 iterations serially, and a count that differed on 2 ranks, so that the
#: increments (``easy``) and then the path differed (the peak 875.69 N serially, 875.39 N on 2
#: ranks). In steps that converge the last correction is 1e-12 to 3e-8 of the fields with ``|R|``
#: at the floor, and the one before it at least 3e-7 with ``|R|`` above ``stall |t q|``. The
#: load-stepping Newton has the same test (``statics.newton``'s ``stol``, PETSc SNES's step test).
XTOL = 1e-10


@dataclass(frozen=True)
class PathOptions:
    """Options of :func:`follow_path`.

    Args:
        increment: The first control increment (same units as the control quantity).
        end: Stop when the control reaches this value.
        min_load: Stop when, past the peak, the load factor falls below this share of the peak
            (the body has failed).
        max_steps: At most this many converged steps.
        max_it: Newton iterations per step.
        rtol, atol: Newton stops when ``|R| <= max(atol, rtol |t q|)``, ``t`` the largest of
            the iterate's load factor, the step's start and the peak's.
        stall: Or when no step length decreases ``|R|`` any more and ``|R| <= stall |t q|``
            (the round-off floor of a law's non-smooth points).
        xtol: Or when ``|R| <= stall |t q|`` and the last iteration changed the primal fields
            by at most ``xtol`` of their norm: ``|R|`` has reached its round-off floor, which
            can lie above ``rtol |t q|`` where the load is small (:data:`XTOL`).
        grow: The increment is multiplied by this after a step that converged in at most
            ``easy`` iterations, up to ``max_increment`` (default ``8 increment``); not after
            the first step, whose quick convergence tells of the elastic start, not of the
            nonlinearity ahead.
        max_cuts: Halvings of a step's increment before :class:`PathError`.
    """

    increment: float
    end: float
    min_load: float = 0.0
    max_steps: int = 500
    max_it: int = 25
    rtol: float = 1e-9
    atol: float = 1e-12
    stall: float = 1e-4
    xtol: float = XTOL
    grow: float = 1.5
    easy: int = 4
    max_increment: float | None = None
    max_cuts: int = 8

    def __post_init__(self) -> None:
        if not (np.isfinite(self.increment) and self.increment > 0):
            raise ValueError(f"increment={self.increment!r} must be a positive number")
        if not (np.isfinite(self.end) and self.end > self.increment):
            raise ValueError(
                f"end={self.end!r} must be a number above increment={self.increment!r}: the "
                "control grows from its start (0) to end"
            )
        if not 0.0 <= self.min_load < 1.0:
            raise ValueError(f"min_load={self.min_load!r} must lie in [0, 1)")
        for name in ("max_steps", "max_it", "easy", "max_cuts"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 1):
                raise ValueError(f"{name}={value!r} must be an integer >= 1")
        if not 0.0 <= self.xtol < 1e-3:
            raise ValueError(f"xtol={self.xtol!r} must lie in [0, 1e-3) (0: no such test)")
        if not self.grow >= 1.0:
            raise ValueError(f"grow={self.grow!r} must be >= 1")


@dataclass
class PathResult:
    """The followed path: per converged step the control value, the load factor, Newton's
    iterations; the energies; the coupled solution at the end."""

    control: list[float] = field(default_factory=list)
    load_factor: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    #: External work of the dead loads, ``int t q . dx`` over the free dofs (trapezoidal).
    external_work: list[float] = field(default_factory=list)
    #: Recoverable energy ``sum_q W(eps_q, state_q) w_q`` over every point with state, the
    #: cohesive faces' and, with a :class:`~dolfinx_meshfree.LinearElastic` bulk, its strain
    #: energy ``x . f_int(x) / 2`` (a finite-strain law without state is not counted).
    stored_energy: list[float] = field(default_factory=list)
    #: Energy dissipated, by the laws' own closed forms at the committed states.
    dissipated_energy: list[float] = field(default_factory=list)
    #: The monitored quantities (``follow_path(monitors=...)``) per converged step, by name.
    monitors: dict[str, list[float]] = field(default_factory=dict)
    cuts: int = 0
    seconds: float = 0.0
    solution: CoupledSolution | None = None
    #: The growths of cracks that find their path (``follow_path(growth=...)``): ``(step,
    #: control, new tip)`` each, the tip a point on the exterior boundary once the crack
    #: splits the body.
    extensions: list[tuple[int, float, list[float]]] = field(default_factory=list)
    #: Per extension (as :attr:`extensions`): the degrees its segment was turned off the stress
    #: criterion's direction so that its far half keeps ``NEAR_ROW`` spacing off every particle
    #: (:data:`~dolfinx_meshfree.statics.cohesive_growth.TURNS`; 0 where it passes clear).
    turns: list[float] = field(default_factory=list)
    #: With cohesive cracks in an elastic bulk: per converged step, the largest averaged largest
    #: principal stress of the bulk three spacings or more from every crack (FE side included;
    #: :func:`~dolfinx_meshfree.statics.cohesive_initiation.bulk_stress_peak`) and where. Above
    #: the faces' ``f_t`` a further crack would start there (``follow_path(initiation=...)``
    #: starts it; else the model does not follow it).
    bulk_stress: list[float] = field(default_factory=list)
    bulk_point: list[list[float]] = field(default_factory=list)
    #: Per converged step, the sign of the bordered tangent's determinant relative to the path's
    #: first step's (:mod:`~dolfinx_meshfree.statics.bifurcation`; with arc length, ``det K``'s
    #: times the step's load increment's): -1 past a bifurcation, on a branch a body with any
    #: imperfection leaves; ``None`` where unknown (an iterative solver; the sign restarts after
    #: a crack or the patch grew).
    stability: list[float | None] = field(default_factory=list)
    #: The step from which the sign stayed flipped for ``BIFURCATION_STEPS`` steps
    #: (:class:`~dolfinx_meshfree.BifurcationWarning`), or ``None``.
    bifurcation: int | None = None
    #: The cracks that started during the path (``follow_path(initiation=...)``): ``(step,
    #: control, first stretch)`` each, the stretch's end points.
    initiations: list[tuple[int, float, list[list[float]]]] = field(default_factory=list)
    #: The bulk's peaks above the new faces' ``f_t`` that could not start a crack
    #: (``follow_path(initiation=...)``): ``(step, point, stress, why)`` each. The region of
    #: tension about such a site (the candidates above ``f_t`` joined to it,
    #: :func:`~dolfinx_meshfree.statics.cohesive_initiation.bulk_stress_peaks`' ``exclude``) is
    #: left out from then on, and the peak of another region above ``f_t`` is tried.
    refused: list[tuple[int, list[float], float, str]] = field(default_factory=list)
    #: With a law with state and cracks that grow: per rebuild of the model on its changed
    #: cracks, ``(step, dissipated before, dissipated after, moved, crossed)``: the bulk's
    #: dissipated energy before and after its states were carried to the new points
    #: (:mod:`~dolfinx_meshfree.statics.state_carry`; the difference is what the transfer
    #: changed), the points that took a state from another position and, of them, those that
    #: took it across a crack. With a :class:`~dolfinx_meshfree.CrackBandSwitch`, "after"
    #: counts the energy the hand-over moved to the new faces in place of the bulk's share.
    carried: list[tuple[int, float, float, int, int]] = field(default_factory=list)
    #: With a :class:`~dolfinx_meshfree.CrackBandSwitch`: per extension, ``(step, energy,
    #: frozen)``: the bulk's dissipated energy handed to the new faces (summed over the ranks;
    #: the faces' dissipation takes it exactly) and the bulk points frozen
    #: (:func:`~dolfinx_meshfree.statics.crack_band_switch.hand_over`).
    handovers: list[tuple[int, float, int]] = field(default_factory=list)
    #: The growths of the patch (``follow_path(adapt=...)``): one
    #: :class:`~dolfinx_meshfree.statics.patch_growth.PatchEvent` each, with the stored energy
    #: the rebuild changed that the load's work does not account for (``energy_change``).
    patch_events: list[PatchEvent] = field(default_factory=list)
    #: The model at the end: the one given, or, after the patch grew (``adapt``), the model
    #: rebuilt on the grown patch (a new object; the given one keeps its first patch).
    model: CoupledElasticity | EFGElasticity | None = None
    #: With ``adapt``: whether a criterion ever named a cell, patch cells included (none did:
    #: :class:`~dolfinx_meshfree.PatchCriterionWarning`).
    adapt_named: bool = False
    #: A :class:`~dolfinx_meshfree.RankineDamage` patch whose crack band reached the FE
    #: interface (:mod:`~dolfinx_meshfree.statics.band_reach`): ``(step, point, damage, damage
    #: across)`` at the first step it did (:class:`BandCutWarning`), else ``None``.
    band_cut: tuple[int, list[float], float, float] | None = None

    @property
    def peak(self) -> tuple[float, float]:
        """``(load factor, control)`` at the peak load."""
        k = int(np.argmax(self.load_factor))
        return self.load_factor[k], self.control[k]

    @property
    def energy_error(self) -> float:
        """``|W - U - D| / W`` at the last step: the share of the load's work ``W`` by which the
        stored energy ``U`` and the dissipated energy ``D`` miss it (NaN before any work)."""
        if not self.external_work or not self.external_work[-1] > 0.0:
            return float("nan")
        work = self.external_work[-1]
        return abs(work - self.stored_energy[-1] - self.dissipated_energy[-1]) / work


def _owned(vecs: Sequence[PETSc.Vec]) -> list[np.ndarray]:
    return [v.getArray(readonly=True).copy() for v in vecs]


def _particle_field(built: BlockModel | EFGBlockModel | FEBlockModel) -> int:
    """The index of the last primal field in ``x``: the particles' (1 beside the FE field, 0 in
    pure EFG), or pure FE's only field (0)."""
    return built.problem.num_primal - 1


def _comm(built: BlockModel | EFGBlockModel | FEBlockModel) -> MPI.Comm:
    return built.model.patch.comm if isinstance(built, BlockModel) else built.model.comm


def _control_function(
    built: BlockModel | EFGBlockModel | FEBlockModel, control: DisplacementControl
) -> Callable[[Sequence[np.ndarray]], float]:
    """``g`` of block fields given as owned arrays (collective)."""
    model, comm = built.model, _comm(built)
    if isinstance(built, FEBlockModel):  # a linear functional of the owned dofs
        points, directions = raise_on_all_ranks(
            comm, lambda: control.check(model.V.mesh.geometry.dim)
        )
        w = fe_point_functional(model.V, points, directions)

        def g(parts: Sequence[np.ndarray]) -> float:
            return float(comm.allreduce(float(w @ np.asarray(parts[0]))))

    elif isinstance(built, EFGBlockModel):
        P = model.particles
        points, directions = raise_on_all_ranks(comm, lambda: control.check(P.gdim))
        values = raise_on_all_ranks(comm, lambda: model.mls.tabulate(points, 0)).values

        def g(parts: Sequence[np.ndarray]) -> float:
            owned = np.concatenate(comm.allgather(np.asarray(parts[0])))
            coeffs = owned.reshape(-1, P.gdim)[P.petsc_index]
            return float(np.sum((values @ coeffs) * directions))

    else:
        P = model.patch.particles
        points, directions = raise_on_all_ranks(
            comm, lambda: control.check(model.V.mesh.geometry.dim)
        )
        u = dolfinx.fem.Function(model.V)
        n_owned = built.fe.n_owned

        def g(parts: Sequence[np.ndarray]) -> float:
            u.x.array[:n_owned] = parts[0]
            u.x.scatter_forward()
            owned = np.concatenate(comm.allgather(np.asarray(parts[1])))
            coeffs = owned.reshape(-1, P.gdim)[P.petsc_index]
            sol = CoupledSolution(
                u=u, coefficients=coeffs, mls=model.mls, patch=model.patch,
                interface=built.extra.get("interface"),
            )  # fmt: skip
            return float(np.sum(sol.displacement(points) * directions))

    g.weight = float(np.abs(directions).sum())  # |g(v)| <= weight max|v| (partition of unity)
    return g


def _bulk_points(
    built: BlockModel | EFGBlockModel,
) -> list[tuple[PointState, np.ndarray, Callable[[], np.ndarray]]]:
    """The bulk's sets of points with state (the FE cells', the particles', the ramps' blended
    cells'; not the cohesive faces'), in a fixed order: ``(state, weights, strain)`` each, where
    ``strain()`` is the Voigt strain at the current ``x``."""
    out = []
    fe = getattr(getattr(built, "fe", None), "state_law", None)
    if fe is not None:
        out.append((fe.state, fe.weights, fe.strain))
    side = getattr(built, "particles", None)  # pure FE has none
    if side is not None and side.state is not None:
        forces = side.forces

        def particle_strain() -> np.ndarray:
            coeffs = side.coefficients(built.x[_particle_field(built)])
            return voigt_strain(forces.displacement_gradient(coeffs))

        out.append((side.state, forces.weights, particle_strain))
    for shared in built.problem.shared:  # the ramps' blended cells
        if not hasattr(shared, "energies") and getattr(shared, "state", None) is not None:
            gdim = shared.forces.gdim

            def blended_strain(shared: object = shared, gdim: int = gdim) -> np.ndarray:
                return voigt_strain(shared.deformation_gradient(built.x[:2]) - np.eye(gdim))

            out.append((shared.state, shared.forces.weights, blended_strain))
    return out


def _band_cut(built: BlockModel | EFGBlockModel) -> tuple[np.ndarray, float, float] | None:
    """Where a :class:`~dolfinx_meshfree.RankineDamage` patch's crack band is cut by the FE
    interface (:func:`~dolfinx_meshfree.statics.band_reach.band_at_interface`; collective),
    or ``None`` (also without a patch)."""
    side = getattr(built, "particles", None)
    patch = getattr(built.model, "patch", None)
    if (
        patch is None
        or side is None
        or not isinstance(getattr(side.state, "law", None), RankineDamage)
    ):
        return None
    others = [st for st, _, _ in _bulk_points(built) if st is not side.state]
    return band_at_interface(patch, side.state, others)


def _energies(built: BlockModel | EFGBlockModel) -> tuple[float, float]:
    """``(stored, dissipated)`` over every point with state (summed over ranks)."""
    stored = dissipated = 0.0
    for st, weights, strain in _bulk_points(built):
        stored += float(st.law.stored_energy(strain(), st.committed) @ weights)
        dissipated += st.dissipated(weights)
    for shared in built.problem.shared:  # the cohesive faces
        if hasattr(shared, "energies"):
            more = shared.energies([built.x[i] for i in shared.fields])
            stored, dissipated = stored + more[0], dissipated + more[1]
    comm = _comm(built)
    stored, dissipated = comm.allreduce(stored), comm.allreduce(dissipated)
    law = built.model.material if isinstance(built, EFGBlockModel) else built.model.law
    if isinstance(law, LinearElastic):  # an elastic bulk (cohesive faces): 1/2 x . f_int(x)
        for i, side in enumerate(built.problem.sides):
            f = side.internal_force(built.x[i])
            stored += 0.5 * f.dot(built.x[i])
            f.destroy()
        for shared in built.problem.shared:  # the ramps' blended cells
            if hasattr(shared, "strain_energy"):
                local = shared.strain_energy([built.x[i] for i in shared.fields])
                stored += comm.allreduce(local)
    return stored, dissipated


def _residual(problem: BlockProblem, x: Sequence[PETSc.Vec], t: float) -> tuple[list, float]:
    problem.t = t
    r = problem.residual(x)
    return r, float(np.sqrt(sum(v.norm() ** 2 for v in r)))


def _newton_directions(
    problem: BlockProblem,
    x: Sequence[PETSc.Vec],
    r: list[PETSc.Vec],
    q: list[PETSc.Vec],
    solver: SolverOptions,
    sign: bool = False,
) -> tuple[list[np.ndarray], list[np.ndarray], float | None]:
    """``J da = -R`` and ``J db = q`` with one factorisation of the tangent at ``x`` (the
    residual ``r`` is consumed: scaled, then destroyed), and with ``sign`` the sign of ``det J``
    (``None`` where the solver does not give it)."""
    blocks = problem.jacobian(x)
    for v in r:
        v.scale(-1.0)
    system = BlockSystem(blocks, r, num_primal=problem.num_primal, names=problem.names)
    da, db = system.solve_many([q], solver, sign=sign, kept=problem.kept_factorisation)
    det = system.determinant_sign
    system.destroy()
    _destroy_all(r)
    return da, db, det


#: A step whose load work per unit of control and of load (:func:`_lever`) exceeds the last
#: step's by this factor is cut: measured at most 1.02 along localising paths (FE and lagrange
#: bars with a notched column, 4 to 8 cells across) and 18.5-24.8 at the step where Newton's
#: predictor, overshooting the peak, carried columns outside the controlled gauge onto their
#: softening branch (3.8-5.2 times the energy of the localised path dissipated, silently).
#: The jump is measured from at least :data:`LEVER_FLOOR` times the path's first lever. A jump
#: that persists down to ``2^-max_cuts`` of the increment stops the path (:class:`PathError`).
LEVER_JUMP = 4.0

#: :data:`LEVER_JUMP` is measured from ``max(last lever, LEVER_FLOOR x the first step's)``. Past
#: a snap-back of the loaded points the lever passes through zero, and from a lever near zero any
#: step onward is a "jump": the unnotched beam under CMOD control stopped at step 22 with a
#: lever 20.3 times its last step's, 0.024 against a first step's 135.8 (lane B; lane A's last
#: lever fell just below zero and went unchecked). Over the test suite's 129 paths the branch
#: jumps of the coarse bars came from 0.97-0.99 of the first lever to 18-20 of it; the other 7
#: cuts, all on legitimate paths (an interior cohesive crack growing down to a mouth opening
#: controlled at the bottom edge, the shear beam), from 5.5e-4 to 2.6e-3 of it to at most
#: 1.2e-2 of it.
LEVER_FLOOR = 0.1


def _lever_jump(lever: float | None, first: float | None, new: float | None) -> float:
    """The factor by which a step's lever ``new`` (:func:`_lever`) exceeds the last step's
    ``lever``, or ``LEVER_FLOOR * first`` (the path's first lever) if larger; 0 where either
    lever is not measured. A last lever below zero (the loaded points moved back, past a
    snap-back) is measured from the floor."""
    if lever is None or new is None or first is None:
        return 0.0
    reference = max(lever, LEVER_FLOOR * abs(first))
    return new / reference if reference > 0.0 else 0.0


def _lever(work: float, t: float, t_new: float, dg: float, peak: float) -> float | None:
    """A step's load work per unit of control and of load, ``W / (t_mean dg)``: how far the
    loaded points move per unit of the control quantity (constant while elastic, falling as the
    control's gauge takes the deformation; below zero where the loaded points move back, as
    past a snap-back of the load point). ``None`` where the load is under a fifth of the peak
    (the work is then round-off), and for a step with no control increment."""
    mean = 0.5 * (t + t_new)
    if dg <= 0.0 or mean <= 0.2 * max(peak, t, t_new):
        return None
    return work / (mean * dg)


#: :func:`_turning` reports a control quantity that turns where, before the peak, its last
#: converged step grew it by less than this share of its growth per unit load at the start.
TURNING_RATE = 0.5


def _turning(start: float, control: Sequence[float], load: Sequence[float]) -> str:
    """Where a path cannot be followed before its peak: a clause for the error when the control
    quantity's growth per unit load ``dg/dt`` in the last converged step fell below
    :data:`TURNING_RATE` of its first step's (local; the same on every rank).

    Before the peak a body that softens or yields gives way more per unit load, so its
    control's ``dg/dt`` grows. One that falls heads for a maximum of the control along the
    path, where no increment of it has a solution and every cut fails alike: a bar with a
    notch on one side controlled by the elongation of its other edge, which shortens as the
    notched side softens and the bar bends (measured: 0.10-0.23 of the first step's rate at the
    failure, FE and lagrange, 4 and 8 cells across)."""
    g, t = [start, *control], [0.0, *load]
    if len(g) < 3 or t[1] <= 0.0 or t[-1] <= t[-2] or t[-1] < max(t):
        return ""
    first, last = (g[1] - g[0]) / t[1], (g[-1] - g[-2]) / (t[-1] - t[-2])
    ratio = last / first
    if ratio >= TURNING_RATE:
        return ""
    return (
        f" (before the peak, the control quantity's growth per unit load fell to {ratio:.2g} "
        "of its first step's: it stiffens while the body gives way, and turns here, where no "
        "increment of it has a solution, e.g. an elongation on a side that the bending unloads)"
    )


@dataclass(frozen=True)
class _Tolerance:
    """Newton's stopping rule in a step of the path: ``|R| <= max(atol, rtol |q| max(|t|, s))``
    (:class:`PathOptions`' ``rtol``, ``atol``), accepted after a stall below the same with
    ``PathOptions.stall``; ``t`` the iterate's load factor and ``s`` the larger of the step's
    start and the path's peak (1e-3 before any load). Read at the iterate, not at the step's
    start: the first step starts from ``t = 0``, and a tolerance fixed there lay below the
    round-off of the load the step finds (1e-12 of it at ``rtol`` 1e-9), so that Newton ran on
    to its stall test after as many iterations as round-off allowed: a count that differed
    between serial and 2 ranks, and the next increments follow the count (``PathOptions.easy``).
    A user's quarter plate with a hole (J2, a ramp-coupled patch at the hole, an elastic first
    step): 8 to 10 iterations serially and 10 or 11 on 2 ranks, now 3 or 4 on both. ``least``: a
    floor, for a loosened first try."""

    norm: float
    floor: float
    rtol: float
    atol: float
    stall_rtol: float
    least: float = 0.0

    def at(self, t: float) -> float:
        """The tolerance at load factor ``t``."""
        return max(self.atol, self.least, self.rtol * self.norm * max(abs(t), self.floor))

    def stall_at(self, t: float) -> float:
        """The stall floor at load factor ``t``."""
        return max(self.at(t), self.stall_rtol * self.norm * max(abs(t), self.floor))


def _reequilibrate(
    problem: BlockProblem,
    x: list[PETSc.Vec],
    t: float,
    target: float,
    g: Callable[[Sequence[np.ndarray]], float],
    q: list[PETSc.Vec],
    tol: _Tolerance,
    options: PathOptions,
    solver: SolverOptions,
) -> tuple[float, int]:
    """Back to equilibrium at the same control value after a crack grew: :func:`_bordered_step`
    from the refitted state; if it fails, again from that state with the first iteration
    line-searched too (the control holds already; the new faces' forces can make the full first
    step overshoot onto a residual Newton does not recover from: the shear beam's pure EFG
    path at h = 20 mm); if that fails, from that state with the cohesive faces' secant
    stiffness until the residual has fallen by 1e-3 (slow but from further away: the line search
    stalled at the loading-unloading switches of the faces, the shear beam's lagrange path at
    h = 15 mm with CMSD increments of 2.4e-4 mm), then Newton again to the tolerance. Returns
    ``(t, iterations)`` of the tries that converged; ``ArithmeticError`` when all fail."""
    start = [v.copy() for v in x]
    faces = [s for s in problem.shared if isinstance(s, CohesiveSide)]

    def again() -> None:  # from the refitted state
        for v, w in zip(x, start, strict=True):
            w.copy(v)
        problem.restore()
        problem.t = t

    try:
        try:
            return _bordered_step(problem, x, t, target, g, q, tol, options, solver)
        except ArithmeticError:
            again()
        try:
            return _bordered_step(
                problem, x, t, target, g, q, tol, options, solver, search_first=True
            )
        except ArithmeticError:
            if not faces:
                raise
            again()
        r0, n0 = _residual(problem, x, t)
        _destroy_all(r0)
        for side in faces:
            side.secant = True
        try:
            loose = replace(options, max_it=4 * options.max_it)
            t1, its = _bordered_step(
                problem, x, t, target, g, q, replace(tol, least=1e-3 * n0), loose, solver,
                search_first=True,
            )  # fmt: skip
        finally:
            for side in faces:
                side.secant = False
        problem.t = t1
        t2, more = _bordered_step(problem, x, t1, target, g, q, tol, options, solver)
        return t2, its + more
    finally:
        _destroy_all(start)


def _bordered_step(
    problem: BlockProblem,
    x: list[PETSc.Vec],
    t: float,
    target: float,
    g: Callable[[Sequence[np.ndarray]], float],
    q: list[PETSc.Vec],
    tol: _Tolerance,
    options: PathOptions,
    solver: SolverOptions,
    search_first: bool = False,
    stability: list[float | None] | None = None,
) -> tuple[float, int]:
    """Newton on ``R(x, t) = 0, g(x) = target`` from ``(x, t)``; returns ``(t, iterations)``
    (``x`` updated in place) or raises ``ArithmeticError`` when it does not converge. With
    ``search_first``, a first iteration that starts on the constraint is line-searched too.
    With ``stability``, a converged step appends the sign of the bordered system's determinant
    at its last factorisation (:func:`~dolfinx_meshfree.statics.bifurcation.bordered_sign`).

    Every update keeps the constraint: ``x += alpha da + beta db`` with ``beta = (gap - alpha
    g(da)) / g(db)`` holds ``g(x) = target`` for any ``alpha`` (``g`` is linear), so once the
    first iteration has met it, a backtracking line search on ``|R|`` (Armijo, halving
    ``alpha`` up to 6 times) damps the loading-unloading switches of a softening law near the
    peak, where full steps can cycle; when no length decreases ``|R|`` the step fails (and is
    cut): accepting a step that does not decrease it lets Newton wander onto another branch
    (one where the whole body softens). A residual that stagnates below ``stall`` (the
    non-smooth points of a law: its damage cap, equal principal stresses) is accepted as
    converged, as is one below ``stall`` after an iteration that changed the primal fields by at
    most ``xtol`` of their norm (its round-off floor: :data:`XTOL`)."""
    scale = max(abs(target), 1e-300)
    comm = x[0].getComm().tompi4py()
    r, norm = _residual(problem, x, t)
    bordered, moved = None, np.inf  # the last iteration's change of the primal fields, relative
    for it in range(options.max_it + 1):
        gap = target - g(_owned(x))
        floor = moved <= options.xtol and norm <= tol.stall_at(t)  # |R| at its round-off floor
        if it > 0 and (norm <= tol.at(t) or floor) and abs(gap) <= 1e-10 * scale:
            _destroy_all(r)
            if stability is not None:
                stability.append(bordered)
            return t, it
        if it == options.max_it or not np.isfinite(norm):
            break
        da, db, det = _newton_directions(problem, x, r, q, solver, sign=stability is not None)
        ga, gb = g(da), g(db)
        bordered = bordered_sign(det, gb)
        size = comm.allreduce(
            max((float(np.abs(b).max()) for b in db if b.size), default=0.0), op=MPI.MAX
        )
        if not abs(gb) > 1e-10 * size * g.weight:
            raise ValueError(
                "the control quantity does not move under the load (dg/dt = 0): choose a "
                "quantity the load changes, e.g. an opening across the band where the body fails"
            )
        start = [v.copy() for v in x]
        alpha, best = 1.0, None
        for _ in range(7):
            beta = (gap - alpha * ga) / gb
            for xi, x0, a, b in zip(x, start, da, db, strict=True):
                xi.array[:] = x0.getArray(readonly=True) + alpha * a + beta * b
            r_try, n_try = _residual(problem, x, t + beta)
            # the first iteration meets the constraint and may raise |R| from 0: full step
            first = it == 0 and not (search_first and abs(gap) <= 1e-10 * scale)
            if first or n_try <= (1.0 - 1e-4 * alpha) * norm:
                best = (alpha, beta, r_try, n_try)
                break
            _destroy_all(r_try)
            alpha *= 0.5
        if best is None:  # no decrease on this branch
            for xi, x0 in zip(x, start, strict=True):
                x0.copy(xi)
            _destroy_all(start)
            if norm <= tol.stall_at(t) and abs(gap) <= 1e-10 * scale:  # stagnated near it
                problem.t = t
                _destroy_all(problem.residual(x))  # the trial state of x again
                if stability is not None:
                    stability.append(bordered)
                return t, it + 1
            raise ArithmeticError("no step length decreases the residual")
        alpha, beta, r, norm = best
        for xi, x0, a, b in zip(x, start, da, db, strict=True):
            xi.array[:] = x0.getArray(readonly=True) + alpha * a + beta * b
        moved = _relative_change(
            [alpha * a + beta * b for a, b in zip(da, db, strict=True)], x, problem.num_primal
        )
        _destroy_all(start)
        t += beta
    _destroy_all(r)
    raise ArithmeticError("not converged")


def _relative_change(dx: Sequence[np.ndarray], x: Sequence[PETSc.Vec], num_primal: int) -> float:
    """``|dx| / |x|`` over the first ``num_primal`` fields (the owned parts; collective), inf
    where ``x`` is zero."""
    comm = x[0].getComm().tompi4py()
    local = np.array(
        [
            sum(float(d @ d) for d in dx[:num_primal]),
            sum(float(a @ a) for a in (v.getArray(readonly=True) for v in x[:num_primal])),
        ]
    )
    change, size = np.sqrt(comm.allreduce(local))
    return float(change / size) if size > 0.0 else np.inf


def _dot(a: Sequence[np.ndarray], b: Sequence[np.ndarray], comm: MPI.Comm) -> float:
    return comm.allreduce(sum(float(u @ v) for u, v in zip(a, b, strict=True)))


def _arc_step(
    problem: BlockProblem,
    x: list[PETSc.Vec],
    t: float,
    dl: float,
    previous: list[np.ndarray] | None,
    q: list[PETSc.Vec],
    tol: _Tolerance,
    num_primal: int,
    options: PathOptions,
    solver: SolverOptions,
    stability: list[float | None] | None = None,
) -> tuple[float, int, list[np.ndarray]]:
    """Newton on ``R(x, t) = 0, |Dx| = dl`` (``Dx``: the step's change of the primal fields) from
    ``(x, t)``; returns ``(t, iterations, Dx)`` or raises ``ArithmeticError``. With
    ``stability``, a converged step appends ``det J``'s sign at its last factorisation times its
    load increment's (:func:`~dolfinx_meshfree.statics.bifurcation.bordered_sign`: the two turn
    together at a limit point, ``det J`` alone at a bifurcation).

    Each iteration: ``J da = -R``, ``J db = q``, ``dx = da + dt db`` with ``dt`` a root of
    ``|Dx + da + dt db|^2 = dl^2`` (Crisfield 1991, sec. 9.3.1), the root whose new ``Dx``
    turns least from the old; the first (predictor) ``dt = +-dl / |db|``, the sign of the last
    step's direction (``db . Dx_prev``). Complex roots (the constraint's circle misses the
    iteration's line) fail the step, which is then cut."""
    comm = x[0].getComm().tompi4py()
    r, norm = _residual(problem, x, t)
    Dx = [np.zeros(v.getLocalSize()) for v in x[:num_primal]]
    det, t_start = None, t  # det J's sign at the last factorisation
    moved = np.inf  # the last iteration's change of the primal fields, relative
    for it in range(options.max_it + 1):
        # converged; or stagnated near the solution at the last iteration (a law's non-smooth
        # points: its damage cap, equal principal stresses), or at |R|'s round-off floor
        stalled = it == options.max_it or moved <= options.xtol
        if it > 0 and (norm <= tol.at(t) or (stalled and norm <= tol.stall_at(t))):
            _destroy_all(r)
            if stability is not None:
                stability.append(bordered_sign(det, t - t_start))
            return t, it, Dx
        if it == options.max_it or not np.isfinite(norm):
            break
        da, db, det = _newton_directions(problem, x, r, q, solver, sign=stability is not None)
        a, b = da[:num_primal], db[:num_primal]
        if it == 0:
            sign = 1.0
            if previous is not None and _dot(b, previous, comm) < 0.0:
                sign = -1.0
            dt = sign * dl / np.sqrt(_dot(b, b, comm))
        else:
            u = [d + e for d, e in zip(Dx, a, strict=True)]
            c2, c1 = _dot(b, b, comm), 2.0 * _dot(b, u, comm)
            c0 = _dot(u, u, comm) - dl * dl
            disc = c1 * c1 - 4.0 * c2 * c0
            if disc < 0.0:
                raise ArithmeticError("the arc-length equation has no real root")
            roots = [(-c1 + sg * np.sqrt(disc)) / (2.0 * c2) for sg in (1.0, -1.0)]
            # the root whose new Dx makes the smallest angle with the old one
            turn = [_dot([w + z * e for w, e in zip(u, b, strict=True)], Dx, comm) for z in roots]
            dt = roots[int(np.argmax(turn))]
        for xi, d, e in zip(x, da, db, strict=True):
            xi.array[:] += d + dt * e
        moved = _relative_change([d + dt * e for d, e in zip(a, b, strict=True)], x, num_primal)
        Dx = [w + d + dt * e for w, d, e in zip(Dx, a, b, strict=True)]
        t += dt
        r, norm = _residual(problem, x, t)
    _destroy_all(r)
    raise ArithmeticError("not converged")


@dataclass
class _Loads:
    """The reference load of a built model: ``q = R(x, 0) - R(x, 1)`` (the residual is affine
    in ``t``), its primal fields as arrays with the held FE dofs zeroed (their values are
    reactions' work, not dead loads'), and its norm. Rebuilt when the model's layout changes
    (a grown patch)."""

    q: list[PETSc.Vec]
    f_ext: list[np.ndarray]
    norm: float

    @classmethod
    def of(cls, built: BlockModel | EFGBlockModel, efg: bool) -> _Loads:
        """Of ``built`` at its current ``x`` (collective; ``problem.t`` is left at 1)."""
        problem, x = built.problem, built.x
        problem.t = 0.0
        r0 = problem.residual(x)
        problem.t = 1.0
        r1 = problem.residual(x)
        q = []
        for a, b in zip(r0, r1, strict=True):
            a.axpy(-1.0, b)
            b.destroy()
            q.append(a)
        f_ext = [v.getArray(readonly=True).copy() for v in q[: _particle_field(built) + 1]]
        if not efg:
            f_ext[0][built.fe.fixed_local] = 0.0  # held dofs: reactions, not dead loads
        return cls(q, f_ext, float(np.sqrt(sum(v.norm() ** 2 for v in q))))

    def destroy(self) -> None:
        _destroy_all(self.q)


def _work(
    f_ext: Sequence[np.ndarray],
    x: Sequence[PETSc.Vec],
    before: Sequence[np.ndarray],
    t: float,
    t_new: float,
    comm: MPI.Comm,
) -> float:
    """The work of the dead loads ``t q`` from ``before`` to ``x`` (the primal fields), by the
    trapezoidal rule in ``t`` (collective)."""
    dx = [a.getArray(readonly=True) - b for a, b in zip(x, before, strict=True)]
    local = sum(float(f @ d) for f, d in zip(f_ext, dx, strict=True))
    return comm.allreduce(0.5 * (t + t_new) * local)


def _check_growth(
    model: CoupledElasticity | EFGElasticity,
    efg: bool,
    growths: Sequence[CohesiveGrowth],
    control: DisplacementControl | ArcLength,
    cracks: Sequence,
) -> None:
    """Refuse what growing cracks cannot carry (local; call on every rank)."""
    if not growths:
        return
    if not all(isinstance(gr, CohesiveGrowth) for gr in growths):
        raise TypeError("growth must be a CohesiveGrowth or a sequence of them")
    if isinstance(control, ArcLength):
        raise ValueError(
            "growth needs indirect displacement control (DisplacementControl): after a crack "
            "grew, equilibrium is found again at the same control value, which ArcLength has not"
        )
    law = model.material if efg else model.law
    if not (isinstance(law, LinearElastic) or is_stateful(law)):
        raise ValueError(
            f"growth with a {type(law).__name__} bulk: cracks grow in a small-strain bulk, "
            "elastic (LinearElastic, the fictitious crack model) or with state (RankineDamage, "
            "J2Plasticity: carried to the cut cells' new points); not at finite strain"
        )
    for gr in growths:
        gr.check(model.cohesive, cracks)


def _register_switches(
    model: CoupledElasticity | EFGElasticity, efg: bool, growths: object, cracks: Sequence
) -> None:
    """Give each :class:`~dolfinx_meshfree.CrackBandSwitch`'s crack its faces' record (no
    segment yet) in ``model.cohesive``; refuse a crack that is not one of the model's
    ``cracks``, a crack whose faces carry a law already, and a bulk that is not a RankineDamage
    (local; every rank alike)."""
    if not isinstance(growths, Sequence):
        return  # _check_growth names it
    law = model.material if efg else model.law
    for gr in growths:
        if not isinstance(gr, CrackBandSwitch):
            continue
        gr.check([], cracks)  # the crack is the model's
        mine = [c for c in model.cohesive if c.crack is gr.crack]
        if mine and mine[0].segments == ():  # registered by a path that stopped at a check
            continue
        if mine:
            raise ValueError(
                f"CrackBandSwitch: {gr.crack!r} carries a traction-separation law already "
                "(add_cohesive); the switch gives the crack its faces as it grows from the "
                "band: leave add_cohesive out, or grow the crack with mf.CohesiveGrowth"
            )
        model.cohesive.append(gr.faces(law))


def _check_unloaded(model: CoupledElasticity | EFGElasticity | FEElasticity) -> None:
    """Refuse a model whose last ``solve()`` left an inelastic state (local; every rank
    alike): the path starts from the unloaded state, its load factor an unknown from 0, so it
    cannot continue that history (:mod:`~dolfinx_meshfree.statics.history`); an elastic
    history is the start's own path."""
    history = getattr(model, "history", None)
    if history is not None and history.inelastic:
        raise ValueError(
            f"follow_path: this {type(model).__name__} yielded, softened or opened in its last "
            "solve() (its law's state is that solve's history); a path starts from the "
            "unloaded, virgin state and cannot continue it: call model.reset() first, or "
            "follow the path from the start"
        )


def _check_fe_only(law: object, growth: object, initiation: object, adapt: object) -> None:
    """Refuse what a pure FE model cannot carry (local; every rank): an elastic law's straight
    path; cracks, which FE cells do not carry; a patch to grow, which it has not."""
    if isinstance(law, LinearElastic):
        raise ValueError(
            "follow_path needs a law whose response is not linear (a law with state): an "
            "FEElasticity model with a LinearElastic law has a straight path; solve it"
        )
    given = [
        name
        for name, value in (("growth", growth), ("initiation", initiation), ("adapt", adapt))
        if value is not None
    ]
    if given:
        raise ValueError(
            f"follow_path with an FEElasticity model and {', '.join(given)}: FE cells carry no "
            "crack and the model has no particle patch to grow; put a ParticlePatch where the "
            "crack runs (CoupledElasticity) or use EFGElasticity, or leave "
            f"{' and '.join(given)} out"
        )


def _check_initiation(
    model: CoupledElasticity | EFGElasticity,
    efg: bool,
    initiation: CrackInitiation | None,
    control: DisplacementControl | ArcLength,
) -> None:
    """Refuse what cracks that start during the path cannot carry (local; every rank)."""
    if initiation is None:
        return
    if not isinstance(initiation, CrackInitiation):
        raise TypeError(f"initiation must be a CrackInitiation, got {type(initiation).__name__}")
    if isinstance(control, ArcLength):
        raise ValueError(
            "initiation needs indirect displacement control (DisplacementControl): a crack that "
            "starts is brought to equilibrium at the same control value, which ArcLength has not"
        )
    law = model.material if efg else model.law
    if not isinstance(law, LinearElastic) or not model.cohesive:
        raise ValueError(
            "initiation starts further cohesive cracks in an elastic bulk beside the model's "
            f"cohesive ones: the model needs a LinearElastic law (it has "
            f"{type(law).__name__}) and a crack with add_cohesive"
        )
    enriched = model.mls.table_transforms if efg else model.patch.crack_enrichment
    if enriched:
        raise ValueError(
            "initiation with crack_enrichment: a crack that starts would need its tips enriched "
            "as the model was built; build the model without crack_enrichment (cohesive tips "
            "carry no singularity)"
        )


def _grow(
    built: BlockModel | EFGBlockModel,
    growths: Sequence[CohesiveGrowth],
    model: CoupledElasticity | EFGElasticity,
    efg: bool,
) -> tuple[list[float], np.ndarray, float, Callable | None] | None:
    """Grow the first crack of ``growths`` whose softening front nears its tip, or, for a
    :class:`~dolfinx_meshfree.CrackBandSwitch`, in front of which the bulk has localised
    (collective): its new end point, the refitted particle coefficients, the degrees the new
    segment was turned off the particles and, for a switch, the hand-over to call on the rebuilt
    model (``handover(built) -> (taken, given, frozen)``,
    :func:`~dolfinx_meshfree.statics.crack_band_switch.hand_over`), or ``None`` when none grew.
    The model's cohesive record follows."""
    if not growths:
        return None
    sides = [s for s in built.problem.shared if isinstance(s, CohesiveSide)]
    domain = model._domain if efg else model.patch

    def coefficients() -> np.ndarray:  # gathered only when a crack grows
        return built.solution().coefficients

    # the direction of a new segment: the averaged elastic stress of the total strain (with a
    # law with state, the principal strain's direction, by isotropy)
    law = model.material
    elastic = law.elastic() if is_stateful(law) else law
    h = particle_spacing(domain)
    for gr in growths:
        handover = None
        # collective; its errors (a crack leaving the patch) are raised on every rank
        if isinstance(gr, CrackBandSwitch):
            # the particles' points: the crack runs in the patch (FE points beside it too
            # would send it to the FE interface, where it is refused)
            states = [built.particles.state]
            side = next((s for s in sides if s.cohesive.crack is gr.crack), None)
            grown = switch_once(gr, states, side, model.mls, coefficients, elastic, domain, h)
            if grown is not None:  # the band beside the new segment, before the carry
                *grown, segment = grown
                old = [(st, w) for st, w, _ in _bulk_points(built)]
                band = BandEnergy.of(gr, old, segment, h, _comm(built))

                def handover(
                    new: BlockModel | EFGBlockModel,
                    gr: CrackBandSwitch = gr,
                    band: BandEnergy = band,
                ) -> tuple[float, float, int]:
                    side = next(
                        s
                        for s in new.problem.shared
                        if isinstance(s, CohesiveSide) and s.cohesive.crack is gr.crack
                    )
                    bulk = [(st, w) for st, w, _ in _bulk_points(new)]
                    return hand_over(gr, band, bulk, side, h)
        else:
            side = next(s for s in sides if s.cohesive.crack is gr.crack)
            grown = grow_once(gr, side, model.mls, coefficients, elastic, domain, side.h)
        if grown is not None:
            end, fitted, turn = grown
            k = next(i for i, c in enumerate(model.cohesive) if c.crack is gr.crack)
            model.cohesive[k] = gr.extended(model.cohesive[k], end)
            return gr.crack.points[end].tolist(), fitted, turn, handover
    return None


def _rebuild(
    model: CoupledElasticity | EFGElasticity,
    built: BlockModel | EFGBlockModel,
    efg: bool,
    u: dolfinx.fem.Function | None,
) -> tuple[BlockModel | EFGBlockModel, tuple[float, float, int, int] | None, np.ndarray | None]:
    """The block model of ``model`` after its cracks or its patch changed (collective): the
    fields of ``built`` carried over, the cohesive faces' committed states carried point by
    point (the old face points keep their positions; new ones start bonded), the bulk's
    committed states carried to its new points (:mod:`.state_carry`). Also returns the bulk's
    dissipated energy before and after, and the points that took a state from another position
    and, of them, across a crack (summed over ranks; ``None`` without a law with state); and,
    when the patch grew (``model`` on another patch than ``built``'s), the new particle
    coefficients fitted to the old field (:func:`.path_patch.fit_particles`; the FE dofs are
    copied, the held ones set to their values, the multipliers start from zero), else ``None``.
    ``built`` is destroyed once the new model is built (on an error it is left to the
    caller)."""
    state = _owned(built.x)
    comm = _comm(built)
    grown = not efg and built.model.patch is not model.patch
    faces = {  # the old faces' states (plain arrays: they outlive the destroyed model)
        id(side.cohesive.crack): side.state
        for side in built.problem.shared
        if isinstance(side, CohesiveSide)
    }
    bulk = _bulk_points(built)
    before = comm.allreduce(sum(st.dissipated(w) for st, w, _ in bulk))
    if efg:
        new = model.block_model()
        for v, a in zip(new.x, state, strict=True):
            v.array[:] = a
    else:
        # a grown patch has another layout: only the FE field (the same space) is carried as
        # it was; the multipliers start from zero
        start = None if grown else state
        new = build_block_problem(model, law_internal_force(model.law, u), u, model.law, start)
    fitted = None
    if grown:
        new.x[0].array[:] = state[0]
        fitted = fit_particles(built.solution(), new)
        new.x[0].array[new.fe.fixed_local] = built.problem.t * new.fe.fixed_values
    built.destroy()
    for side in new.problem.shared:
        if isinstance(side, CohesiveSide) and id(side.cohesive.crack) in faces:
            carry_at_points(faces[id(side.cohesive.crack)], side.state, comm, 1e-9 * side.h)
    if not bulk:
        return new, None, fitted
    cracks = model.cracks if efg else model.patch.cracks
    h = particle_spacing(model._domain if efg else model.patch)
    new_bulk = _bulk_points(new)
    carry = carry_pooled if grown else carry_states  # a converted cell's points: its FE points'
    counts = carry([b[0] for b in bulk], [b[0] for b in new_bulk], cracks, h)
    after = comm.allreduce(sum(st.dissipated(w) for st, w, _ in new_bulk))
    moved, crossed = (comm.allreduce(n) for n in (counts.moved, counts.crossed))
    return new, (before, after, moved, crossed), fitted


def _reequilibrated(
    model: CoupledElasticity | EFGElasticity,
    efg: bool,
    u: dolfinx.fem.Function | None,
    built: BlockModel | EFGBlockModel,
    fitted: np.ndarray | None,
    control: DisplacementControl,
    monitors: dict[str, DisplacementControl] | None,
    loads: _Loads,
    t: float,
    tau: float,
    tol: _Tolerance,
    options: PathOptions,
    solver: SolverOptions,
    event: str,
    result: PathResult,
    handover: Callable | None = None,
) -> tuple[BlockModel | EFGBlockModel, float, int, float, Callable, dict[str, Callable]]:
    """``model`` brought back to equilibrium at the control value ``tau`` after its cracks
    changed (one grew, or one started: ``event``, the errors' opening words) or its patch grew
    (``fitted`` ``None``): rebuilt on them (the faces' states carried; a switch's ``handover``
    called on the rebuilt model, :attr:`PathResult.handovers`), the particle field set
    to the refitted ``fitted`` (a grown patch: fitted to the old field, and ``loads`` rebuilt on
    the new layout, the work counted from the fitted state), re-equilibrated. Returns the new
    built model, the load factor, Newton's iterations, the work of the load on the way, and the
    control and monitor functions on the new model (collective)."""
    k_p = _particle_field(built)
    old = _owned(built.x)
    comm = _comm(built)
    try:
        built, carried, refit = _rebuild(model, built, efg, u)
    except MomentMatrixError as err:  # raised on every rank
        raise PathError(
            f"{event} and the MLS cannot be evaluated beside it ({err}); choose a finer particle "
            "spacing or a larger dilation",
            result,
        ) from None
    if handover is not None:  # the band's energy to the faces: counted in the carry's record
        taken, given, frozen = handover(built)
        result.handovers.append((len(result.control) + 1, taken, frozen))
        if carried is not None:
            carried = (carried[0], carried[1] - given + taken, *carried[2:])
    if carried is not None:  # the step being converged: its record is appended after this
        step = len(result.control) + 1
        result.carried.append((step, *carried))
        before, after = carried[0], carried[1]
        if before > 0.0 and abs(after - before) > CARRY_TOLERANCE * before:  # every rank
            warnings.warn(
                f"{event}: carrying the bulk's states to the new points changed its dissipated "
                f"energy from {before:.6g} to {after:.6g} ({(after - before) / before:+.2%}, "
                f"more than CARRY_TOLERANCE={CARRY_TOLERANCE:g}): the cells the crack newly cut "
                "held strongly varying states; refine the particle spacing along the path "
                "(PathResult.carried)",
                StateCarryWarning,
                stacklevel=3,
            )
    problem, x = built.problem, built.x
    side = built.particles
    if refit is not None:  # a grown patch: the new layout's loads
        fitted = refit
        loads.destroy()
        new = _Loads.of(built, efg)
        loads.q, loads.f_ext, loads.norm = new.q, new.f_ext, new.norm
    lo, hi = x[k_p].getOwnershipRange()
    mine = (side.dof_map >= lo) & (side.dof_map < hi)
    x[k_p].array[side.dof_map[mine] - lo] = fitted[mine]
    if refit is not None:
        old = _owned(x)
    g = _control_function(built, control)
    watch = {k: _control_function(built, c) for k, c in (monitors or {}).items()}
    problem.t = t
    try:
        t_new, its = _reequilibrate(problem, x, t, tau, g, loads.q, tol, options, solver)
    except ArithmeticError as err:
        fix = (
            "a smaller increment (PathOptions.max_increment: the patch then grows by fewer "
            "cells at a time) or a patch that covers more from the start"
            if refit is not None
            else "a smaller increment or a larger CohesiveGrowth.ahead"
        )
        raise PathError(
            f"{event} and no equilibrium was found at the same control value ({err}); choose {fix}",
            result,
        ) from None
    problem.t = t_new
    problem.commit(x)
    work = _work(loads.f_ext, x[: k_p + 1], old[: k_p + 1], t, t_new, comm)
    return built, t_new, its, work, g, watch


def _solution(built: BlockModel, model: CoupledElasticity) -> CoupledSolution:
    """The coupled solution at ``built``'s state, with the model's small-strain law (for the
    criteria's stresses) and the committed states of its laws (for
    :class:`~dolfinx_meshfree.StateAbove`; collective)."""
    solution = built.solution()
    solution.material = model.material
    solution.states = built.problem.states
    return solution


def _regrown(
    model: CoupledElasticity,
    criteria: list,
    context: GrowthContext,
    built: BlockModel,
    result: PathResult,
    reequilibrated: Callable,
) -> tuple[CoupledElasticity, BlockModel, float, int, float, Callable, dict] | None:
    """Grow the patch where ``criteria`` name FE cells, rebuild and re-equilibrate
    (:mod:`.path_patch`; collective) by ``reequilibrated(model, built, None, what)`` (the path's
    :func:`_reequilibrated` at its current state): the new model, built model, load factor,
    Newton's iterations, the work of the load on the way, the control and monitor functions;
    ``None`` when no FE cell is named. The event goes to :attr:`PathResult.patch_events`;
    whether a criterion named any cell, patch cells included, to ``result.adapt_named``."""
    regrown, named = grow_patch(model, criteria, context)
    result.adapt_named |= named
    if regrown is None:
        return None
    model, patch_event = regrown
    stored, records = _energies(built)[0], len(result.carried)
    what = f"the patch grew by {patch_event.cells_added} cells"
    built, t, its, work, g, watch = reequilibrated(model, built, None, what)
    patch_event.energy_change = _energies(built)[0] - stored - work
    if len(result.carried) > records:  # the bulk's states, carried by this rebuild
        patch_event.carried = result.carried[-1][1:]
    result.patch_events.append(patch_event)
    return model, built, t, its, work, g, watch


#: The most sites that could not start a crack tried in one step (each then left out:
#: :attr:`PathResult.refused`) before the path goes on.
MAX_REFUSED_PER_STEP = 8


def _bulk_peaks(
    built: BlockModel | EFGBlockModel,
    law: LinearElastic,
    refused: list[tuple[int, list[float], float, str]],
    initiation: CrackInitiation | None,
) -> tuple[tuple[np.ndarray | None, float], tuple[np.ndarray | None, float]]:
    """The bulk's peak (the record) and where the next crack would start: the same peak, or,
    with ``refused`` sites or the initiation's ``region``, the peak inside the region of the
    regions of tension above ``f_t`` other than the refused sites' (collective)."""
    if initiation is None:
        return bulk_stress_peaks(built.solution(), material=law)
    return bulk_stress_peaks(
        built.solution(),
        material=law,
        exclude=[np.asarray(point) for _, point, _, _ in refused],
        above=initiation.law.ft,
        region=initiation.region,
    )


def _start_crack(
    built: BlockModel | EFGBlockModel,
    model: CoupledElasticity | EFGElasticity,
    efg: bool,
    initiation: CrackInitiation,
    growths: list[CohesiveGrowth],
    point: np.ndarray,
) -> tuple[Crack | None, np.ndarray | None, str]:
    """Start a crack at the bulk's peak ``point`` (:mod:`.crack_initiation`): ``(crack,
    refitted coefficients, "")``, or ``(None, None, why)`` (collective)."""
    solution = built.solution()
    coupled = not efg
    domain = model._domain if efg else model.patch
    cracks = list(model.cracks if efg else model.patch.cracks)
    if coupled and not _inside(domain, np.asarray(point, dtype=float)[None])[0]:
        return (
            None,
            None,
            (
                "it lies on the FE side of the coupled model, which cannot carry a crack: add the "
                "cells around it to the patch"
            ),
        )
    site = site_at(solution, point, initiation.law.ft, model.material if efg else model.law)
    clearance = float(model.mls.radii.max()) if coupled else 0.0
    crack, why = first_stretch(initiation, site, domain, cracks, coupled, clearance)
    if crack is None:
        return None, None, why
    try:  # its checks raise on every rank alike
        c = solution.coefficients
        fitted = insert_crack(model, efg, crack, initiation.law, c, site.spacing)
    except ValueError as err:  # the crack's checks, raised on every rank: not started
        first = crack.points.round(6).tolist()
        return None, None, f"its first stretch {first} is refused ({err})"
    template = growths[0] if growths else CohesiveGrowth(crack)
    growths.append(replace(template, crack=crack))
    return crack, fitted, ""


def _destroy_all(objects: Sequence) -> None:
    for obj in objects:
        obj.destroy()


def follow_path(
    model: CoupledElasticity | EFGElasticity | FEElasticity,
    control: DisplacementControl | ArcLength,
    options: PathOptions,
    solver: str | SolverOptions = "mumps",
    on_step: Callable[[int, float, float], None] | None = None,
    monitors: dict[str, DisplacementControl] | None = None,
    growth: CohesiveGrowth | Sequence[CohesiveGrowth] | None = None,
    initiation: CrackInitiation | None = None,
    adapt: Any = None,
) -> PathResult:
    """Follow the equilibrium path of ``model`` by indirect displacement control (collective).

    The model's loads (tractions, body forces, prescribed displacements) are scaled by the load
    factor ``t``, an unknown; the control quantity grows by adaptive increments from 0 to
    ``options.end``. The law may have state (:class:`~dolfinx_meshfree.RankineDamage`,
    :class:`~dolfinx_meshfree.J2Plasticity`): it is committed at every converged step.

    Args:
        model: A :class:`~dolfinx_meshfree.CoupledElasticity` (with a law with state, or any law
            of a coupling of :data:`~dolfinx_meshfree.FINITE_STRAIN_COUPLINGS`), a pure
            :class:`~dolfinx_meshfree.EFGElasticity` with a law with state or at finite strain,
            or a pure FE :class:`~dolfinx_meshfree.FEElasticity` (no cracks: without
            ``growth``, ``initiation`` and ``adapt``).
        control: The controlled quantity (:class:`DisplacementControl`), or
            :class:`ArcLength` (Crisfield's cylindrical arc length).
        options: Increments, the end, Newton's tolerances (:class:`PathOptions`).
        solver: The linear solver of each iteration (two solves per iteration).
        on_step: Called as ``on_step(step, t, tau)`` after every converged step.
        monitors: Other quantities of the same kind recorded at every converged step (e.g. the
            deflection under the load), in :attr:`PathResult.monitors` by name.
        growth: Cohesive cracks that find their path
            (:class:`~dolfinx_meshfree.statics.cohesive_growth.CohesiveGrowth`): after a
            converged step a crack whose softening front nears its tip grows, the model is
            rebuilt on it (the faces' states carried) and brought back to equilibrium at the same
            control value, then checked again. With a small-strain bulk (elastic, or with
            state: carried to the cut cells' new points, :mod:`.state_carry`) and indirect
            displacement control; :attr:`PathResult.extensions` records each growth (and
            :attr:`PathResult.carried` each transfer of a state). A
            :class:`~dolfinx_meshfree.CrackBandSwitch` grows a crack from a RankineDamage
            bulk's band where it has localised, the band's softening handed to the new faces
            (:attr:`PathResult.handovers`).
        initiation: Start further cohesive cracks where the bulk's averaged largest principal
            stress passes ``f_t`` (:class:`~dolfinx_meshfree.CrackInitiation`, multiple
            cracking: :mod:`~dolfinx_meshfree.statics.crack_initiation`); each then grows like
            the first of ``growth``. :attr:`PathResult.initiations` records them. With an
            elastic bulk, cohesive cracks and indirect displacement control.
        adapt: A patch that grows along the path (:mod:`.path_patch`): a criterion
            (:class:`~dolfinx_meshfree.NearTips`, :class:`~dolfinx_meshfree.FieldAbove`,
            :class:`~dolfinx_meshfree.CellsWhere`, or the user's ``select(patch, context)``) or
            a list. After every converged step, and before every extension of a growing crack,
            the FE cells it names become particle cells: the model is rebuilt on the larger
            patch (:func:`~dolfinx_meshfree.statics.coupled.on_patch`), the particle field
            fitted to the old one, the states carried, and equilibrium found again at the same
            control value. ``NearTips()`` keeps the patch two spacings beyond what a growing
            crack's next extension needs (its increment plus a support radius).
            :attr:`PathResult.patch_events` records each growth. A
            :class:`~dolfinx_meshfree.CoupledElasticity` with a coupling of
            :data:`~dolfinx_meshfree.statics.path_patch.ADAPT_COUPLINGS`.

    Returns:
        The :class:`PathResult`.

    Warns:
        PatchCriterionWarning: with ``adapt``, when no criterion named a cell in the whole
            path (patch cells included): the patch never grew.
        BulkStrengthWarning: with cohesive cracks in an elastic bulk, once the bulk's averaged
            principal stress three spacings or more from every crack passes ``f_t``
            (:attr:`PathResult.bulk_stress`) and no crack is started there (no ``initiation``,
            or it says why not): a further crack would start there.

    Raises:
        PathError: a step does not converge after ``options.max_cuts`` halvings (naming the
            step, the control value and the load factor, and a control quantity that turns
            there; the path so far in ``result``), or converges at every increment only on a
            branch where the body deforms off the control (:data:`LEVER_JUMP`).
        ValueError: a control quantity that does not move under the load.
    """
    efg = isinstance(model, EFGElasticity)
    fe_only = isinstance(model, FEElasticity)
    comm = model.comm if efg or fe_only else model.patch.comm
    solver = raise_on_all_ranks(comm, lambda: solver_options(solver))
    given = model  # a grown patch rebuilds the model: the path ends on result.model
    t0 = time.perf_counter()
    if fe_only:
        raise_on_all_ranks(comm, lambda: _check_fe_only(model.law, growth, initiation, adapt))
    cracks = model.cracks if efg or fe_only else model.patch.cracks
    growths = [] if growth is None else [growth] if isinstance(growth, CohesiveGrowth) else growth
    raise_on_all_ranks(comm, lambda: _register_switches(model, efg, growths, cracks))
    raise_on_all_ranks(comm, lambda: check_through(cracks, model.cohesive))
    raise_on_all_ranks(comm, lambda: _check_unloaded(model))
    growths = list(growths)  # cracks that start during the path add theirs
    raise_on_all_ranks(comm, lambda: _check_growth(model, efg, growths, control, cracks))
    raise_on_all_ranks(comm, lambda: _check_initiation(model, efg, initiation, control))
    criteria = []  # a patch that grows along the path
    if adapt is not None:
        criteria = raise_on_all_ranks(comm, lambda: check_adapt(model, efg, adapt, growths))
    bulk_law = model.material if efg else model.law
    grown = [  # a switch's faces take over from the band: no double softening
        c.law.ft
        for c in model.cohesive
        if any(gr.crack is c.crack and not isinstance(gr, CrackBandSwitch) for gr in growths)
    ]
    if isinstance(bulk_law, RankineDamage) and grown and bulk_law.ft <= max(grown):
        warnings.warn(
            f"the bulk's RankineDamage has f_t={bulk_law.ft:g}, not above the growing cohesive "
            f"faces' f_t={max(grown):g}: ahead of the tip the bulk softens where the bonded "
            "faces do, and the fracture energy is dissipated twice there; give the bulk a larger "
            "f_t (its damage then stays away from the crack), or an elastic bulk",
            DoubleSofteningWarning,
            stacklevel=2,
        )
    if efg:
        if isinstance(model.material, LinearElastic) and not model.cohesive:
            raise ValueError(
                "follow_path needs a law whose response is not linear (a law with state, or a "
                "finite-strain law) or cohesive cracks (add_cohesive): a LinearElastic model's "
                "path is a straight line; solve it"
            )
        built, u = model.block_model(), None
    elif fe_only:
        built, u = model.block_model(), None
    else:
        u = dolfinx.fem.Function(model.V)
        u.x.array[:] = 0.0
        built = build_block_problem(model, law_internal_force(model.law, u), u, model.law)
    problem, x = built.problem, built.x
    k_p = _particle_field(built)
    result = PathResult()
    law = model.material if efg else model.law
    watch_bulk = bool(model.cohesive) and isinstance(law, LinearElastic)  # cohesive: 2D
    ft_bulk = min((c.law.ft for c in model.cohesive), default=np.inf)
    warned = False
    arc = isinstance(control, ArcLength)
    try:
        g = None if arc else _control_function(built, control)
        watch = {k: _control_function(built, c) for k, c in (monitors or {}).items()}
        result.monitors = {k: [] for k in watch}
        loads = _Loads.of(built, efg)

        def reequilibrated(
            model: CoupledElasticity | EFGElasticity,
            built: BlockModel | EFGBlockModel,
            fitted: np.ndarray | None,
            what: str,
            handover: Callable | None = None,
        ) -> tuple[BlockModel | EFGBlockModel, float, int, float, Callable, dict]:
            """:func:`_reequilibrated` at the path's current step, control value, load factor
            and tolerances, after ``what`` happened (collective)."""
            event = f"at step {step} (control {tau:.6g}, load factor {t:.6g}) {what}"
            return _reequilibrated(
                model, efg, u, built, fitted, control, monitors, loads, t, tau, tol,
                options, solver, event, result, handover,
            )  # fmt: skip

        t, tau, dtau, cuts = 0.0, 0.0 if arc else g(_owned(x)), options.increment, 0
        tau_start = tau
        previous: list[np.ndarray] | None = None  # the last arc-length step's direction
        reason = ""
        max_dtau = options.max_increment or 8.0 * options.increment
        work, peak = 0.0, 0.0
        lever: float | None = None  # the last step's load work per unit control and load
        first_lever: float | None = None  # the path's first
        stable, signs = StabilityWatch(), []  # the bordered determinant's sign per step
        step = 0
        while tau < options.end - 1e-14 * abs(options.end) and step < options.max_steps:
            target = min(options.end, tau + dtau)
            saved = [v.copy() for v in x]
            tol = _Tolerance(
                loads.norm, max(abs(t), peak, 1e-3), options.rtol, options.atol, options.stall
            )
            try:
                if arc:
                    t_new, its, previous_new = _arc_step(
                        problem, x, t, target - tau, previous, loads.q, tol, k_p + 1,
                        options, solver, stability=signs,
                    )  # fmt: skip
                else:
                    t_new, its = _bordered_step(
                        problem, x, t, target, g, loads.q, tol, options, solver, stability=signs
                    )
            except ArithmeticError as err:
                reason = str(err)
                restore_step(problem, x, saved)
                result.cuts += 1
                if cuts == options.max_cuts:
                    what = "arc length" if arc else "control"
                    why = (
                        "the arc-length equation found no real root"
                        if "root" in reason
                        else f"Newton did not converge in max_it={options.max_it} iterations"
                    )
                    fix = (
                        "a smaller increment (arc length), or indirect displacement control"
                        if arc
                        else "a control quantity that grows monotonically through the failure, "
                        "or a smaller increment"
                    )
                    turning = "" if arc else _turning(tau_start, result.control, result.load_factor)
                    if turning:  # no increment helps
                        why += turning
                        fix = (
                            "a control quantity that grows monotonically through the failure "
                            "(an opening across where the body fails, on the side that opens)"
                        )
                    raise PathError(
                        f"the path could not be followed at step {step + 1}: from {what} "
                        f"{tau:.6g} (load factor {t:.6g}), at every increment down to "
                        f"{dtau:.3g} {why}; choose {fix}",
                        result,
                    ) from None
                cuts, dtau = cuts + 1, 0.5 * dtau
                continue
            problem.t = t_new
            before = _owned(saved[: k_p + 1])
            w_step = _work(loads.f_ext, x[: k_p + 1], before, t, t_new, comm)
            new_lever = None if arc else _lever(w_step, t, t_new, target - tau, peak)
            jump = _lever_jump(lever, first_lever, new_lever)
            if jump > LEVER_JUMP:
                # the body deformed where the control does not see: another branch; a smaller
                # increment keeps Newton's predictor off it
                restore_step(problem, x, saved)
                result.cuts += 1
                if cuts == options.max_cuts:
                    raise PathError(
                        f"the path could not be followed at step {step + 1}: from control "
                        f"{tau:.6g} (load factor {t:.6g}), at every increment down to {dtau:.3g} "
                        f"the step's converged state has the load's work per unit of control "
                        f"and load {jump:.3g} times the last step's (or a tenth of the first "
                        "step's, if larger): the body "
                        "deforms where the control does not see (cells or particles off the "
                        "control's gauge soften or yield, a second branch of the equilibrium); "
                        "choose a control across the whole region that fails",
                        result,
                    )
                cuts, dtau = cuts + 1, 0.5 * dtau
                continue
            problem.commit(x)
            for w in saved:
                w.destroy()
            work += w_step
            lever = new_lever
            if first_lever is None:
                first_lever = lever
            events = len(result.extensions) + len(result.patch_events) + len(result.initiations)
            t, tau, step = t_new, target, step + 1
            result.stability.append(stable.record(signs[-1] if signs else None, step, tau, t))
            result.bifurcation = stable.warned_at
            for _ in range(max((gr.max_extensions for gr in growths), default=0) + 1):
                if criteria:  # the patch first: a crack's next extension stays inside it
                    context = path_context(model, growths, step, _solution(built, model))
                    regrown = _regrown(model, criteria, context, built, result, reequilibrated)
                    if regrown is not None:
                        model, built, t, its_g, work_g, g, watch = regrown
                        problem, x = built.problem, built.x
                        its, work = its + its_g, work + work_g
                        previous = previous_new = None  # the arc's direction: the old layout
                grown = _grow(built, growths, model, efg)
                if grown is None:
                    break
                grown, fitted, turn, handover = grown
                result.extensions.append((step, tau, grown))
                result.turns.append(turn)
                # the model on the longer crack, the faces' states carried (a switch's band
                # handed over), the particle field refitted across the new segment, back to
                # equilibrium at the same control value (the work of the load on the way recorded)
                built, t, its_g, work_g, g, watch = reequilibrated(
                    model, built, fitted, f"the crack grew to {grown}", handover
                )
                problem, x = built.problem, built.x
                its, work = its + its_g, work + work_g
            else:
                raise PathError(
                    f"at step {step} (control {tau:.6g}, load factor {t:.6g}) the crack grew "
                    f"{len(result.extensions)} times and its softening front still reaches "
                    "within CohesiveGrowth.ahead of the tip: the crack runs at a constant control "
                    "value (a snap-back this control cannot follow); choose a control that grows "
                    "through the failure, or a smaller increment",
                    result,
                )
            bulk = None
            if watch_bulk:  # where a further crack would start: the bulk's stress off the cracks
                # the bulk's peak, and past sites that could not start one the next above f_t
                bulk, candidate = _bulk_peaks(built, law, result.refused, initiation)
            if initiation is not None and bulk is not None:
                tries = 0
                while (
                    candidate[1] > initiation.law.ft
                    and len(result.initiations) < initiation.max_cracks
                    and tries < MAX_REFUSED_PER_STEP
                ):
                    if criteria:  # the patch first: around the site, as around a tip
                        context = site_context(
                            model, growths, step, _solution(built, model), candidate[0],
                            initiation.lead,
                        )  # fmt: skip
                        regrown = _regrown(model, criteria, context, built, result, reequilibrated)
                        if regrown is not None:  # the peak again, on the new model
                            model, built, t, its_g, work_g, g, watch = regrown
                            problem, x = built.problem, built.x
                            its, work = its + its_g, work + work_g
                            bulk, candidate = _bulk_peaks(built, law, result.refused, initiation)
                            continue
                    crack, fitted, reason = _start_crack(
                        built, model, efg, initiation, growths, candidate[0]
                    )
                    if crack is None:  # left out from now on; the next peak is tried
                        tries += 1
                        result.refused.append((step, candidate[0].tolist(), candidate[1], reason))
                    else:
                        result.initiations.append((step, tau, crack.points.tolist()))
                        built, t, its_g, work_g, g, watch = reequilibrated(
                            model,
                            built,
                            fitted,
                            f"a crack started at {crack.points.round(6).tolist()}",
                        )
                        problem, x = built.problem, built.x
                        its, work = its + its_g, work + work_g
                    bulk, candidate = _bulk_peaks(built, law, result.refused, initiation)
            if len(result.extensions) + len(result.patch_events) + len(result.initiations) > events:
                lever = None  # a crack grew or started, the patch grew: a new model's lever
                stable.reset()
            if arc:
                previous = previous_new
            peak = max(peak, t)
            stored, dissipated = _energies(built)
            cut = None if result.band_cut is not None else _band_cut(built)
            if cut is not None:  # the same on every rank
                point, damage, across = cut
                result.band_cut = (step, point.tolist(), damage, across)
                warnings.warn(
                    f"at step {step} (control {tau:.6g}, load factor {t:.6g}) the crack band of "
                    f"the particle points reached the FE interface at "
                    f"{np.round(point, 6).tolist()} (damage {damage:.4f}; the cell across the "
                    f"interface {across:.4f}): the particle field is tied to the FE trace there "
                    "and cannot localise over the band width the law assumes (the MLS dilation "
                    "times the cell size), so it does not dissipate G_f per unit crack area (a "
                    "bar softening in the patch cell on the interface: 0.65 G_f; with the ramp, "
                    "whose blended cells' band is one cell, 1.29 G_f). Widen the patch there, "
                    "so that the band keeps half its width off the interface",
                    BandCutWarning,
                    stacklevel=2,
                )
            result.control.append(tau)
            result.load_factor.append(t)
            result.iterations.append(its)
            result.external_work.append(work)
            result.stored_energy.append(stored)
            result.dissipated_energy.append(dissipated)
            owned = _owned(x)
            for k, fn in watch.items():
                result.monitors[k].append(fn(owned))
            if bulk is not None:
                point, stress = bulk
                result.bulk_stress.append(stress)
                result.bulk_point.append(point.tolist())
                ft_new = ft_bulk if initiation is None else initiation.law.ft
                if stress > ft_new and not warned:  # the same on every rank
                    warned = True
                    if initiation is None:
                        why = (
                            "this model does not start it (it carries the cracks it was given "
                            "or grew; follow_path(initiation=CrackInitiation(law)) starts it)"
                        )
                    elif len(result.initiations) >= initiation.max_cracks:
                        why = f"CrackInitiation.max_cracks={initiation.max_cracks} have started"
                    elif (
                        initiation.region is not None
                        and not initiation.region(np.asarray(point, dtype=float)[None])[0]
                    ):
                        why = "it lies outside CrackInitiation.region, where none may start"
                    else:  # the peak is in a refused site's region
                        where = result.refused[0][1]
                        why = (
                            f"no crack is started at ({where[0]:.6g}, {where[1]:.6g}): "
                            f"{result.refused[0][3]}; its region of tension is left out and "
                            "the peaks of other regions above f_t are tried (PathResult.refused "
                            "lists the sites refused)"
                        )
                    warnings.warn(
                        f"at step {step} (control {tau:.6g}, load factor {t:.6g}) the bulk's "
                        f"averaged largest principal stress reaches {stress / ft_new:.3f} f_t "
                        f"at ({point[0]:.6g}, {point[1]:.6g}), three spacings or more from "
                        f"every crack: a further crack would start there; {why}. The path "
                        "beyond this step is that of the cracks the model carries "
                        "(PathResult.bulk_stress)",
                        BulkStrengthWarning,
                        stacklevel=2,
                    )
            if on_step is not None:
                on_step(step, t, tau)
            if cuts:
                cuts -= 1
            if step > 1 and its <= options.easy:  # the first: the elastic start
                dtau = min(max_dtau, options.grow * dtau)
            for side in problem.shared:  # a cohesive zone that reached the end of its path
                end = side.reached_end() if hasattr(side, "reached_end") else None
                if end is not None:
                    raise PathError(
                        f"at step {step} (control {tau:.6g}, load factor {t:.6g}) the faces of "
                        f"the cohesive crack soften at ({end[0]:.6g}, {end[1]:.6g}), within one "
                        "particle spacing of the tip of its cohesive path: the crack would run "
                        "further than the model can follow; extend the crack's polyline (and "
                        "its cohesive segments) ahead of that tip",
                        result,
                    )
            if options.min_load > 0 and peak > 0 and t < options.min_load * peak:
                break
        else:  # the loop's own condition ended it: the end reached, or max_steps
            if tau < options.end - 1e-14 * abs(options.end):  # the same on every rank
                last = np.diff(result.control[-11:]) if len(result.control) > 1 else []
                warnings.warn(
                    f"follow_path stopped after PathOptions.max_steps={options.max_steps} "
                    f"converged steps at control {tau:.6g} of end={options.end:.6g} (load factor "
                    f"{t:.6g}); the last increments average {np.mean(last) if len(last) else 0:.3g}"
                    f" against increment={options.increment:.3g}. The result is the path up to "
                    "there: raise max_steps, or, if the increments stayed small (each step "
                    "re-equilibrated after a crack grew or started takes more than "
                    f"easy={options.easy} iterations and the increment does not grow), a larger "
                    "increment",
                    PathShortWarning,
                    stacklevel=2,
                )
        error = result.energy_error
        if error > ENERGY_TOLERANCE:  # the energies are global: the same on every rank
            work, stored = result.external_work[-1], result.stored_energy[-1]
            warnings.warn(
                f"the path's energy record does not balance: at its end (step "
                f"{len(result.control)}, control {tau:.6g}) the work of the load minus the "
                f"stored energy, {work - stored:.6g}, misses the dissipated energy, "
                f"{result.dissipated_energy[-1]:.6g}, by {error:.1%} of the work {work:.6g} "
                f"(ENERGY_TOLERANCE={ENERGY_TOLERANCE:g}). Energy changed where no step followed "
                "it (a crack extension re-equilibrated at a fixed control, a step past a "
                "failure): the curve is not resolved there. Follow the path with smaller "
                "increments (PathOptions.increment, max_increment) and compare "
                "(PathResult.energy_error)",
                EnergyBalanceWarning,
                stacklevel=2,
            )
        loads.destroy()
        result.solution = built.solution()
        result.model = model
        # a later solve() continues from the path's end (on the model the path ended with)
        problem.t = t
        given.reset()
        given.history.moved = model is not given
        model.history.record(problem, x)
        if criteria and not result.adapt_named:  # the same on every rank
            warn_unused(criteria, "follow_path", f"{len(result.control)} converged step(s)")
        result.solution.states = problem.states
    finally:
        built.destroy()
    result.seconds = time.perf_counter() - t0
    return result
