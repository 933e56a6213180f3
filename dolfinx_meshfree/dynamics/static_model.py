"""What explicit dynamics takes from a static model, and what it leaves behind.

:meth:`ExplicitDynamics.coupled <dolfinx_meshfree.dynamics.ExplicitDynamics.coupled>` builds
the dynamic system from a static model (:class:`~dolfinx_meshfree.CoupledElasticity`, a
:class:`~dolfinx_meshfree.CoupledLinearProblem`'s ``model``, a
:class:`~dolfinx_meshfree.HybridElasticity`): its mesh, patch, couplings, material and options.
Its Dirichlet conditions, tractions and body forces are *not* carried (dynamics holds facets
with ``fixed_facets=`` and loads them with ``add_traction(..., amplitude)`` and
``add_body_force``, functions of time). Before, they were dropped without a word: a static
model clamped at one end and pulled at the other ran in dynamics as a free body at rest.
:func:`check_static_model` now warns (:class:`StaticModelWarning`), naming what is left behind
and the calls that carry it, and refuses an elastic support in the user's form (a ``ds`` term
of the unknown, :mod:`~dolfinx_meshfree.statics.facet_terms`), which dynamics does not carry.
"""

from __future__ import annotations

import warnings

import numpy as np
from mpi4py import MPI

from ..parallel import raise_on_all_ranks
from ..statics.facet_terms import facet_integrals

__all__ = ["StaticModelWarning", "check_static_model"]


class StaticModelWarning(UserWarning):
    """A static model's Dirichlet conditions, tractions or body forces, which explicit dynamics
    does not take, were given to it."""


def _held(problem: object) -> bool:
    """The model holds some dof (strong FE conditions or facet conditions), on this rank."""
    strong = getattr(problem, "strong", None) or []
    if any(np.asarray(flags).any() for flags, _ in strong):
        return True
    return bool(
        getattr(problem, "dirichlet", None) or getattr(problem, "component_dirichlet", None)
    )


def _loaded(tractions: list) -> bool:
    """Some traction is not zero on this rank (a form's traction, tabulated as ``A + B n``, is
    known; a callable is taken as a load)."""
    for _, fn in tractions:
        A, B = getattr(fn, "A", None), getattr(fn, "B", None)
        if A is None or B is None or np.abs(A).max(initial=0.0) or np.abs(B).max(initial=0.0):
            return True
    return False


def check_static_model(problem: object) -> None:
    """Refuse a form with facet terms of the unknown and warn of the static conditions and
    loads that dynamics leaves behind (collective: the same on every rank)."""
    comm = getattr(getattr(problem, "patch", None), "comm", MPI.COMM_WORLD)
    form = getattr(problem, "form", None)

    def check_form() -> None:
        if form is not None and facet_integrals(form):
            raise ValueError(
                "the CoupledLinearProblem's bilinear form has ds integrals of the unknown (an "
                "elastic support): explicit dynamics does not carry them yet; model the support "
                "with held velocities or contact, or solve the statics only"
            )

    raise_on_all_ranks(comm, check_form)
    local = np.array(
        [
            _held(problem),
            _loaded(getattr(problem, "tractions", None) or []),
            bool(getattr(problem, "body_forces", None)),
        ],
        dtype=int,
    )
    comm.Allreduce(MPI.IN_PLACE, local, op=MPI.MAX)
    names = (
        "Dirichlet conditions (fixed_facets=[(facets, components)])",
        "tractions (dyn.add_traction(facets, t, amplitude))",
        "body forces (dyn.add_body_force(b, amplitude))",
    )
    what = [name for name, on in zip(names, local, strict=True) if on]
    if what:
        warnings.warn(
            "explicit dynamics does not take the static model's "
            + ", ".join(what)
            + ": they are not applied; give them to the dynamics as shown, or build the "
            "model without them",
            StaticModelWarning,
            stacklevel=3,
        )
