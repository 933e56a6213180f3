# # What every rank holds of every particle (issue 28's baseline)
#
# Issue 28 asks that each rank hold its own particles and a halo, and a check that nothing global
# remains: no per-rank array with the global particle count as a dimension. Today every rank
# holds every particle. This benchmark measures how much: it builds a coupled model as a user
# would (a plate of quadrilaterals, a Lagrange patch over its middle third, particles at the
# cells' spacing, `CoupledElasticity`, a static solve), then walks the model, its patch, its
# particles, its MLS and its solution, and lists on each rank the numpy arrays and scipy
# matrices that have the global particle count as a dimension (:func:`replicated_arrays`), with
# their bytes. Printed per run: the ranks, the particles, the largest rank's count of such
# arrays and their bytes per particle, and the five largest. Under issue 28 the count is 0 on
# more than one rank. The walk sees what the objects hold as attributes: arrays inside
# closures, caches keyed elsewhere or compiled objects are not counted, so the bytes are a
# lower bound.
#
# Run: ``OMP_NUM_THREADS=1 mpirun -n P python benchmarks/bench_replicated.py --n 64`` for P =
# 1, 2, 4 (4 oversubscribed on two cores: for the memory, not for time). ``--json F`` writes the
# records.

# +
from __future__ import annotations

import argparse
from typing import Any

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import scipy.sparse as sp
from harness import write_json
from mpi4py import MPI
from petsc4py import PETSc

#: Values the walk does not enter: scalars, strings, PETSc objects and communicators.
LEAVES = (str, bytes, int, float, bool, complex, type(None), PETSc.Object, MPI.Comm)


def replicated_arrays(root: Any, n: int, name: str = "model", depth: int = 10) -> dict:
    """The numpy arrays and scipy sparse matrices reachable from ``root`` with ``n`` as one of
    their dimensions: ``{path: (shape, bytes)}`` (local). The walk enters dicts, lists, tuples
    and the attributes of this package's objects (not DOLFINx's, UFL's or PETSc's), each object
    once, at most ``depth`` levels down."""
    found: dict = {}
    seen: set[int] = set()
    stack = [(name, root, 0)]
    while stack:
        path, obj, level = stack.pop()
        if id(obj) in seen or level > depth or isinstance(obj, LEAVES):
            continue
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            if n in obj.shape:
                found[path] = (tuple(obj.shape), int(obj.nbytes))
            continue
        if sp.issparse(obj):
            if n in obj.shape:
                parts = [getattr(obj, a, None) for a in ("data", "indices", "indptr", "row", "col")]
                nbytes = sum(int(p.nbytes) for p in parts if isinstance(p, np.ndarray))
                found[path] = (tuple(obj.shape), nbytes)
            continue
        if isinstance(obj, dict):
            items = [(f"{path}[{k!r}]", v) for k, v in obj.items()]
        elif isinstance(obj, list | tuple):
            items = [(f"{path}[{i}]", v) for i, v in enumerate(obj)]
        elif type(obj).__module__.startswith("dolfinx_meshfree"):
            names = list(getattr(obj, "__dict__", {})) + list(getattr(obj, "__slots__", ()))
            items = [(f"{path}.{a}", getattr(obj, a, None)) for a in names]
        else:
            continue
        stack.extend((p, v, level + 1) for p, v in items)
    return found


def build(n: int, comm: MPI.Comm = MPI.COMM_WORLD) -> tuple[mf.CoupledElasticity, Any, int]:
    """The plate (module header) of ``n`` x ``n / 2`` cells solved: ``(model, solution,
    particles)``."""
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.array([2.0, 1.0])], [n, n // 2], dolfinx.mesh.CellType.quadrilateral
    )
    cells = dolfinx.mesh.locate_entities(msh, 2, lambda x: (x[0] > 2 / 3) & (x[0] < 4 / 3))
    patch = mf.ParticlePatch(msh, cells, 1.0 / n)
    V = _compat.vector_function_space(msh)
    model = mf.CoupledElasticity(V, patch, mf.LinearElastic(1.0, 0.3, plane="stress"))
    left = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0))
    right = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 2.0))
    model.add_dirichlet(left, lambda x: np.zeros_like(x))
    model.add_traction(right, lambda x, normal: np.tile([1.0, 0.0], (len(x), 1)))
    solution = model.solve()
    return model, solution, patch.particles.num_particles


def run(n: int, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """One model: the largest rank's replicated arrays (count, bytes, bytes per particle) and
    the five largest of rank 0's."""
    model, solution, particles = build(n, comm)
    found = replicated_arrays({"model": model, "solution": solution}, particles, "root")
    nbytes = sum(b for _, b in found.values())
    worst = comm.allreduce((nbytes, len(found)), op=MPI.MAX)
    largest = sorted(found.items(), key=lambda kv: -kv[1][1])[:5]
    return {
        "ranks": comm.size,
        "particles": particles,
        "arrays": worst[1],
        "bytes": worst[0],
        "bytes_per_particle": worst[0] / particles,
        "largest": [[path, list(shape), b] for path, (shape, b) in largest],
    }


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--n", type=int, nargs="+", default=[32, 64], help="cells across the plate")
    p.add_argument("--json", default=None, help="write the records to this JSON file")
    args = p.parse_args(argv)
    records = [run(n) for n in args.n]
    if MPI.COMM_WORLD.rank == 0:
        print(f"{'ranks':>5} {'particles':>9} {'arrays':>6} {'MB':>8} {'B/particle':>10}")
        for r in records:
            print(
                f"{r['ranks']:5d} {r['particles']:9d} {r['arrays']:6d} "
                f"{r['bytes'] / 2**20:8.2f} {r['bytes_per_particle']:10.0f}"
            )
        for path, shape, b in records[-1]["largest"]:
            print(f"    {path} {tuple(shape)} {b / 2**20:.2f} MB")
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
