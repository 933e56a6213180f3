# # Axisymmetric models: thick cylinder and shell, breathing modes of a cylinder and a sphere, rods
#
# A solid of revolution under loads of revolution is modelled on its (r, z) section with
# ``LinearElastic(E, nu, plane="axisymmetric")`` (issue 27, item 1;
# :mod:`dolfinx_meshfree.physics.axisymmetry`): the hoop strain ``u_r / r`` joins the plane
# strains and every integral takes the weight ``2 pi r``. Five problems with closed forms, each
# run by FE, pure EFG, the lagrange, edge-to-edge, bridging, ramp and master–slave couplings and
# the hybrid SPH–FE coupling (particles where the section is most strained: at the bore, near
# the axis or the centre, at the rods' contact; FE elsewhere) on a refinement series, report
# their error and their cost:
#
# * **Lamé's thick cylinder** (statics): ``a = 1 <= r <= b = 2``, internal pressure ``p``, plane
#   strain along the axis (rollers on ``z = 0`` and ``z = H``). ``u_r = (1 + nu) / E ((1 - 2 nu)
#   A r + B / r)`` with ``A = p a^2 / (b^2 - a^2)``, ``B = p a^2 b^2 / (b^2 - a^2)``; stresses
#   ``sigma_rr = A - B / r^2``, ``sigma_tt = A + B / r^2``. FE is the user's own UFL form written
#   with the module's helpers (``inner(ufl_stress(u), ufl_strain(v)) 2 pi r dx``) and
#   ``mf.solve_forms``; EFG is ``mf.EFGElasticity`` (VCI, the default); lagrange is
#   ``mf.CoupledElasticity`` (lagrange, edge-to-edge, bridging, ramp, master–slave) or
#   ``mf.HybridElasticity`` with particles on ``r < 1.5``.
# * **A thick spherical shell under internal pressure** (statics): ``a = 1 <= rho <= b = 2``
#   (``rho`` the spherical radius), pressure ``p`` in the bore. ``u_rho = A rho + B / rho^2``
#   with ``A = p a^3 / ((b^3 - a^3)(3 lambda + 2 mu))``, ``B = p a^3 b^3 / (4 mu (b^3 -
#   a^3))``. The quarter of its meridian section (a polar grid of ``n`` x ``2 n``
#   quadrilaterals, rollers on ``z = 0``, the axis held radially); the couplings' particles at
#   the bore (``rho < 1.4``), reaching the axis and the rollers. It is the check on the hoop
#   strain of particles near the axis under a stress that varies there: with the axis offset
#   taken off the test functions' hoop under VCI too (the first version), EFG was 6 times FE's
#   error (9.7e-3 against 1.5e-3 at 16 cells) and lagrange and edge-to-edge stalled (3.1e-2 and
#   4.2e-2, rates 0.72 and 0.17), while every patch test held to round-off.
# * **The radial mode of a solid cylinder** (explicit dynamics): ``0 <= r <= a``, rollers on the
#   end planes, the axis held radially. The free radial mode is ``u_r = J1(k r) cos(omega t)``
#   with ``k a J0(k a) = (1 - 2 nu) / (1 - nu) J1(k a)`` and ``omega = k c_p``. Started from its
#   shape at rest, the displacement at ``(a / 2, H / 2)`` is compared with the closed form over
#   two periods. The same run with ``plane="strain"`` (no hoop strain) misses it by about 200 %.
# * **The breathing mode of a solid sphere** (a standing spherical wave): the quarter of its
#   meridian section (``r, z >= 0``, rollers on ``z = 0``, the axis held radially), meshed by
#   rings of nodes. ``u = j1(k rho) e_rho cos(omega t)`` (``rho`` the spherical radius) with
#   ``(lambda + 2 mu) k a j1'(k a) + 2 lambda j1(k a) = 0``. EFG takes the dilation 2.5 here: at
#   2.0 the row-sum mass of the particle on the axis next to the pole is negative on this mesh
#   (the ``2 pi r`` weight favours its negative lobes), which the model refuses by name.
#
# * **Two rods meet head on** (explicit dynamics with contact between bodies): steel rods of
#   radius ``R = 0.01 m`` and length ``L = 0.1 m`` on the axis, ``nu = 0`` (the field is
#   uniaxial and the 1D wave solution exact), fly at each other at ``+-10 m/s``. The contact
#   force holds ``rho c v0 pi R^2`` for ``2 L / c``; the penalty ``k = E / h`` per unit area lets
#   the faces overlap by ``sigma / k``, i.e. ``h rho c v0 / E`` (1.9e-3 h). FE meets it within
#   2.1 %, which checks the contact's revolved tributary areas (``int N_s 2 pi r ds``): with the
#   plane tributary lengths instead, FE's force is off by +1275 % and its deepest overlap is 59
#   times the closed form. EFG overlaps 36 % more than the closed form (its MLS surface,
#   evaluated at the end vertices, deepest on the axis), and the plane lengths would not show in
#   its force (+2.3 %; its overlap falls to -38 %): for the tributary areas the check is FE's.
#   The axis is held radially (``fixed_facets``), as every model whose particles reach it.
#
# Usage:
#
#     python demos/axisymmetric.py [--cells 8 16 32] [--method fe efg] [--json out.json]
#     mpirun -n 2 python demos/axisymmetric.py

# +
from __future__ import annotations

import argparse
import json
import sys
import time

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat
from dolfinx_meshfree.physics import axisymmetry

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI
from scipy.optimize import brentq
from scipy.spatial import Delaunay
from scipy.special import j0, j1, spherical_jn

METHODS = ("fe", "efg", "lagrange", "edge-to-edge", "bridging", "ramp", "master-slave", "hybrid")
#: Options of a coupling in explicit dynamics: the ramps' dynamic operators are not VCI-corrected,
#: and their supports span the interface cells at their default dilation 2.5.
DYNAMIC_OPTIONS = {
    "ramp": {"consistent": False, "dilation": 2.5},
    "ramp-cubic": {"consistent": False, "dilation": 2.5},
}
E, NU, RHO = 1.0, 0.3, 1.0
MATERIAL = mf.LinearElastic(E=E, nu=NU, rho=RHO, plane="axisymmetric")
#: Lamé: bore, outer radius, height, pressure.
A_IN, B_OUT, HEIGHT, PRESSURE = 1.0, 2.0, 0.5, 1.0
#: The radial modes: radius, height of the cylinder's slice, amplitude.
RADIUS, SLICE, AMPLITUDE = 1.0, 0.25, 1e-3
SPHERE_DILATION = 2.5
# -


# ## The closed forms


# +
def lame(r: np.ndarray, material: mf.LinearElastic = MATERIAL) -> tuple[np.ndarray, ...]:
    """``u_r``, ``sigma_rr``, ``sigma_tt`` of the pressurised thick cylinder in plane strain."""
    a2, b2 = A_IN**2, B_OUT**2
    A, B = PRESSURE * a2 / (b2 - a2), PRESSURE * a2 * b2 / (b2 - a2)
    nu = material.nu
    u = (1.0 + nu) / material.E * ((1.0 - 2.0 * nu) * A * r + B / r)
    return u, A - B / r**2, A + B / r**2


def cylinder_wavenumber(nu: float = NU) -> float:
    """``k a`` of the first radial mode of a free solid cylinder in plane strain."""
    ratio = (1.0 - 2.0 * nu) / (1.0 - nu)
    return brentq(lambda x: x * j0(x) - ratio * j1(x), 1.0, 3.8)


def sphere_wavenumber(material: mf.LinearElastic = MATERIAL) -> float:
    """``k a`` of the first breathing mode of a free solid sphere."""
    lam, mu = material.lmbda, material.mu

    def f(x: float) -> float:
        return (lam + 2 * mu) * x * spherical_jn(1, x, derivative=True) + 2 * lam * spherical_jn(
            1, x
        )

    xs = np.linspace(0.5, 6.0, 200)
    v = f(xs)
    i = int(np.flatnonzero(np.sign(v[:-1]) != np.sign(v[1:]))[0])
    return brentq(f, xs[i], xs[i + 1])


def sphere_mode(x: np.ndarray, ka: float) -> np.ndarray:
    """``j1(k rho) e_rho`` (times the amplitude) at points (m, 2) of the meridian section."""
    rho = np.linalg.norm(x[:, :2], axis=1)
    safe = np.where(rho > 0, rho, 1.0)
    s = np.where(rho > 0, AMPLITUDE * spherical_jn(1, ka * rho / RADIUS) / safe, 0.0)
    return x[:, :2] * s[:, None]


def cylinder_mode(x: np.ndarray, ka: float) -> np.ndarray:
    return np.column_stack([AMPLITUDE * j1(ka * x[:, 0] / RADIUS), np.zeros(len(x))])


# -


# ## Meshes


# +
def quarter_disc(comm: MPI.Comm, n: int, radius: float = RADIUS) -> dolfinx.mesh.Mesh:
    """Triangles of the quarter disc ``r, z >= 0``, ``r^2 + z^2 <= radius^2``: rings of nodes
    at ``k radius / n`` (about ``pi k / 2`` segments each) triangulated by Delaunay."""
    pts = [np.zeros((1, 2))]
    for k in range(1, n + 1):
        th = np.linspace(0.0, np.pi / 2, max(1, round(k * np.pi / 2)) + 1)
        pts.append(np.column_stack([np.cos(th), np.sin(th)]) * k * radius / n)
    x = np.vstack(pts)
    cells = Delaunay(x).simplices
    like = dolfinx.mesh.create_unit_square(comm, 1, 1, dolfinx.mesh.CellType.triangle)
    if comm.rank != 0:
        cells, x = np.zeros((0, 3), np.int64), np.zeros((0, 2))
    return _compat.create_mesh_ghosted(like, cells, x)


def rectangle(comm, r0, r1, h, n, m, cell="quadrilateral") -> dolfinx.mesh.Mesh:
    return dolfinx.mesh.create_rectangle(
        comm, [np.array([r0, 0.0]), np.array([r1, h])], [n, m],
        getattr(dolfinx.mesh.CellType, cell),
    )  # fmt: skip


def coupled(V, patch, material, method: str, **options):
    """``mf.CoupledElasticity`` with ``coupling=method``, or ``mf.HybridElasticity`` (the hybrid
    SPH–FE coupling at its defaults: HA-F, centred SPH particles, smoothed strains) for
    ``"hybrid"``."""
    if method == "hybrid":
        options.pop("dilation", None)  # SPH: its smoothing length is its own
        return mf.HybridElasticity(V, patch, material, **options)
    return mf.CoupledElasticity(V, patch, material, coupling=method, **options)


def facets(msh: dolfinx.mesh.Mesh, marker) -> np.ndarray:
    return dolfinx.mesh.locate_entities_boundary(msh, msh.topology.dim - 1, marker)


def patch_of(msh: dolfinx.mesh.Mesh, marker) -> mf.ParticlePatch:
    """A particle patch on the owned cells whose midpoints ``marker`` flags (points (3, m)),
    one particle per vertex."""
    n = msh.topology.index_map(msh.topology.dim).size_local
    mid = dolfinx.mesh.compute_midpoints(msh, msh.topology.dim, np.arange(n, dtype=np.int32))
    cells = np.flatnonzero(marker(mid.T)).astype(np.int32)
    return mf.ParticlePatch(msh, cells, placement="vertices")


# -


# ## Lamé's cylinder in statics


# +
def _section_errors(msh, u, g, material=MATERIAL) -> tuple[float, float]:
    """Relative L2 errors (weight ``r``) of the displacement and of ``(sigma_rr, sigma_tt)``."""
    q = mf.geometry.quadrature.cell_quadrature(msh, 6)
    r = q.points[:, 0]
    w = q.weights * r
    ue, srr, stt = lame(r, material)
    s = axisymmetry.stress(material, q.points, u, g)
    sums = np.array([
        np.sum(w * ((u[:, 0] - ue) ** 2 + u[:, 1] ** 2)), np.sum(w * ue**2),
        np.sum(w * ((s[:, 0, 0] - srr) ** 2 + (s[:, 2, 2] - stt) ** 2)),
        np.sum(w * (srr**2 + stt**2)),
    ])  # fmt: skip
    sums = msh.comm.allreduce(sums, op=MPI.SUM)
    return float(np.sqrt(sums[0] / sums[1])), float(np.sqrt(sums[2] / sums[3]))


def lame_cylinder(method: str, n: int, cell: str = "quadrilateral", comm=MPI.COMM_WORLD) -> dict:
    """The thick cylinder on ``n`` x ``n / 2`` cells: errors and seconds."""
    msh = rectangle(comm, A_IN, B_OUT, HEIGHT, n, max(2, n // 2), cell)
    ends = facets(msh, lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], HEIGHT))
    bore = facets(msh, lambda x: np.isclose(x[0], A_IN))
    t0 = time.perf_counter()
    if method == "fe":
        V = _compat.vector_function_space(msh, 1)
        u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        weight = 2.0 * ufl.pi * axisymmetry.radius(msh)
        stress, strain = axisymmetry.ufl_stress(u, MATERIAL), axisymmetry.ufl_strain(v)
        a = ufl.inner(stress, strain) * weight * ufl.dx
        tags = dolfinx.mesh.meshtags(msh, 1, np.sort(bore), np.ones(bore.size, np.int32))
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        n_ = ufl.FacetNormal(msh)
        L = -PRESSURE * ufl.dot(n_, v) * weight * ds(1)
        V1 = V.sub(1)
        dofs = dolfinx.fem.locate_dofs_topological(V1, 1, ends)
        bc = dolfinx.fem.dirichletbc(np.float64(0.0), dofs, V1)
        sol = mf.solve_forms(a, L, [bc])
        q = mf.geometry.quadrature.cell_quadrature(msh, 6)
        tab = mf.tabulate_in_cells(V, q.points, q.cells, derivatives=1)
        coef = sol.u.x.array.reshape(-1, 2)  # owned and ghost nodes: the table's columns
        values, grads = tab.values @ coef, tab.gradient(coef)
    else:
        if method == "efg":
            P = mf.ParticleSet.from_cells(msh, spacing=(B_OUT - A_IN) / n)
            prob = mf.EFGElasticity(P, MATERIAL)
        else:  # particles at the bore (r < 1.5), FE outside
            V = _compat.vector_function_space(msh, 1)
            patch = patch_of(msh, lambda x: x[0] < 0.5 * (A_IN + B_OUT))
            prob = coupled(V, patch, MATERIAL, method)
        prob.add_dirichlet(ends, lambda x: np.zeros_like(x), components=(1,))
        prob.add_traction(bore, lambda x, nrm: -PRESSURE * nrm)
        sol = prob.solve()
        q = mf.geometry.quadrature.cell_quadrature(msh, 6)
        if method == "efg":
            values, grads = sol.evaluate(q.points)
        else:
            values, grads = sol.evaluate_at_quadrature(q)
    seconds = time.perf_counter() - t0
    e_u, e_s = _section_errors(msh, values, grads)
    return {"method": method, "cells": n, "l2": e_u, "stress": e_s, "seconds": seconds}


# -


# ## A thick spherical shell in statics


# +
def shell_displacement(x: np.ndarray, material: mf.LinearElastic = MATERIAL) -> np.ndarray:
    """The pressurised thick spherical shell's displacement at points ``x`` (m, 2) = (r, z)."""
    a3, b3 = A_IN**3, B_OUT**3
    lam, mu = material.lmbda, material.mu
    A = PRESSURE * a3 / ((b3 - a3) * (3.0 * lam + 2.0 * mu))
    B = PRESSURE * a3 * b3 / ((b3 - a3) * 4.0 * mu)
    rho = np.linalg.norm(x[:, :2], axis=1)
    return ((A * rho + B / rho**2) / rho)[:, None] * x[:, :2]


def shell_section(comm: MPI.Comm, n: int) -> dolfinx.mesh.Mesh:
    """The quarter meridian section ``A_IN <= rho <= B_OUT``: ``n`` x ``2 n`` quadrilaterals of
    a polar grid, the axis vertices exactly at ``r = 0``."""
    msh = rectangle(comm, A_IN, B_OUT, np.pi / 2, n, 2 * n)
    x = msh.geometry.x
    rho, theta = x[:, 0].copy(), x[:, 1].copy()
    x[:, 0], x[:, 1] = rho * np.cos(theta), rho * np.sin(theta)
    x[np.abs(x[:, 0]) < 1e-12, 0] = 0.0
    return msh


def spherical_shell(method: str, n: int, comm=MPI.COMM_WORLD) -> dict:
    """The shell on ``n`` x ``2 n`` cells: the relative L2 error of ``u`` (weight ``r``) and the
    seconds."""
    msh = shell_section(comm, n)
    axis = facets(msh, lambda x: np.isclose(x[0], 0.0))
    rollers = facets(msh, lambda x: np.isclose(x[1], 0.0))
    bore = facets(msh, lambda x: np.isclose(np.hypot(x[0], x[1]), A_IN))
    zero = lambda x: np.zeros_like(x)  # noqa: E731
    t0 = time.perf_counter()
    q = mf.geometry.quadrature.cell_quadrature(msh, 6)
    if method == "fe":
        V = _compat.vector_function_space(msh, 1)
        u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        weight = 2.0 * ufl.pi * axisymmetry.radius(msh)
        a = ufl.inner(axisymmetry.ufl_stress(u, MATERIAL), axisymmetry.ufl_strain(v)) * weight
        tags = dolfinx.mesh.meshtags(msh, 1, np.sort(bore), np.ones(bore.size, np.int32))
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        L = -PRESSURE * ufl.dot(ufl.FacetNormal(msh), v) * weight * ds(1)
        bcs = [dolfinx.fem.dirichletbc(np.float64(0.0),
                                       dolfinx.fem.locate_dofs_topological(V.sub(i), 1, f),
                                       V.sub(i)) for i, f in ((0, axis), (1, rollers))]  # fmt: skip
        sol = mf.solve_forms(a * ufl.dx, L, bcs)
        tab = mf.tabulate_in_cells(V, q.points, q.cells, derivatives=0)
        values = tab.values @ sol.u.x.array.reshape(-1, 2)
    else:
        if method == "efg":
            prob = mf.EFGElasticity(mf.ParticleSet.from_vertices(msh), MATERIAL)
        else:  # particles at the bore, reaching the axis and the rollers
            V = _compat.vector_function_space(msh, 1)
            patch = patch_of(msh, lambda x: np.hypot(x[0], x[1]) < 1.4)
            prob = coupled(V, patch, MATERIAL, method)
        prob.add_dirichlet(axis, zero, components=(0,))
        prob.add_dirichlet(rollers, zero, components=(1,))
        prob.add_traction(bore, lambda x, nrm: -PRESSURE * nrm)
        sol = prob.solve()
        if method == "efg":
            values = sol.evaluate(q.points)[0]
        else:
            values = sol.evaluate_at_quadrature(q)[0]
    seconds = time.perf_counter() - t0
    w = q.weights * q.points[:, 0]
    exact = shell_displacement(q.points)
    sums = msh.comm.allreduce(
        np.array([np.sum(w * np.sum((values - exact) ** 2, 1)), np.sum(w * np.sum(exact**2, 1))]),
        op=MPI.SUM,
    )
    return {"method": method, "cells": n, "l2": float(np.sqrt(sums[0] / sums[1])),
            "seconds": seconds}  # fmt: skip


# -


# ## The breathing modes in explicit dynamics


# +
def breathing(
    shape: str,
    method: str,
    n: int,
    plane: str = "axisymmetric",
    dilation: float | None = None,
    comm=MPI.COMM_WORLD,
) -> dict:
    """The radial mode of the cylinder (``shape="cylinder"``) or the breathing mode of the
    sphere (``"sphere"``) over two periods: the largest error at the probe over 40 output times
    (relative to the mode's amplitude there), the energy drift and the seconds of the run."""
    material = mf.LinearElastic(E=E, nu=NU, rho=RHO, plane=plane)
    if shape == "cylinder":
        ka = cylinder_wavenumber()
        msh = rectangle(comm, 0.0, RADIUS, SLICE, n, max(2, n // 4))
        rollers = facets(msh, lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], SLICE))
        probe = np.array([[0.5 * RADIUS, 0.5 * SLICE]])
        mode = cylinder_mode
        dilation = 2.0 if dilation is None else dilation
    else:
        ka = sphere_wavenumber()
        msh = quarter_disc(comm, n)
        rollers = facets(msh, lambda x: np.isclose(x[1], 0.0))
        probe = np.array([[0.3 * RADIUS, 0.4 * RADIUS]])
        mode = sphere_mode
        dilation = SPHERE_DILATION if dilation is None else dilation
    axis = facets(msh, lambda x: np.isclose(x[0], 0.0))
    fixed = [(rollers, (1,)), (axis, (0,))]
    omega = ka / RADIUS * material.wave_speed()
    t0 = time.perf_counter()
    if method == "fe":
        dyn = mf.ExplicitDynamics.fe(_compat.vector_function_space(msh, 1), material,
                                     fixed_facets=fixed)  # fmt: skip
    elif method == "efg":
        P = mf.ParticleSet.from_cells(msh, spacing=RADIUS / n)
        dyn = mf.ExplicitDynamics.efg(P, material, dilation=dilation, fixed_facets=fixed)
    else:  # particles within half the radius of the centre, FE outside
        V = _compat.vector_function_space(msh, 1)
        patch = patch_of(msh, lambda x: np.hypot(x[0], x[1] if shape == "sphere" else 0) < 0.5)
        options = {"dilation": dilation, **DYNAMIC_OPTIONS.get(method, {})}
        prob = coupled(V, patch, material, method, **options)
        dyn = mf.ExplicitDynamics.coupled(prob, fixed_facets=fixed)
    dyn.set_initial(displacement=lambda x: mode(x, ka))
    period = 2.0 * np.pi / omega
    times, values = [], []

    def record(d, step, t) -> None:
        times.append(t)
        values.append(d.displacement_at(probe)[0])

    res = dyn.run(2.0 * period, outputs=np.linspace(0.0, 2.0 * period, 41)[1:], on_output=record)
    seconds = time.perf_counter() - t0
    exact = mode(probe, ka)[0][None, :] * np.cos(omega * np.asarray(times))[:, None]
    error = np.abs(np.asarray(values) - exact).max() / np.abs(mode(probe, ka)).max()
    return {"shape": shape, "method": method, "cells": n, "plane": plane, "error": float(error),
            "drift": float(res.energy_drift), "steps": int(res.steps), "seconds": seconds,
            "ka": ka}  # fmt: skip


# -


# ## Two rods meet head on


# +
ROD_STEEL = mf.LinearElastic(210e9, 0.0, "axisymmetric", rho=7850.0)
ROD_LENGTH, ROD_RADIUS, ROD_SPEED = 0.1, 0.01, 10.0


def rods_mesh(comm, n: int, gap: float = 0.02) -> tuple[dolfinx.mesh.Mesh, float, float]:
    """Two rods ``0 <= r <= R`` on the axis, ``[0, L]`` and ``[L + gap h, 2 L + gap h]`` in z,
    ``n`` cells along each (``h = L / n``): a rectangle of ``2 n + 1`` rows less the middle
    one, the upper rod moved down by ``(1 - gap) h``. Returns the mesh, ``h`` and the gap."""
    h = ROD_LENGTH / n
    m = max(1, round(ROD_RADIUS / h))
    big = rectangle(comm, 0.0, ROD_RADIUS, 2 * ROD_LENGTH + h, m, 2 * n + 1)
    ncells = big.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(big, 2, np.arange(ncells, dtype=np.int32))
    keep = np.flatnonzero(np.abs(mid[:, 1] - (ROD_LENGTH + h / 2)) > h / 2).astype(np.int32)
    msh = mf.submesh(big, keep)
    x = msh.geometry.x
    x[x[:, 1] > ROD_LENGTH + h / 4, 1] -= h * (1.0 - gap)
    return msh, h, gap * h


def rods(method: str, n: int, comm=MPI.COMM_WORLD) -> dict:
    """The head-on impact through parting: the force's plateau against ``rho c v0 pi R^2``
    (the lower rod's momentum change from 0.2 to 1.8 ``L / c`` after touching), the contact's
    duration against ``2 L / c`` (in ``h / c``), the deepest overlap against ``h rho c v0 / E``,
    the energy balance's drift, whether they parted, the seconds."""
    msh, h, gap = rods_mesh(comm, n)
    lower = mf.boundary_facets(msh, lambda x: np.isclose(x[1], ROD_LENGTH))
    upper = mf.boundary_facets(msh, lambda x: np.isclose(x[1], ROD_LENGTH + gap))
    axis = [(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0)), (0,))]
    t0 = time.perf_counter()
    if method == "fe":
        V = _compat.vector_function_space(msh, 1)
        dyn = mf.ExplicitDynamics.fe(V, ROD_STEEL, fixed_facets=axis)
    elif method == "efg":  # particles at the nodes of both rods: each rod's MLS its own
        P = mf.ParticleSet.from_vertices(msh)
        dyn = mf.ExplicitDynamics.efg(P, ROD_STEEL, fixed_facets=axis)
    else:  # particles on the lower rod's last 0.3 L, at the contact, FE elsewhere
        V = _compat.vector_function_space(msh, 1)
        patch = patch_of(msh, lambda x: (x[1] > 0.7 * ROD_LENGTH) & (x[1] < ROD_LENGTH))
        problem = coupled(V, patch, ROD_STEEL, method, **DYNAMIC_OPTIONS.get(method, {}))
        dyn = mf.ExplicitDynamics.coupled(problem, fixed_facets=axis)
    dyn.add_contact(lower, upper)
    split = ROD_LENGTH + gap / 2
    dyn.set_initial(velocity=lambda x: np.column_stack(
        [np.zeros(len(x)), np.where(x[:, 1] < split, ROD_SPEED, -ROD_SPEED)]
    ))  # fmt: skip
    c = ROD_STEEL.wave_speed()
    touch = gap / (2 * ROD_SPEED)
    t_end = touch + 2.4 * ROD_LENGTH / c
    hist = []

    def momentum(d) -> float:  # the lower rod's z momentum (revolved lumped masses)
        disc, total = d.evaluator.disc, 0.0
        for k, (f, v) in enumerate(zip(d.fields, d.stepper.current_velocity(), strict=True)):
            below = disc.owned_points(k)[:, 1] < split
            total += np.dot(f.mass.array_r[1::2][below], v.array_r[1::2][below])
        return d.comm.allreduce(total)

    def record(d, step, t) -> None:
        hist.append((t, d.system.contact_force(d.u)[1], d.system.last["penetration"], momentum(d)))

    res = dyn.run(t_end, outputs=list(np.linspace(0.0, t_end, 241)), on_output=record)
    seconds = time.perf_counter() - t0
    hist = np.array(hist)
    ia, ib = (int(np.argmin(np.abs(hist[:, 0] - (touch + s * ROD_LENGTH / c)))) for s in (0.2, 1.8))
    force = (hist[ib, 3] - hist[ia, 3]) / (hist[ib, 0] - hist[ia, 0])
    exact = -ROD_STEEL.rho * c * ROD_SPEED * np.pi * ROD_RADIUS**2
    touching = hist[hist[:, 1] < 0.0, 0]
    duration = (touching.max() - touching.min() - 2 * ROD_LENGTH / c) / (h / c)
    e0 = res.energies[0].kinetic
    drift = max(abs(r.kinetic + r.internal - r.external - r.constraint - e0) for r in res.energies)
    overlap = ROD_STEEL.rho * c * ROD_SPEED / ROD_STEEL.E  # sigma / k over h
    return {"problem": "rods", "method": method, "cells": n, "seconds": seconds,
            "force": float(force / exact - 1.0),
            "duration_cells": float(duration),
            "overlap": float(hist[:, 2].max() / h / overlap - 1.0),
            "drift": float(drift / e0), "parted": bool(hist[-1, 1] == 0.0),
            "steps": int(res.steps)}  # fmt: skip


# -


# ## The tables and the checks
#
# Margins about twice the figures measured at 8 and 16 cells (lane A, serial = 2 ranks); the
# convergence rates are checked on both sides.

# +
#: (problem, method) -> the error at 16 cells, and the rate from 8 to 16 cells (low, high).
TARGETS = {
    ("lame", "fe"): (6.5e-4, (1.5, 2.5)),
    ("lame", "efg"): (1.0e-4, (1.7, 2.8)),
    ("cylinder", "fe"): (1.3e-2, (1.6, 2.6)),
    ("cylinder", "efg"): (5.5e-3, (1.4, 2.3)),
    ("sphere", "fe"): (2.5e-2, (1.4, 2.4)),
    ("sphere", "efg"): (3.0e-2, (1.1, 1.9)),
    ("lame", "lagrange"): (2.4e-4, (1.6, 2.6)),
    ("cylinder", "lagrange"): (7.0e-3, (1.3, 2.1)),
    ("sphere", "lagrange"): (9.0e-3, (1.6, 2.4)),
    ("lame", "master-slave"): (2.9e-4, (1.6, 2.5)),
    ("cylinder", "master-slave"): (2.0e-2, (2.2, 3.3)),
    ("sphere", "master-slave"): (1.9e-2, (1.8, 2.8)),
    ("lame", "edge-to-edge"): (3.2e-4, (1.6, 2.6)),
    ("cylinder", "edge-to-edge"): (3.8e-2, (1.8, 2.8)),
    ("sphere", "edge-to-edge"): (3.6e-2, (0.9, 1.8)),
    ("lame", "bridging"): (2.4e-4, (1.6, 2.6)),
    ("cylinder", "bridging"): (7.6e-3, (1.5, 2.5)),
    ("sphere", "bridging"): (1.1e-2, (1.9, 2.9)),
    ("lame", "ramp"): (2.0e-4, (1.6, 2.5)),
    ("cylinder", "ramp"): (4.0e-3, (2.3, 3.3)),
    ("sphere", "ramp"): (1.3e-2, (1.5, 2.5)),
    ("shell", "fe"): (3.0e-3, (1.6, 2.4)),
    ("shell", "efg"): (1.1e-3, (1.7, 2.6)),
    ("shell", "lagrange"): (1.7e-3, (1.7, 2.5)),
    ("shell", "edge-to-edge"): (9.0e-4, (2.0, 2.9)),
    ("shell", "bridging"): (1.75e-3, (1.7, 2.6)),
    ("shell", "ramp"): (1.5e-3, (1.5, 2.3)),
    ("shell", "master-slave"): (1.45e-3, (1.7, 2.6)),
    ("lame", "hybrid"): (7.5e-4, (2.1, 3.1)),
    ("shell", "hybrid"): (2.8e-3, (2.0, 3.0)),
    ("cylinder", "hybrid"): (2.0e-2, (0.9, 1.7)),
    ("sphere", "hybrid"): (4.7e-2, (1.4, 2.3)),
}
#: The energy drift of the linear runs (round-off).
DRIFT = 1e-12
#: The rods at 20 cells: per method, the largest |figure| (measured: fe force +1.7 %, duration
#: -0.34 h / c, overlap -2.1 % off ``h rho c v0 / E``, drift 6.1e-4; efg -2.0 %, +2.08, +36 %,
#: 1.7e-3: its MLS surface, evaluated at the end vertices, is softer than the FE nodes;
#: lagrange -0.04 %, +0.98, +16 %, 8.7e-4; edge-to-edge -0.21 %, +0.98, +16 %, 9.0e-4;
#: bridging +0.007 %, +0.98, +16 %, 8.4e-4; ramp +0.90 %, +0.10, +23 %, 6.3e-4;
#: master-slave -0.13 %, +0.98, +16 %, 8.8e-4; hybrid +0.46 %, +1.47, +17 %, 7.2e-4).
ROD_MARGINS = {
    "fe": {"force": 0.034, "duration_cells": 0.7, "overlap": 0.045, "drift": 1.2e-3},
    "efg": {"force": 0.04, "duration_cells": 4.0, "overlap": 0.7, "drift": 3.5e-3},
    "lagrange": {"force": 0.01, "duration_cells": 2.0, "overlap": 0.32, "drift": 1.8e-3},
    "edge-to-edge": {"force": 0.01, "duration_cells": 2.0, "overlap": 0.32, "drift": 1.8e-3},
    "bridging": {"force": 0.01, "duration_cells": 2.0, "overlap": 0.32, "drift": 1.8e-3},
    "ramp": {"force": 0.018, "duration_cells": 0.2, "overlap": 0.45, "drift": 1.3e-3},
    "hybrid": {"force": 0.01, "duration_cells": 3.0, "overlap": 0.34, "drift": 1.5e-3},
    "master-slave": {"force": 0.01, "duration_cells": 2.0, "overlap": 0.32, "drift": 1.8e-3},
}


def rate(e_coarse: float, e_fine: float) -> float:
    return float(np.log2(e_coarse / e_fine))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Axisymmetric models against closed forms")
    p.add_argument("--cells", type=int, nargs="+", default=[8, 16])
    p.add_argument("--method", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--rod-cells", type=int, default=20, help="cells along each rod")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    comm = MPI.COMM_WORLD
    lame_cylinder("fe", 2)  # compile the forms first: the times exclude JIT
    rows, failed = [], []
    for method in args.method:
        for n in args.cells:
            r = lame_cylinder(method, n)
            rows.append({"problem": "lame", **r, "error": r["l2"]})
            r = spherical_shell(method, n)
            rows.append({"problem": "shell", **r, "error": r["l2"]})
            for shape in ("cylinder", "sphere"):
                rows.append({"problem": shape, **breathing(shape, method, n)})
    plain = breathing("cylinder", "fe", max(args.cells), plane="strain")
    impacts = [rods(method, args.rod_cells) for method in args.method]
    for r in impacts:
        for key, margin in ROD_MARGINS[r["method"]].items():
            if args.rod_cells == 20 and abs(r[key]) > margin:
                failed.append(f"rods {r['method']}: {key} {r[key]:+.3g} beyond {margin}")
        if not r["parted"]:
            failed.append(f"rods {r['method']}: the rods did not part")
    for (problem, method), (margin, (lo, hi)) in TARGETS.items():
        mine = {r["cells"]: r["error"] for r in rows
                if r["problem"] == problem and r["method"] == method}  # fmt: skip
        if 16 in mine and mine[16] > margin:
            failed.append(f"{problem} {method}: error {mine[16]:.3g} at 16 cells beyond {margin}")
        if 8 in mine and 16 in mine and not lo <= rate(mine[8], mine[16]) <= hi:
            failed.append(f"{problem} {method}: rate {rate(mine[8], mine[16]):.2f} outside "
                          f"[{lo}, {hi}]")  # fmt: skip
    for r in rows:
        if r["problem"] not in ("lame", "shell") and r["drift"] > DRIFT:
            failed.append(f"{r['problem']} {r['method']} {r['cells']}: drift {r['drift']:.2e}")
    if plain["error"] < 0.5:
        failed.append(f"plane strain matched the axisymmetric mode ({plain['error']:.3g})")
    if comm.rank == 0:
        print(f"axisymmetric models, {comm.size} rank(s): errors against closed forms")
        print(f"{'problem':<10}{'method':<13}{'cells':>6}{'error':>11}{'rate':>7}{'stress':>11}"
              f"{'drift':>10}{'steps':>7}{'time s':>8}{'vs fe':>7}")  # fmt: skip
        for r in rows:
            prev = [s for s in rows if s["problem"] == r["problem"]
                    and s["method"] == r["method"] and s["cells"] == r["cells"] // 2]  # fmt: skip
            fe = [s for s in rows if s["problem"] == r["problem"] and s["method"] == "fe"
                  and s["cells"] == r["cells"]]  # fmt: skip
            print(
                f"{r['problem']:<10}{r['method']:<13}{r['cells']:>6}{r['error']:>11.3e}"
                + (f"{rate(prev[0]['error'], r['error']):>7.2f}" if prev else f"{'-':>7}")
                + (f"{r['stress']:>11.3e}" if "stress" in r else f"{'-':>11}")
                + (f"{r['drift']:>10.1e}{r['steps']:>7d}" if "drift" in r else f"{'-':>10}{'-':>7}")
                + f"{r['seconds']:>8.2f}"
                + (f"{r['seconds'] / fe[0]['seconds']:>6.2f}x" if fe else f"{'-':>7}")
            )
        print(f"the cylinder's mode with plane='strain' (no hoop strain), fe, {plain['cells']} "
              f"cells: error {plain['error']:.3g}")  # fmt: skip
        print(f"two rods at +-{ROD_SPEED} m/s, {args.rod_cells} cells each: the 1D solution")
        print(f"{'method':<13}{'force':>9}{'duration':>10}{'overlap':>9}{'drift':>9}{'steps':>7}"
              f"{'time s':>8}")  # fmt: skip
        for r in impacts:
            print(f"{r['method']:<13}{r['force']:>+9.2%}{r['duration_cells']:>+9.2f}h"
                  f"{r['overlap']:>+9.1%}{r['drift']:>9.1e}{r['steps']:>7d}"
                  f"{r['seconds']:>8.2f}")  # fmt: skip
        print("force: plateau vs rho c v0 pi R^2; duration: vs 2 L / c in h / c; overlap: the "
              "deepest vs h rho c v0 / E")  # fmt: skip
        if args.json:
            with open(args.json, "w") as fh:
                json.dump({"ranks": comm.size, "rows": rows, "plane_strain": plain,
                           "rods": impacts, "rod_margins": ROD_MARGINS,
                           "targets": {f"{k[0]} {k[1]}": v for k, v in TARGETS.items()}},
                          fh, indent=1)  # fmt: skip
        for line in failed:
            print("FAILED", line)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
# -
