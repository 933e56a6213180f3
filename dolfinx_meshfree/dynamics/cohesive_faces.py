"""Cohesive crack faces in explicit dynamics (issue 24: "cohesive cracks in dynamics").

The faces of the cracks a :class:`~dolfinx_meshfree.CoupledElasticity` carries with
:meth:`~dolfinx_meshfree.CoupledElasticity.add_cohesive` (or pure EFG's
``ExplicitDynamics.efg(..., cohesive=[(crack, law)])``) hold the traction of their
:class:`~dolfinx_meshfree.LinearCohesive` law (Hillerborg's fictitious crack; Rabczuk et al.
2006, sec. 6.1.2: "a linear traction-crack opening relation is applied"), as in statics
(:mod:`~dolfinx_meshfree.statics.cohesive`): along each cohesive segment, sample points ``x_q``
with length weights ``w_q`` carry the jump in the segment's frame,

.. math::
    [w_n, w_s]_q = R_q (u^+(x_q) - u^-(x_q)) = (B d)_q, \\qquad
    f_c = B^T (t(w) w_q),

with ``R_q = [n; s]`` (``s = (n_y, -n_x)``) and ``u^±`` the one-sided limits of the crack-aware
MLS. The law's state (the largest effective opening ``kappa``) is updated and committed at every
evaluation of the internal force: central differences evaluate it once per step, at the new
displacement (an explicit update; evaluating it again at the same displacement changes nothing,
``kappa`` being a maximum).

Energy: the records' ``internal`` holds the faces' stored energy and the energy they have
dissipated (the law's closed form at the committed ``kappa``), so that the balance closes.
Stable step: the bound sees the faces at their largest stiffness, the bonding penalty ``K_0`` on
both components (``K_0 B^T W B``, an upper bound in the PSD order of their secant stiffness in
any state). ``K_0 = factor E / h`` (30 by default) therefore shortens the step, as crack
contact's penalty does.

Scope: small strain, the couplings whose particle field holds every particle (not
master-slave), and no ``crack_contact=`` beside them (the law closes the faces by ``K_0`` in
compression already).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from ..geometry.crack import CrackDomain, particle_spacing
from ..parallel import Layout, raise_on_all_ranks
from ..physics.state import PointState
from ..statics.cohesive import CohesiveCrack, check_cohesive, owned_face_points
from ..statics.petsc import create_aij
from ..statics.state_carry import carry_at_points
from .linalg import add_weighted_gram
from .system import LinearSystem, SemiDiscreteSystem, WrappedSystem, wrapped

if TYPE_CHECKING:  # annotations only
    from ..approx.mls import MLS
    from ..geometry.crack import Crack
    from ..geometry.particles import ParticleSet
    from ..physics.cohesive import LinearCohesive
    from .builders import Model

__all__ = [
    "CohesiveFacesSystem",
    "carry_faces",
    "cohesive_records",
    "frame_jump_operator",
    "with_cohesive_faces",
]


def cohesive_records(
    pairs: Sequence[tuple[Crack, LinearCohesive]], cracks: Sequence[Crack], gdim: int
) -> list[CohesiveCrack]:
    """The faces' records of ``(crack, law)`` pairs (pure EFG's ``cohesive=``), each crack one
    of ``cracks`` (local; ValueError or TypeError naming the bad one)."""
    out = []
    for k, pair in enumerate(pairs):
        if not (isinstance(pair, tuple | list) and len(pair) == 2):
            raise TypeError(f"cohesive[{k}]={pair!r:.80} must be a (crack, LinearCohesive) pair")
        out.append(check_cohesive(pair[0], pair[1], cracks, None, 3, gdim))
    return out


def frame_jump_operator(
    particles: ParticleSet, mls: MLS, cohesive: CohesiveCrack, h: float
) -> tuple[PETSc.Mat, np.ndarray, np.ndarray]:
    """The jump operator ``B`` of one cohesive crack's faces (rows ``2q``: the normal opening,
    ``2q + 1``: the sliding, at this rank's face points; columns: the particle dofs in PETSc
    order), the points (m, 2) and their length weights (m,) (collective)."""
    gdim = particles.gdim
    dof_map = particles.petsc_dofs(gdim)
    x, n, w = owned_face_points(particles, cohesive, h)
    m = len(x)
    ones = np.ones(m, dtype=np.int64)
    plus, minus = raise_on_all_ranks(
        particles.comm,
        lambda: (mls.tabulate(x, 0, ones), mls.tabulate(x, 0, -ones)) if m else (None, None),
    )
    rows, cols, vals = [], [], []
    if m:
        jump = (plus.values - minus.values).tocoo()
        s = np.stack([n[:, 1], -n[:, 0]], axis=1)
        for a, frame in enumerate((n, s)):
            for c in range(gdim):
                rows.append(2 * jump.row + a)
                cols.append(dof_map[jump.col, c])
                vals.append(jump.data * frame[jump.row, c])
    layout = Layout.from_local(particles.comm, 2 * m)
    cat = lambda parts, dt: np.concatenate([*parts, np.zeros(0, dt)])  # noqa: E731
    local = sp.csr_matrix(
        (cat(vals, float), (cat(rows, np.int64) + layout.start, cat(cols, np.int64))),
        shape=(layout.size_global, gdim * particles.num_particles),
    )
    B = create_aij(particles.comm, local, layout, particles.dof_layout(gdim))
    return B, x, w


class CohesiveFacesSystem(WrappedSystem):
    """A :class:`~dolfinx_meshfree.dynamics.system.SemiDiscreteSystem` with cohesive crack
    faces (module docstring): the inner system's internal force plus ``B^T (t w)`` on the
    particle field, its strain energy plus the faces' stored and dissipated energy, its tangent
    plus ``K_0 B^T W B`` (for the stable step).

    Args:
        inner: The system without the faces (small strain).
        faces: Per cohesive crack: ``(B, law, points, weights)`` (:func:`frame_jump_operator`,
            the law with its ``K_0`` set).
        field: The index of the particle field.
        cracks: The cracks of ``faces``, in order.
    """

    def __init__(
        self,
        inner: SemiDiscreteSystem,
        faces: Sequence[tuple[PETSc.Mat, LinearCohesive, np.ndarray, np.ndarray]],
        field: int,
        cracks: Sequence[Crack] = (),
    ) -> None:
        super().__init__(inner)
        self.field = field
        #: The cracks whose faces these are, in the order of :attr:`faces` and :attr:`states`.
        self.cracks = list(cracks)
        self.faces = [(B, law, np.asarray(w, dtype=float)) for B, law, _, w in faces]
        #: The state of each crack's face points (committed at every evaluation).
        self.states = [PointState(law, x) for _, law, x, _ in faces]
        self._jumps = [B.createVecLeft() for B, _, _ in self.faces]
        self._force = faces[0][0].createVecRight() if faces else None
        self._tangent: PETSc.Mat | None = None

    def jumps(self, u: Sequence[PETSc.Vec]) -> list[np.ndarray]:
        """The jumps ``(w_n, w_s)`` (m, 2) at this rank's face points of each crack."""
        out = []
        for (B, _, _), v in zip(self.faces, self._jumps, strict=True):
            B.mult(u[self.field], v)
            out.append(v.array_r.reshape(-1, 2).copy())
        return out

    def _tractions(self, u: Sequence[PETSc.Vec], commit: bool) -> list[np.ndarray]:
        """Put ``t w`` of each crack into its jump vector (the state committed if ``commit``);
        returns the jumps (:meth:`jumps`) it evaluated the law at."""
        jumps = self.jumps(u)
        for (_, _, w), v, st, jump in zip(self.faces, self._jumps, self.states, jumps, strict=True):
            t, _ = st.evaluate(jump)
            if commit:
                st.commit()
            v.array[:] = (t * w[:, None]).ravel()
        return jumps

    def internal_force(
        self, u: Sequence[PETSc.Vec], out: Sequence[PETSc.Vec] | None = None
    ) -> list[PETSc.Vec]:
        """The inner force plus ``B^T (t w)`` (collective); the faces' states committed."""
        y = self.inner.internal_force(u, out)
        self._tractions(u, commit=True)
        for (B, _, _), v in zip(self.faces, self._jumps, strict=True):
            B.multTransposeAdd(v, y[self.field], y[self.field])
        return y

    def face_energies(
        self, u: Sequence[PETSc.Vec], jumps: Sequence[np.ndarray] | None = None
    ) -> tuple[float, float]:
        """The faces' stored and dissipated energy at the committed state (every rank);
        ``jumps``: the faces' jumps at ``u`` when the caller has them (:meth:`jumps`)."""
        stored = dissipated = 0.0
        jumps = self.jumps(u) if jumps is None else jumps
        for (_, law, w), st, jump in zip(self.faces, self.states, jumps, strict=True):
            stored += float(law.stored_energy(jump, st.committed) @ w)
            dissipated += st.dissipated(w)
        comm = self.faces[0][0].getComm().tompi4py()
        return comm.allreduce(stored, op=MPI.SUM), comm.allreduce(dissipated, op=MPI.SUM)

    def strain_energy(self, u: Sequence[PETSc.Vec], f_int: Sequence[PETSc.Vec]) -> float:
        """The inner system's energy (from ``f_int`` minus the faces' force) plus the faces'
        stored and dissipated energy."""
        jumps = self._tractions(u, commit=False)
        inner_f = list(f_int)
        inner_f[self.field] = f_int[self.field].copy()
        for (B, _, _), v in zip(self.faces, self._jumps, strict=True):
            B.multTranspose(v, self._force)
            inner_f[self.field].axpy(-1.0, self._force)
        energy = self.inner.strain_energy(u, inner_f)
        inner_f[self.field].destroy()
        return energy + sum(self.face_energies(u, jumps))

    def tangent(self, u: Sequence[PETSc.Vec] | None = None) -> dict:
        """The inner tangent with ``K_0 B^T W B`` added to the particle block: an upper bound,
        in the PSD order, of the faces' secant stiffness in any state."""
        blocks = dict(self.inner.tangent(u))
        if self._tangent is None:
            K = blocks[self.field, self.field].convert("aij", PETSc.Mat())  # a new matrix
            for B, law, w in self.faces:
                add_weighted_gram(K, B, law.K0 * np.repeat(w, 2))
            self._tangent = K
        blocks[self.field, self.field] = self._tangent
        return blocks

    def destroy(self) -> None:
        """Destroy the faces' objects and the inner system (collective)."""
        for obj in [*(B for B, _, _ in self.faces), *self._jumps, self._force, self._tangent]:
            if obj is not None:
                obj.destroy()
        self.inner.destroy()


def with_cohesive_faces(
    model: Model, cohesive: Sequence[CohesiveCrack], crack_contact: object = None
) -> Model:
    """``model`` with the cohesive faces ``cohesive`` (a problem's ``add_cohesive`` records) on
    its particle field (collective): its system becomes a :class:`CohesiveFacesSystem` around
    the linear system of its blocks; ``model`` itself when ``cohesive`` is empty. Refused (on
    every rank, naming the crack): master-slave's reduced particle field, a finite-strain
    system, ``crack_contact`` beside the faces."""
    if not cohesive:
        return model
    where = cohesive[0].crack.points.round(6).tolist()
    if model.reduction is not None:
        raise ValueError(
            f"the cohesive faces of the crack {where} in explicit dynamics need every particle "
            "in the particle field; coupling='master-slave' holds the masters only: use "
            "coupling='lagrange' or 'edge-to-edge'"
        )
    if model.system is not None:
        raise ValueError(
            f"the cohesive faces of the crack {where} in explicit dynamics are small strain: "
            "build the problem with a LinearElastic material"
        )
    if crack_contact is not None:
        raise ValueError(
            f"crack_contact= beside the cohesive faces of the crack {where}: the law closes "
            "the faces by its penalty K_0 in compression already; leave crack_contact=None"
        )
    domain = model.patch if model.patch is not None else CrackDomain.from_particles(model.particles)
    h = particle_spacing(domain)
    field = [f.name for f in model.fields].index("particles")
    faces = []
    for c in cohesive:
        B, x, w = frame_jump_operator(model.particles, model.mls, c, h)
        faces.append((B, c.law.with_stiffness(model.material.E, h), x, w))
    inner = LinearSystem(model.fields, model.blocks, model.constraint)
    system = CohesiveFacesSystem(inner, faces, field, [c.crack for c in cohesive])
    return dataclasses.replace(model, fields=inner.fields, blocks={}, system=system)


def carry_faces(old: object, new: object) -> int:
    """Carry the faces' committed states from the system ``old`` into ``new``, the same model
    rebuilt on a changed patch (a conversion): crack by crack in order, each new face point
    that lies where an old one lay (within 1e-9 of the crack's length) takes its state, so that
    no opened face heals. Returns the number of cracks carried (collective)."""
    before = wrapped(old, CohesiveFacesSystem)
    after = wrapped(new, CohesiveFacesSystem)
    if not before or not after:
        return 0
    s0, s1 = before[0], after[0]
    comm = s0.faces[0][0].getComm().tompi4py() if s0.faces else MPI.COMM_SELF
    for crack, st0, st1 in zip(s1.cracks, s0.states, s1.states, strict=False):
        carry_at_points(st0, st1, comm, 1e-9 * crack.length)
    return min(len(s0.states), len(s1.states))
