"""Essential conditions of the static hybrid SPH–FE coupling.

On facets beside FE cells the conditions are strong (rows and columns of the FE dofs removed,
values lifted into the right-hand side, also through ``K_pf``). On facets beside patch cells:

* with ``integration="smoothed"`` and ``nitsche > 0``, Nitsche's method (Nitsche 1971,
  symmetric) with the tractions of the smoothed strains (:func:`nitsche_terms`);
* otherwise piecewise-constant multipliers on pieces of the boundary at least
  ``multiplier_length`` particle spacings long
  (:func:`~dolfinx_meshfree.geometry.facet_groups.grouped_facet_quadrature`), refused before
  the solve when they are linearly dependent (:func:`check_multipliers`): one multiplier per
  facet outnumbers the centred particles near the boundary once the spacing reaches the element
  size, and the saddle point is then singular.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import dolfinx
import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from ..approx.tables import strain_operator
from ..geometry.facet_groups import FacetGroups, constraint_rank_check, grouped_facet_quadrature
from ..geometry.quadrature import QuadraturePoints
from ..parallel import Layout, raise_on_all_ranks
from ..physics.axisymmetry import RADIUS_TOLERANCE, axisymmetric_operator, revolved_if
from ..physics.user_functions import vector_values
from ..statics.efg import facet_multipliers
from ..statics.petsc import create_aij, create_vector
from .base import CouplingOperators, fe_dof_layout, node_flags
from .hybrid_discretisation import HybridDiscretisation, global_facets
from .hybrid_smoothing import EXTERIOR

__all__ = [
    "Multipliers",
    "StrongConditions",
    "apply_strong_conditions",
    "check_multipliers",
    "multiplier_blocks",
    "nitsche_terms",
    "strong_conditions",
]

VectorFunction = Callable[[np.ndarray], np.ndarray]


def nitsche_terms(
    d: HybridDiscretisation,
    conditions: list[tuple[np.ndarray, VectorFunction, tuple[int, ...]]],
    smoothed: tuple[list[sp.csr_matrix], np.ndarray],
) -> tuple[sp.coo_matrix, np.ndarray]:
    """Nitsche's terms (Nitsche 1971, symmetric) of ``u = ubar`` on patch facets with
    smoothed strains (collective):
    ``-int (t(u).v + t(v).u) + beta int u.v`` and ``-int t(v).ubar + beta int v.ubar`` over
    the exterior edge points of the smoothing cells on those facets, ``t = D B_k n`` the
    traction of the smoothed strain of the edge's sub-cell (``smoothed``: the gradients and
    areas of :func:`~dolfinx_meshfree.couplings.hybrid_strains.smoothed_gradients`), ``u`` the
    particles' interpolant (the functions of the traction loads), ``beta = nitsche * max(D) /
    h_k`` with ``h_k`` the sub-cell's size. Only the held ``components`` of each condition
    enter (a roller: the rows of that component of ``u``, ``v`` and the tractions). Axisymmetric:
    the smoothed strains with their hoop row (``D`` the 4 x 4 law), the edge weights revolved
    (``2 pi r``); on the axis, where that weight vanishes with the exact solution's work, the
    penalty keeps the edge's plain weight so that ``u_r = 0`` is held there. Returns ``K``
    (combined numbering) and ``f`` (interleaved [particles | FE nodes], this rank's share)."""
    msh, comm = d.V.mesh, d.comm
    sc = d.smoothing_cells()
    n = d.patch.particles.num_particles
    N = d.hybrid.interpolation.shape[1]
    grads, areas = smoothed
    axi = d.material.axisymmetric
    if axi:  # B4 (rows rr, zz, rz, tt) and the 4 x 4 law; areas: the revolved volumes
        B = axisymmetric_operator(grads, d.hoop()).tocsr()
        Dm = d.material.axisymmetric_voigt()
        areas = areas / (2.0 * np.pi * sc.centroids[:, 0])
    else:
        B = strain_operator(grads).tocsr()  # (3 ns x 2(n + N))
        Dm = d.material.voigt()
    nv = Dm.shape[0]
    dof = d.dof_map()
    Ks, f = [], np.zeros(2 * (n + N))
    for facets, fn, components in conditions:
        on = np.flatnonzero(
            (sc.fe_cell == EXTERIOR) & np.isin(sc.facet, global_facets(msh, facets))
        )
        w = np.linalg.norm(sc.normals[on], axis=1)
        nrm = sc.normals[on] / np.maximum(w, 1e-300)[:, None]
        x = sc.points[on]
        k = sc.owner[on]
        g = raise_on_all_ranks(
            comm, lambda fn=fn, x=x: vector_values(fn, (x,), len(x), "the Dirichlet value")
        )
        t = raise_on_all_ranks(comm, lambda x=x: d.evaluator.tabulate(x, 0)).values.tocoo()
        m = on.size
        # U: (2m x 2(n + N)) values of the particles' interpolant, interleaved
        U = sp.csr_matrix(
            (
                np.r_[t.data, t.data],
                (np.r_[2 * t.row, 2 * t.row + 1], np.r_[2 * t.col, 2 * t.col + 1]),
            ),
            shape=(2 * m, 2 * (n + N)),
        )
        # T: (2m x 2(n + N)) tractions N_n D B_k (the hoop row carries no in-plane traction)
        Nn = np.zeros((m, 2, nv))
        Nn[:, 0, 0], Nn[:, 0, 2] = nrm[:, 0], nrm[:, 1]
        Nn[:, 1, 1], Nn[:, 1, 2] = nrm[:, 1], nrm[:, 0]
        ND = Nn @ Dm  # (m, 2, nv)
        rows = (nv * k[:, None] + np.arange(nv)).ravel()
        Bk = B[rows]  # (nv m x ...)
        # block diagonal of the (2 x nv) blocks ND[i], built directly (no block_diag of a list)
        NDm = sp.bsr_matrix((ND, np.arange(m), np.arange(m + 1)), shape=(2 * m, nv * m)).tocsr()
        T = (NDm @ Bk).tocsr() if m else sp.csr_matrix((0, 2 * (n + N)))
        beta = d.nitsche * np.max(np.diag(Dm)) / np.sqrt(areas[k])
        wp = w  # the penalty's weight
        if axi:  # revolved; the axis keeps its plain weight in the penalty
            r = x[:, 0]
            scale = max(float(np.abs(sc.points[:, :2]).max(initial=0.0)), 1.0)
            wp = np.where(r <= RADIUS_TOLERANCE * scale, w, 2.0 * np.pi * r * w)
            w = 2.0 * np.pi * r * w
        held = np.zeros((m, 2))
        held[:, list(components)] = 1.0  # only the held components' rows
        W = sp.diags((w[:, None] * held).ravel())
        Wb = sp.diags(((wp * beta)[:, None] * held).ravel())
        K = -(U.T @ W @ T) - (T.T @ W @ U) + U.T @ Wb @ U
        Ks.append(K.tocoo())
        gv = g.ravel()
        f += -(T.T @ (W.diagonal() * gv)) + U.T @ (Wb.diagonal() * gv)
    K = sum(Ks[1:], Ks[0]).tocoo() if Ks else sp.coo_matrix((2 * (n + N),) * 2)
    return sp.coo_matrix((K.data, (dof[K.row], dof[K.col])), shape=K.shape), f


def check_multipliers(
    d: HybridDiscretisation, pieces: list[FacetGroups], components: list[tuple[int, ...]]
) -> None:
    """Refuse linearly dependent multipliers of the patch's essential conditions, on every
    rank before the solve (collective): the rows ``int_g phi_J`` of all pieces ``g`` (the
    same on every rank: the particles are replicated) must have full rank, or the saddle
    point is singular and its solution garbage
    (:func:`~dolfinx_meshfree.geometry.facet_groups.constraint_rank_check`). Checked per
    component, over the pieces whose condition holds it (``components``, one tuple per piece
    list).

    Raises:
        ValueError: on every rank, naming where the dependent multipliers sit.
    """
    rows, where = [], []
    deg = max(d.quadrature_degree, 4)
    for groups in pieces:
        q = revolved_if(groups.quadrature(deg), d.material, True)
        m = np.arange(len(q))
        S = sp.csr_matrix((q.weights, (q.entities, m)), shape=(groups.num_groups, len(q)))
        t = raise_on_all_ranks(d.comm, lambda q=q: d.evaluator.tabulate(q.points, 0))
        rows.append(S @ t.values)
        where.append(np.stack([S @ q.points[:, k] for k in range(2)], axis=1))
        where[-1] /= (S @ np.ones(len(q)))[:, None]
    for comp in (0, 1):
        held = [k for k, c in enumerate(components) if comp in c]
        if not held:
            continue
        block = sp.vstack([rows[k] for k in held]).tocsr()
        at = np.vstack([where[k] for k in held])
        raise_on_all_ranks(
            d.comm, lambda b=block, a=at: constraint_rank_check(b, a, "HybridElasticity")
        )


@dataclass
class StrongConditions:
    """The FE side's strong conditions and the patch side's multiplier pieces.

    Attributes:
        rows: Global FE dofs fixed by this rank (owned). x_bc: Their values (zero elsewhere).
        mask: 1 on free FE dofs, 0 on fixed ones. patch_bc: ``(facets, value, components)``
        of the patch facets with multipliers. quadratures: This rank's quadrature of each
        piece list.
    """

    rows: np.ndarray
    x_bc: PETSc.Vec
    mask: PETSc.Vec
    patch_bc: list[tuple[np.ndarray, VectorFunction, tuple[int, ...]]]
    quadratures: list[QuadraturePoints]


def strong_conditions(
    d: HybridDiscretisation,
    dirichlet: list[tuple[np.ndarray, VectorFunction, tuple[int, ...]]],
    fe_active: np.ndarray,
    nitsche: bool,
) -> StrongConditions:
    """Values of ``u = value(x)`` at the FE nodes of FE facets (the held ``components`` of each
    condition), 0 at FE nodes that no FE cell holds (``fe_active`` false); without Nitsche, the
    multiplier pieces of the patch facets by component (revolved, ``2 pi r ds``, in an
    axisymmetric model), checked by :func:`check_multipliers` (collective).

    Raises:
        ValueError: on every rank, before the solve, if the patch's multipliers are linearly
            dependent.
    """
    V, comm, msh = d.V, d.comm, d.V.mesh
    fe_layout, l2g = fe_dof_layout(d.V)
    n_owned = V.dofmap.index_map.size_local
    fixed = np.repeat(~fe_active, 2).reshape(-1, 2)  # by dof
    values = np.zeros((fixed.shape[0], 2))
    coords = V.tabulate_dof_coordinates()[:, :2]
    patch_bc, dq, pieces, comps = [], [], [], []
    for facets, fn, components in dirichlet:
        f_fe, f_pf = d.split(facets)
        flags = node_flags(d.V, dolfinx.fem.locate_dofs_topological(V, msh.topology.dim - 1, f_fe))
        xn = coords[flags]
        vals = raise_on_all_ranks(
            comm, lambda fn=fn, xn=xn: vector_values(fn, (xn,), len(xn), "the Dirichlet value")
        )
        c = list(components)
        values[np.ix_(flags, c)] = vals[:, c]
        fixed[np.ix_(flags, c)] = True
        if nitsche:
            continue
        patch_bc.append((f_pf, fn, tuple(components)))
        pieces.append(grouped_facet_quadrature(msh, f_pf, d.multiplier_length * d.spacing))
        q = pieces[-1].quadrature(max(d.quadrature_degree, 4), comm.rank)
        dq.append(raise_on_all_ranks(comm, lambda q=q: revolved_if(q, d.material, True)))
        comps.append(tuple(components))
    if pieces:
        check_multipliers(d, pieces, comps)
    node, comp = np.nonzero(fixed[:n_owned])
    rows = (2 * l2g[node] + comp).astype(PETSc.IntType)
    x_bc = create_vector(comm, fe_layout, rows, values[node, comp])
    mask = create_vector(comm, fe_layout, np.zeros(0, np.int64), np.zeros(0))
    mask.set(1.0)
    mask.setValues(rows, np.zeros(rows.size), addv=PETSc.InsertMode.INSERT_VALUES)
    mask.assemble()
    return StrongConditions(rows, x_bc, mask, patch_bc, dq)


def _lift(A: PETSc.Mat, x: PETSc.Vec, b: PETSc.Vec) -> None:
    """``b -= A x``."""
    y = A.createVecLeft()
    A.mult(x, y)
    b.axpy(-1.0, y)
    y.destroy()


def apply_strong_conditions(
    ops: CouplingOperators, bc: StrongConditions, b_fe: PETSc.Vec, b_p: PETSc.Vec
) -> None:
    """Impose the strong conditions on the operators and loads in place: ``b_p -= K_pf x_bc``,
    the fixed columns of ``K_pf`` and rows of ``K_fp`` zeroed, rows and columns of ``K_fe``
    replaced by the identity (its diagonal allocated first) with the values in ``b_fe``."""
    K_fe, K_fp, K_pf = ops.K_fe, ops.K_fp, ops.K_pf
    _lift(K_pf, bc.x_bc, b_p)  # b_p -= K_pf x_bc
    K_pf.diagonalScale(R=bc.mask)
    K_fp.diagonalScale(L=bc.mask)
    K_fe.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    zero = K_fe.createVecLeft()
    zero.set(0.0)
    K_fe.setDiagonal(zero, addv=PETSc.InsertMode.ADD_VALUES)
    zero.destroy()
    K_fe.zeroRowsColumns(bc.rows, diag=1.0, x=bc.x_bc, b=b_fe)


@dataclass
class Multipliers:
    """The multiplier blocks of the patch's essential conditions.

    Attributes:
        D: (multipliers x particle dofs). DT: its transpose. rhs: the prescribed values'
        integrals. layout: the multipliers' layout.
    """

    D: PETSc.Mat
    DT: PETSc.Mat
    rhs: PETSc.Vec
    layout: Layout


def multiplier_blocks(
    d: HybridDiscretisation, bc: StrongConditions
) -> tuple[Multipliers | None, Layout]:
    """The piecewise-constant multipliers of ``bc.patch_bc`` on their pieces with the particles'
    interpolant (:func:`~dolfinx_meshfree.statics.efg.facet_multipliers`; collective): the
    blocks, or None when there are none, and their layout (size 0 when none)."""
    comm, P = d.comm, d.patch.particles
    dtabs = [
        raise_on_all_ranks(comm, lambda q=q: d.evaluator.tabulate(q.points, 0))
        for q in bc.quadratures
    ]
    ml = Layout(0, 0, 0)
    if not bc.patch_bc:
        return None, ml
    Gd, d_rows, d_vals, ml = facet_multipliers(P, bc.patch_bc, bc.quadratures, dtabs, d.material.E)
    if not ml.size_global:
        return None, ml
    pl = d.patch.particles.dof_layout()
    D = create_aij(comm, Gd, ml, pl)
    DT = create_aij(comm, Gd.T.tocsr(), pl, ml)
    return Multipliers(D, DT, create_vector(comm, ml, d_rows, d_vals), ml), ml
