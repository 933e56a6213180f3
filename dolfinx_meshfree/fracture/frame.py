"""The crack-tip frame: origin at the tip, ``e1`` along the crack's extension ahead of the tip,
``e2`` = ``e1`` turned by +90 degrees. The faces of a straight crack lie at ``theta = +-pi``;
``K_I > 0`` opens the crack (``sigma_22 > 0`` ahead of the tip) and ``K_II > 0`` means
``sigma_12 > 0`` ahead of the tip, both in this frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TipFrame"]


@dataclass(frozen=True)
class TipFrame:
    """Tip position and crack direction (the unit tangent pointing ahead of the tip).

    Args:
        tip: (2,) tip coordinates. direction: (2,) any nonzero vector along the crack's
            extension (normalised here).
    """

    tip: np.ndarray
    direction: np.ndarray

    def __post_init__(self) -> None:
        tip = np.asarray(self.tip, dtype=float)
        d = np.asarray(self.direction, dtype=float)
        if tip.shape != (2,) or not np.all(np.isfinite(tip)):
            raise ValueError(f"tip should be two finite coordinates (x, y), got {self.tip!r}")
        if d.shape != (2,) or not np.all(np.isfinite(d)):
            raise ValueError(
                f"direction should be a finite 2-vector along the crack ahead of the tip, "
                f"got {self.direction!r}"
            )
        n = float(np.hypot(*d))
        if not n > 1e-14 * max(1.0, float(np.abs(tip).max())):
            raise ValueError(
                f"direction={self.direction!r} at tip {tip.tolist()} has zero length; pass the "
                f"unit tangent of the crack pointing ahead of the tip"
            )
        object.__setattr__(self, "tip", tip)
        object.__setattr__(self, "direction", d / n)

    @property
    def rotation(self) -> np.ndarray:
        """Q (2, 2) with rows ``e1``, ``e2``: local = Q @ (global - tip)."""
        c, s = self.direction
        return np.array([[c, s], [-s, c]])

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """Tip coordinates (m, 2) of global points (m, 2)."""
        return (np.asarray(points, dtype=float) - self.tip) @ self.rotation.T

    def to_global(self, local: np.ndarray) -> np.ndarray:
        """Global points (m, 2) of tip coordinates (m, 2)."""
        return np.asarray(local, dtype=float) @ self.rotation + self.tip

    def vectors_to_global(self, v: np.ndarray) -> np.ndarray:
        """Vectors (m, 2) from tip components to global components."""
        return v @ self.rotation

    def tensors_to_global(self, t: np.ndarray) -> np.ndarray:
        """Second-order tensors (m, 2, 2) from tip components to global: ``Q^T t Q``."""
        Q = self.rotation
        return Q.T @ t @ Q

    def tensors_to_local(self, t: np.ndarray) -> np.ndarray:
        """Second-order tensors (m, 2, 2) from global components to tip: ``Q t Q^T``."""
        Q = self.rotation
        return Q @ t @ Q.T
