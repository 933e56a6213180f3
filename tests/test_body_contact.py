"""Contact between bodies in explicit dynamics (issue 27, item 2; ``dynamics/body_contact.py``):
a node-to-segment penalty between two pieces of one mesh.

Oracle: the head-on impact of two identical elastic bars (``demos/bar_impact.py``; length L,
height H, ``nu = 0``: the 2D field is uniaxial, the 1D wave solution exact). Bars meeting at
``+-v0`` press on each other with ``sigma = rho c v0`` (the force ``rho c v0 H``) for ``2 L / c``,
then part with their velocities reversed and no energy left in them (Graff, *Wave Motion in
Elastic Solids*, sec. 1.4). The penalty's compliance and the discrete wave's ringing leave a
share of the energy behind, which falls with h (measured below). Further: the energy balance's
drift falls with the step; the penetration is the pressure over the penalty; linear momentum
is conserved to round-off in an oblique impact of a block on a plate (triangles); the
stable-step bound lies above the largest eigenvalue of ``M^-1 (K + K_c)`` at a closed contact
state (``K_c`` by differences of the force) and a run at the step without contact blows up; the
compiled closest-point kernel makes the numpy reference's choices; serial = 2 ranks.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.dynamics import BodyContact, ExplicitDynamics
from dolfinx_meshfree.dynamics.body_contact import (
    EVERY,
    _split_quadrilaterals,
    candidates,
    closest_points,
    closest_points_compiled,
)
from dolfinx_meshfree.geometry.quadrature import facet_normals

import dolfinx
import numpy as np
import pytest
from conftest import load_demo
from mpi4py import MPI

COMM = MPI.COMM_WORLD
L, H, V0 = 1.0, 0.1, 0.01
MAT = mf.LinearElastic(1.0, 0.0, "strain", rho=1.0)  # c = 1
H3 = 0.2  # the 3D bars' square section
MAT3 = mf.LinearElastic(1.0, 0.0, None, rho=1.0)
METHODS = ["fe", "lagrange", "ramp", "bridging", "master-slave", "efg", "hybrid"]
demo = load_demo("bar_impact")


def split_mesh(comm, n):
    return demo.split_mesh(comm, n, L, H)


def bars(method, n=20, comm=COMM, contact=None):
    return demo.build(method, n, comm, MAT, L, H, V0, contact)


def impact(method, n=20, dt=None, contact=None, comm=COMM, force=False):
    return demo.impact(method, n, comm, MAT, L, H, V0, contact, dt, force)


def closed_jacobian(n=10, cell="quadrilateral"):
    """Serial FE bars of n cells pressed together by the gap (the right bar moved left by twice
    the gap): the dense Jacobian of the internal force (central differences), the masses and
    the model's bound of omega_max. The right bar is the vertices past ``L`` by half the gap:
    ``x > L`` took a vertex of the left bar's end face at ``1 + 2e-16`` with it, so that face
    was warped by twice the gap at one corner, a corner that the mesh generator's round-off
    chose (lane B's package stack chose another: omega 65.6 against 14.1, an asymmetric
    Jacobian)."""
    if cell == "quadrilateral":
        dyn, _, gap = bars("fe", n, MPI.COMM_SELF)
    else:
        dyn, _, gap = demo.build("fe", n, MPI.COMM_SELF, MAT3, L, H3, V0, None, cell)

    def pressed(x):
        d = np.zeros_like(x)
        d[:, 0] = np.where(x[:, 0] > L + 0.5 * gap, -2.0 * gap, 0.0)
        return d

    dyn.set_initial(displacement=pressed)
    J = difference_jacobian(dyn, 1e-4 * gap)
    pairs = dyn.system.last["pairs"]
    m = dyn.fields[0].mass.array.copy()
    bound = dyn.critical_time_step()["omega_bound"]
    dyn.destroy()
    return J, m, bound, pairs


def difference_jacobian(dyn, eps):
    """The dense Jacobian of a serial one-field model's internal force at its displacement
    (central differences of step ``eps``); the model's system last evaluated there."""
    u = dyn.u[0]
    base = u.array.copy()
    out = [u.duplicate()]
    dyn.system.internal_force([u], out)  # the contact's state at the point itself
    J = np.zeros((base.size, base.size))
    for j in range(base.size):
        cols = []
        for s in (1.0, -1.0):
            u.array[:] = base
            u.array[j] += s * eps
            dyn.system.internal_force([u], out)
            cols.append(out[0].array.copy())
        J[:, j] = (cols[0] - cols[1]) / (2 * eps)
    u.array[:] = base
    dyn.system.internal_force([u], out)
    out[0].destroy()
    return J


def block_on_plate(method, comm=COMM, v=(0.5 * V0, -V0), body=False):
    """A 0.3 x 0.2 block (triangles) falling obliquely at ``v`` onto a free 1 x 0.2 plate, a gap
    of 0.02 h between them; the particles (coupled methods) in the block's lower half.
    ``body``: every node of the plate a slave of the block's bottom face
    (``BodyContact(slaves="body")``, ``tests/test_nodes_contact.py``)."""
    n = 20
    h = 1.0 / n
    big = dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.array([1.0, 0.45])], [n, 9], dolfinx.mesh.CellType.triangle
    )
    ncells = big.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(big, 2, np.arange(ncells, dtype=np.int32))
    block = (np.abs(mid[:, 0] - 0.5) < 0.15) & (mid[:, 1] > 0.25)
    keep = np.flatnonzero((mid[:, 1] < 0.2) | block).astype(np.int32)
    msh = mf.submesh(big, keep)
    x = msh.geometry.x
    gap = 0.02 * h
    x[x[:, 1] > 0.225, 1] -= h - gap
    top = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.2))
    bottom = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.2 + gap))
    V = _compat.vector_function_space(msh)
    if method == "fe":
        dyn = ExplicitDynamics.fe(V, MAT)
    elif method == "efg":  # particles at the nodes of both bodies
        dyn = ExplicitDynamics.efg(mf.ParticleSet.from_vertices(msh), MAT)
    else:
        ncells = msh.topology.index_map(2).size_local
        mid = dolfinx.mesh.compute_midpoints(msh, 2, np.arange(ncells, dtype=np.int32))
        cells = np.flatnonzero((mid[:, 1] > 0.2) & (mid[:, 1] < 0.3))
        problem = mf.CoupledElasticity(V, mf.ParticlePatch(msh, cells, h), MAT, coupling=method)
        dyn = ExplicitDynamics.coupled(problem)
    if body:
        dyn.add_contact(top, bottom, BodyContact(slaves="body"))
    else:
        dyn.add_contact(bottom, top)
    dyn.set_initial(
        velocity=lambda x: np.where(x[:, 1:2] > 0.2 + gap / 2, np.array(v)[None, :], 0.0)
    )
    return dyn, h, gap


def block_velocity(dyn):
    """The block's mean velocity (2,) over ``V0`` (by cell quadrature; every rank)."""
    q, vals = dyn.evaluator.at_quadrature(dyn.stepper.current_velocity(), 3)
    blk = q.points[:, 1] > 0.2
    s = dyn.comm.allreduce(
        np.array([*(q.weights[blk, None] * vals[blk]).sum(0), q.weights[blk].sum()])
    )
    return s[:2] / s[2] / V0


def momentum(dyn, on=None):
    """Total linear momentum (2,) of the lumped masses and v_n (every rank)."""
    p = np.zeros(2)
    for f, x in zip(dyn.fields, dyn.stepper.current_velocity(), strict=True):
        m, v = f.mass.array_r, x.array_r
        for c in range(2):
            p[c] += np.dot(m[c::2], v[c::2])
    return dyn.comm.allreduce(p)


#: measured (n = 20; fe / lagrange / ramp / bridging / master-slave / efg / hybrid, efg with
#: particles at the nodes of both bars, each bar's MLS its own, the hybrid's SPH particles at the
#: left bar's end): the force's plateau (the left bar's impulse over 0.2-1.8 L/c) +0.5 / +1.5 /
#: -0.1 / +1.5 / +1.4 / +0.05 / +0.53 % off rho c v0 H (the ringing about it); the contact's
#: duration -0.09 / -0.41 / +0.89 / -0.41 / -0.41 / +0.89 / +0.34 h/c off 2 L / c; the mean
#: velocities reversed to 1.9 / 3.2 / 2.5 / 3.2 / 3.3 / 3.5 / 2.8 % (the energy left in the bars'
#: ringing, falling with h: test_residual_falls_with_h); the deepest penetration 0.0104 / 0.0129
#: / 0.0127 / 0.0129 / 0.0129 / 0.0133 / 0.0103 h; the balance's drift 4.9e-3 / 5.8e-3 / 4.5e-3
#: / 4.8e-3 / 5.2e-3 / 7.5e-3 / 3.1e-3 (falling with the step: test_drift_falls_with_the_step;
#: efg's 7.5e-3, 2.6e-3, 5.6e-4 at dt, dt/2, dt/4; the hybrid's 3.1e-3, 9.9e-4, 1.6e-4). The
#: margins are the demo's (demo.MARGINS: 3 %, 4 h/c, 7 %, 0.025 h, 0.012), about 2x these and
#: the demo's own at 40 cells.
@pytest.mark.parametrize("method", METHODS)
def test_head_on_bars_follow_the_1d_wave(method):
    r = impact(method)
    figures = demo.figures(r, MAT, L, H, V0)
    for key, margin in demo.MARGINS.items():
        assert abs(figures[key]) < margin, (key, figures[key])
    assert figures["parted"]
    assert 0.3 < r["critical"] / r["critical_without"] < 0.5  # the contact's step: 0.40-0.41
    hist, t0 = r["hist"], r["t0"]
    touching = hist[hist[:, 1] < 0.0, 0]
    assert t0 <= touching.min() <= t0 + r["dt"] + (hist[1, 0] - hist[0, 0])


def test_residual_falls_with_h():
    """The share of the impact left in the bars falls with h: mean velocities reversed to
    1.92 % (n = 20) and 0.99 % (n = 80), measured."""
    coarse, fine = (1.0 + impact("fe", n=n)["mean"][0] for n in (20, 80))
    assert fine < coarse / 1.4 and fine < 0.02, (coarse, fine)


def test_drift_falls_with_the_step():
    """The balance's drift (the contact's start and end are not smooth): 4.9e-3, 5.8e-4,
    2.8e-4 at dt, dt/2, dt/4 (measured)."""
    dt = impact("fe")["dt"]
    drifts = [impact("fe", dt=dt / k)["drift"] for k in (1, 2, 4)]
    assert drifts[2] < drifts[0] / 5.0 and drifts[1] < drifts[0], drifts
    assert drifts[0] < 0.01 and drifts[2] < 6e-4, drifts


@pytest.mark.parametrize("factor", [1.0, 10.0])
def test_penetration_is_the_pressure_over_the_penalty(factor):
    """On the plateau the two passes press with ``2 k g``: ``g = sigma h / (2 factor E)``
    (measured 0.8 % and 1.1 % above at factor 1 and 10)."""
    r = impact("fe", contact=BodyContact(factor=factor))
    sigma = MAT.rho * MAT.wave_speed() * V0
    expected = sigma * r["h"] / (2.0 * factor * MAT.E)
    assert demo.plateau(r, 2, L, 1.0) == pytest.approx(expected, rel=0.05)


def test_stable_step_bounds_the_closed_contact():
    """omega_max of M^-1 (K + K_c) at a closed state (K_c by differences of the force): 32.0,
    above the bound without contact (22.8: a step from it would be unstable) and below the
    model's bound with contact (56.3, 1.76x). A run at the step without contact blows up."""
    J, m, bound, pairs = closed_jacobian()
    s = 1.0 / np.sqrt(m)
    A = s[:, None] * J * s[None, :]
    omega = np.sqrt(np.linalg.eigvalsh(0.5 * (A + A.T)).max())
    msh, _, _ = split_mesh(MPI.COMM_SELF, 10)
    plain = ExplicitDynamics.fe(_compat.vector_function_space(msh), MAT)
    without = plain.critical_time_step()["omega_bound"]
    plain.destroy()
    assert pairs > 0
    assert without < omega <= bound < 3.5 * omega, (without, omega, bound)
    msh, _, _ = split_mesh(COMM, 20)
    plain = ExplicitDynamics.fe(_compat.vector_function_space(msh), MAT)
    r = impact("fe", dt=plain.stable_time_step(), force=True)
    plain.destroy()
    assert r["ke_after"] > 2.0, r["ke_after"]


@pytest.mark.parametrize("method", ["fe", "lagrange", "efg"])
def test_oblique_impact_conserves_momentum(method):
    """A block on a free plate (triangles): momentum to round-off (measured 1.3e-14, 7e-15,
    3.1e-14), the block bounced, its tangential velocity kept to 0.11 / 0.19 / 0.19 %
    (frictionless), the deepest penetration 0.0059 / 0.0060 / 0.0061 h (fe / lagrange / efg:
    particles at the nodes of both bodies, each body's MLS its own)."""
    dyn, h, gap = block_on_plate(method)
    p0 = momentum(dyn)
    t_end = gap / V0 + 1.0
    pens, ps = [], []

    def out(d, step, t):
        pens.append(d.system.last["penetration"])
        ps.append(momentum(d))

    dyn.run(t_end, outputs=list(np.linspace(0.0, t_end, 101)), on_output=out)
    assert np.abs(np.array(ps) - p0).max() < 1e-12 * np.abs(p0).max()
    v = block_velocity(dyn)
    assert v[0] == pytest.approx(0.5, rel=5e-3) and v[1] > 0.05, v
    assert 0.0 < max(pens) < 0.012 * h
    dyn.destroy()


def test_two_ranks_equal_serial():
    runs = [impact("lagrange", comm=comm) for comm in (COMM, MPI.COMM_SELF)]
    a, b = runs
    assert a["steps"] == b["steps"]
    assert np.allclose(a["hist"], b["hist"], rtol=1e-9, atol=1e-15)
    assert a["mean"] == pytest.approx(b["mean"], rel=1e-10)
    assert a["ke_after"] == pytest.approx(b["ke_after"], rel=1e-10)


def test_bad_input():
    msh, _, gap = split_mesh(COMM, 10)
    a = mf.boundary_facets(msh, lambda x: np.isclose(x[0], L))
    b = mf.boundary_facets(msh, lambda x: np.isclose(x[0], L + gap))
    V = _compat.vector_function_space(msh)
    dyn = ExplicitDynamics.fe(V, MAT)
    with pytest.raises(ValueError, match=r"share .* vertex"):
        dyn.add_contact(a, a)
    with pytest.raises(ValueError, match="surface_b is empty on every rank"):
        dyn.add_contact(a, np.zeros(0, dtype=np.int32))
    with pytest.raises(ValueError, match="surface_a must be a 1D array of facet indices"):
        dyn.add_contact(np.array([1.5]), b)
    with pytest.raises(ValueError, match="not owned here"):
        dyn.add_contact(np.array([10**7]), b)
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    n_own = msh.topology.index_map(tdim - 1).size_local
    exterior = dolfinx.mesh.exterior_facet_indices(msh.topology)
    inner = np.setdiff1d(np.arange(n_own), exterior)[:1].astype(np.int32)
    with pytest.raises(ValueError, match="interior facet"):
        dyn.add_contact(np.concatenate([a, inner]), b)
    with pytest.raises(TypeError, match="BodyContact"):
        dyn.add_contact(a, b, "penalty")
    without = dyn.stable_time_step()
    dyn.add_contact(a, b)  # a step the model without contact takes is now refused
    dyn.set_initial()
    assert dyn.stable_time_step() < 0.5 * without
    with pytest.raises(ValueError, match="above the stable time step"):
        dyn.run(10 * without, dt=without)
    bad_options = (
        dict(factor=0.0), dict(penalty=-1.0), dict(depth=np.inf), dict(two_pass=1),
        dict(friction=-0.1), dict(friction=True),
    )  # fmt: skip
    for bad in bad_options:
        with pytest.raises(ValueError, match=next(iter(bad))):
            BodyContact(**bad)
    dyn.destroy()


def same_choices(y, slaves, facets, depth=0.05, least=80):
    """Both kernels on the tree's candidates and on every pair: the same facets, gaps, weights
    and normals (to round-off)."""
    near, cand = candidates(y, slaves, facets, depth)
    every = np.broadcast_to(np.arange(len(facets)), (len(slaves), len(facets)))
    runs = (((near, cand), (near, cand)), ((slaves, np.ascontiguousarray(every)), (slaves, EVERY)))
    for numpy_args, compiled_args in runs:
        out = []
        for kernel, (pts, cnd) in (
            (closest_points, numpy_args),
            (closest_points_compiled, compiled_args),
        ):
            m = len(pts)
            arrays = (np.full(m, -1, np.int64), np.zeros(m), np.zeros((m, 3)), np.zeros((m, 3)))
            kernel(y, pts, facets, cnd, depth, 0.05, *arrays)
            out.append(arrays)
        (h1, g1, w1, n1), (h2, g2, w2, n2) = out
        assert np.array_equal(h1, h2) and (h1 >= 0).sum() > least, (
            (h1 >= 0).sum(),
            (h2 >= 0).sum(),
        )
        assert np.allclose(g1, g2, rtol=1e-12, atol=1e-15)
        assert np.allclose(w1, w2, rtol=1e-12, atol=1e-14) and np.allclose(n1, n2, atol=1e-14)


@pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not importable: numpy runs alone")
def test_compiled_kernel_makes_the_reference_choices():
    """A wavy master of 40 segments, 300 slaves about it."""
    rng = np.random.default_rng(3)
    xs = np.linspace(0.0, 1.0, 41)
    master = np.stack([xs, 0.02 * np.sin(7.0 * xs)], axis=1)
    y = np.vstack([master, rng.uniform([-0.05, -0.06], [1.05, 0.06], (300, 2))])
    segs = np.stack([np.arange(1, 41), np.arange(40)], axis=1)  # normals up
    same_choices(y, np.arange(41, 341), segs)


# --- 3D: node-to-face (triangles; quadrilateral faces split in two) ----------------------------


#: measured (10 cells, section 0.2 x 0.2: 2 x 2 cells): the force +0.09 / +1.17 / +1.66 /
#: -1.47 % off rho c v0 H^2; the exit velocities 2.2 / 4.0 / 5.5 / 4.1 % off; the deepest
#: penetration 0.0147 / 0.0128 / 0.0148 / 0.0167 h; the drift 1.2e-3 / 7.8e-4 / 1.2e-3 /
#: 2.3e-3 (efg checked 5e-3); the duration +1.58 / +1.38 / +0.68 / +1.35 h/c off 2 L / c; the
#: contact's step 0.21 / 0.24 / 0.21 / 0.21 of the step without.
@pytest.mark.parametrize(
    "cell, method",
    [
        ("hexahedron", "fe"),
        ("tetrahedron", "fe"),
        ("hexahedron", "lagrange"),
        ("tetrahedron", "efg"),
    ],
)
def test_3d_head_on_bars_follow_the_1d_wave(cell, method):
    r = demo.impact(method, 10, COMM, MAT3, L, H3, V0, None, None, False, cell)
    figures = demo.figures(r, MAT3, L, H3, V0)
    assert abs(figures["force"]) < 0.03
    assert abs(figures["exit"]) < 0.11
    assert 0.0 < figures["penetration"] < 0.03
    assert figures["drift"] < (5e-3 if method == "efg" else 3e-3)
    assert abs(figures["duration_cells"]) < 4.0 and figures["parted"]
    assert 0.15 < r["critical"] / r["critical_without"] < 0.35


def test_3d_stable_step_bounds_the_closed_contact():
    """Hexahedral bars of 4 cells pressed together: the bound lies above omega_max of M^-1 (K +
    K_c) (measured 54.2 against 14.1: 3.8x, the disc's widening of a coarse surface; the bound
    without contact 13.1, below it)."""
    J, m, bound, pairs = closed_jacobian(4, "hexahedron")
    s = 1.0 / np.sqrt(m)
    A = s[:, None] * J * s[None, :]
    omega = np.sqrt(np.linalg.eigvalsh(0.5 * (A + A.T)).max())
    msh, _, _ = demo.split_mesh(MPI.COMM_SELF, 4, L, H3, cell="hexahedron")
    plain = ExplicitDynamics.fe(_compat.vector_function_space(msh), MAT3)
    without = plain.critical_time_step()["omega_bound"]
    plain.destroy()
    assert pairs > 0
    assert without < omega <= bound < 8.0 * omega, (without, omega, bound)


@pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not importable: numpy runs alone")
def test_compiled_3d_kernel_makes_the_reference_choices():
    """A wavy triangulated sheet (8 x 8 squares, 128 triangles, normals up), 400 slaves about
    it."""
    rng = np.random.default_rng(5)
    xs = np.linspace(0.0, 1.0, 9)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    sheet = np.stack([X.ravel(), Y.ravel(), 0.02 * np.sin(5.0 * X.ravel() + 3.0 * Y.ravel())], 1)
    idx = np.arange(81).reshape(9, 9)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[:-1, 1:].ravel(),
        idx[1:, 1:].ravel(),
    )
    tris = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])  # normals up
    y = np.vstack([sheet, rng.uniform([-0.05, -0.05, -0.06], [1.05, 1.05, 0.06], (400, 3))])
    same_choices(y, np.arange(81, 481), tris, least=100)


def test_3d_two_ranks_equal_serial():
    runs = [
        demo.impact("lagrange", 10, comm, MAT3, L, H3, V0, None, None, False, "hexahedron")
        for comm in (COMM, MPI.COMM_SELF)
    ]
    a, b = runs
    assert a["steps"] == b["steps"]
    assert np.allclose(a["hist"], b["hist"], rtol=1e-9, atol=1e-15)
    assert a["mean"] == pytest.approx(b["mean"], rel=1e-10)


def test_two_pairs_newtons_cradle():
    """Three identical bars in a row, the left one at v0 (two contact pairs): the 1D wave runs
    through all three, and tension cannot cross a contact, so the left and middle bars stop
    and the right one leaves at v0 (measured: mean velocities 0.011, 0.057, 0.978 v0 at 20
    cells each, the middle bar's share the discrete wave's ringing; momentum to round-off)."""
    n, gap = 20, 0.02
    h = L / n
    big = dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.array([3 * L + 2 * h, H])], [3 * n + 2, 2],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    ncells = big.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(big, 2, np.arange(ncells, dtype=np.int32))[:, 0]
    columns = [L + h / 2, 2 * L + 1.5 * h]
    keep = np.flatnonzero(np.all([np.abs(mid - c) > h / 2 for c in columns], axis=0))
    msh = mf.submesh(big, keep.astype(np.int32))
    x = msh.geometry.x
    shift = np.where(x[:, 0] > 2 * L + 1.25 * h, 2.0, np.where(x[:, 0] > L + h / 4, 1.0, 0.0))
    x[:, 0] -= shift * h * (1.0 - gap)
    ends = [L, L + gap * h, 2 * L + gap * h, 2 * L + 2 * gap * h]
    facets = [mf.boundary_facets(msh, lambda x, e=e: np.isclose(x[0], e)) for e in ends]
    dyn = ExplicitDynamics.fe(_compat.vector_function_space(msh), MAT)
    dyn.add_contact(facets[0], facets[1])
    dyn.add_contact(facets[2], facets[3])

    def velocity(x):
        v = np.zeros_like(x)
        v[:, 0] = np.where(x[:, 0] < L + gap * h / 2, V0, 0.0)
        return v

    dyn.set_initial(velocity=velocity)
    p0 = momentum(dyn)
    dyn.run(gap * h / V0 + 4.0 * L)
    assert np.abs(momentum(dyn) - p0).max() < 1e-12 * np.abs(p0).max()
    q, vals = dyn.evaluator.at_quadrature(dyn.stepper.current_velocity(), 3)
    means = []
    for lo, hi in ((0.0, L), (L, 2 * L + h), (2 * L + h, 3 * L + h)):
        m = (q.points[:, 0] > lo) & (q.points[:, 0] < hi)
        s = dyn.comm.allreduce(np.array([np.sum(q.weights[m] * vals[m, 0]), q.weights[m].sum()]))
        means.append(s[0] / s[1] / V0)
    assert abs(means[0]) < 0.025 and abs(means[1]) < 0.12 and abs(means[2] - 1.0) < 0.05, means
    dyn.destroy()


@pytest.mark.parametrize("cell", ["hexahedron", "tetrahedron"])
def test_3d_surfaces_tile_the_faces(cell):
    """The triangles of each bar's end cover it once (their areas sum to H^2; a quadrilateral
    split across its sides would fold), point out of their bar, and their vertices' shares sum
    to the same area."""
    dyn, _, _ = demo.build("fe", 4, COMM, MAT3, L, H3, V0, None, cell)
    s = dyn.system.surfaces
    n = facet_normals(s.points, s.facets)
    for body, outward in ((0, 1.0), (1, -1.0)):
        on = s.body == body
        assert s.measures()[on].sum() == pytest.approx(H3 * H3, rel=1e-12)
        assert np.allclose(n[on], [outward, 0.0, 0.0], atol=1e-12)
        assert s.tributary()[s.vertex_body == body].sum() == pytest.approx(H3 * H3, rel=1e-12)
    dyn.destroy()


def test_quadrilateral_split_whatever_the_vertex_order():
    """A quadrilateral face's two triangles tile it whatever order its vertices come in (DOLFINx
    gives tensor order, 0-1-3-2 around; lane A's facets happened to come around), and the
    diagonal is the same for every order (it starts at the vertex first in coordinates)."""
    rng = np.random.default_rng(2)
    square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    bent = np.array([[0.0, 0.0, 0.0], [1.0, 0.1, 0.0], [0.1, 1.0, 0.05], [1.2, 1.1, 0.0]])
    around = [0, 1, 3, 2]  # corners[around] go around the face; [0, 1, 2, 3]: tensor order
    orders = [np.arange(4), np.array(around)]
    orders += [rng.permutation(4) for _ in range(6)]
    orders += [np.roll(around, k) for k in range(1, 4)]
    for corners, order in [(c, o) for c in (square, bent) for o in orders]:
        # a quadrilateral's area: half the cross product of its diagonals (planar up to 0.05)
        area = 0.5 * np.linalg.norm(np.cross(corners[3] - corners[0], corners[2] - corners[1]))
        x = corners.copy()
        tris = _split_quadrilaterals(x, order[None, :])
        p = x[tris]
        areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        assert areas.sum() == pytest.approx(area, rel=0.02) and areas.min() > 0.3 * area
        # the diagonal from corner 0 (first in coordinates) to 3, whatever the order
        assert set(tris[0]) & set(tris[1]) == {0, 3}


@pytest.mark.xfail(
    strict=True,
    reason="known limit (guide, dynamics: contact between bodies): at v0 / c = 0.2 the particle "
    "face under the penalty's vertex forces tilts and slides off the FE face (exit velocity "
    "55 % off, FE 1.3 %); it needs the contact to act on the particles, not only at the "
    "surface's vertices",
)
def test_particles_at_the_contact_at_high_speed():
    """The bars at v0 / c = 0.2 (steel at 1,060 m/s), lagrange: the same figures as at low
    speed (small strain, so the same up to the contact's geometry)."""
    r = demo.impact("lagrange", 40, COMM, MAT, L, H, 0.2, None, None, False)
    figures = demo.figures(r, MAT, L, H, 0.2)
    assert abs(figures["exit"]) < 0.07 and abs(figures["force"]) < 0.03


def incline(mu, theta=np.pi / 6, method="fe", t_end=5.0, comm=COMM, g=1e-3, rise=1.0, dim=2):
    """A 0.2 x 0.1 block (3D: 0.2 x 0.2 x 0.1) on a plate 0.1 thick held at its bottom, gravity
    ``g`` tilted by ``theta`` about z (the plate is the incline) and raised linearly over
    ``rise`` (ten transits of the block's height: it settles without bouncing), the block
    starting in touch, Coulomb's ``mu``: its mean velocity along the plate at ``t_end``, the
    model's dissipated work, and its records."""
    n = 40 if dim == 2 else 10
    h = 1.0 / n if dim == 2 else 0.05
    top_y = 0.1
    if dim == 2:
        big = dolfinx.mesh.create_rectangle(
            comm, [np.zeros(2), np.array([1.0, 0.2 + h])], [n, 9],
            dolfinx.mesh.CellType.quadrilateral,
        )  # fmt: skip
    else:
        big = dolfinx.mesh.create_box(
            comm, [np.zeros(3), np.array([0.6, 0.2 + h, 0.3])], [12, 5, 6],
            dolfinx.mesh.CellType.hexahedron,
        )  # fmt: skip
    tdim = big.topology.dim
    ncells = big.topology.index_map(tdim).size_local
    mid = dolfinx.mesh.compute_midpoints(big, tdim, np.arange(ncells, dtype=np.int32))
    block = (np.abs(mid[:, 0] - 0.3) < 0.1) & (mid[:, 1] > top_y + h)
    if dim == 3:
        block &= np.abs(mid[:, 2] - 0.15) < 0.1
    msh = mf.submesh(big, np.flatnonzero((mid[:, 1] < top_y) | block).astype(np.int32))
    x = msh.geometry.x
    gap = 1e-3 * h
    x[x[:, 1] > top_y + h / 4, 1] -= h - gap
    V = _compat.vector_function_space(msh)
    material = MAT if dim == 2 else MAT3
    bottom = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.0))
    if method == "fe":
        dyn = ExplicitDynamics.fe(V, material, fixed_facets=bottom)
    else:
        ncells = msh.topology.index_map(tdim).size_local
        mid = dolfinx.mesh.compute_midpoints(msh, tdim, np.arange(ncells, dtype=np.int32))
        cells = np.flatnonzero(mid[:, 1] > top_y)  # the block
        patch = mf.ParticlePatch(msh, cells, h)
        problem = mf.CoupledElasticity(V, patch, material, coupling=method)
        dyn = ExplicitDynamics.coupled(problem, fixed_facets=bottom)
    top = mf.boundary_facets(msh, lambda x: np.isclose(x[1], top_y))
    under = mf.boundary_facets(msh, lambda x: np.isclose(x[1], top_y + gap))
    dyn.add_contact(under, top, BodyContact(friction=mu))
    load = np.zeros(dim)
    load[:2] = material.rho * g * np.array([np.sin(theta), -np.cos(theta)])
    dyn.add_body_force(lambda x: np.tile(load, (len(x), 1)), lambda t: min(t / rise, 1.0))

    def touching(x):  # the block moved down by the gap: the faces touch, unloaded
        d = np.zeros_like(x)
        d[:, 1] = np.where(x[:, 1] > top_y + gap / 2, -gap, 0.0)
        return d

    dyn.set_initial(displacement=touching)
    res = dyn.run(t_end)
    q, vals = dyn.evaluator.at_quadrature(dyn.stepper.current_velocity(), 3)
    on = q.points[:, 1] > top_y
    s = dyn.comm.allreduce(np.array([np.sum(q.weights[on] * vals[on, 0]), q.weights[on].sum()]))
    out = {"v": s[0] / s[1], "dissipated": dyn.system.dissipated, "records": res.energies}
    dyn.destroy()
    return out


def balance(records):
    """The largest |kinetic + internal - external - constraint| over the largest |external|
    (internal holds the contact's stored energy and the friction's dissipated work)."""
    scale = max(abs(r.external) for r in records)
    return max(abs(r.kinetic + r.internal - r.external - r.constraint) for r in records) / scale


#: measured (gravity raised over t = 1, t_end = 5): frictionless, the block's velocity
#: g sin(theta) (t_end - 1/2) to 6e-6 in 2D and 1.2e-5 in 3D (checked 3e-5); mu = 0.3,
#: g (sin - mu cos)(t_end - 1/2) to 1.6 % in 2D and 0.02 % in 3D (hexahedra; checked 4 %),
#: the energy balance closing to 0.30 % and 0.28 % (checked 1 %).
@pytest.mark.parametrize("mu, dim", [(0.0, 2), (0.3, 2), (0.3, 3)])
def test_incline_slides_with_coulomb_friction(mu, dim):
    theta, g, t_end = np.pi / 6, 1e-3, 5.0
    r = incline(mu, theta, "fe", t_end, g=g, dim=dim)
    expected = g * (np.sin(theta) - mu * np.cos(theta)) * (t_end - 0.5)
    assert r["v"] == pytest.approx(expected, rel=3e-5 if mu == 0.0 else 0.04)
    assert (r["dissipated"] > 0.0) == (mu > 0.0)
    assert balance(r["records"]) < 0.01


def test_incline_sticks_above_the_friction_angle():
    """mu = 0.7 > tan(30 degrees): the block moves at 7.7 % of its frictionless speed by
    t = 5 (checked 15 %: it starts before the normal force has built up, and the undamped
    block's vibrations ratchet it), the balance to 1.6 % (checked 3.5 %)."""
    free = incline(0.0)["v"]
    r = incline(0.7)
    assert 0.0 <= r["v"] < 0.15 * free, (r["v"], free)
    assert balance(r["records"]) < 0.035


def test_friction_two_ranks_equal_serial():
    a, b = (incline(0.3, comm=comm, t_end=2.0) for comm in (COMM, MPI.COMM_SELF))
    assert a["v"] == pytest.approx(b["v"], rel=1e-9)
    assert a["dissipated"] == pytest.approx(b["dissipated"], rel=1e-9)
