"""Johnson–Cook plasticity (isothermal) as a rate-form material point for explicit dynamics.

G.R. Johnson and W.H. Cook, "A constitutive model and data for metals subjected to large
strains, high strain rates and high temperatures", 7th International Symposium on Ballistics,
The Hague, 1983, pp. 541–547, eq. 1 without its thermal factor: the von Mises flow stress::

    sigma_y = (A + B eps_p^n) (1 + C ln(eps_rate / eps0)),

the rate term only for ``eps_rate > eps0`` (a quasi-static floor), ``eps_rate = sqrt(2/3 e:e)``
the step's deviatoric strain rate (as explicit codes take it, so that the return stays a
function of the step alone). The projectile steel of Rabczuk, Xiao & Sauer 2006, sec. 6.2.2
(Hanchak's 4340 ogive-nosed rod) is of this kind; :meth:`JohnsonCook.steel_4340` gives Johnson
and Cook's 4340 steel (Rc 30) constants. Isothermal: the thermal softening ``1 - T*^m`` is left
out (an impact's adiabatic heating softens the projectile; a rigid or elastic projectile is the
usual simplification when it barely deforms).

The pressure is the hypo-elastic one integrated exactly, ``p = -K ln J`` (``K`` the bulk modulus
of ``E`` and ``nu``), the deviator the rate form of :mod:`~dolfinx_meshfree.physics.objective`
(Jaumann rate, symmetric Hughes–Winget step) with a radial return: ``q_trial - 3 G d eps_p =
sigma_y(eps_p + d eps_p)``, solved by bisection (the flow stress rises with the plastic strain,
so the root is unique; the hardening's slope is infinite at ``eps_p = 0`` for ``n < 1``, which
rules plain Newton out at first yield). The compiled backend (``backend="numba"``, the default
with numba) finds the same root by Newton's steps kept inside the bisection's bracket, a
bisection wherever a step would leave it (:func:`~dolfinx_meshfree.physics.rate_kernels.
_jc_return`). The state also carries ``F`` and the stress work per unit reference volume.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import ClassVar

import numpy as np

from . import rate_kernels
from .bulk_viscosity import DEFAULT_VISCOSITY, BulkViscosity, check_viscosity
from .objective import RateStep, check_arguments, check_step, virgin_state

__all__ = ["JohnsonCook"]

_EYE = np.eye(3)
#: Bisection steps of the radial return (the bracket shrinks by 2^-60).
_BISECTIONS = 60


@dataclass(frozen=True)
class JohnsonCook:
    """Johnson–Cook plasticity without temperature (module docstring).

    Args:
        rho: Reference density. E, nu: Young's modulus and Poisson's ratio. A, B, n: Initial
            yield stress, hardening modulus and exponent (``0 < n <= 1``). C: Strain-rate
            coefficient. eps0: Reference strain rate (1/s in SI). plane: ``None`` (3D),
            ``"strain"`` (2D) or ``"axisymmetric"`` (2D; :meth:`update` takes the hoop stretch).
        viscosity: The artificial bulk viscosity of explicit dynamics, as
            :class:`~dolfinx_meshfree.physics.hjc.HolmquistJohnsonCook`'s (``None``: none).
        backend: ``"numba"`` (the default with numba: one compiled pass over the points,
            :mod:`~dolfinx_meshfree.physics.rate_kernels`) or ``"numpy"`` (the reference); as
            :class:`~dolfinx_meshfree.physics.hjc.HolmquistJohnsonCook`'s.
    """

    rho: float
    E: float
    nu: float
    A: float
    B: float
    n: float
    C: float
    eps0: float = 1.0
    plane: str | None = None
    viscosity: BulkViscosity | None = DEFAULT_VISCOSITY
    backend: str | None = field(default=None, compare=False)

    #: State arrays per point: the deviatoric Cauchy stress (row-major 3 x 3), the pressure, the
    #: equivalent plastic strain, the stress work per unit reference volume and ``F``.
    state_fields: ClassVar[dict[str, int]] = {
        "deviator": 9,
        "pressure": 1,
        "plastic_strain": 1,
        "work": 1,
        "F": 9,
    }
    #: Its plastic flow keeps the volume: P1 triangles and tetrahedra, and Q1 at its full rule,
    #: lock under it (:mod:`~dolfinx_meshfree.dynamics.rate_dilatation`).
    isochoric_flow: ClassVar[bool] = True

    @classmethod
    def steel_4340(
        cls,
        plane: str | None = None,
        backend: str | None = None,
        viscosity: BulkViscosity | None = DEFAULT_VISCOSITY,
    ) -> JohnsonCook:
        """4340 steel (Rc 30) of Johnson & Cook 1983, Table 1, in SI units: rho 7830, E 200 GPa,
        nu 0.29, A 792 MPa, B 510 MPa, n 0.26, C 0.014."""
        return cls(
            rho=7830.0, E=200e9, nu=0.29, A=792e6, B=510e6, n=0.26, C=0.014, plane=plane,
            backend=backend, viscosity=viscosity,
        )  # fmt: skip

    def __post_init__(self) -> None:
        rate_kernels.resolve_backend(self.backend)
        check_viscosity("JohnsonCook", self.viscosity)

        def refuse(name: str, rule: str, fix: str) -> None:
            raise ValueError(f"JohnsonCook: {name}={getattr(self, name)!r} {rule}; {fix}")

        for name in ("rho", "E", "A", "eps0"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                refuse(name, "must be a positive finite number", "give it in consistent units")
        for name in ("B", "C"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value >= 0):
                refuse(name, "must be a finite number >= 0", "give 0 to leave the term out")
        if not (isinstance(self.nu, int | float) and -1.0 < self.nu < 0.5):
            refuse("nu", "must lie in (-1, 0.5)", "give a Poisson ratio in range")
        if not (isinstance(self.n, int | float) and 0.0 < self.n <= 1.0):
            refuse("n", "must lie in (0, 1]", "the hardening exponent of Johnson and Cook")
        if self.plane not in (None, "strain", "axisymmetric"):
            refuse(
                "plane", "is not None (3D), 'strain' or 'axisymmetric'",
                "plane stress has no out-of-plane strain; use 3D, plane strain or axisymmetry",
            )  # fmt: skip

    @property
    def gdim(self) -> int:
        """3, or 2 for ``plane="strain"`` and ``"axisymmetric"``."""
        return 3 if self.plane is None else 2

    @property
    def G(self) -> float:
        """The shear modulus ``E / (2 (1 + nu))``."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def K(self) -> float:
        """The bulk modulus ``E / (3 (1 - 2 nu))``."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))

    @property
    def stiffest_bulk_modulus(self) -> float:
        """``K`` (the hypo-elastic pressure's tangent ``K / J`` grows as ``J`` falls; the run's
        wave-speed check covers it)."""
        return self.K

    def flow_stress(self, plastic_strain: np.ndarray, rate: np.ndarray) -> np.ndarray:
        """``sigma_y = (A + B eps_p^n) (1 + C ln max(rate / eps0, 1))``."""
        ratio = np.maximum(np.asarray(rate, dtype=float) / self.eps0, 1.0)
        eps_p = np.maximum(np.asarray(plastic_strain, dtype=float), 0.0)
        return (self.A + self.B * eps_p**self.n) * (1.0 + self.C * np.log(ratio))

    def initial_state(self, m: int) -> dict[str, np.ndarray]:
        """The virgin, stress-free state of ``m`` points (``F = I``)."""
        return virgin_state(self.state_fields, m)

    def update(
        self,
        F: np.ndarray,
        dt: float,
        state: dict[str, np.ndarray],
        hoop: np.ndarray | None = None,
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """``(sigma (m, 3, 3), new state)`` at ``F`` ``(m, d, d)`` after a step ``dt`` from the
        committed ``state`` (never modified); ``hoop`` as in
        :meth:`~dolfinx_meshfree.physics.hjc.HolmquistJohnsonCook.update` (and its hand-over
        of a step the compiled backend cannot take to the reference)."""
        if rate_kernels.resolve_backend(self.backend) == "numba":
            check_arguments(self, F, dt, state, hoop)
            sigma, new, flags = rate_kernels.johnson_cook_update(
                self._constants, _BISECTIONS, F, hoop, dt, state, self.state_fields
            )
            if not flags.any():
                return sigma, new
        return self._update_reference(F, dt, state, hoop)

    @cached_property
    def _constants(self) -> np.ndarray:
        """The parameters in the order :mod:`rate_kernels` takes them."""
        return np.array([getattr(self, n) for n in rate_kernels.JC_PARAMETERS], dtype=float)

    def _update_reference(
        self,
        F: np.ndarray,
        dt: float,
        state: dict[str, np.ndarray],
        hoop: np.ndarray | None = None,
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """:meth:`update` by whole-array operations (the ``"numpy"`` backend, the reference)."""
        F3, J = check_step(self, F, dt, state, hoop)
        m = len(F3)
        step = RateStep.start(state["F"].reshape(m, 3, 3), F3, state["deviator"].reshape(m, 3, 3))
        s_trial = step.s_rot + 2.0 * self.G * step.e
        q = np.sqrt(1.5 * np.einsum("qij,qij->q", s_trial, s_trial))
        rate = step.equivalent_rate(dt)
        eps_p = state["plastic_strain"][:, 0]
        yielding = q > self.flow_stress(eps_p, rate)
        lo, hi = np.zeros(m), np.where(yielding, q / (3.0 * self.G), 0.0)
        for _ in range(_BISECTIONS):  # q - 3 G d - sigma_y(eps_p + d) falls with d
            mid = 0.5 * (lo + hi)
            above = q - 3.0 * self.G * mid > self.flow_stress(eps_p + mid, rate)
            lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
        d_eps_p = np.where(yielding, 0.5 * (lo + hi), 0.0)
        scale = np.where(yielding, 1.0 - 3.0 * self.G * d_eps_p / np.where(q > 0, q, 1.0), 1.0)
        s_mid = scale[:, None, None] * s_trial
        p = -self.K * np.log(J)
        sigma = step.rotate(s_mid) - p[:, None, None] * _EYE
        new = {
            "deviator": step.rotate(s_mid).reshape(m, 9),
            "pressure": p[:, None],
            "plastic_strain": (eps_p + d_eps_p)[:, None],
            "work": state["work"] + step.work(state["pressure"][:, 0], s_mid, p)[:, None],
            "F": F3.reshape(m, 9),
        }
        return sigma, new

    def wave_speed(self, state: dict[str, np.ndarray] | None = None) -> float:
        """The dilatational wave speed ``sqrt((K + 4 G / 3) / rho)`` at the reference density,
        or the largest over the points of ``state`` at their current density ``rho_0 / J`` (0
        without points)."""
        c2 = (self.K + 4.0 * self.G / 3.0) / self.rho
        if state is None:
            return float(np.sqrt(c2))
        J = np.linalg.det(state["F"].reshape(-1, 3, 3))
        return float(np.sqrt(c2 * np.max(J, initial=0.0)))
