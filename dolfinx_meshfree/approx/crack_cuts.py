"""Crack-aware MLS weights: the visibility criterion and the diffraction method as pair cuts.

A crack cuts the weight ``w_I(x)`` of eq. (3.7) (Belytschko et al. 1995; "0 ... across
boundaries" in eq. 3.10) for the (point, particle) pairs whose segment ``x - x_I`` crosses it:

* ``"visibility"`` (Belytschko, Lu & Gu 1994): the pair is dropped. The shape functions jump
  across the crack, but also across the crack's extension beyond a tip (the spurious
  discontinuity the diffraction method removes).
* ``"diffraction"`` (Organ, Fleming & Belytschko 1996, the default): the distance in the weight
  becomes the length of a path bent around the tip ``x_c``,

  .. math::
      d_I(x) = \\left(\\frac{s_1 + s_2(x)}{s_0(x)}\\right)^\\lambda s_0(x), \\quad
      s_0 = |x - x_I|,\\ s_1 = |x_I - x_c|,\\ s_2 = |x - x_c|,

  with the exact gradient
  ``grad d = lambda r^(lambda-1) grad s2 + (1 - lambda) r^lambda grad s0``, ``r = (s1+s2)/s0``.
  On the crack's extension the path is straight (``s1 + s2 = s0``): ``d`` and its gradient are
  continuous there, so the shape functions are continuous ahead of the tip and discontinuous
  across the faces. Pairs whose bent path exceeds the support radius drop out. Of several tips
  the shortest admissible path is taken (a path whose legs cross the crack is not admissible;
  a pair with none drops out). ``lambda = 2`` is the default, the value Organ et al. 1996 and
  later EFG fracture work use most; ``lambda = 1`` (the plain path length) is available.

Points on the crack faces take the side given by ``MLS.tabulate(..., sides=...)``: their values
are the one-sided limits. All pairs are handled in the pair arrays (no Python loop per pair).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..geometry.crack import CRACK_METHODS, Crack, CrackDomain, validate_in_patch
from .mls import MLS, MomentMatrixError
from .mouth_supports import widen_at_mouths

if TYPE_CHECKING:  # annotations only
    from ..geometry.patch import ParticlePatch

__all__ = [
    "CRACK_METHODS",
    "CrackCut",
    "attach_cracks",
    "diffraction_distance",
    "support_radius_at",
]


def diffraction_distance(
    x: np.ndarray, xp: np.ndarray, tip: np.ndarray, exponent: float
) -> tuple[np.ndarray, np.ndarray]:
    """Diffracted distance ``d`` (n,) and its gradient w.r.t. ``x`` (n, 2) (Organ et al. 1996).

    Args:
        x: Evaluation points of the pairs (n, 2).
        xp: Particles of the pairs (n, 2) (``x_I``), distinct from ``x``.
        tip: The crack tip ``x_c`` of each pair (n, 2).
        exponent: ``lambda`` (>= 1).
    """
    dx = x - xp
    s0 = np.linalg.norm(dx, axis=1)
    s1 = np.linalg.norm(xp - tip, axis=1)
    r2 = x - tip
    s2 = np.linalg.norm(r2, axis=1)
    ds0 = dx / s0[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        ds2 = np.where(s2[:, None] > 0.0, r2 / s2[:, None], 0.0)
    r = (s1 + s2) / s0
    lam = float(exponent)
    d = r**lam * s0
    grad = (lam * r ** (lam - 1.0))[:, None] * ds2 + ((1.0 - lam) * r**lam)[:, None] * ds0
    return d, grad


class CrackCut:
    """A pair cut (see :attr:`~dolfinx_meshfree.MLS.pair_cuts`) for a list of cracks.

    Args:
        mls: The approximation whose weights are cut (its particles and support radii).
        cracks: The cracks.
        method: ``"diffraction"`` (default) or ``"visibility"``.
        exponent: ``lambda`` of the diffraction method (default 2).

    A pair crossing two cracks drops out. Raises :class:`~dolfinx_meshfree.MomentMatrixError`
    naming the nearest crack tip when the cut leaves a point with fewer particles than the basis
    needs.
    """

    def __init__(
        self,
        mls: MLS,
        cracks: Sequence[Crack],
        method: str = "diffraction",
        exponent: float = 2.0,
    ) -> None:
        if method not in CRACK_METHODS:
            raise ValueError(f"crack_method={method!r} is not known; use one of {CRACK_METHODS}")
        if not (isinstance(exponent, int | float) and np.isfinite(exponent) and exponent >= 1):
            raise ValueError(
                f"exponent={exponent!r} of the diffraction method must be >= 1 (1 or 2 are usual)"
            )
        if mls.gdim != 2:
            raise ValueError(f"cracks are 2D; the MLS has gdim={mls.gdim}")
        bad = [c for c in cracks if not isinstance(c, Crack)]
        if bad:
            raise ValueError(f"cracks should be Crack objects, got {bad[0]!r:.80}")
        self.mls = mls
        self.cracks = list(cracks)
        self.method = method
        self.exponent = float(exponent)

    def __call__(
        self,
        x: np.ndarray,
        i: np.ndarray,
        j: np.ndarray,
        dx: np.ndarray,
        dist: np.ndarray,
        ddist: np.ndarray,
        sides: np.ndarray | None = None,
        check: bool = True,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        cut = self._cut(x, i, j, dist, ddist, sides)
        if cut is None:  # no weight cut: every pair kept as it is
            return i, j, dx, dist, ddist
        keep, dist, ddist = cut
        if check:
            self._check_counts(x, i, keep)
        return i[keep], j[keep], dx[keep], dist[keep], ddist[keep]

    def unchecked(
        self, *pairs: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The cut (the arguments of a call) without the refusal of a point left with too few
        particles (for :meth:`~dolfinx_meshfree.MLS.support_quality`, which reports them)."""
        return self(*pairs, check=False)

    def _cut(
        self,
        x: np.ndarray,
        i: np.ndarray,
        j: np.ndarray,
        dist: np.ndarray,
        ddist: np.ndarray,
        sides: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(keep, dist, ddist)``: the pairs kept and their distances (diffracted where a
        pair is seen around a tip); ``None`` when no pair crosses a crack."""
        if not self.cracks or i.size == 0:
            return None
        if sides is not None and not np.all(np.isin(sides, (-1, 0, 1))):
            bad = np.asarray(sides)[~np.isin(sides, (-1, 0, 1))]
            raise ValueError(f"sides should be +1, -1 or 0 (the crack face), got {bad[:5]}")
        side = None if sides is None else np.asarray(sides).reshape(-1)[i]
        ncross = np.zeros(i.size, dtype=np.int64)
        which = np.full(i.size, -1)
        for c, crack in enumerate(self.cracks):  # loop over cracks, pairs vectorised
            hit = crack.crosses_pairs(x, i, self.mls.points, j, side)
            ncross += hit
            which[hit] = c
        if not ncross.any():
            return None
        keep = ncross == 0
        dist, ddist = dist.copy(), ddist.copy()
        if self.method == "diffraction":
            once = np.flatnonzero(ncross == 1)
            for c, crack in enumerate(self.cracks):
                sel = once[which[once] == c]
                if sel.size == 0:
                    continue
                d, grad = self._around_tips(
                    crack, x[i[sel]], self.mls.points[j[sel]], None if side is None else side[sel]
                )
                ok = d < self.mls.radii[j[sel]]
                dist[sel[ok]], ddist[sel[ok]] = d[ok], grad[ok]
                keep[sel[ok]] = True
        return keep, dist, ddist

    def hint(self, x: np.ndarray) -> str:
        """Why a point ``x`` (gdim,) beside a crack may see too few particles, for a refusal's
        message ("" when no crack is within the largest support radius)."""
        if not self.cracks:
            return ""
        d = np.array(
            [float(c.distance(np.asarray(x, dtype=float)[None, :2])[0]) for c in self.cracks]
        )
        k = int(d.argmin())
        if d[k] >= float(self.mls.radii.max()):
            return ""
        return (
            f"the point is {d[k]:.3g} from a crack ({self.cracks[k]!r:.80}), which cuts off the "
            "particles past it: a crack that runs within a tenth of a spacing of a row of "
            "particles leaves the points beside it one row to see (CrackPlacementWarning "
            "flags such a crack when it is placed); move the crack about half a spacing off "
            "the rows"
        )

    def _around_tips(
        self, crack: Crack, p: np.ndarray, q: np.ndarray, side: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Shortest admissible diffracted distance (``inf`` where none) and its gradient."""
        best = np.full(p.shape[0], np.inf)
        grad = np.zeros_like(p)
        for tip in crack.tips:  # one or two tips
            t = np.broadcast_to(tip, p.shape)
            ok = ~crack.crosses(q, t) & ~crack.crosses(p, t, side)
            d, g = diffraction_distance(p, q, t, self.exponent)
            better = ok & (d < best)
            best[better], grad[better] = d[better], g[better]
        return best, grad

    def _check_counts(self, x: np.ndarray, i: np.ndarray, keep: np.ndarray) -> None:
        m, nb = x.shape[0], self.mls.num_basis
        before = np.bincount(i, minlength=m)
        after = np.bincount(i[keep], minlength=m)
        bad = np.flatnonzero((after < nb) & (before >= nb))
        if bad.size == 0:
            return
        q = int(bad[0])
        tips = np.vstack([c.tips for c in self.cracks])
        where = "a crack that splits the body: particles on both sides of it"
        if len(tips):
            dt = np.linalg.norm(tips - x[q], axis=1)
            k = int(dt.argmin())
            where = f"the nearest crack tip is at {tips[k]} ({dt[k]:.3g} away)"
        raise MomentMatrixError(
            f"MLS moment matrix is singular at {bad.size} point(s) near a crack ({self.method}); "
            f"first: point {q} at {x[q]} sees {after[q]} of its {before[q]} particle(s) past the "
            f"crack but the {self.mls.basis} basis needs at least {nb}; {where}: "
            f"{self.mls._fix} so that enough particles are visible around the tip, or add "
            "particles near the tip"
        )


def support_radius_at(mls: MLS, x: np.ndarray) -> float:
    """The largest support radius of the particles whose supports cover the point ``x`` (0 if
    none): how far a cut at ``x`` changes the shape functions (local)."""
    return float(mls.radii[np.linalg.norm(mls.points - x, axis=1) < mls.radii].max(initial=0))


def attach_cracks(
    mls: MLS,
    cracks: Sequence[Crack],
    method: str = "diffraction",
    exponent: float = 2.0,
    patch: ParticlePatch | None = None,
    domain: ParticlePatch | CrackDomain | None = None,
) -> CrackCut:
    """Cut the weights of ``mls`` by ``cracks``: appends a :class:`CrackCut` to
    ``mls.pair_cuts``, marks ``mls`` changed, and has every later :meth:`Crack.extend` mark it
    changed too (tables built before are then stale).

    With ``domain`` (or ``patch``; collective), the supports at the cracks' mouths are widened
    where the crack meets the boundary at a sharp angle
    (:func:`~dolfinx_meshfree.approx.mouth_supports.widen_at_mouths`: eq. 3.11's search for
    enough particles, with the crack as a boundary; recorded in ``mls.widened``).

    With ``patch`` (collective), each tip must be at least the largest support radius of the
    particles around it from the FE interface: the cut changes the shape functions wherever a
    support reaches past the crack, up to a support radius around the tip, and the FE side and
    the interface elements cannot follow (:func:`~dolfinx_meshfree.geometry.crack.validate_in_patch`
    checks one particle spacing when the crack is added, before the supports are known).
    """
    cut = CrackCut(mls, cracks, method, exponent)
    region = domain if domain is not None else patch
    if region is not None:
        mls.pair_cuts.append(cut)
        try:
            widen_at_mouths(mls, cut.cracks, region)
        finally:
            mls.pair_cuts.pop()
    if patch is not None:
        for crack in cut.cracks:
            # a crack through the body has no tip
            r = max((support_radius_at(mls, t) for t in crack.tips), default=0.0)
            validate_in_patch(crack, patch, clearance=r)
    mls.pair_cuts.append(cut)
    for crack in cut.cracks:
        crack.add_listener(mls.changed)
    mls.changed()
    return cut
