"""The structure of explicit dynamics: the semi-discrete system behind ExplicitDynamics and the
import graph of the dynamics subpackage (no cycles, no deferred imports); serial and 2 ranks."""

from __future__ import annotations

import ast
import pathlib

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import ExplicitDynamics, LinearSystem, SemiDiscreteSystem

import numpy as np
import pytest
from conftest import CELL_TYPES, rectangle
from mpi4py import MPI

PACKAGE = pathlib.Path(mf.__file__).resolve().parent
MAT = mf.LinearElastic(1.0, 0.3, "strain", rho=1.0)
METHODS = [
    "fe",
    "efg",
    "lagrange",
    "edge-to-edge",
    "ramp",
    "ramp-cubic",
    "bridging",
    "master-slave",
]


def build(method: str) -> ExplicitDynamics:
    """A 4 x 2 block, h = 0.5; particles (spacing h / 2) on x > 2."""
    comm = MPI.COMM_WORLD
    msh = rectangle(comm, [0.0, 0.0], [4.0, 2.0], [8, 4], CELL_TYPES["quadrilateral"])
    V = _compat.vector_function_space(msh)
    if method == "fe":
        return ExplicitDynamics.fe(V, MAT)
    if method == "efg":
        return ExplicitDynamics.efg(mf.ParticleSet.from_cells(msh, 0.25), MAT, quadrature_degree=3)
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 2.0), 0.25)
    options = {"overlap": 1} if method == "bridging" else {}
    if method.startswith("ramp"):
        options["dilation"] = 2.5
    problem = mf.CoupledElasticity(V, patch, MAT, coupling=method, quadrature_degree=3, **options)
    return ExplicitDynamics.coupled(problem)


# --- the system -----------------------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_strain_energy_of_a_homogeneous_strain(method):
    """u = (a x + c y, b y + c x): every method reproduces the linear field, so the system's
    strain energy 1/2 u^T f_int(u) equals the exact 1/2 int eps : C : eps = 1/2 (lambda
    (tr eps)^2 + 2 mu eps : eps) |Omega| to round-off (plane strain, |Omega| = 8), and a rigid
    motion has no internal force."""
    a, b, c = 1e-3, -4e-4, 2.5e-4
    dyn = build(method)
    system = dyn.system
    assert isinstance(system, SemiDiscreteSystem) and isinstance(system, LinearSystem)
    dyn.set_initial(displacement=lambda x: np.stack([a * x[:, 0] + c * x[:, 1],
                                                     b * x[:, 1] + c * x[:, 0]], 1))  # fmt: skip
    f = system.internal_force(dyn.u)
    lam = MAT.E * MAT.nu / ((1 + MAT.nu) * (1 - 2 * MAT.nu))
    mu = MAT.E / (2 * (1 + MAT.nu))
    exact = 0.5 * (lam * (a + b) ** 2 + 2 * mu * (a**2 + b**2 + 2 * c**2)) * 8.0
    assert system.strain_energy(dyn.u, f) == pytest.approx(exact, rel=1e-10)
    dyn.set_initial(displacement=lambda x: np.tile([0.3, -0.2], (len(x), 1)))
    system.internal_force(dyn.u, f)
    scale = max(g.norm() for g in system.tangent().values()) * 0.3
    assert max(g.norm() for g in f) <= 1e-12 * scale
    for g in f:
        g.destroy()
    dyn.destroy()


def test_linear_system_rebuild():
    """A linear system has nothing to rebuild when nothing changed, and refuses to follow a
    changed approximation (its blocks are assembled)."""
    dyn = build("lagrange")
    assert dyn.system.rebuild(()) is False
    with pytest.raises(NotImplementedError, match="changed=\\['approximation'\\]"):
        dyn.system.rebuild({"approximation"})
    assert dyn.system.constraints() is dyn.G and dyn.G is not None
    dyn.destroy()


# --- the import graph -----------------------------------------------------------------------------


def _module(path: pathlib.Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(node: ast.AST, in_function: bool = False):
    """``(import node, inside a function)`` of a tree, ``TYPE_CHECKING`` blocks skipped."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
            continue
        func = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
        if isinstance(child, ast.Import | ast.ImportFrom):
            yield child, func
        yield from _imports(child, func)


def _targets(node: ast.Import | ast.ImportFrom, package: str, modules: set[str]) -> list[str]:
    """The modules an import loads: ``from pkg import submodule`` the submodule, ``from mod
    import name`` the module."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    parts = package.split(".")
    base = ".".join(parts[: len(parts) - node.level + 1]) if node.level else ""
    target = ".".join(p for p in (base, node.module or "") if p)
    subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in modules]
    return subs or [target]


def _import_graph() -> tuple[dict[str, set[str]], list[tuple[str, int, str]]]:
    """Module-level imports between package modules (a module's own parent packages are loaded
    before it: not an edge) and the imports of package modules inside functions."""
    paths = {_module(p): p for p in PACKAGE.rglob("*.py")}
    edges: dict[str, set[str]] = {m: set() for m in paths}
    deferred: list[tuple[str, int, str]] = []
    for mod, path in paths.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        parents = {".".join(mod.split(".")[:i]) for i in range(1, mod.count(".") + 1)}
        for node, func in _imports(ast.parse(path.read_text())):
            for t in _targets(node, package, set(paths)):
                if t not in paths or t == mod or t in parents:
                    continue
                if func:
                    deferred.append((mod, node.lineno, t))
                else:
                    edges[mod].add(t)
    return edges, deferred


def _cycles(edges: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[set[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges[v]:
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    for v in edges:
        if v not in index:
            connect(v)
    return out


def test_dynamics_has_no_import_cycle_and_no_deferred_import():
    """No module of dolfinx_meshfree.dynamics is on an import cycle, counting the imports
    deferred into functions as edges too, and none defers an import of a package module."""
    edges, deferred = _import_graph()
    assert any(m.startswith("dolfinx_meshfree.dynamics.") for m in edges)  # the graph is read
    assert "dolfinx_meshfree.statics.coupled" in edges["dolfinx_meshfree.dynamics.methods"]
    ours = [d for d in deferred if d[0].startswith("dolfinx_meshfree.dynamics")]
    assert not ours, ours
    full = {m: set(t) for m, t in edges.items()}
    for mod, _, target in deferred:
        full[mod].add(target)
    through = [
        c for c in _cycles(full) if any(m.startswith("dolfinx_meshfree.dynamics") for m in c)
    ]
    assert not through, through
