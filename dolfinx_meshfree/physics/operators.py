"""Operators of linear elasticity (2D and 3D) from shape tables: stiffness, loads, VCI gradients.

With tables every operator is sparse algebra (Belytschko et al. 1995, eq. 4.3):
``K = B_test^T (W (x) D) B_trial`` and ``f_I = sum_b N_I(x_b) t(x_b) w_b``.
Dofs are interleaved, ``gdim I + i`` for component ``i`` of node ``I``; the dimension is the
number of gradient tables (2 or 3), the Voigt order that of
:func:`~dolfinx_meshfree.approx.tables.voigt_pairs`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..approx.tables import strain_operator, voigt_pairs
from .assembly_kernel import gradient_form, resolve_backend
from .materials import LinearElastic

if TYPE_CHECKING:  # annotations only
    from mpi4py import MPI

__all__ = [
    "consistent_gradients",
    "corrected_gradients",
    "load_vector",
    "moment_corrections",
    "stiffness_matrix",
    "vci_constants",
    "voigt_tangent",
]


def voigt_tangent(D: np.ndarray, gdim: int) -> np.ndarray:
    """The (gdim^2 x gdim^2) tangent ``A[d i + a, d k + b]`` of a Voigt matrix ``D``, with
    ``B^T D B = G^T A G`` for the strain operator ``B`` of
    :func:`~dolfinx_meshfree.approx.tables.strain_operator` and the displacement-gradient
    operator ``G`` (``du_i/dx_a`` at ``d i + a``): ``A = P^T D P`` with ``P[r, d i + a] = 1``
    where Voigt component ``r`` contains ``du_i/dx_a`` (engineering shears hold both orders)."""
    pairs = voigt_pairs(gdim)
    P = np.zeros((len(pairs), gdim * gdim))
    for r, (i, j) in enumerate(pairs):
        P[r, gdim * i + j] = 1.0
        P[r, gdim * j + i] = 1.0
    return P.T @ D @ P


def stiffness_matrix(
    test_gradients: list[sp.csr_matrix],
    weights: np.ndarray,
    material: LinearElastic,
    trial_gradients: list[sp.csr_matrix] | None = None,
    node_map: np.ndarray | None = None,
    backend: str | None = None,
) -> sp.csr_matrix:
    """Stiffness ``K = sum_q B_test(x_q)^T D B_trial(x_q) w_q`` (gdim n x gdim n).

    Belytschko et al. 1995, eq. (4.3), with ``gdim = len(test_gradients)`` (2 or 3; the material
    must be the law of that dimension). ``trial_gradients`` defaults to ``test_gradients``; they
    differ for variationally consistent integration, which corrects the test functions only
    (Chen, Hillman & Rüter 2013).

    Args:
        node_map: (n,) the output number of each table column (a permutation of ``range(n)``,
            e.g. :attr:`~dolfinx_meshfree.ParticleSet.petsc_index`): rows and columns
            ``gdim node_map[I] + i``. Default: the table's numbering.
        backend: ``"numba"`` (the default when numba is importable: one compiled pass from the
            tables to the CSR, :mod:`~dolfinx_meshfree.physics.assembly_kernel`) or ``"scipy"``
            (the sparse product ``B_test^T (W (x) D) B_trial``, the reference; the default
            without numba). ``DOLFINX_MESHFREE_ASSEMBLY_BACKEND`` sets the default. They agree to
            round-off; the numba path keeps the structural zeros of the pattern.
    """
    gdim = len(test_gradients)
    material.check_gdim(gdim, "the shape table")
    trial = test_gradients if trial_gradients is None else trial_gradients
    n = test_gradients[0].shape[1]
    if resolve_backend(backend) == "numba":
        A = voigt_tangent(material.voigt(), gdim)
        return gradient_form(test_gradients, trial, weights, A, node_map, n)
    Bt = strain_operator(test_gradients)
    B = Bt if trial_gradients is None else strain_operator(trial_gradients)
    D = material.voigt()
    DW = sp.kron(sp.diags(weights), sp.csr_matrix(D), format="csr")
    K = (Bt.T @ DW @ B).tocsr()
    if node_map is None:
        return K
    dofs = (gdim * np.asarray(node_map)[:, None] + np.arange(gdim)).ravel()
    K = K.tocoo()
    return sp.csr_matrix((K.data, (dofs[K.row], dofs[K.col])), shape=(gdim * n, gdim * n))


def load_vector(values: sp.csr_matrix, weights: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """Consistent load ``f_{gdim I + i} = sum_b N_I(x_b) t_i(x_b) w_b``; ``forces`` is (nb, gdim).

    Belytschko et al. 1995, eq. (4.3) (the traction and body-force terms of ``f``).
    """
    f = values.T @ (weights[:, None] * forces)
    return np.asarray(f).reshape(-1)


def consistent_gradients(
    cell_values: sp.csr_matrix,
    cell_gradients: list[sp.csr_matrix],
    cell_weights: np.ndarray,
    boundary_values: sp.csr_matrix,
    boundary_weights: np.ndarray,
    boundary_normals: np.ndarray,
    comm: MPI.Comm,
    positions: np.ndarray | None = None,
    inactive: np.ndarray | None = None,
    hoop: sp.csr_matrix | None = None,
) -> list[sp.csr_matrix]:
    """Variationally consistent integration (VCI) of test-function gradients.

    Chen, Hillman & Rüter 2013: linear exactness of a Galerkin method needs the integration
    constraint ``sum_q grad N_I(x_q) w_q = sum_b N_I(x_b) n(x_b) w_b`` (the divergence theorem
    under the quadrature actually used). The corrected gradients
    ``grad^ N_I = grad N_I + xi_I N_I`` with one constant vector per node

    .. math::
        \\xi_I = \\frac{\\sum_b N_I n w_b - \\sum_q \\nabla N_I w_q}{\\sum_q N_I w_q}

    satisfy it exactly, so the linear patch test passes to round-off with any quadrature.
    Where the gradients share the values' CSR pattern (the MLS tables) the corrected tables
    keep it (the same products and sums as the sparse-matrix form, entry by entry, without
    dropping the entries that happen to cancel to zero).
    Sums run over every rank's cells and boundary facets (collective); the boundary must be the
    whole boundary of the integration domain. Any dimension: ``boundary_normals`` is (nb, gdim)
    with ``gdim = len(cell_gradients)``. ``positions`` and ``inactive``: see
    :func:`vci_constants`.

    ``hoop``: an axisymmetric model's hoop table (m x n,
    :func:`~dolfinx_meshfree.physics.axisymmetry.hoop_table`), the weights revolved (``2 pi r
    w``). Its virtual work on ``N_I e_r`` joins the radial identity, ``sum_q dN_I/dr 2 pi r w_q
    = sum_b N_I n_r 2 pi r w_b - sum_q hoop_qI 2 pi r w_q`` (the divergence theorem for ``N_I r
    e_r``, ``d(r N)/dr = r dN/dr + N``, where the hoop is ``N / r``), so that the axisymmetric
    patch test ``u = (a r, b z)`` is exact.
    """
    gdim = len(cell_gradients)
    vol = cell_values.T @ cell_weights
    rhs = np.stack(
        [
            boundary_values.T @ (boundary_weights * boundary_normals[:, k])
            - cell_gradients[k].T @ cell_weights
            for k in range(gdim)
        ],
        axis=1,
    )
    if hoop is not None:  # the hoop's share of the virtual work on N_I e_r
        rhs[:, 0] -= hoop.T @ cell_weights
    xi = vci_constants(vol, rhs, comm, positions, inactive)
    return corrected_gradients(cell_values, cell_gradients, xi)


def vci_constants(
    vol: np.ndarray,
    rhs: np.ndarray,
    comm: MPI.Comm,
    positions: np.ndarray | None = None,
    inactive: np.ndarray | None = None,
) -> np.ndarray:
    """The VCI constants ``xi`` (n, gdim) of :func:`consistent_gradients` from this rank's sums
    ``vol = sum_q N_I w_q`` (n,) and ``rhs = sum_b N_I n w_b - sum_q grad N_I w_q`` (n, gdim),
    summed over the ranks (collective).

    A node whose function integrates to about zero is refused on every rank (its support misses
    the quadrature), named by its coordinates when ``positions`` (n, gdim) is given. Nodes
    flagged in ``inactive`` (n,) bool are left uncorrected (``xi = 0``) and never refused:
    nodes the caller removes from the system because the integration weights vanish on their
    whole support (the bridging band where ``alpha = 0``), whose test gradients enter no sum."""
    from mpi4py import MPI

    vol = comm.allreduce(vol, op=MPI.SUM)
    rhs = comm.allreduce(rhs, op=MPI.SUM)
    active = np.ones(vol.size, dtype=bool) if inactive is None else ~np.asarray(inactive, bool)
    scale = np.abs(vol[active]).max(initial=0.0)
    small = active & (np.abs(vol) <= 1e-14 * scale)
    if np.any(small):
        i = int(np.flatnonzero(small)[0])
        who = (
            f"the shape function of the particle at {np.round(positions[i], 12).tolist()}"
            if positions is not None and i < len(positions)
            else f"shape function {i} (an enrichment function past the particles)"
            if positions is not None
            else f"shape function {i}"
        )
        raise ValueError(
            f"consistent integration: {who} integrates to {vol[i]:.2e} over the domain (the "
            f"largest integrates to {scale:.2e}): its support misses the quadrature; increase "
            "the dilation (or the quadrature degree)"
        )
    xi = np.zeros_like(rhs)
    xi[active] = rhs[active] / vol[active, None]
    return xi


def corrected_gradients(
    values: sp.spmatrix, gradients: list[sp.csr_matrix], xi: np.ndarray
) -> list[sp.csr_matrix]:
    """``grad^ N_I = grad N_I + xi_I N_I`` (Chen, Hillman & Rüter 2013). Where the gradients
    share the values' CSR pattern (the MLS tables) the result keeps it (one O(nnz) pass, no
    entry that happens to cancel is dropped); else sparse sums."""
    V = values.tocsr()
    if all(_same_pattern(g, V) for g in gradients):
        return [
            sp.csr_matrix((g.data + V.data * xi[V.indices, k], V.indices, V.indptr), V.shape)
            for k, g in enumerate(gradients)
        ]
    return [(g + V @ sp.diags(xi[:, k])).tocsr() for k, g in enumerate(gradients)]


def _same_pattern(a: sp.spmatrix, b: sp.csr_matrix) -> bool:
    """Whether ``a`` is a CSR with exactly the pattern (and entry order) of ``b``."""
    return (
        sp.isspmatrix_csr(a)
        and a.nnz == b.nnz
        and np.array_equal(a.indptr, b.indptr)
        and np.array_equal(a.indices, b.indices)
    )


def moment_corrections(
    cell_values: sp.csr_matrix,
    cell_points: np.ndarray,
    cell_weights: np.ndarray,
    boundary_mismatch: sp.csr_matrix,
    boundary_points: np.ndarray,
    boundary_weights: np.ndarray,
    boundary_normals: np.ndarray,
    comm: MPI.Comm,
) -> list[sp.csr_matrix]:
    """Gradient corrections ``c_I(x) N_I(x)``, ``c_I`` linear in ``x`` per component, that carry
    a boundary term ``int_Gamma D_I n`` into the test gradients with its first moments.

    The VCI of :func:`consistent_gradients` with one constant per node carries a boundary
    term ``int D_I n`` (e.g. the difference between the boundary values the coupling uses and
    the trace ``N_I``) at the support's centroid: exact for a constant stress, while for a
    linear stress it adds ``int (sigma_bar_I - sigma) n D_I`` to node ``I``'s equation.
    Here ``c_I = a_I . p``, ``p = (1, x - x_I)/r_I`` (centred and scaled by the support's
    ``N_I``-weighted centroid and spread), solves the moment conditions

    .. math::
        \\sum_q c_{I,k}(x_q) N_I(x_q) p(x_q) w_q = \\sum_b D_I(x_b) n_k(x_b) p(x_b) w_b,

    so that ``sum_q sigma : (c_I N_I) w_q = int_Gamma sigma n D_I`` for every linear
    ``sigma`` (Chen, Hillman & Rüter 2013, the integration constraint of the next order).
    The ``p = 1`` condition is the constant VCI's, so the linear patch test is unchanged.
    Sums run over every rank's points (collective); nodes whose ``D_I`` vanishes get no
    correction. Any dimension (``gdim = cell_points.shape[1]``).

    Returns:
        One (nq x n) CSR per component, with the pattern of ``cell_values``.
    """
    from mpi4py import MPI

    gdim = cell_points.shape[1]
    n = cell_values.shape[1]
    V = cell_values.tocoo()
    wv = V.data * cell_weights[V.row]
    # the N_I-weighted centroid and spread of every support
    mass = comm.allreduce(np.bincount(V.col, wv, minlength=n), op=MPI.SUM)
    first = comm.allreduce(
        np.stack(
            [np.bincount(V.col, wv * cell_points[V.row, k], minlength=n) for k in range(gdim)], 1
        ),
        op=MPI.SUM,
    )
    centre = first / np.where(mass > 0, mass, 1.0)[:, None]
    second = comm.allreduce(
        np.bincount(V.col, wv * np.sum((cell_points[V.row] - centre[V.col]) ** 2, 1), minlength=n),
        op=MPI.SUM,
    )
    # the spread can be <= 0 where signed MLS functions (e.g. cut by a crack) weigh it: unit scale
    spread = np.where(mass > 0, second / np.where(mass > 0, mass, 1.0), 1.0)
    radius = np.sqrt(np.where(spread > 0, spread, 1.0))

    def basis(points: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return np.column_stack([np.ones(len(cols)), (points - centre[cols]) / radius[cols, None]])

    p = basis(cell_points[V.row], V.col)  # (nnz, 1 + gdim)
    m = gdim + 1
    M = np.zeros((n, m, m))
    for a in range(m):
        for b in range(a, m):
            M[:, a, b] = M[:, b, a] = np.bincount(V.col, wv * p[:, a] * p[:, b], minlength=n)
    D = boundary_mismatch.tocoo()
    pb = basis(boundary_points[D.row], D.col)
    dw = D.data * boundary_weights[D.row]
    rhs = np.zeros((n, gdim, m))
    for k in range(gdim):
        for a in range(m):
            rhs[:, k, a] = np.bincount(
                D.col, dw * boundary_normals[D.row, k] * pb[:, a], minlength=n
            )
    M = comm.allreduce(M, op=MPI.SUM)
    rhs = comm.allreduce(rhs, op=MPI.SUM)
    used = np.flatnonzero(np.abs(rhs).reshape(n, -1).max(axis=1) > 0)
    coef = np.zeros((n, gdim, m))
    if used.size:
        coef[used] = np.einsum("iab,ikb->ika", np.linalg.pinv(M[used], rcond=1e-12), rhs[used])
    return [
        sp.csr_matrix(
            (V.data * np.einsum("ia,ia->i", coef[V.col, k], p), (V.row, V.col)),
            shape=cell_values.shape,
        )
        for k in range(gdim)
    ]
