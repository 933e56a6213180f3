"""Strains of the hybrid sums and the particle energy of the hybrid SPH–FE coupling (HA-F).

Rabczuk et al. 2006, sec. 5.5 (Sauer 2000). At a stress point ``x_q`` of the patch the
displacement gradient is that of the hybrid sums over particles and FE integration points
(eq. 125–126, 128 with the corrected kernel gradients), written over [particles | FE nodes]
through ``u^FE(X_g) = sum_a N_a(X_g) u_a``; the particle forces of eq. 127 are the derivatives of
the particle strain energy, a linear operator

.. math::
    K_p = \\sum_q w_q \\hat B_q^T D B_q ,

whose FE rows give the FE nodes their share by interpolation (HA-F, eq. 135). The stress points
are Gauss points of the patch cells with integration-consistent test gradients
(:func:`consistent_test_gradients`, Chen, Hillman & Rüter 2013), the particles themselves, or
smoothing cells with strains smoothed by the divergence theorem (:func:`smoothed_gradients`,
:mod:`~dolfinx_meshfree.couplings.hybrid_smoothing`): symmetric and consistent.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from ..approx.fe_points import locate_points, tabulate_in_cells
from ..approx.tables import strain_operator
from ..geometry.quadrature import QuadraturePoints, facet_quadrature
from ..parallel import raise_on_all_ranks
from ..physics.axisymmetry import axisymmetric_stiffness, revolved_if
from .base import fe_dof_layout
from .hybrid_discretisation import HybridDiscretisation
from .hybrid_smoothing import EXTERIOR, INTERIOR

__all__ = [
    "consistent_test_gradients",
    "energy_cells",
    "energy_tables",
    "particle_energy_matrix",
    "smoothed_gradients",
    "strain_rows",
]


def strain_rows(d: HybridDiscretisation, points: np.ndarray) -> sp.csr_matrix:
    """Strain operator (3m x 2(n + N)) of the hybrid sums at ``points`` over [particles |
    FE nodes] (eq. 126/128 with the correction; collective for the error)."""
    t = raise_on_all_ranks(d.comm, lambda: d.sph.tabulate(points))
    Z = d.node_map()
    return strain_operator([(g @ Z).tocsr() for g in t.gradients])


def _facet_index(q: QuadraturePoints) -> np.ndarray:
    """Position of each facet quadrature point's facet in the facet list it was made from."""
    _, index = np.unique(q.entities, return_inverse=True)
    return index


def consistent_test_gradients(
    d: HybridDiscretisation,
    values: sp.csr_matrix,
    grads: list[sp.csr_matrix],
    weights: np.ndarray,
    hoop: sp.csr_matrix | None = None,
) -> list[sp.csr_matrix]:
    """Integration-consistent test gradients (Chen, Hillman & Rüter 2013) of the hybrid
    sums over [particles | FE nodes] (collective).

    ``Ghat_c = G_c + xi_c Nhat_c`` with one vector per column so that
    ``sum_q Ghat_c(x_q) w_q = b_c``, the boundary term of the divergence theorem of the
    patch: for a particle ``b_J = int N_J n`` over the patch's exterior facets (``N_J`` the
    particles' interpolant, the functions of the traction loads); for an FE node
    ``b_a = int N_a n_P`` over the interface (the FE trace, ``n_P`` out of the patch), which
    cancels the FE cells' own boundary term ``int N_a n_FE``. With these, a linear field
    leaves no force at any dof but the loaded boundary's (patch test), for either variant.
    Axisymmetric (``hoop``: :meth:`~dolfinx_meshfree.couplings.hybrid_discretisation.
    HybridDiscretisation.hoop`, ``weights`` revolved): the boundary terms are
    revolved and the hoop's virtual work joins the radial identity, ``sum_q Ghat_c,r w_q =
    b_c,r - sum_q hoop_qc w_q`` (the divergence theorem for ``N_c r e_r``), as
    :func:`~dolfinx_meshfree.physics.operators.consistent_gradients` does.
    """
    V, patch, comm, msh = d.V, d.patch, d.comm, d.V.mesh
    P = patch.particles
    n = P.num_particles
    N = d.hybrid.interpolation.shape[1]
    deg = max(d.quadrature_degree, 4)
    target = np.zeros((n + N, 2))
    eq = facet_quadrature(msh, patch.exterior_facets, deg, patch.exterior_cells)
    eq = raise_on_all_ranks(comm, lambda: revolved_if(eq, d.material))
    et = raise_on_all_ranks(comm, lambda: d.evaluator.tabulate(eq.points, 0)).values
    target[:n] = et.T @ (eq.weights[:, None] * eq.normals)
    iq = facet_quadrature(msh, patch.interface_facets, deg, patch.interface_patch_cells)
    iq = raise_on_all_ranks(comm, lambda: revolved_if(iq, d.material))
    it = tabulate_in_cells(V, iq.points, patch.interface_fe_cells[_facet_index(iq)], 0)
    _, l2g = fe_dof_layout(d.V)
    fl = it.values.T @ (iq.weights[:, None] * iq.normals)  # (local FE nodes, 2)
    np.add.at(target, n + l2g[: fl.shape[0]], fl)
    if hoop is not None:  # the hoop's share of the virtual work on N_c e_r
        target[:, 0] -= hoop.T @ weights
    integral = np.stack([g.T @ weights for g in grads], axis=1)
    volume = values.T @ weights
    sums = comm.allreduce(np.hstack([target, integral, volume[:, None]]), op=MPI.SUM)
    target, integral, volume = sums[:, :2], sums[:, 2:4], sums[:, 4]
    used = np.abs(volume) > 1e-12 * np.abs(volume).max()
    xi = np.where(used[:, None], (target - integral) / np.where(used, volume, 1.0)[:, None], 0)
    return [(g + values @ sp.diags(xi[:, k])).tocsr() for k, g in enumerate(grads)]


def smoothed_gradients(d: HybridDiscretisation) -> tuple[list[sp.csr_matrix], np.ndarray]:
    """Smoothed gradients (ns x (n + N)) of this rank's smoothing cells over [particles |
    FE nodes] and the cells' areas (collective;
    :mod:`~dolfinx_meshfree.couplings.hybrid_smoothing`):
    ``(1 / |Omega_k|) sum_p w_p n_p N_c(x_p)`` over the Gauss points of the cell's edges,
    ``N_c`` the hybrid sums' functions inside the patch (eq. 125), the particles' own
    interpolant on the exterior boundary (the functions of the traction loads) and the FE basis
    on the interface. Axisymmetric: :func:`_revolved_smoothing`, the weights then the revolved
    volumes.
    """
    sc = d.smoothing_cells()
    n = d.patch.particles.num_particles
    N = d.hybrid.interpolation.shape[1]
    inner = np.flatnonzero(sc.fe_cell == INTERIOR)
    # an edge inside the patch belongs to two sub-cells: tabulate its points once
    key = np.round(sc.points[inner] / (1e-9 * d.spacing)).astype(np.int64)
    _, first, back = np.unique(key, axis=0, return_index=True, return_inverse=True)
    pts = sc.points[inner[first]]
    t = raise_on_all_ranks(d.comm, lambda: d.sph.tabulate(pts, 0))
    T = (t.values @ d.node_map()).tocsr()[back.ravel()].tocoo()
    rows, cols, vals = [inner[T.row]], [T.col], [T.data]
    outer = np.flatnonzero(sc.fe_cell == EXTERIOR)
    t = raise_on_all_ranks(d.comm, lambda: d.evaluator.tabulate(sc.points[outer], 0))
    T = t.values.tocoo()
    rows, cols, vals = [*rows, outer[T.row]], [*cols, T.col], [*vals, T.data]
    iface = np.flatnonzero(sc.fe_cell >= 0)
    if iface.size:
        _, l2g = fe_dof_layout(d.V)
        tf = tabulate_in_cells(d.V, sc.points[iface], sc.fe_cell[iface], 0).values.tocoo()
        rows.append(iface[tf.row])
        cols.append(n + l2g[tf.col])
        vals.append(tf.data)
    m = sc.points.shape[0]
    T = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, n + N)
    )
    ns = sc.areas.size
    if d.material.axisymmetric:  # int over the revolved sub-cell: 2 pi r_c |Omega_k| (Pappus)
        return _revolved_smoothing(d, sc, T)
    grads = []
    for k in range(2):
        R = sp.csr_matrix(
            (sc.normals[:, k] / sc.areas[sc.owner], (sc.owner, np.arange(m))), shape=(ns, m)
        )
        grads.append((R @ T).tocsr())
    return grads, sc.areas


def _revolved_smoothing(d: HybridDiscretisation, sc, T: sp.csr_matrix) -> tuple:
    """Axisymmetric smoothed gradients (Chen, Yoon, Wang & Liu 2002 for axisymmetric nodal
    integration): over the revolved sub-cell of volume ``V_k = 2 pi r_k |Omega_k|``,

    .. math::
        \\tilde u_{,z} = \\frac{1}{r_k |\\Omega_k|} \\oint u n_z r \\, ds, \\qquad
        \\tilde u_{,r} = \\frac{1}{r_k |\\Omega_k|} \\oint u n_r r \\, ds - \\tilde h,

    the divergence theorem for ``u r`` (``d(r u)/dr = r du/dr + u``), with the smoothed hoop
    ``h~ = N(x_k) / r_k`` (:meth:`~dolfinx_meshfree.couplings.hybrid_discretisation.
    HybridDiscretisation.hoop`). The edges carry ``r u``, quadratic for a
    linear ``u``: the two-point edge rule of :meth:`HybridDiscretisation.smoothing_cells`
    integrates it exactly, so a linear field has its exact smoothed strains. Returns the
    gradients and the volumes ``V_k``."""
    m, ns = sc.points.shape[0], sc.areas.size
    rc = sc.centroids[:, 0]
    scale = sc.points[:, 0] / (sc.areas * rc)[sc.owner]
    grads = []
    for k in range(2):
        R = sp.csr_matrix((sc.normals[:, k] * scale, (sc.owner, np.arange(m))), shape=(ns, m))
        grads.append((R @ T).tocsr())
    grads[0] = (grads[0] - d.hoop()).tocsr()
    return grads, 2.0 * np.pi * rc * sc.areas


def energy_tables(
    d: HybridDiscretisation, smoothed: tuple[list[sp.csr_matrix], np.ndarray] | None = None
) -> tuple[np.ndarray, list[sp.csr_matrix], list[sp.csr_matrix], np.ndarray]:
    """The particle energy's rule over [particles | FE nodes] on this rank (collective):
    ``(points, trial gradients, test gradients, weights)``. ``"smoothed"``: the smoothing
    cells' centroids, smoothed gradients (``smoothed``, computed here if not given) for both,
    and areas; else the stress points, the corrected kernel gradients of the hybrid sums and,
    if ``consistent``, their integration-consistent test gradients."""
    if d.integration == "smoothed":
        grads, areas = smoothed if smoothed is not None else smoothed_gradients(d)
        return d.smoothing_cells().centroids, grads, grads, areas
    q = d.stress_points()
    t = raise_on_all_ranks(d.comm, lambda: d.sph.tabulate(q.points))
    Z = d.node_map()
    grads = [(g @ Z).tocsr() for g in t.gradients]
    test = grads
    if d.consistent:
        values = (t.values @ Z).tocsr()  # linear-consistent (CorrectedSPH)
        test = consistent_test_gradients(d, values, grads, q.weights, d.hoop())
    return q.points, grads, test, q.weights


def energy_cells(d: HybridDiscretisation) -> np.ndarray:
    """The local cell (m,) of each point of this rank's particle-energy rule (:func:`energy_tables`,
    in its order): a smoothing cell's cell, a stress point's, an owned particle's (located: it
    lies in an owned cell of its rank)."""
    if d.integration == "smoothed":
        return np.asarray(d.smoothing_cells().cells, dtype=np.int64)
    q = d.stress_points()
    cells = np.asarray(q.cells, dtype=np.int64)
    if np.any(cells < 0):
        cells = locate_points(d.V.mesh, q.points)
    return cells


def particle_energy_matrix(
    d: HybridDiscretisation, smoothed: tuple[list[sp.csr_matrix], np.ndarray] | None = None
) -> sp.coo_matrix:
    """``sum_q w_q Bhat_q^T D B_q`` of this rank's stress points in the combined numbering
    of :meth:`~dolfinx_meshfree.couplings.hybrid_discretisation.HybridDiscretisation.dof_map`
    (collective; eq. 127 as the derivative of the particle strain energy); ``Bhat = B`` unless
    ``consistent``. With ``"smoothed"``: ``sum_k |Omega_k| B_k^T D B_k`` of the smoothed strains
    ``smoothed`` (:func:`smoothed_gradients`, computed here if not given; symmetric and
    consistent; ``consistent`` has no effect). The rule: :func:`energy_tables`."""
    dof = d.dof_map()
    _, grads, test, weights = energy_tables(d, smoothed)
    hoop = d.hoop()
    if hoop is not None:  # axisymmetric: B4 with the hoop row, revolved weights
        K = axisymmetric_stiffness(test, hoop, weights, d.material, grads).tocoo()
        return sp.coo_matrix((K.data, (dof[K.row], dof[K.col])), shape=K.shape)
    D = sp.csr_matrix(d.material.voigt())
    B = strain_operator(grads)
    Bt = B if test is grads else strain_operator(test)
    K = (Bt.T @ sp.kron(sp.diags(weights), D, format="csr") @ B).tocoo()
    return sp.coo_matrix((K.data, (dof[K.row], dof[K.col])), shape=K.shape)
