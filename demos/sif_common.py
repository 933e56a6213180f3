"""Shared parts of the stress intensity factor demos (``sif_edge_crack.py``,
``sif_inclined_crack.py``): the crack placement off the particle rows, the model (pure EFG or a
particle patch around the crack in a user's UFL model, ``CoupledLinearProblem``), the table and
the JSON."""

from __future__ import annotations

import json
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

COMM = MPI.COMM_WORLD
#: Domain radii of the interaction integral in particle spacings (the solutions' default).
RADII = (3.0, 4.0, 5.0)


def grid_clearance(points: np.ndarray, origin: np.ndarray, h: float) -> float:
    """Smallest distance, in spacings, from the crack polyline ``points`` to the particle grid
    ``origin + h Z^2``."""
    lo, hi = points.min(axis=0) - h, points.max(axis=0) + h
    i = np.arange(np.floor((lo[0] - origin[0]) / h), np.ceil((hi[0] - origin[0]) / h) + 1)
    j = np.arange(np.floor((lo[1] - origin[1]) / h), np.ceil((hi[1] - origin[1]) / h) + 1)
    g = origin + h * np.stack(np.meshgrid(i, j), -1).reshape(-1, 2)
    a, b = points[:-1], points[1:]
    d = np.inf
    for k in range(len(a)):
        e = b[k] - a[k]
        xi = np.clip((g - a[k]) @ e / (e @ e), 0.0, 1.0)
        d = min(d, float(np.linalg.norm(g - a[k] - xi[:, None] * e, axis=1).min()))
    return d / h


def choose_shift(crack_points, origin: np.ndarray, h: float, clearance: float = 0.02) -> np.ndarray:
    """A shift of the crack (a fraction of ``h``) that keeps it at least ``clearance`` h off
    every particle (a particle on a crack has no side; a slanted crack of n spacings passes
    within about 0.5 / (2 n) h of some particle whatever the shift): the first of a fixed
    sequence of candidates that does, else the best of them."""
    best, best_d = np.zeros(2), -1.0
    for k in range(200):
        s = h * np.array([(0.137 * k) % 0.5, (0.291 * k + 0.02) % 0.5]) if k else np.zeros(2)
        d = grid_clearance(np.asarray(crack_points(s)), origin, h)
        if d >= clearance:
            return s
        if d > best_d:
            best, best_d = s, d
    return best


def owned_cells(msh, predicate) -> np.ndarray:
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    return np.flatnonzero(predicate(mid))


def coupled_forms(msh, material, tractions=()):
    """The user's model of the FE side: vector Q1/P1 space ``V``, ``a(u, v) = (sigma(u),
    eps(v))`` and ``L(v)`` = the constant ``tractions`` (``(facets, (tx, ty))``) on their facets.

    Returns ``(V, a, L)``."""
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(material.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    L = ufl.dot(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.dx
    if tractions:
        f_all = np.concatenate([f for f, _ in tractions])
        tag = np.concatenate(
            [np.full(f.size, k + 1, np.int32) for k, (f, _) in enumerate(tractions)]
        )
        order = np.argsort(f_all)
        mt = dolfinx.mesh.meshtags(msh, 1, f_all[order], tag[order])
        ds = ufl.Measure("ds", domain=msh, subdomain_data=mt)
        for k, (_, t) in enumerate(tractions):
            L = L + ufl.dot(dolfinx.fem.Constant(msh, np.asarray(t, float)), v) * ds(k + 1)
    return V, a, L


def rigid_motion_bcs(V, pin, roll, roll_component: int = 1) -> list:
    """Three scalar point conditions on FE nodes that remove the rigid motions of a free plate,
    statically determinate (with self-equilibrated loads their reactions vanish): ``u = 0`` at
    the boundary node ``pin`` and ``u_i = 0`` (``i = roll_component``) at the boundary node
    ``roll`` (``DirichletBC`` on ``V`` and on ``V.sub(i)``). Both must be mesh vertices on the
    boundary, outside the particle patch."""
    msh = V.mesh

    def vertex(p):
        return dolfinx.mesh.locate_entities_boundary(
            msh, 0, lambda x: np.isclose(x[0], p[0]) & np.isclose(x[1], p[1])
        )

    for p in (pin, roll):
        if COMM.allreduce(vertex(p).size) == 0:
            raise ValueError(f"no boundary mesh vertex at {list(p)} for a rigid-motion condition")
    dofs = dolfinx.fem.locate_dofs_topological(V, 0, vertex(pin))
    Vi = V.sub(roll_component)
    dofs_i = dolfinx.fem.locate_dofs_topological(Vi, 0, vertex(roll))
    return [
        dolfinx.fem.dirichletbc(np.zeros(2), dofs, V),
        dolfinx.fem.dirichletbc(np.float64(0.0), dofs_i, Vi),
    ]


def solve(
    method, msh, h, material, crack, patch_cells=None, dirichlet=None, tractions=(), enrich=False
):
    """Solve with particles everywhere (``method="efg"``) or a particle patch of ``patch_cells``
    coupled by ``method`` to Q1 elements in a UFL model; ``dirichlet = (facets, fn)`` on all
    components, ``tractions``: ``(facets, (tx, ty))`` constant tractions; ``enrich``: the
    near-tip enrichment (``crack_enrichment=True``).

    Returns ``(solution, sizes, seconds)``."""
    t0 = time.perf_counter()
    if method == "efg":
        P = mf.ParticleSet.from_cells(msh, h)
        prob = mf.EFGElasticity(P, material, cracks=[crack], crack_enrichment=enrich)
        if dirichlet is not None:
            prob.add_dirichlet(*dirichlet)
        for facets, t in tractions:
            prob.add_traction(facets, lambda x, n, t=t: np.tile(t, (len(x), 1)))
        sol = prob.solve()
        sizes = {"particle_dofs": 2 * P.num_particles, "fe_dofs": 0}
        return sol, sizes, time.perf_counter() - t0
    V, a, L = coupled_forms(msh, material, tractions)
    bcs = []
    if dirichlet is not None:
        facets, fn = dirichlet
        g = dolfinx.fem.Function(V)
        g.interpolate(lambda x: fn(x[:2].T).T)
        bcs.append(dolfinx.fem.dirichletbc(g, dolfinx.fem.locate_dofs_topological(V, 1, facets)))
    patch = mf.ParticlePatch(msh, patch_cells, h, cracks=[crack], crack_enrichment=enrich)
    sol = mf.CoupledLinearProblem(a, L, bcs, patch, material=material, coupling=method).solve()
    sizes = {
        "particle_dofs": 2 * patch.particles.num_particles,
        "fe_dofs": 2 * V.dofmap.index_map.size_global,
    }
    return sol, sizes, time.perf_counter() - t0


def write_json(path, record) -> None:
    if path and COMM.rank == 0:
        with open(path, "w") as f:
            json.dump(record, f, indent=1)
