"""Prescribed (non-zero, time-dependent) velocities of held dofs in explicit dynamics.

FE nodes: a held FE dof has ``M^{-1} = 0``
(:func:`~dolfinx_meshfree.dynamics.system.inverse_masses`), so central differences leave its
velocity alone; a prescribed velocity ``vbar(t)`` is imposed by setting ``v_{n+1/2} =
vbar(t_{n+1/2})`` there after the trial step (Belytschko et al. 1995, eq. 93), so that
``d_{n+1} = d_n + dt vbar(t_{n+1/2})`` (the midpoint rule of ``int vbar``). The reaction that
drives the dofs is the force the free equation of motion would need,

.. math::
    r_n = M (v_{n+1/2} - v_{n-1/2}) / (\\gamma\\, dt) + f^{int}(d_n) - f^{ext}_n

(eq. 4.4 on the held rows), and its work ``r_n . (d_{n+1} - d_{n-1}) / 2`` enters the external
work of the energy record (:func:`~dolfinx_meshfree.dynamics.energy.reaction_work`), so the
discrete energy balance closes to round-off as for a load.

Particles (pure EFG): the facet multipliers of the held facets
(:mod:`~dolfinx_meshfree.dynamics.conditions`) get the right-hand side ``int_f vbar_i(t)``: the
velocity correction solves ``G v_{n+1/2} = g(t_{n+1/2})`` (eq. 94–96 with a non-zero
right-hand side), and the work of its reaction ``-G^T lambda / dt`` is the constraint work of
the record (:func:`~dolfinx_meshfree.dynamics.energy.constraint_work`).

Given as ``fixed_facets`` triples ``(facets, components, velocity)``
(:func:`~dolfinx_meshfree.dynamics.conditions.held_velocities`): ``velocity(t)`` a number or one
number per held component, the same on all the facets (the impact of a flat projectile, the
driven end of a bar). Refused: driven facets on particle cells of a coupled model.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import dolfinx
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..parallel import raise_on_all_ranks
from .conditions import first_cells, fixed_fe_dofs, particle_conditions
from .discretisation import Discretisation
from .energy import reaction_work

__all__ = ["HeldVelocity", "PrescribedMotion"]

#: ``(facets, components, velocity(t))``
#: (:func:`~dolfinx_meshfree.dynamics.conditions.held_velocities`).
HeldVelocity = tuple[np.ndarray, tuple[int, ...], Callable[[float], float | Sequence[float]] | None]


class PrescribedMotion:
    """Held dofs driven at prescribed velocities, and the work of their reactions.

    Args:
        disc: The model's spaces.
        held: Every ``fixed_facets`` group ``(facets, components, velocity or None)``, in order
            (:func:`~dolfinx_meshfree.dynamics.conditions.held_velocities`).
        comm: The communicator.

    Raises:
        ValueError: on every rank: a driven facet on a particle cell of a coupled model
            (naming its midpoint), or ``velocity(t)`` not one number or one per component.
    """

    def __init__(self, disc: Discretisation, held: Sequence[HeldVelocity], comm: MPI.Comm) -> None:
        self.comm = comm
        V, msh = disc.V, disc.mesh

        def check() -> None:
            for facets, _, velocity in held:
                if V is None or disc.in_patch is None or velocity is None or not facets.size:
                    continue
                on_p = disc.in_patch[first_cells(msh, facets)]
                if np.any(on_p):
                    f = np.array([facets[np.flatnonzero(on_p)[0]]], dtype=np.int32)
                    x = dolfinx.mesh.compute_midpoints(msh, msh.topology.dim - 1, f)[0]
                    raise ValueError(
                        f"the facet at {np.round(x[: msh.geometry.dim], 12).tolist()} with a "
                        "prescribed velocity lies on a particle cell of a coupled model; "
                        "prescribed velocities drive FE nodes (or the particles of pure EFG): "
                        "move the particle patch away from the driven facets or load them by a "
                        "traction"
                    )

        raise_on_all_ranks(comm, check)
        self.held = [(f, tuple(c), v) for f, c, v in held]
        gdim = msh.geometry.dim
        #: the owned FE dofs of each driven group's components (FE models)
        self._dofs: list[np.ndarray] = []
        self.rows: np.ndarray | None = None  # particles: the multipliers' right-hand side
        if V is not None:
            for facets, comps, velocity in self.held:
                if velocity is not None:
                    mask = fixed_fe_dofs(V, facets).reshape(-1, gdim)
                    self._dofs += [np.flatnonzero(mask[:, c]) * gdim + c for c in comps]
        else:
            self._particle_rows(disc)
        self._held = np.unique(np.concatenate([*self._dofs, np.zeros(0, dtype=np.int64)]))

    def _particle_rows(self, disc: Discretisation) -> None:
        """The facet multipliers of pure EFG as the builder makes them (the same groups in the
        same order): per owned row its group, component and ``int_f 1`` (collective)."""
        mls = disc.mls
        _, dl, rows, measure = particle_conditions(
            disc.particles,
            [f for f, _, _ in self.held],
            [lambda q: mls.tabulate(q.points, 0)] * len(self.held),
            [c for _, c, _ in self.held],
            measures=True,
        )
        group, comp = [], []
        for j, (facets, comps, _) in enumerate(self.held):
            n = np.unique(facets).size  # one multiplier per facet and component
            group.append(np.full(n * len(comps), j))
            comp.append(np.tile(np.arange(len(comps)), n))
        self.group = np.concatenate([*group, np.zeros(0, dtype=np.int64)])
        self.comp = np.concatenate([*comp, np.zeros(0, dtype=np.int64)])
        self.measure = np.zeros(dl.size_local)
        np.add.at(self.measure, np.asarray(rows) - dl.start, measure)  # one per facet point
        if self.group.size != dl.size_local:  # the builder's layout, rank by rank
            raise RuntimeError("the held facets' multipliers do not match the builder's rows")
        self.rows = np.unique(rows)

    def values(self, t: float) -> list[np.ndarray]:
        """The velocity of each group's components at ``t`` (zero for groups held at rest;
        checked on every rank)."""

        def check() -> list[np.ndarray]:
            out = []
            for _, comps, velocity in self.held:
                if velocity is None:
                    out.append(np.zeros(len(comps)))
                    continue
                v = np.atleast_1d(np.asarray(velocity(t), dtype=float))
                if v.shape not in ((1,), (len(comps),)) or not np.all(np.isfinite(v)):
                    raise ValueError(
                        f"velocity({t!r}) gave {v!r:.80}: give one finite number, or one per held "
                        f"component {comps}"
                    )
                out.append(np.broadcast_to(v, (len(comps),)))
            return out

        return raise_on_all_ranks(self.comm, check)

    def target(self, t: float) -> np.ndarray | None:
        """Pure EFG: the owned rows of ``g(t) = int_f vbar(t)`` of the velocity constraint
        ``G v = g``; ``None`` for an FE model (collective)."""
        if self.rows is None:
            return None
        vals = self.values(t)
        table = np.zeros((len(vals), max((v.size for v in vals), default=0)))
        for j, v in enumerate(vals):
            table[j, : v.size] = v
        return self.measure * table[self.group, self.comp]

    def kept(self, G: Sequence[PETSc.Mat | None], vecs: Sequence[PETSc.Vec]) -> np.ndarray | None:
        """Pure EFG: ``G x`` on the driven rows, 0 elsewhere: the right-hand side that keeps the
        driven values of ``x`` when it is projected onto a rebuilt constraint (a grown crack);
        ``None`` for an FE model (collective)."""
        if self.rows is None:
            return None
        gx = G[-1].createVecLeft()
        G[-1].mult(vecs[-1], gx)
        driven = np.array([v is not None for _, _, v in self.held])[self.group]
        out = np.where(driven, gx.array_r, 0.0)
        gx.destroy()
        return out

    def impose(
        self,
        mass: PETSc.Vec,
        residual: PETSc.Vec,
        v_old: PETSc.Vec,
        v_new: PETSc.Vec,
        t: float,
        dt: float,
        gamma: float,
    ) -> float:
        """Set the driven FE dofs of ``v_new`` (``v_{n+1/2}``, the FE field) to the velocity at
        ``t + dt/2`` and return the work of their reaction over the step ``n`` (at ``t``), in
        the form of :func:`~dolfinx_meshfree.dynamics.energy.external_work`; 0 for pure EFG
        (its reaction is a constraint force; collective).

        Args:
            mass: The field's lumped masses. residual: ``f^int(d_n) - f^ext_n`` there.
            v_old: ``v_{n-1/2}``. gamma: The step's velocity-update factor (0.5 at ``n = 0``).
        """
        if self.rows is not None:
            return 0.0
        vals = [x for (_, _, v), g in zip(self.held, self.values(t + 0.5 * dt), strict=True)
                if v is not None for x in g]  # fmt: skip
        arr = v_new.array
        for d, v in zip(self._dofs, vals, strict=True):
            arr[d] = v
        return reaction_work(mass, residual, v_old, v_new, self._held, dt, gamma, self.comm)
