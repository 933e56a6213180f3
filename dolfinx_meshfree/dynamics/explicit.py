"""The public entry point of explicit dynamics: :class:`ExplicitDynamics`.

Semi-discrete equations of motion (Belytschko et al. 1995, eq. 4.4–4.5; Rabczuk et al. 2006,
eq. 86–92), one block per field (FE nodes, particles):

.. math::
    M \\ddot d + f^{int}(d) = f^{ext} + G^T \\lambda, \\qquad G \\dot d = 0,

with ``M`` lumped (row sums, :mod:`~dolfinx_meshfree.dynamics.masses`), ``f^int(d) = K d`` for
linear
elasticity (:class:`~dolfinx_meshfree.dynamics.system.LinearSystem`: diagonal blocks per field
and, for the ramp couplings, the bridging penalty, master–slave and the hybrid coupling,
off-diagonal blocks), and ``G`` the constraint blocks (interface multipliers, and essential
conditions on particles). The facade puts together one module per idea: the system, central
differences (:mod:`~dolfinx_meshfree.dynamics.central_difference`), the multiplier correction
(:mod:`~dolfinx_meshfree.dynamics.constraint`), the stable step
(:mod:`~dolfinx_meshfree.dynamics.time_step`), the loads, the initial conditions, the
evaluation and the builders of every method (:mod:`~dolfinx_meshfree.dynamics.builders`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from ..approx.mls import MLS
from ..couplings.bridging import BridgingBand
from ..couplings.hybrid import HybridElasticity
from ..couplings.ramp import RampInterface
from ..geometry.adaptive_quadrature import AdaptiveQuadrature
from ..geometry.crack import Crack
from ..geometry.particles import ParticleSet
from ..geometry.patch import ParticlePatch
from ..parallel import raise_on_all_ranks
from ..physics.cohesive import LinearCohesive
from ..physics.constitutive import Material
from ..physics.materials import LinearElastic, is_axisymmetric
from ..statics.coupled import CoupledElasticity
from .builders import Model, build_coupled, build_efg, build_fe
from .central_difference import CentralDifference
from .cohesive_faces import cohesive_records, with_cohesive_faces
from .conditions import held_velocities
from .constraint import VelocityProjection, check_multiplier_solver
from .crack_contact import CrackContact, with_crack_contact
from .discretisation import Discretisation, VectorFunction
from .evaluation import FieldEvaluator
from .initial import check_particle_values, initial_values
from .loads import Amplitude, BodyLoad, ExternalLoads, Traction
from .prescribed import HeldVelocity
from .queries import StateQueries
from .results import DynamicsResult
from .run import integrate
from .static_model import check_static_model
from .struck import Struck
from .system import Field, LinearSystem, SemiDiscreteSystem, inverse_masses
from .time_step import TimeStepBound, check_safety, warn_default_density

__all__ = ["ExplicitDynamics"]

OnOutput = Callable[["ExplicitDynamics", int, float], None]


class ExplicitDynamics(StateQueries, Struck):
    """Central-difference explicit dynamics of elasticity, FE, EFG or coupled: small strain
    (:class:`~dolfinx_meshfree.LinearElastic`, ``f^int = K d``) or finite strain, total
    Lagrangian (:class:`~dolfinx_meshfree.NeoHookean`,
    :class:`~dolfinx_meshfree.SaintVenantKirchhoff`: the
    :class:`~dolfinx_meshfree.dynamics.finite_strain.NonlinearSystem`, with the stable step
    re-bounded as the material stiffens, :class:`~dolfinx_meshfree.dynamics.time_step.Rebound`).

    Build with :meth:`fe`, :meth:`efg` or :meth:`coupled` (every coupling of
    :data:`~dolfinx_meshfree.dynamics.DYNAMICS_METHODS`), in 2D or 3D (the mesh's ``gdim``
    sets the components; in 3D FE, EFG, lagrange, edge-to-edge and bridging, the couplings that
    refuse 3D saying so when their static problem is built); set the initial state with
    :meth:`set_initial`; optionally :meth:`add_traction` and :meth:`add_body_force`; then
    :meth:`run`. The velocity can be evaluated at any points (:meth:`velocity_at`) and compared
    with an exact solution (:meth:`velocity_error`, Rabczuk et al. 2006, eq. 137) after a run,
    at the final time or in the ``on_output`` callback. Collective throughout.

    Args:
        fields: One or two :class:`~dolfinx_meshfree.dynamics.system.Field` (FE first).
        material: The law (density and wave speed): :class:`~dolfinx_meshfree.LinearElastic`,
            a finite-strain :class:`~dolfinx_meshfree.physics.constitutive.Material`, or (from
            the builders) a rate-form law or :class:`~dolfinx_meshfree.MaterialZones` bound as
            :class:`~dolfinx_meshfree.dynamics.rate_forms.RateLaws`.
        constraint: The constraint blocks ``G_f`` of each field (``None`` for a field without),
            or ``None``: no constraint.
        safety: Fraction of the critical time step used by default and allowed without
            ``force`` (0 < safety <= 1).
        blocks: Off-diagonal stiffness blocks ``{(k, l): K_kl}`` (rows of field ``k``, columns
            of field ``l``).
        multiplier_solver: How ``S = G M^{-1} G^T`` is factorised (once): ``"dense"``
            (Cholesky on every rank, one ``Allgatherv`` of ``G v`` per step: the fastest for
            interface-sized ``S``), ``"mumps"`` (distributed LU), or ``None``: dense up to
            2000 multipliers.
        V, mls, particles, mesh, in_patch, patch, interface, reduction: The spaces, for
            loads and evaluation (see
            :class:`~dolfinx_meshfree.dynamics.discretisation.Discretisation`).
        body_load: ``body_load(b) -> (fe, particles)``: the consistent loads of a body force
            (set by the builders, :class:`~dolfinx_meshfree.dynamics.loads.ExternalLoads`);
            ``None``: :meth:`add_body_force` uses the lumped masses.
        system: The semi-discrete system; ``None``: the
            :class:`~dolfinx_meshfree.dynamics.system.LinearSystem` of ``fields``, ``blocks``
            and ``constraint`` (the builders give a
            :class:`~dolfinx_meshfree.dynamics.finite_strain.NonlinearSystem` for a
            finite-strain material).
        rebound_every: Steps between two checks of the current wave speed of a finite-strain
            system (a growth above 5 % re-bounds the step, :class:`Rebound`; a bulk
            viscosity's damper, :mod:`~dolfinx_meshfree.physics.bulk_viscosity`, is checked at
            every step). held: FE facets
            driven at prescribed velocities (:mod:`~dolfinx_meshfree.dynamics.prescribed`).

    Attributes:
        system: The :class:`~dolfinx_meshfree.dynamics.system.SemiDiscreteSystem`.
        projection: The :class:`~dolfinx_meshfree.dynamics.constraint.VelocityProjection`, or
            ``None`` without a constraint.
        u, v: ``d_n`` and ``v_{n-1/2}`` per field (PETSc vectors).
        quadrature: The particle cells' :class:`~dolfinx_meshfree.AdaptiveQuadrature` (set by
            :meth:`efg` and :meth:`coupled`), or ``None``: the uniform rule.
    """

    quadrature: AdaptiveQuadrature | None = None
    #: ``(quadrature, MLS table)`` of the particle masses on the patch cells (set by
    #: :meth:`coupled`): what a conversion fits new particles on.
    mass_rule: tuple | None = None
    #: The ramps' interface cells: ``(quadrature, blended table [local FE nodes | particles])``.
    blended_rule: tuple | None = None

    def __init__(
        self,
        fields: Sequence[Field],
        material: LinearElastic | Material,
        constraint: Sequence[PETSc.Mat | None] | None = None,
        safety: float = 0.9,
        *,
        blocks: dict[tuple[int, int], PETSc.Mat] | None = None,
        V: dolfinx.fem.FunctionSpace | None = None,
        mls: MLS | None = None,
        particles: ParticleSet | None = None,
        mesh: dolfinx.mesh.Mesh | None = None,
        in_patch: np.ndarray | None = None,
        patch: ParticlePatch | None = None,
        interface: RampInterface | BridgingBand | None = None,
        reduction: tuple[PETSc.Mat, PETSc.Mat] | None = None,
        timings: dict | None = None,
        multiplier_solver: str | None = None,
        body_load: BodyLoad | None = None,
        system: SemiDiscreteSystem | None = None,
        rebound_every: int = 10,
        held: Sequence[HeldVelocity] = (),
    ) -> None:
        check_safety(safety)
        check_multiplier_solver(multiplier_solver)
        warn_default_density(material)
        if system is None:
            system = LinearSystem(fields, blocks, constraint)
        self.system = system
        self.fields, self.G = self.system.fields, self.system.constraints()
        self.blocks = getattr(self.system, "blocks", {})
        self.rebound_every = rebound_every
        self.material = material
        self.V, self.mls, self.particles, self.mesh = V, mls, particles, mesh
        self.in_patch, self.patch = in_patch, patch
        self.interface, self.reduction = interface, reduction
        disc = Discretisation(
            self.system.fields, V, mls, particles, mesh, in_patch, patch, interface, reduction,
            is_axisymmetric(material),  # rate laws' too
        )  # fmt: skip
        self.comm = self.fields[0].mass.getComm().tompi4py()
        self.timings = dict(timings or {})
        t0 = time.perf_counter()
        self._minv, self.active, self.free = inverse_masses(self.fields)
        self.multiplier_solver = multiplier_solver
        self.projection: VelocityProjection | None = None
        if self.G is not None:
            self.projection = VelocityProjection(self.G, self._minv, self.comm, multiplier_solver)
            self.multiplier_solver = self.projection.solver
        self.bound = TimeStepBound(self.system, material, self._minv, self.free, self.comm, safety)
        self.loads = ExternalLoads(disc, self.free, self.comm, material.rho, body_load, held)
        self.stepper = CentralDifference(self.system, self._minv, self.loads, self.projection)
        if hasattr(self.system, "wave_speed"):  # bounded at the current state
            self.bound.state = lambda: self.stepper.u
        self.evaluator = FieldEvaluator(disc, self.comm)
        for side in getattr(self.system, "shared", ()):  # master-slave's rotating links
            if getattr(side, "correction", None) is not None:
                self.evaluator.expand = lambda vecs, side=side: side.expand(vecs, self.stepper.u)
        self.u, self.v = self.stepper.u, self.stepper.v
        self.timings["setup"] = self.timings.get("setup", 0.0) + time.perf_counter() - t0

    @classmethod
    def _from_model(
        cls,
        model: Model,
        safety: float,
        multiplier_solver: str | None = None,
        fixed=None,
        quadrature: AdaptiveQuadrature | None = None,
    ) -> ExplicitDynamics:
        args = dict(model.arguments(), held=held_velocities(model.mesh, fixed))
        dyn = cls(**args, safety=safety, multiplier_solver=multiplier_solver)
        dyn.quadrature = quadrature
        dyn.mass_rule, dyn.blended_rule = model.mass_rule, model.blended_rule
        return dyn

    @classmethod
    def fe(
        cls,
        V: dolfinx.fem.FunctionSpace,
        material: LinearElastic | Material,
        safety: float = 0.9,
        fixed_facets: npt.ArrayLike | None = None,
        dilatation: str | None = None,
    ) -> ExplicitDynamics:
        """Pure FE: DOLFINx's stiffness ``inner(sigma(u), eps(v)) dx`` and row-sum masses.

        ``fixed_facets``: owned exterior facets whose nodes are held at rest (strongly), or
        ``(facets, components)`` pairs holding only some components, e.g.
        ``[(symmetry_plane, (0,))]`` (particles, the hybrid's too: a multiplier per facet and
        component); ``(facets, components, velocity)`` triples drive FE nodes (``held``).
        ``dilatation``: a rate-form law's volumetric strain: ``None`` (automatic: the cell's
        mean on quadrilaterals and hexahedra in plane strain, axisymmetry and 3D, where the
        full rule locks under plastic flow), ``"mean"`` or ``"pointwise"``
        (:mod:`~dolfinx_meshfree.dynamics.rate_dilatation`).
        """
        check_safety(safety)
        model = build_fe(V, material, fixed_facets, dilatation)
        return cls._from_model(model, safety, None, fixed_facets)

    @classmethod
    def efg(
        cls,
        particles: ParticleSet,
        material: LinearElastic | Material,
        weight: str = "quartic",
        dilation: float = 2.0,
        basis: str = "linear",
        quadrature_degree: int = 7,
        particle_mass: str = "row-sum",
        safety: float = 0.9,
        fixed_facets: npt.ArrayLike | None = None,
        multiplier_solver: str | None = None,
        integration: str = "cells",
        cracks: Sequence[Crack] = (),
        crack_method: str = "diffraction",
        crack_contact: CrackContact | None = None,
        quadrature: AdaptiveQuadrature | None = None,
        cohesive: Sequence[tuple[Crack, LinearCohesive]] = (),
    ) -> ExplicitDynamics:
        """Pure EFG on ``particles`` (Belytschko et al. 1995, sec. 5.2), on their background
        cells or (``integration="stress-points"``) at the particles and stress points; fixed
        facets by facet multipliers on the velocities; ``cracks`` cut the MLS weights and the
        cells. Arguments: see :func:`~dolfinx_meshfree.dynamics.builders.build_efg`;
        ``crack_contact``: the faces' contact (:mod:`~dolfinx_meshfree.dynamics.crack_contact`);
        ``cohesive``: ``(crack, law)`` pairs, cracks of ``cracks`` whose faces carry a
        :class:`~dolfinx_meshfree.LinearCohesive` law on all their segments
        (:mod:`~dolfinx_meshfree.dynamics.cohesive_faces`).
        """
        check_safety(safety)
        check_multiplier_solver(multiplier_solver)
        records = raise_on_all_ranks(
            particles.comm, lambda: cohesive_records(cohesive, cracks, particles.gdim)
        )
        model = build_efg(
            particles,
            material,
            weight=weight,
            dilation=dilation,
            basis=basis,
            quadrature_degree=quadrature_degree,
            particle_mass=particle_mass,
            fixed_facets=fixed_facets,
            integration=integration,
            cracks=cracks,
            crack_method=crack_method,
            quadrature=quadrature,
        )
        if records:
            model = with_cohesive_faces(model, records, crack_contact)
        else:
            model = with_crack_contact(model, crack_contact)
        return cls._from_model(model, safety, multiplier_solver, fixed_facets, quadrature)

    @classmethod
    def coupled(
        cls,
        problem: CoupledElasticity | HybridElasticity,
        particle_mass: str = "row-sum",
        safety: float = 0.9,
        multiplier_solver: str | None = None,
        fixed_facets: npt.ArrayLike | None = None,
        integration: str = "cells",
        slaves: str | None = None,
        material: Material | None = None,
        crack_contact: CrackContact | None = None,
        fe_dilatation: str | None = None,
    ) -> ExplicitDynamics:
        """A :class:`~dolfinx_meshfree.CoupledElasticity` (any coupling) or a
        :class:`~dolfinx_meshfree.HybridElasticity` in dynamics, from the static problem's
        operators (:meth:`CoupledElasticity.operators`: stiffness and constraint blocks, MLS,
        quadrature, interface shape functions). Give loads with :meth:`add_traction` and
        :meth:`add_body_force`. ``integration="stress-points"``: Lagrangian-kernel stress
        points (lagrange, edge-to-edge, master-slave); ``slaves="coincident"``: Johnson's
        coupling (master-slave, Rabczuk et al. 2006, eq. 15–16); ``None``: the static model's
        ``slaves`` (``"layer"`` unless ``model.slaves = "first-layer"`` was set). ``material``:
        a finite-strain law whose linear twin is the problem's material (every coupling; the
        hybrid with HA-F); ``None``: the law the problem was built with (a
        ``CoupledElasticity`` built on a ``NeoHookean`` runs at finite strain),
        ``problem.material`` its small-strain twin.
        ``crack_contact``: contact of the patch's crack faces, as in :meth:`efg`. The problem's
        cohesive faces (``add_cohesive``) carry their law
        (:mod:`~dolfinx_meshfree.dynamics.cohesive_faces`). ``fe_dilatation``: a rate-form
        law's FE cells, as :meth:`fe`'s ``dilatation`` (``None``: the problem's
        ``fe_dilatation``). Arguments: see
        :func:`~dolfinx_meshfree.dynamics.builders.build_coupled`.
        """
        check_safety(safety)
        check_multiplier_solver(multiplier_solver)
        check_static_model(problem)  # what the static model holds that dynamics leaves out
        cohesive = list(getattr(problem, "cohesive", None) or [])
        model = build_coupled(
            problem, particle_mass, fixed_facets, integration, slaves, material, fe_dilatation
        )
        if cohesive:  # the faces' law (refused, on every rank, where it cannot be carried)
            model = with_cohesive_faces(model, cohesive, crack_contact)
        else:
            model = with_crack_contact(model, crack_contact)
        quadrature = getattr(getattr(problem, "patch", None), "quadrature", None)
        return cls._from_model(model, safety, multiplier_solver, fixed_facets, quadrature)

    @property
    def safety(self) -> float:
        """Fraction of the critical time step used by default."""
        return self.bound.safety

    @property
    def step(self) -> int:
        """The current step."""
        return self.stepper.step

    @property
    def time(self) -> float:
        """The current time."""
        return self.stepper.time

    def constraint_residual(self, vel: list[PETSc.Vec] | None = None) -> float:
        """Relative residual ``|sum_f G_f v_f|_inf / sum_f |G_f|_inf |v_f|_inf`` (collective);
        0 without a constraint. Default: the velocities at the current time."""
        return self.stepper.residual(vel)

    def critical_time_step(self, iterations: int = 30) -> dict:
        """Critical time step ``2 / omega_bound`` from an upper bound of ``omega_max``
        (collective, computed once): see :mod:`~dolfinx_meshfree.dynamics.time_step`.

        Returns:
            A dict with the keys ``"courant"`` (``h_min / c``), ``"spectral"``
            (``2 / omega_bound``), ``"critical"`` (the same, the guard), ``"omega_bound"``,
            ``"gershgorin"`` (``2 /`` the row-sum bound with ``y = 1``), ``"h_min"`` and
            ``"wave_speed"``.
        """
        return self.bound.critical(iterations)

    def stable_time_step(self) -> float:
        """``safety`` times the critical time step (collective)."""
        return self.bound.stable()

    def set_initial(
        self,
        velocity: VectorFunction | None = None,
        displacement: VectorFunction | None = None,
        particle_values: str = "collocation",
    ) -> None:
        """Initial displacement and velocity from functions of position (m, gdim) -> (m, gdim).

        FE dofs take the nodal values; particle coefficients either reproduce the values at the
        particles (``"collocation"``: ``Phi(x_J) c = f(x_J)``, one sparse LU, MLS being not
        interpolating) or take them (``"nodal"``); master–slave keeps the masters' values. Fixed
        dofs start at rest. With a constraint, both fields are then projected onto ``G d = 0``,
        ``G v = 0`` in the mass metric. Resets time to 0.
        """
        check_particle_values(particle_values)
        disc = self.evaluator.disc
        for target, fn, mask in (
            (self.u, displacement, self.active),
            (self.v, velocity, self.free),
        ):
            for k in range(len(self.fields)):
                target[k].set(0.0)
                if fn is not None:
                    vals = initial_values(disc, k, fn, particle_values, self.comm)
                    target[k].array[:] = vals * mask[k]
            if fn is not None and self.projection is not None:
                self.projection.correct(target)
        self.stepper.reset()
        if self.bound.state is not None:  # a state-dependent tangent: bound the new state
            self.bound.invalidate()

    def add_traction(
        self, facets: npt.ArrayLike, traction: Traction, amplitude: Amplitude | None = None
    ) -> None:
        """External load ``amplitude(t) * traction(x, n)`` on owned exterior facets: see
        :meth:`ExternalLoads.add_traction
        <dolfinx_meshfree.dynamics.loads.ExternalLoads.add_traction>` (collective)."""
        self.loads.add_traction(facets, traction, amplitude)

    def add_body_force(self, force: VectorFunction, amplitude: Amplitude | None = None) -> None:
        """External load ``amplitude(t) * int b . v`` of a body force ``b(x)`` per unit volume
        on the whole body: see :meth:`ExternalLoads.add_body_force
        <dolfinx_meshfree.dynamics.loads.ExternalLoads.add_body_force>` (collective)."""
        self.loads.add_body_force(force, amplitude)

    def run(
        self,
        t_end: float,
        dt: float | None = None,
        *,
        force: bool = False,
        outputs: Sequence[float] = (),
        energy_records: int = 100,
        on_output: OnOutput | None = None,
        xdmf: str | os.PathLike | None = None,
        progress: bool | None = None,
    ) -> DynamicsResult:
        """Integrate from the current time to ``t_end`` (Belytschko et al. 1995, sec. 5.2;
        Rabczuk et al. 2006, Table I; :mod:`~dolfinx_meshfree.dynamics.central_difference`).
        Collective.

        Args:
            t_end: Final time (> current time).
            dt: Requested time step; default the stable one (:meth:`stable_time_step`). The step
                actually used is ``(t_end - t) / ceil((t_end - t) / dt)`` so that ``t_end`` is
                hit exactly.
            force: Allow ``dt`` above the stable step.
            outputs: Times at which ``on_output(self, step, time)`` is called with the state at
                the nearest step (``velocity_at``/``velocity_error`` then see ``v_n``).
            energy_records: About how many :class:`EnergyRecord` to keep (outputs added).
            on_output: ``on_output(self, step, time)``, called at each output time, e.g. a
                :class:`~dolfinx_meshfree.io.DynamicsWriter`.
            xdmf: An output prefix: write the FE fields, the particle cloud and the energy
                records at every output time through a
                :class:`~dolfinx_meshfree.io.DynamicsWriter` made (and closed) for this run,
                before ``on_output`` is called; without ``outputs``, at the current time and at
                ``t_end``. A second run with the same prefix overwrites the files (pass one
                writer as ``on_output`` to several runs to append instead).
            progress: A progress bar on rank 0's stderr (:class:`~dolfinx_meshfree.io.ProgressBar`):
                ``True`` on, ``False`` off, ``None`` on when stderr is a terminal.

        Raises:
            ValueError: ``dt`` not positive, above the stable step without ``force``, or
                ``t_end`` not after the current time; ``progress`` not a bool or ``None``; an
                unusable ``xdmf`` prefix (on every rank, before any file is written).
        """
        return integrate(self, t_end, dt, force, outputs, energy_records, on_output, xdmf, progress)

    def num_dofs(self) -> dict:
        """Active FE dofs, particle dofs (master–slave: the masters) and multipliers (global)."""
        out = {"fe_dofs": 0, "particle_dofs": 0, "multiplier_dofs": 0}
        for f, act in zip(self.fields, self.active, strict=True):
            key = "fe_dofs" if f.name == "fe" else "particle_dofs"
            out[key] = int(self.comm.allreduce(int(act.sum()), op=MPI.SUM))
        if self.projection is not None:
            out["multiplier_dofs"] = self.projection.num_multipliers
        return out

    def destroy(self) -> None:
        """Destroy the PETSc objects (collective)."""
        self.stepper.destroy()
        self.loads.destroy()
        if self.projection is not None:
            self.projection.destroy()
        for obj in (*self._minv, *(self.reduction or ())):
            obj.destroy()
        self.system.destroy()
