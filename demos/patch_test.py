# # Linear patch test
#
# Belytschko et al. 1995, sec. 5.1.1: the displacement ``u = (x, y)`` (eq. 5.1) is prescribed on
# the whole boundary of a square patch with no body force; the exact solution is that linear
# field, and a consistent method reproduces it to round-off. With EFG the error that remains
# comes from quadrature: the paper reports 1e-6 with Gauss cells. Variationally consistent
# integration (VCI, Chen, Hillman & Rüter 2013; ``--consistent``) removes it.
#
# Meshes: ``regular`` (an n x n grid of cells, particles on a regular grid) or ``irregular``
# (interior mesh vertices moved by up to 30 % of a cell, particles jittered by up to 30 % of their
# spacing). The demo prints the maximum displacement error over the particles and 1000 random
# points, and checks it: at most 1e-10 with consistent integration (or for FE), and reported as
# measured otherwise.
#
#     python demos/patch_test.py --method efg --mesh irregular --consistent [--json out.json]

# +
from __future__ import annotations

import argparse
import json
import sys

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
from mpi4py import MPI

# -


def perturb_interior(msh, amount: float, size: float) -> None:
    """Move interior vertices by up to ``amount`` (deterministic in the coordinates, so every
    rank moves its copies of a shared vertex alike)."""
    x = msh.geometry.x
    interior = np.all((x[:, :2] > 1e-9) & (x[:, :2] < size - 1e-9), axis=1)
    phase = np.sin(12.9898 * x[:, 0] + 78.233 * x[:, 1]) * 43758.5453
    u = phase - np.floor(phase)
    phase2 = np.sin(39.3468 * x[:, 0] + 11.135 * x[:, 1]) * 24634.6345
    v = phase2 - np.floor(phase2)
    x[interior, 0] += amount * (2 * u[interior] - 1)
    x[interior, 1] += amount * (2 * v[interior] - 1)


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description="Linear patch test (Belytschko et al. 1995, 5.1.1)")
    p.add_argument("--method", choices=("fe", "efg"), default="efg")
    p.add_argument("--mesh", choices=("regular", "irregular"), default="regular")
    p.add_argument("--cell", choices=("quadrilateral", "triangle"), default="quadrilateral")
    p.add_argument("--cells", type=int, default=6, help="cells per side")
    p.add_argument("--consistent", action="store_true", help="variationally consistent integration")
    p.add_argument("--quadrature-degree", type=int, default=7)
    p.add_argument("--weight", choices=("quartic", "cubic", "gaussian"), default="quartic")
    p.add_argument("--dilation", type=float, default=2.0)
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    if args.cells < 2:
        p.error(f"--cells must be at least 2, got {args.cells}")

    comm = MPI.COMM_WORLD
    size = 2.0
    n = args.cells
    cell = getattr(dolfinx.mesh.CellType, args.cell)
    msh = dolfinx.mesh.create_rectangle(comm, [np.zeros(2), np.full(2, size)], [n, n], cell)
    if args.mesh == "irregular":
        perturb_interior(msh, 0.3 * size / n, size)
    exact = mf.LinearField()
    material = mf.LinearElastic(1000.0, 0.3)
    boundary = mf.boundary_facets(msh)
    rng = np.random.default_rng(0)
    samples = rng.uniform(0, size, (1000, 2)) if comm.rank == 0 else np.zeros((0, 2))

    if args.method == "fe":
        V = _compat.vector_function_space(msh)
        sol = mf.solve_fe_elasticity(
            V, material, dirichlet=[(boundary, lambda x: exact.displacement(x[:2].T).T)]
        )
        u = mf.evaluate_fe_function(sol.u, samples)
        err = float(np.abs(u - exact.displacement(samples)).max(initial=0.0))
    else:
        jitter = 0.3 if args.mesh == "irregular" else 0.0
        particles = mf.ParticleSet.from_cells(msh, size / n, jitter=jitter)
        problem = mf.EFGElasticity(
            particles,
            material,
            weight=args.weight,
            dilation=args.dilation,
            quadrature_degree=args.quadrature_degree,
            consistent=args.consistent,
        )
        problem.add_dirichlet(boundary, exact.displacement)
        sol = problem.solve()
        pts = np.vstack([particles.positions, samples])
        err = float(np.abs(sol.displacement(pts) - exact.displacement(pts)).max())
    err = comm.allreduce(err, op=MPI.MAX)

    rec = {
        "method": args.method,
        "mesh": args.mesh,
        "cell": args.cell,
        "consistent": bool(args.consistent) if args.method == "efg" else None,
        "quadrature_degree": args.quadrature_degree,
        "max_error": err,
        "ranks": comm.size,
        "dolfinx_version": mf.DOLFINX_VERSION,
    }
    exact_expected = args.method == "fe" or args.consistent
    if comm.rank == 0:
        label = "consistent (VCI)" if args.consistent else f"Gauss degree {args.quadrature_degree}"
        label = "FE" if args.method == "fe" else label
        print(
            f"patch test {args.method:4} {args.mesh:9} {args.cell:13} {label:18} "
            f"max |u - u_exact| = {err:.2e}"
        )
        if args.json:
            with open(args.json, "w") as f:
                json.dump(rec, f, indent=1)
    # The check: exact methods pass to round-off. Plain Gauss quadrature is reported, not judged.
    if exact_expected and not err <= 1e-10:
        if comm.rank == 0:
            print(f"CHECK FAILED: patch test error {err:.2e} > 1e-10", file=sys.stderr)
        sys.exit(1)
    return rec


if __name__ == "__main__":
    main()
