"""HA-S: the particles' stresses load the FE interface as tractions (Rabczuk et al. 2006,
eq. 131–134, Fig. 8–9; Sauer 2000).

At the end node ``k`` of an interface edge the stress is the kernel average of the stresses of
the particles it can see (eq. 131), ``P_k = sum_J P_J N_J / sum_J N_J``; the visibility
criterion keeps the particles on the patch side of that edge, ``(X_J - X_k) . n >= 0`` with
``n`` the FE side's outward normal (so at a corner each edge sees its own side only). The edge's
traction ``t = n . P_k`` (eq. 132–133) gives the node the force ``l/2 t`` per edge (eq. 134).
The particles' stresses ``P_J = D B_J u`` are linear in the dofs, so the FE rows of the internal
force are a matrix (:func:`traction_matrix`); it is not the transpose of the particles' rows, so
``K`` is not symmetric.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .. import _compat
from ..approx.fe_points import tabulate_in_cells
from ..approx.kernels import sph_cubic_spline
from ..approx.neighbours import pairs_within_support
from ..parallel import raise_on_all_ranks
from .base import fe_dof_layout
from .hybrid_discretisation import HybridDiscretisation
from .hybrid_strains import strain_rows

__all__ = ["traction_matrix"]


def traction_matrix(d: HybridDiscretisation) -> sp.coo_matrix:
    """HA-S: ``-F`` of eq. 131–134 as a matrix (FE rows, combined numbering), this rank's
    owned interface edges (collective).

    For each end node ``k`` of an interface edge (length ``l``, normal ``n`` out of the FE
    cell), the visible particles ``(X_J - X_k) . n >= 0`` within the kernel support give the
    stress ``P_k = sum_J N_J P_J / sum_J N_J`` (eq. 131, ``N_J = V_J W``), the traction
    ``n . P_k`` (eq. 132–133) and the node force ``l/2 n . P_k`` (eq. 134); the internal
    force is its negative.

    Raises:
        ValueError: on every rank, if an interface node sees no particle within the kernel
            support (its stress, eq. 131, is undefined).
    """
    V, patch, comm = d.V, d.patch, d.comm
    msh = V.mesh
    P = patch.particles
    facets = patch.interface_facets
    fe_cells = patch.interface_fe_cells
    ends = msh.geometry.x[_compat.entities_to_geometry(msh, 1, facets), :2].reshape(-1, 2, 2)
    tvec = ends[:, 1] - ends[:, 0]
    length = np.linalg.norm(tvec, axis=1)
    normal = np.stack([tvec[:, 1], -tvec[:, 0]], axis=1) / np.maximum(length, 1e-300)[:, None]
    centroid = msh.geometry.x[_compat.geometry_dofmap(msh)[fe_cells], :2].mean(axis=1)
    mid = ends.mean(axis=1)
    flip = np.einsum("fi,fi->f", mid - centroid, normal) < 0.0
    normal[flip] *= -1.0
    xe = ends.reshape(-1, 2)  # the two end nodes of each edge
    ne = np.repeat(normal, 2, axis=0)
    half = np.repeat(0.5 * length, 2)
    _, l2g = fe_dof_layout(d.V)
    tab = tabulate_in_cells(V, xe, np.repeat(fe_cells, 2), derivatives=0).values.tocoo()
    at_node = tab.data > 0.5  # N_a(X_k) = 1 at the edge's own nodes
    node = np.full(xe.shape[0], -1, dtype=np.int64)
    node[tab.row[at_node]] = l2g[tab.col[at_node]]
    radius = 2.0 * d.smoothing_length
    i, j, dx = pairs_within_support(xe, P.positions, np.full(P.num_particles, radius))
    tol = 1e-10 * d.spacing
    visible = np.einsum("pi,pi->p", -dx, ne[i]) >= -tol  # visibility criterion
    i, j, dx = i[visible], j[visible], dx[visible]
    W, _ = sph_cubic_spline(np.linalg.norm(dx, axis=1) / d.smoothing_length, d.smoothing_length, 2)
    w = P.volumes[j] * W
    total = np.bincount(i, weights=w, minlength=xe.shape[0])

    def check() -> None:
        blind = np.flatnonzero(total <= 0.0)
        if blind.size:
            k = int(blind[0])
            raise ValueError(
                f"HA-S: {blind.size} interface node(s) see no particle within the kernel "
                f"support {radius:.3g}; first at {xe[k]}: increase smoothing or the particle "
                "density near the interface"
            )
        if np.any(node < 0):
            raise ValueError("HA-S: an interface edge end is not an FE node of its cell")

    raise_on_all_ranks(comm, check)
    w = w / np.where(total > 0, total, 1.0)[i]
    # stresses of the particles in use, D B_J (eq. 131's P(X_J))
    used, jj = np.unique(j, return_inverse=True)
    B = strain_rows(d, P.positions[used])  # (3 nu x 2(n+N))
    S = sp.kron(sp.identity(used.size), sp.csr_matrix(d.material.voigt()), format="csr") @ B
    # A: Voigt stresses of the used particles -> node forces l/2 w (n . P)
    coef = half[i] * w
    nx, ny = ne[i, 0], ne[i, 1]
    n = P.num_particles
    r0 = 2 * n + 2 * node[i]
    rows = np.concatenate([r0, r0, r0 + 1, r0 + 1])
    cols = np.concatenate([3 * jj, 3 * jj + 2, 3 * jj + 2, 3 * jj + 1])
    vals = np.concatenate([coef * nx, coef * ny, coef * nx, coef * ny])
    N = d.hybrid.interpolation.shape[1]
    A = sp.csr_matrix((vals, (rows, cols)), shape=(2 * (n + N), 3 * used.size))
    K = (-(A @ S)).tocoo()
    dof = d.dof_map()
    return sp.coo_matrix((K.data, (K.row, dof[K.col])), shape=K.shape)
