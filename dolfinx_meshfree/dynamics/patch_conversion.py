"""Cells that become particles during an explicit run: the state carried from a model to the
model rebuilt on a larger patch (issue 25, item 1 in dynamics).

Rabczuk et al. (2006), sec. 5.5, cite the adaptive conversion of elements into particles (Sauer)
as the purpose of a coupled model; Belytschko et al. (1995), sec. 6, grew their refinement ahead
of a running crack. The old model (``d_n``, ``v_{n-1/2}`` on FE nodes and particles) and the new
one share the mesh and the FE space; the new patch holds the old one and the converted cells,
and its particles are placed afresh. :func:`convert` carries the state over:

* **FE dofs**: copied; those inside the new patch (no FE cell left around them) are zeroed and,
  massless, held at rest as the builders hold them;
* **particles**: the new coefficients are the ``L2`` projection of the old field (FE on the
  converted cells, the old particles elsewhere, blended as the old model evaluates it) onto the
  new particles' MLS space, with the rule and the ``rho``-weighted table of the new particle
  masses:

  .. math:: \\Phi^T W \\Phi \\, d = \\Phi^T W \\, u_{old}(x_q),

  solved by MUMPS (a private KSP) for each component of ``d_n`` and ``v_{n-1/2}``;
* **the ramps** (Belytschko et al. 1995, eq. 3.12): the new FE dofs (the nodes off the patch
  and off Gamma_E) are copied as above (a node off Gamma_E has ``R = 0``, so the old field there
  is its FE value); the fit adds the new interface cells, with the particle columns of their
  blended functions and the old field less the new FE part ``(1 - R) sum_a N_a u_a``. The
  ramps' supports are widened over the interface cells
  (:func:`~dolfinx_meshfree.couplings.ramp.ramp_mls`), and the consistent mass of such wide
  functions determines its oscillating modes poorly: the plain projection fits the field (its
  consistent kinetic energy kept to 4e-6) with coefficients that swing about it, and the lumped
  kinetic energy, the one the explicit run carries, rose 15 % on a plate. The fit is therefore
  stabilised towards the old field's values at the particles ``d_0`` (from which the MLS
  reproduces linear fields too):

  .. math:: (M + \\lambda M_L) \\, d = \\Phi^T W \\, u_{old}(x_q) + \\lambda M_L d_0,

  ``M_L`` the row sums of ``M`` and ``lambda`` = :data:`RAMP_STABILISATION` (0.01: the lumped
  kinetic energy then changes by 0.08 %). The modes whose consistent mass is below ``lambda``
  times their lumped mass follow the values, the others the projection. Linear fields stay
  exact (both fits reproduce them);
* **master-slave** (Rabczuk et al. 2006, eq. 27-28): the particle field is
  ``T_PF u_FE + S u_M``; the slaves follow the copied FE dofs, and the masters are the fit
  ``S^T (M x I) S u_M = S^T Phi^T W (u_old - Phi T_PF u_FE)``. At finite strain with links of
  finite length (``slaves="band"``) the slaves' motion is not linear in the dofs, and the
  conversion is refused;
* **shrinking back** (``ConvertingPatch(..., release_after=k)``, through
  :class:`~dolfinx_meshfree.dynamics.AdaptiveRun`): particle cells that no criterion has named
  for ``k`` checks return to FE; the FE nodes they give back take the old field's values
  there (linear fields stay exact), the remaining particles are fitted as above. The momentum
  the nodal values miss (a rough field's lumped integral differs from its integral: up to
  1.5e-2 of the momentum scale behind a pulse) is restored by a uniform velocity on those
  nodes, where the difference was made, and recorded;
* **a rate-form law's state** (:mod:`~dolfinx_meshfree.dynamics.rate_forms`: stress, damage,
  plastic strain, compaction, the stress work): every new point takes the state of the nearest
  old point in its cell (its own side's where that side had points there:
  :func:`~dolfinx_meshfree.dynamics.rate_forms.carry_state`), so a failing FE cell's particles
  carry its stress and history, and the points of unchanged cells keep theirs; the new model's
  first force, at the same time, takes the new field's deformation gradients as the state's
  (the next increment is the motion's, not the fit's difference). The stress work the records
  count as internal energy is then integrated on the new rule: its change is in
  ``strain_change``;
* the constraint rows of the new interface are then met in the mass metric (the projection of
  :mod:`~dolfinx_meshfree.dynamics.constraint`), as after a rebuild at a crack extension;
* the step, the time and the work accounts are carried unchanged;
* **a rigid projectile** (:meth:`~dolfinx_meshfree.ExplicitDynamics.add_projectile`, added
  again by the user's ``build``) continues from its tip, velocity, force and history
  (:func:`~dolfinx_meshfree.dynamics.rigid_projectile.carry_projectiles`); its penalty acts on
  the new model's points, so the new particles join the contact. A new particle that the
  projectile already covers is pushed out from the next step: the penalty's energy it starts
  with is in ``strain_change``.

**Conservation.** With row-sum lumping, ``sum_I M_II v_I = rho sum_q w_q v^h(x_q)`` (the MLS and
the FE functions are partitions of unity). Summing the rows of the projection gives the same
for the new particles: ``rho sum_q w_q v_new(x_q) = rho sum_q w_q v_old(x_q)``. On the old patch
cells the new rule is the old one (same cells, same rule), on the converted cells it integrates
the bilinear FE field exactly, and the FE nodes lose exactly the converted cells' share. So the
total mass and the linear momentum are conserved to round-off and the projection's residual (the
interface rows of the constraint projection sum to zero over the dofs: ``sum_i N_i = sum_I
phi_I = 1``); both are measured at every conversion, not assumed. A held particle row (an
essential condition on the patch) would exchange momentum with its support: that component is
then a reaction, as in the run itself. When a crack extension is made in the same rebuild
(:class:`ConvertingPatch` with ``extend``), the cells it cuts get a new rule, on which the old
field (smooth there) integrates slightly differently: a uniform velocity on the free particle
dofs restores the momentum, and its size is recorded (``momentum_correction``; 1e-10 to 6e-8 on
Kalthoff-Winkler, round-off without an extension). With the ramps the particle functions are
not a partition of unity on the interface cells (the FE nodes keep ``(1 - R) N_a``), nor is
the stabilised fit's row sum the momentum: the same uniform velocity restores it, and its size
is recorded (1e-5 of the momentum scale on the plate, 2.6e-6 on Kalthoff-Winkler at 41 nodes).
So it is for bridging (its band's FE masses integrated by DOLFINx's rule, its particle masses
by the particle rule: 3.5e-7) and master-slave (the fit's rows are the masters', whose
functions miss the slaves' share: 2e-4 on a wave).

**The hybrid's SPH particles** (Rabczuk et al. 2006, sec. 5.5; Sauer's adaptive conversion)
carry their own values (``rho V_I`` masses, no mass rule to fit on): a particle of the old set
keeps its displacement and velocity, a new one takes the old field at its position
(:func:`_sph_values`); the same uniform velocity restores the momentum the samples miss (up to
3.1e-3 of the scale on the concrete bar, ``demos/concrete_impact.py``).

**Energy.** The projection is the best fit in the consistent mass metric, so the kinetic energy
can only drop by what the new space cannot represent (and by the difference of consistent and
lumped masses); the strain energy changes as the stiffness of the new particles differs from the
FE stiffness they replace (on Kalthoff-Winkler at 41 nodes, the conversion as the wave reaches
the notch: lagrange +0.09 %, the ramp -1.8 %, whose fit of the displacement near the tip is
smoothed by the wide supports; the kinetic energy +0.16 % and +0.13 %). Both changes are
recorded (:class:`Conversion`), not hidden: the
energy balance of a run counts them as energy the conversion removed.
"""

from __future__ import annotations

import inspect
import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from ..approx.fe_points import locate_points
from ..geometry.patch_criteria import (
    GrowthContext,
    NearTips,
    as_criteria,
    cells_near,
    named_cells,
    warn_unused,
)
from ..geometry.quadrature import QuadraturePoints
from ..parallel import raise_on_all_ranks
from ..statics.petsc import create_aij, create_vector
from .body_contact import carry_friction
from .cohesive_faces import carry_faces
from .energy import kinetic_energy, strain_energy
from .explicit import ExplicitDynamics
from .linalg import mumps_lu
from .nodes_contact import carry_contacts
from .rate_forms import RateLaws, carry_state
from .rigid_projectile import carry_projectiles

__all__ = [
    "RAMP_STABILISATION",
    "Conversion",
    "ConvertingPatch",
    "carry_clock",
    "convert",
    "momentum",
    "total_mass",
]

#: The ramps' default weight of the particle values in the fit (module docstring): measured on a
#: plate after 20 steps of a non-linear motion, the plain projection raised the lumped kinetic
#: energy by 15 %, 0.01 by 0.08 % (0.001: 0.16 %; the values alone: -0.01 %, with a momentum
#: correction 60x larger).
RAMP_STABILISATION = 0.01


@dataclass
class Conversion:
    """One conversion of FE cells into particles during an explicit run.

    Attributes:
        step, time: The model's step and time.
        cells_added: Cells that joined the patch (global count).
        cells_released: Cells that left it, back to FE (global count).
        particles_before, particles_after: Particle counts.
        mass_error: ``|M_new - M_old| / M_old`` of the total mass (every field's lumped masses
            summed, per component).
        momentum_error: ``|p_new - p_old| / (sum_i M_ii |v_i|)`` of the linear momentum of
            ``v_{n-1/2}`` (the largest over the components; the scale is the momentum the
            masses could carry at the same speeds, so a body at rest in the mean is measured too).
        momentum_correction: The momentum the uniform particle velocity restored, on the
            same scale (round-off for a conversion alone; where a crack extension is made in
            the same rebuild, the cells it cuts change their rule, and the old field, smooth
            there, is integrated by the new rule: 1e-9 measured on Kalthoff-Winkler).
        momentum_reaction: The momentum the projection onto the new constraint rows changed, on
            the same scale: the interface rows' columns sum to zero, so only an essential
            condition on the patch's border (a held particle row) exchanges momentum, with its
            support, in the component it holds; round-off without one (1e-16 on the plate;
            9e-6 in y on Kalthoff-Winkler's symmetry line, reached by bridging's patch). Part of
            ``momentum_error``.
        momentum_components: ``|p_new - p_old| / scale`` per component (``momentum_error``
            is their largest): in an axisymmetric model only the axial one is a conserved
            quantity (the axis held radially takes radial momentum, as the hoop stresses do
            in the run), so that is the one to read there.
        kinetic_change, strain_change: The new minus the old kinetic energy (of ``v_{n-1/2}``)
            and strain energy (of ``d_n``).
        velocity_change: The largest change of the velocity field ``v_{n-1/2}`` at the old
            particles' positions, over the largest old speed there: what the fit did to the
            motion of the cells that were already particles. Round-off for a linear field;
            behind a steep front not (the HJC bar of ``demos/concrete_impact.py``, 20 cells:
            up to 4 % at 100 m/s on rollers, where it fails sound concrete next to the old
            interface, and 20 % at 300 m/s with free sides, where the failed depth still
            meets EFG's: a figure to read, not a verdict; guide, impact materials).
        energy_change: Their sum.
        time_rebuild: Seconds of the new model's build and the transfer.
        by: The criteria that named the cells.
        rebuild: ``"full"`` (every table and operator rebuilt).
    """

    step: int
    time: float
    cells_added: int
    cells_released: int
    particles_before: int
    particles_after: int
    mass_error: float
    momentum_error: float
    momentum_correction: float
    momentum_reaction: float
    kinetic_change: float
    strain_change: float
    energy_change: float
    velocity_change: float = 0.0
    momentum_components: list[float] = field(default_factory=list)
    time_rebuild: float = 0.0
    by: list[str] = field(default_factory=list)
    rebuild: str = "full"

    def as_dict(self) -> dict:
        """Plain values (for JSON)."""
        return asdict(self)


def total_mass(dyn: ExplicitDynamics) -> float:
    """The model's total mass: every field's lumped masses summed, per component (collective)."""
    gdim = dyn.mesh.geometry.dim
    local = math.fsum(math.fsum(f.mass.array_r) for f in dyn.fields)  # exact sums: the check
    return math.fsum(dyn.comm.allgather(local)) / gdim  # measures the masses, not the adding


def momentum(dyn: ExplicitDynamics, v: list[PETSc.Vec] | None = None) -> tuple[np.ndarray, float]:
    """``(p, scale)``: the linear momentum ``sum_i M_ii v_i`` per component of ``v`` (default
    ``v_{n-1/2}``) and ``sum_i M_ii |v_i|`` (collective)."""
    gdim = dyn.mesh.geometry.dim
    v = dyn.stepper.v if v is None else v
    parts: list[list[float]] = [[] for _ in range(gdim)]
    scale = 0.0
    for f, x in zip(dyn.fields, v, strict=True):
        mv = (f.mass.array_r * x.array_r).reshape(-1, gdim)
        for k in range(gdim):
            parts[k].append(math.fsum(mv[:, k]))
        scale += float(np.abs(mv).sum())
    gathered = dyn.comm.allgather([math.fsum(pk) for pk in parts])
    p = np.array([math.fsum(g[k] for g in gathered) for k in range(gdim)])
    return p, float(dyn.comm.allreduce(scale))


def carry_clock(old: ExplicitDynamics, new: ExplicitDynamics) -> None:
    """After the dofs are carried into ``new``: meet its constraint rows in the mass metric
    (driven rows keep their prescribed values) and carry the step, the time and the work
    accounts of ``old`` (collective)."""
    so, sn = old.stepper, new.stepper
    if new.projection is not None:
        held = new.loads.motion
        for x in (sn.u, sn.v):
            new.projection.correct(x, target=None if held is None else held.kept(new.G, x))
    sn.step, sn.time, sn.dt_prev = so.step, so.time, so.dt_prev
    sn.records, sn.w_ext, sn.w_c = list(so.records), so.w_ext, so.w_c.copy()


def _kinetic(dyn: ExplicitDynamics) -> float:
    work = [x.duplicate() for x in dyn.stepper.v]
    try:
        return kinetic_energy([f.mass for f in dyn.fields], dyn.stepper.v, work)
    finally:
        for x in work:
            x.destroy()


def _require_convertible(model: ExplicitDynamics) -> None:
    """A conversion needs a coupled model, with linear slave links for master-slave (local)."""
    if model.patch is None:
        raise ValueError(
            "adapt= converts FE cells of a coupled model; pure EFG has no FE cell (its "
            "particles fill the body already)"
        )
    if model.reduction is not None and model.evaluator.expand is not None:
        raise ValueError(
            "adapt= with master-slave at finite strain: its slave links rotate with the FE "
            "interface (u_P is not linear in the dofs), which the conversion's fit does not "
            "carry; use master-slave with a linear material, or lagrange"
        )


def _check(old: ExplicitDynamics, new: ExplicitDynamics) -> None:
    """The two models must be a coupled model and its rebuild on another patch."""
    names = [f.name for f in new.fields]
    if names != ["fe", "particles"] or [f.name for f in old.fields] != names:
        raise ValueError(
            "a conversion carries a coupled model (FE and particle fields) to a coupled model; "
            f"got fields {[f.name for f in old.fields]} -> {names}"
        )
    _require_convertible(new)
    if isinstance(old.material, RateLaws) != isinstance(new.material, RateLaws):
        raise ValueError(
            "the rebuilt model must have the old one's material: got "
            f"{type(old.material).__name__} -> {type(new.material).__name__}"
        )
    if old.V is not new.V and old.V.mesh is not new.V.mesh:
        raise ValueError("the rebuilt model must live on the old model's mesh")
    if old.u[0].getSize() != new.u[0].getSize():
        raise ValueError(
            f"the rebuilt model has {new.u[0].getSize()} FE dofs, the old one "
            f"{old.u[0].getSize()}: build the new model on the same FE space"
        )


def _consistent_mass(
    rules: list[tuple[sp.csr_matrix, np.ndarray]], perm: np.ndarray, n: int
) -> sp.coo_matrix:
    """``sum_r T_r^T W_r T_r`` of rules given as (table, weights), rows and columns in PETSc
    particle numbering (``perm``; this rank's share)."""
    M = sum((t.T.multiply(w[None, :]) @ t).tocoo() for t, w in rules).tocoo()
    return sp.coo_matrix((M.data, (perm[M.row], perm[M.col])), shape=(n, n))


def _fit(old: ExplicitDynamics, new: ExplicitDynamics, stabilisation: float) -> None:
    """The new particle coefficients of ``d_n`` and ``v_{n-1/2}``: the L2 projection of the old
    fields on the new mass rule (module docstring); with the ramps, of the old fields less the
    new FE part on the interface cells, with the blended particle functions there; with
    ``stabilisation`` ``lam > 0``, ``(M + lam M_L) d = b + lam M_L d_0``, ``M_L`` the row sums of
    ``M`` and ``d_0`` the old fields at the particles (:func:`_values`)."""
    q, table = new.mass_rule
    P = new.particles
    comm, gdim = new.comm, P.gdim
    n = P.num_particles
    rules = [(q, table, np.asarray(q.weights, dtype=float), None)]
    if new.blended_rule is not None:  # the ramps' interface cells: [local FE nodes | particles]
        qi, ti = new.blended_rule
        n_loc = ti.shape[1] - n
        ti = ti.tocsc()
        rules.append(
            (qi, ti[:, n_loc:].tocsr(), np.asarray(qi.weights, dtype=float), ti[:, :n_loc])
        )
    perm = P.petsc_index
    M = _consistent_mass([(t, wq) for _, t, wq, _ in rules], perm, n)
    layout = P.dof_layout(1)
    lumped = d0 = None
    if stabilisation > 0:
        ml = sp.diags(np.asarray(M.sum(axis=1)).ravel()).tocoo()  # this rank's share
        lumped = create_aij(comm, ml, layout, layout)
        M = (M + stabilisation * ml).tocoo()
        _values(old, new)
        d0 = [dst[1].array_r.reshape(-1, gdim).copy() for dst in (new.stepper.u, new.stepper.v)]
    A = create_aij(comm, M, layout, layout)
    ksp = mumps_lu(A)
    x = A.createVecLeft()
    try:
        for j, (src, dst) in enumerate(
            ((old.stepper.u, new.stepper.u), (old.stepper.v, new.stepper.v))
        ):
            rhs = np.zeros((n, gdim))
            for qr, t, wq, t_fe in rules:
                values = np.asarray(old.evaluator.at_cells(src, qr)).reshape(-1, gdim)
                if t_fe is not None:  # less the new FE part (copied before the fit)
                    fe, _ = new.evaluator.local_values(dst, particles=False)
                    values = values - t_fe @ fe.x.array.reshape(-1, gdim)
                rhs += np.asarray(t.T @ (wq[:, None] * values))
            out = dst[1].array.reshape(-1, gdim)
            for k in range(gdim):
                nz = np.flatnonzero(rhs[:, k])  # this rank's quadrature reaches these particles
                b = create_vector(comm, layout, perm[nz], rhs[nz, k])
                if lumped is not None:
                    x.array[:] = d0[j][:, k]
                    y = lumped.createVecLeft()
                    lumped.mult(x, y)
                    b.axpy(stabilisation, y)
                    y.destroy()
                ksp.solve(b, x)
                reason = ksp.getConvergedReason()
                b.destroy()
                if reason < 0:
                    raise RuntimeError(
                        f"the conversion's projection onto the new particles failed (KSP reason "
                        f"{reason}): the new particles' consistent mass is singular"
                    )
                out[:, k] = x.array_r
    finally:
        for obj in (x, ksp, A, lumped):
            if obj is not None:
                obj.destroy()


def _fit_reduced(old: ExplicitDynamics, new: ExplicitDynamics) -> None:
    """Master-slave (Rabczuk et al. 2006, eq. 27-28): the particle field is
    ``T_PF u_FE + S u_M``; with the new FE dofs copied, the masters' dofs are the L2 fit
    ``S^T (M x I) S u_M = S^T Phi^T W (u_old - Phi T_PF u_FE)`` on the new mass rule (one
    MUMPS factorisation, every component at once)."""
    q, table = new.mass_rule
    P = new.particles
    comm, gdim = new.comm, P.gdim
    n = P.num_particles
    Tpf, S = new.reduction
    w = np.asarray(q.weights, dtype=float)
    perm = P.petsc_index
    M = _consistent_mass([(table, w)], perm, n)
    rows = (gdim * M.row[:, None] + np.arange(gdim)).ravel()
    cols = (gdim * M.col[:, None] + np.arange(gdim)).ravel()
    Mdof = sp.coo_matrix((np.repeat(M.data, gdim), (rows, cols)), shape=(gdim * n, gdim * n))
    layout = P.dof_layout(gdim)
    M_full = create_aij(comm, Mdof, layout, layout)
    A = M_full.PtAP(S)
    M_full.destroy()
    ksp = mumps_lu(A)
    full, b = Tpf.createVecLeft(), S.createVecRight()
    try:
        for src, dst in ((old.stepper.u, new.stepper.u), (old.stepper.v, new.stepper.v)):
            Tpf.mult(dst[0], full)  # the new FE dofs' share of the particle field
            fe_part = np.concatenate(comm.allgather(full.array_r.copy()))
            fe_part = fe_part.reshape(-1, gdim)[perm]  # per particle, original order
            target = np.asarray(old.evaluator.at_cells(src, q)).reshape(-1, gdim)
            target = target - table @ fe_part
            rhs = np.asarray(table.T @ (w[:, None] * target))  # (n, gdim), original order
            nz = np.flatnonzero(np.any(rhs != 0.0, axis=1))
            dofs = (gdim * perm[nz][:, None] + np.arange(gdim)).ravel()
            b_full = create_vector(comm, layout, dofs, rhs[nz].ravel())
            S.multTranspose(b_full, b)
            b_full.destroy()
            ksp.solve(b, dst[1])
            reason = ksp.getConvergedReason()
            if reason < 0:
                raise RuntimeError(
                    f"the conversion's fit of the new masters failed (KSP reason {reason}): "
                    "S^T M S is singular"
                )
    finally:
        for obj in (full, b, ksp, A):
            obj.destroy()


def _values(old: ExplicitDynamics, new: ExplicitDynamics, rows: np.ndarray | None = None) -> None:
    """The new particle coefficients of ``d_n`` and ``v_{n-1/2}``: the old fields at the
    particles (the MLS reproduces linear fields from these values); the cell of a particle on a
    cell boundary is an old patch cell where there is one. ``rows``: bool per owned particle
    (PETSc order), the only ones set (default: all). Collective."""
    P = new.particles
    gdim = P.gdim
    own = new.evaluator.disc.owned_particles()
    rows = np.ones(own.size, dtype=bool) if rows is None else rows
    x = P.positions[own[rows]]
    cells = locate_points(new.mesh, x, preferred=old.in_patch)
    if (cells < 0).any():
        raise RuntimeError("an owned particle lies in no owned cell of its rank")
    q = QuadraturePoints(x, np.ones(len(x)), cells.astype(np.int32))
    for src, dst in ((old.stepper.u, new.stepper.u), (old.stepper.v, new.stepper.v)):
        values = np.asarray(old.evaluator.at_cells(src, q)).reshape(-1, gdim)
        dst[1].array.reshape(-1, gdim)[rows] = values


def _sph_values(old: ExplicitDynamics, new: ExplicitDynamics) -> None:
    """The hybrid's SPH particles (Rabczuk et al. 2006, sec. 5.5): a particle of the old set
    keeps its own ``d_n`` and ``v_{n-1/2}`` (SPH particles carry their values; re-sampling
    the field at them would smooth it at every conversion: measured, the old particles'
    velocities changed by up to half their speed), a new one takes the old field at its
    position (:func:`_values`). Collective."""
    P0, P1 = old.particles, new.particles
    gdim = P1.gdim
    scale = float(np.ptp(P1.positions, axis=0).max()) or 1.0
    dist, match = cKDTree(P0.positions).query(P1.positions[new.evaluator.disc.owned_particles()])
    kept = dist <= 1e-9 * scale
    _values(old, new, rows=~kept)
    for src, dst in ((old.stepper.u, new.stepper.u), (old.stepper.v, new.stepper.v)):
        values = np.concatenate(old.comm.allgather(src[1].array_r.copy())).reshape(-1, gdim)
        values = values[P0.petsc_index]  # the old particles' coefficients, original order
        out = dst[1].array.reshape(-1, gdim)
        out[kept] = values[match[kept]]


def _restore_momentum(
    new: ExplicitDynamics, p0: np.ndarray, back: np.ndarray | None = None
) -> float:
    """Add the uniform velocity ``delta = (p0 - p) / M`` to the free particle dofs (the MLS
    being a partition of unity, the particle field shifts by ``delta``), or, where cells went
    back to FE, to the free dofs of the nodes they gave back (``back``: bool per owned FE node;
    the interpolation there made the difference), so that the momentum is ``p0``; returns
    ``max |delta M|`` (collective)."""
    gdim = new.mesh.geometry.dim
    p = momentum(new)[0]
    k = 1 if back is None else 0
    free = new.free[k].reshape(-1, gdim)
    if back is not None:
        free = free * back[:, None]
    m = new.fields[k].mass.array_r.reshape(-1, gdim) * free
    mp = np.array([math.fsum(g[c] for g in new.comm.allgather(m.sum(axis=0))) for c in range(gdim)])
    delta = np.where(mp > 0, (p0 - p) / np.where(mp > 0, mp, 1.0), 0.0)
    v = new.stepper.v[k].array.reshape(-1, gdim)
    v += free * delta[None, :]
    return float(np.abs(delta * mp).max())


def convert(
    old: ExplicitDynamics,
    new: ExplicitDynamics,
    cells_added: int = 0,
    stabilisation: float | None = None,
    cells_released: int = 0,
) -> Conversion:
    """Carry the state of ``old`` into ``new``, its rebuild on another patch (module docstring;
    collective): a larger one, or one that has given cells back to FE (their nodes take the
    old field's values). Returns the :class:`Conversion` record; ``old`` is left as it was.

    ``stabilisation``: the weight ``lam`` of the particle values in the fit (module docstring);
    default ``RAMP_STABILISATION`` for the ramps, 0 (the plain projection) otherwise.
    """

    def check() -> float:
        _check(old, new)
        carry_projectiles(old.system, new.system)  # before the new model's first force
        carry_friction(old.system, new.system)
        carry_faces(old.system, new.system)  # an opened cohesive face does not heal
        if carry_contacts(old.system, new.system):
            new.bound.invalidate()
        lam = (
            (RAMP_STABILISATION if new.blended_rule is not None else 0.0)
            if stabilisation is None
            else stabilisation
        )
        if not (isinstance(lam, (int, float)) and math.isfinite(lam) and lam >= 0):
            raise ValueError(f"stabilisation must be a finite number >= 0, got {stabilisation!r}")
        return float(lam)

    lam = raise_on_all_ranks(old.comm, check)
    so, sn = old.stepper, new.stepper
    mass0, (p0, scale) = total_mass(old), momentum(old)
    kin0, strain0 = _kinetic(old), strain_energy(old.system, so.u)
    gdim = new.mesh.geometry.dim
    back = (new.active[0] & ~old.active[0]).reshape(-1, gdim).any(axis=1)  # FE again
    returned = new.comm.allreduce(int(back.sum()))
    if returned:
        nodes = new.V.tabulate_dof_coordinates()[: back.size][back, :gdim]
    for src, dst in ((so.u, sn.u), (so.v, sn.v)):
        src[0].copy(dst[0])
        dst[0].array[~new.active[0]] = 0.0  # inside the new patch: massless, at rest
        if returned:  # the nodes that leave the patch: the old field there (collective)
            dst[0].array.reshape(-1, gdim)[back] = old.evaluator.at_points(src, nodes)
    if new.reduction is not None:
        _fit_reduced(old, new)
    elif new.mass_rule is None:  # the hybrid's SPH particles: kept, and the new ones' values
        _sph_values(old, new)
    else:
        _fit(old, new, lam)
    correction = _restore_momentum(new, p0, back if returned else None)
    correction = correction / scale if scale > 0 else 0.0
    p_fit = momentum(new)[0]
    carry_clock(old, new)  # the new interface rows; the step, time and work accounts
    if isinstance(new.material, RateLaws):  # the points' state, then the new field's F
        raise_on_all_ranks(new.comm, lambda: carry_state(old.material, new.material))
        new.system.set_time(so.time)
        force = new.system.internal_force(sn.u)
        for x in force:
            x.destroy()
    mass1, (p1, _) = total_mass(new), momentum(new)
    kin1, strain1 = _kinetic(new), strain_energy(new.system, sn.u)
    at = old.particles.positions[np.asarray(old.particles.owned, dtype=np.int64)][:, :gdim]
    v_old, v_new = old.evaluator.at_points(so.v, at), new.evaluator.at_points(sn.v, at)
    change = new.comm.allreduce(float(np.abs(v_new - v_old).max(initial=0.0)), op=MPI.MAX)
    speed = new.comm.allreduce(float(np.abs(v_old).max(initial=0.0)), op=MPI.MAX)
    return Conversion(
        step=so.step, time=so.time, cells_added=int(cells_added),
        cells_released=int(cells_released),
        particles_before=old.particles.num_particles, particles_after=new.particles.num_particles,
        mass_error=abs(mass1 - mass0) / mass0,
        momentum_error=float(np.abs(p1 - p0).max() / scale) if scale > 0 else 0.0,
        momentum_correction=correction,
        momentum_reaction=float(np.abs(p1 - p_fit).max() / scale) if scale > 0 else 0.0,
        kinetic_change=kin1 - kin0, strain_change=strain1 - strain0,
        energy_change=(kin1 - kin0) + (strain1 - strain0),
        velocity_change=change / speed if speed > 0 else change,
        momentum_components=[float(x) for x in np.abs(p1 - p0) / (scale if scale > 0 else 1.0)],
    )  # fmt: skip


class ConvertingPatch:
    """The patch of a :class:`~dolfinx_meshfree.dynamics.DynamicCrackGrowth` or an
    :class:`~dolfinx_meshfree.dynamics.AdaptiveRun` that changes during the run (its
    ``adapt``): at each check (for crack growth: before the first step and before each
    extension, with the tip the extension will make), the criteria name the FE cells that must
    be particles; the model is then rebuilt by the user's ``build(..., cells=...)`` on the
    changed patch and the state carried over (:func:`convert`).

    Args:
        adapt: One criterion or a list (:class:`~dolfinx_meshfree.NearTips`,
            :class:`~dolfinx_meshfree.FieldAbove` on the current displacement,
            :class:`~dolfinx_meshfree.CellsWhere`).
        model: The first model (``build(crack)``), checked for what a conversion needs.
        build: The user's builder, which must take ``cells`` (the patch's local cells).
        sif_radius: The SIF domains' outer radius, if given (``NearTips()``'s default radius).
        increment: The crack segment (``NearTips``' reserve is counted in segments).
        release_after: Shrinking back: a particle cell that no criterion has named in this
            many checks in a row returns to FE (its nodes take the field's values), unless it
            belongs to the first patch or carries a crack. ``None`` (default): the patch only
            grows.

    Attributes:
        conversions: One :class:`Conversion` per change of the patch.
    """

    def __init__(
        self,
        adapt: Any,
        model: ExplicitDynamics,
        build: Any,
        sif_radius: float | None = None,
        increment: float | None = None,
        release_after: int | None = None,
    ) -> None:
        def check() -> list:
            if release_after is not None and (
                isinstance(release_after, bool)
                or not isinstance(release_after, int)
                or release_after < 1
            ):
                raise ValueError(
                    f"release_after={release_after!r} must be a number of checks >= 1, or None "
                    "(the patch only grows)"
                )
            items = as_criteria(adapt)
            for c in items:
                if isinstance(c, NearTips) and c.spacings is None and sif_radius is None:
                    raise ValueError(
                        "NearTips() takes its radius from the SIF domains, and the dynamic "
                        "growth's default domains fit the room they find: give "
                        "NearTips(spacings=k) (e.g. the domains' outer radius in spacings plus "
                        "2) or the growth's radius"
                    )
            try:
                params = inspect.signature(build).parameters
            except (TypeError, ValueError):
                params = {}
            if "cells" not in params and not any(
                p.kind == inspect.Parameter.VAR_KEYWORD for p in params.values()
            ):
                raise TypeError(
                    "adapt= rebuilds the model on a larger patch by build(..., cells=...): "
                    "give build a cells argument (the patch's local cells, for "
                    "mf.ParticlePatch(mesh, cells, ...))"
                )
            _require_convertible(model)
            return items

        self.criteria = raise_on_all_ranks(model.comm, check)
        self.build, self.sif_radius, self.increment = build, sif_radius, increment
        self.conversions: list[Conversion] = []
        #: Whether any criterion has named a cell (patch cells included) in any check.
        self.selected = False
        self._warned = False
        self.release_after = release_after
        n_own = model.mesh.topology.index_map(model.mesh.topology.dim).size_local
        #: bool per owned cell: the first patch, never released.
        self.first = np.asarray(model.in_patch[:n_own], dtype=bool).copy()
        #: per owned cell: the checks since a criterion last named it.
        self.unnamed = np.zeros(n_own, dtype=np.int64)

    def grow(
        self,
        model: ExplicitDynamics,
        rebuild: Any,
        new_tip: np.ndarray | None = None,
        driver: str = "DynamicCrackGrowth",
    ) -> ExplicitDynamics | None:
        """Ask the criteria (with the tips of the model's cracks and ``new_tip``, and the
        model's current state for field criteria); when FE cells must be particles, or (with
        ``release_after``) particle cells go back to FE: ``rebuild(cells)``, the model on the
        changed patch, and the state converted. Returns the new model or ``None``
        (collective)."""
        patch, comm = model.patch, model.comm
        tips = [c.tips for c in patch.cracks if len(c.tips)]
        if new_tip is not None:
            tips.append(np.asarray(new_tip)[None])
        tips = np.concatenate(tips) if tips else np.zeros((0, 2))
        state = model.evaluator.solution(model.u)
        state.material = model.material
        ctx = GrowthContext(model.step, tips, state, self.sif_radius, self.increment)
        want, by, named, chosen = named_cells(self.criteria, patch, ctx, driver)
        self.selected |= named
        release = self._released(model, chosen)
        added = comm.allreduce(int(want.sum()))
        released = comm.allreduce(int(release.sum()))
        if not added and not released:
            return None
        tic = time.perf_counter()
        cells = np.union1d(np.setdiff1d(patch.cells, np.flatnonzero(release)), np.flatnonzero(want))
        try:
            new = rebuild(cells.astype(np.int32))
        except ValueError as e:  # raised on every rank by the build: give it the event
            raise ValueError(
                f"{driver}: the model rebuilt on the changed patch ({added} cell(s) added by "
                f"{by}, {released} released) at step {model.step}, t = {model.time:.6g}, was "
                f"refused: {e}"
            ) from e
        record = convert(model, new, added, cells_released=released)
        record.time_rebuild, record.by = time.perf_counter() - tic, by
        self.conversions.append(record)
        return new

    def _released(self, model: ExplicitDynamics, chosen: np.ndarray) -> np.ndarray:
        """bool per owned cell: particle cells that return to FE at this check
        (``release_after``): unnamed for that many checks, not in the first patch, not cut by
        a crack."""
        self.unnamed += 1
        self.unnamed[chosen] = 0
        n_own = self.unnamed.size
        if self.release_after is None:
            return np.zeros(n_own, dtype=bool)
        out = model.in_patch[:n_own] & ~self.first & (self.unnamed >= self.release_after)
        cut = np.zeros(n_own, dtype=bool)
        for crack in model.patch.cracks:  # the FE side cannot carry a crack
            cut[cells_near(model.mesh, crack.points, 0.0)] = True
        return out & ~cut

    def finish(self, driver: str, checks: str) -> None:
        """At the end of a driver's run: a :class:`~dolfinx_meshfree.PatchCriterionWarning`,
        once per driver, if no criterion has named any cell (``checks``: e.g. "12 check(s)")."""
        if not self.selected and not self._warned:
            warn_unused(self.criteria, driver, checks, stacklevel=4)
            self._warned = True
