"""Cohesive crack faces in the particle patch: the traction–separation law's forces and tangent
on the block problem.

A crack of the patch whose faces carry :class:`~dolfinx_meshfree.LinearCohesive` (all its
segments, or those chosen) adds to the particles' internal force the virtual work of the
tractions over its faces (Rabczuk et al. 2006, sec. 6.1.2; Hillerborg, Modéer & Petersson 1976),

.. math::
    \\delta W_c = \\int_\\Gamma t([u]) \\cdot \\delta[u] \\, d\\Gamma
        \\approx \\sum_q w_q\\, t_q \\cdot (R_q B_q \\delta d), \\qquad
    [u](x_q) = \\sum_J (\\phi_J^+(x_q) - \\phi_J^-(x_q))\\, d_J = B_q d,

with ``phi^±`` the one-sided limits of the crack-aware MLS at points ``x_q`` on the faces (the
face machinery of crack contact, :func:`~dolfinx_meshfree.dynamics.crack_contact.contact_points`:
Gauss–Legendre points on pieces of at most one particle spacing), ``R_q`` the rotation to the
crack's local frame (normal: the left normal of the segment, towards the ``+1`` side of
:meth:`~dolfinx_meshfree.Crack.side`; then the segment's direction), so that

.. math::
    f_c = \\sum_q w_q B_q^T R_q^T t_q, \\qquad
    K_c = \\sum_q w_q B_q^T R_q^T \\frac{\\partial t}{\\partial w} R_q B_q .

The faces are bonded (the law is intrinsic: its initial stiffness ``K_0`` is a penalty) until
the normal traction reaches ``f_t``, then soften to zero at ``w_c = 2 G_f / f_t``; in
compression they are held by the same penalty (contact). The state of each face point (its
largest effective opening) is a :class:`~dolfinx_meshfree.physics.state.PointState`, committed
with the bulk's at every converged step.

A cohesive path must be given where the crack will run (Hillerborg's fictitious crack: the
ligament of a notched beam in mode I). :meth:`CohesiveSide.reached_end` tells when the softening
zone has reached the last piece before a tip of that path, beyond which the model cannot follow
the crack: :func:`~dolfinx_meshfree.follow_path` then stops with a
:class:`~dolfinx_meshfree.PathError` naming the point, never a silently too stiff answer.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from ..geometry.crack import Crack
from ..geometry.crack_faces import contact_points, owned_points
from ..parallel import raise_on_all_ranks
from ..physics.cohesive import LinearCohesive
from ..physics.state import PointState
from .petsc import create_aij, create_vector

if TYPE_CHECKING:  # annotations only
    from ..approx.mls import MLS
    from ..geometry.particles import ParticleSet
    from .sides import ParticleSide

__all__ = ["CohesiveCrack", "CohesiveSide", "check_cohesive", "check_through"]


@dataclass(frozen=True)
class CohesiveCrack:
    """A crack of the patch whose faces carry a traction–separation law.

    Attributes:
        crack: The crack (one of the patch's).
        law: The law (its ``K_0`` is set from the bulk's ``E`` and the particle spacing when it
            has none).
        segments: Indices of the polyline's segments that carry the law (``None``: all); the
            others are traction-free (a notch).
        points: Gauss–Legendre points per piece of at most one particle spacing.
    """

    crack: Crack
    law: LinearCohesive
    segments: tuple[int, ...] | None = None
    points: int = 3


def _block_diagonal(blocks: np.ndarray) -> sp.csr_matrix:
    """The block-diagonal matrix of ``blocks`` (m, a, b) as a CSR matrix (m a x m b), built
    directly (scipy's ``block_diag`` of a list is slow and turns into a sparse array)."""
    m, a, b = blocks.shape
    shape = (m * a, m * b)
    return sp.bsr_matrix((blocks, np.arange(m), np.arange(m + 1)), shape=shape).tocsr()


def check_cohesive(
    crack: object,
    law: object,
    cracks: Sequence[Crack],
    segments: Sequence[int] | None,
    points: int,
    gdim: int,
) -> CohesiveCrack:
    """The :class:`CohesiveCrack` of a model's ``add_cohesive`` arguments; ValueError or
    TypeError naming the bad one."""
    if gdim != 2:
        raise ValueError(
            f"cohesive cracks are 2D (a crack is a polyline); the model's mesh has gdim={gdim}"
        )
    if not isinstance(law, LinearCohesive):
        raise TypeError(
            f"law must be a LinearCohesive (a traction-separation law), got {type(law).__name__}"
        )
    if not any(crack is c for c in cracks):
        where = crack.points.tolist() if isinstance(crack, Crack) else repr(crack)
        raise ValueError(
            f"crack={where} is not one of the model's cracks: pass the Crack object given to the "
            "ParticlePatch (or EFGElasticity) in cracks=[...]"
        )
    nseg = len(crack.points) - 1
    if segments is not None:
        segs = tuple(int(s) for s in np.atleast_1d(np.asarray(segments, dtype=np.int64)))
        if not segs or any(s < 0 or s >= nseg for s in segs) or len(set(segs)) != len(segs):
            raise ValueError(
                f"segments={segments!r} must be distinct indices of the crack's {nseg} segments "
                f"(0 to {nseg - 1}: segment i runs from points[i] to points[i + 1]), or None (all)"
            )
        segments = segs
    if isinstance(points, bool) or not (isinstance(points, int) and points >= 1):
        raise ValueError(f"points={points!r} must be an integer >= 1 (Gauss points per piece)")
    return CohesiveCrack(crack, law, segments, points)


def check_through(cracks: Sequence[Crack], cohesive: Sequence[CohesiveCrack]) -> None:
    """Refuse a crack that splits the body (``through=True``) whose faces carry no law: nothing
    would hold its parts together (a singular system, or a silently free part)."""
    for crack in cracks:
        if getattr(crack, "through", False) and not any(c.crack is crack for c in cohesive):
            raise ValueError(
                f"{crack!r} splits the body (through=True) but its faces carry no "
                "traction-separation law: add one with model.add_cohesive(crack, "
                "LinearCohesive(ft=..., Gf=...)), or end the crack inside the body"
            )


def owned_face_points(
    particles: ParticleSet, cohesive: CohesiveCrack, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The face points of ``cohesive`` this rank owns: ``(x, n, w)`` (collective)."""
    crack = cohesive.crack
    x, n, w = contact_points(crack, h, cohesive.points, segments=cohesive.segments)
    own = owned_points(particles, x)
    return x[own], n[own], w[own]


class CohesiveSide:
    """The cohesive faces of one crack as a side of the block problem over the particle field
    (module docstring): ``fields``, ``internal_force(xs)``, ``tangent(xs)`` by blocks,
    ``states``, ``energies(xs)``; see :class:`~dolfinx_meshfree.statics.sides.BlockProblem`.

    Args:
        cohesive: The crack and its law.
        particles: The particle side (numbering, coefficients).
        mls: The crack-aware MLS of the particles.
        field: The index of the particle field in the block problem.
        E: The bulk's Young's modulus, h: the particle spacing (the default ``K_0``).
    """

    def __init__(
        self,
        cohesive: CohesiveCrack,
        particles: ParticleSide,
        mls: MLS,
        field: int,
        E: float,
        h: float,
    ) -> None:
        self.cohesive, self.side, self.comm = cohesive, particles, particles.comm
        self.fields = (field,)
        self.law = cohesive.law.with_stiffness(E, h)
        self.h = float(h)
        x, n, w = owned_face_points(particles.P, cohesive, h)
        self.points, self.normals, self.weights = x, n, w
        m, gdim = len(x), particles.gdim
        ones = np.ones(m, dtype=np.int64)
        plus, minus = raise_on_all_ranks(
            self.comm,
            lambda: (mls.tabulate(x, 0, ones), mls.tabulate(x, 0, -ones)) if m else (None, None),
        )
        N = particles.P.num_particles
        self.B = sp.csr_matrix((0, gdim * N))
        if m:
            # rows (q, a): a = 0 the normal opening n.[u], a = 1 the sliding s.[u], with
            # s = (n_y, -n_x) the segment's direction: the rotation R_q of each point's global
            # jump (the one-sided difference, times the identity per component; columns: the
            # interleaved coefficients)
            frame = np.stack([n, np.stack([n[:, 1], -n[:, 0]], axis=1)], axis=1)  # (m, 2, 2)
            jump = sp.kron(plus.values - minus.values, sp.identity(gdim))
            self.B = (_block_diagonal(frame) @ jump).tocsr()
        #: The state of the face points (the largest effective opening).
        self.state = PointState(self.law, x)

    @property
    def states(self) -> list[PointState]:
        return [self.state]

    def jump(self, xs: Sequence[PETSc.Vec]) -> np.ndarray:
        """The local jumps ``(w_n, w_s)`` (m, 2) at this rank's face points."""
        d = self.side.coefficients(xs[0])
        return (self.B @ d).reshape(-1, self.side.gdim)

    def _evaluate(self, xs: Sequence[PETSc.Vec]) -> tuple[np.ndarray, np.ndarray]:
        return self.state.evaluate(self.jump(xs))

    def internal_force(self, xs: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        """``[f_c]`` on the particle field (collective)."""
        t, _ = self._evaluate(xs)
        f = self.B.T @ (t * self.weights[:, None]).ravel()
        side = self.side
        return [create_vector(self.comm, side.layout, side.dof_map, f)]

    #: The tangent is the law's secant stiffness (:meth:`LinearCohesive.secant_stiffness`)
    #: instead of its consistent tangent: set by path following's fallback after a crack grew.
    secant: bool = False

    def tangent(self, xs: Sequence[PETSc.Vec]) -> dict[tuple[int, int], PETSc.Mat]:
        """``{(0, 0): K_c}`` (collective)."""
        jump = self.jump(xs)
        _, D = self.state.evaluate(jump)
        if self.secant:
            D = self.law.secant_stiffness(jump, self.state.committed)
        D = _block_diagonal(D * self.weights[:, None, None]) if len(D) else None
        side = self.side
        n = side.dof_map.size
        if D is None:
            local = sp.csr_matrix((n, n))
        else:
            K = (self.B.T @ D @ self.B).tocoo()
            dm = side.dof_map
            local = sp.csr_matrix((K.data, (dm[K.row], dm[K.col])), shape=(n, n))
        return {(0, 0): create_aij(self.comm, local, side.layout, side.layout)}

    def energies(self, xs: Sequence[PETSc.Vec]) -> tuple[float, float]:
        """``(stored, dissipated)`` on this rank's faces at the committed state (not summed over
        ranks)."""
        st = self.state
        stored = float(self.law.stored_energy(self.jump(xs), st.committed) @ self.weights)
        return stored, st.dissipated(self.weights)

    def reached_end(self) -> np.ndarray | None:
        """A point (2,) of the last piece before a tip of the cohesive path where the faces
        soften (the committed state), else ``None`` (collective: the same on every rank)."""
        crack = self.cohesive.crack
        kappa = self.state.committed["kappa"][:, 0]
        hit = np.zeros((0, 2))
        if len(self.points) and crack.tips.size:
            near = np.min(
                np.linalg.norm(self.points[:, None, :] - crack.tips[None, :, :], axis=2), axis=1
            )
            hit = self.points[(near <= self.h) & (kappa > self.law.w_0)]
        hits = [p for p in self.comm.allgather(hit) if len(p)]
        return np.concatenate(hits)[0] if hits else None
