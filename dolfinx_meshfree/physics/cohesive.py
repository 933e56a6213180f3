"""A traction–separation law for cohesive cracks: linear softening, mixed mode, unloading to the
origin, contact in compression.

The faces of a cohesive crack carry a traction ``t`` that depends on the jump ``w = u+ - u-`` of
the displacement across them (Hillerborg, Modéer & Petersson 1976, the fictitious crack model;
Rabczuk et al. 2006, sec. 6.1.2: "a linear traction–crack-opening law on the discontinuity").
The law works point-wise on stacked arrays in the crack's LOCAL frame: column 0 is the normal
opening ``w_n`` (positive: opening), the other columns the sliding ``w_s`` (one in 2D, two in
3D).

Intrinsic and of damage type, with the effective opening of Camacho & Ortiz (1996, "Computational
modelling of impact damage in brittle materials", Int. J. Solids Struct. 33, eq. 29-31) for
mixed mode:

.. math::
    w_{eff} = \\sqrt{\\langle w_n \\rangle^2 + \\beta^2 |w_s|^2}, \\qquad
    \\kappa = \\max_{history} w_{eff},

    T(\\kappa) = \\begin{cases} K_0 \\kappa & \\kappa \\le w_0 = f_t / K_0 \\\\
        f_t (w_c - \\kappa) / (w_c - w_0) & w_0 < \\kappa < w_c = 2 G_f / f_t \\\\
        0 & \\kappa \\ge w_c \\end{cases}, \\qquad s(\\kappa) = T(\\kappa) / \\kappa,

    t_n = s\\, w_n \\; (w_n \\ge 0), \\quad t_n = K_0 w_n \\; (w_n < 0), \\qquad
    t_s = \\beta^2 s\\, w_s.

* The envelope peaks at ``f_t`` and encloses ``f_t w_c / 2 = G_f``: the energy dissipated per
  unit crack area when the faces separate, in mode I and, since ``t_s dw_s = T dw_eff``, in
  pure sliding too. ``K_0`` is a penalty (the faces are bonded until ``f_t``): the default
  :meth:`LinearCohesive.with_stiffness` ``factor E / h = 30 E / h`` adds an opening of
  ``f_t h / (30 E)`` before softening, 3 % of the elastic stretch of a strip one spacing wide.
* Unloading and reloading follow the secant to the origin (``s`` frozen at ``kappa``).
* In compression the normal jump is penalised by ``K_0`` (frictionless contact of the faces);
  compression never damages, sliding does.
* ``s`` never falls below ``residual f_t / w_c`` (a traction of ``residual f_t`` at ``w_c``: a
  residual stiffness that keeps the tangent regular once the faces have separated). It is
  relative to the envelope, not to the penalty ``K_0``: ``K_0 w_c`` is thousands of ``f_t``,
  and a floor of ``1e-4 K_0`` would have held 0.7 ``f_t`` at ``w_c`` and stopped the dissipation
  at 59 % of ``G_f`` (measured on the bar of the tests).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .inelastic import _positive

__all__ = ["LinearCohesive"]


def _check_positive(name: str, value: float, fix: str) -> None:
    _positive("LinearCohesive", name, value, fix)


@dataclass(frozen=True)
class LinearCohesive:
    """Linear-softening traction–separation law of a cohesive crack (module docstring).

    Args:
        ft: Tensile strength (stress units), the peak of the envelope.
        Gf: Fracture energy per unit crack area (force / length), the area of the envelope.
        shear: ``beta``, the weight of the sliding in the effective opening (0: sliding is free
            and does not damage; 1: the two modes alike).
        stiffness: ``K_0``, the initial stiffness per unit area (stress / length); ``None``: set
            by the crack's side from the bulk's ``E`` and the particle spacing
            (:meth:`with_stiffness`).
        factor: ``K_0 = factor E / h`` when ``stiffness`` is ``None``. The faces are bonded by a
            penalty: too soft, they add compliance (``h / (factor E)`` per unit stress); too
            stiff, they lock the two one-sided MLS fields together at every face point and
            stiffen the body near a bonded crack (a crack cut ahead of where it will open).
            30 balances the two on the notched beam: its first CMOD within 5 % of the uncut
            beam's at 8 cells over the depth (``tests/test_concrete_beam.py``, measured 3.9 %).
        residual: The floor of the secant in units of ``f_t / w_c``, in (0, 1).
    """

    ft: float
    Gf: float
    shear: float = 1.0
    stiffness: float | None = None
    factor: float = 30.0
    residual: float = 1e-4

    #: The state of a face point: the largest effective opening so far.
    state_fields: ClassVar[dict[str, int]] = {"kappa": 1}
    #: No crack band: the law is per unit crack area
    #: (:class:`~dolfinx_meshfree.physics.state.PointState` reads it).
    needs_band: ClassVar[bool] = False

    def __post_init__(self) -> None:
        _check_positive("ft", self.ft, "give the tensile strength f_t > 0")
        _check_positive("Gf", self.Gf, "give the fracture energy G_f > 0 (per unit crack area)")
        if not (np.isfinite(self.shear) and self.shear >= 0):
            raise ValueError(
                f"LinearCohesive: shear={self.shear!r} must be a finite number >= 0 (the weight "
                "beta of the sliding in the effective opening, 1 by default)"
            )
        _check_positive("factor", self.factor, "K_0 = factor E / h; the default is 30")
        if not (np.isfinite(self.residual) and 0.0 < self.residual < 1.0):
            raise ValueError(
                f"LinearCohesive: residual={self.residual!r} must lie in (0, 1) (the floor of "
                "the secant in units of f_t / w_c keeps the tangent regular); use e.g. 1e-4"
            )
        if self.stiffness is not None:
            _check_positive(
                "stiffness", self.stiffness, "give K_0 > 0 (stress per length), or None"
            )
            if self.ft / self.stiffness >= self.w_c:
                raise ValueError(
                    f"LinearCohesive: stiffness={self.stiffness!r} is too low: the elastic "
                    f"opening f_t/K_0 = {self.ft / self.stiffness:.4g} reaches the critical "
                    f"opening w_c = 2 G_f / f_t = {self.w_c:.4g}; give K_0 well above "
                    f"f_t^2 / (2 G_f) = {self.ft**2 / (2 * self.Gf):.4g}"
                )

    # -- constants ----------------------------------------------------------------------------

    @property
    def w_c(self) -> float:
        """The critical opening ``2 G_f / f_t`` where the traction vanishes."""
        return 2.0 * self.Gf / self.ft

    @property
    def K0(self) -> float:
        """``K_0`` (ValueError while it is not set)."""
        if self.stiffness is None:
            raise ValueError(
                "LinearCohesive: stiffness=None: the initial stiffness K_0 is not set; call "
                "with_stiffness(E, h) (the crack's side does it), or give stiffness="
            )
        return float(self.stiffness)

    @property
    def w_0(self) -> float:
        """The opening at the peak, ``f_t / K_0``."""
        return self.ft / self.K0

    @property
    def floor(self) -> float:
        """The floor of the secant, ``residual f_t / w_c``."""
        return self.residual * self.ft / self.w_c

    @property
    def kappa_cap(self) -> float:
        """The opening where the secant reaches its floor ``residual f_t / w_c``."""
        w0, wc = self.w_0, self.w_c
        r = self.floor
        return self.ft * wc / (self.ft + r * (wc - w0))

    def with_stiffness(self, E: float, h: float) -> LinearCohesive:
        """A copy with ``K_0`` set: ``stiffness`` if given, else ``factor E / h``."""
        if self.stiffness is not None:
            return self
        _check_positive("E", E, "the bulk's Young's modulus")
        _check_positive("h", h, "the particle spacing")
        return dataclasses.replace(self, stiffness=self.factor * float(E) / float(h))

    @property
    def max_dissipation(self) -> float:
        """The energy per unit area dissipated at :attr:`kappa_cap` (just below ``G_f``)."""
        return float(self.dissipated_energy({"kappa": np.array([self.kappa_cap])})[0])

    def opening_of_dissipation(self, d: np.ndarray) -> np.ndarray:
        """The history ``kappa`` (m,) of face points that have dissipated ``d`` (m,) per unit
        area, the inverse of :meth:`dissipated_energy`: past the peak that is linear in
        ``kappa``, ``G_f (kappa - w_0) / (w_c - w_0)`` (its two parts, ``int T`` and ``T kappa
        / 2``, are quadratic with opposite ``kappa^2`` terms), so ``kappa = w_0 + (w_c - w_0) d
        / G_f``; 0 (virgin) where ``d <= 0``. ValueError where ``d`` exceeds
        :attr:`max_dissipation`."""
        d = np.asarray(d, dtype=float).reshape(-1)
        top = self.max_dissipation
        if np.any(d > top * (1.0 + 1e-12)):
            raise ValueError(
                f"LinearCohesive: a dissipation of {d.max():.6g} per unit area exceeds what the "
                f"faces can dissipate before their cap, {top:.6g} (G_f = {self.Gf:.6g})"
            )
        kappa = self.w_0 + (self.w_c - self.w_0) * np.minimum(d, top) / self.Gf
        return np.where(d > 0.0, np.minimum(kappa, self.kappa_cap), 0.0)

    def initial_state(self, m: int) -> dict[str, np.ndarray]:
        """The virgin state of ``m`` face points."""
        return {"kappa": np.zeros((m, 1))}

    # -- the envelope -------------------------------------------------------------------------

    def traction_curve(self, w: np.ndarray) -> np.ndarray:
        """The envelope ``T(w)`` (mode I, no cap)."""
        w = np.asarray(w, dtype=float)
        w0, wc = self.w_0, self.w_c
        soft = self.ft * (wc - w) / (wc - w0)
        return np.where(w <= w0, self.K0 * w, np.where(w >= wc, 0.0, soft))

    def _secant(self, kappa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``s(kappa)`` and ``ds/dkappa`` (0 on the elastic branch and at the cap)."""
        K0, w0, wc, ft = self.K0, self.w_0, self.w_c, self.ft
        floor = self.floor
        k = np.maximum(kappa, w0)  # no division by 0 on the elastic branch
        T = ft * (wc - k) / (wc - w0)
        s = np.maximum(T / k, floor)
        # d(T/k)/dk = (T' k - T) / k^2 with T' = -ft / (wc - w0): -ft wc / ((wc - w0) k^2)
        ds = -ft * wc / ((wc - w0) * k * k)
        soft = (kappa > w0) & (T / k > floor)
        return np.where(kappa <= w0, K0, s), np.where(soft, ds, 0.0)

    # -- the update ---------------------------------------------------------------------------

    def _parts(self, jump: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = np.asarray(jump, dtype=float)
        if w.ndim != 2 or w.shape[1] not in (2, 3):
            raise ValueError(
                f"LinearCohesive: jump of shape {w.shape} must be (m, 2) or (m, 3): the normal "
                "opening, then the sliding, at m face points"
            )
        # M w: the derivative of w_eff^2 / 2, the opening weighted by the modes
        Mw = w.copy()
        Mw[:, 0] = np.maximum(w[:, 0], 0.0)
        Mw[:, 1:] *= self.shear**2
        w_eff = np.sqrt(Mw[:, 0] ** 2 + self.shear**2 * np.sum(w[:, 1:] ** 2, axis=1))
        return w, Mw, w_eff

    def update(
        self, jump: np.ndarray, state: dict[str, np.ndarray], band: None = None
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """``(traction (m, d), tangent (m, d, d), trial state)`` from the jump at the end of a
        step (local frame) and the committed state at its start (never modified); ``band`` is
        not used (the interface of :class:`~dolfinx_meshfree.physics.state.PointState`)."""
        K0 = self.K0
        w, Mw, w_eff = self._parts(jump)
        kappa_old = np.asarray(state["kappa"], dtype=float).reshape(len(w))
        kappa = np.maximum(kappa_old, w_eff)
        s, ds = self._secant(kappa)
        t = s[:, None] * Mw
        opening = w[:, 0] >= 0.0
        t[:, 0] = np.where(opening, s * w[:, 0], K0 * w[:, 0])
        D = self._secant_matrix(w, s)
        # loading (on or beyond the loading surface, past the peak, below the cap): the secant
        # moves with w_eff, d t / d w += ds/dkappa (M w)(M w)^T / w_eff
        loading = (w_eff >= kappa_old) & (ds != 0.0) & (w_eff > 0.0)
        if np.any(loading):
            g = np.where(loading, ds / np.where(w_eff > 0.0, w_eff, 1.0), 0.0)
            D += g[:, None, None] * Mw[:, :, None] * Mw[:, None, :]
        return t, D, {"kappa": kappa[:, None].copy()}

    def secant_stiffness(self, jump: np.ndarray, state: dict[str, np.ndarray]) -> np.ndarray:
        """The secant stiffness ``(m, d, d)`` at the jump from the committed state: the tangent of
        :meth:`update` without its loading term, ``diag(s or K_0, beta^2 s)`` at the trial
        ``kappa``. Positive definite (``s`` has its floor) where the consistent tangent of a
        softening point is not; Newton with it converges slowly but from further away (the
        fallback of :func:`~dolfinx_meshfree.follow_path` after a crack grew)."""
        w, _, w_eff = self._parts(jump)
        kappa = np.maximum(np.asarray(state["kappa"], dtype=float).reshape(len(w)), w_eff)
        return self._secant_matrix(w, self._secant(kappa)[0])

    def unloading_tangent(
        self, jump: np.ndarray, state: dict[str, np.ndarray], band: None = None
    ) -> np.ndarray:
        """The tangent of unloading (m, d, d): :meth:`secant_stiffness`, Newton's first iteration
        of a load step that unloads opened faces (:mod:`~dolfinx_meshfree.statics.history`)."""
        return self.secant_stiffness(jump, state)

    def _secant_matrix(self, w: np.ndarray, s: np.ndarray) -> np.ndarray:
        """``diag(s or K_0 (closed), beta^2 s, ...)`` (m, d, d) at the jumps ``w`` (m, d)."""
        m, d = w.shape
        diag = np.empty((m, d))
        diag[:, 0] = np.where(w[:, 0] >= 0.0, s, self.K0)
        diag[:, 1:] = (self.shear**2 * s)[:, None]
        D = np.zeros((m, d, d))
        D[:, np.arange(d), np.arange(d)] = diag
        return D

    # -- energies -----------------------------------------------------------------------------

    def stored_energy(self, jump: np.ndarray, state: dict[str, np.ndarray]) -> np.ndarray:
        """The recoverable energy per unit area ``(m,)``: ``s (<w_n>^2 + beta^2 |w_s|^2) / 2``
        plus the contact penalty's ``K_0 <-w_n>^2 / 2``."""
        w, _, w_eff = self._parts(jump)
        s, _ = self._secant(np.asarray(state["kappa"], dtype=float).reshape(len(w)))
        closed = np.minimum(w[:, 0], 0.0)
        return 0.5 * s * w_eff**2 + 0.5 * self.K0 * closed**2

    def dissipated_energy(self, state: dict[str, np.ndarray]) -> np.ndarray:
        """The energy dissipated per unit area up to ``kappa`` ``(m,)``: ``int_0^kappa T -
        T(kappa) kappa / 2`` (the free energy ``s w_eff^2 / 2`` loses ``ds kappa^2 / 2`` as ``s``
        falls), frozen at the cap; ``G_f`` at ``w_c`` without the cap."""
        kappa = np.asarray(state["kappa"], dtype=float).ravel()
        w0, wc, ft = self.w_0, self.w_c, self.ft
        k = np.clip(kappa, w0, self.kappa_cap)
        G = 0.5 * ft * w0 + ft * (wc * (k - w0) - 0.5 * (k * k - w0 * w0)) / (wc - w0)
        T = ft * (wc - k) / (wc - w0)
        return np.where(kappa <= w0, 0.0, G - 0.5 * T * k)
