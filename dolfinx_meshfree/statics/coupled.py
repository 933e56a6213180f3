"""FE–EFG elastostatics on a mesh with a particle patch: the model and its coupling.

:class:`CoupledElasticity` holds what a coupled model is made of: the FE space on the whole mesh
(the FE side lives on its non-patch cells), the :class:`~dolfinx_meshfree.ParticlePatch`, the
material, the MLS approximation of the particle side, the essential conditions, tractions and
body forces, and optionally the user's bilinear form (set by
:class:`~dolfinx_meshfree.CoupledLinearProblem`). The coupling itself, how the two sides are tied
and assembled into a PETSc nest block system, is a family of
:mod:`~dolfinx_meshfree.couplings` chosen by name (``coupling=``): Lagrange multipliers
(``lagrange``, ``edge-to-edge``, Rabczuk et al. 2006, sec. 5.4), interface elements with a
ramp (``ramp``, ``ramp-cubic``, Belytschko et al. 1995, sec. 3.2), the bridging domain
(``bridging``, Rabczuk et al. 2006, sec. 5.3) and master–slave links (``master-slave``,
Rabczuk et al. 2006, sec. 5.1.2).
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import dolfinx
import numpy as np
import ufl

from ..approx.body_cuts import separate_bodies
from ..approx.crack_cuts import attach_cracks
from ..approx.fe_dofs import node_flags
from ..approx.mls import MLS
from ..approx.tip_enrichment import enrich_tips
from ..couplings import COUPLINGS, DEFAULT_DILATION, REGISTRY
from ..couplings.base import (
    CoupledSolution,
    CouplingOperators,
    cell_indicator,
    check_dimension,
    material_stiffness_form,
)
from ..couplings.bridging import check_options
from ..couplings.lagrange import interface_particles
from ..couplings.master_slave import SLAVES
from ..geometry.crack import Crack
from ..geometry.partition import warn_imbalance
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import particle_quadrature_degree
from ..geometry.smoothing import STABILISATION, refuse_smoothed, resolve_integration
from ..geometry.stress_points import check_integration
from ..parallel import raise_on_all_ranks
from ..physics import axisymmetry
from ..physics.body_loads import CallableBodyForce
from ..physics.cohesive import LinearCohesive
from ..physics.constitutive import Material
from ..physics.materials import LinearElastic, linear_twin
from ..physics.state import check_not_rate_law, is_stateful
from ..physics.user_functions import check_arguments, check_facets
from .cohesive import CohesiveCrack, check_cohesive, check_through
from .coupled_newton import (
    FINITE_STRAIN_COUPLINGS,
    check_load_steps,
    law_internal_force,
    solve_finite_strain,
)
from .history import SolveHistory
from .kept_factor import KeptFactorisation, check_kept
from .mean_dilatation import resolve_dilatation
from .newton import NewtonOptions
from .petsc import SolverOptions, solver_options
from .sides import check_particle_band

__all__ = [
    "AXISYMMETRIC_COUPLINGS",
    "COMPONENT_COUPLINGS",
    "COUPLINGS",
    "CRACK_COUPLINGS",
    "DEFAULT_DILATION",
    "SMOOTHED_COUPLINGS",
    "STATIC_CRACK_COUPLINGS",
    "CoupledElasticity",
    "CoupledSolution",
    "CouplingOperators",
    "check_angle_and_band",
    "coupled_integration",
    "material_stiffness_form",
    "on_patch",
]

VectorFunction = Callable[[np.ndarray], np.ndarray]

#: The couplings that hold single components of FE nodes (a roller, a symmetry plane): every one.
#: The ramps hold them away from their interface cells (whose FE nodes they blend: a component held
#: there is refused, naming the node); master-slave's links carry a held component's value to the
#: slaves.
COMPONENT_COUPLINGS: tuple[str, ...] = COUPLINGS

#: The couplings that carry cracks in the patch (cut MLS weights, cut-cell quadrature, the crack
#: faces in the consistent integration's boundary): the variational couplings.
CRACK_COUPLINGS: tuple[str, ...] = ("lagrange", "edge-to-edge", "bridging")

#: The couplings that carry cracks in statics: :data:`CRACK_COUPLINGS`, the ramps and
#: master-slave, whose patch cells are cut and whose interface elements or slave layer the crack
#: keeps away from (a tip at least a support radius from the FE interface). Explicit dynamics
#: keeps :data:`CRACK_COUPLINGS`.
STATIC_CRACK_COUPLINGS: tuple[str, ...] = (*CRACK_COUPLINGS, "ramp", "ramp-cubic", "master-slave")

#: The couplings whose patch takes the smoothed integrations
#: (:mod:`~dolfinx_meshfree.geometry.smoothing`): those whose particle block is the plain EFG
#: block. Lagrange's interface receives ``int phi_J sigma n``, the smoothing's own boundary term
#: (exact on a straight interface; where the interface turns the multipliers carry ``sigma Pi
#: n``). Edge-to-edge (its interface values are the interpolant of the particle functions), the
#: bridging band (weights ``alpha``) and the ramps (blended functions) integrate their interface
#: with their own terms, which the smoothing does not carry.
SMOOTHED_COUPLINGS: tuple[str, ...] = ("lagrange", "master-slave")


def check_angle_and_band(corner_angle: float | None, particle_band: float | None) -> None:
    """Refuse a ``corner_angle`` outside (0, 90) degrees or a ``particle_band`` that is not a
    positive number (local, the same on every rank); ``None`` passes for both."""
    if corner_angle is not None and not (
        isinstance(corner_angle, (int, float)) and 0.0 < corner_angle < 90.0
    ):
        raise ValueError(
            f"corner_angle={corner_angle!r} must be None (multipliers continuous along the "
            "interface, the default) or an angle in degrees between 0 and 90"
        )
    check_particle_band(particle_band)


def coupled_integration(
    consistent: bool | None,
    integration: str | None,
    coupling: str,
    patch: ParticlePatch,
    material: LinearElastic | Material,
) -> str:
    """The integration of a coupled model's patch (local, the same on every rank): ``integration``
    or, without it, ``consistent`` or the coupling's default
    (:func:`~dolfinx_meshfree.geometry.smoothing.resolve_integration`). A smoothed one is refused
    with a coupling outside :data:`SMOOTHED_COUPLINGS`, a cracked patch or one with an adaptive
    quadrature, or, when stabilised, a law that is not linear."""
    if consistent is None and integration is None:
        consistent = REGISTRY[coupling].consistent_default
    integration = resolve_integration(consistent, integration)
    if integration not in STABILISATION:
        return integration
    if coupling not in SMOOTHED_COUPLINGS:
        raise ValueError(
            f"integration={integration!r} with coupling={coupling!r}: the smoothing does not carry "
            f"its interface terms; use one of {list(SMOOTHED_COUPLINGS)}, or integration='vci'"
        )
    refuse_smoothed(
        integration,
        cracked=bool(patch.cracks) or patch.quadrature is not None,
        nonlinear=not isinstance(material, LinearElastic),
    )
    return integration


def _check_plane(
    law: LinearElastic, msh: dolfinx.mesh.Mesh, coupling: str, given: str | None = None
) -> None:
    """The law's dimension against the mesh's; an axisymmetric law only with the couplings of
    :data:`AXISYMMETRIC_COUPLINGS`, on a section in ``r >= 0`` (collective). ``given``: the
    class of the user's law, when ``law`` is its linear twin."""
    law.check_gdim(msh.geometry.dim, "V's mesh", given)
    if coupling not in AXISYMMETRIC_COUPLINGS:
        law.refuse_axisymmetric(
            f"CoupledElasticity (coupling={coupling!r}; axisymmetric: "
            f"{', '.join(AXISYMMETRIC_COUPLINGS)})"
        )
    if law.axisymmetric:
        x = msh.geometry.x
        raise_on_all_ranks(msh.comm, lambda: axisymmetry.check_half_plane(x, "V's mesh"))


#: The couplings of an axisymmetric (r, z) model (``plane="axisymmetric"``): their interface,
#: loads, conditions and masses take the ``2 pi r`` weights
#: (:mod:`~dolfinx_meshfree.physics.axisymmetry`): every one (the hybrid is its own class).
AXISYMMETRIC_COUPLINGS: tuple[str, ...] = COUPLINGS


def _attach_cracks(model: CoupledElasticity, coupling: str) -> None:
    """Cut the MLS weights of ``model`` by its patch's cracks (Organ, Fleming & Belytschko 1996);
    only the couplings whose particle side is the plain cracked EFG block can carry them."""
    if coupling not in STATIC_CRACK_COUPLINGS:
        raise ValueError(
            f"coupling={coupling!r} cannot carry a cracked patch (its particle block is "
            f"not integrated on cut cells with the crack faces as boundary); use one of "
            f"{list(STATIC_CRACK_COUPLINGS)}, or leave the cracks out of the patch"
        )
    if coupling == "master-slave" and model.consistent:
        # measured on tests/test_crack_solvers.py's uniaxial patch test: 1.0e-3 with a crack
        # against 3.4e-5 without (Gauss: 7.5e-6 with and without)
        raise ValueError(
            "coupling='master-slave' with consistent=True cannot carry a cracked patch: "
            "VCI on the cut cells, with the slaves' mismatch on the interface, misses the "
            "linear field by 1e-3 (30x its error without the crack); leave consistent at "
            "its default (Gauss quadrature), or use coupling='lagrange'"
        )
    patch = model.patch
    attach_cracks(model.mls, patch.cracks, patch.crack_method, patch=patch)
    if patch.crack_enrichment:
        enrich_tips(model.mls, patch.cracks, patch.crack_method)


class CoupledElasticity:
    """Linear elastostatics with FE cells and a particle patch, coupled by Lagrange multipliers.

    Args:
        V: Vector P1/Q1 space on the whole mesh (the FE side lives on its non-patch cells), 2D
            (triangles, quadrilaterals) or 3D (tetrahedra, hexahedra): one code path, the
            mesh's ``gdim`` sets the components. In 3D ``lagrange``, ``edge-to-edge`` and
            ``bridging`` work; ``ramp``, ``ramp-cubic`` and ``master-slave`` refuse a 3D mesh
            with a ValueError saying what they lack (their ``missing_3d``). Edge-to-edge in 3D
            integrates the interface with the FE interpolant of the particle functions (exact
            patch test when the interface FE nodes are particles, e.g. a grid at h / 2 on a
            regular mesh or ``placement="vertices"``).
        patch: :class:`~dolfinx_meshfree.ParticlePatch` on the same mesh.
        material: :class:`~dolfinx_meshfree.LinearElastic`, used on both sides; or a
            finite-strain law (:class:`~dolfinx_meshfree.NeoHookean`,
            :class:`~dolfinx_meshfree.SaintVenantKirchhoff`) with a coupling of
            :data:`~dolfinx_meshfree.FINITE_STRAIN_COUPLINGS`: :meth:`solve` then runs Newton,
            the FE cells with the law's UFL twin, and :attr:`material` is its small-strain twin
            (the linear blocks; :attr:`law` the law given).
        coupling: ``"lagrange"`` (compatibility coupling with FE trace multipliers, Rabczuk et
            al. 2006, sec. 5.4) or ``"edge-to-edge"`` (multipliers collocated at the interface
            particles, see :meth:`interface_particles`), ``"ramp"`` or ``"ramp-cubic"``
            (interface elements blending FE and particles with a ramp function, Belytschko et al.
            1995, sec. 3.2; see :mod:`~dolfinx_meshfree.couplings.ramp`), ``"bridging"``
            (overlap band with energy weights and multipliers on the band's FE nodes, Rabczuk et
            al. 2006, sec. 5.3; see :mod:`~dolfinx_meshfree.couplings.bridging`) or
            ``"master-slave"`` (particles rigidly linked to the FE boundary, Rabczuk et al. 2006,
            sec. 5.1.2; see :mod:`~dolfinx_meshfree.couplings.master_slave`).
        weight, dilation, basis: MLS options of the particle side. The default dilation is
            ``DEFAULT_DILATION[coupling]``: 2.0 (Belytschko et al. 1995), but 2.5 for the ramp
            couplings, whose particle functions must also cover the interface cells up to their
            FE-side edge, which d_max = 2 leaves to collinear particles only.
        quadrature_degree: Gauss degree on cells and facets. ``None`` (default): the lowest odd
            degree from 7 with 15 Gauss points per patch particle or more
            (:func:`~dolfinx_meshfree.geometry.quadrature.particle_quadrature_degree`): 7 with
            particles at the vertices, 15 (8 x 8) at ``h / 2`` on quadrilaterals; 7 with cracks.
        consistent: Variationally consistent integration on the patch (VCI, Chen, Hillman &
            Rüter 2013, over the patch boundary, interface included): the linear patch test
            passes to round-off. Default (``None``): on for every variational coupling, off for
            ``master-slave``, first order by construction, whose slaves carry the interface
            traction VCI's identity assumes multipliers carry (with VCI its rigid-body motion is
            2e-5 to 4e-4 off, not 3e-14: tests/test_master_slave.py). ``False``: plain Gauss.
        integration: ``"vci"``, ``"smoothed"``, ``"smoothed-subcells"`` or ``"gauss"`` (see
            :class:`~dolfinx_meshfree.EFGElasticity`; ``None``: from ``consistent``). The
            smoothed ones with :data:`SMOOTHED_COUPLINGS`, no crack and no adaptive
            quadrature; ``"smoothed"`` with the linear law only.
        particle_band: With a law that softens (:class:`~dolfinx_meshfree.RankineDamage`): the
            crack band width of the particle points, in sizes of their integration cells.
            Default (``None``): the MLS dilation, about one support radius, the narrowest band
            a smooth MLS field localises in; 1.0 makes it the FE cells' band (their size).
        fe_dilatation: With a law with state: ``None`` (automatic), ``"mean"`` or
            ``"pointwise"``, the FE cells' volumetric strain (see
            :class:`~dolfinx_meshfree.FEElasticity`'s ``dilatation``). Automatic: the cell's mean
            (B-bar) on quadrilaterals and hexahedra in plane strain and 3D, where the full rule
            locks under plastic flow.
        overlap, penalty, constraint: ``coupling="bridging"`` (bridging domain, Rabczuk et al.
            2006, sec. 5.3, see :mod:`~dolfinx_meshfree.couplings.bridging`): band width in cell
            layers (>= 1), the augmented-Lagrangian penalty ``p >= 0``, and where the band is tied:
            ``"integral"`` (the default: Gauss quadrature over the band cells, eq. 52) or
            ``"points"`` (at the band particles, eq. 79-81, which needs enough band particles to
            determine the multipliers on the band nodes: grid particles on a gmsh mesh are not).
        band_width: ``coupling="bridging"``: a band of this physical width instead of
            ``overlap`` cell layers, with ``alpha = min(d / band_width, 1)`` and ``d`` the
            distance to the interface (see
            :class:`~dolfinx_meshfree.couplings.bridging.BridgingBand`).
        corner_angle: ``coupling="lagrange"``: ``None`` (the default): the multipliers are the
            FE traces of the interface nodes, continuous where the interface turns (Rabczuk et
            al. 2006, eq. 109; :func:`~dolfinx_meshfree.couplings.lagrange.projected_normals`).
            A number in (0, 90) degrees (the earlier default,
            :data:`~dolfinx_meshfree.couplings.lagrange.CORNER_ANGLE`): one multiplier per side
            where it turns by more, which over-constrains a staircase interface (1.7-3.9x the FE
            error at spacings >= 0.75 h, tests/test_staircase_couplings.py; 0.9-1.1x with
            ``None``).
    """

    def __init__(
        self,
        V,
        patch: ParticlePatch,
        material: LinearElastic,
        coupling: str = "lagrange",
        weight: str = "quartic",
        dilation: float | None = None,
        basis: str = "linear",
        quadrature_degree: int | None = None,
        consistent: bool | None = None,
        overlap: int = 2,
        penalty: float = 0.0,
        constraint: str = "integral",
        band_width: float | None = None,
        corner_angle: float | None = None,
        particle_band: float | None = None,
        integration: str | None = None,
        fe_dilatation: str | None = None,
    ):
        #: The constructor's options, for the same model on another patch (:func:`on_patch`).
        self._given = {k: v for k, v in locals().items() if k not in ("self", "V", "patch")}
        if coupling not in REGISTRY:
            raise ValueError(
                f"coupling={coupling!r} is not available; choose one of {list(COUPLINGS)}"
            )
        check_angle_and_band(corner_angle, particle_band)
        resolve_dilatation(
            fe_dilatation,
            material if is_stateful(material) else None,
            V.mesh.topology.cell_type.name,
            "CoupledElasticity: fe_dilatation",
        )
        #: The FE cells' volumetric strain with a law with state (``None``: automatic,
        #: :func:`~dolfinx_meshfree.statics.mean_dilatation.resolve_dilatation`).
        self.fe_dilatation = fe_dilatation
        #: A law that softens: the crack band of a particle point in integration-cell sizes
        #: (``None``: the MLS dilation, :class:`~dolfinx_meshfree.statics.sides.ParticleSide`).
        self.particle_band = particle_band
        family = REGISTRY[coupling]
        check_dimension(V.mesh, coupling, family.dimensions, family.missing_3d)
        if corner_angle is not None and V.mesh.geometry.dim != 2:
            raise ValueError(
                f"corner_angle={corner_angle!r} splits the multipliers where a 2D interface turns "
                "(a polyline); it is not defined on a 3D interface: leave it None (multipliers "
                "continuous along the interface)"
            )
        check_not_rate_law(material, "CoupledElasticity")
        if not isinstance(material, LinearElastic | Material) and not is_stateful(material):
            raise TypeError(
                f"material must be a LinearElastic, a finite-strain Material (NeoHookean, "
                f"SaintVenantKirchhoff) or a law with state (RankineDamage, J2Plasticity), got "
                f"{type(material).__name__}"
            )
        if not isinstance(material, LinearElastic) and coupling not in FINITE_STRAIN_COUPLINGS:
            raise ValueError(
                f"material={type(material).__name__}: coupling={coupling!r} is not available at "
                f"finite strain (its family has no finite-strain system); use one of "
                f"{list(FINITE_STRAIN_COUPLINGS)} or material=LinearElastic"
            )
        _check_plane(linear_twin(material), V.mesh, coupling, type(material).__name__)
        if V.mesh is not patch.mesh:
            raise ValueError("V and patch must live on the same mesh object")
        if patch.comm.allreduce(patch.fe_cells.size) == 0:
            raise ValueError(
                "the patch covers the whole mesh: no FE cells are left to couple to; solve with "
                "EFGElasticity, or leave some cells out of the patch"
            )
        warn_imbalance(V.mesh, patch.in_patch)
        t0 = time.perf_counter()
        self.V, self.patch, self.coupling = V, patch, coupling
        #: The small-strain law of the linear blocks (``law`` itself when it is linear).
        self.material = linear_twin(material)
        #: The law given, :class:`~dolfinx_meshfree.LinearElastic` (one linear solve) or a
        #: finite-strain :class:`~dolfinx_meshfree.physics.constitutive.Material` (Newton).
        self.law = material
        self.quadrature_degree = particle_quadrature_degree(
            V.mesh, patch.cells, patch.particles.positions, quadrature_degree, bool(patch.cracks)
        )
        self.corner_angle = None if corner_angle is None else float(corner_angle)
        #: The coupling family (:mod:`~dolfinx_meshfree.couplings`).
        self.family = REGISTRY[coupling]()
        #: One of ``smoothing.INTEGRATIONS`` (``consistent``: VCI corrects the test gradients).
        self.integration = coupled_integration(consistent, integration, coupling, patch, material)
        self.consistent = self.integration == "vci"
        self.overlap, self.penalty, self.constraint, self.band_width = check_options(
            overlap, penalty, constraint, band_width
        )
        self.mls = raise_on_all_ranks(
            patch.comm,
            lambda: MLS(
                patch.particles,
                weight=weight,
                dilation=self.family.default_dilation if dilation is None else dilation,
                basis=basis,
            ),
        )
        self.mls = self.family.prepare_mls(self.mls, patch)
        separate_bodies(self.mls, V.mesh)
        if patch.cracks:
            raise_on_all_ranks(patch.comm, lambda: _attach_cracks(self, coupling))
        self.dirichlet: list[tuple[np.ndarray, VectorFunction]] = []
        self.tractions: list[tuple[np.ndarray, Callable]] = []
        #: The cracks whose faces carry a traction-separation law (:meth:`add_cohesive`).
        self.cohesive: list[CohesiveCrack] = []
        #: The user's bilinear form (from a CoupledLinearProblem); ``None``: :attr:`material`'s.
        self.form: ufl.Form | None = None
        # set by CoupledLinearProblem: strong conditions by node (flags, values)
        self.strong: list[tuple[np.ndarray, np.ndarray]] = []
        #: ``(facets, value, components)`` of :meth:`add_dirichlet` by component (all facets)
        self.component_dirichlet: list[tuple[np.ndarray, VectorFunction, tuple[int, ...]]] = []
        #: Held single nodes of patch cells (``couplings.point_conditions``; CoupledLinearProblem)
        self.point_dirichlet: list = []
        #: Body forces (``physics.body_loads``): :meth:`set_body_force`'s or a problem's ``L``'s.
        self.body_forces: list = []
        #: Where the last solve with state ended, the next's start (:mod:`.history`).
        self.history = SolveHistory("CoupledElasticity")
        #: master-slave's slaves (``master_slave.SLAVES``): ``"first-layer"``: a layer off Gamma_I.
        self.slaves = "layer"
        self.setup_time = time.perf_counter() - t0

    def reset(self) -> None:
        """Forget the path: the next :meth:`solve` starts from the unloaded, virgin state."""
        self.history.clear()

    def add_cohesive(
        self,
        crack: Crack,
        law: LinearCohesive,
        segments: Sequence[int] | None = None,
        points: int = 3,
    ) -> None:
        """Let the faces of ``crack`` (one of the patch's) carry ``law``, a
        :class:`~dolfinx_meshfree.LinearCohesive`, on the ``segments`` of its polyline (``None``:
        all; the others stay traction-free, a notch), with ``points`` Gauss points per piece of
        one spacing (:mod:`~dolfinx_meshfree.statics.cohesive`). The model is then solved by
        Newton (:meth:`solve`) or past its peak (:func:`~dolfinx_meshfree.follow_path`), the
        faces' state committed with the bulk's; ``K_0`` defaults to ``30 E / h``. Collective."""
        args = (crack, law, self.patch.cracks, segments, points, self.V.mesh.geometry.dim)

        def check() -> CohesiveCrack:
            if self.form is not None and not is_stateful(self.law):
                raise ValueError(
                    "a CoupledLinearProblem's own bilinear form cannot carry cohesive faces: "
                    "Newton would assemble the FE cells from the law, not from your form; give "
                    "the model CoupledElasticity(V, patch, law) with callables instead"
                )
            return check_cohesive(*args)

        self.cohesive.append(raise_on_all_ranks(self.patch.comm, check))

    def add_dirichlet(
        self, facets: np.ndarray, value: VectorFunction, components: tuple[int, ...] | None = None
    ) -> None:
        """``u = value(x)`` on owned exterior facets (FE side: strongly; patch side: multipliers).
        ``value`` maps points (m, gdim) to (m, gdim). ``components`` constrains only those
        components (a roller, a symmetry plane): on FE facets their nodes' components are held
        strongly (every coupling, :data:`COMPONENT_COUPLINGS`), on patch facets one constant
        multiplier per facet and component, e.g. to remove the rigid motions of a traction
        problem with three scalar conditions. Collective."""
        check_arguments(value, 1, "the Dirichlet value")
        facets = check_facets(self.V.mesh, facets, "add_dirichlet: facets")
        if components is None:
            self.dirichlet.append((facets, value))
            return
        gdim = self.V.mesh.geometry.dim
        on_patch = np.isin(facets, self.patch.exterior_facets)
        comm = self.patch.comm

        def check() -> tuple[int, ...]:
            c = tuple(components)
            if not c or len(set(c)) != len(c) or any(k not in range(gdim) for k in c):
                raise ValueError(
                    f"components={components!r} must be distinct indices in 0..{gdim - 1}"
                )
            return c

        c = raise_on_all_ranks(comm, check)
        # the FE nodes' components held strongly, by dof, on every facet (as a DirichletBC on
        # V.sub(i) does): FE facets, and patch facets whose nodes FE cells carry (bridging band)
        V = self.V
        fdim = V.mesh.topology.dim - 1
        nodes = node_flags(V, dolfinx.fem.locate_dofs_topological(V, fdim, facets))
        flags = np.zeros((nodes.size, gdim), dtype=bool)
        flags[np.ix_(nodes, list(c))] = True
        x = V.tabulate_dof_coordinates()[: nodes.size, :gdim]
        values = np.zeros((nodes.size, gdim))
        # on every rank, with or without nodes: ``value`` may be collective (a Function)
        values[nodes] = np.asarray(value(x[nodes]), dtype=float).reshape(-1, gdim)
        self.strong.append((flags, values))
        self.component_dirichlet.append((facets, value, c))
        if comm.allreduce(int(on_patch.sum())):
            self.dirichlet.append((facets[on_patch], value, c))

    def add_traction(self, facets: np.ndarray, traction: Callable) -> None:
        """Traction ``traction(x, n)`` (m, gdim) on owned exterior facets, on either side."""
        check_arguments(traction, 2, "traction")
        self.tractions.append((check_facets(self.V.mesh, facets, "add_traction: facets"), traction))

    def set_body_force(self, force: VectorFunction) -> None:
        """Body force per unit volume ``b(x)`` (m, gdim) on the whole body (replaces a previous
        one), as
        :meth:`EFGElasticity.set_body_force <dolfinx_meshfree.EFGElasticity.set_body_force>`.

        Every coupling integrates it with the functions and weights of its stiffness (see
        :mod:`~dolfinx_meshfree.physics.body_loads`): FE cells with ``N_a``, patch cells with
        ``phi_J``, ramp interface cells with the blended functions (Belytschko et al. 1995,
        eq. 3.15), a bridging band with ``1 - alpha`` and ``alpha`` (Rabczuk et al. 2006,
        eq. 49)."""
        self.body_forces = [CallableBodyForce(force)]

    def cell_indicator(self, owned_flags: np.ndarray) -> dolfinx.fem.Function:
        """DG0 Function equal to 1 on the owned cells flagged in ``owned_flags`` (and on their
        ghost copies), 0 elsewhere (collective)."""
        return cell_indicator(self.V.mesh, owned_flags)

    def fe_form(self, weight: ufl.core.expr.Expr) -> ufl.Form:
        """The FE bilinear form weighted by ``weight`` (a scalar UFL expression: a cell indicator,
        or the bridging energy weight ``1 - alpha``).

        Without a user form (:class:`~dolfinx_meshfree.CoupledLinearProblem` sets
        :attr:`form`), it is ``weight inner(sigma(u), eps(v)) dx`` of :attr:`material`;
        with one, every cell integral of the user's form is multiplied by ``weight``, so that the
        user's own measures, subdomain data and metadata are kept.
        """
        if self.form is None:
            return material_stiffness_form(self.material, self.V, weight)
        return ufl.Form(
            [itg.reconstruct(integrand=weight * itg.integrand()) for itg in self.form.integrals()]
        )

    def interface_particles(self) -> np.ndarray:
        """Indices of the particles on the interface facets, the same on every rank (collective);
        see :func:`~dolfinx_meshfree.couplings.lagrange.interface_particles`."""
        return interface_particles(self)

    def operators(
        self, integration: str = "cells", slaves: str = "layer", consistent: bool = False
    ) -> CouplingOperators:
        """The coupling's assembled operators without essential conditions (collective).

        Stiffness blocks, constraint blocks with unit scaling, the weights of the FE energy and
        the particle quadrature with its MLS table (for lumped masses), and the coupling's
        interface object; see :class:`CouplingOperators`. Tractions and Dirichlet conditions
        given to this object are not used. Every coupling of :data:`COUPLINGS` is available.

        Args:
            integration: ``"cells"`` (default): the particle stiffness on the patch cells' Gauss
                rule; ``"stress-points"``: at the particles and stress points with their
                volumes (Rabczuk, Belytschko & Xiao 2004; see
                :mod:`~dolfinx_meshfree.geometry.stress_points`), for ``lagrange``, ``edge-to-edge``
                and ``master-slave``; :attr:`CouplingOperators.particle_quadrature` is then that
                rule. The ramp and bridging couplings integrate blended or weighted functions
                on cells and refuse it.
            slaves: ``master-slave`` only: ``"layer"`` (default, the first particle layer
                rigidly linked to the interface, eq. 17–28) or ``"coincident"`` (Johnson's
                particles fixed to the interface FE nodes, eq. 15–16); see
                :class:`~dolfinx_meshfree.couplings.master_slave.MasterSlaveLinks`.
            consistent: Variationally consistent integration in the particle stiffness. Default
                ``False`` whatever :attr:`consistent` says: explicit dynamics needs a symmetric
                ``K`` for its discrete energy identity; the VCI stiffness is Petrov-Galerkin, not
                symmetric (rod of tests/test_dynamic_couplings.py, two transits: energy drift
                1.4e-3 to 3.1e-3 instead of 1e-14, velocity error unchanged to 3 %, master-slave
                +47 %). ``True``: VCI for lagrange, edge-to-edge, bridging and master-slave.
                A problem built with ``integration="smoothed"`` keeps its smoothed stiffness,
                symmetric and consistent (:mod:`~dolfinx_meshfree.geometry.smoothing`).

        Raises:
            ValueError: on every rank, for an unknown or unsupported option.
        """
        check_integration(integration)
        if slaves not in SLAVES:
            raise ValueError(f"slaves={slaves!r} is not known; use one of {list(SLAVES)}")
        if slaves != "layer" and self.coupling != "master-slave":
            raise ValueError(
                f"slaves={slaves!r} is an option of coupling='master-slave', not of "
                f"coupling={self.coupling!r}"
            )
        if integration not in self.family.integrations:
            raise ValueError(
                f"integration={integration!r} is not available with coupling={self.coupling!r} "
                "(its particle functions are blended or weighted on cells); use 'cells', or "
                "lagrange, edge-to-edge or master-slave"
            )
        # the builders read the option from the problem: a shallow copy carries this call's
        problem = copy.copy(self)
        problem.consistent = bool(consistent)
        return self.family.operators(problem, integration, slaves)

    def solve(
        self,
        solver: str | SolverOptions = "mumps",
        petsc_options: Mapping[str, Any] | None = None,
        prefix: str | None = None,
        load_steps: int = 1,
        newton: NewtonOptions | None = None,
        kept: KeptFactorisation | None = None,
    ) -> CoupledSolution:
        """Assemble the nest block system and solve it (collective); with a finite-strain
        material, by Newton over ``load_steps`` steps of the tractions, body force and prescribed
        displacements (total Lagrangian, :mod:`~dolfinx_meshfree.statics.nonlinear`: the FE
        cells' ``int P(F) : grad v dX`` of the law's UFL twin, the particles'
        ``sum_q B0^T P(F_q) w_q``); the solution's ``newton`` then holds the
        :class:`~dolfinx_meshfree.NonlinearSolveResult` (a step that does not converge raises
        :class:`~dolfinx_meshfree.statics.newton.NewtonError` with the residual history).

        Args:
            solver: ``"mumps"`` (direct, the default), ``"fieldsplit"`` (Schur complement on
                the augmented Lagrangian) or ``"iterative"`` (FGMRES, one GAMG V-cycle and the
                rigid-body modes: no factorisation; ``statics.petsc.BlockSystem``); or a
                :class:`~dolfinx_meshfree.statics.petsc.SolverOptions`
                (with ``"iterative"``, options changed, e.g. ``{"ksp_rtol": 1e-10}``).
            petsc_options: PETSc options of a KSP on the assembled block system instead, as
                ``dolfinx.fem.petsc.LinearProblem`` takes them (e.g. ``{"pc_type":
                "fieldsplit", ...}``; the nest's fields: ``fe``, ``particles``,
                ``multiplier0``, ...). Nothing is left in PETSc's options database.
            prefix: The KSP's options prefix (default: a unique one).
            load_steps: Finite strain: the loads and prescribed displacements in ``k /
                load_steps`` steps (ignored by a linear material). A law with state (or
                cohesive faces) continues from the last solve: the steps run from its loads to
                the current ones, from its state (a load sweep; :meth:`reset` starts again).
            newton: Finite strain: :class:`~dolfinx_meshfree.statics.newton.NewtonOptions`.
            kept: A :class:`~dolfinx_meshfree.KeptFactorisation` the caller owns: a direct
                solve of the last one's matrix (a load sweep) is not factorised again
                (:func:`~dolfinx_meshfree.statics.petsc.solve_lu`); a law with state ignores it.
        """
        comm = self.patch.comm
        options = raise_on_all_ranks(comm, lambda: solver_options(solver, petsc_options, prefix))
        raise_on_all_ranks(comm, lambda: check_kept(kept))
        raise_on_all_ranks(comm, lambda: check_through(self.patch.cracks, self.cohesive))
        if isinstance(self.law, LinearElastic) and not self.cohesive:
            solution = self.family.solve(self, options, kept)
            solution.material = self.material
            solution.take_loads(self.body_forces)
            return solution
        raise_on_all_ranks(comm, lambda: check_load_steps(load_steps))
        u = dolfinx.fem.Function(self.V)
        u.x.array[:] = 0.0
        F_int = law_internal_force(self.law, u)
        history = self.history if is_stateful(self.law) or self.cohesive else None
        out = solve_finite_strain(
            self, F_int, u, self.law, load_steps, newton or NewtonOptions(), options, None, history
        )
        out.solution.newton = out.result
        return out.solution


def on_patch(model: CoupledElasticity, patch: ParticlePatch) -> CoupledElasticity:
    """The same model on another patch of the same mesh (collective): its law, coupling and
    options, its essential conditions, tractions, body forces and cohesive faces, as given by
    the ``add_*`` calls; a model made by :class:`~dolfinx_meshfree.CoupledLinearProblem`
    (``problem.model``) from the problem's forms and conditions
    (:meth:`~dolfinx_meshfree.CoupledLinearProblem.with_patch`). What a patch that grows along
    a followed path rebuilds (:func:`~dolfinx_meshfree.follow_path` with ``adapt``). The patch's
    cracks are those it was given (``patch.add_crack``): every cohesive crack must be among
    them."""
    problem = getattr(model, "_problem", None)
    if problem is not None:
        new = problem.with_patch(patch).model
    else:
        new = CoupledElasticity(model.V, patch, **model._given)
        for facets, value, components in model.component_dirichlet:
            new.add_dirichlet(facets, value, components)
        for entry in model.dirichlet:  # the by-component ones are replayed above
            if len(entry) == 2:
                new.add_dirichlet(*entry)
        for facets, traction in model.tractions:
            new.add_traction(facets, traction)
        new.body_forces = list(model.body_forces)
    for c in model.cohesive:
        new.add_cohesive(c.crack, c.law, c.segments, c.points)
    new.slaves = model.slaves  # set after construction: not among the constructor's options
    return new
