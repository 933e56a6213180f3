"""The discretisation of the hybrid SPH–FE coupling: particles, hybrid sums and their numbering.

Rabczuk et al. 2006, sec. 5.5, eq. 125–130 (Sauer 2000). :class:`HybridDiscretisation` holds what
every part of :class:`~dolfinx_meshfree.HybridElasticity` reads and nothing it assembles: the
options (checked on every rank), the particle spacing and smoothing length, the SPH particles (the
patch's own or :func:`~dolfinx_meshfree.couplings.hybrid_sph.centred_particles`), the FE integration
points that join the sums (:func:`~dolfinx_meshfree.couplings.hybrid_sph.hybrid_points`), the hybrid
sums over both (eq. 125–126) and the particles' own interpolant
(:class:`~dolfinx_meshfree.couplings.hybrid_sph.CorrectedSPH`), the smoothing cells of
``integration="smoothed"`` (:mod:`~dolfinx_meshfree.couplings.hybrid_smoothing`) and the stress
points of the particle energy; and the combined numbering [particles | FE nodes] of the operators
(:meth:`HybridDiscretisation.node_map`, :meth:`HybridDiscretisation.dof_map`).
"""

from __future__ import annotations

import copy
import math
import time
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

if TYPE_CHECKING:  # annotations only
    import dolfinx.fem
    import dolfinx.mesh

from ..approx.body_cuts import body_cut
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import QuadraturePoints, cell_quadrature
from ..parallel import raise_on_all_ranks
from ..physics import axisymmetry
from ..physics.materials import LinearElastic
from .base import check_dimension
from .hybrid_smoothing import SmoothingCells, smoothing_cells
from .hybrid_sph import (
    CorrectedSPH,
    centred_particles,
    hybrid_points,
    particle_spacing_median,
)

__all__ = [
    "HYBRID_INTEGRATIONS",
    "HYBRID_PARTICLES",
    "HYBRID_VARIANTS",
    "HybridDiscretisation",
    "check_axisymmetric",
    "check_options",
    "global_facets",
]

#: How the particle forces reach the FE nodes (Rabczuk et al. 2006, sec. 5.5).
HYBRID_VARIANTS = ("HA-S", "HA-F")
#: Stress points of the particle energy.
HYBRID_INTEGRATIONS = ("cells", "particles", "smoothed")
#: Where the SPH particles sit: centres of a lattice of squares, or the patch's own particles.
HYBRID_PARTICLES = ("centred", "patch")


def check_options(
    V: dolfinx.fem.FunctionSpace,
    patch: ParticlePatch,
    material: LinearElastic,
    variant: str,
    smoothing: float,
    quadrature_degree: int | None,
    hybrid_degree: int | None,
    integration: str | None,
    consistent: bool,
    particles: str | None,
    multiplier_length: float,
    nitsche: float,
) -> None:
    """Check the arguments of :class:`~dolfinx_meshfree.HybridElasticity` (local; the caller
    raises on every rank through :func:`~dolfinx_meshfree.parallel.raise_on_all_ranks`).

    Raises:
        ValueError: an unknown ``variant``, ``integration`` or ``particles``, a mesh mismatch,
            a smoothing, degree, ``nitsche`` or ``multiplier_length`` out of range.
        TypeError: a material that is not a :class:`~dolfinx_meshfree.LinearElastic`.
    """
    check_dimension(
        V.mesh,
        "hybrid",
        (2,),
        "its SPH particles (a 2D lattice of squares), kernel normalisation and interface "
        "tractions (Rabczuk et al. 2006, eq. 131-135) are written for 2D",
    )
    if variant not in HYBRID_VARIANTS:
        raise ValueError(
            f"variant={variant!r} is not known; use 'HA-S' (forces by interface "
            "tractions, Rabczuk et al. 2006, eq. 131-134) or 'HA-F' (by interpolation, "
            "eq. 135)"
        )
    if integration is not None and integration not in HYBRID_INTEGRATIONS:
        raise ValueError(
            f"integration={integration!r} is not known; use 'cells' (Gauss points of "
            "the patch cells), 'smoothed' (strains smoothed over sub-cells: symmetric "
            "and consistent) or 'particles' (nodal integration, dynamics only)"
        )
    if particles is not None and particles not in HYBRID_PARTICLES:
        raise ValueError(
            f"particles={particles!r} is not known; use 'centred' (SPH particles at the "
            "centres of a lattice of squares, the default) or 'patch' (the patch's own "
            "particles)"
        )
    if not isinstance(material, LinearElastic):
        raise TypeError(f"material must be a LinearElastic, got {type(material).__name__}")
    if material.axisymmetric:
        check_axisymmetric(V, variant, integration)
    if V.mesh is not patch.mesh:
        raise ValueError("V and patch must live on the same mesh object")
    if isinstance(smoothing, bool) or not (
        isinstance(smoothing, int | float) and math.isfinite(smoothing) and smoothing > 0
    ):
        raise ValueError(
            f"smoothing={smoothing!r} must be a positive number (the smoothing length "
            "over the particle spacing; 1.3 is usual)"
        )
    for name, deg in (
        ("quadrature_degree", quadrature_degree),
        ("hybrid_degree", hybrid_degree),
    ):
        if deg is not None and (isinstance(deg, bool) or not isinstance(deg, int) or deg < 1):
            raise ValueError(f"{name}={deg!r} must be a positive integer or None")

    if not isinstance(consistent, bool | np.bool_):
        raise ValueError(f"consistent={consistent!r} must be True or False")
    if isinstance(nitsche, bool) or not (
        isinstance(nitsche, int | float) and math.isfinite(nitsche) and nitsche >= 0
    ):
        raise ValueError(
            f"nitsche={nitsche!r} must be a number >= 0 (Nitsche's parameter of the "
            "patch's essential conditions, 10.0 by default; 0 for multipliers)"
        )
    if isinstance(multiplier_length, bool) or not (
        isinstance(multiplier_length, int | float)
        and math.isfinite(multiplier_length)
        and multiplier_length >= 0
    ):
        raise ValueError(
            f"multiplier_length={multiplier_length!r} must be a number >= 0 (the "
            "length of the pieces of a patch Dirichlet boundary that carry one "
            "multiplier, in particle spacings; 2.0 is the default, 0 one per facet)"
        )


def check_axisymmetric(V: dolfinx.fem.FunctionSpace, variant: str, integration: str | None) -> None:
    """Refuse what the axisymmetric hybrid does not revolve (local): HA-S (its interface
    tractions, eq. 131-134, are plane) and nodal integration (``"particles"``: a particle's
    volume is not revolved); a section outside ``r >= 0``."""
    if variant != "HA-F" or integration == "particles":
        raise ValueError(
            f"material plane='axisymmetric' with variant={variant!r}, "
            f"integration={integration!r}: the axisymmetric hybrid is HA-F with "
            "integration='smoothed' (the default) or 'cells': HA-S's interface tractions and "
            "nodal integration are plane"
        )
    axisymmetry.check_half_plane(V.mesh.geometry.x, "V's mesh")


class HybridDiscretisation:
    """Particles, FE integration points and hybrid sums of the hybrid SPH–FE coupling
    (Rabczuk et al. 2006, eq. 125–130; collective). The arguments are those of
    :class:`~dolfinx_meshfree.HybridElasticity`, which documents them and derives from this
    class.

    Raises:
        ValueError: on every rank, for an argument out of range (:func:`check_options`) or
            particles too sparse for the kernel.
    """

    def __init__(
        self,
        V: dolfinx.fem.FunctionSpace,
        patch: ParticlePatch,
        material: LinearElastic,
        variant: str = "HA-F",
        smoothing: float = 1.0,
        quadrature_degree: int | None = None,
        hybrid_degree: int | None = None,
        integration: str | None = None,
        consistent: bool = True,
        particles: str | None = None,
        multiplier_length: float = 2.0,
        nitsche: float = 10.0,
    ) -> None:
        comm = patch.comm
        raise_on_all_ranks(
            comm,
            lambda: check_options(
                V,
                patch,
                material,
                variant,
                smoothing,
                quadrature_degree,
                hybrid_degree,
                integration,
                consistent,
                particles,
                multiplier_length,
                nitsche,
            ),
        )
        if integration is None:
            integration = "smoothed" if variant == "HA-F" else "cells"
        if particles is None:
            particles = "centred" if variant == "HA-F" else "patch"
        t0 = time.perf_counter()
        self.consistent = bool(consistent)
        self.multiplier_length = float(multiplier_length)
        self.nitsche = float(nitsche)
        self.variant, self.integration = variant, integration
        # the median nearest-neighbour distance, but not below the spacing the patch was asked
        # for: the conforming placement's border particles (at the FE nodes) are closer than the
        # grid, and a kernel sized on them leaves the interior particles of a coarse grid with
        # too few neighbours (singular corrections at spacing 1.5 h)
        self.spacing = max(particle_spacing_median(patch.particles.positions), patch.spacing or 0.0)
        if particles == "centred":
            patch = copy.copy(patch)
            patch.particles = centred_particles(patch, self.spacing)
        #: The patch whose particles carry the particle field (a copy with the SPH particles of
        #: ``particles="centred"``).
        self.V, self.patch, self.material = V, patch, material
        P = patch.particles
        self.smoothing_length = float(smoothing) * self.spacing
        msh = V.mesh
        q0 = cell_quadrature(msh, 1)
        area = np.bincount(np.searchsorted(np.unique(q0.cells), q0.cells), weights=q0.weights)
        s = comm.allreduce(np.array([np.sqrt(area).sum(), area.size], dtype=float), op=MPI.SUM)
        self.cell_size = float(s[0] / s[1])
        ratio = self.cell_size / self.spacing
        if quadrature_degree is None:
            quadrature_degree = 2 * max(2, math.ceil(2.0 * ratio - 1e-9)) - 1
        if hybrid_degree is None:
            hybrid_degree = 2 * max(1, math.ceil(ratio - 1e-9)) - 1
        self.quadrature_degree, self.hybrid_degree = int(quadrature_degree), int(hybrid_degree)
        radius = 2.0 * self.smoothing_length
        self.hybrid = hybrid_points(V, patch.fe_cells, P.positions, radius, self.hybrid_degree)
        hp = self.hybrid
        #: The hybrid sums: particles first, then the FE integration points (eq. 125-126).
        self.sph = raise_on_all_ranks(
            comm,
            lambda: CorrectedSPH(
                np.vstack([P.positions, hp.points]),
                np.concatenate([P.volumes, hp.weights]),
                self.smoothing_length,
            ),
        )
        #: The particles' own interpolant: displacement in the patch, loads, masses.
        self.evaluator = raise_on_all_ranks(
            comm, lambda: CorrectedSPH(P.positions, P.volumes, self.smoothing_length)
        )
        # the sums stop at the gaps between the mesh's bodies (a projectile and its target):
        # each body's sums are over its own particles and hybrid points (approx.body_cuts)
        cut = body_cut(self.sph.points, self.sph.support, msh)
        if cut is not None:
            self.sph.pair_cuts.append(cut)
            self.evaluator.pair_cuts.append(cut.subset(np.arange(P.num_particles)))
        self._smoothing: SmoothingCells | None = None
        self._hoop: sp.csr_matrix | None = None
        self._setup = time.perf_counter() - t0

    @property
    def comm(self) -> MPI.Comm:
        """The patch's communicator."""
        return self.patch.comm

    # -- numbering ------------------------------------------------------------------------------

    def node_map(self) -> sp.csr_matrix:
        """``Z = diag(I, E)``: values of the hybrid sums' points from [particles | FE nodes]."""
        n = self.patch.particles.num_particles
        return sp.bmat([[sp.identity(n, format="csr"), None], [None, self.hybrid.interpolation]])

    def dof_map(self) -> np.ndarray:
        """Combined dof of each interleaved column ``2 c + i`` of [particles | FE nodes]:
        particle PETSc dofs ``0 .. 2n-1``, then ``2n +`` the FE global dofs."""
        P = self.patch.particles
        n = P.num_particles
        N = self.hybrid.interpolation.shape[1]
        return np.concatenate([P.petsc_dofs(2).ravel(), 2 * n + np.arange(2 * N)])

    def split(self, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exterior facets beside FE cells and beside patch cells."""
        msh = self.V.mesh
        msh.topology.create_connectivity(msh.topology.dim - 1, msh.topology.dim)
        f2c = msh.topology.connectivity(msh.topology.dim - 1, msh.topology.dim)
        first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
        on_p = self.patch.in_patch[first]
        return facets[~on_p], facets[on_p]

    # -- stress points --------------------------------------------------------------------------

    def smoothing_cells(self) -> SmoothingCells:
        """This rank's smoothing cells (``"smoothed"``): ``(quadrature_degree + 1) // 2``
        sub-cells per patch cell and direction, as many as the Gauss points of ``"cells"``."""
        if self._smoothing is None:
            n = max(1, (self.quadrature_degree + 1) // 2)
            degree = 2 if self.material.axisymmetric else 1  # axisymmetric edges carry r u
            self._smoothing = smoothing_cells(
                self.V.mesh, self.patch.cells, self.patch.in_patch, n, degree
            )
        return self._smoothing

    def hoop(self) -> sp.csr_matrix | None:
        """For an axisymmetric law, the hoop strain ``N_c / r`` (m x (n + N)) of the hybrid
        sums' functions over [particles | FE nodes] at this rank's :meth:`stress_points` (with
        ``"smoothed"`` the smoothing cells' centroids: the smoothed hoop ``int_k (u_r / r) 2 pi
        r dA / V_k = N_c(x_k) / r_k``), computed once; ``None`` in plane (collective for the
        error). The functions reproduce linear fields
        (:class:`~dolfinx_meshfree.couplings.hybrid_sph.CorrectedSPH`), so ``u_r = a r`` has
        the hoop strain ``a``; these points never lie on the axis."""
        if not self.material.axisymmetric:
            return None
        if self._hoop is None:
            points = self.stress_points().points
            t = raise_on_all_ranks(self.comm, lambda: self.sph.tabulate(points, 0))
            values = (t.values @ self.node_map()).tocsr()
            self._hoop = raise_on_all_ranks(
                self.comm, lambda: axisymmetry.hoop_table(values, points)
            )
        return self._hoop

    def stress_points(self) -> QuadraturePoints:
        """This rank's stress points of the particle energy: Gauss points of its patch cells
        (``"cells"``), the centroids of the smoothing cells with their areas (``"smoothed"``)
        or its owned particles with their volumes (``"particles"``)."""
        if self.integration == "cells":  # axisymmetric: revolved, 2 pi r w
            q = cell_quadrature(self.V.mesh, self.quadrature_degree, self.patch.cells)
            return axisymmetry.revolved_if(q, self.material)
        if self.integration == "smoothed":  # axisymmetric: 2 pi r_c |Omega_k| (Pappus)
            sc = self.smoothing_cells()
            q = QuadraturePoints(sc.centroids, sc.areas, sc.cells)
            return axisymmetry.revolved_if(q, self.material)
        P = self.patch.particles
        own = P.owned
        return QuadraturePoints(
            P.positions[own], P.volumes[own], np.full(own.size, -1, dtype=np.int64)
        )


def global_facets(msh: dolfinx.mesh.Mesh, facets: np.ndarray) -> np.ndarray:
    """The given owned facets of every rank, as local facet indices of this rank where it
    holds them (collective): an exterior facet that one rank owns may bound a cell that another
    rank owns."""
    fmap = msh.topology.index_map(msh.topology.dim - 1)
    n_local = fmap.size_local + fmap.num_ghosts
    to_global = np.asarray(fmap.local_to_global(np.arange(n_local, dtype=np.int32)))
    wanted = np.concatenate(msh.comm.allgather(to_global[np.asarray(facets, dtype=np.int64)]))
    return np.flatnonzero(np.isin(to_global, wanted))
