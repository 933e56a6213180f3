"""Master–slave at finite strain: rigid links that rotate with their interface edge.

Rabczuk, Xiao & Sauer 2006 (sec. 5.1.2, eq. 17–27) link a slave particle ``P`` to the closest
point ``C = x_a + xi t`` of an interface edge ``(a, b)`` (``t = x_b - x_a``) by a rigid link
``d = x_P - x_C``, and linearise its rotation (``theta e_z x d``,
:mod:`~dolfinx_meshfree.couplings.master_slave`). At finite rotation the link turns with the
edge: the edge's current direction ``t' = t + u_b - u_a`` has turned by
``theta = angle(t') - angle(t)``, and the slave's target is

.. math::
    w_P(u) = (1 - \\xi) u_a + \\xi u_b + (R(\\theta) - I) d,

with ``d theta / d t' = e_z x t' / |t'|^2`` and the Hessian of ``atan2``; for ``d = 0`` (the
default slaves, particles on Gamma_I) it is the linear interpolation of the edge, as in the linear
link. Equally close edges: the mean of their targets, as the linear rows.

The links are imposed as constraints ``g_P(u) = u^h(x_P) - w_P(u) = 0`` (the layer's value
tie; ``u_P - w_P`` for a coefficient tie) with multipliers ``mu`` scaled by ``E`` — the same
constrained equilibrium as the linear solve's elimination ``u = T u_m + g``, whose nonlinear
form ``T(u)`` would need the reduced tangent ``T'^T K T'`` for every iteration. Newton's tangent
carries the links' curvature ``-E mu . d^2 w / du^2`` in the FE block. With zero-length links
the constraint is linear and a linear law through Newton equals the linear master–slave solve.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from ..parallel import Layout, raise_on_all_ranks
from ..statics.efg import particle_stiffness
from ..statics.petsc import create_aij, create_vector
from ..statics.sides import FESide, ParticleSide
from .assembly import (
    append_patch_conditions,
    essential_conditions,
    fe_active,
    fe_stiffness,
    fix_fe_rows,
    patch_rules,
    traction_loads,
)
from .master_slave import (
    MasterSlaveCoupling,
    MasterSlaveLinks,
    outside_slave_layer,
    slave_solve,
    strong_dofs,
)

if TYPE_CHECKING:  # annotations only: the model imports this module
    from ..statics.coupled import CoupledElasticity

__all__ = [
    "FiniteMasterSlaveCoupling",
    "LinkMotion",
    "RotatingLinks",
    "SlaveCorrection",
    "master_slave_system",
]

_J = np.array([[0.0, -1.0], [1.0, 0.0]])  # e_z x


class LinkMotion:
    """The motion ``w_P(u)`` of the rigid links of the slaves ``own`` (positions in
    ``links.slaves``), one term per link (a slave linked to equally close edges has one term per
    edge, weighted by ``1 / count``): targets and derivatives in the edge ends' displacements.

    Attributes:
        k: The slot (position in ``own``) of each term; dofs: (terms, 2 ends, 2) global FE dofs
            of the edge ends.
    """

    def __init__(self, links: MasterSlaveLinks, own: np.ndarray) -> None:
        k, e, xi, d, w = [], [], [], [], []
        for slot, s in enumerate(own):
            ties = links.links[s]
            for edge, x, link in ties:
                k.append(slot)
                e.append(edge)
                xi.append(x)
                d.append(link)
                w.append(1.0 / len(ties))
        self.k = np.asarray(k, dtype=np.int64)
        e = np.asarray(e, dtype=np.int64)
        self.xi, self.w = np.asarray(xi), np.asarray(w)
        self.d = np.asarray(d, dtype=float).reshape(-1, 2)
        self.t = (links.edges[e, 1] - links.edges[e, 0]).reshape(-1, 2)
        # FE dofs (global) of the edge ends, (terms, 2 ends, 2 components)
        self.dofs = 2 * links.nodes[e][:, :, None] + np.arange(2)

    def _links(self, u: np.ndarray):
        """Targets ``w`` (terms, 2) and, per term, ``R d``, ``J R d``, ``grad theta`` and its
        Hessian (of ``theta`` in ``t'``)."""
        ua, ub = u[:, 0], u[:, 1]
        tp = self.t + ub - ua
        cross = self.t[:, 0] * tp[:, 1] - self.t[:, 1] * tp[:, 0]
        theta = np.arctan2(cross, np.einsum("ij,ij->i", self.t, tp))
        c, s = np.cos(theta), np.sin(theta)
        Rd = np.stack([c * self.d[:, 0] - s * self.d[:, 1], s * self.d[:, 0] + c * self.d[:, 1]], 1)
        JRd = Rd @ _J.T
        r2 = np.einsum("ij,ij->i", tp, tp)
        grad = (tp @ _J.T) / r2[:, None]
        x, y = tp[:, 0], tp[:, 1]
        off = y * y - x * x
        hess = np.stack([np.stack([2 * x * y, off], 1), np.stack([off, -2 * x * y], 1)], 1)
        hess /= (r2**2)[:, None, None]
        xi = self.xi[:, None]
        w = self.w[:, None] * ((1.0 - xi) * ua + xi * ub + Rd - self.d)
        return w, Rd, JRd, grad, hess

    def _derivative(self, JRd: np.ndarray, grad: np.ndarray) -> np.ndarray:
        """``d w / d(u_a, u_b)``, (terms, 2 components, 2 ends, 2 components)."""
        turn = JRd[:, :, None] * grad[:, None, :]  # d(R d)/d t'
        eye = np.eye(2)[None]
        da = self.w[:, None, None] * ((1.0 - self.xi)[:, None, None] * eye - turn)
        db = self.w[:, None, None] * (self.xi[:, None, None] * eye + turn)
        return np.stack([da, db], axis=2)

    def _fe_values(self, x: PETSc.Vec) -> np.ndarray:
        """The edge ends' displacements (terms, 2, 2) from the distributed FE state
        (collective)."""
        full = np.concatenate(x.getComm().tompi4py().allgather(x.getArray(readonly=True)))
        return full[self.dofs]


class RotatingLinks(LinkMotion):
    """The slaves' rigid links at finite rotation as constraints over the FE, particle and link
    multiplier fields (a shared side of :class:`~dolfinx_meshfree.statics.sides.BlockProblem`).

    Args:
        fe, particles: The two sides (state and numbering).
        links: The :class:`~dolfinx_meshfree.couplings.master_slave.MasterSlaveLinks`.
        tie: (k x n) sparse rows of this rank's owned slaves: their MLS values at their
            positions (value tie) or their selection (coefficient tie).
        own: Positions in ``links.slaves`` of this rank's owned slaves.
        layout: The multiplier layout (2 per owned slave).
        scale: The multipliers' scaling (``E``).
    """

    fields = (0, 1, 2)

    def __init__(
        self,
        fe: FESide,
        particles: ParticleSide,
        links: MasterSlaveLinks,
        tie: sp.csr_matrix,
        own: np.ndarray,
        layout: Layout,
        scale: float,
    ) -> None:
        super().__init__(links, own)
        self.fe, self.particles, self.comm = fe, particles, particles.comm
        self.layout, self.scale = layout, float(scale)
        tie2 = sp.kron(tie, sp.identity(2), format="coo")
        rows = layout.start + tie2.row
        cols = particles.dof_map[tie2.col]
        n_p = particles.layout.size_global
        self._Phi = sp.csr_matrix(
            (self.scale * tie2.data, (rows, cols)), shape=(layout.size_global, n_p)
        )
        self._held = np.isin(self.dofs.ravel(), fe.held_everywhere()).reshape(self.dofs.shape)

    def internal_force(self, xs: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        """``[-E (dw/du_FE)^T mu, E Phi^T mu, E (Phi u_P - w(u_FE))]``. Collective."""
        u = self._fe_values(xs[0])
        w, _, JRd, grad, _ = self._links(u)
        mu = xs[2].getArray(readonly=True).reshape(-1, 2)[self.k]
        D = self._derivative(JRd, grad)
        f_fe = -self.scale * np.einsum("tc,tcej->tej", mu, D)
        keep = ~self._held
        fe = create_vector(self.comm, self.fe.layout, self.dofs[keep], f_fe[keep])
        Phi = create_aij(self.comm, self._Phi, self.layout, self.particles.layout)
        p = Phi.createVecRight()
        Phi.multTranspose(xs[2], p)
        g = Phi.createVecLeft()
        Phi.mult(xs[1], g)
        wk = np.zeros((self.layout.size_local // 2, 2))
        np.add.at(wk, self.k, w)
        g.array[:] -= self.scale * wk.ravel()
        Phi.destroy()
        return [fe, p, g]

    def tangent(self, xs: Sequence[PETSc.Vec]) -> dict[tuple[int, int], PETSc.Mat]:
        """Blocks FE-FE (the links' curvature), FE-link, link-FE, particle-link, link-particle."""
        u = self._fe_values(xs[0])
        _, Rd, JRd, grad, hess = self._links(u)
        mu = xs[2].getArray(readonly=True).reshape(-1, 2)[self.k]
        D = self._derivative(JRd, grad)
        nfe, nl = self.fe.layout.size_global, self.layout.size_global
        # curvature in t' = t + u_b - u_a: c = w (mu . (-R d) g g^T + (mu . J R d) H)
        c = self.w[:, None, None] * (
            np.einsum("tc,tc->t", mu, -Rd)[:, None, None] * grad[:, :, None] * grad[:, None, :]
            + np.einsum("tc,tc->t", mu, JRd)[:, None, None] * hess
        )
        sign = np.array([-1.0, 1.0])  # t' = t - u_a + u_b
        H = -self.scale * sign[None, :, None, None, None] * sign[None, None, None, :, None]
        H = H * c[:, None, :, None, :]  # (terms, end, comp, end, comp)
        rows = np.broadcast_to(self.dofs[:, :, :, None, None], H.shape)
        cols = np.broadcast_to(self.dofs[:, None, None, :, :], H.shape)
        held = np.broadcast_to(self._held[:, :, :, None, None], H.shape)
        K = sp.csr_matrix((H[~held], (rows[~held], cols[~held])), shape=(nfe, nfe))
        # link rows: -E dw/du_FE
        lrow = (
            self.layout.start + 2 * self.k[:, None, None, None] + np.arange(2)[None, :, None, None]
        )
        lrow = np.broadcast_to(lrow, D.shape)
        lcol = np.broadcast_to(self.dofs[:, None, :, :], D.shape)
        G = sp.csr_matrix((-self.scale * D.ravel(), (lrow.ravel(), lcol.ravel())), shape=(nl, nfe))
        lheld = np.broadcast_to(self._held[:, None, :, :], D.shape).ravel()
        Gt = sp.csr_matrix(
            (-self.scale * D.ravel()[~lheld], (lcol.ravel()[~lheld], lrow.ravel()[~lheld])),
            shape=(nfe, nl),
        )
        fl, pl, ll = self.fe.layout, self.particles.layout, self.layout
        return {
            (0, 0): create_aij(self.comm, K, fl, fl),
            (0, 2): create_aij(self.comm, Gt, fl, ll),
            (2, 0): create_aij(self.comm, G, ll, fl),
            (1, 2): create_aij(self.comm, self._Phi.T.tocsr(), pl, ll),
            (2, 1): create_aij(self.comm, self._Phi, ll, pl),
        }


def master_slave_system(problem: CoupledElasticity, tables: dict | None = None) -> tuple:
    """Master–slave's finite-strain block system (collective): fields FE, particles, link
    multipliers (2 per slave) and patch-side Dirichlet multipliers. The links' blocks depend on
    the state: ``blocks`` has ``None`` there and ``extra["shared_sides"]`` builds the
    :class:`RotatingLinks` that supply them. See
    :func:`~dolfinx_meshfree.couplings.lagrange.interface_system` for ``tables`` and the other
    entries of ``extra``; the linear solve eliminates the links instead
    (:func:`~dolfinx_meshfree.couplings.master_slave.solve_master_slave`)."""
    patch, P = problem.patch, problem.patch.particles
    comm = patch.comm
    pdofs = P.petsc_dofs(2)
    pl = P.dof_layout()
    boundary = patch.boundary() if problem.consistent else None
    q, bq = patch_rules(problem)  # cut cells and crack faces with cracks
    tables = {} if tables is None else tables  # the stiffness's rule: the loads' stresses too
    Kp_loc, _, _, kt = particle_stiffness(
        P, problem.mls, problem.material, problem.quadrature_degree, boundary, tables=tables,
        quadrature=q, boundary_quadrature=bq,
    )  # fmt: skip
    _, patch_bc, dq, dtabs, ubc, is_bc = essential_conditions(problem)
    active = fe_active(problem)
    held, held_values = strong_dofs(problem, is_bc, ubc)
    links = raise_on_all_ranks(
        comm, lambda: MasterSlaveLinks(problem, held, held_values, problem.slaves)
    )
    patch_bc, dq, dtabs = outside_slave_layer(problem, links, patch_bc, dq, dtabs)
    sl = links.slaves
    own = np.flatnonzero(P.owner[sl] == comm.rank)
    lay = Layout.from_local(comm, own.size)
    ml = Layout(2 * lay.size_local, 2 * lay.size_global, 2 * lay.start)
    # the layer's value tie (its default, see master_slave._reduction)
    tie = raise_on_all_ranks(comm, lambda: problem.mls.tabulate(P.positions[sl[own]], 0).values)
    tie = sp.csr_matrix(tie)

    b_fe, f_p = traction_loads(problem, tables)
    loads = (b_fe.copy(), f_p.copy())
    K_fe = fe_stiffness(problem)
    fixed = is_bc | ~active
    values = np.where(is_bc[:, None], ubc.x.array.reshape(-1, 2), 0.0)
    x_bc = fix_fe_rows(problem, K_fe, b_fe, fixed, values)
    Kp = create_aij(comm, Kp_loc, pl, pl)
    b_p = create_vector(comm, pl, pdofs.ravel(), f_p)
    zero = create_vector(comm, ml, np.zeros(0, np.int64), np.zeros(0))
    blocks = [[K_fe, None, None], [None, Kp, None], [None, None, None]]
    rhs = [b_fe, b_p, zero]
    mats = [K_fe, Kp, loads[0]]
    dl, *pins = append_patch_conditions(problem, blocks, rhs, mats, patch_bc, dq, dtabs)
    scale = problem.material.E
    extra = {
        "pins": tuple(pins),
        "x_bc": x_bc,
        "active": active,
        "is_bc": is_bc,
        "fixed": fixed,
        "fixed_values": np.where(np.repeat(is_bc, 2), ubc.x.array, 0.0),
        "multipliers": ml.size_global + dl.size_global,
        "setup": kt["setup"],
        "assemble": kt["assemble"],
        "loads": loads,
        "fe_cells": ~patch.in_patch,
        "fe_weight": None,
        "constant_diagonal": [None, None],
        "shared_sides": lambda fe, particles, material: [
            RotatingLinks(fe, particles, links, tie, own, ml, scale)
        ],
        "links": links,
    }
    return blocks, rhs, mats, extra


class FiniteMasterSlaveCoupling(MasterSlaveCoupling):
    """Master–slave (Rabczuk et al. 2006, sec. 5.1.2) with its finite-strain system: rigid
    links that rotate with their interface edge (:class:`RotatingLinks`)."""

    name: ClassVar[str] = "master-slave"

    def system(self, problem: CoupledElasticity, tables: dict | None = None) -> tuple:
        return master_slave_system(problem, tables)


class SlaveCorrection(LinkMotion):
    """The finite-rotation part of master–slave's reduction in explicit dynamics.

    The linear reduction (:func:`~dolfinx_meshfree.couplings.master_slave.master_slave_operators`)
    is ``u_P = T_PF u_FE + S u_M`` with the links' rotation linearised (eq. 27); at finite
    rotation a slave's target is ``w_P(u)`` of :class:`LinkMotion`, so

    .. math::
        u_P = T_{PF} u_{FE} + S u_M + X c(u_{FE}), \\qquad c = w(u) - w'(0) u,

    with ``X`` the map from the slaves' targets to their parameters (``Phi_SS^{-1}``, value tie,
    or the identity, :func:`~dolfinx_meshfree.couplings.master_slave.slave_solve`). ``c`` is of
    second order in the rotation and vanishes for links of length zero (slaves on Gamma_I).
    Every rank evaluates every slave's links (replicated FE state of the edge ends) and keeps
    the rows of its owned slaves.

    Args:
        problem: The coupled problem (MLS, particles).
        links: Its :class:`~dolfinx_meshfree.couplings.master_slave.MasterSlaveLinks`.
        fe_layout, particle_layout: The dof layouts.
        tie: What a link fixes (``None``: the default of the links' kind).
    """

    def __init__(
        self,
        problem: CoupledElasticity,
        links: MasterSlaveLinks,
        fe_layout: Layout,
        particle_layout: Layout,
        tie: str | None = None,
    ) -> None:
        sl = links.slaves
        super().__init__(links, np.arange(sl.size))
        P, comm = problem.patch.particles, problem.patch.comm
        own = np.flatnonzero(P.owner[sl] == comm.rank)
        X, _ = raise_on_all_ranks(comm, lambda: slave_solve(problem, links, tie, own))
        self.X2 = sp.kron(X, sp.identity(2), format="csr")
        self.rows = P.petsc_dofs(2)[sl[own]].ravel()
        self.local_rows = self.rows - particle_layout.start
        self.fe_layout, self.particle_layout, self.comm = fe_layout, particle_layout, comm
        self.num_slaves = sl.size
        #: The longest link (0: slaves on Gamma_I, ``c = 0``).
        self.length = float(np.max(np.linalg.norm(self.d, axis=1), initial=0.0))
        if self.length <= 1e-12 * links.spacing:
            self.length = 0.0
        _, _, JRd, grad, _ = self._links(np.zeros((self.k.size, 2, 2)))
        self.D0 = self._derivative(JRd, grad)

    def values(self, x_fe: PETSc.Vec) -> np.ndarray:
        """``X c(u_FE)`` on this rank's owned slaves' dofs (:attr:`local_rows`; collective)."""
        u = self._fe_values(x_fe)
        w = self._links(u)[0] - np.einsum("tcej,tej->tc", self.D0, u)
        c = np.zeros((self.num_slaves, 2))
        np.add.at(c, self.k, w)
        return self.X2 @ c.ravel()

    def jacobian(self, x_fe: PETSc.Vec) -> PETSc.Mat:
        """``X dc/du_FE`` (particle dofs x FE dofs, PETSc; collective)."""
        u = self._fe_values(x_fe)
        _, _, JRd, grad, _ = self._links(u)
        D = self._derivative(JRd, grad) - self.D0
        rows = np.broadcast_to(
            2 * self.k[:, None, None, None] + np.arange(2)[:, None, None], D.shape
        )
        cols = np.broadcast_to(self.dofs[:, None, :, :], D.shape)
        nfe = self.fe_layout.size_global
        Dc = sp.csr_matrix(
            (D.ravel(), (rows.ravel(), cols.ravel())), shape=(2 * self.num_slaves, nfe)
        )
        J = (self.X2 @ Dc).tocoo()
        local = sp.csr_matrix(
            (J.data, (self.rows[J.row], J.col)), shape=(self.particle_layout.size_global, nfe)
        )
        return create_aij(self.comm, local, self.particle_layout, self.fe_layout)
