# # Cook's membrane at finite strain: FE, EFG and the couplings against a fine P2 reference
#
# The tapered panel of Cook (vertices (0, 0), (48, 44), (48, 60), (0, 44)), clamped on its left
# edge, carries a uniform shear traction on its right edge (total force `--force`), in plane
# strain with a compressible neo-Hookean law (total Lagrangian, Rabczuk et al. 2006, eq. 1–5,
# 34). The quantity of interest is the vertical displacement of the top right corner (48, 60).
# Its reference comes from DOLFINx alone: vector P2 elements on a fine mesh (`--ref-cells`),
# the same residual and Newton, no particle code. The particle patch covers the region near the
# loaded edge (x > 32), where the panel bends most; FE everywhere else.
#
#     python demos/cooks_membrane.py [--method fe efg lagrange edge-to-edge] [--cells 8 16 32]
#         [--force 0.25] [--json F]
#
# The table gives the corner displacement, its error against the reference, the Newton
# iterations and the time of each run, over a refinement series: error against time is the
# comparison of the methods. The demo checks that every method converges to the reference
# (error below 1 % at the finest run and falling under refinement).

# +
from __future__ import annotations

import argparse
import json
import time

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

METHODS = ("fe", "efg", *mf.FINITE_STRAIN_COUPLINGS)
CORNER = np.array([[48.0, 60.0]])
MATERIAL = mf.NeoHookean(E=1.0, nu=0.3, plane="strain")
# -


# ## The panel, as a DOLFINx user builds it
#
# A structured mesh of the unit square mapped onto the tapered panel: (s, t) -> (48 s,
# 44 s + t (44 + 16 s - 44 s)).


# +
def cook_mesh(n: int, cell=dolfinx.mesh.CellType.quadrilateral):
    msh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, n, n, cell)
    s, t = msh.geometry.x[:, 0].copy(), msh.geometry.x[:, 1].copy()
    msh.geometry.x[:, 0] = 48.0 * s
    msh.geometry.x[:, 1] = 44.0 * s + t * (44.0 - 28.0 * s)
    return msh


def residual(V, u, force: float):
    msh = V.mesh
    v = ufl.TestFunction(V)
    right = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 48.0))
    mt = dolfinx.mesh.meshtags(msh, 1, np.sort(right), np.full(right.size, 1, np.int32))
    ds = ufl.Measure("ds", domain=msh, subdomain_data=mt)
    dx = ufl.Measure("dx", domain=msh, metadata={"quadrature_degree": 4})
    traction = dolfinx.fem.Constant(msh, np.array([0.0, force / 16.0]))
    F = ufl.Identity(2) + ufl.grad(u)
    return ufl.inner(MATERIAL.ufl_first_piola(F), ufl.grad(v)) * dx - ufl.inner(traction, v) * ds(1)


def clamp(V):
    left = dolfinx.mesh.locate_entities_boundary(V.mesh, 1, lambda x: np.isclose(x[0], 0.0))
    return [
        dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, left), V)
    ]


def reference(args) -> float:
    """Vertical corner displacement with vector P2 on a fine mesh (DOLFINx only)."""
    msh = cook_mesh(args.ref_cells)
    V = _compat.vector_function_space(msh, degree=2)
    u = dolfinx.fem.Function(V)
    problem = mf.FENonlinearProblem(residual(V, u, args.force), u, clamp(V), load_steps=args.steps)
    problem.solve()
    # the corner is a vertex, hence a P2 node: its value, from the rank that owns it
    n_owned = V.dofmap.index_map.size_local
    xy = V.tabulate_dof_coordinates()[:n_owned, :2]
    at = np.flatnonzero(np.linalg.norm(xy - CORNER, axis=1) < 1e-9)
    value = u.x.array[2 * at[0] + 1] if at.size else -np.inf
    return float(msh.comm.allreduce(value, op=MPI.MAX))


# -


# ## One run


# +
def run(method: str, n: int, args) -> dict:
    comm = MPI.COMM_WORLD
    msh = cook_mesh(n)
    spacing = np.sqrt(1440.0) / n  # the mean element size (the panel's area is 1440)
    t0 = time.perf_counter()
    if method == "efg":
        particles = mf.ParticleSet.from_cells(msh, spacing)
        problem = mf.EFGElasticity(particles, MATERIAL)
        problem.add_dirichlet(
            mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0)), lambda x: np.zeros_like(x)
        )
        problem.add_traction(
            mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48.0)),
            lambda x, nrm: np.tile([0.0, args.force / 16.0], (len(x), 1)),
        )
        sol = problem.solve(load_steps=args.steps)
        w, iterations = sol.displacement(CORNER)[0, 1], sol.newton.iterations
        dofs = 2 * particles.num_particles
    else:
        V = _compat.vector_function_space(msh)
        u = dolfinx.fem.Function(V)
        F = residual(V, u, args.force)
        if method == "fe":
            result = mf.FENonlinearProblem(F, u, clamp(V), load_steps=args.steps).solve()
            w = mf.evaluate_fe_function(u, CORNER)[0, 1]
            dofs = 2 * V.dofmap.index_map.size_global
        else:
            nc = msh.topology.index_map(2).size_local
            xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:nc], 0].mean(axis=1)
            patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 32.0), spacing=spacing)
            problem = mf.CoupledNonlinearProblem(
                F, u, clamp(V), patch, MATERIAL, coupling=method, load_steps=args.steps
            )
            result = problem.solve()
            w = problem.solution.displacement(CORNER)[0, 1]
            dofs = 2 * V.dofmap.index_map.size_global + 2 * patch.particles.num_particles
        iterations = result.iterations
    seconds = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    return {"method": method, "cells": n, "corner_v": float(w), "newton_iterations": iterations,
            "dofs": int(dofs), "time_total": seconds}  # fmt: skip


# -


# ## Table and checks


# +
def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--method", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--cells", nargs="+", type=int, default=[8, 16, 32], help="cells per side")
    p.add_argument("--force", type=float, default=0.25, help="total shear force on the edge")
    p.add_argument("--steps", type=int, default=2, help="load steps")
    p.add_argument("--ref-cells", type=int, default=48, help="P2 reference: cells per side")
    p.add_argument("--json", default=None)
    p.add_argument("--no-check", action="store_true")
    args = p.parse_args(argv)
    comm = MPI.COMM_WORLD
    t0 = time.perf_counter()
    ref = reference(args)
    t_ref = time.perf_counter() - t0
    records = [run(m, n, args) for m in args.method for n in sorted(args.cells)]
    for r in records:
        r["reference"] = ref
        r["error"] = abs(r["corner_v"] - ref) / abs(ref)
    if comm.rank == 0:
        print(
            f"Cook's membrane, plane strain neo-Hookean (E = 1, nu = 0.3), force {args.force:g}, "
            f"{comm.size} rank(s), DOLFINx {mf.DOLFINX_VERSION}; reference: P2 on "
            f"{args.ref_cells} x {args.ref_cells} cells, v = {ref:.6f} ({t_ref:.1f} s)"
        )
        cols = "method          cells    dofs   corner v     error  Newton  time s"
        print(cols)
        print("-" * len(cols))
        for r in records:
            print(
                f"{r['method']:14s} {r['cells']:6d} {r['dofs']:7d} {r['corner_v']:10.6f} "
                f"{r['error']:9.3%} {r['newton_iterations']:7d} {r['time_total']:7.2f}"
            )
        if args.json:
            with open(args.json, "w") as f:
                json.dump(records, f, indent=1)
    failures = []
    if not args.no_check and len(args.cells) > 1:
        for m in args.method:
            errs = [r["error"] for r in records if r["method"] == m]
            if not errs[-1] < errs[0]:
                failures.append(f"{m}: error does not fall under refinement: {errs}")
            if max(args.cells) >= 32 and not errs[-1] <= 0.01:
                failures.append(f"{m}: error {errs[-1]:.2%} > 1 % at the finest run")
    if failures:
        if comm.rank == 0:
            print("FAILED:\n  " + "\n  ".join(failures))
        raise SystemExit(1)
    return records


if __name__ == "__main__":
    main()
# -
