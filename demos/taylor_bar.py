# # The Taylor bar: a copper rod against a rigid wall (axisymmetric, large plastic flow)
#
# The classic benchmark of explicit codes for finite-strain plasticity (the set-up of Wilkins &
# Guinan, J. Appl. Phys. 44, 1973, as computed by many codes since; the same bar in the ANSYS
# Technology Showcase, ch. 17, "Metal Bar Impacting a Rigid Wall"): a copper rod of length
# ``L0 = 32.4 mm`` and radius ``R0 = 3.2 mm`` strikes a rigid, frictionless wall at
# ``v0 = 227 m/s``. Copper: ``E = 117 GPa``, ``nu = 0.35``, ``rho = 8930 kg/m^3``, von Mises
# with linear isotropic hardening from ``sigma_y = 400 MPa`` with tangent modulus ``E_t =
# 100 MPa``, rate- and temperature-independent. By 80 us the rod has stopped: its foot has
# flattened into a mushroom of radius about 7.0-7.2 mm, the rod has shortened to about
# 21.4-21.5 mm, and the plastic strain at the centre of the foot is about 3. These are the
# figures commonly quoted for this benchmark across codes; the original papers were not
# available here to re-read, so the reference (21.45 and 7.10 mm) is a central value of that
# quote, the demo's margins (1 % and 2 %) are about twice the largest deviation measured here
# at the default resolution, and the methods are also checked against each other
# (``tests/test_taylor_bar.py``: a coupled foot against FE, with and without the viscosity).
#
# The model is axisymmetric on the rod's (r, z) section, as a user writes it from the README:
#
# * the material: ``mf.JohnsonCook(A=400 MPa, B=H, n=1, C=0, plane="axisymmetric")``, the
#   bilinear hardening as Johnson–Cook's power law with ``n = 1`` and the plastic modulus
#   ``H = E E_t / (E - E_t)``; its artificial bulk viscosity is on (the default);
# * the wall: the foot's facets held in z (rollers: the wall is frictionless and, over 80 us,
#   the foot does not leave it); the axis held in r;
# * ``--method``: ``fe`` (Q1 with the cells' mean dilatation, the default), ``efg`` (particles
#   at the element size over the whole rod), or a coupling of ``dynamics.rate_forms.RATE_METHODS``:
#   particles over the foot (the cells below ``--patch`` of the length, 0.3 by default: where
#   the flow is large), FE above. Particles only where the physics needs them;
# * ``--cell hexahedron``: the rod in 3D, a quarter of it in hexahedra (a box whose square
#   section is mapped onto the quarter disc), its symmetry planes on rollers, the same law with
#   ``plane=None``; fe, efg, lagrange, edge-to-edge and bridging. Its foot radius is the mean
#   over the rim's nodes of the quarter (the mapped cells are not alike around the rim).
#
# Printed per method: the final length and foot radius against the benchmark's, the largest
# equivalent plastic strain, the energy balance (kinetic and internal, the viscous work in the
# internal energy, against the initial kinetic energy), the kinetic energy left, the steps,
# the last step over the first, the time and the time against FE. The run fails if the
# length or the radius leaves its margin around the benchmark's, or the balance its margin.
# At the default 5 cells across the radius every method but the hybrid is within the margins;
# the hybrid's SPH foot is 4.8 % too narrow (6.756 mm) and the run fails on it, saying so; at
# ``--cells 10`` it reaches 7.046 mm (the guide's impact page has the table).
#
# Why it is here: a user's Taylor bar at default options inverted its foot at 49 us. The bulk
# viscosity then sized its damper by the cell's reference size times ``J^(1/3)``. Plastic
# flow keeps ``J`` at 1, so that length stayed at the reference size while the foot's cells
# flattened to a fifth of it, and the linear term grew unstable against a step bounded by
# their thickness (with the linear term alone, the largest plastic strain ran away to 23). The
# viscosity now takes the cell's current thickness
# (``dolfinx_meshfree.physics.bulk_viscosity.current_lengths``), and the runs end at the
# benchmark's figures (``tests/test_taylor_bar.py``). The 3D rod then found a silent failure:
# with edge-to-edge at the foot it flew through the wall (14.24 mm long at 80 us, no plastic
# strain), because the velocity projection read the wall's rows, of the order of ``h^2`` in
# SI units, as redundant beside the coupling's unit rows; it now decides at a unit diagonal
# (``dolfinx_meshfree.dynamics.constraint``; the axisymmetry guide says more).
#
# Usage:
#
#     python demos/taylor_bar.py [--method fe efg lagrange ...] [--cells 5] [--patch 0.3]
#         [--cell quadrilateral|hexahedron] [--no-viscosity] [--json out.json]
#     mpirun -n 2 python demos/taylor_bar.py

# +
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics.rate_forms import RATE_METHODS

import dolfinx
import numpy as np
from mpi4py import MPI

LENGTH, RADIUS, VELOCITY, T_END = 32.4e-3, 3.2e-3, 227.0, 80e-6
E, NU, RHO, YIELD, TANGENT = 117e9, 0.35, 8930.0, 400e6, 100e6
#: Von Mises with linear hardening as Johnson–Cook (``n = 1``, no rate term): ``B`` is the
#: plastic modulus of the tangent modulus ``E_t``.
COPPER = mf.JohnsonCook(
    rho=RHO, E=E, nu=NU, A=YIELD, B=E * TANGENT / (E - TANGENT), n=1.0, C=0.0,
    plane="axisymmetric",
)  # fmt: skip
#: The benchmark's final length and foot radius (mm), as the literature quotes them.
REFERENCE = {"length": 21.45, "radius": 7.10}
#: The checks' margins, relative (about 2x the largest deviation measured at 5 cells over the
#: methods but the hybrid: length 0.44 %, radius 0.83 %; see the module header) and the
#: balance's.
MARGINS = {"length": 0.01, "radius": 0.02, "balance": 0.01}
METHODS = list(RATE_METHODS)
#: The methods of a 3D rod (``--cell hexahedron``): the couplings that carry 3D.
METHODS_3D = ["fe", "efg", "lagrange", "edge-to-edge", "bridging"]
CELLS = ["quadrilateral", "hexahedron"]
# -


# ## The model


def rod_mesh(cells: int, comm=MPI.COMM_WORLD, cell: str = "quadrilateral") -> dolfinx.mesh.Mesh:
    """The rod's (r, z) section in ``cells`` x ``cells L0 / R0`` quadrilaterals, its foot at
    z = 0; or (``cell="hexahedron"``) a quarter of the rod in ``cells`` x ``cells`` x ``cells
    L0 / R0`` hexahedra: a box whose unit square section is mapped onto the quarter disc
    (``x sqrt(1 - y^2 / 2)``, ``y sqrt(1 - x^2 / 2)``: the square's sides x = 0 and y = 0 stay
    the symmetry planes, its corner goes to the rim at 45 degrees)."""
    nz = max(1, round(cells * LENGTH / RADIUS))
    if cell == "quadrilateral":
        return dolfinx.mesh.create_rectangle(
            comm,
            [np.zeros(2), np.array([RADIUS, LENGTH])],
            [cells, nz],
            dolfinx.mesh.CellType.quadrilateral,
        )
    msh = dolfinx.mesh.create_box(
        comm,
        [np.zeros(3), np.array([1.0, 1.0, LENGTH])],
        [cells, cells, nz],
        dolfinx.mesh.CellType.hexahedron,
    )
    x = msh.geometry.x
    a, b = x[:, 0].copy(), x[:, 1].copy()
    x[:, 0] = RADIUS * a * np.sqrt(1.0 - 0.5 * b * b)
    x[:, 1] = RADIUS * b * np.sqrt(1.0 - 0.5 * a * a)
    return msh


def build(
    method: str,
    cells: int,
    comm=MPI.COMM_WORLD,
    law: object | None = None,
    patch: float = 0.3,
    cell: str = "quadrilateral",
) -> mf.ExplicitDynamics:
    """The rod of ``law`` (default :data:`COPPER`; in 3D the same law with ``plane=None``)
    thrown at the wall at :data:`VELOCITY`: its foot on rollers, its axis held in r (3D: the
    quarter's symmetry planes on rollers); a coupling's particles over the cells whose midpoint
    lies below ``patch`` of the length."""
    law = COPPER if law is None else law
    msh = rod_mesh(cells, comm, cell)
    d = msh.geometry.dim
    if d == 3:
        law = dataclasses.replace(law, plane=None)
    axial = d - 1
    wall = mf.boundary_facets(msh, lambda x: np.isclose(x[axial], 0.0))
    fixed = [(wall, (axial,))]
    for k in range(d - 1):  # the axis (2D), the symmetry planes (3D)
        fixed.append((mf.boundary_facets(msh, lambda x, k=k: np.isclose(x[k], 0.0)), (k,)))
    h = RADIUS / cells
    if method == "fe":
        dyn = mf.ExplicitDynamics.fe(_compat.vector_function_space(msh), law, fixed_facets=fixed)
    elif method == "efg":
        particles = mf.ParticleSet.from_cells(msh, h)
        dyn = mf.ExplicitDynamics.efg(particles, law, fixed_facets=fixed)
    else:
        n = msh.topology.index_map(d).size_local
        mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], axial].mean(axis=1)
        particles = mf.ParticlePatch(msh, np.flatnonzero(mid < patch * LENGTH), h)
        V = _compat.vector_function_space(msh)
        # the problem's law gives the masses only (the same density and plane)
        masses = mf.LinearElastic(E, NU, law.plane, rho=RHO)
        if method == "hybrid":  # HA-F; the SPH mass rho V_I (the corrected sums can be < 0)
            problem = mf.HybridElasticity(V, particles, masses, variant="HA-F")
            dyn = mf.ExplicitDynamics.coupled(
                problem, particle_mass="volume", material=law, fixed_facets=fixed
            )
        else:
            options = {"overlap": 1} if method == "bridging" else {}
            problem = mf.CoupledElasticity(V, particles, masses, coupling=method, **options)
            dyn = mf.ExplicitDynamics.coupled(problem, material=law, fixed_facets=fixed)

    def thrown(x: np.ndarray) -> np.ndarray:
        v = np.zeros_like(x)
        v[:, -1] = -VELOCITY
        return v

    dyn.set_initial(velocity=thrown)
    return dyn


def rim_nodes(cells: int) -> np.ndarray:
    """The mesh's nodes on the 3D foot's rim (:func:`rod_mesh`'s images of the box's sides x = 1
    and y = 1 at z = 0): on the circle of radius :data:`RADIUS` (the rim between them is the
    mesh's polygon, inside it)."""
    t = np.linspace(0.0, 1.0, cells + 1)
    a = np.concatenate([np.ones(cells + 1), t[:-1]])
    b = np.concatenate([t, np.ones(cells)])
    x, y = RADIUS * a * np.sqrt(1.0 - 0.5 * b * b), RADIUS * b * np.sqrt(1.0 - 0.5 * a * a)
    return np.column_stack([x, y, np.zeros(len(x))])


def shape(dyn: mf.ExplicitDynamics, cells: int) -> tuple[float, float]:
    """The rod's final length (the top of its axis) and its foot's radius (the rim on the
    wall; 3D: the mean over the rim's nodes, :func:`rim_nodes`), in mm (collective)."""
    d = dyn.evaluator.disc.gdim
    top = np.zeros((1, d))
    top[0, -1] = LENGTH
    rim = np.array([[RADIUS, 0.0]]) if d == 2 else rim_nodes(cells)
    u = dyn.displacement_at(np.vstack([top, rim]))
    radii = np.linalg.norm((rim + u[1:])[:, : d - 1], axis=1)
    return (LENGTH + u[0, -1]) * 1e3, float(radii.mean()) * 1e3


# ## The run and its figures


def impact(
    method: str,
    cells: int = 5,
    comm=MPI.COMM_WORLD,
    law=None,
    patch: float = 0.3,
    cell: str = "quadrilateral",
) -> dict:
    """One run to :data:`T_END`; its row of figures (lengths in mm)."""
    dyn = build(method, cells, comm, law, patch, cell)
    dt0 = dyn.stable_time_step()
    tic = time.perf_counter()
    res = dyn.run(T_END)
    seconds = time.perf_counter() - tic
    length, radius = shape(dyn, cells)
    eps = dyn.material.state["plastic_strain"][:, 0]
    first, last = res.energies[0], res.energies[-1]
    row = {
        "method": method,
        "cells": cells,
        "cell": cell,
        "length": length,
        "radius": radius,
        "plastic_strain": comm.allreduce(float(eps.max(initial=0.0)), op=MPI.MAX),
        "balance": (last.kinetic + last.internal - first.kinetic) / first.kinetic,
        "kinetic_left": last.kinetic / first.kinetic,
        "steps": res.steps,
        "dt_ratio": res.dt / dt0,
        "seconds": seconds,
    }
    dyn.destroy()
    return row


def check(row: dict) -> list[str]:
    """The row's figures outside their margins (:data:`MARGINS`)."""
    failed = []
    for key in ("length", "radius"):
        off = row[key] / REFERENCE[key] - 1.0
        if abs(off) > MARGINS[key]:
            failed.append(f"{row['method']}: {key} {row[key]:.3f} mm is {off:+.2%} off the "
                          f"benchmark's {REFERENCE[key]} (margin {MARGINS[key]:.0%})")  # fmt: skip
    if abs(row["balance"]) > MARGINS["balance"]:
        failed.append(f"{row['method']}: energy balance {row['balance']:+.2e}")
    return failed


# ## The table, the checks, the JSON


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="The Taylor bar: a copper rod against a rigid wall")
    p.add_argument("--method", nargs="+", default=["fe", "efg", "lagrange"], choices=METHODS)
    p.add_argument("--cells", type=int, default=5, help="cells across the radius")
    p.add_argument("--patch", type=float, default=0.3, help="the couplings' particles: this "
                   "fraction of the length at the foot")  # fmt: skip
    p.add_argument("--cell", default="quadrilateral", choices=CELLS, help="quadrilateral: the "
                   "axisymmetric section; hexahedron: a quarter of the 3D rod")  # fmt: skip
    p.add_argument("--no-viscosity", action="store_true", help="the law without bulk viscosity")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    comm = MPI.COMM_WORLD
    if not (args.cells >= 1 and 0.0 < args.patch < 1.0):
        p.error(f"--cells {args.cells} must be >= 1 and --patch {args.patch} in (0, 1)")
    if args.cell == "hexahedron" and not set(args.method) <= set(METHODS_3D):
        p.error(f"--method {' '.join(sorted(set(args.method) - set(METHODS_3D)))} has no 3D "
                f"model; with --cell hexahedron give some of {' '.join(METHODS_3D)}")  # fmt: skip
    law = dataclasses.replace(COPPER, viscosity=None) if args.no_viscosity else COPPER
    build("fe", 1, comm, law, cell=args.cell).destroy()  # compile first: times exclude JIT
    rows, failed = [], []
    for method in args.method:
        row = impact(method, args.cells, comm, law, args.patch, args.cell)
        rows.append(row)
        failed += check(row)
    fe_time = next((r["seconds"] for r in rows if r["method"] == "fe"), None)
    if comm.rank == 0:
        print(
            f"Taylor bar: copper at {VELOCITY} m/s, {args.cells} {args.cell} cells across the "
            f"radius, {comm.size} rank(s), viscosity {'off' if args.no_viscosity else 'on'}"
        )
        print(f"{'method':<14}{'L_f mm':>8}{'R_f mm':>8}{'eps_p':>7}{'balance':>10}"
              f"{'KE left':>9}{'steps':>7}{'dt/dt0':>8}{'time s':>8}{'vs fe':>7}")  # fmt: skip
        for r in rows:
            ratio = f"{r['seconds'] / fe_time:.2f}x" if fe_time else "-"
            print(
                f"{r['method']:<14}{r['length']:>8.3f}{r['radius']:>8.3f}"
                f"{r['plastic_strain']:>7.2f}{r['balance']:>+10.1e}{r['kinetic_left']:>9.2%}"
                f"{r['steps']:>7d}{r['dt_ratio']:>8.3f}"
                f"{r['seconds']:>8.2f}{ratio:>7}"
            )
        print(f"benchmark: L_f {REFERENCE['length']} mm, R_f {REFERENCE['radius']} mm; "
              f"margins {MARGINS['length']:.0%}, {MARGINS['radius']:.0%}")  # fmt: skip
        if args.json:
            with open(args.json, "w") as fh:
                json.dump({"cells": args.cells, "cell": args.cell, "patch": args.patch,
                           "ranks": comm.size,
                           "viscosity": not args.no_viscosity, "reference": REFERENCE,
                           "margins": MARGINS, "rows": rows}, fh, indent=1)  # fmt: skip
        for line in failed:
            print("FAILED", line)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
