"""Operators of linear elasticity (2D and 3D) from shape tables: stiffness, loads, VCI gradients.

With tables every operator is sparse algebra (Belytschko et al. 1995, eq. 4.3):
``K = B_test^T (W (x) D) B_trial`` and ``f_I = sum_b N_I(x_b) t(x_b) w_b``.
Dofs are interleaved, ``gdim I + i`` for component ``i`` of node ``I``; the dimension is the
number of gradient tables (2 or 3), the Voigt order that of
:func:`~dolfinx_meshfree.approx.tables.voigt_pairs`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..approx.tables import strain_operator
from .materials import LinearElastic

if TYPE_CHECKING:  # annotations only
    from mpi4py import MPI

__all__ = ["consistent_gradients", "load_vector", "stiffness_matrix"]


def stiffness_matrix(
    test_gradients: list[sp.csr_matrix],
    weights: np.ndarray,
    material: LinearElastic,
    trial_gradients: list[sp.csr_matrix] | None = None,
) -> sp.csr_matrix:
    """Stiffness ``K = sum_q B_test(x_q)^T D B_trial(x_q) w_q`` (gdim n x gdim n).

    Belytschko et al. 1995, eq. (4.3), with ``gdim = len(test_gradients)`` (2 or 3; the material
    must be the law of that dimension). ``trial_gradients`` defaults to ``test_gradients``; they
    differ for variationally consistent integration, which corrects the test functions only
    (Chen, Hillman & Rüter 2013).
    """
    material.check_gdim(len(test_gradients), "the shape table")
    Bt = strain_operator(test_gradients)
    B = Bt if trial_gradients is None else strain_operator(trial_gradients)
    D = material.voigt()
    DW = sp.kron(sp.diags(weights), sp.csr_matrix(D), format="csr")
    return (Bt.T @ DW @ B).tocsr()


def load_vector(values: sp.csr_matrix, weights: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """Consistent load ``f_{gdim I + i} = sum_b N_I(x_b) t_i(x_b) w_b``; ``forces`` is (nb, gdim).

    Belytschko et al. 1995, eq. (4.3) (the traction and body-force terms of ``f``).
    """
    f = values.T @ (weights[:, None] * forces)
    return np.asarray(f).reshape(-1)


def consistent_gradients(
    cell_values: sp.csr_matrix,
    cell_gradients: list[sp.csr_matrix],
    cell_weights: np.ndarray,
    boundary_values: sp.csr_matrix,
    boundary_weights: np.ndarray,
    boundary_normals: np.ndarray,
    comm: MPI.Comm,
) -> list[sp.csr_matrix]:
    """Variationally consistent integration (VCI) of test-function gradients.

    Chen, Hillman & Rüter 2013: linear exactness of a Galerkin method needs the integration
    constraint ``sum_q grad N_I(x_q) w_q = sum_b N_I(x_b) n(x_b) w_b`` (the divergence theorem
    under the quadrature actually used). The corrected gradients
    ``grad^ N_I = grad N_I + xi_I N_I`` with one constant vector per node

    .. math::
        \\xi_I = \\frac{\\sum_b N_I n w_b - \\sum_q \\nabla N_I w_q}{\\sum_q N_I w_q}

    satisfy it exactly, so the linear patch test passes to round-off with any quadrature.
    Sums run over every rank's cells and boundary facets (collective); the boundary must be the
    whole boundary of the integration domain. Any dimension: ``boundary_normals`` is (nb, gdim)
    with ``gdim = len(cell_gradients)``.
    """
    from mpi4py import MPI

    gdim = len(cell_gradients)
    vol = cell_values.T @ cell_weights
    rhs = np.stack(
        [
            boundary_values.T @ (boundary_weights * boundary_normals[:, k])
            - cell_gradients[k].T @ cell_weights
            for k in range(gdim)
        ],
        axis=1,
    )
    vol = comm.allreduce(vol, op=MPI.SUM)
    rhs = comm.allreduce(rhs, op=MPI.SUM)
    small = np.abs(vol) <= 1e-14 * np.abs(vol).max()
    if np.any(small):
        i = int(np.flatnonzero(small)[0])
        raise ValueError(
            f"consistent integration: shape function {i} integrates to ~0 over the domain "
            f"({vol[i]:.2e}); its support misses the quadrature: increase the dilation"
        )
    xi = rhs / vol[:, None]
    return [(g + cell_values @ sp.diags(xi[:, k])).tocsr() for k, g in enumerate(cell_gradients)]
