"""Adaptive quadrature of particle cells: a dense rule near the crack tips, a coarse one elsewhere.

Belytschko et al. 1995 (sec. 5.2.2, the Kalthoff–Winkler example) integrate the EFG cells with
4 x 4 Gauss and remark that most of the cost of EFG is its quadrature: "higher order quadrature
is needed only in the vicinity of the crack tip", which, with the coupling, would make the model
about ten times cheaper than pure EFG. :class:`AdaptiveQuadrature` is that rule: the cells within
``radius`` of a crack tip (the fields' singularity, where the crack may go in the next
extensions and where the interaction integral's domain lies) get the Gauss rule of degree
``near`` (7: 4 x 4 on quadrilaterals), the other cells the rule of degree ``far`` (3: 2 x 2).
Cells a crack cuts are integrated piece by piece either way
(:func:`~dolfinx_meshfree.geometry.cut_cells.cut_cell_quadrature`) with their zone's degree.

The rule follows the crack: it is computed from the cracks passed in, so a model rebuilt after
each extension (:class:`~dolfinx_meshfree.dynamics.DynamicCrackGrowth`'s ``build(crack)``) moves
its dense zone with the tip; :func:`changed_cells` tells a local rebuild which cells' rules
differ between two crack states.

A coarse rule under-integrates the EFG stiffness (the MLS functions are rational, not
polynomial). 2 x 2 per cell keeps the stiffness of a free body free of spurious zero-energy modes
(three rigid modes; the lowest non-rigid eigenvalue 0.94-1.44x the 4 x 4 rule's, dilations
1.5-3, cracked and not) and the central difference conserves energy to 3e-15 over 2,000 steps;
one point per cell has near-zero modes (7e-6 - 6e-4 of the 4 x 4 rule's lowest), so ``far=1`` is
refused (``tests/test_adaptive_quadrature.py``).

What it saves: only what depends on the cell rule, i.e. building the stiffness, the masses
and the loads (the MLS tables at the points and the assembly). In explicit dynamics the
stiffness is assembled once per model, so a step's cost (a sparse product) and the interaction
integral (its own annulus rule) do not change. Kalthoff–Winkler at 101 nodes
(``benchmarks/bench_adaptive_quadrature.py``): a rebuild costs about half (pure EFG, radius 8
spacings, 2 x 2 far), the whole run 0.67-0.81x; the SIF histories before the first extension
differ from the uniform rule's by 3.9e-3 (pure EFG: the 2 x 2 rule over the whole plate) and
1.3e-4 (lagrange: the coarse cells are in the particle box only).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from .. import _compat
from .cut_cells import cells_cut_by, crack_polylines, cut_cell_quadrature
from .quadrature import QuadraturePoints, cell_quadrature

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = ["MIN_FAR_DEGREE", "AdaptiveQuadrature", "changed_cells", "near_tip_cells"]

#: The smallest ``far`` degree accepted: 2 (2 x 2 Gauss on quadrilaterals, 3 points on
#: triangles, both exact to degree 2 at least). Degree 1 (one point per cell) gives spurious
#: zero-energy modes in the EFG stiffness (measured: see the module docstring).
MIN_FAR_DEGREE = 2


def _tips(cracks: Any) -> np.ndarray:
    """The tips (n, 2) of ``cracks`` (objects with ``tips`` or plain polylines: both ends)."""
    out = []
    for c in cracks if isinstance(cracks, list | tuple) else [cracks]:
        tips = getattr(c, "tips", None)
        if tips is None:
            p = crack_polylines([c])[0]
            tips = p[[0, -1]]
        out.append(np.asarray(tips, dtype=float).reshape(-1, 2))
    return np.concatenate(out) if out else np.zeros((0, 2))


def near_tip_cells(
    msh: dolfinx.mesh.Mesh, cells: npt.ArrayLike, cracks: Any, radius: float
) -> np.ndarray:
    """Which of ``cells`` lie within ``radius`` of a crack tip: a bool mask (len(cells),).

    A cell is near when the distance from a tip to the cell's bounding box is at most ``radius``
    (a box is never farther than the cell, so every cell that reaches into the disc is near).
    Local (no communication).

    Args:
        msh: 2D mesh with a degree-1 geometry.
        cells: Local cell indices.
        cracks: A :class:`~dolfinx_meshfree.Crack` (its tips) or a sequence of them; plain
            polylines count both ends as tips.
        radius: The radius of the disc around each tip.
    """
    cells = np.asarray(cells, dtype=np.int64)
    tips = _tips(cracks)
    if cells.size == 0 or tips.shape[0] == 0:
        return np.zeros(cells.size, dtype=bool)
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :2]  # (nc, nv, 2)
    lo, hi = nodes.min(axis=1), nodes.max(axis=1)
    gap = np.maximum(np.maximum(lo[:, None] - tips[None], tips[None] - hi[:, None]), 0.0)
    return np.linalg.norm(gap, axis=2).min(axis=1) <= radius


@dataclass(frozen=True)
class AdaptiveQuadrature:
    """The Gauss rule of degree ``near`` in cells within ``radius`` of a crack tip, ``far``
    elsewhere (Belytschko et al. 1995, sec. 5.2.2; see the module docstring).

    Args:
        radius: Radius of the dense zone around each tip (a length, > 0). It should cover the
            interaction integral's domain and the next extension: e.g. the outer SIF radius plus
            a segment (plus a spacing for the support of the functions).
        near: Degree of the dense rule (default 7: 4 x 4 Gauss on quadrilaterals, the
            package's uniform default).
        far: Degree of the coarse rule (default 3: 2 x 2 Gauss), at least
            :data:`MIN_FAR_DEGREE` and at most ``near``.

    Raises:
        ValueError: naming the argument, its value and the fix.
    """

    radius: float
    near: int = 7
    far: int = 3

    def __post_init__(self) -> None:
        r = self.radius
        if isinstance(r, bool) or not isinstance(r, int | float | np.floating | np.integer):
            raise ValueError(f"AdaptiveQuadrature: radius should be a length > 0, got {r!r}")
        if not (np.isfinite(r) and r > 0):
            raise ValueError(
                f"AdaptiveQuadrature: radius should be a finite length > 0, got {r!r}; give the "
                "dense zone's radius around each tip, e.g. the outer SIF radius plus a segment"
            )
        for name in ("near", "far"):
            d = getattr(self, name)
            if isinstance(d, bool) or int(d) != d or d < 1:
                raise ValueError(f"AdaptiveQuadrature: {name} should be an integer >= 1, got {d!r}")
        if self.far < MIN_FAR_DEGREE:
            raise ValueError(
                f"AdaptiveQuadrature: far={self.far!r} under-integrates the EFG stiffness "
                f"(one point per cell gives spurious zero-energy modes); use far >= "
                f"{MIN_FAR_DEGREE} (3: 2 x 2 Gauss)"
            )
        if self.far > self.near:
            raise ValueError(
                f"AdaptiveQuadrature: far={self.far!r} is above near={self.near!r}; the dense "
                "rule is the one near the tips: swap them"
            )

    def near_cells(self, msh: dolfinx.mesh.Mesh, cells: npt.ArrayLike, cracks: Any) -> np.ndarray:
        """Bool mask of ``cells`` in the dense zone (:func:`near_tip_cells`)."""
        return near_tip_cells(msh, cells, cracks, self.radius)

    def rule(self, msh: dolfinx.mesh.Mesh, cells: npt.ArrayLike, cracks: Any) -> QuadraturePoints:
        """The quadrature of ``cells`` (local): the dense zone with degree ``near``, the rest
        with ``far``, cells cut by ``cracks`` piece by piece
        (:func:`~dolfinx_meshfree.geometry.cut_cells.cut_cell_quadrature`). Points come
        grouped by cell in the order of ``cells``. Without cracks (no tips) every cell is far."""
        cells = np.asarray(cells, dtype=np.int64)
        near = self.near_cells(msh, cells, cracks)
        polys = crack_polylines(cracks) if _has_cracks(cracks) else []
        parts = []
        for mask, degree in ((near, self.near), (~near, self.far)):
            sub = cells[mask]
            parts.append(
                cut_cell_quadrature(msh, sub, polys, degree)
                if polys and sub.size
                else cell_quadrature(msh, degree, sub)
            )
        place = np.zeros(int(cells.max()) + 1 if cells.size else 0, dtype=np.int64)
        place[cells] = np.arange(cells.size)  # a cell -> its place in ``cells``
        position = [place[p.cells] for p in parts]
        order = np.argsort(np.concatenate(position), kind="stable")
        owners = np.concatenate([p.cells for p in parts])[order]
        return QuadraturePoints(
            points=np.concatenate([p.points for p in parts])[order],
            weights=np.concatenate([p.weights for p in parts])[order],
            cells=owners,
            entities=owners.copy(),
        )


def _has_cracks(cracks: Any) -> bool:
    return not (isinstance(cracks, list | tuple) and len(cracks) == 0)


def changed_cells(
    msh: dolfinx.mesh.Mesh,
    cells: npt.ArrayLike,
    old: Any,
    new: Any,
    quadrature: AdaptiveQuadrature | None = None,
) -> np.ndarray:
    """The cells among ``cells`` whose quadrature differs between the crack states ``old`` and
    ``new`` (local indices, sorted): for a local rebuild after an extension.

    A cell's rule changes when it enters or leaves the dense zone of ``quadrature`` (``None``:
    the uniform rule, no zone), or when the set of crack segments through its interior changes
    (a cell the new segments cut, or one cut by one state and not the other).

    Args:
        msh: 2D mesh, degree-1 geometry.
        cells: Local cell indices (e.g. the particles' cells).
        old, new: A :class:`~dolfinx_meshfree.Crack`, a polyline or a sequence, before and
            after (e.g. the crack and its grown copy). Pass copies: a crack extended in place
            is the same object before and after.
        quadrature: The adaptive rule in use, or ``None``.
    """
    cells = np.asarray(cells, dtype=np.int64)
    changed = np.zeros(cells.size, dtype=bool)
    if quadrature is not None:
        changed |= quadrature.near_cells(msh, cells, old) != quadrature.near_cells(msh, cells, new)
    old_segs = _segment_set(old)
    new_segs = [s for s in _segment_list(new) if s not in old_segs]
    gone = [s for s in _segment_list(old) if s not in set(_segment_list(new))]
    for segs in (new_segs, gone):
        if segs:
            polys = [np.array(s).reshape(2, 2) for s in segs]
            changed |= np.isin(cells, cells_cut_by(msh, cells, polys))
    return np.sort(cells[changed])


def _segment_list(cracks: Any) -> list[tuple[float, ...]]:
    out = []
    for p in crack_polylines(cracks):
        for a, b in itertools.pairwise(p):
            out.append((float(a[0]), float(a[1]), float(b[0]), float(b[1])))
    return out


def _segment_set(cracks: Any) -> set[tuple[float, ...]]:
    return set(_segment_list(cracks))
