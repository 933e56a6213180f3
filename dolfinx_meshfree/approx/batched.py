"""Batched inverses of many small matrices.

``numpy.linalg.inv`` calls LAPACK once per matrix, which dominates for millions of 2 x 2 / 3 x 3
moment matrices and Jacobians; closed-form adjugate inverses are vectorised instead.
"""

from __future__ import annotations

import numpy as np

__all__ = ["inv"]


def inv(A: np.ndarray) -> np.ndarray:
    """Inverse of each matrix in a stack ``A`` (..., k, k); closed form for k <= 3."""
    k = A.shape[-1]
    if k == 1:
        return 1.0 / A
    if k == 2:
        a, b, c, d = A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1]
        det = a * d - b * c
        out = np.empty_like(A)
        out[..., 0, 0], out[..., 0, 1] = d / det, -b / det
        out[..., 1, 0], out[..., 1, 1] = -c / det, a / det
        return out
    if k == 3:
        c00 = A[..., 1, 1] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 1]
        c01 = A[..., 1, 2] * A[..., 2, 0] - A[..., 1, 0] * A[..., 2, 2]
        c02 = A[..., 1, 0] * A[..., 2, 1] - A[..., 1, 1] * A[..., 2, 0]
        det = A[..., 0, 0] * c00 + A[..., 0, 1] * c01 + A[..., 0, 2] * c02
        out = np.empty_like(A)
        out[..., 0, 0] = c00
        out[..., 1, 0] = c01
        out[..., 2, 0] = c02
        out[..., 0, 1] = A[..., 0, 2] * A[..., 2, 1] - A[..., 0, 1] * A[..., 2, 2]
        out[..., 1, 1] = A[..., 0, 0] * A[..., 2, 2] - A[..., 0, 2] * A[..., 2, 0]
        out[..., 2, 1] = A[..., 0, 1] * A[..., 2, 0] - A[..., 0, 0] * A[..., 2, 1]
        out[..., 0, 2] = A[..., 0, 1] * A[..., 1, 2] - A[..., 0, 2] * A[..., 1, 1]
        out[..., 1, 2] = A[..., 0, 2] * A[..., 1, 0] - A[..., 0, 0] * A[..., 1, 2]
        out[..., 2, 2] = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
        return out / det[..., None, None]
    return np.linalg.inv(A)
