"""The multiplier correction of the velocities: ``G v = 0`` after every step.

Trial velocities ``vbar`` (Belytschko et al. 1995, eq. 93; Rabczuk et al. 2006, eq. 93) are
projected onto the constraint in the mass metric (eq. 94–96):

.. math::
    (G M^{-1} G^T) \\lambda = G \\bar v, \\qquad v = \\bar v - M^{-1} G^T \\lambda.

``S = G M^{-1} G^T`` is factorised once (dense Cholesky on every rank, or MUMPS), so each
correction costs two sparse products with ``G`` and one triangular solve; ``G v`` stays at
round-off. Dofs with ``M^{-1} = 0`` (held at rest) are not moved.

With the dense factor every rank holds ``G_f``'s columns of its owned dofs (all multiplier
rows): ``G v`` is the sum over the ranks of their columns' products, one ``Allreduce`` of the
multipliers per step, and ``G^T lambda`` is local; PETSc's products would exchange ghost
values four times and gather ``G v`` once (on 2 ranks of a shared machine each exchange can
cost a time slice).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc
from scipy.linalg import LinAlgError, cho_factor
from scipy.linalg.lapack import dpotrs

from ..approx.jit import jit
from .compiled_product import resolve_product
from .linalg import mumps_lu

__all__ = ["MULTIPLIER_SOLVERS", "VelocityProjection", "check_multiplier_solver"]

#: Factorisations of ``S`` (``None``: automatic, dense up to :data:`DENSE_MAX` multipliers).
MULTIPLIER_SOLVERS = (None, "dense", "mumps")
DENSE_MAX = 2000
#: A pivot ``d`` of the Cholesky factor of ``S`` scaled to a unit diagonal (Jacobi) with ``d^2``
#: below this marks a redundant constraint (:meth:`VelocityProjection._deflate`). The scaling
#: makes the test blind to the rows' units: a coupling's rows of unit scale (edge-to-edge's
#: collocated MLS values) beside a wall's facet rows (``int_f phi``, of the order of ``h^2`` in
#: 3D: 1e-6 m^2 on a copper Taylor bar) made the wall's pivots 1e-13 of the largest diagonal,
#: and the unscaled test deflated the wall as redundant: the rod went through it. The two null
#: directions of a bridging band cut by a roller (the axisymmetric cylinder's, 8 cells) have
#: eigenvalues 3.0e-16 and 3.9e-16 of the scaled diagonal, the next 4.4e-4.
REDUNDANT = 1e-12


def check_multiplier_solver(solver: str | None) -> str | None:
    """Return ``solver`` if known, else raise a ``ValueError`` naming the choices."""
    if solver not in MULTIPLIER_SOLVERS:
        raise ValueError(
            f"multiplier_solver={solver!r} is not known; use None (automatic), 'dense' or 'mumps'"
        )
    return solver


class VelocityProjection:
    """The projection ``v -> v - M^{-1} G^T S^{-1} G v`` onto ``G v = 0`` (eq. 94–96).

    Args:
        G: The constraint blocks ``G_f`` of each field (``None`` for a field without).
        minv: ``M^{-1}`` per field (0 on dofs held at rest).
        comm: The communicator.
        solver: ``"dense"`` (Cholesky on every rank, one ``Allgatherv`` of ``G v`` per step:
            the fastest for interface-sized ``S``), ``"mumps"`` (distributed LU), or ``None``:
            dense up to 2000 multipliers. The choice made is :attr:`solver`.
        product: The dense path's local products ``G_f v_f`` and ``v_f -= M_f^{-1} G_f^T
            lambda``: ``"numba"`` (compiled, each field in one pass: the default with numba) or
            ``"petsc"`` (scipy's products and numpy's arithmetic, the reference); the same to
            the bit (the sums in the same order). ``None``: ``DOLFINX_MESHFREE_PRODUCT`` or the
            default, as the stiffness products
            (:func:`~dolfinx_meshfree.dynamics.compiled_product.resolve_product`).

    Raises:
        ValueError: ``S`` is singular (dense): two constraints act on the same dofs only.
    """

    def __init__(
        self,
        G: Sequence[PETSc.Mat | None],
        minv: Sequence[PETSc.Vec],
        comm: MPI.Comm,
        solver: str | None = None,
        product: str | None = None,
    ) -> None:
        self.product = resolve_product(product)
        self.G = list(G)
        self.minv = list(minv)
        self.comm = comm
        self.ksp: PETSc.KSP | None = None
        self.chol: tuple | None = None
        self._pinv: np.ndarray | None = None
        #: The number of redundant constraints ``S``'s null space holds (dense path,
        #: :meth:`_deflate`): combinations that act on dofs held at rest only.
        self.redundant = 0
        self._work = [m.duplicate() for m in self.minv]
        self._tmp = [m.duplicate() for m in self.minv]
        S = None
        #: per field, ``G_f`` restricted to the columns of the owned dofs (every row; scipy
        #: CSR, local column numbers) and its transpose: the dense path's local products
        self._cols: list[tuple[scipy.sparse.csr_matrix, scipy.sparse.csr_matrix] | None] = []
        for g, mi in zip(self.G, self.minv, strict=True):
            if g is None:
                self._cols.append(None)
                continue
            GT = g.transpose(PETSc.Mat())  # (without an argument petsc4py transposes in place)
            ai, aj, av = GT.getValuesCSR()  # rows: owned dofs, columns: global multipliers
            gt = scipy.sparse.csr_matrix(
                (av, aj, ai), shape=(GT.getLocalSize()[0], GT.getSize()[1])
            )
            self._cols.append((gt.T.tocsr(), gt))
            GT.diagonalScale(L=mi)
            Sf = g.matMult(GT)
            GT.destroy()
            if S is None:
                S = Sf
            else:
                S.axpy(1.0, Sf, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                Sf.destroy()
        self.S: PETSc.Mat = S
        #: per field, the owned dofs ``G_f`` acts on (the rows of ``G_f^T`` with entries)
        self._rows = [
            None if c is None else np.flatnonzero(np.diff(c[1].indptr)) for c in self._cols
        ]
        size = S.getSize()[0]
        if solver is None:
            solver = "dense" if size <= DENSE_MAX else "mumps"
        self.solver: str = solver
        if solver == "dense":
            self._dense(S, size)
        else:
            self.ksp = mumps_lu(S)
        self._lam = S.createVecRight()
        self._gv = S.createVecLeft()
        self._gnorm = [0.0 if g is None else g.norm(PETSc.NormType.INFINITY) for g in self.G]

    @property
    def num_multipliers(self) -> int:
        """Global number of multipliers (rows of ``G``)."""
        return int(self.S.getSize()[0])

    def _dense(self, S: PETSc.Mat, size: int) -> None:
        """Small ``S``: every rank holds its Cholesky factor, one Allgatherv per step. The
        factor is of ``S`` scaled to a unit diagonal, ``D^-1/2 S D^-1/2`` (rows with a zero
        diagonal, acting on held dofs only, unscaled), so that the rows' units (a coupling's
        against a wall's) do not decide which constraints count as redundant
        (:data:`REDUNDANT`); ``lambda = D^-1/2 (scaled solve)(D^-1/2 G v)``."""
        ai, aj, av = S.getValuesCSR()
        lo, hi = S.getOwnershipRange()
        rows = np.repeat(np.arange(lo, hi), np.diff(ai))
        parts = self.comm.allgather((rows, np.asarray(aj), np.asarray(av)))
        dense = np.zeros((size, size))
        for r, c, v in parts:
            np.add.at(dense, (r, c), v)
        self._full = np.zeros(size)
        diagonal = np.diag(dense).copy()
        self._jacobi = np.where(diagonal > 0.0, 1.0 / np.sqrt(np.abs(diagonal)), 1.0)
        dense *= np.outer(self._jacobi, self._jacobi)
        scale = float(np.abs(np.diag(dense)).max(initial=0.0))
        try:
            self.chol = cho_factor(dense)
            if np.min(np.abs(np.diag(self.chol[0])), initial=np.inf) ** 2 > REDUNDANT * scale:
                return
        except LinAlgError:
            pass
        self.chol, self.redundant = None, self._deflate(dense, scale, size)

    def _deflate(self, dense: np.ndarray, scale: float, size: int) -> int:
        """A rank-deficient ``S``: the pseudo-inverse on its range (every rank), or a refusal.

        A null vector ``mu`` of ``S = G M^{-1} G^T`` has ``G^T mu = 0`` on every moving dof:
        the constraints it combines act only on dofs held at rest (``M^{-1} = 0``), e.g. the
        bridging band's rows at FE nodes on a roller together with the roller's rows on the
        particles (a band cut by a symmetry plane). They repeat what the held dofs already
        satisfy: ``mu . G v = 0`` for every ``v`` that leaves held dofs at rest, so ``S
        lambda = G v`` is consistent and its least-norm solution corrects ``v`` as the full
        rank system would. Eigenvalues below :data:`REDUNDANT` times the largest diagonal are
        that null space; a negative one beyond it (a negative mass) is refused."""
        w, vecs = np.linalg.eigh(dense)
        if w.min(initial=0.0) < -REDUNDANT * scale or not np.any(w > REDUNDANT * scale):
            raise ValueError(
                f"the constraint matrix G M^-1 G^T ({size} rows) is not positive semi-definite "
                f"(its smallest eigenvalue {w.min():.3e} against {scale:.3e}): a lumped mass "
                "is negative or the constraints act on no moving dof; check the masses "
                "(particle_mass, dilation) and the fixed facets"
            )
        keep = w > REDUNDANT * scale
        self._pinv = (vecs[:, keep] / w[keep]) @ vecs[:, keep].T
        return int(size - keep.sum())

    def correct(
        self,
        vel: Sequence[PETSc.Vec],
        impulse: Sequence[PETSc.Vec] | None = None,
        target: np.ndarray | None = None,
    ) -> None:
        """Project ``vel`` in place onto ``G v = 0`` (``G v = target``, the owned rows, for
        prescribed values: :mod:`~dolfinx_meshfree.dynamics.prescribed`): solve ``S lambda =
        G v - target``, then ``v -= M^{-1} G^T lambda``; ``impulse`` receives ``G_f^T lambda``
        per field (collective)."""
        if self.chol is not None or self._pinv is not None:
            self._correct_dense(vel, impulse, target)
            return
        self._gv.set(0.0)
        for g, x in zip(self.G, vel, strict=True):
            if g is not None:
                g.multAdd(x, self._gv, self._gv)
        if target is not None:
            self._gv.array[:] -= target
        self.ksp.solve(self._gv, self._lam)
        for k, (g, x) in enumerate(zip(self.G, vel, strict=True)):
            if g is None:
                continue
            w = self._work[k] if impulse is None else impulse[k]
            g.multTranspose(self._lam, w)
            self._tmp[k].pointwiseMult(self.minv[k], w)
            x.axpy(-1.0, self._tmp[k])

    def _correct_dense(
        self,
        vel: Sequence[PETSc.Vec],
        impulse: Sequence[PETSc.Vec] | None,
        target: np.ndarray | None,
    ) -> None:
        """:meth:`correct` with the dense factor: ``G v`` from the owned columns, summed over
        the ranks in one ``Allreduce``; ``G^T lambda`` and the update local (collective)."""
        gv = self._full
        gv[:] = 0.0
        compiled = self.product == "numba"
        for cols, x in zip(self._cols, vel, strict=True):
            if cols is None:
                continue
            if compiled:
                _gather(cols[0].indptr, cols[0].indices, cols[0].data, x.array_r, gv)
            else:
                gv += cols[0] @ x.array_r
        if target is not None:  # the owned rows' targets, once over the ranks
            lo, hi = self._lam.getOwnershipRange()
            gv[lo:hi] -= target
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, gv, op=MPI.SUM)
        if not np.isfinite(gv).all():  # the same on every rank (summed above)
            raise FloatingPointError(
                "the constraint projection met a non-finite G v: the velocities hold NaN or "
                "inf (an unstable run: shorten the time step or check the masses)"
            )
        gv *= self._jacobi  # the unit-diagonal scaling of S (:meth:`_dense`; gv is reset above)
        if self.chol is not None:  # LAPACK's solve with the factor, as cho_solve without its
            lam = dpotrs(self.chol[0], gv, lower=self.chol[1])[0]  # checks of the factor
        else:
            lam = self._pinv @ gv
        lam *= self._jacobi
        for k, (cols, x) in enumerate(zip(self._cols, vel, strict=True)):
            if cols is None:
                continue
            w = self._work[k] if impulse is None else impulse[k]
            if compiled:  # only G_f's non-zero columns change (x - M^-1 0 = x, to the bit)
                C, rows, mi = cols[1], self._rows[k], self.minv[k].array_r
                w.set(0.0)
                _apply(rows, C.indptr, C.indices, C.data, lam, mi, x.array, w.array)
            else:
                w.array[:] = cols[1] @ lam
                x.array[:] -= self.minv[k].array_r * w.array_r

    def residual(self, vel: Sequence[PETSc.Vec], target: np.ndarray | None = None) -> float:
        """Relative residual ``|sum_f G_f v_f - target|_inf / sum_f |G_f|_inf |v_f|_inf``
        (collective)."""
        self._gv.set(0.0)
        scale = 0.0
        for g, x, gn in zip(self.G, vel, self._gnorm, strict=True):
            if g is not None:
                g.multAdd(x, self._gv, self._gv)
                scale += gn * x.norm(PETSc.NormType.INFINITY)
        if target is not None:
            self._gv.array[:] -= target
        r = self._gv.norm(PETSc.NormType.INFINITY)
        return float(r / scale) if scale > 0 else float(r)

    def destroy(self) -> None:
        """Destroy the factorisation and work vectors (not ``G`` or ``M^{-1}``; collective)."""
        for obj in (self.ksp, self.S, self._lam, self._gv, *self._work, *self._tmp):
            if obj is not None:
                obj.destroy()


@jit
def _gather(indptr, indices, data, x, out):  # pragma: no cover - compiled
    """``out += C x`` (CSR ``C``), each row's sum taken alone first, as scipy's product and
    the ``+=`` after it."""
    for i in range(indptr.shape[0] - 1):
        acc = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            acc += data[p] * x[indices[p]]
        out[i] += acc


@jit
def _apply(rows, indptr, indices, data, lam, minv, x, w):  # pragma: no cover - compiled
    """``w = C lam`` and ``x -= minv * w`` on the ``rows`` of the CSR ``C`` (its rows with
    entries; ``w`` is 0 elsewhere), in one pass."""
    for i in rows:
        acc = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            acc += data[p] * lam[indices[p]]
        w[i] = acc
        x[i] -= minv[i] * acc
