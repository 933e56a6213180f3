"""The particles' law against the user's residual at finite strain (``CoupledNonlinearProblem``).

Saint Venant-Kirchhoff and neo-Hookean share their linearisation, which is all the linear
problem compares: before, a residual written with one and ``material`` the other ran FE cells and
particles on two laws, silently (the block's middle moved 0.1 %, the patch's stresses by
tens of percent). Now the residual on the patch cells is assembled at two homogeneous
deformations and compared with ``P(F)`` of the material. Oracles: the closed-form nominal stress
written by hand in UFL here (independent of the library's UFL), the library's own
``ufl_first_piola`` in plane strain, plane stress and 3D, and each mismatch refused with the law
it encodes named.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

pytestmark = pytest.mark.filterwarnings("ignore::dolfinx_meshfree.PartitionImbalanceWarning")

COMM = MPI.COMM_WORLD
E, NU = 1000.0, 0.3


def block(dim):
    if dim == 3:
        msh = dolfinx.mesh.create_box(
            COMM, [[0.0, 0.0, 0.0], [3.0, 1.0, 1.0]], [6, 2, 2], dolfinx.mesh.CellType.tetrahedron
        )
    else:
        msh = dolfinx.mesh.create_rectangle(
            COMM, [[0.0, 0.0], [3.0, 1.0]], [12, 4], dolfinx.mesh.CellType.quadrilateral
        )
    V = _compat.vector_function_space(msh, 1)
    tdim = msh.topology.dim
    n = msh.topology.index_map(tdim).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n]].mean(axis=1)
    cells = np.flatnonzero((mid[:, 0] > 1.0) & (mid[:, 0] < 2.0)).astype(np.int32)
    left = dolfinx.mesh.locate_entities_boundary(msh, tdim - 1, lambda x: np.isclose(x[0], 0.0))
    bc = dolfinx.fem.dirichletbc(
        np.zeros(msh.geometry.dim), dolfinx.fem.locate_dofs_topological(V, tdim - 1, left), V
    )
    return msh, V, cells, [bc]


def by_hand_neo_hookean(F, law):
    """``P = mu (F - F^-T) + lambda ln J F^-T`` written here (plane strain and 3D)."""
    FinvT = ufl.inv(F).T
    return law.mu * (F - FinvT) + law.lmbda * ufl.ln(ufl.det(F)) * FinvT


def build(dim, user, material):
    msh, V, cells, bcs = block(dim)
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    F = ufl.Identity(dim) + ufl.grad(u)
    dx = ufl.dx(metadata={"quadrature_degree": 4})  # plane-stress neo-Hookean needs a degree
    residual = ufl.inner(user(F), ufl.grad(v)) * dx
    patch = mf.ParticlePatch(msh, cells, spacing=0.25 if dim == 2 else 0.5)
    return mf.CoupledNonlinearProblem(residual, u, bcs, patch, material, coupling="lagrange")


@pytest.mark.parametrize(
    "dim, plane, law",
    [(2, "strain", "nh"), (2, "stress", "nh"), (2, "strain", "svk"), (2, "stress", "svk"),
     (2, "strain", "linear"), (3, None, "nh"), (3, None, "svk")],
)  # fmt: skip
def test_the_laws_own_residual_is_taken(dim, plane, law):
    cls = {"nh": mf.NeoHookean, "svk": mf.SaintVenantKirchhoff, "linear": mf.LinearElastic}[law]
    material = cls(E=E, nu=NU, plane=plane)
    build(dim, material.ufl_first_piola, material)  # no error


@pytest.mark.parametrize("dim", [2, 3])
def test_a_residual_written_by_hand_is_taken(dim):
    material = mf.NeoHookean(E=E, nu=NU, plane="strain" if dim == 2 else None)
    build(dim, lambda F: by_hand_neo_hookean(F, material), material)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_law_that_shares_only_the_linearisation_is_refused(dim):
    plane = "strain" if dim == 2 else None
    nh = mf.NeoHookean(E=E, nu=NU, plane=plane)
    svk = mf.SaintVenantKirchhoff(E=E, nu=NU, plane=plane)
    with pytest.raises(ValueError, match=r"at finite strain .*F matches SaintVenantKirchhoff"):
        build(dim, svk.ufl_first_piola, nh)
    with pytest.raises(ValueError, match=r"at finite strain .*F matches NeoHookean"):
        build(dim, lambda F: by_hand_neo_hookean(F, nh), svk)


def test_a_law_of_the_users_own_is_refused_without_a_name():
    """A volumetric term ``kappa / 2 (J - 1)^2`` instead of ``lambda / 2 ln(J)^2``: no law of
    the library; the error says to pass the user's law as a Material."""
    nh = mf.NeoHookean(E=E, nu=NU, plane="strain")

    def other(F):
        J = ufl.det(F)
        FinvT = ufl.inv(F).T
        return nh.mu * (F - FinvT) + nh.lmbda * (J - 1) * J * FinvT

    with pytest.raises(ValueError, match=r"at finite strain(?!.*F matches).*Material of your own"):
        build(2, other, nh)


def test_a_measure_without_a_degree_on_an_unrolled_law_is_refused():
    """Plane-stress neo-Hookean's UFL stress unrolls a Newton on the thickness stretch: FFCx
    estimates degree 2048 (residual) and 8104 (Jacobian) and ran out of memory building 16 M
    points per cell (a ``MemoryError`` of 1.9 PiB); now a ``ValueError`` names the fix."""
    msh, V, cells, bcs = block(2)
    material = mf.NeoHookean(E=E, nu=NU, plane="stress")
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    F = ufl.inner(material.ufl_first_piola(ufl.Identity(2) + ufl.grad(u)), ufl.grad(v)) * ufl.dx
    with pytest.raises(ValueError, match=r"estimated quadrature degree of \d+ .*quadrature_degree"):
        mf.FENonlinearProblem(F, u, bcs)
    patch = mf.ParticlePatch(msh, cells, spacing=0.25)
    with pytest.raises(ValueError, match=r"estimated quadrature degree"):
        mf.CoupledNonlinearProblem(F, u, bcs, patch, material)


@pytest.mark.parametrize("cls", [mf.NeoHookean, mf.SaintVenantKirchhoff, mf.LinearElastic])
def test_a_plane_law_on_a_3d_mesh_is_refused_by_name(cls):
    """The laws default to ``plane="stress"``: on a 3D mesh UFL said only "Can't add
    expressions with different shapes"."""
    _, V, _, _ = block(3)
    u = dolfinx.fem.Function(V)
    with pytest.raises(ValueError, match=r"is a 2D law but ufl_first_piola's F is 3D: pass plane="):
        cls(E=E, nu=NU).ufl_first_piola(ufl.Identity(3) + ufl.grad(u))
    if cls is mf.LinearElastic:
        with pytest.raises(ValueError, match=r"2D law but ufl_stress's u is 3D"):
            cls(E=E, nu=NU).ufl_stress(u)
    with pytest.raises(ValueError, match=r"3D law but ufl_first_piola's F is 2D"):
        cls(E=E, nu=NU, plane=None).ufl_first_piola(ufl.Identity(2))
