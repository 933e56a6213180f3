# # Benchmark: dynamic crack growth on random user set-ups, with and without fitted segments
#
# A user's model written from scratch: a steel plate 0.2 x 0.12 m (spacing 0.004, triangles or
# quadrilaterals, the particles on the vertices), an edge crack from a random height (0.05 to
# 0.07 m) at a random angle (within 23 degrees) to x = 0.05 m, sudden tractions on the top edge
# (100 MPa) and the right edge (a random 0.3 to 1 of it), ``DynamicCrackGrowth`` with K_Ic = 2
# MPa m^0.5, segments of 3.5 spacings at 1000 m/s, K on domains of 2 and 3 spacings, 60 us;
# pure EFG, or a coupling on a patch that grows with the tip (``mf.NearTips(8)``, starting from
# the cells within 8 spacings of the crack). Each draw runs twice in one process: with the
# default ``fit_segments=True`` (``dynamics/growth_probe.py``: a segment the crack-aware MLS
# cannot carry is turned by up to 15 degrees) and with ``fit_segments=False`` (every segment
# the criterion's, the paper's). Printed per method and cell type: the runs, those stopped by a
# refused model (an ill-conditioned moment matrix: the number is what the probe removes) or
# by anything else, the runs with a turned segment, the turns and the largest. JSON with
# ``--json``; ``--small`` is a smoke run (two draws of pure EFG on quadrilaterals).

# +
from __future__ import annotations

import argparse
import warnings

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx.mls import MomentMatrixError
from dolfinx_meshfree.dynamics import DynamicCrackGrowth

import dolfinx
import numpy as np
from harness import print_table, write_json
from mpi4py import MPI

MATERIAL = mf.LinearElastic(E=200e9, nu=0.3, plane="strain", rho=7800.0)
L, HEIGHT, H = 0.2, 0.12, 0.004
CELLS = {"triangle": dolfinx.mesh.CellType.triangle,
         "quadrilateral": dolfinx.mesh.CellType.quadrilateral}  # fmt: skip
# -


# +
def draws(seed: int, n: int) -> list[tuple[float, float, float]]:
    """``n`` random set-ups: the crack's start height, its angle (radians), the right edge's
    traction relative to the top's."""
    rng = np.random.default_rng(seed)
    return [
        (0.05 + rng.uniform(0.0, 0.02), rng.uniform(-0.4, 0.4), rng.uniform(0.3, 1.0))
        for _ in range(n)
    ]


def run(msh, method: str, draw: tuple, fit: bool, t_end: float = 60e-6) -> dict:
    """One growth run: ``{"stopped": None | "refused" | the error's class, "turns": [...]}``."""
    y0, angle, tx = draw
    crack0 = mf.Crack([[0.0, y0], [0.05, y0 + 0.05 * np.tan(angle)]])
    top = mf.boundary_facets(msh, lambda x: np.isclose(x[1], HEIGHT))
    right = mf.boundary_facets(msh, lambda x: np.isclose(x[0], L))

    def build(crack, cells=None):
        if method == "efg":
            dyn = mf.ExplicitDynamics.efg(mf.ParticleSet.from_cells(msh, H), MATERIAL,
                                          cracks=[crack])  # fmt: skip
        else:
            if cells is None:
                cells = mf.cells_near(msh, crack.points, 8 * H)
            V = _compat.vector_function_space(msh)
            patch = mf.ParticlePatch(msh, cells, H, cracks=[crack])
            dyn = mf.ExplicitDynamics.coupled(mf.CoupledElasticity(V, patch, MATERIAL,
                                                                   coupling=method))  # fmt: skip
        dyn.add_traction(top, lambda x, n: 100e6 * n)
        dyn.add_traction(right, lambda x, n: tx * 100e6 * n)
        return dyn

    adapt = None if method == "efg" else mf.NearTips(8)
    stopped, turns = None, []
    try:
        g = DynamicCrackGrowth(
            build, crack0, K_Ic=2.0e6, speed=1000.0, segment=3.5 * H, check_every=5,
            radius=[2 * H, 3 * H], adapt=adapt, fit_segments=fit,
        )  # fmt: skip
        g.run(t_end)
        turns = [c.turn for c in g.history if c.extended]
    except MomentMatrixError:
        stopped = "refused"
    except ValueError as e:  # a rebuilt model refused, or a path that leaves the body
        stopped = "refused" if "ill-conditioned" in str(e) or "singular" in str(e) else "other"
    return {"stopped": stopped, "turns": turns}


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--methods", nargs="+", default=["efg", "lagrange", "edge-to-edge"])
    p.add_argument("--cells", nargs="+", default=list(CELLS), choices=list(CELLS))
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--seed", type=int, default=2)
    p.add_argument("--small", action="store_true", help="a smoke run")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    if args.small:
        args.methods, args.cells, args.draws = ["efg"], ["quadrilateral"], 2
    comm = MPI.COMM_WORLD
    records = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the cracks' placement warnings, draw after draw
        for cell in args.cells:
            msh = dolfinx.mesh.create_rectangle(
                comm, [np.array([0.0, 0.0]), np.array([L, HEIGHT])],
                [round(L / H), round(HEIGHT / H)], CELLS[cell],
            )  # fmt: skip
            for method in args.methods:
                for fit in (True, False):
                    runs = [run(msh, method, d, fit) for d in draws(args.seed, args.draws)]
                    turns = [t for r in runs for t in r["turns"] if t != 0.0]
                    records.append({
                        "method": method, "cells": cell, "fit_segments": fit, "runs": len(runs),
                        "refused": sum(r["stopped"] == "refused" for r in runs),
                        "other": sum(r["stopped"] == "other" for r in runs),
                        "turned_runs": sum(any(t != 0.0 for t in r["turns"]) for r in runs),
                        "turns": len(turns),
                        "largest_turn": max((abs(t) for t in turns), default=0.0),
                        "stopped_draws": [i for i, r in enumerate(runs) if r["stopped"]],
                    })  # fmt: skip
    if comm.rank == 0:
        print(f"Dynamic crack growth on {args.draws} random set-ups (seed {args.seed}), "
              f"{comm.size} rank(s)")  # fmt: skip
        columns = [("method", "<13"), ("cells", "<13"), ("fit", "<5"), ("runs", "5d"),
                   ("refused", "8d"), ("other", "6d"), ("turned", "7d"), ("turns", "6d"),
                   ("largest deg", "11.1f")]  # fmt: skip
        print_table(columns, [[r["method"], r["cells"], str(r["fit_segments"]), r["runs"],
                               r["refused"], r["other"], r["turned_runs"], r["turns"],
                               r["largest_turn"]] for r in records])  # fmt: skip
    write_json(args.json, records, seed=args.seed, draws=args.draws)
    return {"records": records}


if __name__ == "__main__":
    main()
# -
