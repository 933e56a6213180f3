"""Local update of a growth step (issue 10, item 5): ``QuasiStaticCrackGrowth(update="local")``.

Oracles: after every step of the growth loop the particle stiffness equals that of a model built
from scratch with the grown crack, and the step's solution equals the fresh model's solution
(relative 1e-10; measured 1e-15 on K, 1e-13 on u for EFG, 6e-12 on u for Lagrange, 5e-15 for
a CoupledLinearProblem with an interior crack); the region
where the crack-aware MLS changes (derived in ``statics/growth_update.py``) holds every point
whose tabulated row changes, checked against direct tabulations before and after an extension.
Serial and 2 ranks.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx.crack_cuts import attach_cracks
from dolfinx_meshfree.statics.growth_update import changed_rows, new_segments

import dolfinx
import numpy as np
import pytest
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from test_crack_growth import H, edge_crack, model

COMM = MPI.COMM_WORLD


def particle_stiffness_matrix(prob, tables: dict | None = None) -> sp.csr_matrix:
    """The assembled particle stiffness in the particles' original dof order, on every rank."""
    system, objects, _ = prob.system(tables)
    K = system.blocks[0][0]
    ia, ja, a = K.getValuesCSR()
    r0, r1 = K.getOwnershipRange()
    M = sp.csr_matrix((a, ja, ia), shape=(r1 - r0, K.getSize()[1]))
    for o in (system, *objects):
        o.destroy()
    M = sp.vstack(COMM.allgather(M)).tocsr()
    dm = prob.particles.petsc_dofs(2).ravel()
    return M[dm][:, dm]


@pytest.mark.parametrize(
    ("method", "consistent"),
    [("efg", True), ("efg", False), ("lagrange", None), ("edge-to-edge", None), ("bridging", None)],
)
def test_each_local_step_equals_a_model_built_with_the_grown_crack(method, consistent):
    """``consistent=False``: plain Gauss (no VCI constants to update); None: the default.
    Edge-to-edge (interface terms) and bridging (its own stiffness) update only the crack rules
    locally and rebuild the stiffness (measured 1.5e-12 to 7.4e-12 on u)."""

    def build(c: mf.Crack):
        p = model(c, method)
        if consistent is not None:
            p.consistent = consistent
        return p

    crack = edge_crack(30.0)
    prob = build(crack)
    g = mf.QuasiStaticCrackGrowth(prob, crack, increment=2 * H, steps=3)
    for k in range(3):
        g.step()
        # the solve of step k saw the crack without its last extension
        sol = build(mf.Crack(crack.points[:-1])).solve()
        u, ref = g.solution.coefficients, sol.coefficients
        assert np.abs(u - ref).max() < 1e-10 * np.abs(ref).max()
        if method == "efg":  # the stiffness of the grown crack (updated once more, locally)
            ta, tb = {}, {}
            Ka = particle_stiffness_matrix(prob, ta)
            Kb = particle_stiffness_matrix(build(mf.Crack(crack.points)), tb)
            assert abs(Ka - Kb).max() < 1e-10 * abs(Kb).max()
            # the tables a finite-strain solve reads (rows in another order): integrals of the
            # shape functions and of their (VCI) test gradients per particle
            for t in (ta, tb):
                w = t["quadrature"].weights
                t["sums"] = np.concatenate(
                    [t["table"].values.T @ w, *(g.T @ w for g in t["test_gradients"])]
                )
            sa, sb = (COMM.allreduce(t["sums"]) for t in (ta, tb))
            assert np.abs(sa - sb).max() < 1e-10 * np.abs(sb).max()
        if method in ("efg", "lagrange") and (k or method == "efg"):
            # the last update of the stiffness was local and re-tabulated a part of the rows
            last = g.local.last  # (this rank's rows: 1 of 2 ranks may hold none)
            assert last["mode"] == "local"
            rows = COMM.allreduce(last["rows"])
            assert 0 < rows < 0.25 * COMM.allreduce(last["cell_rows"])


def test_full_update_by_option_and_bad_input():
    crack = edge_crack(0.0)
    prob = model(crack)
    g = mf.QuasiStaticCrackGrowth(prob, crack, increment=2 * H, steps=2, update="full")
    assert g.local is None
    hist = g.run()
    ref = mf.QuasiStaticCrackGrowth(model(c := edge_crack(0.0)), c, increment=2 * H, steps=2)
    for a, b in zip(hist, ref.run(), strict=True):
        assert abs(a.K_I - b.K_I) < 1e-10 * abs(b.K_I)
    with pytest.raises(ValueError, match="update='partial' is not known"):
        mf.QuasiStaticCrackGrowth(prob, crack, increment=0.1, steps=1, update="partial")


def test_new_segments():
    old = np.array([[0.0, 0.0], [1.0, 0.0]])
    end = np.vstack([old, [[1.5, 0.5]]])
    assert np.array_equal(new_segments(old, end), [[[1.0, 0.0], [1.5, 0.5]]])
    start = np.vstack([[[-0.5, 0.1], [-0.2, 0.0]], old])
    assert np.array_equal(
        new_segments(old, start), [[[0.0, 0.0], [-0.2, 0.0]], [[-0.2, 0.0], [-0.5, 0.1]]]
    )
    assert new_segments(old, old[::-1]) is None


@pytest.mark.parametrize("method", ["diffraction", "visibility"])
def test_changed_rows_hold_every_row_that_changes(method):
    """Tabulate the crack-aware MLS at many points before and after an extension: every row that
    changes lies within R_1 of the new segment (the region derived in growth_update)."""
    msh = dolfinx.mesh.create_unit_square(COMM, 8, 8, dolfinx.mesh.CellType.quadrilateral)
    crack = mf.Crack([[0.15, 0.513 * 0.05 + 0.5], [0.4, 0.55]])  # an interior crack, two tips
    mls = mf.MLS(mf.ParticleSet.from_cells(msh, 0.05))
    attach_cracks(mls, [crack], method)
    upd = mf.statics.growth_update.enable_local_update(mls, [crack])
    rng = np.random.default_rng(3)
    x = rng.uniform(0.02, 0.98, size=(6000, 2))
    x = x[crack.distance(x) > 1e-3]
    before = mls.tabulate(x)
    crack.extend(np.deg2rad(25.0), 0.1, tip=-1)
    after = mls.tabulate(x)
    segs = upd._since(0)
    R = upd.radius(segs)
    diff = abs(after.values - before.values) + sum(
        abs(a - b) for a, b in zip(after.gradients, before.gradients, strict=True)
    )
    changed = np.flatnonzero(np.asarray(diff.max(axis=1).todense()).ravel() > 0)
    region = changed_rows(x, segs, R)
    assert changed.size > 50  # the extension is felt
    assert np.isin(changed, region).all()
    # the region is not far larger than what changes (measured 296 against 118 / 111 changed
    # rows: ratio 2.5 diffraction, 2.7 visibility; bound 2x that)
    assert region.size < 5.5 * changed.size


def user_model(crack: mf.Crack) -> mf.CoupledLinearProblem:
    """A user's UFL model of the unit square pulled apart (u_y = -+1e-3 on the bottom and top
    edges), an interior crack in a particle patch, lagrange coupling."""
    msh = dolfinx.mesh.create_unit_square(COMM, 20, 20, dolfinx.mesh.CellType.quadrilateral)
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    mat = mf.LinearElastic(1000.0, 0.3, plane="strain")
    a = ufl.inner(mat.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    L = ufl.dot(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.dx
    g = dolfinx.fem.Function(V)
    g.interpolate(lambda x: np.vstack([0.0 * x[0], 2e-3 * (x[1] - 0.5)]))
    facets = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], 1.0))
    bcs = [dolfinx.fem.dirichletbc(g, dolfinx.fem.locate_dofs_topological(V, 1, facets))]
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    cells = np.flatnonzero((np.abs(mid - 0.5) < 0.45).all(axis=1))
    patch = mf.ParticlePatch(msh, cells, 0.05, cracks=[crack])
    return mf.CoupledLinearProblem(a, L, bcs, patch, material=mat, coupling="lagrange")


def test_local_steps_through_a_users_model():
    """CoupledLinearProblem: each step's solution equals a fresh model's with the crack of that
    step (measured 4.0e-15 and 4.6e-15 relative after the two local steps)."""
    crack = mf.Crack([[0.3, 0.4813], [0.5, 0.4813]])
    g = mf.QuasiStaticCrackGrowth(user_model(crack), crack, increment=0.08, steps=3, tip=-1)
    for _ in range(3):
        g.step()
        sol = user_model(mf.Crack(crack.points[:-1])).solve()
        u, ref = g.solution.coefficients, sol.coefficients
        assert np.abs(u - ref).max() < 1e-10 * np.abs(ref).max()
    assert g.local.last["mode"] == "local"
