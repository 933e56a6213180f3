"""Artificial bulk viscosity: the shock smearing of explicit dynamics for rate-form laws.

A compressive front in a discretised solid has no width of its own: it rings behind the front
(Gibbs), the stress overshoots, and a law with damage or crushing fails the points the ringing
reaches, so that where the material fails moves with the mesh and the time step. The cure of
von Neumann & Richtmyer (1950) spreads the front over a few cells by a pressure ``q`` added to
the law's, in compression only; the form of Wilkins (1980, "Use of artificial viscosity in
multidimensional fluid dynamic calculations", J. Comput. Phys. 36) and of LS-DYNA's default
(Hallquist, LS-DYNA Theory Manual, sec. "Bulk viscosity"; coefficients 1.5 and 0.06), with
the volumetric strain rate ``eps_v' = tr D = J' / J``::

    q = rho l (c_q^2 l eps_v'^2 - c_l c eps_v'),    eps_v' < 0;    q = 0 otherwise,

``rho = rho_0 / J`` the current density, ``l = l_0 s_min(F)`` the current thickness of a
point's cell (:func:`current_lengths`: ``l_0`` its reference size, ``s_min`` the smallest
principal stretch, in the section's plane for plane strain and axisymmetry), ``c`` the law's
dilatational wave speed (its stiffest linear twin's, which the stable step is bounded with)
and ``c_q``, ``c_l`` the quadratic and the linear coefficient. The Cauchy stress the forces see
is ``sigma - q I``; the law's own state does not see ``q``.

The length is the cell's thinnest extent, as LS-DYNA's characteristic length (a solid's volume
over its largest face), because that is the length the stable step sees (the cells'
frequencies grow as ``c / (s_min l_0)``, :meth:`~dolfinx_meshfree.dynamics.rate_forms.RateLaw.
stretches`). Under a uniform compression it is ``l_0 J^(1/d)``. A cell flattened at constant
volume (the plastic flow at a Taylor bar's foot) keeps ``J = 1`` while its thickness falls to a
fraction of ``l_0``: a damper sized by ``l_0 J^(1/d)`` there is ``1 / s_min`` times stiffer
than the factor below allows for, and the run blows up (measured: the copper Taylor bar of
``demos/taylor_bar.py`` inverted its foot at 49 us with ``l_0 J^(1/3)``; with the thickness it
runs to the published length).

Over a step from ``J_n`` to ``J_{n+1}`` the rate is ``(J_{n+1} - J_n) / (dt (J_n + J_{n+1}) /
2)`` and the work ``q`` does per unit reference volume, all of it dissipated, is
``-(q_n + q_{n+1}) / 2 (J_{n+1} - J_n) >= 0`` (trapezoidal, as the laws' stress work), so the
energy record holds it with the internal energy.

The viscous force is a damper on the cell's highest mode; central differences stay stable for
``dt <= l / (b + sqrt(b^2 + c^2))`` (Wilkins 1980), ``b = 2 c_q^2 l |eps_v'| + c_l c``
in compression (the damper's tangent, twice its secant for the quadratic term), ``b = 0``
otherwise: ``(b + sqrt(b^2 + c^2)) / c`` is the factor by which the step falls
(:func:`viscous_pressure`); the stable step is divided by the largest over the points
(:meth:`~dolfinx_meshfree.dynamics.time_step.TimeStepBound.stable`): each point's damper scales
its frequencies by at most it, so the bound over it stays a bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from . import rate_kernels

__all__ = [
    "DEFAULT_VISCOSITY",
    "BulkViscosity",
    "check_viscosity",
    "current_lengths",
    "particle_lengths",
    "viscous_pressure",
    "volume_ratios",
    "volumetric_rate",
]


@dataclass(frozen=True)
class BulkViscosity:
    """The coefficients of the artificial bulk viscosity (module docstring), a rate-form law's
    ``viscosity`` (on by default; ``viscosity=None`` leaves it out).

    Args:
        quadratic: ``c_q`` (1.5, LS-DYNA's Q1): spreads a shock over about ``c_q^2`` cells.
        linear: ``c_l`` (0.06, LS-DYNA's Q2): damps the ringing left behind.
    """

    quadratic: float = 1.5
    linear: float = 0.06

    def __post_init__(self) -> None:
        for name in ("quadratic", "linear"):
            value = getattr(self, name)
            if not (
                isinstance(value, int | float)
                and not isinstance(value, bool)
                and np.isfinite(value)
                and value >= 0.0
            ):
                raise ValueError(
                    f"BulkViscosity: {name}={value!r} must be a finite number >= 0 (LS-DYNA's "
                    "defaults are quadratic=1.5, linear=0.06)"
                )
        if self.quadratic == 0.0 and self.linear == 0.0:
            raise ValueError(
                "BulkViscosity: quadratic=0 and linear=0 is no viscosity; give the law "
                "viscosity=None to leave it out"
            )


#: LS-DYNA's default coefficients: the rate-form laws' default ``viscosity``.
DEFAULT_VISCOSITY = BulkViscosity()


def check_viscosity(owner: str, viscosity: object) -> None:
    """Refuse a law's ``viscosity`` that is neither ``None`` nor a :class:`BulkViscosity`."""
    if viscosity is not None and not isinstance(viscosity, BulkViscosity):
        raise ValueError(
            f"{owner}: viscosity={viscosity!r} is not a BulkViscosity; give "
            "mf.BulkViscosity(quadratic=1.5, linear=0.06) or None (no viscosity)"
        )


def volume_ratios(F: np.ndarray) -> np.ndarray:
    """``det F`` (m,) of gradients stored row-major (m, 9), by the rule of Sarrus."""
    a = np.asarray(F, dtype=float)
    return (
        a[:, 0] * (a[:, 4] * a[:, 8] - a[:, 5] * a[:, 7])
        - a[:, 1] * (a[:, 3] * a[:, 8] - a[:, 5] * a[:, 6])
        + a[:, 2] * (a[:, 3] * a[:, 7] - a[:, 4] * a[:, 6])
    )


def volumetric_rate(J_old: np.ndarray, J_new: np.ndarray, dt: float) -> np.ndarray:
    """``eps_v' = (J_new - J_old) / (dt (J_old + J_new) / 2)`` (m,)."""
    return (J_new - J_old) / (dt * 0.5 * (J_new + J_old))


def current_lengths(
    F: np.ndarray, length0: np.ndarray, plane: str | None, backend: str | None = None
) -> np.ndarray:
    """The current thickness ``l_0 s_min(F)`` (m,) of cells of reference size ``length0`` (m,)
    at their points' gradients ``F`` (m, 9) (row-major 3 x 3): ``s_min`` the smallest singular
    value of the in-plane 2 x 2 block for a 2D law (``plane`` ``"strain"`` or
    ``"axisymmetric"``: the hoop stretch does not thin the section's cell), of ``F`` in 3D
    (``plane=None``; by the law's ``backend``: compiled Jacobi on ``F^T F``, or numpy's SVD)."""
    a = np.asarray(F, dtype=float)
    if plane is None:
        if rate_kernels.resolve_backend(backend) == "numba":
            s = rate_kernels.smallest_stretches(a, np.ones(len(a), dtype=bool))
        else:
            s = np.linalg.svd(a.reshape(-1, 3, 3), compute_uv=False)[:, -1] if len(a) else a[:, 0]
    else:  # sigma_min^2 = (T - sqrt(T^2 - 4 D^2)) / 2 of the 2 x 2 block (T = |A|^2, D = det A)
        t = a[:, 0] ** 2 + a[:, 1] ** 2 + a[:, 3] ** 2 + a[:, 4] ** 2
        d = a[:, 0] * a[:, 4] - a[:, 1] * a[:, 3]
        # (T - sqrt(T^2 - 4 D^2)) / 2 = 2 D^2 / (T + sqrt(T^2 - 4 D^2)): no cancellation
        s = np.sqrt(2.0 * d * d / (t + np.sqrt(np.maximum(t * t - 4.0 * d * d, 0.0))))
    return np.asarray(length0, dtype=float) * s


def viscous_pressure(
    rate: np.ndarray,
    J: np.ndarray,
    rho0: float | np.ndarray,
    c: float | np.ndarray,
    length: np.ndarray,
    quadratic: float | np.ndarray,
    linear: float | np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``(q, factor)`` (m,) of the module docstring at the rate ``rate`` and the volume ratio
    ``J`` of points of current length ``length`` (:func:`current_lengths`), reference density
    ``rho0`` and wave speed ``c``: the viscous pressure (0 where the point expands) and ``(b +
    sqrt(b^2 + c^2)) / c >= 1``, the factor by which it lowers the point's stable step (1 where
    it expands)."""
    compressing = rate < 0.0
    q = rho0 / J * length * (quadratic**2 * length * rate**2 - linear * c * rate)
    b = np.where(compressing, 2.0 * quadratic**2 * length * np.abs(rate) + linear * c, 0.0)
    return np.where(compressing, q, 0.0), (b + np.sqrt(b * b + c * c)) / c


def particle_lengths(positions: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The reference length of points (m, gdim) of a particle rule: the nearest particle's
    distance to its own nearest neighbour (the local particle spacing; positions (n, gdim))."""
    positions, points = np.asarray(positions, dtype=float), np.asarray(points, dtype=float)
    if len(points) == 0:
        return np.zeros(0)
    if len(positions) < 2:
        raise ValueError(
            f"particle_lengths: {len(positions)} particle(s) give no spacing; a particle side "
            "needs two at least"
        )
    tree = cKDTree(positions)
    spacing = tree.query(positions, k=2)[0][:, 1]
    return spacing[tree.query(points, k=1)[1]]
