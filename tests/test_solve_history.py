"""A model with a law with state continues from its last ``solve()`` (a load sweep).

DOLFINx users load a plastic or softening model in a loop: set a ``Constant`` (or the value a
callable reads), solve, record, again. Before, every ``solve()`` started from the virgin state, so
a strip loaded past yield and unloaded came back to zero strain, silently
(:mod:`dolfinx_meshfree.statics.history`).

The oracle is the closed form of a strip of J2 plasticity with linear hardening ``H`` in uniaxial
stress (plane stress, rollers on two edges, so the stress is uniaxial and uniform): loaded to
``s > sigma_y`` from the virgin state the strain is ``s / E + (s - sigma_y) / H``; unloading is
elastic (slope ``E``) down to ``-(sigma_y + H alpha)``; past it, in compression, ``alpha`` grows
again. Each solve is one load step (radial return is exact for this path), so every figure is
exact to Newton's tolerance: measured 3e-14 relative at most, checked at 1e-9. Softening
laws (damage, cohesive faces) unloaded from their softening branch go back along their secant,
also exact (measured below 1e-12).

Serial and 2 ranks.
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import pytest
import test_cohesive as tc
import ufl
from mpi4py import MPI
from petsc4py import PETSc

pytestmark = pytest.mark.filterwarnings("ignore::dolfinx_meshfree.PartitionImbalanceWarning")

E, NU, SY, H = 200e3, 0.3, 250.0, 20e3
LX, LY = 4.0, 1.0
TOL = 1e-9


def _strain_after(loads: list[float]) -> list[float]:
    """The closed-form axial strain after each stress of a uniaxial sweep (tension positive)."""
    eps_p, alpha, out = 0.0, 0.0, []
    for s in loads:
        over = abs(s) - (SY + H * alpha)
        if over > 0.0:  # yields in the direction of s
            d = over / H
            alpha += d
            eps_p += np.sign(s) * d
        out.append(s / E + eps_p)
    return out


SWEEP = [1.2 * SY, 0.6 * SY, 0.0, 1.2 * SY, 1.3 * SY]


def _mesh(cell: str = "quadrilateral"):
    return dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [LX, LY]], [8, 2], getattr(dolfinx.mesh.CellType, cell)
    )


def _rollers(model, msh) -> None:
    """x held at x = 0, y held at y = 0: uniaxial stress along x."""
    model.add_dirichlet(
        mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0)), np.zeros_like, components=(0,)
    )
    model.add_dirichlet(
        mf.boundary_facets(msh, lambda p: np.isclose(p[1], 0.0)), np.zeros_like, components=(1,)
    )


def _model(method: str, msh):
    law = mf.J2Plasticity(E=E, nu=NU, sigma_y=SY, H=H, plane="stress")
    if method == "fe":
        return mf.FEElasticity(_compat.vector_function_space(msh), law)
    if method == "efg":
        particles = mf.ParticleSet.from_cells(msh, spacing=0.25)
        return mf.EFGElasticity(particles, law)
    cells = dolfinx.mesh.locate_entities(msh, 2, lambda p: (p[0] > 1.0 - 1e-9) & (p[0] < 3 + 1e-9))
    patch = mf.ParticlePatch(msh, cells, spacing=0.25)
    return mf.CoupledElasticity(_compat.vector_function_space(msh), patch, law, coupling=method)


@pytest.mark.parametrize("method", ["fe", "efg", "lagrange", "bridging", "ramp"])
def test_a_traction_sweep_follows_the_path(method):
    """Load past yield, unload (in steps), reload and load further, one ``solve()`` each: the
    end's strain is the closed form's at every stop, the permanent strain included (before:
    0 after unloading, the virgin response). Unloading takes one Newton iteration a step (the
    elastic predictor; with the elastoplastic tangent of the yield surface it took 4)."""
    msh = _mesh()
    model = _model(method, msh)
    _rollers(model, msh)
    stress = [0.0]
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], LX))
    model.add_traction(right, lambda p, n: np.tile([stress[0], 0.0], (len(p), 1)))
    expected = _strain_after(SWEEP)
    for k, (s, eps) in enumerate(zip(SWEEP, expected, strict=True)):
        stress[0] = s
        sol = model.solve(load_steps=3 if s < 0.7 * SY else 1)
        u = sol.displacement(np.array([[LX, 0.5], [0.5 * LX, 0.25]]))
        assert u[0, 0] / LX == pytest.approx(eps, rel=TOL, abs=TOL * SY / E)
        assert u[1, 0] / (0.5 * LX) == pytest.approx(eps, rel=TOL, abs=TOL * SY / E)
        if k and s < SWEEP[k - 1]:  # unloading is elastic: the elastic predictor lands on it
            assert max(step.iterations for step in sol.newton.steps) <= 1
    assert expected[2] == pytest.approx(0.2 * SY / H)  # the permanent strain: 2.5e-3
    model.reset()  # from the virgin state again: elastic below yield
    stress[0] = 0.6 * SY
    u = model.solve().displacement(np.array([[LX, 0.5]]))
    assert u[0, 0] / LX == pytest.approx(0.6 * SY / E, rel=TOL)


def test_a_user_form_sweep_by_a_constant():
    """The FEniCSx pattern: ``CoupledLinearProblem`` with J2, the traction a ``Constant`` set
    between solves (each in two load steps): load, unload to zero (the permanent strain 2.5e-3),
    reload."""
    msh = _mesh("triangle")
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    law = mf.J2Plasticity(E=E, nu=NU, sigma_y=SY, H=H, plane="stress")
    lmb, mu = E * NU / (1 - NU**2), E / (2 * (1 + NU))

    def eps(w):
        return ufl.sym(ufl.grad(w))

    a = ufl.inner(lmb * ufl.tr(eps(u)) * ufl.Identity(2) + 2 * mu * eps(u), eps(v)) * ufl.dx
    fdim = 1
    facets = {
        k: dolfinx.mesh.locate_entities_boundary(msh, fdim, f)
        for k, f in {
            "left": lambda p: np.isclose(p[0], 0.0),
            "bottom": lambda p: np.isclose(p[1], 0.0),
            "right": lambda p: np.isclose(p[0], LX),
        }.items()
    }
    tags = dolfinx.mesh.meshtags(
        msh, fdim, facets["right"], np.full(len(facets["right"]), 1, dtype=np.int32)
    )
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    t = dolfinx.fem.Constant(msh, PETSc.ScalarType((0.0, 0.0)))
    L = ufl.dot(t, v) * ds(1)
    bcs = [
        dolfinx.fem.dirichletbc(
            PETSc.ScalarType(0.0),
            dolfinx.fem.locate_dofs_topological(V.sub(i), fdim, facets[name]),
            V.sub(i),
        )
        for i, name in ((0, "left"), (1, "bottom"))
    ]
    cells = dolfinx.mesh.locate_entities(msh, 2, lambda p: (p[0] > 1.0 - 1e-9) & (p[0] < 3 + 1e-9))
    patch = mf.ParticlePatch(msh, cells, spacing=0.25)
    problem = mf.CoupledLinearProblem(a, L, bcs, patch, material=law, coupling="lagrange")
    sweep = [1.2 * SY, 0.0, 1.2 * SY]
    for s, strain in zip(sweep, _strain_after(sweep), strict=True):
        t.value[:] = (s, 0.0)
        end = problem.solve(load_steps=2).displacement(np.array([[LX, 0.5]]))
        assert end[0, 0] / LX == pytest.approx(strain, rel=TOL, abs=TOL * SY / E)
    problem.reset()
    t.value[:] = (0.0, 0.0)
    assert problem.solve().displacement(np.array([[LX, 0.5]]))[0, 0] == pytest.approx(0, abs=1e-14)


def test_a_prescribed_displacement_sweep():
    """Displacement control by the held values: pull to a strain of 4e-3, back to the permanent
    strain 2.5e-3 (the stress back to zero, ``alpha`` kept), then to 0 (reversed yield:
    ``alpha`` grows by 1e-3 / 1.1), pure FE; the virgin start would give ``alpha`` 1.136e-3 at
    the second stop."""
    msh = _mesh()
    law = mf.J2Plasticity(E=E, nu=NU, sigma_y=SY, H=H, plane="stress")
    model = mf.FEElasticity(_compat.vector_function_space(msh), law)
    _rollers(model, msh)
    end = [0.0]
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], LX))
    model.add_dirichlet(right, lambda p: np.tile([end[0], 0.0], (len(p), 1)), components=(0,))
    alpha = []
    for strain in (4e-3, 2.5e-3, 0.0):
        end[0] = strain * LX
        (state,) = model.solve().states
        a = state.committed["alpha"]
        assert a.size == 0 or np.ptp(a) < 1e-12  # uniform
        alpha.append(MPI.COMM_WORLD.allreduce(float(a.max()) if a.size else 0.0, op=MPI.MAX))
    assert alpha[0] == pytest.approx(2.5e-3, rel=TOL)
    assert alpha[1] == pytest.approx(2.5e-3, rel=TOL)  # unloading is elastic
    assert alpha[2] == pytest.approx(2.5e-3 + 1e-3 / 1.1, rel=TOL)


def test_a_path_and_solve_continue_each_other():
    """``follow_path`` ends where ``solve()`` continues: the strip pulled to a strain of 4e-3
    by indirect displacement control (load factor 1.2 of a reference ``sigma_y``), then
    unloaded by ``solve()`` keeps the permanent strain 2.5e-3. A path cannot continue an
    inelastic ``solve()`` (it starts unloaded): refused, until ``reset()``."""
    msh = _mesh()
    model = _model("fe", msh)
    _rollers(model, msh)
    stress = [SY]
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], LX))
    model.add_traction(right, lambda p, n: np.tile([stress[0], 0.0], (len(p), 1)))
    control = mf.DisplacementControl([[LX, 0.5]], [[1.0, 0.0]])
    path = mf.follow_path(model, control, mf.PathOptions(2e-3, 4e-3 * LX))
    assert path.load_factor[-1] == pytest.approx(1.2, rel=TOL)
    stress[0] = 0.0
    u = model.solve().displacement(np.array([[LX, 0.5]]))
    assert u[0, 0] / LX == pytest.approx(0.2 * SY / H, rel=TOL)
    with pytest.raises(ValueError, match=r"follow_path: this FEElasticity yielded.*model.reset"):
        mf.follow_path(model, control, mf.PathOptions(2e-3, 4e-3 * LX))
    model.reset()
    stress[0] = SY
    path = mf.follow_path(model, control, mf.PathOptions(2e-3, 4e-3 * LX))
    assert path.load_factor[-1] == pytest.approx(1.2, rel=TOL)


def test_a_changed_model_is_refused():
    """A condition added after a solve changes the held dofs: the history does not fit the
    model any more, refused by name; ``reset()`` starts again."""
    msh = _mesh()
    model = _model("fe", msh)
    _rollers(model, msh)
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], LX))
    model.add_traction(right, lambda p, n: np.tile([0.5 * SY, 0.0], (len(p), 1)))
    model.solve()
    top = mf.boundary_facets(msh, lambda p: np.isclose(p[1], LY))
    model.add_dirichlet(top, np.zeros_like, components=(1,))
    with pytest.raises(ValueError, match=r"changed its held dofs .* model.reset\(\)"):
        model.solve()
    model.reset()
    u = model.solve().displacement(np.array([[LX, 0.5]]))
    # the top held in y too: plane strain in the plane (eps_yy = 0), elastic
    assert u[0, 0] == pytest.approx((1 - NU**2) * 0.5 * SY / E * LX, rel=TOL)


@pytest.mark.parametrize("method", ["efg", "lagrange"])
def test_cohesive_faces_unload_along_their_secant(method):
    """Cohesive faces remember their largest opening: a bar split by a cohesive crack, pulled
    past its peak by ``follow_path`` and then loaded by ``solve()`` to half the stress it ended
    at, unloads along the secant to the origin, as the bulk does: the end moves back to half its
    displacement exactly (measured below 1e-12 relative, checked 1e-9). Newton's first
    iteration takes the faces' tangent of unloading: with the loading one it found the
    equilibrium further down the softening branch, 1.28 times the end's displacement; from the
    virgin state (before) the faces were bonded, a sixth of it."""
    crack = mf.Crack([[tc.L / 2, 0.0], [tc.L / 2, tc.H]], through=True)
    model, msh = tc._bar(method, crack)
    law = mf.LinearCohesive(ft=tc.FT, Gf=tc.GF)
    model.add_cohesive(crack, law)
    scale = [1.0]  # a second traction, scale - 1: none along the path (its reference load 1)
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], tc.L))
    model.add_traction(right, lambda x, n: np.tile([scale[0] - 1.0, 0.0], (len(x), 1)))
    path = tc._follow(model, end=0.04, steps=40)
    sigma, u_end = path.load_factor[-1], path.control[-1]
    assert sigma < 0.9 * tc.FT  # past the peak, softening
    scale[0] = 0.5 * sigma  # the two tractions now add up to half the stress of the end
    u = model.solve(load_steps=2).displacement(np.array([[tc.L, tc.H / 2]]))[0, 0]
    assert u == pytest.approx(0.5 * u_end, rel=TOL)


@pytest.mark.parametrize("method", ["fe", "lagrange"])
def test_a_damaged_bar_unloads_along_its_secant(method):
    """Damage (crack band) remembers its largest strain: a bar pulled past its peak by
    ``follow_path`` and then loaded by ``solve()`` to 0.4 of the stress it ended at unloads
    every point along its secant to the origin: the end moves back to 0.4 of its displacement
    exactly (measured below 1.1e-12 relative, checked 1e-9). Newton's first iteration takes the
    tangent of unloading: with the loading one it went on softening (on a bar of uniform
    section, to 2.1 (FE) and 6.3 (lagrange) times the end's displacement).

    The bar has a waist 1e-3 thinner at x = 1.5, where it localises. Of uniform section every
    point reaches f_t at once, a bifurcation that round-off decides: FE followed the branch on
    which the whole bar softens, and lagrange's Newton failed at the second step on one machine
    (it had passed on another)."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [2.0, 1.0]], [8, 4], dolfinx.mesh.CellType.quadrilateral
    )
    x = msh.geometry.x
    x[:, 1] *= 1.0 - 1e-3 * np.isclose(x[:, 0], 1.5)  # the waist
    law = mf.RankineDamage(E=1000.0, nu=0.0, ft=1.0, Gf=0.02, plane="stress")
    V = _compat.vector_function_space(msh)
    if method == "fe":
        model = mf.FEElasticity(V, law)
    else:
        cells = dolfinx.mesh.locate_entities(msh, 2, lambda p: p[0] > 1.0 - 1e-9)
        model = mf.CoupledElasticity(V, mf.ParticlePatch(msh, cells, placement="vertices"), law)
    model.add_dirichlet(mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0)), np.zeros_like)
    scale = [1.0]
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 2.0))
    model.add_traction(right, lambda x, n: np.tile([scale[0], 0.0], (len(x), 1)))
    control = mf.DisplacementControl([[2.0, 0.5]], [[1.0, 0.0]])
    path = mf.follow_path(model, control, mf.PathOptions(2e-3, 0.05, max_increment=1e-2))
    sigma, u_end = path.load_factor[-1], path.control[-1]
    assert sigma < 0.8  # past the peak (f_t = 1)
    scale[0] = 0.4 * sigma
    u = model.solve().displacement(np.array([[2.0, 0.5]]))[0, 0]
    assert u == pytest.approx(0.4 * u_end, rel=TOL)


@pytest.mark.parametrize("method", ["fe", "lagrange"])
def test_a_hyperelastic_sweep_steps_from_the_last_load(method):
    """``FENonlinearProblem`` and ``CoupledNonlinearProblem`` (neo-Hookean, a cantilever bent
    to a tip deflection of about a third of its length): a second ``solve()`` steps the load
    from the last solve's, not from zero. Solved again unchanged, each of its three steps is
    already in equilibrium: 1, 0 and 0 Newton iterations (checked at most 1; before, the steps
    went from a third of the load, unbending and bending the beam again: 7, 5 and 5); raised by
    a quarter in two steps, it lands where a fresh problem solved at the new load in six steps
    does (checked 1e-8 of the deflection)."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [LX, LY]], [16, 4], dolfinx.mesh.CellType.quadrilateral
    )
    law = mf.NeoHookean(E=100.0, nu=0.3, plane="strain")
    cells = dolfinx.mesh.locate_entities(msh, 2, lambda p: (p[0] > 1.0 - 1e-9) & (p[0] < 3 + 1e-9))
    patch = mf.ParticlePatch(msh, cells, spacing=0.25)
    tip = np.array([[LX, 0.5]])

    def build(load_steps: int):
        V = _compat.vector_function_space(msh)
        u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
        right = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda p: np.isclose(p[0], LX))
        tags = dolfinx.mesh.meshtags(msh, 1, right, np.full(len(right), 1, dtype=np.int32))
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        t = dolfinx.fem.Constant(msh, PETSc.ScalarType((0.0, -0.6)))
        F = ufl.inner(law.ufl_first_piola(ufl.Identity(2) + ufl.grad(u)), ufl.grad(v)) * ufl.dx
        F -= ufl.dot(t, v) * ds(1)
        left = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda p: np.isclose(p[0], 0.0))
        zero = np.zeros(2, dtype=PETSc.ScalarType)
        bcs = [dolfinx.fem.dirichletbc(zero, dolfinx.fem.locate_dofs_topological(V, 1, left), V)]
        if method == "fe":
            problem = mf.FENonlinearProblem(F, u, bcs, load_steps=load_steps)

            def deflection():
                return mf.evaluate_fe_function(u, tip)[0, 1]
        else:
            problem = mf.CoupledNonlinearProblem(F, u, bcs, patch, law, load_steps=load_steps)

            def deflection():
                return problem.solution.displacement(tip)[0, 1]

        return problem, t, deflection

    problem, t, deflection = build(3)
    problem.solve()
    first = deflection()
    assert first < -0.25 * LX
    again = problem.solve()
    assert len(again.steps) == 3 and max(s.iterations for s in again.steps) <= 1
    assert deflection() == pytest.approx(first, rel=1e-8)
    t.value[:] = (0.0, -0.75)
    problem.load_steps = 2
    problem.solve()
    fresh, t_fresh, fresh_deflection = build(6)
    t_fresh.value[:] = (0.0, -0.75)
    fresh.solve()
    assert deflection() == pytest.approx(fresh_deflection(), rel=1e-8)


def test_a_path_that_grew_its_patch_goes_on_on_its_model():
    """``follow_path(..., adapt=...)`` rebuilds the model on the grown patch: a ``solve()``
    continues from the path's end on ``path.model`` (the strip unloaded keeps its plastic
    strain, ``u - t / E`` at the end, within 1e-9), and the model the path started from refuses
    to solve (it would start unloaded on the old patch) until ``reset()``."""
    msh = _mesh()
    model = _model("lagrange", msh)  # patch 1 <= x <= 3
    _rollers(model, msh)
    scale = [1.0]
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], LX))
    model.add_traction(right, lambda p, n: np.tile([scale[0], 0.0], (len(p), 1)))
    control = mf.DisplacementControl([[LX, 0.5]], [[1.0, 0.0]])
    grow = mf.StateAbove("alpha", 1e-4, where=lambda x: x[:, 0] > 3.0)
    path = mf.follow_path(model, control, mf.PathOptions(2e-3, 4e-3 * LX), adapt=grow)
    assert len(path.patch_events) == 1 and path.model is not model
    t, u_end = path.load_factor[-1], path.control[-1]
    scale[0] = 0.0
    u = path.model.solve().displacement(np.array([[LX, 0.5]]))[0, 0]
    assert u == pytest.approx(u_end - t / E * LX, rel=TOL)
    assert u == pytest.approx(0.2 * SY / H * LX, rel=1e-6)  # t = 1.2 sigma_y (the path's tol)
    with pytest.raises(ValueError, match=r"follow_path grew this model's patch.*path\.model"):
        model.solve()
    model.reset()
    assert model.solve().displacement(np.array([[LX, 0.5]]))[0, 0] == pytest.approx(0, abs=1e-15)


@pytest.mark.parametrize("method", ["fe", "efg", "ramp"])
def test_the_plastic_zone_as_a_field(method):
    """``mf.state_field(solution, "alpha")``: a static solution's state as a DG0 function, for
    ``XDMFFile``. The strip loaded to 1.2 sigma_y and unloaded has ``alpha = 0.2 sigma_y / H``
    at every point, so every cell, FE, patch or interface, holds it (checked 1e-9); the field
    is made of the solution's states, owned cells and ghosts alike. Vector state variables,
    unknown names and a law without state are refused by name."""
    msh = _mesh()
    model = _model(method, msh)
    _rollers(model, msh)
    stress = [1.2 * SY]
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], LX))
    model.add_traction(right, lambda p, n: np.tile([stress[0], 0.0], (len(p), 1)))
    model.solve()
    stress[0] = 0.0
    solution = model.solve()
    alpha = mf.state_field(solution, "alpha")
    assert alpha.name == "alpha"
    assert np.allclose(alpha.x.array, 0.2 * SY / H, rtol=TOL, atol=0.0)
    mean = mf.state_field(solution, "dissipation", reduce="mean")
    assert np.allclose(mean.x.array, SY * 0.2 * SY / H, rtol=TOL, atol=0.0)  # sigma_y alpha
    with pytest.raises(ValueError, match=r"'plastic_strain' is not a scalar .* \['alpha'"):
        mf.state_field(solution, "plastic_strain")
    elastic = mf.FEElasticity(_compat.vector_function_space(msh), mf.LinearElastic(E, NU))
    with pytest.raises(ValueError, match="has no state at points"):
        mf.state_field(elastic_solution(elastic, msh), "alpha")


def elastic_solution(model, msh):
    """A linear-elastic FE solution (no state) of the strip."""
    _rollers(model, msh)
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], LX))
    model.add_traction(right, lambda p, n: np.tile([1.0, 0.0], (len(p), 1)))
    return model.solve()
