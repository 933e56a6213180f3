"""Explicit dynamics: central differences with lumped masses, for FE, EFG and every coupling.

The public entry point of explicit dynamics (Belytschko et al. 1995, sec. 4.2 and 5.2; Rabczuk
et al. 2006, sec. 5.3.3 and Table I). The pieces live in modules of one idea each:

* :mod:`~dolfinx_meshfree.masses`: row-sum lumped masses (eq. 4.5; weighted, eq. 88–89) and the
  node/particle spacings of the Courant condition;
* :mod:`~dolfinx_meshfree.integrator`: :class:`ExplicitDynamics`, the central-difference
  integrator with the multiplier correction of the velocities (eq. 93–96), the stable time step
  and its guard, the energy records, and the evaluation of the velocity;
* :mod:`~dolfinx_meshfree.dynamic_builders`: the builders of pure FE, pure EFG and every static
  coupling in dynamics, from :meth:`CoupledElasticity.operators
  <dolfinx_meshfree.CoupledElasticity.operators>`, and of the hybrid SPH–FE coupling
  (:mod:`~dolfinx_meshfree.couplings.hybrid`);
* :mod:`~dolfinx_meshfree.verification.waves`: exact solutions of the rod benchmarks.
"""

from __future__ import annotations

from .integrator import DynamicsResult, EnergyRecord, ExplicitDynamics, Field
from .masses import fe_lumped_mass, particle_lumped_mass, table_lumped_mass
from .statics.coupled import COUPLINGS

__all__ = [
    "DYNAMICS_METHODS",
    "DynamicsResult",
    "EnergyRecord",
    "ExplicitDynamics",
    "Field",
    "check_method",
    "fe_lumped_mass",
    "particle_lumped_mass",
    "table_lumped_mass",
]

#: Methods available in explicit dynamics: pure FE, pure EFG, every static coupling and the
#: hybrid SPH-FE coupling (:class:`~dolfinx_meshfree.couplings.hybrid.HybridElasticity`).
DYNAMICS_METHODS = ("fe", "efg", *COUPLINGS, "hybrid")


def check_method(method: str) -> str:
    """Return ``method`` if explicit dynamics supports it, else raise a ``ValueError``."""
    if method not in DYNAMICS_METHODS:
        raise ValueError(
            f"method={method!r} is not available in explicit dynamics; choose one of "
            f"{list(DYNAMICS_METHODS)}"
        )
    return method
