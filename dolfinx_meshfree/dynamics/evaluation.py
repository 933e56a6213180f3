"""The displacement or velocity of an explicit model anywhere: at points, at quadrature points,
as DOLFINx Functions, and its relative L2 error (Rabczuk et al. 2006, eq. 137).

FE on FE cells, the particles' approximation on particle cells, the ramp's blended functions on
interface cells (Belytschko et al. 1995, eq. 3.15) and ``(1 - alpha) u_FE + alpha u_P`` on
bridging band cells (Rabczuk et al. 2006, eq. 46–48); master–slave expands the slaves
(``u_P = T_PF u_FE + S u_M``, eq. 27).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import dolfinx
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from ..approx.fe_points import ensure_points_in_mesh, evaluate_fe_function, tabulate_in_cells
from ..couplings.bridging import BridgingBand, BridgingSolution
from ..couplings.ramp import RampInterface
from ..geometry.quadrature import QuadraturePoints, cell_quadrature
from ..parallel import raise_on_all_ranks
from ..statics.coupled import CoupledSolution
from .discretisation import Discretisation

__all__ = ["FieldEvaluator"]

Tables = tuple[QuadraturePoints, sp.csr_matrix | None, sp.csr_matrix | None]


def _gathered(x: PETSc.Vec, comm: MPI.Comm) -> np.ndarray:
    """The whole of the distributed vector ``x`` on every rank, in its global order: one
    ``Allgatherv`` of the owned values (a copy on one rank; collective): the values of
    concatenating every rank's owned array, without pickling them."""
    if comm.size == 1:
        return x.array_r.copy()
    ranges = np.asarray(x.getOwnershipRanges())
    out = np.empty(int(ranges[-1]), dtype=PETSc.ScalarType)
    comm.Allgatherv(x.array_r, [out, np.diff(ranges), ranges[:-1], MPI.DOUBLE])
    return out


class FieldEvaluator:
    """Evaluates fields given by their dof vectors (one per field) on a discretisation.

    Collective throughout; the quadrature tables are cached per degree.
    """

    def __init__(self, disc: Discretisation, comm: MPI.Comm) -> None:
        self.disc = disc
        self.comm = comm
        self._tables: dict[int, Tables] = {}
        #: ``expand(vecs) -> particle vector``: master–slave's expansion when it depends on the
        #: state (finite-rotation links, set by ExplicitDynamics); ``None``: ``T_PF u + S u_M``.
        self.expand: Callable[[Sequence[PETSc.Vec]], PETSc.Vec] | None = None
        #: :meth:`particle_rows`' last columns and particles (held: compared by identity) and
        #: where their entries are on this rank
        self._rows: tuple | None = None

    def local_values(
        self, vecs: Sequence[PETSc.Vec], particles: bool = True, fe: bool = True
    ) -> tuple[dolfinx.fem.Function | None, np.ndarray | None]:
        """(FE Function with ghosts or None, particle coefficients (n, gdim) or None); with
        ``particles=False`` the particle coefficients are not gathered, with ``fe=False`` no
        FE Function is made (``None``)."""
        d = self.disc
        coeffs = None
        fe_out: dolfinx.fem.Function | None = None
        for f, x in zip(d.fields, vecs, strict=True):
            if (f.name != "fe" and not particles) or (f.name == "fe" and not fe):
                continue
            if f.name == "fe":
                fe_out = dolfinx.fem.Function(d.V)
                fe_out.x.array[: x.getLocalSize()] = x.array_r
                fe_out.x.scatter_forward()
            else:
                if self.expand is not None:  # master-slave with rotating links
                    full = self.expand(vecs)
                    owned = _gathered(full, self.comm)
                    full.destroy()
                elif d.reduction is not None:  # master-slave: u_P = T_PF u_FE + S u_M
                    Tpf, S = d.reduction
                    full = Tpf.createVecLeft()
                    Tpf.mult(vecs[0], full)
                    S.multAdd(x, full, full)
                    owned = _gathered(full, self.comm)
                    full.destroy()
                else:
                    owned = _gathered(x, self.comm)
                coeffs = owned.reshape(-1, d.gdim)[d.particles.petsc_index]
        return fe_out, coeffs

    def particle_rows(
        self, states: Sequence[Sequence[PETSc.Vec]], columns: np.ndarray
    ) -> list[np.ndarray]:
        """The particle coefficients ``(len(columns), gdim)`` of the particles ``columns`` in
        each state (dof vectors per field), on every rank: each rank puts in the entries it
        owns and one ``Allreduce`` sums them for all the states (exact: every entry comes from
        one rank, the others add zeros). The rows of :meth:`local_values`' coefficients, to
        the bit, without gathering every particle (collective). Master-slave's particle field
        (slaves expanded from the FE field) takes the full gather."""
        d = self.disc
        columns = np.asarray(columns, dtype=np.int64)
        if self.expand is not None or d.reduction is not None:
            return [self.local_values(vecs, fe=False)[1][columns] for vecs in states]
        k = next(i for i, f in enumerate(d.fields) if f.name != "fe")
        lo, hi = states[0][k].getOwnershipRange()  # every state's layout is the field's
        plan = self._rows
        if plan is None or plan[0] is not columns or plan[1] is not d.particles or plan[2] != lo:
            dofs = (d.gdim * d.particles.petsc_index[columns][:, None] + np.arange(d.gdim)).ravel()
            mine = np.flatnonzero((dofs >= lo) & (dofs < hi))
            plan = self._rows = (columns, d.particles, lo, dofs.size, mine, dofs[mine] - lo)
        out = np.zeros((len(states), plan[3]))
        for s, vecs in enumerate(states):
            out[s, plan[4]] = vecs[k].array_r[plan[5]]
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return [row.reshape(-1, d.gdim) for row in out]

    def at_points(self, vecs: Sequence[PETSc.Vec], points: npt.ArrayLike) -> np.ndarray:
        """The field with dof values ``vecs`` at this rank's points (m, gdim) -> (m, gdim).

        Raises:
            PointsOutsideMeshError: a point is outside the body (on every rank).
        """
        d = self.disc
        fe, coeffs = self.local_values(vecs)
        if coeffs is None:
            return evaluate_fe_function(fe, points)
        if fe is None:
            x = ensure_points_in_mesh(d.mesh, points)
            return d.mls.tabulate(x, 0).values @ coeffs
        return self._coupled(fe, coeffs).displacement(points)

    def solution(self, vecs: Sequence[PETSc.Vec]) -> CoupledSolution:
        """The field of ``vecs`` as a :class:`~dolfinx_meshfree.CoupledSolution` of this rank
        (its ``evaluate_at_quadrature`` at points of local cells: no search, no routing), the
        ramps' interface cells and the bridging band blended as the model blends them.
        Collective (the coefficients are gathered)."""
        return self._coupled(*self.local_values(vecs))

    def _coupled(self, fe: dolfinx.fem.Function, coeffs: np.ndarray) -> CoupledSolution:
        """The coupled solution of these values (the ramps' and bridging's blends)."""
        d = self.disc
        if isinstance(d.interface, BridgingBand):
            sol = BridgingSolution(u=fe, coefficients=coeffs, mls=d.mls, patch=d.patch)
            sol.band = d.interface
            return sol
        ramp = d.interface if isinstance(d.interface, RampInterface) else None
        return CoupledSolution(u=fe, coefficients=coeffs, mls=d.mls, patch=d.patch, interface=ramp)

    def at_cells(self, vecs: Sequence[PETSc.Vec], q: QuadraturePoints) -> np.ndarray:
        """The field at points of this rank's local cells ``q.cells`` (m, gdim), as
        :meth:`solution` evaluates it (collective)."""
        return self.solution(vecs).evaluate_at_quadrature(q)[0]

    def fe_function(self, vecs: Sequence[PETSc.Vec], name: str) -> dolfinx.fem.Function:
        """The FE field of ``vecs`` as a new Function named ``name`` (ghosts updated)."""
        fe, _ = self.local_values(vecs, particles=False)
        fe.name = name
        return fe

    def quadrature_tables(self, degree: int) -> Tables:
        """Cell quadrature and the maps ``(A_FE, A_P)`` (nq x local FE nodes, nq x particles)
        from FE nodal values and particle coefficients to the field at its points
        (:meth:`point_tables`; cached)."""
        if degree not in self._tables:
            q = cell_quadrature(self.disc.mesh, degree)
            self._tables[degree] = (q, *self.point_tables(q.points, q.cells))
        return self._tables[degree]

    def point_tables(
        self, points: np.ndarray, cells: np.ndarray
    ) -> tuple[sp.csr_matrix | None, sp.csr_matrix | None]:
        """The maps ``(A_FE, A_P)`` (m x local FE nodes, m x particles; ``None`` for a field
        the model lacks) from FE nodal values and particle coefficients to the field at points
        (m, gdim) of this rank's local ``cells`` (m,): FE on FE cells, MLS on particle cells,
        the ramp's blended functions on interface cells and ``(1 - alpha) N, alpha phi`` on
        bridging band cells. Collective (the MLS tabulation's errors are raised on every
        rank)."""
        d = self.disc
        points = np.asarray(points, dtype=float).reshape(-1, d.gdim)
        cells = np.asarray(cells, dtype=np.int32)
        nq = len(cells)
        on_p = d.on_particles(cells)
        blended = d.blended_cells()
        mixed = blended[cells] if blended is not None else np.zeros(nq, dtype=bool)
        n_fe = d.V.dofmap.index_map.size_local + d.V.dofmap.index_map.num_ghosts if d.V else 0
        n_p = d.particles.num_particles if d.particles is not None else 0
        parts_fe: list = []
        parts_p: list = []

        def add(parts: list, rows: np.ndarray, mat: sp.spmatrix) -> None:
            c = mat.tocoo()
            parts.append((rows[c.row], c.col, c.data))

        pure_fe = np.flatnonzero(~on_p & ~mixed)
        pure_p = np.flatnonzero(on_p & ~mixed)
        mix = np.flatnonzero(mixed)
        if d.V is not None and pure_fe.size:
            t = tabulate_in_cells(d.V, points[pure_fe], cells[pure_fe], 0).values
            add(parts_fe, pure_fe, t)
        if d.mls is not None:
            pts = points[pure_p]
            t = raise_on_all_ranks(self.comm, lambda: d.mls.tabulate(pts, 0)).values
            add(parts_p, pure_p, t)
        if blended is not None:
            t_fe, t_p = d.blended_tables(points[mix], cells[mix], self.comm)
            add(parts_fe, mix, t_fe)
            add(parts_p, mix, t_p)

        def assemble(parts: list, ncols: int) -> sp.csr_matrix | None:
            if not ncols:
                return None
            r, c, v = (np.concatenate([p[i] for p in parts] + [np.zeros(0)]) for i in range(3))
            return sp.csr_matrix((v, (r.astype(np.int64), c.astype(np.int64))), shape=(nq, ncols))

        return assemble(parts_fe, n_fe), assemble(parts_p, n_p)

    def at_quadrature(
        self, vecs: Sequence[PETSc.Vec], degree: int = 5
    ) -> tuple[QuadraturePoints, np.ndarray]:
        """Cell quadrature of degree ``degree`` on the owned cells and the field (nq, gdim)
        there."""
        q, A_fe, A_p = self.quadrature_tables(degree)
        fe, coeffs = self.local_values(vecs)
        gdim = self.disc.gdim
        vals = np.zeros((len(q), gdim))
        if A_fe is not None:
            vals += A_fe @ fe.x.array.reshape(-1, gdim)
        if A_p is not None:
            vals += A_p @ coeffs
        return q, vals

    def relative_error(
        self,
        vecs: Sequence[PETSc.Vec],
        exact: Callable[[np.ndarray, float], np.ndarray],
        time: float,
        degree: int = 5,
    ) -> float:
        """Relative L2 error ``|f_h - f| / |f|`` of the field against ``exact(points, time)``
        (Rabczuk et al. 2006, eq. 137), integrated on the owned cells (same on every rank)."""
        q, vh = self.at_quadrature(vecs, degree)
        ve = np.asarray(exact(q.points, time), dtype=float)
        s = np.array(
            [
                np.sum(q.weights * np.sum((vh - ve) ** 2, axis=1)),
                np.sum(q.weights * np.sum(ve**2, 1)),
            ]
        )
        s = self.comm.allreduce(s, op=MPI.SUM)
        return float(np.sqrt(s[0] / s[1])) if s[1] > 0 else float(np.sqrt(s[0]))
