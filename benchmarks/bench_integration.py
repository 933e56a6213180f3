# # Benchmark: the particle integrations against each other and against FE (issue 26, item 1)
#
# The Timoshenko cantilever of ``demos/cantilever.py`` (its mesh, loads and runners), solved
# with FE, pure EFG and the Lagrange coupling (patch: the last ``--patch-fraction`` of the beam)
# under each particle integration (``--integration``, default ``vci`` and ``smoothed``), at
# each ``--h``. For each case it prints the relative L2 and energy errors beside the median
# over ``--repeats`` runs of the setup, assembly and solve times and of the total, and the total
# as a multiple of FE's at the same ``h`` (one run, the same machine: the ratios are what
# compare). JIT compilation is excluded (the demo's warm-up, then one untimed run of each case).
# ``--small`` is the CI smoke run. Run:
# ``OMP_NUM_THREADS=1 python benchmarks/bench_integration.py --h 0.25 0.125 --json out.json``.

# +
from __future__ import annotations

import argparse

import dolfinx_meshfree as mf

import numpy as np
from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI

# -


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--h", nargs="+", type=float, default=[0.25, 0.125])
    p.add_argument("--integration", nargs="+", choices=mf.INTEGRATIONS,
                   default=["vci", "smoothed"])  # fmt: skip
    p.add_argument("--method", nargs="+", choices=("efg", *mf.SMOOTHED_COUPLINGS),
                   default=["efg", "lagrange"])  # fmt: skip
    p.add_argument("--patch-fraction", type=float, default=0.25)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--small", action="store_true", help="CI smoke run: h = 2, one repeat")
    p.add_argument("--json", default=None)
    return p.parse_args(argv)


def _case(demo, args, method: str, integration: str | None, h: float) -> dict:
    """One run of the demo's runner (collective): errors and the slowest rank's times."""
    comm = MPI.COMM_WORLD
    cli = ["--h", str(h), "--patch-fraction", str(args.patch_fraction), "--no-check"]
    if integration is not None:
        cli += ["--integration", integration]
    dargs = demo.parse(cli)
    material = mf.LinearElastic(dargs.E, dargs.nu, dargs.plane)
    beam = mf.TimoshenkoBeam(material, L=dargs.L, D=dargs.D, P=dargs.P)
    msh = demo.make_mesh(comm, dargs, h)
    errors, sizes, timings, _ = demo.run_method(msh, dargs, beam, material, h, method)
    timings = {k: comm.allreduce(timings[k], op=MPI.MAX) for k in ("setup", "assemble", "solve")}
    dofs = sum(sizes.get(k, 0) for k in ("fe_dofs", "particle_dofs"))
    return {"errors": errors, "timings": timings, "dofs": dofs}


def main(argv: list[str] | None = None) -> list[dict]:
    args = parse(argv)
    if args.small:
        args.h, args.repeats = [2.0], 1
    demo = load_demo("cantilever")
    comm = MPI.COMM_WORLD
    dargs = demo.parse(["--no-check"])
    material = mf.LinearElastic(dargs.E, dargs.nu, dargs.plane)
    demo.warm_jit(dargs, material, mf.TimoshenkoBeam(material, L=dargs.L, D=dargs.D, P=dargs.P))
    cases = [("fe", None)] + [(m, i) for m in args.method for i in args.integration]
    records = []
    for h in args.h:
        for method, integration in cases:  # one untimed run of each (numba, caches)
            _case(demo, args, method, integration, max(h, 2.0))
        for method, integration in cases:
            runs = [_case(demo, args, method, integration, h) for _ in range(args.repeats)]
            med = {k: float(np.median([r["timings"][k] for r in runs])) for k in runs[0]["timings"]}
            med["total"] = float(np.median([sum(r["timings"].values()) for r in runs]))
            records.append({
                "method": method, "integration": integration, "h": h, "dofs": runs[0]["dofs"],
                "error_l2": runs[0]["errors"]["l2"], "error_energy": runs[0]["errors"]["energy"],
                "time": med, "ranks": comm.size, "repeats": args.repeats,
                "patch_fraction": args.patch_fraction if method != "efg" else None,
                "dolfinx_version": mf.DOLFINX_VERSION,
            })  # fmt: skip
    fe_total = {r["h"]: r["time"]["total"] for r in records if r["method"] == "fe"}
    vci_l2 = {(r["method"], r["h"]): r["error_l2"] for r in records if r["integration"] == "vci"}
    for r in records:
        r["x_fe"] = ratio(r["time"]["total"], fe_total[r["h"]])
        r["l2_x_vci"] = ratio(r["error_l2"], vci_l2.get((r["method"], r["h"])))
    if comm.rank == 0:
        print(f"Cantilever, {comm.size} rank(s), median of {args.repeats} (JIT excluded), "
              f"patch fraction {args.patch_fraction} for the couplings")  # fmt: skip
        print_table(
            [("method", "<9"), ("integration", "<11"), ("h", "6.3g"), ("dofs", "7d"),
             ("L2 error", "9.2e"), ("L2/vci", "6.2f"), ("energy", "9.3e"), ("setup", "6.3f"),
             ("assem", "6.3f"), ("solve", "6.3f"), ("total", "6.3f"), ("x FE", "6.2f")],
            [(r["method"], r["integration"] or "", r["h"], r["dofs"], r["error_l2"],
              r["l2_x_vci"], r["error_energy"], r["time"]["setup"], r["time"]["assemble"],
              r["time"]["solve"], r["time"]["total"], r["x_fe"]) for r in records],
        )  # fmt: skip
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
