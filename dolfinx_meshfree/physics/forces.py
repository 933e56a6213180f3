"""Internal force and consistent tangent of the total-Lagrangian weak form, from shape tables.

Rabczuk, Xiao & Sauer 2006, eq. 34: ``delta W_int = int_Omega0 (grad_0 delta u)^T : P(F) dOmega_0``
with ``F = I + grad_0 u`` (eq. 2's nominal stress ``P``). With shape functions ``N_J`` tabulated
in the reference configuration (a :class:`~dolfinx_meshfree.ShapeTable`, the same at every load
level or time step) and quadrature weights ``w_q``:

.. math::
    F_q = I + \\sum_J u_J \\otimes \\nabla_0 N_J(X_q), \\qquad
    f^{int}_{Ji} = \\sum_q P_{iL}(F_q) \\, \\partial_L \\hat N_J(X_q) \\, w_q, \\qquad
    K_{Ji,Kk} = \\sum_q \\partial_J \\hat N \\, A_{iJkL}(F_q) \\, \\partial_L N_K \\, w_q,

i.e. ``f_int = sum_q B0(F_q)^T P(F_q) w_q`` and ``K_T = sum_q G^T A(F_q) G w_q`` with ``A = dP/dF``
(material and geometric stiffness both). ``hat N`` are the test functions: the trial ones, or the
variationally consistent (VCI) gradients of
:func:`~dolfinx_meshfree.physics.operators.consistent_gradients`, which keep the patch test exact
at any
load level (a homogeneous ``F`` gives ``f_int`` = the boundary integral of ``N_J P n^0``, eq. 5).
Dofs are interleaved as in :func:`~dolfinx_meshfree.physics.operators.stiffness_matrix`: component
``i``
of node ``J`` is ``d J + i``. For :class:`~dolfinx_meshfree.LinearElastic` ``K_T`` is that
stiffness and ``f_int(u) = K u``.

Example: Newton with load steps needs only ``internal_force`` and ``tangent`` (this loop is
``tests/test_forces.py::test_newton_with_internal_force_and_tangent_converges_quadratically``;
``free`` are the unconstrained dofs)::

    forces = InternalForces(table, q.weights, NeoHookean(E=1e3, nu=0.3), test_gradients=vci)
    u = np.zeros(forces.num_dofs)
    for lam in (0.5, 1.0):                       # load steps
        for it in range(25):
            r = lam * f_ext - forces.internal_force(u)
            if np.linalg.norm(r[free]) <= 1e-10 * np.linalg.norm(f_ext[free]):
                break
            K = forces.tangent(u)[free][:, free]
            u[free] += scipy.sparse.linalg.spsolve(K.tocsc(), r[free])
        else:
            raise RuntimeError("Newton did not converge")   # never return the last iterate
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, TypeVar

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from ..approx.tables import Approximation, ShapeTable, check_current
from ..parallel import raise_on_all_ranks
from .assembly_kernel import GradientForm, resolve_backend
from .axisymmetry import hoop_operator, hoop_table
from .constitutive import Material
from .materials import is_axisymmetric

if TYPE_CHECKING:  # annotations only
    from mpi4py import MPI

_T = TypeVar("_T")

__all__ = ["InternalForces", "gradient_operator"]


def gradient_operator(gradients: Sequence[sp.spmatrix]) -> sp.csr_matrix:
    """Sparse ``G`` (m d^2 x d n) with ``(G u)[d^2 q + d i + J] = sum_K dN_K/dX_J(X_q) u_{dK+i}``.

    ``G u`` is the displacement gradient ``H_iJ = du_i/dX_J`` at every point, row-major per
    point; ``G^T`` maps a per-point (d x d) stress to interleaved nodal forces.

    Args:
        gradients: ``d`` tables (m x n), ``gradients[J][q, K] = dN_K/dX_J (X_q)``.
    """
    d = len(gradients)
    m, n = gradients[0].shape
    rows, cols, vals = [], [], []
    for J, g in enumerate(gradients):
        if g.shape != (m, n):
            raise ValueError(f"gradient table {J} has shape {g.shape}, expected {(m, n)}")
        c = sp.coo_matrix(g)
        for i in range(d):
            rows.append(d * d * c.row + d * i + J)
            cols.append(d * c.col + i)
            vals.append(c.data)
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(d * d * m, d * n),
    )


class InternalForces:
    """``f_int(u)`` and ``K_T(u)`` of a material on tabulated shape functions (eq. 34).

    Args:
        table: Trial shape functions at the quadrature points, with gradients (reference frame).
        weights: (m,) quadrature weights (reference volume; any extra factor such as a bridging
            weight included).
        material: A :class:`~dolfinx_meshfree.physics.constitutive.Material` with ``gdim`` equal to
        the
            table's dimension.
        test_gradients: Test-function gradients (default: the table's), e.g. VCI-corrected.
        comm: If given, material errors (``det F <= 0`` at a point) are raised on every rank of
            ``comm``, so each call is collective; by default calls are local (no communication).
        approximation: The approximation that tabulated ``table`` (an MLS or SPH): every call
            checks that it has not changed since (its ``version``), and raises
            :class:`~dolfinx_meshfree.approx.tables.StaleTableError` if it has.
        hoop: An axisymmetric material's hoop table (m x n,
            :func:`~dolfinx_meshfree.physics.axisymmetry.hoop_table`) of the trial strain;
            default ``N / R``.
        test_hoop: The test functions' hoop table (default ``hoop``): VCI pairs a meshfree
            trial strain with the axis offset taken off with the test functions' plain ``N /
            R`` (:func:`~dolfinx_meshfree.physics.axisymmetry.approximation_hoop`).

    All results are this rank's contributions (the quadrature points it was given), unassembled
    across ranks, in the table's column numbering.
    """

    def __init__(
        self,
        table: ShapeTable,
        weights: npt.ArrayLike,
        material: Material,
        test_gradients: Sequence[sp.spmatrix] | None = None,
        comm: MPI.Comm | None = None,
        approximation: Approximation | None = None,
        hoop: sp.csr_matrix | None = None,
        test_hoop: sp.csr_matrix | None = None,
    ) -> None:
        def check() -> np.ndarray:
            if not isinstance(material, Material):
                raise TypeError(
                    f"material must follow the Material protocol (first_piola, tangent, ...), "
                    f"got {type(material).__name__}"
                )
            d = len(table.gradients)
            if d != material.gdim:
                raise ValueError(
                    f"the table has {d} gradient components (gdim {d}) but the material is "
                    f"{material.gdim}D (plane={material.plane!r}); tabulate with derivatives=1 "
                    "or use plane=None in 3D / 'strain'|'stress' in 2D"
                )
            w = np.asarray(weights, dtype=float)
            if w.shape != (table.shape[0],):
                raise ValueError(f"weights should have shape ({table.shape[0]},), got {w.shape}")
            if test_gradients is not None and len(test_gradients) != d:
                raise ValueError(
                    f"test_gradients has {len(test_gradients)} components, expected {d}"
                )
            return w

        self.weights = check() if comm is None else raise_on_all_ranks(comm, check)
        self.table = table
        self.approximation = approximation
        self.material = material
        self.comm = comm
        self.gdim = material.gdim
        self._G = gradient_operator(table.gradients)
        self._Gt = self._G if test_gradients is None else gradient_operator(test_gradients)
        self._test_gradients = table.gradients if test_gradients is None else test_gradients
        self._form: GradientForm | None = None  # the compiled tangent's pattern, on first use
        if self._Gt.shape != self._G.shape:
            raise ValueError(
                f"test_gradients give an operator of shape {self._Gt.shape}, the table "
                f"{self._G.shape}"
            )
        #: An axisymmetric material (``plane="axisymmetric"``): the hoop terms join (``weights``
        #: must then be revolved, ``2 pi R w``; :meth:`_hoop_force`, :meth:`_hoop_tangent`).
        self.axisymmetric = is_axisymmetric(material)
        if self.axisymmetric:  # u_r / R at every point (or its limit: ``hoop``)
            table_hoop = hoop_table(table.values, table.points) if hoop is None else hoop
            self._H = hoop_operator(table_hoop)
            self._Ht = self._H if test_hoop is None else hoop_operator(test_hoop)
            # D u = du_r/dr + du_z/dz (trial and test), for the tangent's hoop coupling
            self._D, self._Dt = (op[0::4] + op[3::4] for op in (self._G, self._Gt))
        m, d2 = table.shape[0], self.gdim**2
        base = d2 * np.arange(m)[:, None, None]
        r = np.arange(d2)
        shape = (m, d2, d2)
        # sparsity of the block diagonal of the per-point (d^2 x d^2) tangents, fixed
        self._blk_rows = np.broadcast_to(base + r[None, :, None], shape).ravel()
        self._blk_cols = np.broadcast_to(base + r[None, None, :], shape).ravel()

    @property
    def num_dofs(self) -> int:
        """Interleaved dofs of the table's nodes (``d n``)."""
        return self._G.shape[1]

    def _call(self, fn: Callable[[], _T]) -> _T:
        def checked() -> _T:
            if self.approximation is not None:
                check_current(self.table, self.approximation, "this internal-force operator")
            return fn()

        return checked() if self.comm is None else raise_on_all_ranks(self.comm, checked)

    def _vector(self, u: npt.ArrayLike) -> np.ndarray:
        u = np.asarray(u, dtype=float).reshape(-1)
        if u.shape != (self.num_dofs,):
            raise ValueError(
                f"u should have {self.num_dofs} interleaved entries (d * nodes), got {u.size}"
            )
        return u

    def displacement_gradient(self, u: npt.ArrayLike) -> np.ndarray:
        """``H_iJ = du_i/dX_J`` (m, d, d) at the quadrature points (trial gradients)."""
        d = self.gdim
        return (self._G @ self._vector(u)).reshape(-1, d, d)

    def deformation_gradient(self, u: npt.ArrayLike) -> np.ndarray:
        """``F = I + H`` (m, d, d)."""
        return np.eye(self.gdim) + self.displacement_gradient(u)

    def internal_force(self, u: npt.ArrayLike) -> np.ndarray:
        """``f_int = sum_q B0(F_q)^T P(F_q) w_q`` (d n,), interleaved (eq. 34)."""
        F = self.deformation_gradient(u)
        if self.axisymmetric:
            return self._hoop_force(F, self._vector(u))
        P = self._call(lambda: self.material.first_piola(F, self.table.points))
        return self._Gt.T @ (self.weights[:, None, None] * P).ravel()

    def _hoop_force(self, F: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The axisymmetric internal force: ``sum_q (B0^T P + N_I P_tt / R e_r) 2 pi R w_q``
        with the hoop stretch ``F_tt = 1 + u_r / R`` (Zienkiewicz & Taylor, vol. 1, ch. 5, at
        finite strain in the total-Lagrangian frame)."""
        hoop = 1.0 + self._H @ u
        P, P_tt = self._call(lambda: self.material.axisymmetric_piola(F, self.table.points, hoop))
        w = self.weights
        return self._Gt.T @ (w[:, None, None] * P).ravel() + self._Ht.T @ (w * P_tt)

    def tangent(self, u: npt.ArrayLike, backend: str | None = None) -> sp.csr_matrix:
        """Consistent tangent ``K_T = d f_int/du = sum_q G_test^T A(F_q) G w_q`` (CSR, dn x dn).

        ``backend``: as in :func:`~dolfinx_meshfree.physics.operators.stiffness_matrix`
        (``"numba"``: a :class:`~dolfinx_meshfree.physics.assembly_kernel.GradientForm`, its
        sparsity pattern computed on the first call and reused; ``"scipy"``: the sparse
        product, the reference).
        """
        backend = resolve_backend(backend)
        F = self.deformation_gradient(u)
        A = self._call(lambda: self.material.tangent(F, self.table.points))
        d2 = self.gdim**2
        if backend == "numba":
            if self._form is None:
                self._form = GradientForm(self._test_gradients, self.table.gradients)
            K = self._form(self.weights, A.reshape(-1, d2, d2))
        else:
            blocks = self.weights[:, None, None] * A.reshape(-1, d2, d2)
            n = blocks.shape[0] * d2
            M = sp.csr_matrix((blocks.ravel(), (self._blk_rows, self._blk_cols)), shape=(n, n))
            K = (self._Gt.T @ M @ self._G).tocsr()
        return K + self._hoop_tangent(A) if self.axisymmetric else K  # both backends

    def _hoop_tangent(self, A: np.ndarray) -> sp.csr_matrix:
        """The hoop rows and columns of an isotropic tangent ``A`` (m, 2, 2, 2, 2) at ``F = I``
        (``lambda = A_rrzz``, ``lambda + 2 mu = A_rrrr``): ``H_test^T (lambda + 2 mu) H +
        D_test^T lambda H + H_test^T lambda D`` with ``D u = du_r/dr + du_z/dz``, weighted by
        ``w``; what
        the stable-step bound of a rate-form law needs (its twin's elastic tangent)."""
        w = self.weights
        lam, l2m = w * A[:, 0, 0, 1, 1], w * A[:, 0, 0, 0, 0]
        D, Dt, H, Ht = self._D, self._Dt, self._H, self._Ht
        return (
            Ht.T @ sp.diags(l2m) @ H + Dt.T @ sp.diags(lam) @ H + Ht.T @ sp.diags(lam) @ D
        ).tocsr()

    def strain_energy(self, u: npt.ArrayLike) -> float:
        """Stored energy ``sum_q W(F_q) w_q`` of this rank's points (not summed over ranks)."""
        F = self.deformation_gradient(u)
        W = self._call(lambda: self.material.strain_energy_density(F, self.table.points))
        return float(W @ self.weights)
