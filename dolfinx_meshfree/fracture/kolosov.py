"""Plane elasticity from Kolosov–Muskhelishvili complex potentials: displacement, displacement
gradient and stress from ``phi(z)``, ``psi(z)`` and their derivatives (Muskhelishvili 1953,
sec. 32–33), and the elastic constants ``kappa`` and ``E'`` of a 2D law."""

from __future__ import annotations

import numpy as np

from ..physics.materials import LinearElastic

__all__ = ["PotentialField", "effective_modulus", "kolosov_constant", "kolosov_fields"]


def _check_2d(material: LinearElastic) -> None:
    if material.plane not in ("stress", "strain"):
        raise ValueError(
            f"material plane={material.plane!r}: fracture fields are 2D; use "
            f"LinearElastic(E, nu, plane='stress') or plane='strain'"
        )


def kolosov_constant(material: LinearElastic) -> float:
    """``kappa = 3 - 4 nu`` (plane strain) or ``(3 - nu) / (1 + nu)`` (plane stress)."""
    _check_2d(material)
    nu = material.nu
    return 3.0 - 4.0 * nu if material.plane == "strain" else (3.0 - nu) / (1.0 + nu)


def effective_modulus(material: LinearElastic) -> float:
    """``E' = E`` (plane stress) or ``E / (1 - nu^2)`` (plane strain), so that
    ``J = (K_I^2 + K_II^2) / E'``."""
    _check_2d(material)
    E, nu = material.E, material.nu
    return E / (1.0 - nu**2) if material.plane == "strain" else E


def kolosov_fields(
    z: np.ndarray,
    phi: np.ndarray,
    dphi: np.ndarray,
    d2phi: np.ndarray,
    psi: np.ndarray,
    dpsi: np.ndarray,
    material: LinearElastic,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fields of the potentials at points ``z = x + i y`` (all arrays complex, shape (m,)).

    .. math::
        2\\mu (u_x + i u_y) = \\kappa\\phi - z\\overline{\\phi'} - \\overline{\\psi},\\quad
        \\sigma_{xx} + \\sigma_{yy} = 4\\,\\mathrm{Re}\\,\\phi',\\quad
        \\sigma_{yy} - \\sigma_{xx} + 2i\\sigma_{xy} = 2(\\bar z\\phi'' + \\psi').

    The gradient follows from ``2 mu du/dz = kappa phi' - conj(phi')`` and
    ``2 mu du/dzbar = -z conj(phi'') - conj(psi')``.

    Returns:
        u (m, 2), grad (m, 2, 2) with ``grad[:, i, j] = du_i/dx_j``, sigma (m, 2, 2).
    """
    mu, kappa = material.mu, kolosov_constant(material)
    u = (kappa * phi - z * np.conj(dphi) - np.conj(psi)) / (2.0 * mu)
    du_dz = (kappa * dphi - np.conj(dphi)) / (2.0 * mu)
    du_dzbar = -(z * np.conj(d2phi) + np.conj(dpsi)) / (2.0 * mu)
    du_dx = du_dz + du_dzbar
    du_dy = 1j * (du_dz - du_dzbar)
    grad = np.empty((len(z), 2, 2))
    grad[:, 0, 0], grad[:, 1, 0] = du_dx.real, du_dx.imag
    grad[:, 0, 1], grad[:, 1, 1] = du_dy.real, du_dy.imag
    s = 4.0 * dphi.real
    d = 2.0 * (np.conj(z) * d2phi + dpsi)
    sigma = np.empty((len(z), 2, 2))
    sigma[:, 0, 0] = 0.5 * (s - d.real)
    sigma[:, 1, 1] = 0.5 * (s + d.real)
    sigma[:, 0, 1] = sigma[:, 1, 0] = 0.5 * d.imag
    return np.stack([u.real, u.imag], axis=1), grad, sigma


class PotentialField:
    """Accessors shared by the exact plane fields: a subclass defines ``fields(points)``
    returning displacement (m, 2), displacement gradient (m, 2, 2) (``[:, i, j] = du_i/dx_j``)
    and stress (m, 2, 2) at global points (m, 2), in global components."""

    def fields(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

    def displacement(self, points: np.ndarray) -> np.ndarray:
        """Displacement (m, 2) at global points (m, 2)."""
        return self.fields(points)[0]

    def displacement_gradient(self, points: np.ndarray) -> np.ndarray:
        """Displacement gradient (m, 2, 2), ``[:, i, j] = du_i/dx_j``, at global points."""
        return self.fields(points)[1]

    def stress(self, points: np.ndarray) -> np.ndarray:
        """Cauchy stress (m, 2, 2) at global points (m, 2)."""
        return self.fields(points)[2]
