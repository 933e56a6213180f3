"""Essential conditions of explicit dynamics: facets held at rest, in all components or in some
(symmetry planes, rollers: ``fixed_facets=[(facets, (0,)), ...]``), or FE facets driven at a
prescribed velocity (``(facets, (0,), velocity)`` triples:
:mod:`~dolfinx_meshfree.dynamics.prescribed`).

FE dofs are held strongly (zero velocity and acceleration: ``M^{-1} = 0``), particles by one
multiplier per facet and held component
(:func:`~dolfinx_meshfree.statics.efg.facet_multipliers`) added to the velocity constraint, so
that ``int_f v^h_i = 0`` after every correction (Rabczuk et al. 2006, Table I, step 6;
Belytschko et al. 1995, eq. 94–96).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import dolfinx
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from .. import _compat
from ..approx.tables import ShapeTable
from ..geometry.particles import ParticleSet
from ..geometry.quadrature import QuadraturePoints, facet_quadrature
from ..parallel import Layout, raise_on_all_ranks
from ..physics import user_functions
from ..statics.efg import facet_multipliers
from ..statics.petsc import create_aij

__all__ = [
    "check_facets",
    "first_cells",
    "fixed_fe_dofs",
    "fixed_groups",
    "held_velocities",
    "particle_conditions",
    "stack_rows",
]


def check_facets(msh: dolfinx.mesh.Mesh, facets: npt.ArrayLike | None) -> np.ndarray:
    """Validated owned exterior facets of ``fixed_facets`` (empty when ``None``), checked on
    every rank (:func:`~dolfinx_meshfree.physics.user_functions.check_facets`: facets that no
    rank holds are refused too).

    Raises:
        ValueError: not a 1D integer array, a facet not owned here, or none on any rank (on
            every rank).
    """
    if facets is None:
        return np.zeros(0, dtype=np.int32)

    def check() -> None:
        if _is_pairs(facets):
            raise ValueError(
                "fixed_facets as (facets, components) pairs is not available with this method; "
                "pass facets whose nodes are held in all components"
            )

    raise_on_all_ranks(msh.comm, check)
    return user_functions.check_facets(msh, facets, "fixed_facets")


def _is_pairs(fixed_facets: object) -> bool:
    """Whether ``fixed_facets`` is a list of ``(facets, components)`` pairs or
    ``(facets, components, velocity)`` triples."""
    return (
        isinstance(fixed_facets, list)
        and len(fixed_facets) > 0
        and all(isinstance(p, tuple) and len(p) in (2, 3) for p in fixed_facets)
    )


def fixed_groups(
    msh: dolfinx.mesh.Mesh, fixed_facets: npt.ArrayLike | list | None
) -> list[tuple[np.ndarray, tuple[int, ...]]]:
    """``fixed_facets`` as validated ``(facets, components)`` groups (collective checks).

    ``fixed_facets``: ``None``, owned exterior facets (all components held), or a list of
    ``(facets, components)`` pairs, e.g. ``[(left, (0, 1)), (bottom, (1,))]``: the facets hold
    only the given components (a symmetry plane: the normal component); a third item, a
    velocity, is dropped here (:func:`held_velocities`).
    """
    if not _is_pairs(fixed_facets):
        f = check_facets(msh, fixed_facets)
        return [(f, tuple(range(msh.geometry.dim)))] if fixed_facets is not None else []
    gdim = msh.geometry.dim
    groups = []
    for facets, components, *_ in fixed_facets:

        def check(components: object = components) -> tuple[int, ...]:
            c = tuple(np.atleast_1d(components).tolist())
            if not c or len(set(c)) != len(c) or any(k not in range(gdim) for k in c):
                raise ValueError(
                    f"fixed_facets has components={components!r}; give distinct component "
                    f"indices in 0..{gdim - 1}, e.g. (0,) to hold u_x on a symmetry plane x = 0"
                )
            return c

        groups.append((check_facets(msh, facets), raise_on_all_ranks(msh.comm, check)))
    return groups


def held_velocities(
    msh: dolfinx.mesh.Mesh, fixed_facets: npt.ArrayLike | list | None
) -> list[tuple[np.ndarray, tuple[int, ...], Callable | None]]:
    """The groups of ``fixed_facets`` with their prescribed velocities, when some are given as
    ``(facets, components, velocity)`` triples: ``velocity(t)`` (a number, or one per
    component) drives the facets in those components instead of holding them at rest; a
    pair's velocity is ``None`` (held at rest). Empty without triples (collective checks; see
    :class:`~dolfinx_meshfree.dynamics.prescribed.PrescribedMotion`). E.g. the impact of
    Kalthoff–Winkler: ``[(symmetry, (1,)), (impact, (0,), lambda t: v0 * min(t / t_r, 1))]``.

    Raises:
        ValueError: on every rank: a velocity that is not callable; bad facets or components
            (:func:`fixed_groups`).
    """
    if not _is_pairs(fixed_facets) or all(len(item) == 2 for item in fixed_facets):
        return []
    groups = fixed_groups(msh, fixed_facets)
    out = []
    for (facets, comps), item in zip(groups, fixed_facets, strict=True):
        velocity = item[2] if len(item) == 3 else None

        def check(velocity: object = velocity) -> None:
            if velocity is not None and not callable(velocity):
                raise ValueError(
                    f"fixed_facets has the velocity {velocity!r:.80}; give a callable "
                    "velocity(t) -> a number or one number per held component"
                )

        raise_on_all_ranks(msh.comm, check)
        out.append((facets, comps, velocity))
    return out


def _one(x: np.ndarray) -> np.ndarray:
    """Unit values (m, gdim) at points (m, gdim): the facets' measures as right-hand side."""
    return np.ones(x.shape)


def first_cells(msh: dolfinx.mesh.Mesh, facets: np.ndarray) -> np.ndarray:
    """The first cell of each facet (the only one of an exterior facet)."""
    tdim = msh.topology.dim
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    return np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]].astype(np.int64)


def fixed_fe_dofs(
    V: dolfinx.fem.FunctionSpace,
    facets: np.ndarray | list[tuple[np.ndarray, tuple[int, ...]]],
) -> np.ndarray:
    """bool per owned FE dof: a node of one of the facets (on any rank; collective); with
    :func:`fixed_groups`' ``(facets, components)`` groups, only the held components."""
    if isinstance(facets, list):
        out = np.zeros(V.dofmap.index_map.size_local * V.mesh.geometry.dim, dtype=bool)
        for f, comps in facets:
            mask = fixed_fe_dofs(V, f).reshape(-1, V.mesh.geometry.dim)
            mask[:, [k for k in range(mask.shape[1]) if k not in comps]] = False
            out |= mask.ravel()
        return out
    msh = V.mesh
    nodes = dolfinx.fem.locate_dofs_topological(V, msh.topology.dim - 1, facets)
    f = dolfinx.fem.Function(V)
    f.x.array[:] = 0.0
    bs = msh.geometry.dim
    f.x.array[bs * np.asarray(nodes, dtype=np.int64)] = 1.0
    _compat.scatter_reverse_add(f)
    f.x.scatter_forward()
    n_owned = V.dofmap.index_map.size_local
    return np.repeat(f.x.array[0 : bs * n_owned : bs] > 0.5, bs)


def _zero(x: np.ndarray) -> np.ndarray:
    """Zero values (m, gdim) at points (m, gdim)."""
    return np.zeros(x.shape)


def particle_conditions(
    particles: ParticleSet,
    facets: Sequence[np.ndarray],
    tables: Sequence[Callable[[QuadraturePoints], ShapeTable]],
    components: Sequence[tuple[int, ...]] | None = None,
    measures: bool = False,
) -> tuple[sp.csr_matrix, Layout] | tuple[sp.csr_matrix, Layout, np.ndarray, np.ndarray]:
    """Facet multipliers ``int_f phi_J`` (unit scale) of groups of facets, each with the
    particle table of its cells and, optionally, the components it holds (collective);
    ``measures``: also the global rows and ``int_f 1`` of each multiplier (the right-hand side
    of a unit held value,
    :func:`~dolfinx_meshfree.statics.efg.facet_multipliers`)."""
    msh = particles.mesh
    comm = particles.comm
    conds, quads, tabs = [], [], []
    if components is None:
        components = [tuple(range(particles.gdim))] * len(facets)
    for f, table, comps in zip(facets, tables, components, strict=True):
        q = facet_quadrature(msh, f, 4)
        conds.append((f, _one if measures else _zero, comps))
        quads.append(q)
        tabs.append(raise_on_all_ranks(comm, lambda q=q, table=table: table(q)))
    D, rows, vals, dl = facet_multipliers(particles, conds, quads, tabs, 1.0)
    return (D, dl, rows, vals) if measures else (D, dl)


def stack_rows(
    comm: MPI.Comm,
    mats: Sequence[PETSc.Mat | None],
    row_layouts: Sequence[Layout],
    col: Layout,
) -> tuple[PETSc.Mat, Layout]:
    """Rows of several matrices with the same columns stacked (rank by rank); ``None``: zero
    rows (collective)."""
    parts, total = [], 0
    for A, rl in zip(mats, row_layouts, strict=True):
        if A is None:
            total += rl.size_local
            continue
        ai, aj, av = A.getValuesCSR()
        rows = np.repeat(np.arange(rl.size_local), np.diff(ai)) + total
        parts.append((rows, np.asarray(aj, dtype=np.int64), np.asarray(av)))
        total += rl.size_local
    lay = Layout.from_local(comm, total)
    r, c, v = (np.concatenate([p[i] for p in parts] + [np.zeros(0)]) for i in range(3))
    loc = sp.csr_matrix(
        (v, (r.astype(np.int64) + lay.start, c.astype(np.int64))),
        shape=(lay.size_global, col.size_global),
    )
    return create_aij(comm, loc, lay, col), lay
