"""Frictionless crack-face contact in explicit dynamics: a one-sided penalty on the normal gap.

The faces of a crack in a particle model are traction-free (natural) while they open; under
compression they would interpenetrate, since the crack-aware MLS (visibility or diffraction,
:mod:`~dolfinx_meshfree.approx.crack_cuts`) lets the two sides move independently. This module
adds the contact of the faces (frictionless, small strain) as a penalty on the normal gap.

Along each crack polyline, sample points ``x_q`` with weights ``w_q`` (Gauss–Legendre points on
pieces of at most one particle spacing ``h``, up to the tips by default: the jump vanishes at
a tip, and the faces' term of the stress intensity factors, :func:`face_term`, wants the faces
closed there too) carry the normal gap

.. math::
    g_q = n_q \\cdot (u^+(x_q) - u^-(x_q)) = (B d)_q, \\qquad
    u^\\pm(x_q) = \\sum_J \\phi_J^\\pm(x_q) d_J,

with ``n_q`` the left normal of the segment (pointing to the ``+1`` side of
:meth:`~dolfinx_meshfree.Crack.side`) and ``phi^±`` the one-sided limits of the crack-aware MLS
(``MLS.tabulate(..., sides=±1)``). ``g < 0`` is interpenetration. The penalty energy and its
force (added to the internal force, the sign of ``M a + f^int = f^ext``) are

.. math::
    E_c = \\tfrac12 \\sum_q k w_q \\min(g_q, 0)^2, \\qquad
    f_c = \\partial E_c / \\partial d = B^T (k w \\min(B d, 0)),

one-sided: ``f_c = 0`` exactly while every face point is open (``g >= 0``). Central
differences then conserve ``kinetic + strain + E_c`` up to a drift that falls with the step (a
conservative but non-smooth force: measured 9.6e-4, 1.1e-4, 4.1e-5 at dt, dt/2, dt/4 for faces
that hit and bounce; round-off while they stay closed or open);
:meth:`ContactSystem.strain_energy` includes ``E_c``. The penalty stiffens the closed faces:
the stable step is bounded with the full contact stiffness ``K + k B^T W B`` (every point
closed, an upper bound of the tangent of any contact state in the PSD order), so the step is
safe whatever the state.

The penalty ``k`` (a normal stiffness per unit face area, Pa/m) is ``factor * E / h`` by
default (:class:`CrackContact`): under a compressive normal stress ``sigma`` the faces then
penetrate by ``|g| = sigma / k = (sigma / E) h / factor``, i.e. ``1 / factor`` of the elastic
shortening of a strip of one particle spacing; the contact springs add about ``factor * E`` to
the particle stiffness of the face particles, which lowers the stable step (see
:class:`CrackContact`). Stress intensity factors with contact:
:func:`~dolfinx_meshfree.dynamics.sifs.dynamic_sifs` adds :func:`face_term`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from ..approx.tables import ShapeTable
from ..fracture.interaction import StressIntensityFactors, q_weight
from ..geometry.crack import Crack, CrackDomain, particle_spacing
from ..geometry.crack_faces import contact_points, owned_points
from ..geometry.quadrature import gauss_legendre
from ..parallel import Layout, raise_on_all_ranks
from ..statics.petsc import create_aij
from .discretisation import approximation_cracks
from .linalg import add_weighted_gram
from .system import LinearSystem, SemiDiscreteSystem, WrappedSystem

if TYPE_CHECKING:  # annotations only
    from ..approx.mls import MLS
    from ..geometry.particles import ParticleSet
    from ..physics.materials import LinearElastic
    from .builders import Model

__all__ = [
    "ContactSystem",
    "CrackContact",
    "FaceTerm",
    "contact_points",
    "face_term",
    "jump_operator",
    "owned_points",
    "with_crack_contact",
]


@dataclasses.dataclass(frozen=True)
class CrackContact:
    """Options of frictionless crack-face contact (a penalty on the normal gap).

    Attributes:
        factor: The penalty ``k = factor * E / h`` (``h`` the particle spacing) when
            ``penalty`` is ``None``. The default 10 keeps the penetration at 1/10 of the elastic
            shortening of a one-spacing strip (the accurate choice: the penetration falls like
            ``1/k``, measured slopes 0.99-1.02); its cost is the stable step, which the bound
            sees: 0.26x the step without contact on the tests' unit square (factor 1: 0.68x,
            100: 0.08x), 0.30x in Kalthoff–Winkler (3.3x the steps).
        penalty: ``k`` itself (Pa/m), or ``None``.
        points: Gauss–Legendre points per piece of the polylines (pieces at most ``h`` long).
        tip_gap: Points closer than ``tip_gap * h`` to a tip are left out (default 0: none;
            the faces' term of the SIFs then sees closed faces up to the tip: a compressed
            crack's K_I/K0 -0.011 against -0.027 with ``tip_gap=1``).
    """

    factor: float = 10.0
    penalty: float | None = None
    points: int = 2
    tip_gap: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.factor) and self.factor > 0.0):
            raise ValueError(f"factor={self.factor!r} must be a positive number (k = factor E/h)")
        if self.penalty is not None and not (np.isfinite(self.penalty) and self.penalty > 0.0):
            raise ValueError(f"penalty={self.penalty!r} must be a positive number (Pa/m) or None")
        if isinstance(self.points, bool) or not (isinstance(self.points, int) and self.points >= 1):
            raise ValueError(f"points={self.points!r} must be an integer >= 1 (Gauss points)")
        if not (np.isfinite(self.tip_gap) and self.tip_gap >= 0.0):
            raise ValueError(f"tip_gap={self.tip_gap!r} must be >= 0 (in particle spacings)")

    def stiffness(self, E: float, h: float) -> float:
        """``k``: :attr:`penalty`, else ``factor * E / h``."""
        return float(self.penalty) if self.penalty is not None else self.factor * E / h


def jump_operator(
    particles: ParticleSet, mls: MLS, cracks: Sequence[Crack], h: float, contact: CrackContact
) -> tuple[PETSc.Mat, np.ndarray, np.ndarray, np.ndarray]:
    """The normal-gap operator ``B`` (rows: this rank's sample points; columns: the particle
    dofs in PETSc order), the rows' points and unit normals (owned rows, (m, 2) each) and their
    length weights ``w`` (m,), collective.

    ``B[q, (J, c)] = n_qc (phi_J^+(x_q) - phi_J^-(x_q))`` (see the module docstring).
    """
    gdim = particles.gdim
    dof_map = particles.petsc_dofs(gdim)
    rows, cols, vals, weights, where, normals = [], [], [], [], [], []
    count = 0
    for crack in cracks:
        x, n, w = contact_points(crack, h, contact.points, contact.tip_gap)
        own = owned_points(particles, x)
        x, n, w = x[own], n[own], w[own]
        ones = np.ones(len(x), dtype=np.int64)
        plus, minus = raise_on_all_ranks(
            particles.comm,
            lambda x=x, ones=ones: (
                (mls.tabulate(x, 0, ones), mls.tabulate(x, 0, -ones)) if len(x) else (None, None)
            ),
        )
        if len(x):
            jump = (plus.values - minus.values).tocoo()
            for c in range(gdim):
                rows.append(count + jump.row)
                cols.append(dof_map[jump.col, c])
                vals.append(jump.data * n[jump.row, c])
        weights.append(w)
        where.append(x)
        normals.append(n)
        count += len(x)
    layout = Layout.from_local(particles.comm, count)
    cat = lambda parts, dt: np.concatenate([*parts, np.zeros(0, dt)])  # noqa: E731
    local = sp.csr_matrix(
        (cat(vals, float), (cat(rows, np.int64) + layout.start, cat(cols, np.int64))),
        shape=(layout.size_global, gdim * particles.num_particles),
    )
    B = create_aij(particles.comm, local, layout, particles.dof_layout(gdim))
    empty = np.zeros((0, 2))
    return (
        B,
        np.concatenate([*where, empty]),
        np.concatenate([*normals, empty]),
        cat(weights, float),
    )


class ContactSystem(WrappedSystem):
    """A :class:`~dolfinx_meshfree.dynamics.system.SemiDiscreteSystem` with crack-face contact:
    the inner system's internal force plus ``f_c = B^T (k w min(B d, 0))`` on one field (the
    particles), its strain energy plus ``E_c``, its tangent plus the full contact stiffness
    ``k B^T W B`` (for the stable step). Everything else is the inner system's.

    Args:
        inner: The system without contact (small strain).
        B: The normal-gap operator (:func:`jump_operator`) on the columns of field ``field``.
        kw: ``k w_q`` per owned row of ``B``.
        field: The index of the particle field.
        points, normals, weights: The rows' points and unit normals (m, 2) and length weights
            ``w_q`` (m,).
        remake: ``remake() -> (B, points, normals, weights)``: the operator of the current
            faces (:func:`jump_operator` of the model's cracks, which a local update extends in
            place), for :meth:`refresh`; ``None``: the faces never change.
        k: The penalty ``k`` (``kw = k w``), for :meth:`refresh`.
    """

    def __init__(
        self,
        inner: SemiDiscreteSystem,
        B: PETSc.Mat,
        kw: np.ndarray,
        field: int,
        points: np.ndarray,
        normals: np.ndarray,
        weights: np.ndarray,
        remake: Callable[[], tuple[PETSc.Mat, np.ndarray, np.ndarray, np.ndarray]] | None = None,
        k: float | None = None,
    ) -> None:
        super().__init__(inner)
        self.field = field
        self.remake, self.k = remake, k
        self._tangent: PETSc.Mat | None = None
        self._set(B, kw, points, normals, weights)

    def _set(
        self,
        B: PETSc.Mat,
        kw: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        weights: np.ndarray,
    ) -> None:
        self.B = B
        self.kw = np.asarray(kw, dtype=float)
        self.points, self.normals = np.asarray(points, float), np.asarray(normals, float)
        self.weights = np.asarray(weights, float)
        self._gap = B.createVecLeft()
        self._force = B.createVecRight()
        self.num_points = B.getSize()[0]

    def refresh(self) -> None:
        """Rebuild the faces' operator for the current cracks (after a local update extended
        them: new sample points on the new segments, the one-sided shape functions changed
        near them) and drop the cached contact stiffness of the stable-step bound; the state
        is untouched (collective).

        Raises:
            ValueError: on every rank, a system made without ``remake`` and ``k``.
        """
        if self.remake is None or self.k is None:  # the same on every rank
            raise ValueError(
                "this ContactSystem was made without remake= and k=: it cannot follow a grown "
                "crack; build it with with_crack_contact, or rebuild the model"
            )
        B, x, n, w = self.remake()
        for obj in (self.B, self._gap, self._force, self._tangent):
            if obj is not None:
                obj.destroy()
        self._tangent = None
        self._set(B, self.k * w, x, n, w)

    def gap(self, u: Sequence[PETSc.Vec]) -> np.ndarray:
        """The normal gaps ``g = B d`` at this rank's sample points (a copy)."""
        self.B.mult(u[self.field], self._gap)
        return self._gap.array_r.copy()

    def _multipliers(self, u: Sequence[PETSc.Vec]) -> float:
        """Put ``k w min(g, 0)`` into the gap vector; return this rank's ``E_c``."""
        self.B.mult(u[self.field], self._gap)
        closed = np.minimum(self._gap.array_r, 0.0)
        self._gap.array[:] = self.kw * closed
        return 0.5 * float(np.dot(self.kw, closed * closed))

    def contact_energy(self, u: Sequence[PETSc.Vec]) -> float:
        """``E_c = 1/2 sum_q k w_q min(g_q, 0)^2`` (collective, every rank)."""
        return float(self.B.getComm().tompi4py().allreduce(self._multipliers(u), op=MPI.SUM))

    def internal_force(
        self, u: Sequence[PETSc.Vec], out: Sequence[PETSc.Vec] | None = None
    ) -> list[PETSc.Vec]:
        """The inner force plus ``B^T (k w min(B d, 0))`` (collective)."""
        y = self.inner.internal_force(u, out)
        self._multipliers(u)
        self.B.multTransposeAdd(self._gap, y[self.field], y[self.field])
        return y

    def strain_energy(self, u: Sequence[PETSc.Vec], f_int: Sequence[PETSc.Vec]) -> float:
        """The inner system's energy (from ``f_int`` minus the contact force) plus ``E_c``."""
        energy = self.contact_energy(u)  # leaves k w min(g, 0) in the gap vector
        self.B.multTranspose(self._gap, self._force)
        inner_f = list(f_int)
        inner_f[self.field] = f_int[self.field].copy()
        inner_f[self.field].axpy(-1.0, self._force)
        energy += self.inner.strain_energy(u, inner_f)
        inner_f[self.field].destroy()
        return energy

    def tangent(self, u: Sequence[PETSc.Vec] | None = None) -> dict:
        """The inner tangent with ``k B^T W B`` (every point closed) added to the particle
        block: an upper bound, in the PSD order, of the tangent of any contact state."""
        blocks = dict(self.inner.tangent(u))
        if self._tangent is None:
            K = blocks[self.field, self.field].convert("aij", PETSc.Mat())  # a new matrix
            add_weighted_gram(K, self.B, self.kw)
            self._tangent = K
        blocks[self.field, self.field] = self._tangent
        return blocks

    def destroy(self) -> None:
        """Destroy the contact objects and the inner system (collective)."""
        for obj in (self.B, self._gap, self._force, self._tangent):
            if obj is not None:
                obj.destroy()
        self.inner.destroy()


def face_term(
    mls: MLS,
    coefficients: np.ndarray,
    material: LinearElastic,
    crack: Crack,
    sifs: StressIntensityFactors,
    weight: str = "linear",
    points: int = 16,
) -> np.ndarray:
    """The crack-face term of the domain interaction integral for closed faces: ``Delta K_I``
    per domain of ``sifs`` (no communication: the coefficients are replicated).

    The domain integral of :func:`~dolfinx_meshfree.interaction_integral` assumes traction-free
    faces; a normal face pressure ``p`` adds ``-int_faces t . u^aux_,1 q ds``, which on the
    straight faces behind the tip (``theta = +-pi``) is ``2 int_0^r2 p(r) q(r) / sqrt(2 pi r)
    dr`` for K_I (the weight function of a semi-infinite crack under face pressure; Tada, Paris
    & Irwin) and 0 for K_II (the auxiliary mode II field has ``u_2,1 = 0`` on the faces; no
    shear traction without friction). ``p = -n . sigma n`` is the field's own normal stress
    (the mean of the two faces' limits) where the faces are closed (``g < 0``), 0 where they
    are open: consistent with the domain integral of the same field (a uniform stress across
    closed faces gives K = 0 whatever the penalty; the penalty's ``k |g|`` is too small near the
    tip, where the jump of the shape functions vanishes). The rule is Gauss in ``s`` with
    ``r = r2 s^2`` (``points`` points), which removes the ``1/sqrt(r)``.

    Args:
        mls: The crack-aware approximation. coefficients: Its particle coefficients (n, 2).
        material: The law. crack: The crack of ``sifs``' tip.
        sifs: The domain integral's result (tip, direction, radii).
        weight: ``q``, one of :data:`~dolfinx_meshfree.fracture.interaction.Q_WEIGHTS`.
    """
    term = FaceTerm(mls, crack, sifs.tip, sifs.direction, sifs.inner, sifs.outer, weight, points)
    return term(coefficients, material)


class FaceTerm:
    """:func:`face_term` with its shape functions tabulated once: the two faces' MLS values
    and gradients at the rule's points behind one tip (local). The term is not linear in the
    field (a face pair counts where it is closed), but the gap and the pressure at the points
    are: a call is a few products. The tables belong to one MLS version (the caller keeps it).

    Args:
        mls: The crack-aware approximation. crack: The crack of the tip.
        tip, direction: The tip and the crack's tangent ahead of it.
        inner, outer: The domains' radii (k,). weight, points: As :func:`face_term`.
    """

    def __init__(
        self,
        mls: MLS,
        crack: Crack,
        tip: np.ndarray,
        direction: np.ndarray,
        inner: np.ndarray,
        outer: np.ndarray,
        weight: str = "linear",
        points: int = 16,
    ) -> None:
        s, ws = gauss_legendre(points)
        s, ws = 0.5 * (s + 1.0), 0.5 * ws
        d = np.asarray(direction, dtype=float)
        self.normal = np.array([-d[1], d[0]])
        xs, ups = [], []
        #: per domain: its rows of the tables and its rule's factors
        self.domains: list[tuple[slice, np.ndarray]] = []
        for r1, r2 in zip(inner, outer, strict=True):
            r = r2 * s * s
            x = np.asarray(tip, dtype=float)[None, :] - r[:, None] * d[None, :]
            up = crack.side(x + 1e-6 * r2 * self.normal[None, :])  # the side n points to
            q = q_weight(r, r1, r2, weight)
            # int_0^r2 f(r) / sqrt(r) dr = 2 sqrt(r2) int_0^1 f(r2 s^2) ds
            factor = 2.0 * 2.0 * np.sqrt(r2) * ws * q / np.sqrt(2.0 * np.pi)
            start = sum(len(v) for v in xs)
            self.domains.append((slice(start, start + len(x)), factor))
            xs.append(x)
            ups.append(up)
        # every domain's points in one table per face (each point's functions are its own)
        x_all = np.concatenate(xs) if xs else np.zeros((0, 2))
        up_all = np.concatenate(ups) if ups else np.zeros(0, dtype=np.int64)
        up, down = mls.tabulate(x_all, 1, up_all), mls.tabulate(x_all, 1, -up_all)
        tables = [up.values, *up.gradients, down.values, *down.gradients]
        #: the particles whose functions the tables hold (sorted); the tables' columns
        self.columns = np.unique(np.concatenate([t.indices for t in tables]).astype(np.int64))
        #: the faces' table: the upper face's points, then the lower face's (one product for
        #: both: each row's sum is its own, so the values are those of two tables)
        self.tables = _on_columns(
            ShapeTable(
                np.concatenate([x_all, x_all]), sp.vstack([up.values, down.values], "csr"),
                [sp.vstack(g, "csr") for g in zip(up.gradients, down.gradients, strict=True)],
                up.version,
            ),
            self.columns,
        )  # fmt: skip

    def __call__(self, coefficients: np.ndarray, material: LinearElastic) -> np.ndarray:
        """``Delta K_I`` (k,) of the particle coefficients (n, 2)."""
        return self.on_columns(coefficients[self.columns], material)

    def on_columns(self, coefficients: np.ndarray, material: LinearElastic) -> np.ndarray:
        """:meth:`__call__` from the rows of :attr:`columns` only (p, 2): the same term to
        the bit (the tables' entries and their order are the tabulation's)."""
        n, m = self.normal, self.tables.shape[0] // 2
        values = self.tables.values @ coefficients
        gap = (values[:m] - values[m:]) @ n
        stress = material.stress(self.tables.gradient(coefficients))
        sigma = 0.5 * (stress[:m] + stress[m:])
        p = np.where(gap < 0.0, -np.einsum("i,mij,j->m", n, sigma, n), 0.0)
        out = np.zeros(len(self.domains))
        for k, (rows, factor) in enumerate(self.domains):
            out[k] = np.sum(factor * p[rows])
        return out


def _on_columns(table: ShapeTable, columns: np.ndarray) -> ShapeTable:
    """``table`` with the sorted ``columns`` (every column it stores) as its only columns:
    the same entries in the same order, renumbered (a product's sums are unchanged)."""
    where = np.full(table.shape[1], -1, dtype=np.int64)
    where[columns] = np.arange(columns.size)

    def compact(t: sp.csr_matrix) -> sp.csr_matrix:
        return sp.csr_matrix((t.data, where[t.indices], t.indptr), shape=(t.shape[0], columns.size))

    return ShapeTable(table.points, compact(table.values), [compact(g) for g in table.gradients],
                      table.version)  # fmt: skip


def with_crack_contact(model: Model, contact: CrackContact | None) -> Model:
    """``model`` with crack-face contact on its particle field (collective): its system becomes
    a :class:`ContactSystem` around the linear system of its blocks; ``model`` itself when
    ``contact`` is ``None`` or no crack cuts its particles (the patch's cracks, or those
    attached to the MLS of pure EFG:
    :func:`~dolfinx_meshfree.dynamics.discretisation.approximation_cracks`).

    Args:
        model: A small-strain particle or coupled model.
        contact: The options, or ``None``: no contact.
    """
    if contact is not None and not isinstance(contact, CrackContact):  # the same on every rank
        raise TypeError(
            f"crack_contact must be a CrackContact or None, got {type(contact).__name__}: "
            "use crack_contact=dolfinx_meshfree.dynamics.CrackContact()"
        )
    cracks = approximation_cracks(model.patch, model.mls) if contact is not None else []
    if not cracks:
        return model
    domain = model.patch if model.patch is not None else CrackDomain.from_particles(model.particles)
    h = particle_spacing(domain)
    if model.reduction is not None:  # the same on every rank
        raise ValueError(
            "crack_contact= is not available with coupling='master-slave': its particle field "
            "holds the masters only (the slaves follow the FE nodes), and the faces' jump "
            "operator acts on every particle; use coupling='lagrange' or 'edge-to-edge' for a "
            "cracked patch with contact, or crack_contact=None"
        )
    if model.system is not None:
        raise ValueError(
            "crack_contact= needs a small-strain model (LinearElastic): its finite-strain system "
            "is refused with cracks anyway"
        )
    field = [f.name for f in model.fields].index("particles")

    def remake() -> tuple[PETSc.Mat, np.ndarray, np.ndarray, np.ndarray]:
        return jump_operator(model.particles, model.mls, cracks, h, contact)

    B, x, n, w = remake()
    k = contact.stiffness(model.material.E, h)
    inner = LinearSystem(model.fields, model.blocks, model.constraint)
    system = ContactSystem(inner, B, k * w, field, x, n, w, remake=remake, k=k)
    return dataclasses.replace(model, fields=inner.fields, blocks={}, system=system)
