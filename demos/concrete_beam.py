# # A notched concrete beam in three-point bending: a cohesive crack in a particle patch
#
# Concrete is quasi-brittle: a crack opens gradually over a fracture process zone and the
# load–opening curve softens after the peak. The beam is modelled as a user would: a DOLFINx mesh of
# the whole beam, FE cells everywhere but a particle patch around the notch, where the crack runs.
# Rabczuk, Xiao & Sauer 2006, sec. 6.1.2, model the concrete as linear elastic in compression with
# damage in tension, and a linear traction–crack-opening law on the discontinuity. Two models of
# the fracture process zone, `--crack`:
#
# * `cohesive` (the default): Hillerborg's fictitious crack (Hillerborg, Modéer & Petersson 1976),
#   the model Petersson computed this beam with. The bulk is elastic; the notch goes on up the
#   ligament to the top edge as a crack (`mf.Crack(..., through=True)`) whose faces carry
#   `mf.LinearCohesive`: bonded until the normal traction reaches f_t, then linear softening to
#   zero at w_c = 2 G_f / f_t, closed by contact in compression. The path of a mode I crack in
#   this beam is known (straight up from the notch) and given by default; `--path found` starts
#   the cohesive crack as a bonded stretch of four spacings above the notch and lets it grow
#   (`mf.CohesiveGrowth`: the tip kept three spacings ahead of where the faces reach f_t, each new
#   segment normal to the averaged principal stress at the front); it finds the mode I path,
#   vertical to 1e-3 h, with the given path's peak within 1 % (`tests/test_cohesive_growth.py`;
#   measured at h = 20 and 10 mm in `benchmarks/bench_concrete_beam.py --path found`).
# * `band`: `mf.RankineDamage` in the bulk, isotropic damage driven by the largest principal
#   effective stress, linear softening regularised by the crack band (Bažant & Oh 1983); it acts
#   on the FE cells and the particles alike.
#
# The states (of the faces or of the bulk) are committed at every converged step. The peak is
# passed by indirect displacement control (`mf.follow_path`): the crack mouth opening displacement
# (CMOD) across the notch grows, the load factor is an unknown.
#
# Setup `three-point-bend` (the default): a simply supported beam of span `--span` and depth
# `--depth` with a notch of depth `--notch-depth` at mid-span (a traction-free crack of zero
# width in the patch), loaded at mid-span on the top edge. Defaults: the beam of Petersson's thesis
# (P.-E. Petersson, *Crack growth and development of fracture zones in plain concrete and similar
# materials*, Report TVBM-1006, Lund Institute of Technology, 1981), widely used as a benchmark of
# smeared and cohesive crack models: span 2000 mm, depth 200 mm, thickness 50 mm, notch 100 mm,
# E = 30,000 MPa, nu = 0.2, f_t = 3.33 MPa, G_f = 0.124 N/mm. Units: mm, MPa, N/mm, N.
#
# The supports hold the vertical displacement of the beam's end faces (shear supports, free to
# rotate) and the horizontal displacement of the top edge at mid-span (the symmetry line), so
# that no support restrains the bending: a roller held at one corner node concentrates a reaction
# that cracks the concrete there.
#
# Methods: `lagrange` (the default), `edge-to-edge`, `bridging`, `ramp`, `ramp-cubic`,
# `master-slave` (a particle patch of width `--patch-width` around the notch, FE elsewhere) and
# `efg` (particles at every vertex of the mesh: the reference the couplings are compared with).
# Master–slave integrates its patch by Gauss quadrature (consistent integration is not its choice,
# see `dolfinx_meshfree.couplings.master_slave`), so its cut ligament stiffens the first step a
# little more: 1.6 % at h = 10 mm, 3.9 % at 20 mm, and 5.1 % at 25 mm, where the 5 % check below
# stops it (lagrange: 0.9 %, 2.9 %; pure EFG 3.9 % at 25 mm).
#
# Self-checks (on by default, `--no-check` skips them):
#
# * the first step is elastic and equals the linear-elastic solve of the same model (the same
#   mesh, patch, coupling and load): to 1e-6 with `band`; with `cohesive`, whose bonded faces
#   cut the particle field along the ligament, within 5 % of the uncut beam's (measured 3.9 %
#   at 8 cells over the depth, h = 25 mm; 1.1 % at 20 cells);
# * the energy balance: external work minus stored energy equals the energy the laws dissipated
#   (their closed forms at the committed states) within 2 %;
# * `band`: the damage stays in the patch (the FE cells stay elastic), else widen
#   `--patch-width`;
# * the path passes the peak (the final load is below half the peak).
#
# Printed and in the JSON: the load–CMOD and load–deflection curves, the peak load, the CMOD at
# the peak, the dissipated energy (J) and its ratio to G_f times the ligament area (a reliability
# figure, not a check: the crack is not fully open at the end; with `band` a smooth MLS field
# spreads the damage over about one support radius, so this ratio runs above 1 in the tail), the
# crack path (`path`: the face points past f_t, or the particle points with damage >= 0.9), the
# counts of particles, FE cells and Newton iterations, the time.
#
# Usage:
#
#     python demos/concrete_beam.py [--h 10] [--method lagrange] [--json beam.json] [--png beam.png]
#     mpirun -n 2 python demos/concrete_beam.py --h 20

# +
from __future__ import annotations

import argparse
import json
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
from mpi4py import MPI

SETUPS = ("three-point-bend",)
#: A crack whose path is found (`--path found`): the spacings kept between the softening front and
#: the tip (mf.CohesiveGrowth's default).
AHEAD = 3.0
CRACKS = ("cohesive", "band")
METHODS = ("efg", *mf.COMPONENT_COUPLINGS)  # the supports hold single components
# -


# ## The model, as a DOLFINx user builds it


# +
def particles_cracks(model) -> list:
    """The model's cracks (pure EFG's, or its patch's)."""
    return model.cracks if isinstance(model, mf.EFGElasticity) else model.patch.cracks


def beam_model(args, law, cohesive=None):
    """Mesh, patch with the notch, the coupled model, its supports and its reference load (1 N
    per mm of thickness at mid-span). With a ``cohesive`` law: the notch goes on up to the top
    edge as a crack through the beam whose ligament faces carry the law (Hillerborg's
    fictitious crack: they are bonded until f_t)."""
    S, D = args.span, args.depth
    L = args.length or S
    nx = round(L / args.h)
    nx += (nx + 1) % 2  # an odd count: mid-span in the middle of a cell column
    ny = max(2, round(D / args.h))
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD,
        [np.array([0.0, 0.0]), np.array([L, D])],
        [nx, ny],
        dolfinx.mesh.CellType.quadrilateral,
    )
    hx = L / nx
    xm = L / 2
    V = _compat.vector_function_space(msh)
    if cohesive is None:
        notch = mf.Crack([[xm, 0.0], [xm, args.notch_depth]])
    elif args.path == "found":  # a bonded stretch ahead of the notch, grown as the faces soften
        top = min(D - 2 * hx, args.notch_depth + (AHEAD + 1) * hx)
        notch = mf.Crack([[xm, 0.0], [xm, args.notch_depth], [xm, top]], through=True)
    else:
        notch = mf.Crack([[xm, 0.0], [xm, args.notch_depth], [xm, D]], through=True)
    if args.method == "efg":  # particles everywhere: the reference of the couplings
        particles = mf.ParticleSet.from_vertices(msh)
        model = mf.EFGElasticity(particles, law, cracks=[notch])
    else:
        cells = dolfinx.mesh.locate_entities(
            msh, 2, lambda p: np.abs(p[0] - xm) < args.patch_width / 2 + 1e-9 * L
        )
        patch = mf.ParticlePatch(msh, cells, placement="vertices", cracks=[notch])
        particles = patch.particles
        model = mf.CoupledElasticity(
            V, patch, law, coupling=args.method, particle_band=args.particle_band
        )
    if cohesive is not None:
        model.add_cohesive(notch, cohesive, segments=[1])  # the notch itself is traction-free
    a, b = (L - S) / 2, (L + S) / 2  # the supports
    tol = 1e-9 * L
    if a > tol:  # an overhang: the supports are the bottom facets beside x = a and x = b
        left = mf.boundary_facets(msh, lambda p: np.isclose(p[1], 0) & (np.abs(p[0] - a) < hx))
        right = mf.boundary_facets(msh, lambda p: np.isclose(p[1], 0) & (np.abs(p[0] - b) < hx))
    else:  # the end faces
        left = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0))
        right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    for facets in (left, right):
        model.add_dirichlet(facets, lambda x: np.zeros_like(x), components=(1,))
    top_mid = mf.boundary_facets(msh, lambda p: np.isclose(p[1], D) & (np.abs(p[0] - xm) < hx / 2))
    model.add_dirichlet(top_mid, lambda x: np.zeros_like(x), components=(0,))
    width = 3 * hx  # the load: 1 N/mm over the top facets of the three middle columns
    top = mf.boundary_facets(
        msh, lambda p: np.isclose(p[1], D) & (np.abs(p[0] - xm) < width / 2 + tol)
    )
    model.add_traction(top, lambda x, n: np.tile([0.0, -1.0 / width], (len(x), 1)))
    return model, particles, msh, xm, hx


# -


# ## One run


# +
def run(args) -> dict:
    comm = MPI.COMM_WORLD
    elastic = mf.LinearElastic(args.E, args.nu, plane="stress")
    if args.crack == "cohesive":
        law, cohesive = elastic, mf.LinearCohesive(ft=args.ft, Gf=args.Gf)
    else:
        law = mf.RankineDamage(E=args.E, nu=args.nu, ft=args.ft, Gf=args.Gf, plane="stress")
        cohesive = None
    t0 = time.perf_counter()
    model, particles, msh, xm, hx = beam_model(args, law, cohesive)
    growth = None
    if cohesive is not None and args.path == "found":
        (crack,) = particles_cracks(model)
        growth = mf.CohesiveGrowth(crack, ahead=AHEAD)
    d = hx / 2  # the CMOD: the bottom points half a cell either side of the notch
    cmod = mf.DisplacementControl([[xm - d, 0.0], [xm + d, 0.0]], [[-1.0, 0.0], [1.0, 0.0]])
    deflection = mf.DisplacementControl([[xm - hx / 2, args.depth]], [[0.0, -1.0]])
    options = mf.PathOptions(
        increment=args.end_cmod / 250,
        end=args.end_cmod,
        min_load=args.min_load,
        max_increment=args.end_cmod / 25,
    )
    path = mf.follow_path(model, cmod, options, monitors={"deflection": deflection}, growth=growth)
    seconds = time.perf_counter() - t0
    B = args.thickness
    load = np.array(path.load_factor) * B  # N
    k = int(np.argmax(load))
    if cohesive is None:
        *fe_state, particle_state = path.solution.states  # no FE state in pure EFG
        damage = particle_state.committed["damage"][:, 0]
        zone = particle_state.points[damage >= 0.9]
        fe_damage = max([float(st.committed["damage"].max(initial=0.0)) for st in fe_state] + [0.0])
    else:  # the face points that have passed f_t: the process zone and the open crack
        (faces,) = path.solution.states
        zone = faces.points[faces.committed["kappa"][:, 0] > faces.law.w_0]
        fe_damage = 0.0  # the bulk is elastic
    zone = np.concatenate(comm.allgather(zone)) if comm.size > 1 else zone
    fe_damage = comm.allreduce(fe_damage, op=MPI.MAX)
    ligament = (args.depth - args.notch_depth) * B
    n_cells = msh.topology.index_map(2).size_local
    record = {
        "setup": args.setup,
        "method": args.method,
        "crack": args.crack,
        "h_mm": args.h,
        "particles": particles.num_particles,
        "fe_cells": 0
        if args.method == "efg"
        else comm.allreduce(int((~model.patch.in_patch[:n_cells]).sum())),
        "newton_iterations": int(sum(path.iterations)),
        "steps": len(load),
        "cuts": path.cuts,
        "cmod": list(map(float, path.control)),
        "deflection": list(map(float, path.monitors["deflection"])),
        "load": list(map(float, load)),
        "peak_load_N": float(load[k]),
        "cmod_at_peak_mm": float(path.control[k]),
        "dissipated_energy_J": float(path.dissipated_energy[-1] * B / 1000.0),
        "energy_balance_J": float((path.external_work[-1] - path.stored_energy[-1]) * B / 1000.0),
        "energy_ratio_to_Gf_area": float(path.dissipated_energy[-1] * B / (args.Gf * ligament)),
        "fe_max_damage": fe_damage,
        "damage_zone": zone.tolist(),
        "path": zone.tolist(),
        "time_total": seconds,
    }
    # the first step against the linear-elastic solve of the same model
    twin, *_ = beam_model(args, mf.LinearElastic(args.E, args.nu, plane="stress"))
    linear = twin.solve()
    pts = np.array([[xm - d, 0.0], [xm + d, 0.0]])
    opening = float(np.diff(linear.displacement(pts)[:, 0])[0])  # per unit load factor
    record["elastic_step_error"] = abs(path.control[0] / path.load_factor[0] - opening) / opening
    return record


# -


# ## Checks, table, plot


# +
def check(r: dict) -> None:
    bound = 0.05 if r["crack"] == "cohesive" else 1e-6  # the cut ligament's bond (see top)
    assert r["elastic_step_error"] <= bound, (
        f"first step vs linear solve: {r['elastic_step_error']}"
    )
    balance = abs(r["energy_balance_J"] - r["dissipated_energy_J"])
    assert balance <= 0.02 * r["dissipated_energy_J"], (
        f"energy balance: external work - stored {r['energy_balance_J']:.4g} J against "
        f"dissipated {r['dissipated_energy_J']:.4g} J"
    )
    assert r["fe_max_damage"] == 0.0, (
        f"the damage left the patch (FE damage {r['fe_max_damage']:.3f}): widen --patch-width"
    )
    assert r["load"][-1] < 0.5 * r["peak_load_N"], (
        "the path did not pass the peak: raise --end-cmod"
    )


def plot(r: dict, png: str) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed, PNG skipped: apt-get install python3-matplotlib")
        return
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(r["cmod"], r["load"], "-o", ms=2)
    ax[0].set_xlabel("CMOD (mm)")
    ax[0].set_ylabel("load (N)")
    z = np.asarray(r["damage_zone"]).reshape(-1, 2)
    ax[1].plot(z[:, 0], z[:, 1], ".", ms=3)
    ax[1].set_xlabel("x (mm)")
    ax[1].set_ylabel("y (mm)")
    ax[1].set_title(
        "crack faces past f_t" if r["crack"] == "cohesive" else "particle points, damage >= 0.9"
    )
    fig.suptitle(f"{r['setup']}, {r['method']}, {r['crack']}, h = {r['h_mm']:g} mm")
    fig.tight_layout()
    fig.savefig(png, dpi=120)


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--setup", default="three-point-bend", choices=SETUPS)
    p.add_argument("--method", default="lagrange", choices=METHODS)
    p.add_argument(
        "--crack",
        default="cohesive",
        choices=CRACKS,
        help="cohesive: an elastic bulk and a cohesive crack up the ligament; band: damage "
        "with the crack band in the bulk",
    )
    p.add_argument(
        "--path",
        default="given",
        choices=("given", "found"),
        help="cohesive: the crack's path given up the ligament, or found as it grows "
        "(mf.CohesiveGrowth: normal to the averaged principal stress ahead of the tip)",
    )
    p.add_argument("--span", type=float, default=2000.0, help="mm")
    p.add_argument("--length", type=float, default=None, help="mm (default: the span)")
    p.add_argument("--depth", type=float, default=200.0, help="mm")
    p.add_argument("--thickness", type=float, default=50.0, help="mm")
    p.add_argument("--notch-depth", type=float, default=100.0, help="mm")
    p.add_argument("--notch-width", type=float, default=0.0, help="mm (0: a crack)")
    p.add_argument("--E", type=float, default=30000.0, help="MPa")
    p.add_argument("--nu", type=float, default=0.2)
    p.add_argument("--ft", type=float, default=3.33, help="MPa")
    p.add_argument("--Gf", type=float, default=0.124, help="N/mm")
    p.add_argument("--h", type=float, default=10.0, help="cell size and particle spacing, mm")
    p.add_argument("--patch-width", type=float, default=200.0, help="mm, centred on the notch")
    p.add_argument(
        "--particle-band",
        type=float,
        default=None,
        help="crack band of the particle points in cell sizes (default: the MLS dilation)",
    )
    p.add_argument("--end-cmod", type=float, default=0.5, help="mm")
    p.add_argument("--min-load", type=float, default=0.1, help="stop below this share of peak")
    p.add_argument("--json", default=None)
    p.add_argument("--png", default=None)
    p.add_argument("--no-check", action="store_true")
    p.add_argument("--quiet", action="store_true", help="print nothing (benchmarks)")
    args = p.parse_args(argv)
    if args.notch_width != 0.0:
        p.error(
            f"--notch-width {args.notch_width}: the notch is a crack of zero width in this "
            "release; give 0"
        )
    if args.length is not None and args.length < args.span:
        p.error(f"--length {args.length} must be at least --span {args.span}")
    if not 0 < args.notch_depth < args.depth:
        p.error(f"--notch-depth {args.notch_depth} must lie in (0, --depth {args.depth})")
    r = run(args)
    if MPI.COMM_WORLD.rank == 0 and not args.quiet:
        print(
            f"{r['setup']}: {r['method']}, {r['crack']}, h = {r['h_mm']:g} mm, "
            f"{r['particles']} particles, "
            f"{r['fe_cells']} FE cells, {MPI.COMM_WORLD.size} rank(s)"
        )
        print(
            f"peak {r['peak_load_N']:.1f} N at CMOD {r['cmod_at_peak_mm']:.4f} mm; "
            f"dissipated {r['dissipated_energy_J']:.4f} J "
            f"({r['energy_ratio_to_Gf_area']:.2f} x G_f x ligament) at CMOD {r['cmod'][-1]:.3f} "
            f"mm and {r['load'][-1]:.1f} N; {r['steps']} steps, {r['newton_iterations']} Newton "
            f"iterations, {r['time_total']:.1f} s"
        )
        step = max(1, len(r["load"]) // 15)
        print("   CMOD mm  deflection mm    load N")
        for c, w, f in list(zip(r["cmod"], r["deflection"], r["load"], strict=True))[::step]:
            print(f"  {c:8.4f}  {w:13.4f}  {f:8.1f}")
    if MPI.COMM_WORLD.rank == 0:
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(r, fh, indent=1)
        if args.png:
            plot(r, args.png)
    if not args.no_check:
        check(r)
    return r


if __name__ == "__main__":
    main()
# -
