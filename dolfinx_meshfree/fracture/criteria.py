"""Crack growth by the maximum hoop stress criterion (Erdogan & Sih 1963).

Angles are measured in the tip frame (:class:`~.frame.TipFrame`): ``theta`` positive
counterclockwise from the crack's extension (from ``e1`` towards ``e2``). The near-tip hoop stress
of the K-field is

.. math::
    \\sqrt{2\\pi r}\\,\\sigma_{\\theta\\theta} = \\cos\\frac\\theta2
        \\left[K_I \\cos^2\\frac\\theta2 - \\frac32 K_{II}\\sin\\theta\\right],

stationary (and ``tau_r_theta = 0``) where ``K_I sin(theta) + K_II (3 cos(theta) - 1) = 0``, i.e.

.. math::
    \\theta_c = 2\\arctan\\frac{K_I - \\sqrt{K_I^2 + 8K_{II}^2}}{4K_{II}},

negative for ``K_II > 0`` (the crack turns clockwise, away from the side the shear pushes
towards) and ``-70.53`` degrees in pure mode II. The equivalent SIF is that hoop stress at
``theta_c``: ``K_eq = cos^3(theta_c/2) K_I - 3/2 cos(theta_c/2) sin(theta_c) K_II``; the crack
grows where ``K_eq >= K_Ic``.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "advance",
    "equivalent_sif",
    "grows",
    "hoop_stress_factor",
    "kink_angle",
    "kinked_direction",
]


def _pair(K_I: float | np.ndarray, K_II: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    KI, KII = np.broadcast_arrays(np.asarray(K_I, dtype=float), np.asarray(K_II, dtype=float))
    if not (np.all(np.isfinite(KI)) and np.all(np.isfinite(KII))):
        raise ValueError(f"K_I={K_I!r}, K_II={K_II!r} must be finite")
    return KI, KII


def hoop_stress_factor(
    theta: float | np.ndarray, K_I: float | np.ndarray, K_II: float | np.ndarray
) -> np.ndarray:
    """``sqrt(2 pi r) sigma_theta_theta`` of the K-field at angle ``theta`` (radians)."""
    KI, KII = _pair(K_I, K_II)
    h = 0.5 * np.asarray(theta, dtype=float)
    return np.cos(h) * (KI * np.cos(h) ** 2 - 1.5 * KII * np.sin(2.0 * h))


def kink_angle(K_I: float | np.ndarray, K_II: float | np.ndarray) -> np.ndarray:
    """Kink angle ``theta_c`` (radians, in ``(-pi, pi)``) of the maximum hoop stress criterion.

    ``K_II = 0`` gives 0 (the formula's limit for ``K_I > 0``; a closed crack, ``K_I <= 0``,
    ``K_II = 0``, also gets 0 and never grows: ``K_eq = K_I <= 0``). Evaluated without
    cancellation for ``K_I > 0`` as ``2 atan(-2 K_II / (K_I + sqrt(K_I^2 + 8 K_II^2)))``, the
    same number as the formula in the module docstring. Crack-face contact (``K_I < 0``) is
    not modelled.
    """
    KI, KII = _pair(K_I, K_II)
    root = np.sqrt(KI**2 + 8.0 * KII**2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(KI > 0, -2.0 * KII / (KI + root), (KI - root) / (4.0 * KII))
    return np.where(KII == 0, 0.0, 2.0 * np.arctan(t))


def equivalent_sif(
    K_I: float | np.ndarray, K_II: float | np.ndarray, theta: float | np.ndarray | None = None
) -> np.ndarray:
    """``K_eq``: the hoop stress factor at ``theta`` (default the kink angle ``theta_c``)."""
    th = kink_angle(K_I, K_II) if theta is None else theta
    return hoop_stress_factor(th, K_I, K_II)


def grows(K_I: float | np.ndarray, K_II: float | np.ndarray, K_Ic: float) -> np.ndarray:
    """Growth decision ``K_eq >= K_Ic`` (``K_Ic`` > 0, the fracture toughness)."""
    if not (np.isfinite(K_Ic) and K_Ic > 0):
        raise ValueError(f"K_Ic={K_Ic} must be a positive fracture toughness")
    return equivalent_sif(K_I, K_II) >= K_Ic


def kinked_direction(direction: np.ndarray, theta: float) -> np.ndarray:
    """The unit crack direction (2,) after a kink by ``theta`` (radians, counterclockwise)."""
    d = np.asarray(direction, dtype=float)
    n = float(np.hypot(*d)) if d.shape == (2,) else 0.0
    if not (np.isfinite(n) and n > 0):
        raise ValueError(f"direction={direction!r} must be a nonzero 2-vector")
    c, s = np.cos(theta), np.sin(theta)
    return np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]]) / n


def advance(
    tip: np.ndarray, direction: np.ndarray, K_I: float, K_II: float, increment: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """One growth step: kink by ``theta_c`` at the tip, then a straight segment of length
    ``increment`` (``da``).

    Returns:
        The new tip (2,), the new unit direction (2,) and ``theta_c`` (radians).
    """
    if not (np.isfinite(increment) and increment > 0):
        raise ValueError(f"increment={increment} must be a positive crack extension da")
    tip = np.asarray(tip, dtype=float)
    if tip.shape != (2,) or not np.all(np.isfinite(tip)):
        raise ValueError(f"tip should be two finite coordinates (x, y), got {tip.tolist()}")
    theta = float(kink_angle(K_I, K_II))
    d = kinked_direction(direction, theta)
    return tip + increment * d, d, theta
