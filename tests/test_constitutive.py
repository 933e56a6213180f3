"""Finite-strain materials: P = dW/dF and A = dP/dF by finite differences, objectivity, balance of
angular momentum, the small-strain limit, plane stress/strain against the 3D law, exact wave speeds
against the acoustic tensor, the UFL twin against numpy, bad input.

Every check is local to a rank (runs identically serial and under mpirun -n 2); the UFL check uses
each rank's own cells of a distributed mesh.
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx.fe_points import tabulate_in_cells
from dolfinx_meshfree.geometry.quadrature import cell_quadrature
from dolfinx_meshfree.physics.constitutive import check_deformation_gradients

import dolfinx
import numpy as np
import pytest
import scipy.optimize
import ufl
from mpi4py import MPI
from petsc4py import PETSc

E, NU = 3.0, 0.3
PLANES = ["strain", "stress", None]


def _materials():
    out = []
    for cls in (mf.SaintVenantKirchhoff, mf.NeoHookean):
        out += [pytest.param(cls, p, id=f"{cls.__name__}-{p}") for p in PLANES]
    out += [pytest.param(mf.LinearElastic, p, id=f"LinearElastic-{p}") for p in PLANES]
    return out


def _deformations(d: int, n: int = 6, scale: float = 0.25, seed: int = 0) -> np.ndarray:
    """Random F with det F > 0 (moderately large strains and rotations)."""
    rng = np.random.default_rng(seed)
    F = np.eye(d) + scale * rng.standard_normal((n, d, d))
    assert np.all(np.linalg.det(F) > 0.2)
    return F


def _rotation(d: int, angle: float = 0.7) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    if d == 2:
        return np.array([[c, -s], [s, c]])
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    c1, s1 = np.cos(1.1), np.sin(1.1)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, c1, -s1], [0.0, s1, c1]])
    return Rz @ Rx


def _central(fn, F: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of fn (values (n, ...)) in each F_kL: shape (n, ..., d, d)."""
    d = F.shape[1]
    cols = []
    for k in range(d):
        for L in range(d):
            dF = np.zeros_like(F)
            dF[:, k, L] = h
            cols.append((fn(F + dF) - fn(F - dF)) / (2 * h))
    out = np.stack(cols, axis=-1)
    return out.reshape(*out.shape[:-1], d, d)


@pytest.mark.parametrize(("cls", "plane"), _materials())
def test_stress_and_tangent_by_finite_differences(cls, plane):
    m = cls(E=E, nu=NU, plane=plane)
    assert isinstance(m, mf.Material)
    F = _deformations(m.gdim)
    P = m.first_piola(F)
    A = m.tangent(F)
    P_fd = _central(m.strain_energy_density, F)
    A_fd = _central(m.first_piola, F)
    # measured <= 3e-10 (O(h^2) truncation and eps/h cancellation at h = 1e-6)
    assert np.abs(P - P_fd).max() <= 1e-8 * np.abs(P).max()
    assert np.abs(A - A_fd).max() <= 1e-8 * np.abs(A).max()
    # hyperelastic: major symmetry A_iJkL = A_kLiJ
    assert np.abs(A - A.transpose(0, 3, 4, 1, 2)).max() <= 1e-13 * np.abs(A).max()


@pytest.mark.parametrize("cls", [mf.SaintVenantKirchhoff, mf.NeoHookean])
@pytest.mark.parametrize("plane", PLANES)
def test_objectivity_and_angular_momentum(cls, plane):
    """P(RF) = R P(F), W(RF) = W(F), A(RF) = R R A(F); P F^T symmetric (Rabczuk 2006, eq. 3)."""
    m = cls(E=E, nu=NU, plane=plane)
    d = m.gdim
    F = _deformations(d, seed=1)
    R = _rotation(d)
    RF = np.einsum("ij,qjk->qik", R, F)
    P, W, A = m.first_piola(F), m.strain_energy_density(F), m.tangent(F)
    scale = np.abs(P).max()
    assert np.abs(m.first_piola(RF) - np.einsum("ij,qjk->qik", R, P)).max() <= 1e-13 * scale
    assert np.abs(m.strain_energy_density(RF) - W).max() <= 1e-13 * np.abs(W).max()
    A_rot = np.einsum("ia,kb,qaJbL->qiJkL", R, R, A)
    assert np.abs(m.tangent(RF) - A_rot).max() <= 1e-13 * np.abs(A).max()
    tau = np.einsum("qiJ,qkJ->qik", P, F)  # Kirchhoff stress P F^T
    assert np.abs(tau - tau.transpose(0, 2, 1)).max() <= 1e-13 * scale


def test_small_strain_member_is_not_objective():
    """The linearised law stresses a rigid rotation: a 90-degree turn gives |P| of order E (the
    reason the spinning plate needs a finite-strain law)."""
    m = mf.LinearElastic(E=E, nu=NU, plane="strain")
    R = _rotation(2, np.pi / 2)[None]
    assert np.abs(m.first_piola(R)).max() >= 0.5 * E
    assert np.abs(mf.NeoHookean(E=E, nu=NU).first_piola(R)).max() <= 1e-14 * E


@pytest.mark.parametrize("cls", [mf.SaintVenantKirchhoff, mf.NeoHookean])
@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_small_strain_limit_is_linear_elastic(cls, plane):
    """A(I) is exactly the linear C (plane stress: the condensed lambda*), and P(I + e H) is the
    linear stress of e H up to O(e^2)."""
    m, lin = cls(E=E, nu=NU, plane=plane), mf.LinearElastic(E=E, nu=NU, plane=plane)
    eye = np.eye(2)[None]
    assert np.abs(m.tangent(eye) - lin.tangent(eye)).max() <= 1e-14 * E
    H = 1e-6 * np.random.default_rng(2).standard_normal((4, 2, 2))
    sig = lin.stress(H)
    rel = np.abs(m.first_piola(eye + H) - sig).max() / np.abs(sig).max()
    assert rel <= 1e-5  # O(|H|) = 1e-6 relative; measured 2e-6
    assert m.wave_speed() == pytest.approx(lin.wave_speed(), rel=1e-15)


def test_linear_member_matches_stress_of_grad_u():
    """LinearElastic.first_piola(I + grad u) is today's stress(grad u): bitwise when I + H - I is
    exact (dyadic H), to the round-off of forming F otherwise; W = 1/2 sigma : eps."""
    lin = mf.LinearElastic(E=E, nu=NU, plane="stress")
    rng = np.random.default_rng(3)
    H = rng.integers(-64, 64, (5, 2, 2)) / 256.0
    assert np.array_equal(lin.first_piola(np.eye(2) + H), lin.stress(H))
    H = 1e-3 * rng.standard_normal((5, 2, 2))
    diff = np.abs(lin.first_piola(np.eye(2) + H) - lin.stress(H)).max()
    assert diff <= 8 * np.finfo(float).eps * (lin.lmbda + 2 * lin.mu)
    eps = 0.5 * (H + H.transpose(0, 2, 1))
    W = lin.strain_energy_density(np.eye(2) + H)
    assert np.allclose(W, 0.5 * np.einsum("qij,qij->q", lin.stress(H), eps), rtol=1e-9)


def _diag3(F2: np.ndarray, l3: np.ndarray) -> np.ndarray:
    F3 = np.zeros((F2.shape[0], 3, 3))
    F3[:, :2, :2] = F2
    F3[:, 2, 2] = l3
    return F3


@pytest.mark.parametrize("cls", [mf.SaintVenantKirchhoff, mf.NeoHookean])
def test_plane_laws_are_the_3d_law(cls):
    """Plane strain = the 3D law at F_33 = 1; plane stress = the 3D law at the F_33 that makes
    P_33 = 0 (independently: SVK's closed form, the neo-Hookean's Newton root)."""
    F2 = _deformations(2, seed=4)
    m3 = cls(E=E, nu=NU, plane=None)
    scale = np.abs(m3.first_piola(_diag3(F2, np.ones(len(F2))))).max()
    ps = cls(E=E, nu=NU, plane="strain")
    P3 = m3.first_piola(_diag3(F2, np.ones(len(F2))))
    assert np.abs(ps.first_piola(F2) - P3[:, :2, :2]).max() <= 1e-14 * scale
    W3 = m3.strain_energy_density(_diag3(F2, np.ones(len(F2))))
    assert np.abs(ps.strain_energy_density(F2) - W3).max() <= 1e-14 * np.abs(W3).max()
    pst = cls(E=E, nu=NU, plane="stress")
    if cls is mf.NeoHookean:
        l3 = pst.thickness_stretch(F2)
    else:
        trE = 0.5 * (np.einsum("qij,qij->q", F2, F2) - 2.0)
        l3 = np.sqrt(1.0 - 2.0 * m3.lmbda / (m3.lmbda + 2 * m3.mu) * trE)
    P3 = m3.first_piola(_diag3(F2, l3))
    assert np.abs(P3[:, 2, 2]).max() <= 1e-13 * scale
    assert np.abs(pst.first_piola(F2) - P3[:, :2, :2]).max() <= 1e-13 * scale
    W3 = m3.strain_energy_density(_diag3(F2, l3))
    assert np.abs(pst.strain_energy_density(F2) - W3).max() <= 1e-13 * np.abs(W3).max()


def _max_acoustic(A: np.ndarray) -> float:
    """max over unit N and points of the largest eigenvalue of Q(N) = A_iJkL N_J N_L: dense
    sampling of directions, then Nelder-Mead from the best sample (independent of the closed
    forms)."""
    d = A.shape[1]

    def lam_max(N: np.ndarray, a: np.ndarray) -> np.ndarray:
        N = N / np.linalg.norm(N, axis=-1, keepdims=True)
        return np.linalg.eigvalsh(np.einsum("iJkL,nJ,nL->nik", a, N, N))[:, -1]

    if d == 2:
        t = np.linspace(0.0, np.pi, 2001)
        dirs = np.stack([np.cos(t), np.sin(t)], axis=1)
    else:
        k = 4000
        i = np.arange(k) + 0.5
        phi, th = np.arccos(1 - 2 * i / k), np.pi * (1 + 5**0.5) * i
        dirs = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
    best = -np.inf
    for a in A:
        vals = lam_max(dirs, a)
        x0 = dirs[int(np.argmax(vals))]
        res = scipy.optimize.minimize(
            lambda x, a=a: -lam_max(x[None], a)[0],
            x0,
            method="Nelder-Mead",
            options={"xatol": 1e-10, "fatol": 1e-14, "maxiter": 4000},
        )
        best = max(best, vals.max(), -res.fun)
    return float(best)


@pytest.mark.parametrize(("cls", "plane"), _materials())
def test_wave_speed_is_the_acoustic_maximum(cls, plane):
    m = cls(E=E, nu=NU, plane=plane)
    F = _deformations(m.gdim, n=3, scale=0.3, seed=5)
    q_max = _max_acoustic(m.tangent(F))
    c = m.wave_speed(F)
    # exact closed forms: equal to the numerical maximum (measured |relative gap| <= 1.3e-15)
    assert m.rho * c**2 >= q_max * (1 - 1e-12)
    assert m.rho * c**2 <= q_max * (1 + 1e-12)
    q0 = _max_acoustic(m.tangent(np.eye(m.gdim)[None]))
    assert m.rho * m.wave_speed() ** 2 == pytest.approx(q0, rel=1e-10)
    # the step must follow the material: SVK stiffens in stretch, the neo-Hookean in compression
    if cls is not mf.LinearElastic:
        stiffer = 1.2 if cls is mf.SaintVenantKirchhoff else 0.8
        assert m.wave_speed(stiffer * np.eye(m.gdim)[None]) > 1.05 * m.wave_speed()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"E": E, "nu": 0.5}, "nu=0.5 must lie in"),
        ({"E": E, "nu": 0.7}, "nu=0.7"),
        ({"E": 0.0, "nu": NU}, "E=0.0 must be a positive"),
        ({"E": -1.0, "nu": NU}, "E=-1.0"),
        ({"E": E, "nu": float("nan")}, "nu=nan"),
        ({"E": E, "nu": NU, "rho": 0.0}, "rho=0.0"),
        ({"E": E, "nu": NU, "plane": "membrane"}, "plane='membrane'"),
    ],
)
@pytest.mark.parametrize("cls", [mf.SaintVenantKirchhoff, mf.NeoHookean])
def test_bad_parameters(cls, kwargs, match):
    with pytest.raises(ValueError, match=match):
        cls(**kwargs)


@pytest.mark.parametrize("cls", [mf.SaintVenantKirchhoff, mf.NeoHookean])
@pytest.mark.parametrize("plane", PLANES)
def test_inverted_point_stops_with_its_coordinates(cls, plane):
    m = cls(E=E, nu=NU, plane=plane)
    d = m.gdim
    F = np.repeat(np.eye(d)[None], 3, axis=0)
    F[1, 0, 0] = -0.5
    points = np.arange(3 * d, dtype=float).reshape(3, d)
    for fn in (m.first_piola, m.tangent, m.strain_energy_density):
        with pytest.raises(ValueError, match=r"det F = -5\.000e-01 <= 0.*X = \[.*stop: no NaNs"):
            fn(F, points)
    with pytest.raises(ValueError, match="quadrature point 1: the deformation inverts"):
        m.first_piola(F)
    F[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="F is not finite"):
        m.tangent(F, points)
    with pytest.raises(ValueError, match=rf"shape \(num_points, {d}, {d}\)"):
        m.first_piola(np.eye(5 - d)[None])


def test_svk_plane_stress_thickness_collapse_stops():
    m = mf.SaintVenantKirchhoff(E=E, nu=NU, plane="stress")
    with pytest.raises(ValueError, match="thickness stretch squared"):
        m.first_piola(2.0 * np.eye(2)[None])  # tr E = 3: E_33 = -(3/7) 3 < -1/2
    check_deformation_gradients(np.eye(2)[None], 2)


def _ufl_case(cls, plane, G=None, nu=NU):
    m = cls(E=E, nu=nu, plane=plane)
    d = m.gdim
    comm = MPI.COMM_WORLD
    if d == 2:
        msh = dolfinx.mesh.create_unit_square(comm, 3, 3)
    else:
        msh = dolfinx.mesh.create_unit_cube(comm, 2, 2, 2)
    V = _compat.vector_function_space(msh, 1)
    if G is None:  # F of the field
        G = np.eye(d) + 0.3 * np.random.default_rng(6).standard_normal((d, d))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: (G - np.eye(d)) @ x[:d] + 0.1)
    F = ufl.Identity(d) + ufl.grad(u)
    X, _ = _compat.quadrature_rule(msh.topology.cell_type.name, 2)
    expr = _compat.create_expression(m.ufl_first_piola(F), X, msh)
    cells = np.arange(msh.topology.index_map(d).size_local, dtype=np.int32)
    P_ufl = _compat.eval_expression(expr, msh, cells, d * d).reshape(-1, d, d)
    P = m.first_piola(np.repeat(G[None], P_ufl.shape[0], axis=0))
    return P_ufl, P


@pytest.mark.parametrize(("cls", "plane"), _materials())
def test_ufl_first_piola_equals_numpy(cls, plane):
    """The FE side's law (a DOLFINx Expression of ufl_first_piola(I + grad u)) at quadrature
    points equals first_piola of the same F for an affine u (exactly interpolated by P1)."""
    P_ufl, P = _ufl_case(cls, plane)
    assert np.abs(P_ufl - P).max() <= 1e-12 * max(np.abs(P).max(), 1e-300)


@pytest.mark.parametrize(
    "G", [[[2.2, 0.3], [0.0, 1.8]], [[0.45, 0.1], [-0.1, 0.5]]], ids=["J4", "J0.23"]
)
@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_ufl_plane_stress_neo_hookean_at_large_strain(G, nu):
    """The UFL twin's unrolled thickness Newton (8 steps from the small-strain root) still equals
    the numpy root at large in-plane stretch and compression (measured: converged in <= 7 steps
    for 0.05 <= J_2D <= 20, nu <= 0.49)."""
    P_ufl, P = _ufl_case(mf.NeoHookean, "stress", np.array(G), nu)
    assert np.abs(P_ufl - P).max() <= 1e-12 * np.abs(P).max()


@pytest.mark.parametrize(
    ("cls", "plane"),
    [
        (mf.SaintVenantKirchhoff, "strain"),
        (mf.NeoHookean, "stress"),
        (mf.NeoHookean, None),
    ],
)
def test_fe_residual_and_jacobian_match_internal_forces(cls, plane):
    """The FE side, independently: DOLFINx assembles inner(ufl_first_piola(I + grad u), grad v) dx
    and its UFL derivative on P1; InternalForces on the P1 basis table at the same quadrature
    gives the same residual and the same tangent action (owned dofs, summed over ranks)."""
    m = cls(E=E, nu=NU, plane=plane)
    d = m.gdim
    comm = MPI.COMM_WORLD
    if d == 2:
        msh = dolfinx.mesh.create_unit_square(comm, 3, 3)
    else:
        msh = dolfinx.mesh.create_unit_cube(comm, 2, 2, 2)
    V = _compat.vector_function_space(msh, 1)
    u, w = dolfinx.fem.Function(V), dolfinx.fem.Function(V)
    rng = np.random.default_rng(7)
    u.interpolate(lambda x: 0.15 * np.sin(3 * x[:d] + rng.standard_normal((d, 1))))
    w.interpolate(lambda x: np.cos(2 * x[:d] + 1.0))
    v, du = ufl.TestFunction(V), ufl.TrialFunction(V)
    P = m.ufl_first_piola(ufl.Identity(d) + ufl.grad(u))
    dx = ufl.dx(metadata={"quadrature_degree": 2})
    R = ufl.inner(P, ufl.grad(v)) * dx
    b = _compat.assemble_vector(_compat.create_form(R))
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    A = _compat.assemble_matrix(_compat.create_form(ufl.derivative(R, u, du)))
    Aw = A.createVecLeft()
    A.mult(_compat.function_petsc_vec(w), Aw)

    q = cell_quadrature(msh, 2)
    forces = mf.InternalForces(tabulate_in_cells(V, q.points, q.cells), q.weights, m)
    mine = dolfinx.fem.Function(V)
    n_owned = V.dofmap.index_map.size_local * d
    for vec, ref in (
        (forces.internal_force(u.x.array), b),
        (forces.tangent(u.x.array) @ w.x.array, Aw),
    ):
        mine.x.array[:] = vec
        _compat.scatter_reverse_add(mine)
        got, want = mine.x.array[:n_owned], ref.array[:n_owned]
        scale = comm.allreduce(np.abs(want).max(initial=0.0), op=MPI.MAX)
        err = comm.allreduce(np.abs(got - want).max(initial=0.0), op=MPI.MAX)
        assert err <= 1e-12 * scale, (err, scale)  # measured <= 1e-15 relative
    for obj in (A, Aw, b):
        obj.destroy()


@pytest.mark.serial
@pytest.mark.parametrize("plane", ["stress", "strain", None])
def test_material_parameters_are_form_arguments_not_literals(plane):
    """Two parameter sets of a law give UFL forms of one signature, so that FFCx compiles a
    law's form once, not once per (E, nu) (``physics.materials.ufl_constants``: a float in a
    form is a literal of the generated C code); the values are still each law's
    (``test_ufl_first_piola_equals_numpy``)."""
    d = 3 if plane is None else 2
    msh = (
        dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
        if d == 3
        else dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 1, 1)
    )
    V = _compat.vector_function_space(msh, 1)
    u, v, w = ufl.TrialFunction(V), ufl.TestFunction(V), dolfinx.fem.Function(V)
    F = ufl.Identity(d) + ufl.grad(w)
    for cls in (mf.LinearElastic, mf.SaintVenantKirchhoff, mf.NeoHookean):
        laws = [cls(1.0, 0.3, plane), cls(210e3, 0.2, plane)]
        forms = [ufl.inner(m.ufl_first_piola(F), ufl.grad(v)) * ufl.dx for m in laws]
        assert forms[0].signature() == forms[1].signature(), cls.__name__
    linear = [mf.LinearElastic(E, 0.25, plane) for E in (1.0, 3e7)]
    forms = [ufl.inner(m.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx for m in linear]
    assert forms[0].signature() == forms[1].signature()
