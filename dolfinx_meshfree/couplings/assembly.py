"""The assembly steps every coupling shares, as functions of the model.

Each takes the :class:`~dolfinx_meshfree.CoupledElasticity` that holds the model (space, patch,
material, MLS, loads, essential conditions) and builds one piece of a coupled block system:
the FE stiffness on the FE cells, the essential conditions (strong on FE facets, piecewise
constant multipliers on patch facets, as :mod:`~dolfinx_meshfree.statics.efg`), traction and body
loads
(each side with its own functions), and the solve of the PETSc nest with the particle
coefficients gathered. The coupling modules compose them with their own interface terms.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import dolfinx
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .. import _compat
from ..approx.fe_points import tabulate_in_cells
from ..geometry.cut_cells import cut_facet_quadrature
from ..geometry.quadrature import QuadraturePoints, cell_quadrature, facet_quadrature
from ..geometry.smoothing import STABILISATION, smoothing_rule
from ..geometry.stress_points import stress_point_quadrature
from ..parallel import Layout, raise_on_all_ranks
from ..physics import axisymmetry
from ..physics.axisymmetry import revolved_if
from ..physics.body_loads import StressRule, body_load_vectors
from ..physics.operators import load_vector
from ..physics.user_functions import vector_values
from ..statics.efg import check_multiplier_facets, crack_rules, facet_multipliers
from ..statics.kept_factor import KeptFactorisation
from ..statics.petsc import BlockSystem, SolverOptions, create_aij, create_vector
from .base import fe_dof_layout, node_flags
from .point_conditions import PinRows, pin_rows

if TYPE_CHECKING:  # annotations only
    import scipy.sparse as sp
    import ufl

    from ..approx.tables import ShapeTable
    from ..statics.coupled import CoupledElasticity

__all__ = [
    "append_patch_conditions",
    "body_loads",
    "component_conditions",
    "essential_conditions",
    "fe_active",
    "fe_facet_loads",
    "fe_stiffness",
    "fix_fe_rows",
    "fixed_dofs",
    "particle_rule",
    "patch_facet_rule",
    "patch_rules",
    "primal_nodes",
    "sizes",
    "solve_and_gather",
    "split_facets",
    "traction_loads",
]


def split_facets(problem: CoupledElasticity, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exterior facets beside FE cells and beside patch cells."""
    msh = problem.patch.mesh
    f2c = msh.topology.connectivity(msh.topology.dim - 1, msh.topology.dim)
    first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
    in_patch = problem.patch.in_patch[first]
    return facets[~in_patch], facets[in_patch]


def fe_stiffness(problem: CoupledElasticity, weight: ufl.core.expr.Expr | None = None) -> PETSc.Mat:
    """DOLFINx assembly of :meth:`fe_form` with ``weight`` (default: 1 on the FE cells, 0 on
    the patch)."""
    if weight is None:
        weight = problem.cell_indicator(~problem.patch.in_patch)
    return _compat.assemble_matrix(_compat.create_form(problem.fe_form(weight)))


def fe_active(problem: CoupledElasticity, cells: np.ndarray | None = None) -> np.ndarray:
    """Flag of every local FE node of the given owned cells (default: the FE cells)."""
    cells = problem.patch.fe_cells if cells is None else cells
    return node_flags(problem.V, _compat.dofmap_array(problem.V)[cells].ravel())


def particle_rule(problem: CoupledElasticity, integration: str) -> QuadraturePoints | None:
    """The stress-point rule of the patch, or ``None`` for the cells' Gauss rule."""
    if integration == "cells":
        return None
    return stress_point_quadrature(problem.patch.particles)


def patch_rules(
    problem: CoupledElasticity, integration: str = "cells", facet_degree: int | None = None
) -> tuple[QuadraturePoints | None, QuadraturePoints | None]:
    """The particle cell rule and VCI boundary rule of the patch (collective): with cracks in
    the patch, cut cells integrated side by side and the crack faces in the boundary set
    (:func:`~dolfinx_meshfree.statics.efg.crack_rules`; cells only, a ValueError on every rank
    for stress points); with a smoothed ``problem.integration`` and ``integration="cells"``,
    the :func:`~dolfinx_meshfree.geometry.smoothing.smoothing_rule` of the patch cells
    (``facet_degree``: that of the loads' facet rule, default the quadrature degree; explicit
    dynamics gives :data:`~dolfinx_meshfree.geometry.quadrature.DYNAMIC_FACET_DEGREE`) and
    ``None``; otherwise :func:`particle_rule` and ``None`` (the facet rule of
    ``patch.boundary()``)."""
    patch = problem.patch
    if not patch.cracks and patch.quadrature is None:
        smoothed = getattr(problem, "integration", "vci") in STABILISATION
        if smoothed and integration == "cells":
            beta = STABILISATION[problem.integration]
            msh, deg = patch.mesh, problem.quadrature_degree
            return raise_on_all_ranks(
                patch.comm,
                lambda: smoothing_rule(msh, patch.particles.cells, deg, beta, facet_degree),
            ), None
        return particle_rule(problem, integration), None

    def check() -> None:
        if integration != "cells":
            raise ValueError(
                f"integration={integration!r}: a cracked patch (or one with an "
                "AdaptiveQuadrature) is integrated on its cells; use integration='cells'"
            )

    raise_on_all_ranks(patch.comm, check)
    boundary = patch.boundary() if problem.consistent else None
    return crack_rules(
        patch.mesh, patch.particles.cells, patch.cracks, problem.quadrature_degree, boundary,
        quadrature=patch.quadrature,
    )  # fmt: skip


def patch_facet_rule(problem: CoupledElasticity, facets: np.ndarray) -> QuadraturePoints:
    """The rule of patch facets for loads and conditions (local): split where a crack of the
    patch meets them (its mouth on the exterior boundary), so that each side of the mouth is
    integrated on its own, as in pure EFG
    (:func:`~dolfinx_meshfree.geometry.cut_cells.cut_facet_quadrature`; the VCI boundary rule
    of a cracked patch splits them too); without cracks, the plain facet rule."""
    msh, deg, cracks = problem.V.mesh, problem.quadrature_degree, problem.patch.cracks
    if cracks:
        return cut_facet_quadrature(msh, facets, cracks, deg)
    return facet_quadrature(msh, facets, deg)


def body_loads(
    problem: CoupledElasticity,
    fe_weight: ufl.core.expr.Expr,
    particle_weights: Callable[[QuadraturePoints], np.ndarray] | None = None,
    interface_rule: tuple[QuadraturePoints, sp.csr_matrix] | None = None,
    tables: dict | None = None,
    interface_stress: StressRule | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """This coupling's shares of its body forces (collective): the FE loads per owned dof
    (``fe_weight``: the FE energy's weight) and the particle loads (original interleaved
    order) on the patch cells' Gauss rule (cut cells of a cracked patch: side by side, as the
    stiffness), its weights multiplied by ``particle_weights(q)``
    if given (the bridging band's ``alpha``); see
    :func:`~dolfinx_meshfree.physics.body_loads.body_load_vectors`. A load with a stress part
    is integrated on the particles with the stiffness's rule and test gradients in ``tables``
    (what :func:`~dolfinx_meshfree.statics.efg.particle_stiffness` fills, with the bridging
    band's ``"weights"``) and on a ramp's interface cells with ``interface_stress``."""
    msh, comm, deg = problem.V.mesh, problem.patch.comm, problem.quadrature_degree
    cells, cracks = problem.patch.particles.cells, problem.patch.cracks
    # cells a crack cuts: each side on its own (the rule of the stiffness, crack_rules)
    adaptive = problem.patch.quadrature
    q = crack_rules(msh, cells, cracks, deg, None, quadrature=adaptive)[0]
    q = cell_quadrature(msh, deg, cells) if q is None else q
    q = raise_on_all_ranks(comm, lambda: revolved_if(q, problem.material))
    if problem.material.axisymmetric:  # the FE cells' loads on the revolved volume too
        fe_weight = fe_weight * axisymmetry.measure(msh)
    if particle_weights is not None:
        q = QuadraturePoints(q.points, q.weights * particle_weights(q), q.cells)
    table = raise_on_all_ranks(comm, lambda: problem.mls.tabulate(q.points, 0)).values
    stress = None
    if tables is not None and "test_gradients" in tables:
        qs = tables["quadrature"]
        stress = StressRule(qs, tables.get("weights", qs.weights), tables["test_gradients"])
    return body_load_vectors(
        problem.body_forces, problem.V, fe_weight, deg, (q, table), interface_rule, comm,
        stress, interface_stress,
    )  # fmt: skip


def essential_conditions(
    problem: CoupledElasticity,
    also_strong: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple:
    """Split the essential conditions: strong on FE facets, multipliers on patch facets.

    Args:
        also_strong: Optional ``also_strong(patch_facets) -> facets`` naming patch facets whose
            FE nodes are fixed strongly as well (the bridging band, where FE also lives).

    Returns:
        ``(fe_bc, patch_bc, quadratures, tables, ubc, is_bc)``: the ``(facets, value)`` pairs
        on FE facets (strong) and on patch facets (then the held points of
        ``problem.point_dirichlet``, with no facets and a one-point rule each), the patch
        facets' quadratures and particle tables (for
        :func:`~dolfinx_meshfree.statics.efg.facet_multipliers`), the FE values as a Function
        and the flag of every local FE node fixed strongly (collective).
    """
    V, comm = problem.V, problem.patch.comm
    msh = V.mesh
    if problem.material.axisymmetric:  # the particles need the axis held
        groups = [(f, comps[0] if comps else None) for f, _, *comps in problem.dirichlet]
        axisymmetry.check_axis_held(msh, groups, problem.patch.in_patch, "CoupledElasticity")
    fe_bc, patch_bc = [], []
    for facets, fn, *components in problem.dirichlet:  # components: patch facets only
        f_fe, f_p = split_facets(problem, facets)
        if also_strong is not None:
            strong = also_strong(f_p)
            if components and _held_by_node(problem, strong, components[0]):
                strong = strong[:0]  # the FE dofs are held by component already
            if components and comm.allreduce(strong.size):
                raise ValueError(  # the same on every rank (a reduced count)
                    f"components={tuple(components[0])} on {comm.allreduce(strong.size)} patch "
                    "facet(s) where FE nodes are fixed strongly too (the bridging band): those "
                    "fix all components; choose facets of the patch outside the band"
                )
            f_fe = np.concatenate([f_fe, strong])
        fe_bc.append((f_fe, fn))
        patch_bc.append((f_p, fn, *components))
    dq = [patch_facet_rule(problem, c[0]) for c in patch_bc]
    # multipliers = reaction tractions (axisymmetric: 2 pi r ds, the axis kept)
    dq = [raise_on_all_ranks(comm, lambda d=d: revolved_if(d, problem.material, True)) for d in dq]
    # nodes of patch cells held alone (point_conditions): collocated multipliers
    for pc in problem.point_dirichlet:
        patch_bc.append((np.zeros(0, dtype=np.int32), pc.value, pc.components))
        dq.append(pc.rule())
    dtabs = [raise_on_all_ranks(comm, lambda d=d: problem.mls.tabulate(d.points, 0)) for d in dq]
    gdim = msh.geometry.dim
    ubc = dolfinx.fem.Function(V)
    ubc.x.array[:] = 0.0
    is_bc = np.zeros(ubc.x.array.size // gdim, dtype=bool)
    coords = V.tabulate_dof_coordinates()[:, :gdim]
    for f, fn in fe_bc:
        flags = node_flags(
            problem.V, dolfinx.fem.locate_dofs_topological(V, msh.topology.dim - 1, f)
        )
        xn = coords[flags]
        vals = raise_on_all_ranks(
            comm,
            lambda fn=fn, xn=xn: vector_values(fn, (xn,), len(xn), "the Dirichlet value", gdim),
        )
        ubc.x.array.reshape(-1, gdim)[flags] = vals
        is_bc |= flags
    for flags, vals in problem.strong:  # by node or, (n, gdim) flags, by dof
        ubc.x.array.reshape(-1, gdim)[flags] = vals[flags]
        if flags.ndim == 1:
            is_bc |= flags
    return fe_bc, patch_bc, dq, dtabs, ubc, is_bc


def component_conditions(problem: CoupledElasticity) -> tuple[np.ndarray, np.ndarray]:
    """The FE dofs held by component (``problem.strong`` entries with (n, gdim) flags, set by
    :class:`~dolfinx_meshfree.CoupledLinearProblem` for ``DirichletBC``s on ``V.sub(i)``):
    flags and values, (num local nodes, gdim) each (local)."""
    gdim = problem.V.mesh.geometry.dim
    n = problem.V.dofmap.index_map.size_local + problem.V.dofmap.index_map.num_ghosts
    flags, values = np.zeros((n, gdim), dtype=bool), np.zeros((n, gdim))
    for f, vals in getattr(problem, "strong", []):
        if f.ndim == 2:
            flags |= f
            values[f] = vals[f]
    return flags, values


def fixed_dofs(problem: CoupledElasticity, is_bc: np.ndarray) -> np.ndarray:
    """Flags (num local nodes, gdim) of every FE dof fixed strongly: the nodes ``is_bc`` and
    the dofs held by component (:func:`component_conditions`)."""
    return is_bc[:, None] | component_conditions(problem)[0]


def strong_values(
    problem: CoupledElasticity, is_bc: np.ndarray, ubc: dolfinx.fem.Function
) -> tuple[np.ndarray, np.ndarray]:
    """Every FE dof held strongly and its value, (num local nodes, gdim) each: the nodes fixed
    whole (``is_bc``, their values in ``ubc``) and the components held
    (:func:`component_conditions`); the values 0 elsewhere. What the blocks a coupling adds to
    the FE rows beside ``K_FE`` (the bridging penalty, the ramps' blended cells) must drop as
    rows and lift as columns: with whole nodes only, a roller's row stayed in them."""
    flags, cvals = fixed_dofs(problem, is_bc), component_conditions(problem)[1]
    gdim = flags.shape[1]
    values = np.where(is_bc[:, None], ubc.x.array.reshape(-1, gdim), np.where(flags, cvals, 0.0))
    return flags, values


def _held_by_node(problem: CoupledElasticity, facets: np.ndarray, components) -> bool:
    """Whether the FE nodes of ``facets`` hold ``components`` by dof already (collective)."""
    V = problem.V
    flags = node_flags(V, dolfinx.fem.locate_dofs_topological(V, V.mesh.topology.dim - 1, facets))
    held = component_conditions(problem)[0][flags][:, list(components)].all()
    return bool(problem.patch.comm.allreduce(int(held), op=MPI.MIN))


def fix_fe_rows(
    problem: CoupledElasticity,
    K_fe: PETSc.Mat,
    b_fe: PETSc.Vec,
    fixed_local: np.ndarray,
    values: np.ndarray,
) -> PETSc.Vec:
    """Fix FE dofs: zero their rows and columns of ``K_fe`` with 1 on the diagonal and lift the
    values into ``b_fe`` (``MatZeroRowsColumns``). Collective.

    Args:
        fixed_local: bool per local node (owned and ghost) to fix.
        values: (num local nodes, gdim) values of the fixed nodes (others ignored).

    Returns:
        The PETSc vector of fixed values (the caller destroys it).
    """
    fe_layout, l2g = fe_dof_layout(problem.V)
    n_owned = problem.V.dofmap.index_map.size_local
    bs = problem.V.dofmap.index_map_bs
    fixed = np.flatnonzero(fixed_local[:n_owned])
    rows = (bs * l2g[fixed][:, None] + np.arange(bs)).ravel().astype(PETSc.IntType)
    vals = np.asarray(values).reshape(-1, bs)[fixed].ravel()
    # dofs held by component (DirichletBCs on V.sub(i)) on nodes not fixed whole
    flags, cvals = component_conditions(problem)
    flags = flags[:n_owned] & ~np.asarray(fixed_local[:n_owned], dtype=bool)[:, None]
    node, comp = np.nonzero(flags)
    rows = np.concatenate([rows, bs * l2g[node] + comp]).astype(PETSc.IntType)
    vals = np.concatenate([vals, cvals[node, comp]])
    x_bc = create_vector(problem.patch.comm, fe_layout, rows, vals)
    # rows of dofs that no FE cell supports are empty, diagonal included: add it
    K_fe.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    zero = K_fe.createVecLeft()
    zero.set(0.0)
    K_fe.setDiagonal(zero, addv=PETSc.InsertMode.ADD_VALUES)
    zero.destroy()
    K_fe.zeroRowsColumns(rows, diag=1.0, x=x_bc, b=b_fe)
    return x_bc


def fe_facet_loads(
    V: dolfinx.fem.FunctionSpace,
    facets: np.ndarray,
    traction: Callable,
    degree: int,
    material: object,
    comm: MPI.Comm,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The FE loads of ``traction(x, n)`` on owned ``facets`` (the rule of ``degree``, revolved
    when ``material`` is axisymmetric): global dof rows and values per component, this rank's
    contributions (collective: the traction is checked on every rank)."""
    msh = V.mesh
    gdim = msh.geometry.dim
    l2g = fe_dof_layout(V)[1]
    q = revolved_if(facet_quadrature(msh, facets, degree), material)
    t = raise_on_all_ranks(
        comm, lambda: vector_values(traction, (q.points, q.normals), len(q), "traction", gdim)
    )
    tab = tabulate_in_cells(V, q.points, q.cells, derivatives=0).values
    fl = load_vector(tab, q.weights, t).reshape(-1, gdim)
    rows = [gdim * l2g[: fl.shape[0]] + comp for comp in range(gdim)]
    return rows, [fl[:, comp] for comp in range(gdim)]


def traction_loads(
    problem: CoupledElasticity, tables: dict | None = None
) -> tuple[PETSc.Vec, np.ndarray]:
    """Tractions on FE facets (FE load vector, PETSc) and on patch facets (particle loads in
    original particle order, local contributions), plus the body forces (FE cells with
    ``N_a``, patch cells with ``phi_J``; a stress part with the particle stiffness's
    ``tables``, :func:`body_loads`). Collective."""
    V, comm = problem.V, problem.patch.comm
    msh, deg = V.mesh, problem.quadrature_degree
    fe_layout = fe_dof_layout(problem.V)[0]
    gdim = msh.geometry.dim
    f_fe_rows, f_fe_vals = [np.zeros(0, np.int64)], [np.zeros(0)]
    f_p = np.zeros(gdim * problem.patch.particles.num_particles)
    for facets, fn in problem.tractions:
        f_fe_facets, f_p_facets = split_facets(problem, facets)
        rows, vals = fe_facet_loads(V, f_fe_facets, fn, deg, problem.material, comm)
        f_fe_rows += rows
        f_fe_vals += vals
        q = revolved_if(patch_facet_rule(problem, f_p_facets), problem.material)
        t = raise_on_all_ranks(
            comm,
            lambda fn=fn, q=q: vector_values(fn, (q.points, q.normals), len(q), "traction", gdim),
        )
        tab = raise_on_all_ranks(comm, lambda q=q: problem.mls.tabulate(q.points, 0)).values
        f_p += load_vector(tab, q.weights, t)
    b_fe = create_vector(comm, fe_layout, np.concatenate(f_fe_rows), np.concatenate(f_fe_vals))
    if problem.body_forces:  # FE cells with N_a, patch cells with phi_J
        fe, fp = body_loads(problem, problem.cell_indicator(~problem.patch.in_patch), tables=tables)
        b_fe.array[:] += fe
        f_p += fp
    return b_fe, f_p


def append_patch_conditions(
    problem: CoupledElasticity,
    blocks: list[list[PETSc.Mat | None]],
    rhs: list[PETSc.Vec],
    mats: list[PETSc.Mat],
    patch_bc: list,
    dq: list[QuadraturePoints],
    dtabs: list[ShapeTable],
) -> tuple[Layout, PinRows, int | None]:
    """Append the multiplier field of essential conditions on patch facets and points (it
    couples to field 1, the particles) to ``blocks``/``rhs``; new PETSc objects go to ``mats``.
    Returns its layout, where its pins' multipliers lie (:class:`PinRows`) and its index among
    the multiplier fields (``None``: no field, nothing held on the patch)."""
    P, comm = problem.patch.particles, problem.patch.comm
    pl = P.dof_layout(P.gdim)
    check_multiplier_facets(P, dq, "Dirichlet conditions on the patch's exterior facets")
    Gd, d_rows, d_vals, dl = facet_multipliers(P, patch_bc, dq, dtabs, problem.material.E)
    pins = pin_rows(patch_bc, dq, dtabs, problem.material.E, P.gdim)
    if dl.size_global:
        D = create_aij(comm, Gd, dl, pl)
        DT = create_aij(comm, Gd.T.tocsr(), pl, dl)
        for row in blocks:
            row.append(None)
        blocks[1][-1] = DT
        blocks.append([None, D] + [None] * (len(blocks) - 1))
        rhs.append(create_vector(comm, dl, d_rows, d_vals))
        mats += [D, DT]
    return dl, pins, (len(blocks) - 3 if dl.size_global else None)


def primal_nodes(problem: CoupledElasticity) -> list[np.ndarray]:
    """The positions of this rank's owned FE nodes and particles in the order of their PETSc
    dofs: the rigid-body modes of ``solver="iterative"`` (:class:`BlockSystem`)."""
    V, P = problem.V, problem.patch.particles
    gdim = V.mesh.geometry.dim
    fe = V.tabulate_dof_coordinates()[: V.dofmap.index_map.size_local, :gdim]
    return [fe, P.owned_positions()[:, :gdim]]


def solve_and_gather(
    problem: CoupledElasticity,
    blocks: list[list[PETSc.Mat | None]],
    rhs: list[PETSc.Vec],
    objects: list,
    solver: str | SolverOptions,
    kept: KeptFactorisation | None = None,
) -> tuple[dolfinx.fem.Function, np.ndarray, float, list[np.ndarray]]:
    """Solve the nest (fields FE, particles, multipliers...; a direct solve on ``kept``'s
    factorisation where it serves, :func:`~dolfinx_meshfree.statics.petsc.solve_lu`), destroy
    ``objects`` and ``rhs``, and return the FE Function, the particle coefficients (n, gdim) in
    original order, the solve time and the owned values of each multiplier field.
    Collective."""
    V, P, comm = problem.V, problem.patch.particles, problem.patch.comm
    bs = V.dofmap.index_map_bs
    names = ["fe", "particles"] + [f"multiplier{i}" for i in range(len(blocks) - 2)]
    system = BlockSystem(blocks, rhs, num_primal=2, names=names, coordinates=primal_nodes(problem))
    t0 = time.perf_counter()
    parts = system.solve(solver, kept=kept)
    seconds = time.perf_counter() - t0
    system.destroy()
    for obj in [*objects, *rhs]:
        obj.destroy()
    uh = dolfinx.fem.Function(V)
    uh.x.array[: bs * V.dofmap.index_map.size_local] = parts[0]
    uh.x.scatter_forward()
    owned = np.concatenate(comm.allgather(parts[1]))
    return uh, owned.reshape(-1, bs)[P.petsc_index], seconds, list(parts[2:])


def pin_forces(extra: dict, multipliers: list[np.ndarray]) -> list[np.ndarray]:
    """The forces of a solved system's pins (:attr:`CoupledSolution.point_forces`) from the
    multipliers :func:`solve_and_gather` returned and the ``extra["pins"]`` that the system
    kept from :func:`append_patch_conditions` (local)."""
    pins, field = extra["pins"]
    if field is None:  # nothing held on the patch: no pins either
        return [np.zeros((0, pins.gdim)) for _ in pins.rows]
    return pins.forces(multipliers[field])


def sizes(problem: CoupledElasticity, active: np.ndarray, multiplier_dofs: int) -> dict:
    """The system's sizes for :attr:`CoupledSolution.sizes`: active FE dofs (from the flags
    of the local nodes), particle dofs and multiplier dofs (collective)."""
    n_owned = problem.V.dofmap.index_map.size_local
    bs = problem.V.dofmap.index_map_bs
    return {
        "fe_dofs": bs * problem.patch.comm.allreduce(int(np.sum(active[:n_owned]))),
        "particle_dofs": bs * problem.patch.particles.num_particles,
        "multiplier_dofs": multiplier_dofs,
    }
