"""The Holmquist–Johnson–Cook (HJC) concrete as a rate-form material point for explicit dynamics.

T.J. Holmquist, G.R. Johnson and W.H. Cook, "A computational constitutive model for concrete
subjected to large strains, high strain rates, and high pressures", 14th International
Symposium on Ballistics, Quebec, 1993, pp. 591–600 (LS-DYNA ``*MAT_JOHNSON_HOLMQUIST_CONCRETE``,
MAT_111). The concrete of Rabczuk, Xiao & Sauer 2006, sec. 6.2.2 (the Hanchak slab) is of this
kind: pressure-dependent strength, a strain-rate term, damage from plastic and crushing strain
and a three-region equation of state with crush and lock. Units are the user's (SI in the
examples); pressure ``P`` is positive in compression, ``P* = P / fc``, ``T* = T / fc``.

**Strength** (HJC eq. 1), the normalised von Mises stress ``sigma* = q / fc``::

    sigma* = [A (1 - D) + B P*^N] [1 + C ln(eps_rate / eps0)],   P* >= 0,   sigma* <= SFMAX,

the rate term only for ``eps_rate > eps0`` (a quasi-static floor), ``eps_rate = sqrt(2/3 e:e)``
the deviatoric strain rate. In tension (``P* < 0``) HJC gives no form; here the strength falls
linearly from ``A (1 - D)`` at ``P* = 0`` to zero at the pressure cut-off ``P* = -T* (1 - D)``:
``sigma* = A (1 - D + P* / T*)`` (times the rate term), so that a fully damaged point (``D = 1``)
carries no tensile and no deviatoric stress at ``P <= 0`` and only the crushed material's
frictional ``B P*^N`` under compression. Nothing is deleted: a failed point keeps its mass.

**Damage** (HJC eq. 2), from the equivalent plastic strain ``eps_p`` and the plastic volumetric
strain ``mu_p``::

    dD = (d eps_p + d mu_p) / eps_f,     eps_f = max(EFMIN, D1 (P* + T*)^D2),     D <= 1.

**Equation of state** (HJC eq. 3–5), ``mu = rho / rho_0 - 1 = 1 / J - 1`` with its largest value
``mu_max`` reached so far:

* region I (elastic), ``mu <= mu_crush``: ``P = K_e mu``, ``K_e = P_crush / mu_crush``;
* region II (air voids crush), ``mu_crush < mu <= mu_plock``: loading along
  ``P = P_crush + (P_lock - P_crush) (mu - mu_crush) / (mu_plock - mu_crush)``; unloading from
  ``mu_max`` with the interpolated modulus ``K = (1 - F) K_e + F K1``,
  ``F = (mu_max - mu_crush) / (mu_plock - mu_crush)``;
* region III (fully dense), ``mu > mu_plock``: ``P = K1 mu_bar + K2 mu_bar^2 + K3 mu_bar^3`` with
  ``mu_bar = (mu - mu_lock) / (1 + mu_lock)`` on loading.

``mu_plock`` is where the fully dense curve reaches ``P_lock``, so the loading curve is
continuous. HJC unload region III along ``P = K1 mu_bar``, which does not pass through the state
reached (the pressure would jump on unloading); here region III unloads from ``(mu_max,
P(mu_max))`` with the modulus ``max(K1, dP/dmu)``, the largest of the fully dense modulus and the
loading tangent, which keeps ``P`` continuous and ``mu_p`` non-decreasing (no negative
dissipation). The permanent strain ``mu_p`` is the unloading line's zero. In tension the pressure
is cut off at ``-T (1 - D)``.

**The update** (rate form, Jaumann rate by the Hughes–Winget algorithm of
:mod:`~dolfinx_meshfree.physics.objective`, split symmetrically): the deviatoric Cauchy stress is
rotated by the half rotation ``Q_h``, incremented elastically with ``2 G dev(d eps)``, scaled back
onto the strength surface of the step's pressure and the damage at its start (radial return,
``d eps_p = (q_trial - sigma_y) / (3 G)``) and rotated by ``Q_h`` again; the pressure comes from
the equation of state of the current ``J``, and ``sigma = s - P I``. The state also carries ``F``
(the gradient of the last update, from which the next one's increment is taken) and the stress
work per unit reference volume ``sum J_{n+1/2} (sigma_n + sigma_{n+1}) / 2 : d eps``
(trapezoidal, both stresses seen in the mid-step frame), the internal energy an explicit run's
balance needs.

**Erosion** (``erosion=eps_e``, off by default): a point whose deformation inverts
(``det F <= 0``), or which is fully damaged (``D = 1``) with ``eps_p >= eps_e``, is eroded: it
carries no stress from then on and its state stays as it was (``eroded = 1``). Its mass stays
where it was (the nodes' and particles', which a projectile still pushes): nothing is deleted.
The stress work done on it stays in ``work``, so the energy balance closes; what it would have
released is dissipated. This is the Lagrangian codes' erosion with the mass retained, the way a
total-Lagrangian model (FE, or particles whose neighbours are fixed in the reference
configuration) lets a projectile pass through material it has crushed. Without erosion an
inverted point stops the run (:class:`~dolfinx_meshfree.physics.constitutive.DeformationError`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import ClassVar

import numpy as np

from . import rate_kernels
from .bulk_viscosity import DEFAULT_VISCOSITY, BulkViscosity, check_viscosity
from .objective import RateStep, as_3d, check_arguments, check_step, virgin_state

__all__ = ["HolmquistJohnsonCook"]

_EYE = np.eye(3)


def _refuse(name: str, value: float, rule: str, fix: str) -> None:
    raise ValueError(f"HolmquistJohnsonCook: {name}={value!r} {rule}; {fix}")


@dataclass(frozen=True)
class HolmquistJohnsonCook:
    """Holmquist–Johnson–Cook concrete (module docstring), the parameters of LS-DYNA's MAT_111.

    Args:
        rho: Reference density. G: Shear modulus. A, B, N: Normalised cohesive strength, pressure
            hardening coefficient and exponent. C: Strain-rate coefficient. fc: Uniaxial
            compressive strength. T: Maximum hydrostatic tension (the pressure cut-off of intact
            concrete, > 0). efmin: Least plastic strain to fracture. sfmax: Largest normalised
            strength. p_crush, mu_crush: Crushing pressure and volumetric strain (region I ends).
            p_lock, mu_lock: Locking pressure and volumetric strain (``mu_lock = rho_grain / rho
            - 1``, where the voids are gone). D1, D2: Damage constants. K1, K2, K3: The fully dense
            pressure's coefficients. eps0: The reference strain rate of the rate term (1/s in SI).
            plane: ``None`` (3D), ``"strain"`` (a 2D model's ``F_zz = 1``) or
            ``"axisymmetric"`` (the (r, z) section of a solid of revolution: :meth:`update`
            takes the hoop stretch ``r / R`` as ``F_zz``).
        viscosity: The artificial bulk viscosity that spreads a shock in explicit dynamics
            (:class:`~dolfinx_meshfree.BulkViscosity`, LS-DYNA's default coefficients);
            ``None`` leaves it out (the law's own stress only: a shock rings).
        erosion: ``None`` (default: an inverted point stops the run), or the equivalent
            plastic strain ``eps_e > 0`` at which a fully damaged point erodes; an inverted
            point erodes too (module docstring).
        backend: ``"numba"`` (the default with numba: :mod:`~dolfinx_meshfree.physics.rate_kernels`,
            one compiled pass over the points) or ``"numpy"`` (the reference, whole-array
            operations); the two agree to round-off. ``None``: the default, which
            ``DOLFINX_MESHFREE_LAW_BACKEND`` overrides.

    :meth:`concrete_48mpa` gives the published 48 MPa set (SI units).
    """

    rho: float
    G: float
    A: float
    B: float
    N: float
    C: float
    fc: float
    T: float
    efmin: float
    sfmax: float
    p_crush: float
    mu_crush: float
    p_lock: float
    mu_lock: float
    D1: float
    D2: float
    K1: float
    K2: float
    K3: float
    eps0: float = 1.0
    plane: str | None = None
    erosion: float | None = None
    viscosity: BulkViscosity | None = DEFAULT_VISCOSITY
    backend: str | None = field(default=None, compare=False)

    #: State arrays per point (``(m, k)``): the deviatoric Cauchy stress (row-major 3 x 3), the
    #: pressure, the largest volumetric strain, the permanent volumetric strain, the equivalent
    #: plastic strain, the damage, the stress work per unit reference volume and ``F``.
    state_fields: ClassVar[dict[str, int]] = {
        "deviator": 9,
        "pressure": 1,
        "mu_max": 1,
        "mu_plastic": 1,
        "plastic_strain": 1,
        "damage": 1,
        "work": 1,
        "F": 9,
        "eroded": 1,
    }

    @classmethod
    def concrete_48mpa(
        cls,
        plane: str | None = None,
        erosion: float | None = None,
        backend: str | None = None,
        viscosity: BulkViscosity | None = DEFAULT_VISCOSITY,
    ) -> HolmquistJohnsonCook:
        """The 48 MPa concrete of Holmquist, Johnson & Cook 1993 in SI units (kg, m, s, Pa), as
        LS-DYNA's MAT_111 examples list it: rho 2440, G 14.86 GPa, A 0.79, B 1.60, N 0.61,
        C 0.007, fc 48 MPa, T 4 MPa, EFMIN 0.01, SFMAX 7, P_crush 16 MPa, mu_crush 0.001,
        P_lock 0.80 GPa, mu_lock 0.10, D1 0.04, D2 1.0, K1 85 GPa, K2 -171 GPa, K3 208 GPa."""
        return cls(
            rho=2440.0, G=14.86e9, A=0.79, B=1.60, N=0.61, C=0.007, fc=48e6, T=4e6,
            efmin=0.01, sfmax=7.0, p_crush=16e6, mu_crush=0.001, p_lock=0.80e9, mu_lock=0.10,
            D1=0.04, D2=1.0, K1=85e9, K2=-171e9, K3=208e9, plane=plane, erosion=erosion,
            backend=backend, viscosity=viscosity,
        )  # fmt: skip

    def __post_init__(self) -> None:
        rate_kernels.resolve_backend(self.backend)
        check_viscosity("HolmquistJohnsonCook", self.viscosity)
        for f in fields(self):
            if f.name in ("plane", "erosion", "backend", "viscosity"):
                continue
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and np.isfinite(value)):
                _refuse(f.name, value, "is not a finite number", "give every parameter a value")
        positive = ("rho", "G", "fc", "T", "efmin", "sfmax", "p_crush", "mu_crush", "D1", "K1")
        for name in (*positive, "N", "eps0"):
            if not getattr(self, name) > 0:
                _refuse(name, getattr(self, name), "must be > 0", "see LS-DYNA MAT_111's ranges")
        for name in ("A", "B", "C", "D2"):
            if getattr(self, name) < 0:
                _refuse(name, getattr(self, name), "must be >= 0", "see LS-DYNA MAT_111's ranges")
        if self.erosion is not None and not (
            isinstance(self.erosion, int | float)
            and not isinstance(self.erosion, bool)
            and np.isfinite(self.erosion)
            and self.erosion > 0
        ):
            _refuse(
                "erosion", self.erosion, "is not None or a positive plastic strain",
                "give None (no erosion) or e.g. erosion=1.0",
            )  # fmt: skip
        if self.plane not in (None, "strain", "axisymmetric"):
            _refuse(
                "plane", self.plane, "is not None (3D), 'strain' or 'axisymmetric'",
                "plane stress has no out-of-plane strain to give the pressure; use 3D, plane "
                "strain or an axisymmetric model",
            )  # fmt: skip
        if self.p_lock <= self.p_crush:
            _refuse(
                "p_lock", self.p_lock, f"is not above p_crush={self.p_crush!r}",
                "the voids crush between them: give P_lock > P_crush",
            )  # fmt: skip
        if self.mu_lock <= self.mu_crush:
            _refuse(
                "mu_lock", self.mu_lock, f"is not above mu_crush={self.mu_crush!r}",
                "give mu_lock > mu_crush",
            )  # fmt: skip
        self._check_dense_curve()
        slope = (self.p_lock - self.p_crush) / (self.mu_plock - self.mu_crush)
        if slope > min(self.K_elastic, self.K1):
            _refuse(
                "p_lock", self.p_lock,
                f"makes region II's loading slope {slope:.4g} exceed the unloading moduli "
                f"(K_e = P_crush / mu_crush = {self.K_elastic:.4g}, K1 = {self.K1:.4g}), so that "
                "unloading would cross the loading curve",
                "check the units of P_lock, mu_crush and K1",
            )  # fmt: skip

    def _check_dense_curve(self) -> None:
        """Refuse a fully dense curve ``K1 x + K2 x^2 + K3 x^3`` that is not increasing for
        every ``x >= 0`` (the equation of state would be non-monotone)."""
        K1, K2, K3 = self.K1, self.K2, self.K3
        if K3 < 0 or (K3 == 0 and K2 < 0):
            worst = "large compression"
        elif K3 > 0 and K2 < 0 and K1 - K2 * K2 / (3.0 * K3) <= 0:
            worst = f"mu_bar = {-K2 / (3.0 * K3):.4g}"
        else:
            return
        _refuse(
            "K2", K2,
            f"with K1={K1!r}, K3={K3!r} makes the fully dense pressure decrease at {worst} (the "
            "equation of state is non-monotone)",
            "give K3 > 0 and K2^2 < 3 K1 K3",
        )  # fmt: skip

    # ----------------------------------------------------------------- derived constants
    @property
    def gdim(self) -> int:
        """3, or 2 for ``plane="strain"`` and ``"axisymmetric"`` (2D with a hoop stretch)."""
        return 3 if self.plane is None else 2

    @property
    def stiffest_bulk_modulus(self) -> float:
        """``max(K_e, K1)``: the largest bulk modulus short of extreme compaction (the fully
        dense curve's tangent passes ``K1`` only past ``mu_bar = -2 K2 / (3 K3)``), for the
        stable-step bound of an explicit run."""
        return max(self.K_elastic, self.K1)

    @property
    def K_elastic(self) -> float:
        """Region I's bulk modulus ``K_e = P_crush / mu_crush``."""
        return self.p_crush / self.mu_crush

    @cached_property
    def mu_plock(self) -> float:
        """The volumetric strain where the fully dense curve reaches ``P_lock`` (region III
        begins): the root ``x >= 0`` of ``K1 x + K2 x^2 + K3 x^3 = P_lock``, ``mu_plock =
        mu_lock + x (1 + mu_lock)``."""
        roots = np.roots([self.K3, self.K2, self.K1, -self.p_lock])
        real = roots[np.abs(roots.imag) <= 1e-12 * np.abs(roots).max()].real
        x = float(np.min(real[real >= 0.0]))
        return self.mu_lock + x * (1.0 + self.mu_lock)

    # ------------------------------------------------------------------ closed forms
    def loading_pressure(self, mu: np.ndarray) -> np.ndarray:
        """The pressure on the loading curve (regions I–III) at ``mu``; region I's line also
        for ``mu < 0`` (without the cut-off)."""
        mu = np.asarray(mu, dtype=float)
        mpl = self.mu_plock
        transition = self.p_crush + (self.p_lock - self.p_crush) * (mu - self.mu_crush) / (
            mpl - self.mu_crush
        )
        x = (mu - self.mu_lock) / (1.0 + self.mu_lock)
        dense = self.K1 * x + self.K2 * x**2 + self.K3 * x**3
        return np.where(
            mu <= self.mu_crush, self.K_elastic * mu, np.where(mu <= mpl, transition, dense)
        )

    def loading_tangent(self, mu: np.ndarray) -> np.ndarray:
        """``dP/dmu`` on the loading curve."""
        mu = np.asarray(mu, dtype=float)
        mpl = self.mu_plock
        x = (mu - self.mu_lock) / (1.0 + self.mu_lock)
        dense = (self.K1 + 2.0 * self.K2 * x + 3.0 * self.K3 * x**2) / (1.0 + self.mu_lock)
        transition = (self.p_lock - self.p_crush) / (mpl - self.mu_crush)
        return np.where(mu <= self.mu_crush, self.K_elastic, np.where(mu <= mpl, transition, dense))

    def unloading_modulus(self, mu_max: np.ndarray) -> np.ndarray:
        """The bulk modulus of unloading from ``mu_max``: ``K_e`` in region I, ``(1 - F) K_e + F
        K1`` in region II, ``max(K1, dP/dmu)`` in region III (module docstring)."""
        mu_max = np.asarray(mu_max, dtype=float)
        mpl = self.mu_plock
        frac = np.clip((mu_max - self.mu_crush) / (mpl - self.mu_crush), 0.0, 1.0)
        blended = (1.0 - frac) * self.K_elastic + frac * self.K1
        dense = np.maximum(self.K1, self.loading_tangent(mu_max))
        return np.where(mu_max <= mpl, blended, dense)

    def permanent_strain(self, mu_max: np.ndarray) -> np.ndarray:
        """The plastic volumetric strain ``mu_p`` after reaching ``mu_max``: the zero of the
        unloading line (0 in region I)."""
        mu_max = np.asarray(mu_max, dtype=float)
        mu_p = mu_max - self.loading_pressure(mu_max) / self.unloading_modulus(mu_max)
        return np.where(mu_max <= self.mu_crush, 0.0, np.maximum(mu_p, 0.0))

    def pressure(self, mu: np.ndarray, mu_max: np.ndarray, damage: np.ndarray) -> np.ndarray:
        """The equation of state: ``P(mu)`` given the largest ``mu_max >= mu`` reached so far and
        the damage (the tension cut-off ``P >= -T (1 - D)``)."""
        mu = np.asarray(mu, dtype=float)
        mu_max = np.maximum(np.asarray(mu_max, dtype=float), mu)
        unload = self.loading_pressure(mu_max) - self.unloading_modulus(mu_max) * (mu_max - mu)
        p = np.where(mu >= mu_max, self.loading_pressure(mu), unload)
        return np.maximum(p, -self.T * (1.0 - np.asarray(damage, dtype=float)))

    def strength(self, p_star: np.ndarray, damage: np.ndarray, rate: np.ndarray) -> np.ndarray:
        """The normalised strength ``sigma* = q / fc`` at ``P* = P / fc``, the damage and the
        deviatoric strain rate (module docstring; ``>= 0``)."""
        p_star = np.asarray(p_star, dtype=float)
        intact = self.A * (1.0 - np.asarray(damage, dtype=float))
        compression = intact + self.B * np.maximum(p_star, 0.0) ** self.N
        tension = intact + self.A * p_star * self.fc / self.T
        ratio = np.maximum(np.asarray(rate, dtype=float) / self.eps0, 1.0)
        s = np.where(p_star >= 0.0, compression, tension) * (1.0 + self.C * np.log(ratio))
        return np.clip(s, 0.0, self.sfmax)

    def failure_strain(self, p_star: np.ndarray) -> np.ndarray:
        """``eps_f = max(EFMIN, D1 (P* + T*)^D2)`` (``EFMIN`` where ``P* + T* <= 0``)."""
        s = np.asarray(p_star, dtype=float) + self.T / self.fc
        return np.maximum(self.efmin, self.D1 * np.maximum(s, 0.0) ** self.D2)

    # -------------------------------------------------------------------- the point
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
        """``(sigma (m, 3, 3), new state)``: the Cauchy stress at the deformation gradients ``F``
        ``(m, d, d)`` reached over a step of length ``dt`` from the committed ``state`` (never
        modified; the new one is made of new arrays). 2D models give the hoop stretch ``r / R``
        of an axisymmetric point in ``hoop`` (``F_zz``), plane strain leaves it ``None``.

        The compiled backend (class docstring) hands a step it cannot take (an inverted or
        non-finite ``F`` without erosion, a singular mid-step gradient) to the reference, whose
        errors name the point."""
        if rate_kernels.resolve_backend(self.backend) == "numba":
            check_arguments(self, F, dt, state, hoop)
            sigma, new, flags = rate_kernels.hjc_update(
                self._constants, self.erosion, F, hoop, dt, state, self.state_fields
            )
            if not flags.any():
                return sigma, new
        return self._update_reference(F, dt, state, hoop)

    @cached_property
    def _constants(self) -> np.ndarray:
        """The parameters in the order :mod:`rate_kernels` takes them."""
        return np.array([getattr(self, name) for name in rate_kernels.PARAMETERS], dtype=float)

    def _update_reference(
        self,
        F: np.ndarray,
        dt: float,
        state: dict[str, np.ndarray],
        hoop: np.ndarray | None = None,
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """:meth:`update` by whole-array operations (the ``"numpy"`` backend, the reference)."""
        gone = np.zeros(len(F), dtype=bool)
        F_new, committed = None, state
        if self.erosion is not None:  # eroded and inverting points: computed at rest, then zeroed
            F_new = as_3d(np.asarray(F, dtype=float), hoop)
            J_new = np.linalg.det(F_new) if len(F_new) else np.zeros(0)
            ok = np.all(np.isfinite(F_new), axis=(1, 2))
            gone = (state["eroded"][:, 0] > 0) | ~ok | ~(J_new > 0.0)
            if gone.any():
                F = np.array(F, dtype=float)
                F[gone] = np.eye(F.shape[1])
                if hoop is not None:
                    hoop = np.where(gone, 1.0, hoop)
                state = dict(state, F=state["F"].copy())
                state["F"][gone] = _EYE.ravel()
        F3, J = check_step(self, F, dt, state, hoop)
        m = len(F3)
        step = RateStep.start(state["F"].reshape(m, 3, 3), F3, state["deviator"].reshape(m, 3, 3))
        s_trial = step.s_rot + 2.0 * self.G * step.e

        damage = state["damage"][:, 0]
        mu = 1.0 / J - 1.0
        mu_max = np.maximum(state["mu_max"][:, 0], mu)
        p = self.pressure(mu, mu_max, damage)
        mu_p = np.maximum(self.permanent_strain(mu_max), state["mu_plastic"][:, 0])
        d_mu_p = mu_p - state["mu_plastic"][:, 0]

        sigma_y = self.fc * self.strength(p / self.fc, damage, step.equivalent_rate(dt))
        q = np.sqrt(1.5 * np.einsum("qij,qij->q", s_trial, s_trial))
        yielding = q > sigma_y
        scale = np.where(yielding, sigma_y / np.where(q > 0, q, 1.0), 1.0)
        s_mid = scale[:, None, None] * s_trial
        s = step.rotate(s_mid)
        d_eps_p = np.where(yielding, (q - sigma_y) / (3.0 * self.G), 0.0)
        d_damage = (d_eps_p + d_mu_p) / self.failure_strain(p / self.fc)
        sigma = s - p[:, None, None] * _EYE
        d_work = step.work(state["pressure"][:, 0], s_mid, p)
        new = {
            "deviator": s.reshape(m, 9),
            "pressure": p[:, None],
            "mu_max": mu_max[:, None],
            "mu_plastic": mu_p[:, None],
            "plastic_strain": state["plastic_strain"] + d_eps_p[:, None],
            "damage": np.minimum(1.0, damage + d_damage)[:, None],
            "work": state["work"] + d_work[:, None],
            "F": F3.reshape(m, 9),
            "eroded": state["eroded"].copy(),
        }
        if self.erosion is not None:
            # the eroded and the inverted keep their committed state (their update at rest is
            # no update); the worn keep this step's (it wore them)
            for name in ("mu_max", "mu_plastic", "plastic_strain", "damage"):
                new[name][gone] = committed[name][gone]
            gone |= (new["damage"][:, 0] >= 1.0) & (new["plastic_strain"][:, 0] >= self.erosion)
            if gone.any():
                sigma[gone] = 0.0
                for name in ("deviator", "pressure"):
                    new[name][gone] = 0.0
                new["damage"][gone] = 1.0
                new["eroded"][gone] = 1.0
                new["F"][gone] = F_new[gone].reshape(-1, 9)
                new["work"][gone] = committed["work"][gone]
        return sigma, new

    def wave_speed(self, state: dict[str, np.ndarray] | None = None) -> float:
        """The largest dilatational wave speed ``sqrt((K + 4 G / 3) / rho)`` over the points of
        ``state`` (``K`` the larger of the loading tangent and the unloading modulus at the
        state's ``mu_max``, ``rho = rho_0 (1 + mu)``; 0 without points); at ``state=None`` the
        virgin one."""
        if state is None:
            return float(np.sqrt((self.K_elastic + 4.0 * self.G / 3.0) / self.rho))
        if rate_kernels.resolve_backend(self.backend) == "numba":
            return rate_kernels.hjc_wave_speed(self._constants, state)
        live = state["eroded"][:, 0] == 0  # an eroded point carries nothing
        mu_max = state["mu_max"][live, 0]
        K = np.maximum(self.loading_tangent(mu_max), self.unloading_modulus(mu_max))
        F = state["F"][live].reshape(-1, 3, 3)
        rho = self.rho / np.linalg.det(F)
        return float(np.max(np.sqrt((K + 4.0 * self.G / 3.0) / rho), initial=0.0))
