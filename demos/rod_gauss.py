# # Rod with a Gaussian initial velocity: explicit dynamics, FE, EFG and coupled
#
# Rabczuk et al. 2006, sec. 6.2.1 and Table III: a rod 60 x 5 mm in plane strain, E = 210000
# MPa, nu = 0, rho = 0.0078 g/mm^3 (units g, mm, ms: c = sqrt(E/rho) = 5189 mm/ms; this is the
# benchmark's 7.8e-9 t/mm^3 with times in ms instead of s), free everywhere, with the initial
# velocity ``v = (exp(-0.025 (x - 30)^2), 0)``. With nu = 0 the 1D d'Alembert solution is exact
# in 2D (no lateral stress); the free ends reflect the two half-pulses, which meet again at the
# start after ``L / c = 0.011563`` ms and again after ``0.023126`` ms
# (:class:`dolfinx_meshfree.verification.waves.GaussianPulseRod`).
#
# Methods (``--method``; default: all of them, ``mf.dynamics.DYNAMICS_METHODS``):
#
# * ``fe``: Q1 finite elements with row-sum lumped masses on the whole rod;
# * ``efg``: EFG on a particle grid with the same number of particles, integrated on a background
#   mesh whose cells are the particle spacing (2 x 2 Gauss points per cell);
# * every static coupling (``lagrange``, ``edge-to-edge``, ``ramp``, ``ramp-cubic``,
#   ``bridging``, ``master-slave``): FE on x < 30, particles on x > 30 with about ``--ratio``
#   particles per FE node: the particle spacing is ``h / sqrt(ratio)``, and for the ramp
#   couplings ``h / k`` with ``k = round(sqrt(ratio))`` so that particles sit on the FE nodes of
#   the interface, which they need (the realised ratio, active FE nodes to particles, is
#   printed). The multiplier couplings correct the trial velocities each step (Rabczuk et
#   al. 2006, eq. 93–96, Table I); bridging weights stiffness and masses across a band of
#   ``--overlap`` cell layers (eq. 46–48, 88–89); the ramp couplings blend FE and particles in
#   the interface elements (Belytschko et al. 1995, eq. 3.15), whose MLS supports span the
#   interface element at any ``k`` (radii ``(d_max - 1) h / k + h``, see
#   ``mf.couplings.ramp.ramp_mls``);
#   master–slave ties the first particle layer to the FE edges (eq. 27–28).
# * ``hybrid`` (sec. 5.5): SPH particles with the FE integration points in their sums, forces on
#   the FE nodes by interpolation (HA-F). The particles sit at the centres of a lattice of
#   squares of spacing ``h / sqrt(ratio)``, none on the interface, with their squares' areas as
#   volumes (``--hybrid-particles centred``), and the particle strains are smoothed over
#   sub-cells (``--hybrid-integration smoothed``): a symmetric, integration-consistent ``K``.
#   ``--hybrid-particles patch --hybrid-integration cells`` is the former discretisation, whose
#   error depended on the ratio (particles on the interface FE nodes, volumes sampled by 3 x 3
#   Gauss points per cell, inconsistent integration that reflects waves at the interface).
#
# ``--integration stress-points`` integrates the particle stiffness of ``efg``, ``lagrange``,
# ``edge-to-edge`` and ``master-slave`` at the particles and the stress points between them
# (Rabczuk, Belytschko & Xiao 2004, Lagrangian kernel) instead of the background cells;
# ``--integration smoothed`` integrates ``efg``, ``lagrange`` and ``master-slave`` with strains
# smoothed over the cells (symmetric and consistent: ``dolfinx_meshfree.geometry.smoothing``);
# ``--slaves coincident`` runs master-slave as Johnson's coupling, the particles on the interface
# fixed to the FE nodes they sit on (Rabczuk et al. 2006, eq. 15-16; particle spacing ``h / k``
# as for the ramps).
#
# ``--sweep 1 2 4 8`` runs every method at each ratio and prints the Table III-style table;
# ``--transits N`` runs N wave transits (``N L / c``) and reports the energy drift.
#
# Central differences at 0.9 of the critical time step ``2 / omega_bound`` (an upper bound of
# ``omega_max``: ExplicitDynamics.critical_time_step). The relative L2 velocity error
# (Rabczuk eq. 137) is reported at t1 = 0.011563 and t2 = 0.023126 beside the paper's Table III,
# with the energy balance: ``drift`` is the relative change of the energy that central differences
# conserve exactly (round-off), ``osc`` the O(dt^2) oscillation of the kinetic energy at integer
# steps. Times exclude JIT compilation (the FE forms are compiled on a tiny mesh first).
#
# On several ranks the coupled rods are built on ``mf.balanced_mesh`` (``--partition balanced``,
# the default), which gives every rank its share of the FE cells and of the particle cells: on
# DOLFINx's own partition (``--partition dolfinx``) one rank holds the FE half and the other the
# particles, and a lagrange step was 1.05x faster on 2 ranks than on one; balanced, every method
# 1.82-1.93x with PETSc's product, and 1.71-1.94x with the compiled products (the default with
# numba), which make each step 2.9-3.2x faster (20k nodes and particles;
# ``docs/guide/solvers.md``, work-balanced MPI and compiled products). With the multipliers'
# projection compiled too, a later session gave lagrange 1.75x and bridging 1.82x
# (master-slave, without multipliers, 1.71x; best of 3).
#
# Usage (the command-line contract):
#
#     python demos/rod_gauss.py [--method fe efg lagrange ...] [--nodes 20000] [--ratio 4]
#         [--center 30] [--t-end 0.023126] [--json out.json] [--probe-in P.npy --probe-out V.npy]
#         [--sweep 1 2 4 8] [--transits 10] [--integration cells|stress-points|smoothed]
#         [--slaves layer|coincident] [--partition balanced|dolfinx]
#     mpirun -n 2 python demos/rod_gauss.py --nodes 2000

# +
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import DYNAMICS_METHODS, ExplicitDynamics, check_method
from dolfinx_meshfree.geometry.partition import PATCH_CELL_WORK
from dolfinx_meshfree.verification.waves import GaussianPulseRod

import dolfinx
import numpy as np
from mpi4py import MPI

LENGTH, HEIGHT = 60.0, 5.0
T1, T2 = 0.011563, 0.023126

#: Rabczuk et al. 2006, Table III: error at t1, at t2, CPU minutes (2006 hardware).
PAPER = {
    "master-slave": (0.0289, 0.0465, 5.3),
    "hybrid": (0.0141, 0.0152, 5.5),
    "ramp": (0.0179, 0.0323, 5.5),
    "ramp-cubic": (0.0179, 0.0323, 5.5),
    "lagrange": (0.016, 0.03201, 5.6),
    "bridging": (0.0107, 0.0111, 5.8),
    "efg": (0.007842, 0.007901, 9.1),
}
# -


# ## Command line


# +
def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description="Rod with a Gaussian initial velocity (Table III)")
    p.add_argument("--method", nargs="+", default=list(DYNAMICS_METHODS))
    p.add_argument("--nodes", type=int, default=20000, help="FE nodes + particles (about)")
    p.add_argument("--ratio", type=float, default=4.0, help="particles per FE node (coupled)")
    p.add_argument("--center", type=float, default=30.0, help="centre of the Gaussian")
    p.add_argument("--t-end", type=float, default=T2, help="final time (ms)")
    p.add_argument("--E", type=float, default=210000.0)
    p.add_argument("--rho", type=float, default=0.0078, help="g/mm^3 (times in ms)")
    p.add_argument("--safety", type=float, default=0.9, help="fraction of the critical step")
    p.add_argument(
        "--dilation", type=float, default=None, help="MLS d_max (default: mf.DEFAULT_DILATION)"
    )
    p.add_argument("--overlap", type=int, default=2, help="bridging band, cell layers")
    p.add_argument(
        "--hybrid-variant",
        nargs="+",
        choices=mf.HYBRID_VARIANTS,
        default=["HA-F"],
        help="hybrid: forces on the FE nodes by interpolation (HA-F, default) or by tractions "
        "(HA-S: unstable in explicit dynamics, its K is not symmetric; reported, fails the check)",
    )
    p.add_argument(
        "--hybrid-particles",
        choices=mf.couplings.hybrid.HYBRID_PARTICLES,
        default="centred",
        help="hybrid: SPH particles at the centres of a lattice of squares with their areas "
        "(centred, default) or the patch's grid through the interface nodes with sampled Voronoi "
        "volumes (patch: the error then depends on the particle:node ratio)",
    )
    p.add_argument(
        "--hybrid-integration",
        choices=("smoothed", "cells"),
        default="smoothed",
        help="hybrid: particle strains smoothed over sub-cells (smoothed, default: symmetric and "
        "consistent) or at Gauss points of the patch cells (cells: symmetric, inconsistent; "
        "reflects part of a wave at the interface)",
    )
    p.add_argument(
        "--integration",
        choices=("cells", "stress-points", "smoothed"),
        default="cells",
        help="particle stiffness of efg, lagrange, edge-to-edge, master-slave: background cells "
        "(Gauss), stress points (Lagrangian kernel) or smoothed strains (symmetric and "
        "consistent: efg, lagrange, master-slave)",
    )
    p.add_argument(
        "--slaves",
        choices=("layer", "coincident"),
        default="layer",
        help="master-slave: the first particle layer (eq. 17-28) or Johnson's particles on the "
        "interface nodes (eq. 15-16)",
    )
    p.add_argument("--sweep", type=float, nargs="+", default=None, help="ratios to sweep")
    p.add_argument("--transits", type=float, default=None, help="run N transits L/c")
    p.add_argument("--weight", choices=("quartic", "cubic", "gaussian"), default="quartic")
    p.add_argument(
        "--quadrature-points",
        type=int,
        default=2,
        help="Gauss points per particle spacing and direction on particle cells",
    )
    p.add_argument("--json", default=None, help="write the results as JSON")
    p.add_argument("--probe-in", default=None, help="(m, 2) .npy points")
    p.add_argument("--probe-out", default=None, help="(m, 2) .npy velocities at t-end, rank 0")
    p.add_argument("--no-check", action="store_true", help="skip the demo's self-checks")
    p.add_argument(
        "--partition",
        choices=("balanced", "dolfinx"),
        default="balanced",
        help="on several ranks, the coupled rods' mesh: redistributed so that every rank holds "
        "its share of the FE cells and of the particle cells (mf.balanced_mesh, balanced, "
        "default), or DOLFINx's partition by cells alone (dolfinx)",
    )
    p.add_argument(
        "--xdmf",
        default=None,
        metavar="PREFIX",
        help="XDMF of the FE fields and particles at 11 frames and t1, t2: PREFIX_<method>_*.xdmf",
    )
    args = p.parse_args(argv)
    if args.nodes < 40:
        p.error(f"--nodes {args.nodes} is too small; give at least 40")
    for name in ("ratio", "t_end", "E", "rho", "dilation", "transits"):
        v = getattr(args, name)
        if v is None:
            continue
        if not (np.isfinite(v) and v > 0):
            p.error(f"--{name.replace('_', '-')} must be positive, got {v}")
    if not 0.0 <= args.center <= LENGTH:
        p.error(f"--center must lie on the rod [0, {LENGTH}], got {args.center}")
    if not 0.0 < args.safety <= 1.0:
        p.error(f"--safety must lie in (0, 1], got {args.safety}")
    if args.quadrature_points < 1:
        p.error(f"--quadrature-points must be >= 1, got {args.quadrature_points}")
    for m in args.method:
        if m not in DYNAMICS_METHODS:
            p.error(f"--method {m!r} is not available; choose from {list(DYNAMICS_METHODS)}")
    if args.sweep is not None and not all(np.isfinite(r) and r >= 1 for r in args.sweep):
        p.error(f"--sweep ratios must be >= 1, got {args.sweep}")
    if args.integration != "cells":
        able = ("fe", "efg", *mf.SMOOTHED_COUPLINGS)
        if args.integration == "stress-points":
            able = ("fe", "efg", "lagrange", "edge-to-edge", "master-slave")
        bad = [m for m in args.method if m not in able]
        if bad:
            p.error(f"--integration {args.integration} is not available for {bad}")
    if args.overlap < 1:
        p.error(f"--overlap must be >= 1, got {args.overlap}")
    if (args.probe_in is None) != (args.probe_out is None):
        p.error("--probe-in and --probe-out go together")
    if args.xdmf is not None and not os.path.isdir(os.path.dirname(args.xdmf) or "."):
        p.error(f"--xdmf {args.xdmf!r}: the directory does not exist")
    return args


# -


# ## Discretisations of the rod
#
# ``--nodes`` fixes the spacing: ``h = sqrt(L H / nodes)`` for one method on the whole rod, and
# for the coupling ``h_FE = sqrt((L H / 2) (1 + ratio) / nodes)`` so that the FE half holds
# ``nodes / (1 + ratio)`` nodes and the particle half ``ratio`` times more. ``h`` is rounded so
# that the height holds a whole number of cells.


# +
def rod_mesh(comm, h: float):
    ny = max(1, round(HEIGHT / h))
    h = HEIGHT / ny
    nx = max(2, 2 * round(LENGTH / (2 * h)))  # even: the interface x = 30 is a mesh line
    corners = [np.array([0.0, 0.0]), np.array([LENGTH, HEIGHT])]
    return dolfinx.mesh.create_rectangle(
        comm, corners, [nx, ny], dolfinx.mesh.CellType.quadrilateral
    )


def degree_for(points_per_direction: int) -> int:
    """Gauss degree with ``points_per_direction`` points per direction on quadrilaterals."""
    return 2 * max(1, points_per_direction) - 1


def build(method: str, args, material, comm):
    """The :class:`ExplicitDynamics` of a method, and its spacings."""
    check_method(method)
    area = LENGTH * HEIGHT
    mopts = {"weight": args.weight, "dilation": args.dilation or 2.0}
    if method == "fe":
        msh = rod_mesh(comm, np.sqrt(area / args.nodes))
        dyn = ExplicitDynamics.fe(_compat.vector_function_space(msh), material, args.safety)
        h = HEIGHT / round(HEIGHT / np.sqrt(area / args.nodes))
        return dyn, {"h_fe": h, "h_p": None, "dilation": None}
    if method == "efg":
        h = HEIGHT / max(1, round(HEIGHT / np.sqrt(area / args.nodes)))
        msh = rod_mesh(comm, h)
        particles = mf.ParticleSet.from_cells(msh, h)
        dyn = ExplicitDynamics.efg(
            particles,
            material,
            **mopts,
            quadrature_degree=degree_for(args.quadrature_points),
            safety=args.safety,
            integration=args.integration,
        )
        return dyn, {"h_fe": None, "h_p": h, "dilation": mopts["dilation"]}
    # the ramps need particles on the interface nodes: h / k with an integer k
    # (and Johnson's master-slave: a particle on every interface node)
    on_nodes = method.startswith("ramp") or (method == "master-slave" and johnson(args))
    k = max(1, round(np.sqrt(args.ratio))) if on_nodes else np.sqrt(args.ratio)
    h = HEIGHT / max(1, round(HEIGHT / np.sqrt(0.5 * area * (1 + k * k) / args.nodes)))
    msh = rod_mesh(comm, h)
    if comm.size > 1 and args.partition == "balanced":
        # what PartitionImbalanceWarning asks a user to do: DOLFINx gives each rank equal cells,
        # so one rank would hold the FE half and the other the particles (2-rank speed-up of a
        # lagrange step 1.05x); balanced_mesh gives each its share of both kinds of cell
        in_patch = lambda x: np.where(x[0] > 0.5 * LENGTH, PATCH_CELL_WORK, 1.0)  # noqa: E731
        msh = mf.balanced_mesh(msh, in_patch)
    hp = h / k
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 0.5 * LENGTH), hp)
    V = _compat.vector_function_space(msh)
    per_cell = int(np.ceil(args.quadrature_points * h / hp - 1e-9))
    if method == "hybrid":  # SPH particles, FE integration points in their sums (sec. 5.5)
        problem = mf.HybridElasticity(
            V,
            patch,
            material,
            variant=getattr(args, "variant", "HA-F"),
            quadrature_degree=degree_for(per_cell),  # also the smoothing cells per direction
            integration=getattr(args, "hybrid_integration", "smoothed"),
            consistent=False,  # "cells": the symmetric K, HA-F conserves energy to round-off
            particles=getattr(args, "hybrid_particles", "centred"),
        )
        dyn = ExplicitDynamics.coupled(problem, particle_mass="volume", safety=args.safety)
        return dyn, {"h_fe": h, "h_p": hp, "dilation": None}
    dilation = args.dilation
    if dilation is None:
        dilation = mf.DEFAULT_DILATION[method]
    smoothed = args.integration == "smoothed"  # the problem's own integration
    problem = mf.CoupledElasticity(
        V,
        patch,
        material,
        coupling=method,
        weight=args.weight,
        dilation=dilation,
        quadrature_degree=degree_for(per_cell),
        overlap=args.overlap,
        **({"integration": "smoothed"} if smoothed else {}),
    )
    options = {}
    if method in ("lagrange", "edge-to-edge", "master-slave") and not smoothed:
        options["integration"] = args.integration
    if method == "master-slave":
        options["slaves"] = getattr(args, "slaves", "layer")
    dyn = ExplicitDynamics.coupled(problem, safety=args.safety, **options)
    return dyn, {"h_fe": h, "h_p": hp, "dilation": dilation}


def johnson(args) -> bool:
    return getattr(args, "slaves", "layer") == "coincident"


def variant_label(method: str, args, variant: str | None = None) -> str | None:
    """The options that change a method, for the table and the JSON (``None``: defaults;
    the hybrid: its variant, then its particles and integration where not the defaults)."""
    parts = [variant] if variant else []
    if method == "hybrid":
        for name, default in (("hybrid_particles", "centred"), ("hybrid_integration", "smoothed")):
            value = getattr(args, name, default)
            if value != default:
                parts.append(value)
    if method == "master-slave" and johnson(args):
        parts.append("coincident")
    if method in ("efg", "lagrange", "edge-to-edge", "master-slave"):
        integration = getattr(args, "integration", "cells")
        if integration != "cells":
            parts.append({"stress-points": "stress-pts"}.get(integration, integration))
    return " ".join(parts) or None


def warm_jit(args, material) -> None:
    """Compile the FE forms (stiffness, lumped masses) once, on a tiny mesh, before timing."""
    # (the forms do not depend on the band width: a one-cell band fits any tiny rod)
    small = argparse.Namespace(**{**vars(args), "nodes": 40, "ratio": 1.0, "overlap": 1})
    for method in sorted(set(args.method) - {"efg"}):
        dyn, _ = build(method, small, material, MPI.COMM_SELF)
        dyn.destroy()


# -


# ## Run one method


# +
def run(method: str, args, material, rod: GaussianPulseRod, comm, probe_points) -> dict:
    comm.Barrier()
    t0 = time.perf_counter()
    dyn, spacing = build(method, args, material, comm)
    # SPH particles carry their values (the hybrid); MLS coefficients reproduce them
    how = "nodal" if method == "hybrid" else "collocation"
    dyn.set_initial(velocity=rod.initial_velocity, particle_values=how)
    dyn.critical_time_step()  # the stable-step bound (cached): set-up work, not a step's
    setup = time.perf_counter() - t0  # the builder's own dyn.timings["setup"] included
    errors: dict[float, float] = {}
    t_end = args.t_end if args.transits is None else args.transits * rod.transit_time
    outputs = [t for t in (T1, T2) if t <= t_end * (1 + 1e-9)]
    xdmf, frames = None, []
    if args.xdmf is not None:  # --xdmf: files per method (and ratio in a sweep), 11 frames
        xdmf = f"{args.xdmf}_{method}" + (f"_ratio{args.ratio:g}" if args.sweep else "")
        frames = list(np.linspace(0.0, t_end, 11))
    res = dyn.run(
        t_end,
        outputs=[*outputs, args.t_end, *frames],
        on_output=lambda d, n, t: errors.setdefault(t, d.velocity_error(rod.velocity)),
        xdmf=xdmf,
    )

    def error_at(t_req: float) -> float | None:  # the output step nearest to t_req
        if t_req not in outputs:
            return None
        return errors[min(errors, key=lambda t: abs(t - t_req))]

    end_error = dyn.velocity_error(rod.velocity)
    sizes = dyn.num_dofs()
    rec = {
        "method": method,
        "nodes": (sizes["fe_dofs"] + sizes["particle_dofs"]) // 2,
        "fe_nodes": sizes["fe_dofs"] // 2,
        "particles": sizes["particle_dofs"] // 2,
        "ratio": sizes["particle_dofs"] / sizes["fe_dofs"] if method not in ("fe", "efg") else None,
        "requested_ratio": args.ratio if method not in ("fe", "efg") else None,
        "transits": res.time / rod.transit_time,
        **spacing,
        "multiplier_dofs": sizes["multiplier_dofs"],
        "error_t1": error_at(T1),
        "error_t2": error_at(T2),
        "error_end": end_error,
        "t1": T1 if T1 in outputs else None,
        "t2": T2 if T2 in outputs else None,
        "t_end": res.time,
        "steps": res.steps,
        "dt": res.dt,
        "dt_courant": res.critical["courant"],
        "dt_spectral": res.critical["spectral"],
        "energy_drift": res.energy_drift,
        "energy_oscillation": res.energy_oscillation,
        "energy_transfer": res.energies[-1].transfer,
        "constraint_residual": res.max_residual,
        "time_setup": comm.allreduce(setup, op=MPI.MAX),
        "time_steps": comm.allreduce(res.timings["steps"], op=MPI.MAX),
        "time_per_step": comm.allreduce(res.timings["per_step"], op=MPI.MAX),
        "ranks": comm.size,
        "dolfinx_version": mf.DOLFINX_VERSION,
    }
    rec["time_total"] = rec["time_setup"] + rec["time_steps"]
    if probe_points is not None:
        v = dyn.velocity_at(probe_points)
        if comm.rank == 0:
            np.save(args.probe_out, v)
    dyn.destroy()
    return rec


# -


# ## Driver: run, tabulate beside Table III, check


# +
def main(argv: list[str] | None = None) -> list[dict]:
    args = parse(argv)
    for method in args.method:
        check_method(method)
    comm = MPI.COMM_WORLD
    rod = GaussianPulseRod(E=args.E, rho=args.rho, length=LENGTH, center=args.center)
    material = mf.LinearElastic(args.E, 0.0, "strain", rho=args.rho)
    probe_points = None
    if args.probe_in is not None:
        probe_points = np.load(args.probe_in) if comm.rank == 0 else np.zeros((0, 2))
    warm_jit(args, material)
    ratios = [args.ratio] if args.sweep is None else args.sweep
    records = []
    for ratio in ratios:
        a = argparse.Namespace(**{**vars(args), "ratio": ratio})
        for m in args.method:
            if m in ("fe", "efg") and ratio != ratios[0]:
                continue  # the pure methods do not depend on the ratio
            for variant in args.hybrid_variant if m == "hybrid" else [None]:
                a.variant = variant
                records.append(run(m, a, material, rod, comm, probe_points))
                records[-1]["variant"] = variant_label(m, a, variant)
                records[-1]["integration"] = (
                    a.integration if m != "hybrid" else a.hybrid_integration
                )
                records[-1]["placement"] = a.hybrid_particles if m == "hybrid" else None
                records[-1]["slaves"] = a.slaves if m == "master-slave" else None
    report(records, comm)
    if args.json and comm.rank == 0:
        with open(args.json, "w") as f:
            json.dump(records[0] if len(records) == 1 else records, f, indent=1)
    if not args.no_check:
        defaults = vars(parse([]))
        ignored = {"method", "json", "xdmf", "probe_in", "probe_out", "no_check", "variant"}
        default_run = all(v == defaults.get(k) for k, v in vars(args).items() if k not in ignored)
        check(records, comm, default_run)
    return records


def _fmt(x, spec: str) -> str:
    width = int(spec.split(".")[0])
    return "-".rjust(width) if x is None else format(x, spec)


def report(records: list[dict], comm) -> None:
    if comm.rank != 0:
        return
    print(
        f"Rod with Gaussian velocity (Rabczuk et al. 2006, Table III), {comm.size} rank(s), "
        f"DOLFINx {mf.DOLFINX_VERSION} (JIT excluded)"
    )

    def label_of(r: dict) -> str:
        return r["method"] + (f" {r['variant']}" if r.get("variant") else "")

    w = max(12, *(len(label_of(r)) for r in records))
    head = (
        f"{'method':{w}} {'ratio':>5} {'nodes':>6} {'FE':>6} {'part.':>6} {'err t1':>9} "
        f"{'err t2':>9} {'t2/t1':>5} {'paper t1':>8} {'paper t2':>8} {'steps':>6} {'dt':>9} "
        f"{'drift':>8} {'osc':>8} {'setup s':>8} {'steps s':>8} {'total s':>8}"
    )
    print(head)
    print("-" * len(head))
    for r in records:
        p = PAPER.get(r["method"], (None, None, None))
        label = label_of(r)
        growth = None
        if r["error_t1"] is not None and r["error_t2"] is not None:
            growth = r["error_t2"] / r["error_t1"]
        print(
            f"{label:{w}} {_fmt(r['ratio'], '5.2f')} {r['nodes']:6d} {r['fe_nodes']:6d} "
            f"{r['particles']:6d} {_fmt(r['error_t1'], '9.3e')} {_fmt(r['error_t2'], '9.3e')} "
            f"{_fmt(growth, '5.2f')} {_fmt(p[0], '8.4f')} {_fmt(p[1], '8.4f')} {r['steps']:6d} "
            f"{r['dt']:9.3e} {r['energy_drift']:8.1e} {r['energy_oscillation']:8.1e} "
            f"{r['time_setup']:8.2f} {r['time_steps']:8.2f} {r['time_total']:8.2f}"
        )
    if any(r["transits"] > 2.5 for r in records):
        print(
            "energy over "
            + ", ".join(
                f"{r['method']} {r['transits']:.1f} transits: drift {r['energy_drift']:.1e}"
                f" osc {r['energy_oscillation']:.1e}"
                for r in records
            )
        )
    print(
        "paper: about 20,000 nodes + particles, ratio 4:1, CPU minutes on 2006 hardware: "
        + ", ".join(f"{m} {v[2]}" for m, v in PAPER.items())
    )


#: Velocity error bounds at t1 and t2 of the default run (about 20,000 nodes + particles, ratio
#: about 4, pulse at 30 mm, quartic weight): about twice the larger of the two measured errors
#: (fe 5.9e-5, efg 5.5e-5, lagrange / edge-to-edge / master-slave 1.22e-4, bridging 1.21e-4,
#: ramp / ramp-cubic 4.55e-4, hybrid HA-F 2.36e-4; lane A, 1 rank).
DEFAULT_RUN_BOUNDS = {
    "fe": 1.2e-4,
    "efg": 1.1e-4,
    "lagrange": 2.5e-4,
    "edge-to-edge": 2.5e-4,
    "master-slave": 2.5e-4,
    "bridging": 2.5e-4,
    "ramp": 9.1e-4,
    "ramp-cubic": 9.1e-4,
    "hybrid": 4.8e-4,
}


def check(records: list[dict], comm, default_run: bool = False) -> None:
    """The demo checks its own results.

    * the discrete energy of central differences is conserved to round-off (drift < 1e-9) and
      the constraint residual stays at round-off (< 1e-12);
    * every velocity error below 0.2; from 15,000 nodes on, below the paper's best coupled
      error 0.0107 (bridging, Table III) at both times (the issue's target), and in the default
      run (``default_run``: the defaults of every option but ``--method``) below
      :data:`DEFAULT_RUN_BOUNDS`;
    * hybrid, from 15,000 nodes on: the error grows by at most 10 % from t1 to t2 (the issue's
      target: no spurious reflection).
    """
    failures = []
    for r in records:
        m = r["method"] + (f" {r['variant']}" if r.get("variant") else "")
        growth_checked = r["method"] == "hybrid" and r["nodes"] >= 15000
        if growth_checked and r["error_t1"] is not None and r["error_t2"] is not None:
            if not r["error_t2"] <= 1.10 * r["error_t1"]:  # the issue's target for the hybrid
                failures.append(
                    f"{m}: error grows t1 -> t2 by {r['error_t2'] / r['error_t1']:.3f} > 1.10"
                )
        if not r["energy_drift"] < 1e-9:
            failures.append(f"{m}: energy drift {r['energy_drift']:.2e} >= 1e-9")
        if not r["constraint_residual"] < 1e-12:
            failures.append(f"{m}: constraint residual {r['constraint_residual']:.2e} >= 1e-12")
        bound = 0.0107 if r["nodes"] >= 15000 else 0.2
        for key in ("error_t1", "error_t2", "error_end"):
            tight = default_run and key != "error_end" and r["method"] in DEFAULT_RUN_BOUNDS
            limit = DEFAULT_RUN_BOUNDS[r["method"]] if tight else bound
            if r[key] is not None and not r[key] < limit:
                failures.append(f"{m}: {key} {r[key]:.3e} >= {limit}")
    if failures:
        if comm.rank == 0:
            print("CHECK FAILED:\n  " + "\n  ".join(failures), file=sys.stderr)
        sys.exit(1)
    if comm.rank == 0:
        print("checks passed")


if __name__ == "__main__":
    main()
# -
