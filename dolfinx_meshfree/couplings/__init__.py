"""The FE–particle coupling families, one module each, and their registry.

Each family is a class of the :class:`~dolfinx_meshfree.couplings.base.Coupling` protocol;
:class:`~dolfinx_meshfree.CoupledElasticity` dispatches to it by its ``coupling=`` name through
:data:`REGISTRY`. Adding a coupling: a module here with its class, and one line in
:data:`REGISTRY`.
"""

from __future__ import annotations

from .base import CoupledSolution, Coupling, CouplingOperators
from .bridging import BridgingCoupling
from .lagrange import EdgeToEdgeCoupling, LagrangeCoupling
from .master_slave_finite import FiniteMasterSlaveCoupling
from .ramp import CubicRampCoupling, RampCoupling

__all__ = [
    "COUPLINGS",
    "DEFAULT_DILATION",
    "REGISTRY",
    "CoupledSolution",
    "Coupling",
    "CouplingOperators",
]

#: The coupling families by name, in the order the documentation and the demos list them.
REGISTRY: dict[str, type[Coupling]] = {
    cls.name: cls
    for cls in (
        LagrangeCoupling,
        EdgeToEdgeCoupling,
        RampCoupling,
        CubicRampCoupling,
        BridgingCoupling,
        FiniteMasterSlaveCoupling,
    )
}

#: Couplings available in this release.
COUPLINGS: tuple[str, ...] = tuple(REGISTRY)

#: Default MLS dilation ``d_max`` of each coupling (see
#: :class:`~dolfinx_meshfree.CoupledElasticity`).
DEFAULT_DILATION: dict[str, float] = {name: cls.default_dilation for name, cls in REGISTRY.items()}
