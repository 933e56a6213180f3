"""A law with state on the FE cells: stress and tangent as quadrature-point functions.

The FE side of a coupled model stays a DOLFINx form; what changes is where the stress comes from.
A law with internal state (:mod:`~dolfinx_meshfree.physics.inelastic`) has no UFL expression, so
its stress ``sigma_q`` and consistent tangent ``C_q`` (Voigt) live in "Quadrature" element
functions, one value per quadrature point of every FE cell, and the forms read them:

.. math::
    R(v) = \\int \\chi\\, \\sigma_q \\cdot \\varepsilon(v)\\, dx, \\qquad
    J(\\delta u, v) = \\int \\chi\\, (C_q\\, \\varepsilon(\\delta u)) \\cdot \\varepsilon(v)\\, dx

with the integral taken on the same points (``quadrature_scheme="default"``), ``chi`` the FE cells'
indicator (the bridging band's ``1 - alpha`` is put into ``sigma_q`` and ``C_q``). Before every
assembly :meth:`FEStateLaw.update` evaluates ``eps(u)`` at the points (a compiled
``dolfinx.fem.Expression``), runs the law from the committed state
(:class:`~dolfinx_meshfree.physics.state.PointState`) and writes ``sigma_q`` and ``C_q``. This is
the quadrature-function route of the FEniCSx plasticity demos; it works with DOLFINx 0.5 and
current DOLFINx alike, where ``dolfinx-external-operator`` needs current DOLFINx only (lane B),
and it puts the FE and particle points under one state store. On quadrilaterals and hexahedra in
plane strain and 3D the law runs at the mean-dilatation strain (B-bar,
:mod:`~dolfinx_meshfree.statics.mean_dilatation`), and :meth:`FEStateLaw.complete_tangent` adds
the tangent's cell terms that a form cannot hold.
"""

from __future__ import annotations

import dolfinx
import numpy as np
import ufl
from petsc4py import PETSc

from .. import _compat
from ..geometry.quadrature import cell_quadrature, cell_sizes
from ..parallel import raise_on_all_ranks
from ..physics.state import PointState, StatefulLaw
from .mean_dilatation import MeanDilatation, resolve_dilatation, warn_locking

__all__ = ["FE_STATE_DEGREE", "FEStateLaw", "check_bands", "ufl_voigt_strain"]

#: Quadrature degree of a law with state on P1/Q1 cells: 2 x 2 Gauss on quadrilaterals (full
#: integration of Q1), 3 points on triangles, 4 on tetrahedra, 2 x 2 x 2 on hexahedra.
FE_STATE_DEGREE = 2


def ufl_voigt_strain(w: ufl.core.expr.Expr, d: int) -> ufl.core.expr.Expr:
    """The engineering Voigt strain of a vector field ``w`` in UFL (order of
    :func:`~dolfinx_meshfree.approx.tables.voigt_pairs`)."""
    e = ufl.sym(ufl.grad(w))
    if d == 2:
        return ufl.as_vector([e[0, 0], e[1, 1], 2 * e[0, 1]])
    return ufl.as_vector([e[0, 0], e[1, 1], e[2, 2], 2 * e[1, 2], 2 * e[0, 2], 2 * e[0, 1]])


class FEStateLaw:
    """A :class:`~dolfinx_meshfree.physics.state.StatefulLaw` on the owned FE cells ``cells``.

    Args:
        u: The FE displacement (vector P1/Q1).
        law: The law.
        cells: Local indices of the owned cells it acts on (the FE cells of a coupled model).
        weight: An extra factor of the integrand (the bridging band's ``1 - alpha``), or ``None``.
        degree: Quadrature degree (:data:`FE_STATE_DEGREE`).
        dilatation: ``None`` (automatic), ``"mean"`` or ``"pointwise"``: whether the law runs at
            the strain with its trace replaced by the cell's mean (B-bar,
            :mod:`~dolfinx_meshfree.statics.mean_dilatation`). Automatic: on quadrilaterals and
            hexahedra in plane strain and 3D, where the full rule locks under plastic flow.

    Attributes:
        state: The :class:`~dolfinx_meshfree.physics.state.PointState` of the cells' points
            (``len(cells) * points per cell``, cell by cell); the band width of each is its
            cell's size (:func:`~dolfinx_meshfree.geometry.quadrature.cell_sizes`).
        weights: The points' quadrature weights times ``weight`` (for energies).
        mean_dilatation: The :class:`~dolfinx_meshfree.statics.mean_dilatation.MeanDilatation`
            of the cells, or ``None`` (pointwise strain).
    """

    def __init__(
        self,
        u: dolfinx.fem.Function,
        law: StatefulLaw,
        cells: np.ndarray,
        weight: ufl.core.expr.Expr | None = None,
        degree: int = FE_STATE_DEGREE,
        dilatation: str | None = None,
    ) -> None:
        V = u.function_space
        msh = V.mesh
        d = msh.geometry.dim
        nv = d * (d + 1) // 2
        self.u, self.law, self.d, self.nv = u, law, d, nv
        self.cells = np.asarray(cells, dtype=np.int32)
        X, w_ref = _compat.quadrature_rule(msh.topology.cell_type.name, degree)
        self.num_points = X.shape[0]
        self._strain = _compat.create_expression(ufl_voigt_strain(u, d), X, msh)
        self.stress = dolfinx.fem.Function(_compat.quadrature_space(msh, degree, nv))
        self.tangent = dolfinx.fem.Function(_compat.quadrature_space(msh, degree, nv * nv))
        self.stress.x.array[:] = 0.0
        self.tangent.x.array[:] = 0.0
        dofs = _compat.dofmap_array(self.stress.function_space)
        self._dofs = dofs[self.cells].ravel()  # point dofs, cell by cell
        q = cell_quadrature(msh, degree, self.cells)
        if q.points.shape[0] != self._dofs.size:  # the rule of the spaces and this one differ
            raise RuntimeError("the FE state's quadrature does not match its quadrature space")
        self.points = q.points
        # the extra weight at the points, put into the stress and tangent the forms read (mean
        # dilatation's cell means need it outside the forms)
        self._factor = np.ones(q.weights.size)
        if weight is not None:  # the bridging band's 1 - alpha, in the energies too
            factor = _compat.create_expression(weight, X, msh)
            self._factor = _compat.eval_expression(factor, msh, self.cells, 1).reshape(-1)
        self.weights = q.weights * self._factor
        cell_name = msh.topology.cell_type.name
        self.mean_dilatation: MeanDilatation | None = None
        warn_locking(law, cell_name)
        if resolve_dilatation(dilatation, law, cell_name, "FEStateLaw"):
            self.mean_dilatation = MeanDilatation(V, self.cells, X, w_ref, q.weights, self._factor)
        band = cell_sizes(msh, self.cells).repeat(self.num_points) if law.needs_band else None
        self.state = PointState(law, self.points, band, q.cells)
        dxq = ufl.Measure(
            "dx",
            domain=msh,
            metadata={"quadrature_degree": degree, "quadrature_scheme": "default"},
        )
        v, du = ufl.TestFunction(V), ufl.TrialFunction(V)
        C = ufl.as_matrix([[self.tangent[nv * i + j] for j in range(nv)] for i in range(nv)])
        r = ufl.inner(self.stress, ufl_voigt_strain(v, d))
        j = ufl.inner(ufl.dot(C, ufl_voigt_strain(du, d)), ufl_voigt_strain(v, d))
        #: The residual and Jacobian forms (before restriction to the cells).
        self.residual_form = r * dxq
        self.jacobian_form = j * dxq

    def strain(self) -> np.ndarray:
        """The Voigt strain (points, nv) the law runs at, of the current ``u`` at the cells'
        points: with mean dilatation its trace is the cell's mean."""
        msh = self.u.function_space.mesh
        e = _compat.eval_expression(self._strain, msh, self.cells, self.nv).reshape(-1, self.nv)
        md = self.mean_dilatation
        return e if md is None else md.strain(e)

    def update(self) -> None:
        """Run the law at the current ``u`` from the committed state and write ``sigma_q`` and
        ``C_q`` (local: each rank its own cells)."""
        strain = self.strain()
        md = self.mean_dilatation
        # on every rank alike (a return map that fails on one rank's points; Newton's line
        # search shortens its step on every rank)
        comm = self.u.function_space.mesh.comm
        stress, tangent = raise_on_all_ranks(comm, lambda: self.state.evaluate(strain))
        if md is not None:
            stress, tangent = md.stress_tangent(stress, tangent)
        else:
            stress = self._factor[:, None] * stress
            tangent = self._factor[:, None, None] * tangent
        nv = self.nv
        self.stress.x.array.reshape(-1, nv)[self._dofs] = stress
        self.tangent.x.array.reshape(-1, nv * nv)[self._dofs] = tangent.reshape(-1, nv * nv)

    def complete_tangent(self, A: PETSc.Mat) -> None:
        """Add to ``A``, assembled from :attr:`jacobian_form` at the last :meth:`update`, what
        the form cannot hold: mean dilatation's rank-one cell terms (nothing without it;
        collective)."""
        if self.mean_dilatation is not None:
            self.mean_dilatation.add_to(A)

    def dissipated(self, trial: bool = False) -> float:
        """Energy dissipated on this rank's cells (committed state unless ``trial``)."""
        return self.state.dissipated(self.weights, trial)


def check_bands(
    msh: dolfinx.mesh.Mesh, law: StatefulLaw, in_patch: np.ndarray, factor: float
) -> None:
    """Check the crack band of every owned cell against ``law`` (local): its size
    (:func:`~dolfinx_meshfree.geometry.quadrature.cell_sizes`), times ``factor`` on the patch
    cells (``in_patch``); a band the law refuses (local snap-back) is named by the cell's
    midpoint."""
    n = msh.topology.index_map(msh.topology.dim).size_local
    cells = np.arange(n, dtype=np.int64)
    q = cell_quadrature(msh, 1, cells)
    mid = np.zeros((n, msh.geometry.dim))
    np.add.at(mid, q.cells, q.points * q.weights[:, None])
    volume = np.bincount(q.cells, weights=q.weights, minlength=n)
    band = cell_sizes(msh, cells) * np.where(in_patch[:n], factor, 1.0)
    law.check_band(band, mid / np.maximum(volume, 1e-300)[:, None])
