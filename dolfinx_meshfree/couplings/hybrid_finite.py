"""The hybrid SPH–FE coupling at finite strain: SPH sums of the nominal stress.

Rabczuk, Xiao & Sauer 2006 (sec. 5.5, eq. 125–130) write the particle forces of the hybrid
coupling in the reference configuration (total Lagrangian, eq. 1–5): at a stress point ``X_q``
the deformation gradient is the hybrid sum over the particles and the FE integration points
that join it,

.. math::
    F(X_q) = I + \\sum_J u_J \\otimes G_J(X_q) + \\sum_g u^{FE}(X_g) \\otimes G_g(X_q),

with the corrected kernel gradients ``G`` of the reference configuration
(:class:`~dolfinx_meshfree.couplings.hybrid_sph.CorrectedSPH`), and the forces are the
derivatives of the particle energy ``sum_q w_q W(F_q)``: ``f = sum_q w_q Bhat_q^T P(F_q)``
(eq. 127 with ``P`` the nominal stress, the pair form being that derivative for nodal
integration). Its linear limit is the ``sum_q w_q Bhat_q^T D B_q`` of
:func:`~dolfinx_meshfree.couplings.hybrid_strains.particle_energy_matrix`, on the same rule
(:func:`~dolfinx_meshfree.couplings.hybrid_strains.energy_tables`: smoothed strains, stress
points or particles). The forces reach the FE nodes by interpolation (HA-F, eq. 135); HA-S's
interface tractions (eq. 131–134) are not written at finite strain.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from ..approx.tables import ShapeTable
from ..physics.bulk_viscosity import particle_lengths
from ..physics.constitutive import Material
from ..physics.forces import InternalForces
from ..statics.petsc import create_aij, create_vector
from ..statics.sides import particle_coefficients
from .base import fe_dof_layout
from .hybrid_discretisation import HybridDiscretisation
from .hybrid_strains import energy_cells, energy_tables

__all__ = ["HybridForces"]


class HybridForces:
    """The particle energy of a hybrid (HA-F) discretisation at finite strain, over the FE and
    particle fields (a shared side of
    :class:`~dolfinx_meshfree.dynamics.finite_strain.NonlinearSystem`): ``f_int``, ``K_T``,
    ``W`` and ``F`` on the rule of :func:`~dolfinx_meshfree.couplings.hybrid_strains.
    energy_tables`, columns [particles | FE nodes]. Collective methods.

    Args:
        d: The hybrid discretisation (:class:`~dolfinx_meshfree.HybridElasticity`).
        material: The finite-strain law, or a rate-form law bound to these points
            (:class:`~dolfinx_meshfree.dynamics.rate_forms.RateLaw`: attached to them here).
        smoothed: Its smoothed gradients and areas, if already computed.
    """

    fields = (0, 1)

    def __init__(
        self,
        d: HybridDiscretisation,
        material: Material,
        smoothed: tuple[list[sp.csr_matrix], np.ndarray] | None = None,
    ) -> None:
        self.P, self.comm = d.patch.particles, d.comm
        n = self.P.num_particles
        N = d.hybrid.interpolation.shape[1]
        points, grads, test, weights = energy_tables(d, smoothed)
        attach = getattr(material, "attach", None)
        if attach is not None:  # a bound rate-form law: its points and their cells
            attach(points, energy_cells(d), particle_lengths(self.P.positions, points))
        table = ShapeTable(points, sp.csr_matrix((points.shape[0], n + N)), grads)
        self.forces = InternalForces(  # axisymmetric: the hoop of the hybrid sums (or smoothed)
            table, weights, material, test_gradients=test, comm=d.comm, hoop=d.hoop()
        )
        self.fe_layout, _ = fe_dof_layout(d.V)
        self.particle_layout = self.P.dof_layout()
        self.np = 2 * n
        self.dofs = np.concatenate([self.P.petsc_dofs(2).ravel(), np.arange(2 * N)])

    def _coefficients(self, xs: Sequence[PETSc.Vec]) -> np.ndarray:
        """[particles (original order) | FE nodes (global order)], interleaved, every rank."""
        fe = np.concatenate(self.comm.allgather(xs[0].getArray(readonly=True)))
        return np.concatenate([particle_coefficients(self.P, xs[1]), fe])

    def internal_force(self, xs: Sequence[PETSc.Vec]) -> list[PETSc.Vec]:
        """``[FE rows, particle rows]`` of ``sum_q w_q Bhat_q^T P(F_q)`` (collective)."""
        f = self.forces.internal_force(self._coefficients(xs))
        k = self.np
        fe = create_vector(self.comm, self.fe_layout, self.dofs[k:], f[k:])
        p = create_vector(self.comm, self.particle_layout, self.dofs[:k], f[:k])
        return [fe, p]

    def tangent(self, xs: Sequence[PETSc.Vec]) -> dict[tuple[int, int], PETSc.Mat]:
        """``K_T`` by blocks ``{(i, j): Mat}`` of :attr:`fields` (collective)."""
        K = self.forces.tangent(self._coefficients(xs)).tocoo()
        r, c = self.dofs[K.row], self.dofs[K.col]
        fe_r, fe_c = K.row >= self.np, K.col >= self.np
        layouts = [self.fe_layout, self.particle_layout]
        out = {}
        for i, rows in enumerate((fe_r, ~fe_r)):
            for j, cols in enumerate((fe_c, ~fe_c)):
                sel = rows & cols
                shape = (layouts[i].size_global, layouts[j].size_global)
                local = sp.csr_matrix((K.data[sel], (r[sel], c[sel])), shape=shape)
                out[i, j] = create_aij(self.comm, local, layouts[i], layouts[j])
        return out

    def strain_energy(self, xs: Sequence[PETSc.Vec]) -> float:
        """``sum_q w_q W(F_q)`` of this rank's points."""
        return self.forces.strain_energy(self._coefficients(xs))

    def deformation_gradient(self, xs: Sequence[PETSc.Vec]) -> np.ndarray:
        """``F`` (m, 2, 2) at this rank's points."""
        return self.forces.deformation_gradient(self._coefficients(xs))
