"""A particle patch that grows along a followed path (issue 24: the patch grows where a cohesive
crack runs or the material fails; issue 25, item 1, in statics with state).

:func:`~dolfinx_meshfree.follow_path` with ``adapt`` asks its criteria
(:mod:`~dolfinx_meshfree.geometry.patch_criteria`: :class:`~dolfinx_meshfree.NearTips`,
:class:`~dolfinx_meshfree.FieldAbove`, :class:`~dolfinx_meshfree.CellsWhere`, or the user's)
after every converged step which FE cells must be particles. When any must:

* the patch grows (:meth:`~dolfinx_meshfree.ParticlePatch.grown`: the new cells' particles
  placed as at build time), the cracks move into it, and the model is rebuilt on it with its
  law, coupling, conditions, loads and cohesive faces (:func:`~.coupled.on_patch`); the
  interface and its multipliers move with the patch because they are built from it;
* the FE dofs are copied (the same space); the particle coefficients are the ``L2``
  projection of the old coupled field (FE on the converted cells, the old particles elsewhere)
  onto the new particles' MLS space on the new patch rule,
  ``Phi^T W Phi d = Phi^T W u_old(x_q)`` (:func:`fit_particles`); the multipliers start from
  zero (the coupling's linear part, which the first Newton iteration solves exactly);
* the committed states move with their points: the cohesive faces' at the same positions
  (:func:`~.state_carry.carry_at_points`), the bulk's by the closest-point transfer within each
  cell (:func:`~.state_carry.carry_pooled`: a converted cell's particle points take the states
  of its FE points);
* the model is brought back to equilibrium at the same control value, as after a crack grew.

What a rebuild changes is recorded, not assumed: the stored energy before and after, with the
work of the load on the way (:attr:`PatchEvent.energy_change`), and the bulk's dissipated energy
before and after the transfer (:attr:`~.path_following.PathResult.carried`).
"""

from __future__ import annotations

import time
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..approx.crack_cuts import support_radius_at
from ..geometry.crack import CrackPlacementWarning, particle_spacing
from ..geometry.patch_criteria import (
    GrowthContext,
    NearTips,
    PatchCriterion,
    as_criteria,
    named_cells,
)
from ..parallel import raise_on_all_ranks
from .cohesive_growth import CohesiveGrowth
from .coupled import STATIC_CRACK_COUPLINGS, on_patch
from .patch_growth import PatchEvent

if TYPE_CHECKING:  # annotations only
    from ..couplings.base import CoupledSolution
    from .coupled import CoupledElasticity
    from .coupled_newton import BlockModel

__all__ = [
    "ADAPT_COUPLINGS",
    "check_adapt",
    "fit_particles",
    "grow_patch",
    "path_context",
    "site_context",
]

#: The couplings whose patch grows along a followed path: those that carry a crack in statics.
#: The projection fits the particle coefficients on the patch rule; the ramps' blended interface
#: cells and master-slave's slave links are not in that rule, and the re-equilibration that
#: follows brings them to equilibrium (measured against a fixed patch: ``tests/test_path_patch.py``
#: and the softening guide).
ADAPT_COUPLINGS: tuple[str, ...] = STATIC_CRACK_COUPLINGS


def check_adapt(
    model: Any, efg: bool, adapt: Any, growths: list[CohesiveGrowth]
) -> list[PatchCriterion]:
    """The criteria of ``adapt`` for ``model`` (local: a ``TypeError`` or ``ValueError`` naming
    the fix). A :class:`~dolfinx_meshfree.NearTips` radius below the reach a growing crack's
    next extension needs (:func:`path_context`) is refused: the tip would leave the patch."""
    if efg:
        raise TypeError(
            "follow_path(adapt=...) grows the particle patch of a CoupledElasticity; a pure "
            "EFGElasticity has particles everywhere: there is no FE cell to convert"
        )
    if model.coupling not in ADAPT_COUPLINGS:
        raise ValueError(
            f"follow_path(adapt=...) with coupling={model.coupling!r}: the patch grows with "
            f"{list(ADAPT_COUPLINGS)}; choose one of these, or a fixed patch that covers the path"
        )
    criteria = as_criteria(adapt)
    h = particle_spacing(model.patch)
    need = sum(_reach(model, growths)) / h
    for c in criteria:
        if isinstance(c, NearTips) and c.spacings is not None and c.spacings < need:
            raise ValueError(
                f"{c!r}: a growing crack's next extension needs the patch {need:.3g} spacings "
                "about its tip (the increment and a support radius, so that the new tip stays a "
                f"support radius from the FE interface); give spacings >= {need:.3g}, or None "
                "(two spacings more)"
            )
    return criteria


def _reach(model: CoupledElasticity, growths: list[CohesiveGrowth]) -> tuple[float, float]:
    """The growing cracks' increment (without growing cracks, the default step of a crack
    that starts) and the largest support radius at the tips (without tips, the median one):
    their sum is the reach of the next extension, as its check measures it (the new tip a
    support radius from the FE interface; :func:`path_context`)."""
    step = max((gr.step for gr in growths), default=CohesiveGrowth.step)  # a crack to start
    mls = model.mls
    tips = [c.points[e] for c in model.patch.cracks for e in c.tip_ends]
    radius = max((support_radius_at(mls, tip) for tip in tips), default=0.0)
    return step * particle_spacing(model.patch), radius or float(np.median(mls.radii))


def path_context(
    model: CoupledElasticity, growths: list[CohesiveGrowth], step: int, solution: Any
) -> GrowthContext:
    """What the criteria read after a converged step: the tips of the patch's cracks, the
    solution, the growing cracks' increment (``step`` spacings; without growing cracks, the
    default step of a crack that starts), and the reach the next extension needs: the increment
    plus the largest support radius (the new tip stays a support radius from the FE interface).
    :class:`~dolfinx_meshfree.NearTips` with its default radius adds two spacings to that
    reach."""
    cracks = model.patch.cracks
    tips = [c.points[e] for c in cracks for e in c.tip_ends]
    increment, radius = _reach(model, growths)
    reach = increment + radius
    return GrowthContext(
        step=step,
        tips=np.asarray(tips, dtype=float).reshape(-1, 2),
        solution=solution,
        sif_radius=reach,
        increment=increment,
    )


def site_context(
    model: CoupledElasticity,
    growths: list[CohesiveGrowth],
    step: int,
    solution: Any,
    site: np.ndarray,
    lead: float,
) -> GrowthContext:
    """:func:`path_context` with a site where a crack is to start among the tips, and the reach
    its first stretch needs: ``lead`` spacings and the particles' largest support radius, the
    clearance :func:`~dolfinx_meshfree.statics.crack_initiation.first_stretch` keeps from the FE
    interface."""
    context = path_context(model, growths, step, solution)
    context.tips = np.vstack([context.tips, np.asarray(site, dtype=float)[None, :2]])
    first = lead * particle_spacing(model.patch) + float(model.mls.radii.max())
    context.sif_radius = max(context.sif_radius, first)
    return context


def grow_patch(
    model: CoupledElasticity, criteria: list[PatchCriterion], context: GrowthContext
) -> tuple[tuple[CoupledElasticity, PatchEvent] | None, bool]:
    """Ask ``criteria``; when FE cells must be particles, the model on the grown patch and the
    event, else ``None``; and whether any criterion named a cell, patch cells included
    (collective). The cracks move to the new patch (released from the old one and its MLS);
    the old model is left as it was otherwise."""
    patch = model.patch
    comm = patch.comm
    want, by, named, _ = named_cells(criteria, patch, context, "follow_path")
    added = comm.allreduce(int(want.sum()))
    if added == 0:
        return None, named
    t0 = time.perf_counter()
    grown = patch.grown(np.flatnonzero(want))
    with warnings.catch_warnings():  # the path is the physics' (as Crack.extend's)
        warnings.simplefilter("ignore", CrackPlacementWarning)
        for crack in patch.cracks:
            grown.add_crack(crack)
    for crack in grown.cracks:
        crack.release(patch, model.mls)
    new = on_patch(model, grown)
    event = PatchEvent(
        step=context.step, cells_added=added, by=by,
        particles_before=patch.particles.num_particles,
        particles_after=grown.particles.num_particles,
        cells_after=comm.allreduce(int(np.asarray(grown.cells).size)),
        time_rebuild=time.perf_counter() - t0,
    )  # fmt: skip
    return (new, event), named


def fit_particles(old: CoupledSolution, new: BlockModel) -> np.ndarray:
    """The new particle coefficients (interleaved, original order, the same on every rank): the
    ``L2`` projection of the old coupled field ``old`` onto the new particles' MLS space on the
    new patch rule, ``Phi^T W Phi d = Phi^T W u_old(x_q)`` (collective). Exact for any field the
    new MLS reproduces (linear fields)."""
    side = new.particles
    q = side.rule
    gdim = side.gdim
    n = side.P.num_particles
    phi = side.forces.table.values.tocsr()
    w = np.asarray(q.weights, dtype=float)
    values = raise_on_all_ranks(side.comm, lambda: old.evaluate_at_quadrature(q)[0])
    M = (phi.T @ sp.diags(w) @ phi).tocoo()
    b = np.asarray(phi.T @ (w[:, None] * values)).reshape(n, gdim)
    parts = side.comm.allgather((M.row, M.col, M.data))
    rows, cols, data = (np.concatenate([p[k] for p in parts]) for k in range(3))
    M = sp.csc_matrix((data, (rows, cols)), shape=(n, n))
    b = side.comm.allreduce(b)
    d = spla.spsolve(M, b).reshape(n, gdim)

    def check() -> None:
        if not np.all(np.isfinite(d)):
            raise RuntimeError(
                "the projection of the old field onto the grown patch's particles failed: their "
                "consistent mass on the patch rule is singular"
            )

    raise_on_all_ranks(side.comm, check)
    return d.ravel()
