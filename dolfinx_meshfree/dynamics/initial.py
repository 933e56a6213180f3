"""Initial dof values of an explicit model from functions of position.

FE dofs take the nodal values; particle coefficients either reproduce the values at the
particles (``"collocation"``: ``Phi(x_J) c = f(x_J)``, one sparse LU, MLS being not
interpolating) or take them (``"nodal"``); master–slave keeps the masters' values.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from ..couplings.master_slave import MASTER_SELECTION
from ..parallel import Layout, raise_on_all_ranks
from ..statics.petsc import create_aij, create_vector
from .discretisation import Discretisation, VectorFunction, vector_values
from .linalg import mumps_lu

__all__ = [
    "PARTICLE_VALUES",
    "check_particle_values",
    "fe_nodal_values",
    "initial_values",
    "particle_coefficients",
]

#: How particle coefficients take the values of a function.
PARTICLE_VALUES = ("collocation", "nodal")


def check_particle_values(how: str) -> str:
    """Return ``how`` if it is one of :data:`PARTICLE_VALUES`, else raise a ``ValueError``."""
    if how not in PARTICLE_VALUES:
        raise ValueError(f"particle_values={how!r} is not known; use 'collocation' or 'nodal'")
    return how


def fe_nodal_values(disc: Discretisation, fn: VectorFunction, comm: MPI.Comm) -> np.ndarray:
    """``fn`` at the owned FE nodes (PETSc order), interleaved (gdim per node; collective)."""
    x = disc.owned_points(0)
    vals = raise_on_all_ranks(comm, lambda: vector_values(fn, x))
    return vals.ravel()


def particle_coefficients(
    disc: Discretisation, fn: VectorFunction, how: str, comm: MPI.Comm
) -> np.ndarray:
    """Owned particle coefficients (PETSc order, interleaved) of the particle field; for
    master–slave those of the masters (collective).

    Raises:
        RuntimeError: the collocation solve failed.
    """
    P = disc.particles
    own = disc.owned_particles()
    x = P.positions[own]
    vals = raise_on_all_ranks(comm, lambda: vector_values(fn, x))
    if how == "collocation":
        n = P.num_particles
        sl = Layout(P.layout.size_local, n, P.layout.start)
        phi = raise_on_all_ranks(comm, lambda: disc.mls.tabulate(x, 0)).values.tocoo()
        rows = P.petsc_index[own]
        A_loc = sp.csr_matrix((phi.data, (rows[phi.row], P.petsc_index[phi.col])), shape=(n, n))
        A = create_aij(comm, A_loc, sl, sl)
        ksp = mumps_lu(A)  # one factorisation, every component
        out = np.empty_like(vals)
        xs = A.createVecRight()
        for comp in range(vals.shape[1]):
            b = create_vector(comm, sl, rows, vals[:, comp])
            ksp.solve(b, xs)
            if ksp.getConvergedReason() < 0:
                raise RuntimeError("the collocation solve Phi(x_J) c = f(x_J) failed (MUMPS)")
            out[:, comp] = xs.array_r
            b.destroy()
        for obj in (xs, ksp, A):
            obj.destroy()
        vals = out
    if disc.reduction is None:
        return vals.ravel()
    # master-slave: keep the masters' coefficients (the selection of S's master rows)
    S = disc.reduction[1].query(MASTER_SELECTION) or disc.reduction[1]
    full = S.createVecLeft()
    full.array[:] = vals.ravel()
    masters = S.createVecRight()
    S.multTranspose(full, masters)
    out = masters.array_r.copy()
    full.destroy()
    masters.destroy()
    return out


def initial_values(
    disc: Discretisation, k: int, fn: VectorFunction, how: str, comm: MPI.Comm
) -> np.ndarray:
    """The owned dof values of field ``k`` taking ``fn``: nodal values on the FE field,
    coefficients (``how``) on the particle field (collective)."""
    if disc.fields[k].name == "fe":
        return fe_nodal_values(disc, fn, comm)
    return particle_coefficients(disc, fn, how, comm)
