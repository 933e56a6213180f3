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

__all__ = ["BodyForce", "CallableBodyForce", "body_load_vectors"]

VectorFunction = Callable[[np.ndarray], np.ndarray]


class BodyForce:
    """A body force per unit volume: its FE load and its values at quadrature points.

    Subclasses implement :meth:`fe_load` (collective) and :meth:`values` (local).
    """

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


def body_load_vectors(
    forces: list[BodyForce],
    V: dolfinx.fem.FunctionSpace | None,
    fe_weight: ufl.core.expr.Expr | None,
    degree: int,
    particle_rule: tuple[QuadraturePoints, sp.csr_matrix] | None = None,
    interface_rule: tuple[QuadraturePoints, sp.csr_matrix] | None = None,
    comm: MPI.Comm | None = None,
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
    for force in forces:
        if V is not None:
            fe += force.fe_load(V, fe_weight, degree)
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
