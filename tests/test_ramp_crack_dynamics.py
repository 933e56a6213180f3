"""Cracked patches of the ramp and master-slave couplings in explicit dynamics (issue 25, item
3; found while building it): the ramp's dynamic particle block was integrated by plain Gauss
across the crack (its static block was cut), and master-slave with crack-face contact failed
inside PETSc on a size mismatch."""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import CrackContact

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

COMM = MPI.COMM_WORLD
#: nu = 0: the field u = (x, 0) is a uniaxial stress sigma_xx, which leaves horizontal crack
#: faces free of traction.
MATERIAL = mf.LinearElastic(1000.0, 0.0, plane="stress")


def cracked(coupling, contact=None):
    msh = dolfinx.mesh.create_unit_square(COMM, 20, 20, dolfinx.mesh.CellType.quadrilateral)
    crack = mf.Crack([[0.38, 0.5125], [0.62, 0.5125]])
    cells = mf.cells_near(msh, np.array([[0.5, 0.5]]), 0.3)
    patch = mf.ParticlePatch(msh, cells, 0.05, cracks=[crack])
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, MATERIAL, coupling=coupling, consistent=False)
    return mf.ExplicitDynamics.coupled(problem, crack_contact=contact), patch.particles


def test_ramp_particle_block_is_cut():
    """The internal force of the uniaxial field at the particles near the crack (their supports
    reach neither the exterior boundary nor the FE side, and the crack faces are traction-free:
    zero exactly, up to the quadrature of the cut MLS): 6.5e-3 of E h with the cut cells
    integrated side by side, 2.3e-2 with the plain Gauss rule it had; checked 1.3e-2."""
    dyn, P = cracked("ramp")
    K = dyn.fields[1].K
    dofs = P.petsc_dofs(2)
    x = P.positions[:, :2]
    full = np.zeros(2 * P.num_particles)
    full[dofs[:, 0]] = x[:, 0]  # u = (x, 0): reproduced exactly by the cut MLS
    d, f = K.createVecRight(), K.createVecLeft()
    r0, r1 = d.getOwnershipRange()
    d.array[:] = full[r0:r1]
    K.mult(d, f)
    res = np.zeros_like(full)
    res[r0:r1] = f.array_r
    res = COMM.allreduce(res)
    near = (np.abs(x[:, 1] - 0.5125) < 0.12) & (np.abs(x[:, 0] - 0.5) < 0.12)
    assert np.abs(res[dofs[near].ravel()]).max() <= 1.3e-2 * MATERIAL.E * 0.05


def test_master_slave_contact_refused():
    with pytest.raises(ValueError, match="crack_contact= is not available with coupling='master"):
        cracked("master-slave", CrackContact())
