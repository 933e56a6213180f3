"""Prescribed (non-zero, time-dependent) velocities of held FE dofs in explicit dynamics.

A held FE dof has ``M^{-1} = 0`` (:func:`~dolfinx_meshfree.dynamics.system.inverse_masses`), so
central differences leave its velocity alone; a prescribed velocity ``vbar(t)`` is imposed by
setting ``v_{n+1/2} = vbar(t_{n+1/2})`` there after the trial step (Belytschko et al. 1995, eq.
93), so that ``d_{n+1} = d_n + dt vbar(t_{n+1/2})`` (the midpoint rule of ``int vbar``). The
reaction that drives the dofs is the force the free equation of motion would need,

.. math::
    r_n = M (v_{n+1/2} - v_{n-1/2}) / (\\gamma\\, dt) + f^{int}(d_n) - f^{ext}_n

(eq. 4.4 on the held rows), and its work ``r_n . (d_{n+1} - d_{n-1}) / 2`` enters the external
work of the energy record (:func:`~dolfinx_meshfree.dynamics.energy.reaction_work`), so the
discrete energy balance closes to round-off as for a load.

Given as ``fixed_facets`` triples ``(facets, components, velocity)``
(:func:`~dolfinx_meshfree.dynamics.conditions.held_velocities`): ``velocity(t)`` a number or one
number per held component, the same on all the facets' nodes (the impact of a flat projectile,
the driven end of a bar). FE nodes only: facets of particle cells are refused (a particle's
held value would need a non-zero right-hand side of the velocity constraint).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import dolfinx
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..parallel import raise_on_all_ranks
from .conditions import first_cells, fixed_fe_dofs
from .discretisation import Discretisation
from .energy import reaction_work

__all__ = ["HeldVelocity", "PrescribedMotion"]

#: ``(facets, components, velocity(t))``
#: (:func:`~dolfinx_meshfree.dynamics.conditions.held_velocities`).
HeldVelocity = tuple[np.ndarray, tuple[int, ...], Callable[[float], float | Sequence[float]]]


class PrescribedMotion:
    """The held FE dofs driven at prescribed velocities, and the work of their reactions.

    Args:
        disc: The model's spaces (its FE space holds the dofs).
        held: ``(facets, components, velocity)`` groups (validated facets and components).
        comm: The communicator.

    Raises:
        ValueError: on every rank: the model has no FE space, or a facet lies on a particle
            cell (naming its midpoint), or ``velocity(t)`` does not give one number or one per
            component.
    """

    def __init__(self, disc: Discretisation, held: Sequence[HeldVelocity], comm: MPI.Comm) -> None:
        self.comm = comm
        V, msh = disc.V, disc.mesh

        def check() -> None:
            if V is None:
                raise ValueError(
                    "fixed_facets with a velocity (facets, components, velocity) drives FE nodes; "
                    "this model has none (pure EFG): hold the facets at rest or load them by a "
                    "traction (add_traction)"
                )
            for facets, _, _ in held:
                if disc.in_patch is None or not facets.size:
                    continue
                on_p = disc.in_patch[first_cells(msh, facets)]
                if np.any(on_p):
                    f = int(facets[np.flatnonzero(on_p)[0]])
                    fs = np.array([f], dtype=np.int32)
                    x = dolfinx.mesh.compute_midpoints(msh, msh.topology.dim - 1, fs)[0]
                    x = x[: msh.geometry.dim]
                    raise ValueError(
                        f"the facet at {np.round(x, 12).tolist()} with a prescribed velocity lies "
                        "on a particle cell; prescribed velocities drive FE nodes only: move the "
                        "particle patch away from the driven facets or load them by a traction"
                    )

        raise_on_all_ranks(comm, check)
        gdim = msh.geometry.dim
        #: per group: the owned FE dofs of each held component and ``velocity``
        self.groups: list[tuple[list[np.ndarray], Callable]] = []
        for facets, comps, velocity in held:
            mask = fixed_fe_dofs(V, facets).reshape(-1, gdim)
            self.groups.append(([np.flatnonzero(mask[:, c]) * gdim + c for c in comps], velocity))
        self.components = [tuple(c) for _, c, _ in held]
        self._dofs = [d for ds, _ in self.groups for d in ds]
        self._held = np.unique(np.concatenate([*self._dofs, np.zeros(0, dtype=np.int64)]))

    def values(self, t: float) -> list[np.ndarray]:
        """The velocity of each group's components at ``t`` (checked on every rank)."""

        def check() -> list[np.ndarray]:
            out = []
            for (dofs, velocity), comps in zip(self.groups, self.components, strict=True):
                v = np.atleast_1d(np.asarray(velocity(t), dtype=float))
                if v.shape not in ((1,), (len(comps),)) or not np.all(np.isfinite(v)):
                    raise ValueError(
                        f"velocity({t!r}) gave {v!r:.80}: give one finite number, or one per held "
                        f"component {comps}"
                    )
                out.append(np.broadcast_to(v, (len(dofs),)))
            return out

        return raise_on_all_ranks(self.comm, check)

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
        """Set the held dofs of the FE field's ``v_new`` (``v_{n+1/2}``) to the velocity at
        ``t + dt/2`` and return the work of the reaction over the step ``n`` (at ``t``), in the
        form of :func:`~dolfinx_meshfree.dynamics.energy.external_work` (collective).

        Args:
            mass: The FE field's lumped masses. residual: ``f^int(d_n) - f^ext_n`` there.
            v_old: ``v_{n-1/2}``. gamma: The step's velocity-update factor (0.5 at ``n = 0``).
        """
        vals = [x for group in self.values(t + 0.5 * dt) for x in group]
        arr = v_new.array
        for d, v in zip(self._dofs, vals, strict=True):
            arr[d] = v
        return reaction_work(mass, residual, v_old, v_new, self._held, dt, gamma, self.comm)
