"""A static model handed to explicit dynamics: what it leaves behind is said, not dropped.

``ExplicitDynamics.coupled(model)`` takes the model's mesh, patch, coupling and material, not its
Dirichlet conditions, tractions or body forces (dynamics takes ``fixed_facets=`` and loads that
are functions of time). Before, a user's ``CoupledLinearProblem`` pulled by a traction and a body
force ran in dynamics at rest (kinetic energy 0 to the end), without a word; now a
``StaticModelWarning`` names each item and the call that carries it.
"""

from __future__ import annotations

import warnings

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

pytestmark = pytest.mark.filterwarnings("ignore::dolfinx_meshfree.PartitionImbalanceWarning")

COMM = MPI.COMM_WORLD
MAT = mf.LinearElastic(E=1000.0, nu=0.3, plane="strain", rho=1.0)


def model(traction: bool, body: bool, clamp: bool):
    msh = dolfinx.mesh.create_rectangle(
        COMM, [[0.0, 0.0], [4.0, 1.0]], [16, 4], dolfinx.mesh.CellType.quadrilateral
    )
    V = _compat.vector_function_space(msh, 1)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(MAT.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    right = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 4.0))
    tags = dolfinx.mesh.meshtags(
        msh, 1, np.sort(right).astype(np.int32), np.full(right.size, 1, np.int32)
    )
    ds = ufl.Measure("ds", msh, subdomain_data=tags)
    L = ufl.inner(dolfinx.fem.Constant(msh, np.array([0.0, 0.0])), v) * ds(1)
    if traction:
        L += ufl.inner(dolfinx.fem.Constant(msh, np.array([1.0, 0.0])), v) * ds(1)
    if body:
        L += ufl.inner(dolfinx.fem.Constant(msh, np.array([0.0, -0.5])), v) * ufl.dx
    bcs = []
    if clamp:
        left = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 0.0))
        dofs = dolfinx.fem.locate_dofs_topological(V, 1, left)
        bcs.append(dolfinx.fem.dirichletbc(np.zeros(2), dofs, V))
    cells = dolfinx.mesh.locate_entities(msh, 2, lambda x: x[0] >= 2.0 - 1e-9)
    patch = mf.ParticlePatch(msh, cells, spacing=0.25)
    return mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, coupling="lagrange").model


@pytest.mark.parametrize(
    "traction, body, clamp, named",
    [(True, True, False, ("tractions", "body forces")), (False, False, True, ("Dirichlet",)),
     (True, False, True, ("Dirichlet", "tractions"))],
)  # fmt: skip
def test_the_static_conditions_and_loads_left_behind_are_named(traction, body, clamp, named):
    with pytest.warns(mf.StaticModelWarning) as record:
        mf.ExplicitDynamics.coupled(model(traction, body, clamp))
    (message,) = [str(w.message) for w in record if w.category is mf.StaticModelWarning]
    for name in named:
        assert name in message
    for name in {"Dirichlet", "tractions", "body forces"} - set(named):
        assert name not in message


def test_a_model_without_them_builds_in_silence():
    """A zero traction (a form needs an integral) is no load."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", mf.StaticModelWarning)
        mf.ExplicitDynamics.coupled(model(False, False, False))
