"""Reference finite-element elastostatics through DOLFINx (plane stress and plane strain).

The stiffness and the loads are ordinary DOLFINx forms; the solve uses the same MUMPS route as the
meshfree solvers (:func:`~dolfinx_meshfree.statics.petsc.solve_lu`) so that costs compare fairly.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import dolfinx
import numpy as np
import numpy.typing as npt
import ufl

from .. import _compat
from ..approx.fe_points import evaluate_fe_function
from ..physics.materials import LinearElastic
from .petsc import solve_lu

__all__ = ["FESolution", "solve_fe_elasticity", "solve_forms"]


@dataclass
class FESolution:
    """Displacement Function and timings (``setup`` includes JIT compilation); of a law with
    state (:class:`~dolfinx_meshfree.FEElasticity`), the committed ``states`` of its points
    (:class:`~dolfinx_meshfree.physics.state.PointState`) and Newton's record ``newton``."""

    u: dolfinx.fem.Function
    timings: dict = field(default_factory=dict)
    states: list = field(default_factory=list)
    newton: Any = None

    def displacement(self, points: npt.ArrayLike) -> np.ndarray:
        """``u`` at any points of the mesh, (m, gdim) for this rank's ``points`` (collective)."""
        return evaluate_fe_function(self.u, points)

    @property
    def num_dofs(self) -> int:
        imap = self.u.function_space.dofmap.index_map
        return imap.size_global * self.u.function_space.dofmap.index_map_bs


def solve_fe_elasticity(
    V: dolfinx.fem.FunctionSpace,
    material: LinearElastic,
    dirichlet: Sequence[tuple[np.ndarray, Callable]] = (),
    tractions: Sequence[tuple[np.ndarray, Callable]] = (),
) -> FESolution:
    """Solve ``-div sigma(u) = 0`` with Dirichlet and traction conditions on facets.

    Args:
        V: Vector Lagrange space.
        dirichlet: ``(facets, g)`` pairs; ``g(x)`` takes DOLFINx-style coordinates (3, m) and
            returns (2, m) values, interpolated into ``V`` on the facets' dofs.
        tractions: ``(facets, t)`` pairs; ``t(x)`` takes ``ufl.SpatialCoordinate`` and returns a
            UFL vector, integrated exactly by the form compiler.
    """
    t0 = time.perf_counter()
    msh = V.mesh
    fdim = msh.topology.dim - 1
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(material.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    x = ufl.SpatialCoordinate(msh)
    if tractions:
        facets = np.concatenate([np.asarray(f, dtype=np.int32) for f, _ in tractions])
        tags = np.concatenate(
            [np.full(len(f), k + 1, dtype=np.int32) for k, (f, _) in enumerate(tractions)]
        )
        order = np.argsort(facets)
        mt = dolfinx.mesh.meshtags(msh, fdim, facets[order], tags[order])
        ds = ufl.Measure("ds", domain=msh, subdomain_data=mt)
        L = sum(ufl.dot(t(x), v) * ds(k + 1) for k, (_, t) in enumerate(tractions))
    else:
        zero = dolfinx.fem.Constant(msh, np.zeros(2))
        L = ufl.dot(zero, v) * ufl.dx
    bcs = []
    for facets, g in dirichlet:
        ug = dolfinx.fem.Function(V)
        ug.interpolate(g)
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, np.asarray(facets, dtype=np.int32))
        bcs.append(dolfinx.fem.dirichletbc(ug, dofs))
    solution = solve_forms(a, L, bcs)
    solution.timings["setup"] += time.perf_counter() - t0
    return solution


def solve_forms(a: ufl.Form, L: ufl.Form, bcs: Sequence = ()) -> FESolution:
    """A linear model solved as written for DOLFINx: ``a`` and ``L`` (UFL forms on one space),
    ``DirichletBC`` objects lifted into the right-hand side, and the MUMPS LU of
    :func:`~dolfinx_meshfree.statics.petsc.solve_lu` (collective). The reference that the coupled
    runs
    are measured against."""
    from petsc4py import PETSc

    t0 = time.perf_counter()
    a_form, L_form = _compat.create_form(a), _compat.create_form(L)
    setup = time.perf_counter() - t0

    t1 = time.perf_counter()
    A = _compat.assemble_matrix(a_form, bcs)
    b = _compat.assemble_vector(L_form)
    _compat.apply_lifting(b, a_form, bcs)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    _compat.set_bc(b, bcs)
    assemble = time.perf_counter() - t1

    t2 = time.perf_counter()
    x_vec = solve_lu(A, b)
    solve = time.perf_counter() - t2
    V = a.arguments()[0].ufl_function_space()
    uh = dolfinx.fem.Function(V)
    n_owned = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
    uh.x.array[:n_owned] = x_vec.getArray(readonly=True)
    uh.x.scatter_forward()
    for obj in (A, b, x_vec):
        obj.destroy()
    return FESolution(uh, {"setup": setup, "assemble": assemble, "solve": solve})
