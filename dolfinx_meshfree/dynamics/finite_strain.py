"""The finite-deformation member of the semi-discrete systems: ``f^int(d) = sum_q B0^T P(F_q) w_q``.

Total-Lagrangian explicit dynamics (Rabczuk et al. 2006, eq. 1–5, 34 and 86–92): the lumped
masses, the constraint blocks ``G`` (interface multipliers, essential conditions on particles)
and the velocity projection of eq. 94–96 are those of the linear model (they do not depend on
the deformation); only the internal force changes:

* FE side: DOLFINx assembles ``int_FE P(I + grad u) : grad v dX`` of the material's UFL law
  (:meth:`~dolfinx_meshfree.physics.constitutive.Material.ufl_first_piola`) on the FE cells
  (the cells whose energy the coupling gives to FE), through
  :class:`~dolfinx_meshfree.statics.sides.FESide`, on a fixed Gauss rule;
* particle side: :class:`~dolfinx_meshfree.physics.forces.InternalForces` on the particle
  quadrature and the shape table the builders use for the masses and ``K_P`` (test gradients
  VCI-corrected when the coupling is consistent), through
  :class:`~dolfinx_meshfree.statics.sides.ParticleSide`;
* sides over both fields (:class:`SharedSide`): the ramps' interface cells on their blended
  table (:class:`~dolfinx_meshfree.statics.sides.BlendedSide`, Belytschko et al. 1995, eq.
  3.15–3.16) and master–slave's particles seen through the reduction with rotating links
  (:class:`ReducedParticles`, eq. 27–28);
* constant blocks: the bridging penalty (eq. 72–75), linear in the displacements.

The strain energy is the stored energy ``sum_q W(F_q) w_q`` of both sides (the FE one on the same
Gauss rule as its force, with the FE basis tabulated at those points), not ``1/2 d^T K d``; the
tangent is the consistent one of both sides at the current state (for the stable step, see
:mod:`~dolfinx_meshfree.dynamics.time_step`), and :meth:`NonlinearSystem.wave_speed` the
largest current Lagrangian wave speed, the cheap test of stiffening between two bounds.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from ..approx.fe_points import tabulate_in_cells
from ..geometry.particles import ParticleSet
from ..geometry.quadrature import QuadraturePoints, cell_quadrature
from ..parallel import raise_on_all_ranks
from ..physics.constitutive import DeformationError, Material, check_deformation_gradients
from ..physics.forces import InternalForces
from ..physics.materials import LinearElastic, linear_twin
from ..physics.state import check_not_rate_law, check_stateless, is_rate_law
from ..physics.zones import MaterialZones
from ..statics.sides import FESide, ParticleSide
from .rate_forms import RATE_METHODS, RateLaws
from .system import Blocks, Field

if TYPE_CHECKING:  # annotations only
    from ..couplings.master_slave_finite import SlaveCorrection

__all__ = [
    "FINITE_STRAIN_DYNAMICS",
    "FEForces",
    "NonlinearSystem",
    "ReducedParticles",
    "SharedSide",
    "bind_rate_law",
    "fe_forces",
    "particle_forces",
    "small_strain",
]

#: Methods of explicit dynamics at finite strain (``fe``, ``efg`` and these couplings).
FINITE_STRAIN_DYNAMICS = (
    "fe",
    "efg",
    "lagrange",
    "edge-to-edge",
    "bridging",
    "ramp",
    "ramp-cubic",
    "master-slave",
    "hybrid",
)

#: What the other methods miss at finite strain in explicit dynamics.
MISSING: dict[str, str] = {}


def bind_rate_law(material: object, method: str, mesh: dolfinx.mesh.Mesh | None = None) -> object:
    """A rate-form law over the sides of a model (:class:`~dolfinx_meshfree.dynamics.
    rate_forms.RateLaws`) for the methods that carry it, else ``material`` itself. A
    :class:`~dolfinx_meshfree.MaterialZones` law is located on ``mesh`` (the zone of every local
    cell; collective then).

    Raises:
        ValueError: a rate-form law with a ``method`` not in
            :data:`~dolfinx_meshfree.dynamics.rate_forms.RATE_METHODS`; zones with no mesh, or
            a cell in no zone or in two (on every rank).
    """
    if not is_rate_law(material):
        return material
    if method not in RATE_METHODS:
        raise ValueError(
            f"material={type(material).__name__} is a rate-form law, which explicit dynamics "
            f"carries on {list(RATE_METHODS)} only (method={method!r}: its sides over both "
            "fields do not carry the points' state yet)"
        )
    if not isinstance(material, MaterialZones):
        return RateLaws(material)
    if mesh is None:
        raise ValueError(f"{material!r} needs the model's mesh to locate its zones")
    return RateLaws(material, material.cell_zones(mesh))


def small_strain(material: LinearElastic | Material, method: str) -> LinearElastic:
    """The small-strain law a model is assembled with: ``material`` itself if it is a
    :class:`~dolfinx_meshfree.LinearElastic`, else its linear twin (same ``E``, ``nu``,
    ``plane``, ``rho``: the masses, the constraints and the tangent at ``d = 0``).

    Raises:
        TypeError: ``material`` is not a material.
        ValueError: a finite-strain material with a ``method`` not in
            :data:`FINITE_STRAIN_DYNAMICS` (naming what it misses).
    """
    if isinstance(material, LinearElastic):
        return material
    if isinstance(material, RateLaws):
        return material.twin
    check_not_rate_law(material, "explicit dynamics")
    check_stateless(material, "explicit dynamics")
    if not isinstance(material, Material):
        raise TypeError(
            f"material must be a LinearElastic or a finite-strain Material (NeoHookean, "
            f"SaintVenantKirchhoff), got {type(material).__name__}"
        )
    name = type(material).__name__
    if method not in FINITE_STRAIN_DYNAMICS:
        missing = MISSING.get(method, "a finite-strain internal force")
        raise ValueError(
            f"material={name}: coupling={method!r} is not available at finite strain in explicit "
            f"dynamics (missing: {missing}); use one of {list(FINITE_STRAIN_DYNAMICS)} or "
            "LinearElastic"
        )
    return linear_twin(material)


class FEForces:
    """The FE side of a finite-strain system: the assembled UFL internal force and tangent
    (:class:`~dolfinx_meshfree.statics.sides.FESide`) and, on the same Gauss rule, the FE basis
    at the points for ``F`` and ``W(F)`` (:class:`~dolfinx_meshfree.physics.forces.InternalForces`).

    Args:
        side: The assembled side (its Function holds the state).
        points: Its quadrature, as :class:`InternalForces` of the FE basis (local nodes).
    """

    def __init__(self, side: FESide, points: InternalForces) -> None:
        self.side, self.points = side, points

    def state(self, x: PETSc.Vec) -> np.ndarray:
        """Set the side's Function to ``x`` (ghosts updated) and return its local values,
        interleaved (owned and ghost nodes: the columns of the table)."""
        self.side.set_state(x)
        return self.side.u.x.array

    def deformation_gradient(self, x: PETSc.Vec) -> np.ndarray:
        """``F`` (m, d, d) at this rank's FE quadrature points."""
        return self.points.deformation_gradient(self.state(x))


def fe_forces(
    V: dolfinx.fem.FunctionSpace,
    material: Material,
    cells: np.ndarray | None = None,
    degree: int = 2,
    weight: ufl.core.expr.Expr | None = None,
    weight_at: Callable[[QuadraturePoints], np.ndarray] | None = None,
) -> FEForces:
    """The FE side of a finite-strain system on the owned cells flagged in ``cells`` (``None``:
    every cell), with ``degree`` the Gauss rule of both the assembled force and the energy
    (collective).

    ``degree = 2`` integrates the P1/Q1 stiffness exactly (its linear limit is DOLFINx's
    ``inner(sigma(u), eps(v)) dx``, also with a P1 weight) and ``W(F)`` exactly on triangles
    (``F`` constant per cell). ``weight`` (UFL) multiplies the FE energy, e.g. the bridging
    coupling's ``beta_FE`` (Rabczuk et al. 2006, eq. 47–48), and ``weight_at(q)`` (m,) gives its
    values at the points of the energy's rule.
    """
    msh = V.mesh
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    u = dolfinx.fem.Function(V)
    u.x.array[:] = 0.0
    v = ufl.TestFunction(V)
    dx = ufl.dx(metadata={"quadrature_degree": degree})
    F = ufl.Identity(gdim) + ufl.grad(u)
    F_int = ufl.inner(material.ufl_first_piola(F), ufl.grad(v)) * dx
    n_local = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    side = FESide(F_int, u, cells, np.zeros(n_local, dtype=bool), weight)
    n_owned = msh.topology.index_map(tdim).size_local
    owned = np.arange(n_owned) if cells is None else np.flatnonzero(cells[:n_owned])
    q = cell_quadrature(msh, degree, owned)
    table = tabulate_in_cells(V, q.points, q.cells, derivatives=1)
    w = q.weights if weight_at is None else q.weights * weight_at(q)
    return FEForces(side, InternalForces(table, w, material, comm=msh.comm))


def particle_forces(particles: ParticleSet, tables: dict, material: Material) -> ParticleSide:
    """The particle side on ``tables`` (``"quadrature"``, ``"table"``, ``"test_gradients"``,
    optional ``"weights"``: what :func:`~dolfinx_meshfree.statics.efg.particle_stiffness`
    returns), in PETSc numbering."""
    return ParticleSide(particles, tables, material)


@runtime_checkable
class SharedSide(Protocol):
    """Internal force over several fields (:attr:`fields`, block indices): the ramps' blended
    cells (:class:`~dolfinx_meshfree.statics.sides.BlendedSide`), master–slave's reduced
    particles (:class:`ReducedParticles`). Collective methods."""

    fields: tuple[int, ...]

    def internal_force(self, xs: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        """``f_int`` per field of :attr:`fields` (new vectors the caller owns)."""
        ...

    def tangent(self, xs: Sequence[PETSc.Vec]) -> Blocks:
        """``K_T`` by blocks ``{(a, b): Mat}`` (positions in :attr:`fields`)."""
        ...

    def strain_energy(self, xs: Sequence[PETSc.Vec]) -> float:
        """``sum_q W(F_q) w_q`` on this rank."""
        ...

    def deformation_gradient(self, xs: Sequence[PETSc.Vec]) -> np.ndarray:
        """``F`` (m, d, d) at this rank's points."""
        ...


class ReducedParticles:
    """Master–slave's particle side in the reduced state ``(u_FE, u_M)`` (Rabczuk et al. 2006,
    eq. 27–28): the particle parameters ``u_P = T_PF u_FE + S u_M`` (plus, for links of
    nonzero length, the finite-rotation part ``X c(u_FE)`` of
    :class:`~dolfinx_meshfree.couplings.master_slave_finite.SlaveCorrection`), the force
    ``T(u)^T f_P(u_P)`` with ``T(u) = [T_PF + X c'(u), S]`` (work conjugate: the gradient of the
    stored energy of the reduced state) and the tangent ``T^T K_T T`` (the links' curvature
    ``c''`` left out: it only serves the stable-step bound).

    The masses stay those of the linear reduction, the row sums of ``T^T M T`` at the reference
    (:func:`~dolfinx_meshfree.dynamics.reduction.reduce_master_slave`): a constant mass matrix,
    so central differences keep the energy balance of ``1/2 v^T M v + W``.

    Args:
        side: The particle side (all particles, PETSc numbering).
        reduction: ``(T_PF, S)`` of the linear operators (not owned).
        correction: The finite-rotation part, or ``None`` (links of length zero: ``c = 0``).
    """

    fields = (0, 1)

    def __init__(
        self,
        side: ParticleSide,
        reduction: tuple[PETSc.Mat, PETSc.Mat],
        correction: SlaveCorrection | None = None,
    ) -> None:
        self.side, (self.T, self.S), self.correction = side, reduction, correction
        self.forces = side.forces

    def particle_state(self, xs: Sequence[PETSc.Vec]) -> PETSc.Vec:
        """``u_P`` of the reduced state (a new vector; collective)."""
        y = self.T.createVecLeft()
        self.T.mult(xs[0], y)
        self.S.multAdd(xs[1], y, y)
        if self.correction is not None:
            y.array[self.correction.local_rows] += self.correction.values(xs[0])
        return y

    def expand(self, vecs: Sequence[PETSc.Vec], state: Sequence[PETSc.Vec]) -> PETSc.Vec:
        """The particle parameters of ``vecs`` (a new vector; collective): ``u_P(u)`` if
        ``vecs`` is the displacement ``state`` itself, else a rate ``T(u) v`` at the state (the
        velocity of the slaves, whose links turn with their edges)."""
        if all(a is b for a, b in zip(vecs, state, strict=True)):
            return self.particle_state(state)
        T = self._map(state)
        y = T.createVecLeft()
        T.mult(vecs[0], y)
        self.S.multAdd(vecs[1], y, y)
        T.destroy()
        return y

    def _map(self, xs: Sequence[PETSc.Vec]) -> PETSc.Mat:
        """``T_PF + X c'(u_FE)`` (a new matrix; collective)."""
        T = self.T.copy()
        if self.correction is not None:
            J = self.correction.jacobian(xs[0])
            T.axpy(1.0, J, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            J.destroy()
        return T

    def internal_force(self, xs: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        """``[T(u)^T f_P, S^T f_P]`` (collective)."""
        y = self.particle_state(xs)
        f = self.side.internal_force(y)
        T = self._map(xs)
        fe, m = T.createVecRight(), self.S.createVecRight()
        T.multTranspose(f, fe)
        self.S.multTranspose(f, m)
        for obj in (y, f, T):
            obj.destroy()
        return [fe, m]

    def tangent(self, xs: Sequence[PETSc.Vec]) -> Blocks:
        """``T^T K_T T`` by blocks (PETSc ``PtAP`` and products; collective)."""
        y = self.particle_state(xs)
        K = self.side.tangent(y)
        T = self._map(xs)
        KS = K.matMult(self.S)
        out = {
            (0, 0): K.PtAP(T),
            (0, 1): T.transposeMatMult(KS),
            (1, 0): KS.transposeMatMult(T),
            (1, 1): K.PtAP(self.S),
        }
        for obj in (y, K, T, KS):
            obj.destroy()
        return out

    def strain_energy(self, xs: Sequence[PETSc.Vec]) -> float:
        y = self.particle_state(xs)
        energy = self.forces.strain_energy(self.side.coefficients(y))
        y.destroy()
        return energy

    def deformation_gradient(self, xs: Sequence[PETSc.Vec]) -> np.ndarray:
        y = self.particle_state(xs)
        F = self.forces.deformation_gradient(self.side.coefficients(y))
        y.destroy()
        return F


class NonlinearSystem:
    """Finite deformation: ``f^int(d)`` of a hyperelastic material on each field, with the masses
    and constraints of the linear model.

    Args:
        fields: The fields of the linear model (FE first): masses, spacing, fixed dofs; their
            ``K`` is the tangent at ``d = 0`` (the linear twin's stiffness).
        sides: Per field its :class:`FEForces` (FE),
            :class:`~dolfinx_meshfree.statics.sides.ParticleSide` (particles) or ``None`` (a
            field whose force only ``shared`` sides give: master–slave's masters).
        material: The hyperelastic law (its current wave speed).
        constraint: The constraint blocks ``G_f`` of each field (``None`` for a field without),
            or ``None``: no constraint.
        shared: Sides over several fields (:class:`SharedSide`): the ramps' blended interface
            cells, master–slave's :class:`ReducedParticles`.
        constant: Constant stiffness blocks ``{(k, l): B_kl}`` added to ``f^int`` as ``B u``
            and to the energy as ``1/2 u^T B u`` (the bridging penalty, eq. 72–75: its
            constraint ``u_FE - u_P`` stays linear; owned by the system).
    """

    def __init__(
        self,
        fields: Sequence[Field],
        sides: Sequence[FEForces | ParticleSide | None],
        material: Material,
        constraint: Sequence[PETSc.Mat | None] | None = None,
        shared: Sequence[SharedSide] = (),
        constant: Blocks | None = None,
    ) -> None:
        if len(sides) != len(fields):
            raise ValueError(f"{len(sides)} sides for {len(fields)} fields")
        self.fields, self.sides, self.material = list(fields), list(sides), material
        self.shared, self.constant = list(shared), dict(constant or {})
        self.G: list[PETSc.Mat | None] | None = None
        if constraint is not None and any(g is not None for g in constraint):
            self.G = list(constraint)
        self.comm: MPI.Comm = self.fields[0].mass.getComm().tompi4py()
        self._tangent: list[PETSc.Mat] = []

    def mass(self) -> list[PETSc.Vec]:
        """The lumped masses of each field."""
        return [f.mass for f in self.fields]

    def _check_fe(self, side: FEForces, x: PETSc.Vec) -> None:
        """Name the first FE point where ``det F <= 0`` or ``F`` is not finite (every rank)."""
        F, gdim = side.deformation_gradient(x), self.material.gdim
        points = side.points.table.points
        raise_on_all_ranks(self.comm, lambda: check_deformation_gradients(F, gdim, points))

    def internal_force(
        self, u: Sequence[PETSc.Vec], out: Sequence[PETSc.Vec] | None = None
    ) -> list[PETSc.Vec]:
        """``f^int(u)`` per field (collective). Raises a
        :class:`~dolfinx_meshfree.physics.constitutive.DeformationError` on every rank, naming
        the point, where ``det F <= 0`` (particles: at once; FE: when the assembled force is not
        finite, and at every wave-speed check)."""
        y = list(out) if out is not None else [f.mass.duplicate() for f in self.fields]
        for k, side in enumerate(self.sides):
            if side is None:
                y[k].set(0.0)
                continue
            if isinstance(side, FEForces):
                r = side.side.internal_force(u[k])
                finite = bool(np.all(np.isfinite(r.array_r)))
                if not self.comm.allreduce(finite, op=MPI.LAND):
                    r.destroy()
                    self._check_fe(side, u[k])
                    raise DeformationError("the FE internal force is not finite; stop")
            else:
                r = side.internal_force(u[k])
            y[k].array[:] = r.array_r
            r.destroy()
        for shared in self.shared:
            forces = shared.internal_force([u[i] for i in shared.fields])
            for i, r in zip(shared.fields, forces, strict=True):
                y[i].axpy(1.0, r)
                r.destroy()
        for (k, j), B in self.constant.items():
            B.multAdd(u[j], y[k], y[k])
        return y

    def tangent(self, u: Sequence[PETSc.Vec] | None = None) -> Blocks:
        """The consistent tangent of each field at ``u`` (``None``: ``d = 0``); the system owns
        the matrices until the next call (collective)."""
        for M in self._tangent:
            M.destroy()
        if u is None:
            u = [f.mass.duplicate() for f in self.fields]
            for x in u:
                x.set(0.0)
        blocks: Blocks = {}
        for k, side in enumerate(self._raw_sides()):
            if side is not None:
                blocks[k, k] = side.tangent(u[k])
        different = PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN
        parts = [
            (shared.fields[a], shared.fields[b], M, True)
            for shared in self.shared
            for (a, b), M in shared.tangent([u[i] for i in shared.fields]).items()
        ]
        parts += [(k, j, B, False) for (k, j), B in self.constant.items()]
        for k, j, M, owned in parts:
            if (k, j) in blocks:
                blocks[k, j].setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
                blocks[k, j].axpy(1.0, M, structure=different)
                if owned:
                    M.destroy()
            else:
                blocks[k, j] = M if owned else M.copy()
        # diagonal blocks first, in field order
        order = sorted(blocks, key=lambda kl: (kl[0] != kl[1], kl))
        self._tangent = [blocks[kl] for kl in order]
        return {kl: blocks[kl] for kl in order}

    def _raw_sides(self) -> list:
        return [s.side if isinstance(s, FEForces) else s for s in self.sides]

    def constraints(self) -> list[PETSc.Mat | None] | None:
        """The constraint blocks (``None``: no constraint)."""
        return self.G

    def strain_energy(self, u: Sequence[PETSc.Vec], f_int: Sequence[PETSc.Vec]) -> float:
        """The stored energy ``sum_q W(F_q) w_q`` over both sides and all ranks (``f_int`` is
        not used; collective)."""
        local = 0.0
        for side, x in zip(self.sides, u, strict=True):
            if isinstance(side, FEForces):
                local += side.points.strain_energy(side.state(x))
            elif side is not None:
                local += side.forces.strain_energy(side.coefficients(x))
        for shared in self.shared:
            local += shared.strain_energy([u[i] for i in shared.fields])
        energy = float(self.comm.allreduce(local, op=MPI.SUM))
        for (k, j), B in self.constant.items():  # 1/2 u^T B u, collective
            y = B.createVecLeft()
            B.mult(u[j], y)
            energy += 0.5 * y.dot(u[k])
            y.destroy()
        return energy

    def deformation_gradients(self, u: Sequence[PETSc.Vec]) -> np.ndarray:
        """``F`` (m, d, d) at this rank's quadrature points of every field."""
        out = []
        for side, x in zip(self.sides, u, strict=True):
            if isinstance(side, FEForces):
                out.append(side.deformation_gradient(x))
            elif side is not None:
                out.append(side.forces.deformation_gradient(side.coefficients(x)))
        for shared in self.shared:
            out.append(shared.deformation_gradient([u[i] for i in shared.fields]))
        return np.concatenate(out)

    def set_time(self, t: float) -> None:
        """The time of the next internal force (the stepper's ``t_n``): a rate-form law advances
        its state to it (:mod:`~dolfinx_meshfree.dynamics.rate_forms`); nothing for the others."""
        if isinstance(self.material, RateLaws):
            self.material.set_time(t)

    def wave_speed(self, u: Sequence[PETSc.Vec]) -> float:
        """The largest current Lagrangian wave speed over every quadrature point and rank
        (:meth:`~dolfinx_meshfree.physics.constitutive.Material.wave_speed`); raises a
        :class:`~dolfinx_meshfree.physics.constitutive.DeformationError` on every rank where
        ``det F <= 0`` (collective). A rate-form law's speed is its points' state's (their
        last update: no gradient to compute)."""
        if isinstance(self.material, RateLaws):
            return float(self.comm.allreduce(self.material.wave_speed(), op=MPI.MAX))
        F = self.deformation_gradients(u)
        if F.shape[0] == 0:
            return float(self.comm.allreduce(0.0, op=MPI.MAX))
        c = raise_on_all_ranks(self.comm, lambda: self.material.wave_speed(F))
        return float(self.comm.allreduce(c, op=MPI.MAX))

    @property
    def viscous(self) -> bool:
        """Whether the material is a rate-form law with a bulk viscosity."""
        return isinstance(self.material, RateLaws) and self.material.viscous

    def viscous_factor(self) -> float:
        """The largest step factor of a rate-form law's bulk viscosity over every point and
        rank (1 without; collective): the damper's, by which the stable step is divided."""
        local = self.material.viscous_factor() if isinstance(self.material, RateLaws) else 1.0
        return float(self.comm.allreduce(local, op=MPI.MAX))

    def rebuild(self, changed: Collection[str]) -> bool:
        """Nothing to rebuild when nothing changed (``False``).

        Raises:
            NotImplementedError: ``changed`` is not empty: the tables follow the reference
                configuration of the model; build a new ExplicitDynamics instead.
        """
        if changed:
            raise NotImplementedError(
                f"changed={sorted(changed)!r}: a NonlinearSystem keeps the reference tables of "
                "its model; build a new ExplicitDynamics from the changed model"
            )
        return False

    def destroy(self) -> None:
        """Destroy the tangents, the constant blocks, the fields' reference stiffness and masses
        and the constraint blocks (collective)."""
        objs = [*self._tangent, *self.constant.values()]
        for f in self.fields:
            objs += [f.K, f.mass]
        objs += [g for g in (self.G or []) if g is not None]
        for obj in objs:
            obj.destroy()
        self._tangent = []
