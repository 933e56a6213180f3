"""Compatibility (Lagrange-multiplier) FE–EFG coupling: ParticlePatch and CoupledElasticity.

Oracles: the linear patch test (exact with consistent integration), the Timoshenko solution
(rates and the pure-FE error at the same h, computed here), the interface constraint itself
(continuity tested against the multiplier space), and the same problem solved on COMM_SELF.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI


def square(comm, cell="quadrilateral", n=6):
    return dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.full(2, 2.0)], [n, n], getattr(dolfinx.mesh.CellType, cell)
    )


def cells_right_of(msh, x0):
    n = msh.topology.index_map(2).size_local
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2]
    return np.flatnonzero(nodes[:, :, 0].mean(axis=1) > x0)


def beam_mesh(comm, h):
    return dolfinx.mesh.create_rectangle(
        comm,
        [np.array([0.0, -6.0]), np.array([48.0, 6.0])],
        [round(48 / h), round(12 / h)],
        dolfinx.mesh.CellType.quadrilateral,
    )


def solve_beam(comm, h, consistent=False):
    mat = mf.LinearElastic(3e7, 0.3)
    beam = mf.TimoshenkoBeam(mat)
    msh = beam_mesh(comm, h)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 24.0), h)
    problem = mf.CoupledElasticity(
        _compat.vector_function_space(msh), patch, mat, consistent=consistent
    )
    problem.add_dirichlet(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0)), beam.displacement)
    problem.add_traction(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48)), beam.traction)
    sol = problem.solve()
    return msh, sol, mf.error_norms(msh, sol.evaluate_at_quadrature, beam, mat)


def fe_beam_error(h):
    mat = mf.LinearElastic(3e7, 0.3)
    beam = mf.TimoshenkoBeam(mat)
    msh = beam_mesh(MPI.COMM_WORLD, h)
    V = _compat.vector_function_space(msh)
    inertia = beam.inertia

    def t(x):
        return ufl.as_vector((0.0, beam.P / (2 * inertia) * (beam.D**2 / 4 - x[1] ** 2)))

    sol = mf.solve_fe_elasticity(
        V,
        mat,
        [(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0)),
          lambda x: beam.displacement(x[:2].T).T)],
        [(mf.boundary_facets(msh, lambda x: np.isclose(x[0], 48)), t)],
    )  # fmt: skip
    local = sol.u.x.array.reshape(-1, 2)

    def evaluate(q):
        tab = mf.tabulate_in_cells(V, q.points, q.cells)
        return tab.values @ local, tab.gradient(local)

    return mf.error_norms(msh, evaluate, beam, mat)["l2"]


def test_patch_interface_and_boundary_facets():
    msh = beam_mesh(MPI.COMM_WORLD, 1.0)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 24.0), 1.0)
    comm = msh.comm
    assert comm.allreduce(len(patch.interface_facets)) == 12
    assert comm.allreduce(len(patch.exterior_facets)) == 24 + 24 + 12
    assert patch.particles.num_particles == 25 * 13
    q = mf.facet_quadrature(msh, patch.interface_facets, 3, patch.interface_patch_cells)
    # the interface is x = 24 and normals point out of the patch
    assert np.allclose(q.points[:, 0], 24.0)
    assert np.allclose(q.normals, [-1.0, 0.0])


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_patch_test_exact_with_consistent_integration(cell, rank_rng):
    """Default options (consistent integration; ``consistent=None`` is the default) pass the
    linear patch test to round-off; plain Gauss (``consistent=False``) does not (2e-4)."""
    comm = MPI.COMM_WORLD
    msh = square(comm, cell)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 1.0), 1 / 3)
    V = _compat.vector_function_space(msh)
    exact = mf.LinearField(G=((0.3, -0.2), (0.5, 0.1)), c=(0.1, -0.4))
    errors = {}
    for consistent in (False, None):
        problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1000, 0.3), consistent=consistent)
        problem.add_dirichlet(mf.boundary_facets(msh), exact.displacement)
        sol = problem.solve()
        x = rank_rng.uniform(0, 2, (200, 2))
        err = np.abs(sol.displacement(x) - exact.displacement(x)).max(initial=0.0)
        errors[consistent] = comm.allreduce(err, op=MPI.MAX)
    assert errors[None] <= 1e-10
    # Gauss quadrature alone leaves an integration error: the check above can fail
    assert errors[False] > 1e-8


@pytest.mark.parametrize("consistent", [False, True])
def test_cantilever_rate_and_error_against_pure_fe(consistent):
    """Measured (both integrations): fitted L2 rate 1.98; error 0.900, 0.896, 0.894 x pure FE's
    at h = 3, 1.5, 1. Bounds: rate in [1.8, 2.2]; ratio in [0.8, 1.0] (below FE, as the README
    states, with twice the measured 10 % gain as the lower margin)."""
    hs = [3.0, 1.5, 1.0]
    errs = [solve_beam(MPI.COMM_WORLD, h, consistent)[2]["l2"] for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert 1.8 <= slope <= 2.2
    for h, e in zip(hs, errs, strict=True):
        assert 0.8 <= e / fe_beam_error(h) <= 1.0, (h, e)


def test_interface_continuity_in_the_multiplier_space():
    """The constraint G_FE u_FE + G_P u_P = 0: int_Gamma N_k (u_FE - u_P) vanishes for every
    interface node k (tested here node by node with the FE trace functions)."""
    msh, sol, _ = solve_beam(MPI.COMM_WORLD, 1.5)
    patch = sol.patch
    V = sol.u.function_space
    q = mf.facet_quadrature(msh, patch.interface_facets, 7, patch.interface_fe_cells)
    tab = mf.tabulate_in_cells(V, q.points, q.cells, derivatives=0).values
    jump = tab @ sol.u.x.array.reshape(-1, 2) - sol.mls.tabulate(q.points, 0).values @ (
        sol.coefficients
    )
    local = tab.T @ (q.weights[:, None] * jump)  # (local nodes, 2)
    f = dolfinx.fem.Function(V)
    f.x.array[:] = local.ravel()
    _compat.scatter_reverse_add(f)
    n_owned = V.dofmap.index_map.size_local
    residual = MPI.COMM_WORLD.allreduce(np.abs(f.x.array[: 2 * n_owned]).max(initial=0), MPI.MAX)
    scale = MPI.COMM_WORLD.allreduce(np.abs(sol.u.x.array).max(), op=MPI.MAX)
    assert residual <= 1e-10 * scale


@pytest.mark.parametrize("consistent", [True, False])
def test_parallel_equals_serial(rank_rng, consistent):
    """Also on the interface x = 24, where the weakly coupled sides differ (by ~1e-5): those
    points are evaluated on the FE side on any partition."""
    pts = rank_rng.uniform([0.5, -5.5], [47.5, 5.5], (20, 2))
    pts = np.vstack([pts, np.column_stack([np.full(13, 24.0), np.linspace(-6.0, 6.0, 13)])])
    _, world, _ = solve_beam(MPI.COMM_WORLD, 1.0, consistent=consistent)
    _, alone, _ = solve_beam(MPI.COMM_SELF, 1.0, consistent=consistent)
    a = world.displacement(pts)
    b = alone.displacement(pts)
    assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()


def test_cells_from_locate_entities_with_ghosts():
    """``dolfinx.mesh.locate_entities`` lists ghost cells too (issue 23, item 6: refused on 2
    ranks). The patch from it is the patch of the owned cells alone; a ghost cell named only on
    a rank that does not own it joins the patch on its owner."""
    comm = MPI.COMM_WORLD
    msh = square(comm)
    n = msh.topology.index_map(2).size_local
    located = dolfinx.mesh.locate_entities(msh, 2, lambda x: x[0] >= 1.0 - 1e-12)
    owned = cells_right_of(msh, 1.0)
    assert np.array_equal(located[located < n], owned)
    a = mf.ParticlePatch(msh, located, 1 / 3)
    b = mf.ParticlePatch(msh, owned, 1 / 3)
    assert np.array_equal(a.cells, b.cells)
    assert np.array_equal(a.in_patch, b.in_patch)
    assert np.array_equal(a.particles.positions, b.particles.positions)
    # the ghosts alone: the owners get exactly the ghosted part of the patch
    ghosts = located[located >= n]
    assert comm.size == 1 or comm.allreduce(ghosts.size) > 0  # the case of the issue is here
    c = mf.ParticlePatch(msh, ghosts, 1 / 3) if comm.allreduce(ghosts.size) else None
    if c is not None:
        imap = msh.topology.index_map(2)
        named = np.concatenate(comm.allgather(np.asarray(imap.ghosts)[ghosts - n]))
        start = imap.local_range[0]
        assert np.array_equal(c.cells, np.flatnonzero(np.isin(np.arange(n) + start, named)))
        assert comm.allreduce(c.cells.size) > 0


def test_bad_input_on_every_rank():
    comm = MPI.COMM_WORLD
    msh = square(comm)
    n = msh.topology.index_map(2).size_local
    n_local = n + msh.topology.index_map(2).num_ghosts
    with pytest.raises(ValueError, match="not cells of the mesh on this rank"):
        mf.ParticlePatch(msh, np.array([n_local + 5]) if comm.rank == 0 else np.zeros(0, int), 0.3)
    with pytest.raises(ValueError, match="patch is empty"):
        mf.ParticlePatch(msh, np.zeros(0, dtype=np.int64), 0.3)
    with pytest.raises(ValueError, match=r"cells=None: give the patch's cells.*cells_near"):
        mf.ParticlePatch(msh, None, 0.3)  # an adaptive build(crack, cells=None) passing it on
    with pytest.raises(ValueError, match="spacing"):
        mf.ParticlePatch(msh, cells_right_of(msh, 1.0), -1.0)
    patch = mf.ParticlePatch(msh, cells_right_of(msh, 1.0), 1 / 3)
    V = _compat.vector_function_space(msh)
    with pytest.raises(ValueError, match="coupling='bridge' is not available"):
        mf.CoupledElasticity(V, patch, mf.LinearElastic(1.0, 0.3), coupling="bridge")
    whole = mf.ParticlePatch(msh, np.arange(n), 1 / 3)
    for coupling in mf.COUPLINGS:
        with pytest.raises(ValueError, match="the patch covers the whole mesh"):
            mf.CoupledElasticity(V, whole, mf.LinearElastic(1.0, 0.3), coupling=coupling)
    # particles too sparse for the support: one particle per patch cell row is not enough
    sparse = mf.ParticlePatch(msh, cells_right_of(msh, 1.0), 1.0)
    problem = mf.CoupledElasticity(V, sparse, mf.LinearElastic(1.0, 0.3), dilation=1.05)
    problem.add_dirichlet(mf.boundary_facets(msh), mf.LinearField().displacement)
    with pytest.raises(ValueError, match="dilation"):
        problem.solve()


def test_edge_to_edge_without_interface_particles_is_refused():
    """An FE hole inside a jittered patch: no particle lies on the interface, so edge-to-edge
    would leave the two sides uncoupled; it must say so on every rank."""
    comm = MPI.COMM_WORLD
    msh = square(comm)
    n = msh.topology.index_map(2).size_local
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2]
    centre = nodes.mean(axis=1)
    hole = np.all(np.abs(centre - 1.0) < 1 / 3, axis=1)  # the 2 x 2 cells around (1, 1)
    # (the grid alone: the default placement puts particles on the interface nodes)
    patch = mf.ParticlePatch(msh, np.flatnonzero(~hole), 1 / 3, jitter=0.3, placement="grid")
    assert comm.allreduce(len(patch.interface_facets)) == 8
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, mf.LinearElastic(1.0, 0.3), coupling="edge-to-edge")
    problem.add_dirichlet(mf.boundary_facets(msh), mf.LinearField().displacement)
    with pytest.raises(ValueError, match="no particle on the interface"):
        problem.solve()
