"""The master–slave reduction of an explicit model (Rabczuk et al. 2006, eq. 27–28).

The slave particles follow the FE interface, ``u = T u_M`` with ``T = [[I, 0], [T_PF, S]]``
(FE dofs, then the particles from the FE dofs and the free particles, the masters): the
stiffness becomes ``T^T K T`` (PETSc ``PtAP``), the lumped masses the row sums of
``T^T M T`` (the slaves' masses go to their masters), forces ``T^T f`` and the particle
constraints ``D T``. The state holds the FE dofs and the free particles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from ..geometry.particles import ParticleSet

__all__ = ["Reduced", "free_particle_points", "reduce_master_slave"]


@dataclass
class Reduced:
    """The reduced blocks, masses and constraints.

    Attributes:
        K_fe, K_m: The diagonal blocks (FE with ``T_PF^T K_P T_PF`` added; masters).
        blocks: The off-diagonal blocks ``{(0, 1): T_PF^T K_P S, (1, 0): S^T K_P T_PF}``.
        mass_fe, mass_m: Row sums of ``T^T M T`` on the FE dofs and the masters.
        G_fe, G_m: ``D T_PF`` and ``D S`` (``None`` without particle constraints ``D``).
    """

    K_fe: PETSc.Mat
    K_m: PETSc.Mat
    blocks: dict[tuple[int, int], PETSc.Mat]
    mass_fe: PETSc.Vec
    mass_m: PETSc.Vec
    G_fe: PETSc.Mat | None
    G_m: PETSc.Mat | None


def reduce_master_slave(
    K_fe: PETSc.Mat,
    K_p: PETSc.Mat,
    reduction: tuple[PETSc.Mat, PETSc.Mat],
    mass_fe: PETSc.Vec,
    mass_p: PETSc.Vec,
    active: np.ndarray,
    D: PETSc.Mat | None = None,
) -> Reduced:
    """Reduce by ``T = [[I, 0], [T_PF, S]]`` (eq. 27–28; collective).

    ``K_fe`` and ``mass_fe`` are updated in place and returned; ``K_p``, ``mass_p`` and ``D``
    are destroyed. ``active``: bool per owned FE dof, the dofs of the FE field.
    """
    Tpf, S = reduction
    A_pp = K_p.PtAP(Tpf)
    K_fe.axpy(1.0, A_pp, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    KpS = K_p.matMult(S)
    A_fm = Tpf.transposeMatMult(KpS)
    A_mf = KpS.transposeMatMult(Tpf)
    K_m = K_p.PtAP(S)
    for m in (A_pp, KpS, K_p):
        m.destroy()
    # row sums of T^T M T: T^T (M (T 1))
    ones_f, ones_m = Tpf.createVecRight(), S.createVecRight()
    ones_f.array[:] = active
    ones_m.set(1.0)
    e = Tpf.createVecLeft()
    Tpf.mult(ones_f, e)
    S.multAdd(ones_m, e, e)
    e.pointwiseMult(e, mass_p)
    Tpf.multTransposeAdd(e, mass_fe, mass_fe)
    mass_m = S.createVecRight()
    S.multTranspose(e, mass_m)
    for x in (ones_f, ones_m, e, mass_p):
        x.destroy()
    G_fe = G_m = None
    if D is not None:
        G_fe, G_m = D.matMult(Tpf), D.matMult(S)
        D.destroy()
    return Reduced(K_fe, K_m, {(0, 1): A_fm, (1, 0): A_mf}, mass_fe, mass_m, G_fe, G_m)


def free_particle_points(particles: ParticleSet, slaves: np.ndarray) -> np.ndarray:
    """Positions of the owned free particles (the masters) in PETSc order."""
    P = particles
    own = P.owned[np.argsort(P.petsc_index[P.owned], kind="stable")]
    is_slave = np.zeros(P.num_particles, dtype=bool)
    is_slave[slaves] = True
    return P.positions[own[~is_slave[own]]]
