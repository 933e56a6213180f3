"""Body loads of every coupling: each discretisation's share, weighted like its energy.

A body force ``b`` (per unit volume) enters the virtual work ``int b . v`` with the same shape
functions and weights as the stiffness of each coupling:

* FE cells: ``int beta_FE N_a b`` with the coupling's FE weight ``beta_FE``: the DG0 indicator
  of the FE cells (Belytschko et al. 1995, eq. 4.3), and in a bridging band ``1 - alpha``
  (Rabczuk et al. 2006, eq. 47-49);
* patch cells: ``int beta_P phi_J b`` with ``beta_P = 1``, ``alpha`` in a bridging band (eq. 49);
* ramp interface cells: ``int ((1 - R) N_a + R phi_J) b``, the blended functions of eq. 3.15
  (Belytschko et al. 1995; Rabczuk et al. 2006, eq. 38-42), the FE part on the FE nodes and the
  particle part (and the ``(1 - R) N_a`` of the interface nodes, which are particles) on the
  particles.

A load may also hold a stress ``S`` against the test gradients, ``int S : grad(v)`` (a thermal,
initial or residual stress: the cell integrals of a user's ``L`` with ``grad(v)``,
:mod:`~dolfinx_meshfree.statics.form_loads`). Each side integrates it with the test gradients and
the rule of its own stiffness, given as a :class:`StressRule`: the FE cells by DOLFINx (the
weighted integrand), the particles with the gradients of their stiffness (VCI-corrected,
smoothed, one-sided at a crack; weights ``alpha w_q`` in a bridging band), the ramps' interface
cells with the blended gradients ``grad((1 - R) N_a + R phi_J)`` (Belytschko et al. 1995, eq.
3.16). A constant ``S = C : eps_0`` is then balanced by the displacement ``eps_0 x`` exactly,
as the linear patch test is.

A body force is a :class:`BodyForce`: a callable ``b(x)`` (:class:`CallableBodyForce`, what
:meth:`CoupledElasticity.set_body_force <dolfinx_meshfree.CoupledElasticity.set_body_force>`
and :meth:`ExplicitDynamics.add_body_force
<dolfinx_meshfree.dynamics.ExplicitDynamics.add_body_force>` take), or the cell integrals of a
UFL linear form (:class:`~dolfinx_meshfree.statics.problem.FormBodyForce`).
:func:`body_load_vectors`
assembles the shares of a list of them from the quadrature rules of a coupling.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import dolfinx
import numpy as np
import scipy.sparse as sp

from .. import _compat
from ..approx.fe_points import tabulate_in_cells
from ..geometry.quadrature import QuadraturePoints, cell_quadrature
from ..parallel import raise_on_all_ranks
from .operators import load_vector
from .user_functions import vector_values

if TYPE_CHECKING:  # annotations only
    import ufl
    from mpi4py import MPI

__all__ = ["BodyForce", "CallableBodyForce", "StressRule", "body_load_vectors", "stress_load"]

VectorFunction = Callable[[np.ndarray], np.ndarray]


class BodyForce:
    """A body force per unit volume: its FE load and its values at quadrature points.

    Subclasses implement :meth:`fe_load` (collective) and :meth:`values` (local); a load with a
    stress part sets :attr:`has_stress` and implements :meth:`stresses` too.
    """

    #: Whether the load holds a stress ``S : grad(v)`` (:meth:`stresses`).
    has_stress: bool = False

    def stresses(self, q: QuadraturePoints) -> np.ndarray:
        """``S`` (len(q), gdim, gdim) at any points ``q`` in their cells. Local."""
        raise NotImplementedError

    def at_points(self, x: np.ndarray, V: dolfinx.fem.FunctionSpace | None) -> np.ndarray:
        """``b`` (m, gdim) at any points ``x`` (m, gdim) of the body, the same ``x`` on every rank
        (collective; ``V``: the FE space of the model, ``None`` in pure EFG)."""
        raise NotImplementedError

    def fe_load(
        self, V: dolfinx.fem.FunctionSpace, weight: ufl.core.expr.Expr | None, degree: int
    ) -> np.ndarray:
        """``int weight N_a b`` per owned dof of the vector space ``V`` (ghost contributions
        accumulated), shape (gdim num_owned_nodes,); ``weight``: a scalar UFL expression or
        ``None`` (1 on every cell). Collective."""
        raise NotImplementedError

    def values(self, q: QuadraturePoints) -> np.ndarray:
        """``b`` (len(q), gdim) at the points of a cell rule of :func:`cell_quadrature`. Local."""
        raise NotImplementedError


class CallableBodyForce(BodyForce):
    """``b(x)``: a callable mapping points (m, gdim) to forces per unit volume (m, gdim)."""

    def __init__(self, force: VectorFunction) -> None:
        if not callable(force):
            raise TypeError(
                f"the body force must be a callable b(x) mapping points (m, 2) to (m, 2), got "
                f"{type(force).__name__}"
            )
        self.force = force

    def values(self, q: QuadraturePoints) -> np.ndarray:
        return vector_values(self.force, (q.points,), len(q), "the body force", q.points.shape[1])

    def at_points(self, x: np.ndarray, V: dolfinx.fem.FunctionSpace | None) -> np.ndarray:
        return vector_values(self.force, (x,), len(x), "the body force", x.shape[1])

    def fe_load(
        self, V: dolfinx.fem.FunctionSpace, weight: ufl.core.expr.Expr | None, degree: int
    ) -> np.ndarray:
        msh = V.mesh
        q = cell_quadrature(msh, degree)
        w = q.weights
        if weight is not None:
            X, _ = _compat.quadrature_rule(msh.topology.cell_type.name, degree)
            expr = _compat.create_expression(weight, X, msh)  # collective
            n_owned = msh.topology.index_map(msh.topology.dim).size_local
            cells = np.arange(n_owned, dtype=np.int32)
            w = w * _compat.eval_expression(expr, msh, cells, 1).ravel()
        on = np.flatnonzero(w != 0.0)
        q = QuadraturePoints(q.points[on], w[on], q.cells[on])
        b = raise_on_all_ranks(msh.comm, lambda: self.values(q))
        tab = tabulate_in_cells(V, q.points, q.cells, derivatives=0).values
        return accumulate(V, load_vector(tab, q.weights, b))


def accumulate(V: dolfinx.fem.FunctionSpace, local: np.ndarray) -> np.ndarray:
    """Owned dof values (gdim num_owned,) of local contributions (gdim num_local,) to the nodes of
    ``V``, owned and ghost, summed over the ranks that hold each node (collective)."""
    f = dolfinx.fem.Function(V)
    f.x.array[:] = 0.0
    f.x.array[: local.size] = local
    _compat.scatter_reverse_add(f)
    return f.x.array[: V.dofmap.index_map_bs * V.dofmap.index_map.size_local].copy()


@dataclass
class StressRule:
    """Where a stiffness integrates: its points (their cells), weights and test gradients (a
    list of gdim CSR (m x n), columns those of the load vector's nodes)."""

    quadrature: QuadraturePoints
    weights: np.ndarray
    gradients: list[sp.csr_matrix]


def stress_load(force: BodyForce, rule: StressRule, comm: MPI.Comm) -> np.ndarray:
    """``f_Ji = sum_q w_q S_ij(x_q) G_j[q, J]``: the load of ``force``'s stress on the nodes of
    ``rule``'s test gradients ``G``, interleaved (gdim n,) (this rank's points; collective
    for the errors)."""
    S = raise_on_all_ranks(comm, lambda: force.stresses(rule.quadrature))
    d = S.shape[1]
    n = rule.gradients[0].shape[1]
    f = np.zeros((n, d))
    for i in range(d):
        for j in range(d):
            f[:, i] += rule.gradients[j].T @ (rule.weights * S[:, i, j])
    return f.ravel()


def body_load_vectors(
    forces: list[BodyForce],
    V: dolfinx.fem.FunctionSpace | None,
    fe_weight: ufl.core.expr.Expr | None,
    degree: int,
    particle_rule: tuple[QuadraturePoints, sp.csr_matrix] | None = None,
    interface_rule: tuple[QuadraturePoints, sp.csr_matrix] | None = None,
    comm: MPI.Comm | None = None,
    particle_stress: StressRule | None = None,
    interface_stress: StressRule | None = None,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The FE and particle shares of body forces (module docstring). Collective.

    Args:
        forces: The :class:`BodyForce` objects (their loads are summed).
        V: The vector P1/Q1 space of the FE side, or ``None`` (pure EFG).
        fe_weight: Scalar UFL weight of the FE energy (``CouplingOperators.fe_weight``), or
            ``None``: 1 on every cell.
        degree: Quadrature degree of the FE cells' rule (callable forces).
        particle_rule: ``(q, table)``: the particles' quadrature with its weights (times
            ``alpha`` in a bridging band) and the MLS values there, (len(q) x n) CSR with
            columns in original particle order; ``None`` without particles.
        interface_rule: Ramp couplings: ``(q, table)``, the interface cells' rule and the blended
            functions there (:meth:`~dolfinx_meshfree.couplings.ramp.RampInterface.table`, columns
            ``[local FE nodes | particles]``).
        comm: The communicator (default: ``V``'s mesh's).
        particle_stress, interface_stress: The rules of the particle and interface stiffness
            (:class:`StressRule`, columns as ``particle_rule``'s and ``interface_rule``'s
            tables), for forces with a stress part; a force with one is refused without them.

    Returns:
        ``(fe, particles)``: the FE loads per owned dof of ``V`` (``None`` without ``V``) and
        this rank's particle loads ``(gdim n,)`` interleaved in original particle order
        (``None`` without particles; the ranks' contributions add up).
    """
    comm = V.mesh.comm if comm is None else comm
    fe = None if V is None else np.zeros(V.dofmap.index_map_bs * V.dofmap.index_map.size_local)
    f_p = None
    if particle_rule is not None:
        gdim = particle_rule[0].points.shape[1]
        f_p = np.zeros(particle_rule[1].shape[1] * gdim)
    missing = (particle_rule is not None and particle_stress is None) or (
        interface_rule is not None and interface_stress is None
    )
    for force in forces:
        if force.has_stress and missing:
            raise ValueError(
                "a load with a stress S : grad(v) (from a dx integral of L) reached a "
                "discretisation that cannot integrate it with its stiffness's test gradients; "
                "only the static couplings of CoupledLinearProblem and CoupledNonlinearProblem "
                "take one"
            )
        if V is not None:
            fe += force.fe_load(V, fe_weight, degree)
        if force.has_stress and particle_rule is not None:
            f_p += stress_load(force, particle_stress, comm)
        if force.has_stress and interface_rule is not None:
            fl = stress_load(force, interface_stress, comm)
            nf = fl.size - f_p.size
            fe += accumulate(V, fl[:nf])
            f_p += fl[nf:]
        if particle_rule is not None:
            q, table = particle_rule
            b = raise_on_all_ranks(comm, lambda f=force, q=q: f.values(q))
            f_p += load_vector(table, q.weights, b)
        if interface_rule is not None:
            q, table = interface_rule
            b = raise_on_all_ranks(comm, lambda f=force, q=q: f.values(q))
            fl = load_vector(table, q.weights, b)
            nf = fl.size - f_p.size
            fe += accumulate(V, fl[:nf])
            f_p += fl[nf:]
    return fe, f_p
