"""Mean dilatation at finite strain for a rate-form law on Q1 cells in explicit dynamics: no
volumetric locking under plastic flow.

Johnson–Cook's flow is isochoric, and HJC's failed concrete keeps only a pressure. Q1 cells
integrated by their full rule (2 x 2 Gauss points, 2 x 2 x 2 on hexahedra) ask every point's
volume change to follow it, and lock. A cylindrical cavity in Johnson–Cook steel driven at
200 m/s (the axisymmetric strip of ``tests/test_cavity_expansion.py``) needed 22, 6.7 and
1.9 % more pressure than the 1D cavity with 10, 20 and 40 cells per radius. Nothing in the run
told the user.

The statics' cure (:mod:`~dolfinx_meshfree.statics.mean_dilatation`, Hughes' B-bar) at finite
strain is the mean-dilatation deformation gradient of Nagtegaal, Parks & Rice (1974), as Simo,
Taylor & Pister (1985, CMAME 51) and Moran, Ortiz & Shih (1990, IJNME 29) write it: every point
of a cell runs its law at

.. math::
    \\bar F_q = \\left(\\frac{\\bar J}{J_q}\\right)^{1/d} F_q, \\qquad
    \\bar J = \\frac{\\sum_q w_q\\, J_q}{\\sum_q w_q}

(the cell's volume ratio: ``w_q`` the points' weights in the force sum, ``2 pi R`` included in
axisymmetry, the bridging band's ``1 - alpha`` too), so the deviatoric motion stays each point's
own and the volume change is the cell's. ``d`` counts the components that change the volume: 3
in 3D and in axisymmetry (the hoop stretch ``r / R`` is scaled with the (r, z) block), 2 in plane
strain (``F_zz = 1`` kept, as de Souza Neto et al. 1996 take F-bar's exponent in plane strain).
Plane stress has no volumetric constraint; a triangle's strain is constant per cell. The
ramps' blended interface cells (a strip of one cell) and the particles keep their own rules.

The internal force is the derivative of the work ``sum_q w_q P(bar F_q) : d bar F_q`` that the
law's state accumulates (its ``work``), so the energy record balances as before. With ``sigma_q``
the law's Cauchy stress at ``bar F_q``, ``p_q`` its mean over the ``d`` volumetric components and
``bar p`` the cell's ``w``-weighted mean of ``p_q``, the nominal stress that the force sum
``sum_q w_q B0_q^T P_q`` of the explicit loop (Rabczuk et al. 2006, eq. 86-92) takes is

.. math::
    P_q = \\bar J\\, (\\sigma_q - p_q\\, I_d)\\, F_q^{-T} + \\bar p\\, J_q F_q^{-T}

(``I_d`` the identity on the volumetric components): the point's deviatoric stress with the
cell's volume, and the cell's mean pressure with the point's own ``J F^{-T}`` (its cofactor,
defined also where ``J_q <= 0``). It follows from ``d bar F F^{-1}``'s deviator being
``dF F^{-1}``'s and ``sum_q w_q d J_q = W d bar J``. At small strain it is B-bar's
``sigma + (bar p - p) I``. A uniform deformation has ``bar F = F`` and ``P = J sigma F^{-T}``, so
every patch test holds as without the mean.

A point whose ``J_q <= 0`` (an inverted corner of a crushed cell) runs at its own ``F``: HJC
erodes it (it carries nothing from then on, but its volume still counts in ``bar J``), and
Johnson–Cook refuses it, both as without the mean.

**What the mean gives up.** Nothing but the deviatoric stress resists a cell's corner folding
in at constant cell volume. Under a concentrated load on a soft deviatoric response (a plastic
or failed material pressed by contact nodes) a corner can then collapse: Hanchak's deformable
projectile (``demos/hanchak.py --projectile johnson-cook``, two cells across its radius, 16
through the slab, 1060 m/s) exits at 757 m/s against the rigid projectile's 1006, with a plastic
strain of 9 at a point, and at four cells across one of its points inverts at 58 microseconds;
the full rule gives 1028 and 1006. A point whose volume ratio leaves its cell's by a factor
``2^d`` (``max(s, 1 / s) >= 2``; measured at most 1.05 on a Taylor bar at 300 m/s, not a
test, and 1.13 on the cavity expanded twentyfold) is such a collapse:
:class:`CellCollapseWarning` names it, once per law. Refine where the load is concentrated, or
give that model ``dilatation="pointwise"``.

The stable step is bounded by the pointwise elastic tangent, as before: the mean dilatation
only softens the volumetric part (Jensen: ``bar theta^2 <= mean of theta^2``), so the bound
stays safe.

The two passes around the law's update (``bar F`` before it, ``P`` after) are compiled
(:func:`_scaled_kernel`, :func:`_nominal_kernel`) with the law's ``backend``; the numpy
methods are the reference (``tests/test_dynamic_dilatation.py`` compares them). Compiled, they
cost 0.1 of a Johnson–Cook update per point; in numpy they cost as much as the update itself.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np

from ..approx.jit import jit
from ..physics import rate_kernels
from ..physics.objective import as_3d, cofactor_3x3

if TYPE_CHECKING:  # annotations only (rate_forms builds this law's side)
    from .rate_forms import RateLaw

__all__ = ["COLLAPSE", "CellCollapseWarning", "MeanDilatationLaw"]

#: ``max(s, 1 / s)`` at which a point's volume ratio has left its cell's by a factor ``2^d``: a
#: cell collapsing at a corner (module docstring).
COLLAPSE = 2.0


class CellCollapseWarning(UserWarning):
    """A Q1 cell at its mean dilatation folds at a corner: one point's volume ratio is ``2^d``
    times away from its cell's (module :mod:`~dolfinx_meshfree.dynamics.rate_dilatation`). The
    stress there is unreliable; refine where the load is concentrated, or run the model with
    ``dilatation="pointwise"``."""


@jit
def _scaled_kernel(F, group, w, volume, d, s, J, Jbar):  # pragma: no cover - compiled
    """:meth:`MeanDilatationLaw._scaled`'s ``(s, J, bar J)`` into ``s``, ``J``, ``Jbar``."""
    total = np.zeros(volume.shape[0])
    for q in range(F.shape[0]):
        J[q] = rate_kernels.det3(F[q])
        total[group[q]] += w[q] * J[q]
    for q in range(F.shape[0]):
        c = group[q]
        Jbar[q] = total[c] / volume[c] if volume[c] > 0.0 else J[q]
        s[q] = (Jbar[q] / J[q]) ** (1.0 / d) if J[q] > 0.0 and Jbar[q] > 0.0 else 1.0


@jit
def _nominal_kernel(sigma, F, J, Jbar, group, w, volume, d, P):  # pragma: no cover - compiled
    """:meth:`MeanDilatationLaw._nominal`'s ``P_q`` into ``P`` (zeros on entry)."""
    m = F.shape[0]
    p = np.empty(m)
    total = np.zeros(volume.shape[0])
    for q in range(m):
        acc = 0.0
        for i in range(d):
            acc += sigma[q, i, i]
        p[q] = acc / d
        total[group[q]] += w[q] * p[q]
    cof = np.empty((3, 3))
    dev = np.empty((3, 3))
    for q in range(m):
        c = group[q]
        pbar = total[c] / volume[c] if volume[c] > 0.0 else p[q]
        rate_kernels.cofactor3(F[q], cof)
        live = False
        for i in range(3):
            for j in range(3):
                dev[i, j] = sigma[q, i, j] - (p[q] if i == j and i < d else 0.0)
                live = live or dev[i, j] != 0.0
        scale = Jbar[q] / J[q] if live and J[q] > 0.0 else 0.0
        for i in range(3):
            for j in range(3):
                acc = pbar * cof[i, j]
                if scale != 0.0:
                    for k in range(3):
                        acc += scale * dev[i, k] * cof[k, j]
                P[q, i, j] = acc


class MeanDilatationLaw:
    """A :class:`~dolfinx_meshfree.dynamics.rate_forms.RateLaw` run at the mean-dilatation
    gradient of its points' cells (module docstring), as the
    :class:`~dolfinx_meshfree.physics.constitutive.Material` the FE force sum reads.

    Args:
        law: The bound law of the FE points (its state, stress and work stay its own: the
            state criteria, the output and a conversion read ``law``).
        cells: The local cell of every point (m,).
        weights: The points' weights in the force sum (m,): reference volume (``2 pi R`` in
            axisymmetry) times any factor of the integrand.
    """

    def __init__(self, law: RateLaw, cells: np.ndarray, weights: np.ndarray) -> None:
        cells = np.asarray(cells, dtype=np.int64)
        weights = np.asarray(weights, dtype=float)
        if cells.shape != weights.shape:
            raise ValueError(f"{cells.shape} cells but {weights.shape} weights: one per point")
        self.law = law
        _, self._group = np.unique(cells, return_inverse=True)
        self._weights = weights
        self._volume = np.bincount(self._group, weights)
        #: The volumetric components: 2 in plane strain, 3 in 3D and axisymmetry.
        self.d = 2 if law.plane == "strain" else 3
        self.rho, self.plane = law.rho, law.plane
        #: ``"numba"`` (compiled passes) or ``"numpy"`` (the reference): the law's backend.
        self.backend = rate_kernels.resolve_backend(getattr(law.law, "backend", None))
        #: Whether :class:`CellCollapseWarning` was given (once per law).
        self.warned = False

    @property
    def gdim(self) -> int:
        return self.law.gdim

    def cell_mean(self, values: np.ndarray) -> np.ndarray:
        """Each point's cell's ``w``-weighted mean of ``values`` (m,); a cell of zero weight
        (a bridging band's edge, where ``1 - alpha = 0``) keeps its points' own values."""
        total = np.bincount(self._group, self._weights * values, minlength=len(self._volume))
        with np.errstate(divide="ignore", invalid="ignore"):
            mean = (total / self._volume)[self._group]
        return np.where(self._volume[self._group] > 0.0, mean, values)

    def _scaled(self, F3: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(s, J, bar J)`` (m,) with ``bar F = s F`` on the volumetric components."""
        if self.backend == "numba":
            m = len(F3)
            s, J, Jbar = np.empty(m), np.empty(m), np.empty(m)
            F3 = np.ascontiguousarray(F3)
            _scaled_kernel(F3, self._group, self._weights, self._volume, self.d, s, J, Jbar)
            return s, J, Jbar
        J = np.linalg.det(F3) if len(F3) else np.zeros(0)
        Jbar = self.cell_mean(J)
        s = np.ones_like(J)
        ok = (J > 0.0) & (Jbar > 0.0)
        s[ok] = (Jbar[ok] / J[ok]) ** (1.0 / self.d)
        return s, J, Jbar

    def _watch(self, s: np.ndarray, points: np.ndarray | None) -> None:
        """:class:`CellCollapseWarning` at the first ``max(s, 1 / s) >= COLLAPSE`` (local)."""
        if self.warned or not len(s):
            return
        ratio = np.maximum(s, 1.0 / s)
        q = int(np.argmax(ratio))
        if ratio[q] < COLLAPSE:
            return
        self.warned = True
        where = self.law.points if self.law.points is not None else points
        at = "" if where is None else f" at the point {np.round(where[q], 12).tolist()} (reference)"
        warnings.warn(
            f"a cell at its mean dilatation folds at a corner{at}: the point's volume ratio is "
            f"{ratio[q] ** self.d:.3g} times away from its cell's, so the cell's volume holds "
            "while the corner collapses, and the stress there is unreliable (a concentrated "
            "load on a soft deviatoric response). Refine where the load is concentrated, or "
            "give the model dilatation='pointwise'",
            CellCollapseWarning,
            stacklevel=2,
        )

    def _nominal(self, sigma: np.ndarray, F3: np.ndarray, J: np.ndarray, Jbar: np.ndarray):
        """``P_q`` (m, 3, 3) of the module docstring."""
        d = self.d
        if self.backend == "numba":
            P = np.zeros((len(F3), 3, 3))
            args = (self._group, self._weights, self._volume, d, P)
            _nominal_kernel(np.ascontiguousarray(sigma), np.ascontiguousarray(F3), J, Jbar, *args)
            return P
        p = np.trace(sigma[:, :d, :d], axis1=1, axis2=2) / d
        pbar = self.cell_mean(p)
        dev = sigma.copy()
        dev[:, np.arange(d), np.arange(d)] -= p[:, None]
        cof = cofactor_3x3(F3)
        P = pbar[:, None, None] * cof
        live = np.any(dev != 0.0, axis=(1, 2)) & (J > 0.0)
        if live.any():  # F^{-T} = cof / J
            scale = (Jbar[live] / J[live])[:, None, None]
            P[live] += scale * dev[live] @ cof[live]
        return P

    def first_piola(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """``P_q`` (m, d, d) at ``F`` (m, d, d), the law's state advanced at ``bar F``."""
        F = np.asarray(F, dtype=float)
        if self.law.plane == "axisymmetric":
            return self.law.first_piola(F, points)  # refused there, by name
        F3 = as_3d(F)
        s, J, Jbar = self._scaled(F3)
        self._watch(s, points)
        gdim = F.shape[1]
        sigma = self.law.stress(s[:, None, None] * F, points)
        return self._nominal(sigma, F3, J, Jbar)[:, :gdim, :gdim]

    def axisymmetric_piola(
        self, F: np.ndarray, points: np.ndarray, hoop: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``P_q``'s (r, z) block (m, 2, 2) and hoop component (m,) at ``F`` (m, 2, 2) and the
        hoop stretch ``hoop`` (m,): the law's state advanced at ``bar F = s F``, ``s hoop``."""
        F = np.asarray(F, dtype=float)
        hoop = np.asarray(hoop, dtype=float)
        F3 = as_3d(F, hoop)
        s, J, Jbar = self._scaled(F3)
        self._watch(s, points)
        sigma = self.law.stress(s[:, None, None] * F, points, s * hoop)
        P = self._nominal(sigma, F3, J, Jbar)
        return P[:, :2, :2], P[:, 2, 2]

    def tangent(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """The law's pointwise elastic bound (the stable step's; module docstring)."""
        return self.law.tangent(F, points)

    def strain_energy_density(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """The stress work per unit reference volume that the law's state carries."""
        return self.law.strain_energy_density(F, points)

    def ufl_first_piola(self, F: object) -> object:
        return self.law.ufl_first_piola(F)

    def wave_speed(self, F: np.ndarray | None = None) -> float:
        return self.law.wave_speed(F)
