"""Builders of the explicit models of :class:`~dolfinx_meshfree.ExplicitDynamics`: pure FE, pure
EFG and every static coupling, from the same operators as the static solvers.

Each coupling enters dynamics through :meth:`CoupledElasticity.operators
<dolfinx_meshfree.CoupledElasticity.operators>` (Rabczuk et al. 2006, Table I):

* ``lagrange``, ``edge-to-edge``, ``bridging``: the stiffness blocks and the constraint blocks
  ``G_FE``, ``G_P`` of the static system act on the velocities: trial velocities, then the
  multiplier correction of eq. 93–96. The bridging coupling weights both the stiffness and the
  masses with ``beta_FE = 1 - alpha`` and ``beta_P = alpha`` (eq. 46–48, 88–89), and its
  optional penalty enters as stiffness blocks (eq. 72–75, the ``p g^T G`` of eq. 93).
* ``ramp``, ``ramp-cubic``: the interface cells' blended shape functions (Belytschko et al.
  1995, eq. 3.15–3.16) give their stiffness (diagonal and off-diagonal blocks) and their share
  of the row-sum masses (eq. 4.5): no constraint.
* ``hybrid`` (:func:`build_hybrid`): a :class:`~dolfinx_meshfree.couplings.hybrid.HybridElasticity`,
  whose FE integration points join the particle sums (Rabczuk et al. 2006, sec. 5.5): its
  stiffness blocks, FE masses on the FE cells and SPH particle masses; no constraint.
* ``master-slave``: the slave particles follow the FE interface, ``u = T u_M`` (eq. 27): the
  reduced stiffness ``T^T K T`` (PETSc ``PtAP``) and the row sums of ``T^T M T``, i.e. the
  slaves' masses go to their masters; forces by ``T^T`` (eq. 28). The state holds the FE dofs
  and the free particles; evaluation expands the slaves.

Cracks (2D, small strain, ``integration="cells"``): pure EFG takes them as statics does
(:class:`~dolfinx_meshfree.EFGElasticity`: placed, the MLS weights cut, diffraction by default),
and so do the couplings of :data:`~dolfinx_meshfree.CRACK_COUPLINGS` through the patch; the
particle stiffness, the row-sum masses and the body loads all use the cut-cell rule of
:func:`~dolfinx_meshfree.statics.efg.crack_rules` (each side of a crack on its own, Belytschko et
al. 1995, sec. 5.2.2); the faces are traction-free (natural). The ramps and master-slave refuse
a cracked patch when their static problem is built, the hybrid here; stress points and
finite-strain laws with cracks are refused (:func:`check_crack_options`).

Essential conditions (``fixed_facets``: the displacement held at its initial value, in all
components or, with ``(facets, components)`` pairs, in some: symmetry planes): FE dofs
strongly (zero velocity and acceleration), particles by one multiplier per facet and held
component
(:mod:`~dolfinx_meshfree.dynamics.conditions`) added to the velocity constraint, so that
``int_f v^h = 0`` after every correction (Table I, step 6). On ramp interface cells the particle
part of the blended functions is constrained in the same way.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from .. import _compat
from ..approx.body_cuts import separate_bodies
from ..approx.crack_cuts import attach_cracks
from ..approx.fe_points import locate_points
from ..approx.mls import MLS
from ..approx.tables import ShapeTable
from ..couplings.base import material_stiffness_form
from ..couplings.bridging import BridgingBand
from ..couplings.hybrid import HybridElasticity
from ..couplings.hybrid_finite import HybridForces
from ..couplings.master_slave_finite import SlaveCorrection
from ..couplings.ramp import RampInterface
from ..geometry.adaptive_quadrature import AdaptiveQuadrature
from ..geometry.crack import Crack, CrackDomain, place_crack
from ..geometry.particles import ParticleSet
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import DYNAMIC_FACET_DEGREE, cell_sizes
from ..geometry.smoothing import STABILISATION, refuse_smoothed, smoothing_rule, value_rule
from ..geometry.stress_points import check_integration, stress_point_quadrature
from ..parallel import raise_on_all_ranks
from ..physics import axisymmetry
from ..physics.axisymmetry import check_half_plane, check_particle_section
from ..physics.body_loads import CallableBodyForce, body_load_vectors
from ..physics.bulk_viscosity import particle_lengths
from ..physics.constitutive import Material
from ..physics.materials import LinearElastic, is_axisymmetric
from ..statics.coupled import CoupledElasticity, CouplingOperators
from ..statics.efg import crack_rules, particle_stiffness
from ..statics.mean_dilatation import resolve_dilatation, warn_locking
from ..statics.petsc import create_aij
from ..statics.sides import BlendedSide
from .conditions import (
    first_cells,
    fixed_fe_dofs,
    fixed_groups,
    particle_conditions,
    stack_rows,
)
from .finite_strain import (
    NonlinearSystem,
    ReducedParticles,
    bind_rate_law,
    fe_forces,
    particle_forces,
    small_strain,
)
from .loads import BodyLoad
from .masses import (
    fe_lumped_mass,
    fe_spacing,
    particle_lumped_mass,
    particle_spacing,
    table_lumped_mass,
)
from .methods import DYNAMICS_METHODS
from .rate_forms import PointFESide, RateLaws, zone_laws
from .reduction import free_particle_points, reduce_master_slave
from .system import Field

if TYPE_CHECKING:  # annotations only
    from ..geometry.quadrature import QuadraturePoints
    from ..physics.body_loads import VectorFunction

__all__ = [
    "Model",
    "build_coupled",
    "build_efg",
    "build_fe",
    "build_hybrid",
    "check_crack_options",
    "check_particle_mass",
    "fe_cells_dilatation",
]


@dataclass
class Model:
    """An assembled explicit model: the arguments of :class:`~dolfinx_meshfree.ExplicitDynamics`
    beside ``safety`` and ``multiplier_solver`` (see there).

    Attributes:
        fields: One or two :class:`~dolfinx_meshfree.dynamics.system.Field` (FE first).
        material: The material. constraint: The constraint blocks per field, or ``None``.
        blocks: Off-diagonal stiffness blocks. timings: Seconds spent building.
        system: The finite-strain system, or ``None``: the linear one of the blocks.
        V, mls, particles, mesh, in_patch, patch, interface, reduction, body_load: What
            evaluation and loads need.
    """

    fields: list[Field]
    material: LinearElastic
    constraint: list[PETSc.Mat | None] | None = None
    blocks: dict[tuple[int, int], PETSc.Mat] = field(default_factory=dict)
    V: dolfinx.fem.FunctionSpace | None = None
    mls: MLS | None = None
    particles: ParticleSet | None = None
    mesh: dolfinx.mesh.Mesh | None = None
    in_patch: np.ndarray | None = None
    patch: ParticlePatch | None = None
    interface: RampInterface | BridgingBand | None = None
    reduction: tuple[PETSc.Mat, PETSc.Mat] | None = None
    timings: dict = field(default_factory=dict)
    body_load: BodyLoad | None = None
    system: NonlinearSystem | None = None
    #: ``(quadrature, MLS table)`` of the particle masses on the patch cells (a coupled model),
    #: what a conversion fits the new particles on.
    mass_rule: tuple | None = None
    #: The ramps: ``(quadrature, blended table)`` of the interface cells, columns ``[local FE
    #: nodes | particles]`` (:meth:`~dolfinx_meshfree.couplings.ramp.RampInterface.table`).
    blended_rule: tuple | None = None

    def arguments(self) -> dict:
        """The attributes as keyword arguments of ``ExplicitDynamics`` (no copies)."""
        rules = ("mass_rule", "blended_rule")
        return {
            f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in rules
        }


def _check_material(material: LinearElastic) -> None:
    if not isinstance(material, LinearElastic):
        raise TypeError(f"material must be a LinearElastic, got {type(material).__name__}")


def _check_twin(law: Material | LinearElastic, twin: LinearElastic, problem: LinearElastic) -> None:
    """Raise a ``ValueError`` unless ``twin``, the small-strain law of ``law``, is the
    problem's material."""
    if twin != problem:
        raise ValueError(
            f"material={law!r} reduces to {twin!r} at small strain, but the problem's material "
            f"is {problem!r}: build the problem with the linear twin "
            "(dolfinx_meshfree.physics.materials.linear_twin(material))"
        )


def fe_cells_dilatation(
    dilatation: str | None, law: Material | LinearElastic, msh: dolfinx.mesh.Mesh, what: str
) -> bool:
    """Whether the FE cells' rate-form ``law`` runs at their mean dilatation
    (:mod:`~dolfinx_meshfree.dynamics.rate_dilatation`): ``dilatation`` (``None``: automatic,
    ``"mean"``, ``"pointwise"``) checked as the statics check it
    (:func:`~dolfinx_meshfree.statics.mean_dilatation.resolve_dilatation`; a law without state
    refuses ``"mean"``); Johnson–Cook on triangles or tetrahedra warns, a zone of a
    :class:`~dolfinx_meshfree.MaterialZones` law too
    (:class:`~dolfinx_meshfree.VolumetricLockingWarning`). Local, the same on every rank."""
    rate = isinstance(law, RateLaws)
    cell = msh.topology.cell_type.name
    use = resolve_dilatation(dilatation, law if rate else None, cell, what)
    if rate:
        for member in zone_laws(law.law):  # a zoned law: each zone's
            warn_locking(member, cell)
    return use


def _check_rate_twin(law: RateLaws, problem: LinearElastic) -> None:
    """A rate-form law's model takes its masses from the problem's material: the densities and
    planes must agree (its stiffness is not used: the system's tangent is the law's). A zoned
    law (MaterialZones) gives its own densities: the planes must agree."""
    if (not law.zoned and problem.rho != law.rho) or problem.plane != law.plane:
        raise ValueError(
            f"material={type(law.law).__name__} (rho={law.rho}, plane={law.plane!r}) but the "
            f"problem's material has rho={problem.rho}, plane={problem.plane!r}: build the "
            "problem with a LinearElastic of the same density and plane (its stiffness is not "
            "used at finite strain)"
        )


def check_particle_mass(particle_mass: str, default: str = "row-sum") -> str:
    """Return ``particle_mass`` if known, else raise a ``ValueError`` naming the choices."""
    if particle_mass not in ("row-sum", "volume"):
        if default == "volume":
            raise ValueError(
                f"particle_mass={particle_mass!r} is not known; use 'volume' (rho V_I) or 'row-sum'"
            )
        raise ValueError(f"particle_mass={particle_mass!r} is not known; use 'row-sum' or 'volume'")
    return particle_mass


def _check_integration(integration: str, gdim: int) -> None:
    """Refuse an unknown ``integration`` and stress points in 3D (the same on every rank: the
    dimension is global)."""
    check_integration(integration)
    if integration == "stress-points" and gdim != 2:
        raise ValueError(
            f"integration='stress-points' works on 2D meshes only, this mesh has gdim={gdim}: "
            "the stress points and their volumes are built in the plane (the vertices of the "
            "particles' Voronoi diagram, sampled Voronoi areas; "
            "dolfinx_meshfree.geometry.stress_points); in 3D use integration='cells'"
        )


def check_crack_options(
    cracked: bool, integration: str, finite_strain: bool, comm: MPI.Comm
) -> None:
    """Refuse, on every rank, what a cracked particle model cannot carry in explicit dynamics:
    stress points (a cracked body is integrated on its cut cells,
    :func:`~dolfinx_meshfree.statics.efg.crack_rules`) and a finite-strain law (not verified
    with cut cells)."""

    def check() -> None:
        if not cracked:
            return
        if integration != "cells":
            raise ValueError(
                f"integration={integration!r}: a cracked particle model is integrated on its cut "
                "cells in explicit dynamics; use integration='cells'"
            )
        if finite_strain:
            raise ValueError(
                "a finite-strain material with cracks is not available in explicit dynamics "
                "(the cut-cell rule is verified at small strain only); use the linear law "
                "(dolfinx_meshfree.physics.materials.linear_twin(material)) or no cracks"
            )

    raise_on_all_ranks(comm, check)


def check_quadrature_option(
    quadrature: AdaptiveQuadrature | None, integration: str, comm: MPI.Comm
) -> None:
    """Refuse, on every rank, a ``quadrature`` that is not an
    :class:`~dolfinx_meshfree.AdaptiveQuadrature` or one combined with stress points."""

    def check() -> None:
        if quadrature is None:
            return
        if not isinstance(quadrature, AdaptiveQuadrature):
            raise ValueError(
                f"quadrature={quadrature!r}: give an AdaptiveQuadrature(radius=..., near=..., "
                "far=...) or None (the uniform rule of quadrature_degree)"
            )
        if integration != "cells":
            raise ValueError(
                f"quadrature=AdaptiveQuadrature(...) with integration={integration!r}: the "
                "adaptive rule is a cell rule; use integration='cells'"
            )

    raise_on_all_ranks(comm, check)


# -- pure FE, pure EFG -------------------------------------------------------------------------


def _fe_density(
    law: object, material: LinearElastic, V: dolfinx.fem.FunctionSpace
) -> float | dolfinx.fem.Function:
    """The FE masses' density: the material's, or the zones' DG0 field (MaterialZones)."""
    if isinstance(law, RateLaws):
        return law.fe_density(V)
    return float(material.rho)


def _particle_density(
    law: object, material: LinearElastic, kind: str, q: QuadraturePoints, particles: ParticleSet
) -> float | np.ndarray:
    """The particle masses' density: the material's, or (MaterialZones) per point of the rule
    ``q`` by its cell (``"row-sum"``) or per particle by its position (``"volume"``)."""
    if not (isinstance(law, RateLaws) and law.zoned):
        return float(material.rho)
    if kind == "volume":
        return raise_on_all_ranks(particles.comm, lambda: law.density_at(particles.positions))
    cells = np.asarray(q.cells, dtype=np.int64)
    if np.any(cells < 0):  # a rule of particles (the hybrid's "particles"): their owned cells
        cells = locate_points(particles.mesh, q.points)
    return law.density_at_cells(cells)


def _check_axisymmetric_efg(
    particles: ParticleSet,
    integration: str,
    cracks: Sequence[Crack],
    quadrature: AdaptiveQuadrature | None,
    particle_mass: str,
) -> None:
    """Refuse what axisymmetric explicit EFG does not revolve (local)."""
    if integration != "cells" or cracks or quadrature is not None or particle_mass != "row-sum":
        raise ValueError(
            f"material plane='axisymmetric' with integration={integration!r}, "
            f"{len(cracks)} crack(s), quadrature={quadrature!r}, particle_mass="
            f"{particle_mass!r}: axisymmetric explicit EFG takes integration='cells' and "
            "particle_mass='row-sum' (the defaults), without cracks or an adaptive quadrature "
            "(the other options are plane; a row-sum mass that is not positive, a particle on "
            "the axis near a corner, is cured by a larger dilation)"
        )
    check_particle_section(particles)


def _check_axisymmetric_masses(particles: ParticleSet, mass: PETSc.Vec) -> None:
    """Refuse a row-sum mass that is not positive, naming the particle (collective)."""
    comm, gdim = particles.comm, particles.gdim
    local = mass.array_r[::gdim]
    i = int(np.argmin(local)) if local.size else -1
    lo = float(local[i]) if local.size else np.inf
    lo_all = comm.allreduce(lo, op=MPI.MIN)
    if lo_all > 0.0:
        return
    lo_rank = comm.allreduce((lo, comm.rank), op=MPI.MINLOC)[1]
    where = particles.owned_positions()[i] if comm.rank == lo_rank else None
    where = comm.bcast(where, root=lo_rank)
    raise ValueError(
        f"a lumped particle mass is not positive ({lo_all:.3e}, the particle at "
        f"{np.round(where, 12).tolist()}): in an axisymmetric model the row sum weighs a "
        "shape function by 2 pi r, so a particle near the axis, whose negative lobes lie "
        "farther out than its centre, can weigh less than nothing; raise the dilation (e.g. "
        "2.5)"
    )


def build_fe(
    V: dolfinx.fem.FunctionSpace,
    material: LinearElastic | Material,
    fixed_facets: npt.ArrayLike | None = None,
    dilatation: str | None = None,
) -> Model:
    """Pure FE: DOLFINx's stiffness ``inner(sigma(u), eps(v)) dx``, row-sum masses, fixed
    facets' nodes held strongly; at finite strain the assembled ``int P(F) : grad v dX``
    (:class:`~dolfinx_meshfree.dynamics.finite_strain.NonlinearSystem`); a rate-form law at the
    cells' mean dilatation by :func:`fe_cells_dilatation`'s ``dilatation``. Collective."""
    material = bind_rate_law(material, "fe", V.mesh)
    mean = fe_cells_dilatation(dilatation, material, V.mesh, "ExplicitDynamics.fe: dilatation")
    law, material = material, small_strain(material, "fe")
    t0 = time.perf_counter()
    msh = V.mesh
    raise_on_all_ranks(msh.comm, lambda: material.check_gdim(msh.geometry.dim, "V's mesh"))
    groups = fixed_groups(msh, fixed_facets)
    weight = None  # 2 pi r in axisymmetry, for the masses and the body loads
    if is_axisymmetric(material):
        raise_on_all_ranks(msh.comm, lambda: check_half_plane(msh.geometry.x, "V's mesh"))
        weight = axisymmetry.measure(msh)
    a = material_stiffness_form(material, V, 1.0)  # axisymmetric: the hoop strain and 2 pi r
    K = _compat.assemble_matrix(_compat.create_form(a))
    mass = fe_lumped_mass(V, _fe_density(law, material, V), weight=weight)
    n_owned = msh.topology.index_map(msh.topology.dim).size_local
    h = fe_spacing(msh, np.arange(n_owned))
    fe_field = Field("fe", K, mass, h, fixed=fixed_fe_dofs(V, groups))

    def body_load(
        force: VectorFunction,
    ) -> tuple[
        np.ndarray | None, np.ndarray | None
    ]:  # int N_a b, Gauss degree 4 (as the tractions)
        return body_load_vectors([CallableBodyForce(force)], V, weight, 4)

    system = None
    if law is not material:
        if isinstance(law, RateLaws):
            side = PointFESide(V, law.bind(), dilatation=mean)
        else:
            side = fe_forces(V, law)
        system = NonlinearSystem([fe_field], [side], law)
    return Model(
        [fe_field],
        law,
        V=V,
        mesh=msh,
        timings={"setup": time.perf_counter() - t0},
        body_load=body_load,
        system=system,
    )


def build_efg(
    particles: ParticleSet,
    material: LinearElastic | Material,
    weight: str = "quartic",
    dilation: float = 2.0,
    basis: str = "linear",
    quadrature_degree: int = 7,
    particle_mass: str = "row-sum",
    fixed_facets: npt.ArrayLike | None = None,
    integration: str = "cells",
    cracks: Sequence[Crack] = (),
    crack_method: str = "diffraction",
    quadrature: AdaptiveQuadrature | None = None,
) -> Model:
    """Pure EFG on the particles' background cells (Belytschko et al. 1995, sec. 5.2):
    :func:`~dolfinx_meshfree.statics.efg.particle_stiffness` and row-sum masses. Collective.

    Args:
        particles, weight, dilation, basis: The particles and their MLS approximation.
        quadrature_degree: The Gauss rule on the background cells.
        particle_mass: ``"row-sum"`` (eq. 4.5) or ``"volume"`` (``rho V_I``).
        fixed_facets: Owned exterior facets held at rest, by facet multipliers on the
            velocities (one per facet and component, corrected each step like eq. 94–96).
        integration: ``"cells"`` (the Gauss rule of ``quadrature_degree``), ``"smoothed"``
            (strains smoothed over each cell, stabilised by the Gauss points' strains:
            symmetric and consistent, so that the linear patch test is exact in dynamics too,
            :func:`~dolfinx_meshfree.geometry.smoothing.smoothing_rule`; masses and body loads
            on the Gauss rule; small strain, no cracks) or ``"stress-points"``: the particles
            and the stress points between them, with their volumes and MLS functions of the
            reference configuration (Lagrangian kernel, computed once at t = 0; Rabczuk,
            Belytschko & Xiao 2004;
            :mod:`~dolfinx_meshfree.geometry.stress_points`); the row-sum masses are then
            ``rho sum_q phi_I(x_q) V_q``.
        cracks: 2D :class:`~dolfinx_meshfree.Crack` polylines in the particles' cells, as in
            statics (:class:`~dolfinx_meshfree.EFGElasticity`): the MLS weights cut by them
            (``crack_method``: ``"diffraction"``, the default, or ``"visibility"``; Organ,
            Fleming & Belytschko 1996), the cut cells integrated side by side
            (:func:`~dolfinx_meshfree.statics.efg.crack_rules`: Belytschko et al. 1995, sec.
            5.2.2) for the stiffness, the lumped masses and the body loads alike; the crack
            faces are traction-free (natural). Small strain and ``integration="cells"`` only.
        quadrature: An :class:`~dolfinx_meshfree.AdaptiveQuadrature`: the cells within its
            radius of a crack tip integrated with its ``near`` degree, the others with ``far``
            (Belytschko et al. 1995, sec. 5.2.2), for the stiffness, masses and body loads;
            computed from ``cracks``, so a model rebuilt after an extension moves the zone with
            the tip. ``None`` (default): the uniform rule of ``quadrature_degree``.

    A finite-strain ``material`` gives the internal force of
    :class:`~dolfinx_meshfree.InternalForces` on the same rule and table.
    """
    if particles.mesh is None:
        raise ValueError("explicit EFG needs particles with a background mesh (mesh=...)")
    material = bind_rate_law(material, "efg", particles.mesh)
    law, material = material, small_strain(material, "efg")
    _check_integration(integration, particles.gdim)
    cracks = list(cracks)
    check_crack_options(bool(cracks), integration, law is not material, particles.comm)
    check_quadrature_option(quadrature, integration, particles.comm)
    gdim = particles.gdim
    raise_on_all_ranks(particles.comm, lambda: material.check_gdim(gdim, "the particles' mesh"))
    check_particle_mass(particle_mass)
    if is_axisymmetric(material):
        raise_on_all_ranks(
            particles.comm,
            lambda: _check_axisymmetric_efg(particles, integration, cracks, quadrature,
                                            particle_mass),
        )  # fmt: skip
    t0 = time.perf_counter()
    comm = particles.comm
    groups = fixed_groups(particles.mesh, fixed_facets)
    if is_axisymmetric(material):
        axisymmetry.check_axis_held(particles.mesh, groups, None, "ExplicitDynamics.efg")
    mls = raise_on_all_ranks(
        comm, lambda: MLS(particles, weight=weight, dilation=dilation, basis=basis)
    )
    separate_bodies(mls, particles.mesh)
    refuse_smoothed(integration, nonlinear=law is not material, fix="integration='cells'")
    rule = None
    if integration == "stress-points":
        rule = stress_point_quadrature(particles)
    elif integration == "smoothed":
        msh, cells = particles.mesh, particles.integration_cells()
        beta = STABILISATION["smoothed"]
        rule = raise_on_all_ranks(
            comm, lambda: smoothing_rule(msh, cells, quadrature_degree, beta, DYNAMIC_FACET_DEGREE)
        )
    if cracks or quadrature is not None:  # as EFGElasticity: placed, MLS cut, cut cells
        domain = CrackDomain.from_particles(particles)  # integrated side by side
        for crack in cracks:
            place_crack(crack, domain)
        if cracks:
            raise_on_all_ranks(
                comm, lambda: attach_cracks(mls, cracks, crack_method, domain=domain)
            )
        rule = crack_rules(
            particles.mesh, domain.cells, cracks, quadrature_degree, None, quadrature=quadrature
        )[0]
    tables: dict = {}
    K_loc, q, tq, _ = particle_stiffness(
        particles, mls, material, quadrature_degree, quadrature=rule, tables=tables
    )
    pl = particles.dof_layout(particles.gdim)
    K = create_aij(comm, K_loc, pl, pl)
    q, values = raise_on_all_ranks(comm, lambda: value_rule(mls, q, tq))  # masses, loads
    rho = _particle_density(law, material, particle_mass, q, particles)
    axi = is_axisymmetric(material)
    mass = particle_lumped_mass(particles, values, q.weights, rho, particle_mass, check=not axi)
    if axi:
        _check_axisymmetric_masses(particles, mass)
    constraint = None
    if groups and comm.allreduce(sum(f.size for f, _ in groups)):
        D, dl = particle_conditions(
            particles,
            [f for f, _ in groups],
            [lambda q: mls.tabulate(q.points, 0)] * len(groups),
            [c for _, c in groups],
        )
        constraint = [create_aij(comm, D, dl, pl)]

    def body_load(
        force: VectorFunction,
    ) -> tuple[
        np.ndarray | None, np.ndarray | None
    ]:  # int phi_J b on the particle rule (cells or stress points)
        forces = [CallableBodyForce(force)]
        return body_load_vectors(forces, None, None, quadrature_degree, (q, values), comm=comm)

    fields = [Field("particles", K, mass, particle_spacing(particles), block_size=particles.gdim)]
    system = None
    if law is not material:
        side_law = law
        if isinstance(law, RateLaws):
            side_law = law.bind()
            rule = tables["quadrature"]
            lengths = particle_lengths(particles.positions, rule.points)
            side_law.attach(rule.points, rule.cells, lengths)
        side = particle_forces(particles, tables, side_law)
        system = NonlinearSystem(fields, [side], law, constraint)
    return Model(
        fields,
        law,
        constraint,
        mls=mls,
        particles=particles,
        mesh=particles.mesh,
        timings={"setup": time.perf_counter() - t0},
        body_load=body_load,
        system=system,
    )


# -- couplings ---------------------------------------------------------------------------------


def _add_interface_masses(
    ops: CouplingOperators,
    V: dolfinx.fem.FunctionSpace,
    P: ParticleSet,
    rho: float | np.ndarray,
    mass_fe: PETSc.Vec,
    mass_p: PETSc.Vec,
    comm: MPI.Comm,
) -> None:
    """Add the ramp's interface cells' share of the row-sum masses (eq. 4.5 with the blended
    functions, Belytschko et al. 1995, eq. 3.15) and check the particle masses positive
    (collective). ``rho``: a number, or per interface quadrature point (zones)."""
    imap = V.dofmap.index_map
    l2g = np.asarray(
        imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    )
    gdim = P.gdim
    fe_dofs = gdim * l2g[:, None] + np.arange(gdim)
    m_fe, m_p = table_lumped_mass(
        ops.interface_table,
        ops.interface_quadrature.weights,
        rho,
        fe_dofs,
        ops.fe_layout,
        P.petsc_dofs(gdim),
        ops.particle_layout,
        comm,
    )
    mass_fe.axpy(1.0, m_fe)
    mass_p.axpy(1.0, m_p)
    m_fe.destroy()
    m_p.destroy()
    lo = comm.allreduce(
        float(mass_p.array_r.min()) if mass_p.getLocalSize() else np.inf, op=MPI.MIN
    )
    if not lo > 0.0:
        raise ValueError(
            f"a lumped particle mass is not positive (min {lo:.3e}); raise quadrature_degree "
            "or the dilation"
        )


def build_coupled(
    problem: CoupledElasticity | HybridElasticity,
    particle_mass: str = "row-sum",
    fixed_facets: npt.ArrayLike | None = None,
    integration: str = "cells",
    slaves: str | None = None,
    material: Material | None = None,
    fe_dilatation: str | None = None,
) -> Model:
    """Explicit dynamics of a :class:`~dolfinx_meshfree.CoupledElasticity` (any coupling),
    from :meth:`~dolfinx_meshfree.CoupledElasticity.operators` (collective).

    Args:
        problem: The static coupling object (its MLS, quadrature degree, band, options).
        particle_mass: ``"row-sum"`` (eq. 4.5; bridging: weighted by ``alpha``, eq. 89) or
            ``"volume"`` (``rho V_I``; not with bridging or the ramp couplings, whose masses
            follow their weighted/blended functions). Row sums are taken on the particle rule
            in use (cells or stress points).
        fixed_facets: Owned exterior facets held at rest (FE nodes strongly, particles by facet
            multipliers on the velocities). The static problem's own Dirichlet conditions,
            tractions and body force are not used
            (:class:`~dolfinx_meshfree.dynamics.static_model.StaticModelWarning` says so).
        integration: ``"cells"`` or ``"stress-points"`` (Rabczuk, Belytschko & Xiao 2004;
            lagrange, edge-to-edge and master-slave), see :meth:`CoupledElasticity.operators
            <dolfinx_meshfree.CoupledElasticity.operators>`.
        slaves: master-slave: ``None`` (the static model's ``slaves``: ``"layer"`` unless it
            was set to ``"first-layer"``), ``"layer"``, ``"first-layer"`` or ``"coincident"``
            (Johnson's particles on the interface nodes, Rabczuk et al. 2006, eq. 15–16: the
            node and its particle share the acceleration ``(F_K + F_P) / (m_K + m_P)``, which
            the reduction ``T^T M T``, ``T^T f`` below gives).
        material: A finite-strain law (:class:`~dolfinx_meshfree.NeoHookean`,
            :class:`~dolfinx_meshfree.SaintVenantKirchhoff`) whose linear twin is the problem's
            material: the internal force is then the total-Lagrangian one of both sides
            (:class:`~dolfinx_meshfree.dynamics.finite_strain.NonlinearSystem`; every coupling
            of :data:`~dolfinx_meshfree.dynamics.finite_strain.FINITE_STRAIN_DYNAMICS`: the
            ramps' interface cells blended, master-slave's links rotating, the bridging
            penalty linear). ``None``: the law the problem was built with
            (``CoupledElasticity(V, patch, NeoHookean(...))`` runs finite-strain dynamics);
            ``material=problem.material`` (its linear twin) asks for small-strain dynamics.
        fe_dilatation: A rate-form law's FE cells: ``None`` (the problem's ``fe_dilatation``,
            automatic by default: the cells' mean dilatation on quadrilaterals and hexahedra
            outside plane stress), ``"mean"`` or ``"pointwise"`` (:func:`fe_cells_dilatation`).
    """
    if fe_dilatation is None:  # the static problem's choice
        fe_dilatation = getattr(problem, "fe_dilatation", None)
    if slaves is None:  # the static model's choice (the hybrid has none: its own sums)
        slaves = getattr(problem, "slaves", "layer")
    if isinstance(problem, HybridElasticity):  # the hybrid SPH-FE coupling: its own builder
        if (integration, slaves) != ("cells", "layer"):
            raise ValueError(
                f"integration={integration!r}, slaves={slaves!r}: the hybrid coupling has its "
                "own SPH sums; use integration='cells', slaves='layer'"
            )
        return build_hybrid(problem, particle_mass, fixed_facets, material, fe_dilatation)
    if not isinstance(problem, CoupledElasticity):
        raise TypeError(f"problem must be a CoupledElasticity, got {type(problem).__name__}")
    coupling = problem.coupling
    if coupling not in DYNAMICS_METHODS:
        raise ValueError(
            f"coupling={coupling!r} is not available in explicit dynamics; available: "
            f"{list(DYNAMICS_METHODS)}"
        )
    check_particle_mass(particle_mass)
    _check_integration(integration, problem.V.mesh.geometry.dim)
    if particle_mass == "volume" and coupling in ("bridging", "ramp", "ramp-cubic"):
        raise ValueError(
            f"particle_mass='volume' is not available with coupling={coupling!r}: its particle "
            "masses follow the weighted/blended shape functions; use particle_mass='row-sum'"
        )
    # the law the model was built with, unless the caller names another (issue 23, item 2)
    law = getattr(problem, "law", problem.material) if material is None else material
    law = bind_rate_law(law, coupling, problem.V.mesh)
    mean = fe_cells_dilatation(
        fe_dilatation, law, problem.V.mesh, "ExplicitDynamics.coupled: fe_dilatation"
    )
    material = small_strain(law, coupling)
    if isinstance(law, RateLaws):
        _check_rate_twin(law, problem.material)
    else:
        _check_twin(law, material, problem.material)
    check_crack_options(
        bool(problem.patch.cracks), integration, law is not material, problem.patch.comm
    )
    refuse_smoothed(  # the same on every rank
        getattr(problem, "integration", "vci"),
        nonlinear=law is not material,
        fix="a problem built with integration='vci'",
    )
    t0 = time.perf_counter()
    V, patch, mls = problem.V, problem.patch, problem.mls
    P, comm, msh = patch.particles, patch.comm, V.mesh
    held = fixed_groups(msh, fixed_facets)
    if is_axisymmetric(material):
        axisymmetry.check_axis_held(msh, held, patch.in_patch, "ExplicitDynamics.coupled")
    if is_axisymmetric(material) and particle_mass != "row-sum":  # the same on every rank
        raise ValueError(
            f"particle_mass={particle_mass!r}: an axisymmetric model takes particle_mass="
            "'row-sum' (the particles' Voronoi volumes are not revolved)"
        )
    ops = problem.operators(integration, slaves)
    fl, pl = ops.fe_layout, ops.particle_layout
    fe_weight = ops.fe_weight  # the FE energy's weight; axisymmetric: times 2 pi r
    if is_axisymmetric(material):
        fe_weight = fe_weight * axisymmetry.measure(msh)

    # lumped masses (eq. 4.5, 88-89)
    mass_fe = fe_lumped_mass(V, _fe_density(law, material, V), weight=fe_weight)
    pq = ops.particle_quadrature
    rho_p = _particle_density(law, material, particle_mass, pq, P)
    mass_p = particle_lumped_mass(
        P, ops.particle_table, pq.weights, rho_p, particle_mass, check=ops.interface_table is None
    )
    if ops.interface_table is not None:  # ramp: the interface cells' share, same functions
        iq = ops.interface_quadrature
        rho_i = _particle_density(law, material, "row-sum", iq, P)  # per point by its cell
        _add_interface_masses(ops, V, P, rho_i, mass_fe, mass_p, comm)
    n_owned = V.dofmap.index_map.size_local
    active = np.repeat(ops.fe_active[:n_owned], msh.geometry.dim)
    mass_fe.array[:] = mass_fe.array_r * active  # inactive FE dofs: no mass, held at rest

    # essential conditions: FE nodes strongly, particles by facet multipliers
    fixed_fe = fixed_fe_dofs(V, held)
    D = dl = None
    if held and comm.allreduce(sum(f.size for f, _ in held)):
        groups, tables, comps = [], [], []
        blend = ops.interface if ops.interface_table is not None else None
        for facets, c in held:
            on_p = patch.in_patch[first_cells(msh, facets)]
            groups.append(facets[on_p])
            tables.append(lambda q: mls.tabulate(q.points, 0))
            comps.append(c)
            if blend is not None:  # the particle part of the ramp's interface cells
                n_loc = blend.num_fe_columns
                groups.append(blend.blended_facets(facets[~on_p]))
                tables.append(
                    lambda q, n_loc=n_loc: ShapeTable(
                        q.points, blend.table(q.points, q.cells, 0).values[:, n_loc:].tocsr(), []
                    )
                )
                comps.append(c)
        D_loc, dl = particle_conditions(P, groups, tables, comps)
        if dl.size_global:
            D = create_aij(comm, D_loc, dl, pl)

    # fields, blocks, constraints
    blocks: dict = {}
    G_fe, G_p = ops.G_fe, ops.G_p
    if ops.reduction is None:
        K_fe, K_p = ops.K_fe, ops.K_p
        if ops.K_fp is not None:
            blocks = {(0, 1): ops.K_fp, (1, 0): ops.K_pf}
        if D is not None:
            if G_p is None:
                G_fe, G_p = None, D
            else:
                ml = ops.multiplier_layout
                G_fe2, _ = stack_rows(comm, [G_fe, None], [ml, dl], fl)
                G_p2, _ = stack_rows(comm, [G_p, D], [ml, dl], pl)
                for m in (G_fe, G_p, D):
                    m.destroy()
                G_fe, G_p = G_fe2, G_p2
        particle_points = None
    else:  # master-slave: reduce by T = [[I, 0], [T_PF, S]] (eq. 27-28)
        red = reduce_master_slave(ops.K_fe, ops.K_p, ops.reduction, mass_fe, mass_p, active, D)
        K_fe, K_p, blocks = red.K_fe, red.K_m, red.blocks
        mass_fe, mass_p = red.mass_fe, red.mass_m
        if D is not None:
            G_fe, G_p = red.G_fe, red.G_m
        particle_points = free_particle_points(P, ops.interface.slaves)
    fe_cells = patch.fe_cells
    if coupling == "bridging":
        fe_cells = np.concatenate([fe_cells, ops.interface.cells])
    fields = [
        Field("fe", K_fe, mass_fe, fe_spacing(msh, fe_cells), fixed=fixed_fe, block_size=P.gdim),
        Field(
            "particles", K_p, mass_p, particle_spacing(P), points=particle_points, block_size=P.gdim
        ),
    ]
    constraint = None if G_p is None and G_fe is None else [G_fe, G_p]
    # body forces with the functions and weights of the masses: FE weight, particle rule
    # (bridging: times alpha), ramp interface cells blended; master-slave reduced by T^T
    p_rule = (pq, ops.particle_table)
    i_rule = None
    if ops.interface_table is not None:
        i_rule = (ops.interface_quadrature, ops.interface_table)

    def body_load(force: VectorFunction) -> tuple[np.ndarray | None, np.ndarray | None]:
        forces = [CallableBodyForce(force)]
        deg = problem.quadrature_degree
        return body_load_vectors(forces, V, fe_weight, deg, p_rule, i_rule, comm)

    system = None
    if law is not material:
        system = _finite_strain_system(problem, ops, law, fields, constraint, blocks, mean)
        blocks = {}
    else:
        for B in ops.penalty_blocks or ():  # already in K_fe, K_p
            B.destroy()
    return Model(
        fields,
        law,
        constraint,
        blocks=blocks,
        V=V,
        mls=mls,
        particles=P,
        mesh=msh,
        in_patch=patch.in_patch,
        patch=patch,
        interface=ops.interface if ops.reduction is None else None,
        reduction=ops.reduction,
        timings={"setup": time.perf_counter() - t0, "operators": ops.timings["operators"]},
        body_load=body_load,
        system=system,
        mass_rule=p_rule if np.ndim(rho_p) == 0 else _density_weighted(p_rule, rho_p),
        blended_rule=i_rule,
    )


def _density_weighted(rule: tuple, rho: np.ndarray) -> tuple:
    """``(quadrature, table)`` with the weights times the points' densities: a conversion's
    projection in the mass metric of zones of several densities (MaterialZones)."""
    q, table = rule
    return dataclasses.replace(q, weights=q.weights * rho), table


def _finite_strain_system(
    problem: CoupledElasticity,
    ops: CouplingOperators,
    law: Material,
    fields: list[Field],
    constraint: list[PETSc.Mat | None] | None,
    blocks: dict[tuple[int, int], PETSc.Mat],
    mean: bool = False,
) -> NonlinearSystem:
    """The finite-strain system of a coupling from its operators: the FE law on the cells
    whose energy is FE (weighted by ``beta_FE`` in the bridging band, eq. 47–48; not the ramps'
    interface cells) and the particle tables of ``K_P`` (bridging: weights times ``alpha``,
    eq. 46); the ramps' interface cells on their blended table (Belytschko et al. 1995,
    eq. 3.15–3.16, :class:`~dolfinx_meshfree.statics.sides.BlendedSide`); master–slave's
    particles through the reduction (eq. 27–28, :class:`ReducedParticles`, finite-rotation
    links); the bridging penalty (eq. 72–75, linear in the displacements) as constant blocks.
    The linear model's off-diagonal ``blocks`` are taken over (the penalty's) or destroyed.
    ``mean``: a rate-form law's FE cells at their mean dilatation. Collective.
    """
    constant: dict = {}
    if ops.penalty_blocks is not None:  # the bridging penalty: its four blocks stay linear
        constant = {(0, 0): ops.penalty_blocks[0], (1, 1): ops.penalty_blocks[1], **blocks}
    else:
        for B in blocks.values():  # the ramps' or master-slave's linear blocks: not used
            B.destroy()
    V, patch = problem.V, problem.patch
    cells, weight, weight_at = ~patch.in_patch, None, None
    if ops.interface_table is not None:  # ramps: the interface cells are blended
        cells = cells & ~ops.interface.in_interface
    if problem.coupling == "bridging":
        band = ops.interface
        cells, weight = cells | band.in_band, ops.fe_weight

        def weight_at(
            q: QuadraturePoints,
        ) -> np.ndarray:  # beta_FE = 1 - alpha in the band, 1 on the FE cells
            w = np.ones(len(q))
            b = band.in_band[q.cells]
            w[b] = 1.0 - band.alpha_at(q.points[b], q.cells[b])
            return w

    rate = isinstance(law, RateLaws)
    if rate:  # each side its own points' state (module rate_forms)
        fe = fe_side = PointFESide(V, law.bind(), cells, weight_at, dilatation=mean)
        particle_law, q = law.bind(), ops.particle_tables["quadrature"]
        lengths = particle_lengths(patch.particles.positions, q.points)
        particle_law.attach(q.points, q.cells, lengths)
    else:
        fe = fe_forces(V, law, cells, weight=weight, weight_at=weight_at)
        fe_side, particle_law = fe.side, law
    particles = particle_forces(patch.particles, ops.particle_tables, particle_law)
    sides: list = [fe, particles]
    shared: list = []
    if ops.interface_table is not None:  # the ramps' interface cells on their blended table
        q, blend = ops.interface_quadrature, ops.interface
        table = raise_on_all_ranks(patch.comm, lambda: blend.table(q.points, q.cells))
        blend_law = law.bind() if rate else law  # a rate law: their own points' state
        if rate:
            blend_law.attach(q.points, q.cells, cell_sizes(problem.V.mesh, q.cells))
        shared = [BlendedSide(fe_side, particles, table, q.weights, blend_law)]
    elif ops.reduction is not None:  # master-slave: the particles through the reduction
        reduced = ReducedParticles(particles, ops.reduction, _links(problem, ops))
        shared, sides = [reduced], [fe, None]
    return NonlinearSystem(fields, sides, law, constraint, shared, constant)


def _links(problem: CoupledElasticity, ops: object) -> SlaveCorrection | None:
    """Master–slave's finite-rotation part of its links, ``None`` for links of length zero
    (``u_P = T u`` exactly)."""
    correction = SlaveCorrection(problem, ops.interface, ops.fe_layout, ops.particle_layout)
    return correction if correction.length > 0.0 else None


# -- hybrid SPH-FE ---------------------------------------------------------------------------------


def build_hybrid(
    problem: HybridElasticity,
    particle_mass: str = "volume",
    fixed_facets: npt.ArrayLike | None = None,
    material: Material | None = None,
    fe_dilatation: str | None = None,
) -> Model:
    """Explicit dynamics of a :class:`~dolfinx_meshfree.couplings.hybrid.HybridElasticity` (Rabczuk
    et al.
    2006, sec. 5.5, with central differences as there), from its assembled operators
    (collective).

    The internal force is ``K u`` with the blocks of
    :meth:`~dolfinx_meshfree.couplings.hybrid.HybridElasticity.operators` (FE cells and the FE rows
    of
    HA-S tractions or HA-F interpolation; particle rows of the particle energy with the FE
    integration points in the sums). No constraint joins the two fields. Central differences
    conserve the discrete energy when ``K`` is symmetric: HA-F with its default smoothed strains
    (also integration-consistent: no reflection at the interface) or with Gauss points and
    ``consistent=False``; HA-S and the consistent Gauss integration give an unsymmetric ``K``.

    Args:
        problem: The static hybrid object.
        particle_mass: ``"volume"`` (``rho V_I``, the SPH mass) or ``"row-sum"``
            (``rho sum_q N_I(x_q) w_q`` with the particles' interpolant at the stress points).
        fixed_facets: Owned exterior facets held at rest (FE nodes strongly, particles by facet
            multipliers on the velocities).
        material: A finite-strain law whose linear twin is the problem's material (HA-F): the
            FE cells' ``int P(F) : grad v dX`` and the SPH sums of ``P`` on the particle
            energy's rule (:class:`~dolfinx_meshfree.couplings.hybrid_finite.HybridForces`);
            ``None``: the problem's material.
        fe_dilatation: A rate-form law's FE cells (:func:`fe_cells_dilatation`).
    """
    if not isinstance(problem, HybridElasticity):
        raise TypeError(f"problem must be a HybridElasticity, got {type(problem).__name__}")
    if problem.patch.cracks:  # the same on every rank: the cracks are global
        raise ValueError(
            "the hybrid coupling cannot carry a cracked patch in explicit dynamics (its SPH "
            "particle sums are not cut by the crack); use a coupling of "
            "dolfinx_meshfree.CRACK_COUPLINGS or pure EFG (ExplicitDynamics.efg(..., cracks=...))"
        )
    check_particle_mass(particle_mass, default="volume")
    law = problem.material if material is None else material
    law = bind_rate_law(law, "hybrid", problem.V.mesh)
    mean = fe_cells_dilatation(
        fe_dilatation, law, problem.V.mesh, "ExplicitDynamics.coupled: fe_dilatation"
    )
    material = small_strain(law, "hybrid")
    if law is not material:
        if isinstance(law, RateLaws):
            _check_rate_twin(law, problem.material)
        else:
            _check_twin(law, material, problem.material)
        if problem.variant != "HA-F":
            raise ValueError(
                f"variant={problem.variant!r}: the hybrid coupling at finite strain is HA-F (the "
                "forces reach the FE nodes by interpolation, eq. 135); HA-S's interface "
                "tractions of the particle stresses (eq. 131-134) are not written for the "
                "nominal stress: use variant='HA-F'"
            )
    _check_material(material)
    t0 = time.perf_counter()
    V, patch = problem.V, problem.patch
    P, comm, msh = patch.particles, patch.comm, V.mesh
    held = fixed_groups(msh, fixed_facets)  # (facets, components): rollers too
    if is_axisymmetric(material):
        axisymmetry.check_axis_held(msh, held, patch.in_patch, "ExplicitDynamics.coupled")
    ops = problem.operators()
    fe_weight = ops.fe_weight  # axisymmetric: times 2 pi r (the stress points are revolved)
    if is_axisymmetric(material):
        fe_weight = fe_weight * axisymmetry.measure(msh)
    mass_fe = fe_lumped_mass(V, _fe_density(law, material, V), weight=fe_weight)
    pq = ops.particle_quadrature
    rho_p = _particle_density(law, material, particle_mass, pq, P)
    mass_p = particle_lumped_mass(
        P, ops.particle_table, pq.weights, rho_p, particle_mass, revolve=is_axisymmetric(material)
    )  # the row-sum's weights are revolved already (the stress points)
    n_owned = V.dofmap.index_map.size_local
    active = np.repeat(ops.fe_active[:n_owned], msh.geometry.dim)
    mass_fe.array[:] = mass_fe.array_r * active
    fixed_fe = fixed_fe_dofs(V, held)
    on_p = [patch.in_patch[first_cells(msh, facets)] for facets, _ in held]
    constraint = None
    if comm.allreduce(int(sum(np.sum(p) for p in on_p))):
        ev = problem.evaluator
        groups = [facets[p] for (facets, _), p in zip(held, on_p, strict=True)]
        tables = [lambda q: ev.tabulate(q.points, 0)] * len(groups)
        D_loc, dl = particle_conditions(P, groups, tables, [c for _, c in held])
        constraint = [None, create_aij(comm, D_loc, dl, ops.particle_layout)]
    fields = [
        Field(
            "fe",
            ops.K_fe,
            mass_fe,
            fe_spacing(msh, patch.fe_cells),
            fixed=fixed_fe,
            block_size=P.gdim,
        ),
        Field("particles", ops.K_p, mass_p, particle_spacing(P), block_size=P.gdim),
    ]
    blocks, system = {(0, 1): ops.K_fp, (1, 0): ops.K_pf}, None
    if law is not material:  # FE cells by UFL, the particle energy by the SPH sums of P
        if isinstance(law, RateLaws):  # the FE Gauss points' and the energy's points' states
            fe = PointFESide(V, law.bind(), ~patch.in_patch, dilatation=mean)
            energy_law = law.bind()
        else:
            fe, energy_law = fe_forces(V, law, ~patch.in_patch), law
        forces = HybridForces(problem, energy_law)
        system = NonlinearSystem(fields, [fe, None], law, constraint, [forces])
        for B in blocks.values():
            B.destroy()
        blocks = {}
    return Model(
        fields,
        law,
        constraint,
        blocks=blocks,
        V=V,
        mls=problem.evaluator,
        particles=P,
        mesh=msh,
        in_patch=patch.in_patch,
        patch=patch,
        timings={"setup": time.perf_counter() - t0, "operators": ops.timings["operators"]},
        system=system,
    )
