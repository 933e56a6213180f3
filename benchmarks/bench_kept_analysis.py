# # Benchmark: MUMPS's analysis kept between Newton's tangents, against one analysis per tangent
#
# A MUMPS factorisation is an analysis (ordering and symbolic factorisation: where the nonzeros
# are) and a numerical factorisation (their values). The nonlinear static solvers keep the
# analysis of a tangent for the next tangents of the same sparsity pattern
# (``statics/kept_factor.py``, ``BlockProblem.kept_factorisation``). This benchmark runs the
# same models both ways in one run, alternating, ``--repeats`` times each (the fastest run of
# each is reported):
#
# * ``beam``: Petersson's notched beam (``demos/concrete_beam.py``, the cohesive crack up the
#   ligament, path following to CMOD ``--end`` mm) at ``--h`` mm, pure EFG and the couplings of
#   ``--methods``; the crack's growth changes the pattern, so part of the tangents is analysed
#   afresh anyway;
# * ``deflection``: the slender cantilever under a dead tip load (``demos/large_deflection.py``,
#   K = 5, load steps by Newton on the user's UFL residual: ``FENonlinearProblem`` and
#   ``CoupledNonlinearProblem``), FE, EFG and the couplings;
# * ``sweep``: a linear load sweep, ``--sweep-loads`` tip loads on Timoshenko's cantilever
#   (48 x 12, plane stress, h = ``--sweep-h``) solved one after the other with
#   ``solve(kept=kept)``: pure EFG (``EFGElasticity``) and the couplings on a patch over the
#   half x > 24 (``CoupledLinearProblem``, a ``Constant`` load in ``L``). The matrix is
#   assembled again at every load, with the same values, so the kept factors solve every load
#   after the first without a factorisation.
#
# Per model: the analyses and numerical factorisations counted by PETSc's event log
# (``MatLUFactorSym`` / ``MatCholFctrSym`` and their numerical events, summed), their seconds,
# the whole run's seconds both ways and their ratio, and the largest difference of the two runs'
# results (the beam's load-CMOD curve, the tip's deflection) relative to the largest value:
# kept analyses change no answer (measured: none to the bit). Prints a table, writes JSON
# (``--json``); ``--small`` is a smoke run for CI (no timing is checked anywhere).

# +
from __future__ import annotations

import argparse
import contextlib
import time
from collections.abc import Callable, Iterator

import dolfinx_meshfree as mf  # first: the MPI of the lane
from dolfinx_meshfree import _compat
from dolfinx_meshfree.statics.kept_factor import KeptFactorisation

import dolfinx
import numpy as np
import ufl
from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI
from petsc4py import PETSc

# -

SYMBOLIC = ("MatLUFactorSym", "MatCholFctrSym")
NUMERIC = ("MatLUFactorNum", "MatCholFctrNum")


def _events(names: tuple[str, ...]) -> tuple[int, float]:
    """Calls and seconds of PETSc's events ``names`` so far (summed; this rank's)."""
    infos = [PETSc.Log.Event(name).getPerfInfo() for name in names]
    return sum(i["count"] for i in infos), sum(i["time"] for i in infos)


@contextlib.contextmanager
def _fresh(fresh: bool) -> Iterator[None]:
    """With ``fresh``, every factorisation analyses its system afresh (the kept one is dropped:
    what the solvers did before the analysis was kept)."""
    take = KeptFactorisation.take
    if fresh:
        KeptFactorisation.take = lambda self, A, key: self.clear()
    try:
        yield
    finally:
        KeptFactorisation.take = take


def _measure(run: Callable[[], np.ndarray], fresh: bool) -> dict:
    """One run: its result array, seconds, analyses and factorisations (PETSc's counts)."""
    s0, n0 = _events(SYMBOLIC), _events(NUMERIC)
    MPI.COMM_WORLD.barrier()
    t0 = time.perf_counter()
    with _fresh(fresh):
        values = run()
    seconds = MPI.COMM_WORLD.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    s1, n1 = _events(SYMBOLIC), _events(NUMERIC)
    return {
        "values": values,
        "seconds": seconds,
        "analyses": s1[0] - s0[0],
        "analysis_s": s1[1] - s0[1],
        "factorisations": n1[0] - n0[0],
        "numeric_s": n1[1] - n0[1],
    }


def _beam(method: str, h: float, end: float) -> Callable[[], np.ndarray]:
    demo = load_demo("concrete_beam")
    argv = ["--method", method, "--h", f"{h:g}", "--end", f"{end:g}", "--quiet", "--no-check"]

    def run() -> np.ndarray:
        r = demo.main(argv)
        return np.concatenate([np.asarray(r["cmod"], float), np.asarray(r["load"], float)])

    return run


def _deflection(method: str, h: float) -> Callable[[], np.ndarray]:
    demo = load_demo("large_deflection")
    argv = ["--method", method, "--load", "5", "--h", f"{h:g}", "--no-check"]

    def run() -> np.ndarray:
        with contextlib.redirect_stdout(None):
            (r,) = demo.main(argv)
        return np.array([r["tip_w_over_L"], r["tip_u_over_L"]])

    return run


def _sweep(method: str, h: float, loads: int) -> Callable[[], np.ndarray]:
    """``loads`` tip loads on the cantilever, one solve each on one kept factorisation; the tip
    deflections (every rank)."""
    comm = MPI.COMM_WORLD
    n = round(48.0 / h)
    msh = dolfinx.mesh.create_rectangle(
        comm, [[0.0, -6.0], [48.0, 6.0]], [n, n // 4], dolfinx.mesh.CellType.quadrilateral
    )
    material = mf.LinearElastic(E=3e7, nu=0.3, plane="stress")
    tip = np.array([[48.0, 0.0]])
    shear = [0.0]  # the load of the EFG problem's traction (N/m along the end)
    if method == "efg":
        problem = mf.EFGElasticity(mf.ParticleSet.from_cells(msh, spacing=h), material)
        clamp = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0))
        problem.add_dirichlet(clamp, lambda x: np.zeros_like(x))
        end = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48.0))
        problem.add_traction(end, lambda x, nrm: np.tile([0.0, shear[0]], (len(x), 1)))
    else:
        V = _compat.vector_function_space(msh, 1)
        u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        mu, lmbda = 3e7 / 2.6, 3e7 * 0.3 / (1 - 0.09)  # plane stress
        eps = ufl.sym(ufl.grad(u))
        sigma = 2 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(2)
        a = ufl.inner(sigma, ufl.sym(ufl.grad(v))) * ufl.dx
        facets = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 48.0))
        tags = dolfinx.mesh.meshtags(
            msh, 1, np.sort(facets).astype(np.int32), np.full(facets.size, 1, np.int32)
        )
        load = dolfinx.fem.Constant(msh, np.array([0.0, 0.0]))
        L = ufl.inner(load, v) * ufl.Measure("ds", msh, subdomain_data=tags)(1)
        left = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 0.0))
        dofs = dolfinx.fem.locate_dofs_topological(V, 1, left)
        bcs = [dolfinx.fem.dirichletbc(np.zeros(2), dofs, V)]
        cells = dolfinx.mesh.locate_entities(msh, 2, lambda x: x[0] >= 24.0 - 1e-9)
        cells = cells[cells < msh.topology.index_map(2).size_local]
        patch = mf.ParticlePatch(msh, cells, spacing=h)
        problem = mf.CoupledLinearProblem(a, L, bcs, patch, material=material, coupling=method)

    def run() -> np.ndarray:
        kept = KeptFactorisation()
        out = []
        for k in range(1, loads + 1):
            shear[0] = -1000.0 * k / 12.0
            if method != "efg":
                load.value = [0.0, shear[0]]
            out.append(problem.solve(kept=kept).displacement(tip)[0, 1])
        kept.destroy()
        return np.array(out)

    return run


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--methods", nargs="+", default=["efg", "lagrange", "bridging"])
    p.add_argument("--h", type=float, default=10.0, help="the beam's spacing, mm")
    p.add_argument("--end", type=float, default=0.5, help="the beam's last CMOD, mm")
    p.add_argument("--deflection-h", type=float, default=0.25, help="the cantilever's h / D")
    p.add_argument("--sweep-h", type=float, default=0.25, help="the load sweep's spacing")
    p.add_argument("--sweep-loads", type=int, default=5, help="the load sweep's loads")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--small", action="store_true", help="a smoke run (coarse, one repeat)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    if args.small:
        args.methods, args.h, args.end, args.deflection_h, args.repeats = (
            ["lagrange"], 25.0, 0.1, 1.0, 1
        )  # fmt: skip
        args.sweep_h, args.sweep_loads = 2.0, 3
    PETSc.Log.begin()
    cases = [(f"beam h={args.h:g}", m, _beam(m, args.h, args.end)) for m in args.methods]
    cases += [
        (f"deflection h={args.deflection_h:g}", m, _deflection(m, args.deflection_h))
        for m in ["fe", *args.methods]
    ]
    cases += [
        (f"sweep h={args.sweep_h:g}", m, _sweep(m, args.sweep_h, args.sweep_loads))
        for m in args.methods
    ]
    records = []
    for model, method, run in cases:
        runs: dict[bool, list[dict]] = {True: [], False: []}
        for _ in range(args.repeats):
            for fresh in (True, False):  # alternating: the machine's drift hits both alike
                runs[fresh].append(_measure(run, fresh))
        best = {fresh: min(r, key=lambda m: m["seconds"]) for fresh, r in runs.items()}
        kept, fresh = best[False], best[True]
        ref = max(float(np.abs(fresh["values"]).max()), 1e-300)
        difference = max(
            float(np.abs(r["values"] - fresh["values"]).max()) / ref for r in runs[False]
        )
        records.append(
            {
                "model": model,
                "method": method,
                "factorisations": kept["factorisations"],
                "analyses_kept": kept["analyses"],
                "analyses_fresh": fresh["analyses"],
                "analysis_s_kept": kept["analysis_s"],
                "analysis_s_fresh": fresh["analysis_s"],
                "numeric_s_kept": kept["numeric_s"],
                "numeric_s_fresh": fresh["numeric_s"],
                "seconds_kept": kept["seconds"],
                "seconds_fresh": fresh["seconds"],
                "ratio": ratio(kept["seconds"], fresh["seconds"]),
                "max_difference": difference,
            }
        )
    if MPI.COMM_WORLD.rank == 0:
        print(
            f"MUMPS's analysis kept against one per tangent, {MPI.COMM_WORLD.size} rank(s), "
            f"best of {args.repeats} alternating runs each"
        )
        print_table(
            [
                ("model", "<17"),
                ("method", "<9"),
                ("factor.", "7d"),
                ("analyses", ">9"),
                ("analysis s", ">11"),
                ("numeric s", ">10"),
                ("run s", ">13"),
                ("kept/fresh", "10.2f"),
                ("difference", "10.1e"),
            ],
            [
                (
                    r["model"],
                    r["method"],
                    r["factorisations"],
                    f"{r['analyses_kept']}/{r['analyses_fresh']}",
                    f"{r['analysis_s_kept']:.2f}/{r['analysis_s_fresh']:.2f}",
                    f"{r['numeric_s_kept']:.2f}/{r['numeric_s_fresh']:.2f}",
                    f"{r['seconds_kept']:.2f}/{r['seconds_fresh']:.2f}",
                    r["ratio"],
                    r["max_difference"],
                )
                for r in records
            ],
        )
        print("(kept/fresh pairs; analyses and seconds from PETSc's event log, rank 0)")
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
