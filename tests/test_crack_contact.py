"""Frictionless crack-face contact in explicit dynamics (issue 11; ``dynamics/crack_contact.py``):
a one-sided penalty on the normal gap of the crack faces, for pure EFG and the crack couplings.

Oracles: the exact homogeneous fields of ``test_dynamics_crack`` (the unit square, an interior
crack along x). Under a straining that compresses the faces (``sigma_yy`` rate -1, the linear
field being the exact solution of the uncracked body and of a cracked body whose faces stay
in contact) the model with contact must follow the linear field like the uncracked model
up to the cut-cell quadrature error and a penetration ``~ 1/k``; without contact the faces
overlap and the error is an order of magnitude larger. Under an opening straining the contact
force is exactly zero (``g > 0``): the runs with and without contact are identical. The stable
step bound is compared with the dense eigenvalues of ``M^-1 (K + k B^T W B)``.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import ContactSystem, CrackContact
from dolfinx_meshfree.dynamics.crack_contact import contact_points

import dolfinx
import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
from mpi4py import MPI
from test_dynamics_crack import COUPLED_CRACK, INTERIOR, MAT, OPENING, H, C

COMM = MPI.COMM_WORLD
CLOSING = -OPENING  # sigma_yy rate -1: the faces pressed together
DT = 2.5e-4  # below the stable step of every model here (0.5 x 5.1e-4 at factor 100)
X = np.random.default_rng(1).uniform(0.02, 0.98, (200, 2))


def model(method, crack_points, contact=None, comm=COMM):
    """The unit square (10 x 10 cells, particles at spacing 0.1), cracked by ``crack_points``
    (None: uncracked), with ``contact`` (a CrackContact or None)."""
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.ones(2)], [10, 10], dolfinx.mesh.CellType.quadrilateral
    )
    cracks = [] if crack_points is None else [mf.Crack(crack_points)]
    if method == "efg":
        P = mf.ParticleSet.from_cells(msh, H)
        dyn = mf.ExplicitDynamics.efg(
            P, MAT, dilation=2.5, cracks=cracks, safety=0.5, crack_contact=contact
        )
        return msh, dyn
    V = _compat.vector_function_space(msh)
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    cells = np.flatnonzero((np.abs(mid - 0.5) < 0.4).all(axis=1))
    patch = mf.ParticlePatch(msh, cells, H, cracks=cracks)
    prob = mf.CoupledElasticity(V, patch, MAT, coupling=method)
    return msh, mf.ExplicitDynamics.coupled(prob, safety=0.5, crack_contact=contact)


def strained(method, crack_points, G, contact=None, steps=40, comm=COMM):
    """40 steps of DT from ``v = C + G x`` with the tractions of the linear field (rate 1):
    the relative velocity error at X, the displacements at X, the smallest gap (0 without
    contact), the energy drift."""
    msh, dyn = model(method, crack_points, contact, comm)
    dyn.set_initial(velocity=lambda x: C + x[:, :2] @ G.T)
    rate = MAT.stress(np.asarray(G)[None])[0]
    dyn.add_traction(mf.boundary_facets(msh), lambda x, n: n @ rate.T, amplitude=lambda t: t)
    gaps = []
    if isinstance(dyn.system, ContactSystem):

        def record(d, step, t):
            gaps.append(comm.allreduce(float(d.system.gap(d.u).min(initial=np.inf)), op=MPI.MIN))

        res = dyn.run(steps * DT, DT, outputs=np.linspace(0.0, steps * DT, 11), on_output=record)
    else:
        res = dyn.run(steps * DT, DT)
    exact = C + X @ G.T
    v, u = dyn.velocity_at(X), dyn.displacement_at(X)
    err = comm.allreduce(float(np.abs(v - exact).max()), op=MPI.MAX)
    err /= comm.allreduce(float(np.abs(exact).max()), op=MPI.MAX)
    dyn.destroy()
    return err, u, (min(gaps) if gaps else 0.0), res.energy_drift


#: Relative velocity errors after 40 steps of compression normal to the crack, measured:
#: method: uncracked / cracked without contact / with contact (factor 10).
#: efg 1.3e-7 / 1.07e-3 / 9.6e-5. The bounds are twice the contact figures.
@pytest.mark.parametrize(
    ("method", "crack", "bound"),
    [
        ("efg", INTERIOR, 1.9e-4),
        ("lagrange", COUPLED_CRACK, None),
        ("edge-to-edge", COUPLED_CRACK, None),
        ("bridging", COUPLED_CRACK, None),
    ],
)
def test_closed_crack_behaves_like_the_uncracked_body(method, crack, bound):
    err_0, u_0, _, _ = strained(method, None, CLOSING)
    err_open, u_open, _, _ = strained(method, crack, CLOSING)
    err_c, u_c, gap, drift = strained(method, crack, CLOSING, CrackContact())
    scale = COMM.allreduce(float(np.abs(u_0).max()), op=MPI.MAX)
    du_c = COMM.allreduce(float(np.abs(u_c - u_0).max()), op=MPI.MAX) / scale
    du_open = COMM.allreduce(float(np.abs(u_open - u_0).max()), op=MPI.MAX) / scale
    print(method, err_0, err_open, err_c, du_c, du_open, gap, drift)
    assert bound is None or err_c <= bound
    assert err_open >= 5.0 * err_c
    assert du_open >= 5.0 * du_c
    assert gap < 0.0
    assert drift <= 1e-12
