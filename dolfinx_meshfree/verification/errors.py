"""Error norms against exact solutions, by quadrature on the owned cells of a mesh (collective).

* relative L2 displacement error, Rabczuk et al. 2006, eq. (136), with the integral norm of
  Belytschko et al. 1995, eq. (5.4);
* energy error ``[int 1/2 (eps_h - eps)^T (sigma_h - sigma)]^{1/2}``, Belytschko et al. 1995,
  eq. (5.5), reported relative to the exact energy ``[int 1/2 eps^T sigma]^{1/2}``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import numpy as np
from mpi4py import MPI

from ..geometry.quadrature import QuadraturePoints, cell_quadrature
from ..physics.materials import LinearElastic

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = ["ExactSolution", "error_norms"]

Evaluator = Callable[[QuadraturePoints], tuple[np.ndarray, np.ndarray]]


class ExactSolution(Protocol):
    """An exact displacement field (e.g. :class:`~dolfinx_meshfree.TimoshenkoBeam`)."""

    def displacement(self, x: np.ndarray) -> np.ndarray:
        """Displacement (m, gdim) at points (m, gdim)."""
        ...

    def displacement_gradient(self, x: np.ndarray) -> np.ndarray:
        """Gradient ``du_i/dx_j`` (m, gdim, gdim) at points (m, gdim)."""
        ...


def _energy_density(grad: np.ndarray, material: LinearElastic) -> np.ndarray:
    sig = material.stress(grad)
    eps = 0.5 * (grad + np.swapaxes(grad, -1, -2))
    return 0.5 * np.einsum("qij,qij->q", eps, sig)


def error_norms(
    msh: dolfinx.mesh.Mesh,
    evaluate: Evaluator,
    exact: ExactSolution,
    material: LinearElastic,
    degree: int = 8,
    cells: np.ndarray | None = None,
) -> dict[str, float]:
    """Relative L2 and energy errors of a computed displacement field.

    Args:
        msh: Mesh whose owned cells (or ``cells``) cover the domain of the error integral.
        evaluate: ``evaluate(q)`` returns the computed displacement (nq, 2) and gradient
            (nq, 2, 2) at the quadrature points ``q``.
        exact: Object with ``displacement(x)`` and ``displacement_gradient(x)``.
        material: The law that turns gradients into stresses.

    Returns:
        ``{"l2": ..., "energy": ..., "l2_abs": ..., "energy_abs": ...}`` on every rank.
    """
    q = cell_quadrature(msh, degree, cells)
    uh, gh = evaluate(q)
    ue = exact.displacement(q.points)
    ge = exact.displacement_gradient(q.points)
    w = q.weights
    sums = np.array(
        [
            np.sum(w * np.sum((uh - ue) ** 2, axis=1)),
            np.sum(w * np.sum(ue**2, axis=1)),
            np.sum(w * _energy_density(gh - ge, material)),
            np.sum(w * _energy_density(ge, material)),
        ]
    )
    sums = msh.comm.allreduce(sums, op=MPI.SUM)
    l2_abs, energy_abs = np.sqrt(sums[0]), np.sqrt(max(sums[2], 0.0))
    return {
        "l2": float(l2_abs / np.sqrt(sums[1])),
        "energy": float(energy_abs / np.sqrt(sums[3])),
        "l2_abs": float(l2_abs),
        "energy_abs": float(energy_abs),
    }
