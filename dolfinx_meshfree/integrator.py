"""The explicit central-difference integrator with lumped masses and a velocity constraint.

Semi-discrete equations of motion (Belytschko et al. 1995, eq. 4.4–4.5; Rabczuk et al. 2006,
eq. 86–92), one block per field (FE nodes, particles):

.. math::
    M \\ddot d + K d = f^{ext} + G^T \\lambda, \\qquad G \\dot d = 0,

with ``M`` lumped (row sums, :mod:`~dolfinx_meshfree.masses`), ``K`` the block stiffness
(diagonal blocks per field and, for the ramp couplings and the bridging penalty, off-diagonal
blocks), and ``G`` the constraint blocks (interface multipliers, and essential conditions on
particles). Central differences with half-step velocities (Belytschko et al. 1995, sec. 5.2):
``vbar = v_{n-1/2} + dt M^{-1} (f^ext_n - K d_n)`` (trial velocities, eq. 93), then the
multiplier correction (eq. 94–96)

.. math::
    (G M^{-1} G^T) \\lambda = G \\bar v, \\qquad v_{n+1/2} = \\bar v - M^{-1} G^T \\lambda,

and ``d_{n+1} = d_n + dt v_{n+1/2}``; ``v_{1/2} = v_0 + dt/2 M^{-1} f_0``. ``G M^{-1} G^T`` is
factorised once (dense Cholesky on every rank, or MUMPS), so each step costs the stiffness
products, two sparse products with ``G`` and one triangular solve; ``G v`` stays at round-off.
Dofs fixed strongly (FE Dirichlet nodes) have ``M^{-1} = 0``: zero velocity and acceleration.

The velocity at an output time is ``v_n = (v_{n-1/2} + v_{n+1/2}) / 2``.

Stable time step: ``2 / omega_bound`` with ``omega_bound`` an upper bound of the largest
frequency of the constrained system (a weighted Gershgorin / Schur-test bound of
``M^{-1/2} K M^{-1/2}``, see :meth:`ExplicitDynamics.critical_time_step`), so the step is never
above the critical one (Belytschko et al. 1995, sec. 5.2); measured 1.00-1.14x the true
``omega_max`` on FE, EFG and every coupling. The Courant condition ``h_min / c`` is reported
only: it is exact for square Q1 elements at ``nu = 0`` but exceeds the critical step on
triangles (1.44x on right triangles), for ``nu -> 1/2`` and for small weighted masses
(bridging); for EFG it is conservative.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import dolfinx
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.linalg import LinAlgError, cho_factor, cho_solve

from .approx.fe_points import ensure_points_in_mesh, evaluate_fe_function, tabulate_in_cells
from .approx.mls import MLS
from .couplings.master_slave import MASTER_SELECTION
from .geometry.particles import ParticleSet
from .geometry.quadrature import QuadraturePoints, cell_quadrature, facet_quadrature
from .parallel import Layout, raise_on_all_ranks
from .physics.materials import LinearElastic
from .physics.operators import load_vector
from .statics.petsc import create_aij, create_vector

__all__ = ["DynamicsResult", "EnergyRecord", "ExplicitDynamics", "Field"]

_prefix_counter = itertools.count()
_DENSE_MAX = 2000

VectorFunction = Callable[[np.ndarray], np.ndarray]


@dataclass
class Field:
    """One discretisation of an explicit system: stiffness and lumped masses of its dofs.

    Attributes:
        name: ``"fe"`` or ``"particles"``.
        K: Assembled stiffness (PETSc, owned rows).
        mass: Lumped masses (PETSc vector, same layout); 0 marks dofs outside the field (FE nodes
            that only patch cells touch), which the integrator holds at rest.
        spacing: Smallest node or particle spacing (for the Courant condition).
        points: (owned nodes, 2) positions of the owned nodes/particles in PETSc order (two dofs
            each); ``None``: derived from the field's space or particle set.
        fixed: bool per owned dof: held at zero velocity and acceleration (strong essential
            conditions: ``M^{-1} = 0`` there); ``None``: none.
    """

    name: str
    K: PETSc.Mat
    mass: PETSc.Vec
    spacing: float
    points: np.ndarray | None = None
    fixed: np.ndarray | None = None


@dataclass
class EnergyRecord:
    """Energy balance at step ``n`` (every rank).

    Attributes:
        kinetic: ``1/2 v_n^T M v_n`` with ``v_n = (v_{n-1/2} + v_{n+1/2}) / 2``.
        internal: ``1/2 d_n^T K d_n``.
        external: Work of the external loads, ``sum_k f_k . (d_{k+1} - d_{k-1}) / 2``.
        constraint: Net work of the constraint forces ``-G^T lambda / dt`` in the same form
            (zero to round-off, since ``G v = 0``).
        transfer: The constraint work on the particles: the energy that crossed the interface
            from the FE side to the particles (the FE side receives ``constraint - transfer``).
        discrete: ``1/2 v_{n+1/2}^T M v_{n+1/2} + 1/2 d_n^T K d_{n+1}``, the energy that central
            differences conserve exactly for linear problems (with the velocity projection too):
            ``discrete - external - constraint`` is constant to round-off.
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
        """``kinetic + internal - external - constraint``: constant up to an O(dt^2)
        oscillation (the averaged velocity ``v_n`` is not the conserved one)."""
        return self.kinetic + self.internal - self.external - self.constraint

    @property
    def balance(self) -> float:
        """``discrete - external - constraint``: constant to round-off (linear problems)."""
        return self.discrete - self.external - self.constraint


@dataclass
class DynamicsResult:
    """What :meth:`ExplicitDynamics.run` did.

    Attributes:
        dt: The time step. steps: Number of steps taken. time: The final time.
        energies: :class:`EnergyRecord` at this run's energy steps (outputs included; a run
            continued with another step size starts a new level of the discrete energy).
        outputs: ``(step, time)`` of each requested output time (nearest step).
        critical: :meth:`ExplicitDynamics.critical_time_step` (``critical = spectral =
            2 / omega_bound``, the guard; ``courant = h_min / c`` reported only) and ``stable``
            (times ``safety``).
        timings: Seconds in ``steps`` (the loop, outputs excluded), ``per_step``, ``outputs``.
    """

    dt: float
    steps: int
    time: float
    energies: list[EnergyRecord]
    outputs: list[tuple[int, float]]
    critical: dict
    timings: dict = field(default_factory=dict)

    def _relative_change(self, key: str) -> float:
        if not self.energies:
            return 0.0
        e0 = getattr(self.energies[0], key)
        scale = max(abs(e0), *(r.kinetic + r.internal for r in self.energies))
        if scale == 0.0:
            return 0.0
        return max(abs(getattr(r, key) - e0) for r in self.energies) / scale

    @property
    def energy_drift(self) -> float:
        """Relative drift of :attr:`EnergyRecord.balance` (the conserved discrete energy minus
        the work done on the system): ``max_n |B_n - B_0| / max(|B_0|, max_n (kin + int))``."""
        return self._relative_change("balance")

    @property
    def energy_oscillation(self) -> float:
        """The same for :attr:`EnergyRecord.total` (kinetic energy at integer steps): an O(dt^2)
        oscillation of the averaged velocities, not a drift."""
        return self._relative_change("total")

    @property
    def max_residual(self) -> float:
        """Largest relative constraint residual over the records."""
        return max((r.residual for r in self.energies), default=0.0)


# -- the integrator ----------------------------------------------------------------------------


class ExplicitDynamics:
    """Central-difference explicit dynamics of linear elasticity, FE, EFG or coupled.

    Build with :meth:`fe`, :meth:`efg` or :meth:`coupled` (every coupling of
    :data:`~dolfinx_meshfree.dynamics.DYNAMICS_METHODS`); set the initial state with
    :meth:`set_initial`; optionally :meth:`add_traction` and :meth:`add_body_force`; then
    :meth:`run`. The velocity can be
    evaluated at any points (:meth:`velocity_at`) and compared with an exact solution
    (:meth:`velocity_error`, Rabczuk et al. 2006, eq. 137) after a run, at the final time or in
    the ``on_output`` callback. Collective throughout.

    Args:
        fields: One or two :class:`Field` (FE first).
        material: The :class:`~dolfinx_meshfree.LinearElastic` law (density and wave speed).
        constraint: The constraint blocks ``G_f`` of each field (``None`` for a field without),
            or ``None``: no constraint.
        safety: Fraction of the critical time step used by default and allowed without
            ``force`` (0 < safety <= 1).
        blocks: Off-diagonal stiffness blocks ``{(k, l): K_kl}`` (rows of field ``k``, columns
            of field ``l``).
        multiplier_solver: How ``S = G M^{-1} G^T`` is factorised (once): ``"dense"``
            (Cholesky on every rank, one ``Allgatherv`` of ``G v`` per step: the fastest for
            interface-sized ``S``), ``"mumps"`` (distributed LU), or ``None``: dense up to
            2000 multipliers.
        V, mls, particles, mesh, in_patch, patch: What evaluation needs: the FE space, the MLS
            approximation and its particles, the mesh, the patch flag of each local cell.
        interface: The coupling's interface object for evaluation: a
            :class:`~dolfinx_meshfree.couplings.ramp.RampInterface` (blended interface cells) or a
            :class:`~dolfinx_meshfree.couplings.bridging.BridgingBand` (weighted band cells).
        reduction: ``(T_PF, S)`` when the particle field holds master particles only
            (master–slave): the particle coefficients are ``T_PF d_FE + S d_M``.
        body_load: ``body_load(b) -> (fe, particles)``: the consistent loads of a body force
            ``b(x)`` per owned FE dof and per particle dof (original interleaved order, this
            rank's contributions), either ``None`` for a missing field; set by the builders
            (:mod:`~dolfinx_meshfree.dynamic_builders`). ``None``: :meth:`add_body_force` uses
            the lumped masses.
    """

    def __init__(
        self,
        fields: Sequence[Field],
        material: LinearElastic,
        constraint: Sequence[PETSc.Mat | None] | None = None,
        safety: float = 0.9,
        *,
        blocks: dict[tuple[int, int], PETSc.Mat] | None = None,
        V=None,
        mls: MLS | None = None,
        particles: ParticleSet | None = None,
        mesh=None,
        in_patch: np.ndarray | None = None,
        patch=None,
        interface=None,
        reduction: tuple[PETSc.Mat, PETSc.Mat] | None = None,
        timings: dict | None = None,
        multiplier_solver: str | None = None,
        body_load: Callable | None = None,
    ):
        if isinstance(safety, bool) or not (
            isinstance(safety, int | float) and 0.0 < safety <= 1.0
        ):
            raise ValueError(
                f"safety={safety!r} must lie in (0, 1] (a fraction of the critical time step)"
            )
        if multiplier_solver not in (None, "dense", "mumps"):
            raise ValueError(
                f"multiplier_solver={multiplier_solver!r} is not known; use None (automatic), "
                "'dense' or 'mumps'"
            )
        self.fields = list(fields)
        self.material = material
        self.safety = float(safety)
        self.blocks = dict(blocks or {})
        self.V, self.mls, self.particles, self.mesh = V, mls, particles, mesh
        self.in_patch, self.patch = in_patch, patch
        self.interface, self.reduction = interface, reduction
        self._body_load = body_load
        self.comm = self.fields[0].mass.getComm().tompi4py()
        self.timings = dict(timings or {})
        t0 = time.perf_counter()
        self._minv = []
        self.active = []
        self.free = []
        for f in self.fields:
            mi = f.mass.duplicate()
            m = f.mass.array_r
            free = m > 0.0
            if f.fixed is not None:
                free &= ~f.fixed
            mi.array[:] = np.where(free, 1.0 / np.where(m > 0.0, m, 1.0), 0.0)
            self._minv.append(mi)
            self.active.append(m > 0.0)
            self.free.append(free)
        self.u = [f.mass.duplicate() for f in self.fields]
        self.v = [f.mass.duplicate() for f in self.fields]  # v_{n-1/2} (v_0 before the first step)
        for x in (*self.u, *self.v):
            x.set(0.0)
        self.step, self.time = 0, 0.0
        self._dt_prev = 0.0
        self._records: list[EnergyRecord] = []
        self._w_ext, self._w_c = 0.0, np.zeros(len(self.fields))
        self._loads: list[tuple[list[PETSc.Vec | None], Callable[[float], float]]] = []
        self._v_now: list[PETSc.Vec] | None = None  # v_n at the current output time
        self._tables: dict = {}
        self._critical: dict | None = None
        self.G: list[PETSc.Mat | None] | None = None
        self._ksp = None
        self._S = None
        self.multiplier_solver = multiplier_solver
        self._work = [f.mass.duplicate() for f in self.fields]
        self._tmp = [f.mass.duplicate() for f in self.fields]
        if constraint is not None and any(g is not None for g in constraint):
            self.G = list(constraint)
            self._factorise()
        self.timings["setup"] = self.timings.get("setup", 0.0) + time.perf_counter() - t0

    # -- builders ------------------------------------------------------------------------------

    @classmethod
    def fe(
        cls,
        V,
        material: LinearElastic,
        safety: float = 0.9,
        fixed_facets: npt.ArrayLike | None = None,
    ) -> ExplicitDynamics:
        """Pure FE: DOLFINx's stiffness ``inner(sigma(u), eps(v)) dx`` and row-sum masses.

        ``fixed_facets``: owned exterior facets whose nodes are held at rest (strongly).
        """
        from .dynamic_builders import build_fe

        return build_fe(cls, V, material, safety, fixed_facets)

    @classmethod
    def efg(
        cls,
        particles: ParticleSet,
        material: LinearElastic,
        weight: str = "quartic",
        dilation: float = 2.0,
        basis: str = "linear",
        quadrature_degree: int = 7,
        particle_mass: str = "row-sum",
        safety: float = 0.9,
        fixed_facets: npt.ArrayLike | None = None,
        multiplier_solver: str | None = None,
        integration: str = "cells",
    ) -> ExplicitDynamics:
        """Pure EFG on ``particles`` integrated on their background cells (Belytschko et al.
        1995, sec. 5.2): :func:`~dolfinx_meshfree.statics.efg.particle_stiffness` and row-sum
        masses.

        ``fixed_facets``: owned exterior facets held at rest, by facet multipliers on the
        velocities (one per facet and component, corrected each step like eq. 94–96).
        ``integration``: ``"cells"`` (the Gauss rule of ``quadrature_degree``) or
        ``"stress-points"``: the particles and the stress points between them, with their
        volumes and MLS functions of the reference configuration (Lagrangian kernel, computed
        once at t = 0; Rabczuk, Belytschko & Xiao 2004;
        :mod:`~dolfinx_meshfree.geometry.stress_points`);
        the row-sum masses are then ``rho sum_q phi_I(x_q) V_q``.
        """
        from .dynamic_builders import build_efg

        return build_efg(
            cls,
            particles,
            material,
            weight=weight,
            dilation=dilation,
            basis=basis,
            quadrature_degree=quadrature_degree,
            particle_mass=particle_mass,
            safety=safety,
            fixed_facets=fixed_facets,
            multiplier_solver=multiplier_solver,
            integration=integration,
        )

    @classmethod
    def coupled(
        cls,
        problem,
        particle_mass: str = "row-sum",
        safety: float = 0.9,
        multiplier_solver: str | None = None,
        fixed_facets: npt.ArrayLike | None = None,
        integration: str = "cells",
        slaves: str = "layer",
    ) -> ExplicitDynamics:
        """A :class:`~dolfinx_meshfree.CoupledElasticity` in dynamics, any coupling.

        Reuses the static coupling's operators (:meth:`CoupledElasticity.operators`): the
        stiffness blocks, the MLS, the quadrature, the constraint blocks and the interface
        shape functions; see :func:`~dolfinx_meshfree.dynamic_builders.build_coupled`.
        ``fixed_facets``: owned exterior facets held at rest (FE nodes strongly, particles by
        facet multipliers on the velocities). The static problem's own Dirichlet conditions,
        tractions and body force are not used (give loads with :meth:`add_traction` and
        :meth:`add_body_force`).

        ``integration="stress-points"`` integrates the particle stiffness at the particles and
        stress points (Rabczuk, Belytschko & Xiao 2004, Lagrangian kernel: the MLS functions
        of the reference configuration, computed once at t = 0), for lagrange, edge-to-edge
        and master-slave. ``slaves="coincident"`` (master-slave only) fixes the particles on
        the interface to the FE nodes they sit on: Johnson's coupling, Rabczuk et al. 2006,
        sec. 5.1.1, eq. 15–16 (see :mod:`~dolfinx_meshfree.couplings.master_slave`).
        """
        from .dynamic_builders import build_coupled

        return build_coupled(
            cls,
            problem,
            particle_mass,
            safety,
            multiplier_solver,
            fixed_facets,
            integration=integration,
            slaves=slaves,
        )

    # -- stiffness -----------------------------------------------------------------------------

    def _apply_K(self, x: Sequence[PETSc.Vec], y: Sequence[PETSc.Vec]) -> None:
        """``y = K x`` with the diagonal and off-diagonal blocks."""
        for k, f in enumerate(self.fields):
            f.K.mult(x[k], y[k])
        for (k, j), B in self.blocks.items():
            B.multAdd(x[j], y[k], y[k])

    # -- constraint ----------------------------------------------------------------------------

    def _factorise(self) -> None:
        """``S = sum_f G_f M_f^{-1} G_f^T`` (eq. 96's matrix), factorised once."""
        S = None
        for G, mi in zip(self.G, self._minv, strict=True):
            if G is None:
                continue
            GT = G.transpose(PETSc.Mat())  # (without an argument petsc4py transposes in place)
            GT.diagonalScale(L=mi)
            Sf = G.matMult(GT)
            GT.destroy()
            if S is None:
                S = Sf
            else:
                S.axpy(1.0, Sf, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                Sf.destroy()
        self._S = S
        size = S.getSize()[0]
        solver = self.multiplier_solver
        if solver is None:
            solver = "dense" if size <= _DENSE_MAX else "mumps"
        self.multiplier_solver = solver
        if solver == "dense":
            # small S: every rank holds its Cholesky factor, one Allgatherv per step
            ai, aj, av = S.getValuesCSR()
            lo, hi = S.getOwnershipRange()
            rows = np.repeat(np.arange(lo, hi), np.diff(ai))
            parts = self.comm.allgather((rows, np.asarray(aj), np.asarray(av)))
            dense = np.zeros((size, size))
            for r, c, v in parts:
                np.add.at(dense, (r, c), v)
            try:
                self._chol = cho_factor(dense)
            except LinAlgError as e:
                raise ValueError(
                    f"the constraint matrix G M^-1 G^T ({size} rows) is singular: two constraints "
                    "act on the same dofs only (e.g. an interface node on a fixed facet whose "
                    "particles are fixed too); fix fewer facets or move the interface"
                ) from e
            self._counts = np.array(self.comm.allgather(hi - lo))
            self._full = np.zeros(size)
        else:
            self._ksp = _lu(S)
        self._lam = S.createVecRight()
        self._gv = S.createVecLeft()
        self._gnorm = [0.0 if G is None else G.norm(PETSc.NormType.INFINITY) for G in self.G]

    def _correct(self, vel: list[PETSc.Vec], impulse: list[PETSc.Vec] | None = None) -> None:
        """Project velocities onto ``G v = 0`` (eq. 95–96): solve ``S lambda = G v``, then
        ``v -= M^{-1} G^T lambda``; ``impulse`` receives ``G_f^T lambda`` per field."""
        self._gv.set(0.0)
        for G, x in zip(self.G, vel, strict=True):
            if G is not None:
                G.multAdd(x, self._gv, self._gv)
        if self._ksp is not None:
            self._ksp.solve(self._gv, self._lam)
        else:
            self.comm.Allgatherv(self._gv.array_r, [self._full, self._counts])
            lam = cho_solve(self._chol, self._full)
            lo, hi = self._lam.getOwnershipRange()
            self._lam.array[:] = lam[lo:hi]
        for k, (G, x) in enumerate(zip(self.G, vel, strict=True)):
            if G is None:
                continue
            w = self._work[k] if impulse is None else impulse[k]
            G.multTranspose(self._lam, w)
            self._tmp[k].pointwiseMult(self._minv[k], w)
            x.axpy(-1.0, self._tmp[k])

    def constraint_residual(self, vel: list[PETSc.Vec] | None = None) -> float:
        """Relative residual ``|sum_f G_f v_f|_inf / sum_f |G_f|_inf |v_f|_inf`` (collective);
        0 without a constraint. Default: the velocities at the current time."""
        if self.G is None:
            return 0.0
        vel = vel if vel is not None else (self._v_now or self.v)
        self._gv.set(0.0)
        scale = 0.0
        for G, x, gn in zip(self.G, vel, self._gnorm, strict=True):
            if G is not None:
                G.multAdd(x, self._gv, self._gv)
                scale += gn * x.norm(PETSc.NormType.INFINITY)
        r = self._gv.norm(PETSc.NormType.INFINITY)
        return float(r / scale) if scale > 0 else float(r)

    # -- time step -----------------------------------------------------------------------------
    def critical_time_step(self, iterations: int = 30) -> dict:
        """Critical time step from an upper bound of ``omega_max`` (collective, computed once).

        Central differences are stable for ``dt <= 2 / omega_max`` (Belytschko et al. 1995,
        sec. 5.2), ``omega_max^2`` the largest eigenvalue of the constrained operator
        ``P M^{-1} K`` on the free dofs (``P`` the velocity projection of eq. 94–96, which is
        ``M``-orthogonal, and dofs with ``M^{-1} = 0`` held at rest). A too large estimate of
        the step is unstable, so the guard is a bound that cannot be too small in ``omega``:
        the Schur test with ``B = M^{-1/2} K M^{-1/2}`` (free dofs) and any positive ``y``,

        .. math::
            \\omega_{max}^2 \\le |P M^{-1} K|_M \\le |B|_2 \\le \\sqrt{
            \\max_i \\frac{(|K| y)_i}{m_i y_i} \\, \\max_j \\frac{(|K|^T y)_j}{m_j y_j}},

        since ``|P|_M = 1``. With ``y = 1`` it is Gershgorin's row-sum bound
        ``max_i sum_j |K_ij| / m_i`` (for a symmetric ``K`` both factors agree); ``y`` is then
        improved by ``iterations`` power steps with ``M^{-1} (|K| + |K|^T) / 2`` and the smallest
        bound is kept (every iterate gives a valid bound; it tends to the spectral radius of
        ``|M^{-1} K|``). The bound holds for a non-symmetric ``K`` too (consistent integration),
        for ``|lambda|``. The Courant estimate ``h_min / c`` is reported, not used: it exceeds
        the critical step on triangles (0.69 h/c), for ``nu -> 1/2`` and for small weighted
        masses (bridging), and is conservative for EFG.

        Returns:
            ``{"courant": h_min / c, "spectral": 2 / omega_bound, "critical": the same (the
            guard), "omega_bound": ..., "gershgorin": 2 / (the row-sum bound with y = 1),
            "h_min": ..., "wave_speed": ...}``.
        """
        if self._critical is not None:
            return self._critical
        c = self.material.wave_speed()
        h = min(f.spacing for f in self.fields)
        F = len(self.fields)
        absolute = {(k, k): _absolute(f.K) for k, f in enumerate(self.fields)}
        absolute.update({kl: _absolute(B) for kl, B in self.blocks.items()})
        free = [fr.astype(float) for fr in self.free]
        y = [f.mass.duplicate() for f in self.fields]
        r = [f.mass.duplicate() for f in self.fields]
        col = [f.mass.duplicate() for f in self.fields]
        for yk, fk in zip(y, free, strict=True):
            yk.array[:] = fk

        def ratio(vecs: list[PETSc.Vec]) -> float:
            """``max_i v_i / (m_i y_i)`` over the free dofs (every rank)."""
            loc = 0.0
            for v, yk, f, fk in zip(vecs, y, self.fields, free, strict=True):
                on = fk > 0.0
                if on.any():
                    loc = max(
                        loc, float(np.max(v.array_r[on] / (f.mass.array_r[on] * yk.array_r[on])))
                    )
            return float(self.comm.allreduce(loc, op=MPI.MAX))

        best, first = np.inf, np.inf
        for it in range(iterations + 1):
            for k in range(F):
                r[k].set(0.0)
                col[k].set(0.0)
            for (k, j), A in absolute.items():
                A.multAdd(y[j], r[k], r[k])
                A.multTransposeAdd(y[k], col[j], col[j])
            lam = np.sqrt(ratio(r) * ratio(col))
            best = min(best, lam)
            if it == 0:
                first = lam
            if it == iterations or lam == 0.0:
                break
            top = 0.0
            for k in range(F):  # y <- M^{-1} (|K| + |K|^T) y / 2 on the free dofs
                yk = 0.5 * (r[k].array_r + col[k].array_r) * self._minv[k].array_r * free[k]
                y[k].array[:] = yk
                top = max(top, float(yk.max(initial=0.0)))
            top = self.comm.allreduce(top, op=MPI.MAX)
            if top <= 0.0:
                break
            for yk, fk in zip(y, free, strict=True):  # positive on the free dofs
                yk.array[:] = np.maximum(yk.array_r / top, 1e-3) * fk
        for obj in (*absolute.values(), *y, *r, *col):
            obj.destroy()
        spectral = 2.0 / np.sqrt(best) if best > 0 else np.inf
        self._critical = {
            "courant": float(h / c),
            "spectral": float(spectral),
            "critical": float(spectral),
            "omega_bound": float(np.sqrt(best)),
            "gershgorin": float(2.0 / np.sqrt(first)) if first > 0 else np.inf,
            "h_min": float(h),
            "wave_speed": float(c),
        }
        return self._critical

    def stable_time_step(self) -> float:
        """``safety`` times the critical time step (collective)."""
        return self.safety * self.critical_time_step()["critical"]

    # -- state ---------------------------------------------------------------------------------

    def set_initial(
        self,
        velocity: VectorFunction | None = None,
        displacement: VectorFunction | None = None,
        particle_values: str = "collocation",
    ) -> None:
        """Initial displacement and velocity from functions of position (m, 2) -> (m, 2).

        FE dofs take the nodal values; particle coefficients either reproduce the values at the
        particles (``"collocation"``: ``Phi(x_J) c = f(x_J)``, one sparse LU, MLS being not
        interpolating) or take them (``"nodal"``); master–slave keeps the masters' values. Fixed
        dofs start at rest. With a constraint, both fields are then projected onto ``G d = 0``,
        ``G v = 0`` in the mass metric. Resets time to 0.
        """
        if particle_values not in ("collocation", "nodal"):
            raise ValueError(
                f"particle_values={particle_values!r} is not known; use 'collocation' or 'nodal'"
            )
        for target, fn, mask in (
            (self.u, displacement, self.active),
            (self.v, velocity, self.free),
        ):
            for k, f in enumerate(self.fields):
                target[k].set(0.0)
                if fn is None:
                    continue
                if f.name == "fe":
                    vals = self._fe_nodal_values(fn)
                else:
                    vals = self._particle_coefficients(fn, particle_values)
                target[k].array[:] = vals * mask[k]
            if fn is not None and self.G is not None:
                self._correct(target)
        self.step, self.time = 0, 0.0
        self._dt_prev = 0.0
        self._v_now = None
        self._records, self._w_ext, self._w_c = [], 0.0, np.zeros(len(self.fields))

    def _owned_points(self, k: int) -> np.ndarray:
        """Positions (owned, in PETSc order) of field ``k``'s nodes or particles."""
        f = self.fields[k]
        if f.points is not None:
            return f.points
        if f.name == "fe":
            n_owned = self.V.dofmap.index_map.size_local
            return self.V.tabulate_dof_coordinates()[:n_owned, :2]
        P = self.particles
        return P.positions[P.owned[np.argsort(P.petsc_index[P.owned], kind="stable")]]

    def _fe_nodal_values(self, fn: VectorFunction) -> np.ndarray:
        x = self._owned_points(0)
        vals = raise_on_all_ranks(self.comm, lambda: _values(fn, x))
        return vals.ravel()

    def _particle_coefficients(self, fn: VectorFunction, how: str) -> np.ndarray:
        """Owned particle coefficients (PETSc order) of the particle field."""
        P = self.particles
        own = P.owned[np.argsort(P.petsc_index[P.owned], kind="stable")]
        x = P.positions[own]
        vals = raise_on_all_ranks(self.comm, lambda: _values(fn, x))
        if how == "collocation":
            n = P.num_particles
            sl = Layout(P.layout.size_local, n, P.layout.start)
            phi = raise_on_all_ranks(self.comm, lambda: self.mls.tabulate(x, 0)).values.tocoo()
            rows = P.petsc_index[own]
            A_loc = sp.csr_matrix((phi.data, (rows[phi.row], P.petsc_index[phi.col])), shape=(n, n))
            A = create_aij(self.comm, A_loc, sl, sl)
            ksp = _lu(A)  # one factorisation, two components
            out = np.empty_like(vals)
            xs = A.createVecRight()
            for comp in range(2):
                b = create_vector(self.comm, sl, rows, vals[:, comp])
                ksp.solve(b, xs)
                if ksp.getConvergedReason() < 0:
                    raise RuntimeError("the collocation solve Phi(x_J) c = f(x_J) failed (MUMPS)")
                out[:, comp] = xs.array_r
                b.destroy()
            for obj in (xs, ksp, A):
                obj.destroy()
            vals = out
        if self.reduction is None:
            return vals.ravel()
        # master-slave: keep the masters' coefficients (the selection of S's master rows)
        S = self.reduction[1].query(MASTER_SELECTION) or self.reduction[1]
        full = S.createVecLeft()
        full.array[:] = vals.ravel()
        masters = S.createVecRight()
        S.multTranspose(full, masters)
        out = masters.array_r.copy()
        full.destroy()
        masters.destroy()
        return out

    def add_traction(
        self,
        facets: npt.ArrayLike,
        traction: Callable[[np.ndarray, np.ndarray], np.ndarray],
        amplitude: Callable[[float], float] | None = None,
    ) -> None:
        """External load ``amplitude(t) * traction(x, n)`` on owned exterior facets (collective).

        ``traction`` maps points (m, 2) and outward normals (m, 2) to tractions (m, 2), assembled
        with the FE basis on facets of FE cells and with the MLS functions on facets of particle
        cells (Belytschko et al. 1995, eq. 4.5). ``amplitude`` defaults to 1 (a step load).
        Facets of ramp interface cells or bridging band cells are refused (``ValueError``).
        """
        msh = self.mesh
        deg = 4
        facets = np.asarray(facets, dtype=np.int32)
        msh.topology.create_connectivity(msh.topology.dim - 1, msh.topology.dim)
        f2c = msh.topology.connectivity(msh.topology.dim - 1, msh.topology.dim)
        first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
        blended = self._blended_cells()

        def check() -> None:
            if blended is not None and np.any(blended[first]):
                raise ValueError(
                    f"{int(np.sum(blended[first]))} traction facet(s) lie on ramp interface or "
                    "bridging band cells, where the load would need the blended functions; load "
                    "facets of pure FE or particle cells"
                )

        raise_on_all_ranks(self.comm, check)
        if self.in_patch is not None:
            on_p = self.in_patch[first]
        else:
            on_p = np.full(facets.size, self.V is None)
        parts = []
        for f in self.fields:
            sel = facets[on_p] if f.name == "particles" else facets[~on_p]
            q = facet_quadrature(msh, sel, deg)
            t = raise_on_all_ranks(self.comm, lambda q=q: _values(traction, q.points, q.normals))
            if f.name == "fe":
                imap = self.V.dofmap.index_map
                l2g = np.asarray(
                    imap.local_to_global(
                        np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
                    )
                )
                tab = tabulate_in_cells(self.V, q.points, q.cells, derivatives=0).values
                fl = load_vector(tab, q.weights, t).reshape(-1, 2)
                parts.append(((2 * l2g[: fl.shape[0], None] + np.arange(2)).ravel(), fl.ravel()))
            else:
                tab = raise_on_all_ranks(self.comm, lambda q=q: self.mls.tabulate(q.points, 0))
                parts.append(
                    (self.particles.petsc_dofs(2).ravel(), load_vector(tab.values, q.weights, t))
                )
        self._add_load(parts, amplitude)

    def add_body_force(
        self, force: VectorFunction, amplitude: Callable[[float], float] | None = None
    ) -> None:
        """External load ``amplitude(t) * int b . v`` of a body force ``b(x)`` per unit volume
        (points (m, 2) -> (m, 2)) on the whole body (collective).

        FE, EFG and every coupling of :meth:`coupled` integrate it with the functions and
        weights of their masses and stiffness (:mod:`~dolfinx_meshfree.physics.body_loads`: ramp
        interface cells blended, eq. 3.15 of Belytschko et al. 1995; bridging band weighted by
        ``1 - alpha`` and ``alpha``, Rabczuk et al. 2006, eq. 49; master-slave through ``T^T``,
        eq. 28); other models take the lumped load ``M b(x_I) / rho`` at their nodes and
        particles, exact for a constant ``b``. ``amplitude`` defaults to 1 (a step load).
        """
        if self._body_load is not None:
            fe, f_p = self._body_load(force)
            parts = []
            for f in self.fields:
                if f.name == "fe":
                    lo, hi = f.mass.getOwnershipRange()
                    parts.append((np.arange(lo, hi), fe))
                else:
                    parts.append((self.particles.petsc_dofs(2).ravel(), f_p))
            self._add_load(parts, amplitude)
            return
        vecs = []
        for k, f in enumerate(self.fields):
            x = self._owned_points(k)
            b = raise_on_all_ranks(self.comm, lambda x=x: _values(force, x))
            vec = f.mass.duplicate()
            vec.array[:] = f.mass.array_r * b.ravel() / self.material.rho
            vecs.append(vec)
        self._add_load_vectors(vecs, amplitude)

    def _add_load(self, parts: list, amplitude: Callable[[float], float] | None) -> None:
        """Add a load given per field as ``(global dofs, values)`` (any rank may add any dof; a
        master-slave particle field's values are reduced to the FE nodes and masters by
        ``T^T``, eq. 28). Collective."""
        vecs: list[PETSc.Vec] = []
        for f, (rows, vals) in zip(self.fields, parts, strict=True):
            if self.reduction is not None and f.name == "particles":
                # master-slave: particle forces reach the masters through T^T (eq. 28)
                Tpf, S = self.reduction
                full = create_vector(self.comm, _row_layout(S), rows, vals)
                b = S.createVecRight()
                S.multTranspose(full, b)
                Tpf.multTransposeAdd(full, vecs[0], vecs[0])
                full.destroy()
                vecs.append(b)
                continue
            b = f.mass.duplicate()
            b.set(0.0)
            b.setValues(rows.astype(PETSc.IntType), vals, addv=PETSc.InsertMode.ADD_VALUES)
            b.assemblyBegin()
            b.assemblyEnd()
            vecs.append(b)
        self._add_load_vectors(vecs, amplitude)

    def _add_load_vectors(self, vecs: list[PETSc.Vec], amplitude) -> None:
        for k, b in enumerate(vecs):  # no load on fixed dofs
            b.array[:] = b.array_r * self.free[k]
        self._loads.append((vecs, amplitude if amplitude is not None else _one))

    # -- stepping ------------------------------------------------------------------------------

    def run(
        self,
        t_end: float,
        dt: float | None = None,
        *,
        force: bool = False,
        outputs: Sequence[float] = (),
        energy_records: int = 100,
        on_output: Callable[[ExplicitDynamics, int, float], None] | None = None,
        xdmf: str | os.PathLike | None = None,
        progress: bool | None = None,
    ) -> DynamicsResult:
        """Integrate from the current time to ``t_end`` (Belytschko et al. 1995, sec. 5.2;
        Rabczuk et al. 2006, Table I). Collective.

        Args:
            t_end: Final time (> current time).
            dt: Requested time step; default the stable one (:meth:`stable_time_step`). The step
                actually used is ``(t_end - t) / ceil((t_end - t) / dt)`` so that ``t_end`` is
                hit exactly.
            force: Allow ``dt`` above the stable step.
            outputs: Times at which ``on_output(self, step, time)`` is called with the state at
                the nearest step (``velocity_at``/``velocity_error`` then see ``v_n``).
            energy_records: About how many :class:`EnergyRecord` to keep (outputs added).
            on_output: ``on_output(self, step, time)``, called at each output time, e.g. a
                :class:`~dolfinx_meshfree.io.DynamicsWriter`.
            xdmf: An output prefix: write the FE fields, the particle cloud and the energy
                records at every output time through a
                :class:`~dolfinx_meshfree.io.DynamicsWriter` made (and closed) for this run,
                before ``on_output`` is called; without ``outputs``, at the current time and at
                ``t_end``. A second run with the same prefix overwrites the files (pass one
                writer as ``on_output`` to several runs to append instead).
            progress: A progress bar on rank 0's stderr (:class:`~dolfinx_meshfree.io.ProgressBar`):
                ``True`` on, ``False`` off, ``None`` on when stderr is a terminal.

        Raises:
            ValueError: ``dt`` not positive, above the stable step without ``force``, or
                ``t_end`` not after the current time; ``progress`` not a bool or ``None``; an
                unusable ``xdmf`` prefix (on every rank, before any file is written).
        """
        crit = self.critical_time_step()
        stable = self.safety * crit["critical"]
        span = float(t_end) - self.time
        if not (np.isfinite(span) and span > 0.0):
            raise ValueError(f"t_end={t_end!r} must lie after the current time {self.time}")
        if dt is None:
            dt = stable
        elif not (isinstance(dt, int | float) and np.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt={dt!r} must be a positive number")
        elif dt > stable * (1.0 + 1e-12) and not force:
            raise ValueError(
                f"dt={dt:.6g} is above the stable time step {stable:.6g} (safety {self.safety} x "
                f"critical 2/omega_bound = {crit['critical']:.6g}, omega_bound >= omega_max; "
                f"Courant h_min/c = {crit['courant']:.6g} with h_min = {crit['h_min']:.4g}); "
                f"pass dt <= {stable:.6g}, dt=None for the stable step, or force=True"
            )
        nsteps = max(1, int(np.ceil(span / dt - 1e-9)))
        dt = span / nsteps
        n0 = self.step
        t0 = self.time
        from .io import DynamicsWriter, ProgressBar

        progress_bar = ProgressBar(nsteps, self.comm, progress, label="explicit dynamics ")
        writer = DynamicsWriter(xdmf, self) if xdmf is not None else None
        if writer is not None and not len(outputs):
            outputs = (t0, float(t_end))
        callback = on_output
        if writer is not None:

            def callback(d: ExplicitDynamics, n: int, t: float) -> None:
                writer(d, n, t)
                if on_output is not None:
                    on_output(d, n, t)

        F = len(self.fields)
        out_steps = {n0 + min(nsteps, max(0, round((t - t0) / dt))): t for t in outputs}
        every = max(1, nsteps // max(1, energy_records))
        energy_steps = set(range(n0, n0 + nsteps + 1, every)) | set(out_steps) | {n0 + nsteps}
        ku, vnew, vnow, imp = ([f.mass.duplicate() for f in self.fields] for _ in range(4))
        for x in imp:
            x.set(0.0)
        records: list[EnergyRecord] = self._records
        first = len(records)
        w_ext, w_c = self._w_ext, self._w_c
        pk = [k for k, f in enumerate(self.fields) if f.name == "particles"]
        t_out = 0.0
        outs: list[tuple[int, float]] = []
        clock = time.perf_counter()
        try:
            for n in range(n0, n0 + nsteps + 1):
                tn = t0 + (n - n0) * dt
                # v_{n+1/2} = v_{n-1/2} + (dt_{n-1/2} + dt_{n+1/2}) / 2 a_n (a new run may
                # change dt)
                gamma = 0.5 if n == 0 else (0.5 * (1.0 + self._dt_prev / dt) if n == n0 else 1.0)
                amps = [a(tn) for _, a in self._loads]
                # trial velocities (eq. 93): vbar = v_{n-1/2} + gamma dt M^{-1} (f_ext - K d_n)
                self._apply_K(self.u, ku)
                for k in range(F):
                    ku[k].copy(self._work[k])
                    for (vecs, _), an in zip(self._loads, amps, strict=True):
                        if vecs[k] is not None and an != 0.0:
                            self._work[k].axpy(-an, vecs[k])
                    vnew[k].pointwiseMult(self._minv[k], self._work[k])
                    vnew[k].aypx(-gamma * dt, self.v[k])
                # multiplier correction (eq. 94-96): G v_{n+1/2} = 0
                if self.G is not None:
                    self._correct(vnew, imp)
                # work of the step, f_n . (d_{n+1} - d_{n-1}) / 2
                # = dt f_n . (v_{n+1/2} + v_{n-1/2}) / 2, which balances the central-difference
                # energy exactly (see EnergyRecord)
                d_ext, d_c = 0.0, np.zeros(F)
                if n > 0:
                    for (vecs, _), an in zip(self._loads, amps, strict=True):
                        for b, v0, v1 in zip(vecs, self.v, vnew, strict=True):
                            if b is not None and an != 0.0:
                                d_ext += 0.5 * an * dt * (b.dot(v0) + b.dot(v1))
                    if self.G is not None:  # constraint force -G^T lambda / dt
                        for k in range(F):
                            if self.G[k] is not None:
                                d_c[k] = -0.5 * (imp[k].dot(self.v[k]) + imp[k].dot(vnew[k]))
                if n in energy_steps:
                    tic = time.perf_counter()
                    for k in range(F):  # v_n
                        if n == 0:
                            self.v[k].copy(vnow[k])
                        else:
                            vnow[k].waxpy(1.0, self.v[k], vnew[k])
                            vnow[k].scale(0.5)
                    kin = half = internal = cross = 0.0
                    for k, f in enumerate(self.fields):
                        kin += 0.5 * f.mass.dot(_times(vnow[k], vnow[k], self._tmp[k]))
                        half += 0.5 * f.mass.dot(_times(vnew[k], vnew[k], self._tmp[k]))
                        internal += 0.5 * self.u[k].dot(ku[k])
                        cross += 0.5 * dt * ku[k].dot(vnew[k])
                    rec = EnergyRecord(
                        step=n,
                        time=tn,
                        kinetic=float(kin),
                        internal=float(internal),
                        external=float(w_ext + d_ext),
                        constraint=float((w_c + d_c).sum()),
                        transfer=float((w_c + d_c)[pk[0]]) if pk and self.G is not None else 0.0,
                        discrete=float(half + internal + cross),
                        residual=self.constraint_residual(vnew),
                    )
                    records.append(rec)
                    if n in out_steps:
                        self._v_now = vnow
                        self.time, self.step = tn, n
                        outs.append((n, tn))
                        if callback is not None:
                            callback(self, n, tn)
                        self._v_now = None
                    t_out += time.perf_counter() - tic
                if n == n0 + nsteps:
                    break  # v_N is known; the state stays (d_N, v_{N-1/2}) for a next run
                w_ext += d_ext
                w_c = w_c + d_c
                for k in range(F):
                    self.u[k].axpy(dt, vnew[k])
                    vnew[k].copy(self.v[k])
                progress_bar.update(n + 1 - n0, t0 + (n + 1 - n0) * dt)
        finally:
            progress_bar.close(nsteps if n == n0 + nsteps else None, t0 + (n - n0) * dt)
            if writer is not None:
                writer.close()
        t_loop = time.perf_counter() - clock - t_out
        self.step, self.time = n0 + nsteps, t0 + span
        self._dt_prev = dt
        # keep v_N for evaluation after the run
        for x in getattr(self, "_final", []):
            x.destroy()
        self._final = [x.copy() for x in vnow]
        self._v_now = self._final
        self._records, self._w_ext, self._w_c = records, w_ext, w_c
        for obj in (*ku, *vnew, *vnow, *imp):
            obj.destroy()
        return DynamicsResult(
            dt=dt,
            steps=nsteps,
            time=self.time,
            energies=records[first:],
            outputs=outs,
            critical={**crit, "stable": stable},
            timings={"steps": t_loop, "per_step": t_loop / nsteps, "outputs": t_out},
        )

    # -- evaluation ----------------------------------------------------------------------------

    def _current(self) -> list[PETSc.Vec]:
        return self._v_now if self._v_now is not None else self.v

    def _blended_cells(self) -> np.ndarray | None:
        """bool per local cell: a ramp interface cell or a bridging band cell (else ``None``)."""
        if self.interface is None:
            return None
        for name in ("in_interface", "in_band"):
            flags = getattr(self.interface, name, None)
            if flags is not None:
                return flags
        return None

    def _local_values(self, vecs: list[PETSc.Vec], particles: bool = True) -> tuple:
        """(FE Function with ghosts or None, particle coefficients (n, 2) or None); with
        ``particles=False`` the particle coefficients are not gathered (``None``)."""
        fe, coeffs = None, None
        for f, x in zip(self.fields, vecs, strict=True):
            if f.name != "fe" and not particles:
                continue
            if f.name == "fe":
                fe = dolfinx.fem.Function(self.V)
                fe.x.array[: x.getLocalSize()] = x.array_r
                fe.x.scatter_forward()
            else:
                if self.reduction is not None:  # master-slave: u_P = T_PF u_FE + S u_M
                    Tpf, S = self.reduction
                    full = Tpf.createVecLeft()
                    Tpf.mult(vecs[0], full)
                    S.multAdd(x, full, full)
                    owned = np.concatenate(self.comm.allgather(full.array_r.copy()))
                    full.destroy()
                else:
                    owned = np.concatenate(self.comm.allgather(x.array_r.copy()))
                coeffs = owned.reshape(-1, 2)[self.particles.petsc_index]
        return fe, coeffs

    def velocity_at(self, points: npt.ArrayLike) -> np.ndarray:
        """Velocity (m, 2) at this rank's points, which may lie anywhere in the mesh
        (collective). Raises :class:`~dolfinx_meshfree.PointsOutsideMeshError` on every rank if
        a point is outside the body."""
        return self._field_at(self._current(), points)

    def displacement_at(self, points: npt.ArrayLike) -> np.ndarray:
        """Displacement (m, 2) at this rank's points, like :meth:`velocity_at` (collective)."""
        return self._field_at(self.u, points)

    def fe_functions(self) -> tuple[dolfinx.fem.Function, dolfinx.fem.Function]:
        """The FE displacement and velocity at the current time as new DOLFINx Functions named
        ``"displacement"`` and ``"velocity"`` (ghosts updated; collective). FE nodes outside
        the FE field (touched by patch cells only) hold zero.

        Raises:
            ValueError: the model has no FE field (pure EFG).
        """
        if self.V is None:
            raise ValueError("this model has no FE field (pure EFG): no FE functions")
        out = []
        for name, vecs in (("displacement", self.u), ("velocity", self._current())):
            fe, _ = self._local_values(vecs, particles=False)
            fe.name = name
            out.append(fe)
        return out[0], out[1]

    @property
    def energy_record(self) -> EnergyRecord | None:
        """The latest :class:`EnergyRecord` (at an output time: that step's), or ``None``."""
        return self._records[-1] if self._records else None

    def _field_at(self, vecs: list[PETSc.Vec], points: npt.ArrayLike) -> np.ndarray:
        """The field with dof values ``vecs`` at this rank's points (collective)."""
        fe, coeffs = self._local_values(vecs)
        if coeffs is None:
            return evaluate_fe_function(fe, points)
        if fe is None:
            x = ensure_points_in_mesh(self.mesh, points)
            return self.mls.tabulate(x, 0).values @ coeffs
        from .couplings.base import CoupledSolution
        from .couplings.bridging import BridgingBand, BridgingSolution
        from .couplings.ramp import RampInterface

        ramp = self.interface if isinstance(self.interface, RampInterface) else None
        sol = CoupledSolution(
            u=fe, coefficients=coeffs, mls=self.mls, patch=self.patch, interface=ramp
        )
        if isinstance(self.interface, BridgingBand):
            sol = BridgingSolution(u=fe, coefficients=coeffs, mls=self.mls, patch=self.patch)
            sol.band = self.interface
        return sol.displacement(points)

    def _quadrature_tables(self, degree: int):
        """Cell quadrature and the maps ``(A_FE, A_P)`` (nq x local FE nodes, nq x particles)
        from FE nodal values and particle coefficients to the field at its points: FE on FE
        cells, MLS on particle cells, the ramp's blended functions on interface cells and
        ``(1 - alpha) N, alpha phi`` on bridging band cells (cached)."""
        if degree in self._tables:
            return self._tables[degree]
        q = cell_quadrature(self.mesh, degree)
        nq = len(q)
        if self.in_patch is not None:
            on_p = self.in_patch[q.cells]
        else:
            on_p = np.full(nq, self.V is None)
        blended = self._blended_cells()
        mixed = blended[q.cells] if blended is not None else np.zeros(nq, dtype=bool)
        n_fe = (
            self.V.dofmap.index_map.size_local + self.V.dofmap.index_map.num_ghosts if self.V else 0
        )
        n_p = self.particles.num_particles if self.particles is not None else 0
        parts_fe: list = []
        parts_p: list = []

        def add(parts, rows, mat):
            c = mat.tocoo()
            parts.append((rows[c.row], c.col, c.data))

        pure_fe = np.flatnonzero(~on_p & ~mixed)
        pure_p = np.flatnonzero(on_p & ~mixed)
        mix = np.flatnonzero(mixed)
        if self.V is not None and pure_fe.size:
            add(
                parts_fe,
                pure_fe,
                tabulate_in_cells(self.V, q.points[pure_fe], q.cells[pure_fe], 0).values,
            )
        if self.mls is not None:
            pts = q.points[pure_p]
            t = raise_on_all_ranks(self.comm, lambda: self.mls.tabulate(pts, 0)).values
            add(parts_p, pure_p, t)
        if blended is not None:
            pts, cells = q.points[mix], q.cells[mix]
            if hasattr(self.interface, "in_interface"):  # ramp: [FE nodes | particles] columns
                t = raise_on_all_ranks(self.comm, lambda: self.interface.table(pts, cells, 0))
                t = t.values.tocsc()
                add(parts_fe, mix, t[:, :n_fe])
                add(parts_p, mix, t[:, n_fe:])
            else:  # bridging band: (1 - alpha) u_FE + alpha u_P
                a = self.interface.alpha_at(pts, cells)
                t_fe = tabulate_in_cells(self.V, pts, cells, 0).values
                t_p = raise_on_all_ranks(self.comm, lambda: self.mls.tabulate(pts, 0)).values
                add(parts_fe, mix, sp.diags(1.0 - a) @ t_fe)
                add(parts_p, mix, sp.diags(a) @ t_p)

        def assemble(parts, ncols):
            if not ncols:
                return None
            r, c, v = (np.concatenate([p[i] for p in parts] + [np.zeros(0)]) for i in range(3))
            return sp.csr_matrix((v, (r.astype(np.int64), c.astype(np.int64))), shape=(nq, ncols))

        self._tables[degree] = (q, assemble(parts_fe, n_fe), assemble(parts_p, n_p))
        return self._tables[degree]

    def velocity_at_quadrature(self, degree: int = 5) -> tuple[QuadraturePoints, np.ndarray]:
        """Cell quadrature of degree ``degree`` on the owned cells and the velocity (nq, 2)
        there: FE on FE cells, MLS on particle cells, blended on ramp interface and bridging
        band cells (tables cached; collective)."""
        q, A_fe, A_p = self._quadrature_tables(degree)
        fe, coeffs = self._local_values(self._current())
        vals = np.zeros((len(q), 2))
        if A_fe is not None:
            vals += A_fe @ fe.x.array.reshape(-1, 2)
        if A_p is not None:
            vals += A_p @ coeffs
        return q, vals

    def velocity_error(
        self, exact: Callable[[np.ndarray, float], np.ndarray], degree: int = 5
    ) -> float:
        """Relative L2 velocity error ``|v_h - v| / |v|`` at the current time (Rabczuk et al.
        2006, eq. 137), integrated on the owned cells (collective, same on every rank).

        Args:
            exact: ``exact(points (m, 2), t) -> (m, 2)``.
        """
        q, vh = self.velocity_at_quadrature(degree)
        ve = np.asarray(exact(q.points, self.time), dtype=float)
        s = np.array(
            [
                np.sum(q.weights * np.sum((vh - ve) ** 2, axis=1)),
                np.sum(q.weights * np.sum(ve**2, 1)),
            ]
        )
        s = self.comm.allreduce(s, op=MPI.SUM)
        return float(np.sqrt(s[0] / s[1])) if s[1] > 0 else float(np.sqrt(s[0]))

    def num_dofs(self) -> dict:
        """Active FE dofs, particle dofs (master–slave: the masters) and multipliers (global)."""
        out = {"fe_dofs": 0, "particle_dofs": 0, "multiplier_dofs": 0}
        for f, act in zip(self.fields, self.active, strict=True):
            key = "fe_dofs" if f.name == "fe" else "particle_dofs"
            out[key] = int(self.comm.allreduce(int(act.sum()), op=MPI.SUM))
        if self._S is not None:
            out["multiplier_dofs"] = int(self._S.getSize()[0])
        return out

    def destroy(self) -> None:
        """Destroy the PETSc objects (collective)."""
        objs = [*self.u, *self.v, *self._minv, *self.blocks.values(), *(self.reduction or ())]
        for f in self.fields:
            objs += [f.K, f.mass]
        objs += [g for g in (self.G or []) if g is not None]
        for name in ("_ksp", "_S", "_lam", "_gv"):
            if getattr(self, name, None) is not None:
                objs.append(getattr(self, name))
        objs += self._work + self._tmp + getattr(self, "_final", [])
        for vecs, _ in self._loads:
            objs += [b for b in vecs if b is not None]
        for obj in objs:
            obj.destroy()


# -- helpers -----------------------------------------------------------------------------------


def _absolute(A: PETSc.Mat) -> PETSc.Mat:
    """``|A|`` (entrywise absolute values), a new AIJ matrix with the layout of ``A``."""
    ai, aj, av = A.getValuesCSR()
    B = PETSc.Mat().createAIJ(A.getSizes(), csr=(ai, aj, np.abs(av)), comm=A.getComm())
    B.assemble()
    return B


def _lu(A: PETSc.Mat) -> PETSc.KSP:
    """A private KSP (own options prefix) holding the MUMPS LU factorisation of ``A``."""
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(f"dolfinx_meshfree_dyn_{next(_prefix_counter)}_")
    ksp.setOperators(A)
    ksp.setType(PETSc.KSP.Type.PREONLY)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.LU)
    pc.setFactorSolverType("mumps")
    ksp.setUp()
    pc.destroy()  # our handle only (the KSP keeps its PC): see petsc.solve_lu
    return ksp


def _row_layout(A: PETSc.Mat) -> Layout:
    lo, hi = A.getOwnershipRange()
    return Layout(hi - lo, A.getSize()[0], lo)


def _one(t: float) -> float:
    return 1.0


def _times(a: PETSc.Vec, b: PETSc.Vec, out: PETSc.Vec | None = None) -> PETSc.Vec:
    """Pointwise product ``a * b`` (into ``out`` or a new vector the caller owns)."""
    w = out if out is not None else a.duplicate()
    w.pointwiseMult(a, b)
    return w


def _values(fn, *args) -> np.ndarray:
    m = args[0].shape[0]
    v = np.asarray(fn(*args), dtype=float)
    if v.shape != (m, 2):
        raise ValueError(f"the function must return an array of shape ({m}, 2), got {v.shape}")
    return v
