"""The methods available in explicit dynamics."""

from __future__ import annotations

from ..statics.coupled import COUPLINGS

__all__ = ["DYNAMICS_METHODS", "check_method"]

#: Methods available in explicit dynamics (pure FE, pure EFG, every static coupling and the
#: hybrid SPH-FE coupling, :class:`~dolfinx_meshfree.couplings.hybrid.HybridElasticity`).
DYNAMICS_METHODS = ("fe", "efg", *COUPLINGS, "hybrid")


def check_method(method: str) -> str:
    """Return ``method`` if explicit dynamics supports it, else raise a ``ValueError``."""
    if method not in DYNAMICS_METHODS:
        raise ValueError(
            f"method={method!r} is not available in explicit dynamics; choose one of "
            f"{list(DYNAMICS_METHODS)}"
        )
    return method
