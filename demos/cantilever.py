# # Timoshenko cantilever: finite elements against element-free Galerkin
#
# The cantilever of Rabczuk et al. 2006, sec. 6.1.1 (also Belytschko et al. 1995, sec. 5.1.2):
# a beam ``[0, L] x [-D/2, D/2]`` with the exact Timoshenko–Goodier displacement prescribed at
# ``x = 0`` and the parabolic shear traction ``t_y = P/(2I) (D^2/4 - y^2)`` on ``x = L``.
# Defaults: E = 3e7, nu = 0.3, L = 48, D = 12, P = 1000, plane stress, unit thickness.
#
# Methods (default: all of them; ``mf.COUPLINGS`` lists the couplings):
#
# * ``fe``: Q1 finite elements through DOLFINx, Dirichlet values interpolated at x = 0;
# * ``efg``: EFG on a particle grid of spacing ``--particle-spacing`` (default ``h``), integrated
#   on the FE mesh's cells (4 x 4 Gauss), essential conditions by Lagrange multipliers;
# * ``lagrange``: FE on the fixed part, particles on the free-end fraction ``--patch-fraction``
#   of the beam (default 0.5, as in the paper), joined by the compatibility coupling with Lagrange
#   multipliers on the interface (Rabczuk et al. 2006, sec. 5.4);
# * ``edge-to-edge``: the same split, with the multipliers collocated at the interface particles
#   (continuity exactly at those particles; Rabczuk et al. 2006, sec. 5.4);
# * ``master-slave``: the same split, the first particle layer rigidly linked to the interface
#   edges (Rabczuk et al. 2006, sec. 5.1.2); first order, see the self-check;
# * ``ramp`` / ``ramp-cubic``: interface elements on the FE side with shape functions
#   (1 - R) N + R phi (Belytschko et al. 1995, sec. 3.2; smoothed ramp of Rabczuk eq. 38–42);
# * ``bridging``: the patch's first ``--overlap`` cell layers form a band where both
#   discretisations live with energy weights 1 - alpha and alpha, tied by multipliers on the FE
#   nodes at the band's particles (Rabczuk et al. 2006, sec. 5.3).
#
# For each run the demo prints the relative L2 error (Rabczuk eq. 136) and the relative energy
# error (Belytschko eq. 5.5) beside the cost split into setup, assembly and solve. JIT
# compilation is excluded: the FE forms are compiled once on a tiny mesh before any timing.
#
# Usage (the command-line contract; outside scripts rely on it):
#
#     python demos/cantilever.py --method fe efg --h 3 1.5 1 0.75 0.5 [--json out.json]
#     mpirun -n 2 python demos/cantilever.py --method efg --h 1
#     python demos/cantilever.py --method efg --h 1 --probe-in pts.npy --probe-out u.npy
#     python demos/cantilever.py --method fe efg lagrange --h 0.25 --integration smoothed

# +
from __future__ import annotations

import argparse
import json
import sys
import time

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

METHODS = ("fe", "efg", *mf.COUPLINGS, "hybrid")
# -


# ## Command line


# +
def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__ or "Timoshenko cantilever")
    p.add_argument("--method", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--h", nargs="+", type=float, default=[1.0], help="FE element size(s)")
    p.add_argument("--particle-spacing", type=float, default=None, help="default: h")
    p.add_argument("--E", type=float, default=3e7)
    p.add_argument("--nu", type=float, default=0.3)
    p.add_argument("--L", type=float, default=48.0)
    p.add_argument("--D", type=float, default=12.0)
    p.add_argument("--P", type=float, default=1000.0)
    p.add_argument("--plane", choices=("stress", "strain"), default="stress")
    p.add_argument(
        "--patch-fraction",
        type=float,
        default=0.5,
        help="fraction of the length at the free end modelled with particles by the couplings "
        "(efg models all of it)",
    )
    p.add_argument(
        "--placement",
        choices=mf.PLACEMENTS,
        default=mf.PLACEMENTS[0],
        help="particles of the couplings' patch (see mf.ParticlePatch; 'vertices' ignores "
        "--particle-spacing)",
    )
    p.add_argument("--weight", choices=("quartic", "cubic", "gaussian"), default="quartic")
    p.add_argument(
        "--dilation",
        type=float,
        default=None,
        help="MLS d_max (default: 2.0; 2.5 for the ramp couplings, see mf.DEFAULT_DILATION)",
    )
    p.add_argument(
        "--quadrature-degree",
        type=int,
        default=None,
        help="Gauss degree of the particle cells (default: the library's, 15 points per particle "
        "or more: 7, 4 x 4 on quads, with particles at the vertices; 15 at h/2; hybrid: 7)",
    )
    p.add_argument(
        "--consistent",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="variationally consistent integration (default: the library's, on for EFG and the "
        "variational couplings, off for master-slave); --no-consistent: the papers' plain Gauss",
    )
    p.add_argument(
        "--integration",
        choices=mf.INTEGRATIONS,
        default=None,
        help="the particle integration of EFG and of the couplings that take the smoothed ones "
        "(mf.SMOOTHED_COUPLINGS; the others keep their default): 'vci' (the default), "
        "'smoothed' (symmetric and consistent: LDL^T), 'smoothed-subcells', 'gauss'",
    )
    p.add_argument("--overlap", type=int, default=2, help="bridging: band width in cells")
    p.add_argument(
        "--hybrid-variant",
        choices=mf.HYBRID_VARIANTS,
        default="HA-F",
        help="hybrid: FE forces by interface tractions (HA-S) or interpolation (HA-F)",
    )
    p.add_argument(
        "--constraint",
        choices=("points", "integral"),
        default="integral",
        help="bridging: tie the band over its cells (eq. 52, the default) or at its particles "
        "(eq. 79-81, the paper's)",
    )
    p.add_argument("--cell", choices=("quadrilateral", "triangle"), default="quadrilateral")
    p.add_argument(
        "--balance",
        type=float,
        default=None,
        help="redistribute the mesh over the ranks by work (mf.balanced_mesh), a patch cell "
        "weighing this many FE cells (default: DOLFINx's partition, equal cells per rank)",
    )
    p.add_argument("--json", default=None, help="write the results as JSON")
    p.add_argument("--probe-in", default=None, help="(m, 2) .npy points to evaluate u at")
    p.add_argument("--probe-out", default=None, help="(m, 2) .npy displacements, from rank 0")
    p.add_argument("--no-check", action="store_true", help="skip the demo's self-checks")
    args = p.parse_args(argv)
    for name in ("h", "E", "L", "D", "dilation"):
        if getattr(args, name) is None:
            continue
        vals = np.atleast_1d(getattr(args, name))
        if not np.all(np.isfinite(vals) & (vals > 0)):
            p.error(f"--{name} must be positive, got {getattr(args, name)}")
    if args.particle_spacing is not None and not args.particle_spacing > 0:
        p.error(f"--particle-spacing must be positive, got {args.particle_spacing}")
    if not 0.0 < args.patch_fraction <= 1.0:
        p.error(f"--patch-fraction must lie in (0, 1], got {args.patch_fraction}")
    coupled = sorted(set(args.method) & {*mf.COUPLINGS, "hybrid"})
    if args.patch_fraction == 1.0 and coupled:
        p.error(
            f"--patch-fraction 1 leaves no finite elements for --method {' '.join(coupled)} to "
            "couple to; give a fraction below 1 (efg models the whole beam)"
        )
    if (args.probe_in is None) != (args.probe_out is None):
        p.error("--probe-in and --probe-out go together")
    for h in args.h:
        if round(args.L / h) < 1 or round(args.D / h) < 1:
            p.error(f"--h {h} is larger than the beam ({args.L} x {args.D})")
        if coupled and args.patch_fraction <= min_patch_fraction(args, h):
            p.error(
                f"--patch-fraction {args.patch_fraction} selects no cell at --h {h}; give a "
                f"fraction above {min_patch_fraction(args, h):.4g} or a smaller --h"
            )
    return args


def min_patch_fraction(args, h: float) -> float:
    """The patch fractions above this select at least one cell at ``h``: the last cell
    column's centroids lie ``h_x / 2`` (quadrilaterals) or ``h_x / 3`` (triangles) from the end."""
    hx = args.L / max(1, round(args.L / h))
    return hx / (2.0 if args.cell == "quadrilateral" else 3.0) / args.L


# -


# ## The model: mesh, boundaries, exact solution


# +
def make_mesh(comm, args, h: float):
    cell = getattr(dolfinx.mesh.CellType, args.cell)
    n = [max(1, round(args.L / h)), max(1, round(args.D / h))]
    corners = [np.array([0.0, -args.D / 2]), np.array([args.L, args.D / 2])]
    return dolfinx.mesh.create_rectangle(comm, corners, n, cell)


def patch_weight(args):
    """``--balance``'s cell weight: the patch cells (centroid in the free-end fraction, as
    :func:`make_patch` selects them) weigh ``--balance`` FE cells."""
    start = (1.0 - args.patch_fraction) * args.L
    return lambda x: np.where(x[0] > start, args.balance, 1.0)


def boundaries(msh, args):
    left = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0))
    right = mf.boundary_facets(msh, lambda x: np.isclose(x[0], args.L))
    return left, right


def ufl_traction(beam: mf.TimoshenkoBeam):
    inertia = beam.inertia

    def t(x):
        return ufl.as_vector((0.0, beam.P / (2 * inertia) * (beam.D**2 / 4 - x[1] ** 2)))

    return t


# -


# ## The two methods
#
# Each returns the errors, the sizes and the timings, and a function that evaluates the
# displacement at probe points on rank 0.


# +
def run_fe(msh, args, beam, material):
    left, right = boundaries(msh, args)
    V = _compat.vector_function_space(msh)
    sol = mf.solve_fe_elasticity(
        V,
        material,
        dirichlet=[(left, lambda x: beam.displacement(x[:2].T).T)],
        tractions=[(right, ufl_traction(beam))],
    )
    local = sol.u.x.array.reshape(-1, V.dofmap.index_map_bs)

    def evaluate(q):
        t = mf.tabulate_in_cells(V, q.points, q.cells)
        return t.values @ local, t.gradient(local)

    errors = mf.error_norms(msh, evaluate, beam, material)
    sizes = {"fe_dofs": sol.num_dofs, "particle_dofs": 0, "multiplier_dofs": 0}
    return errors, sizes, sol.timings, lambda pts: mf.evaluate_fe_function(sol.u, pts)


def dilation(args, method: str) -> float:
    """The dilation a method runs with: ``--dilation`` or the method's default."""
    if args.dilation is not None:
        return args.dilation
    return mf.DEFAULT_DILATION.get(method, 2.0)


def consistent(args, method: str) -> bool | None:
    """Whether a method runs with consistent integration: ``--consistent`` /
    ``--no-consistent``, ``--integration``, or the library's default (on for EFG and the
    variational couplings, off for master-slave); ``None`` for FE."""
    if method == "fe":
        return None
    if args.consistent is not None:
        return args.consistent
    if args.integration is not None and method in ("efg", *mf.SMOOTHED_COUPLINGS):
        return args.integration != "gauss"
    return method != "master-slave"


def integration(args, method: str) -> str | None:
    """The particle integration a method runs with (``None`` for FE and the hybrid)."""
    if method in ("fe", "hybrid"):
        return None
    if args.integration is not None and method in ("efg", *mf.SMOOTHED_COUPLINGS):
        return args.integration
    return "vci" if consistent(args, method) else "gauss"


def particle_options(args, method: str) -> dict:
    """The particle-side options shared by every meshfree method."""
    options = {
        "weight": args.weight,
        "dilation": dilation(args, method),
        "quadrature_degree": args.quadrature_degree,
    }
    if args.consistent is not None:  # else the library's default
        options["consistent"] = args.consistent
    if args.integration is not None and method in ("efg", *mf.SMOOTHED_COUPLINGS):
        options["integration"] = args.integration
    return options


def run_efg(msh, args, beam, material, h):
    t0 = time.perf_counter()
    left, right = boundaries(msh, args)
    particles = mf.ParticleSet.from_cells(msh, args.particle_spacing or h)
    problem = mf.EFGElasticity(particles, material, **particle_options(args, "efg"))
    problem.add_dirichlet(left, beam.displacement)
    problem.add_traction(right, beam.traction)
    particle_time = time.perf_counter() - t0
    sol = problem.solve()
    sol.timings["setup"] += particle_time
    errors = mf.error_norms(msh, lambda q: sol.evaluate(q.points), beam, material)
    sizes = {
        "fe_dofs": 0,
        "particle_dofs": 2 * particles.num_particles,
        "multiplier_dofs": sol.num_multipliers,
    }

    def probe(pts):
        x = mf.ensure_points_in_mesh(msh, pts)
        return sol.displacement(x)

    return errors, sizes, sol.timings, probe


def make_patch(msh, args, h: float) -> mf.ParticlePatch:
    """The couplings' patch: the cells whose centroid lies in the free-end fraction
    ``--patch-fraction`` of the length, particles of ``--placement`` (collective). A fraction
    thinner than the cells at ``h`` is refused on every rank, naming the flag and the fix."""
    n = msh.topology.index_map(2).size_local
    centroid_x = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    cells = np.flatnonzero(centroid_x > (1.0 - args.patch_fraction) * args.L)
    if msh.comm.allreduce(cells.size) == 0:
        last = msh.comm.allreduce(float(centroid_x.max(initial=-np.inf)), op=MPI.MAX)
        raise ValueError(
            f"--patch-fraction {args.patch_fraction} selects no cell at --h {h}: the centroids "
            f"of the last cells lie at x = {last:.6g}, outside the last "
            f"{args.patch_fraction * args.L:.6g} of the beam; give --patch-fraction above "
            f"{1.0 - last / args.L:.4g} or a smaller --h"
        )
    if args.placement == "vertices":
        return mf.ParticlePatch(msh, cells, placement="vertices")
    return mf.ParticlePatch(msh, cells, args.particle_spacing or h, placement=args.placement)


def run_coupled(msh, args, beam, material, h, coupling, overlap=None, solver="mumps"):
    t0 = time.perf_counter()
    left, right = boundaries(msh, args)
    patch = make_patch(msh, args, h)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh),
        patch,
        material,
        coupling=coupling,
        **particle_options(args, coupling),
        **(
            {"overlap": overlap or args.overlap, "constraint": args.constraint}
            if coupling == "bridging"
            else {}
        ),
    )
    problem.add_dirichlet(left, beam.displacement)
    problem.add_traction(right, beam.traction)
    patch_time = time.perf_counter() - t0
    sol = problem.solve(solver)
    sol.timings["setup"] += patch_time
    errors = mf.error_norms(msh, sol.evaluate_at_quadrature, beam, material)
    return errors, sol.sizes, sol.timings, sol.displacement


def run_hybrid(msh, args, beam, material, h):
    """The hybrid SPH-FE coupling (Rabczuk et al. 2006, sec. 5.5) through its assembled linear
    operator ``K u = f``: the same split, clamp and load as the couplings; SPH particles of
    spacing ``--particle-spacing`` with the integration-consistent stress points."""
    t0 = time.perf_counter()
    left, right = boundaries(msh, args)
    patch = make_patch(msh, args, h)
    problem = mf.HybridElasticity(
        _compat.vector_function_space(msh),
        patch,
        material,
        variant=args.hybrid_variant,
        # the demo's rule for the hybrid's stress points: 4 x 4 unless given
        quadrature_degree=7 if args.quadrature_degree is None else args.quadrature_degree,
    )
    problem.add_dirichlet(left, beam.displacement)
    problem.add_traction(right, beam.traction)
    patch_time = time.perf_counter() - t0
    sol = problem.solve()
    sol.timings["setup"] += patch_time
    errors = mf.error_norms(msh, sol.evaluate_at_quadrature, beam, material)
    sizes = {k: sol.sizes[k] for k in ("fe_dofs", "particle_dofs", "multiplier_dofs")}
    return errors, sizes, sol.timings, sol.displacement


def run_method(msh, args, beam, material, h: float, method: str):
    """One method on ``msh``: :func:`run_fe`, :func:`run_efg`, :func:`run_hybrid` or
    :func:`run_coupled` (collective). Returns their ``(errors, sizes, timings, probe)``."""
    if method == "fe":
        return run_fe(msh, args, beam, material)
    if method == "efg":
        return run_efg(msh, args, beam, material, h)
    if method == "hybrid":
        return run_hybrid(msh, args, beam, material, h)
    return run_coupled(msh, args, beam, material, h, method)


def warm_jit(args, material, beam):
    """Compile the FE forms once on a tiny mesh so that timings exclude JIT compilation.

    The forms depend on the material, the cell and the quadrature degree only: the patch, its
    particles and the bridging band of the warm-up are fixed (half the beam, particles at the
    element size, a one-cell band), so that it runs for every value of the other flags (a
    patch fraction below a quarter selects no cell of this two-cell mesh)."""
    warm = argparse.Namespace(
        **{
            **vars(args),
            "patch_fraction": 0.5,
            "particle_spacing": None,
            "placement": mf.PLACEMENTS[0],
            "overlap": 1,
        }
    )
    msh = make_mesh(MPI.COMM_SELF, warm, max(args.L, args.D) / 2)
    run_fe(msh, warm, beam, material)
    for coupling in sorted(set(args.method) & set(mf.COUPLINGS)):
        # (one patch cell on this mesh: a one-cell bridging band)
        run_coupled(msh, warm, beam, material, max(args.L, args.D) / 2, coupling)
    if "hybrid" in args.method:  # (cells of D / 4: enough particles for the kernel sums)
        h = args.D / 4
        run_hybrid(make_mesh(MPI.COMM_SELF, warm, h), warm, beam, material, h)


# -


# ## Driver: run, tabulate, check


# +
def rates(hs: list[float], errs: list[float]) -> list[float]:
    return [
        float(np.log(errs[k - 1] / errs[k]) / np.log(hs[k - 1] / hs[k])) for k in range(1, len(hs))
    ]


def main(argv: list[str] | None = None) -> list[dict]:
    args = parse(argv)
    comm = MPI.COMM_WORLD
    material = mf.LinearElastic(args.E, args.nu, args.plane)
    beam = mf.TimoshenkoBeam(material, L=args.L, D=args.D, P=args.P)
    if set(args.method) & {"fe", "hybrid", *mf.COUPLINGS}:
        warm_jit(args, material, beam)
    records = []
    probe_points = None
    if args.probe_in is not None:
        probe_points = np.load(args.probe_in) if comm.rank == 0 else np.zeros((0, 2))
    for method in args.method:
        for h in args.h:
            comm.Barrier()
            msh = make_mesh(comm, args, h)
            if args.balance is not None and method in mf.COUPLINGS:
                msh = mf.balanced_mesh(msh, patch_weight(args))
            errors, sizes, timings, probe = run_method(msh, args, beam, material, h, method)
            # the slowest rank's times
            timings = {k: comm.allreduce(v, op=MPI.MAX) for k, v in timings.items()}
            rec = {
                "method": method,
                "h": h,
                "particle_spacing": (args.particle_spacing or h) if method != "fe" else None,
                **sizes,
                "error_l2": errors["l2"],
                "error_energy": errors["energy"],
                "time_setup": timings["setup"],
                "time_assemble": timings["assemble"],
                "time_solve": timings["solve"],
                "time_total": timings["setup"] + timings["assemble"] + timings["solve"],
                "ranks": comm.size,
                "dolfinx_version": mf.DOLFINX_VERSION,
                "plane": args.plane,
                "weight": args.weight if method != "fe" else None,
                "dilation": dilation(args, method) if method != "fe" else None,
                "consistent": consistent(args, method),
                "integration": integration(args, method),
                "balance": args.balance if method in mf.COUPLINGS else None,
            }
            records.append(rec)
            if probe_points is not None:
                u = probe(probe_points)
                if comm.rank == 0:
                    np.save(args.probe_out, u)
    report(records, comm)
    if args.json and comm.rank == 0:
        with open(args.json, "w") as f:
            json.dump(records[0] if len(records) == 1 else records, f, indent=1)
    if not args.no_check:
        check(records, comm)
    return records


def report(records: list[dict], comm) -> None:
    if comm.rank != 0:
        return
    w = max(6, *(len(r["method"]) for r in records))
    head = (
        f"{'method':{w}} {'h':>5} {'S':>5} {'FE dofs':>8} {'part.dofs':>9} {'mult':>5} "
        f"{'L2 error':>9} {'rate':>5} {'energy':>9} {'rate':>5} "
        f"{'setup s':>8} {'assem s':>8} {'solve s':>8} {'total s':>8}"
    )
    print(
        f"Timoshenko cantilever, {records[0]['plane']}, {comm.size} rank(s), "
        f"DOLFINx {mf.DOLFINX_VERSION} (JIT excluded)"
    )
    print(head)
    print("-" * len(head))
    prev: dict[str, dict] = {}
    for r in records:
        p = prev.get(r["method"])
        rl2 = ren = ""
        if p is not None and p["h"] != r["h"]:
            lh = np.log(p["h"] / r["h"])
            rl2 = f"{np.log(p['error_l2'] / r['error_l2']) / lh:5.2f}"
            ren = f"{np.log(p['error_energy'] / r['error_energy']) / lh:5.2f}"
        s = "" if r["particle_spacing"] is None else f"{r['particle_spacing']:5.3g}"
        print(
            f"{r['method']:{w}} {r['h']:5.3g} {s:>5} {r['fe_dofs']:8d} {r['particle_dofs']:9d} "
            f"{r['multiplier_dofs']:5d} {r['error_l2']:9.2e} {rl2:>5} {r['error_energy']:9.2e} "
            f"{ren:>5} {r['time_setup']:8.4f} {r['time_assemble']:8.4f} {r['time_solve']:8.4f} "
            f"{r['time_total']:8.4f}"
        )
        prev[r["method"]] = r


def check(records: list[dict], comm) -> None:
    """The demo checks its own results.

    * every run: a relative L2 error below 5 % (the coarsest mesh, h = 3, gives 2.8 % with FE),
      15 % for the first-order couplings (master-slave 4.5 %, hybrid 9.1 % at h = 3);
    * couplings: L2 error within 1.5x pure FE at the same h when both ran;
    * a refinement series of 3 or more sizes: fitted L2 rate >= 1.8 and energy rate >= 0.9
      (optimal rates 2 and 1 for bilinear FE and linear-basis EFG);
    * master-slave, first order by construction: fitted L2 rate >= 1.1 instead of the two above.
    """
    failures = []
    first_order = {"master-slave", "hybrid"}
    for r in records:
        cap = 0.15 if r["method"] in first_order else 0.05
        if not r["error_l2"] < cap:
            failures.append(f"{r['method']} h={r['h']}: L2 error {r['error_l2']:.3e} >= {cap}")
    fe = {r["h"]: r["error_l2"] for r in records if r["method"] == "fe"}
    # Master-slave is first order by construction (issue: "Master-slave measured and explained";
    # see dolfinx_meshfree.couplings.master_slave): the slave layer moves rigidly with the interface
    # edges, dropping the strain across a band of width h. Measured L2 rates 1.36/1.21/1.14/1.10 for
    # h = 3..0.5 (Rabczuk et al. 2006, Table II: 1.23/1.23/1.13), energy 0.56-0.66, so it is
    # checked against the paper's rate 1.1 instead of pure FE and the optimal rates.
    # The hybrid coupling is checked the same way: its particle side (corrected SPH gradients,
    # not derivatives of its interpolant) converges at about first order, L2 1.5/1.2/1.7 for
    # h = 3..0.75 (Table II: 1.23/1.23/1.13 for the hybrid), errors 2.5-9x pure FE.
    for r in records:
        if r["method"] in first_order:
            continue
        if r["method"] in mf.COUPLINGS and r["h"] in fe and not r["error_l2"] <= 1.5 * fe[r["h"]]:
            failures.append(
                f"{r['method']} h={r['h']}: L2 error {r['error_l2']:.3e} > 1.5 x FE "
                f"{fe[r['h']]:.3e}"
            )
    for method in {r["method"] for r in records}:
        runs = sorted((r for r in records if r["method"] == method), key=lambda r: -r["h"])
        hs = [r["h"] for r in runs]
        if len(set(hs)) >= 3:
            lh = np.log(hs)
            sl2 = np.polyfit(lh, np.log([r["error_l2"] for r in runs]), 1)[0]
            sen = np.polyfit(lh, np.log([r["error_energy"] for r in runs]), 1)[0]
            if comm.rank == 0:
                print(f"{method}: fitted rates L2 {sl2:.2f}, energy {sen:.2f}")
            if method in first_order:
                if sl2 < 1.1:
                    failures.append(f"{method}: fitted L2 rate {sl2:.2f} < 1.1 (the paper's)")
                continue
            if sl2 < 1.8:
                failures.append(f"{method}: fitted L2 rate {sl2:.2f} < 1.8")
            if sen < 0.9:
                failures.append(f"{method}: fitted energy rate {sen:.2f} < 0.9")
    if failures:
        if comm.rank == 0:
            print("CHECK FAILED:\n  " + "\n  ".join(failures), file=sys.stderr)
        sys.exit(1)
    if comm.rank == 0:
        print("checks passed")


if __name__ == "__main__":
    main()
# -
