"""The shape table: the one currency every approximation of the package is tabulated into.

A :class:`ShapeTable` holds the values and first derivatives of a set of shape functions (MLS/EFG,
SPH, FE basis functions) at ``m`` evaluation points, as scipy CSR matrices with one column per node
(particle or FE node). Operators of both papers are then sparse algebra on tables.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp

__all__ = [
    "Approximation",
    "ShapeTable",
    "StaleTableError",
    "check_current",
    "strain_operator",
    "voigt_pairs",
]


@dataclass
class ShapeTable:
    """Values and gradients of ``n`` shape functions at ``m`` points.

    Attributes:
        points: Evaluation points, shape (m, gdim).
        values: CSR matrix (m x n), ``values[q, I] = N_I(x_q)``.
        gradients: ``gdim`` CSR matrices (m x n), ``gradients[k][q, I] = dN_I/dx_k (x_q)``, or an
            empty list when derivatives were not requested.
        version: The :attr:`Approximation.version` of the approximation when it tabulated this
            table; a consumer that keeps the table checks it against the approximation's
            current version (:func:`check_current`) and rebuilds when they differ.
    """

    points: np.ndarray
    values: sp.csr_matrix
    gradients: list[sp.csr_matrix]
    version: int = 0

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


def voigt_pairs(gdim: int) -> list[tuple[int, int]]:
    """Index pairs ``(i, j)`` of the Voigt components of a symmetric gdim x gdim tensor, in order.

    2D: ``xx, yy, xy``; 3D: ``xx, yy, zz, yz, xz, xy`` (the normal components, then the shear
    components ``(i, j)`` with ``i < j`` in the order ``yz, xz, xy``). The strain operator of
    :func:`strain_operator` and the material matrix of
    :meth:`~dolfinx_meshfree.LinearElastic.voigt` share this order; shears are engineering
    shears ``gamma_ij = 2 eps_ij``.
    """
    if gdim not in (1, 2, 3):
        raise ValueError(f"gdim={gdim} must be 1, 2 or 3")
    shears = {1: [], 2: [(0, 1)], 3: [(1, 2), (0, 2), (0, 1)]}[gdim]
    return [(k, k) for k in range(gdim)] + shears


def strain_operator(gradients: list[sp.csr_matrix]) -> sp.csr_matrix:
    """Voigt strain-displacement operator B for interleaved vector dofs (gdim 1, 2 or 3).

    With ``nv = gdim (gdim + 1) / 2`` Voigt components, rows ``nv q + r`` give component ``r``
    of the strain at point ``q`` in the order of :func:`voigt_pairs` (2D: ``eps_xx, eps_yy,
    gamma_xy``; 3D: ``eps_xx, eps_yy, eps_zz, gamma_yz, gamma_xz, gamma_xy``, engineering
    shears ``gamma_ij = du_i/dx_j + du_j/dx_i``); column ``gdim I + i`` is component ``i`` of
    node ``I`` (the layout of a DOLFINx vector space of block size gdim). This is the ``B_I`` of
    Belytschko et al. 1995, eq. (4.3).

    Args:
        gradients: ``[dN/dx, dN/dy(, dN/dz)]``, each (m x n).

    Returns:
        CSR matrix (nv m x gdim n).
    """
    gdim = len(gradients)
    if gdim not in (2, 3):
        raise ValueError(f"strain_operator needs 2 or 3 gradient tables, got {gdim}")
    g = [t.tocoo() for t in gradients]
    m, n = gradients[0].shape
    pairs = voigt_pairs(gdim)
    nv = len(pairs)
    rows, cols, vals = [], [], []
    for r, (i, j) in enumerate(pairs):
        # d u_i / d x_j, then (shears) d u_j / d x_i
        for comp, der in ((i, j), (j, i)) if i != j else ((i, i),):
            rows.append(nv * g[der].row + r)
            cols.append(gdim * g[der].col + comp)
            vals.append(g[der].data)
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(nv * m, gdim * n),
    )


@runtime_checkable
class Approximation(Protocol):
    """What consumers need of an approximation (MLS/EFG, SPH): shape functions tabulated at
    points, and a ``version`` that changes whenever the functions do (particles move, supports
    change, a crack cuts the supports), so that whatever was built from an older table (a
    stiffness, masses, an internal-force operator) is rebuilt, not used stale."""

    version: int

    def tabulate(self, x: np.ndarray, derivatives: int = 1) -> ShapeTable:
        """Values (and gradients with ``derivatives=1``) at the points ``x``."""
        ...


class StaleTableError(ValueError):
    """A table built from an older version of its approximation was used."""


def check_current(table: ShapeTable, approximation: Approximation, what: str) -> None:
    """Raise :class:`StaleTableError` (local) if ``approximation`` changed since it tabulated
    ``table``; ``what`` names the consumer in the message."""
    if table.version != approximation.version:
        raise StaleTableError(
            f"{what} was built on version {table.version} of its {type(approximation).__name__} "
            f"approximation, which is now at version {approximation.version} (its particles or "
            "supports changed): rebuild it (a new problem or operator) after such a change"
        )
