"""Where a particle patch's crack band is cut short by the FE interface.

The crack band model (Bažant & Oh 1983) dissipates ``G_f`` per unit crack area only if the
strain localises over the band width ``h`` the law was given: the energy per unit volume is
``G_f / h``. In the particle patch ``h`` is the MLS dilation times the integration cell's size
(:func:`~dolfinx_meshfree.statics.sides.particle_band_factor`), the width over which a smooth
MLS field localises. Next to the FE interface the particle field is tied to the FE trace and
cannot localise over that width: the band is cut short, softens in a narrower zone and
dissipates less, silently. Measured (``tests/test_softening.py``, a bar in tension thinned where
it fails, lagrange, band 2 cells): 0.65 ``G_f`` per unit area when the thinning is in the patch
cell on the interface, 0.97 two cells from it; a 3D bar whose patch was two cells wide, 0.71 to
0.73 ``G_f`` against 0.96 to 1.00 with a patch four to six cells wide (by hand). With the ramps
the band spills into the blended cells, whose band is one cell, and dissipates more: 1.29.

:func:`band_at_interface` finds such a point: a particle point that has softened fully
(damage >= :data:`CUT_DAMAGE`) within :data:`REACH` of its cell's size of an interface facet of
its cell, while the cell across that facet (FE, or a ramp's blended cell) has not. Where the
band crosses the interface and the FE cells soften as much, the patch does not carry the crack
at all (the demos check that the FE cells keep elastic). :func:`~dolfinx_meshfree.follow_path`
warns with :class:`BandCutWarning` at the first step it happens.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .. import _compat
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import cell_sizes, facet_normals
from ..physics.state import PointState
from ..state_fields import cell_values

__all__ = ["CUT_DAMAGE", "REACH", "BandCutWarning", "band_at_interface"]

#: The damage of a point that has softened fully (and of a cell across that has not).
CUT_DAMAGE = 0.9
#: How near an interface facet (in sizes of the point's cell) a softened particle point cuts
#: the band: the outer rows of the cell's Gauss points (0.02 to 0.21 of the size from the
#: facet for 8 x 8 to 2 x 2 points), not its middle.
REACH = 0.25


class BandCutWarning(UserWarning):
    """The crack band of the particle points reached the FE interface: it is cut short there
    and does not dissipate ``G_f`` per unit crack area (less; more where it spills into a
    ramp's blended cells, whose band is one cell)."""


def band_at_interface(
    patch: ParticlePatch, particles: PointState, others: Sequence[PointState]
) -> tuple[np.ndarray, float, float] | None:
    """A particle point where the crack band is cut by the interface (collective): ``(point,
    its damage, the damage of the cell across)``, the same on every rank (the least by
    coordinates), or ``None``.

    Args:
        patch: The model's particle patch (its interface facets and the cells either side).
        particles: The particle points' state (its ``cells``: the patch cells).
        others: The states of the cells off the patch (the FE cells', a ramp's blended cells').

    The cells either side of a facet on a partition boundary are both local (ghost cells), so
    the rank that holds a particle point checks every facet of its cell.
    """
    msh, comm = patch.mesh, patch.comm
    damage = particles.committed["damage"][:, 0]
    cells = [st.cells for st in others if st.cells is not None]
    values = [st.committed["damage"][:, 0] for st in others if st.cells is not None]
    across = cell_values(
        msh,
        np.concatenate([*cells, np.zeros(0, np.int64)]),
        np.concatenate([*values, np.zeros(0)]),
        0.0,
    )  # collective: every rank takes part
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim, tdim - 1)  # on every rank (no-ops: the patch has them)
    msh.topology.create_connectivity(tdim - 1, tdim)
    c2f = msh.topology.connectivity(tdim, tdim - 1)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    gdim = msh.geometry.dim
    soft = np.flatnonzero(damage >= CUT_DAMAGE)
    cells_soft = np.unique(particles.cells[soft])  # the cells of softened particle points
    links = []  # (their index, facet, cell across): facets on the interface, across intact
    for i, c in enumerate(cells_soft):
        for f in c2f.links(c):
            pair = f2c.links(f)
            other = pair[0] if pair[-1] == c else pair[-1]
            if len(pair) == 2 and not patch.in_patch[other] and across[other] < CUT_DAMAGE:
                links.append((i, f, other))
    found = np.zeros((0, gdim + 2))
    if links:
        i, f, other = (np.array(v) for v in zip(*links, strict=True))
        nodes = _compat.entities_to_geometry(msh, tdim - 1, f.astype(np.int32))
        x = msh.geometry.x[:, :gdim]
        centre, normal = x[nodes].mean(axis=1), facet_normals(x, nodes[:, :gdim])
        reach = REACH * cell_sizes(msh, cells_soft)[i]
        rows = []
        for k in range(len(f)):
            here = soft[particles.cells[soft] == cells_soft[i[k]]]
            near = here[np.abs((particles.points[here] - centre[k]) @ normal[k]) <= reach[k]]
            rows.append(
                np.column_stack(
                    [particles.points[near], damage[near], np.full(near.size, across[other[k]])]
                )
            )
        found = np.vstack(rows)
    gathered = np.vstack(comm.allgather(found)) if comm.size > 1 else found
    if gathered.shape[0] == 0:
        return None
    first = gathered[np.lexsort(gathered[:, :gdim].T[::-1])[0]]
    return first[:gdim], float(first[gdim]), float(first[gdim + 1])
