"""Explicit dynamics: central differences with lumped masses, for FE, EFG and every coupling.

The public entry point is :class:`ExplicitDynamics` (Belytschko et al. 1995, sec. 4.2 and 5.2;
Rabczuk et al. 2006, sec. 5.3.3 and Table I). The pieces live in modules of one idea each:

* :mod:`~dolfinx_meshfree.dynamics.system`: the semi-discrete system
  (:class:`SemiDiscreteSystem`: ``mass()``, ``internal_force(u)``, ``tangent(u)``,
  ``constraints()``, ``rebuild(changed)``) and its linear member :class:`LinearSystem`
  (``f^int = K u``);
* :mod:`~dolfinx_meshfree.dynamics.finite_strain`: the finite-deformation member
  :class:`NonlinearSystem` (total Lagrangian, ``f^int = sum_q B0^T P(F_q) w_q``, stored energy
  ``W(F)``);
* :mod:`~dolfinx_meshfree.dynamics.central_difference`: the stepping (eq. 93), written on
  ``internal_force``;
* :mod:`~dolfinx_meshfree.dynamics.constraint`: the multiplier correction of the velocities
  (eq. 94–96);
* :mod:`~dolfinx_meshfree.dynamics.time_step`: the stable step (an upper bound of
  ``omega_max``) and its re-bounding hook;
* :mod:`~dolfinx_meshfree.dynamics.energy`: :class:`EnergyRecord`, the strain energy from the
  system, the discrete energy and the work of loads and constraints;
* :mod:`~dolfinx_meshfree.dynamics.loads`, :mod:`~dolfinx_meshfree.dynamics.initial`,
  :mod:`~dolfinx_meshfree.dynamics.evaluation`: tractions and body forces, initial conditions,
  the fields anywhere and their error (eq. 137); :mod:`~dolfinx_meshfree.dynamics.queries`:
  what a running model can be asked (the base of :class:`ExplicitDynamics`);
* :mod:`~dolfinx_meshfree.dynamics.prescribed`: held dofs driven at prescribed velocities
  (``fixed_facets`` triples ``(facets, components, velocity)``) and the work of their reactions;
* :mod:`~dolfinx_meshfree.dynamics.builders` (with :mod:`~dolfinx_meshfree.dynamics.conditions`):
  pure FE, pure EFG, every static coupling from :meth:`CoupledElasticity.operators
  <dolfinx_meshfree.CoupledElasticity.operators>` and the hybrid SPH–FE coupling;
* :mod:`~dolfinx_meshfree.dynamics.results`: :class:`DynamicsResult`;
* :mod:`~dolfinx_meshfree.dynamics.sifs`: dynamic stress intensity factors at a stationary tip
  (the interaction integral with the inertia term) and :class:`SIFHistory`, an ``on_output``
  recorder of K_I(t), K_II(t);
* :mod:`~dolfinx_meshfree.dynamics.crack_growth`: :class:`DynamicCrackGrowth`, dynamic crack
  growth (initiation, direction and arrest by the maximum hoop stress, a prescribed tip speed,
  straight segments; the model updated in place near the tip,
  :mod:`~dolfinx_meshfree.dynamics.growth_local`, or rebuilt with the state carried over);
* :func:`state_field` (:mod:`~dolfinx_meshfree.state_fields`): a rate-form law's state (damage,
  plastic strain) per cell as a DG0 function; :class:`~dolfinx_meshfree.DynamicsWriter` writes
  every such variable beside the displacement.

Dimension-generic: the mesh's ``gdim`` sets the components (2D: triangles, quadrilaterals; 3D:
tetrahedra, hexahedra). In 3D ``fe``, ``efg``, ``lagrange``, ``edge-to-edge`` and ``bridging``
run, small strain and finite strain (``plane=None`` laws); ``ramp``, ``ramp-cubic``,
``master-slave`` and the hybrid coupling refuse a 3D mesh when their static problem is built,
saying what they lack, and stress-point integration is 2D only.

Row-sum lumped masses (eq. 4.5; weighted, eq. 88–89) are in
:mod:`~dolfinx_meshfree.dynamics.masses`, the
exact solutions of the rod benchmarks in :mod:`~dolfinx_meshfree.verification.waves`.
"""

from __future__ import annotations

from ..state_fields import state_field
from .adaptive_run import AdaptiveRun
from .body_contact import BodyContact, BodyContactSystem
from .cohesive_growth import CohesiveDynamicGrowth
from .crack_contact import ContactSystem, CrackContact
from .crack_growth import DynamicCrackGrowth, GrowthCheck, rayleigh_speed
from .energy import EnergyRecord
from .explicit import ExplicitDynamics
from .finite_strain import FINITE_STRAIN_DYNAMICS, NonlinearSystem
from .growth_local import LocalModelUpdate
from .masses import fe_lumped_mass, particle_lumped_mass, table_lumped_mass
from .methods import DYNAMICS_METHODS, check_method
from .nodes_contact import NodesContactSystem
from .patch_conversion import Conversion
from .results import DynamicsResult
from .rigid_projectile import ProjectileContactSystem, ProjectileState, RigidProjectile
from .sifs import SIFHistory
from .system import Field, LinearSystem, SemiDiscreteSystem

__all__ = [
    "DYNAMICS_METHODS",
    "FINITE_STRAIN_DYNAMICS",
    "AdaptiveRun",
    "BodyContact",
    "BodyContactSystem",
    "CohesiveDynamicGrowth",
    "ContactSystem",
    "Conversion",
    "CrackContact",
    "DynamicCrackGrowth",
    "DynamicsResult",
    "EnergyRecord",
    "ExplicitDynamics",
    "Field",
    "GrowthCheck",
    "LinearSystem",
    "LocalModelUpdate",
    "NodesContactSystem",
    "NonlinearSystem",
    "ProjectileContactSystem",
    "ProjectileState",
    "RigidProjectile",
    "SIFHistory",
    "SemiDiscreteSystem",
    "check_method",
    "fe_lumped_mass",
    "particle_lumped_mass",
    "rayleigh_speed",
    "state_field",
    "table_lumped_mass",
]
