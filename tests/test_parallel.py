"""Parallel equals serial: the same problem on MPI.COMM_WORLD and on MPI.COMM_SELF in one run.

Under one rank both are the same computation (the test is then trivially true); under two ranks
the COMM_WORLD run distributes cells, particles, multipliers and the MUMPS factorisation, and
must agree with every rank's private serial solve at every rank's own probe points to round-off
(``1e-10`` relative: the two runs differ only in summation order and pivoting).
"""

import itertools

import dolfinx_meshfree as mf

import numpy as np
import pytest
from conftest import (
    beam_mesh,
    efg_errors,
    fe_errors,
    solve_beam_efg,
    solve_beam_fe,
)
from mpi4py import MPI

RTOL = 1e-10
BEAM = mf.TimoshenkoBeam(mf.LinearElastic(3e7, 0.3))


def probes(rng, m=30):
    """Points of the beam, different on every rank (the rng is seeded by the rank)."""
    return rng.uniform([0.0, -6.0], [48.0, 6.0], (m, 2))


@pytest.mark.parametrize(
    "cell_name, h, consistent",
    [("quadrilateral", 3.0, False), ("quadrilateral", 1.5, True), ("triangle", 3.0, False)],
)
def test_efg_cantilever_parallel_equals_serial(cell_name, h, consistent, rank_rng):
    x = probes(rank_rng)
    out = {}
    for name, comm in (("world", MPI.COMM_WORLD), ("self", MPI.COMM_SELF)):
        msh = beam_mesh(comm, h, cell_name)
        sol = solve_beam_efg(msh, BEAM, h, consistent=consistent)
        out[name] = (sol, sol.evaluate(x), efg_errors(msh, sol, BEAM))
    (sw, (uw, gw), ew), (ss, (us, gs), es) = out["world"], out["self"]
    np.testing.assert_array_equal(sw.mls.points, ss.mls.points)
    assert sw.num_multipliers == ss.num_multipliers
    assert np.abs(sw.coefficients - ss.coefficients).max() <= RTOL * np.abs(ss.coefficients).max()
    assert np.abs(uw - us).max() <= RTOL * np.abs(us).max()
    assert np.abs(gw - gs).max() <= RTOL * np.abs(gs).max()
    for key in ("l2", "energy"):
        assert abs(ew[key] - es[key]) <= 1e-8 * es[key]
    # and the solution is the cantilever's, not merely the same garbage twice
    assert es["l2"] < 0.01


@pytest.mark.parametrize("cell_name", ["quadrilateral", "triangle"])
def test_fe_cantilever_parallel_equals_serial(cell_name, rank_rng):
    x = probes(rank_rng)
    values, errors = [], []
    for comm in (MPI.COMM_WORLD, MPI.COMM_SELF):
        msh = beam_mesh(comm, 1.5, cell_name)
        sol = solve_beam_fe(msh, BEAM)
        values.append(mf.evaluate_fe_function(sol.u, x))
        errors.append(fe_errors(msh, sol, BEAM))
        assert sol.num_dofs == 2 * (round(48 / 1.5) + 1) * (round(12 / 1.5) + 1)
    assert np.abs(values[0] - values[1]).max() <= RTOL * np.abs(values[1]).max()
    for key in ("l2", "energy"):
        assert abs(errors[0][key] - errors[1][key]) <= 1e-8 * errors[1][key]
    assert errors[1]["l2"] < 0.1


def test_particle_sets_agree_and_partition_the_particles():
    sets = [
        mf.ParticleSet.from_cells(beam_mesh(comm, 3.0), 1.5, jitter=0.2)
        for comm in (MPI.COMM_WORLD, MPI.COMM_SELF)
    ]
    world, serial = sets
    np.testing.assert_array_equal(world.positions, serial.positions)
    # Voronoi volumes by quadrature: the same up to summation order, adding up to the area
    np.testing.assert_allclose(world.volumes, serial.volumes, rtol=1e-12)
    assert abs(serial.volumes.sum() - 48.0 * 12.0) <= 1e-10 * 48.0 * 12.0
    comm = MPI.COMM_WORLD
    # every particle is owned by exactly one rank; the PETSc numbering is owner by owner
    owned = np.concatenate(comm.allgather(world.owned))
    assert np.array_equal(np.sort(owned), np.arange(world.num_particles))
    assert np.array_equal(np.sort(world.petsc_index), np.arange(world.num_particles))
    starts = comm.allgather((world.layout.start, world.layout.size_local))
    assert starts[0][0] == 0
    for (s0, n0), (s1, _) in itertools.pairwise(starts):
        assert s1 == s0 + n0
    assert np.array_equal(
        np.sort(world.petsc_index[world.owned]), np.arange(world.layout.start, world.layout.end)
    )
