"""What a built explicit model can be struck by: another body of the model (contact between
bodies, :mod:`~dolfinx_meshfree.dynamics.body_contact`; every node of a body against another's
surface, :mod:`~dolfinx_meshfree.dynamics.nodes_contact`) and a rigid projectile
(:mod:`~dolfinx_meshfree.dynamics.rigid_projectile`). Each wraps the model's semi-discrete
system in one that adds its forces, its energy and its stiffness (the stable step is bounded
again with it).

:class:`Struck` is a base of :class:`~dolfinx_meshfree.ExplicitDynamics`, which owns what it
changes: ``system`` (also the stepper's and the bound's), ``bound``, ``evaluator`` and
``material``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from .body_contact import BodyContact, with_body_contact
from .evaluation import FieldEvaluator
from .nodes_contact import with_nodes_contact
from .rigid_projectile import (
    ProjectileContactSystem,
    RigidProjectile,
    projectiles,
    with_projectile,
)
from .system import SemiDiscreteSystem

__all__ = ["Struck"]


class Struck:
    """Contact between bodies and a rigid projectile added to a built explicit model (the base
    of :class:`~dolfinx_meshfree.ExplicitDynamics`; see the module docstring)."""

    system: SemiDiscreteSystem
    evaluator: FieldEvaluator

    def _wrap(self, system: SemiDiscreteSystem) -> None:
        """Make ``system`` the model's (the stepper's and the bound's too) and re-bound."""
        self.system = self.stepper.system = self.bound.system = system
        self.bound.invalidate()

    def add_contact(
        self,
        surface_a: npt.ArrayLike,
        surface_b: npt.ArrayLike,
        contact: BodyContact | None = None,
    ) -> None:
        """Contact between two bodies of the model (2D and 3D; node-to-facet penalty,
        frictionless or Coulomb, :mod:`~dolfinx_meshfree.dynamics.body_contact`): ``surface_a`` and
        ``surface_b`` are owned exterior facets (e.g. ``mf.boundary_facets(mesh, marker)``) of
        two pieces of the mesh that share no vertex, each discretised as the model discretises
        it (FE, particle or blended cells; each body's particles are its own: the model's MLS
        stops at the bodies' gap, :func:`~dolfinx_meshfree.separate_bodies`). The contact
        force joins the internal force, its penalty energy the strain energy of the energy
        records, and the stable step is bounded again with the contact's stiffness
        (:meth:`critical_time_step`). Several pairs may be added. Collective.

        Args:
            contact: The options (:class:`~dolfinx_meshfree.dynamics.BodyContact`; default:
                penalty ``E / h``, two-pass, frictionless). ``BodyContact(slaves="body")``
                takes every node of ``surface_a``'s body as a slave of ``surface_b``'s facets
                (a projectile ``surface_b`` that perforates its target,
                :mod:`~dolfinx_meshfree.dynamics.nodes_contact`).

        Raises:
            ValueError: facets that are not owned exterior facets, an empty surface, surfaces
                that share a vertex, a particle whose support reaches both surfaces (on every
                rank).
        """
        contact = BodyContact() if contact is None else contact
        E = getattr(self.material, "E", None)
        if isinstance(contact, BodyContact) and contact.slaves == "body":
            omega_0 = self.bound.critical()["omega_bound"]
            system = with_nodes_contact(
                self.system, self.evaluator, self.material, omega_0, surface_a, surface_b, contact
            )
            self._wrap(system)
            return
        self._wrap(with_body_contact(self.system, self.evaluator, E, surface_a, surface_b, contact))

    def add_projectile(
        self,
        projectile: RigidProjectile,
        where: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> ProjectileContactSystem:
        """A rigid projectile that strikes the model (an ogive- or flat-nosed body of revolution
        about the model's axis, :mod:`~dolfinx_meshfree.dynamics.rigid_projectile`): every
        vertex and particle (or those where ``where(x)`` holds, reference positions (m, gdim)
        -> (m,) bool) is pushed out of it by a penalty, and the projectile is decelerated by
        the reaction. Its state and history are the returned system's ``state``
        (:class:`~dolfinx_meshfree.dynamics.rigid_projectile.ProjectileState`; the exit
        velocity is ``state.history[-1][2]``); the stable step is bounded again with the
        penalty's stiffness. Call it before the first run. Collective.

        Raises:
            ValueError: a model without a mesh, ``where`` selecting no point, master–slave's
                rotating links (on every rank).
        """
        omega_0 = self.bound.critical()["omega_bound"]
        system = with_projectile(self.system, self.evaluator, omega_0, projectile, where)
        self._wrap(system)
        return system

    @property
    def projectiles(self) -> list[ProjectileContactSystem]:
        """The systems of the projectiles that strike the model, in the order they were added
        (:meth:`add_projectile`); each one's ``state`` is its
        :class:`~dolfinx_meshfree.dynamics.rigid_projectile.ProjectileState`. After a
        conversion (:class:`~dolfinx_meshfree.dynamics.AdaptiveRun`) the model is a new one:
        read ``run.model.projectiles``, which continue the old ones' states."""
        return projectiles(self.system)[::-1]
