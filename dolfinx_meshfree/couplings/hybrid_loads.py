"""Loads of the hybrid SPH–FE coupling: tractions and body forces as vectors of both fields.

Traction loads use the FE basis on facets beside FE cells and the particles' own interpolant
(:class:`~dolfinx_meshfree.couplings.hybrid_sph.CorrectedSPH`) on facets beside patch cells;
with ``integration="smoothed"`` the patch facets are integrated by the smoothing cells' edge rule
(:meth:`~dolfinx_meshfree.couplings.hybrid_smoothing.SmoothingCells.exterior_quadrature`), so
that the loads of a constant stress are the boundary terms of the particle energy (patch test).
Body loads on the patch cells go to the dofs through the hybrid sums' functions over [particles
| FE nodes] (Rabczuk et al. 2006, eq. 125–126): the displacement whose strains the particle
energy holds, so the load is its work conjugate.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from petsc4py import PETSc

from ..approx.fe_points import tabulate_in_cells
from ..geometry.quadrature import cell_quadrature, facet_quadrature
from ..parallel import raise_on_all_ranks
from ..physics import axisymmetry
from ..physics.axisymmetry import revolved_if
from ..physics.body_loads import CallableBodyForce, body_load_vectors
from ..physics.operators import load_vector
from ..physics.user_functions import vector_values
from ..statics.petsc import create_vector
from .base import cell_indicator, fe_dof_layout
from .hybrid_discretisation import HybridDiscretisation, global_facets

__all__ = ["hybrid_loads"]


def hybrid_loads(
    d: HybridDiscretisation,
    tractions: list[tuple[np.ndarray, Callable]],
    body_forces: list[CallableBodyForce],
    extra: np.ndarray | None = None,
) -> tuple[PETSc.Vec, PETSc.Vec]:
    """Traction and body loads ``(b_fe, b_p)`` (collective): FE basis on FE facets and cells,
    the particles' interpolant on patch facets (with ``"smoothed"`` by the smoothing cells' edge
    rule), the hybrid sums' functions (eq. 125) on patch cells.

    Args:
        d: The hybrid discretisation.
        tractions: ``(facets, t(x, n))`` pairs of owned exterior facets.
        body_forces: Body forces per unit volume on the whole body.
        extra: Interleaved [particles | FE nodes] values added to the loads (Nitsche's terms of
            the patch's essential conditions), this rank's share.
    """
    V, comm, msh = d.V, d.comm, d.V.mesh
    P = d.patch.particles
    fe_layout, l2g = fe_dof_layout(d.V)
    pl = d.patch.particles.dof_layout()
    deg = max(d.quadrature_degree, 4)
    rows, vals = [np.zeros(0, np.int64)], [np.zeros(0)]
    f_p = np.zeros(2 * P.num_particles)
    for facets, fn in tractions:
        f_fe, f_pf = d.split(facets)
        for sel, side in ((f_fe, "fe"), (f_pf, "p")):
            if side == "p" and d.integration == "smoothed":
                q = d.smoothing_cells().exterior_quadrature(msh, global_facets(msh, sel))
            else:
                q = facet_quadrature(msh, sel, deg)
            q = revolved_if(q, d.material)
            t = raise_on_all_ranks(
                comm,
                lambda fn=fn, q=q: vector_values(fn, (q.points, q.normals), len(q), "traction"),
            )
            if side == "fe":
                tab = tabulate_in_cells(V, q.points, q.cells, derivatives=0).values
                fl = load_vector(tab, q.weights, t).reshape(-1, 2)
                rows.append((2 * l2g[: fl.shape[0], None] + np.arange(2)).ravel())
                vals.append(fl.ravel())
            else:
                tab = raise_on_all_ranks(comm, lambda q=q: d.evaluator.tabulate(q.points, 0)).values
                f_p += load_vector(tab, q.weights, t)
    fe = None
    if extra is not None:  # interleaved [particles | FE nodes] (Nitsche's terms)
        n2 = 2 * P.num_particles
        f_p += extra[:n2]
        hit = np.flatnonzero(extra[n2:])
        rows.append(hit)
        vals.append(extra[n2:][hit])
    if body_forces:
        q = revolved_if(cell_quadrature(msh, d.quadrature_degree, d.patch.cells), d.material)
        chi = cell_indicator(msh, ~d.patch.in_patch)
        if d.material.axisymmetric:  # the FE cells' loads on the revolved volume too
            chi = chi * axisymmetry.measure(msh)
        # the hybrid sums' functions over [particles | FE nodes] (eq. 125): the displacement
        # whose strains the particle energy holds, so the load is its work conjugate
        t = raise_on_all_ranks(comm, lambda: d.sph.tabulate(q.points, 0))
        table = (t.values @ d.node_map()).tocsr()
        fe, fp = body_load_vectors(body_forces, V, chi, deg, (q, table), comm=comm)
        n2 = 2 * P.num_particles
        f_p += fp[:n2]
        hit = np.flatnonzero(fp[n2:])
        rows.append(hit)
        vals.append(fp[n2:][hit])
    b_fe = create_vector(comm, fe_layout, np.concatenate(rows), np.concatenate(vals))
    if fe is not None:
        b_fe.array[:] += fe
    b_p = create_vector(comm, pl, P.petsc_dofs(2).ravel(), f_p)
    return b_fe, b_p
