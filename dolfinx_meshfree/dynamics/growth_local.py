"""Local update of a cracked explicit model after its crack grows (issue 11, item 2).

Belytschko et al. (1995), remark after eq. (3.11): the MLS shape functions change as the crack
grows, but only near the new segment ``S``. :mod:`~dolfinx_meshfree.statics.growth_update`
shows which rows of a shape table can change: those at points within ``R_1`` of ``S``
(:func:`~dolfinx_meshfree.statics.growth_update.change_radius`; every other row is the same
function of the same weights). The cell rule changes only in the cells ``S`` cuts
(:func:`~dolfinx_meshfree.geometry.cut_cells.cut_cell_quadrature` is cell by cell), plus any
cells whose rule the caller changes (``extra_cells``: the hook of an adaptive rule that moves
with the tip).

So an :class:`ExplicitDynamics <dolfinx_meshfree.ExplicitDynamics>` is updated in place, on the
cells ``C`` that hold a changed row (``C`` = the particle cells within ``R_1`` of ``S``, the
cells ``S`` cuts and ``extra_cells``): with the old rule and table on ``C`` (tabulated before the
crack moves) and the new ones (after),

* the particle stiffness (Belytschko et al. 1995, eq. 4.3, plain Gauss on the cut cells as the
  builders):  ``K += sum_{q in C, new} B^T D B w_q - sum_{q in C, old} B^T D B w_q``;
* the row-sum masses (eq. 4.5): ``M_II += rho (sum_{new} phi_I w_q - sum_{old} phi_I w_q)``,
  then ``M^{-1}``, the multiplier projection ``G M^{-1} G^T`` (Rabczuk et al. 2006, eq. 94–96)
  and the stable step (a new bound of the changed system) are rebuilt;
* the bridging band's weights ``alpha`` (Rabczuk et al. 2006, eq. 46, 89) are applied to the
  rule as the builder does;
* crack-face contact (:mod:`~dolfinx_meshfree.dynamics.crack_contact`): the faces' gap
  operator is rebuilt whole for the grown crack (its sample points along every face; cheap
  beside the tables of the cells) and the stable step sees its new stiffness.

Everything else is unchanged, bit for bit, unless a constraint row (interface multipliers,
edge-to-edge collocation, the bridging band's constraints and penalty, facet multipliers of
fixed facets) or a particle load has a particle within ``R_1 + r_J`` of ``S``: such a row may
change (a changed row at ``x`` has ``dist(x, S) < R_1`` and a particle ``J`` non-zero there,
``|x - x_J| < r_J``), and :meth:`LocalModelUpdate.prepare` then answers ``None``: the caller
rebuilds the model in full (:class:`~dolfinx_meshfree.dynamics.crack_growth.DynamicCrackGrowth`
does). The result equals a full rebuild to round-off (``tests/test_dynamic_growth_local.py``).

The model's rule degree is not stored in the model: :class:`LocalModelUpdate` checks it
(and that the masses are the rule's row sums, not ``rho V_I``) on the particles around the tip
when it is made, and refuses a mismatch.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from .. import _compat
from ..approx.tables import ShapeTable
from ..couplings.bridging import BridgingBand
from ..couplings.ramp import RampInterface
from ..geometry.adaptive_quadrature import changed_cells
from ..geometry.crack import Crack
from ..geometry.cut_cells import cut_cell_quadrature
from ..geometry.quadrature import QuadraturePoints
from ..parallel import raise_on_all_ranks
from ..physics.materials import LinearElastic
from ..physics.operators import stiffness_matrix
from ..statics.growth_update import change_radius, new_segments
from ..statics.petsc import create_aij
from .constraint import VelocityProjection
from .crack_contact import ContactSystem
from .energy import strain_energy
from .linalg import blocked
from .masses import particle_lumped_mass
from .sifs import model_cracks
from .system import LinearSystem
from .time_step import TimeStepBound

if TYPE_CHECKING:  # annotations only
    from .explicit import ExplicitDynamics

__all__ = ["LocalModelUpdate", "Plan"]

Rule = Callable[[np.ndarray, Sequence[Crack]], QuadraturePoints]


@dataclass
class Plan:
    """An update prepared before the crack moves: the new segments, the radius, the cells
    ``C`` and the old rule, weights and table there."""

    segments: np.ndarray
    radius: float
    cells: np.ndarray
    old: tuple[QuadraturePoints, np.ndarray, ShapeTable]


class LocalModelUpdate:
    """Updates a cracked explicit model in place after its crack is extended (module
    docstring). Collective throughout.

    Args:
        dyn: A linear elastic :class:`~dolfinx_meshfree.ExplicitDynamics` with cracks: pure
            EFG or a coupling of :data:`~dolfinx_meshfree.CRACK_COUPLINGS` (lagrange,
            edge-to-edge, bridging) on cells, row-sum particle masses.
        quadrature_degree: The degree of the model's cell rule (the builders' default 7).

    Attributes:
        rule: ``rule(cells, cracks) -> QuadraturePoints``: the cell rule of the model on
            ``cells`` (default: the cut-cell rule of ``quadrature_degree``). An adaptive rule
            replaces it and passes the cells whose rule it changed as ``extra_cells``.
        last: What the last update did (``mode``, cells, points, radius), or why it was
            refused (``mode="full"``, ``reason``).

    Raises:
        ValueError: on every rank: not such a model, or its masses are not the row sums of the
            rule of ``quadrature_degree`` around the tip (another degree, or ``rho V_I``).
    """

    def __init__(self, dyn: ExplicitDynamics, quadrature_degree: int = 7) -> None:
        self.dyn = dyn
        self.degree = int(quadrature_degree)
        self.cracks, domain = model_cracks(dyn)
        comm = dyn.comm

        #: The faces' contact (:class:`~dolfinx_meshfree.dynamics.crack_contact.ContactSystem`
        #: around the linear system), whose operator :meth:`apply` rebuilds; or ``None``.
        self.contact = dyn.system if isinstance(dyn.system, ContactSystem) else None
        linear = dyn.system if self.contact is None else self.contact.inner

        def check() -> int:
            if not isinstance(linear, LinearSystem) or not isinstance(dyn.material, LinearElastic):
                raise ValueError(
                    "update='local' needs a small-strain model (LinearElastic, a LinearSystem); "
                    "use update='full'"
                )
            names = [f.name for f in dyn.fields]
            ramp = isinstance(dyn.interface, RampInterface)  # blended cells: no local update
            if not self.cracks or "particles" not in names or dyn.reduction is not None or ramp:
                raise ValueError(
                    "update='local' needs a cracked particle model (pure EFG, lagrange, "
                    "edge-to-edge or bridging); use update='full'"
                )
            return names.index("particles")

        self.k = raise_on_all_ranks(comm, check)
        P = dyn.particles
        self.cells = (dyn.patch.particles.cells if dyn.patch is not None else domain.cells).astype(
            np.int64
        )
        msh = dyn.mesh
        self._geo = msh.geometry.x[_compat.entities_to_geometry(msh, 2, self.cells), :2]
        self._mid = self._geo.mean(axis=1)
        self._reach = np.linalg.norm(self._geo - self._mid[:, None], axis=2).max(axis=1)
        self._inv = np.empty(P.num_particles, dtype=np.int64)
        self._inv[P.petsc_index] = np.arange(P.num_particles)
        self.quadrature = getattr(dyn, "quadrature", None)
        if self.quadrature is None:
            self.rule: Rule = lambda c, cracks: cut_cell_quadrature(msh, c, cracks, self.degree)
        else:  # the model's adaptive rule: its dense zone moves with the tips
            adaptive = self.quadrature
            self.rule = lambda c, cracks: adaptive.rule(msh, c, cracks)
        self.last: dict = {}
        self._check_masses()

    # -- pieces ---------------------------------------------------------------------------------
    def _weights(self, q: QuadraturePoints) -> np.ndarray:
        """The rule's weights as the model integrates them: times ``alpha`` on bridging band
        cells (Rabczuk et al. 2006, eq. 46, 89)."""
        w = q.weights.copy()
        band = self.dyn.interface
        if isinstance(band, BridgingBand):
            b = band.in_band[q.cells]
            w[b] *= band.alpha_at(q.points[b], q.cells[b])
        return w

    def _tabulate(self, cells: np.ndarray) -> tuple[QuadraturePoints, np.ndarray, ShapeTable]:
        q = raise_on_all_ranks(self.dyn.comm, lambda: self.rule(cells, self.cracks))
        tab = raise_on_all_ranks(self.dyn.comm, lambda: self.dyn.mls.tabulate(q.points))
        return q, self._weights(q), tab

    def _cells_near(self, segments: np.ndarray, radius: float) -> np.ndarray:
        """The particle cells (this rank's) with a point within ``radius`` of ``segments``."""
        return self.cells[_distance(self._mid, segments) < radius + self._reach]

    def _mass_delta(self, new: tuple, old: tuple | None) -> PETSc.Vec:
        """``rho (sum_new phi_I w - sum_old phi_I w)`` per particle dof (collective)."""
        vals, w = new[2].values, new[1]
        if old is not None:
            vals, w = sp.vstack([vals, old[2].values], format="csr"), np.concatenate([w, -old[1]])
        rho = self.dyn.material.rho
        return particle_lumped_mass(self.dyn.particles, vals, w, rho, check=False)

    def _check_masses(self) -> None:
        """The model's masses of the particles whose support lies in the cells around the tip
        equal the row sums of :attr:`rule` there (to 1e-10), else a ``ValueError``."""
        dyn, P, comm = self.dyn, self.dyn.particles, self.dyn.comm
        tips = np.array([c.points[e] for c in self.cracks for e in c.tip_ends]).reshape(-1, 2)
        r = dyn.mls.radii
        span = 3.0 * float(r.max()) + 2.0 * comm.allreduce(
            float(self._reach.max(initial=0.0)), op=MPI.MAX
        )
        seg = np.stack([tips, tips], axis=1)
        cells = self._cells_near(seg, span) if tips.size else self.cells[:0]
        m = self._mass_delta(self._tabulate(cells), None)
        # particles whose support (radius r_I) meets only cells with a midpoint within span
        x = P.positions[:, :2]
        reach = comm.allreduce(float(self._reach.max(initial=0.0)), op=MPI.MAX)
        dist = _distance(x, seg)
        inside = dist + r + 2.0 * reach < span
        owned = self._owned_particles()
        on = np.repeat(inside[owned], P.gdim)
        mine = dyn.fields[self.k].mass.array_r[on]
        theirs = m.array_r[on]
        m.destroy()
        err = float(np.abs(mine - theirs).max(initial=0.0))
        scale = float(np.abs(mine).max(initial=0.0))
        err, scale = comm.allreduce(err, op=MPI.MAX), comm.allreduce(scale, op=MPI.MAX)
        count = comm.allreduce(int(on.sum()), op=MPI.SUM)

        def check() -> None:
            if count == 0 or err > 1e-10 * scale:
                raise ValueError(
                    f"update='local': the model's particle masses near the tip are not the row "
                    f"sums of its cut-cell rule of quadrature_degree={self.degree} (difference "
                    f"{err:.3g} of {scale:.3g} on {count} dofs): pass the model's "
                    "quadrature_degree, or update='full' (e.g. particle_mass='volume')"
                )

        raise_on_all_ranks(comm, check)

    def _owned_particles(self) -> np.ndarray:
        """Local indices of the owned particles in PETSc order."""
        return self.dyn.evaluator.disc.owned_particles()

    def _touched(self, segments: np.ndarray, radius: float, rule_only: bool = False) -> str | None:
        """Why a constraint row or a particle load may change (a particle ``J`` of it within
        ``radius + r_J`` of ``segments``), or ``None`` (collective). ``rule_only``: only the
        cell rule changes there (not the shape functions): constraint rows (on facets or at
        points) and tractions keep, unless bridging ties over band cells or a body force was
        added (both integrated with the cell rule)."""
        dyn, P = self.dyn, self.dyn.particles
        r, x, gdim = dyn.mls.radii, P.positions[:, :2], P.gdim

        def near(ids: np.ndarray) -> bool:
            if ids.size == 0:
                return False
            return bool(np.any(_distance(x[ids], segments) < radius + r[ids]))

        reasons = []

        def columns(A: PETSc.Mat) -> np.ndarray:  # the particles of A's non-zero columns
            _, cols, vals = A.getValuesCSR()
            return self._inv[np.unique(np.asarray(cols)[np.asarray(vals) != 0.0]) // gdim]

        G = dyn.G[self.k] if dyn.G is not None else None
        banded = isinstance(dyn.interface, BridgingBand)
        if G is not None and (banded or not rule_only):
            reasons.append("a constraint row" if near(columns(G)) else None)
        for (_, j), B in dyn.blocks.items():  # the bridging penalty's FE-particle block
            if j == self.k:
                reasons.append("a coupling block" if near(columns(B)) else None)
        owned = self._owned_particles()
        for vecs, _ in dyn.loads.loads if dyn.loads.body_forces or not rule_only else ():
            b = vecs[self.k]
            if b is not None:
                on = np.flatnonzero(b.array_r.reshape(-1, gdim).any(axis=1))
                reasons.append("a particle load" if near(owned[on]) else None)
        mine = next((s for s in reasons if s is not None), "")
        every = dyn.comm.allgather(mine)
        return next((s for s in every if s), None)

    # -- the update -----------------------------------------------------------------------------
    def prepare(
        self, grown: np.ndarray, crack: Crack, extra_cells: np.ndarray | None = None
    ) -> Plan | None:
        """Before ``crack`` (one of the model's) is extended to the points ``grown``: the new
        segments, the cells whose rows change and their old rule and table; ``None`` when the
        change reaches a constraint row or a particle load, or is not an extension (the
        caller rebuilds in full; :attr:`last` says why). Collective."""
        segs = new_segments(crack.points, np.asarray(grown, dtype=float))
        if segs is None or segs.shape[0] == 0:
            self.last = {"mode": "full", "reason": "not an extension at the crack's ends"}
            return None
        R = change_radius(self.dyn.mls, segs)
        why = self._touched(segs, R)
        if why is not None:
            self.last = {"mode": "full", "reason": f"{why} within reach of the new segment"}
            return None
        cells = self._cells_near(segs, R)
        if self.quadrature is not None:  # the cells entering or leaving the dense zone
            old = [c.points.copy() for c in self.cracks]
            new = [np.asarray(grown, dtype=float) if c is crack else p
                   for c, p in zip(self.cracks, old, strict=True)]  # fmt: skip
            moved = changed_cells(self.dyn.mesh, self.cells, old, new, self.quadrature)
            extra_cells = moved if extra_cells is None else np.union1d(extra_cells, moved)
        if extra_cells is not None:
            extra_cells = np.asarray(extra_cells, dtype=np.int64)
            ends = np.repeat(self._mid[np.isin(self.cells, extra_cells)][:, None], 2, axis=1)
            reach = self.dyn.comm.allreduce(float(self._reach.max(initial=0.0)), op=MPI.MAX)
            why = self._touched(ends, reach, rule_only=True)
            if why is not None:
                self.last = {"mode": "full", "reason": f"{why} on a cell whose rule changes"}
                return None
            cells = np.union1d(cells, extra_cells)
        return Plan(segs, R, cells, self._tabulate(cells))

    def apply(self, plan: Plan) -> float:
        """After the crack moved: add the new minus the old contributions of ``plan.cells`` to
        the particle stiffness and masses, rebuild ``M^{-1}``, the projection and the stable
        step, and project the state onto the constraint in the new mass metric. Returns the
        strain energy released at ``d_n`` (old minus new ``1/2 d^T K d``). Collective.

        Raises:
            ValueError: on every rank, a lumped particle mass that is no longer positive.
        """
        dyn, comm, k = self.dyn, self.dyn.comm, self.k
        P, st = dyn.particles, dyn.stepper
        before = self._energy()
        new = self._tabulate(plan.cells)
        old = plan.old
        gdim = P.gdim
        grads = [
            sp.vstack([a, b], format="csr")
            for a, b in zip(new[2].gradients, old[2].gradients, strict=True)
        ]
        w = np.concatenate([new[1], -old[1]])
        dK_loc = stiffness_matrix(grads, w, dyn.material, grads, P.petsc_index)
        pl = P.dof_layout(gdim)
        dK = create_aij(comm, dK_loc, pl, pl)
        K = dyn.fields[k].K
        if K.getType() != dK.getType():
            B = blocked(dK, gdim, "baij" if "baij" in K.getType() else "aij")
            if B is not None:
                dK.destroy()
                dK = B
        K.axpy(1.0, dK, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        dK.destroy()
        dm = self._mass_delta(new, old)
        mass = dyn.fields[k].mass
        mass.axpy(1.0, dm)
        dm.destroy()
        m, free = mass.array_r, dyn.free[k]
        lo = comm.allreduce(float(m[dyn.active[k]].min(initial=np.inf)), op=MPI.MIN)

        def check() -> None:
            if not lo > 0.0:
                tip = np.round(plan.segments[-1, 1], 12).tolist()
                raise ValueError(
                    f"a lumped particle mass is not positive (min {lo:.3e}) after the crack grew "
                    f"to {tip}: a shape function integrates to <= 0 on the cut cells; raise the "
                    "quadrature degree or the dilation"
                )

        raise_on_all_ranks(comm, check)
        st.minv[k].array[:] = np.where(free, 1.0 / np.where(m > 0.0, m, 1.0), 0.0)
        if self.contact is not None:  # the faces grew: their gap operator, from scratch
            self.contact.refresh()
        if dyn.projection is not None:
            proj = VelocityProjection(
                dyn.G, st.minv, comm, dyn.projection.solver, dyn.projection.product
            )
            dyn.projection.destroy()
            dyn.projection = st.projection = proj
            held = dyn.loads.motion  # driven rows (prescribed velocities) keep their values
            for x in (st.u, st.v):
                proj.correct(x, target=None if held is None else held.kept(dyn.G, x))
        dyn.bound = TimeStepBound(dyn.system, dyn.material, st.minv, dyn.free, comm, dyn.safety)
        dyn.evaluator._tables.clear()  # the cached quadrature tables of the old approximation
        dyn.loads.body_load = _stale_body_load
        self.last = {
            "mode": "local",
            "cells": int(comm.allreduce(plan.cells.size, op=MPI.SUM)),
            "points": int(comm.allreduce(len(new[0]) + len(old[0]), op=MPI.SUM)),
            "radius": plan.radius,
        }
        return before - self._energy()

    def _energy(self) -> float:
        return strain_energy(self.dyn.system, self.dyn.stepper.u)


def _distance(x: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance (m,) from points ``x`` (m, 2) to the nearest of ``segments`` (k, 2, 2), which
    may have length zero (points)."""
    a, b = segments[:, 0], segments[:, 1]
    t = b - a
    r = x[:, None, :] - a[None, :, :]
    tt = np.einsum("kd,kd->k", t, t)
    xi = np.clip(np.einsum("mkd,kd->mk", r, t) / np.where(tt > 0, tt, 1.0), 0.0, 1.0)
    return np.linalg.norm(r - xi[..., None] * t[None], axis=-1).min(axis=1, initial=np.inf)


def _stale_body_load(force: object) -> tuple:
    raise ValueError(
        "add_body_force after a local crack update: the builder's body-load rule predates the "
        "grown crack; add body forces in build(crack), before the growth runs"
    )
