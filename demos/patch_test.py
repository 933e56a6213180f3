# # Linear patch test
#
# Belytschko et al. 1995, sec. 5.1.1: the displacement ``u = (x, y)`` (eq. 5.1) is prescribed on
# the whole boundary of the square ``[0, 2] x [0, 2]`` with no body force; the exact solution is
# that linear field, and a consistent method reproduces it to round-off. With EFG the error that
# remains comes from quadrature: the paper reports 1e-6 with Gauss cells. Variationally
# consistent integration (VCI, Chen, Hillman & Rüter 2013), the library's default, removes it;
# ``--no-consistent`` gives the plain Gauss quadrature of the papers, and ``--plain`` the papers'
# methods as published (plain Gauss, and bridging tied at its band particles, eq. 79-81).
# ``--field general`` prescribes ``u = c + G x`` with a shear and a rotation in ``G`` instead
# (the field of the coupling tests in ``tests/``).
#
# Methods: ``fe`` (Q1/P1 through DOLFINx), ``efg`` (particles everywhere, essential conditions by
# multipliers), and every coupling of ``mf.COUPLINGS``, whose particle patch is the right half
# of the square (the cells with centroid x > 1, particle spacing = the nominal cell size 2/n),
# the left half staying finite elements, as in the coupling tests (``tests/test_coupled.py``,
# ``test_ramp.py``, ``test_bridging.py``, ``test_edge_to_edge.py``). ``--method all`` runs them
# all and prints one table. ``--patch`` chooses the patch cells by another criterion:
# ``slanted`` (centroid right of the line x + 0.4 y = 1.45, which crosses the cells), ``curved``
# (centroid within 1.1 of the midpoint (2, 1) of the right side: an interface that follows a
# circle through the cells). ``--placement vertices`` puts the couplings' particles on the
# vertices of the patch cells instead of the (jittered) grid.
#
# Meshes (``--cells n`` per side, default 6):
#
# * ``regular``: DOLFINx's n x n grid of cells; particles on the regular grid;
# * ``irregular``: an unstructured gmsh mesh of the square, committed under ``meshes/`` as XDMF
#   (no gmsh needed to run; ``meshes/make_meshes.py`` regenerates it). Its two halves share the
#   line x = 1 with n uniform segments, so that the couplings' interface is straight and its
#   nodes sit on the particle grid; particles jittered by up to 30 % of their spacing;
# * ``perturbed``: the regular grid with interior vertices moved by up to 30 % of a cell (except
#   those on the line x = 1, the couplings' interface); particles jittered as on ``irregular``.
#
# The demo prints the maximum displacement error over the particles, the mesh vertices and a
# 41 x 41 grid of probe points, beside the target of the issue, and checks it:
#
# * targets: 1e-10 for FE and for every method with consistent integration (the default);
#   1e-6 with Gauss quadrature; none for master–slave (first order by construction, exempt);
# * a method that meets its target today and is expected to (``EXPECTED_TO_PASS``: FE, and EFG
#   and every variational coupling with consistent integration, on every mesh and patch) fails
#   the run (exit code 1) when it misses; bridging with ``--constraint points`` refuses where its
#   band has fewer particles than FE nodes (grid particles on the gmsh meshes), as expected;
# * the methods that are known to miss are reported as MISSED with the measured figure (reasons
#   in ``KNOWN_MISSES``) and do not change the exit code.
#
# Gauss quadrature alone reaches 1e-6 only with many more points than the 4 x 4 rule of the
# paper: the MLS functions are rational and only C2 across the edges of the supports, which
# cross the cells, so the Gauss error falls algebraically (about as n^-4 in the n points per
# direction: EFG 1.2e-4, 2.2e-6, 9.5e-8 for n = 4, 10, 25 on the regular quadrilaterals), not
# exponentially. ``--preset dense-gauss`` is the cheapest setting measured to reach 1e-6 for
# EFG, Lagrange and both ramps on the regular and the gmsh meshes, quadrilaterals and
# triangles: quartic weight, d_max = 3, Gauss degree 49 (25 x 25 points per quadrilateral, 39
# times the 4 x 4 rule; 0.5 to 5 s per method here). Under it those methods are expected to
# pass on those meshes (``PRESET_EXPECTED``); elsewhere (the perturbed mesh needs degree 59 for
# EFG) they are reported as measured. With the paper's own parameters (quartic, d_max = 2, 4 x 4
# Gauss; the defaults) the error is 1e-4 to 6e-4, not the 1e-6 of sec. 5.1.1, and the Gaussian
# weight (3.10a) as written is not zero at r = 1 (exp(-6.25) = 2e-3): its functions jump at the
# support edges and the error stays at 1e-3 to 2e-2 whatever the quadrature.
#
#     python demos/patch_test.py --method efg --mesh irregular [--json out.json]
#     python demos/patch_test.py --method all --mesh irregular --cell triangle --patch curved
#     python demos/patch_test.py --method all --mesh irregular --plain
#     python demos/patch_test.py --method all --mesh irregular --preset dense-gauss

# +
from __future__ import annotations

import argparse
import json
import pathlib
import sys

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat

import dolfinx
import dolfinx.io
import numpy as np
from mpi4py import MPI

METHODS = ("fe", "efg", *mf.COUPLINGS)
MESHES = ("regular", "irregular", "perturbed")
PATCHES = ("axis", "slanted", "curved")
MESH_DIR = pathlib.Path(__file__).resolve().parents[1] / "meshes"
SIZE = 2.0

#: Issue targets on the maximum error: exact methods and consistent integration, Gauss quadrature.
TARGET_EXACT, TARGET_GAUSS = 1e-10, 1e-6
#: (method, consistent) pairs that meet their target today: missing it fails the demo.
EXPECTED_TO_PASS = {
    ("fe", False),
    ("fe", True),
    ("efg", True),
    ("lagrange", True),
    ("edge-to-edge", True),
    ("ramp", True),
    ("ramp-cubic", True),
    ("bridging", True),
}
#: Settings (weight, d_max, Gauss degree) that trade cost for a smaller quadrature error; an
#: explicit --weight / --dilation / --quadrature-degree overrides the preset's value. The preset's
#: d_max applies to PRESET_METHODS only; the other methods keep their own.
PRESETS = {
    "dense-gauss": {"weight": "quartic", "dilation": 3.0, "quadrature_degree": 49},
}
PRESET_METHODS = ("efg", "lagrange", "ramp", "ramp-cubic")
#: (method, mesh) pairs expected to meet the Gauss target under a preset's exact settings, as
#: measured (6 x 6 cells; worst 6.2e-7, EFG on the gmsh quadrilaterals). Missing it fails the demo.
PRESET_EXPECTED = {
    "dense-gauss": {(m, mesh) for m in PRESET_METHODS for mesh in ("regular", "irregular")},
}
#: Defaults without a preset: 4 x 4 Gauss and the quartic weight of Belytschko et al. 1995.
DEFAULT_WEIGHT, DEFAULT_DEGREE = "quartic", 7
#: Why the others miss (measured figures: README and the coupling tests).
KNOWN_MISSES = {
    "efg": "Gauss quadrature error of the non-polynomial MLS functions (1e-4 to 6e-4 at the "
    "defaults); --preset dense-gauss brings it below 1e-6 on the regular and gmsh meshes, "
    "--consistent removes it",
    "lagrange": "Gauss quadrature error on the patch (2e-4 in tests/test_coupled.py); "
    "--preset dense-gauss brings it below 1e-6, --consistent removes it",
    "edge-to-edge": "collocated multipliers pass the interface force to the particles as "
    "int sigma n I_h phi (the FE interpolant), not int sigma n phi: an O(1) force error with "
    "Gauss quadrature (4e-2 here); --consistent writes the VCI identity with I_h phi on the "
    "interface and passes",
    "ramp": "blended interface functions are not polynomials: Gauss error (1.5e-4 to 5.6e-4 at "
    "the defaults); --preset dense-gauss brings it below 1e-6 on the regular and gmsh meshes; "
    "--consistent (VCI over the patch and the interface cells) passes",
    "ramp-cubic": "as ramp (1.9e-4 to 5e-4 at the defaults); --preset dense-gauss brings it "
    "below 1e-6 on the regular and gmsh meshes; --consistent passes",
    "bridging": "Gauss quadrature error of the alpha-weighted particle energy (8e-5 with the "
    "integral constraint); the point constraints (--plain) also do not transmit the band's "
    "force consistently (3.6e-2); consistent integration (the default) passes with either",
    "master-slave": "exempt: rigid links drop the strain across the first particle layer",
}
# -


# ## Command line


# +
def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description="Linear patch test (Belytschko et al. 1995, 5.1.1)")
    p.add_argument("--method", choices=(*METHODS, "all"), default="efg")
    p.add_argument("--mesh", choices=MESHES, default="regular")
    p.add_argument("--cell", choices=("quadrilateral", "triangle"), default="quadrilateral")
    p.add_argument("--cells", type=int, default=6, help="cells per side (nominal for irregular)")
    p.add_argument("--patch", choices=PATCHES, default="axis", help="criterion of the patch cells")
    p.add_argument(
        "--placement",
        choices=("grid", "vertices"),
        default="grid",
        help="couplings' particles: on the grid of spacing 2/n (jittered on the irregular "
        "meshes), or one at every vertex of the patch cells",
    )
    p.add_argument(
        "--consistent",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="variationally consistent integration (default: on, off with --plain or --preset)",
    )
    p.add_argument(
        "--plain",
        action="store_true",
        help="the papers' methods: plain Gauss quadrature, bridging tied at its band particles",
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default=None,
        help="dense-gauss: quartic weight, d_max 3, Gauss degree 49 (below 1e-6 without VCI "
        "for efg, lagrange, ramp, ramp-cubic on the regular and gmsh meshes; 39 x the points)",
    )
    p.add_argument(
        "--quadrature-degree",
        type=int,
        default=None,
        help=f"Gauss degree (default {DEFAULT_DEGREE}: 4 x 4 points on quadrilaterals)",
    )
    p.add_argument(
        "--weight",
        choices=("quartic", "cubic", "gaussian"),
        default=None,
        help=f"MLS weight (default {DEFAULT_WEIGHT})",
    )
    p.add_argument(
        "--dilation",
        type=float,
        default=None,
        help="MLS d_max (default: 2.0; each coupling's mf.DEFAULT_DILATION, 2.5 for the ramps)",
    )
    p.add_argument("--overlap", type=int, default=2, help="bridging: band width in cells")
    p.add_argument(
        "--constraint",
        choices=("points", "integral"),
        default=None,
        help="bridging: tie the band over its cells (eq. 52, default) or at its particles "
        "(eq. 79-81, default with --plain)",
    )
    p.add_argument(
        "--field",
        choices=("identity", "general"),
        default="identity",
        help="identity: u = (x, y) (Belytschko eq. 5.1); general: u = c + G x of the tests",
    )
    p.add_argument("--json", default=None, help="write the record(s) as JSON")
    args = p.parse_args(argv)
    preset = PRESETS.get(args.preset, {})
    if args.consistent is None and (args.plain or args.preset is not None):
        args.consistent = False
    if args.constraint is None:
        args.constraint = "points" if args.plain else "integral"
    args.preset_overridden = [
        k for k in preset if getattr(args, k) is not None and getattr(args, k) != preset[k]
    ]
    for key, default in (("weight", DEFAULT_WEIGHT), ("quadrature_degree", DEFAULT_DEGREE)):
        if getattr(args, key) is None:
            setattr(args, key, preset.get(key, default))
    if args.quadrature_degree < 1:
        p.error(f"--quadrature-degree must be at least 1, got {args.quadrature_degree}")
    if args.cells < 2:
        p.error(f"--cells must be at least 2, got {args.cells}")
    if args.dilation is not None and not (np.isfinite(args.dilation) and args.dilation > 0):
        p.error(f"--dilation must be positive, got {args.dilation}")
    if args.mesh == "irregular" and not mesh_file(args.cell, args.cells).exists():
        p.error(
            f"no irregular mesh {mesh_file(args.cell, args.cells)}; generate it with "
            f"'python3 meshes/make_meshes.py --cells {args.cells}' (needs gmsh)"
        )
    return args


# -


# ## Meshes


# +
def mesh_file(cell: str, n: int) -> pathlib.Path:
    """The committed gmsh mesh (see ``meshes/make_meshes.py``, which names it)."""
    return MESH_DIR / f"patch_irregular_{cell}_{n}.xdmf"


def perturb_interior(msh, amount: float, size: float) -> None:
    """Move interior vertices by up to ``amount`` (deterministic in the coordinates, so every
    rank moves its copies of a shared vertex alike). Vertices on the line ``x = size / 2`` (the
    couplings' interface) stay where they are, on the particle grid."""
    x = msh.geometry.x
    interior = np.all((x[:, :2] > 1e-9) & (x[:, :2] < size - 1e-9), axis=1)
    interior &= ~np.isclose(x[:, 0], size / 2)
    phase = np.sin(12.9898 * x[:, 0] + 78.233 * x[:, 1]) * 43758.5453
    u = phase - np.floor(phase)
    phase2 = np.sin(39.3468 * x[:, 0] + 11.135 * x[:, 1]) * 24634.6345
    v = phase2 - np.floor(phase2)
    x[interior, 0] += amount * (2 * u[interior] - 1)
    x[interior, 1] += amount * (2 * v[interior] - 1)


def make_mesh(comm, args):
    """The patch-test mesh of ``--mesh`` and ``--cell``, and the particle jitter that goes
    with it."""
    n = args.cells
    if args.mesh == "irregular":
        encoding = dolfinx.io.XDMFFile.Encoding.ASCII
        with dolfinx.io.XDMFFile(comm, str(mesh_file(args.cell, n)), "r", encoding=encoding) as f:
            msh = f.read_mesh(name="mesh")
        return msh, 0.3
    cell = getattr(dolfinx.mesh.CellType, args.cell)
    msh = dolfinx.mesh.create_rectangle(comm, [np.zeros(2), np.full(2, SIZE)], [n, n], cell)
    if args.mesh == "perturbed":
        perturb_interior(msh, 0.3 * SIZE / n, SIZE)
        return msh, 0.3
    return msh, 0.0


def probe_points(msh, n: int, comm) -> np.ndarray:
    """This rank's share of the mesh vertices and of a 41 x 41 grid on the square."""
    s = np.linspace(0.0, SIZE, 41)
    grid = np.stack(np.meshgrid(s, s), axis=-1).reshape(-1, 2)
    vertices = msh.geometry.x[:, :2]
    return np.vstack([vertices, grid[comm.rank :: comm.size]])


def patch_cells(msh, patch: str) -> np.ndarray:
    """Owned cells of the patch of ``--patch``, chosen by their centroid ``c``: ``axis``
    ``c_x > 1`` (the coupling tests' patch); ``slanted`` ``c_x + 0.4 c_y > 1.45``; ``curved``
    ``|c - (2, 1)| < 1.1``."""
    n = msh.topology.index_map(msh.topology.dim).size_local
    c = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    if patch == "slanted":
        return np.flatnonzero(c[:, 0] + 0.4 * c[:, 1] > 1.45)
    if patch == "curved":
        return np.flatnonzero(np.hypot(c[:, 0] - SIZE, c[:, 1] - SIZE / 2) < 1.1)
    return np.flatnonzero(c[:, 0] > SIZE / 2)


# -


# ## The methods
#
# Each returns the maximum error on this rank and the number of particles.


# +
def dilation(args, method: str) -> float:
    if args.dilation is not None:
        return args.dilation
    if args.preset is not None and method in PRESET_METHODS:
        return PRESETS[args.preset]["dilation"]
    return mf.DEFAULT_DILATION.get(method, 2.0)


def consistent_option(args, method: str) -> bool:
    """``--consistent`` / ``--no-consistent`` / ``--plain``, else the library's default: VCI for
    EFG and every variational coupling, plain Gauss for master-slave (see
    :class:`~dolfinx_meshfree.CoupledElasticity`)."""
    if args.consistent is not None:
        return bool(args.consistent)
    return method != "master-slave"


def run_fe(msh, args, exact, material, points):
    V = _compat.vector_function_space(msh)
    sol = mf.solve_fe_elasticity(
        V, material, dirichlet=[(mf.boundary_facets(msh), lambda x: exact.displacement(x[:2].T).T)]
    )
    u = mf.evaluate_fe_function(sol.u, points)
    return float(np.abs(u - exact.displacement(points)).max(initial=0.0)), 0


def run_efg(msh, args, exact, material, points, jitter):
    particles = mf.ParticleSet.from_cells(msh, SIZE / args.cells, jitter=jitter)
    problem = mf.EFGElasticity(
        particles,
        material,
        weight=args.weight,
        dilation=dilation(args, "efg"),
        quadrature_degree=args.quadrature_degree,
        consistent=consistent_option(args, "efg"),
    )
    problem.add_dirichlet(mf.boundary_facets(msh), exact.displacement)
    sol = problem.solve()
    # (EFG evaluation is local: the particles are replicated, each rank takes a share of them)
    comm = msh.comm
    pts = np.vstack([particles.positions[comm.rank :: comm.size], points])
    err = np.abs(sol.displacement(pts) - exact.displacement(pts)).max(initial=0.0)
    return float(err), particles.num_particles


def run_coupled(msh, args, exact, material, points, jitter, coupling):
    cells = patch_cells(msh, args.patch)
    if args.placement == "vertices":
        patch = mf.ParticlePatch(msh, cells, placement="vertices")
    else:
        patch = mf.ParticlePatch(msh, cells, SIZE / args.cells, jitter=jitter)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh),
        patch,
        material,
        coupling=coupling,
        weight=args.weight,
        dilation=dilation(args, coupling),
        quadrature_degree=args.quadrature_degree,
        consistent=consistent_option(args, coupling),
        **(
            {"overlap": args.overlap, "constraint": args.constraint}
            if coupling == "bridging"
            else {}
        ),
    )
    problem.add_dirichlet(mf.boundary_facets(msh), exact.displacement)
    sol = problem.solve()
    comm = msh.comm
    pts = np.vstack([patch.particles.positions[comm.rank :: comm.size], points])
    err = np.abs(sol.displacement(pts) - exact.displacement(pts)).max(initial=0.0)
    return float(err), patch.particles.num_particles


# -


# ## Driver: run, tabulate, check


# +
def target(method: str, consistent: bool) -> float | None:
    """The issue's target for a method, None for master–slave (exempt)."""
    if method == "master-slave":
        return None
    if method == "fe" or consistent:
        return TARGET_EXACT
    return TARGET_GAUSS


def preset_expects(args, method: str, consistent: bool) -> bool:
    """Whether ``--preset`` expects ``method`` to meet the Gauss target here: its measured
    (method, mesh) pairs, at the preset's own settings (not overridden by a flag)."""
    return (
        args.preset is not None
        and not consistent
        and not args.preset_overridden
        and (method, args.mesh) in PRESET_EXPECTED[args.preset]
    )


def refusal_expected(args, method: str, error: str) -> bool:
    """Bridging with its point constraints refuses (a ValueError naming the remedies) where
    its band has fewer particles than FE nodes: grid particles on the gmsh meshes."""
    return (
        method == "bridging"
        and args.constraint == "points"
        and "cannot determine the band multipliers" in error
    )


def run(args, method: str, comm) -> dict:
    msh, jitter = make_mesh(comm, args)
    exact = (
        mf.LinearField(G=((0.3, -0.2), (0.5, 0.1)), c=(0.1, -0.4))
        if args.field == "general"
        else mf.LinearField()
    )
    material = mf.LinearElastic(1000.0, 0.3)
    points = probe_points(msh, args.cells, comm)
    consistent = consistent_option(args, method) if method != "fe" else False
    note = ""
    try:
        if method == "fe":
            err, particles = run_fe(msh, args, exact, material, points)
        elif method == "efg":
            err, particles = run_efg(msh, args, exact, material, points, jitter)
        else:
            err, particles = run_coupled(msh, args, exact, material, points, jitter, method)
        err = comm.allreduce(err, op=MPI.MAX)
    except (ValueError, RuntimeError) as e:
        # The library raises these alike on every rank: a refusal with its remedy, or a solve
        # that fails (reported, so that one method cannot hide the table)
        refused = refusal_expected(args, method, str(e))
        err, particles = None, 0
        note = f"{'refused by the library' if refused else 'ERROR'}: {e}"
    goal = target(method, consistent)
    expected = (method, consistent) in EXPECTED_TO_PASS or preset_expects(args, method, consistent)
    if note.startswith("refused"):
        status = "refused"
    elif err is None:
        status = "FAILED" if expected else "ERROR"
    elif goal is None:
        status = "exempt"
    elif err is not None and err <= goal:
        status = "PASS"
    else:
        status = "FAILED" if expected else "MISSED"
    if status in ("MISSED", "exempt") and not note:
        note = KNOWN_MISSES.get(method, "")
    return {
        "method": method,
        "mesh": args.mesh,
        "patch": args.patch,
        "placement": args.placement,
        "cell": args.cell,
        "cells": msh.topology.index_map(msh.topology.dim).size_global,
        "particles": particles,
        "consistent": consistent if method != "fe" else None,
        "constraint": args.constraint if method == "bridging" else None,
        "quadrature_degree": args.quadrature_degree,
        "dilation": dilation(args, method) if method != "fe" else None,
        "weight": args.weight if method != "fe" else None,
        "preset": args.preset,
        "field": args.field,
        "max_error": err,
        "target": goal,
        "expected_to_pass": expected,
        "status": status,
        "note": note,
        "ranks": comm.size,
        "dolfinx_version": mf.DOLFINX_VERSION,
    }


def report(records: list[dict], comm) -> None:
    if comm.rank != 0:
        return
    field = "u = (x, y)" if records[0]["field"] == "identity" else "u = c + G x"
    print(
        f"Linear patch test (Belytschko et al. 1995, sec. 5.1.1), {field}, "
        f"{comm.size} rank(s), DOLFINx {mf.DOLFINX_VERSION}"
    )
    r0 = next((r for r in records if r["weight"]), records[0])
    preset = f", preset {r0['preset']}" if r0["preset"] else ""
    print(
        f"weight {r0['weight'] or '-'}, Gauss degree {r0['quadrature_degree']}{preset}, "
        f"patch {r0['patch']}"
    )
    head = (
        f"{'method':12} {'mesh':9} {'cells':17} {'part.':>5} {'d_max':>5} {'consistent':>10} "
        f"{'max error':>9} {'target':>7}  status"
    )
    print(head)
    print("-" * len(head))
    for r in records:
        cells = f"{r['cell']} {r['cells']}"
        cons = "-" if r["consistent"] is None else ("VCI" if r["consistent"] else "Gauss")
        err = "n/a" if r["max_error"] is None else f"{r['max_error']:.2e}"
        goal = "-" if r["target"] is None else f"{r['target']:.0e}"
        part = str(r["particles"]) if r["max_error"] is not None else "-"
        dmax = "-" if r["dilation"] is None else f"{r['dilation']:g}"
        print(
            f"{r['method']:12} {r['mesh']:9} {cells:17} {part:>5} {dmax:>5} {cons:>10} "
            f"{err:>9} {goal:>7}  {r['status']}"
        )
    notes = [r for r in records if r["note"]]
    for r in notes:
        print(f"  {r['method']}: {r['note']}")


def main(argv: list[str] | None = None) -> dict | list[dict]:
    """Run the patch test; returns the record of ``--method M`` or the list of ``all``."""
    args = parse(argv)
    comm = MPI.COMM_WORLD
    methods = METHODS if args.method == "all" else (args.method,)
    records = [run(args, method, comm) for method in methods]
    report(records, comm)
    result = records if args.method == "all" else records[0]
    if args.json and comm.rank == 0:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    # The check: the methods expected to pass must pass; the others are reported as measured.
    failed = [r for r in records if r["status"] == "FAILED"]
    if failed:
        if comm.rank == 0:
            lines = [
                f"{r['method']} ({r['mesh']}, {r['cell']}, consistent={r['consistent']}): "
                f"max error {r['max_error']} > target {r['target']:.0e}"
                for r in failed
            ]
            print("CHECK FAILED:\n  " + "\n  ".join(lines), file=sys.stderr)
        sys.exit(1)
    if comm.rank == 0:
        print("checks passed (every method expected to pass did)")
    return result


if __name__ == "__main__":
    main()
# -
