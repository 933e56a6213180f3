"""The body force's term in the dynamic interaction integral (before: refused).

The balance is ``sigma_ij,j = rho (u_tt - b / rho)``, so the integral's inertia term takes the
acceleration less ``b / rho`` (:meth:`ExternalLoads.body_acceleration
<dolfinx_meshfree.dynamics.loads.ExternalLoads.body_acceleration>`), in the full integral and in
the linear functionals (:meth:`SIFFunctional.at_points
<dolfinx_meshfree.statics.sif_functional.SIFFunctional.at_points>`).

Oracle: a closed form with K = 0. A free body under a uniform body force ``b`` (with a time
amplitude) accelerates rigidly at ``amplitude(t) b / rho``: the lumped masses and the body loads
share their rule, so every dof takes that acceleration and the field stays undeformed (checked).
Its crack carries no stress, so K_I = K_II = 0, which the inertia term alone would miss: without
the body force's term K_I and K_II were 0.9 % and 9 % of ``rho |a| a_crack^1.5`` (pure EFG;
lagrange 0.87 % and 8.7 %). With it: 4e-15 (measured; bound 1e-10).
"""

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics.sifs import dynamic_sifs

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

E, NU, RHO, A, H = 1000.0, 0.3, 2.0, 0.4, 0.05
LAW = mf.LinearElastic(E, NU, plane="strain", rho=RHO)
B = np.array([0.3, 1.0])  # the body force per unit volume, across and along the crack

pytestmark = [
    pytest.mark.filterwarnings("ignore::dolfinx_meshfree.PartitionImbalanceWarning"),
]


def free_body(method: str) -> tuple:
    """A free square with an edge crack (half a spacing off the particle rows) under ``B``
    ramped in time, run 20 stable steps; pure EFG or a cracked patch."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([0.0, -0.5]), np.array([1.0, 0.5])], [20, 20],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    crack = mf.Crack([[0.0, 0.5 * H], [A, 0.5 * H]])
    if method == "efg":
        particles = mf.ParticleSet.from_cells(msh, spacing=H)
        dyn = mf.ExplicitDynamics.efg(particles, LAW, cracks=[crack])
    else:
        n = msh.topology.index_map(2).size_local
        mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
        cells = np.flatnonzero((mid[:, 0] < 0.8) & (np.abs(mid[:, 1]) < 0.35))
        patch = mf.ParticlePatch(msh, cells, H, cracks=[crack])
        model = mf.CoupledElasticity(
            _compat.vector_function_space(msh), patch, LAW, coupling=method
        )
        dyn = mf.ExplicitDynamics.coupled(model)
    dyn.add_body_force(lambda x: np.tile(B, (len(x), 1)), amplitude=lambda t: 1.0 + 10.0 * t)
    dyn.run(20 * dyn.stable_time_step())
    return dyn, crack


@pytest.mark.parametrize("method", ["efg", "lagrange"])
def test_a_free_body_under_a_body_force_has_no_k(method):
    dyn, crack = free_body(method)
    try:
        scale = RHO * np.linalg.norm(B / RHO) * A**1.5
        x = np.random.default_rng(0).uniform([0, -0.5], [1, 0.5], (50, 2))
        u = dyn.displacement_at(x)
        assert np.abs(u - u[0]).max() <= 1e-12 * np.abs(u).max()  # rigid: no strain
        for radius in ([2 * H, 3 * H], None):
            for j in (True, False):  # the full integral and the kept functionals
                k = dynamic_sifs(dyn, crack, 0, radius, j_integral=j)
                assert np.abs(k.K_I).max() <= 1e-10 * scale, (radius, j, k.K_I)
                assert np.abs(k.K_II).max() <= 1e-10 * scale, (radius, j, k.K_II)
        # the inertia term alone (the body force's term left out) is far from zero
        saved, dyn.loads.body_fields = dyn.loads.body_fields, []
        try:
            k = dynamic_sifs(dyn, crack, 0, [2 * H, 3 * H])
        finally:
            dyn.loads.body_fields = saved
        assert np.abs(k.K_II).max() >= 0.02 * scale, k.K_II
    finally:
        dyn.destroy()
