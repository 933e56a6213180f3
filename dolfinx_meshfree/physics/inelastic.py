"""Small-strain inelastic laws with history: Rankine damage (crack band) and J2 plasticity.

Both laws work point-wise on Voigt vectors stacked along axis 0 (``m`` points) with the
conventions of :meth:`~dolfinx_meshfree.physics.materials.LinearElastic.voigt`: strains with
ENGINEERING shears, 2D ``[e_xx, e_yy, gamma_xy]`` and 3D ``[e_xx, e_yy, e_zz, gamma_yz, gamma_xz,
gamma_xy]`` (``gamma_ij = 2 e_ij``), stresses with their plain components ``[s_xx, s_yy, s_xy]``
and ``[s_xx, s_yy, s_zz, s_yz, s_xz, s_xy]``; ``nv = 3`` (2D) or ``6`` (3D).

The common interface (a frozen dataclass per law):

* ``state_fields``: name -> number of components per point of each history array; every state
  array has the shape ``(m, k)``, ``k >= 1``;
* ``initial_state(m)``: the virgin state of ``m`` points (new arrays);
* ``update(strain, state, band=None) -> (stress, tangent, new_state)``: the total strain
  ``(m, nv)`` at the end of a step and the COMMITTED state at its start give the stress
  ``(m, nv)``, the consistent (algorithmic) tangent ``d stress / d strain`` ``(m, nv, nv)`` (with
  respect to the engineering-shear strain vector) and the new (trial) state as new arrays. The
  input ``state`` is never modified (a caller that cuts a step restores the committed state), and
  the result depends on the arguments only (backward Euler / history maximum);
* ``elastic()``: the :class:`~dolfinx_meshfree.physics.materials.LinearElastic` twin;
* ``stored_energy(strain, state)``: the recoverable (Helmholtz) free energy density ``(m,)``;
* ``dissipated_energy(state)``: the energy dissipated per unit volume up to ``state`` ``(m,)``;
* ``needs_band`` / ``check_band(band, points=None)``: whether ``update`` needs the crack band
  width ``h`` per point, and its validity check.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .materials import LinearElastic, linear_twin, resolve_density

__all__ = ["J2Plasticity", "RankineDamage"]

#: 3D Voigt helpers (order xx, yy, zz, yz, xz, xy): the unit tensor, the factors from
#: engineering-shear strains to tensor components, and the weights of the tensor inner product.
_ONE6 = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
_HALF6 = np.array([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])
_TWO6 = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
#: In-plane rows/columns (xx, yy, xy) of the 3D Voigt order.
_PLANE = np.array([0, 1, 5])
_SQRT23 = float(np.sqrt(2.0 / 3.0))
#: A yielded J2 point whose trial stress lies within this fraction of the yield radius of its
#: surface is on it (round-off of the return map): its tangent is the loading one.
_ON_SURFACE = 1e-10
#: Plane stress: ``sigma^T P sigma = ||dev sigma||^2`` of ``[s_xx, s_yy, s_xy]`` (s_zz = 0);
#: ``P sigma`` is the engineering plastic strain rate (Simo & Hughes 1998, sec. 3.4).
_P_STRESS = np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, 0.0], [0.0, 0.0, 6.0]]) / 3.0
#: Newton iterations of the plane-stress consistency condition (measured: 7-13 for strains of
#: 1.05 to 1000 times the yield strain).
_PLANE_STRESS_ITERATIONS = 60
_EPS = float(np.finfo(float).eps)


def _positive(law: str, name: str, value: float, fix: str) -> None:
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{law}: {name}={value} must be a positive finite number; {fix}")


def _check_elastic(law: str, E: float, nu: float, rho: float | None) -> None:
    """The checks of the elastic constants shared by both laws (named after ``law``)."""
    _positive(law, "E", E, "give Young's modulus E > 0")
    if not (np.isfinite(nu) and -1.0 < nu < 0.5):
        raise ValueError(f"{law}: nu={nu} must lie in (-1, 0.5); give a Poisson ratio in range")
    if rho is not None:
        _positive(law, "rho", rho, "give a mass density rho > 0 (or leave it None)")


def _as_points(strain: np.ndarray, nv: int, law: str) -> np.ndarray:
    strain = np.asarray(strain, dtype=float)
    if strain.ndim != 2 or strain.shape[1] != nv:
        raise ValueError(
            f"{law}: strain should have shape (m, {nv}) (Voigt, engineering shears), "
            f"got {strain.shape}"
        )
    return strain


def _check_state(state: dict[str, np.ndarray], fields: dict[str, int], m: int, law: str) -> None:
    for name, k in fields.items():
        if name not in state:
            raise ValueError(
                f"{law}: state has no field {name!r} (fields {sorted(state)}); build it with "
                f"initial_state(m) and pass the state update() returned"
            )
        if np.shape(state[name]) != (m, k):
            raise ValueError(
                f"{law}: state[{name!r}] should have shape ({m}, {k}), got {np.shape(state[name])}"
            )


@dataclass(frozen=True)
class RankineDamage:
    """Isotropic scalar damage driven by the Rankine (largest principal effective stress)
    criterion, linear softening regularised by the crack band: damage in tension, elastic in
    compression.

    Effective stress ``sbar = C eps`` (``C`` = :meth:`LinearElastic.voigt`); equivalent strain
    of the "modified" Rankine criterion (Jirásek & Bažant, *Inelastic Analysis of Structures*,
    Wiley 2002, the Rankine-type equivalent strain of isotropic damage; Jirásek, "Non-local damage
    mechanics", Rev. Eur. Génie Civil 11, 2007)::

        eps_eq = <sigma_1(sbar)> / E        (<x> = max(0, x), sigma_1 the largest principal value)

    where plane strain counts the out-of-plane effective stress ``sbar_zz = lambda (e_xx + e_yy)``
    (3D Lamé ``lambda = nu E / ((1 + nu)(1 - 2 nu))``) among the principal values (it can only be
    the largest positive one for ``nu < 0``), plane stress has ``sbar_zz = 0``, and 3D takes the
    3 x 3 tensor. History ``kappa = max(kappa_old, eps_eq)`` starting at ``eps0 = ft / E``; the
    damage of linear softening in the crack band model (Bažant & Oh, "Crack band theory for
    fracture of concrete", Matériaux et Constructions 16, 1983)::

        D(kappa) = 1 - (eps0 / kappa) (eps_f - kappa) / (eps_f - eps0),   eps0 < kappa < eps_f,
        eps_f = 2 Gf / (ft h),

    ``D = 0`` for ``kappa <= eps0`` and ``D`` capped at ``max_damage`` (reached at ``kappa_c``,
    slightly below ``eps_f``; ``D = max_damage`` beyond), so that the uniaxial stress-strain
    curve rises linearly to ``ft`` at ``eps0`` and falls linearly to (almost) zero at ``eps_f``,
    dissipating ``Gf / h`` per unit volume: ``Gf`` per unit crack area over a band of width ``h``,
    the same for any ``h`` (objectivity). Stress ``sigma = (1 - D) C eps``.

    No crack closure: once cracked, the damage degrades the compressive stiffness too (as in
    the scalar models of Lemaitre and Mazars); but a state with no positive principal effective
    stress never creates damage (elastic in compression).

    Consistent tangent: ``(1 - D) C`` when the damage does not grow (elastic, unloading,
    ``kappa >= kappa_c``), else ``(1 - D) C - sbar (x) (dD/dkappa d eps_eq / d eps)`` with
    ``d eps_eq / d eps = C n_voigt / E``, ``n_voigt`` the derivative of the top eigenvalue with
    respect to the Voigt components of ``sbar`` (``[n_x^2, n_y^2, 2 n_x n_y]``, 3D ``[n_x^2, n_y^2,
    n_z^2, 2 n_y n_z, 2 n_x n_z, 2 n_x n_y]``), or ``lambda [1, 1, 0] / E`` when ``sbar_zz`` is
    the largest in plane strain.

    State fields: ``kappa`` (history variable); ``frozen`` (1 where the point no longer
    damages: :class:`~dolfinx_meshfree.CrackBandSwitch` hands a band point's softening to a
    cohesive crack and freezes it, so that ``kappa`` stays, elastic with ``(1 - D) C``); and,
    written by :meth:`update` so that :meth:`stored_energy` and :meth:`dissipated_energy` need no
    band, ``damage`` (``D``) and
    ``dissipation``: ``int Y dD`` with ``Y = eps : C : eps / 2``, the growth of the uniaxial
    closed form :meth:`dissipated_energy_of` over a step times ``Y / (E kappa^2 / 2)`` at the
    step's strain (1 in uniaxial stress, where it is the closed form to round-off; exact on
    proportional paths, first order in the step on others). The closed form alone, the
    uniaxial-equivalent value of ``kappa``, was 3 % above the energy balance's dissipation in a
    notched beam whose crack band starts at the notch's corners (FE, h = 25 mm).

    Args:
        E: Young's modulus (> 0). nu: Poisson's ratio (-1 < nu < 0.5). ft: Tensile strength
            (> 0). Gf: Fracture energy per unit crack area (> 0). plane: ``"stress"``,
            ``"strain"`` (2D) or ``None`` (3D). rho: Mass density (> 0) or ``None``
            (:func:`resolve_density`). max_damage: Cap of ``D`` in (0, 1) (keeps a residual
            stiffness ``(1 - max_damage) C``).
    """

    E: float
    nu: float
    ft: float
    Gf: float
    plane: str | None = "stress"
    rho: float | None = None
    max_damage: float = 0.9999

    needs_band: ClassVar[bool] = True

    def __post_init__(self) -> None:
        law = "RankineDamage"
        _check_elastic(law, self.E, self.nu, self.rho)
        _positive(law, "ft", self.ft, "give the tensile strength ft > 0")
        _positive(law, "Gf", self.Gf, "give the fracture energy per unit crack area Gf > 0")
        if self.plane not in ("stress", "strain", None):
            raise ValueError(
                f"{law}: plane={self.plane!r} must be 'stress' or 'strain' (2D), or None (3D)"
            )
        if not (np.isfinite(self.max_damage) and 0.0 < self.max_damage < 1.0):
            raise ValueError(
                f"{law}: max_damage={self.max_damage} must lie in (0, 1) (open: a residual "
                f"stiffness keeps the tangent regular); use e.g. max_damage=0.9999"
            )
        resolve_density(self)
        object.__setattr__(self, "_C", self.elastic().voigt())

    # --- the elastic side -----------------------------------------------------------------

    @property
    def gdim(self) -> int:
        """2 with ``plane="stress"|"strain"``, 3 with ``plane=None``."""
        return 3 if self.plane is None else 2

    @property
    def nv(self) -> int:
        """Number of Voigt components, 3 (2D) or 6 (3D)."""
        return 6 if self.plane is None else 3

    @property
    def eps0(self) -> float:
        """Strain at the peak of the uniaxial curve, ``ft / E`` (the initial ``kappa``)."""
        return self.ft / self.E

    @property
    def lmbda3d(self) -> float:
        """3D Lamé lambda ``nu E / ((1 + nu)(1 - 2 nu))`` (of ``sbar_zz`` in plane strain)."""
        return self.nu * self.E / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def state_fields(self) -> dict[str, int]:
        """``{"kappa": 1, "damage": 1, "dissipation": 1, "frozen": 1}`` (a new dict)."""
        return {"kappa": 1, "damage": 1, "dissipation": 1, "frozen": 1}

    def elastic(self) -> LinearElastic:
        """The linear elastic twin: the same ``E``, ``nu``, ``plane`` and ``rho``."""
        return linear_twin(self)

    def initial_state(self, m: int) -> dict[str, np.ndarray]:
        """Virgin state of ``m`` points: ``kappa = eps0``, no damage, no dissipation, not
        frozen."""
        return {
            "kappa": np.full((m, 1), self.eps0),
            "damage": np.zeros((m, 1)),
            "dissipation": np.zeros((m, 1)),
            "frozen": np.zeros((m, 1)),
        }

    # --- the crack band ---------------------------------------------------------------------

    @property
    def max_band(self) -> float:
        """Largest valid band width ``2 E Gf / ft^2`` (local snap-back at ``eps_f <= eps0``)."""
        return 2.0 * self.E * self.Gf / self.ft**2

    def check_band(self, band: np.ndarray, points: np.ndarray | None = None) -> None:
        """Raise a ValueError unless every band width ``h`` (scalar or ``(m,)``) is positive and
        below :attr:`max_band`: at ``h >= 2 E Gf / ft^2`` the softening branch would end before
        the peak (``eps_f <= eps0``), a local snap-back the law cannot represent. ``points``
        ``(m, gdim)`` names the coordinates of the first offending point."""
        h = np.atleast_1d(np.asarray(band, dtype=float))
        bad = ~(np.isfinite(h) & (h > 0))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"RankineDamage: crack band width h={h[i]} at point {i}{self._where(points, i)} "
                f"must be a positive finite length ({int(bad.sum())} such points); give the "
                f"element size / particle spacing there"
            )
        hmax = self.max_band
        snap = h >= hmax
        if snap.any():
            i = int(np.flatnonzero(snap)[0])
            raise ValueError(
                f"RankineDamage: crack band width h={h[i]} at point {i}{self._where(points, i)} "
                f"reaches the snap-back limit 2 E Gf / ft^2 = {hmax} ({int(snap.sum())} such "
                f"points): the softening would end before the peak (eps_f <= eps0); refine the "
                f"mesh/particle spacing there below h = {hmax}, or raise Gf"
            )

    @staticmethod
    def _where(points: np.ndarray | None, i: int) -> str:
        if points is None:
            return ""
        return f" (x = {np.asarray(points, dtype=float)[i].tolist()})"

    def _band(self, band: np.ndarray | None, m: int) -> np.ndarray:
        if band is None:
            raise ValueError(
                "RankineDamage needs the crack band width h per point (band=None given): pass "
                "band=h of shape (m,), the element size / particle spacing at each point"
            )
        h = np.asarray(band, dtype=float)
        if h.ndim == 0:
            h = np.full(m, float(h))
        if h.shape != (m,):
            raise ValueError(f"RankineDamage: band should have shape ({m},), got {h.shape}")
        self.check_band(h)
        return h

    # --- damage function --------------------------------------------------------------------

    def _softening(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``eps_f = 2 Gf / (ft h)`` and ``kappa_c``, where ``D(kappa_c) = max_damage``."""
        eps0 = self.eps0
        eps_f = 2.0 * self.Gf / (self.ft * h)
        r = 1.0 - self.max_damage
        kappa_c = eps0 * eps_f / (eps0 + r * (eps_f - eps0))
        return eps_f, kappa_c

    def _damage(self, kappa: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``D(kappa)`` and ``dD/dkappa`` (zero where ``D`` does not grow)."""
        eps0 = self.eps0
        eps_f, kappa_c = self._softening(h)
        k = np.maximum(kappa, eps0)  # no division by a zero kappa; D = 0 at kappa <= eps0
        lin = 1.0 - (eps0 / k) * (eps_f - k) / (eps_f - eps0)
        D = np.where(kappa <= eps0, 0.0, np.where(kappa >= kappa_c, self.max_damage, lin))
        grows = (kappa > eps0) & (kappa < kappa_c)
        dD = np.where(grows, eps0 * eps_f / ((eps_f - eps0) * k**2), 0.0)
        return D, dD

    def damage(self, state: dict[str, np.ndarray], band: np.ndarray | None = None) -> np.ndarray:
        """``D(kappa)`` (m,) of the state for the band widths ``band``; without ``band``, the
        ``damage`` field :meth:`update` stored."""
        if band is None:
            return np.asarray(state["damage"], dtype=float)[:, 0].copy()
        kappa = np.asarray(state["kappa"], dtype=float)[:, 0]
        return self._damage(kappa, self._band(band, kappa.shape[0]))[0]

    def dissipated_energy_of(self, kappa: np.ndarray, band: np.ndarray) -> np.ndarray:
        """Closed-form dissipation per unit volume up to ``kappa`` (m,) for band widths ``h``.

        ``int Y dD`` with the energy release rate of uniaxial tension on the loading branch,
        ``Y = E kappa^2 / 2``; with ``dD/dkappa = eps0 eps_f / ((eps_f - eps0) kappa^2)``::

            W_d = (Gf / h) (min(kappa, kappa_c) - eps0) / (eps_f - eps0),   kappa >= eps0,

        ``Gf / h = ft eps_f / 2`` at ``kappa = eps_f`` without the cap (``max_damage`` stops the
        dissipation at ``kappa_c``: a fraction ``~(1 - max_damage) eps_f / eps0`` less). Exact on
        uniaxial tension paths (the calibration of the band); on multiaxial paths it is the
        uniaxial-equivalent value of the same ``kappa``.
        """
        kappa = np.asarray(kappa, dtype=float)
        h = self._band(band, kappa.shape[0])
        eps_f, kappa_c = self._softening(h)
        frac = (np.minimum(kappa, kappa_c) - self.eps0) / (eps_f - self.eps0)
        return self.Gf / h * np.clip(frac, 0.0, None)

    # --- the update ---------------------------------------------------------------------------

    def _top_principal(self, strain: np.ndarray, sbar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Largest principal value of ``sbar`` (m,) and its gradient w.r.t. the strain (m, nv)."""
        C = self._C
        if self.plane is None:
            T = sbar[:, [[0, 5, 4], [5, 1, 3], [4, 3, 2]]]
            w, v = np.linalg.eigh(T)
            n = v[:, :, -1]
            nvoigt = np.column_stack(
                [
                    n[:, 0] ** 2,
                    n[:, 1] ** 2,
                    n[:, 2] ** 2,
                    2 * n[:, 1] * n[:, 2],
                    2 * n[:, 0] * n[:, 2],
                    2 * n[:, 0] * n[:, 1],
                ]
            )
            return w[:, -1], nvoigt @ C
        sxx, syy, sxy = sbar.T
        half = 0.5 * (sxx - syy)
        R = np.hypot(half, sxy)
        ok = R > 0
        Rs = np.where(ok, R, 1.0)
        cos2 = np.where(ok, half / Rs, 1.0)  # cos(2 theta), theta the top direction
        sin2 = np.where(ok, sxy / Rs, 0.0)
        top = 0.5 * (sxx + syy) + R
        grad = np.column_stack([0.5 * (1 + cos2), 0.5 * (1 - cos2), sin2]) @ C
        if self.plane == "strain":
            szz = self.lmbda3d * (strain[:, 0] + strain[:, 1])
            zz = szz > top
            top = np.where(zz, szz, top)
            grad = np.where(zz[:, None], self.lmbda3d * np.array([1.0, 1.0, 0.0]), grad)
        return top, grad

    def equivalent_strain(self, strain: np.ndarray) -> np.ndarray:
        """``eps_eq = <sigma_1(C eps)> / E`` (m,)."""
        strain = _as_points(strain, self.nv, "RankineDamage")
        return np.maximum(self._top_principal(strain, strain @ self._C)[0], 0.0) / self.E

    def unloading_tangent(
        self, strain: np.ndarray, state: dict[str, np.ndarray], band: np.ndarray | None = None
    ) -> np.ndarray:
        """The secant ``(1 - D) C`` (m, nv, nv) at ``strain`` from the committed ``state``: the
        tangent of unloading, which :meth:`update` gives inside the loading surface. Newton's
        first iteration of a load step that unloads a damaged body takes it (on the surface,
        :meth:`update` gives the loading one, which would carry the body further down its
        softening branch: :mod:`~dolfinx_meshfree.statics.history`)."""
        strain = _as_points(strain, self.nv, "RankineDamage")
        h = self._band(band, strain.shape[0])
        kappa_old = np.asarray(state["kappa"], dtype=float)[:, 0]
        kappa = self._history(kappa_old, self.equivalent_strain(strain), state)
        return (1.0 - self._damage(kappa, h)[0])[:, None, None] * self._C

    @staticmethod
    def _history(
        kappa_old: np.ndarray, eps_eq: np.ndarray, state: dict[str, np.ndarray]
    ) -> np.ndarray:
        """``kappa = max(kappa_old, eps_eq)``, ``kappa_old`` where the point is frozen."""
        frozen = np.asarray(state["frozen"], dtype=float)[:, 0] > 0.0
        return np.where(frozen, kappa_old, np.maximum(kappa_old, eps_eq))

    def update(
        self,
        strain: np.ndarray,
        state: dict[str, np.ndarray],
        band: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Stress (m, nv), consistent tangent (m, nv, nv) and new state at the total ``strain``
        (m, nv) from the committed ``state`` (not modified); ``band``: ``h`` per point (m,)."""
        strain = _as_points(strain, self.nv, "RankineDamage")
        m = strain.shape[0]
        _check_state(state, self.state_fields, m, "RankineDamage")
        h = self._band(band, m)
        C = self._C
        sbar = strain @ C
        top, grad = self._top_principal(strain, sbar)
        eps_eq = np.maximum(top, 0.0) / self.E
        kappa_old = np.asarray(state["kappa"], dtype=float)[:, 0]
        kappa = self._history(kappa_old, eps_eq, state)
        D, dD = self._damage(kappa, h)
        # damage grows only on the loading branch; grad is zero-weighted where eps_eq = 0. On
        # the loading surface of a damaged point (eps_eq = kappa_old > eps0: the strain of the
        # last converged step, bitwise) the tangent is the loading one, the one-sided derivative
        # towards more damage: the first iteration of the next step then predicts further
        # softening where the last step softened, instead of an elastic step that overshoots
        # the peak and lets Newton fall onto a branch where the whole body softens
        loading = (eps_eq > kappa_old) | ((eps_eq == kappa_old) & (kappa_old > self.eps0))
        loading &= np.asarray(state["frozen"], dtype=float)[:, 0] <= 0.0
        dD = np.where(loading, dD, 0.0)
        stress = (1.0 - D)[:, None] * sbar
        tangent = (1.0 - D)[:, None, None] * C - np.einsum(
            "qi,qj->qij", sbar, (dD / self.E)[:, None] * grad
        )
        # the dissipation int Y dD, Y = eps : C : eps / 2: the closed form's growth (uniaxial,
        # Y = E kappa^2 / 2) scaled on the loading branch by this strain's Y / (E kappa^2 / 2),
        # 1 in uniaxial stress (the closed form kept to round-off), exact on proportional paths
        grown = self.dissipated_energy_of(kappa, h) - self.dissipated_energy_of(kappa_old, h)
        y = 0.5 * np.einsum("qi,qi->q", sbar, strain)
        scale = np.where(kappa > kappa_old, y / (0.5 * self.E * kappa**2), 1.0)
        new = {
            "kappa": kappa[:, None],
            "damage": D[:, None],
            "dissipation": np.asarray(state["dissipation"], dtype=float) + (scale * grown)[:, None],
            "frozen": np.asarray(state["frozen"], dtype=float).copy(),
        }
        return stress, tangent, new

    def stored_energy(self, strain: np.ndarray, state: dict[str, np.ndarray]) -> np.ndarray:
        """``1/2 (1 - D) eps : C : eps`` (m,) with the ``damage`` field of ``state``."""
        strain = _as_points(strain, self.nv, "RankineDamage")
        D = np.asarray(state["damage"], dtype=float)[:, 0]
        return 0.5 * (1.0 - D) * np.einsum("qi,qi->q", strain @ self._C, strain)

    def dissipated_energy(self, state: dict[str, np.ndarray]) -> np.ndarray:
        """Dissipation per unit volume (m,): the ``dissipation`` field (``int Y dD``, class
        docstring; in uniaxial tension the closed form of :meth:`dissipated_energy_of`, ``Gf /
        h`` when fully softened)."""
        return np.asarray(state["dissipation"], dtype=float)[:, 0].copy()


@dataclass(frozen=True)
class J2Plasticity:
    """Small-strain von Mises plasticity with linear isotropic hardening: radial return mapping
    (plane strain and 3D), the closest-point return of plane stress.

    Simo & Hughes, *Computational Inelasticity*, Springer 1998: yield function (Box 3.1)
    ``f = ||s|| - sqrt(2/3) (sigma_y + H alpha)`` with ``s`` the deviatoric stress and ``alpha``
    the equivalent plastic strain (``d alpha = sqrt(2/3) d gamma``); the radial return of Box 3.1
    (trial ``s_tr = 2 mu dev(eps - eps_p)``, ``dgamma = f_tr / (2 mu + 2 H / 3)``, ``n = s_tr /
    ||s_tr||``, ``s = s_tr - 2 mu dgamma n``, ``eps_p += dgamma n``, ``alpha += sqrt(2/3)
    dgamma``) and the consistent elastoplastic tangent of Box 3.2::

        C_alg = K 1 (x) 1 + 2 mu theta I_dev - 2 mu thetabar n (x) n,
        theta = 1 - 2 mu dgamma / ||s_tr||,   thetabar = 1 / (1 + H / (3 mu)) - (1 - theta),

    mapped to Voigt with engineering shears (``I_dev`` gets ``1/2`` on the shear diagonal, ``n``
    enters with its tensor components). Radial return is exact for proportional loading with
    linear hardening.

    Plane strain embeds the strain in 3D (``e_zz = 0``, no out-of-plane shears), returns the
    in-plane stress ``[s_xx, s_yy, s_xy]`` and the in-plane (xx, yy, xy) block of the 3D tangent;
    :meth:`out_of_plane_stress` gives ``s_zz``.

    Plane stress (``s_zz = 0``; Simo & Taylor 1986; Simo & Hughes 1998, sec. 3.4) has no radial
    return: the in-plane stress obeys ``(C^-1 + dgamma P) sigma = eps - eps_p_n`` with ``C`` the
    plane-stress elastic matrix and ``P`` the matrix of ``sigma^T P sigma = ||s||^2``. ``C`` and
    ``P`` share the eigenvectors ``(1, 1, 0) / sqrt 2``, ``(1, -1, 0) / sqrt 2``, ``(0, 0, 1)``, so
    ``sigma(dgamma)`` is the trial stress scaled mode by mode (``1 / (1 + E dgamma / (3 (1 -
    nu)))`` and ``1 / (1 + 2 mu dgamma)``), and the consistency condition ``phi(dgamma) =
    sqrt(2/3) (sigma_y + H (alpha_n + sqrt(2/3) dgamma phi))``, ``phi = ||s||``, is one scalar
    equation per point, strictly decreasing in ``dgamma``: Newton's method safeguarded by
    bisection on a bracket, to round-off. ``eps_p += dgamma P sigma`` (``e_p_zz = -(e_p_xx +
    e_p_yy)``), and the consistent tangent (symmetric; ``Xi = (C^-1 + dgamma P)^-1``,
    ``n = P sigma``)::

        C_alg = Xi - (Xi n) (Xi n)^T / (n^T Xi n + b),
        b = beta phi^2 / (phi - beta dgamma),   beta = (2/3) sqrt(2/3) H (sigma_y + H alpha).

    Energies: free energy ``psi = 1/2 (eps - eps_p) : C : (eps - eps_p) + 1/2 H alpha^2``. With
    the hardening energy stored in ``psi``, the dissipation rate is ``s : d eps_p - H alpha d alpha
    = (sigma_y + H alpha) d alpha - H alpha d alpha = sigma_y d alpha``, so the increment of the
    ``dissipation`` field, ``sigma_y (alpha_new - alpha_old)``, is exact for linear hardening
    (the plastic work ``(sigma_y + H (alpha_old + alpha_new) / 2) (alpha_new - alpha_old)``, exact
    as well, is this plus the increment of ``1/2 H alpha^2``).

    State fields: ``plastic_strain`` (6: the 3D tensor ``[xx, yy, zz, yz, xz, xy]`` with
    engineering shears, also in plane strain), ``alpha`` (1), ``dissipation`` (1).

    Args:
        E: Young's modulus (> 0). nu: Poisson's ratio (-1 < nu < 0.5). sigma_y: Initial
            uniaxial yield stress (> 0). H: Linear isotropic hardening modulus (>= 0, with
            respect to ``alpha``). plane: ``"strain"`` or ``"stress"`` (2D), or ``None`` (3D).
            rho: Mass density (> 0) or ``None`` (:func:`resolve_density`).
    """

    E: float
    nu: float
    sigma_y: float
    H: float = 0.0
    plane: str | None = "strain"
    rho: float | None = None

    needs_band: ClassVar[bool] = False
    #: Its plastic flow keeps the volume: cells that cannot deform at constant volume (P1
    #: triangles and tetrahedra, and Q1 at its full rule) lock under it
    #: (:mod:`~dolfinx_meshfree.statics.mean_dilatation`).
    isochoric_flow: ClassVar[bool] = True

    def __post_init__(self) -> None:
        law = "J2Plasticity"
        _check_elastic(law, self.E, self.nu, self.rho)
        _positive(law, "sigma_y", self.sigma_y, "give the initial yield stress sigma_y > 0")
        if not (np.isfinite(self.H) and self.H >= 0):
            raise ValueError(
                f"{law}: H={self.H} must be a finite hardening modulus >= 0 (softening is not "
                f"supported); use H=0.0 for perfect plasticity"
            )
        if self.plane not in ("strain", "stress", None):
            raise ValueError(
                f"{law}: plane={self.plane!r} must be 'strain' or 'stress' (2D) or None (3D)"
            )
        resolve_density(self)
        lin3 = LinearElastic(self.E, self.nu, plane=None)
        object.__setattr__(self, "_mu", lin3.mu)
        if self.plane == "stress":  # the plane-stress Hooke matrix of the return map
            object.__setattr__(self, "_C", LinearElastic(self.E, self.nu, "stress").voigt())
        object.__setattr__(self, "_K", self.E / (3.0 * (1.0 - 2.0 * self.nu)))

    @property
    def gdim(self) -> int:
        """2 with ``plane="strain"`` or ``"stress"``, 3 with ``plane=None``."""
        return 3 if self.plane is None else 2

    @property
    def nv(self) -> int:
        """Number of Voigt components, 3 (2D) or 6 (3D)."""
        return 6 if self.plane is None else 3

    @property
    def mu(self) -> float:
        """Shear modulus ``E / (2 (1 + nu))``."""
        return self._mu

    @property
    def K(self) -> float:
        """Bulk modulus ``E / (3 (1 - 2 nu))``."""
        return self._K

    @property
    def state_fields(self) -> dict[str, int]:
        """``{"plastic_strain": 6, "alpha": 1, "dissipation": 1}`` (a new dict)."""
        return {"plastic_strain": 6, "alpha": 1, "dissipation": 1}

    def elastic(self) -> LinearElastic:
        """The linear elastic twin: the same ``E``, ``nu``, ``plane`` and ``rho``."""
        return linear_twin(self)

    def initial_state(self, m: int) -> dict[str, np.ndarray]:
        """Virgin state of ``m`` points: no plastic strain, ``alpha = 0``, no dissipation."""
        return {
            "plastic_strain": np.zeros((m, 6)),
            "alpha": np.zeros((m, 1)),
            "dissipation": np.zeros((m, 1)),
        }

    def check_band(self, band: np.ndarray, points: np.ndarray | None = None) -> None:
        """No-op: the law has no softening and needs no band."""

    def unloading_tangent(
        self, strain: np.ndarray, state: dict[str, np.ndarray], band: np.ndarray | None = None
    ) -> np.ndarray:
        """The elastic tangent (m, nv, nv), the elastic predictor of a load step that unloads
        (:mod:`~dolfinx_meshfree.statics.history`): on the yield surface :meth:`update` gives
        the elastoplastic one, softer, and Newton took 4 iterations to unload a yielded strip
        where this takes 1 (unloading is elastic)."""
        m = _as_points(strain, self.nv, "J2Plasticity").shape[0]
        return np.broadcast_to(self.elastic().voigt(), (m, self.nv, self.nv)).copy()

    def _strain3(self, strain: np.ndarray) -> np.ndarray:
        """The 3D engineering strain (m, 6) of ``strain`` (plane strain: embedded)."""
        strain = _as_points(strain, self.nv, "J2Plasticity")
        if self.plane is None:
            return strain
        out = np.zeros((strain.shape[0], 6))
        out[:, _PLANE] = strain
        return out

    def _elastic_parts(
        self, strain: np.ndarray, plastic_strain: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Trace (m,) and deviator (m, 6, tensor components) of ``eps - eps_p``."""
        ee = (self._strain3(strain) - np.asarray(plastic_strain, dtype=float)) * _HALF6
        tr = ee[:, :3].sum(axis=1)
        return tr, ee - (tr / 3.0)[:, None] * _ONE6

    def update(
        self,
        strain: np.ndarray,
        state: dict[str, np.ndarray],
        band: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Stress (m, nv), consistent tangent (m, nv, nv) and new state at the total ``strain``
        (m, nv) from the committed ``state`` (not modified); ``band`` is ignored."""
        m = _as_points(strain, self.nv, "J2Plasticity").shape[0]
        _check_state(state, self.state_fields, m, "J2Plasticity")
        if self.plane == "stress":
            return self._update_plane_stress(np.asarray(strain, dtype=float), state)
        mu, K, H = self._mu, self._K, self.H
        alpha = np.asarray(state["alpha"], dtype=float)[:, 0]
        tr, dev = self._elastic_parts(strain, state["plastic_strain"])
        s_tr = 2.0 * mu * dev
        norm = np.sqrt(np.einsum("qi,qi->q", s_tr * _TWO6, s_tr))
        radius = _SQRT23 * (self.sigma_y + H * alpha)
        f_tr = norm - radius
        plastic = f_tr > 0
        # on the yield surface of a point that has yielded (the strain of the last converged
        # step: its return map puts the stress there only to round-off, either side) the
        # tangent is the loading one, as RankineDamage's: the next step's first iteration then
        # predicts further flow where the last step flowed, whatever the round-off (which
        # differed between serial and 2 ranks, and with it the path's cuts)
        loading = plastic | ((alpha > 0) & (np.abs(f_tr) <= _ON_SURFACE * radius))
        dgamma = np.where(plastic, f_tr / (2.0 * mu + 2.0 * H / 3.0), 0.0)
        safe = np.where(norm > 0, norm, 1.0)
        n = s_tr / safe[:, None]
        stress = (K * tr)[:, None] * _ONE6 + s_tr - (2.0 * mu * dgamma)[:, None] * n

        theta = 1.0 - 2.0 * mu * dgamma / safe
        thetabar = np.where(loading, 1.0 / (1.0 + H / (3.0 * mu)) - (1.0 - theta), 0.0)
        idev = np.diag(_HALF6) - np.outer(_ONE6, _ONE6) / 3.0
        tangent = (
            K * np.outer(_ONE6, _ONE6)
            + (2.0 * mu * theta)[:, None, None] * idev
            - (2.0 * mu * thetabar)[:, None, None] * np.einsum("qi,qj->qij", n, n)
        )
        dalpha = _SQRT23 * dgamma
        new = {
            "plastic_strain": np.asarray(state["plastic_strain"], dtype=float)
            + dgamma[:, None] * n * _TWO6,
            "alpha": (alpha + dalpha)[:, None],
            "dissipation": np.asarray(state["dissipation"], dtype=float)
            + self.sigma_y * dalpha[:, None],
        }
        if self.plane is None:
            return stress, tangent, new
        return stress[:, _PLANE], tangent[:, _PLANE][:, :, _PLANE], new

    def _update_plane_stress(
        self, strain: np.ndarray, state: dict[str, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """:meth:`update` in plane stress: the closest-point return of the class docstring."""
        E, nu, H, sy = self.E, self.nu, self.H, self.sigma_y
        C = self._C
        alpha = np.asarray(state["alpha"], dtype=float)[:, 0]
        eps_p = np.asarray(state["plastic_strain"], dtype=float)
        s_tr = (strain - eps_p[:, _PLANE]) @ C.T
        # the trial stress in the common eigenvectors of C and P, the modes' stiffness rates
        a1, two_mu = E / (3.0 * (1.0 - nu)), 2.0 * self._mu
        A1 = (s_tr[:, 0] + s_tr[:, 1]) ** 2 / 6.0
        A2 = 0.5 * (s_tr[:, 0] - s_tr[:, 1]) ** 2 + 2.0 * s_tr[:, 2] ** 2
        radius = _SQRT23 * (sy + H * alpha)
        g_tr = np.sqrt(A1 + A2) - radius
        plastic = g_tr > 0
        loading = plastic | ((alpha > 0) & (np.abs(g_tr) <= _ON_SURFACE * radius))
        dgamma = np.zeros_like(alpha)
        if plastic.any():
            dgamma[plastic] = _plane_stress_dgamma(
                A1[plastic], A2[plastic], alpha[plastic], a1, two_mu, sy, H
            )
        q1, q2 = 1.0 / (1.0 + a1 * dgamma), 1.0 / (1.0 + two_mu * dgamma)
        total, diff = (s_tr[:, 0] + s_tr[:, 1]) * q1, (s_tr[:, 0] - s_tr[:, 1]) * q2
        stress = np.column_stack([0.5 * (total + diff), 0.5 * (total - diff), s_tr[:, 2] * q2])
        n = stress @ _P_STRESS.T  # n = P sigma: the engineering plastic strain rate
        phi = np.sqrt(np.einsum("qi,qi->q", stress, n))
        alpha_new = alpha + _SQRT23 * dgamma * phi
        # Xi = (C^-1 + dgamma P)^-1 by its eigenvalues on the modes (1,1,0), (1,-1,0), (0,0,1)
        xi1, xi2, xi3 = E / (1.0 - nu) * q1, two_mu * q2, 0.5 * two_mu * q2
        Xi = np.zeros((alpha.size, 3, 3))
        Xi[:, 0, 0] = Xi[:, 1, 1] = 0.5 * (xi1 + xi2)
        Xi[:, 0, 1] = Xi[:, 1, 0] = 0.5 * (xi1 - xi2)
        Xi[:, 2, 2] = xi3
        beta = (2.0 / 3.0) * _SQRT23 * H * (sy + H * alpha_new)
        b = beta * phi**2 / np.where(loading, phi - beta * dgamma, 1.0)
        Xn = np.einsum("qij,qj->qi", Xi, n)
        denominator = np.einsum("qi,qi->q", n, Xn) + b
        safe = np.where(loading, denominator, 1.0)
        tangent = Xi - np.where(loading, 1.0 / safe, 0.0)[:, None, None] * np.einsum(
            "qi,qj->qij", Xn, Xn
        )
        d_eps_p = dgamma[:, None] * n
        new_eps_p = eps_p.copy()
        new_eps_p[:, _PLANE] += d_eps_p
        new_eps_p[:, 2] -= d_eps_p[:, 0] + d_eps_p[:, 1]  # isochoric flow
        new = {
            "plastic_strain": new_eps_p,
            "alpha": alpha_new[:, None],
            "dissipation": np.asarray(state["dissipation"], dtype=float)
            + sy * (alpha_new - alpha)[:, None],
        }
        return stress, tangent, new

    def out_of_plane_stress(self, strain: np.ndarray, state: dict[str, np.ndarray]) -> np.ndarray:
        """Plane strain ``s_zz`` (m,) at ``strain`` with the plastic strain of ``state``: pass
        the state :meth:`update` returned for that strain (then it is the ``zz`` component of
        the 3D stress of the return map). Plane stress: zeros."""
        if self.plane == "stress":
            return np.zeros(_as_points(strain, self.nv, "J2Plasticity").shape[0])
        if self.plane is None:
            raise ValueError(
                "J2Plasticity: out_of_plane_stress is for plane='strain'; in 3D s_zz is "
                "stress[:, 2] of update()"
            )
        tr, dev = self._elastic_parts(strain, state["plastic_strain"])
        return self._K * tr + 2.0 * self._mu * dev[:, 2]

    def stored_energy(self, strain: np.ndarray, state: dict[str, np.ndarray]) -> np.ndarray:
        """``1/2 (eps - eps_p) : C : (eps - eps_p) + 1/2 H alpha^2`` (m,)."""
        if self.plane == "stress":  # the in-plane elastic strains with C of plane stress
            ee = (
                _as_points(strain, self.nv, "J2Plasticity")
                - np.asarray(state["plastic_strain"], dtype=float)[:, _PLANE]
            )
            elastic = 0.5 * np.einsum("qi,ij,qj->q", ee, self._C, ee)
            return elastic + 0.5 * self.H * np.asarray(state["alpha"], dtype=float)[:, 0] ** 2
        tr, dev = self._elastic_parts(strain, state["plastic_strain"])
        alpha = np.asarray(state["alpha"], dtype=float)[:, 0]
        elastic = 0.5 * self._K * tr**2 + self._mu * np.einsum("qi,qi->q", dev * _TWO6, dev)
        return elastic + 0.5 * self.H * alpha**2

    def dissipated_energy(self, state: dict[str, np.ndarray]) -> np.ndarray:
        """Dissipation per unit volume (m,): the ``dissipation`` field, ``sigma_y alpha`` for a
        state grown from the virgin one (see the class docstring)."""
        return np.asarray(state["dissipation"], dtype=float)[:, 0].copy()


def _plane_stress_dgamma(
    A1: np.ndarray,
    A2: np.ndarray,
    alpha: np.ndarray,
    a1: float,
    two_mu: float,
    sigma_y: float,
    H: float,
) -> np.ndarray:
    """The plastic multiplier of plane-stress J2 at yielding points: the root of
    ``g(x) = phi(x) - sqrt(2/3) (sigma_y + H (alpha + sqrt(2/3) x phi(x)))`` with
    ``phi(x)^2 = A1 / (1 + a1 x)^2 + A2 / (1 + 2 mu x)^2`` (``A1 = (s_xx + s_yy)^2 / 6``,
    ``A2 = (s_xx - s_yy)^2 / 2 + 2 s_xy^2`` of the trial stress). ``g`` decreases strictly
    (``phi`` falls, ``x phi`` rises) from ``g(0) > 0``; since ``phi(x) <= phi(0) / (1 + c x)``
    with ``c = min(a1, 2 mu)``, ``g`` is negative at ``x = (phi(0) / r - 1) / c``, ``r =
    sqrt(2/3) (sigma_y + H alpha)``: Newton's steps inside that bracket, bisection where a
    step leaves it, until ``|g|`` is round-off (``8 eps r``) or the bracket closes on ``x``."""
    r0 = _SQRT23 * (sigma_y + H * alpha)
    lo = np.zeros_like(A1)
    hi = (np.sqrt(A1 + A2) / r0 - 1.0) / min(a1, two_mu)
    x = np.zeros_like(A1)
    for _ in range(_PLANE_STRESS_ITERATIONS):
        q1, q2 = 1.0 / (1.0 + a1 * x), 1.0 / (1.0 + two_mu * x)
        phi = np.sqrt(A1 * q1**2 + A2 * q2**2)
        g = phi - _SQRT23 * (sigma_y + H * (alpha + _SQRT23 * x * phi))
        dphi = -(A1 * a1 * q1**3 + A2 * two_mu * q2**3) / phi
        dg = dphi - (2.0 / 3.0) * H * (phi + x * dphi)
        # g is a difference of terms of size r0: below 8 eps r0 it is round-off, and a
        # Newton step would move x only by its round-off
        done = (np.abs(g) <= 8 * _EPS * r0) | (hi - lo <= 4 * _EPS * x)
        if done.all():
            return x
        lo, hi = np.where(g > 0, x, lo), np.where(g > 0, hi, x)
        trial = x - g / dg
        inside = (trial >= lo) & (trial <= hi)  # a root on the bracket's end: kept
        x = np.where(done, x, np.where(inside, trial, 0.5 * (lo + hi)))
    raise ArithmeticError(
        f"J2Plasticity (plane stress): the return map did not converge in "
        f"{_PLANE_STRESS_ITERATIONS} iterations at {(~done).sum()} point(s); the strain "
        "increment may be too large: take smaller load steps"
    )
