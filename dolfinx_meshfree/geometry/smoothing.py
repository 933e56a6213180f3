"""Smoothed strains: a symmetric, consistent integration of the particle stiffness.

Strain smoothing (stabilised conforming nodal integration, Chen, Wu, Yoon & You 2001, in its
cell-based form: Liu, Dai & Nguyen-Thoi 2007, the smoothed finite element method) replaces the
strain on a smoothing domain ``Omega_k`` by its mean, computed by the divergence theorem on the
domain's boundary,

.. math::
    \\tilde\\nabla N_I(\\Omega_k)
    = \\frac{1}{|\\Omega_k|}\\int_{\\partial\\Omega_k} N_I\\,n\\,d\\Gamma
    \\approx \\frac{1}{|\\Omega_k|} \\sum_b N_I(x_b)\\, n_b\\, w_b ,

so that only values of the shape functions are needed there. For a linear field ``u^h`` (which
MLS reproduces) the sum is exact, so the smoothed strain is exact; and since a facet shared by
two domains carries the same points on both sides with opposite normals, ``sum_k |Omega_k|
B~_k[I] = sum_b N_I n w`` over the boundary of the integration domain only: the divergence
identity the linear patch test needs (Chen, Hillman & Rüter 2013), here with the facet rule of
:func:`~dolfinx_meshfree.geometry.quadrature.facet_quadrature`, the rule of the tractions and of
the multipliers, so the identity holds with the loads' own rule. The stiffness built from
``B~`` is symmetric (Bubnov–Galerkin), unlike VCI's, which corrects the test functions only.

Two variants (:data:`INTEGRATIONS`):

* ``"smoothed"`` (:func:`smoothing_rule` with ``stabilisation = 1``): one smoothing domain per
  integration cell, stabilised by the cell's Gauss points (Puso, Chen, Zywicz & Elmer 2008:
  the energy of the difference between the point strains and the smoothed one). Consistent
  and symmetric; on the cantilever as accurate as VCI (0.95-1.06x its L2 error at h = 2 to
  0.5, 0.38x at h = 0.125).
* ``"smoothed-subcells"`` (``stabilisation = 0``): one sub-cell per facet (the triangle or
  pyramid between the facet and the mean of the cell's vertices), no stabilisation, no
  derivative tabulated: the plain variant. Constant strains per sub-cell make it far less
  accurate (17-39x VCI's L2 error on the cantilever), and with many particles per cell it is
  rank deficient (hexahedra with 8 particles each: 57 zero-energy modes past the rigid ones on
  a 3 x 3 x 3 grid, where the stabilised one has none).
"""

from __future__ import annotations

from dataclasses import dataclass

import dolfinx.mesh
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from .. import _compat
from ..approx.tables import Approximation, ShapeTable
from .quadrature import QuadraturePoints, cell_quadrature, facet_quadrature

__all__ = [
    "INTEGRATIONS",
    "STABILISATION",
    "SmoothingRule",
    "refuse_smoothed",
    "resolve_integration",
    "smoothed_gradients",
    "smoothed_table",
    "smoothing_rule",
]

#: The integrations of a particle stiffness: ``"vci"`` (Gauss points with variationally
#: consistent test gradients, Chen, Hillman & Rüter 2013: Petrov–Galerkin, unsymmetric),
#: ``"smoothed"`` (this module: strains smoothed over each cell, stabilised by the point
#: strains; symmetric and consistent), ``"smoothed-subcells"`` (smoothed over sub-cells, no
#: stabilisation, no derivative tabulated: the plain variant, 17 to 39x VCI's L2 error on the
#: cantilever at h = 2 to 0.5) and ``"gauss"`` (plain Gauss points, Belytschko et al. 1995:
#: symmetric, not consistent).
INTEGRATIONS = ("vci", "smoothed", "smoothed-subcells", "gauss")

#: The stabilisation factor ``beta`` of each smoothed integration (:func:`smoothing_rule`).
STABILISATION = {"smoothed": 1.0, "smoothed-subcells": 0.0}


def resolve_integration(consistent: bool | None, integration: str | None) -> str:
    """The integration named by a model's ``consistent`` and ``integration`` arguments (local).

    ``integration`` wins when given; ``consistent`` alone is the older switch (``True``:
    ``"vci"``, ``False``: ``"gauss"``); neither: ``"vci"``. Contradictory values (``consistent=
    False`` with a consistent integration, or ``consistent=True`` with ``"gauss"``) are refused.
    """
    if integration is None:
        return "gauss" if consistent is False else "vci"
    if integration not in INTEGRATIONS:
        raise ValueError(
            f"integration={integration!r}: choose one of {', '.join(map(repr, INTEGRATIONS))}"
        )
    if consistent is not None and bool(consistent) != (integration != "gauss"):
        raise ValueError(
            f"consistent={consistent!r} contradicts integration={integration!r}: give only "
            "integration= ('vci' and the smoothed ones are consistent, 'gauss' is not)"
        )
    return integration


def refuse_smoothed(
    integration: str,
    cracked: bool = False,
    nonlinear: bool = False,
    fix: str = "integration='vci' (the default)",
) -> None:
    """Refuse a smoothed ``integration`` where it cannot run yet (local, the same on every
    rank): on cut cells (``cracked``: cracks or an adaptive quadrature) and, the stabilised
    one, with a law integrated point by point (``nonlinear``: a finite-strain law, a law with
    state, cohesive faces), whose internal force does not carry the linear elastic
    stabilisation. ``fix``: what the message offers instead."""
    if integration not in STABILISATION:
        return
    if cracked:
        raise ValueError(
            f"integration={integration!r} does not integrate cut cells yet: give {fix} with "
            "cracks or an adaptive quadrature"
        )
    if nonlinear and STABILISATION[integration] > 0.0:
        raise ValueError(
            f"integration={integration!r} is small-strain: it is stabilised by a linear elastic "
            "term that the point-by-point internal force of a finite-strain law, a law with "
            f"state or cohesive faces does not carry yet; give {fix} (in statics also "
            "'smoothed-subcells')"
        )


@dataclass
class SmoothingRule(QuadraturePoints):
    """The smoothing domains of :func:`smoothing_rule` as a quadrature: one point per domain.

    Attributes:
        points: (nk, gdim) the domains' centroids (the mean of the cell's vertices, or of the
            sub-cell's). weights: (nk,) the domains' volumes ``|Omega_k|``.
            cells: (nk,) the cell of each domain. entities: the same.
        boundary_points: (nb, gdim) the points of the domains' boundary rule (each facet
            once).
        boundary: ``gdim`` CSR matrices (nk x nb): ``boundary[j][k, b] = +-n_j(x_b) w_b /
            |Omega_k|``, so that the smoothed gradient table is ``boundary[j] @ N(x_b)``.
    """

    boundary_points: np.ndarray | None = None
    boundary: list[sp.csr_matrix] | None = None
    #: The cells' Gauss rule: the stabilisation's, and the rule of body loads and masses.
    gauss: QuadraturePoints | None = None
    #: (ng,) the smoothing domain (cell) of each Gauss point, with the stabilisation.
    gauss_domains: np.ndarray | None = None
    #: The stabilisation factor ``beta`` (0: none).
    stabilisation: float = 0.0


def smoothing_rule(
    msh: dolfinx.mesh.Mesh,
    cells: npt.ArrayLike,
    degree: int,
    stabilisation: float = 1.0,
    facet_degree: int | None = None,
) -> SmoothingRule:
    """The smoothing domains of local ``cells`` of a 2D or 3D mesh (local, no communication):
    the cells themselves with ``stabilisation = beta > 0``, their sub-cells without.

    With ``beta > 0`` the stiffness is stabilised by the cells' Gauss rule of ``degree`` (Puso,
    Chen, Zywicz & Elmer 2008: the smoothed stiffness plus ``beta`` times the energy of the
    difference between the point strains and their cell's smoothed strain),

    .. math::
        K = \\sum_k |\\Omega_k| \\tilde B_k^T D \\tilde B_k
          + \\beta \\sum_q w_q (B_q - \\tilde B_{k(q)})^T D (B_q - \\tilde B_{k(q)}),

    symmetric, and still consistent: both strains are exact on a linear field, so the second
    sum vanishes on it. With ``beta = 1`` and an exact rule the second sum would turn the first
    into the Gauss stiffness; with the rule actually used, it is the Gauss stiffness plus a
    correction first order in the rule's error that makes it consistent (as VCI's is).

    Args:
        msh: a mesh of triangles, quadrilaterals, tetrahedra or hexahedra (degree-1 geometry).
        cells: local cell indices (the integration cells).
        degree: exactness degree of the cells' Gauss rule (the stabilisation's, the loads'
            and the masses').
        stabilisation: ``beta`` (0: sub-cells, not stabilised).
        facet_degree: exactness degree of the rule on the cells' facets and the sub-cells'
            inner facets (default ``degree``). On the boundary of the integration domain it
            must be the tractions' rule (that of
            :func:`~dolfinx_meshfree.geometry.quadrature.facet_quadrature` of the same degree)
            for the patch test to be exact.

    Raises:
        ValueError: a cell that is not star-shaped from the mean of its vertices (a sub-cell of
            zero or negative volume), or whose sub-cells do not fill it, named by its vertices'
            coordinates.
    """
    import basix

    tdim, gdim = msh.topology.dim, msh.geometry.dim
    cname = msh.topology.cell_type.name
    cells = np.asarray(cells, dtype=np.int64)
    ctype = getattr(basix.CellType, cname)
    topo = basix.topology(ctype)
    ref_facets = [list(f) for f in topo[tdim - 1]]
    nf = len(ref_facets)
    nc = cells.size
    nk = nc * nf
    if nc == 0:  # a rank without cells: an empty rule of the right shapes
        z = np.zeros((0, gdim))
        return SmoothingRule(
            points=z,
            weights=np.zeros(0),
            cells=cells,
            entities=cells,
            boundary_points=z.copy(),
            boundary=[sp.csr_matrix((0, 0)) for _ in range(gdim)],
            gauss=cell_quadrature(msh, degree, cells),
            gauss_domains=np.zeros(0, dtype=np.int64) if stabilisation > 0.0 else None,
            stabilisation=float(stabilisation),
        )
    X = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]  # (nc, nv, gdim)
    centre = X.mean(axis=1)  # (nc, gdim)
    mids = np.stack([X[:, f].mean(axis=1) for f in ref_facets], axis=1)  # (nc, nf, gdim)

    # the cells' facets, each once, with the rule of the tractions (normals out of one cell)
    msh.topology.create_connectivity(tdim, tdim - 1)
    c2f = msh.topology.connectivity(tdim, tdim - 1)
    offsets = np.asarray(c2f.offsets)
    local_facets = np.asarray(c2f.array)[offsets[cells][:, None] + np.arange(nf)]  # (nc, nf)
    flat = local_facets.ravel()
    unique, first, inverse = np.unique(flat, return_index=True, return_inverse=True)
    fdeg = degree if facet_degree is None else facet_degree
    fq = facet_quadrature(msh, unique, fdeg, cells[first // nf])
    npf = len(fq) // max(unique.size, 1)
    # piece k = (cell, local facet) takes facet inverse[k]'s points, with the sign of whether
    # the facet's normals point out of its own cell; its smoothing domain is the cell with the
    # stabilisation, else the sub-cell between the facet and the centre
    per_cell = stabilisation > 0.0
    nsub = nc if per_cell else nk
    own = np.zeros(nk, dtype=bool)
    own[first] = True
    fpts = inverse[:, None] * npf + np.arange(npf)  # (nk, npf) rows of fq
    sign = np.where(own, 1.0, -1.0)
    domain = np.arange(nk) // nf if per_cell else np.arange(nk)
    rows = [np.repeat(domain, npf)]
    cols = [fpts.ravel()]
    nw = [(sign[:, None, None] * fq.normals[fpts] * fq.weights[fpts][..., None]).reshape(-1, gdim)]
    # the pieces' volumes: (x - c) . n w on the facet (0 on the inner facets, through c)
    rel = fq.points[fpts] - np.repeat(centre, nf, axis=0)[:, None]
    pieces = np.einsum("kpg,kpg->k", rel, nw[0].reshape(nk, npf, gdim)) / gdim
    volume = np.bincount(domain, weights=pieces, minlength=nsub)
    points = [fq.points]
    offset = len(fq)
    if not per_cell:
        _check_fill(msh, cells, X, pieces.reshape(nc, nf))
        # inner facets: 2D the segments (c, x_v), one per vertex; 3D the triangles (c, x_a,
        # x_b), one per edge; each between the two sub-cells whose facets hold the vertex (edge)
        inner = [[v] for v in range(X.shape[1])] if tdim == 2 else [list(e) for e in topo[1]]
        Xr, wr = _inner_rule(tdim, fdeg)
        for piece in inner:
            a, b = [i for i, f in enumerate(ref_facets) if set(piece) <= set(f)]
            edges = X[:, piece] - centre[:, None]  # (nc, tdim - 1, gdim) spanning vectors
            x = centre[:, None] + np.einsum("pd,cdg->cpg", Xr, edges)  # (nc, nr, gdim)
            if tdim == 2:
                t = edges[:, 0]
                n = np.stack([t[:, 1], -t[:, 0]], axis=1)
                size = np.linalg.norm(t, axis=1)
            else:
                n = np.cross(edges[:, 0], edges[:, 1])
                size = 0.5 * np.linalg.norm(n, axis=1)
            n = n / np.linalg.norm(n, axis=1)[:, None]
            # out of sub-cell a: away from its facet's mid-point
            flip = np.einsum("cg,cg->c", n, mids[:, a] - centre) > 0
            n[flip] *= -1.0
            w = size[:, None] * wr[None, :]  # (nc, nr)
            nr = wr.size
            ids = offset + np.arange(nc * nr).reshape(nc, nr)
            offset += nc * nr
            points.append(x.reshape(-1, gdim))
            for sub, sgn in ((a, 1.0), (b, -1.0)):
                rows.append(np.repeat(np.arange(nc) * nf + sub, nr))
                cols.append(ids.ravel())
                nw.append((sgn * n[:, None, :] * w[..., None]).reshape(-1, gdim))

    rows_a, cols_a, nw_a = np.concatenate(rows), np.concatenate(cols), np.concatenate(nw)
    scale = 1.0 / volume[rows_a]
    boundary = [
        sp.csr_matrix((nw_a[:, j] * scale, (rows_a, cols_a)), shape=(nsub, offset))
        for j in range(gdim)
    ]
    gauss = cell_quadrature(msh, degree, cells)
    gauss_domains = None
    if per_cell:
        centroids = centre
        gauss_domains = np.repeat(np.arange(nc), len(gauss) // max(nc, 1))
    else:
        centroids = centre[:, None] + gdim / (gdim + 1.0) * (mids - centre[:, None])
    return SmoothingRule(
        points=centroids.reshape(-1, gdim),
        weights=volume,
        cells=cells if per_cell else np.repeat(cells, nf),
        entities=cells if per_cell else np.repeat(cells, nf),
        boundary_points=np.concatenate(points),
        boundary=boundary,
        gauss=gauss,
        gauss_domains=gauss_domains,
        stabilisation=float(stabilisation),
    )


def smoothed_gradients(rule: SmoothingRule, values: sp.csr_matrix) -> list[sp.csr_matrix]:
    """The smoothed gradient tables (nk x n each) from the shape functions' ``values`` at
    ``rule.boundary_points`` (nb x n): ``grad~ N_I(Omega_k) = sum_b B[k, b] N_I(x_b)``."""
    return [(B @ values).tocsr() for B in rule.boundary]


def smoothed_table(approximation: Approximation, rule: SmoothingRule) -> ShapeTable:
    """The table of a smoothing rule (local): values at the sub-cells' centroids, smoothed
    gradients (:func:`smoothed_gradients`) in place of the gradients; only values are
    tabulated."""
    at = approximation.tabulate(rule.points, derivatives=0)
    on = approximation.tabulate(rule.boundary_points, derivatives=0)
    return ShapeTable(rule.points, at.values, smoothed_gradients(rule, on.values), at.version)


def stiffness_rows(
    approximation: Approximation, rule: SmoothingRule, table: ShapeTable
) -> tuple[list[sp.csr_matrix], np.ndarray]:
    """Gradient rows and weights whose ``sum_r w_r G_r^T D G_r`` is the stiffness of
    :func:`smoothing_rule` (local): one list for test and trial, so that the assembly forms a
    single symmetric pattern.

    Without the stabilisation, the smoothed gradients ``B~`` of ``table`` with the volumes.
    With it, the stiffness of :func:`smoothing_rule` expanded so that no row holds a
    difference of a point's and its cell's gradients (whose pattern would be the whole cell's
    supports at every point). With ``Y_c = sum_{q in c} w_q B_q``, ``W_c = sum_{q in c} w_q``
    and ``a_c = |c| + beta W_c``, its cell terms ``a B~^T D B~ - beta (Y^T D B~ + B~^T D Y)``
    are ``a U^T D U - (beta^2 / a) Y^T D Y`` with ``U = B~ - (beta / a) Y``, so

    ``K = beta sum_q w_q B_q^T D B_q + sum_c [a_c U_c^T D U_c - (beta^2 / a_c) Y_c^T D Y_c]``.
    """
    smoothed = table.gradients
    if rule.stabilisation <= 0.0:
        return smoothed, rule.weights
    beta = rule.stabilisation
    at = approximation.tabulate(rule.gauss.points)
    nc = len(rule)
    W = np.bincount(rule.gauss_domains, weights=rule.gauss.weights, minlength=nc)
    a = rule.weights + beta * W
    gather = sp.csr_matrix(
        (rule.gauss.weights, (rule.gauss_domains, np.arange(len(rule.gauss)))),
        shape=(nc, len(rule.gauss)),
    )
    rows = []
    for g, s in zip(at.gradients, smoothed, strict=True):
        Y = (gather @ g).tocsr()
        U = (s - sp.diags(beta / a) @ Y).tocsr()
        rows.append(sp.vstack([g, U, Y], format="csr"))
    weights = np.concatenate([beta * rule.gauss.weights, a, -(beta**2) / a])
    return rows, weights


def value_rule(
    approximation: Approximation, rule: QuadraturePoints, table: ShapeTable
) -> tuple[QuadraturePoints, sp.csr_matrix]:
    """The rule and values that masses and body loads integrate with (local): a smoothing
    rule's cell Gauss rule and the values there (one point per cell would integrate them to
    first order only), else ``rule`` and ``table.values``."""
    if isinstance(rule, SmoothingRule):
        return rule.gauss, approximation.tabulate(rule.gauss.points, derivatives=0).values
    return rule, table.values


def _inner_rule(tdim: int, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """The rule on an inner facet of the sub-cells as barycentric factors of its spanning
    vectors from the centre (nr, tdim - 1) and reference weights summing to 1."""
    if tdim == 2:
        npts = max(1, (degree + 2) // 2)
        s, w = np.polynomial.legendre.leggauss(npts)
        return (0.5 * (s + 1.0))[:, None], 0.5 * w
    X, w = _compat.quadrature_rule("triangle", degree)
    return np.asarray(X), 2.0 * np.asarray(w)


def _check_fill(msh: dolfinx.mesh.Mesh, cells: np.ndarray, X: np.ndarray, vol: np.ndarray) -> None:
    """Refuse a cell whose sub-cells do not fill it (local): a sub-cell of non-positive volume,
    or volumes that do not add up to the cell's (a cell not star-shaped from its centre)."""
    whole = cell_quadrature(msh, 2, cells).weights.reshape(cells.size, -1).sum(axis=1)
    bad = (vol.min(axis=1) <= 0.0) | (np.abs(vol.sum(axis=1) - whole) > 1e-10 * whole)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"smoothed integration: the cell with vertices {np.round(X[i], 12).tolist()} is not "
            f"star-shaped from the mean of its vertices (sub-cell volumes "
            f"{np.round(vol[i], 15).tolist()}, cell volume {whole[i]:.6e}): its smoothing "
            "sub-cells do not cover it. Use integration='vci' for this mesh, or a mesh of convex "
            "cells"
        )
