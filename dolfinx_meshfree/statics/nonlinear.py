"""Finite-deformation statics: FE, EFG and coupled models solved by Newton (total Lagrangian).

Rabczuk, Xiao & Sauer 2006 write the particle method in the reference configuration: the
momentum balance ``div_0 P + b_0 = 0`` (eq. 1) with the nominal stress ``P(F)`` (eq. 2–5), weak
form eq. 34. Every block of the linear systems keeps its place; only the stiffness blocks become
functions of the state:

* FE side: the residual ``R_FE(u) = int chi (F(u; v) - F(0; v)) dx`` of the user's own UFL
  residual ``F`` (its cell integrals, weighted by the indicator ``chi`` of the FE cells as the
  linear problems weight ``a``), minus the FE share of the external load; Jacobian
  ``dF/du`` by UFL's ``derivative``;
* particle side: ``f_int(u) = sum_q B0(F_q)^T P(F_q) w_q`` and its consistent tangent on the
  patch quadrature (:class:`~dolfinx_meshfree.InternalForces`), with the test gradients of the
  linear stiffness (VCI when consistent, so a homogeneous deformation is reproduced exactly);
* blended cells (the ramps' interface elements, Belytschko et al. 1995, eq. 3.12-3.16): the
  same ``f_int`` and tangent on the blended table, whose columns are the FE nodes and the
  particles, so they add to both fields' rows and fill the FE-particle blocks
  (:class:`~dolfinx_meshfree.statics.sides.BlendedSide`); a coupling's ``system`` supplies
  such sides over several fields (``extra["shared_sides"]``) and names the linear blocks they
  replace (``extra["state_blocks"]``);
* master-slave's rigid links turn with their interface edge: constraints nonlinear in the FE
  displacements, with multipliers
  (:class:`~dolfinx_meshfree.couplings.master_slave_finite.RotatingLinks`);
* the other constraints (interface multipliers, patch Dirichlet multipliers) stay linear in
  the displacements and are the linear system's blocks.

The external load is dead: ``L_ext(v) = -F(0; v)`` (with ``P(I) = 0`` for every law here), split
between FE and particles exactly as :class:`~dolfinx_meshfree.CoupledLinearProblem` splits
``L``. Facet integrals of ``u`` (a follower pressure ``p J inner(inv(F).T N, v) ds``, an elastic
support) belong to the FE residual and its Jacobian, on the FE cells' exterior facets only
(:mod:`~dolfinx_meshfree.statics.facet_terms`: refused on a patch cell's facet); pure FE
(:class:`FENonlinearProblem`) takes every integral of the residual. Load steps take the
external load and the prescribed displacements in ``n`` equal steps from those the last solve
reached (:mod:`~dolfinx_meshfree.statics.history`); a follower load's factor is the user's (a
``Constant`` changed between calls of ``solve``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import dolfinx
import numpy as np
import ufl
from petsc4py import PETSc
from ufl.algorithms import expand_derivatives

from .. import _compat
from ..couplings.base import fe_dof_layout
from ..geometry.patch import ParticlePatch
from ..parallel import raise_on_all_ranks
from ..physics.constitutive import Material, NeoHookean, SaintVenantKirchhoff
from ..physics.materials import LinearElastic, linear_twin
from ..physics.state import check_stateless
from .coupled import CoupledElasticity, CoupledSolution
from .coupled_newton import FINITE_STRAIN_COUPLINGS, check_load_steps, solve_finite_strain
from .facet_terms import FacetTermCheck
from .history import SolveHistory
from .newton import NewtonOptions
from .petsc import solver_options
from .problem import CoupledLinearProblem
from .sides import (
    BlockProblem,
    FESide,
    NonlinearSolveResult,
    cell_part,
    solve_load_steps,
    split_residual,
    zeros,
)

__all__ = [
    "FINITE_STRAIN_COUPLINGS",
    "CoupledNonlinearProblem",
    "FENonlinearProblem",
]


def _check_residual(F: ufl.Form, u: dolfinx.fem.Function) -> dolfinx.fem.FunctionSpace:
    if not isinstance(F, ufl.Form):
        raise TypeError(f"F must be a UFL form (the residual F(u; v)), got {type(F).__name__}")
    if not isinstance(u, dolfinx.fem.Function):
        raise TypeError(f"u must be a dolfinx.fem.Function (the unknown), got {type(u).__name__}")
    if len(F.arguments()) != 1:
        raise ValueError(
            f"F must be linear in one test function (a residual F(u; v)); it has "
            f"{len(F.arguments())} arguments"
        )
    if u not in F.coefficients():
        raise ValueError("F does not depend on u: pass the Function the residual is written in")
    return F.arguments()[0].ufl_function_space()


#: Relative difference above which the residual and the particles' law disagree at finite strain.
LAW_TOLERANCE = 1e-8

#: Homogeneous deformation gradients the residual is compared at (a stretch with shear, a
#: compression with shear), 2D and 3D.
PROBES = {
    2: (np.array([[1.15, 0.1], [0.05, 0.92]]), np.array([[0.9, -0.08], [0.1, 1.08]])),
    3: (
        np.array([[1.15, 0.1, 0.04], [0.05, 0.92, 0.08], [0.02, 0.06, 1.1]]),
        np.array([[0.9, -0.08, 0.05], [0.1, 1.08, -0.04], [0.03, 0.07, 0.95]]),
    ),
}


def check_law_at_finite_strain(
    F_int: ufl.Form, u: dolfinx.fem.Function, model: CoupledElasticity, material: Material
) -> None:
    """Refuse a residual whose law on the patch cells is not the particles' ``material`` at
    finite strain (collective).

    The linear problem checks the linearisation only, which Saint Venant-Kirchhoff and
    neo-Hookean share: a user's residual of one with the other as ``material`` ran with two
    laws, silently. Here ``F_int`` (the cell integrals, weighted by the patch cells' indicator)
    is assembled at the homogeneous deformations :data:`PROBES` and compared with
    ``int P(F) : grad(v)`` of ``material.first_piola``; above :data:`LAW_TOLERANCE` (the
    relative difference of the two vectors) it raises, naming the law the residual encodes when
    it is one of the others with the same constants.
    """
    V = u.function_space
    msh = V.mesh
    d = msh.geometry.dim
    v = F_int.arguments()[0]
    chi = model.cell_indicator(model.patch.in_patch)
    w = dolfinx.fem.Function(V)
    P0 = dolfinx.fem.Constant(msh, np.zeros((d, d)))
    # P(F) is constant on each cell, so degree 2 integrates both exactly (the user's degree
    # may be the one of a law unrolled in UFL, e.g. plane-stress neo-Hookean: millions of points)
    degree = {"quadrature_degree": 2}
    cells = cell_part(ufl.replace(F_int, {u: w}), chi).integrals()
    user = _compat.create_form(
        ufl.Form([i.reconstruct(metadata={**i.metadata(), **degree}) for i in cells])
    )
    reference = _compat.create_form(chi * ufl.inner(P0, ufl.grad(v)) * ufl.dx(metadata=degree))

    def assemble(form: Any) -> PETSc.Vec:
        b = _compat.assemble_vector(form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return b

    def difference(law: Material, G: np.ndarray) -> float:
        P0.value[:] = law.first_piola(G[None])[0]
        b, r = assemble(user), assemble(reference)
        scale = r.norm()
        r.axpy(-1.0, b)
        out = r.norm() / max(scale, 1e-300)
        b.destroy()
        r.destroy()
        return out

    worst, at = 0.0, None
    for G in PROBES[d]:
        w.interpolate(lambda x, G=G: (G - np.eye(d)) @ x[:d])
        rel = difference(material, G)
        if rel > worst:
            worst, at = rel, G
    if worst <= LAW_TOLERANCE:
        return
    hint = ""
    w.interpolate(lambda x: (at - np.eye(d)) @ x[:d])
    for other in _other_laws(material):
        if difference(other, at) <= LAW_TOLERANCE:
            hint = f"; F matches {other}: pass it as material"
            break
    raise ValueError(
        f"F on the patch cells disagrees with material={material} at finite strain (relative "
        f"difference {worst:.3g} > {LAW_TOLERANCE:g} at the homogeneous deformation gradient "
        f"{at.tolist()}){hint}. The particles use the material, so pass the law that F encodes "
        "there (a Material of your own, with first_piola and tangent, if it is none of "
        "NeoHookean, SaintVenantKirchhoff, LinearElastic)"
    )


def _other_laws(material: Material) -> list[Material]:
    """The other hyperelastic laws of this release with ``material``'s constants."""
    from_constants = (NeoHookean, SaintVenantKirchhoff, LinearElastic)
    E, nu = getattr(material, "E", None), getattr(material, "nu", None)
    if E is None or nu is None:
        return []
    plane = getattr(material, "plane", None)
    return [cls(E=E, nu=nu, plane=plane) for cls in from_constants if type(material) is not cls]


# -- pure FE ------------------------------------------------------------------------------------


class FENonlinearProblem:
    """A user's nonlinear FE model ``F(u; v) = 0`` with ``bcs``, by the same Newton as the coupled
    problems (the FE reference of the finite-strain demos, in both DOLFINx lanes).

    Args:
        F: Residual, linear in the test function, written in ``u``; every integral is
            assembled, facet integrals of ``u`` (follower loads, elastic supports) too.
        u: The unknown (updated in place by :meth:`solve`; its values are the initial guess).
        bcs: ``DirichletBC`` objects (their values are reached in ``load_steps`` steps).
        load_steps: External (dead, ``u``-free) load and prescribed values in ``load_steps``
            equal steps from those the last :meth:`solve` reached (zero at first, and after
            :meth:`reset`) to the current ones; terms of ``u`` are not scaled (ramp a follower
            load's ``Constant`` between calls of :meth:`solve`).
        newton: :class:`~dolfinx_meshfree.statics.newton.NewtonOptions`.
        petsc_options, petsc_options_prefix: The linear solver (default MUMPS LU).
    """

    def __init__(
        self,
        F: ufl.Form,
        u: dolfinx.fem.Function,
        bcs: Sequence = (),
        load_steps: int = 1,
        newton: NewtonOptions | None = None,
        petsc_options: Mapping[str, Any] | None = None,
        petsc_options_prefix: str | None = None,
    ):
        comm = u.function_space.mesh.comm
        V = raise_on_all_ranks(comm, lambda: _check_residual(F, u))
        raise_on_all_ranks(comm, lambda: check_load_steps(load_steps))
        self._solver = raise_on_all_ranks(
            comm, lambda: solver_options("mumps", petsc_options, petsc_options_prefix)
        )
        self.F, self.u, self.bcs, self.V = F, u, list(bcs), V
        self.load_steps, self.newton = int(load_steps), newton or NewtonOptions()
        n_local = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
        F_int, L = split_residual(F, u)  # F_int: facet terms of u (follower loads) too
        self.side = FESide(F_int, u, None, np.zeros(n_local, dtype=bool))
        self._hold_bcs()
        v = F.arguments()[0]
        zero = dolfinx.fem.Constant(V.mesh, np.zeros(V.mesh.geometry.dim))
        self._load = _compat.create_form(L if L is not None else ufl.inner(zero, v) * ufl.dx)
        # the loads and held values the last solve reached (Newton starts from u)
        self._history = SolveHistory("FENonlinearProblem", fields=False)

    def reset(self) -> None:
        """The next :meth:`solve` steps its loads and prescribed values from zero again (from
        the current ``u``)."""
        self._history.clear()

    def _hold_bcs(self) -> None:
        """Hold the ``bcs``' owned dofs (by component: a bc may fix one component of a node) at
        their current values."""
        V = self.V
        bs = V.dofmap.index_map_bs
        n_local = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
        count = np.zeros(bs * n_local, dtype=int)
        values = np.zeros(bs * n_local)
        for bc in self.bcs:
            dofs, vals = _compat.dirichlet_values(bc)
            count[dofs] += 1
            values[dofs] = vals
        held = np.flatnonzero(count)
        d = held[held < bs * V.dofmap.index_map.size_local]
        self.side.hold(d, values[d], fe_dof_layout(V)[1])

    def solve(self) -> NonlinearSolveResult:
        """Newton over the load steps (collective); raises
        :class:`~dolfinx_meshfree.statics.newton.NewtonError` if a step does not converge. The
        ``bcs``' values are read afresh (a displacement sweep), as are the residual's
        ``Constant`` and ``Function`` objects."""
        self._hold_bcs()
        u = self.u
        b = _compat.assemble_vector(self._load)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        f = zeros(b.getComm(), self.side.layout)
        f.array[:] = b.array_r[: self.side.n_owned]
        b.destroy()
        x = zeros(f.getComm(), self.side.layout)
        x.array[:] = u.x.array[: self.side.n_owned]
        problem = BlockProblem(["fe"], 1, [self.side], [[None]], [f])

        try:  # from u, the load steps from the last solve's loads and values to the current
            result = solve_load_steps(
                problem, [x], self.load_steps, self.newton, self._solver, self._history
            )
        finally:
            problem.destroy()
        self.side.set_state(x)
        for obj in (f, x):
            obj.destroy()
        self.result = result
        return result


# -- coupled ------------------------------------------------------------------------------------


class CoupledNonlinearProblem:
    """``F(u; v) = 0`` with ``bcs`` on a mesh whose ``patch`` cells are particles, at finite
    strain (total Lagrangian), shaped like DOLFINx's ``NonlinearProblem`` + ``NewtonSolver``.

    Args:
        F: The user's residual on the vector P1/Q1 space of ``u``, linear in its test function:
            e.g. ``inner(P(F(u)), grad(v)) dx - inner(t, v) ds(k) - inner(b, v) dx``. Its cell
            integrals are the FE side (weighted by the FE cells' indicator); its ``u``-free part
            is the dead external load ``-F(0; v)``, split between the FE and particle sides;
            its ``ds`` terms of ``u`` (a follower pressure, an elastic support) are the FE
            side's, on FE cells' facets only (refused on a patch cell's facet).
        u: The FE unknown (updated in place; the FE part of the solution).
        bcs: ``DirichletBC`` objects on ``V`` or on ``V.sub(i)`` (one component: a symmetry
            plane or roller, as :class:`~dolfinx_meshfree.CoupledLinearProblem`).
        patch: :class:`~dolfinx_meshfree.ParticlePatch` on ``u``'s mesh.
        material: The particle side's law (:class:`~dolfinx_meshfree.NeoHookean`,
            :class:`~dolfinx_meshfree.SaintVenantKirchhoff` or
            :class:`~dolfinx_meshfree.LinearElastic`): ``F`` on the patch must be this law,
            which is checked on its linearisation and at two finite deformations
            (:func:`check_law_at_finite_strain`).
        coupling: One of :data:`FINITE_STRAIN_COUPLINGS`.
        load_steps: The dead external load and prescribed values in ``load_steps`` equal
            steps from those the last :meth:`solve` reached (zero at first, and after
            :meth:`reset`) to the current ones: change a ``Constant`` in ``F`` between calls
            (a load sweep; the way to ramp a follower load, which is not scaled), and each call
            continues from the last solution.
        newton: :class:`~dolfinx_meshfree.statics.newton.NewtonOptions`.
        petsc_options, petsc_options_prefix: The linear solver of each Newton iteration.
        **options: Passed to :class:`~dolfinx_meshfree.CoupledElasticity`.
    """

    def __init__(
        self,
        F: ufl.Form,
        u: dolfinx.fem.Function,
        bcs: Sequence | None,
        patch: ParticlePatch,
        material: Material,
        coupling: str = "lagrange",
        load_steps: int = 1,
        newton: NewtonOptions | None = None,
        petsc_options: Mapping[str, Any] | None = None,
        petsc_options_prefix: str | None = None,
        **options,
    ):
        comm = patch.comm if isinstance(patch, ParticlePatch) else u.function_space.mesh.comm

        def check() -> LinearElastic:
            _check_residual(F, u)
            check_load_steps(load_steps)
            if coupling not in FINITE_STRAIN_COUPLINGS:
                raise ValueError(
                    f"coupling={coupling!r} is not available at finite strain in this release "
                    f"(its family has no finite-strain system); use one of "
                    f"{list(FINITE_STRAIN_COUPLINGS)}"
                )
            check_stateless(
                material,
                "CoupledNonlinearProblem (the FE side is the user's UFL residual)",
            )
            if not isinstance(material, Material):
                raise TypeError(
                    f"material must follow the Material protocol, got {type(material).__name__}"
                )
            return linear_twin(material)

        small = raise_on_all_ranks(comm, check)
        V = u.function_space
        du = ufl.TrialFunction(V)
        zero = dolfinx.fem.Function(V)
        zero.x.array[:] = 0.0
        F_int, L0 = split_residual(F, u)
        # the facet terms of u (follower pressures, elastic supports): on FE facets only
        raise_on_all_ranks(comm, FacetTermCheck(F_int, patch, coupling, "F").check)
        a0 = ufl.replace(
            expand_derivatives(ufl.derivative(cell_part(F_int, facets=True), u, du)), {u: zero}
        )
        if L0 is None:
            L0 = (
                ufl.inner(
                    dolfinx.fem.Constant(V.mesh, np.zeros(V.mesh.geometry.dim)), F.arguments()[0]
                )
                * ufl.dx
            )
        self._linear = CoupledLinearProblem(
            a0, L0, bcs, patch, small, coupling, petsc_options, petsc_options_prefix, **options
        )
        check_law_at_finite_strain(F_int, u, self._linear.problem, material)
        self.F, self.F_int, self.u = F, F_int, u
        self.patch, self.material = patch, material
        self.V, self.bcs = V, self._linear.bcs  # what reaction() reads
        self.coupling = coupling
        self.load_steps, self.newton = int(load_steps), newton or NewtonOptions()
        self._solver = self._linear._solver
        self.solution: CoupledSolution | None = None
        self._state: list[np.ndarray] | None = None

    @property
    def model(self) -> CoupledElasticity:
        """The coupled model (space, patch, MLS, loads, essential conditions)."""
        return self._linear.problem

    def reset(self) -> None:
        """The next :meth:`solve` steps its loads and prescribed values from zero again (from
        the last solution)."""
        self.model.reset()

    def solve(self) -> NonlinearSolveResult:
        """Newton over the load steps (collective); returns ``(iterations, converged, steps)``
        and leaves the solution in ``u`` and :attr:`solution`. Raises
        :class:`~dolfinx_meshfree.statics.newton.NewtonError` (with the residual history) when a
        step
        does not converge: the last iterate is not returned as a solution. The ``bcs``' values
        and the dead load's ``Constant`` and ``Function`` objects are read afresh at each call."""
        self._linear._refresh()
        out = solve_finite_strain(
            self.model, self.F_int, self.u, self.material, self.load_steps, self.newton,
            self._solver, self._state, self.model.history,
        )  # fmt: skip
        self.solution, self._state = out.solution, out.state
        self.solution.newton = out.result
        self.result = out.result
        return out.result
