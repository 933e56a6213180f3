"""A grown segment that the crack-aware MLS can carry: the kink angle turned a little where the
criterion's segment would leave points with too few particles (dynamic growth by K_Ic).

A segment that runs nearly along a row of particles, closer than a small fraction of a spacing,
leaves the points between it and the row with only the row beyond on their side of the cut: with
a grid of particles and the linear basis, collinear particles and a singular moment matrix. A
model rebuilt or updated with such a crack is refused (``MomentMatrixError``), and the run
stops. Measured on a user's plate (0.2 x 0.12, spacing 0.004, an inclined edge crack from a
random height and angle, tractions on two edges, 60 us; ``DynamicCrackGrowth`` at 3.5-spacing
segments): 5 of 30 runs of pure EFG on quadrilaterals and 3 of 30 of lagrange with an adaptive
patch on triangles stopped so at an extension; e.g. a tip that had ended 0.005 spacing off a
row, half a spacing from its nearest particles, grew its next segment at 3.7 degrees to the row,
0.03 spacing past a particle of it.

:func:`turn_to_fit` tabulates the MLS, cut by the crack as the extension would make it, at the
cut-cell rule of the particle cells about the new segment (the points a rebuilt or updated
model tabulates there). A kink that lands on a particle or on a row of particles (nearly along
the crack) can leave no next segment to grow (kinks 0.0025 to 0.055 spacing off a row, between
two of its particles, trapped the growth at the next extension: every turn failed there), so
from such a tip the next segments at the usual kinks (:data:`AHEAD`) must tabulate too. The
segment is turned by the first of :data:`TURNS` that passes (Belytschko et al. 1995 grow
straight segments in the direction of the criterion; a turned segment departs from it by at
most 15 degrees, and the next segment takes the criterion's direction again). A segment that
passes as it is, the usual case, is not turned; every turn is recorded by the caller
(``GrowthCheck.turn``). ``benchmarks/bench_growth_robustness.py`` counts the runs stopped and
turned, with and without (``DynamicCrackGrowth(..., fit_segments=False)``). Geometric rules
instead turned far more: keeping every segment ``NEAR_ROW`` spacing off every particle turned
a segment in 25 and 21 of the two 30-run sets above, and refusing every tip on a particle or
a row turned one segment of Kalthoff–Winkler's efg and lagrange runs and two of the adaptive
patch's (101 nodes, 80 us), which the probe leaves alone.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from .. import _compat
from ..approx.crack_cuts import CrackCut
from ..approx.mls import MomentMatrixError
from ..geometry.crack import NEAR_ROW, Crack, particle_spacing, point_segment_distance
from ..geometry.cut_cells import cut_cell_quadrature
from .sifs import model_cracks

if TYPE_CHECKING:  # annotations only
    from .explicit import ExplicitDynamics

__all__ = ["TURNS", "turn_to_fit"]

#: The turns, in degrees, tried in turn for a segment the MLS cannot carry.
TURNS = (0.0, 5.0, -5.0, 10.0, -10.0, 15.0, -15.0)
#: A new tip this many spacings off the segment between two neighbouring particles is on their
#: row (:func:`_on_a_row`; the kinks that trapped the growth lay 0.0025-0.055 spacing off it).
ROW_LINE = 0.1
#: Particles closer than this many spacings are neighbours (a grid's rows and columns, not its
#: diagonals).
NEIGHBOURS = 1.2
#: A row within this many degrees of the arriving segment can trap its tip (:func:`_on_a_row`).
ROW_ANGLE = 30.0
#: The kinks, in degrees, of the next segments that a new tip on a row must carry.
AHEAD = (0.0, 15.0, -15.0)


def _cells(dyn: ExplicitDynamics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """This rank's particle cells, their midpoints and their sizes (midpoint to the farthest
    corner), once per extension for every probe of it."""
    domain = model_cracks(dyn)[1]
    msh = domain.mesh
    cells = np.asarray(domain.cells, dtype=np.int64)
    corners = msh.geometry.x[_compat.geometry_dofmap(msh)[cells]][..., :2]
    mid = corners.mean(axis=1)
    return cells, mid, np.linalg.norm(corners - mid[:, None], axis=2).max(axis=1)


def _carries(
    dyn: ExplicitDynamics,
    crack: Crack,
    trial: Crack,
    end: int,
    degree: int,
    cells: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> bool:
    """Whether the model's MLS, cut by its cracks with ``trial`` in place of ``crack``,
    tabulates at the cut-cell rule of ``degree`` of this rank's particle ``cells`` (with their
    midpoints and sizes, :func:`_cells`) that come within the largest support radius of
    ``trial``'s segment at ``end`` (the points whose supports the segment can cut;
    collective: every rank's answer)."""
    cracks, domain = model_cracks(dyn)
    mls, msh = dyn.mls, domain.mesh
    ids, mid, size = cells
    a, b = (trial.points[-2], trial.points[-1]) if end != 0 else (trial.points[1], trial.points[0])
    gap = point_segment_distance(mid, a[None], b[None])[:, 0] - size
    near = ids[gap < mls.radii.max()]  # a point there may see a particle past the segment
    ok = True
    if near.size:
        swapped = [trial if c is crack else c for c in cracks]
        saved = mls.pair_cuts
        mls.pair_cuts = [
            CrackCut(mls, [trial if c is crack else c for c in cut.cracks], cut.method,
                     cut.exponent) if isinstance(cut, CrackCut) else cut
            for cut in saved
        ]  # fmt: skip
        try:
            mls.tabulate(cut_cell_quadrature(msh, near, swapped, degree).points)
        except MomentMatrixError:
            ok = False
        finally:
            mls.pair_cuts = saved
    return bool(dyn.comm.allreduce(ok, op=MPI.LAND))


def turn_to_fit(
    dyn: ExplicitDynamics, crack: Crack, end: int, theta: float, length: float, degree: int
) -> float:
    """The degrees by which to turn the next segment of ``crack`` at its tip ``end`` (kink
    angle ``theta``, radians, ``length``) so that the model's MLS can carry it: the first of
    :data:`TURNS` whose grown crack tabulates about the new segment (:func:`_carries`) and, for
    a tip on a particle or a row of particles (:func:`_on_a_row`), about the next segments at
    the kinks :data:`AHEAD`; 0 when none does (the extension then fails as it would have;
    collective, the same on every rank). The crack is not changed."""
    domain = model_cracks(dyn)[1]
    particles = domain.particles.positions[:, :2]
    h = particle_spacing(domain)
    cells = _cells(dyn)
    for turn in TURNS:
        trial = _grown(crack, end, theta + np.deg2rad(turn), length)
        if trial is None:
            continue
        if not _carries(dyn, crack, trial, end, degree, cells):
            continue
        # a tip on a particle or on a row of particles can trap the next segment: it must then
        # carry the next segments of the usual kinks (the others, the usual case, are not tried)
        if _on_a_row(trial.points[end], trial.tip_direction(end), particles, h) and not all(
            (ahead := _grown(trial, end, np.deg2rad(a), length)) is None
            or _carries(dyn, crack, ahead, end, degree, cells)
            for a in AHEAD
        ):
            continue
        return float(turn)
    return 0.0


def _on_a_row(tip: np.ndarray, direction: np.ndarray, particles: np.ndarray, h: float) -> bool:
    """Whether a segment arriving at ``tip`` along the unit ``direction`` ends within
    ``NEAR_ROW`` spacing of a particle, or within :data:`ROW_LINE` spacing of the segment
    between two neighbouring particles (closer than :data:`NEIGHBOURS` spacings) that runs
    within :data:`ROW_ANGLE` degrees of ``direction`` (local, the same on every rank with
    replicated particles). A kink there can leave the next segment nowhere to go: the points in
    its wedge see only that row's particles. Measured:
    kinks 0.0025, 0.005 and 0.055 spacing off a row, between two of its particles, the crack
    arriving at 4-9 degrees to the row, from which the criterion's next segment and every turn
    of :data:`TURNS` failed (a tip the user placed 0.025 spacing off a row too)."""
    d = np.linalg.norm(particles - tip, axis=1)
    if d.min() < NEAR_ROW * h:
        return True
    near = particles[d < NEIGHBOURS * h]
    i, j = np.triu_indices(len(near), k=1)
    span = near[j] - near[i]
    length = np.linalg.norm(span, axis=1)
    along = np.abs(span @ direction) > np.cos(np.deg2rad(ROW_ANGLE)) * length
    pairs = (length < NEIGHBOURS * h) & along
    if not pairs.any():
        return False
    gap = point_segment_distance(tip[None], near[i[pairs]], near[j[pairs]])
    return bool(gap.min() < ROW_LINE * h)


def _grown(crack: Crack, end: int, theta: float, length: float) -> Crack | None:
    """A copy of ``crack`` grown by a segment at ``theta`` (radians) from its tip ``end``
    (``None``: the segment folds back or crosses the crack; no patch checks)."""
    trial = Crack(crack.points.copy())
    trial.is_tip = list(crack.is_tip)
    try:
        trial.extend(theta, length, tip=end)
    except ValueError:
        return None
    return trial
