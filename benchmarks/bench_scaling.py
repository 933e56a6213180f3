# # Benchmark: speed and scale (issue 12)
#
# Four parts, each printed as a table and written to JSON (``--json``, one record per run),
# on one rank or, under ``mpirun -n 2``, on every rank with the one-rank reference of each case
# in the same run for the speed-ups (a copy on every rank at once, so that it sees the machine's
# load as the parallel run does: :func:`in_turns`):
#
# 1. **MLS tabulation with gradients**, points per second, the numpy reference and the compiled
#    (numba) path in the same run, for the 2D linear, 2D quadratic and 3D linear bases (quartic
#    weight) at three sizes: particles on a jittered grid in the unit square / cube, four
#    evaluation points per particle at random inside. Next to the speed, the largest difference
#    between the two paths (relative to the largest entry, values and gradients): the cost of
#    speed in accuracy. The first compiled call (compilation, or loading numba's on-disk cache)
#    is timed separately and excluded; timings are medians of ``--repeats``. The compiled path
#    runs on one thread and on two (``--threads``, set through ``DOLFINX_MESHFREE_THREADS``):
#    per CPU second the figure per core, per wall-clock second the parallel speed. One rank
#    only (``--no-mls`` skips it).
# 2. **EFG's MLS backends** on the cantilever (``demos/cantilever.py``, Timoshenko beam): pure
#    EFG with the numpy and the compiled path at the largest ``--h``, the same error
#    (``--backends``; on in ``--small``).
# 3. **Static cantilever at equal dofs**: pure FE, pure EFG and the lagrange coupling with the
#    free-end 25 % and 50 % of the beam in particles (``--patch-fraction``), all with nodes or
#    particles at spacing ``h`` (equal dofs up to the duplicated interface column), at each
#    ``--h``: total time (setup + assembly + solve, FE JIT excluded, the slowest rank), the
#    peak resident memory of the case (the largest rank's, the kernel's high-water mark reset
#    before each case) and its rise over the memory at the case's start, the relative L2 error
#    against the exact solution, and the ratio to FE's time at the same ``h`` in the same run.
#    On several ranks the coupled models run on ``mf.balanced_mesh`` (a patch cell weighing the
#    EFG/FE time ratio measured by the references at the same ``h``, as
#    ``benchmarks/bench_balance.py`` does; ``--no-balance``: DOLFINx's partition). ``--solver``
#    passes through to ``CoupledElasticity.solve(solver=...)``.
# 4. **Explicit rod** (``demos/rod_gauss.py``, Gaussian pulse, about ``--nodes`` nodes +
#    particles, particle : node ratio 4 in the coupled half): the time per step of FE, EFG and
#    the couplings of ``--rod-methods`` (energy records and outputs are outside the timed
#    loop), its ratio to FE's step, the peak memory of the build, the relative L2 velocity error
#    against the exact (d'Alembert) solution at the end and the largest rank's share of the
#    stiffness entries. On several ranks the coupled rods run on ``mf.balanced_mesh``, a patch
#    cell weighing ``ratio x`` (EFG/FE step) as the references measure it (``--small``: ``ratio
#    x`` (EFG/FE stiffness entries), the same on every run: the share a test checks no longer
#    follows the machine's load, which once put 57 % on a rank of a busy CI machine). By
#    default ``balanced_mesh`` splits each kind of cell on its own (``by_class``), so the weight
#    then only tells the patch cells from the FE cells; the demo's own ``--partition`` is set
#    to ``dolfinx`` here, so that ``--no-balance`` measures DOLFINx's partition.
#
# Timings of parts 3 and 4 are the fastest of ``--repeats`` runs (``--rod-repeats`` runs of
# ``--steps`` steps), their median recorded too: on a shared machine the fastest run is the one
# least disturbed by other processes. On several ranks each case's one-rank reference and its
# parallel run are timed in turns (:func:`in_turns`).
#
# Run with ``OMP_NUM_THREADS=1`` (as recorded in the JSON); the numbers are machine dependent:
# compare the ratios of one run (the load average of the machine is printed with every table).
# ``--small`` is a smoke run of about ten seconds for CI (no timing is checked anywhere, nor does
# any checked figure depend on one; the test checks the errors against the exact solutions).
# This supersedes the MLS part of ``benchmarks/bench_tabulation.py``.
#
#     OMP_NUM_THREADS=1 python benchmarks/bench_scaling.py [--h 0.5 0.25 0.125] [--nodes 20000]
#     OMP_NUM_THREADS=1 mpirun -n 2 python benchmarks/bench_scaling.py --no-mls
#     python benchmarks/bench_scaling.py --small

# +
from __future__ import annotations

import argparse
import contextlib
import ctypes
import gc
import os
import time
from collections.abc import Callable

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.approx import mls as mls_module

import numpy as np
from harness import load_demo, print_table, ratio, write_json
from mpi4py import MPI
from petsc4py import PETSc

# -

#: (gdim, basis, dilation, particles per side at the three sizes, and with --small)
CASES = [
    (2, "linear", 2.0, (50, 100, 200), (20,)),
    (2, "quadratic", 2.8, (25, 50, 100), (12,)),
    (3, "linear", 2.0, (10, 16, 25), (6,)),
]


def particles_and_points(gdim: int, n_side: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Jittered grid of ``(n_side + 1)^gdim`` particles in the unit box, and four random
    evaluation points per particle inside it."""
    rng = np.random.default_rng(seed)
    ax = np.linspace(0.0, 1.0, n_side + 1)
    P = np.stack(np.meshgrid(*[ax] * gdim, indexing="ij"), axis=-1).reshape(-1, gdim)
    inner = np.all((P > 0) & (P < 1), axis=1)
    P[inner] += rng.uniform(-0.3, 0.3, (inner.sum(), gdim)) / n_side
    x = rng.uniform(0.0, 1.0, (4 * P.shape[0], gdim))
    return P, x


def spatial_order(x: np.ndarray, n_side: int) -> np.ndarray:
    """An ordering of the points ``x`` by the cells of the particle grid (lexicographic), as
    quadrature points come cell by cell: the random points' order is the worst case for the
    caches, this one the usual case."""
    cells = np.floor(x * n_side).astype(np.int64)
    return np.lexsort(cells.T[::-1])


def median_time(fn, repeats: int) -> tuple[float, float]:
    """Median wall-clock and CPU (process) time of ``fn``: on a shared machine the CPU time is
    the steadier figure of the two."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.median(cpu))


def max_difference(a: mf.ShapeTable, b: mf.ShapeTable) -> float:
    """Largest difference of values and gradients, relative to the largest entry of each."""
    out = 0.0
    for ma, mb in zip([a.values, *a.gradients], [b.values, *b.gradients], strict=True):
        out = max(out, float(abs(ma - mb).max() / abs(ma).max()))
    return out


def set_threads(n: int | None) -> None:
    """Let the compiled path use ``n`` threads (``DOLFINX_MESHFREE_THREADS``; None: unset)."""
    if n is None:
        os.environ.pop("DOLFINX_MESHFREE_THREADS", None)
    else:
        os.environ["DOLFINX_MESHFREE_THREADS"] = str(n)


def bench_mls(sizes_index: str, repeats: int, threads: list[int]) -> list[dict]:
    records = []
    runs = ["numpy"]
    if jit.AVAILABLE:
        runs += ["numba"] + [f"numba{t}" for t in threads if t != 1]  # 1 thread always
    saved = os.environ.get("DOLFINX_MESHFREE_THREADS")
    for gdim, basis, dilation, sizes, small in CASES:
        for n_side in small if sizes_index == "small" else sizes:
            P, x = particles_and_points(gdim, n_side)
            tables, rec = {}, {}
            for run in runs:
                backend = "numpy" if run == "numpy" else "numba"
                if backend == "numba":
                    set_threads(int(run[5:] or 1))
                mls = mf.MLS(P, dilation=dilation, basis=basis, backend=backend)
                t0 = time.perf_counter()
                mls.tabulate(x[:8])  # compile or load the cache; builds the cell list
                first = time.perf_counter() - t0
                tables[run] = mls.tabulate(x)
                t, cpu = median_time(lambda mls=mls, x=x: mls.tabulate(x), repeats)
                if run == "numba":  # the same points in spatial order (as quadrature by cell)
                    xs = x[spatial_order(x, n_side)]
                    mls.tabulate(xs)
                    ts, cs = median_time(lambda mls=mls, xs=xs: mls.tabulate(xs), repeats)
                    rec["numba_sorted"] = {
                        "time": ts,
                        "cpu_time": cs,
                        "points_per_second": x.shape[0] / ts,
                        "points_per_cpu_second": x.shape[0] / cs,
                    }
                rec[run] = {
                    "time": t,
                    "cpu_time": cpu,
                    "points_per_second": x.shape[0] / t,
                    "points_per_cpu_second": x.shape[0] / cpu,
                    "first": first,
                }
            records.append(
                {
                    "kind": "mls",
                    "gdim": gdim,
                    "basis": basis,
                    "weight": "quartic",
                    "dilation": dilation,
                    "particles": P.shape[0],
                    "points": x.shape[0],
                    "pairs_per_point": tables["numpy"].values.nnz / x.shape[0],
                    **{f"time_{b}": r["time"] for b, r in rec.items()},
                    **{f"cpu_time_{b}": r["cpu_time"] for b, r in rec.items()},
                    **{f"points_per_second_{b}": r["points_per_second"] for b, r in rec.items()},
                    **{
                        f"points_per_cpu_second_{b}": r["points_per_cpu_second"]
                        for b, r in rec.items()
                    },
                    "time_first_call_numba": rec.get("numba", {}).get("first"),
                    "max_difference": (
                        max_difference(tables["numpy"], tables["numba"])
                        if "numba" in tables
                        else None
                    ),
                    "repeats": repeats,
                    "max_difference_threads": max(
                        (max_difference(tables["numba"], tables[r]) for r in runs[2:]),
                        default=None,
                    ),
                }
            )
    set_threads(None if saved is None else int(saved))
    return records


def report(mls: list[dict]) -> None:
    print(
        f"MLS tabulation with gradients, quartic weight, 1 rank (OMP_NUM_THREADS="
        f"{os.environ.get('OMP_NUM_THREADS', 'unset')}), median of {mls[0]['repeats']}; "
        "first numba call (compile or cache load) excluded"
    )
    print(
        "points per second of wall-clock time (per CPU second in brackets); numba2: 2 threads; "
        "numba sorted: the same points in spatial order"
    )
    two = "points_per_second_numba2" in mls[0]

    def speeds(r: dict, run: str) -> str | None:  # per second (per CPU second)
        if f"points_per_second_{run}" not in r:
            return None
        return f"{r[f'points_per_second_{run}']:.3g} ({r[f'points_per_cpu_second_{run}']:.3g})"

    runs = ["numpy", "numba", "numba_sorted", *(["numba2"] if two else [])]
    columns = [("case", "12"), ("particles", "9d"), ("points", "8d"), ("pairs/pt", "8.1f"),
               *((f"{run.replace('_', ' ')} pts/s", "21") for run in runs),
               ("speed-up", "8.1f"), ("1st call s", "10.3f"), ("max diff", "9.1e")]  # fmt: skip
    rows = [
        [f"{r['gdim']}D {r['basis']:>9}", r["particles"], r["points"], r["pairs_per_point"],
         *(speeds(r, run) for run in runs),
         ratio(r.get("points_per_second_numba"), r["points_per_second_numpy"]),
         r["time_first_call_numba"], r["max_difference"]]
        for r in mls
    ]  # fmt: skip
    print_table(columns, rows)


# ## Peak memory of a case
#
# ``getrusage`` gives the process's peak since it started; Linux lets a process reset its
# high-water mark (``VmHWM``, by writing 5 to ``/proc/self/clear_refs``), so each case gets its
# own peak. Elsewhere the figure is ``None``.


# +
def _proc_status_mb(key: str) -> float | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


@contextlib.contextmanager
def peak_memory(comm, out: dict):
    """Record in ``out`` the peak resident memory (MB) of the block, the largest rank's
    (``peak_mb``), and its rise over the resident memory at entry (``peak_rise_mb``). The
    earlier cases' garbage is collected and the allocator's free memory returned to the system
    first (``malloc_trim``), so that the peak is this case's."""
    gc.collect()
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        start = _proc_status_mb("VmRSS")
    except OSError:
        start = None
    yield
    peak = _proc_status_mb("VmHWM") if start is not None else None
    known = comm.allreduce(peak is not None, op=MPI.LAND)
    out["peak_mb"] = comm.allreduce(peak, op=MPI.MAX) if known else None
    out["peak_rise_mb"] = comm.allreduce(peak - start, op=MPI.MAX) if known else None


@contextlib.contextmanager
def default_solver(solver: str | None):
    """While active, ``CoupledElasticity.solve`` defaults to ``solver`` (``None``: unchanged):
    ``--solver`` passes through to the coupled problems' ``solver=`` argument."""
    solve = mf.CoupledElasticity.solve
    saved = solve.__defaults__
    if solver is not None:
        solve.__defaults__ = (solver, *saved[1:])
    try:
        yield
    finally:
        solve.__defaults__ = saved


def load() -> tuple[float, float, float]:
    """The machine's load average (1, 5, 15 minutes): the machine is shared."""
    return tuple(round(v, 2) for v in os.getloadavg())


#: A prepared case: ``run()`` times it once and returns its record; ``close()`` frees it.
Prepared = tuple[Callable[[], dict], Callable[[], None]]


def in_turns(comm, cases: list, prepare, weights_of, key: str, repeats: int) -> list[dict]:
    """Each case on one rank (the reference) and, on several ranks, on ``comm``, timed in turns
    ``repeats`` times, the fastest run of each kept (on a shared machine the least disturbed;
    the median of ``key`` is recorded too) with the speed-up (the reference's ``key`` over the
    parallel run's). ``prepare(comm, case, weights)`` returns a :data:`Prepared` case;
    ``weights_of(references so far)`` the balance weights of the parallel run (``None``:
    DOLFINx's partition). Returns the references, then the parallel runs (none on one rank).

    On several ranks every rank runs its own copy of the reference at the same time (alone on
    ``MPI.COMM_SELF``) and the reference's times are the mean over the copies: it sees the same
    load of the machine as the parallel run, taken in turns with it (on an idle machine with a
    core per rank: the time of a serial run), not a waiting rank that polls (MPI waits spin)
    beside a lone worker."""
    refs: list[dict] = []
    runs: list[dict] = []
    for case in cases:
        prepared = [prepare(MPI.COMM_SELF, case, None)]
        if comm.size > 1:
            prepared.append(prepare(comm, case, weights_of(refs)))
        timed: list[list[dict]] = [[] for _ in prepared]
        for _ in range(repeats):
            for (run, _), out in zip(prepared, timed, strict=True):
                comm.Barrier()
                out.append(run())
        for _, close in prepared:
            close()
        if comm.size > 1:  # the reference's times: the mean over its copies
            for r in timed[0]:
                for k in [k for k in r if k.startswith("time_")]:
                    r[k] = float(np.mean(comm.allgather(r[k])))
        best = []  # the fastest run's times, the rest (errors: the same state) the last run's
        for out in timed:
            fastest = min(out, key=lambda r: r[key])
            best.append({**out[-1], **{k: v for k, v in fastest.items() if k.startswith("time_")}})
            best[-1].update(repeats=repeats, **{f"{key}_median": median_of(out, key)})
        refs.append(best[0])
        if comm.size > 1:
            best[0]["one_rank_reference"] = True
            best[1]["speedup"] = best[0][key] / best[1][key]
            runs.append(best[1])
    return refs + runs


def median_of(records: list[dict], key: str) -> float:
    return float(np.median([r[key] for r in records]))


def ratios_to_fe(records: list[dict], key: str, group: tuple[str, ...]) -> None:
    """``<key>_ratio_to_fe``: each record's ``key`` over FE's in the same group (same run)."""
    fe = {tuple(r[g] for g in group): r[key] for r in records if r["method"] == "fe"}
    for r in records:
        ref = fe.get(tuple(r[g] for g in group))
        r[f"{key}_ratio_to_fe"] = None if ref is None else r[key] / ref


# -


# ## Static cantilever at equal dofs: FE, EFG, lagrange with 25 % and 50 % patches


# +
def static_case(comm, case: tuple, solver: str | None) -> dict:
    """One cantilever run on ``comm`` through ``demos/cantilever.py``'s functions (its ``main``
    runs on MPI.COMM_WORLD); ``case = (method, h, patch fraction, balance weight or None)``."""
    cantilever = load_demo("cantilever")
    method, h, fraction, weight = case
    argv = ["--method", method, "--h", str(h), "--no-check"]
    argv += ["--patch-fraction", str(fraction or 0.5)]
    if weight is not None:
        argv += ["--balance", str(weight)]
    args = cantilever.parse(argv)
    material = mf.LinearElastic(args.E, args.nu, args.plane)
    beam = mf.TimoshenkoBeam(material, L=args.L, D=args.D, P=args.P)
    mem: dict = {}
    comm.Barrier()
    with peak_memory(comm, mem), default_solver(solver):
        msh = cantilever.make_mesh(comm, args, h)
        if weight is not None:
            msh = mf.balanced_mesh(msh, cantilever.patch_weight(args))
        errors, sizes, timings, _ = cantilever.run_method(msh, args, beam, material, h, method)
    timings = {k: comm.allreduce(v, op=MPI.MAX) for k, v in timings.items()}
    return {
        "kind": "static",
        "method": method,
        "patch_fraction": fraction,
        "h": h,
        "ranks": comm.size,
        "balanced": weight is not None,
        "weight": weight,
        "solver": solver if method in mf.COUPLINGS else None,
        "mls_backend": mls_module.DEFAULT_BACKEND if method != "fe" else None,
        "dofs": sizes["fe_dofs"] + sizes["particle_dofs"],
        **{k: sizes[k] for k in ("fe_dofs", "particle_dofs", "multiplier_dofs")},
        "error_l2": errors["l2"],
        "error_energy": errors["energy"],
        **{f"time_{k}": timings[k] for k in ("setup", "assemble", "solve")},
        "time_total": timings["setup"] + timings["assemble"] + timings["solve"],
        **mem,
        "load": load(),
    }


def bench_static(
    comm,
    hs: list[float],
    fractions: list[float],
    balance: bool,
    solver: str | None,
    repeats: int,
) -> list[dict]:
    """FE, EFG and the lagrange coupling per patch fraction at each ``h`` (coarsest first, so
    that a case's peak memory is not an earlier case's): on one rank and (several ranks) on
    ``comm``, the couplings on the balanced mesh, in turns (:func:`in_turns`)."""
    cantilever = load_demo("cantilever")
    material = mf.LinearElastic(3e7, 0.3)
    cantilever.warm_jit(
        cantilever.parse(["--method", "fe", "lagrange", "--no-check"]),
        material,
        mf.TimoshenkoBeam(material),
    )
    cases = []
    for h in sorted(hs, reverse=True):  # FE and EFG first: the balance weight needs them
        cases += [("fe", h, None), ("efg", h, None), *(("lagrange", h, f) for f in fractions)]

    def prepare(c, case, weights):
        weight = weights[case[1]] if weights and case[0] in mf.COUPLINGS else None
        return (lambda: static_case(c, (*case, weight), solver)), (lambda: None)

    def weights_of(refs):  # a patch cell costs EFG's time per cell: the EFG/FE ratio at each h
        t = {(r["method"], r["h"]): r["time_total"] for r in refs}
        return {h: t["efg", h] / t["fe", h] for h in hs if ("efg", h) in t} if balance else None

    records = in_turns(comm, cases, prepare, weights_of, "time_total", repeats)
    ratios_to_fe(records, "time_total", ("h", "ranks"))
    ratios_to_fe(records, "dofs", ("h", "ranks"))
    return records


def bench_backends(comm, h: float) -> list[dict]:
    """Pure EFG on the cantilever with each MLS backend (the same discretisation)."""
    records = []
    saved = mls_module.DEFAULT_BACKEND
    try:
        for backend in ["numpy", "numba"] if jit.AVAILABLE else ["numpy"]:
            mls_module.DEFAULT_BACKEND = backend
            records.append({**static_case(comm, ("efg", h, None, None), None), "kind": "backend"})
    finally:
        mls_module.DEFAULT_BACKEND = saved
    return records


# -


# ## Explicit rod: time per step


# +
@contextlib.contextmanager
def balanced_rod(rg, weight: float | None):
    """While active, ``demos/rod_gauss.py`` builds its rods on ``mf.balanced_mesh``, the
    particle half's cells weighing ``weight`` FE cells (``None``: DOLFINx's partition)."""
    original = rg.rod_mesh
    if weight is not None:

        def rod_mesh(comm, h):
            cell_weight = lambda x: np.where(x[0] > 0.5 * rg.LENGTH, weight, 1.0)  # noqa: E731
            return mf.balanced_mesh(original(comm, h), cell_weight)

        rg.rod_mesh = rod_mesh
    try:
        yield
    finally:
        rg.rod_mesh = original


def stiffness_entries(comm, dyn) -> list[float]:
    """The stored stiffness entries of each rank (the work of ``K u``)."""
    local = PETSc.Mat.InfoType.LOCAL  # (the default sums over the ranks)
    nz = sum(f.K.getInfo(local)["nz_used"] for f in dyn.system.fields)
    nz += sum(B.getInfo(local)["nz_used"] for B in getattr(dyn.system, "blocks", {}).values())
    return comm.allgather(float(nz))


def rank_share(comm, dyn) -> float:
    """The largest rank's share of the stored stiffness entries (the work of ``K u``)."""
    per_rank = stiffness_entries(comm, dyn)
    return max(per_rank) / sum(per_rank)


def rod_case(comm, case: tuple, steps: int) -> Prepared:
    """The rod of ``demos/rod_gauss.py`` on ``comm`` (``case = (method, nodes, balance weight
    or None)``), built, set to the pulse and warmed up by 2 steps; each ``run()`` times
    ``steps`` more steps (the slowest rank's time per step; energy records are outside the
    timed loop) and gives the velocity error against the exact solution at its end."""
    rg = load_demo("rod_gauss")
    method, nodes, weight = case
    args = rg.parse(["--nodes", str(nodes), "--no-check", "--partition", "dolfinx"])
    material = mf.LinearElastic(args.E, 0.0, "strain", rho=args.rho)
    rod = mf.verification.waves.GaussianPulseRod(
        E=args.E, rho=args.rho, length=rg.LENGTH, center=args.center
    )
    mem: dict = {}
    comm.Barrier()
    t0 = time.perf_counter()
    with peak_memory(comm, mem), balanced_rod(rg, weight):
        dyn, _ = rg.build(method, args, material, comm)
        dyn.set_initial(velocity=rod.initial_velocity)
    setup = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    dt = dyn.stable_time_step()
    dyn.run(2 * dt, dt=dt, energy_records=1)  # warm-up
    sizes = dyn.num_dofs()
    fixed = {
        "kind": "rod",
        "method": method,
        "nodes": nodes,
        "ranks": comm.size,
        "balanced": weight is not None,
        "weight": weight,
        "dofs": sizes["fe_dofs"] + sizes["particle_dofs"],
        **sizes,
        "largest_share": rank_share(comm, dyn),
        "stiffness_entries": sum(stiffness_entries(comm, dyn)),
        "steps": steps,
        "dt": dt,
        "time_setup": setup,
        **mem,
    }

    def run() -> dict:
        res = dyn.run(dyn.time + steps * dt, dt=dt, energy_records=1)
        return {
            **fixed,
            "time": dyn.time,
            "time_per_step": comm.allreduce(res.timings["per_step"], op=MPI.MAX),
            "error_velocity": dyn.velocity_error(rod.velocity),
            "energy_drift": res.energy_drift,
            "load": load(),
        }

    return run, dyn.destroy


def bench_rod(
    comm,
    methods: list[str],
    nodes: int,
    steps: int,
    repeats: int,
    balance: bool,
    balance_by: str = "time",
) -> list[dict]:
    """Per-step times of the rod's methods on one rank and (several ranks) on ``comm``, in
    turns (:func:`in_turns`), the couplings on the balanced mesh (weight from the references:
    a patch cell holds ``ratio`` particles at EFG's cost per particle, the cost by their time
    per step, or by their stiffness entries with ``balance_by="entries"``: the same on every
    run, as a check of the balance needs)."""
    rg = load_demo("rod_gauss")
    args = rg.parse(
        ["--nodes", str(nodes), "--method", *methods, "--no-check", "--partition", "dolfinx"]
    )
    rg.warm_jit(args, mf.LinearElastic(args.E, 0.0, "strain", rho=args.rho))
    pure = [m for m in methods if m in ("fe", "efg")]  # first: the balance weight needs them

    def prepare(c, method, weight):
        weight = weight if method not in ("fe", "efg") else None
        return rod_case(c, (method, nodes, weight), steps)

    def weights_of(refs):
        key = "time_per_step" if balance_by == "time" else "stiffness_entries"
        t = {r["method"]: r[key] for r in refs}
        if not balance or not {"fe", "efg"} <= set(t):
            return None
        return args.ratio * t["efg"] / t["fe"]

    cases = pure + [m for m in methods if m not in pure]
    records = in_turns(comm, cases, prepare, weights_of, "time_per_step", repeats)
    ratios_to_fe(records, "time_per_step", ("nodes", "ranks"))
    return records


# -


# ## Tables


# +
def _ranks_and_mesh(r: dict) -> tuple[str, str]:
    """The ranks (``1*``: the one-rank reference) and the mesh of a static or rod record."""
    ranks = f"{r['ranks']}" + ("*" if r.get("one_rank_reference") else "")
    return ranks, "balanced" if r["balanced"] else "default"


def report_static(static: list[dict], backends: list[dict]) -> None:
    if backends:
        print(f"\nPure EFG, MLS backends (load {load()})")
        for r in backends:
            print(f"  {r['mls_backend']:>6}: h {r['h']:g}, L2 error {r['error_l2']:.6e}, "
                  f"total {r['time_total']:.3f} s")  # fmt: skip
    if not static:
        return
    print(
        f"\nStatic cantilever at equal dofs (spacing h), lagrange patch at the free end; "
        f"slowest rank's time, best of {static[0]['repeats']}, FE JIT excluded; peak = largest "
        f"rank's resident peak, rise = above the resident memory at the case's start (load "
        f"{load()})"
    )
    columns = [("method", ">8"), ("patch", "5.2f"), ("h", "6.3g"), ("ranks", "5"),
               ("mesh", "8"), ("dofs", "7d"), ("L2 error", "9.2e"), ("setup s", "8.3f"),
               ("assem s", "8.3f"), ("solve s", "8.3f"), ("total s", "8.3f"), ("x FE", "6.2f"),
               ("peak MB", "8.0f"), ("rise MB", "8.0f"), ("speedup", "7.2f")]  # fmt: skip
    rows = [
        [r["method"], r["patch_fraction"], r["h"], *_ranks_and_mesh(r), r["dofs"], r["error_l2"],
         r["time_setup"], r["time_assemble"], r["time_solve"], r["time_total"],
         r["time_total_ratio_to_fe"], r["peak_mb"], r["peak_rise_mb"], r.get("speedup")]
        for r in static
    ]  # fmt: skip
    print_table(columns, rows)
    if any(r.get("one_rank_reference") for r in static):
        print("(ranks 1*: the one-rank reference, a copy on every rank at once, mean time)")


def report_rod(rod: list[dict]) -> None:
    if not rod:
        return
    print(
        f"\nExplicit rod (Gaussian pulse), time per step (best of {rod[0]['repeats']} x "
        f"{rod[0]['steps']} steps, slowest rank; median in brackets), ratio to FE's step "
        f"(load {load()})"
    )
    columns = [("method", ">9"), ("ranks", "5"), ("mesh", "8"), ("dofs", "7d"),
               ("share", "6.3f"), ("step ms", "8.3f"), ("(median)", "8"), ("x FE", "6.2f"),
               ("speedup", "7.2f"), ("setup s", "8.2f"), ("peak MB", "8.0f"),
               ("rise MB", "8.0f"), ("v error", "9.2e")]  # fmt: skip
    rows = [
        [r["method"], *_ranks_and_mesh(r), r["dofs"], r["largest_share"],
         1e3 * r["time_per_step"], f"({1e3 * r['time_per_step_median']:6.3f})",
         r["time_per_step_ratio_to_fe"], r.get("speedup"), r["time_setup"], r["peak_mb"],
         r["peak_rise_mb"], r["error_velocity"]]
        for r in rod
    ]  # fmt: skip
    print_table(columns, rows)
    print("(share: the largest rank's share of the stiffness entries; ranks 1*: the one-rank "
          "reference, a copy on every rank at once, mean time)")  # fmt: skip


# -


# ## Driver


# +
def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description="speed and scale (issue 12)")
    p.add_argument("--small", action="store_true", help="a smoke run of about a minute (CI)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--h", nargs="+", type=float, default=[0.5, 0.25, 0.125], help="static sizes")
    p.add_argument("--patch-fraction", nargs="+", type=float, default=[0.25, 0.5])
    p.add_argument("--solver", default=None, help="the coupled problems' solve(solver=...)")
    p.add_argument("--nodes", type=int, default=20000, help="rod: nodes + particles (about)")
    p.add_argument("--steps", type=int, default=10, help="rod: steps per timed run")
    p.add_argument("--rod-repeats", type=int, default=30, help="rod: timed runs (best taken)")
    p.add_argument("--rod-methods", nargs="+", default=["fe", "efg", "lagrange", "bridging"])
    p.add_argument("--no-balance", action="store_true", help="DOLFINx's partition everywhere")
    p.add_argument("--backends", action="store_true", help="EFG with each MLS backend")
    for part in ("mls", "static", "rod"):
        p.add_argument(f"--no-{part}", action="store_true", help=f"skip the {part} part")
    p.add_argument("--json", default=None)
    p.add_argument(
        "--threads", nargs="+", type=int, default=[1, 2], help="MLS: threads of the compiled path"
    )
    args = p.parse_args(argv)
    if args.small:
        args.repeats, args.h, args.nodes, args.steps, args.rod_repeats = 1, [3.0, 1.5], 600, 5, 1
        args.backends = True
    comm = MPI.COMM_WORLD
    mls = []
    if not args.no_mls:  # one rank: the others wait
        mls = comm.bcast(
            bench_mls("small" if args.small else "full", args.repeats, args.threads)
            if comm.rank == 0
            else None
        )
    backends = bench_backends(comm, max(args.h)) if args.backends else []
    static = []
    if not args.no_static:
        static = bench_static(
            comm, args.h, args.patch_fraction, not args.no_balance, args.solver, args.repeats
        )
    rod = []
    if not args.no_rod:
        rod = bench_rod(
            comm, args.rod_methods, args.nodes, args.steps, args.rod_repeats,
            not args.no_balance, "entries" if args.small else "time",
        )  # fmt: skip
    env = {
        "ranks_total": comm.size,
        "dolfinx_version": mf.DOLFINX_VERSION,
        "numba": jit.AVAILABLE,
        "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS"),
        "NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS"),
    }
    records = [{**r, **env} for r in mls + backends + static + rod]
    if comm.rank == 0:
        if mls:
            report(mls)
        report_static(static, backends)
        report_rod(rod)
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
