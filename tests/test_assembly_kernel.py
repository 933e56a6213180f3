"""The compiled stiffness assembly (physics/assembly_kernel.py) against the scipy products.

Both compute ``K = sum_q w_q B_test^T D B_trial`` (Belytschko et al. 1995, eq. 4.3) and the
finite-strain tangent ``sum_q w_q G_test^T A_q G`` (Rabczuk, Xiao & Sauer 2006, eq. 34) from
the same tables, in different summation orders, so they agree to round-off: ``TOL = 1e-12``
relative to the largest entry is a margin of 200 or more over what is observed (4e-16 to
5e-15 over these cases). The compiled pattern keeps the structural zeros that scipy drops, so
the check is on the difference of the two matrices, plus an exact check of the pattern on the
scipy side.
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.geometry.quadrature import boundary_facets
from dolfinx_meshfree.physics import assembly_kernel
from dolfinx_meshfree.physics.forces import InternalForces
from dolfinx_meshfree.physics.operators import consistent_gradients, stiffness_matrix
from dolfinx_meshfree.statics.efg import crack_rules, particle_stiffness

import dolfinx
import numpy as np
import pytest
import scipy.sparse as sp
from conftest import load_benchmark
from mpi4py import MPI

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not installed")

TOL = 1e-12
COMM = MPI.COMM_WORLD


def assert_same(a: sp.csr_matrix, b: sp.csr_matrix) -> None:
    """``b`` (compiled) equals ``a`` (scipy) to TOL, and holds every entry of ``a``."""
    assert a.shape == b.shape
    assert b.has_sorted_indices and b.format == "csr"
    scale = np.abs(a.data).max()
    assert scale > 0
    assert abs(a - b).max() <= TOL * scale
    pa = a.copy()
    pa.eliminate_zeros()
    pa.data[:] = 1.0
    pb = b.copy()
    pb.data[:] = 1.0
    assert (pa - pa.multiply(pb)).nnz == 0  # scipy's pattern is inside the compiled one
    b.sum_duplicates()  # canonical already: nothing to sum
    assert b.nnz == pb.nnz


def cloud(gdim: int, seed: int) -> tuple[mf.MLS, np.ndarray, np.ndarray]:
    """A jittered grid of particles, random evaluation points and weights."""
    rng = np.random.default_rng(seed)
    ns = {2: 12, 3: 5}[gdim]
    axes = [np.linspace(0.0, 1.0, ns + 1)] * gdim
    P = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, gdim)
    P = P + rng.uniform(-0.2, 0.2, P.shape) / ns
    x = rng.uniform(0.0, 1.0, (3 * len(P), gdim))
    return P, x, rng.uniform(0.5, 1.0, len(x))


def material(gdim: int) -> mf.LinearElastic:
    return mf.LinearElastic(1e3, 0.3, plane="strain" if gdim == 2 else None)


@pytest.mark.parametrize("gdim", [2, 3])
@pytest.mark.parametrize("form", ["galerkin", "petrov", "wider test", "ragged test"])
@pytest.mark.parametrize("renumber", [False, True])
def test_stiffness_equals_scipy(gdim, form, renumber):
    P, x, w = cloud(gdim, seed=gdim)
    rng = np.random.default_rng(7)
    t = mf.MLS(P, dilation=2.0).tabulate(x)
    trial = t.gradients
    if form == "galerkin":
        test = None
    elif form == "petrov":  # a VCI-like correction g + N diag(xi): same pattern, other order
        test = [(g + t.values @ sp.diags(rng.normal(size=len(P)))).tocsr() for g in trial]
    elif form == "wider test":  # supports of test and trial functions differ
        test = mf.MLS(P, dilation=2.6).tabulate(x).gradients
    else:  # the test tables do not share one pattern: gathered onto their union
        test = [g.copy() for g in trial]
        test[0].data[rng.random(test[0].nnz) < 0.2] = 0.0
        test[0].eliminate_zeros()
    node_map = rng.permutation(len(P)) if renumber else None
    mat = material(gdim)
    a = stiffness_matrix(test or trial, w, mat, trial if test else None, node_map, "scipy")
    b = stiffness_matrix(test or trial, w, mat, trial if test else None, node_map, "numba")
    assert_same(a, b)
    if form == "galerkin":  # symmetric to round-off in both
        assert abs(b - b.T).max() <= TOL * np.abs(b.data).max()


def unit_domain(gdim: int) -> dolfinx.mesh.Mesh:
    if gdim == 2:
        return dolfinx.mesh.create_rectangle(
            COMM, [np.zeros(2), np.ones(2)], [8, 8], dolfinx.mesh.CellType.quadrilateral
        )
    return dolfinx.mesh.create_box(
        COMM, [np.zeros(3), np.ones(3)], [3, 3, 3], dolfinx.mesh.CellType.hexahedron
    )


CRACK = [[0.0, 0.52], [0.3, 0.52], [0.55, 0.68]]  # kinked edge crack: cut-cell rules


@pytest.mark.parametrize(
    ("gdim", "consistent", "cracked"),
    [(2, True, False), (2, False, False), (2, True, True), (2, False, True), (3, True, False)],
)
def test_particle_stiffness_equals_scipy(gdim, consistent, cracked, monkeypatch):
    """EFG stiffness as the solvers build it (this rank's cells, PETSc numbering): VCI on and
    off, a cracked patch with cut-cell quadrature and its crack-face boundary rule."""
    msh = unit_domain(gdim)
    h = 1 / 8 if gdim == 2 else 1 / 3
    P = mf.ParticleSet.from_cells(msh, h)
    cracks = [mf.Crack(CRACK)] if cracked else []
    prob = mf.EFGElasticity(P, material(gdim), dilation=2.5, consistent=consistent, cracks=cracks)
    deg = prob.quadrature_degree
    boundary = (boundary_facets(msh), None) if consistent else None
    num_owned = msh.topology.index_map(msh.topology.dim).size_local
    q, bq = crack_rules(msh, np.arange(num_owned), prob.cracks, deg, boundary)
    K = {}
    for backend in ("scipy", "numba"):
        monkeypatch.setattr(assembly_kernel, "DEFAULT_BACKEND", backend)
        K[backend] = particle_stiffness(
            P, prob.mls, prob.linear_material, deg, boundary, quadrature=q, boundary_quadrature=bq
        )[0]
    assert_same(K["scipy"], K["numba"])


@pytest.mark.parametrize("gdim", [2, 3])
@pytest.mark.parametrize("vci", [False, True])
def test_finite_strain_tangent_equals_scipy(gdim, vci):
    """The consistent tangent of a Neo-Hookean law at a finite deformation (per-point A)."""
    P, x, w = cloud(gdim, seed=3)
    rng = np.random.default_rng(4)
    t = mf.MLS(P, dilation=2.0).tabulate(x)
    test = [(g + t.values @ sp.diags(rng.normal(size=len(P)))).tocsr() for g in t.gradients]
    law = mf.NeoHookean(E=1e3, nu=0.3, plane="strain" if gdim == 2 else None)
    forces = InternalForces(t, w, law, test_gradients=test if vci else None)
    u = (0.1 * np.sin(3.0 * P) + 0.2 * P[:, ::-1]).ravel()  # smooth, finite: 10-20 % strains
    a = forces.tangent(u, backend="scipy")
    b = forces.tangent(u, backend="numba")
    assert_same(a, b)
    # the material part differs point by point: A is not constant, so this is not the
    # linear stiffness (a check that the per-point tangents are used)
    K0 = forces.tangent(np.zeros(forces.num_dofs), backend="numba")  # the pattern reused
    assert_same(forces.tangent(np.zeros(forces.num_dofs), backend="scipy"), K0)
    assert abs(b - K0).max() > 1e-3 * np.abs(K0.data).max()


def test_backend_errors(monkeypatch):
    P, x, w = cloud(2, seed=1)
    t = mf.MLS(P, dilation=2.0).tabulate(x)
    with pytest.raises(ValueError, match=r"backend='fortran'.*use one of \('numba', 'scipy'\)"):
        stiffness_matrix(t.gradients, w, material(2), backend="fortran")
    monkeypatch.setattr(jit, "AVAILABLE", False)  # as without numba
    with pytest.raises(ValueError, match=r"needs numba.*backend='scipy'"):
        stiffness_matrix(t.gradients, w, material(2), backend="numba")


@pytest.mark.skipif(COMM.size > 1, reason="the benchmark spawns serial workers")
def test_bench_assembly_smoke():
    """benchmarks/bench_assembly.py on the coarsest beam (a smoke run; no timing is checked): both
    backends give the same matrix (the demo asserts it), each peak holds at least the output,
    and the compiled peak is below half the scipy one (measured 2.8 / 26.8 MB at h = 1)."""
    records = load_benchmark("bench_assembly").main(["--h", "1.0", "--repeats", "1"])
    by = {r["backend"]: r for r in records}
    assert set(by) == {"scipy", "numba"}
    for r in records:
        assert r["particles"] == 637 and r["peak_bytes"] >= r["K_bytes"] > 0
    assert by["numba"]["peak_bytes"] < 0.5 * by["scipy"]["peak_bytes"]


@pytest.mark.parametrize("gdim", [2, 3])
def test_consistent_gradients_same_pattern_path(gdim):
    """VCI on MLS tables (gradients sharing the values' pattern: one O(nnz) pass, the pattern
    kept) equals the sparse-matrix form ``g + N diag(xi)`` (taken when the pattern differs,
    here by passing CSC gradients); the same products and sums, so equal to round-off
    (observed: bitwise)."""
    P, x, w = cloud(gdim, seed=5)
    rng = np.random.default_rng(6)
    mls = mf.MLS(P, dilation=2.0)
    t = mls.tabulate(x)
    xb = rng.uniform(0.0, 1.0, (200, gdim))
    tb = mls.tabulate(xb, derivatives=0)
    normals = rng.normal(size=(len(xb), gdim))
    args = (t.values, w, tb.values, rng.uniform(0.1, 1.0, len(xb)), normals, MPI.COMM_SELF)
    fast = consistent_gradients(t.values, t.gradients, *args[1:])
    slow = consistent_gradients(t.values, [g.tocsc() for g in t.gradients], *args[1:])
    for f, s in zip(fast, slow, strict=True):
        np.testing.assert_array_equal(f.indptr, t.values.indptr)
        np.testing.assert_array_equal(f.indices, t.values.indices)
        assert abs(f - s).max() <= TOL * np.abs(s.data).max()


def test_no_points_gives_empty_matrix():
    """A rank without integration cells (a patch elsewhere) contributes an empty matrix."""
    P, _, _ = cloud(2, seed=2)
    t = mf.MLS(P, dilation=2.0).tabulate(np.zeros((0, 2)))
    perm = np.arange(len(P))[::-1].copy()
    for backend in ("scipy", "numba"):
        K = stiffness_matrix(t.gradients, np.zeros(0), material(2), None, perm, backend)
        assert K.shape == (2 * len(P), 2 * len(P)) and K.nnz == 0
