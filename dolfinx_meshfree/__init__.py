"""dolfinx_meshfree: mesh-free particle methods (EFG, SPH) coupled with DOLFINx finite elements.

Public API (stable names):

* approximations: :class:`MLS` (EFG shape functions), :class:`SPH`, tabulated into a
  :class:`ShapeTable`; weight functions in :mod:`dolfinx_meshfree.approx.kernels`;
* FE basis at arbitrary points: :func:`tabulate_fe_basis`, :func:`evaluate_fe_function`;
* particles: :class:`ParticleSet`; cracks: :class:`Crack` (a 2D polyline in a
  :class:`ParticlePatch`), cutting MLS weights by :func:`attach_cracks` (diffraction or visibility);
* solvers: :class:`EFGElasticity` (pure EFG), :func:`solve_fe_elasticity` and
  :func:`solve_forms` (pure FE: a material, or the user's own forms), :class:`FEElasticity`
  (pure FE with a law with state);
* material and exact solutions: :class:`LinearElastic`, :class:`TimoshenkoBeam`;
* finite deformation: the :class:`Material` protocol (nominal stress ``P(F)``, its tangent, ``W``,
  a UFL twin, the wave speed), :class:`SaintVenantKirchhoff`, :class:`NeoHookean`, and
  :class:`InternalForces` (``f_int(u)``, ``K_T(u)`` from shape tables);
* fracture on any 2D field given by its gradient: :func:`interaction_integral` (K_I, K_II, J
  per domain radius), the near-tip :class:`WilliamsField`, :func:`kink_angle` and
  :func:`equivalent_sif` (maximum hoop stress), growth by :class:`QuasiStaticCrackGrowth`;
  exact references :class:`InclinedCentreCrack` and :func:`edge_crack_factor`;
* output of explicit dynamics: :class:`DynamicsWriter` (XDMF of the FE fields and the particle
  cloud over time), :func:`read_particles`, :class:`ProgressBar`.

Importing this package first loads the ``dolfinx_solver`` wheel's MPI when that lane is in use.
"""

from . import _compat  # noqa: F401  (must come first: loads dolfinx_solver's MPI in lane B)
from ._compat import DOLFINX_VERSION
from .approx.body_cuts import BodyCut, separate_bodies
from .approx.crack_cuts import CRACK_METHODS, attach_cracks
from .approx.fe_points import (
    PointsOutsideMeshError,
    ensure_points_in_mesh,
    evaluate_fe_function,
    tabulate_fe_basis,
    tabulate_in_cells,
)
from .approx.kernels import cubic_spline, gaussian, quartic, sph_cubic_spline
from .approx.mls import MLS, MomentMatrixError
from .approx.sph import SPH
from .approx.tables import Approximation, ShapeTable, StaleTableError
from .couplings.hybrid import HYBRID_VARIANTS, HybridElasticity
from .dynamics import DYNAMICS_METHODS, DynamicsResult, EnergyRecord, ExplicitDynamics
from .dynamics.rate_dilatation import CellCollapseWarning
from .dynamics.static_model import StaticModelWarning
from .fracture.criteria import equivalent_sif, kink_angle
from .fracture.interaction import (
    SIFReliabilityWarning,
    StressIntensityFactors,
    interaction_integral,
)
from .fracture.williams import WilliamsField
from .geometry.adaptive_quadrature import AdaptiveQuadrature
from .geometry.bodies import Bodies, mesh_bodies
from .geometry.crack import Crack
from .geometry.particles import ParticleSet
from .geometry.partition import PartitionImbalanceWarning, balanced_mesh, work_per_rank
from .geometry.patch import PLACEMENTS, ParticlePatch
from .geometry.patch_criteria import (
    CellsWhere,
    FieldAbove,
    NearTips,
    PatchCriterionWarning,
    StateAbove,
    cells_near,
)
from .geometry.quadrature import boundary_facets, cell_quadrature, facet_quadrature
from .geometry.smoothing import INTEGRATIONS
from .geometry.submesh import submesh
from .io import DynamicsWriter, ProgressBar, read_particles
from .physics.bulk_viscosity import BulkViscosity
from .physics.cohesive import LinearCohesive
from .physics.constitutive import DeformationError, Material, NeoHookean, SaintVenantKirchhoff
from .physics.forces import InternalForces
from .physics.hjc import HolmquistJohnsonCook
from .physics.inelastic import J2Plasticity, RankineDamage
from .physics.johnson_cook import JohnsonCook
from .physics.materials import LinearElastic
from .physics.zones import MaterialZones
from .state_fields import state_field
from .statics.band_reach import BandCutWarning
from .statics.bifurcation import BifurcationWarning
from .statics.cohesive_growth import CohesiveGrowth, initiation_direction
from .statics.cohesive_initiation import BulkStrengthWarning, InitiationSite, initiation_site
from .statics.coupled import (
    AXISYMMETRIC_COUPLINGS,
    COMPONENT_COUPLINGS,
    COUPLINGS,
    CRACK_COUPLINGS,
    DEFAULT_DILATION,
    SMOOTHED_COUPLINGS,
    STATIC_CRACK_COUPLINGS,
    CoupledElasticity,
    CoupledSolution,
)
from .statics.crack_band_switch import CrackBandSwitch
from .statics.crack_initiation import CrackInitiation
from .statics.efg import EFGElasticity, EFGSolution
from .statics.fe import FESolution, solve_fe_elasticity, solve_forms
from .statics.fe_model import FEElasticity
from .statics.growth import GrowthStep, GrowthStopped, QuasiStaticCrackGrowth, TipAtBoundary
from .statics.kept_factor import KeptFactorisation
from .statics.large import IterativeOptions, chunked_l2_error, solve_large
from .statics.mean_dilatation import VolumetricLockingWarning
from .statics.newton import NewtonError, NewtonOptions, NewtonResult
from .statics.nonlinear import FINITE_STRAIN_COUPLINGS, CoupledNonlinearProblem, FENonlinearProblem
from .statics.path_following import (
    ArcLength,
    DisplacementControl,
    DoubleSofteningWarning,
    EnergyBalanceWarning,
    PathError,
    PathOptions,
    PathResult,
    PathShortWarning,
    StateCarryWarning,
    follow_path,
)
from .statics.path_patch import ADAPT_COUPLINGS
from .statics.problem import CoupledLinearProblem
from .statics.reactions import reaction
from .statics.sides import NonlinearSolveResult
from .verification.analytic import (
    HeatedBushing,
    KirschPlate,
    LinearField,
    PressurizedBushing,
    TimoshenkoBeam,
)
from .verification.cavity_expansion import (
    CavityExpansion,
    cavity_expansion,
    cavity_pressure_curve,
    hill_cavity_pressure,
    ogive_force,
)
from .verification.crack_fields import InclinedCentreCrack, edge_crack_factor
from .verification.errors import error_norms
from .verification.waves import GaussianPulseRod, StepLoadedRod

__all__ = [
    "ADAPT_COUPLINGS",
    "AXISYMMETRIC_COUPLINGS",
    "COMPONENT_COUPLINGS",
    "COUPLINGS",
    "CRACK_COUPLINGS",
    "CRACK_METHODS",
    "DEFAULT_DILATION",
    "DOLFINX_VERSION",
    "DYNAMICS_METHODS",
    "FINITE_STRAIN_COUPLINGS",
    "HYBRID_VARIANTS",
    "INTEGRATIONS",
    "MLS",
    "PLACEMENTS",
    "SMOOTHED_COUPLINGS",
    "SPH",
    "STATIC_CRACK_COUPLINGS",
    "AdaptiveQuadrature",
    "Approximation",
    "ArcLength",
    "BandCutWarning",
    "BifurcationWarning",
    "Bodies",
    "BodyCut",
    "BulkStrengthWarning",
    "BulkViscosity",
    "CavityExpansion",
    "CellCollapseWarning",
    "CellsWhere",
    "CohesiveGrowth",
    "CoupledElasticity",
    "CoupledLinearProblem",
    "CoupledNonlinearProblem",
    "CoupledSolution",
    "Crack",
    "CrackBandSwitch",
    "CrackInitiation",
    "DeformationError",
    "DisplacementControl",
    "DoubleSofteningWarning",
    "DynamicsResult",
    "DynamicsWriter",
    "EFGElasticity",
    "EFGSolution",
    "EnergyBalanceWarning",
    "EnergyRecord",
    "ExplicitDynamics",
    "FEElasticity",
    "FENonlinearProblem",
    "FESolution",
    "FieldAbove",
    "GaussianPulseRod",
    "GrowthStep",
    "GrowthStopped",
    "HeatedBushing",
    "HolmquistJohnsonCook",
    "HybridElasticity",
    "InclinedCentreCrack",
    "InitiationSite",
    "InternalForces",
    "IterativeOptions",
    "J2Plasticity",
    "JohnsonCook",
    "KeptFactorisation",
    "KirschPlate",
    "LinearCohesive",
    "LinearElastic",
    "LinearField",
    "Material",
    "MaterialZones",
    "MomentMatrixError",
    "NearTips",
    "NeoHookean",
    "NewtonError",
    "NewtonOptions",
    "NewtonResult",
    "NonlinearSolveResult",
    "ParticlePatch",
    "ParticleSet",
    "PartitionImbalanceWarning",
    "PatchCriterionWarning",
    "PathError",
    "PathOptions",
    "PathResult",
    "PathShortWarning",
    "PointsOutsideMeshError",
    "PressurizedBushing",
    "ProgressBar",
    "QuasiStaticCrackGrowth",
    "RankineDamage",
    "SIFReliabilityWarning",
    "SaintVenantKirchhoff",
    "ShapeTable",
    "StaleTableError",
    "StateAbove",
    "StateCarryWarning",
    "StaticModelWarning",
    "StepLoadedRod",
    "StressIntensityFactors",
    "TimoshenkoBeam",
    "TipAtBoundary",
    "VolumetricLockingWarning",
    "WilliamsField",
    "attach_cracks",
    "balanced_mesh",
    "boundary_facets",
    "cavity_expansion",
    "cavity_pressure_curve",
    "cell_quadrature",
    "cells_near",
    "chunked_l2_error",
    "cubic_spline",
    "edge_crack_factor",
    "ensure_points_in_mesh",
    "equivalent_sif",
    "error_norms",
    "evaluate_fe_function",
    "facet_quadrature",
    "follow_path",
    "gaussian",
    "hill_cavity_pressure",
    "initiation_direction",
    "initiation_site",
    "interaction_integral",
    "kink_angle",
    "mesh_bodies",
    "ogive_force",
    "quartic",
    "reaction",
    "read_particles",
    "separate_bodies",
    "solve_fe_elasticity",
    "solve_forms",
    "solve_large",
    "sph_cubic_spline",
    "state_field",
    "submesh",
    "tabulate_fe_basis",
    "tabulate_in_cells",
    "work_per_rank",
]
__version__ = "0.1.0"
