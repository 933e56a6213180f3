"""A load or displacement sweep: ``Constant``s of ``L``, ``bcs`` and ``a`` changed between solves.

DOLFINx's ``LinearProblem`` reads its forms and conditions afresh at every ``solve()``, so a user
sweeps a load by setting a ``Constant`` and solving again. Before, the coupled problems kept the
values of their construction: a traction doubled, or a prescribed displacement doubled, gave the
first answer again, silently (and so did ``FENonlinearProblem``'s conditions); a stiffness
doubled in ``a`` moved the FE side only. Oracles: linearity (twice the load, twice the answer)
and a problem built afresh at the new values; a changed ``a`` that no longer matches the
particles' ``material`` is refused.
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
POINTS = np.array([[4.0, 0.5], [3.6, 0.9], [2.0, 0.5], [1.1, 0.2]])
PATCHES = {"middle": (1.5, 2.5), "end": (3.0, 4.0)}  # tractions on FE facets / on the patch


def beam(where):
    msh = dolfinx.mesh.create_rectangle(
        COMM, [[0.0, 0.0], [4.0, 1.0]], [16, 4], dolfinx.mesh.CellType.quadrilateral
    )
    V = _compat.vector_function_space(msh, 1)
    right = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 4.0))
    tags = dolfinx.mesh.meshtags(
        msh, 1, np.sort(right).astype(np.int32), np.full(right.size, 1, np.int32)
    )
    x0, x1 = PATCHES[where]
    cells = dolfinx.mesh.locate_entities(
        msh, 2, lambda x: (x[0] >= x0 - 1e-9) & (x[0] <= x1 + 1e-9)
    )
    n = msh.topology.index_map(2).size_local
    return msh, V, ufl.Measure("ds", msh, subdomain_data=tags), cells[cells < n]


def linear_problem(where, coupling, E_a=None, t0=(0.0, -1.0), g0=0.0):
    """A cantilever: clamped at x = 0, a shear traction ``t`` and a prescribed ``u_x = g`` at
    x = 4; ``a``'s modulus a ``Constant``."""
    msh, V, ds, cells = beam(where)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    mat = mf.LinearElastic(E=E, nu=NU, plane="strain")
    Ec = dolfinx.fem.Constant(msh, E if E_a is None else E_a)
    mu, lmbda = Ec / (2 * (1 + NU)), Ec * NU / ((1 + NU) * (1 - 2 * NU))
    eps = ufl.sym(ufl.grad(u))
    a = (
        ufl.inner(2 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(2), ufl.sym(ufl.grad(v)))
        * ufl.dx
    )
    t = dolfinx.fem.Constant(msh, np.array(t0))
    L = ufl.inner(t, v) * ds(1)
    left = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 0.0))
    right = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 4.0))
    g = dolfinx.fem.Constant(msh, g0)
    bcs = [dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, left), V)]
    if g0:
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(0), 1, right)
        bcs.append(dolfinx.fem.dirichletbc(g, dofs, V.sub(0)))
    patch = mf.ParticlePatch(msh, cells, spacing=0.25)
    problem = mf.CoupledLinearProblem(a, L, bcs, patch, material=mat, coupling=coupling)
    return problem, Ec, t, g


@pytest.mark.parametrize("where", sorted(PATCHES))
@pytest.mark.parametrize("coupling", ["lagrange", "bridging", "ramp"])
def test_a_traction_sweep(where, coupling):
    problem, _, t, _ = linear_problem(where, coupling)
    u1 = problem.solve().displacement(POINTS)
    t.value = [0.0, -2.0]
    u2 = problem.solve().displacement(POINTS)
    assert np.abs(u2 - 2 * u1).max() < 1e-10 * np.abs(u1).max()  # was u2 = u1
    fresh = linear_problem(where, coupling, t0=(0.0, -2.0))[0].solve().displacement(POINTS)
    assert np.abs(u2 - fresh).max() < 1e-10 * np.abs(u1).max()


@pytest.mark.parametrize("where", sorted(PATCHES))
def test_a_displacement_sweep(where):
    problem, _, _, g = linear_problem(where, "lagrange", t0=(0.0, 0.0), g0=0.01)
    u1 = problem.solve().displacement(POINTS)
    g.value = 0.02
    u2 = problem.solve().displacement(POINTS)
    assert np.abs(u2 - 2 * u1).max() < 1e-10 * np.abs(u1).max()  # was u2 = u1
    assert abs(u2[0, 0] - 0.02) < 1e-10


def test_a_changed_stiffness_in_a_is_refused():
    """The particles keep the ``material`` they were given: an ``a`` that no longer matches it
    is refused at the next solve (it moved the FE side only before, 0.60 instead of 0.5 of the
    deflection)."""
    problem, Ec, _, _ = linear_problem("middle", "lagrange")
    problem.solve()
    Ec.value = 2 * E
    with pytest.raises(ValueError, match=r"since a Constant or Function of a changed.*E=2000"):
        problem.solve()


@pytest.mark.parametrize("method", ["fe", "lagrange"])
@pytest.mark.parametrize("kind", ["bc", "traction"])
def test_a_nonlinear_sweep_equals_a_fresh_solve(method, kind):
    """Two calls of ``solve`` at half and full values against a fresh problem in two load steps
    (the same sequence of states, so they agree to round-off; before, the second call repeated
    the first for a prescribed displacement, and for a dead traction on the coupled model)."""
    msh, V, ds, cells = beam("middle")
    mat = mf.NeoHookean(E=E, nu=NU, plane="strain")
    half = {"bc": 0.05, "traction": -0.5}[kind]
    g = dolfinx.fem.Constant(msh, half if kind == "bc" else 0.0)
    t = dolfinx.fem.Constant(msh, np.array([0.0, half if kind == "traction" else 0.0]))
    left = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 0.0))
    right = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 4.0))
    bcs = [
        dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, left), V),
        dolfinx.fem.dirichletbc(
            g, dolfinx.fem.locate_dofs_topological(V.sub(0), 1, right), V.sub(0)
        ),
    ]

    def problem(steps):
        u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
        F = ufl.inner(mat.ufl_first_piola(ufl.Identity(2) + ufl.grad(u)), ufl.grad(v)) * ufl.dx
        F -= ufl.inner(t, v) * ds(1)
        if method == "fe":
            return mf.FENonlinearProblem(F, u, bcs, load_steps=steps), u
        patch = mf.ParticlePatch(msh, cells, spacing=0.25)
        return mf.CoupledNonlinearProblem(F, u, bcs, patch, mat, load_steps=steps), u

    sweep, u = problem(1)
    sweep.solve()
    first = u.x.array.copy()
    g.value, t.value = 2 * g.value, 2 * t.value
    sweep.solve()
    fresh, w = problem(2)
    fresh.solve()
    scale = COMM.allreduce(np.abs(w.x.array).max(), op=MPI.MAX)
    moved = COMM.allreduce(np.abs(first - w.x.array).max(), op=MPI.MAX)
    assert moved > 0.3 * scale  # the second value moves the model
    assert COMM.allreduce(np.abs(u.x.array - w.x.array).max(), op=MPI.MAX) < 1e-10 * scale
