"""Explicit dynamics: central differences with lumped masses, for FE, EFG and their coupling.

Semi-discrete equations of motion (Belytschko et al. 1995, eq. 4.4–4.5; Rabczuk et al. 2006,
eq. 92), one per field (FE nodes, particles):

.. math::
    M \\ddot d + f^{int} = f^{ext} + f^C, \\qquad f^{int} = K d, \\qquad
    M_{II} = \\sum_J \\int_\\Omega \\rho N_I N_J \\, d\\Omega \\ \\text{(row sums)}.

``K`` is the stiffness the static solvers assemble (DOLFINx's elasticity form on the FE cells,
:func:`~dolfinx_meshfree.efg.particle_stiffness` on the particle cells), so ``f_int = K d`` is
exact for linear elasticity. The row-sum masses are

* FE: ``int rho N_I`` over the FE cells, assembled by DOLFINx as the linear form
  ``rho (1, 1) . v dx(FE)``, which is the row sum of ``rho inner(u, v) dx(FE)`` exactly because
  the P1/Q1 basis sums to one;
* particles: ``rho sum_q phi_I(x_q) w_q``, the row sums of ``rho Phi^T W Phi`` on the same cell
  quadrature as the stiffness (MLS shape functions are a partition of unity, so this is the
  exact row sum). It keeps the total mass exact and puts each particle's mass where its shape
  function lives, consistently with ``K``; the Voronoi volume ``rho V_I`` is available with
  ``particle_mass="volume"``.

Central differences (Belytschko et al. 1995, sec. 5.2) with half-step velocities:
``v_{n+1/2} = v_{n-1/2} + dt M^{-1} (f^ext_n - K d_n)``, ``d_{n+1} = d_n + dt v_{n+1/2}``, and
``v_{1/2} = v_0 + dt/2 M^{-1} f_0``. The velocity at an output time is
``v_n = (v_{n-1/2} + v_{n+1/2}) / 2``.

Compatibility coupling in dynamics (Rabczuk et al. 2006, sec. 5.4, eq. 93–96 and Table I): the
trial velocities ``vbar`` of the uncoupled update (eq. 93) are corrected by the multipliers of
the velocity constraint ``G v = G_FE v_FE + G_P v_P = 0`` (eq. 94):

.. math::
    (G M^{-1} G^T) \\lambda = G \\bar v, \\qquad v = \\bar v - M^{-1} G^T \\lambda
    \\quad \\text{(eq. 95–96)},

with ``G`` the multiplier blocks of the static coupling (FE trace multipliers on the interface,
:class:`~dolfinx_meshfree.CoupledElasticity`). ``G M^{-1} G^T`` is factorised once (MUMPS), so
each step costs two sparse products and one triangular solve, and ``G v`` stays at round-off.

Stable time step: the Courant condition ``dt_crit = h_min / c`` on the smallest FE or particle
spacing (Belytschko et al. 1995, sec. 5.2), capped by ``2 / omega_max`` with ``omega_max^2``
estimated by power iteration on ``M^{-1} K``: ``h_min / c`` is exact for square Q1 elements at
``nu = 0`` but exceeds the critical step on triangles (0.69 h/c) and for ``nu -> 1/2``; for EFG
it is conservative (the critical step is about 1.47 h/c). The constraints do not lower it (the
constrained frequencies interlace the unconstrained ones).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import dolfinx
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from scipy.linalg import cho_factor, cho_solve
from scipy.spatial import cKDTree

from . import _compat
from .efg import particle_stiffness
from .fe_points import ensure_points_in_mesh, evaluate_fe_function, tabulate_in_cells
from .materials import LinearElastic
from .mls import MLS
from .operators import load_vector
from .parallel import Layout, raise_on_all_ranks
from .particles import ParticleSet
from .patch import FE_TAG
from .petsc import create_aij, create_vector
from .quadrature import QuadraturePoints, cell_quadrature, facet_quadrature

__all__ = [
    "DYNAMICS_METHODS",
    "DynamicsResult",
    "EnergyRecord",
    "ExplicitDynamics",
    "Field",
    "check_method",
    "fe_lumped_mass",
    "particle_lumped_mass",
]

#: Methods available in explicit dynamics (the other static couplings follow, issue 4).
DYNAMICS_METHODS = ("fe", "efg", "lagrange")

_prefix_counter = itertools.count()
_DENSE_MAX = 2000

VectorFunction = Callable[[np.ndarray], np.ndarray]


def check_method(method: str) -> str:
    """Return ``method`` if explicit dynamics supports it, else raise a ``ValueError``."""
    if method not in DYNAMICS_METHODS:
        raise ValueError(
            f"method={method!r} is not available in explicit dynamics; choose one of "
            f"{list(DYNAMICS_METHODS)} (edge-to-edge, ramp, bridging and master-slave are not "
            "yet implemented in dynamics)"
        )
    return method


# -- lumped masses ---------------------------------------------------------------------------


def fe_lumped_mass(V, rho: float, dx: ufl.Measure | None = None) -> PETSc.Vec:
    """Row-sum lumped FE masses ``M_II = sum_J int rho N_I N_J = int rho N_I`` (Belytschko et
    al. 1995, eq. 4.5), one entry per owned dof of the vector space ``V`` (collective).

    Assembled by DOLFINx as the linear form ``rho (1, 1) . v dx``, the row sum of the consistent
    mass ``rho inner(u, v) dx`` (the P1/Q1 basis is a partition of unity).

    Args:
        V: Vector P1/Q1 space. rho: Density (> 0).
        dx: The measure of the FE cells (e.g. ``dx(FE_TAG)`` with the patch's cell tags);
            default: every cell.

    Returns:
        A PETSc vector with ``V``'s owned-dof layout (ghost contributions accumulated). Dofs that
        no integrated cell supports get 0.
    """
    msh = V.mesh
    if dx is None:
        dx = ufl.Measure("dx", domain=msh)
    v = ufl.TestFunction(V)
    ones = dolfinx.fem.Constant(msh, np.ones(msh.geometry.dim))
    b = _compat.assemble_vector(_compat.create_form(float(rho) * ufl.dot(ones, v) * dx))
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    imap = V.dofmap.index_map
    bs = V.dofmap.index_map_bs
    m = PETSc.Vec().createMPI((bs * imap.size_local, bs * imap.size_global), comm=msh.comm)
    m.array[:] = b.array_r[: bs * imap.size_local]
    b.destroy()
    return m


def particle_lumped_mass(
    particles: ParticleSet,
    table_values: sp.csr_matrix | None,
    weights: np.ndarray | None,
    rho: float,
    kind: str = "row-sum",
) -> PETSc.Vec:
    """Lumped particle masses, one entry per particle dof in PETSc order (collective).

    Args:
        particles: The particle set.
        table_values: (nq x n) MLS values at this rank's cell quadrature points (the table of
            :func:`~dolfinx_meshfree.efg.particle_stiffness`); ``weights``: (nq,) weights.
        rho: Density.
        kind: ``"row-sum"``: ``M_II = rho sum_q phi_I(x_q) w_q``, the row sums of
            ``rho Phi^T W Phi`` (Belytschko et al. 1995, eq. 4.5); ``"volume"``:
            ``rho V_I`` with the particles' Voronoi volumes.

    Raises:
        ValueError: on every rank when a mass is not positive (a shape function that integrates
            to <= 0 on the quadrature: raise the quadrature degree or the dilation).
    """
    if kind not in ("row-sum", "volume"):
        raise ValueError(f"particle_mass={kind!r} is not known; use 'row-sum' or 'volume'")
    n = particles.num_particles
    comm = particles.comm
    pl = Layout(2 * particles.layout.size_local, 2 * n, 2 * particles.layout.start)
    pdofs = particles.petsc_dofs(2)
    if kind == "row-sum":
        local = float(rho) * np.asarray(table_values.T @ weights).ravel()
        m = create_vector(comm, pl, pdofs.ravel(), np.repeat(local, 2))
    else:
        own = particles.owned
        m = create_vector(
            comm, pl, pdofs[own].ravel(), np.repeat(float(rho) * particles.volumes[own], 2)
        )
    lo = comm.allreduce(float(m.array_r.min()) if m.getLocalSize() else np.inf, op=MPI.MIN)
    if not lo > 0.0:
        raise ValueError(
            f"a lumped particle mass is not positive (min {lo:.3e}); a shape function integrates "
            "to <= 0 on the cell quadrature: raise quadrature_degree or the dilation, or use "
            "particle_mass='volume'"
        )
    return m


def _fe_spacing(msh, cells: np.ndarray) -> float:
    """Smallest distance between two vertices of one of the given owned cells (collective)."""
    gdim = msh.geometry.dim
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :gdim]  # (nc, nv, gdim)
    h = np.inf
    nv = nodes.shape[1]
    for a, b in itertools.combinations(range(nv), 2):
        if len(cells):
            h = min(h, float(np.linalg.norm(nodes[:, a] - nodes[:, b], axis=1).min()))
    return msh.comm.allreduce(h, op=MPI.MIN)


def _particle_spacing(particles: ParticleSet) -> float:
    """Smallest distance between two particles (positions are replicated: no communication)."""
    d, _ = cKDTree(particles.positions).query(particles.positions, k=2)
    return float(d[:, 1].min())


# -- fields, results ---------------------------------------------------------------------------


@dataclass
class Field:
    """One discretisation of an explicit system: stiffness and lumped masses of its dofs.

    Attributes:
        name: ``"fe"`` or ``"particles"``.
        K: Assembled stiffness (PETSc, owned rows).
        mass: Lumped masses (PETSc vector, same layout); 0 marks dofs outside the field (FE nodes
            that only patch cells touch), which the integrator holds at rest.
        spacing: Smallest node or particle spacing (for the Courant condition).
    """

    name: str
    K: PETSc.Mat
    mass: PETSc.Vec
    spacing: float


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
        energies: :class:`EnergyRecord` at the energy steps (outputs included).
        outputs: ``(step, time)`` of each requested output time (nearest step).
        critical: Time-step estimates: ``courant`` (``h_min / c``), ``spectral``
            (``2 / omega_max``), ``critical`` (their minimum) and ``stable`` (times ``safety``).
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

    Build with :meth:`fe`, :meth:`efg` or :meth:`coupled`; set the initial state with
    :meth:`set_initial`; optionally :meth:`add_traction`; then :meth:`run`. The velocity can be
    evaluated at any points (:meth:`velocity_at`) and compared with an exact solution
    (:meth:`velocity_error`, Rabczuk et al. 2006, eq. 137) after a run, at the final time or in
    the ``on_output`` callback. Collective throughout.

    Args:
        fields: One or two :class:`Field`.
        material: The :class:`~dolfinx_meshfree.LinearElastic` law (density and wave speed).
        constraint: The multiplier blocks ``G_f`` of each field (``None`` for a field without),
            or ``None``: no constraint.
        safety: Fraction of the critical time step used by default and allowed without
            ``force`` (0 < safety <= 1).
        multiplier_solver: How ``S = G M^{-1} G^T`` is factorised (once): ``"dense"``
            (Cholesky on every rank, one ``Allgatherv`` of ``G v`` per step: the fastest for
            interface-sized ``S``), ``"mumps"`` (distributed LU), or ``None``: dense up to
            2000 multipliers.
        V, mls, particles, mesh, in_patch: What evaluation needs: the FE space, the MLS
            approximation and its particles, the mesh, and the patch flag of each local cell
            (coupled runs).
    """

    def __init__(
        self,
        fields: Sequence[Field],
        material: LinearElastic,
        constraint: Sequence[PETSc.Mat | None] | None = None,
        safety: float = 0.9,
        *,
        V=None,
        mls: MLS | None = None,
        particles: ParticleSet | None = None,
        mesh=None,
        in_patch: np.ndarray | None = None,
        patch=None,
        timings: dict | None = None,
        multiplier_solver: str | None = None,
    ):
        if not (isinstance(safety, int | float) and 0.0 < safety <= 1.0):
            raise ValueError(f"safety={safety!r} must lie in (0, 1]")
        self.fields = list(fields)
        self.material = material
        self.safety = float(safety)
        self.V, self.mls, self.particles, self.mesh = V, mls, particles, mesh
        self.in_patch, self.patch = in_patch, patch
        self.comm = self.fields[0].mass.getComm().tompi4py()
        self.timings = dict(timings or {})
        t0 = time.perf_counter()
        self._minv = []
        self.active = []
        for f in self.fields:
            mi = f.mass.duplicate()
            m = f.mass.array_r
            mi.array[:] = np.where(m > 0.0, 1.0 / np.where(m > 0.0, m, 1.0), 0.0)
            self._minv.append(mi)
            self.active.append(m > 0.0)
        self.u = [f.mass.duplicate() for f in self.fields]
        self.v = [f.mass.duplicate() for f in self.fields]  # v_{n-1/2} (v_0 before the first step)
        for x in (*self.u, *self.v):
            x.set(0.0)
        self.step, self.time = 0, 0.0
        self._records: list[EnergyRecord] = []
        self._w_ext, self._w_c = 0.0, np.zeros(len(self.fields))
        self._loads: list[tuple[list[PETSc.Vec | None], Callable[[float], float]]] = []
        self._v_now: list[PETSc.Vec] | None = None  # v_n at the current output time
        self._tables: dict = {}
        self._critical: dict | None = None
        self.G: list[PETSc.Mat | None] | None = None
        self._ksp = None
        self._S = None
        if multiplier_solver not in (None, "dense", "mumps"):
            raise ValueError(
                f"multiplier_solver={multiplier_solver!r} is not known; use None (automatic), "
                "'dense' or 'mumps'"
            )
        self.multiplier_solver = multiplier_solver
        if constraint is not None and any(g is not None for g in constraint):
            self.G = list(constraint)
            self._factorise()
        self.timings["setup"] = self.timings.get("setup", 0.0) + time.perf_counter() - t0

    # -- builders ------------------------------------------------------------------------------

    @classmethod
    def fe(cls, V, material: LinearElastic, safety: float = 0.9) -> ExplicitDynamics:
        """Pure FE: DOLFINx's stiffness ``inner(sigma(u), eps(v)) dx`` and row-sum masses."""
        _check_material(material)
        t0 = time.perf_counter()
        msh = V.mesh
        u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        a = ufl.inner(material.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
        K = _compat.assemble_matrix(_compat.create_form(a))
        mass = fe_lumped_mass(V, material.rho)
        n_owned = msh.topology.index_map(msh.topology.dim).size_local
        h = _fe_spacing(msh, np.arange(n_owned))
        return cls(
            [Field("fe", K, mass, h)],
            material,
            safety=safety,
            V=V,
            mesh=msh,
            timings={"setup": time.perf_counter() - t0},
        )

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
    ) -> ExplicitDynamics:
        """Pure EFG on ``particles`` integrated on their background cells (Belytschko et al.
        1995, sec. 5.2): :func:`~dolfinx_meshfree.efg.particle_stiffness` and row-sum masses."""
        _check_material(material)
        if particles.mesh is None:
            raise ValueError("explicit EFG needs particles with a background mesh (mesh=...)")
        t0 = time.perf_counter()
        comm = particles.comm
        mls = raise_on_all_ranks(
            comm, lambda: MLS(particles, weight=weight, dilation=dilation, basis=basis)
        )
        K, mass = _particle_operators(particles, mls, material, quadrature_degree, particle_mass)
        return cls(
            [Field("particles", K, mass, _particle_spacing(particles))],
            material,
            safety=safety,
            mls=mls,
            particles=particles,
            mesh=particles.mesh,
            timings={"setup": time.perf_counter() - t0},
        )

    @classmethod
    def coupled(
        cls,
        problem,
        particle_mass: str = "row-sum",
        safety: float = 0.9,
        multiplier_solver: str | None = None,
    ) -> ExplicitDynamics:
        """A :class:`~dolfinx_meshfree.CoupledElasticity` in dynamics (``coupling="lagrange"``).

        Reuses the static coupling's pieces: its FE stiffness on the FE cells, its MLS, its
        quadrature degree, its interface multiplier numbering and constraint blocks (FE trace
        multipliers, ``G_FE = int_Gamma Lambda^T N``, ``G_P = -int_Gamma Lambda^T phi``, Rabczuk
        et al. 2006, eq. 109). The multipliers act on velocities (eq. 94–96).
        """
        coupling = getattr(problem, "coupling", None)
        if coupling != "lagrange":
            raise ValueError(
                f"coupling={coupling!r} is not available in explicit dynamics yet; available: "
                f"{list(DYNAMICS_METHODS)}"
            )
        material = problem.material
        _check_material(material)
        t0 = time.perf_counter()
        V, patch, mls = problem.V, problem.patch, problem.mls
        P = patch.particles
        msh = V.mesh
        K_fe = problem._fe_stiffness()
        dx = ufl.Measure("dx", domain=msh, subdomain_data=patch.cell_tags)
        mass_fe = fe_lumped_mass(V, material.rho, dx(FE_TAG))
        boundary = patch.boundary() if problem.consistent else None
        K_p, mass_p = _particle_operators(
            P, mls, material, problem.quadrature_degree, particle_mass, boundary
        )
        G_fe, G_p = _lagrange_blocks(problem)
        fields = [
            Field("fe", K_fe, mass_fe, _fe_spacing(msh, patch.fe_cells)),
            Field("particles", K_p, mass_p, _particle_spacing(P)),
        ]
        return cls(
            fields,
            material,
            [G_fe, G_p],
            safety=safety,
            V=V,
            mls=mls,
            particles=P,
            mesh=msh,
            in_patch=patch.in_patch,
            patch=patch,
            timings={"setup": time.perf_counter() - t0},
            multiplier_solver=multiplier_solver,
        )

    # -- constraint ----------------------------------------------------------------------------

    def _factorise(self) -> None:
        """``S = sum_f G_f M_f^{-1} G_f^T`` (eq. 96's matrix), factorised once by MUMPS."""
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
            self._chol = cho_factor(dense)
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

    def critical_time_step(self, iterations: int = 40) -> dict:
        """Critical time-step estimates (collective, computed once).

        Returns:
            ``{"courant": h_min / c, "spectral": 2 / omega_max, "critical": min of both,
            "h_min": ..., "wave_speed": ...}``; ``omega_max^2`` is the Rayleigh quotient after
            ``iterations`` power iterations on ``M^{-1} K`` (a lower bound of the largest
            eigenvalue, converging from below).
        """
        if self._critical is not None:
            return self._critical
        c = self.material.wave_speed()
        h = min(f.spacing for f in self.fields)
        x = [f.mass.duplicate() for f in self.fields]
        y = [f.mass.duplicate() for f in self.fields]
        for f, xf, act in zip(self.fields, x, self.active, strict=True):
            # a hash of the dof's position and component: the same vector on any partition
            pts = self._owned_points(f.name)
            z = 12.9898 * pts[:, 0] + 78.233 * pts[:, 1]
            z = (z[:, None] + 37.719 * np.arange(2)).ravel()
            r = np.sin(z) * 43758.5453
            xf.array[:] = (r - np.floor(r) - 0.5) * act
        w = [f.mass.duplicate() for f in self.fields]

        def mass_norm2() -> float:
            total = 0.0
            for f, xf, wf in zip(self.fields, x, w, strict=True):
                wf.pointwiseMult(f.mass, xf)
                total += xf.dot(wf)
            return total

        lam = 0.0
        for _ in range(iterations):
            mx = mass_norm2()
            if mx <= 0.0:
                break
            kx = 0.0
            for f, xf, yf in zip(self.fields, x, y, strict=True):
                f.K.mult(xf, yf)
                kx += xf.dot(yf)
            lam = max(lam, kx / mx)  # Rayleigh quotient in the mass metric
            for xf, yf, mi in zip(x, y, self._minv, strict=True):
                xf.pointwiseMult(mi, yf)
            norm = np.sqrt(mass_norm2())
            if norm == 0.0:
                break
            for xf in x:
                xf.scale(1.0 / norm)
        for obj in (*x, *y, *w):
            obj.destroy()
        spectral = 2.0 / np.sqrt(lam) if lam > 0 else np.inf
        courant = h / c
        self._critical = {
            "courant": float(courant),
            "spectral": float(spectral),
            "critical": float(min(courant, spectral)),
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
        interpolating) or take them (``"nodal"``). With a constraint, both fields are then
        projected onto ``G d = 0``, ``G v = 0`` in the mass metric. Resets time to 0.
        """
        if particle_values not in ("collocation", "nodal"):
            raise ValueError(
                f"particle_values={particle_values!r} is not known; use 'collocation' or 'nodal'"
            )
        for target, fn in ((self.u, displacement), (self.v, velocity)):
            for k, f in enumerate(self.fields):
                target[k].set(0.0)
                if fn is None:
                    continue
                if f.name == "fe":
                    vals = self._fe_nodal_values(fn)
                else:
                    vals = self._particle_coefficients(fn, particle_values)
                target[k].array[:] = vals * self.active[k]
            if fn is not None and self.G is not None:
                self._ensure_work()
                self._correct(target)
        self.step, self.time = 0, 0.0
        self._v_now = None
        self._records, self._w_ext, self._w_c = [], 0.0, np.zeros(len(self.fields))

    def _owned_points(self, name: str) -> np.ndarray:
        """Positions (owned, in PETSc order) of the FE nodes or the particles."""
        if name == "fe":
            n_owned = self.V.dofmap.index_map.size_local
            return self.V.tabulate_dof_coordinates()[:n_owned, :2]
        return self.particles.positions[self.particles.owned]

    def _fe_nodal_values(self, fn: VectorFunction) -> np.ndarray:
        x = self._owned_points("fe")
        vals = raise_on_all_ranks(self.comm, lambda: _values(fn, x))
        return vals.ravel()

    def _particle_coefficients(self, fn: VectorFunction, how: str) -> np.ndarray:
        P = self.particles
        x = P.positions[P.owned]  # owned particles in PETSc order
        vals = raise_on_all_ranks(self.comm, lambda: _values(fn, x))
        if how == "nodal":
            return vals.ravel()
        n = P.num_particles
        sl = Layout(P.layout.size_local, n, P.layout.start)
        phi = raise_on_all_ranks(self.comm, lambda: self.mls.tabulate(x, 0)).values.tocoo()
        rows = P.petsc_index[P.owned]
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
        xs.destroy()
        ksp.destroy()
        A.destroy()
        return out.ravel()

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
        """
        msh = self.mesh
        deg = 4
        facets = np.asarray(facets, dtype=np.int32)
        msh.topology.create_connectivity(msh.topology.dim - 1, msh.topology.dim)
        f2c = msh.topology.connectivity(msh.topology.dim - 1, msh.topology.dim)
        first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
        if self.in_patch is not None:
            on_p = self.in_patch[first]
        else:
            on_p = np.full(facets.size, self.V is None)
        vecs: list[PETSc.Vec | None] = []
        for f in self.fields:
            sel = facets[on_p] if f.name == "particles" else facets[~on_p]
            q = facet_quadrature(msh, sel, deg)
            t = raise_on_all_ranks(self.comm, lambda q=q: _values(traction, q.points, q.normals))
            b = f.mass.duplicate()
            b.set(0.0)
            if f.name == "fe":
                imap = self.V.dofmap.index_map
                l2g = np.asarray(
                    imap.local_to_global(
                        np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
                    )
                )
                tab = tabulate_in_cells(self.V, q.points, q.cells, derivatives=0).values
                fl = load_vector(tab, q.weights, t).reshape(-1, 2)
                rows = (2 * l2g[: fl.shape[0], None] + np.arange(2)).ravel()
                vals = fl.ravel()
            else:
                tab = raise_on_all_ranks(self.comm, lambda q=q: self.mls.tabulate(q.points, 0))
                vals = load_vector(tab.values, q.weights, t)
                rows = self.particles.petsc_dofs(2).ravel()
            b.setValues(rows.astype(PETSc.IntType), vals, addv=PETSc.InsertMode.ADD_VALUES)
            b.assemblyBegin()
            b.assemblyEnd()
            vecs.append(b)
        self._loads.append((vecs, amplitude if amplitude is not None else _one))

    # -- stepping ------------------------------------------------------------------------------

    def _ensure_work(self) -> None:
        if not hasattr(self, "_work"):
            self._work = [f.mass.duplicate() for f in self.fields]
            self._tmp = [f.mass.duplicate() for f in self.fields]

    def run(
        self,
        t_end: float,
        dt: float | None = None,
        *,
        force: bool = False,
        outputs: Sequence[float] = (),
        energy_records: int = 100,
        on_output: Callable[[ExplicitDynamics, int, float], None] | None = None,
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

        Raises:
            ValueError: ``dt`` not positive, above the stable step without ``force``, or
                ``t_end`` not after the current time.
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
                f"critical {crit['critical']:.6g}: Courant h_min/c = {crit['courant']:.6g} with "
                f"h_min = {crit['h_min']:.4g}, spectral 2/omega_max = {crit['spectral']:.6g}); "
                f"pass dt <= {stable:.6g}, dt=None for the stable step, or force=True"
            )
        nsteps = max(1, int(np.ceil(span / dt - 1e-9)))
        dt = span / nsteps
        n0 = self.step
        t0 = self.time
        self._ensure_work()
        F = len(self.fields)
        out_steps = {n0 + min(nsteps, max(0, round((t - t0) / dt))): t for t in outputs}
        every = max(1, nsteps // max(1, energy_records))
        energy_steps = set(range(n0, n0 + nsteps + 1, every)) | set(out_steps) | {n0 + nsteps}
        ku, vnew, vnow, imp = ([f.mass.duplicate() for f in self.fields] for _ in range(4))
        for x in imp:
            x.set(0.0)
        records: list[EnergyRecord] = self._records
        w_ext, w_c = self._w_ext, self._w_c
        pk = [k for k, f in enumerate(self.fields) if f.name == "particles"]
        t_out = 0.0
        outs: list[tuple[int, float]] = []
        clock = time.perf_counter()
        for n in range(n0, n0 + nsteps + 1):
            tn = t0 + (n - n0) * dt
            gamma = 0.5 if n == 0 else 1.0
            amps = [a(tn) for _, a in self._loads]
            # trial velocities (eq. 93): vbar = v_{n-1/2} + gamma dt M^{-1} (f_ext - K d_n)
            for k, f in enumerate(self.fields):
                f.K.mult(self.u[k], ku[k])
                ku[k].copy(self._work[k])
                for (vecs, _), an in zip(self._loads, amps, strict=True):
                    if vecs[k] is not None and an != 0.0:
                        self._work[k].axpy(-an, vecs[k])
                vnew[k].pointwiseMult(self._minv[k], self._work[k])
                vnew[k].aypx(-gamma * dt, self.v[k])
            # multiplier correction (eq. 94-96): G v_{n+1/2} = 0
            if self.G is not None:
                self._correct(vnew, imp)
            # work of the step, f_n . (d_{n+1} - d_{n-1}) / 2 = dt f_n . (v_{n+1/2} + v_{n-1/2})/2,
            # which balances the central-difference energy exactly (see EnergyRecord)
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
                    if on_output is not None:
                        on_output(self, n, tn)
                    self._v_now = None
                t_out += time.perf_counter() - tic
            if n == n0 + nsteps:
                break  # v_N is known; the state stays (d_N, v_{N-1/2}) for a next run
            w_ext += d_ext
            w_c = w_c + d_c
            for k in range(F):
                self.u[k].axpy(dt, vnew[k])
                vnew[k].copy(self.v[k])
        t_loop = time.perf_counter() - clock - t_out
        self.step, self.time = n0 + nsteps, t0 + span
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
            energies=list(records),
            outputs=outs,
            critical={**crit, "stable": stable},
            timings={"steps": t_loop, "per_step": t_loop / nsteps, "outputs": t_out},
        )

    # -- evaluation ----------------------------------------------------------------------------

    def _current(self) -> list[PETSc.Vec]:
        return self._v_now if self._v_now is not None else self.v

    def _local_values(self, vecs: list[PETSc.Vec]) -> tuple:
        """(FE Function with ghosts or None, particle coefficients (n, 2) or None)."""
        fe, coeffs = None, None
        for f, x in zip(self.fields, vecs, strict=True):
            if f.name == "fe":
                fe = dolfinx.fem.Function(self.V)
                fe.x.array[: x.getLocalSize()] = x.array_r
                fe.x.scatter_forward()
            else:
                owned = np.concatenate(self.comm.allgather(x.array_r.copy()))
                coeffs = owned.reshape(-1, 2)[self.particles.petsc_index]
        return fe, coeffs

    def velocity_at(self, points: npt.ArrayLike) -> np.ndarray:
        """Velocity (m, 2) at this rank's points, which may lie anywhere in the mesh
        (collective). Raises :class:`~dolfinx_meshfree.PointsOutsideMeshError` on every rank if
        a point is outside the body."""
        fe, coeffs = self._local_values(self._current())
        if coeffs is None:
            return evaluate_fe_function(fe, points)
        if fe is None:
            x = ensure_points_in_mesh(self.mesh, points)
            return self.mls.tabulate(x, 0).values @ coeffs
        from .coupled import CoupledSolution

        return CoupledSolution(
            u=fe, coefficients=coeffs, mls=self.mls, patch=self.patch
        ).displacement(points)

    def _quadrature_tables(self, degree: int):
        if degree not in self._tables:
            msh = self.mesh
            q = cell_quadrature(msh, degree)
            if self.in_patch is not None:
                on_p = self.in_patch[q.cells]
            else:
                on_p = np.full(len(q), self.V is None)
            t_fe = t_p = None
            if np.any(~on_p):
                t_fe = tabulate_in_cells(self.V, q.points[~on_p], q.cells[~on_p], 0).values
            if self.mls is not None:
                t_p = raise_on_all_ranks(self.comm, lambda: self.mls.tabulate(q.points[on_p], 0))
                t_p = t_p.values
            self._tables[degree] = (q, on_p, t_fe, t_p)
        return self._tables[degree]

    def velocity_at_quadrature(self, degree: int = 5) -> tuple[QuadraturePoints, np.ndarray]:
        """Cell quadrature of degree ``degree`` on the owned cells and the velocity (nq, 2)
        there: FE on FE cells, MLS on particle cells (tables cached; collective)."""
        q, on_p, t_fe, t_p = self._quadrature_tables(degree)
        fe, coeffs = self._local_values(self._current())
        vals = np.zeros((len(q), 2))
        if t_fe is not None:
            vals[~on_p] = t_fe @ fe.x.array.reshape(-1, 2)
        if t_p is not None and np.any(on_p):
            vals[on_p] = t_p @ coeffs
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
        """Active FE dofs, particle dofs and multipliers (global counts)."""
        out = {"fe_dofs": 0, "particle_dofs": 0, "multiplier_dofs": 0}
        for f, act in zip(self.fields, self.active, strict=True):
            key = "fe_dofs" if f.name == "fe" else "particle_dofs"
            out[key] = int(self.comm.allreduce(int(act.sum()), op=MPI.SUM))
        if self._S is not None:
            out["multiplier_dofs"] = int(self._S.getSize()[0])
        return out

    def destroy(self) -> None:
        """Destroy the PETSc objects (collective)."""
        objs = [*self.u, *self.v, *self._minv]
        for f in self.fields:
            objs += [f.K, f.mass]
        objs += [g for g in (self.G or []) if g is not None]
        for name in ("_ksp", "_S", "_lam", "_gv"):
            if getattr(self, name, None) is not None:
                objs.append(getattr(self, name))
        objs += getattr(self, "_work", []) + getattr(self, "_tmp", [])
        objs += getattr(self, "_final", [])
        for vecs, _ in self._loads:
            objs += [b for b in vecs if b is not None]
        for obj in objs:
            obj.destroy()


# -- helpers -----------------------------------------------------------------------------------


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
    return ksp


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


def _check_material(material) -> None:
    if not isinstance(material, LinearElastic):
        raise TypeError(f"material must be a LinearElastic, got {type(material).__name__}")


def _particle_operators(
    particles: ParticleSet,
    mls: MLS,
    material: LinearElastic,
    degree: int,
    particle_mass: str,
    boundary=None,
) -> tuple[PETSc.Mat, PETSc.Vec]:
    """EFG stiffness (PETSc) and lumped masses from one cell quadrature (collective)."""
    if particle_mass not in ("row-sum", "volume"):
        raise ValueError(f"particle_mass={particle_mass!r} is not known; use 'row-sum' or 'volume'")
    comm = particles.comm
    n = particles.num_particles
    K_loc, q, tq, _ = particle_stiffness(particles, mls, material, degree, boundary)
    pl = Layout(2 * particles.layout.size_local, 2 * n, 2 * particles.layout.start)
    K = create_aij(comm, K_loc, pl, pl)
    mass = particle_lumped_mass(particles, tq.values, q.weights, material.rho, particle_mass)
    return K, mass


def _lagrange_blocks(problem) -> tuple[PETSc.Mat, PETSc.Mat]:
    """The compatibility coupling's multiplier blocks ``G_FE`` (multipliers x FE dofs) and
    ``G_P`` (multipliers x particle dofs), as in :meth:`CoupledElasticity.solve` without the
    Dirichlet columns and with unit scaling (collective)."""
    from .coupled import _fe_constraint_block, _particle_constraint_block

    V, patch, mls = problem.V, problem.patch, problem.mls
    P, comm = patch.particles, patch.comm
    n = P.num_particles
    fe_layout, l2g = problem._fe_layout()
    pl = Layout(2 * P.layout.size_local, 2 * n, 2 * P.layout.start)
    ids, ml = problem._interface_numbering()
    iq = facet_quadrature(
        V.mesh, patch.interface_facets, problem.quadrature_degree, patch.interface_fe_cells
    )
    t_fe = tabulate_in_cells(V, iq.points, iq.cells, derivatives=0).values
    t_p = raise_on_all_ranks(comm, lambda: mls.tabulate(iq.points, 0)).values
    W = sp.diags(iq.weights)
    M_fe = (t_fe.T @ W @ t_fe).tocoo()
    M_p = (t_fe.T @ W @ t_p).tocoo()
    tiny = 1e-14 * (np.abs(M_fe.data).max() if M_fe.nnz else 1.0)
    keep = (ids[M_fe.row] >= 0) & (np.abs(M_fe.data) > tiny)
    ubc = dolfinx.fem.Function(V)
    ubc.x.array[:] = 0.0
    no_bc = np.zeros(ubc.x.array.size // 2, dtype=bool)
    G_fe, _, _ = _fe_constraint_block(
        ids[M_fe.row[keep]],
        M_fe.col[keep],
        M_fe.data[keep],
        False,
        1.0,
        no_bc,
        ubc,
        l2g,
        (ml.size_global, fe_layout.size_global),
    )
    keep = (ids[M_p.row] >= 0) & (np.abs(M_p.data) > tiny)
    G_p = _particle_constraint_block(
        ids[M_p.row[keep]],
        M_p.col[keep],
        M_p.data[keep],
        1.0,
        P.petsc_dofs(2),
        (ml.size_global, 2 * n),
    )
    return create_aij(comm, G_fe, ml, fe_layout), create_aij(comm, G_p, ml, pl)
