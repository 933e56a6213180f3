# # Benchmark: block formats in explicit dynamics, symmetric factorisation in statics
#
# Two measurements, each as ratios within one run (absolute seconds on a shared machine are
# noisy; every time is the best of ``--repeats``):
#
# * **Dynamics** (issue 12, item 2): the per-step time of the rod with a Gaussian initial velocity
#   (``demos/rod_gauss.py``: FE, EFG, lagrange at ``--nodes`` nodes + particles) with the
#   stiffness blocks in PETSc's AIJ format (as assembled; with i-nodes) and as BAIJ
#   (``gdim x gdim`` blocks, the default format), both multiplied by PETSc, and as BAIJ
#   multiplied by the compiled block product (``dynamics.compiled_product``, the default product
#   with numba, issue 26 item 4): three models built alike and stepped in turns from the same
#   state, the CPU time of one product with the particle (or FE) stiffness alone, and the
#   largest relative difference of the models' displacements at the end (round-off).
# * **Statics**: the cantilever (L = 48, D = 12, Timoshenko–Goodier loads) in pure EFG and with
#   the lagrange coupling (right half particles), with Galerkin integration (symmetric saddle
#   point) and with VCI (``consistent=True``, Petrov–Galerkin: not symmetric). The assembled
#   block system is factorised by MUMPS as LU (``solver="mumps-lu"``) and as LDL^T
#   (``solver="mumps"`` picks it where the measured asymmetry is round-off; ">=": a sample's
#   lower bound proved it above, ``statics.petsc.asymmetry_above``): factorisation time
#   and MUMPS's memory (INFOG(22), MB summed over ranks), and the relative difference of the
#   two solutions.
#
# Prints tables and writes JSON (``--json``); ``--small`` is a smoke run (seconds).
#
#     python benchmarks/bench_blocks.py [--nodes 20000] [--h 0.25] [--repeats 3] [--json out.json]
#     python benchmarks/bench_blocks.py --small

# +
from __future__ import annotations

import argparse
import contextlib
import inspect
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree.dynamics.system import LinearSystem
from dolfinx_meshfree.statics.petsc import BlockSystem

import dolfinx
import numpy as np
from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI

# -


def best_product(A, repeats: int, inner: int = 20, multiply=None) -> float:
    """CPU seconds of one ``A x`` (best of ``repeats`` batches of ``inner``, slowest rank), by
    PETSc's product or by ``multiply(x, y)`` (e.g. a compiled product of ``A``)."""
    comm = A.getComm().tompi4py()
    x, y = A.createVecs()
    x.setRandom()
    multiply = A.mult if multiply is None else multiply
    best = np.inf
    for _ in range(repeats):
        comm.Barrier()
        t0 = time.process_time()
        for _ in range(inner):
            multiply(x, y)
        best = min(best, comm.allreduce(time.process_time() - t0, op=MPI.MAX) / inner)
    x.destroy()
    y.destroy()
    return best


#: The rod's variants: (name, matrix format, product) of ``LinearSystem``.
VARIANTS = (("aij", "aij", "petsc"), ("baij", "baij", "petsc"), ("compiled", "baij", "numba"))


@contextlib.contextmanager
def stiffness(fmt: str, product: str):
    """While active, explicit models store their stiffness blocks as ``fmt`` and multiply them
    by ``product`` (the defaults of :class:`~dolfinx_meshfree.dynamics.system.LinearSystem`
    replaced, for this benchmark only)."""
    init = LinearSystem.__init__
    saved = init.__defaults__
    names = list(inspect.signature(init).parameters)[-len(saved) :]
    values = dict(zip(names, saved, strict=True), matrix_format=fmt, product=product)
    init.__defaults__ = tuple(values[n] for n in names)
    try:
        yield
    finally:
        init.__defaults__ = saved


def dynamics(method: str, nodes: int, steps: int, repeats: int, comm) -> dict:
    """Per-step time of the rod in each of :data:`VARIANTS`: models built alike, stepped in
    turns from the same state; their final displacements' largest difference to the first."""
    rg = load_demo("rod_gauss")
    args = rg.parse(["--nodes", str(nodes)])
    material = mf.LinearElastic(args.E, 0.0, "strain", rho=args.rho)
    rod = mf.verification.waves.GaussianPulseRod(
        E=args.E, rho=args.rho, length=rg.LENGTH, center=args.center
    )
    dyns = {}
    for name, fmt, product in VARIANTS:
        with stiffness(fmt, product):
            dyns[name], _ = rg.build(method, args, material, comm)
        dyns[name].set_initial(velocity=rod.initial_velocity)
    dt = dyns["aij"].stable_time_step()
    per_step = dict.fromkeys(dyns, np.inf)
    product, cpu_step = dict(per_step), dict(per_step)
    for dyn in dyns.values():
        dyn.run(dyn.time + 2 * dt, dt=dt)  # warm-up (and the compiled copy made)
    for _ in range(repeats):
        for name, dyn in dyns.items():
            system = dyn.system
            K = system.fields[-1].K  # the particle stiffness (FE for pure FE)
            last = len(system.fields) - 1
            made = system.compiled_product(last, last) if name == "compiled" else None
            mult = None if made is None else made.mult
            product[name] = min(product[name], best_product(K, 2, multiply=mult))
            comm.Barrier()
            t0 = time.process_time()
            res = dyn.run(dyn.time + steps * dt, dt=dt, energy_records=2)
            cpu = comm.allreduce((time.process_time() - t0) / steps, op=MPI.MAX)
            cpu_step[name] = min(cpu_step[name], cpu)
            per_step[name] = min(
                per_step[name], comm.allreduce(res.timings["per_step"], op=MPI.MAX)
            )
    # at points, not dof by dof: two builds of a model on several ranks need not number (or
    # own) their dofs alike
    x = np.linspace(0.0, rg.LENGTH, 401)
    probes = np.column_stack([x, np.full_like(x, 0.5 * rg.HEIGHT)])
    u = {f: d.displacement_at(probes) for f, d in dyns.items()}
    norm = float(np.linalg.norm(u["aij"]))
    diff = max(float(np.linalg.norm(u[n] - u["aij"])) for n in dyns)
    sizes = dyns["baij"].num_dofs()
    rec = {"kind": "dynamics", "method": method, "dofs": sizes["fe_dofs"] + sizes["particle_dofs"],
           "steps": steps, "relative_difference": diff / norm, "ranks": comm.size,
           "dolfinx_version": mf.DOLFINX_VERSION}  # fmt: skip
    for name in dyns:
        rec.update({f"step_{name}": per_step[name], f"cpu_step_{name}": cpu_step[name],
                    f"product_{name}": product[name]})  # fmt: skip
    for dyn in dyns.values():
        dyn.destroy()
    return rec


def cantilever(comm, method: str, h: float, consistent: bool):
    """The Timoshenko–Goodier cantilever, pure EFG or lagrange (right half particles)."""
    mat = mf.LinearElastic(3e7, 0.3)
    beam = mf.TimoshenkoBeam(mat)
    nx, ny = round(48 / h), round(12 / h)
    msh = dolfinx.mesh.create_rectangle(
        comm, [np.array([0, -6.0]), np.array([48.0, 6.0])], [nx, ny],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    if method == "efg":
        problem = mf.EFGElasticity(mf.ParticleSet.from_cells(msh, h), mat, consistent=consistent)
    else:
        n = msh.topology.index_map(2).size_local
        xc = msh.geometry.x[mf._compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
        patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 24.0), h)
        V = mf._compat.vector_function_space(msh)
        problem = mf.CoupledElasticity(V, patch, mat, coupling=method, consistent=consistent)
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0)), beam.displacement)
    problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48)), beam.traction)
    return problem


@contextlib.contextmanager
def timed_direct_solves(repeats: int, out: dict):
    """While active, every ``BlockSystem.solve`` also factorises its system ``repeats`` times
    by LU and by the automatic choice (alternating) and records the best of each in ``out``."""
    original = BlockSystem.solve

    def solve(self, solver="mumps", *args, **kwargs):
        for _ in range(repeats):
            for name in ("mumps-lu", "mumps"):
                parts = original(self, name)
                keys = ("check", "factor", "factor_cpu", "solve")
                rec = out.setdefault(name, dict.fromkeys(keys, np.inf))
                for key in keys:
                    t = self.comm.tompi4py().allreduce(self.stats[key], op=MPI.MAX)
                    rec[key] = min(rec[key], t)
                keep = ("factorisation", "asymmetry", "asymmetry_sampled", "memory_mb")
                rec.update({k: self.stats[k] for k in keep})
                rec["x"] = np.concatenate(parts)
        return original(self, solver, *args, **kwargs)

    BlockSystem.solve = solve
    try:
        yield
    finally:
        BlockSystem.solve = original


def statics(method: str, h: float, consistent: bool, repeats: int, comm) -> dict:
    problem = cantilever(comm, method, h, consistent)
    out: dict = {}
    with timed_direct_solves(repeats, out):
        problem.solve("mumps")
    lu, auto = out["mumps-lu"], out["mumps"]
    diff = np.sqrt(comm.allreduce(float(np.sum((lu["x"] - auto["x"]) ** 2))))
    norm = np.sqrt(comm.allreduce(float(np.sum(lu["x"] ** 2))))
    return {
        "kind": "statics",
        "method": method,
        "integration": "vci" if consistent else "galerkin",
        "h": h,
        "dofs": comm.allreduce(lu["x"].size),
        "asymmetry": auto["asymmetry"],
        "asymmetry_sampled": auto["asymmetry_sampled"],
        "chosen": auto["factorisation"],
        "factor_lu": lu["factor"],
        "factor_auto": auto["factor"],
        "symmetry_check_auto": auto["check"],
        "factor_cpu_lu": lu["factor_cpu"],
        "factor_cpu_auto": auto["factor_cpu"],
        "solve_lu": lu["solve"],
        "solve_auto": auto["solve"],
        "memory_mb_lu": lu["memory_mb"],
        "memory_mb_auto": auto["memory_mb"],
        "relative_difference": diff / norm,
        "ranks": comm.size,
        "dolfinx_version": mf.DOLFINX_VERSION,
    }


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description="AIJ, BAIJ and compiled steps, LU vs LDL^T solves")
    p.add_argument("--nodes", type=int, default=20000, help="rod: FE nodes + particles (about)")
    p.add_argument("--steps", type=int, default=40, help="rod: steps per timing")
    p.add_argument("--methods", nargs="+", default=["fe", "efg", "lagrange"])
    p.add_argument("--h", type=float, nargs="+", default=[0.25], help="cantilever spacings")
    p.add_argument("--statics", nargs="+", default=["efg", "lagrange"])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--small", action="store_true", help="smoke run (seconds)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    if args.small:
        args.nodes, args.steps, args.h, args.repeats = 600, 3, [2.0], 1
    comm = MPI.COMM_WORLD
    recs = [dynamics(m, args.nodes, args.steps, args.repeats, comm) for m in args.methods]
    for h in args.h:
        for m in args.statics:
            for consistent in (False, True):
                recs.append(statics(m, h, consistent, args.repeats, comm))
    if comm.rank == 0:
        print(f"\nRod, per step (wall and CPU) and one stiffness product (CPU), ms, best of "
              f"{args.repeats}, {comm.size} rank(s)")  # fmt: skip
        timed = {"step": "step", "cpu_step": "CPU step", "product": "product"}
        columns = [("method", ""), ("dofs", "d")]
        for label in timed.values():
            columns += [(f"{label} AIJ", ".3f"), (f"{label} BAIJ", ".3f"),
                        (f"{label} compiled", ".3f"), ("BAIJ/compiled", ".2f")]  # fmt: skip
        rows = [
            [r["method"], r["dofs"],
             *(v for k in timed for v in (1e3 * r[f"{k}_aij"], 1e3 * r[f"{k}_baij"],
                                          1e3 * r[f"{k}_compiled"],
                                          ratio(r[f"{k}_baij"], r[f"{k}_compiled"]))),
             r["relative_difference"]]
            for r in recs if r["kind"] == "dynamics"
        ]  # fmt: skip
        print_table([*columns, ("rel. diff u", ".1e")], rows, markdown=True)
        print(f"\nCantilever, MUMPS factorisation (wall and CPU s, best of {args.repeats}) and "
              "memory (INFOG(22), MB)")  # fmt: skip
        columns = [("method", ""), ("integration", ""), ("dofs", "d"), ("asymmetry", ""),
                   ("chosen", ""), ("LU", ".3f"), ("auto", ".3f"), ("LU/auto", ".2f"),
                   ("CPU LU", ".3f"), ("CPU auto", ".3f"), ("LU/auto", ".2f"), ("MB LU", ""),
                   ("MB auto", ""), ("rel. diff", ".1e")]  # fmt: skip
        rows = [
            [r["method"], r["integration"], r["dofs"],
             f"{'>= ' if r['asymmetry_sampled'] else ''}{r['asymmetry']:.1e}", r["chosen"],
             r["factor_lu"], r["factor_auto"], ratio(r["factor_lu"], r["factor_auto"]),
             r["factor_cpu_lu"], r["factor_cpu_auto"],
             ratio(r["factor_cpu_lu"], r["factor_cpu_auto"]), r["memory_mb_lu"],
             r["memory_mb_auto"], r["relative_difference"]]
            for r in recs if r["kind"] == "statics"
        ]  # fmt: skip
        print_table(columns, rows, markdown=True)
        write_json(args.json, recs)
    return recs


if __name__ == "__main__":
    main()
