"""Internal force and consistent tangent from shape tables (total Lagrangian, Rabczuk et al. 2006,
eq. 34): the linear member reproduces today's stiffness, K_T is the derivative of f_int, and the
finite-strain patch test (a homogeneous F on an EFG patch with consistent integration gives f_int
= the boundary integral of N P n^0) holds to round-off in 2D (distributed mesh, serial and 2 ranks)
and 3D."""

import itertools

import dolfinx_meshfree as mf
from dolfinx_meshfree.geometry.quadrature import boundary_facets, cell_quadrature, facet_quadrature
from dolfinx_meshfree.physics.forces import gradient_operator
from dolfinx_meshfree.physics.operators import consistent_gradients, load_vector, stiffness_matrix

import dolfinx
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mpi4py import MPI

E, NU = 5.0, 0.3


def _grid(d: int, k: int, jitter: float, seed: int) -> np.ndarray:
    axes = [np.linspace(0.0, 1.0, k)] * d
    x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
    interior = np.all((x > 0) & (x < 1), axis=1)
    rng = np.random.default_rng(seed)
    x[interior] += jitter / (k - 1) * rng.uniform(-1, 1, (interior.sum(), d))
    return x


def _table(d: int, seed: int = 0):
    """MLS table of a jittered particle grid at random points, random weights, and perturbed
    test gradients (VCI-like ``g + N xi``: test differs from trial, as in the EFG stiffness)."""
    rng = np.random.default_rng(seed)
    k = 6 if d == 2 else 4
    mls = mf.MLS(_grid(d, k, 0.2, seed), dilation=2.5)
    m = 40 if d == 2 else 30
    t = mls.tabulate(0.05 + 0.9 * rng.random((m, d)))
    w = rng.uniform(0.5, 1.0, m) / m
    xi = 0.3 * rng.standard_normal((mls.num_particles, d))
    test = [(g + t.values @ sp.diags(xi[:, j])).tocsr() for j, g in enumerate(t.gradients)]
    return t, w, test


def _voigt_stiffness_3d(grads, w, lam, mu):
    """Independent 3D small-strain stiffness: Voigt B (6 x 3n per point) and the isotropic D."""
    m, n = grads[0].shape
    B = np.zeros((m, 6, 3 * n))
    g = [gj.toarray() for gj in grads]
    for i in range(3):
        B[:, i, i::3] = g[i]
    for r, (i, j) in enumerate([(1, 2), (0, 2), (0, 1)]):
        B[:, 3 + r, i::3] = g[j]
        B[:, 3 + r, j::3] = g[i]
    D = np.diag([lam + 2 * mu] * 3 + [mu] * 3)
    D[:3, :3] += lam - np.diag([lam] * 3)
    return np.einsum("q,qai,ab,qbj->ij", w, B, D, B)


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_linear_member_is_todays_stiffness(plane):
    """LinearElastic: K_T(u) == stiffness_matrix and f_int(u) == K u (test gradients differing
    from the trial ones, as with VCI)."""
    t, w, test = _table(2)
    mat = mf.LinearElastic(E=E, nu=NU, plane=plane)
    K = stiffness_matrix(test, w, mat, t.gradients)
    forces = mf.InternalForces(t, w, mat, test_gradients=test)
    u = 0.1 * np.random.default_rng(1).standard_normal(forces.num_dofs)
    Ku = K @ u
    assert np.abs(forces.internal_force(u) - Ku).max() <= 1e-12 * np.abs(Ku).max()
    KT = forces.tangent(u)
    assert abs(KT - K).max() <= 1e-12 * abs(K).max()
    # every finite-strain law has the same tangent at u = 0
    for cls in (mf.SaintVenantKirchhoff, mf.NeoHookean):
        K0 = mf.InternalForces(t, w, cls(E=E, nu=NU, plane=plane), test).tangent(0 * u)
        assert abs(K0 - K).max() <= 1e-12 * abs(K).max()


def test_3d_tangent_at_rest_is_the_voigt_stiffness():
    """3D: at u = 0 every law's K_T is the small-strain stiffness B^T D B (built independently here
    with a 6-component Voigt B); with a 3D LinearElastic it is also f_int = K u."""
    t, w, _ = _table(3)
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    K = _voigt_stiffness_3d(t.gradients, w, lam, mu)
    u0 = np.zeros(3 * t.shape[1])
    for cls in (mf.SaintVenantKirchhoff, mf.NeoHookean):
        K0 = mf.InternalForces(t, w, cls(E=E, nu=NU, plane=None)).tangent(u0).toarray()
        assert np.abs(K0 - K).max() <= 1e-12 * np.abs(K).max()
    lin = mf.LinearElastic(E=E, nu=NU, plane=None)
    forces = mf.InternalForces(t, w, lin)
    u = 0.1 * np.random.default_rng(2).standard_normal(forces.num_dofs)
    assert np.abs(forces.tangent(u).toarray() - K).max() <= 1e-12 * np.abs(K).max()
    assert np.abs(forces.internal_force(u) - K @ u).max() <= 1e-12 * np.abs(K @ u).max()


@pytest.mark.parametrize("cls", [mf.SaintVenantKirchhoff, mf.NeoHookean])
@pytest.mark.parametrize("plane", ["strain", "stress", None])
def test_tangent_is_the_derivative_of_the_internal_force(cls, plane):
    """K_T against central differences of f_int (every column), at a finite deformation."""
    d = 3 if plane is None else 2
    t, w, test = _table(d, seed=3)
    forces = mf.InternalForces(t, w, cls(E=E, nu=NU, plane=plane), test_gradients=test)
    rng = np.random.default_rng(4)
    u = 0.05 * rng.standard_normal(forces.num_dofs)
    F = forces.deformation_gradient(u)
    assert np.abs(F - np.eye(d)).max() > 0.1  # finite strain at some points
    KT = forces.tangent(u).toarray()
    h = 1e-6
    eye = np.eye(forces.num_dofs)
    fd = np.stack(
        [
            (forces.internal_force(u + h * e) - forces.internal_force(u - h * e)) / (2 * h)
            for e in eye
        ],
        axis=1,
    )
    # measured <= 1e-10 relative (truncation O(h^2), cancellation eps/h)
    assert np.abs(KT - fd).max() <= 1e-8 * np.abs(KT).max()
    # and f_int is the gradient of the stored energy when test = trial (hyperelastic)
    plain = mf.InternalForces(t, w, cls(E=E, nu=NU, plane=plane))
    v = rng.standard_normal(forces.num_dofs)
    dW = (plain.strain_energy(u + h * v) - plain.strain_energy(u - h * v)) / (2 * h)
    assert dW == pytest.approx(plain.internal_force(u) @ v, rel=1e-7)


def _homogeneous(d: int) -> np.ndarray:
    if d == 2:
        return np.array([[1.3, 0.4], [-0.2, 0.9]])
    return np.array([[1.2, 0.3, -0.1], [-0.2, 0.9, 0.25], [0.1, -0.15, 1.1]])


@pytest.mark.parametrize(
    ("cls", "plane"),
    [(mf.SaintVenantKirchhoff, "strain"), (mf.NeoHookean, "strain"), (mf.NeoHookean, "stress")],
)
def test_finite_strain_patch_test_2d(cls, plane):
    """EFG with consistent integration (VCI) on a distributed quadrilateral mesh and a jittered
    particle set: the affine field u = (F0 - I) X has F = F0 at every point and f_int equals the
    boundary integral of N_J P(F0) n^0 (eq. 5) to round-off, at a large F0; summed over ranks."""
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_unit_square(comm, 4, 4, dolfinx.mesh.CellType.quadrilateral)
    particles = mf.ParticleSet.from_cells(msh, 1.0 / 6, jitter=0.2, seed=1)
    mls = mf.MLS(particles, dilation=2.5)
    q = cell_quadrature(msh, 3)
    bq = facet_quadrature(msh, boundary_facets(msh), 3)
    tq = mls.tabulate(q.points)
    tb = mls.tabulate(bq.points, derivatives=0)
    vci = consistent_gradients(
        tq.values, tq.gradients, q.weights, tb.values, bq.weights, bq.normals, comm
    )
    F0 = _homogeneous(2)
    mat = cls(E=E, nu=NU, plane=plane)
    u = ((F0 - np.eye(2)) @ particles.positions.T).T.ravel()  # MLS reproduces linear fields
    forces = mf.InternalForces(tq, q.weights, mat, test_gradients=vci, comm=comm)
    assert np.abs(forces.deformation_gradient(u) - F0).max() <= 1e-12
    f = comm.allreduce(forces.internal_force(u), op=MPI.SUM)
    P0 = mat.first_piola(F0[None])[0]
    f_ref = comm.allreduce(load_vector(tb.values, bq.weights, bq.normals @ P0.T), op=MPI.SUM)
    assert np.abs(f - f_ref).max() <= 1e-12 * np.abs(f_ref).max()  # measured ~1e-15
    energy = comm.allreduce(forces.strain_energy(u), op=MPI.SUM)
    assert energy == pytest.approx(mat.strain_energy_density(F0[None])[0], rel=1e-12)
    # plain Gauss quadrature (no VCI) misses it: the consistency is what makes it exact
    plain = mf.InternalForces(tq, q.weights, mat)
    f_plain = comm.allreduce(plain.internal_force(u), op=MPI.SUM)
    assert np.abs(f_plain - f_ref).max() >= 1e-6 * np.abs(f_ref).max()


def _box_quadrature_3d(k: int, order: int = 2):
    """Gauss points of a k^3 grid of hexahedral cells on the unit cube, and of its faces."""
    s, ws = np.polynomial.legendre.leggauss(order)
    s, ws = 0.5 * (s + 1), 0.5 * ws
    c = (np.arange(k)[:, None] + s[None, :]).ravel() / k
    wc = np.tile(ws, k) / k
    X = np.stack(np.meshgrid(c, c, c, indexing="ij"), -1).reshape(-1, 3)
    W = np.einsum("i,j,k->ijk", wc, wc, wc).ravel()
    face = np.stack(np.meshgrid(c, c, indexing="ij"), -1).reshape(-1, 2)
    wf = np.outer(wc, wc).ravel()
    bx, bw, bn = [], [], []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        for side in (0.0, 1.0):
            x = np.zeros((face.shape[0], 3))
            x[:, others] = face
            x[:, axis] = side
            n = np.zeros(3)
            n[axis] = 1.0 if side else -1.0
            bx.append(x)
            bw.append(wf)
            bn.append(np.repeat(n[None], face.shape[0], axis=0))
    return X, W, np.concatenate(bx), np.concatenate(bw), np.concatenate(bn)


@pytest.mark.parametrize("cls", [mf.SaintVenantKirchhoff, mf.NeoHookean])
def test_finite_strain_patch_test_3d(cls):
    """3D: the same patch test on the unit cube (jittered 4^3 particles, 3^3 cells of 2^3 Gauss
    points, VCI from the six faces' Gauss points), local to each rank."""
    X, W, bx, bw, bn = _box_quadrature_3d(3)
    mls = mf.MLS(_grid(3, 4, 0.2, 7), dilation=2.2)
    tq = mls.tabulate(X)
    tb = mls.tabulate(bx, derivatives=0)
    vci = consistent_gradients(tq.values, tq.gradients, W, tb.values, bw, bn, MPI.COMM_SELF)
    F0 = _homogeneous(3)
    mat = cls(E=E, nu=NU, plane=None)
    forces = mf.InternalForces(tq, W, mat, test_gradients=vci)
    u = ((F0 - np.eye(3)) @ mls.points.T).T.ravel()
    assert np.abs(forces.deformation_gradient(u) - F0).max() <= 1e-12
    P0 = mat.first_piola(F0[None])[0]
    f_ref = load_vector(tb.values, bw, bn @ P0.T)
    f = forces.internal_force(u)
    assert np.abs(f - f_ref).max() <= 1e-12 * np.abs(f_ref).max()


def test_gradient_operator_layout():
    """(G u)[d^2 q + d i + J] = du_i/dX_J: the table's own gradient of the (n, d) coefficients."""
    t, _, _ = _table(2)
    u = np.random.default_rng(5).standard_normal((t.shape[1], 2))
    H = (gradient_operator(t.gradients) @ u.ravel()).reshape(-1, 2, 2)
    assert np.array_equal(H, t.gradient(u))


def test_bad_input():
    t, w, _ = _table(2)
    with pytest.raises(ValueError, match=r"material is 3D \(plane=None\)"):
        mf.InternalForces(t, w, mf.NeoHookean(E=E, nu=NU, plane=None))
    with pytest.raises(ValueError, match=r"weights should have shape \(40,\)"):
        mf.InternalForces(t, w[:-1], mf.NeoHookean(E=E, nu=NU))
    with pytest.raises(TypeError, match="Material protocol"):
        mf.InternalForces(t, w, object())
    forces = mf.InternalForces(t, w, mf.NeoHookean(E=E, nu=NU))
    with pytest.raises(ValueError, match="u should have 72 interleaved entries"):
        forces.internal_force(np.zeros(10))


def test_inverted_point_stops_on_every_rank():
    """det F <= 0 at a point (on rank 0 only) stops every rank, naming the point's coordinates."""
    comm = MPI.COMM_WORLD
    t, w, _ = _table(2)
    forces = mf.InternalForces(t, w, mf.NeoHookean(E=E, nu=NU), comm=comm)
    u = np.zeros(forces.num_dofs)
    if comm.rank == 0:
        u[0::2] = -2.0 * _grid(2, 6, 0.2, 0)[:, 0]  # u_x = -2 X: F_xx = -1, folded over
    with pytest.raises(ValueError, match=r"det F = .* <= 0|on rank 0: ValueError: det F"):
        forces.internal_force(u)
    with pytest.raises(ValueError, match=r"X = \[|on rank 0"):
        forces.tangent(u)


@pytest.mark.parametrize(
    "mat",
    [mf.SaintVenantKirchhoff(E=E, nu=NU), mf.NeoHookean(E=E, nu=NU, plane="stress")],
    ids=["SVK", "NeoHookean-stress"],
)
def test_newton_with_internal_force_and_tangent_converges_quadratically(mat):
    """The module's docstring example: Newton on f_int(u) = lambda f_ext in 2 load steps, with
    f_ext = f_int(u*) of a known bending field u* (max |F - I| = 0.14) and the left column's
    coefficients fixed. It returns u* to round-off with quadratic convergence of the error in the
    last step, e_{k+1} <= 50 e_k^2 (measured constant <= 22; a linear rate fails it from
    e_k ~ 1e-5 on), in at most 6 iterations per step. Local mesh (COMM_SELF): identical on every
    rank."""
    msh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4, dolfinx.mesh.CellType.quadrilateral)
    particles = mf.ParticleSet.from_cells(msh, 1.0 / 6, jitter=0.2, seed=1)
    q = cell_quadrature(msh, 3)
    forces = mf.InternalForces(mf.MLS(particles, dilation=2.5).tabulate(q.points), q.weights, mat)
    x, y = particles.positions.T
    u_star = 0.5 * np.stack([0.2 * x * y - 0.1 * x**2, 0.15 * np.sin(2 * x)], 1).ravel()
    f_ext = forces.internal_force(u_star)
    free = np.flatnonzero(np.repeat(x > 1e-9, 2))
    u = np.zeros(forces.num_dofs)
    for lam in (0.5, 1.0):
        res, err = [], []
        for _ in range(10):
            r = lam * f_ext - forces.internal_force(u)
            res.append(np.linalg.norm(r[free]))
            err.append(np.abs(u - u_star).max())
            if res[-1] <= 1e-12 * np.linalg.norm(f_ext[free]):
                break
            K = forces.tangent(u)[free][:, free].tocsc()
            u[free] += spla.spsolve(K, r[free])
        assert res[-1] <= 1e-12 * np.linalg.norm(f_ext[free]) and len(res) <= 7, res
    pairs = [(a, b) for a, b in itertools.pairwise(err) if b > 1e-12]
    assert len(pairs) >= 3 and all(b <= 50.0 * a**2 for a, b in pairs), err
    assert err[-1] <= 1e-12
