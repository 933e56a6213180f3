"""The shape table: the one currency every approximation of the package is tabulated into.

A :class:`ShapeTable` holds the values and first derivatives of a set of shape functions (MLS/EFG,
SPH, FE basis functions) at ``m`` evaluation points, as scipy CSR matrices with one column per node
(particle or FE node). Operators of both papers are then sparse algebra on tables.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

__all__ = ["ShapeTable", "strain_operator"]


@dataclass
class ShapeTable:
    """Values and gradients of ``n`` shape functions at ``m`` points.

    Attributes:
        points: Evaluation points, shape (m, gdim).
        values: CSR matrix (m x n), ``values[q, I] = N_I(x_q)``.
        gradients: ``gdim`` CSR matrices (m x n), ``gradients[k][q, I] = dN_I/dx_k (x_q)``, or an
            empty list when derivatives were not requested.
    """

    points: np.ndarray
    values: sp.csr_matrix
    gradients: list[sp.csr_matrix]

    @property
    def shape(self) -> tuple[int, int]:
        """(number of points, number of nodes)."""
        return self.values.shape

    def interpolate(self, coefficients: np.ndarray) -> np.ndarray:
        """Evaluate ``sum_I N_I(x) c_I`` at the points; ``coefficients`` is (n,) or (n, k)."""
        return self.values @ coefficients

    def gradient(self, coefficients: np.ndarray) -> np.ndarray:
        """Gradient of ``sum_I N_I c_I`` at the points, shape (m, k, gdim) for (n, k) input."""
        c = np.asarray(coefficients)
        cols = [g @ c for g in self.gradients]
        return np.stack(cols, axis=-1)


def strain_operator(gradients: list[sp.csr_matrix]) -> sp.csr_matrix:
    """Voigt strain-displacement operator B for interleaved vector dofs (2D).

    Rows ``3q, 3q+1, 3q+2`` give ``eps_xx, eps_yy, gamma_xy`` at point ``q``; column ``2I + i``
    is component ``i`` of node ``I`` (the layout of a DOLFINx vector space of block size 2). This
    is the ``B_I`` of Belytschko et al. 1995, eq. (4.3).

    Args:
        gradients: ``[dN/dx, dN/dy]``, each (m x n).

    Returns:
        CSR matrix (3m x 2n).
    """
    if len(gradients) != 2:
        raise ValueError(f"strain_operator is 2D: expected 2 gradient tables, got {len(gradients)}")
    gx = gradients[0].tocoo()
    gy = gradients[1].tocoo()
    m, n = gradients[0].shape
    rows = np.concatenate([3 * gx.row, 3 * gy.row + 1, 3 * gy.row + 2, 3 * gx.row + 2])
    cols = np.concatenate([2 * gx.col, 2 * gy.col + 1, 2 * gy.col, 2 * gx.col + 1])
    vals = np.concatenate([gx.data, gy.data, gy.data, gx.data])
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * m, 2 * n))
