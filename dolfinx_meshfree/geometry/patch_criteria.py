"""Where a particle patch grows during a run (issue 25, item 2): small criterion objects that name
the FE cells which must become particles.

"Model only what a scene needs": the particles belong where the physics needs them (a crack tip,
a failing material), finite elements everywhere else. Belytschko et al. (1995), sec. 6, grew
their refinement ahead of the crack; Rabczuk et al. (2006), sec. 1 and 5.5, cite adaptively
generated EFG domains for crack growth (Karutz) and the conversion of elements into particles
(Sauer). A criterion answers one question at a time: which owned cells must be particles now.
A driver (:class:`~dolfinx_meshfree.QuasiStaticCrackGrowth` with ``adapt``) asks it between
steps, adds the cells it names to the patch (:meth:`ParticlePatch.grown`) and rebuilds the model.
The patch only grows: cells never return to FE (no shrinking back).

Four criteria, each a :class:`PatchCriterion`:

* :class:`NearTips`: every cell within ``k`` particle spacings of a crack tip (the tips after the
  coming extension included), so that the SIF domains and the tip's supports stay in the
  particles;
* :class:`FieldAbove`: the FE cells where a field of the last solution passes a threshold (the
  largest principal stress or strain at the cell midpoint, or a user's function of the
  displacement gradient);
* :class:`StateAbove`: the FE cells where a rate-form law's state variable (damage, plastic
  strain) passes a threshold at any point: failing elements become particles (issue 27);
* :class:`CellsWhere`: a user's callable on the cell midpoints.

:func:`cells_near` gives the cells within a distance of points or a polyline, e.g. the initial
patch around a crack.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import dolfinx
import numpy as np
import numpy.typing as npt

from .. import _compat
from ..mesh_cache import cached
from ..parallel import raise_on_all_ranks
from .crack import _orient, particle_spacing, point_segment_distance, segments_intersect
from .quadrature import QuadraturePoints

if TYPE_CHECKING:  # annotations only
    from ..physics.state import PointState
    from .patch import ParticlePatch

__all__ = [
    "PATCH_FIELDS",
    "CellsWhere",
    "FieldAbove",
    "GrowthContext",
    "NearTips",
    "PatchCriterion",
    "PatchCriterionWarning",
    "StateAbove",
    "as_criteria",
    "cells_near",
    "named_cells",
    "static_state_values",
]


class PatchCriterionWarning(UserWarning):
    """A patch criterion that named no cell in a whole run (statics or dynamics)."""


def warn_unused(criteria: list, driver: str, checks: str, stacklevel: int = 3) -> None:
    """The :class:`PatchCriterionWarning` of a driver whose ``criteria`` never named a cell in
    ``checks`` (e.g. "12 step(s)"); ``stacklevel`` as ``warnings.warn``'s, counted from the
    driver's call of this function plus one."""
    warnings.warn(
        f"{driver}: the criteria {[repr(c) for c in criteria]} named no cell in {checks}; the "
        "patch stayed as given (is the criterion the intended one: its radius, its threshold?)",
        PatchCriterionWarning,
        stacklevel=stacklevel,
    )


#: The named fields of :class:`FieldAbove`.
PATCH_FIELDS = ("max_principal_stress", "max_principal_strain")

#: Spacings that :class:`NearTips` keeps beyond the SIF domains by default (the domains'
#: clearance from the FE interface, one spacing, and one more).
SIF_MARGIN = 2.0


@dataclass
class GrowthContext:
    """What a criterion may read at a step.

    Attributes:
        step: The driver's step (statics: -1 before the first solve; dynamics: the model's
            step).
        tips: (k, 2) the crack tips the patch must carry: every tip of the patch's cracks and
            the tip that the coming extension will make.
        solution: Statics: the last solution, or ``None`` before the first solve; dynamics:
            the running displacement (a ``CoupledSolution`` with the model's material).
        sif_radius: The outer radius of the SIF domains the driver will use, or ``None``.
        increment: The crack's growth per step (``da``), or ``None``.
    """

    step: int
    tips: np.ndarray
    solution: Any = None
    sif_radius: float | None = None
    increment: float | None = None


@runtime_checkable
class PatchCriterion(Protocol):
    """A rule naming the cells that must be particles (write your own: one method)."""

    def select(self, patch: ParticlePatch, context: GrowthContext) -> np.ndarray:
        """Bool per owned cell of ``patch.mesh``: ``True`` where the cell must be a particle
        cell (patch cells may be named or not: only the FE cells named join). Local: the same
        answer on every number of ranks, no collective call needed (one is allowed)."""
        ...


def as_criteria(adapt: Any) -> list[PatchCriterion]:
    """``adapt`` (one criterion or a sequence) as a list of criteria (a local check, the same
    on every rank: a ``TypeError`` or ``ValueError`` naming the fix)."""
    items = list(adapt) if isinstance(adapt, list | tuple) else [adapt]
    for c in items:
        if not isinstance(c, PatchCriterion):
            raise TypeError(
                f"adapt={c!r:.80} is not a patch criterion: give mf.NearTips(...), "
                "mf.FieldAbove(...), mf.CellsWhere(...), a list of them, or an object with "
                "select(patch, context) -> bool per owned cell"
            )
    if not items:
        raise ValueError("adapt=[] names no criterion; leave it out for a fixed patch")
    return items


def named_cells(
    criteria: list[PatchCriterion], patch: ParticlePatch, context: GrowthContext, driver: str
) -> tuple[np.ndarray, list[str], bool, np.ndarray]:
    """Ask ``criteria`` (collective): the owned FE cells that must become particles (bool per
    owned cell), the criteria that named any (their ``repr``), whether any named a cell at
    all (patch cells included), and every owned cell named (patch cells included). A
    criterion's answer of the wrong kind, and a patch that would take the whole mesh, are
    refused on every rank (naming the criteria and the fix)."""
    msh = patch.mesh
    comm = patch.comm
    cmap = msh.topology.index_map(msh.topology.dim)
    n_own = cmap.size_local
    answers = [np.asarray(c.select(patch, context)) for c in criteria]  # may be collective

    def check() -> None:
        for c, sel in zip(criteria, answers, strict=True):
            if sel.shape != (n_own,) or sel.dtype != bool:
                raise ValueError(
                    f"{c!r}.select returned {sel.dtype} of shape {sel.shape}; it must return a "
                    f"bool per owned cell ({n_own} here)"
                )

    raise_on_all_ranks(comm, check)
    fe = ~np.asarray(patch.in_patch[:n_own], dtype=bool)
    counts = comm.allreduce(np.array([[int((s & fe).sum()), int(s.sum())] for s in answers]))
    chosen = np.zeros(n_own, dtype=bool)
    for sel in answers:
        chosen |= sel
    want = chosen & fe
    by = [repr(c) for c, n in zip(criteria, counts, strict=True) if n[0]]
    added = comm.allreduce(int(want.sum()))
    total, in_patch = cmap.size_global, comm.allreduce(int(np.asarray(patch.cells).size))

    def check_size() -> None:
        if added and in_patch + added >= total:
            raise ValueError(
                f"{driver}: the criteria {by} would turn the whole mesh ({total} cells) into "
                f"particles at step {context.step}: use pure EFG, or a criterion that names "
                "fewer cells (a smaller radius or a higher threshold)"
            )

    raise_on_all_ranks(comm, check_size)
    return want, by, bool(counts[:, 1].sum()) if len(answers) else False, chosen


def _cell_edges(msh: dolfinx.mesh.Mesh) -> np.ndarray:
    """The owned cells' edges (cells, facets per cell, 2 ends, 2) of a 2D mesh (built once per
    mesh and geometry)."""
    return cached(msh, "cell_edges", lambda: _build_cell_edges(msh))


def _build_cell_edges(msh: dolfinx.mesh.Mesh) -> np.ndarray:
    tdim = msh.topology.dim
    n_own = msh.topology.index_map(tdim).size_local
    msh.topology.create_connectivity(tdim, tdim - 1)
    msh.topology.create_connectivity(tdim - 1, tdim)  # entities_to_geometry in DOLFINx 0.10+
    c2f = msh.topology.connectivity(tdim, tdim - 1)
    offsets = np.asarray(c2f.offsets)
    per = int(offsets[1] - offsets[0]) if n_own else 3
    facets = np.asarray(c2f.array)[: offsets[n_own]].reshape(n_own, per)
    geo = _compat.entities_to_geometry(msh, tdim - 1, facets.ravel().astype(np.int32))
    edges = msh.geometry.x[geo][:, :, :2].reshape(n_own, per, 2, 2)
    edges.setflags(write=False)  # shared by every later call
    return edges


def cells_near(mesh: dolfinx.mesh.Mesh, points: npt.ArrayLike, distance: float) -> np.ndarray:
    """Owned cells of a 2D ``mesh`` within ``distance`` of ``points`` (exact: the distance from
    the cell, as a polygon, to the points).

    Args:
        mesh: A 2D mesh (triangles or quadrilaterals, convex cells).
        points: (k, 2) points, or a polyline given as ``Crack.points`` with ``k >= 2`` (then the
            distance to its segments).
        distance: >= 0.

    Returns:
        Sorted local indices of owned cells (int32), e.g. for ``ParticlePatch(mesh, cells, h)``.
    """
    if mesh.geometry.dim != 2 or mesh.topology.dim != 2:
        raise ValueError(
            f"cells_near works on 2D meshes (cracks are 2D); this mesh has gdim="
            f"{mesh.geometry.dim}: select 3D cells with dolfinx.mesh.locate_entities"
        )
    p = np.asarray(points, dtype=float)
    if p.ndim == 1:
        p = p[None]
    if p.ndim != 2 or p.shape[1] < 2 or not len(p) or not np.all(np.isfinite(p)):
        raise ValueError(f"points should be (k, 2) finite coordinates, got {p!r:.80}")
    if not (np.isfinite(distance) and distance >= 0):
        raise ValueError(f"distance={distance!r} must be a finite number >= 0")
    p = p[:, :2]
    edges = _cell_edges(mesh)
    if not len(edges):
        return np.zeros(0, dtype=np.int32)
    e0, e1 = edges[:, :, 0].reshape(-1, 2), edges[:, :, 1].reshape(-1, 2)
    a, b = (p[:-1], p[1:]) if len(p) > 1 else (p, p)
    # a prefilter: cells whose bounding box is within the distance of the points' box
    lo, hi = edges.min(axis=(1, 2)), edges.max(axis=(1, 2))
    plo, phi = p.min(axis=0) - distance, p.max(axis=0) + distance
    cand = np.flatnonzero(np.all((hi >= plo) & (lo <= phi), axis=1))
    if not cand.size:
        return np.zeros(0, dtype=np.int32)
    per = edges.shape[1]
    idx = (cand[:, None] * per + np.arange(per)).ravel()
    E0, E1 = e0[idx], e1[idx]
    d = np.minimum(
        point_segment_distance(E0, a, b).min(axis=1), point_segment_distance(E1, a, b).min(axis=1)
    )  # a cell vertex to the polyline
    d = np.minimum(d, point_segment_distance(p, E0, E1).min(axis=0))  # a point to a cell edge
    d = np.where(segments_intersect(E0, E1, a, b).any(axis=1), 0.0, d)
    near = d.reshape(-1, per).min(axis=1) <= distance
    # a point strictly inside a cell (no edge within the distance): same side as the midpoint
    mid = edges[cand].reshape(len(cand), -1, 2).mean(axis=1)
    c0, c1 = edges[cand, :, 0], edges[cand, :, 1]  # (c, per, 2)
    s_mid = _orient(c0, c1, mid[:, None, :])  # (c, per)
    s_pts = _orient(c0[:, :, None], c1[:, :, None], p[None, None])  # (c, per, k)
    inside = np.all(s_pts * s_mid[:, :, None] >= 0, axis=1).any(axis=1)
    return np.sort(cand[near | inside]).astype(np.int32)


class NearTips:
    """Every cell within ``spacings`` particle spacings of a crack tip.

    When a cell within that radius of a tip is still FE, the patch grows to the radius plus
    ``reserve`` crack increments, so that the next ``reserve`` extensions need no rebuild (each
    growth of the patch rebuilds the model).

    Args:
        spacings: The radius in particle spacings ``h`` of the patch. ``None`` (default): the
            driver's SIF domains' outer radius plus ``SIF_MARGIN`` (2) spacings, so that the
            domains keep their one-spacing clearance from the FE interface at every tip (the
            default domains of :class:`~dolfinx_meshfree.QuasiStaticCrackGrowth`, 5 spacings:
            7 spacings).
        reserve: Increments ``da`` of extra radius taken when the patch must grow (>= 0;
            default 1: a rebuild every other step; 0: the least particles, a rebuild at every
            step the tip nears the interface).
        region: ``region(x) -> bool`` of the cells' midpoints (m, gdim): only these cells may
            be named (e.g. the cells beyond a slot of the mesh, across which the particles of
            both faces would see each other: the MLS knows cracks, not gaps); ``None``: all.
    """

    name = "NearTips"

    def __init__(
        self,
        spacings: float | None = None,
        reserve: float = 1.0,
        region: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        if region is not None and not callable(region):
            raise ValueError(f"region={region!r:.80} must be a callable region(x) -> bool or None")
        self.region = region
        if isinstance(reserve, bool) or not (
            isinstance(reserve, int | float | np.integer | np.floating)
            and np.isfinite(reserve)
            and reserve >= 0
        ):
            raise ValueError(
                f"reserve={reserve!r} must be a number of crack increments >= 0 (extra radius "
                "taken when the patch must grow; 0: none)"
            )
        self.reserve = float(reserve)
        if spacings is not None and (
            isinstance(spacings, bool)
            or not isinstance(spacings, int | float | np.integer | np.floating)
            or not np.isfinite(spacings)
            or spacings <= 0
        ):
            raise ValueError(
                f"spacings={spacings!r} must be a positive number of particle spacings, or None "
                "(the SIF domains' radius plus 2 spacings)"
            )
        self.spacings = None if spacings is None else float(spacings)

    def __repr__(self) -> str:
        region = "" if self.region is None else ", region=..."
        return f"NearTips(spacings={self.spacings!r}, reserve={self.reserve:g}{region})"

    def radius(self, h: float, sif_radius: float | None) -> float:
        """The radius about each tip: ``spacings * h``, or the default."""
        if self.spacings is not None:
            return self.spacings * h
        if sif_radius is None:
            raise ValueError(
                "NearTips(spacings=None) takes its radius from the SIF domains; this driver "
                "has none: give spacings"
            )
        return float(sif_radius) + SIF_MARGIN * h

    def cells(
        self,
        mesh: dolfinx.mesh.Mesh,
        tips: npt.ArrayLike,
        h: float,
        sif_radius: float | None = None,
    ) -> np.ndarray:
        """The owned cells within the radius of ``tips`` ((k, 2) or (2,)) in the region, for
        the first patch (``h``: the particle spacing it will have)."""
        tips = np.atleast_2d(np.asarray(tips, dtype=float))
        r = self.radius(h, sif_radius)
        near = np.unique(np.concatenate([cells_near(mesh, t[None, :2], r) for t in tips]))
        if self.region is None or not near.size:
            return near.astype(np.int32)
        mid = dolfinx.mesh.compute_midpoints(mesh, 2, near.astype(np.int32))
        return near[np.asarray(self.region(mid[:, : mesh.geometry.dim]), dtype=bool)].astype(
            np.int32
        )

    def select(self, patch: ParticlePatch, context: GrowthContext) -> np.ndarray:
        n_own = patch.mesh.topology.index_map(2).size_local
        out = np.zeros(n_own, dtype=bool)
        r = self.radius(particle_spacing(patch), context.sif_radius)
        tips = np.atleast_2d(context.tips)
        allowed = np.ones(n_own, dtype=bool)
        if self.region is not None:
            mid = dolfinx.mesh.compute_midpoints(patch.mesh, 2, np.arange(n_own, dtype=np.int32))
            allowed = np.asarray(self.region(mid[:, : patch.mesh.geometry.dim]), dtype=bool)
            if allowed.shape != (n_own,):
                raise ValueError(
                    f"NearTips' region returned shape {allowed.shape} for {n_own} midpoints; it "
                    "must return one bool per point"
                )
        for tip in tips:
            out[cells_near(patch.mesh, tip[None, :2], r)] = True
        out &= allowed
        extra = self.reserve * (context.increment or 0.0)
        fe = out & ~patch.in_patch[:n_own]
        if extra > 0 and patch.comm.allreduce(int(fe.any())):  # must grow: take the reserve
            for tip in tips:
                out[cells_near(patch.mesh, tip[None, :2], r + extra)] = True
            out &= allowed
        return out


def _midpoints(patch: ParticlePatch) -> tuple[np.ndarray, np.ndarray]:
    """The owned FE cells and their midpoints (m, gdim)."""
    msh = patch.mesh
    tdim = msh.topology.dim
    cells = np.asarray(patch.fe_cells, dtype=np.int32)
    mid = dolfinx.mesh.compute_midpoints(msh, tdim, cells)[:, : msh.geometry.dim]
    return cells, mid


class FieldAbove:
    """The FE cells where a field of the last solution, at the cell midpoint, passes
    ``threshold``.

    Args:
        field: ``"max_principal_stress"`` (the solution's material law on the displacement
            gradient; Rankine; with a law with state, its elastic twin's stress of the total
            strain: a damage law's effective stress, plasticity's trial stress, not the stress
            of the return map: :class:`StateAbove` reads the state itself),
            ``"max_principal_strain"``, or a callable ``field(x, grad)``
            of the midpoints (m, gdim) and the displacement gradients (m, gdim, gdim) returning
            (m,) values (e.g. a damage or ``det F`` indicator).
        threshold: The value above which (``>=``) a cell joins the patch.

    Before the first solve it names no cell.
    """

    name = "FieldAbove"

    def __init__(
        self, field: str | Callable[[np.ndarray, np.ndarray], np.ndarray], threshold: float
    ) -> None:
        if not callable(field) and field not in PATCH_FIELDS:
            raise ValueError(
                f"field={field!r} is not known; use one of {list(PATCH_FIELDS)} or a callable "
                "field(x, grad) -> (m,) values"
            )
        if isinstance(threshold, bool) or not np.isfinite(threshold):
            raise ValueError(f"threshold={threshold!r} must be a finite number")
        self.field, self.threshold = field, float(threshold)

    def __repr__(self) -> str:
        name = self.field if isinstance(self.field, str) else getattr(self.field, "__name__", "?")
        return f"FieldAbove({name!r}, threshold={self.threshold:g})"

    def values(self, patch: ParticlePatch, solution: Any) -> tuple[np.ndarray, np.ndarray]:
        """The owned FE cells and the field at their midpoints."""
        cells, mid = _midpoints(patch)
        if not len(cells):
            return cells, np.zeros(0)
        q = QuadraturePoints(mid, np.ones(len(mid)), cells)
        grad = np.asarray(solution.evaluate_at_quadrature(q)[1])
        if callable(self.field):
            v = np.asarray(self.field(mid, grad), dtype=float)
            if v.shape != (len(mid),):
                raise ValueError(
                    f"the field callable returned shape {v.shape} for {len(mid)} midpoints; it "
                    "must return one value per point"
                )
            return cells, v
        if self.field == "max_principal_stress":
            t = np.asarray(solution.material.stress(grad))
        else:
            t = 0.5 * (grad + np.swapaxes(grad, 1, 2))
        return cells, np.linalg.eigvalsh(0.5 * (t + np.swapaxes(t, 1, 2)))[:, -1]

    def select(self, patch: ParticlePatch, context: GrowthContext) -> np.ndarray:
        out = np.zeros(patch.mesh.topology.index_map(patch.mesh.topology.dim).size_local, bool)
        if context.solution is None:
            return out
        cells, v = self.values(patch, context.solution)
        out[cells[v >= self.threshold]] = True
        return out


class StateAbove:
    """The FE cells where a state variable of a rate-form law (``"damage"``,
    ``"plastic_strain"``, any scalar of the law's state) passes ``threshold`` at any of the
    cell's points: failing elements become particles (issue 27, item 4; the state is carried
    over by the conversion). In statics (``follow_path(..., adapt=...)``), the committed state
    of a law with state at the FE cells' quadrature points: ``J2Plasticity``'s ``"alpha"``
    (the equivalent plastic strain) or ``"dissipation"``, ``RankineDamage``'s ``"damage"``,
    ``"kappa"`` or ``"dissipation"``: the patch grows where the material yields or softens.

    Args:
        name: The state variable (the error of an unknown name lists the law's scalar ones:
            ``RateLaws.state_values``).
        threshold: The value at which (``>=``) a cell joins the patch: above the virgin state's
            (a threshold at or below it would convert every cell at the start).
        where: ``where(x) -> bool (m,)`` of the owned cells' midpoints (m, gdim): only the
            cells it marks may join (e.g. the region a projectile passes through, where the
            material is crushed, rather than every cell a tensile wave damages on its way;
            a lone cell far from the patch makes a poor particle patch: the hybrid's SPH
            correction is singular there). ``None`` (default): any cell.

    Needs a model whose material is a rate-form law (``HolmquistJohnsonCook``,
    ``JohnsonCook``) or, in statics, a law with state (``J2Plasticity``, ``RankineDamage``);
    for a law without state, :class:`FieldAbove`.
    """

    name = "StateAbove"

    def __init__(
        self,
        name: str,
        threshold: float,
        where: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        if not isinstance(name, str):
            raise ValueError(f"name={name!r} must be the name of a state variable, e.g. 'damage'")
        if isinstance(threshold, bool) or not np.isfinite(threshold):
            raise ValueError(f"threshold={threshold!r} must be a finite number")
        if where is not None and not callable(where):
            raise ValueError(
                f"where={where!r:.80} must be a callable where(x) -> bool per midpoint"
            )
        self.variable, self.threshold, self.where = name, float(threshold), where

    def __repr__(self) -> str:
        within = "" if self.where is None else f", where={getattr(self.where, '__name__', '?')}"
        return f"StateAbove({self.variable!r}, threshold={self.threshold:g}{within})"

    def select(self, patch: ParticlePatch, context: GrowthContext) -> np.ndarray:
        n_own = patch.mesh.topology.index_map(patch.mesh.topology.dim).size_local
        material = getattr(context.solution, "material", None)

        def check() -> tuple[np.ndarray, np.ndarray]:
            values = getattr(material, "state_values", None)
            stores = [s for s in getattr(context.solution, "states", []) if s.cells is not None]
            if values is None and stores:  # statics: the laws' committed states
                values = partial(static_state_values, stores)
            if values is None:
                raise ValueError(
                    f"{self!r} reads the state of a law with state (HolmquistJohnsonCook, "
                    f"JohnsonCook; in statics J2Plasticity, RankineDamage); the model's "
                    f"material is {type(material).__name__}: use FieldAbove for a law without "
                    "state"
                )
            cells, v, virgin = values(self.variable)
            if self.threshold <= virgin:
                raise ValueError(
                    f"{self!r}: the threshold is at or below the virgin state's "
                    f"{self.variable} = {virgin:g}, so every cell would become particles at the "
                    f"start; give a threshold above {virgin:g}"
                )
            return cells, v

        cells, v = raise_on_all_ranks(patch.comm, check)
        out = np.zeros(n_own, dtype=bool)
        named = cells[v >= self.threshold]
        out[named[named < n_own]] = True
        if self.where is not None:
            out &= raise_on_all_ranks(
                patch.comm, lambda: _marked(patch.mesh, self.where, "StateAbove's where")
            )
        return out


def static_state_values(
    stores: list[PointState], name: str
) -> tuple[np.ndarray, np.ndarray, float]:
    """``(cells, values, virgin)`` of a scalar state variable ``name`` of a static model's laws
    with state: the committed value at every point of ``stores`` (FE cells and particle
    points, each with its local cell), and its value in the virgin state.

    Raises:
        ValueError: ``name`` is not a scalar of the laws' state (the message lists them).
    """
    law = stores[0].law
    scalars = sorted(k for k, n in law.state_fields.items() if n == 1)
    if name not in scalars:
        raise ValueError(
            f"{name!r} is not a scalar state variable of {type(law).__name__}; use one of {scalars}"
        )
    cells = np.concatenate([np.zeros(0, np.int64)] + [s.cells for s in stores])
    values = np.concatenate([np.zeros(0)] + [s.committed[name].reshape(-1) for s in stores])
    return cells, values, float(law.initial_state(1)[name].ravel()[0])


class CellsWhere:
    """The cells whose midpoint ``fn`` marks.

    Args:
        fn: ``fn(x) -> bool (m,)`` of the owned cells' midpoints ``x`` (m, gdim), as
            ``dolfinx.mesh.locate_entities`` markers take them (but by point rows).
    """

    name = "CellsWhere"

    def __init__(self, fn: Callable[[np.ndarray], np.ndarray]) -> None:
        if not callable(fn):
            raise ValueError(f"fn={fn!r:.80} must be a callable fn(x) -> bool per midpoint")
        self.fn = fn

    def __repr__(self) -> str:
        return f"CellsWhere({getattr(self.fn, '__name__', '?')})"

    def select(self, patch: ParticlePatch, context: GrowthContext) -> np.ndarray:
        return raise_on_all_ranks(
            patch.comm, lambda: _marked(patch.mesh, self.fn, "CellsWhere's fn")
        )


def _marked(
    msh: dolfinx.mesh.Mesh, fn: Callable[[np.ndarray], np.ndarray], what: str
) -> np.ndarray:
    """bool per owned cell: ``fn`` of the owned cells' midpoints (m, gdim)."""
    tdim = msh.topology.dim
    n_own = msh.topology.index_map(tdim).size_local
    mid = dolfinx.mesh.compute_midpoints(msh, tdim, np.arange(n_own, dtype=np.int32))
    marked = np.asarray(fn(mid[:, : msh.geometry.dim]))
    if marked.shape != (n_own,):
        raise ValueError(
            f"{what} returned shape {marked.shape} for {n_own} midpoints; it must return one "
            "bool per point"
        )
    return marked.astype(bool)
