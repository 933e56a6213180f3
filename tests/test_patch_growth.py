"""A patch that grows during quasi-static crack growth (issue 25, items 1-2 in statics;
``QuasiStaticCrackGrowth(adapt=...)``, ``statics/patch_growth.py``,
``geometry/patch_criteria.py``).

The model is ``demos/crack_growth.py``'s: an inclined edge crack in a square plate under remote
tension, a user's model (``CoupledLinearProblem``), grown by prescribed increments along the
maximum hoop stress direction. The adaptive patch starts as the cells near the crack and grows
about the tip (``mf.NearTips``); its path is compared with the path of the large fixed patch
(an independent run: the paths differ only by where the coupling sits)."""

import warnings

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.geometry.crack import point_segment_distance
from dolfinx_meshfree.geometry.patch_criteria import GrowthContext

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

COMM = MPI.COMM_WORLD
MATERIAL = mf.LinearElastic(1000.0, 0.3, plane="strain")
Y0, A, DA = 0.0063, 0.3, 0.1
RADII = (0.05, 0.065, 0.08)


def plate(h, cells=None, coupling="lagrange", crack_points=None):
    """The plate [0, 1] x [-0.5, 0.5], its edge crack and a CoupledLinearProblem whose patch is
    ``cells(msh, crack)`` (default: the large box of the demo)."""
    t = np.deg2rad(30.0)
    pts = (
        crack_points if crack_points is not None else [[0, Y0], [A * np.cos(t), Y0 + A * np.sin(t)]]
    )
    crack = mf.Crack(pts)
    n = round(1 / h)
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.array([0.0, -0.5]), np.array([1.0, 0.5])], [n, n],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    if cells is None:
        chosen = dolfinx.mesh.locate_entities(
            msh, 2, lambda x: (x[0] < 0.85 + 1e-9) & (x[1] > -0.2 - 1e-9)
        )
    else:
        chosen = cells(msh, crack)
    patch = mf.ParticlePatch(msh, chosen, h, cracks=[crack])
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(MATERIAL.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    top = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.5))
    bottom = mf.boundary_facets(msh, lambda x: np.isclose(x[1], -0.5))
    facets = np.concatenate([top, bottom])
    order = np.argsort(facets)
    values = np.concatenate([np.full(top.size, 1), np.full(bottom.size, 2)]).astype(np.int32)
    tags = dolfinx.mesh.meshtags(msh, 1, facets[order], values[order])
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    e2 = dolfinx.fem.Constant(msh, np.array([0.0, 1.0]))
    L = ufl.dot(e2, v) * ds(1) - ufl.dot(e2, v) * ds(2)

    def vertex(p):
        return dolfinx.mesh.locate_entities_boundary(
            msh, 0, lambda x: np.isclose(x[0], p[0]) & np.isclose(x[1], p[1])
        )

    V1 = V.sub(1)
    bcs = [  # u = 0 at (0, -0.5), u_y = 0 at (1, -0.5): the rigid motions, no reaction
        dolfinx.fem.dirichletbc(
            np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 0, vertex((0.0, -0.5))), V
        ),
        dolfinx.fem.dirichletbc(
            np.float64(0.0), dolfinx.fem.locate_dofs_topological(V1, 0, vertex((1.0, -0.5))), V1
        ),
    ]
    problem = mf.CoupledLinearProblem(a, L, bcs, patch, material=MATERIAL, coupling=coupling)
    return problem, crack


def near_crack(radius):
    return lambda msh, crack: mf.cells_near(msh, crack.points, radius)


def grow(problem, crack, steps=2, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mf.SIFReliabilityWarning)
        g = mf.QuasiStaticCrackGrowth(problem, crack, increment=DA, steps=steps, radius=RADII, **kw)
        g.run()
    return g


def interface_distance(patch, point):
    """The distance from ``point`` to the patch's FE interface (its facets gathered)."""
    msh = patch.mesh
    geo = _compat.entities_to_geometry(msh, 1, patch.interface_facets)
    seg = msh.geometry.x[geo][:, :, :2].reshape(-1, 2, 2)
    seg = np.concatenate(COMM.allgather(seg)).reshape(-1, 2, 2)
    return float(point_segment_distance(np.asarray(point)[None], seg[:, 0], seg[:, 1]).min())


@pytest.mark.parametrize("coupling", ["lagrange", "bridging"])
def test_adaptive_path_equals_large_patch(coupling):
    """The path of a patch grown about the tip (mf.NearTips()) against the large fixed patch's:
    the two models differ only in where the FE side starts. Measured (h = 0.025, two steps):
    2.9e-4 (lagrange) and 3.5e-4 (bridging) of the crack length, serial and on 2 ranks (issue
    25's target: 1 %; checked at 7e-4). The patch grew, keeps the SIF domains plus 2 spacings
    clear of the FE interface at every tip it solved with, and ends with 458 particles against
    the fixed patch's 1015."""
    h = 0.025
    fixed, c1 = plate(h, coupling=coupling)
    grow(fixed, c1)
    r0 = max(RADII) + 2 * h
    small, c2 = plate(h, cells=near_crack(r0), coupling=coupling)
    n0 = small.patch.particles.num_particles
    g2 = grow(small, c2, adapt=mf.NearTips())
    d = np.linalg.norm(c1.points - c2.points, axis=1).max() / c1.length
    assert d <= 7e-4, d
    assert g2.events and all(e.rebuild == "full" for e in g2.events)
    assert g2.events[0].particles_before == n0
    assert g2.problem is not small and g2.problem.patch.particles.num_particles > n0
    final = g2.problem.patch.particles.num_particles
    assert final < 0.5 * fixed.patch.particles.num_particles  # 458 against 1015
    # every tip the growth solved with (and the last one made) has its SIF domains plus two
    # spacings inside the particles
    for tip in [s.tip for s in g2.history] + [c2.points[-1]]:
        assert interface_distance(g2.problem.patch, tip) >= r0 - 1e-9
    # the crack answers only to the new patch: the old patch's validator was released
    assert len(c2._validators) == 1 and c2._validators[0][0] is g2.problem.patch


def test_cells_near_is_exact():
    """mf.cells_near against a brute-force distance: each cell sampled on a 41 x 41 lattice of
    its reference square (the distance from a cell to a point is a minimum over the cell; the
    sampling overestimates it by at most half a lattice step). Triangles and quadrilaterals,
    a point and a polyline."""
    for ct in (dolfinx.mesh.CellType.quadrilateral, dolfinx.mesh.CellType.triangle):
        msh = dolfinx.mesh.create_unit_square(COMM, 9, 7, ct)
        tdim = 2
        n_own = msh.topology.index_map(tdim).size_local
        nodes = _compat.geometry_dofmap(msh)[:n_own]
        X = msh.geometry.x[nodes][:, :, :2]
        s = np.linspace(0, 1, 41)
        S, T = np.meshgrid(s, s)
        S, T = S.ravel(), T.ravel()
        if ct == dolfinx.mesh.CellType.quadrilateral:  # DOLFINx's tensor ordering 0 1 / 2 3
            w = np.stack([(1 - S) * (1 - T), S * (1 - T), (1 - S) * T, S * T], 1)
        else:
            keep = S + T <= 1
            S, T = S[keep], T[keep]
            w = np.stack([1 - S - T, S, T], 1)
        samples = np.einsum("qv,cvd->cqd", w, X)  # (cells, q, 2)
        step = 1 / 40 * np.linalg.norm(X.max(axis=1) - X.min(axis=1), axis=1).max()
        for pts, r in (([[0.43, 0.51]], 0.17), ([[0.05, 0.2], [0.5, 0.35], [0.7, 0.9]], 0.06)):
            p = np.asarray(pts)
            a, b = (p[:-1], p[1:]) if len(p) > 1 else (p, p)
            d = point_segment_distance(samples.reshape(-1, 2), a, b).min(axis=1)
            d = d.reshape(len(X), -1).min(axis=1)
            got = np.zeros(n_own, bool)
            got[mf.cells_near(msh, p, r)] = True
            sure_in, sure_out = d <= r - 1e-12, d > r + step
            assert np.all(got[sure_in]), np.flatnonzero(sure_in & ~got)
            assert not np.any(got[sure_out])
            assert COMM.allreduce(int(got.sum())) > 0


def test_field_above_selects_against_dolfinx():
    """mf.FieldAbove('max_principal_strain', t) names the FE cells whose largest principal
    strain at the midpoint is >= t, computed independently by a dolfinx Expression of the FE
    displacement's sym(grad u) at the reference midpoint."""
    h = 0.05
    problem, crack = plate(h, cells=near_crack(0.15))
    sol = problem.solve()
    patch = problem.patch
    msh = patch.mesh
    fe = np.asarray(patch.fe_cells, dtype=np.int32)
    mid_ref = np.array([[0.5, 0.5]])
    expr = _compat.create_expression(ufl.sym(ufl.grad(sol.u)), mid_ref, msh)
    eps = _compat.eval_expression(expr, msh, fe, 4).reshape(len(fe), 2, 2)
    e1 = np.linalg.eigvalsh(eps)[:, -1]
    t = float(np.quantile(np.concatenate(COMM.allgather(e1)), 0.8))
    crit = mf.FieldAbove("max_principal_strain", t)
    ctx = GrowthContext(0, crack.tips, sol, None)
    got = crit.select(patch, ctx)
    expect = np.zeros_like(got)
    expect[fe[e1 >= t]] = True
    close = np.zeros_like(got)
    close[fe[np.isclose(e1, t, rtol=1e-9, atol=0)]] = True
    assert np.array_equal(got & ~close, expect & ~close)
    assert COMM.allreduce(int(got.sum())) > 0
    assert not np.any(got & patch.in_patch[: len(got)])  # only FE cells
    # before a solve it names nothing
    assert not crit.select(patch, GrowthContext(0, crack.tips)).any()


def test_bad_input():
    """Each refused with the reason and the fix, on every rank."""
    h = 0.05
    problem, crack = plate(h, cells=near_crack(0.2))
    with pytest.raises(TypeError, match=r"adapt=.*not a patch criterion"):
        mf.QuasiStaticCrackGrowth(problem, crack, DA, 1, adapt="near tips")
    with pytest.raises(ValueError, match="names no criterion"):
        mf.QuasiStaticCrackGrowth(problem, crack, DA, 1, adapt=[])
    with pytest.raises(ValueError, match="spacings=-1"):
        mf.NearTips(-1)
    with pytest.raises(ValueError, match="reserve"):
        mf.NearTips(reserve=-0.5)
    with pytest.raises(ValueError, match="field='damage'"):
        mf.FieldAbove("damage", 0.5)
    with pytest.raises(ValueError, match="threshold"):
        mf.FieldAbove("max_principal_stress", np.nan)
    with pytest.raises(ValueError, match="callable"):
        mf.CellsWhere(3)
    # pure EFG has no FE cell to convert
    msh = problem.patch.mesh
    efg = mf.EFGElasticity(
        mf.ParticleSet.from_cells(msh, h), MATERIAL, cracks=[mf.Crack(crack.points.copy())]
    )
    with pytest.raises(TypeError, match="pure EFG has particles everywhere"):
        mf.QuasiStaticCrackGrowth(efg, efg.cracks[0], DA, 1, adapt=mf.NearTips())
    # a radius inside the SIF domains: refused naming the tip and the spacings needed
    g = mf.QuasiStaticCrackGrowth(problem, crack, DA, 1, radius=RADII, adapt=mf.NearTips(2))
    with pytest.raises(
        ValueError, match=r"NearTips\(spacings=2.0.*tip at \[0.259808, 0.1563\].*spacings >= 3"
    ):
        g.step()
    # a criterion that would turn the whole mesh into particles
    g = mf.QuasiStaticCrackGrowth(
        problem, crack, DA, 1, radius=RADII, adapt=mf.CellsWhere(lambda x: x[:, 0] > -1)
    )
    with pytest.raises(ValueError, match=r"CellsWhere.*whole mesh \(400 cells\)"):
        g.step()
    # a criterion returning the wrong shape
    bad = mf.CellsWhere(lambda x: np.ones(3, bool))
    g = mf.QuasiStaticCrackGrowth(problem, crack, DA, 1, radius=RADII, adapt=bad)
    with pytest.raises(ValueError, match="one bool per point"):
        g.step()


def test_criterion_that_never_selects_warns():
    """A FieldAbove whose threshold nothing reaches: the run warns once that the patch stayed
    as given (and the growth is the fixed patch's)."""
    h = 0.05
    problem, crack = plate(h, cells=near_crack(0.25))
    with pytest.warns(mf.PatchCriterionWarning, match="named no cell in 1 step"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", mf.SIFReliabilityWarning)
            g = mf.QuasiStaticCrackGrowth(
                problem, crack, DA, 1, radius=RADII,
                adapt=mf.FieldAbove("max_principal_stress", 1e9),
            )  # fmt: skip
            g.run()
    assert not g.events and g.problem is problem


def test_criteria_combine():
    """A list of criteria: a cell joins when any names it. NearTips() about the tip with a
    CellsWhere block far from the crack (x > 0.8, y > 0.3): the first event records both, the
    block is in the patch at the end, and the path is NearTips() alone's to 5.7e-6 of the crack
    length (checked 1.2e-5: the block only moves the coupling far from the tip)."""
    h = 0.05
    block = mf.CellsWhere(lambda x: (x[:, 0] > 0.8) & (x[:, 1] > 0.3))
    runs = []
    for adapt in (mf.NearTips(), [mf.NearTips(), block]):
        problem, crack = plate(h, cells=near_crack(max(RADII) + 2 * h))
        g = grow(problem, crack, steps=2, adapt=adapt)
        runs.append((g, crack))
    (_, c1), (g2, c2) = runs
    assert any("CellsWhere" in b for b in g2.events[0].by)
    assert any("NearTips" in b for e in g2.events for b in e.by)
    patch = g2.problem.patch
    n_own = patch.mesh.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(patch.mesh, 2, np.arange(n_own, dtype=np.int32))
    named = (mid[:, 0] > 0.8) & (mid[:, 1] > 0.3)
    assert np.all(patch.in_patch[:n_own][named])
    d = np.linalg.norm(c1.points - c2.points, axis=1).max() / c1.length
    assert d <= 1.2e-5
