"""The energy balance of central differences: records, kinetic, strain and discrete energies,
and the work of the loads and of the constraint forces.

Central differences with half-step velocities conserve, for a linear system, the discrete
energy ``1/2 v_{n+1/2}^T M v_{n+1/2} + 1/2 d_n^T K d_{n+1}`` exactly (Belytschko et al. 1995,
sec. 5.2), also with the multiplier correction of the velocities (eq. 94–96), whose forces do no
net work since ``G v = 0``. The strain energy comes from the system
(:meth:`~dolfinx_meshfree.dynamics.system.SemiDiscreteSystem.strain_energy`: ``1/2 d^T K d``
for the linear system, the stored energy ``W(F)`` for a finite-deformation one).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

__all__ = [
    "EnergyRecord",
    "constraint_work",
    "discrete_energy",
    "external_work",
    "kinetic_energy",
    "reaction_work",
    "strain_energy",
]

Amplified = Sequence[tuple[Sequence[PETSc.Vec | None], float]]


@dataclass
class EnergyRecord:
    """Energy balance at step ``n`` (every rank).

    Attributes:
        kinetic: ``1/2 v_n^T M v_n`` with ``v_n = (v_{n-1/2} + v_{n+1/2}) / 2``.
        internal: The strain energy of the system at ``d_n``: ``1/2 d_n^T K d_n`` (linear), the
            stored energy ``sum_q W(F_q) w_q`` (finite strain).
        external: Work of the external loads, ``sum_k f_k . (d_{k+1} - d_{k-1}) / 2``, and of
            the reactions of prescribed velocities (:func:`reaction_work`).
        constraint: Net work of the constraint forces ``-G^T lambda / dt`` in the same form
            (zero to round-off, since ``G v = 0``).
        transfer: The constraint work on the particles: the energy that crossed the interface
            from the FE side to the particles (the FE side receives ``constraint - transfer``).
        discrete: ``1/2 v_{n+1/2}^T M v_{n+1/2} + 1/2 d_n^T K d_{n+1}``, the energy that central
            differences conserve exactly for linear problems (with the velocity projection too):
            ``discrete - external - constraint`` is constant to round-off; for a nonlinear
            internal force (``internal + dt/2 f^int(d_n) . v_{n+1/2}`` in place of the second
            term) it is conserved to O(dt^2).
        residual: Relative constraint residual ``|G v| / (|G| |v|)`` (max norms) at ``n + 1/2``.
    """

    step: int
    time: float
    kinetic: float
    internal: float
    external: float
    constraint: float
    transfer: float
    discrete: float
    residual: float

    @property
    def total(self) -> float:
        """``kinetic + internal - external - constraint``, constant up to an O(dt^2)
        oscillation (the averaged velocity ``v_n`` is not the conserved one)."""
        return self.kinetic + self.internal - self.external - self.constraint

    @property
    def balance(self) -> float:
        """``discrete - external - constraint``, constant to round-off (linear problems)."""
        return self.discrete - self.external - self.constraint


def kinetic_energy(
    mass: Sequence[PETSc.Vec], v: Sequence[PETSc.Vec], work: Sequence[PETSc.Vec]
) -> float:
    """``1/2 v^T M v`` with lumped masses, summed field by field; ``work`` is scratch of the
    layout of ``v`` (collective)."""
    energy = 0.0
    for m, x, w in zip(mass, v, work, strict=True):
        w.pointwiseMult(x, x)
        energy += 0.5 * m.dot(w)
    return energy


def strain_energy(system: object, u: Sequence[PETSc.Vec]) -> float:
    """The strain energy of ``system`` at the dofs ``u`` (scratch vectors made and destroyed;
    collective)."""
    work = [x.duplicate() for x in u]
    try:
        return float(system.strain_energy(u, system.internal_force(u, work)))
    finally:
        for x in work:
            x.destroy()


def discrete_energy(
    half_kinetic: float,
    strain: float,
    f_int: Sequence[PETSc.Vec],
    v_half: Sequence[PETSc.Vec],
    dt: float,
) -> float:
    """The energy central differences conserve for a linear system,
    ``1/2 v_{n+1/2}^T M v_{n+1/2} + 1/2 d_n^T K d_{n+1}``, written as
    ``half_kinetic + strain + dt/2 f^int(d_n) . v_{n+1/2}`` (``d_{n+1} = d_n + dt v_{n+1/2}``;
    collective)."""
    cross = 0.0
    for f, v in zip(f_int, v_half, strict=True):
        cross += 0.5 * dt * f.dot(v)
    return half_kinetic + strain + cross


def external_work(
    loads: Amplified, v_old: Sequence[PETSc.Vec], v_new: Sequence[PETSc.Vec], dt: float
) -> float:
    """This rank's part of the work of the loads over a step, ``f_n . (d_{n+1} - d_{n-1}) / 2
    = dt f_n . (v_{n-1/2} + v_{n+1/2}) / 2``, which balances the discrete energy exactly: the
    owned dofs' sum, not collective (the caller sums over the ranks where it needs the total,
    once per energy record rather than once per step).

    Args:
        loads: ``(vectors per field (None: no load on that field), amplitude at t_n)``.
    """
    work = 0.0
    for vecs, amp in loads:
        for b, v0, v1 in zip(vecs, v_old, v_new, strict=True):
            if b is not None and amp != 0.0:
                work += 0.5 * amp * dt * float(b.array_r @ (v0.array_r + v1.array_r))
    return work


def constraint_work(
    G: Sequence[PETSc.Mat | None],
    impulse: Sequence[PETSc.Vec],
    v_old: Sequence[PETSc.Vec],
    v_new: Sequence[PETSc.Vec],
) -> np.ndarray:
    """This rank's part of the work of the constraint forces ``-G_f^T lambda / dt`` over a
    step, per field, in the form of :func:`external_work` (``impulse``: ``G_f^T lambda`` per
    field; not collective, like :func:`external_work`)."""
    work = np.zeros(len(G))
    for k, g in enumerate(G):
        if g is not None:
            work[k] = -0.5 * float(impulse[k].array_r @ (v_old[k].array_r + v_new[k].array_r))
    return work


def reaction_work(
    mass: PETSc.Vec,
    residual: PETSc.Vec,
    v_old: PETSc.Vec,
    v_new: PETSc.Vec,
    held: np.ndarray,
    dt: float,
    gamma: float,
    comm: MPI.Comm,
) -> float:
    """Work over a step of the reactions that drive held dofs at prescribed velocities
    (:mod:`~dolfinx_meshfree.dynamics.prescribed`), in the form of :func:`external_work`:
    ``r_n . dt (v_{n-1/2} + v_{n+1/2}) / 2`` with ``r_n = M (v_{n+1/2} - v_{n-1/2}) /
    (gamma dt) + f^int(d_n) - f^ext_n`` on the ``held`` owned dofs of one field (``residual``:
    ``f^int - f^ext``), the force that eq. 4.4 needs there; it balances the discrete energy
    exactly (collective)."""
    m, r = mass.array_r[held], residual.array_r[held]
    v0, v1 = v_old.array_r[held], v_new.array_r[held]
    force = m * (v1 - v0) / (gamma * dt) + r
    return float(comm.allreduce(0.5 * dt * float(force @ (v0 + v1)), op=MPI.SUM))
