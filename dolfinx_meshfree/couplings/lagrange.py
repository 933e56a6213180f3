"""FE–EFG elastostatics on a mesh with a particle patch, coupled by Lagrange multipliers.

Compatibility coupling (Rabczuk et al. 2006, sec. 5.4, eq. 98–110; Hegen 1996): the FE cells and
the patch cells do not overlap and meet on the interface Gamma_I. Displacement continuity is
imposed weakly by a multiplier field discretised with the FE trace functions of the interface
nodes, Lambda_k = N_k on Gamma_I:

.. math::
    G_{FE} = \\int_{\\Gamma_I} \\Lambda^T N_{FE}, \\qquad G_P = -\\int_{\\Gamma_I} \\Lambda^T \\phi,

and the block system (a PETSc MatNest, fields FE, particles, interface multipliers, and patch
Dirichlet multipliers when essential conditions act on patch facets)

.. math::
    \\begin{bmatrix} K_{FE} & 0 & s G_{FE}^T \\\\ 0 & K_P & s G_P^T \\\\
    s G_{FE} & s G_P & 0 \\end{bmatrix}.

``K_FE`` is DOLFINx's assembly of the elasticity form restricted to the FE cells (``dx`` with the
patch's cell tags); FE dofs that no FE cell supports become identity rows. Essential conditions on
FE facets are applied to ``K_FE`` by ``MatZeroRowsColumns`` (which lifts them into the
right-hand side) and removed from the coupling columns; on patch facets they are multiplier
constraints as in :mod:`~dolfinx_meshfree.statics.efg`. ``s = E`` scales the constraint rows.

Edge-to-edge variant (``coupling="edge-to-edge"``, Rabczuk et al. 2006, sec. 5.4): the multipliers
are collocated at the particles ``x_I`` on the interface, one per particle and component, so that
``G_FE[I, a] = N_a(x_I)`` and ``G_P[I, J] = -phi_J(x_I)``: continuity holds exactly at the
interface particles. It does not integrate the interface traction consistently (the particle
forces become the integral of the linear interpolant of ``phi_J``), so the linear patch test is
passed only to first order in h, not exactly.
"""

from __future__ import annotations

import time
from functools import partial
from typing import TYPE_CHECKING, ClassVar

import dolfinx
import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from .. import _compat
from ..approx.fe_points import tabulate_fe_basis, tabulate_in_cells
from ..geometry.quadrature import DYNAMIC_FACET_DEGREE, QuadraturePoints, facet_quadrature
from ..geometry.smoothing import STABILISATION, value_rule
from ..parallel import Layout, raise_on_all_ranks
from ..physics.axisymmetry import revolved_if
from ..statics.efg import particle_stiffness
from ..statics.kept_factor import KeptFactorisation
from ..statics.petsc import SolverOptions, create_aij, create_vector
from .assembly import (
    append_patch_conditions,
    essential_conditions,
    fe_active,
    fe_stiffness,
    fix_fe_rows,
    fixed_dofs,
    patch_rules,
    pin_forces,
    sizes,
    solve_and_gather,
    traction_loads,
)
from .base import (
    CoupledSolution,
    CouplingDefaults,
    CouplingOperators,
    facet_nodes,
    facet_table,
    fe_constraint_block,
    fe_dof_layout,
    particle_constraint_block,
)

if TYPE_CHECKING:  # annotations only
    from ..statics.coupled import CoupledElasticity

__all__ = [
    "CORNER_ANGLE",
    "EdgeToEdgeCoupling",
    "LagrangeCoupling",
    "collocation_rows",
    "interface_particles",
    "lagrange_rows",
]

#: The ``corner_angle`` of the earlier default (degrees): one Lagrange multiplier per side at
#: interface nodes where the interface turns by more than this (see
#: :func:`interface_multipliers`). No longer the default: on staircase interfaces it
#: over-constrains the particles (measured: 2.2x the FE error instead of 1.1x).
CORNER_ANGLE = 30.0


def interface_multipliers(
    problem: CoupledElasticity, iq: QuadraturePoints, t_fe: sp.csr_matrix
) -> tuple[sp.csr_matrix, Layout]:
    """The multiplier basis of the compatibility coupling at the interface quadrature points
    (collective): ``Lambda_k = N_a``, the FE trace of interface node ``a`` (Rabczuk eq. 109).

    By default (``corner_angle=None``) one multiplier per interface node and component,
    continuous along the whole interface: the multiplier space is the FE trace space, so
    the constraint makes the FE trace the L2 projection of the particle trace (a stable
    mortar pairing whatever the particle spacing). With ``corner_angle`` a node where the
    interface turns by more than that angle carries one multiplier per side, so that
    ``sigma n`` may jump there; on a staircase interface (every node a 90 degree turn)
    that is one discontinuous linear function per facet side, twice the FE trace's
    dimension, and the constraint also asks the particle trace's projection to be
    continuous at every step: with particles at spacing >= 0.75 h this over-constrains
    them (1.7-3.9x the FE error, tests/test_staircase_couplings.py). Consistent
    integration does not need the split: :func:`projected_normals` carries the jump of
    ``n`` (the linear patch test passes to round-off either way). The interface is small,
    so its facets are gathered on every rank and every rank numbers the multipliers the
    same way, owner by owner (the owner of the node).

    Args:
        iq: Quadrature points on ``patch.interface_facets`` (``entities``: the facet).
        t_fe: FE basis there, (points x local nodes).

    Returns:
        ``(Lambda, layout)``: (points x global multipliers) CSR with the pattern of ``t_fe``
        and the multipliers' layout (gdim components per multiplier).
    """
    V, patch, comm = problem.V, problem.patch, problem.patch.comm
    imap = V.dofmap.index_map
    l2g = np.asarray(
        imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    )
    facets = patch.interface_facets
    gdim = V.mesh.geometry.dim
    nodes = facet_nodes(V, facets)  # (facets, vertices per facet)
    per_facet = nodes.shape[1]
    parts = comm.allgather(l2g[nodes].reshape(-1, per_facet))
    offset = int(sum(len(p) for p in parts[: comm.rank]))
    ends = np.concatenate(parts).reshape(-1, per_facet)
    # group the facets at each node: joined when their lines differ by < corner_angle (2D);
    # without corner_angle (any dimension) every facet at a node joins the first one
    group: dict[tuple[int, int], int] = {}
    at_node: dict[int, list[int]] = {}
    for f, vertices in enumerate(ends.tolist()):
        for a in vertices:
            at_node.setdefault(a, []).append(f)
    if problem.corner_angle is None:
        for g, fs in at_node.items():
            for f in fs:
                group[(g, f)] = fs[0]
    else:
        xy = V.tabulate_dof_coordinates()[:, :2]
        tangent = xy[nodes[:, 1]] - xy[nodes[:, 0]] if facets.size else np.zeros((0, 2))
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
        lines = np.concatenate(comm.allgather(tangent)).reshape(-1, 2)
        sine = np.sin(np.radians(problem.corner_angle))
        for g, fs in at_node.items():
            for f in fs:
                joined = [
                    group[(g, e)]
                    for e in fs
                    if (g, e) in group
                    and abs(lines[f, 0] * lines[e, 1] - lines[f, 1] * lines[e, 0]) < sine
                ]
                group[(g, f)] = min(joined) if joined else f
    ranges = np.asarray([*comm.allgather(imap.local_range[0]), imap.size_global])
    keys = sorted(
        set(
            (int(np.searchsorted(ranges, g, side="right") - 1), g, k) for (g, _), k in group.items()
        )
    )
    number = {(g, k): i for i, (_, g, k) in enumerate(keys)}
    owners = np.array([r for r, _, _ in keys], dtype=np.int64)
    start = int(np.sum(owners < comm.rank))
    count = int(np.sum(owners == comm.rank))
    # Lambda: the pattern of t_fe, columns renumbered to the multiplier of (node, piece)
    coo = t_fe.tocoo()
    position = {int(f): offset + i for i, f in enumerate(facets)}
    cols = np.array(
        [
            number[(int(l2g[a]), group[(int(l2g[a]), position[int(iq.entities[q])])])]
            for q, a in zip(coo.row, coo.col, strict=True)
        ],
        dtype=np.int64,
    )
    lam = sp.csr_matrix((coo.data, (coo.row, cols)), shape=(len(iq), len(keys)))
    return lam, Layout(gdim * count, gdim * len(keys), gdim * start)


def lagrange_rows(problem: CoupledElasticity, scale: float = 1.0) -> tuple[tuple, tuple, Layout]:
    """Constraint entries of the compatibility coupling (Rabczuk eq. 109): ``G_FE = int
    Lambda^T N`` and ``G_P = int Lambda^T phi`` on the interface (collective).

    Returns:
        ``(fe_rows, p_rows, layout)`` for :func:`_fe_constraint_block` (local node columns)
        and :func:`_particle_constraint_block`, and the multipliers' layout.
    """
    V, patch, comm = problem.V, problem.patch, problem.patch.comm
    iq = facet_quadrature(
        V.mesh, patch.interface_facets, problem.quadrature_degree, patch.interface_fe_cells
    )
    iq = raise_on_all_ranks(comm, lambda: revolved_if(iq, problem.material))  # 2 pi r ds
    t_fe = facet_table(V, iq.points, iq.cells)
    t_p = raise_on_all_ranks(comm, lambda: problem.mls.tabulate(iq.points, 0)).values
    lam, ml = interface_multipliers(problem, iq, t_fe)
    W = sp.diags(iq.weights)
    M_fe = (lam.T @ W @ t_fe).tocoo()  # (multipliers x local nodes)
    M_p = (lam.T @ W @ t_p).tocoo()  # (multipliers x particles)
    tiny = 1e-14 * (np.abs(M_fe.data).max() if M_fe.nnz else 1.0)
    keep = np.abs(M_fe.data) > tiny
    fe_rows = (M_fe.row[keep], M_fe.col[keep], M_fe.data[keep], False)
    keep = np.abs(M_p.data) > tiny
    p_rows = (M_p.row[keep], M_p.col[keep], M_p.data[keep])
    return fe_rows, p_rows, ml


def facet_particles(
    problem: CoupledElasticity, facets: np.ndarray
) -> tuple[np.ndarray, np.ndarray, list]:
    """The particles on each of ``facets`` (local), with their place along it (local).

    A particle is on a facet when its distance to it is below ``1e-10`` times the facet's
    length.

    Returns:
        ``(a, t, on)``: each facet's first vertex and its vector ``t`` to the second (k, 2),
        and per facet ``(particles, xi)`` sorted by ``xi`` in [0, 1], the particle's place
        ``a + xi t``.
    """
    msh, x = problem.patch.mesh, problem.patch.particles.positions
    if facets.size == 0 or msh.geometry.dim != 2:  # 3D facets: no particle lines (I_h)
        return (
            np.zeros((0, 2)),
            np.zeros((0, 2)),
            [(np.zeros(0, np.int64), np.zeros(0))] * len(facets),
        )
    fdim = msh.topology.dim - 1
    ends = msh.geometry.x[_compat.entities_to_geometry(msh, fdim, facets), :2]
    a, t = ends[:, 0], ends[:, 1] - ends[:, 0]
    length = np.linalg.norm(t, axis=1)
    tol = 1e-10 * length
    on = []
    near = cKDTree(x).query_ball_point(a + 0.5 * t, 0.5 * length + 2.0 * tol)
    for f, cand in enumerate(near):
        cand = np.asarray(cand, dtype=np.int64)
        # distance to the segment a + [0, 1] t
        r = x[cand] - a[f]
        xi = np.clip(r @ t[f] / length[f] ** 2, 0.0, 1.0)
        d = np.linalg.norm(r - xi[:, None] * t[f], axis=1)
        hit = d <= tol[f]
        order = np.argsort(xi[hit], kind="stable")
        on.append((cand[hit][order], xi[hit][order]))
    return a, t, on


def particles_on_facets(
    problem: CoupledElasticity, facets: np.ndarray, cells: np.ndarray
) -> np.ndarray:
    """The particles on any of ``facets`` (local), ``cells``: the local cell beside each; local.

    Dimension-generic (segments, triangles, planar or not quadrilaterals): a particle near a
    facet is on it when the degree-1 basis of the cell at the particle is non-negative (it
    lies in the cell) and the basis functions of the facet's nodes sum to 1 (those of the
    other nodes vanish there), both to ``1e-10``.
    """
    V, x = problem.V, problem.patch.particles.positions
    if len(facets) == 0:
        return np.zeros(0, dtype=np.int64)
    msh = V.mesh
    corners = msh.geometry.x[_compat.entities_to_geometry(msh, msh.topology.dim - 1, facets)]
    corners = corners[:, :, : msh.geometry.dim]
    centre = corners.mean(axis=1)
    radius = np.linalg.norm(corners - centre[:, None], axis=2).max(axis=1)
    near = [
        np.asarray(c, dtype=np.int64)
        for c in cKDTree(x).query_ball_point(centre, radius * (1.0 + 1e-9))
    ]
    counts = np.array([c.size for c in near], dtype=np.int64)
    cand = np.concatenate(near) if near else np.zeros(0, np.int64)
    which = np.repeat(np.arange(len(facets)), counts)
    if cand.size == 0:
        return cand
    t = tabulate_in_cells(V, x[cand], np.asarray(cells)[which], derivatives=0).values.tocsr()
    nodes = facet_nodes(V, facets)[which]
    rows = np.repeat(np.arange(cand.size), np.diff(t.indptr))
    on_facet = (t.indices[:, None] == nodes[rows]).any(axis=1)
    on_sum = np.bincount(rows, weights=np.where(on_facet, t.data, 0.0), minlength=cand.size)
    low = np.full(cand.size, np.inf)
    np.minimum.at(low, rows, t.data)
    hit = (np.abs(on_sum - 1.0) <= 1e-10) & (low >= -1e-10)
    return np.unique(cand[hit])


def interface_particles(problem: CoupledElasticity) -> np.ndarray:
    """Indices of the particles on the interface facets, the same on every rank (collective).

    In 2D a particle is on the interface when its distance to one of the interface facets is
    below ``1e-10`` times that facet's length; in 3D by :func:`particles_on_facets`. Each rank
    tests its owned interface facets; the flags are combined by an MPI MAX reduction.
    """
    patch = problem.patch
    flags = np.zeros(patch.particles.num_particles, dtype=np.int8)
    if patch.mesh.geometry.dim == 2:
        for found, _ in facet_particles(problem, patch.interface_facets)[2]:
            flags[found] = 1
    else:
        found = particles_on_facets(problem, patch.interface_facets, patch.interface_patch_cells)
        flags[found] = 1
    patch.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
    found = np.flatnonzero(flags)
    if found.size == 0 and patch.comm.allreduce(len(patch.interface_facets)) > 0:
        raise ValueError(
            "edge-to-edge coupling found no particle on the interface, so the FE and particle "
            "sides would not be coupled; use a particle spacing that puts particles on the "
            "interface (e.g. spacing = h) or coupling='lagrange'"
        )
    return found


def projected_normals(problem: CoupledElasticity, bq: QuadraturePoints) -> np.ndarray:
    """VCI boundary normals of the Lagrange coupling: on the interface facets the normal
    ``n`` is replaced by its L2 projection ``Pi n`` on the multiplier space (collective).

    The FE side of a linear field receives ``int N_a sigma n`` at the interface, which the
    multipliers carry as ``lambda = sigma Pi n`` (every trace ``N_a`` lies in their space);
    the particles then receive ``int phi_J sigma Pi n``, which is what the divergence
    identity of consistent integration must hold with. Where the interface turns inside one
    multiplier's support (every node by default, see :func:`interface_multipliers`) ``n``
    jumps there and ``Pi n != n``; with ``n`` itself the linear patch test missed by 3.8e-5
    (a slanted staircase of gmsh cells).
    The interface's multiplier mass matrix is gathered and solved on every rank.
    """
    V, comm = problem.V, problem.patch.comm
    on = np.flatnonzero(np.isin(bq.entities, problem.patch.interface_facets))
    iq = QuadraturePoints(
        bq.points[on], bq.weights[on], bq.cells[on], bq.normals[on], bq.entities[on]
    )
    lam, _ = interface_multipliers(problem, iq, facet_table(V, iq.points, iq.cells))
    M = (lam.T @ sp.diags(iq.weights) @ lam).tocoo()
    parts = comm.allgather((M.row, M.col, M.data))
    cat = np.concatenate
    M = sp.csc_matrix(
        (cat([p[2] for p in parts]), (cat([p[0] for p in parts]), cat([p[1] for p in parts]))),
        shape=M.shape,
    )
    rhs = comm.allreduce(np.asarray(lam.T @ (iq.weights[:, None] * iq.normals)), op=MPI.SUM)
    coef = np.column_stack([spsolve(M, rhs[:, k]) for k in range(rhs.shape[1])])
    normals = bq.normals.copy()
    normals[on] = lam @ coef
    return normals


def check_smoothed_interface(problem: CoupledElasticity) -> None:
    """Refuse a smoothed integration of the Lagrange coupling where its multipliers cannot
    carry ``sigma n`` (collective; the error on every rank).

    The smoothed strains give the particles the interface force ``int phi_J sigma n``; the
    multipliers pass ``int phi_J sigma Pi n`` (:func:`projected_normals`). Where the
    interface turns at a node whose multiplier is continuous (``corner_angle=None``), ``Pi n
    != n`` and the linear patch test misses (9e-4 relative L2 on a staircase of cells, against
    9e-16 with ``corner_angle=30``): refused, naming the first turning point. VCI carries
    ``Pi n`` in its test gradients instead."""
    if problem.coupling != "lagrange" or problem.integration not in STABILISATION:
        return
    patch = problem.patch
    iq = facet_quadrature(
        patch.mesh, patch.interface_facets, problem.quadrature_degree, patch.interface_patch_cells
    )
    gap = np.linalg.norm(projected_normals(problem, iq) - iq.normals, axis=1)
    worst = float(gap.max(initial=0.0))
    where = iq.points[int(np.argmax(gap))].tolist() if gap.size else None
    worst_all = problem.patch.comm.allreduce(worst, op=MPI.MAX)
    if worst_all > 1e-10:
        points = [w for w, g in problem.patch.comm.allgather((where, worst)) if g == worst_all]
        fix = (
            f"give corner_angle={CORNER_ANGLE} (one multiplier per side where it turns) or "
            "integration='vci'"
            if patch.mesh.geometry.dim == 2
            else "give integration='vci' (a 3D interface that is not planar keeps continuous "
            "multipliers)"
        )
        raise ValueError(
            f"integration={problem.integration!r} with coupling='lagrange': the interface turns "
            f"(near {np.round(points[0], 6).tolist()}) where its multipliers are continuous, "
            f"so they pass sigma Pi n (off n by {worst_all:.2e}) and the linear patch test "
            f"would miss; {fix}"
        )


def interface_interpolant(
    problem: CoupledElasticity, bq: QuadraturePoints, values: sp.csr_matrix
) -> sp.csr_matrix:
    """VCI boundary values of the edge-to-edge coupling: on the interface facets the particle
    functions are replaced by their interpolant on the interface particles,
    ``I_P phi_J = sum_I psi_I phi_J(x_I)`` with ``psi_I`` the piecewise-linear hats of the
    interface particles along each facet (collective).

    The collocated multipliers pass the interface force to particle ``J`` as
    ``sum_I phi_J(x_I) lambda_I``. For a linear field ``lambda_I = int psi_I sigma n``
    balances the FE side (``sum_I N_a(x_I) psi_I = N_a`` on a facet whose ends are
    particles, as the conforming and vertex placements make them) and gives the particles
    ``int sigma n I_P phi_J``; with the consistent integration's divergence identity written
    with the same ``I_P phi_J`` on the interface the linear patch test passes to round-off
    (with ``int sigma n phi_J`` it missed by about 4e-2). With particles only at the facets'
    ends ``I_P`` is the FE interpolant ``I_h phi_J = sum_a N_a phi_J(x_a)``. Particles
    between the ends (spacing < h) need ``I_P``: with ``I_h`` a particle between two nodes
    has ``I_h phi_J`` near 0 where ``phi_J`` is near 1, the correction spoils the particle
    gradients near the interface and the error fell at rate 1.1 only (4.3x the FE error,
    quadrilateral staircase, spacing 0.5 h, traction). A facet whose ends are not particles
    (``placement="grid"``) keeps ``I_h``.

    The stiffness carries the difference ``I_P phi_J - phi_J`` with its first moments
    (``particle_stiffness(..., boundary_moments=True)``,
    :func:`~dolfinx_meshfree.physics.operators.moment_corrections`): with one VCI constant per
    particle that term is weighted by the stress averaged over ``phi_J``'s support instead of
    the stress on the interface, an O(h^2) force error per particle that a free edge does not
    damp (traction on the edges the interface ends on: 1.40x the FE error at h = 1/12 on the
    axis patch, 1.46x on the curved one; with the moments 0.86x and 0.86x,
    ``demos/robustness.py``).
    """
    V, comm, patch = problem.V, problem.patch.comm, problem.patch
    on = np.flatnonzero(np.isin(bq.entities, patch.interface_facets))
    a, t, found = facet_particles(problem, patch.interface_facets)
    index = {int(f): i for i, f in enumerate(patch.interface_facets)}
    fe = facet_table(V, bq.points[on], bq.cells[on])
    gdim = V.mesh.geometry.dim
    xn = V.tabulate_dof_coordinates()[:, :gdim]
    xp = patch.particles.positions
    rows, sites, weights = [], [], []
    for r, q in enumerate(on):
        i = index[int(bq.entities[q])]
        ids, xi = found[i]
        if ids.size >= 2 and xi[0] < 1e-9 and xi[-1] > 1.0 - 1e-9:
            s = float((bq.points[q] - a[i]) @ t[i] / (t[i] @ t[i]))
            k = int(np.clip(np.searchsorted(xi, s, side="right") - 1, 0, ids.size - 2))
            w = (s - xi[k]) / (xi[k + 1] - xi[k])
            pts, ws = xp[ids[k : k + 2]], [1.0 - w, w]
        else:
            row = fe.getrow(r)
            pts, ws = xn[row.indices], list(row.data)
        rows += [r] * len(ws)
        sites.append(pts)
        weights += ws
    sites = np.vstack(sites) if sites else np.zeros((0, gdim))
    phi = raise_on_all_ranks(comm, lambda: problem.mls.tabulate(sites, 0)).values
    B = sp.csr_matrix(
        (
            np.asarray(weights, dtype=float),
            (np.asarray(rows, dtype=np.int64), np.arange(len(sites))),
        ),
        shape=(on.size, len(sites)),
    )
    interpolant = (B @ phi).tocsr()
    place = sp.csr_matrix((np.ones(on.size), (on, np.arange(on.size))), shape=(len(bq), on.size))
    mask = np.ones(len(bq))
    mask[on] = 0.0
    return (sp.diags(mask) @ values + place @ interpolant).tocsr()


def collocation_rows(problem: CoupledElasticity) -> tuple[tuple, Layout]:
    """Edge-to-edge coupling: one multiplier per interface particle and component, owned by
    the particle's owner, rows ``u_FE(x_I) - u_P(x_I)`` (collective).

    Returns:
        ``((block rows, global FE nodes, N values, True), (block rows, particles, phi
        values))`` of this rank's owned interface particles, and the multipliers' layout.
    """
    P, comm = problem.patch.particles, problem.patch.comm
    iface = interface_particles(problem)
    # multiplier blocks in PETSc particle order, hence owner by owner and contiguous per rank
    iface = iface[np.argsort(P.petsc_index[iface], kind="stable")]
    layout = Layout.from_local(comm, int(np.sum(P.owner[iface] == comm.rank)))
    mine = iface[P.owner[iface] == comm.rank]
    block = layout.start + np.arange(mine.size, dtype=np.int64)
    xs = P.positions[mine]
    n_fe = tabulate_fe_basis(problem.V, xs, derivatives=0).values.tocoo()
    keep = np.abs(n_fe.data) > 1e-13  # nodes off the particle's facet: round-off
    phi = raise_on_all_ranks(comm, lambda: problem.mls.tabulate(xs, 0)).values.tocoo()
    phi_keep = phi.data != 0.0
    fe_rows = (block[n_fe.row[keep]], n_fe.col[keep], n_fe.data[keep], True)
    p_rows = (block[phi.row[phi_keep]], phi.col[phi_keep], phi.data[phi_keep])
    d = P.gdim
    ml = Layout(d * layout.size_local, d * layout.size_global, d * layout.start)
    return (fe_rows, p_rows), ml


def interface_operators(
    problem: CoupledElasticity, integration: str = "cells"
) -> CouplingOperators:
    """Lagrange (FE trace multipliers, eq. 109) and edge-to-edge (collocation) operators."""
    t0 = time.perf_counter()
    V, patch, P = problem.V, problem.patch, problem.patch.particles
    comm, n = patch.comm, patch.particles.num_particles
    fe_layout, l2g = fe_dof_layout(problem.V)
    pl = problem.patch.particles.dof_layout(problem.patch.particles.gdim)
    boundary = patch.boundary() if problem.consistent else None
    hook = partial(interface_interpolant, problem) if problem.coupling == "edge-to-edge" else None
    tables: dict = {}
    check_smoothed_interface(problem)
    q, bq = patch_rules(problem, integration, DYNAMIC_FACET_DEGREE)
    Kp_loc, q, tq, _ = particle_stiffness(
        P,
        problem.mls,
        problem.material,
        problem.quadrature_degree,
        boundary,
        hook,
        quadrature=q,
        boundary_quadrature=bq,
        boundary_normals=partial(projected_normals, problem)
        if problem.coupling == "lagrange"
        else None,
        boundary_moments=hook is not None,
        tables=tables,
    )
    # masses and body loads: a smoothing rule's cell Gauss rule
    mq, mvalues = raise_on_all_ranks(comm, lambda: value_rule(problem.mls, q, tq))
    if problem.coupling == "lagrange":
        fe_rows, p_rows, ml = lagrange_rows(problem)
    else:
        (fe_rows, p_rows), ml = collocation_rows(problem)
    no_bc = np.zeros(l2g.size, dtype=bool)
    zero = dolfinx.fem.Function(V)
    zero.x.array[:] = 0.0
    G_fe, _, _ = fe_constraint_block(
        *fe_rows[:3], fe_rows[3], 1.0, no_bc, zero, l2g, (ml.size_global, fe_layout.size_global)
    )
    d = P.gdim
    G_p = particle_constraint_block(*p_rows, 1.0, P.petsc_dofs(d), (ml.size_global, d * n))
    return CouplingOperators(
        coupling=problem.coupling,
        K_fe=fe_stiffness(problem),
        K_p=create_aij(comm, Kp_loc, pl, pl),
        fe_weight=problem.cell_indicator(~patch.in_patch),
        fe_active=fe_active(problem),
        particle_quadrature=mq,
        particle_table=mvalues.tocsr(),
        fe_layout=fe_layout,
        particle_layout=pl,
        G_fe=create_aij(comm, G_fe, ml, fe_layout),
        G_p=create_aij(comm, G_p, ml, pl),
        multiplier_layout=ml,
        particle_tables=tables,
        timings={"operators": time.perf_counter() - t0},
    )


def interface_system(problem: CoupledElasticity, tables: dict | None = None) -> tuple:
    """The Lagrange or edge-to-edge block system, assembled, not solved (collective).

    Args:
        tables: If given, receives the particle quadrature (``"quadrature"``), its MLS table
            (``"table"``) and the test gradients of the stiffness (``"test_gradients"``, VCI
            when consistent): what a finite-strain solve evaluates its internal force with.

    Returns:
        ``(blocks, rhs, mats, extra)``: the nest's blocks and right-hand sides, the PETSc objects
        to destroy, and ``extra`` with ``x_bc`` (PETSc vector of strong values, also to
        destroy), ``active`` and ``is_bc`` (flags per local FE node), ``ubc`` (FE Function of the
        strong values), ``multipliers`` (interface plus patch-boundary multiplier dofs) and the
        ``setup``/``assemble`` seconds.
    """
    patch, P = problem.patch, problem.patch.particles
    comm = patch.comm
    deg = problem.quadrature_degree
    n = P.num_particles
    s = problem.material.E
    d = P.gdim
    pdofs = P.petsc_dofs(d)
    tables = {} if tables is None else tables  # the stiffness's rule: the loads' stresses too
    fe_layout, l2g = fe_dof_layout(problem.V)
    pl = P.dof_layout(d)
    t0 = time.perf_counter()

    # particle side
    boundary = patch.boundary() if problem.consistent else None
    hook = partial(interface_interpolant, problem) if problem.coupling == "edge-to-edge" else None
    normals = partial(projected_normals, problem) if problem.coupling == "lagrange" else None
    check_smoothed_interface(problem)
    q, bq = patch_rules(problem)
    Kp_loc, _, _, kt = particle_stiffness(
        P, problem.mls, problem.material, deg, boundary, hook, boundary_normals=normals,
        tables=tables, boundary_moments=hook is not None, quadrature=q, boundary_quadrature=bq,
    )  # fmt: skip

    # essential conditions: FE side strongly, patch side by multipliers
    _, patch_bc, dq, dtabs, ubc, is_bc = essential_conditions(problem)
    # FE nodes that no FE cell supports
    active = fe_active(problem)

    # interface multipliers
    if problem.coupling == "lagrange":
        fe_rows, p_rows, ml = lagrange_rows(problem)
    else:
        (fe_rows, p_rows), ml = collocation_rows(problem)
    setup = problem.setup_time + time.perf_counter() - t0 - kt["assemble"]

    t1 = time.perf_counter()
    K_fe = fe_stiffness(problem)
    G_fe, g_rows, g_vals = fe_constraint_block(
        *fe_rows[:3],
        fe_rows[3],
        s,
        fixed_dofs(problem, is_bc),
        ubc,
        l2g,
        (ml.size_global, fe_layout.size_global),
    )
    G_p = particle_constraint_block(*p_rows, s, pdofs, (ml.size_global, d * n))

    b_fe, f_p = traction_loads(problem, tables)
    loads = (b_fe.copy(), f_p.copy())
    cat = np.concatenate
    # strong conditions and inactive dofs on K_FE: zero rows and columns, lift into b_fe
    x_bc = fix_fe_rows(
        problem,
        K_fe,
        b_fe,
        is_bc | ~active,
        np.where(is_bc[:, None], ubc.x.array.reshape(-1, d), 0.0),
    )
    Kp = create_aij(comm, Kp_loc, pl, pl)
    b_p = create_vector(comm, pl, pdofs.ravel(), f_p)
    Gfe = create_aij(comm, G_fe, ml, fe_layout)
    GfeT = create_aij(comm, G_fe.T.tocsr(), fe_layout, ml)
    Gp = create_aij(comm, G_p, ml, pl)
    GpT = create_aij(comm, G_p.T.tocsr(), pl, ml)
    g = create_vector(comm, ml, cat([*g_rows, np.zeros(0, np.int64)]), cat([*g_vals, []]))
    blocks = [[K_fe, None, GfeT], [None, Kp, GpT], [Gfe, Gp, None]]
    rhs = [b_fe, b_p, g]
    mats = [K_fe, Kp, Gfe, GfeT, Gp, GpT, loads[0]]
    dl, *pins = append_patch_conditions(problem, blocks, rhs, mats, patch_bc, dq, dtabs)
    extra = {
        "pins": tuple(pins),
        "x_bc": x_bc,
        "active": active,
        "is_bc": is_bc,
        "fixed": is_bc | ~active,
        "fixed_values": np.where(np.repeat(is_bc, d), ubc.x.array, 0.0),
        "multipliers": ml.size_global + dl.size_global,
        "setup": setup,
        "assemble": time.perf_counter() - t1 + kt["assemble"],
        "loads": loads,
        "fe_cells": ~patch.in_patch,
        "fe_weight": None,
        "constant_diagonal": [None, None],
    }
    return blocks, rhs, mats, extra


def solve_interface(
    problem: CoupledElasticity,
    solver: str | SolverOptions = "mumps",
    kept: KeptFactorisation | None = None,
) -> CoupledSolution:
    """Assemble the nest block system and solve it (collective).

    Args:
        solver: ``"mumps"`` (direct) or ``"fieldsplit"`` (Schur complement, displacements
            against multipliers, on the augmented Lagrangian; see
            :class:`~dolfinx_meshfree.statics.petsc.BlockSystem`).
        kept: The direct solve's factorisation shared with earlier solves (a load sweep;
            :func:`~dolfinx_meshfree.statics.petsc.solve_lu`).
    """
    blocks, rhs, mats, extra = interface_system(problem)
    uh, coeffs, solve, lam = solve_and_gather(
        problem, blocks, rhs, [*mats, extra["x_bc"]], solver, kept
    )
    return CoupledSolution(
        u=uh,
        coefficients=coeffs,
        mls=problem.mls,
        patch=problem.patch,
        timings={"setup": extra["setup"], "assemble": extra["assemble"], "solve": solve},
        sizes=sizes(problem, extra["active"], extra["multipliers"]),
        point_forces=pin_forces(extra, lam),
    )


class _InterfaceCoupling(CouplingDefaults):
    """The two multiplier couplings on the interface facets (shared by name below)."""

    default_dilation: ClassVar[float] = 2.0
    consistent_default: ClassVar[bool] = True
    integrations: ClassVar[tuple[str, ...]] = ("cells", "stress-points")
    blended: ClassVar[bool] = False
    dimensions: ClassVar[tuple[int, ...]] = (2, 3)
    missing_3d: ClassVar[str] = ""

    def solve(
        self,
        problem: CoupledElasticity,
        solver: str | SolverOptions,
        kept: KeptFactorisation | None = None,
    ) -> CoupledSolution:
        return solve_interface(problem, solver, kept)

    def operators(
        self, problem: CoupledElasticity, integration: str, slaves: str
    ) -> CouplingOperators:
        return interface_operators(problem, integration)

    def system(self, problem: CoupledElasticity, tables: dict | None = None) -> tuple:
        return interface_system(problem, tables)


class LagrangeCoupling(_InterfaceCoupling):
    """Compatibility coupling: FE trace multipliers on the interface (Rabczuk et al. 2006,
    sec. 5.4, eq. 109)."""

    name: ClassVar[str] = "lagrange"


class EdgeToEdgeCoupling(_InterfaceCoupling):
    """Edge-to-edge coupling: multipliers collocated at the interface particles (Rabczuk et al.
    2006, sec. 5.4)."""

    name: ClassVar[str] = "edge-to-edge"
