"""Stress intensity factors of a solved cracked model: the domain interaction integral
(:func:`~dolfinx_meshfree.fracture.interaction.interaction_integral`; Moran & Shih 1987, Yau,
Wang & Corten 1980) on the crack-aware MLS field of the particles around a tip.

Shared by :meth:`~dolfinx_meshfree.EFGSolution.stress_intensity_factors` and
:meth:`~dolfinx_meshfree.CoupledSolution.stress_intensity_factors`: the tip is resolved, the
domains are checked to stay inside the particle patch (away from its exterior boundary and the
FE interface: the domain form assumes traction-free crack faces and no other boundary within
``r2``, and only the particles carry the crack) and to hold no other tip or kink, every check a
``ValueError`` on every rank before the (local) evaluation.

Default radii: ``r2 = 3, 4, 5`` particle spacings with ``r1 = r2 / 2``. The crack-cut MLS field
is least accurate within about one support radius (2 to 2.5 spacings) of the tip, where
diffraction bends the weights and the linear basis cannot follow the ``sqrt(r)`` field; an
annulus from 1.5 spacings outwards samples the field where it is accurate, and three radii
report the path independence.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..fracture.interaction import StressIntensityFactors, interaction_integral
from ..geometry.crack import Crack, gathered_segments, particle_spacing, point_segment_distance
from ..parallel import raise_on_all_ranks
from ..physics.materials import LinearElastic

if TYPE_CHECKING:  # annotations only
    from ..geometry.crack import CrackDomain
    from ..geometry.patch import ParticlePatch

__all__ = ["DEFAULT_RADII", "resolve_tip", "solution_sifs"]

#: Default outer domain radii, in particle spacings (module docstring).
DEFAULT_RADII = (3.0, 4.0, 5.0)


def resolve_tip(crack: Crack, tip: int | Sequence[float] | np.ndarray, h: float) -> int:
    """Index into ``crack.tips`` of ``tip`` (an index, or the tip's coordinates within
    ``1e-6 h``); a ``ValueError`` naming the tips otherwise."""
    tips = crack.tips
    names = ", ".join(f"({t[0]:.6g}, {t[1]:.6g})" for t in tips)
    if isinstance(tip, int | np.integer):
        if not -len(tips) <= int(tip) < len(tips):
            raise ValueError(
                f"tip={int(tip)}: the crack has {len(tips)} tip(s) [{names}]; give an index in "
                f"0..{len(tips) - 1} or a tip's coordinates"
            )
        return int(tip) % len(tips)
    x = np.asarray(tip, dtype=float)
    if x.shape != (2,) or not np.all(np.isfinite(x)):
        raise ValueError(f"tip={tip!r} should be an index of crack.tips or a point (x, y)")
    d = np.linalg.norm(tips - x, axis=1)
    if d.size == 0 or d.min() > 1e-6 * h:
        raise ValueError(
            f"tip=({x[0]:.6g}, {x[1]:.6g}) is not a tip of the crack; its tips are [{names}]"
        )
    return int(d.argmin())


def solution_sifs(
    grad_u: Callable[[np.ndarray], np.ndarray],
    material: LinearElastic | None,
    cracks: Sequence[Crack],
    domain: ParticlePatch | CrackDomain,
    crack: Crack,
    tip: int | Sequence[float] | np.ndarray = 0,
    radius: float | Sequence | np.ndarray | None = None,
    **options,
) -> StressIntensityFactors:
    """K_I, K_II and J at a tip of ``crack`` from the gradient ``grad_u`` of a solved field
    (collective: the patch boundary is gathered).

    Args:
        grad_u: ``(m, 2) -> (m, 2, 2)``, the crack-aware particle field's gradient.
        material: the 2D linear elastic law of the solve.
        cracks: the model's cracks (``crack`` must be one of them).
        domain: the patch (or :class:`~dolfinx_meshfree.geometry.crack.CrackDomain`).
        tip: an index of ``crack.tips`` or a tip's coordinates.
        radius: outer radii (or ``(r1, r2)`` pairs), default :data:`DEFAULT_RADII` x h.
        options: ``inner``, ``weight``, ``points`` of ``interaction_integral``.
    """
    comm = domain.comm
    segments = np.concatenate(
        [
            gathered_segments(domain, domain.exterior_facets),
            gathered_segments(domain, domain.interface_facets),
        ]
    )

    def check() -> tuple:
        if not isinstance(material, LinearElastic) or material.plane not in ("stress", "strain"):
            raise ValueError(
                f"material={material!r}: stress intensity factors need the 2D LinearElastic law "
                "of the solve (plane='stress' or 'strain'); pass material=..."
            )
        if not any(crack is c for c in cracks):
            raise ValueError(
                f"crack={crack!r:.120} is not one of the solution's cracks; pass the Crack "
                "object given to the model"
            )
        h = particle_spacing(domain)
        k = resolve_tip(crack, tip, h)
        end = crack.tip_ends[k]
        x_tip = crack.tips[k]
        r = np.asarray(DEFAULT_RADII) * h if radius is None else np.asarray(radius, float)
        r_out = float(np.max(r))
        d_bound = float(point_segment_distance(x_tip[None], segments[:, 0], segments[:, 1]).min())
        if r_out >= d_bound:
            raise ValueError(
                f"radius={r_out:.6g}: the domain about the tip ({x_tip[0]:.6g}, {x_tip[1]:.6g}) "
                f"leaves the particle patch (its exterior boundary or the FE interface is "
                f"{d_bound:.6g} away); use radii below {d_bound:.6g} or enlarge the patch"
            )
        own = np.delete(crack.points, 0 if end == 0 else len(crack.points) - 1, axis=0)
        others = [c.points for c in cracks if c is not crack]
        return r, x_tip, crack.tip_direction(end), np.concatenate([own, *others])

    r, x_tip, direction, keep = raise_on_all_ranks(comm, check)
    return raise_on_all_ranks(
        comm,
        lambda: interaction_integral(
            grad_u, material, x_tip, direction, r, keep_outside=keep, **options
        ),
    )
