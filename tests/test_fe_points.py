"""Degree-1 Lagrange basis at arbitrary points: tabulate_fe_basis, evaluate_fe_function,
tabulate_in_cells.

A linear field ``u = c + G x`` lies in the P1 and (isoparametric) Q1 spaces even on distorted
meshes, so its interpolant evaluated anywhere must equal the field and its gradient ``G`` up to
round-off. The mesh is distorted by a smooth map that fixes the boundary, which makes the
quadrilaterals non-affine (the Newton pull-back then does real work).

Tolerance: the reference coordinates come from a Newton iteration stopped at a residual of
1e-13 cell diameters (~500 eps); values therefore carry ~1e-13 |G| h of error and gradients
(through ``J^-1``) a little more. ``TOL = 1e5 eps`` (2.2e-11) relative to the field (gradient)
scale is that with a margin; observed: 1e-16–1e-15.
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx.fe_points import locate_points, reference_coordinates

import dolfinx
import numpy as np
import pytest
import scipy.sparse as sp
from conftest import CELL_TYPES, EPS, rectangle
from mpi4py import MPI

TOL = 1e5 * EPS
G = np.array([[1.5, -0.75], [0.25, 2.0]])
C = np.array([0.5, -1.25])
NX, NY = 8, 5


def distorted_mesh(comm, cell_name):
    msh = rectangle(comm, [0.0, 0.0], [2.0, 1.0], [NX, NY], CELL_TYPES[cell_name])
    x = msh.geometry.x
    bump = 0.08 * np.sin(np.pi * x[:, 0] / 2) * np.sin(np.pi * x[:, 1])
    x[:, 0] += bump
    x[:, 1] += 0.5 * bump
    return msh


def linear_function(msh):
    V = _compat.vector_function_space(msh)
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: C[:, None] + G @ x[:2])
    u.x.scatter_forward()
    return V, u


def exact(x):
    return x @ G.T + C


def global_coefficients(u):
    """The owned values of every rank, concatenated: indexed by global node (block) number."""
    V = u.function_space
    bs = V.dofmap.index_map_bs
    n_owned = V.dofmap.index_map.size_local * bs
    U = np.concatenate(V.mesh.comm.allgather(u.x.array[:n_owned].copy()))
    assert U.size == V.dofmap.index_map.size_global * bs
    return U.reshape(-1, bs)


def probe_points(rng, with_nodes=True):
    """Random points of the domain (each rank its own) and some distorted mesh nodes."""
    pts = rng.uniform([0.0, 0.0], [2.0, 1.0], (40, 2))
    if with_nodes:
        i, j = rng.integers(0, NX + 1, 6), rng.integers(0, NY + 1, 6)
        nodes = np.c_[2.0 * i / NX, 1.0 * j / NY]
        bump = 0.08 * np.sin(np.pi * nodes[:, 0] / 2) * np.sin(np.pi * nodes[:, 1])
        nodes += np.c_[bump, 0.5 * bump]
        pts = np.vstack([pts, nodes])
    return pts


@pytest.mark.parametrize("empty_rank0", [False, True])
@pytest.mark.parametrize("cell_name", sorted(CELL_TYPES))
def test_tabulate_fe_basis_reproduces_linear_field_at_any_rank_points(
    cell_name, empty_rank0, rank_rng
):
    comm = MPI.COMM_WORLD
    msh = distorted_mesh(comm, cell_name)
    V, u = linear_function(msh)
    pts = probe_points(rank_rng)
    if empty_rank0 and comm.rank == 0:
        pts = np.zeros((0, 2))
    # collective calls first, local assertions after, so that a failure on one rank cannot
    # leave the other waiting in a collective
    foreign = comm.allreduce(int(np.sum(locate_points(msh, pts) < 0)))
    table = mf.tabulate_fe_basis(V, pts)
    values_only = mf.tabulate_fe_basis(V, pts, derivatives=0)
    U = global_coefficients(u)  # the owned values of all ranks, by global node number
    vals = mf.evaluate_fe_function(u, pts)

    # the routing is exercised: under MPI some points lie in another rank's cells
    assert comm.size == 1 or foreign > 0
    n_global = V.dofmap.index_map.size_global
    assert sp.issparse(table.values) and table.values.format == "csr"
    assert table.values.shape == (pts.shape[0], n_global)
    assert len(table.gradients) == 2
    assert all(g.shape == (pts.shape[0], n_global) for g in table.gradients)
    # partition of unity of the FE basis; every point sees exactly one cell's nodes
    nv = 3 if cell_name == "triangle" else 4
    assert np.all(np.diff(table.values.indptr) == nv)
    assert np.abs(np.asarray(table.values.sum(axis=1)).ravel() - 1.0).max(initial=0.0) <= TOL

    assert values_only.gradients == []
    assert (values_only.values != table.values).nnz == 0

    # columns are global node numbers: contract with the gathered global coefficients
    scale = np.abs(U).max()
    values = table.values @ U
    assert values.shape == (pts.shape[0], 2)
    assert np.abs(values - exact(pts)).max(initial=0.0) <= TOL * scale
    grads = table.gradient(U)  # (m, 2, 2)
    assert np.abs(grads - G[None]).max(initial=0.0) <= TOL * np.abs(G).max() * NX

    # the same through evaluate_fe_function (local coefficients, routed values)
    assert vals.shape == (pts.shape[0], 2)
    assert np.abs(vals - exact(pts)).max(initial=0.0) <= TOL * scale


@pytest.mark.parametrize("cell_name", sorted(CELL_TYPES))
def test_tabulate_in_cells_uses_local_columns(cell_name):
    msh = distorted_mesh(MPI.COMM_WORLD, cell_name)
    V, u = linear_function(msh)
    q = mf.cell_quadrature(msh, 3)
    table = mf.tabulate_in_cells(V, q.points, q.cells)
    # quadrature on the distorted cells integrates the area exactly (bilinear map: det J is
    # linear in the reference coordinates); the total over ranks is the undistorted 2 x 1
    area = msh.comm.allreduce(float(q.weights.sum()), op=MPI.SUM)
    imap = V.dofmap.index_map
    assert table.values.shape == (len(q), imap.size_local + imap.num_ghosts)
    local = u.x.array.reshape(-1, 2)
    scale = np.abs(local).max()
    assert np.abs(table.values @ local - exact(q.points)).max(initial=0.0) <= TOL * scale
    assert np.abs(table.gradient(local) - G[None]).max(initial=0.0) <= TOL * np.abs(G).max() * NX
    assert abs(area - 2.0) <= 1e-13
    assert mf.tabulate_in_cells(V, q.points, q.cells, derivatives=0).gradients == []


@pytest.mark.parametrize("cell_name", sorted(CELL_TYPES))
@pytest.mark.parametrize("which", ["centres", "mixed"])
def test_tabulate_in_cells_at_cell_centres(cell_name, which):
    """The Newton pull-back starts every point at the reference centre and iterates only the
    points not yet converged: points at the cells' centres converge before any step ("centres":
    only those; "mixed": those among the degree-3 quadrature points, in random order). The
    linear field is reproduced either way, and the pulled-back points map onto the physical ones
    to 2e-13 (the iteration stops at 1e-13 of the cell size, about 0.3 here)."""
    msh = distorted_mesh(MPI.COMM_WORLD, cell_name)
    V, u = linear_function(msh)
    cells = np.arange(msh.topology.index_map(msh.topology.dim).size_local)
    element = _compat.basix_lagrange_p1(msh.topology.cell_type.name)
    centre = np.full((1, 2), 1.0 / 3.0 if cell_name == "triangle" else 0.5)
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :2]
    phi = element.tabulate(0, centre)[0, 0, :, 0]
    pts = np.einsum("v,cvg->cg", phi, nodes)  # the image of the reference centre
    if which == "mixed":
        q = mf.cell_quadrature(msh, 3)
        pts, cells = np.vstack([pts, q.points]), np.concatenate([cells, q.cells])
        order = np.random.default_rng(0).permutation(len(cells))
        pts, cells = pts[order], cells[order]
    table = mf.tabulate_in_cells(V, pts, cells)
    local = u.x.array.reshape(-1, 2)
    scale = np.abs(local).max()
    assert np.abs(table.values @ local - exact(pts)).max(initial=0.0) <= TOL * scale
    assert np.abs(table.gradient(local) - G[None]).max(initial=0.0) <= TOL * np.abs(G).max() * NX
    X = reference_coordinates(msh, pts, cells)
    back = np.einsum("qv,qvg->qg", element.tabulate(0, X)[0, :, :, 0], nodes[cells])
    assert np.abs(back - pts).max(initial=0.0) <= 1e-13 * 2.0


def test_parallel_table_equals_serial_table(rank_rng):
    """The same points on a COMM_WORLD and a COMM_SELF mesh give the same interpolated values."""
    pts = probe_points(rank_rng)
    for cell_name in sorted(CELL_TYPES):
        results = []
        for comm in (MPI.COMM_WORLD, MPI.COMM_SELF):
            msh = distorted_mesh(comm, cell_name)
            V = _compat.vector_function_space(msh)
            u = dolfinx.fem.Function(V)
            # a non-polynomial field: its interpolant is not exact, so this compares the two
            # meshes' tables rather than both against the field
            u.interpolate(lambda x: np.vstack([np.sin(3 * x[0]) * x[1], np.exp(x[0] - x[1])]))
            u.x.scatter_forward()
            results.append(mf.evaluate_fe_function(u, pts))
        scale = np.abs(results[1]).max()
        assert np.abs(results[0] - results[1]).max() <= 1e-12 * scale


def test_point_location_follows_a_moved_mesh():
    """The bounding-box tree is built once per mesh (the same object on a second call) and
    again when the mesh's nodes move: after a shift by 0.5 in x, a point that was outside the
    unit square is found in the cell whose midpoint is 0.1 away, and one left behind is
    outside (a stale tree would say the opposite)."""
    msh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 8, 8)
    tdim = msh.topology.dim
    assert _compat.bb_tree(msh, tdim) is _compat.bb_tree(msh, tdim)
    msh.geometry.x[:, 0] += 0.5
    inside, left = np.array([[1.2, 0.53]]), np.array([[0.2, 0.53]])  # inside a cell
    cells = locate_points(msh, inside)
    found = MPI.COMM_WORLD.allreduce(int((cells >= 0).sum()))
    assert found == 1 and MPI.COMM_WORLD.allreduce(int((locate_points(msh, left) >= 0).sum())) == 0
    if cells[0] >= 0:
        mid = dolfinx.mesh.compute_midpoints(msh, tdim, cells.astype(np.int32))[0, :2]
        assert np.linalg.norm(mid - inside[0]) <= 0.1
