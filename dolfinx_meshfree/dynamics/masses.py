"""Lumped (row-sum) masses and node/particle spacings for explicit dynamics.

Row-sum lumping (Belytschko et al. 1995, eq. 4.5; Rabczuk et al. 2006, eq. 88–89 and 121):

.. math::
    M_{II} = \\sum_J \\int_\\Omega \\beta \\rho N_I N_J \\, d\\Omega
           = \\int_\\Omega \\beta \\rho N_I \\, d\\Omega,

the second form because the shape functions (FE, MLS, ramp-blended) are a partition of unity.
``beta`` is the energy weight of a bridging band (1 elsewhere). It keeps the total mass exact and
puts each dof's mass where its shape function lives, consistently with the stiffness.

* FE: DOLFINx assembles the linear form ``rho beta (1, 1) . v dx`` (:func:`fe_lumped_mass`);
* particles: ``rho sum_q phi_I(x_q) w_q`` on the stiffness' own cell quadrature
  (:func:`particle_lumped_mass`), or the Voronoi volume ``rho V_I``;
* any shape table with columns ``[local FE nodes | particles]`` (the ramp's interface cells):
  :func:`table_lumped_mass`.
"""

from __future__ import annotations

import itertools

import dolfinx
import numpy as np
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from .. import _compat
from ..geometry.particles import ParticleSet
from ..parallel import Layout
from ..statics.petsc import create_vector

__all__ = [
    "fe_lumped_mass",
    "fe_spacing",
    "particle_lumped_mass",
    "particle_spacing",
    "table_lumped_mass",
]


def fe_lumped_mass(
    V: dolfinx.fem.FunctionSpace,
    rho: float | dolfinx.fem.Function,
    dx: ufl.Measure | None = None,
    weight: ufl.core.expr.Expr | None = None,
) -> PETSc.Vec:
    """Row-sum lumped FE masses ``M_II = int beta rho N_I`` (Belytschko et al. 1995, eq. 4.5;
    Rabczuk et al. 2006, eq. 88), one entry per owned dof of the vector space ``V``
    (collective).

    Assembled by DOLFINx as the linear form ``rho weight (1, 1) . v dx``, the row sum of the
    consistent mass ``rho weight inner(u, v) dx`` (the P1/Q1 basis is a partition of unity).

    Args:
        V: Vector P1/Q1 space. rho: Density (> 0), a number or a scalar field (a DG0 field of
            :class:`~dolfinx_meshfree.MaterialZones`' densities).
        dx: The measure (e.g. ``dx(FE_TAG)`` with the patch's cell tags); default: every cell.
        weight: Scalar UFL weight ``beta`` (a DG0 cell indicator, a bridging weight); default 1.

    Returns:
        A PETSc vector with ``V``'s owned-dof layout (ghost contributions accumulated). Dofs that
        no integrated cell supports get 0.
    """
    msh = V.mesh
    if dx is None:
        dx = ufl.Measure("dx", domain=msh)
    v = ufl.TestFunction(V)
    ones = dolfinx.fem.Constant(msh, np.ones(msh.geometry.dim))
    # rho as a Constant, not a literal: one compiled form for every density (ufl_constants)
    if not isinstance(rho, dolfinx.fem.Function):
        rho = dolfinx.fem.Constant(msh, float(rho))
    integrand = rho * ufl.dot(ones, v)
    if weight is not None:
        integrand = weight * integrand
    b = _compat.assemble_vector(_compat.create_form(integrand * dx))
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    imap = V.dofmap.index_map
    bs = V.dofmap.index_map_bs
    m = PETSc.Vec().createMPI((bs * imap.size_local, bs * imap.size_global), comm=msh.comm)
    m.array[:] = b.array_r[: bs * imap.size_local]
    b.destroy()
    return m


def _check_positive(m: PETSc.Vec, comm: MPI.Comm, what: str) -> None:
    lo = comm.allreduce(float(m.array_r.min()) if m.getLocalSize() else np.inf, op=MPI.MIN)
    if not lo > 0.0:
        raise ValueError(
            f"a lumped {what} mass is not positive (min {lo:.3e}); a shape function integrates "
            "to <= 0 on the cell quadrature: raise quadrature_degree or the dilation, or use "
            "particle_mass='volume'"
        )


def particle_lumped_mass(
    particles: ParticleSet,
    table_values: sp.csr_matrix | None,
    weights: np.ndarray | None,
    rho: float | np.ndarray,
    kind: str = "row-sum",
    check: bool = True,
    revolve: bool = False,
) -> PETSc.Vec:
    """Lumped particle masses, one entry per particle dof in PETSc order (collective).

    Args:
        particles: The particle set.
        table_values: (nq x n) MLS values at this rank's cell quadrature points (the table of
            :func:`~dolfinx_meshfree.statics.efg.particle_stiffness`); ``weights``: (nq,) weights
            (bridging: times ``alpha``).
        rho: Density: a number, or per point (nq,) with ``"row-sum"`` and per particle (n,)
            with ``"volume"`` (:class:`~dolfinx_meshfree.MaterialZones`).
        kind: ``"row-sum"``: ``M_II = rho sum_q phi_I(x_q) w_q``, the row sums of
            ``rho Phi^T W Phi`` (Belytschko et al. 1995, eq. 4.5); ``"volume"``:
            ``rho V_I`` with the particles' Voronoi volumes.
        check: Refuse masses that are not positive.
        revolve: ``"volume"`` in an axisymmetric model: ``rho`` times the particle's region
            revolved, :attr:`~dolfinx_meshfree.ParticleSet.revolved_volumes` where the set has
            them (the hybrid's centred particles: they sum to the patch's revolved volume
            whatever the particles' places), else ``2 pi r_I V_I`` (Pappus: exact for a particle
            at its region's centroid). ``"row-sum"`` takes revolved ``weights`` instead.

    Raises:
        ValueError: on every rank when ``kind`` is unknown or, with ``check``, when a mass is
            not positive (a shape function that integrates to <= 0 on the quadrature: raise the
            quadrature degree or the dilation).
    """
    if kind not in ("row-sum", "volume"):
        raise ValueError(
            f"particle_mass={kind!r} is not known; use 'row-sum' (rho sum_q phi_I w_q) or "
            "'volume' (rho V_I)"
        )
    comm, gdim = particles.comm, particles.gdim
    pl = particles.dof_layout(gdim)
    pdofs = particles.petsc_dofs(gdim)
    if kind == "row-sum":
        if np.ndim(rho) == 0:
            local = float(rho) * np.asarray(table_values.T @ weights).ravel()
        else:  # per point
            local = np.asarray(table_values.T @ (weights * np.asarray(rho))).ravel()
        m = create_vector(comm, pl, pdofs.ravel(), np.repeat(local, gdim))
    else:
        own = particles.owned
        volumes = particles.volumes
        if revolve:
            measured = particles.revolved_volumes
            volumes = (
                measured
                if measured is not None
                else volumes * 2.0 * np.pi * particles.positions[:, 0]
            )
        m = create_vector(
            comm,
            pl,
            pdofs[own].ravel(),
            np.repeat((np.asarray(rho, dtype=float) * volumes)[own], gdim),
        )
    if check:
        _check_positive(m, comm, "particle")
    return m


def table_lumped_mass(
    table_values: sp.csr_matrix,
    weights: np.ndarray,
    rho: float | np.ndarray,
    fe_dofs: np.ndarray,
    fe_layout: Layout,
    particle_dofs: np.ndarray,
    particle_layout: Layout,
    comm: MPI.Comm,
) -> tuple[PETSc.Vec, PETSc.Vec]:
    """Row-sum masses ``rho sum_q Nbar_c(x_q) w_q`` of a table with columns ``[local FE nodes |
    particles]`` (the ramp's blended interface functions, Belytschko et al. 1995, eq. 3.15 and
    4.5), added into an FE and a particle vector (collective; any rank may add any dof).

    Args:
        table_values: (nq x (n_loc + n)) CSR; ``weights``: (nq,).
        rho: The density: a number, or per point (nq,) (a
            :class:`~dolfinx_meshfree.MaterialZones` law: each point's cell's zone's).
        fe_dofs: (n_loc, gdim) global FE dofs of the local nodes; ``particle_dofs``: (n, gdim)
            PETSc
            particle dofs.

    Returns:
        ``(FE masses, particle masses)`` (PETSc vectors with the given layouts).
    """
    n_loc, gdim = fe_dofs.shape
    col = np.asarray(table_values.T @ (np.asarray(rho, dtype=float) * weights)).ravel()
    m_fe = create_vector(comm, fe_layout, fe_dofs.ravel(), np.repeat(col[:n_loc], gdim))
    m_p = create_vector(comm, particle_layout, particle_dofs.ravel(), np.repeat(col[n_loc:], gdim))
    return m_fe, m_p


def fe_spacing(msh: dolfinx.mesh.Mesh, cells: np.ndarray) -> float:
    """Smallest distance between two vertices of one of the given owned cells (collective)."""
    gdim = msh.geometry.dim
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]  # (nc, nv, gdim)
    h = np.inf
    if len(cells):
        for a, b in itertools.combinations(range(nodes.shape[1]), 2):
            h = min(h, float(np.linalg.norm(nodes[:, a] - nodes[:, b], axis=1).min()))
    return msh.comm.allreduce(h, op=MPI.MIN)


def particle_spacing(particles: ParticleSet) -> float:
    """Smallest distance between two particles (positions are replicated: no communication)."""
    d, _ = cKDTree(particles.positions).query(particles.positions, k=2)
    return float(d[:, 1].min())
