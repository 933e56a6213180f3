"""A law's state as a field on the mesh: one value per cell (issue 27: the damage field of Rabczuk
et al. 2006, Fig. 21, written with the displacement; and the plastic zone or damage of a static
solution of a law with state, for ``XDMFFile``).

The state of :class:`~dolfinx_meshfree.dynamics.rate_forms.RateLaws` lives at points: the FE
cells' Gauss points and the particle rule's points, each in a cell of the mesh
(:meth:`~dolfinx_meshfree.dynamics.rate_forms.RateLaw.attach`). :func:`state_field` reduces the
points of each cell to one value (their largest, smallest or mean) in a piecewise constant (DG0)
function. The largest is the default: a cell with one failed point is where the material has
failed (the rule :class:`~dolfinx_meshfree.StateAbove` applies to convert cells).
:class:`~dolfinx_meshfree.DynamicsWriter` (``dyn.run(..., xdmf=prefix)``) writes every scalar
state variable of a model with an FE space this way (:func:`state_fields`), beside the
displacement, in ``{prefix}_fe.xdmf``.

Example (one field, for a plot or DOLFINx's own writers)::

    damage = mf.dynamics.state_field(dyn, "damage")  # a DG0 Function named "damage"
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import dolfinx
import numpy as np

from . import _compat
from .mesh_cache import cached
from .parallel import raise_on_all_ranks

if TYPE_CHECKING:  # annotations only
    from .dynamics.explicit import ExplicitDynamics

__all__ = ["REDUCTIONS", "cell_values", "state_field", "state_fields"]

#: How the points of a cell become its value.
REDUCTIONS = ("max", "min", "mean")


def state_field(
    model: ExplicitDynamics | object, name: str, reduce: str = "max"
) -> dolfinx.fem.Function:
    """The scalar state variable ``name`` of ``model``'s rate-form law, or of a static
    solution's law with state, as a DG0 function on its mesh: per cell the ``reduce`` of the
    values at its points (collective).

    Args:
        model: An explicit model whose material is a rate-form law
            (:class:`~dolfinx_meshfree.HolmquistJohnsonCook`,
            :class:`~dolfinx_meshfree.JohnsonCook`); or the solution of a static model with a
            law with state (:class:`~dolfinx_meshfree.RankineDamage`,
            :class:`~dolfinx_meshfree.J2Plasticity`: ``model.solve()``, ``path.solution``),
            its FE cells', particles' and interface cells' points (``"alpha"``,
            ``"damage"``, ``"dissipation"``, ...).
        name: A scalar state variable (``"damage"``, ``"plastic_strain"``, ...).
        reduce: ``"max"`` (default), ``"min"`` or ``"mean"`` over the cell's points.

    Returns:
        A new function of the mesh's scalar DG0 space, named ``name``; a cell without points
        holds the virgin state's value.

    Raises:
        ValueError: on every rank: a model whose law has no state, an unknown variable (the
            message lists the law's scalar ones), an unknown ``reduce``.
    """
    if reduce not in REDUCTIONS:  # the same on every rank
        raise ValueError(f"reduce={reduce!r} must be one of {REDUCTIONS}")
    if not hasattr(model, "evaluator"):  # a static solution
        return _static_state_field(model, name, reduce)
    law = model.material
    msh = model.evaluator.disc.mesh

    def check() -> tuple[np.ndarray, np.ndarray, float]:
        values = getattr(law, "state_values", None)
        if values is None:
            raise ValueError(
                f"state_field reads the state of a rate-form law (HolmquistJohnsonCook, "
                f"JohnsonCook); this model's material is {type(law).__name__}, which has none"
            )
        if msh is None:
            raise ValueError("state_field needs the model's mesh (a model built on one)")
        return values(name)

    cells, v, virgin = raise_on_all_ranks(model.comm, check)
    return _reduced(msh, name, cells, v, virgin, reduce)


def _reduced(
    msh: dolfinx.mesh.Mesh,
    name: str,
    cells: np.ndarray,
    v: np.ndarray,
    virgin: float,
    reduce: str,
) -> dolfinx.fem.Function:
    """The DG0 function ``name`` of the values ``v`` at points of the local ``cells``, reduced
    per owned cell (``virgin`` where a cell has none; collective)."""
    Q, dofs = _dg0(msh)
    n_own = len(dofs)
    own = cells < n_own  # every point's cell is a local cell; ghost cells are filled below
    cells, v = cells[own], v[own]
    if reduce == "mean":
        total = np.bincount(cells, weights=v, minlength=n_own)
        count = np.bincount(cells, minlength=n_own)
        per_cell = np.where(count > 0, total / np.maximum(count, 1), virgin)
    else:
        fill = -np.inf if reduce == "max" else np.inf
        per_cell = np.full(n_own, fill)
        (np.maximum if reduce == "max" else np.minimum).at(per_cell, cells, v)
        per_cell = np.where(np.isfinite(per_cell), per_cell, virgin)
    f = dolfinx.fem.Function(Q, name=name)
    f.x.array[dofs] = per_cell
    f.x.scatter_forward()
    return f


def cell_values(
    msh: dolfinx.mesh.Mesh, cells: np.ndarray, v: np.ndarray, virgin: float, reduce: str = "max"
) -> np.ndarray:
    """The values ``v`` at points of the local ``cells`` reduced per cell (``virgin`` where a
    cell has none), for every local cell, ghosts included: what a rank reads of a neighbour's
    cell across a partition boundary (collective)."""
    f = _reduced(msh, "cell_values", cells, v, virgin, reduce)
    return f.x.array[_compat.dofmap_array(f.function_space)[:, 0]].copy()


def _static_state_field(solution: object, name: str, reduce: str) -> dolfinx.fem.Function:
    """:func:`state_field` of a static solution of a law with state (its ``states``: the FE
    cells', the particles' and the ramps' interface points; cohesive faces have no cell and are
    left out). Collective."""
    stores = [st for st in getattr(solution, "states", None) or [] if st.cells is not None]
    u = getattr(solution, "u", None)
    particles = getattr(solution, "particles", None)
    msh = u.function_space.mesh if u is not None else getattr(particles, "mesh", None)
    if msh is None:  # the same on every rank
        raise ValueError(
            f"state_field: a {type(solution).__name__} without a mesh (the solution of a model "
            "solved on particles and a background mesh, or an explicit model, is needed)"
        )
    comm = msh.comm

    def check() -> tuple[np.ndarray, np.ndarray, float]:
        if not stores:
            raise ValueError(
                f"state_field: this {type(solution).__name__} has no state at points of cells "
                "(solve a model with a law with state: RankineDamage, J2Plasticity)"
            )
        scalars = sorted(
            {k for st in stores for k, a in st.committed.items() if a.ndim == 2 and a.shape[1] == 1}
        )
        if name not in scalars:
            raise ValueError(
                f"state_field: {name!r} is not a scalar state variable of this solution's law; "
                f"its scalar ones are {scalars}"
            )
        cells = np.concatenate([st.cells for st in stores])
        v = np.concatenate([st.committed[name][:, 0] for st in stores])
        virgin = float(stores[0].law.initial_state(1)[name][0, 0])
        return cells, v, virgin

    cells, v, virgin = raise_on_all_ranks(comm, check)
    return _reduced(msh, name, cells, v, virgin, reduce)


def _dg0(msh: dolfinx.mesh.Mesh) -> tuple[dolfinx.fem.FunctionSpace, np.ndarray]:
    """The mesh's scalar DG0 space and the dof of each owned cell (built once per mesh)."""

    def build() -> tuple[dolfinx.fem.FunctionSpace, np.ndarray]:
        Q = _compat.scalar_function_space(msh, "DG", 0)
        n_own = msh.topology.index_map(msh.topology.dim).size_local
        return Q, _compat.dofmap_array(Q)[:n_own, 0].copy()

    return cached(msh, ("state_fields", "dg0"), build)


def state_fields(model: ExplicitDynamics) -> list[dolfinx.fem.Function]:
    """Every scalar state variable of ``model``'s rate-form law as :func:`state_field` (the
    largest per cell), in the law's order; none for a law without state or a model without
    a mesh (collective)."""
    law = model.material
    if getattr(law, "state_values", None) is None or model.evaluator.disc.mesh is None:
        return []
    return [state_field(model, name) for name in law.scalar_names()]
