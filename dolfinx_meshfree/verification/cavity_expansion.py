"""Cavity expansion in a rate-form material, and the force it puts on an ogive nose.

What a perfectly resolved penetration model of a material resists with, computed in 1D, apart
from the package's 2D and 3D discretisations. A rigid projectile's nose meets the target's
normal stress ``sigma_n``; the spherical cavity-expansion approximation (Forrestal & Luk, *Int.
J. Impact Eng.* 12, 1992; Forrestal & Tzou, *Int. J. Solids Struct.* 34, 1997) takes
``sigma_n`` as the radial stress at the wall of a spherical cavity expanded from zero radius at
the nose's normal speed ``V cos theta``. For a tangent ogive of shank radius ``a`` and
caliber-radius-head ``psi`` (arc radius ``s = 2 psi a``) without friction the axial force is

.. math::
    F = 2 \\pi s^2 \\int_{\\theta_0}^{\\pi/2}
        \\Big(\\sin\\theta - \\frac{s - a}{s}\\Big) \\cos\\theta\\;
        \\sigma_r(V \\cos\\theta)\\, d\\theta, \\qquad \\sin\\theta_0 = \\frac{s - a}{s}

(:func:`ogive_force`): ``pi a^2 sigma`` for a constant ``sigma``, and ``pi a^2 N* c V^2`` with
``N* = (8 psi - 1) / (24 psi^2)`` for ``sigma = c V_n^2``.

**The cavity** (:func:`cavity_expansion`): a total-Lagrangian 1D explicit computation (lumped
masses, central differences) of a sphere of the material, or a cylinder in plane strain along
its axis, around a cavity of reference radius ``a0 = radius / growth`` whose wall is driven
outward at ``velocity`` (ramped up over 2 % of the run) until the cavity's radius is
``radius``. The zones' deformation gradients are ``diag(lambda_r, lambda_t, lambda_t)`` (the
sphere) or ``diag(lambda_r, lambda_t, 1)`` (the cylinder), ``lambda_r = dr / dR`` and
``lambda_t = r / R`` at the zone's middle, given to the material's own update
(``law.update(F, dt, state)``); the nodal forces are the first Piola stresses' ``P_rr = J
sigma_rr / lambda_r``, ``P_tt = J sigma_tt / lambda_t`` (each hoop direction) on the zones'
reference volumes. The reference mesh is graded so that the final one is: zones of ``radius /
cells`` at the wall growing by ``grading`` out to ``extent`` radii (``R^3 = a0^3 + r^3 -
radius^3``, ``R^2 = a0^2 + r^2 - radius^2`` for the cylinder: the incompressible maps), the
outer surface held (the elastic wave does not come back within the run). A von
Neumann–Richtmyer viscosity (quadratic 1.5, linear 0.06) acts in compression; the step
follows the current thinnest zone and the material's current wave speed (the wall zones thin
by ``(a0 / a)^2``). The cavity pressure is the wall's reaction over its current area,
averaged over the last 30 % of the growth, where the expansion is self-similar (it is steady
from about ``a = 8 a0``).

Verified against Hill's closed form for an elastic–perfectly-plastic Mises solid
(:func:`hill_cavity_pressure`, after the inertial ``3/2 rho V^2``; within 0.5 %,
``tests/test_cavity_expansion.py``), and independent of the mesh, the viscosity and ``growth``
to 0.1 % for the HJC concrete (measured: the sphere 11.4 ``fc`` at 50 m/s and 24.9 ``fc`` at 430
m/s; the cylinder 28.9 ``fc`` at 430 m/s, which the package's axisymmetric FE model of the
same cylinder meets, ``tests/test_cavity_expansion.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = [
    "CavityExpansion",
    "RateFormLaw",
    "cavity_expansion",
    "cavity_pressure_curve",
    "hill_cavity_pressure",
    "ogive_force",
]

#: von Neumann–Richtmyer's quadratic and linear coefficients, and the fraction of the run over
#: which the wall's speed is ramped up.
VISCOSITY, RAMP = (1.5, 0.06), 0.02
#: The cavities: their hoop directions (the sphere's two, the cylinder's one).
SHAPES = {"sphere": 2, "cylinder": 1}


class RateFormLaw(Protocol):
    """What the cavity needs of a 3D rate-form material point (``HolmquistJohnsonCook``,
    ``JohnsonCook`` with ``plane=None``)."""

    rho: float

    def initial_state(self, m: int) -> dict[str, np.ndarray]: ...

    def update(
        self, F: np.ndarray, dt: float, state: dict[str, np.ndarray]
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]: ...

    def wave_speed(self, state: dict[str, np.ndarray] | None = None) -> float: ...


@dataclass(frozen=True)
class CavityExpansion:
    """A cavity expanded at ``velocity`` (:func:`cavity_expansion`).

    Attributes:
        shape: ``"sphere"`` or ``"cylinder"``.
        velocity: The wall's speed.
        pressure: The steady cavity pressure (compression positive): the mean over the last
            30 % of the growth.
        spread: Its standard deviation there (how steady it was).
        radius: The cavity's radius over the run (sampled).
        history: The cavity pressure at those radii.
        zones: The zones of the 1D mesh.
        steps: The time steps taken.
    """

    shape: str
    velocity: float
    pressure: float
    spread: float
    radius: np.ndarray
    history: np.ndarray
    zones: int
    steps: int


def hill_cavity_pressure(E: float, nu: float, Y: float) -> float:
    """Hill's quasi-static pressure of a spherical cavity expanded from zero radius in an
    elastic–perfectly-plastic Mises solid (*The Mathematical Theory of Plasticity*, 1950, ch.
    V): ``p = 2 Y / 3 [1 + ln(E / (3 (1 - nu) Y))]``."""
    if not (E > 0 and Y > 0 and -1.0 < nu < 0.5 and E > 3 * (1 - nu) * Y):
        raise ValueError(
            f"hill_cavity_pressure: E={E!r}, nu={nu!r}, Y={Y!r}: need E > 0, Y > 0, "
            "-1 < nu < 0.5 and E > 3 (1 - nu) Y (a plastic zone larger than the cavity)"
        )
    return 2.0 * Y / 3.0 * (1.0 + np.log(E / (3.0 * (1.0 - nu) * Y)))


def _reference_radii(
    a0: float, radius: float, cells: int, grading: float, extent: float, dim: int
) -> np.ndarray:
    """The reference nodes whose final positions are graded from the wall: ``radius / cells``
    there, growing by ``grading`` to ``extent`` radii (the incompressible map of a cavity of
    ``dim`` = 3, a sphere, or 2, a cylinder)."""
    r, h = [radius], radius / cells
    while r[-1] < extent * radius:
        r.append(r[-1] + h)
        h *= grading
    r = np.array(r)
    R = np.cbrt(a0**3 + r**3 - radius**3) if dim == 3 else np.sqrt(a0**2 + r**2 - radius**2)
    R[0] = a0
    return R


def cavity_expansion(
    law: RateFormLaw,
    velocity: float,
    radius: float = 0.0127,
    shape: str = "sphere",
    growth: float = 20.0,
    cells: int = 40,
    grading: float = 1.03,
    extent: float = 60.0,
    cfl: float = 0.5,
) -> CavityExpansion:
    """A cavity of ``shape`` (``"sphere"``, or ``"cylinder"`` in plane strain along its axis)
    expanded at ``velocity`` to ``radius`` from ``radius / growth`` in ``law``, and its steady
    pressure (module docstring; ``cells`` zones per ``radius`` at the wall; ``radius`` matters
    through a rate term only: the strain rate is about ``velocity / radius``). SI units or any
    consistent set."""
    checks = {
        "shape": shape in SHAPES,
        "velocity": velocity > 0,
        "radius": radius > 0,
        "growth": growth >= 4,
        "cells": isinstance(cells, int) and cells >= 4,
        "grading": 1.0 <= grading <= 1.2,
        "extent": extent >= 4,
        "cfl": 0.0 < cfl <= 0.9,
    }
    for name, ok in checks.items():
        if not ok:
            raise ValueError(
                f"cavity_expansion: {name}={locals()[name]!r} is out of range (shape 'sphere' or "
                "'cylinder', velocity > 0, radius > 0, growth >= 4 for a self-similar "
                "expansion, cells >= 4, grading in [1, 1.2], extent >= 4, cfl in (0, 0.9])"
            )
    if getattr(law, "plane", None) is not None:
        raise ValueError(
            f"cavity_expansion: law has plane={law.plane!r}; the cavity is 3D: give "
            "the law with plane=None (dataclasses.replace(law, plane=None))"
        )
    cq, cl = VISCOSITY
    hoops = SHAPES[shape]
    a0 = radius / growth
    R = _reference_radii(a0, radius, cells, grading, extent, hoops + 1)
    n = len(R) - 1
    dR, Rm = np.diff(R), 0.5 * (R[1:] + R[:-1])
    if hoops == 2:
        volume = 4.0 * np.pi / 3.0 * (R[1:] ** 3 - R[:-1] ** 3)
    else:  # per unit length
        volume = np.pi * (R[1:] ** 2 - R[:-1] ** 2)
    mass = np.zeros(n + 1)
    mass[:-1] += 0.5 * law.rho * volume
    mass[1:] += 0.5 * law.rho * volume
    t_end = (radius - a0) / velocity
    ramp = RAMP * t_end

    def wall(t: float) -> float:
        return velocity * min(1.0, t / ramp)

    u, v = np.zeros(n + 1), np.zeros(n + 1)
    state = law.initial_state(n)
    F = np.zeros((n, 3, 3))
    F[:, 2, 2] = 1.0  # the cylinder's axis
    J_old, t, steps = np.ones(n), 0.0, 0
    dt = cfl * dR.min() / law.wave_speed()
    samples = []
    while t < t_end:
        v[0] = wall(t + 0.5 * dt)
        u += dt * v
        r = R + u
        lr, lt = np.diff(r) / dR, 0.5 * (r[1:] + r[:-1]) / Rm
        F[:, 0, 0], F[:, 1, 1] = lr, lt
        if hoops == 2:
            F[:, 2, 2] = lt
        sigma, state = law.update(F, dt, state)
        J, length = lr * lt**hoops, lr * dR
        rate = (J - J_old) / (dt * 0.5 * (J + J_old))
        J_old = J
        c = law.wave_speed(state)
        q = np.where(
            rate < 0, law.rho / J * (cq**2 * length**2 * rate**2 - cl * c * length * rate), 0.0
        )
        P_rr = J * (sigma[:, 0, 0] - q) / lr
        hoop = sigma[:, 1, 1] if hoops == 1 else 0.5 * (sigma[:, 1, 1] + sigma[:, 2, 2])
        P_tt = J * (hoop - q) / lt
        f = np.zeros(n + 1)  # dW = volume (P_rr d lambda_r + hoops P_tt d lambda_t)
        f[:-1] += volume * (-P_rr / dR + hoops * P_tt / (2.0 * Rm))
        f[1:] += volume * (P_rr / dR + hoops * P_tt / (2.0 * Rm))
        # Wilkins' step with the viscosity: length / (b + sqrt(b^2 + c^2))
        b = np.where(rate < 0, 2.0 * cq**2 * length * np.abs(rate), 0.0) + cl * c
        dt_new = cfl * float(np.min(length / (b + np.sqrt(b * b + c * c))))
        if not (np.isfinite(dt_new) and dt_new > 0.0):
            raise RuntimeError(
                f"cavity_expansion: the step collapsed at a = {r[0]:.4g} "
                f"(velocity={velocity!r}): a zone inverted; try more cells"
            )
        v -= 0.5 * (dt + dt_new) * f / mass
        v[-1] = 0.0
        t += dt
        dt = dt_new
        steps += 1
        area = 4.0 * np.pi * r[0] ** 2 if hoops == 2 else 2.0 * np.pi * r[0]
        samples.append((r[0], f[0] / area))
    a, p = np.array(samples).T
    late = a >= a0 + 0.7 * (radius - a0)
    return CavityExpansion(
        shape=shape,
        velocity=float(velocity),
        pressure=float(p[late].mean()),
        spread=float(p[late].std()),
        radius=a[::10],
        history=p[::10],
        zones=n,
        steps=steps,
    )


def ogive_force(
    pressure: Callable[[np.ndarray], np.ndarray], velocity: float, radius: float, crh: float
) -> float:
    """The axial force on a rigid tangent ogive (shank radius ``radius``, caliber-radius-head
    ``crh``) moving at ``velocity``, frictionless, with the normal stress ``pressure(V_n)`` at
    the normal speed ``V_n = velocity cos theta`` (module docstring's integral, 2,001-point
    Simpson rule)."""
    if not (radius > 0 and crh >= 0.5 and velocity >= 0):
        raise ValueError(
            f"ogive_force: radius={radius!r}, crh={crh!r}, velocity={velocity!r}: need radius > "
            "0, crh >= 0.5 (a tangent ogive) and velocity >= 0"
        )
    s = 2.0 * crh * radius
    k = (s - radius) / s
    theta = np.linspace(np.arcsin(k), 0.5 * np.pi, 2001)
    f = (np.sin(theta) - k) * np.cos(theta) * pressure(velocity * np.cos(theta))
    h = theta[1] - theta[0]
    simpson = h / 3.0 * (f[0] + f[-1] + 4.0 * f[1:-1:2].sum() + 2.0 * f[2:-1:2].sum())
    return float(2.0 * np.pi * s * s * simpson)


def cavity_pressure_curve(
    law: RateFormLaw, speeds: np.ndarray, radius: float, cells: int = 40
) -> tuple[Callable[[np.ndarray], np.ndarray], list[CavityExpansion]]:
    """``law``'s spherical cavity pressure against the wall's speed: cavities expanded at
    ``speeds`` (increasing, > 0; :func:`cavity_expansion` to ``radius``, ``cells`` zones per
    radius), linear between them and held at the end values beyond (below the slowest: for the
    HJC concrete the pressure at 10 m/s is 4 % below the one at 50). Returns the curve and the
    cavities."""
    speeds = np.asarray(speeds, dtype=float)
    if speeds.ndim != 1 or len(speeds) < 2 or speeds[0] <= 0 or np.any(np.diff(speeds) <= 0):
        raise ValueError(
            f"cavity_pressure_curve: speeds={speeds!r}: give two or more increasing speeds > 0"
        )
    cavities = [cavity_expansion(law, float(w), radius, cells=cells) for w in speeds]
    pressures = np.array([c.pressure for c in cavities])

    def curve(w: np.ndarray) -> np.ndarray:
        return np.interp(w, speeds, pressures)

    return curve, cavities
