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
constraint there keeps its length weights (:func:`revolved` with ``constraint=True``). An MLS
field held on the axis by multipliers is small there but not zero, so in the cells on the axis
the particles' hoop strain takes the offset off, ``(u_r(r, z) - u_r(0, z)) / r``
(:func:`hoop_table`). Point values at ``r = 0`` (:func:`stress`) take ``u_r / r -> du_r/dr``
(l'Hôpital).

Variationally consistent integration (VCI, Chen, Hillman & Rüter 2013) in axisymmetry: a
constant stress with ``sigma_rr = sigma_tt`` (the field ``u = (a r, b z + c)``, the
axisymmetric patch test) does exact virtual work on a test function ``N_I e_r`` when
``sum_q dN_I/dr 2 pi r w_q = sum_b N_I n_r 2 pi r w_b - sum_q N_I 2 pi w_q`` (the divergence
theorem for ``N_I r e_r``: ``d(r N)/dr = r dN/dr + N``) and on ``N_I e_z`` when
``sum_q dN_I/dz 2 pi r w_q = sum_b N_I n_z 2 pi r w_b``.
:func:`~dolfinx_meshfree.physics.operators.consistent_gradients`, given the hoop table,
corrects the gradients to satisfy both (the hoop term ``N_I / r`` is left as it is: it enters
the identity through the ``- sum_q N_I 2 pi w_q`` term).

FE forms: :func:`radius`, :func:`ufl_strain` and :func:`ufl_stress` write the user's
``inner(sigma(u), eps(v)) 2 pi r dx``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import dolfinx.mesh
import numpy as np
import scipy.sparse as sp
import ufl

from .._compat import entities_to_geometry as _entities_to_geometry
from .._compat import geometry_dofmap as _geometry_dofs
from ..approx.tables import strain_operator
from ..geometry.quadrature import QuadraturePoints, boundary_facets
from ..parallel import raise_on_all_ranks
from .materials import LinearElastic, is_axisymmetric, ufl_constants

if TYPE_CHECKING:  # annotations only
    from ..geometry.particles import ParticleSet

__all__ = [
    "approximation_hoop",
    "axis_points",
    "axis_projections",
    "axisymmetric_operator",
    "axisymmetric_stiffness",
    "check_axis_held",
    "check_half_plane",
    "check_particle_section",
    "hoop_operator",
    "hoop_table",
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


def check_particle_section(particles: ParticleSet) -> None:
    """Refuse particles, or their background mesh, outside the half-plane ``r >= 0`` (local;
    :func:`check_half_plane`)."""
    check_half_plane(particles.mesh.geometry.x, "the particles' mesh")
    check_half_plane(particles.positions, "the particles")


def check_axis_held(
    msh: dolfinx.mesh.Mesh,
    groups: Sequence[tuple[np.ndarray, Sequence[int] | None]],
    particle_cells: np.ndarray | None,
    where: str,
) -> None:
    """Refuse a section whose particles reach the axis without its radial component held there
    (collective; raised on every rank).

    ``groups``: the model's held facets, ``(facets, components)`` (``None``: all components);
    ``particle_cells``: flags per local cell of the cells with particles (``None``: every
    cell). The particles' hoop strain takes the axis offset off (:func:`hoop_table`), so it does
    not hold ``u_r = 0`` there by itself: measured, an EFG cylinder's radial mode missed by 22 %
    and a sphere's breathing mode by 33 % with the axis left free. (FE's ``u_r / r`` at the
    axis nodes holds it: FE may leave it free.)"""
    fdim = msh.topology.dim - 1
    scale = max(float(np.abs(msh.geometry.x[:, :2]).max(initial=0.0)), 1.0)
    axis = boundary_facets(msh, lambda x: np.abs(x[0]) <= RADIUS_TOLERANCE * scale)
    if particle_cells is not None and axis.size:
        msh.topology.create_connectivity(fdim, fdim + 1)
        f2c = msh.topology.connectivity(fdim, fdim + 1)
        cells = np.asarray(f2c.array)[np.asarray(f2c.offsets)[axis]]
        axis = axis[np.asarray(particle_cells, dtype=bool)[cells]]
    held = [np.asarray(f) for f, comps in groups if comps is None or 0 in tuple(comps)]
    free = np.setdiff1d(axis, np.concatenate([np.zeros(0, axis.dtype), *held]))

    def check() -> None:
        if free.size:
            nodes = msh.geometry.x[_entities_to_geometry(msh, fdim, free[:1])][0]
            p = np.round(nodes.mean(axis=0)[:2], 12).tolist()
            raise ValueError(
                f"{where}: {free.size} facet(s) on the axis r = 0 (e.g. at {p}) have particles "
                "but their radial component is not held; hold it: fixed_facets=[(axis, (0,))] "
                "in dynamics, add_dirichlet(axis, lambda x: 0 * x, components=(0,)) in statics "
                "(axis = mf.boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0)))"
            )

    raise_on_all_ranks(msh.comm, check)


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


def hoop_table(
    values: sp.csr_matrix,
    points: np.ndarray,
    axis_values: sp.csr_matrix | None = None,
    near_axis: np.ndarray | None = None,
) -> sp.csr_matrix:
    """The hoop strain of each shape function at every point (m x n): ``N_J(x_q) / r_q``, or,
    at the points flagged ``near_axis``, ``(N_J(x_q) - N_J(0, z_q)) / r_q`` with
    ``axis_values`` the functions at the points' projections on the axis.

    The second form is for approximations that do not vanish on the axis by construction. An MLS
    field held radially on the axis by multipliers leaves ``u_r(0, z)`` small but not zero, and
    ``u_r / r`` at a Gauss point a fraction of a cell from the axis multiplies it: measured 57 %
    too much hoop strain at the first points of an elastic EFG cylinder of HJC concrete. Taking
    the offset off is exact for ``u_r = a r + b r^3`` (so for the patch
    test), leaves ``u_r / r`` as it is where ``u_r(0, z) = 0``, and needs the axis held (else a
    uniform ``u_r`` would cost no hoop strain near the axis). FE with the axis held strongly
    needs none.
    """
    r = _radii(points, "the hoop strain")
    if near_axis is None or not np.any(near_axis):
        return (sp.diags(1.0 / r) @ values).tocsr()
    near = sp.diags(np.asarray(near_axis, dtype=float))
    return (sp.diags(1.0 / r) @ (values - near @ axis_values)).tocsr()


def approximation_hoop(
    approximation: object, msh: dolfinx.mesh.Mesh, rule: QuadraturePoints, values: sp.csr_matrix
) -> sp.csr_matrix:
    """The :func:`hoop_table` of a meshfree ``approximation`` (its ``tabulate(points,
    derivatives=0)``) at ``rule`` on ``msh``, with ``values`` its functions there: the axis
    offset taken off at the points of cells that touch the axis (:func:`axis_points`). Local;
    it tabulates on every rank (an empty set where no cell touches the axis), so callers may
    wrap it in :func:`~dolfinx_meshfree.parallel.raise_on_all_ranks`.

    It is the hoop of the *trial* strain. Under VCI the test functions keep the plain ``N /
    r`` (:func:`hoop_table` without the offset). Their radial identity is the divergence theorem
    for ``N r e_r``, and with the offset in it the correction of a particle on the axis was of
    order ``1 / h``: it passed the patch test but not a thick spherical shell (EFG 6 times
    FE's error, lagrange and edge-to-edge stalled at 3-4e-2). Without VCI (explicit dynamics,
    symmetric ``K``) both sides take this table."""
    near = axis_points(msh, rule.cells)
    on_axis = approximation.tabulate(axis_projections(rule.points[near]), derivatives=0).values
    axis_values = sp.csr_matrix((len(rule), on_axis.shape[1]))
    if near.any():
        axis_values = (sp.eye(len(rule), format="csr")[:, np.flatnonzero(near)] @ on_axis).tocsr()
    return hoop_table(values, rule.points, axis_values, near)


def axis_projections(points: np.ndarray) -> np.ndarray:
    """The points' projections ``(0, z)`` on the axis (m, 2)."""
    out = np.array(points, dtype=float)[:, :2]
    out[:, 0] = 0.0
    return out


def axis_points(msh: dolfinx.mesh.Mesh, cells: np.ndarray) -> np.ndarray:
    """Whether each point's cell (local indices ``cells``) has a vertex on the axis (local):
    the points whose hoop strain :func:`hoop_table` takes the axis offset off."""
    x = msh.geometry.x
    dofs = _geometry_dofs(msh)
    scale = max(float(np.abs(x[:, :2]).max(initial=0.0)), 1.0)
    on_axis = np.abs(x[:, 0]) <= RADIUS_TOLERANCE * scale
    cells = np.asarray(cells, dtype=np.int64)
    out = np.zeros(cells.size, dtype=bool)
    valid = cells >= 0
    out[valid] = on_axis[dofs[cells[valid]]].any(axis=1)
    return out


def hoop_operator(hoop: sp.csr_matrix) -> sp.csr_matrix:
    """The hoop strain operator (m x 2n) of a :func:`hoop_table`: ``(H u)_q`` is ``u_r / r``
    (or its limit) at every point, for interleaved (r, z) dofs."""
    H = hoop.tocoo()
    m, n = hoop.shape
    return sp.csr_matrix((H.data, (H.row, 2 * H.col)), shape=(m, 2 * n))


def axisymmetric_operator(gradients: list[sp.csr_matrix], hoop: sp.csr_matrix) -> sp.csr_matrix:
    """``B4`` (4 m x 2 n) of the tables' ``gradients`` and ``hoop`` (:func:`hoop_table`): rows
    ``4 q + (rr, zz, rz, tt)``, columns interleaved (r, z) dofs."""
    B3 = strain_operator(gradients).tocoo()
    H = hoop_operator(hoop).tocoo()
    q, r = np.divmod(B3.row, 3)
    rows = np.concatenate([4 * q + r, 4 * H.row + 3])
    cols = np.concatenate([B3.col, H.col])
    vals = np.concatenate([B3.data, H.data])
    m, n2 = hoop.shape[0], 2 * hoop.shape[1]
    return sp.csr_matrix((vals, (rows, cols)), shape=(4 * m, n2))


def axisymmetric_stiffness(
    test_gradients: list[sp.csr_matrix],
    hoop: sp.csr_matrix,
    weights: np.ndarray,
    material: LinearElastic,
    trial_gradients: list[sp.csr_matrix] | None = None,
    node_map: np.ndarray | None = None,
    trial_hoop: sp.csr_matrix | None = None,
) -> sp.csr_matrix:
    """``K = sum_q B4_test(x_q)^T D B4_trial(x_q) w_q`` (2n x 2n) of an axisymmetric law.

    ``weights`` are the revolved weights ``2 pi r w`` (:func:`revolved`); ``B4`` stacks the
    plane strain operator of the gradients and the hoop row of ``hoop`` (:func:`hoop_table`).
    ``trial_gradients`` default to ``test_gradients`` (they differ under VCI, which corrects
    the test gradients only), ``trial_hoop`` to ``hoop`` (they differ for a meshfree field near
    the axis: :func:`approximation_hoop` for the trial strain, the plain ``N / r`` for the
    test functions). ``node_map``: the output number of each table column, as
    :func:`~dolfinx_meshfree.physics.operators.stiffness_matrix`.
    """
    if len(test_gradients) != 2:
        raise ValueError(f"an axisymmetric model is 2D (r, z), got {len(test_gradients)} tables")
    D = material.axisymmetric_voigt()
    Bt = axisymmetric_operator(test_gradients, hoop)
    if trial_gradients is None and trial_hoop is None:
        B = Bt
    else:
        trial = hoop if trial_hoop is None else trial_hoop
        B = axisymmetric_operator(trial_gradients or test_gradients, trial)
    DW = sp.kron(sp.diags(np.asarray(weights, dtype=float)), sp.csr_matrix(D), format="csr")
    K = (Bt.T @ DW @ B).tocsr()
    if node_map is None:
        return K
    n = hoop.shape[1]
    dofs = (2 * np.asarray(node_map)[:, None] + np.arange(2)).ravel()
    K = K.tocoo()
    return sp.csr_matrix((K.data, (dofs[K.row], dofs[K.col])), shape=(2 * n, 2 * n))


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
    if not is_axisymmetric(material):
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
