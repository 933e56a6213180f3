"""Where the dofs of an explicit model live: the FE space, the particles and their
approximation, the patch and the coupling's interface.

Loads, initial conditions and evaluation need the same facts about a model: the positions of
each field's owned nodes or particles, which cells are particle cells and which are blended
(ramp interface, bridging band), and the master–slave reduction of the particle coefficients.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import dolfinx
import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from ..approx.fe_points import tabulate_in_cells
from ..approx.mls import MLS
from ..couplings.bridging import BridgingBand
from ..couplings.ramp import RampInterface
from ..geometry.particles import ParticleSet
from ..geometry.patch import ParticlePatch
from ..parallel import raise_on_all_ranks
from ..physics import user_functions
from .system import Field

__all__ = ["Discretisation", "approximation_cracks", "vector_values"]

VectorFunction = Callable[[np.ndarray], np.ndarray]


def vector_values(
    fn: Callable[..., np.ndarray], *args: np.ndarray, name: str = "the function"
) -> np.ndarray:
    """``fn(*args)`` as an (m, gdim) float array, ``m, gdim = args[0].shape`` (the points), else
    an error naming ``name`` (:func:`~dolfinx_meshfree.physics.user_functions.vector_values`)."""
    return user_functions.vector_values(fn, args, args[0].shape[0], name, args[0].shape[1])


def approximation_cracks(patch: object | None, mls: object | None) -> list:
    """The cracks cutting a particle approximation: the patch's (a coupled model), or those
    attached to the MLS of pure EFG through its pair cuts; empty without."""
    if patch is not None:
        return list(patch.cracks)
    cuts = getattr(mls, "pair_cuts", ())
    return [c for cut in cuts for c in getattr(cut, "cracks", ())]


@dataclass
class Discretisation:
    """The spaces of an explicit model (``None`` where a model has none).

    Attributes:
        fields: The fields of the system (FE first).
        V: The FE space. mls: The particles' approximation (MLS, or the hybrid's evaluator).
        particles: The particle set. mesh: The mesh. in_patch: bool per local cell: a
            particle cell. patch: The particle patch.
        interface: The coupling's interface: a
        :class:`~dolfinx_meshfree.couplings.ramp.RampInterface`
            (blended interface cells) or a
            :class:`~dolfinx_meshfree.couplings.bridging.BridgingBand`
            (weighted band cells).
        reduction: ``(T_PF, S)`` when the particle field holds master particles only
            (master–slave): the particle coefficients are ``T_PF d_FE + S d_M``.
        axisymmetric: The mesh is the (r, z) section of a solid of revolution: surface
            integrals (tractions) take ``2 pi r`` weights
            (:mod:`~dolfinx_meshfree.physics.axisymmetry`).
    """

    fields: Sequence[Field]
    V: dolfinx.fem.FunctionSpace | None = None
    mls: MLS | None = None
    particles: ParticleSet | None = None
    mesh: dolfinx.mesh.Mesh | None = None
    in_patch: np.ndarray | None = None
    patch: ParticlePatch | None = None
    interface: RampInterface | BridgingBand | None = None
    reduction: tuple[PETSc.Mat, PETSc.Mat] | None = None
    axisymmetric: bool = False

    @property
    def gdim(self) -> int:
        """The geometric dimension (2 or 3): the components of every field."""
        if self.mesh is not None:
            return self.mesh.geometry.dim
        return self.particles.gdim

    @property
    def cracks(self) -> list:
        """The cracks cutting the particles' approximation (:func:`approximation_cracks`)."""
        return approximation_cracks(self.patch, self.mls)

    def blended_tables(
        self, points: np.ndarray, cells: np.ndarray, comm: MPI.Comm
    ) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """The FE part (points x local nodes of ``V``) and the particle part (points x
        particles) of the blended functions at points of local blended cells: the ramps'
        ``(1 - R) N`` and ``R phi`` (Belytschko et al. 1995, eq. 3.12), bridging's
        ``(1 - alpha) N`` and ``alpha phi`` (Rabczuk et al. 2006, eq. 49). Collective."""
        if isinstance(self.interface, RampInterface):  # columns [local FE nodes | particles]
            t = raise_on_all_ranks(comm, lambda: self.interface.table(points, cells, 0))
            n_fe = self.V.dofmap.index_map.size_local + self.V.dofmap.index_map.num_ghosts
            t = t.values.tocsc()
            return t[:, :n_fe].tocsr(), t[:, n_fe:].tocsr()
        a = self.interface.alpha_at(points, cells)
        t_fe = tabulate_in_cells(self.V, points, cells, 0).values
        t_p = raise_on_all_ranks(comm, lambda: self.mls.tabulate(points, 0)).values
        return (sp.diags(1.0 - a) @ t_fe).tocsr(), (sp.diags(a) @ t_p).tocsr()

    def blended_cells(self) -> np.ndarray | None:
        """bool per local cell: a ramp interface cell or a bridging band cell (else ``None``)."""
        if self.interface is None:
            return None
        for name in ("in_interface", "in_band"):
            flags = getattr(self.interface, name, None)
            if flags is not None:
                return flags
        return None

    def on_particles(self, cells: np.ndarray) -> np.ndarray:
        """bool per given local cell: a particle cell (pure EFG: every cell)."""
        if self.in_patch is not None:
            return self.in_patch[cells]
        return np.full(np.asarray(cells).size, self.V is None)

    def owned_particles(self) -> np.ndarray:
        """Local indices of the owned particles in PETSc order."""
        P = self.particles
        return P.owned[np.argsort(P.petsc_index[P.owned], kind="stable")]

    def owned_points(self, k: int) -> np.ndarray:
        """Positions (owned, in PETSc order) of field ``k``'s nodes or particles."""
        f = self.fields[k]
        if f.points is not None:
            return f.points
        if f.name == "fe":
            n_owned = self.V.dofmap.index_map.size_local
            return self.V.tabulate_dof_coordinates()[:n_owned, : self.gdim]
        return self.particles.positions[self.owned_particles()]
