"""The cell integrals of a user's linear form ``L(v)`` as loads of every coupling.

A cell integrand of ``L`` is linear in the test function ``v``. After the derivatives are
expanded it reads ::

    I(v) = b . v + S : grad(v)

with ``b`` a force per unit volume (gravity, a manufactured source) and ``S`` a stress that
does no work against a displacement of its own: a thermal stress ``C : (alpha dT I)``, an
initial or residual stress, an eigenstrain's ``C : eps_0``. :func:`split_test_gradient`
separates the two by replacing ``grad(v)`` and ``v`` (UFL ``replace``), so that
``sym(grad(v))``, ``div(v)``, ``nabla_grad(v)`` and ``v.dx(i)`` are all read.

Each side of a coupling integrates ``S : grad(v)`` with the test gradients of its own
stiffness (:mod:`~dolfinx_meshfree.physics.body_loads`): the FE cells with DOLFINx's assembly of
the weighted integrand, the particles and the ramps' blended cells with the (VCI-corrected,
smoothed, or one-sided at a crack) gradients their stiffness is built from. A constant
``S = C : eps_0`` then loads a body exactly as the stiffness does the displacement
``eps_0 x``, so free thermal expansion is reproduced to round-off by every coupling (the linear
patch test with an initial stress, ``tests/test_initial_stress.py``).
"""

from __future__ import annotations

import basix
import dolfinx
import numpy as np
import ufl
from ufl.algorithms import expand_derivatives
from ufl.corealg.traversal import unique_pre_traversal

from .. import _compat
from ..approx.fe_points import evaluate_fe_function
from ..geometry.quadrature import QuadraturePoints
from ..physics import axisymmetry
from ..physics.body_loads import BodyForce, accumulate
from .facet_terms import integral_entities

__all__ = ["FormBodyForce", "load_integrand_error", "replace_test_function", "split_test_gradient"]


def replace_test_function(
    integrand: ufl.core.expr.Expr,
    v: ufl.Argument,
    msh: dolfinx.mesh.Mesh,
    normal: ufl.core.expr.Expr | None = None,
) -> ufl.core.expr.Expr:
    """The vector ``(I(e_0), ..., I(e_{gdim-1}))`` of a linear integrand ``I(v)``, FacetNormal
    -> ``normal``."""
    mapping = {}
    if normal is not None:
        for node in unique_pre_traversal(integrand):
            if isinstance(node, ufl.classes.FacetNormal):
                mapping[node] = normal
    comps = []
    for e in np.eye(msh.geometry.dim):
        comps.append(ufl.replace(integrand, {**mapping, v: ufl.as_vector(e.tolist())}))
    return ufl.as_vector(comps)


def _gradients_of(expr: ufl.core.expr.Expr, v: ufl.Argument) -> tuple[bool, bool]:
    """Whether the expanded ``expr`` holds ``grad(v)``, and whether it holds a derivative of
    ``v`` that is not ``grad(v)`` (a second derivative)."""
    first = other = False
    for node in unique_pre_traversal(expr):
        if isinstance(node, ufl.classes.Derivative):
            if node.ufl_operands[0] == v and isinstance(node, ufl.classes.Grad):
                first = True
            elif any(sub == v for sub in unique_pre_traversal(node.ufl_operands[0])):
                other = True
    return first, other


def load_integrand_error(integrand: ufl.core.expr.Expr, v: ufl.Argument) -> str | None:
    """Why a cell integrand of ``L`` cannot be a load (a derivative of ``v`` other than its
    gradient), or ``None``."""
    other = _gradients_of(expand_derivatives(integrand), v)[1]
    if other:
        return (
            "it holds a second derivative of the test function; a load may hold v and grad(v) "
            "only (a body force dot(b, v) and a stress inner(S, grad(v)))"
        )
    return None


def split_test_gradient(
    integrand: ufl.core.expr.Expr, v: ufl.Argument, gdim: int
) -> tuple[ufl.core.expr.Expr, ufl.core.expr.Expr | None]:
    """``(b, S)`` of a linear integrand ``I(v) = b . v + S : grad(v)`` (module docstring): the
    vector ``b_i = I(v = e_i, grad(v) = 0)`` and the matrix ``S_ij = I(v = 0, grad(v) = e_i
    e_j^T)``; ``S`` is ``None`` when ``I`` holds no ``grad(v)``."""
    expr = expand_derivatives(integrand)
    zero_v = ufl.as_vector([0.0] * gdim)
    zero_g = ufl.as_matrix([[0.0] * gdim for _ in range(gdim)])
    g = ufl.grad(v)
    b = ufl.as_vector(
        [ufl.replace(expr, {g: zero_g, v: ufl.as_vector(e.tolist())}) for e in np.eye(gdim)]
    )
    if not _gradients_of(expr, v)[0]:
        return b, None
    rows = []
    for i in range(gdim):
        row = []
        for j in range(gdim):
            unit = np.zeros((gdim, gdim))
            unit[i, j] = 1.0
            row.append(ufl.replace(expr, {g: ufl.as_matrix(unit.tolist()), v: zero_v}))
        rows.append(row)
    return b, ufl.as_matrix(rows)


class FormBodyForce(BodyForce):
    """The cell integrals of a linear UFL form ``L(v)`` as a body force with a stress part
    (collective construction).

    The FE share is DOLFINx's assembly of every integral with its integrand multiplied by the
    coupling's FE weight (the user's measures, subdomains and quadrature metadata are kept). At
    a cell rule, ``b`` and ``S`` of :func:`split_test_gradient` come from a DOLFINx
    ``Expression`` of each integrand, zero on the cells the integral does not cover.

    Args:
        integrals: The cell integrals of ``L``.
        v: ``L``'s test function (on the vector P1/Q1 space).
        degree: The quadrature degree of the rules :meth:`values` is called with.
        cut: Points other than the rule's may be asked for (cut cells): compile the fit rule.
        revolved: The integrands carry the ``2 pi r`` of an axisymmetric model.
    """

    def __init__(
        self,
        integrals: list,
        v: ufl.Argument,
        degree: int,
        cut: bool = False,
        revolved: bool = False,
    ) -> None:
        msh = v.ufl_function_space().mesh
        self.integrals, self.mesh, self.degree = list(integrals), msh, degree
        self._interpolant: dolfinx.fem.Function | None = None  # at_points' P1 interpolant
        #: The integrands carry the ``2 pi r`` of an axisymmetric model: the loads per unit
        #: volume are theirs over ``2 pi r`` (the couplings' rules and weights are revolved).
        self.revolved = revolved
        cname = msh.topology.cell_type.name
        X, _ = _compat.quadrature_rule(cname, degree)
        self.num_points = X.shape[0]
        x = ufl.SpatialCoordinate(msh)
        self.gdim = gdim = msh.geometry.dim
        parts = [split_test_gradient(itg.integrand(), v, gdim) for itg in self.integrals]
        #: Whether an integrand holds ``grad(v)``: a stress each side integrates with its
        #: stiffness's test gradients (:class:`~dolfinx_meshfree.physics.body_loads.StressRule`).
        self.has_stress = any(S is not None for _, S in parts)
        self._forces = [b for b, _ in parts]  # b of each integral (at_points' interpolant)
        # points off the standard rule (cut cells, the stiffness's own rules): the fit rule
        fitting = cut or self.has_stress
        X_fit = _compat.quadrature_rule(cname, 2 * degree + 2)[0] if fitting else None
        self._expressions = []
        for itg, (b, S) in zip(self.integrals, parts, strict=True):
            cols = [b[i] for i in range(gdim)]
            if self.has_stress:
                S = ufl.as_matrix([[0.0] * gdim for _ in range(gdim)]) if S is None else S
                cols += [S[i, j] for i in range(gdim) for j in range(gdim)]
            bx = ufl.as_vector(cols + [x[i] for i in range(gdim)])
            expr = _compat.create_expression(bx, X, msh)
            fit = None if X_fit is None else _compat.create_expression(bx, X_fit, msh)
            n_cells = msh.topology.index_map(msh.topology.dim)
            on = np.zeros(n_cells.size_local + n_cells.num_ghosts, dtype=bool)
            on[integral_entities(itg, msh)] = True
            self._expressions.append((expr, fit, on))
        self.num_values = gdim * (gdim + 1) if self.has_stress else gdim
        self.tol = 1e-9 * (np.ptp(msh.geometry.x[:, :gdim], axis=0).max() + 1.0)

    def fe_load(
        self, V: dolfinx.fem.FunctionSpace, weight: ufl.core.expr.Expr | None, degree: int
    ) -> np.ndarray:
        integrals = self.integrals
        if weight is not None and self.revolved:  # the integrands have their 2 pi r already
            weight = weight / axisymmetry.measure(self.mesh)
        if weight is not None:
            integrals = [itg.reconstruct(integrand=weight * itg.integrand()) for itg in integrals]
        b = _compat.assemble_vector(_compat.create_form(ufl.Form(integrals)))
        with b.localForm() as loc:
            local = loc.array_r.copy()
        b.destroy()
        return accumulate(V, local)

    def values(self, q: QuadraturePoints) -> np.ndarray:
        """``b`` (len(q), gdim) at the points of a cell rule of ``degree``: the cells whose
        points are the standard rule's get the integrand there; the others (the pieces of cells
        a crack cuts, with ``cut=True``) get the polynomial of total degree ``degree`` fitted,
        by least squares in the cell, to the integrand at the points of the rule of degree
        ``2 degree + 2``: exact for integrands polynomial to that degree (constant, linear body
        loads), else an approximation of the rule's order. Local."""
        out = self._evaluate(q)[:, : self.gdim]
        if self.revolved:  # per unit volume (cell Gauss points lie off the axis)
            out = out / (2.0 * np.pi * q.points[:, :1])
        return out

    def at_points(self, x: np.ndarray, V: dolfinx.fem.FunctionSpace | None) -> np.ndarray:
        """``b`` at any points ``x`` (collective): its nodal interpolant on ``V`` (vector P1/Q1:
        exact for a ``b`` linear over the cells it covers; at the border of a tagged region,
        the nodes there carry the region's value), evaluated at ``x``: the body-force term of
        the interaction integral (``statics.sifs.body_force_acceleration``)."""
        if self._interpolant is None:
            self._interpolant = self._nodal_interpolant(V)
        out = evaluate_fe_function(self._interpolant, x)
        if self.revolved:  # the integrands' 2 pi r taken off, as in values()
            out = out / (2.0 * np.pi * np.asarray(x, dtype=float)[:, :1])
        return out

    def _nodal_interpolant(self, V: dolfinx.fem.FunctionSpace) -> dolfinx.fem.Function:
        """``b`` at the vertices of the cells each integral covers, summed over the integrals,
        as a Function on ``V`` (collective)."""
        msh, d = self.mesh, self.gdim
        cell = getattr(basix.CellType, msh.topology.cell_type.name)
        vertices = np.asarray(basix.geometry(cell), dtype=float)[:, : msh.topology.dim]
        dofs = _compat.dofmap_array(V)  # P1/Q1: the cell's vertices in reference order
        f = dolfinx.fem.Function(V)
        total = np.zeros((f.x.array.size // d, d))
        for b, (_, _, on) in zip(self._forces, self._expressions, strict=True):
            expr = _compat.create_expression(b, vertices, msh)  # collective
            cells = np.flatnonzero(on[: dofs.shape[0]])
            part = np.zeros_like(total)
            part[dofs[cells].ravel()] = _compat.eval_expression(expr, msh, cells, d).reshape(-1, d)
            total += part
        f.x.array[:] = total.ravel()
        f.x.scatter_forward()
        return f

    def stresses(self, q: QuadraturePoints) -> np.ndarray:
        """``S`` (len(q), gdim, gdim) at any points ``q`` in their cells: at the standard
        rule's points exactly, elsewhere (a smoothing rule, cut cells) fitted as in
        :meth:`values`. Local."""
        d = self.gdim
        if not self.has_stress:
            return np.zeros((len(q), d, d))
        return self._evaluate(q)[:, d:].reshape(-1, d, d)

    def _evaluate(self, q: QuadraturePoints) -> np.ndarray:
        """The expression's values (len(q), num_values) at ``q`` (see :meth:`values`)."""
        nq, d, k = self.num_points, self.gdim, self.num_values
        order = np.argsort(q.cells, kind="stable")
        cells, start, count = np.unique(q.cells[order], return_index=True, return_counts=True)
        out = np.zeros((len(q), k))
        for expr, fit, on in self._expressions:
            vals = _compat.eval_expression(expr, self.mesh, cells, k + d)  # (cells, nq, k + d)
            std = np.zeros(cells.size, dtype=bool)
            full = np.flatnonzero(count == nq)
            if full.size:
                idx = order[start[full, None] + np.arange(nq)]
                std[full] = (np.abs(vals[full, :, k:] - q.points[idx]) <= self.tol).all(axis=(1, 2))
                take = full[std[full] & on[cells[full]]]
                out[order[start[take, None] + np.arange(nq)]] += vals[take, :, :k]
            other = np.flatnonzero(~std)
            if other.size and fit is None:
                raise RuntimeError(
                    "a body load of L was requested at points that are not the Gauss points of "
                    f"degree {self.degree} (internal error: quadrature mismatch)"
                )
            other = other[on[cells[other]]]
            if other.size:
                fv = _compat.eval_expression(fit, self.mesh, cells[other], k + d)
                for n, c in enumerate(other):
                    idx = order[start[c] : start[c] + count[c]]
                    out[idx] += _fitted(fv[n, :, k:], fv[n, :, :k], q.points[idx], self.degree)
        return out


def _fitted(x: np.ndarray, values: np.ndarray, points: np.ndarray, degree: int) -> np.ndarray:
    """The least-squares polynomial of total ``degree`` through ``values`` (m, k) at ``x``
    (m, gdim), evaluated at ``points`` (p, gdim) (coordinates centred and scaled on ``x``)."""
    c, h = x.mean(axis=0), np.ptp(x, axis=0).max()

    def basis(p: np.ndarray) -> np.ndarray:
        y = (p - c) / h
        powers = [e for e in np.ndindex(*(degree + 1,) * y.shape[1]) if sum(e) <= degree]
        return np.stack([np.prod(y ** np.asarray(e), axis=1) for e in powers], axis=1)

    coef = np.linalg.lstsq(basis(x), values, rcond=None)[0]
    return basis(points) @ coef
