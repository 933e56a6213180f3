"""The only module that knows DOLFINx versions.

Two lanes are supported (see ``README.md``):

* lane A: Debian 12's DOLFINx 0.5.2 with PETSc 3.18 and OpenMPI;
* lane B: current DOLFINx (0.10/0.11) from the ``dolfinx-solver-real`` wheel, which must be imported
  before ``dolfinx``, ``petsc4py`` or ``mpi4py`` so that its bundled MPICH is loaded.

Every call whose spelling differs between the lanes lives here, behind one explicit version check
(:data:`MODERN`). Nothing else in the package inspects versions.
"""

from __future__ import annotations

import importlib.util as _importlib_util

if _importlib_util.find_spec("dolfinx_solver") is not None:  # lane B: load bundled MPICH first
    import dolfinx_solver as _dolfinx_solver  # noqa: F401

import typing as _typing

import basix as _basix
import dolfinx as _dolfinx
import dolfinx.fem as _fem
import dolfinx.fem.petsc as _fem_petsc
import dolfinx.geometry as _geometry
import dolfinx.graph as _graph
import dolfinx.mesh as _mesh
import numpy as _np
from ufl.algorithms import estimate_total_polynomial_degree as _estimate_degree
from ufl.algorithms import expand_derivatives as _expand_derivatives

from . import mesh_cache as _mesh_cache

if _typing.TYPE_CHECKING:  # annotations only; the class names are lane B's (0.5.2: *MetaClass)
    from dolfinx.fem import DirichletBC as _DirichletBC
    from dolfinx.fem import Form as _Form
    from petsc4py import PETSc as _PETSc
    from ufl import Form as _UFLForm
    from ufl.core.expr import Expr as _Expr

__all__ = [
    "DOLFINX_VERSION",
    "MODERN",
    "apply_lifting",
    "assemble_matrix",
    "assemble_matrix_into",
    "assemble_vector",
    "basix_lagrange_p1",
    "bb_tree",
    "colliding_cells",
    "coordinate_degree",
    "create_expression",
    "create_form",
    "create_mesh_ghosted",
    "create_mesh_partitioned",
    "dirichlet_values",
    "dofmap_array",
    "entities_to_geometry",
    "eval_expression",
    "function_petsc_vec",
    "geometry_dofmap",
    "quadrature_rule",
    "quadrature_space",
    "refine",
    "scalar_function_space",
    "scatter_reverse_add",
    "set_bc",
    "vector_function_space",
]

DOLFINX_VERSION: str = _dolfinx.__version__
_major_minor = tuple(int(p) for p in DOLFINX_VERSION.split(".")[:2])
#: True for DOLFINx >= 0.10 (lane B), False for 0.5.x (lane A).
MODERN: bool = _major_minor >= (0, 10)
if not MODERN and _major_minor[:2] != (0, 5):
    raise ImportError(
        f"dolfinx_meshfree supports DOLFINx 0.5.x (Debian 12) and >= 0.10; found {DOLFINX_VERSION}"
    )


def vector_function_space(msh: _mesh.Mesh, degree: int = 1) -> _fem.FunctionSpace:
    """Continuous Lagrange vector space of the given degree with ``gdim`` components."""
    gdim = msh.geometry.dim
    if MODERN:
        return _fem.functionspace(msh, ("Lagrange", degree, (gdim,)))
    return _fem.VectorFunctionSpace(msh, ("Lagrange", degree))


def scalar_function_space(msh: _mesh.Mesh, family: str, degree: int) -> _fem.FunctionSpace:
    """Scalar function space of the given family and degree."""
    if MODERN:
        return _fem.functionspace(msh, (family, degree))
    return _fem.FunctionSpace(msh, (family, degree))


def coordinate_degree(msh: _mesh.Mesh) -> int:
    """The degree of the mesh's coordinate element (1: straight-sided cells); DOLFINx >= 0.10
    keeps one coordinate map per cell type (``cmaps``), 0.5 one (``cmap``)."""
    geometry = msh.geometry
    cmap = geometry.cmaps[0] if hasattr(geometry, "cmaps") else geometry.cmap
    return int(cmap.degree)


def geometry_dofmap(msh: _mesh.Mesh) -> _np.ndarray:
    """Geometry node indices of every local cell, shape (num_cells, num_nodes_per_cell)."""
    if MODERN:
        return _np.asarray(
            msh.geometry.dofmaps(0) if callable(msh.geometry.dofmaps) else msh.geometry.dofmaps[0]
        )
    dm = msh.geometry.dofmap
    nc = msh.topology.index_map(msh.topology.dim).size_local + len(
        msh.topology.index_map(msh.topology.dim).ghosts
    )
    return dm.array.reshape(nc, -1)


def dofmap_array(V: _fem.FunctionSpace) -> _np.ndarray:
    """Block (node) indices of every local cell of ``V``, shape (num_cells, num_nodes_per_cell)."""
    if MODERN:
        return _np.asarray(V.dofmap.list)
    nd = V.dofmap.dof_layout.num_dofs
    return V.dofmap.list.array.reshape(-1, nd)


def basix_lagrange_p1(cell_name: str) -> _basix.finite_element.FiniteElement:
    """The degree-1 Lagrange basix element on ``cell_name`` ("triangle", "quadrilateral", ...)."""
    cell = getattr(_basix.CellType, cell_name)
    return _basix.create_element(_basix.ElementFamily.P, cell, 1, _basix.LagrangeVariant.equispaced)


def quadrature_rule(cell_name: str, degree: int) -> tuple[_np.ndarray, _np.ndarray]:
    """A basix quadrature rule of ``degree`` on the reference cell with positive weights.

    Basix's default rule (Gauss–Jacobi on quadrilaterals and hexahedra, Xiao–Gimbutas on
    simplices) unless it has a negative weight (tetrahedra at degrees 3, 7 and 8: -0.8, -0.38
    and -0.24 of the volume), then the Gauss–Jacobi (collapsed Gauss) rule of the same degree: a
    negative weight makes the particle stiffness indefinite (EFG on tetrahedra at degree 3:
    smallest eigenvalue -0.077 of the largest's 0.51, and explicit dynamics blows up).
    """
    cell = getattr(_basix.CellType, cell_name)
    pts, wts = _basix.make_quadrature(cell, degree)
    if _np.any(_np.asarray(wts) < 0.0):
        gj = _basix.QuadratureType.gauss_jacobi
        if MODERN:
            pts, wts = _basix.make_quadrature(cell, degree, rule=gj)
        else:
            pts, wts = _basix.make_quadrature(gj, cell, degree)
    return _np.asarray(pts, dtype=float), _np.asarray(wts, dtype=float)


def quadrature_space(msh: _mesh.Mesh, degree: int, size: int) -> _fem.FunctionSpace:
    """A space of ``size`` values at each point of basix's default quadrature rule of ``degree``
    on every cell (a "Quadrature" element): one dof block of ``size`` per point, cell ``c``'s
    points in the order of :func:`quadrature_rule`'s default rule. Forms that use it must
    integrate with ``metadata={"quadrature_degree": degree, "quadrature_scheme": "default"}``."""
    if MODERN:
        import basix.ufl as _basix_ufl

        element = _basix_ufl.quadrature_element(
            msh.basix_cell(), value_shape=(size,), degree=degree
        )
        return _fem.functionspace(msh, element)
    import ufl as _ufl

    element = _ufl.VectorElement(
        "Quadrature", msh.ufl_cell(), degree=degree, dim=size, quad_scheme="default"
    )
    return _fem.FunctionSpace(msh, element)


def bb_tree(msh: _mesh.Mesh, dim: int) -> _geometry.BoundingBoxTree:
    """Bounding-box tree of the local entities of dimension ``dim``, built once per mesh and
    geometry (:func:`~dolfinx_meshfree.mesh_cache.cached`)."""

    def build() -> _geometry.BoundingBoxTree:
        return _geometry.bb_tree(msh, dim) if MODERN else _geometry.BoundingBoxTree(msh, dim)

    return _mesh_cache.cached(msh, ("bb_tree", dim), build)


def refine(msh: _mesh.Mesh) -> _mesh.Mesh:
    """Uniform refinement of a triangle mesh (every edge split), ghosted like the input."""
    msh.topology.create_entities(1)
    refined = _mesh.refine(msh)
    return refined[0] if isinstance(refined, tuple) else refined


def colliding_cells(
    msh: _mesh.Mesh, tree: _geometry.BoundingBoxTree, points3: _np.ndarray
) -> tuple[_np.ndarray, _np.ndarray]:
    """Local cells that contain each point, as CSR (offsets, cells); ``points3`` is (m, 3)."""
    if MODERN:
        cand = _geometry.compute_collisions_points(tree, points3)
    else:
        cand = _geometry.compute_collisions(tree, points3)
    adj = _geometry.compute_colliding_cells(msh, cand, points3)
    return _np.asarray(adj.offsets), _np.asarray(adj.array)


def entities_to_geometry(msh: _mesh.Mesh, dim: int, entities: _np.ndarray) -> _np.ndarray:
    """Geometry node indices of entities of dimension ``dim``, shape (num_entities, nodes)."""
    entities = _np.asarray(entities, dtype=_np.int32)
    if MODERN:
        return _np.asarray(_mesh.entities_to_geometry(msh, dim, entities, False))
    import dolfinx.cpp.mesh as _cppmesh

    # Debian's 0.5.2 Python Mesh wraps the C++ mesh in ``_mesh``
    cpp_mesh = getattr(msh, "_mesh", msh)
    return _np.asarray(_cppmesh.entities_to_geometry(cpp_mesh, dim, entities, False))


def create_mesh_partitioned(
    like: _mesh.Mesh,
    cells: _np.ndarray,
    x: _np.ndarray,
    destinations: _typing.Callable[[int], tuple[_np.ndarray, _np.ndarray]],
    ghosted: bool,
) -> _mesh.Mesh:
    """A mesh of ``like``'s cell type and coordinate element from ``cells`` (global node
    indices, (n, nodes)) and ``x`` ((num_nodes, gdim), in global node order), distributed by
    ``destinations(nparts) -> (offsets, ranks)``: per input cell (in the order of ``cells``)
    its owner rank followed by the ranks that ghost it (collective; every rank may pass a part
    of the cells, e.g. all on rank 0 and none elsewhere). ``ghosted``: whether the ranks include
    ghosts (facet neighbours; DOLFINx 0.5 needs the ghost mode to match)."""
    domain = like.ufl_domain()
    cells = _np.ascontiguousarray(cells, dtype=_np.int64)
    x = _np.ascontiguousarray(x, dtype=float)
    if MODERN:

        def partitioner(comm: object, nparts: int, cell_types: object, graphs: object) -> object:
            offsets, ranks = destinations(nparts)
            adj = _graph.adjacencylist(ranks.astype(_np.int32), offsets.astype(_np.int32))
            return getattr(adj, "_cpp_object", adj)

        return _mesh.create_mesh(like.comm, cells, domain, x, partitioner=partitioner)

    def partitioner_05(
        comm: object, nparts: int, tdim: int, graph: object, ghost_mode: object
    ) -> object:
        offsets, ranks = destinations(nparts)
        return _graph.create_adjacencylist(ranks.astype(_np.int32), offsets.astype(_np.int32))

    mode = _mesh.GhostMode.shared_facet if ghosted else _mesh.GhostMode.none
    return _mesh.create_mesh(like.comm, cells, x, domain, mode, partitioner_05)


def create_mesh_ghosted(like: _mesh.Mesh, cells: _np.ndarray, x: _np.ndarray) -> _mesh.Mesh:
    """A mesh of ``like``'s cell type and coordinate element from ``cells`` (global node
    indices, (n, nodes)) and ``x`` ((num_nodes, gdim), in global node order), partitioned by
    DOLFINx's default partitioner with ghost cells across facets (shared_facet), as
    ``create_rectangle`` makes them (collective; any rank may pass any part of the cells)."""
    domain = like.ufl_domain()
    cells = _np.ascontiguousarray(cells, dtype=_np.int64)
    x = _np.ascontiguousarray(x, dtype=float)
    if MODERN:
        partitioner = None
        if like.comm.size > 1:
            import dolfinx.cpp as _cpp

            partitioner = _cpp.mesh.create_cell_partitioner(_mesh.GhostMode.shared_facet, 2)
        return _mesh.create_mesh(like.comm, cells, domain, x, partitioner=partitioner)
    return _mesh.create_mesh(like.comm, cells, x, domain, _mesh.GhostMode.shared_facet)


#: The largest quadrature degree a form may reach by FFCx's estimate (no ``quadrature_degree``
#: in its measure's metadata): beyond it, FFCx asks for millions of points per cell.
MAX_ESTIMATED_DEGREE = 50


def check_quadrature_degree(form: _UFLForm) -> None:
    """Refuse a form whose integrand's estimated quadrature degree passes
    :data:`MAX_ESTIMATED_DEGREE` without a degree in its measure (FFCx would run out of memory
    building its tables: a law unrolled in UFL, e.g. plane-stress neo-Hookean's Newton on the
    thickness stretch, estimates 2048 for its residual and 8104 for its Jacobian)."""
    for itg in form.integrals():
        if "quadrature_degree" in (itg.metadata() or {}):
            continue
        degree = _estimate_degree(_expand_derivatives(itg.integrand()), default_degree=1)
        if degree > MAX_ESTIMATED_DEGREE:
            raise ValueError(
                f"a {itg.integral_type()} integral's integrand has an estimated quadrature degree "
                f"of {degree} (> {MAX_ESTIMATED_DEGREE}: millions of points per cell, e.g. a law "
                "unrolled in UFL such as NeoHookean(plane='stress').ufl_first_piola); give its "
                "measure a degree: ufl.Measure('dx', domain=mesh, metadata="
                "{'quadrature_degree': 4})"
            )


def create_form(form: _UFLForm, jit_options: dict | None = None) -> _Form:
    """JIT-compile a UFL form (collective), after :func:`check_quadrature_degree`."""
    check_quadrature_degree(form)
    if MODERN:
        return _fem.form(form, jit_options=jit_options)
    return _fem.form(form, jit_params=jit_options)


def assemble_matrix(
    a: _Form, bcs: _typing.Sequence[_DirichletBC] = (), diagonal: float = 1.0
) -> _PETSc.Mat:
    """Assemble a bilinear form into an assembled PETSc matrix with ``diagonal`` on bc rows."""
    if MODERN:
        A = _fem_petsc.assemble_matrix(a, bcs=list(bcs), diag=diagonal)
    else:
        A = _fem_petsc.assemble_matrix(a, bcs=list(bcs), diagonal=diagonal)
    A.assemble()
    return A


def assemble_matrix_into(A: _PETSc.Mat, a: _Form) -> None:
    """Zero ``A`` and assemble the bilinear form ``a`` into it (its nonzero pattern kept, and
    entries outside the form's pattern, e.g. an inserted diagonal, kept at zero)."""
    A.zeroEntries()
    _fem_petsc.assemble_matrix(A, a)
    A.assemble()


def assemble_vector(L: _Form) -> _PETSc.Vec:
    """Assemble a linear form into a new PETSc vector (ghosted, not yet accumulated)."""
    return _fem_petsc.assemble_vector(L)


def apply_lifting(b: _PETSc.Vec, a: _Form, bcs: _typing.Sequence[_DirichletBC]) -> None:
    """Lift the Dirichlet values of ``bcs`` through ``a`` into ``b`` (DOLFINx ``apply_lifting``)."""
    _fem_petsc.apply_lifting(b, [a], bcs=[list(bcs)])


def set_bc(
    b: _PETSc.Vec,
    bcs: _typing.Sequence[_DirichletBC],
    x0: _PETSc.Vec | None = None,
    scale: float = 1.0,
) -> None:
    """Set Dirichlet values in ``b`` (DOLFINx ``set_bc``)."""
    if MODERN:
        _fem_petsc.set_bc(b, list(bcs), x0, alpha=scale)
    else:
        _fem_petsc.set_bc(b, list(bcs), x0, scale=scale)


def scatter_reverse_add(u: _fem.Function) -> None:
    """Add the ghost values of ``u`` into their owners' values (then ``scatter_forward``)."""
    import dolfinx.la as _la

    if MODERN:
        u.x.scatter_reverse(_la.InsertMode.add)
    else:
        u.x.scatter_reverse(_la.ScatterMode.add)


def function_petsc_vec(u: _fem.Function) -> _PETSc.Vec:
    """The PETSc vector that wraps the owned and ghost values of ``u``."""
    return u.x.petsc_vec if MODERN else u.vector


def create_expression(
    expr: _Expr, points: _np.ndarray, msh: _mesh.Mesh | None = None
) -> _fem.Expression:
    """JIT-compile a UFL expression at reference points ``points`` (k, tdim) (collective).

    With ``msh`` the expression is tied to that mesh by a unit ``Constant`` factor: an expression
    that the form compiler folds to numbers (``-div sigma(u)`` of a quadratic ``u``, whose
    ``SpatialCoordinate`` vanishes when the derivatives are applied) otherwise compiles without a
    mesh, and DOLFINx >= 0.10 refuses to evaluate it ("Expression was created on a different
    mesh")."""
    if msh is not None:
        expr = expr * _fem.Constant(msh, _np.float64(1.0))
    return _fem.Expression(expr, _np.ascontiguousarray(points, dtype=_np.float64))


def eval_expression(
    expr: _fem.Expression, msh: _mesh.Mesh, cells: _np.ndarray, value_size: int
) -> _np.ndarray:
    """Values of a compiled expression on local ``cells``, shape (num_cells, k, value_size)."""
    cells = _np.ascontiguousarray(cells, dtype=_np.int32)
    if cells.size == 0:
        return _np.zeros((0, _np.asarray(expr.X()).shape[0], value_size))
    values = expr.eval(msh, cells) if MODERN else expr.eval(cells)
    return _np.asarray(values).reshape(cells.size, -1, value_size)


def dirichlet_values(bc: _DirichletBC) -> tuple[_np.ndarray, _np.ndarray]:
    """Local dofs (owned and ghost, unrolled by block) of a DirichletBC and its values there.

    The value is the bc's ``Function`` (read at those dofs of its own space) or ``Constant``
    (broadcast by component: dof ``d`` gets ``value[d % value_size]``).
    """
    dofs = _np.asarray(bc.dof_indices()[0], dtype=_np.int64)
    g = bc.g
    if hasattr(g, "x"):
        gx = _np.asarray(g.x.array)
        if list(bc.function_space.component()) and g.function_space is not bc.function_space:
            # bc on V.sub(i) with a Function on the collapsed subspace (the
            # locate_dofs_topological((V.sub(i), V0), ...) form): its values by V's dof
            _, collapse_map = bc.function_space.collapse()
            collapse_map = _np.asarray(collapse_map, dtype=_np.int64)
            if collapse_map.size != gx.size:
                raise ValueError(
                    "a DirichletBC on V.sub(i) has a value Function on a space that is not "
                    "V.sub(i).collapse()[0]; interpolate the value into that space"
                )
            by_dof = _np.zeros(int(collapse_map.max(initial=-1)) + 1)
            by_dof[collapse_map] = gx
            return dofs, by_dof[dofs]
        return dofs, gx[dofs]
    value = _np.atleast_1d(_np.asarray(g.value, dtype=float)).ravel()
    return dofs, value[dofs % value.size]
