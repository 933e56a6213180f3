"""The two sides of a finite-strain block system, and the block problem Newton solves.

* :class:`FESide`: the FE field, residual and Jacobian of a user's UFL residual (its cell
  integrals, weighted by a cell indicator), assembled by DOLFINx;
* :class:`ParticleSide`: the particle field, ``f_int`` and ``K_T`` of a
  :class:`~dolfinx_meshfree.InternalForces` (Rabczuk et al. 2006, eq. 34) in PETSc numbering;
* :class:`BlockProblem`: ``R(x) = f_int(x) - t f_ext + C x - t c`` on a nest whose primal
  diagonal blocks are the sides' tangents and whose other blocks ``C`` (constraints) are
  constant; what :func:`~dolfinx_meshfree.newton.newton` solves.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import dolfinx
import numpy as np
import scipy.sparse as sp
import ufl
from petsc4py import PETSc
from ufl.algorithms import expand_derivatives, extract_coefficients
from ufl.classes import Sum

from . import _compat
from .constitutive import Material
from .fe_dofs import fe_dof_layout
from .forces import InternalForces
from .newton import NewtonOptions, NewtonResult, newton
from .parallel import Layout
from .particles import ParticleSet
from .petsc import SolverOptions, create_aij, create_vector

__all__ = [
    "BlockProblem",
    "FESide",
    "NonlinearSolveResult",
    "ParticleSide",
    "cell_part",
    "solve_load_steps",
    "split_residual",
    "zeros",
]


class NonlinearSolveResult(NamedTuple):
    """``(iterations, converged)`` as DOLFINx's ``NewtonSolver.solve`` returns, over all load
    steps; the per-step :class:`~dolfinx_meshfree.newton.NewtonResult` records in ``steps``."""

    iterations: int
    converged: bool
    steps: list


def zeros(comm, layout: Layout) -> PETSc.Vec:
    """A distributed zero vector of ``layout``."""
    return create_vector(comm, layout, np.zeros(0, np.int64), np.zeros(0))


# -- the two sides ------------------------------------------------------------------------------


def _terms(expr) -> list:
    """The operands of a top-level sum (the terms a user adds in a residual)."""
    if isinstance(expr, Sum):
        return [t for op in expr.ufl_operands for t in _terms(op)]
    return [expr]


def split_residual(F: ufl.Form, u: dolfinx.fem.Function) -> tuple[ufl.Form, ufl.Form | None]:
    """``F(u; v) = F_int(u; v) - L(v)``: the terms that depend on ``u`` and the dead load ``L``
    (minus the terms that do not), integral by integral and term by term of each integrand.

    Returns ``(F_int, L)``; ``L`` is ``None`` without load terms.
    """
    internal, load = [], []
    for itg in expand_derivatives(F).integrals():
        for term in _terms(itg.integrand()):
            part = itg.reconstruct(integrand=term)
            (internal if u in extract_coefficients(term) else load).append(part)
    L = ufl.Form([i.reconstruct(integrand=-i.integrand()) for i in load]) if load else None
    return ufl.Form(internal), L


def cell_part(F: ufl.Form, weight=None) -> ufl.Form:
    """The cell integrals of ``F``, each multiplied by ``weight`` if given."""
    itgs = [i for i in F.integrals() if i.integral_type() == "cell"]
    if weight is not None:
        itgs = [i.reconstruct(integrand=weight * i.integrand()) for i in itgs]
    return ufl.Form(itgs)


class FESide:
    """The FE field: internal force and tangent of the user's residual on the FE cells.

    ``fixed`` (bool per local node) are the dofs held: strong Dirichlet nodes and nodes no FE
    cell carries; their rows and columns of the tangent are the identity and their residual 0.
    """

    def __init__(self, F_int: ufl.Form, u: dolfinx.fem.Function, weight, fixed: np.ndarray):
        V = u.function_space
        self.u, self.V = u, V
        Fw = cell_part(F_int, weight)
        self._R = _compat.create_form(Fw)
        self._J = _compat.create_form(ufl.derivative(Fw, u, ufl.TrialFunction(V)))
        self.layout, l2g = fe_dof_layout(V)
        n_owned = V.dofmap.index_map.size_local
        nodes = np.flatnonzero(fixed[:n_owned])
        self.fixed_rows = (2 * l2g[nodes][:, None] + np.arange(2)).ravel().astype(PETSc.IntType)
        self.fixed_local = (2 * nodes[:, None] + np.arange(2)).ravel()
        self.n_owned = 2 * n_owned

    def set_state(self, x: PETSc.Vec) -> None:
        self.u.x.array[: self.n_owned] = x.getArray(readonly=True)
        self.u.x.scatter_forward()

    def internal_force(self, x: PETSc.Vec) -> PETSc.Vec:
        self.set_state(x)
        b = _compat.assemble_vector(self._R)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        r = zeros(x.getComm(), self.layout)
        r.array[:] = b.array_r[: self.n_owned]
        r.array[self.fixed_local] = 0.0
        b.destroy()
        return r

    def tangent(self, x: PETSc.Vec) -> PETSc.Mat:
        self.set_state(x)
        J = _compat.assemble_matrix(self._J)
        J.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        diag = J.createVecLeft()
        diag.set(0.0)
        J.setDiagonal(diag, addv=PETSc.InsertMode.ADD_VALUES)  # room on empty rows
        diag.destroy()
        J.zeroRowsColumns(self.fixed_rows, diag=1.0)
        return J


class ParticleSide:
    """The particle field: ``f_int`` and ``K_T`` on the patch quadrature, in PETSc numbering."""

    def __init__(self, particles: ParticleSet, tables: dict, material: Material):
        q, tq = tables["quadrature"], tables["table"]
        self.P, self.comm = particles, particles.comm
        self.forces = InternalForces(
            tq, q.weights, material, test_gradients=tables["test_gradients"], comm=particles.comm
        )
        self.dof_map = particles.petsc_dofs(2).ravel()
        self.layout = particles.dof_layout()

    def coefficients(self, x: PETSc.Vec) -> np.ndarray:
        """All particle coefficients, interleaved in original order, on every rank."""
        owned = np.concatenate(self.comm.allgather(x.getArray(readonly=True)))
        return owned.reshape(-1, 2)[self.P.petsc_index].ravel()

    def internal_force(self, x: PETSc.Vec) -> PETSc.Vec:
        f = self.forces.internal_force(self.coefficients(x))
        return create_vector(self.comm, self.layout, self.dof_map, f)

    def tangent(self, x: PETSc.Vec) -> PETSc.Mat:
        K = self.forces.tangent(self.coefficients(x)).tocoo()
        n = self.dof_map.size
        Kg = sp.csr_matrix((K.data, (self.dof_map[K.row], self.dof_map[K.col])), shape=(n, n))
        return create_aij(self.comm, Kg, self.layout, self.layout)


# -- the block problem --------------------------------------------------------------------------


@dataclass
class BlockProblem:
    """``R(x) = f_int(x) - t f_ext + C x - t c`` on a nest whose first fields have nonlinear
    diagonal blocks (``sides``) and whose other blocks ``C`` are constant (constraints)."""

    names: list[str]
    num_primal: int
    sides: list  # one FESide / ParticleSide per primal field
    constant: list[list[PETSc.Mat | None]]  # the C blocks (primal diagonal blocks: None)
    loads: list[PETSc.Vec]  # f_ext per primal field, c per constraint field
    t: float = 1.0
    _owned: list = field(default_factory=list)

    def residual(self, x: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        out = []
        for i, row in enumerate(self.constant):
            r = self.sides[i].internal_force(x[i]) if i < self.num_primal else self.loads[i].copy()
            if i < self.num_primal:
                r.axpy(-self.t, self.loads[i])
            else:
                r.scale(-self.t)
            for j, C in enumerate(row):
                if C is not None:
                    C.multAdd(x[j], r, r)
            if i < self.num_primal and isinstance(self.sides[i], FESide):
                r.array[self.sides[i].fixed_local] = 0.0
            out.append(r)
        return out

    def jacobian(self, x: Sequence[PETSc.Vec]) -> list[list[PETSc.Mat | None]]:
        for M in self._owned:
            M.destroy()
        self._owned = [self.sides[i].tangent(x[i]) for i in range(self.num_primal)]
        blocks = [list(row) for row in self.constant]
        for i, K in enumerate(self._owned):
            blocks[i][i] = K
        return blocks

    def destroy(self) -> None:
        for M in self._owned:
            M.destroy()
        self._owned = []


def solve_load_steps(
    problem: BlockProblem,
    x: list[PETSc.Vec],
    load_steps: int,
    options: NewtonOptions,
    solver: SolverOptions,
    before_step=None,
) -> NonlinearSolveResult:
    steps: list[NewtonResult] = []
    for k in range(1, load_steps + 1):
        problem.t = k / load_steps
        if before_step is not None:
            before_step(problem.t, x)
        steps.append(newton(problem, x, options, solver))
    return NonlinearSolveResult(sum(s.iterations for s in steps), True, steps)
