"""Adaptive quadrature ahead of the crack tip (issue 11, item 4): ``mf.AdaptiveQuadrature``,
the dense Gauss rule (degree 7, 4 x 4) within a radius of the tips and a coarse one elsewhere.

Oracles: exact reproduction (a rigid motion has no strain under any rule: a cracked body keeps
moving rigidly to round-off); the uniform rule itself (a dense zone covering every cell gives
its points and weights bit for bit); the spectrum of the free stiffness (three rigid modes, and
the lowest non-rigid eigenvalue of the coarse rule against the uniform rule's: a spurious
zero-energy mode would put it near zero, as one point per cell does); energy conservation of
the central difference over many steps; the cells' rules compared one by one (for
``changed_cells``); the SIFs of the uniform rule; serial against 2 ranks.
"""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.approx.crack_cuts import attach_cracks
from dolfinx_meshfree.geometry.adaptive_quadrature import changed_cells, near_tip_cells
from dolfinx_meshfree.geometry.crack import CrackDomain, place_crack
from dolfinx_meshfree.geometry.cut_cells import cut_cell_quadrature
from dolfinx_meshfree.geometry.quadrature import cell_quadrature
from dolfinx_meshfree.statics.efg import particle_stiffness

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

COMM = MPI.COMM_WORLD
MAT = mf.LinearElastic(1000.0, 0.3, rho=2.0)  # plane stress
EDGE = [[0.0, 0.52], [0.5, 0.52]]
COUPLED_KINKED = [[0.35, 0.45], [0.5, 0.52], [0.65, 0.47]]
RIGID = np.array([[0.0, 0.3], [-0.3, 0.0]])
C = np.array([0.1, -0.2])


def square(n=10, comm=COMM):
    return dolfinx.mesh.create_rectangle(
        comm, [np.zeros(2), np.ones(2)], [n, n], dolfinx.mesh.CellType.quadrilateral
    )


def owned(msh):
    return np.arange(msh.topology.index_map(2).size_local)


def model(method, crack_points, quadrature, n=10, comm=COMM):
    msh = square(n, comm)
    cracks = [mf.Crack(crack_points)]
    if method == "efg":
        P = mf.ParticleSet.from_cells(msh, 1.0 / n)
        dyn = mf.ExplicitDynamics.efg(
            P, MAT, dilation=2.5, cracks=cracks, safety=0.5, quadrature=quadrature
        )
        return msh, dyn
    V = _compat.vector_function_space(msh)
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[owned(msh)], :2].mean(axis=1)
    cells = np.flatnonzero((np.abs(mid - 0.5) < 0.4).all(axis=1))
    patch = mf.ParticlePatch(msh, cells, 1.0 / n, cracks=cracks, quadrature=quadrature)
    prob = mf.CoupledElasticity(V, patch, MAT, coupling=method)
    return msh, mf.ExplicitDynamics.coupled(prob, safety=0.5)


@pytest.mark.parametrize(("method", "crack"), [("efg", EDGE), ("lagrange", COUPLED_KINKED)])
def test_rigid_motion_with_adaptive_rule(method, crack):
    """A rigid motion (translation + rotation rate) after 40 steps, the dense zone around the
    tip only (radius 0.15, far = 2 x 2): measured 1e-15 - 1e-14 (check 1e-12); energy drift
    ~1e-15 (check 1e-12)."""
    _, dyn = model(method, crack, mf.AdaptiveQuadrature(0.15, near=7, far=3))
    dyn.set_initial(velocity=lambda x: C + x[:, :2] @ RIGID.T)
    dt = dyn.stable_time_step()
    res = dyn.run(40 * dt, dt)
    x = np.random.default_rng(1).uniform(0.02, 0.98, (200, 2))
    exact = C + x @ RIGID.T
    err = COMM.allreduce(float(np.abs(dyn.velocity_at(x) - exact).max()), op=MPI.MAX)
    dyn.destroy()
    assert err / np.abs(exact).max() <= 1e-12
    assert res.energy_drift <= 1e-12


@pytest.mark.parametrize("crack", [EDGE, COUPLED_KINKED])
def test_dense_zone_everywhere_is_the_uniform_rule(crack):
    """A radius covering every cell gives cut_cell_quadrature's points and weights of degree
    ``near`` bit for bit (and with degree 5 far, the rule of degree 5 where nothing is near);
    a small radius changes only the cells near the tips."""
    msh = square(10)
    cells = owned(msh)
    c = mf.Crack(crack)
    for near, far in ((7, 3), (5, 2)):
        q = mf.AdaptiveQuadrature(10.0, near=near, far=far).rule(msh, cells, [c])
        ref = cut_cell_quadrature(msh, cells, [c], near)
        for a, b in ((q.points, ref.points), (q.weights, ref.weights), (q.cells, ref.cells)):
            assert np.array_equal(a, b)
    small = mf.AdaptiveQuadrature(0.12, near=7, far=3)
    q = small.rule(msh, cells, [c])
    near_mask = small.near_cells(msh, cells, [c])
    coarse = cut_cell_quadrature(msh, cells, [c], 3)
    dense = cut_cell_quadrature(msh, cells, [c], 7)
    for cell, is_near in zip(cells, near_mask, strict=True):
        ref = dense if is_near else coarse
        assert np.array_equal(q.points[q.cells == cell], ref.points[ref.cells == cell])
        assert np.array_equal(q.weights[q.cells == cell], ref.weights[ref.cells == cell])
    # the weights still sum to the area (to round-off)
    total = COMM.allreduce(float(q.weights.sum()))
    assert total == pytest.approx(1.0, abs=1e-13)


def test_near_tip_cells_follow_the_tips():
    """The dense zone is the cells whose bounding box reaches into the disc around each tip (a
    brute-force check on sampled points of each cell); a crack's mouth on the boundary is not
    a tip once placed."""
    msh = square(10)
    cells = owned(msh)
    c = mf.Crack(EDGE)
    P = mf.ParticleSet.from_cells(msh, 0.1)
    place_crack(c, CrackDomain.from_particles(P))
    assert c.is_tip == [False, True]
    mask = near_tip_cells(msh, cells, [c], 0.15)
    nodes = msh.geometry.x[_compat.geometry_dofmap(msh)[cells], :2]
    s = np.linspace(0.0, 1.0, 41)
    lo, hi = nodes.min(axis=1), nodes.max(axis=1)
    grid = lo[:, None, :] + (hi - lo)[:, None, :] * np.stack(np.meshgrid(s, s), -1).reshape(
        1, -1, 2
    )
    dist = np.linalg.norm(grid - np.array(EDGE[1]), axis=2).min(axis=1)
    assert np.array_equal(mask, dist <= 0.15 + 1e-12)
    assert mask.sum() >= 1 and not near_tip_cells(msh, cells, [c], 0.15)[dist > 0.2].any()


def _lowest_nonrigid(msh, cracks, q, dilation):
    P = mf.ParticleSet.from_cells(msh, 1.0 / 8)
    mls = mf.MLS(P, weight="quartic", dilation=dilation)
    if cracks:
        place_crack(cracks[0], CrackDomain.from_particles(P))
        attach_cracks(mls, cracks, "diffraction")
    K = particle_stiffness(P, mls, MAT, 7, quadrature=q)[0].toarray()
    ev = np.linalg.eigvalsh(K)
    return ev / ev.max()


@pytest.mark.skipif(COMM.size > 1, reason="a dense eigenvalue problem of the serial stiffness")
@pytest.mark.parametrize(
    ("cracked", "dilation"), [(False, 1.5), (False, 2.0), (False, 3.0), (True, 2.0), (True, 3.0)]
)
def test_coarse_rule_has_no_spurious_zero_energy_modes(cracked, dilation):
    """Free EFG stiffness on 8 x 8 cells: with the coarse rule everywhere (far = 2 and 3, 2 x 2
    Gauss) exactly three rigid modes (|lambda| < 1e-10 lambda_max) and the lowest non-rigid
    eigenvalue within 0.5x - 2x of the 4 x 4 rule's (measured 0.94 - 1.44); one point per cell
    (degree 1, refused by AdaptiveQuadrature) has near-zero modes on the uncracked body (its
    lowest non-rigid eigenvalue 7e-6, 1.5e-5 and 6.3e-4 of the 4 x 4 rule's at dilations 2,
    1.5, 3; checked <= 1.3e-3, 2x the largest): 2 x 2 is the safe minimum."""
    msh = square(8)
    cells = owned(msh)

    def cracks():
        return [mf.Crack(EDGE)] if cracked else []

    def rule(degree):
        cs = cracks()
        return cs, (cut_cell_quadrature(msh, cells, cs, degree) if cs else
                    cell_quadrature(msh, degree, cells))  # fmt: skip

    ref = _lowest_nonrigid(msh, *rule(7), dilation)
    for far in (2, 3):
        cs = cracks()
        q = mf.AdaptiveQuadrature(1e-9, near=7, far=far).rule(msh, cells, cs)
        rel = _lowest_nonrigid(msh, cs, q, dilation)
        assert (np.abs(rel) < 1e-10).sum() == 3
        assert 0.5 <= rel[3] / ref[3] <= 2.0
    if not cracked:
        rel = _lowest_nonrigid(msh, *rule(1), dilation)
        assert rel[3] / ref[3] <= 1.3e-3


def test_coarse_rule_is_stable_over_many_steps():
    """EFG with the coarse rule everywhere but the tip (far = 2 x 2), a random initial velocity
    (every mode excited), 2000 steps at the stable step: the discrete energy is conserved
    (measured drift 3.0e-15, check 1e-10) and the kinetic energy never exceeds the initial total
    (a growing mode would; measured max KE / E_0 = 1.0 at 101 energy records, check 1.5)."""
    _, dyn = model("efg", EDGE, mf.AdaptiveQuadrature(0.12, near=7, far=3), n=8)
    rng = np.random.default_rng(3)
    dyn.set_initial(velocity=lambda x: rng.standard_normal((len(x), 2)) * 1e-3)
    dt = dyn.stable_time_step()
    res = dyn.run(2000 * dt, dt)
    dyn.destroy()
    e0 = res.energies[0].kinetic + res.energies[0].internal
    kmax = max(r.kinetic for r in res.energies)
    assert res.energy_drift <= 1e-10
    assert kmax <= 1.5 * e0


def test_changed_cells_are_the_cells_whose_rule_changes():
    """After a crack grows by one segment, ``changed_cells`` is exactly the set of cells whose
    points or weights differ between the rules of the two states (compared cell by cell), with
    the adaptive rule and with the uniform one (cut cells only)."""
    msh = square(12)
    cells = owned(msh)
    old = mf.Crack([[0.0, 0.52], [0.4, 0.52]])
    new = mf.Crack([[0.0, 0.52], [0.4, 0.52], [0.52, 0.63]])
    for aq in (mf.AdaptiveQuadrature(0.15), None):

        def rule(c, aq=aq):
            return aq.rule(msh, cells, [c]) if aq else cut_cell_quadrature(msh, cells, [c], 7)

        qo, qn = rule(old), rule(new)
        differ = [
            c
            for c in cells
            if not (
                np.array_equal(qo.points[qo.cells == c], qn.points[qn.cells == c])
                and np.array_equal(qo.weights[qo.cells == c], qn.weights[qn.cells == c])
            )
        ]
        got = changed_cells(msh, cells, [old], [new], aq)
        assert np.array_equal(got, np.array(differ, dtype=got.dtype))
        # some cell changes (on some rank: a partition may leave a rank none)
        assert COMM.allreduce(got.size, op=MPI.SUM) > 0


def _sifs(quadrature, dt=None, comm=COMM):
    """K_I, K_II (two domains) of an edge crack under a suddenly applied tension on the top and
    bottom edges after 60 steps of ``dt`` (default half the stable step), pure EFG, 20 x 20
    cells; and ``dt``."""
    msh = square(20, comm)
    P = mf.ParticleSet.from_cells(msh, 0.05)
    crack = mf.Crack([[0.0, 0.5 + 1e-3], [0.5, 0.5 + 1e-3]])
    dyn = mf.ExplicitDynamics.efg(P, MAT, cracks=[crack], quadrature=quadrature)
    edges = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 1.0) | np.isclose(x[1], 0.0))
    dyn.add_traction(edges, lambda x, n: n * 1.0)
    dt = 0.5 * dyn.stable_time_step() if dt is None else dt
    dyn.run(60 * dt, dt)
    k = dyn.stress_intensity_factors(crack, tip=-1, radius=(0.1, 0.15))
    dyn.destroy()
    return np.concatenate([k.K_I, k.K_II]), dt


def test_sifs_adaptive_against_uniform():
    """Dynamic K_I of the edge crack after 60 equal steps with the adaptive rule (radius 0.3 =
    6 spacings, far 2 x 2) against the uniform 4 x 4 rule, both SIF domains: measured 1.27e-3
    and 1.36e-3 relative (check 3e-3); K_II (zero by symmetry up to the crack's 1e-3 offset)
    differs by 1.2e-4 of K_I (check 2.5e-4). Serial = 2 ranks to 1e-10 relative."""
    k_u, dt = _sifs(None)
    aq = mf.AdaptiveQuadrature(0.3, near=7, far=3)
    k_a, _ = _sifs(aq, dt)
    scale = np.abs(k_u[:2])
    assert (np.abs(k_a[:2] - k_u[:2]) <= 3e-3 * scale).all()
    assert (np.abs(k_a[2:] - k_u[2:]) <= 2.5e-4 * scale).all()
    if COMM.size > 1:
        k_s, _ = _sifs(aq, dt, MPI.COMM_SELF)
        assert np.abs(k_s - k_a).max() <= 1e-10 * scale.max()


def test_bad_input():
    with pytest.raises(ValueError, match="radius should be a finite length > 0, got -1"):
        mf.AdaptiveQuadrature(-1.0)
    with pytest.raises(ValueError, match="radius should be a finite length > 0, got nan"):
        mf.AdaptiveQuadrature(float("nan"))
    with pytest.raises(ValueError, match="radius should be a length > 0, got '1'"):
        mf.AdaptiveQuadrature("1")
    with pytest.raises(ValueError, match="far=1 under-integrates"):
        mf.AdaptiveQuadrature(0.1, far=1)
    with pytest.raises(ValueError, match="far=7 is above near=3"):
        mf.AdaptiveQuadrature(0.1, near=3, far=7)
    with pytest.raises(ValueError, match=r"near should be an integer >= 1, got 2\.5"):
        mf.AdaptiveQuadrature(0.1, near=2.5)
    msh = square(4)
    P = mf.ParticleSet.from_cells(msh, 0.25)
    with pytest.raises(ValueError, match="quadrature=7: give an AdaptiveQuadrature"):
        mf.ExplicitDynamics.efg(P, MAT, quadrature=7)
    with pytest.raises(ValueError, match="adaptive rule is a cell rule"):
        mf.ExplicitDynamics.efg(
            P, MAT, quadrature=mf.AdaptiveQuadrature(0.1), integration="stress-points"
        )
    with pytest.raises(ValueError, match="quadrature='dense': give an AdaptiveQuadrature"):
        mf.ParticlePatch(msh, owned(msh), 0.25, quadrature="dense")


# --- statics: comes free (EFGElasticity(quadrature=), ParticlePatch(quadrature=)) ------------
UNIAXIAL = np.array([[1.0 / MAT.E, 0.0], [0.0, -MAT.nu / MAT.E]])  # sigma_xx = 1 only


def _static_error(consistent, coupling=None):
    """The linear field of sigma_xx = 1 (exact for a crack along x: its faces stay free), held
    on the left and right edges, on a cracked body with the adaptive rule (radius 0.15, 2 x 2
    elsewhere); max error at 400 points."""
    msh = square(10)
    aq = mf.AdaptiveQuadrature(0.15, near=7, far=3)
    exact = lambda x: C + np.asarray(x)[:, :2] @ UNIAXIAL.T  # noqa: E731
    sides = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0))
    x = np.random.default_rng(1).uniform(0.0, 1.0, (400, 2))
    if coupling is None:
        P = mf.ParticleSet.from_cells(msh, 0.1)
        prob = mf.EFGElasticity(
            P, MAT, dilation=2.5, consistent=consistent, cracks=[mf.Crack(EDGE)], quadrature=aq
        )
        prob.add_dirichlet(sides, exact)
        u = prob.solve().evaluate(x)[0]
    else:
        import ufl

        V = _compat.vector_function_space(msh)
        u_, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        a = ufl.inner(MAT.ufl_stress(u_), ufl.sym(ufl.grad(v))) * ufl.dx
        L = ufl.dot(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.dx
        g = dolfinx.fem.Function(V)
        g.interpolate(lambda y: exact(y[:2].T).T)
        bcs = [dolfinx.fem.dirichletbc(g, dolfinx.fem.locate_dofs_topological(V, 1, sides))]
        mid = msh.geometry.x[_compat.geometry_dofmap(msh)[owned(msh)], :2].mean(axis=1)
        cells = np.flatnonzero((np.abs(mid - 0.5) < 0.4).all(axis=1))
        crack = mf.Crack([[0.35, 0.52], [0.65, 0.52]])
        patch = mf.ParticlePatch(msh, cells, 0.1, cracks=[crack], quadrature=aq)
        sol = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, coupling=coupling).solve()
        u = sol.displacement(x)
    return COMM.allreduce(float(np.abs(u - exact(x)).max()), op=MPI.MAX)


@pytest.mark.parametrize("coupling", [None, "lagrange", "bridging"])
def test_static_patch_test_with_adaptive_rule(coupling):
    """VCI makes the linear patch test exact whatever the rule: with the adaptive rule (2 x 2
    away from the tips) the cracked body reproduces the linear field to round-off (measured
    9e-16 efg, 9e-15 lagrange and bridging; check 1e-10, the uniform rule's test's); plain
    Gauss (EFG, no VCI) misses it (measured 1.2e-6; the uniform rule 1.6e-6): the check can
    fail."""
    assert _static_error(True, coupling) <= 1e-10
    if coupling is None:
        assert _static_error(False) > 1e-7
