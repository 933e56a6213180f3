"""Axisymmetric (r, z) linear elasticity: the hoop strain and the ``2 pi r`` weights.

A solid of revolution under loads of revolution is modelled on its (r, z) section, the mesh's
``x[0] = r >= 0`` and ``x[1] = z`` (issue 27, item 1; Zienkiewicz & Taylor, *The Finite Element
Method*, vol. 1, ch. 5). With ``u = (u_r, u_z)`` the strain has four components

.. math::
    \\varepsilon = (\\partial_r u_r,\\; \\partial_z u_z,\\;
    \\partial_z u_r + \\partial_r u_z,\\; u_r / r)
    = (\\varepsilon_{rr}, \\varepsilon_{zz}, \\gamma_{rz}, \\varepsilon_{\\theta\\theta}),

the stress ``sigma = D eps`` with the 3D Lamé constants
(:meth:`~dolfinx_meshfree.LinearElastic.axisymmetric_voigt`), and every integral over the solid
is ``int_Omega f dV = int_A f 2 pi r dA`` (a quadrature weight ``w`` becomes ``2 pi r w``:
:func:`revolved`). The shape-function operators of an EFG table (Belytschko et al. 1995,
eq. 4.3) become ``K = sum_q B4_test^T D B4_trial 2 pi r_q w_q`` with ``B4`` the plane strain
operator plus the hoop row ``N_J(x_q) / r_q`` on the radial component
(:func:`axisymmetric_stiffness`).

The axis ``r = 0``: the hoop strain is finite only where ``u_r`` vanishes, which the model
imposes (a roller on the axis, the radial component held). Cell Gauss points are never on the
axis, so no integral divides by zero; a facet on the axis has weight ``0`` once revolved, so a
constraint there keeps its length weights (:func:`revolved` with ``constraint=True``). Point
values at ``r = 0`` (:func:`stress`) take ``u_r / r -> du_r/dr`` (l'Hôpital).

Variationally consistent integration (VCI, Chen, Hillman & Rüter 2013) in axisymmetry: a
constant stress with ``sigma_rr = sigma_tt`` (the field ``u = (a r, b z + c)``, the
axisymmetric patch test) does exact virtual work on a test function ``N_I e_r`` when
``sum_q dN_I/dr 2 pi r w_q = sum_b N_I n_r 2 pi r w_b - sum_q N_I 2 pi w_q`` (the divergence
theorem for ``N_I r e_r``: ``d(r N)/dr = r dN/dr + N``) and on ``N_I e_z`` when
``sum_q dN_I/dz 2 pi r w_q = sum_b N_I n_z 2 pi r w_b``. :func:`axisymmetric_gradients`
corrects the gradients to satisfy both (the hoop term ``N_I / r`` is left as it is: it enters
the identity through the ``- sum_q N_I 2 pi w_q`` term).

FE forms: :func:`radius`, :func:`ufl_strain` and :func:`ufl_stress` write the user's
``inner(sigma(u), eps(v)) 2 pi r dx``.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import dolfinx.mesh
import numpy as np
import scipy.sparse as sp
import ufl

from ..approx.tables import strain_operator
from ..geometry.quadrature import QuadraturePoints
from .materials import AXISYMMETRIC, LinearElastic, ufl_constants
from .operators import corrected_gradients, vci_constants

if TYPE_CHECKING:  # annotations only
    from mpi4py import MPI

__all__ = [
    "axisymmetric_gradients",
    "axisymmetric_stiffness",
    "check_half_plane",
    "hoop_operator",
    "measure",
    "radius",
    "revolved",
    "revolved_if",
    "stress",
    "ufl_strain",
    "ufl_stress",
]

#: Coordinates below ``-RADIUS_TOLERANCE`` times the section's size are outside ``r >= 0``.
RADIUS_TOLERANCE = 1e-12


def check_half_plane(points: np.ndarray, where: str) -> None:
    """Refuse points (m, 2) with ``r = x[0] < 0`` (local): an axisymmetric section lies in
    ``r >= 0``; the first offending point is named by its coordinates."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] < 2:
        raise ValueError(f"{where}: an axisymmetric model needs (r, z) points, got {points.shape}")
    scale = max(float(np.abs(points[:, :2]).max(initial=0.0)), 1.0)
    bad = np.flatnonzero(points[:, 0] < -RADIUS_TOLERANCE * scale)
    if bad.size:  # the farthest from the axis (lowest z among equals): not the storage order
        worst = bad[np.lexsort((points[bad, 1], points[bad, 0]))[0]]
        p = np.round(points[worst, :2], 12).tolist()
        raise ValueError(
            f"{where}: the point {p} has r = x[0] < 0, but an axisymmetric section lies in the "
            "half-plane r >= 0 (x[0] is the radius, x[1] the axis): move the mesh to r >= 0"
        )


def revolved(rule: QuadraturePoints, constraint: bool = False) -> QuadraturePoints:
    """``rule`` with its weights ``w`` replaced by ``2 pi r w`` (``r = points[:, 0]``): a volume
    (or, on facets, surface) integral over the solid of revolution. Refuses ``r < 0``.

    ``constraint=True``: the rule of a constraint ``int_Gamma mu . (u - g) 2 pi r ds = 0`` with
    multipliers constant per facet, whose multipliers are then the reaction tractions (constant
    in a patch test, where ``2 pi r`` times them is not). Points on the axis keep ``w``: there
    ``2 pi r w = 0`` would leave an axis facet's constraint (``u_r = 0``) without a row."""
    check_half_plane(rule.points, "the quadrature")
    r = np.maximum(rule.points[:, 0], 0.0)
    w = 2.0 * np.pi * r * rule.weights
    if constraint:
        scale = max(float(np.abs(rule.points[:, :2]).max(initial=0.0)), 1.0)
        w = np.where(r <= RADIUS_TOLERANCE * scale, rule.weights, w)
    return dataclasses.replace(rule, weights=w)


def _radii(points: np.ndarray, where: str) -> np.ndarray:
    r = np.asarray(points, dtype=float)[:, 0]
    on_axis = np.flatnonzero(r <= 0.0)
    if on_axis.size:
        p = np.round(np.asarray(points)[on_axis[0], :2], 12).tolist()
        raise ValueError(
            f"{where}: the point {p} lies on the axis r = 0, where the hoop strain u_r / r of a "
            "shape function is not defined; integrate with Gauss points inside the cells "
            "(integration='cells' or 'vci'), which never lie on the axis"
        )
    return r


def hoop_operator(values: sp.csr_matrix, points: np.ndarray) -> sp.csr_matrix:
    """The hoop strain operator (m x 2n): ``(H u)_q = sum_J N_J(x_q) u_{2J} / r_q``, i.e.
    ``u_r / r`` at every point, for interleaved (r, z) dofs. Refuses points on the axis."""
    r = _radii(points, "the hoop strain")
    V = (sp.diags(1.0 / r) @ values).tocoo()
    m, n = values.shape
    return sp.csr_matrix((V.data, (V.row, 2 * V.col)), shape=(m, 2 * n))


def _operator(
    gradients: list[sp.csr_matrix], values: sp.csr_matrix, points: np.ndarray
) -> sp.csr_matrix:
    """``B4`` (4 m x 2 n): rows ``4 q + (rr, zz, rz, tt)``."""
    B3 = strain_operator(gradients).tocoo()
    H = hoop_operator(values, points).tocoo()
    q, r = np.divmod(B3.row, 3)
    rows = np.concatenate([4 * q + r, 4 * H.row + 3])
    cols = np.concatenate([B3.col, H.col])
    vals = np.concatenate([B3.data, H.data])
    m, n2 = values.shape[0], 2 * values.shape[1]
    return sp.csr_matrix((vals, (rows, cols)), shape=(4 * m, n2))


def axisymmetric_stiffness(
    test_gradients: list[sp.csr_matrix],
    values: sp.csr_matrix,
    points: np.ndarray,
    weights: np.ndarray,
    material: LinearElastic,
    trial_gradients: list[sp.csr_matrix] | None = None,
    node_map: np.ndarray | None = None,
) -> sp.csr_matrix:
    """``K = sum_q B4_test(x_q)^T D B4_trial(x_q) w_q`` (2n x 2n) of an axisymmetric law.

    ``weights`` are the revolved weights ``2 pi r w`` (:func:`revolved`); ``B4`` stacks the
    plane strain operator of the gradients and the hoop row of the values (module docstring).
    ``trial_gradients`` default to ``test_gradients`` (they differ under VCI, which corrects
    the test gradients only). ``node_map``: the output number of each table column, as
    :func:`~dolfinx_meshfree.physics.operators.stiffness_matrix`.
    """
    if len(test_gradients) != 2:
        raise ValueError(f"an axisymmetric model is 2D (r, z), got {len(test_gradients)} tables")
    D = material.axisymmetric_voigt()
    Bt = _operator(test_gradients, values, points)
    B = Bt if trial_gradients is None else _operator(trial_gradients, values, points)
    DW = sp.kron(sp.diags(np.asarray(weights, dtype=float)), sp.csr_matrix(D), format="csr")
    K = (Bt.T @ DW @ B).tocsr()
    if node_map is None:
        return K
    n = values.shape[1]
    dofs = (2 * np.asarray(node_map)[:, None] + np.arange(2)).ravel()
    K = K.tocoo()
    return sp.csr_matrix((K.data, (dofs[K.row], dofs[K.col])), shape=(2 * n, 2 * n))


def axisymmetric_gradients(
    cell_values: sp.csr_matrix,
    cell_gradients: list[sp.csr_matrix],
    cell_points: np.ndarray,
    cell_weights: np.ndarray,
    boundary_values: sp.csr_matrix,
    boundary_weights: np.ndarray,
    boundary_normals: np.ndarray,
    comm: MPI.Comm,
    positions: np.ndarray | None = None,
) -> list[sp.csr_matrix]:
    """VCI test gradients ``dN_I + xi_I N_I`` of an axisymmetric model (module docstring).

    ``cell_weights`` and ``boundary_weights`` are revolved (``2 pi r w``); the boundary is the
    whole boundary of the section (facets on the axis included: their revolved weight is 0).
    Sums run over every rank (collective); see
    :func:`~dolfinx_meshfree.physics.operators.vci_constants` for the refusals.
    """
    r = _radii(cell_points, "consistent integration")
    vol = cell_values.T @ cell_weights
    rhs = np.stack(
        [
            boundary_values.T @ (boundary_weights * boundary_normals[:, k])
            - cell_gradients[k].T @ cell_weights
            for k in range(2)
        ],
        axis=1,
    )
    rhs[:, 0] -= cell_values.T @ (cell_weights / r)  # the N_I of d(r N_I)/dr
    xi = vci_constants(vol, rhs, comm, positions)
    return corrected_gradients(cell_values, cell_gradients, xi)


def stress(
    material: LinearElastic, points: np.ndarray, u: np.ndarray, grad_u: np.ndarray
) -> np.ndarray:
    """Cauchy stress (m, 3, 3) in (r, z, theta) of an axisymmetric law at points (m, 2) from the
    displacement (m, 2) and its gradient (m, 2, 2) (e.g.
    :meth:`~dolfinx_meshfree.EFGSolution.evaluate`). On the axis the hoop strain ``u_r / r`` is
    its limit ``du_r/dr`` (``u_r = 0`` there)."""
    points, u, g = (np.asarray(a, dtype=float) for a in (points, u, grad_u))
    check_half_plane(points, "stress")
    r = points[:, 0]
    on_axis = r <= 0.0
    hoop = np.where(on_axis, g[:, 0, 0], u[:, 0] / np.where(on_axis, 1.0, r))
    eps = np.zeros((len(points), 3, 3))
    eps[:, :2, :2] = 0.5 * (g + np.swapaxes(g, 1, 2))
    eps[:, 2, 2] = hoop
    lam, mu = material.lmbda, material.mu
    material.axisymmetric_voigt()  # refuses a plane law
    tr = np.trace(eps, axis1=1, axis2=2)[:, None, None]
    return 2.0 * mu * eps + lam * tr * np.eye(3)


def radius(mesh: dolfinx.mesh.Mesh) -> ufl.core.expr.Expr:
    """``r = x[0]`` of the mesh, as UFL: ``2 * ufl.pi * radius(mesh) * ufl.dx`` is the volume
    measure of the solid of revolution."""
    return ufl.SpatialCoordinate(mesh)[0]


def measure(mesh: dolfinx.mesh.Mesh) -> ufl.core.expr.Expr:
    """``2 pi r`` as UFL: the factor of ``dx`` (and ``ds``) over the solid of revolution."""
    return 2.0 * ufl.pi * radius(mesh)


def revolved_if(
    rule: QuadraturePoints, material: object, constraint: bool = False
) -> QuadraturePoints:
    """:func:`revolved` when ``material`` is axisymmetric (``plane="axisymmetric"``), else
    ``rule`` itself: the one test every integral of a model that may be axisymmetric makes."""
    if getattr(material, "plane", None) != AXISYMMETRIC:
        return rule
    return revolved(rule, constraint)


def ufl_strain(u: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """The axisymmetric strain as a 3 x 3 UFL tensor in (r, z, theta): ``sym(grad u)`` in the
    section and ``u_r / r`` on the diagonal's last entry."""
    r = radius(ufl.domain.extract_unique_domain(u))
    g = ufl.sym(ufl.grad(u))
    return ufl.as_tensor([[g[0, 0], g[0, 1], 0.0], [g[1, 0], g[1, 1], 0.0], [0.0, 0.0, u[0] / r]])


def ufl_stress(u: ufl.core.expr.Expr, material: LinearElastic) -> ufl.core.expr.Expr:
    """The axisymmetric stress (3 x 3 UFL tensor) of ``material`` (3D Lamé constants):
    ``a = inner(ufl_stress(u, m), ufl_strain(v)) * 2 * pi * radius(mesh) * dx``."""
    material.axisymmetric_voigt()  # refuses a plane law
    eps = ufl_strain(u)
    mu, lmbda = ufl_constants(u, material.mu, material.lmbda)
    return 2.0 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(3)
