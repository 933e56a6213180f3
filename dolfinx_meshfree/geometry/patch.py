"""A particle patch: cells of an existing DOLFINx mesh whose displacement is carried by particles.

The patch cells become EFG integration cells filled with particles; the other cells stay finite
elements. The patch knows the facets that separate the two (the interface, Rabczuk et al. 2006,
sec. 5.4) and its exterior facets, and tags cells 1 (FE) and 2 (particles) for restricting the
user's forms. Requires a mesh whose ranks share ghost cells across facets (DOLFINx's default
``GhostMode.shared_facet``) so that interface facets on partition boundaries see both sides.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import dolfinx
import numpy as np
import numpy.typing as npt

from .. import _compat
from ..parallel import raise_on_all_ranks
from .adaptive_quadrature import AdaptiveQuadrature
from .crack import CRACK_METHODS, Crack, place_crack
from .particles import ParticleSet
from .quadrature import require_affine

if TYPE_CHECKING:  # annotations only
    from mpi4py import MPI

__all__ = ["FE_TAG", "PATCH_TAG", "PLACEMENTS", "ParticlePatch"]

FE_TAG = 1
PATCH_TAG = 2

#: Particle placements of a :class:`ParticlePatch` (the first is the default).
PLACEMENTS = ("conforming", "grid", "vertices")


class ParticlePatch:
    """Cells of ``mesh`` to be modelled with particles.

    Args:
        mesh: The user's mesh (1D, 2D or 3D, degree-1 geometry, ghosted across facets in
            parallel).
        cells: Local indices of the cells to replace, owned or ghost (as
            ``dolfinx.mesh.locate_entities`` gives them on each rank): a cell named on any rank
            joins the patch, on the rank that owns it (:attr:`cells` are then owned cells).
        spacing: Particle spacing of ``placement="conforming"`` or ``"grid"`` (any positive value;
            0.5 to 1.5 times the element size is the tested range). Must be ``None`` with
            ``placement="vertices"``.
        jitter: Random displacement of interior particles, as a fraction of the spacing.
        placement: ``"conforming"`` (default): a regular grid of the given spacing in the patch
            cells plus a boundary-conforming layer: a particle on every vertex of the patch
            border (interface and exterior facets) and along its facets at about the spacing,
            grid points closer than half a spacing to the border dropped (see
            :meth:`ParticleSet.from_cells` with ``border``). Every coupling works with it
            whatever the cells and spacing: the border has particles at its ends however it is
            shaped (slanted, staircase, curved), and the interface nodes are particles, as the
            ramp couplings need (Belytschko et al. 1995, sec. 3.2). When the border lies on the
            grid lines and the spacing divides the element size it is the grid itself. In 3D
            (tetrahedra, hexahedra) the layer covers the border's triangles or quadrilaterals:
            particles on their vertices, along their edges and on a lattice inside each, at
            about the spacing, and a particle at the centroid of a cell left without one off the
            border (:mod:`~dolfinx_meshfree.geometry.placement_3d`); the same particles on any
            number of ranks. The 3D couplings (lagrange, edge-to-edge, bridging) pass the patch
            test with it at 0.5 to 0.75 times the element size; at the element size and above
            the border facets carry only their vertices (see the 3D guide).
            ``"grid"``: the grid alone, clipped to the cells (the earlier default; near a border
            off the grid lines it can leave too few particles). ``"vertices"``: one particle at
            every vertex of the patch cells (:meth:`ParticleSet.from_vertices`).
        cracks: :class:`~dolfinx_meshfree.Crack` polylines in the patch (:meth:`add_crack`).
        crack_method: ``"diffraction"`` (default) or ``"visibility"``: how the cracks cut the
            MLS weights (:mod:`~dolfinx_meshfree.approx.crack_cuts`).
        crack_enrichment: Enrich the MLS basis around the crack tips with the near-tip functions
            (:mod:`~dolfinx_meshfree.approx.tip_enrichment`, Fleming et al. 1997): SIF errors
            6-17x smaller at equal dofs; ``False`` (default): the linear basis.
        quadrature: An :class:`~dolfinx_meshfree.AdaptiveQuadrature` for the patch cells
            (dense near the crack tips, coarse elsewhere; lagrange, edge-to-edge, bridging),
            or ``None`` (default): the problem's uniform ``quadrature_degree``.

    Attributes:
        particles: The :class:`ParticleSet`.
        in_patch: bool per local cell (owned and ghost).
        interface_facets: Owned facets between a patch cell and an FE cell; with
            ``interface_patch_cells`` and ``interface_fe_cells`` the local cell on each side.
        exterior_facets: Owned exterior facets of patch cells.
        cell_tags: ``MeshTags`` of the owned cells: ``FE_TAG`` or ``PATCH_TAG``.
        cracks: The cracks added (:meth:`add_crack`).
    """

    def __init__(
        self,
        mesh: dolfinx.mesh.Mesh,
        cells: npt.ArrayLike,
        spacing: float | None = None,
        jitter: float = 0.0,
        seed: int = 0,
        placement: str = "conforming",
        cracks: Sequence[Crack] = (),
        crack_method: str = "diffraction",
        crack_enrichment: bool = False,
        quadrature: AdaptiveQuadrature | None = None,
    ) -> None:
        comm = mesh.comm
        require_affine(mesh, "ParticlePatch")
        # what :meth:`grown` builds the larger patch with
        self._options = {
            "spacing": spacing, "jitter": jitter, "seed": seed, "placement": placement,
            "crack_method": crack_method, "crack_enrichment": crack_enrichment,
            "quadrature": quadrature,
        }  # fmt: skip
        if quadrature is not None and not isinstance(quadrature, AdaptiveQuadrature):
            raise ValueError(
                f"quadrature={quadrature!r}: give an AdaptiveQuadrature(radius=..., near=..., "
                "far=...) or None (the problem's uniform quadrature_degree)"
            )
        self.quadrature = quadrature
        if crack_method not in CRACK_METHODS:
            raise ValueError(
                f"crack_method={crack_method!r} is not known; use one of {list(CRACK_METHODS)}"
            )
        if placement not in PLACEMENTS:
            raise ValueError(f"placement={placement!r} is not known; use one of {list(PLACEMENTS)}")
        if placement != "vertices" and spacing is None:
            raise ValueError("spacing=None: give the particle spacing, or placement='vertices'")
        if placement == "vertices" and (spacing is not None or jitter):
            raise ValueError(
                f"placement='vertices' puts the particles on the cells' vertices; spacing="
                f"{spacing!r} and jitter={jitter!r} must be left out"
            )
        tdim = mesh.topology.dim
        cmap = mesh.topology.index_map(tdim)
        num_owned = cmap.size_local
        num_local = num_owned + cmap.num_ghosts

        def check() -> np.ndarray:
            if cells is None:
                raise ValueError(
                    "cells=None: give the patch's cells, this rank's local cell indices (e.g. "
                    "mf.cells_near(mesh, crack.points, r) about a crack, or np.flatnonzero of a "
                    "marker on the cells' midpoints); a build(crack, cells=None) for an adaptive "
                    "patch is first called without cells and must then choose the starting patch"
                )
            c = np.asarray(cells)
            if c.ndim != 1 or (c.size and not np.issubdtype(c.dtype, np.integer)):
                raise ValueError(f"cells should be a 1D array of cell indices, got {c!r:.80}")
            c = c.astype(np.int64)
            if c.size and (c.min() < 0 or c.max() >= num_local):
                bad = c[(c < 0) | (c >= num_local)]
                raise ValueError(
                    f"cells has {bad.size} index(es) that are not cells of the mesh on this rank "
                    f"(valid: 0..{num_local - 1}, owned and ghost cells, as "
                    f"dolfinx.mesh.locate_entities returns them), e.g. {bad[:5].tolist()}"
                )
            return np.unique(c)

        given = raise_on_all_ranks(comm, check)
        # Ghost cells are accepted (dolfinx.mesh.locate_entities lists them on every rank that
        # sees them): a ghost cell given on any rank joins the patch on its owner, through a DG0
        # marker summed into the owners; the patch is the union of what the ranks name.
        Q = _compat.scalar_function_space(mesh, "DG", 0)
        marker = dolfinx.fem.Function(Q)
        dof_of_cell = _compat.dofmap_array(Q)[:, 0]
        marker.x.array[:] = 0.0
        marker.x.array[dof_of_cell[given]] = 1.0
        _compat.scatter_reverse_add(marker)
        c = np.flatnonzero(marker.x.array[dof_of_cell[:num_owned]] > 0.5).astype(np.int64)
        if comm.allreduce(c.size) == 0:
            raise ValueError("the patch is empty: cells names no cell on any rank")
        self.mesh = mesh
        self.cells = c
        # patch membership of ghost cells, through the same marker
        marker.x.array[:] = 0.0
        marker.x.array[dof_of_cell[c]] = 1.0
        marker.x.scatter_forward()
        self.in_patch = marker.x.array[dof_of_cell[:num_local]] > 0.5
        self.fe_cells = np.flatnonzero(~self.in_patch[:num_owned]).astype(np.int32)

        mesh.topology.create_connectivity(tdim - 1, tdim)
        f2c = mesh.topology.connectivity(tdim - 1, tdim)
        fmap = mesh.topology.index_map(tdim - 1)
        nf = fmap.size_local
        offsets = np.asarray(f2c.offsets)[: nf + 1]
        adj = np.asarray(f2c.array)
        count = np.diff(offsets)
        first = adj[offsets[:-1]]
        second = np.where(count > 1, adj[np.minimum(offsets[:-1] + 1, adj.size - 1)], -1)
        exterior = np.zeros(nf, dtype=bool)
        ext = dolfinx.mesh.exterior_facet_indices(mesh.topology)
        exterior[ext[ext < nf]] = True
        if np.any((count == 1) & ~exterior):
            raise ValueError(
                "the mesh has no ghost cells across partition boundaries; create it with "
                "ghost_mode=dolfinx.mesh.GhostMode.shared_facet (the default) for a patch"
            )
        two = count == 2
        p1 = np.where(two, self.in_patch[first], False)
        p2 = np.where(two, self.in_patch[np.maximum(second, 0)], False)
        iface = two & (p1 != p2)
        self.interface_facets = np.flatnonzero(iface).astype(np.int32)
        f, s = first[iface], second[iface]
        self.interface_patch_cells = np.where(self.in_patch[f], f, s).astype(np.int64)
        self.interface_fe_cells = np.where(self.in_patch[f], s, f).astype(np.int64)
        ext_patch = exterior & self.in_patch[first]
        self.exterior_facets = np.flatnonzero(ext_patch).astype(np.int32)
        self.exterior_cells = first[ext_patch].astype(np.int64)

        owned = np.arange(num_owned, dtype=np.int32)
        values = np.where(self.in_patch[:num_owned], PATCH_TAG, FE_TAG).astype(np.int32)
        self.cell_tags = dolfinx.mesh.meshtags(mesh, tdim, owned, values)
        self.placement = placement
        #: The particle spacing asked for (``None`` with ``placement="vertices"``).
        self.spacing = None if spacing is None else float(spacing)
        if placement == "vertices":
            self.particles = ParticleSet.from_vertices(mesh, c)
        else:
            border = None
            if placement == "conforming":
                facets = self.boundary()[0]
                geo = _compat.entities_to_geometry(mesh, tdim - 1, facets)
                # (facets, nodes per facet, 3): end points, triangles or quadrilaterals
                border = mesh.geometry.x[geo]
            self.particles = ParticleSet.from_cells(
                mesh, spacing, c, jitter=jitter, seed=seed, border=border
            )
        self.crack_method = crack_method
        self.crack_enrichment = bool(crack_enrichment)
        self.cracks: list[Crack] = []
        for crack in cracks:
            self.add_crack(crack)

    def add_crack(self, crack: Crack) -> None:
        """Put ``crack`` into the patch (collective): checked by
        :func:`~dolfinx_meshfree.geometry.crack.validate_in_patch` (inside the patch cells, tips
        at least one particle spacing from the FE interface and the exterior boundary, no
        particle on the crack; a ``ValueError`` on every rank otherwise), which also decides its
        tips and mouths; later :meth:`Crack.extend` calls are checked the same way."""
        place_crack(crack, self)
        self.cracks.append(crack)

    def grown(self, cells: npt.ArrayLike) -> ParticlePatch:
        """A new patch of this patch's cells and ``cells`` (local indices, owned or ghost, as
        for the constructor), with the same spacing, placement, jitter and crack options
        (collective). Its particles are placed afresh, as at build time: the grid's points
        stay where they were, the conforming layer moves to the new border. The cracks are
        not carried over: a model rebuilt on it places them (:meth:`add_crack`) after
        :meth:`Crack.release` from this patch."""
        extra = np.asarray(cells)
        if extra.ndim != 1 or (extra.size and not np.issubdtype(extra.dtype, np.integer)):
            raise ValueError(f"cells should be a 1D array of cell indices, got {extra!r:.80}")
        union = np.union1d(self.cells, extra.astype(np.int64))
        return ParticlePatch(self.mesh, union, **self._options)

    @property
    def comm(self) -> MPI.Comm:
        """The communicator of the mesh."""
        return self.mesh.comm

    def boundary(self) -> tuple[np.ndarray, np.ndarray]:
        """The whole boundary of the patch: (facets, the patch cell beside each); outward normals
        of :func:`~dolfinx_meshfree.facet_quadrature` with these cells point out of the patch."""
        return (
            np.concatenate([self.exterior_facets, self.interface_facets]),
            np.concatenate([self.exterior_cells, self.interface_patch_cells]),
        )
