"""Incrementally objective integration of rate-form (hypo-elastic) laws: the Hughes–Winget update.

A rate-form law integrates ``sigma' = C : d`` with an objective stress rate. Over one step from
the deformation gradient ``F_n`` to ``F_{n+1}`` (total-Lagrangian: both known at the point) the
Hughes–Winget algorithm (T.J.R. Hughes and J. Winget, "Finite rotation effects in numerical
integration of rate constitutive equations arising in large-deformation analysis", IJNME 15,
1980, eq. 25–32) takes the displacement increment's gradient in the mid-step configuration::

    G = (F_{n+1} - F_n) F_{n+1/2}^{-1},     F_{n+1/2} = (F_n + F_{n+1}) / 2,
    d eps = (G + G^T) / 2,   d omega = (G - G^T) / 2,
    Q = (I - d omega / 2)^{-1} (I + d omega / 2),

with ``Q`` exactly orthogonal: the Jaumann rate. A rigid rotation ``F_{n+1} = R F_n`` gives
``d eps = 0`` and ``Q = R`` exactly (``G`` is the Cayley transform of ``R``).

Hughes and Winget add the increment after the rotation, ``sigma_{n+1} = Q sigma_n Q^T + d sigma``,
which is first-order accurate when the stress changes while it rotates (the increment is
rotated by a whole step too few or too many). The laws here split the step symmetrically
(Strang): rotate by the half rotation ``Q_h`` (:func:`half_rotation`, ``Q_h^2 = Q`` exactly), add
the increment (and return to the yield surface: an isotropic surface is invariant under
rotation), rotate by ``Q_h`` again::

    sigma_{n+1} = Q_h [Q_h sigma_n Q_h^T + d sigma(d eps)] Q_h^T,

second-order accurate. A stress carried by a spinning body rotates with it to round-off at any
step size (the spinning-plate check); under simple shear the stress follows the Jaumann closed
form ``s_xy = G sin(gamma)``, ``s_xx = -s_yy = G (1 - cos(gamma))`` (Dienes, Acta Mechanica 32,
1979) with an error that falls as the step squared.

Plane strain and axisymmetry enter through :func:`as_3d`: the 2 x 2 in-plane gradient with
``F_zz = 1`` (plane strain) or the hoop stretch ``r / R`` (axisymmetry).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import rate_kernels
from .constitutive import check_deformation_gradients
from .materials import is_axisymmetric

_EYE = np.eye(3)

__all__ = [
    "RateStep",
    "as_3d",
    "cayley",
    "check_arguments",
    "check_step",
    "cofactor_3x3",
    "half_rotation",
    "hughes_winget",
    "inverse_3x3",
    "nominal_stress",
    "virgin_state",
]


def as_3d(F: np.ndarray, hoop: np.ndarray | None = None) -> np.ndarray:
    """The ``(m, 3, 3)`` deformation gradients of ``F`` ``(m, d, d)``, ``d`` 2 or 3.

    A 2D ``F`` gets ``F_zz = 1`` (plane strain) or ``F_zz = hoop`` ``(m,)`` (the hoop stretch
    ``r / R`` of an axisymmetric model, ``(r, z)`` in the plane). A 3D one is returned as a float
    copy; ``hoop`` must then be ``None``.
    """
    F = np.asarray(F, dtype=float)
    if F.ndim != 3 or F.shape[1] != F.shape[2] or F.shape[1] not in (2, 3):
        raise ValueError(f"F should have shape (m, 2, 2) or (m, 3, 3), got {F.shape}")
    if F.shape[1] == 3:
        if hoop is not None:
            raise ValueError("hoop is the out-of-plane stretch of a 2D model; give None in 3D")
        return F.copy()
    out = np.zeros((len(F), 3, 3))
    out[:, :2, :2] = F
    if hoop is None:
        out[:, 2, 2] = 1.0
    else:
        hoop = np.asarray(hoop, dtype=float).reshape(-1)
        if hoop.shape != (len(F),):
            raise ValueError(f"hoop should have shape ({len(F)},), got {hoop.shape}")
        out[:, 2, 2] = hoop
    return out


def cofactor_3x3(A: np.ndarray) -> np.ndarray:
    """``cof(A) = det(A) A^{-T}`` of ``(m, 3, 3)`` matrices: its rows ``a_1 x a_2``,
    ``a_2 x a_0``, ``a_0 x a_1`` (``a_i`` the rows of ``A``), defined for a singular ``A`` too."""
    a0, a1, a2 = A[:, 0], A[:, 1], A[:, 2]
    return np.stack([np.cross(a1, a2), np.cross(a2, a0), np.cross(a0, a1)], axis=1)


def inverse_3x3(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A^{-1}, det A)`` of ``(m, 3, 3)`` matrices by their cofactors: the rows of the
    cofactor matrix are ``a_1 x a_2``, ``a_2 x a_0``, ``a_0 x a_1`` (``a_i`` the rows of ``A``),
    ``det A = a_0 . (a_1 x a_2)`` and ``A^{-1} = cof(A)^T / det A`` (a singular matrix gives
    infinities: check ``det`` first). The same to round-off as ``np.linalg.inv`` and
    ``np.linalg.det`` (``tests/test_hjc.py``), without LAPACK's per-matrix overhead: the
    batched solves of the Hughes–Winget step were 38 % of a coupled Hanchak shot."""
    cof = cofactor_3x3(A)
    det = np.einsum("qi,qi->q", A[:, 0], cof[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = cof.transpose(0, 2, 1) / det[:, None, None]
    return inv, det


def cayley(W: np.ndarray) -> np.ndarray:
    """The Cayley transform ``(I - W)^{-1} (I + W)`` ``(m, 3, 3)`` of skew matrices ``W``
    ``(m, 3, 3)`` in closed form, ``I + 2 (W + W^2) / (1 + w . w)`` (``w`` the axial vector of
    ``W``): a rotation by ``2 atan |w|`` about ``w``."""
    w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    scale = 2.0 / (1.0 + np.einsum("qi,qi->q", w, w))
    return _EYE + scale[:, None, None] * (W + W @ W)


def _kinematics(F_old: np.ndarray, F_new: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(d eps, d omega / 2, det F_{n+1/2})`` of the step (module docstring), checked."""
    F_old = np.asarray(F_old, dtype=float)
    F_new = np.asarray(F_new, dtype=float)
    if F_old.shape != F_new.shape or F_old.ndim != 3 or F_old.shape[1:] != (3, 3):
        raise ValueError(
            f"F_old {F_old.shape} and F_new {F_new.shape} should both have shape (m, 3, 3)"
        )
    inv, det = inverse_3x3(0.5 * (F_old + F_new))
    bad = np.flatnonzero(~(det > 0))
    if bad.size:
        raise ValueError(
            f"the mid-step deformation gradient has det = {det[bad[0]]:.3g} <= 0 at point "
            f"{int(bad[0])}: the step inverts the material; shorten the time step"
        )
    G = (F_new - F_old) @ inv
    Gt = G.transpose(0, 2, 1)
    return 0.5 * (G + Gt), 0.25 * (G - Gt), det


def hughes_winget(F_old: np.ndarray, F_new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(d eps, Q)``, both ``(m, 3, 3)``: the mid-step strain increment and the incremental
    rotation of the Hughes–Winget update (module docstring) from ``F_n`` to ``F_{n+1}``
    ``(m, 3, 3)`` (``Q`` by :func:`cayley`). Raises ``ValueError`` when the mid-step gradient is
    singular (a step that inverts the material)."""
    d_eps, half_w, _ = _kinematics(F_old, F_new)
    return d_eps, cayley(half_w)


def half_rotation(Q: np.ndarray) -> np.ndarray:
    """The rotations ``Q_h`` ``(m, 3, 3)`` with ``Q_h Q_h = Q`` (half the angle about the same
    axis) of rotations ``Q`` ``(m, 3, 3)`` by less than 180 degrees: the rotation factor of the
    polar decomposition of ``I + Q = Q_h (Q_h^T + Q_h)`` (the second factor is symmetric positive
    definite), by an SVD."""
    U, _, Vt = np.linalg.svd(np.eye(3) + np.asarray(Q, dtype=float))
    return U @ Vt


@dataclass(frozen=True)
class RateStep:
    """One symmetric Hughes–Winget step of a rate-form law with a deviatoric stress ``s``: the
    kinematics from ``F_n`` to ``F_{n+1}`` and the old deviator seen in the mid-step frame.

    A law builds it with :meth:`start`, returns its trial deviator ``s_rot + 2 G e`` to its
    strength surface (``s_mid``), and finishes with :meth:`rotate` (``s_{n+1} = Q_h s_mid
    Q_h^T``) and :meth:`work` (module docstring).
    """

    #: Mid-step strain increment ``d eps`` (m, 3, 3) and its deviator ``e``.
    d_eps: np.ndarray
    e: np.ndarray
    #: The half rotation ``Q_h`` (m, 3, 3).
    Qh: np.ndarray
    #: The old deviator rotated by ``Q_h`` (m, 3, 3).
    s_rot: np.ndarray
    #: ``det F_{n+1/2}`` (m,).
    J_mid: np.ndarray

    @classmethod
    def start(cls, F_old: np.ndarray, F_new: np.ndarray, s_old: np.ndarray) -> RateStep:
        """The step from ``F_old`` to ``F_new`` (m, 3, 3) of the deviator ``s_old`` (m, 3, 3)."""
        d_eps, half_w, J_mid = _kinematics(F_old, F_new)
        # Q = cayley(W) turns by 2 atan|w|; half that angle is cayley(W') with
        # |w'| = tan(atan(|w|) / 2) = |w| / (1 + sqrt(1 + |w|^2)): Q_h exactly, no SVD
        # (half_rotation's polar factor gives the same to round-off)
        w2 = half_w[:, 2, 1] ** 2 + half_w[:, 0, 2] ** 2 + half_w[:, 1, 0] ** 2
        Qh = cayley(half_w / (1.0 + np.sqrt(1.0 + w2))[:, None, None])
        e = d_eps - np.trace(d_eps, axis1=1, axis2=2)[:, None, None] / 3.0 * _EYE
        s_rot = Qh @ s_old @ Qh.transpose(0, 2, 1)
        return cls(d_eps, e, Qh, s_rot, J_mid)

    def rotate(self, s_mid: np.ndarray) -> np.ndarray:
        """``Q_h s_mid Q_h^T``: the returned deviator in the end-of-step frame."""
        return self.Qh @ s_mid @ self.Qh.transpose(0, 2, 1)

    def equivalent_rate(self, dt: float) -> np.ndarray:
        """The deviatoric strain rate ``sqrt(2/3 e:e) / dt`` (m,)."""
        return np.sqrt(2.0 / 3.0 * np.einsum("qij,qij->q", self.e, self.e)) / dt

    def work(self, p_old: np.ndarray, s_mid: np.ndarray, p_new: np.ndarray) -> np.ndarray:
        """The stress work of the step per unit reference volume (m,): ``J_{n+1/2} (sigma_n +
        sigma_{n+1}) / 2 : d eps`` with both stresses in the mid-step frame (``sigma = s - p
        I``, the pressures ``p_old``, ``p_new`` (m,))."""
        old = self.s_rot - p_old[:, None, None] * _EYE
        new = s_mid - p_new[:, None, None] * _EYE
        return self.J_mid * np.einsum("qij,qij->q", 0.5 * (old + new), self.d_eps)


def nominal_stress(sigma: np.ndarray, F: np.ndarray, backend: str | None = None) -> np.ndarray:
    """The nominal (first Piola–Kirchhoff) stress ``P = J sigma F^{-T}`` (m, 3, 3) of the Cauchy
    stress ``sigma`` (m, 3, 3) at ``F`` (m, 3, 3) (:func:`as_3d` for a 2D one); ``backend``:
    ``"numba"`` (one compiled pass, :mod:`~dolfinx_meshfree.physics.rate_kernels`; the default
    with numba) or ``"numpy"``, as the rate-form laws' ``backend``."""
    F, sigma = np.asarray(F, dtype=float), np.asarray(sigma, dtype=float)
    if sigma.shape != F.shape or sigma.ndim != 3 or sigma.shape[1:] != (3, 3):
        raise ValueError(f"sigma {sigma.shape} and F {F.shape} should both have shape (m, 3, 3)")
    if rate_kernels.resolve_backend(backend) == "numba":
        return rate_kernels.nominal_stress(sigma, F)
    P = np.zeros_like(sigma)
    live = np.any(sigma != 0.0, axis=(1, 2))  # a point without stress (eroded: F may be singular)
    inv, J = inverse_3x3(F[live])
    P[live] = J[:, None, None] * sigma[live] @ inv.transpose(0, 2, 1)
    return P


def virgin_state(fields: dict[str, int], m: int) -> dict[str, np.ndarray]:
    """The stress-free state of a rate-form law at ``m`` points: zeros of each field's shape
    ``(m, k)``, ``F = I``."""
    state = {name: np.zeros((m, k)) for name, k in fields.items()}
    state["F"][:] = _EYE.ravel()
    return state


def check_step(
    law: object,
    F: np.ndarray,
    dt: float,
    state: dict[str, np.ndarray],
    hoop: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Validate the arguments of a rate-form ``law``'s ``update`` (its ``gdim``, ``plane``,
    ``state_fields``) and return ``(F3 (m, 3, 3), J (m,))`` (:func:`as_3d`; ``det F > 0``)."""
    check_arguments(law, F, dt, state, hoop)
    return check_deformation_gradients(as_3d(F, hoop), 3)


def check_arguments(
    law: object,
    F: np.ndarray,
    dt: float,
    state: dict[str, np.ndarray],
    hoop: np.ndarray | None = None,
) -> None:
    """:func:`check_step` without the gradients' values: the shapes of ``F`` and of the state,
    the step and ``hoop`` (a compiled update checks the values point by point)."""
    name, d = type(law).__name__, law.gdim
    F = np.asarray(F, dtype=float)
    if F.ndim != 3 or F.shape[1:] != (d, d):
        raise ValueError(
            f"{name}: F should have shape (m, {d}, {d}) for plane={law.plane!r}, got {F.shape}"
        )
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"{name}: dt={dt!r} must be a positive time step")
    if is_axisymmetric(law) != (hoop is not None):
        raise ValueError(
            f"{name}: plane={law.plane!r} with hoop={'None' if hoop is None else 'given'}: an "
            "axisymmetric law takes the hoop stretch r / R of every point (hoop=), a plane or "
            "3D one none"
        )
    m = len(F)
    if hoop is not None and np.size(hoop) != m:
        raise ValueError(f"hoop should have shape ({m},), got {np.shape(hoop)}")
    for field, k in law.state_fields.items():
        if field not in state or np.shape(state[field]) != (m, k):
            got = np.shape(state[field]) if field in state else "nothing"
            raise ValueError(
                f"{name}: state[{field!r}] should have shape ({m}, {k}), got {got}; build it "
                "with initial_state(m) and pass the state update() returned"
            )
