"""The stable time step (item 8 of issue 8): the guard ``2 / omega_bound`` of
:meth:`ExplicitDynamics.critical_time_step` against the true ``omega_max`` of the constrained
system from dense eigenvalues, for FE (quadrilaterals, triangles, nu = 0.3 and 0.45), EFG and
every coupling (and the hybrid with its non-symmetric consistent stiffness); serial and 2 ranks.

The true ``omega_max^2`` is the largest ``|lambda|`` of ``Z^T K Z a = lambda Z^T M Z a`` with
``Z`` a basis of the free dofs' null space of the constraint blocks ``G`` (the velocity
projection keeps ``G v = 0``; dofs with ``M^{-1} = 0`` are at rest)."""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import ExplicitDynamics

import numpy as np
import pytest
import scipy.linalg as sla
from conftest import CELL_TYPES, rectangle
from mpi4py import MPI
from petsc4py import PETSc

ROD = mf.LinearElastic(1.0, 0.3, "strain", rho=1.0)
METHODS = ["fe-quadrilateral", "fe-triangle", "fe-nu045", "efg", *mf.COUPLINGS, "hybrid"]


def _dense(A: PETSc.Mat) -> np.ndarray:
    """The global matrix on every rank (small models only)."""
    ai, aj, av = A.getValuesCSR()
    lo, hi = A.getOwnershipRange()
    rows = np.repeat(np.arange(lo, hi), np.diff(ai))
    out = np.zeros(A.getSize())
    for r, c, v in A.getComm().tompi4py().allgather((rows, np.asarray(aj), np.asarray(av))):
        np.add.at(out, (r, c), v)
    return out


def _gathered(x: np.ndarray, comm: MPI.Comm) -> np.ndarray:
    return np.concatenate(comm.allgather(np.asarray(x)))


def true_omega_max(dyn: ExplicitDynamics) -> float:
    """``omega_max`` of the constrained, free-dof system from dense eigenvalues."""
    comm = dyn.comm
    sizes = [f.mass.getSize() for f in dyn.fields]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    n = int(offsets[-1])
    K = np.zeros((n, n))
    for k, f in enumerate(dyn.fields):
        K[offsets[k] : offsets[k + 1], offsets[k] : offsets[k + 1]] = _dense(f.K)
    for (k, j), B in dyn.blocks.items():
        K[offsets[k] : offsets[k + 1], offsets[j] : offsets[j + 1]] += _dense(B)
    m = np.concatenate([_gathered(f.mass.array_r, comm) for f in dyn.fields])
    free = np.concatenate([_gathered(fr, comm) for fr in dyn.free])
    Z = np.eye(n)[:, free]
    if dyn.G is not None:
        G = np.hstack(
            [
                _dense(g) if g is not None else np.zeros((dyn.projection.num_multipliers, sizes[k]))
                for k, g in enumerate(dyn.G)
            ]
        )
        Z = Z @ sla.null_space(G[:, free])
    Kz, Mz = Z.T @ K @ Z, Z.T @ (m[:, None] * Z)
    if np.allclose(K, K.T, rtol=0, atol=1e-10 * np.abs(K).max()):
        lam = sla.eigh(Kz, Mz, eigvals_only=True)
    else:
        lam = sla.eigvals(Kz, Mz)
    return float(np.sqrt(np.abs(lam).max()))


def build(method: str, comm: MPI.Comm) -> ExplicitDynamics:
    """Small models: a 6 x 3 strip, h = 0.5; particles (spacing h / 2) on x > 3."""
    cell = "triangle" if method == "fe-triangle" else "quadrilateral"
    msh = rectangle(comm, [0.0, 0.0], [6.0, 3.0], [12, 6], CELL_TYPES[cell])
    V = _compat.vector_function_space(msh)
    fixed = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0))
    if method.startswith("fe"):
        mat = mf.LinearElastic(1.0, 0.45, "strain", rho=1.0) if method == "fe-nu045" else ROD
        return ExplicitDynamics.fe(V, mat, fixed_facets=fixed)
    if method == "efg":
        P = mf.ParticleSet.from_cells(msh, 0.5)
        return ExplicitDynamics.efg(P, ROD, quadrature_degree=3)
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 3.0), 0.25)
    if method == "hybrid":
        problem = mf.HybridElasticity(V, patch, ROD)
        return ExplicitDynamics.coupled(problem, fixed_facets=fixed)
    dilation = 3.5 if method.startswith("ramp") else None
    problem = mf.CoupledElasticity(
        V, patch, ROD, coupling=method, quadrature_degree=3, dilation=dilation, overlap=1
    )
    return ExplicitDynamics.coupled(problem, fixed_facets=fixed)


# measured bound / true omega_max (serial and 2 ranks, these models): fe-quadrilateral 1.082,
# fe-triangle 1.003, fe-nu045 1.081, efg 1.107, lagrange 1.089, edge-to-edge 1.089, ramp 1.009,
# ramp-cubic 1.008, bridging 1.088, master-slave 1.087, hybrid 1.136 (plain Gershgorin, y = 1:
# 1.18-1.94, ramp the worst). The check allows 1.25: about twice the largest excess (0.136).
TIGHT = 1.25


@pytest.mark.parametrize("method", METHODS)
def test_time_step_bound_is_above_true_omega_max(method):
    """``omega_true <= omega_bound <= 1.25 omega_true``; the plain row-sum bound is above the
    refined one; the same bound on 1 and 2 ranks."""
    dyn = build(method, MPI.COMM_WORLD)
    crit = dyn.critical_time_step()
    true = true_omega_max(dyn)
    ratio = crit["omega_bound"] / true
    assert 1.0 <= ratio <= TIGHT, (method, true, crit)
    assert crit["critical"] == crit["spectral"] == pytest.approx(2.0 / crit["omega_bound"])
    assert crit["gershgorin"] <= crit["spectral"] * (1 + 1e-12)
    assert dyn.stable_time_step() == pytest.approx(0.9 * crit["critical"], rel=1e-12)
    if MPI.COMM_WORLD.size > 1:
        serial = build(method, MPI.COMM_SELF)
        assert serial.critical_time_step()["omega_bound"] == pytest.approx(
            crit["omega_bound"], rel=1e-12
        )
        serial.destroy()
    dyn.destroy()


def test_courant_step_is_not_a_guard():
    """Why the Courant step ``h / c`` is reported but not used: on right triangles it is 1.44x
    the true critical step ``2 / omega_max`` (unstable), at nu = 0.45 on squares 1.06x."""
    for method, low in (("fe-triangle", 1.3), ("fe-nu045", 1.03)):
        dyn = build(method, MPI.COMM_WORLD)
        crit = dyn.critical_time_step()
        assert crit["courant"] > low * 2.0 / true_omega_max(dyn) > crit["critical"]
        dyn.destroy()
