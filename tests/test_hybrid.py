"""The hybrid SPH-FE coupling (Rabczuk et al. 2006, sec. 5.5; Sauer 2000): the corrected SPH
sums, the linear patch test, energy, HA-S against HA-F on a smooth wave, convergence on the
cantilever, parallel = serial, bad input."""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.couplings.hybrid_sph import CorrectedSPH
from dolfinx_meshfree.dynamics import ExplicitDynamics, check_method
from dolfinx_meshfree.verification.waves import GaussianPulseRod

import numpy as np
import pytest
from conftest import BEAM_L, CELL_TYPES, beam_ends, beam_mesh, fitted_rate, load_demo, rectangle
from mpi4py import MPI
from petsc4py import PETSc

ROD = GaussianPulseRod()
STEEL = mf.LinearElastic(ROD.E, 0.0, "strain", rho=ROD.rho)
BEAM_MATERIAL = mf.LinearElastic(3e7, 0.3, "stress")
BEAM = mf.TimoshenkoBeam(BEAM_MATERIAL, L=48.0, D=12.0, P=1000.0)
GRAD = np.array([[1e-3, -0.5e-3], [0.7e-3, 0.2e-3]])  # a linear field's gradient


def linear(x: np.ndarray) -> np.ndarray:
    return np.array([0.3e-3, -0.1e-3]) + x[:, :2] @ GRAD.T


def beam_problem(comm, h, variant="HA-F", **options) -> mf.HybridElasticity:
    """The cantilever with the free-end half in particles (spacing h)."""
    msh = beam_mesh(comm, h)
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 0.5 * BEAM_L), h)
    V = _compat.vector_function_space(msh)
    return mf.HybridElasticity(V, patch, BEAM_MATERIAL, variant=variant, **options)


def rod_problem(comm, h, k, variant, **options) -> mf.HybridElasticity:
    """The rod of Rabczuk sec. 6.2.1, FE on x < 30, particles of spacing h / k on x > 30."""
    msh = rectangle(
        comm, [0, 0], [60, 5], [round(60 / h), round(5 / h)], CELL_TYPES["quadrilateral"]
    )
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 30.0), h / k)
    V = _compat.vector_function_space(msh)
    return mf.HybridElasticity(V, patch, STEEL, variant=variant, **options)


# --- the approximation ---------------------------------------------------------------------------


def test_corrected_sph_reproduces_linear_fields():
    """Values and corrected gradients of linear fields exact near the boundary of an irregular
    cloud (the Shepard values alone are not: their mean point xbar lags behind x)."""
    rng = np.random.default_rng(3)
    xs = np.linspace(0.0, 2.0, 11)
    pts = np.stack(np.meshgrid(xs, xs, indexing="ij"), -1).reshape(-1, 2)
    pts[(pts > 0).all(1) & (pts < 2).all(1)] += rng.uniform(-0.04, 0.04, (81, 2))
    sph = CorrectedSPH(pts, np.full(len(pts), 0.04), 0.2)
    x = np.vstack([rng.uniform(0, 2, (50, 2)), [[0, 0], [2, 1.3], [0.01, 2]]])
    t = sph.tabulate(x)
    f = linear(pts)
    assert np.abs(t.values @ f - linear(x)).max() < 1e-12
    assert np.abs(t.gradient(f) - GRAD).max() < 1e-12
    assert np.abs(t.values.sum(axis=1) - 1.0).max() < 1e-12


# --- the linear patch test -----------------------------------------------------------------------


def _vectors(ops, problem):
    """The linear field at the FE dofs (active) and at the particles, as PETSc vectors."""
    V, P = problem.V, problem.patch.particles
    n_owned = V.dofmap.index_map.size_local
    u_fe = ops.K_fe.createVecRight()
    u_fe.array[:] = linear(V.tabulate_dof_coordinates()[:n_owned]).ravel() * np.repeat(
        ops.fe_active[:n_owned], 2
    )
    own = P.owned[np.argsort(P.petsc_index[P.owned], kind="stable")]
    u_p = ops.K_p.createVecRight()
    u_p.array[:] = linear(P.positions[own]).ravel()
    return u_fe, u_p


def patch_residual(problem) -> tuple[float, float, float]:
    """``max |K u - f|`` over the FE and the particle dofs for the linear field, with ``f`` the
    loads of its own traction ``sigma n`` on every exterior facet, and ``max |f|``."""
    ops = problem.operators()
    u_fe, u_p = _vectors(ops, problem)
    r_fe, r_p = ops.K_fe.createVecLeft(), ops.K_p.createVecLeft()
    ops.K_fe.mult(u_fe, r_fe)
    ops.K_fp.multAdd(u_p, r_fe, r_fe)
    ops.K_p.mult(u_p, r_p)
    ops.K_pf.multAdd(u_fe, r_p, r_p)
    sigma = problem.material.stress(GRAD)
    problem.add_traction(mf.boundary_facets(problem.V.mesh), lambda x, n: n @ sigma.T)
    b_fe, b_p = problem._loads()
    n_owned = problem.V.dofmap.index_map.size_local
    active = np.repeat(ops.fe_active[:n_owned], 2)
    r_fe.axpy(-1.0, b_fe)
    r_p.axpy(-1.0, b_p)
    comm = problem.comm
    fe = comm.allreduce(np.abs(r_fe.array_r * active).max(initial=0.0), op=MPI.MAX)
    p = comm.allreduce(np.abs(r_p.array_r).max(initial=0.0), op=MPI.MAX)
    scale = comm.allreduce(np.abs(b_p.array_r).max(initial=0.0), op=MPI.MAX)
    for obj in (u_fe, u_p, r_fe, r_p, b_fe, b_p):
        obj.destroy()
    ops.destroy()
    return fe, p, scale


@pytest.mark.parametrize("variant", mf.HYBRID_VARIANTS)
def test_linear_patch_test_with_consistent_integration(variant):
    """A linear field leaves no force but its boundary tractions' loads, at every FE node and
    particle, to round-off (measured 5e-15 relative, both variants, h = 3)."""
    fe, p, scale = patch_residual(beam_problem(MPI.COMM_WORLD, 3.0, variant))
    assert scale > 1e4
    assert fe < 1e-12 * scale and p < 1e-12 * scale


def test_linear_patch_test_without_consistency_is_missed_at_the_particles():
    """With the symmetric ``K`` (``consistent=False``) the corrected kernel gradients integrated
    on background cells (``integration="cells"``) leave forces near the exterior boundary:
    measured 0.43 / 0.29 (HA-F, FE / particles) and 0.29 at the particles with exact FE rows
    (HA-S) relative to the boundary loads at h = 3. HA-S's FE rows stay exact: the interface
    tractions of a constant stress are exact (eq. 131-134) and cancel the FE cells' own boundary
    term."""
    fe, p, scale = patch_residual(beam_problem(MPI.COMM_WORLD, 3.0, "HA-S", consistent=False))
    assert fe < 1e-12 * scale
    assert p > 0.1 * scale  # the measured miss, not a tolerance
    fe, p, scale = patch_residual(
        beam_problem(MPI.COMM_WORLD, 3.0, "HA-F", integration="cells", consistent=False)
    )
    assert fe > 0.1 * scale and p > 0.1 * scale


def test_rigid_motions_carry_no_force():
    """K of a rigid translation vanishes (every block, both variants)."""
    for variant in mf.HYBRID_VARIANTS:
        problem = beam_problem(MPI.COMM_WORLD, 3.0, variant)
        ops = problem.operators()
        u_fe, u_p = _vectors(ops, problem)
        n_owned = problem.V.dofmap.index_map.size_local
        u_fe.array[:] = np.tile([1.0, -2.0], n_owned) * np.repeat(ops.fe_active[:n_owned], 2)
        u_p.array[:] = np.tile([1.0, -2.0], u_p.getLocalSize() // 2)
        r = ops.K_fe.createVecLeft()
        ops.K_fe.mult(u_fe, r)
        ops.K_fp.multAdd(u_p, r, r)
        s = ops.K_p.createVecLeft()
        ops.K_p.mult(u_p, s)
        ops.K_pf.multAdd(u_fe, s, s)
        scale = BEAM_MATERIAL.E
        assert r.norm(PETSc.NormType.INFINITY) < 1e-9 * scale
        assert s.norm(PETSc.NormType.INFINITY) < 1e-9 * scale
        for obj in (u_fe, u_p, r, s):
            obj.destroy()
        ops.destroy()


# --- dynamics ------------------------------------------------------------------------------------


def run_rod(variant, consistent=False, t_end=2 * ROD.transit_time):
    problem = rod_problem(MPI.COMM_WORLD, 1.0, 2, variant, consistent=consistent)
    dyn = ExplicitDynamics.coupled(problem, particle_mass="volume")
    dyn.set_initial(velocity=ROD.initial_velocity, particle_values="nodal")
    errors = {}
    res = dyn.run(
        t_end,
        outputs=[ROD.transit_time],
        on_output=lambda d, n, t: errors.setdefault(t, d.velocity_error(ROD.velocity)),
    )
    return dyn, res, errors


def test_hybrid_dynamics_has_the_rods_mass():
    """``ExplicitDynamics.coupled`` of a hybrid problem has an FE and a particle field whose
    lumped masses add up to the rod's mass ``rho L H`` (FE cells' row sums plus ``rho V_I`` of
    the SPH particles, whose volumes tile the patch), to round-off; an unknown method name is
    refused with the list of the available ones."""
    problem = rod_problem(MPI.COMM_WORLD, 1.0, np.sqrt(3.0), "HA-F", integration="smoothed")
    dyn = ExplicitDynamics.coupled(problem, particle_mass="volume")
    assert [f.name for f in dyn.fields] == ["fe", "particles"]
    mass = sum(f.mass.sum() for f in dyn.fields) / 2  # two components per node
    assert abs(mass - ROD.rho * 60.0 * 5.0) < 1e-12 * ROD.rho * 300.0
    assert check_method("hybrid") == "hybrid"
    with pytest.raises(ValueError, match=r"method='hybrid-sph' is not available.*'hybrid'"):
        check_method("hybrid-sph")
    dyn.destroy()


def test_energy_is_conserved_without_load_ha_f():
    """HA-F with the symmetric K: the discrete energy of central differences is constant to
    round-off over two transits (measured 4e-14)."""
    dyn, res, _ = run_rod("HA-F")
    assert res.energy_drift < 1e-10
    assert res.energies[-1].kinetic > 0.1 * res.energies[0].kinetic
    dyn.destroy()


@pytest.mark.xfail(strict=True, reason="HA-S's K is not symmetric: measured drift 0.16")
def test_energy_is_conserved_without_load_ha_s():
    """HA-S loads the FE nodes with the particles' tractions, which are not the work conjugate
    of the kinematic coupling through the sums: ``K`` is not symmetric, and the discrete energy
    is not conserved (measured relative drift 0.16 over two transits, h = 1, 2 x 2 particles
    per cell); with the consistent (Petrov-Galerkin) integration HA-F is not symmetric either
    (0.18)."""
    dyn, res, _ = run_rod("HA-S")
    dyn.destroy()
    assert res.energy_drift < 1e-10


def smooth_wave(x: np.ndarray) -> np.ndarray:
    """A Gaussian displacement wave centred on the interface x = 30 (the hybrid zone)."""
    u = np.zeros((len(x), 2))
    u[:, 0] = 1e-3 * np.exp(-0.025 * (np.asarray(x)[:, 0] - 30.0) ** 2)
    return u


def acceleration_difference(h: float, k: int) -> float:
    """Relative L2 difference of the HA-S and HA-F accelerations of a smooth wave at rest (one
    step from rest: v(dt) = dt a, no time-integration error to grow). Both variants share one
    mesh and patch, so that their quadrature points are the same on every rank."""
    comm = MPI.COMM_WORLD
    msh = rectangle(
        comm, [0, 0], [60, 5], [round(60 / h), round(5 / h)], CELL_TYPES["quadrilateral"]
    )
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 30.0), h / k)
    V = _compat.vector_function_space(msh)
    fields = []
    for variant in mf.HYBRID_VARIANTS:
        problem = mf.HybridElasticity(
            V,
            patch,
            STEEL,
            variant=variant,
            integration="cells",
            consistent=False,
            particles="centred",
        )
        dyn = ExplicitDynamics.coupled(problem, particle_mass="volume")
        dyn.set_initial(displacement=smooth_wave, particle_values="nodal")
        dt = dyn.stable_time_step()
        dyn.run(dt, dt=dt)
        q, v = dyn.velocity_at_quadrature(5)
        fields.append(v / dt)
        dyn.destroy()
    sums = np.array(
        [
            np.sum(q.weights * np.sum((fields[0] - fields[1]) ** 2, 1)),
            np.sum(q.weights * np.sum(fields[1] ** 2, 1)),
        ]
    )
    sums = comm.allreduce(sums, op=MPI.SUM)
    return float(np.sqrt(sums[0] / sums[1]))


def test_ha_s_and_ha_f_agree_on_a_smooth_wave():
    """HA-S (tractions, eq. 131-134) and HA-F (interpolation, eq. 135) give the same forces on
    a smooth wave through the hybrid zone, closer under refinement: relative difference of the
    accelerations 5.2e-2, 3.6e-2 (h = 1, 0.5; Gauss integration of the particle energy for
    both), about h^0.5. With the patch's particle grid, which put particles on the interface
    nodes, the difference was 1.1e-2, 7.6e-3: HA-S's node stress (eq. 131) was then nearly the
    stress of the particle on the node; the centred particles lie half a spacing inside. Against
    the exact acceleration ``c^2 u''`` on 25 < x < 35 the centred particles are the closer for
    both variants (HA-F 6.7e-2 against 9.9e-2, HA-S 9.1e-2 against 0.10, h = 1). (The
    velocities after a transit were compared before, from local arrays of two separately built
    meshes, whose partitions differ: on 2 ranks that compared different points, 1.41.)"""
    coarse = acceleration_difference(1.0, 2)
    fine = acceleration_difference(0.5, 2)
    assert coarse < 0.1  # measured 5.2e-2
    assert fine < 0.8 * coarse  # measured 0.70


# --- statics: the cantilever ---------------------------------------------------------------------


def solve_beam(comm, h, variant, **options):
    problem = beam_problem(comm, h, variant, **options)
    left, right = beam_ends(problem.V.mesh)
    problem.add_dirichlet(left, BEAM.displacement)
    problem.add_traction(right, BEAM.traction)
    return problem, problem.solve()


@pytest.mark.parametrize(
    "variant, rate, finest",
    [("HA-F", (1.8, 2.3), 4e-3), ("HA-S", (1.3, 1.8), 4e-2)],
)
def test_cantilever_converges(variant, rate, finest):
    """Fitted L2 slope over h = 3, 1.5, 1 (Rabczuk et al. 2006, Table II: 1.23 / 1.23 / 1.13 for
    the hybrid coupling) at the default options: HA-F (centred particles, smoothed strains)
    measured 2.04, errors 1.8e-2, 4.3e-3, 1.9e-3; HA-S (the patch's particles, Gauss points,
    consistent test gradients) 1.55, errors 0.11, 3.6e-2, 1.9e-2 (before: HA-F 1.39, 7.6e-2 ..
    1.7e-2). Bounds: the slope within about 0.25 of the measured one on either side, the finest
    error 2x the measured one."""
    hs, errs = [3.0, 1.5, 1.0], []
    for h in hs:
        problem, sol = solve_beam(MPI.COMM_WORLD, h, variant)
        errs.append(
            mf.error_norms(problem.V.mesh, sol.evaluate_at_quadrature, BEAM, BEAM_MATERIAL)["l2"]
        )
    assert rate[0] < fitted_rate(hs, errs) < rate[1]
    assert errs[-1] < finest


def test_two_ranks_equal_serial():
    """The cantilever on COMM_WORLD and on COMM_SELF (every rank alone) gives the same
    displacement at probe points (both variants)."""
    pts = np.array([[1.0, 0.5], [23.9, -5.0], [24.0, 2.0], [30.3, 4.1], [47.9, -5.9]])
    for variant in mf.HYBRID_VARIANTS:
        u = []
        for comm in (MPI.COMM_WORLD, MPI.COMM_SELF):
            _, sol = solve_beam(comm, 3.0, variant)
            u.append(sol.displacement(pts))
        assert np.abs(u[0] - u[1]).max() < 1e-10 * np.abs(u[1]).max()


# --- bad input -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "options, match",
    [
        ({"variant": "HA-X"}, r"variant='HA-X' is not known; use 'HA-S'"),
        ({"integration": "nodes"}, r"integration='nodes' is not known"),
        ({"smoothing": -1.0}, r"smoothing=-1.0 must be a positive number"),
        ({"quadrature_degree": 0}, r"quadrature_degree=0 must be a positive integer"),
    ],
)
def test_bad_input_is_refused_on_every_rank(options, match):
    with pytest.raises(ValueError, match=match):
        beam_problem(MPI.COMM_WORLD, 3.0, **options)


def test_bad_input_on_one_rank_only():
    """A value that is bad on one rank only still raises on every rank (no hang)."""
    comm = MPI.COMM_WORLD
    variant = "HA-X" if comm.rank == comm.size - 1 else "HA-S"
    with pytest.raises(ValueError, match="variant='HA-X' is not known"):
        beam_problem(comm, 3.0, variant)


def test_bad_particle_mass():
    problem = rod_problem(MPI.COMM_WORLD, 2.5, 1, "HA-F")
    with pytest.raises(ValueError, match="particle_mass='lumped' is not known"):
        ExplicitDynamics.coupled(problem, particle_mass="lumped")


# --- the particle:node ratio ---------------------------------------------------------------------


def pulse_errors(ratio: float, comm=MPI.COMM_WORLD, **options) -> tuple[float, float, float]:
    """Relative L2 velocity errors at t1 = L / c and t2 = 2 L / c and the energy drift of the
    rod with FE cells h = 0.5 on x < 30 and particles of spacing h / sqrt(ratio) on x > 30, the
    pulse starting at x = 24 so that it crosses the interface before t1 and after it."""
    rod = GaussianPulseRod(E=ROD.E, rho=ROD.rho, length=60.0, center=24.0)
    problem = rod_problem(comm, 0.5, np.sqrt(ratio), "HA-F", consistent=False, **options)
    dyn = ExplicitDynamics.coupled(problem, particle_mass="volume")
    dyn.set_initial(velocity=rod.initial_velocity, particle_values="nodal")
    errors = {}
    res = dyn.run(
        2 * rod.transit_time,
        outputs=[rod.transit_time, 2 * rod.transit_time],
        on_output=lambda d, n, t: errors.setdefault(t, d.velocity_error(rod.velocity)),
    )
    dyn.destroy()
    e = [errors[t] for t in sorted(errors)]
    return e[0], e[-1], res.energy_drift


@pytest.mark.parametrize("ratio", [2.0, 3.0])
def test_pulse_error_does_not_depend_on_the_ratio(ratio):
    """A pulse crossing the interface, at particle:node ratios whose spacing does not divide the
    cells. Measured (centred particles, smoothed strains), error at t1 / t2: ratio 2 4.6e-3 /
    3.1e-3, ratio 3 2.2e-3 / 2.1e-3 (ratios 1, 4, 6, 8: 1.3e-2 / 7.8e-3, 1.4e-3 / 1.8e-3,
    1.6e-3 / 1.5e-3, 2.1e-3 / 1.4e-3), so the bound 1e-2 is about 2x the larger; growth t1 -> t2
    0.67 and 0.99 (bound 1.5); energy drift 1e-13.

    The former discretisation (the patch's particles through the interface nodes with volumes
    sampled by 3 x 3 Gauss points per cell, Gauss integration of the particle energy) misses
    the bound 16-67x: 0.35 / 0.67 (ratio 2), 0.16 / 0.39 (ratio 3); with centred particles but
    Gauss integration, whose missed patch test reflects part of the wave at the interface:
    1.9e-2 / 2.9e-2 and 1.2e-2 / 1.8e-2."""
    e1, e2, drift = pulse_errors(ratio, integration="smoothed")
    assert e1 < 1e-2 and e2 < 1e-2
    assert e2 < 1.5 * e1
    assert drift < 1e-10
    old = pulse_errors(ratio, particles="patch", integration="cells")
    assert min(old[:2]) > 0.1  # the measured miss, not a tolerance


def test_pulse_two_ranks_equal_serial():
    """The pulse errors and energy drift of the smoothed, centred hybrid (ratio 3) on
    COMM_WORLD and on COMM_SELF agree to round-off: the centred particles, their volumes and the
    smoothing cells do not depend on the partition."""
    world = pulse_errors(3.0, MPI.COMM_WORLD, integration="smoothed")
    alone = pulse_errors(3.0, MPI.COMM_SELF, integration="smoothed")
    assert abs(world[0] - alone[0]) < 1e-9 * alone[0]
    assert abs(world[1] - alone[1]) < 1e-9 * alone[1]


@pytest.mark.parametrize("cell_name", ["quadrilateral", "triangle"])
def test_centred_particles_tile_the_patch(cell_name):
    """The SPH particles of ``particles="centred"``: none on the interface, volumes that add up
    to the patch's area and equal the lattice square's area wherever the square lies inside the
    patch (to round-off), for a patch of cells chosen by a slanted criterion and a spacing that
    divides neither the cells nor the box."""
    comm = MPI.COMM_WORLD
    msh = rectangle(comm, [0, 0], [6, 3], [12, 6], CELL_TYPES[cell_name])
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    cells = np.flatnonzero(xc[:, 0] + 0.5 * xc[:, 1] > 3.2)
    patch = mf.ParticlePatch(msh, cells, 0.37)
    V = _compat.vector_function_space(msh)
    problem = mf.HybridElasticity(V, patch, STEEL, "HA-S", particles="centred")
    assert mf.HybridElasticity(V, patch, STEEL, "HA-S").patch is patch  # HA-S: the patch's own
    P = problem.patch.particles
    assert problem.patch is not patch and patch.particles.num_particles != P.num_particles
    area = comm.allreduce(float(mf.cell_quadrature(msh, 1, patch.cells).weights.sum()))
    assert abs(P.volumes.sum() - area) < 1e-12 * area
    # a particle whose square lies inside the patch (all four corners satisfy the criterion
    # of some patch cell: here, right of the slanted border by a cell diagonal) has the
    # square's area; the squares' areas are the modal volume
    square = np.median(P.volumes)
    inside = P.positions[:, 0] + 0.5 * P.positions[:, 1] > 3.2 + 1.0
    assert inside.sum() > 20
    assert np.abs(P.volumes[inside] - square).max() < 1e-12 * square
    # no particle on an FE node (the staircase interface's corners come nearest: measured 0.21
    # spacing); the patch's own grid puts particles on them
    fe_cells = np.flatnonzero(~patch.in_patch[:n])
    fe_nodes = msh.geometry.x[np.unique(_compat.geometry_dofmap(msh)[fe_cells]), :2]

    def nearest(x: np.ndarray) -> float:
        return np.linalg.norm(x[:, None, :] - fe_nodes[None, :, :], axis=2).min(initial=np.inf)

    assert nearest(P.positions) > 0.1 * np.sqrt(square)
    assert comm.allreduce(nearest(patch.particles.positions), op=MPI.MIN) < 1e-12


@pytest.mark.parametrize("variant", mf.HYBRID_VARIANTS)
def test_smoothed_strains_pass_the_patch_test(variant):
    """Strains smoothed over sub-cells (``integration="smoothed"``, symmetric ``K``): a linear
    field leaves no force at any FE node or particle but its boundary loads, to round-off
    (measured 7e-15 of the loads, h = 1.5, both variants)."""
    problem = beam_problem(MPI.COMM_WORLD, 1.5, variant, integration="smoothed")
    fe, p, scale = patch_residual(problem)
    assert scale > 1e4
    assert fe < 1e-12 * scale and p < 1e-12 * scale


def test_smoothed_stiffness_is_symmetric():
    """``v . K u = u . K v`` over [FE | particles] for random ``u``, ``v`` (HA-F, smoothed; to
    round-off of ``|u| |K| |v|``), which is what makes central differences conserve energy."""
    problem = beam_problem(MPI.COMM_WORLD, 3.0, "HA-F", integration="smoothed")
    ops = problem.operators()
    rng = np.random.default_rng(7 + MPI.COMM_WORLD.rank)
    vecs = []
    for _ in range(2):
        a, b = ops.K_fe.createVecRight(), ops.K_p.createVecRight()
        n_owned = problem.V.dofmap.index_map.size_local
        a.array[:] = rng.standard_normal(a.getLocalSize()) * np.repeat(ops.fe_active[:n_owned], 2)
        b.array[:] = rng.standard_normal(b.getLocalSize())
        vecs.append((a, b))

    def apply(a, b):
        ra, rb = ops.K_fe.createVecLeft(), ops.K_p.createVecLeft()
        ops.K_fe.mult(a, ra)
        ops.K_fp.multAdd(b, ra, ra)
        ops.K_p.mult(b, rb)
        ops.K_pf.multAdd(a, rb, rb)
        return ra, rb

    (ua, ub), (va, vb) = vecs
    Ku, Kv = apply(ua, ub), apply(va, vb)
    vKu = va.dot(Ku[0]) + vb.dot(Ku[1])
    uKv = ua.dot(Kv[0]) + ub.dot(Kv[1])
    scale = (
        ops.K_p.norm(PETSc.NormType.INFINITY) * (ua.norm() + ub.norm()) * (va.norm() + vb.norm())
    )
    assert abs(vKu - uKv) < 1e-13 * scale
    assert abs(vKu) > 1e-6 * scale  # not vacuous
    for obj in (ua, ub, va, vb, *Ku, *Kv):
        obj.destroy()
    ops.destroy()


@pytest.mark.parametrize("cell_name", ["quadrilateral", "triangle"])
@pytest.mark.parametrize("spacing", [0.25, 0.75, None])
def test_slanted_patch_passes_the_patch_test_at_any_spacing(cell_name, spacing):
    """A patch of cells chosen by a slanted criterion (a staircase border), particle spacing
    0.5 h, 1.5 h or the patch's vertices, default options of both variants: the linear patch
    test holds to round-off (measured below 2e-14 of the loads). At 1.5 h the lattice of HA-F's
    centred particles leaves a corner of the staircase with two collinear particles in reach,
    where the corrected sums are not defined; an extra particle in that cell restores them
    (without it: "SPH gradient correction is singular")."""
    comm = MPI.COMM_WORLD
    msh = rectangle(comm, [0, 0], [6, 3], [12, 6], CELL_TYPES[cell_name])
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    cells = np.flatnonzero(xc[:, 0] + 0.5 * xc[:, 1] > 3.2)
    placement = "grid" if spacing else "vertices"
    patch = mf.ParticlePatch(msh, cells, spacing, placement=placement)
    V = _compat.vector_function_space(msh)
    for variant in mf.HYBRID_VARIANTS:
        fe, p, scale = patch_residual(mf.HybridElasticity(V, patch, BEAM_MATERIAL, variant))
        assert scale > 1e3
        assert fe < 1e-12 * scale and p < 1e-12 * scale


@pytest.mark.parametrize("cell_name", ["quadrilateral", "triangle"])
def test_lone_cells_pass_the_patch_test(cell_name):
    """A patch in pieces: a block, a lone cell and a strip one cell wide (what a conversion of
    failing cells names: a cell of the Hanchak slab converted on its own). The centred
    particles of a cell whose centroid sees fewer than three non-collinear ones get a particle
    a quarter of the way from each vertex (before: the tries stacked them on one line, and the
    lone cell was refused, "SPH gradient correction is singular"); the linear patch test then
    holds to round-off in both variants (measured below 1e-14 of the loads)."""
    comm = MPI.COMM_WORLD
    msh = rectangle(comm, [0, 0], [6, 3], [12, 6], CELL_TYPES[cell_name])
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    block = (xc[:, 0] > 4.5) & (xc[:, 1] > 1.5)
    lone = (np.abs(xc[:, 0] - 1.25) < 0.25) & (np.abs(xc[:, 1] - 1.25) < 0.25)
    strip = (np.abs(xc[:, 1] - 2.75) < 0.25) & (xc[:, 0] < 2.0)
    patch = mf.ParticlePatch(msh, np.flatnonzero(block | lone | strip), 0.5)
    V = _compat.vector_function_space(msh)
    for variant in mf.HYBRID_VARIANTS:
        fe, p, scale = patch_residual(mf.HybridElasticity(V, patch, BEAM_MATERIAL, variant))
        assert scale > 1e3
        assert fe < 1e-12 * scale and p < 1e-12 * scale


# --- essential conditions on the patch at coarse particle spacings -------------------------------

robustness = load_demo("robustness")


def _gmsh_axis_case(comm, level: int, **options) -> tuple[float, float]:
    """The robustness matrix's hybrid/gmsh/axis/1.5/none case at one level: the exact quadratic
    displacement on the whole boundary of the gmsh square, patch x > 1 with particles at 1.5 h
    (so the patch carries Dirichlet facets on three sides). Returns (hybrid L2 error, plain FE
    L2 error of the same model by DOLFINx's own assembly)."""
    msh, h = robustness.build_mesh(comm, "gmsh", level)
    model = robustness.user_model(msh, "none")
    fe = robustness.solve_plain_fe(model)["l2"]
    patch = robustness.make_patch(msh, "axis", "1.5", h)
    problem = mf.HybridElasticity(model.V, patch, robustness.MATERIAL, **options)
    problem.add_dirichlet(model.dirichlet_facets, model.exact.displacement)
    solution = problem.solve()
    errors = mf.error_norms(msh, solution.evaluate_at_quadrature, model.exact, robustness.MATERIAL)
    return errors["l2"], fe


@pytest.mark.parametrize(
    "options, ratio_max",
    [
        # Nitsche (the default with smoothed strains): measured 2.62 and 1.81 x FE, rate 2.51
        ({}, 3.6),
        # multipliers on pieces of two spacings: 3.50 and 2.18 x FE, rate 2.67
        ({"nitsche": 0.0}, 4.4),
    ],
)
def test_patch_dirichlet_facets_at_coarse_spacing(options, ratio_max):
    """Dirichlet facets on the patch with particles at 1.5 h: one multiplier per facet and
    component outnumbered the centred particles near the boundary (rank-deficient constraint
    block, condition number 4e18): the error was 3,700 x and 1.1e6 x the plain FE error, rate
    -6.2. Nitsche's method, or multipliers on pieces of two particle spacings, converge like the
    plain FE model (bounds: about 2 x the measured ratio on the finer mesh; rate two-sided).
    Serial and 2 ranks agree to 1e-12 (measured)."""
    comm = MPI.COMM_WORLD
    (e0, f0), (e1, f1) = (_gmsh_axis_case(comm, level, **options) for level in (0, 1))
    rate = np.log2(e0 / e1)
    assert e1 / f1 < ratio_max, (e0 / f0, e1 / f1)
    assert 2.0 < rate < 3.2, rate


def test_dependent_patch_multipliers_are_refused():
    """The safety net: with one multiplier per facet (``multiplier_length=0``, no Nitsche) the
    same case has 52 multipliers of rank 48 on 64 particle dofs; the solve refuses, on every
    rank, instead of returning the garbage of the singular system, and names the fix."""
    with pytest.raises(ValueError, match=r"linearly dependent.*multiplier_length"):
        _gmsh_axis_case(MPI.COMM_WORLD, 0, nitsche=0.0, multiplier_length=0.0)


def test_facet_pieces_do_not_depend_on_the_partition():
    """:func:`~dolfinx_meshfree.geometry.facet_groups.grouped_facet_quadrature` on the boundary of a
    square (one closed chain of length 8, facets 0.25 long): floor(8 / 0.6) = 13 pieces, each
    of length 8/13 within one facet, covering every facet once; the pieces computed on the
    distributed mesh equal those of the same mesh on one rank (checked by their midpoints)."""
    from dolfinx_meshfree.geometry.facet_groups import grouped_facet_quadrature

    def pieces(comm):
        msh = rectangle(comm, [0, 0], [2, 2], [8, 8], CELL_TYPES["triangle"])
        groups = grouped_facet_quadrature(msh, mf.boundary_facets(msh), 0.6)
        q = groups.quadrature(1)
        length = np.bincount(q.entities, weights=q.weights)
        mid = np.stack([np.bincount(q.entities, q.weights * q.points[:, k]) for k in range(2)], 1)
        return length, mid / length[:, None], groups

    length, mid, groups = pieces(MPI.COMM_WORLD)
    assert groups.num_groups == 13 and groups.ends.shape[0] == 32
    assert np.abs(length - 8.0 / 13).max() <= 0.25 + 1e-12
    assert abs(length.sum() - 8.0) < 1e-12
    alone, mid_alone, _ = pieces(MPI.COMM_SELF)
    order = np.lexsort(mid.T[::-1])
    order_alone = np.lexsort(mid_alone.T[::-1])
    assert np.allclose(mid[order], mid_alone[order_alone], atol=1e-12)
    assert np.allclose(length[order], alone[order_alone], atol=1e-12)
