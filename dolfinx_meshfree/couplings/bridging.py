"""FE–EFG bridging domain coupling (Belytschko & Xiao 2004; Rabczuk et al. 2006, sec. 5.3).

The FE discretisation lives on the FE cells and on a band of ``overlap`` layers of patch cells
beside the interface (the overlapping subdomain Omega_int); the particles fill the whole patch,
band included. In the band both energies are weighted (eq. 46–48)

.. math::
    \\beta^{FE} = 1 - \\alpha, \\qquad \\beta^{P} = \\alpha,

with ``alpha`` linear across the band: 0 on its FE-side edge (the interface of the
:class:`~dolfinx_meshfree.ParticlePatch`), 1 on its particle-side edge. ``alpha`` is the FE
interpolant of the node layer index: the interface nodes are layer 0, the nodes of patch cells
touching layer ``k - 1`` are layer ``k``; ``alpha = layer / overlap`` (for a straight interface
and uniform cells, the distance to the interface over the band width). The band cells are the
patch cells whose nodes all lie in layers ``0..overlap``.

Displacements are tied with a multiplier field ``lambda = sum_k N_k lambda_k`` on the FE nodes
of the band, by default over the band cells by Gauss quadrature (``constraint="integral"``,
eq. 52: ``x_L``, ``c_L`` below are the Gauss points and weights), or at the particles ``x_L`` of
the band (closed band cells, unit weights, ``constraint="points"``, eq. 52–53, 57, 79–80):

.. math::
    L^{FE}_{k a} = \\sum_L N_k(x_L) N_a(x_L) c_L, \\qquad
    L^{P}_{k J} = -\\sum_L N_k(x_L) \\phi_J(x_L) c_L,

i.e. ``sum_L lambda(x_L) (u_FE(x_L) - u_P(x_L)) c_L = 0`` for every multiplier field. The optional
augmented-Lagrangian penalty ``p`` (eq. 54, 72–75) adds ``p G^T G`` to the displacement blocks,
with the pointwise constraint gradients ``G^FE = [N_a(x_L)]``, ``G^P = [-phi_J(x_L)]`` (eq. 81).

Assembly: ``K_FE`` is DOLFINx's assembly of the FE form (the material's, or the user's form of a
:class:`~dolfinx_meshfree.CoupledLinearProblem`) weighted by ``beta_FE``: 1 on FE cells,
``1 - alpha`` on band cells with ``alpha`` a P1 function (DG0 indicators select the cells);
``K_P`` is the EFG stiffness by Gauss quadrature on all patch cells with the
weights multiplied by ``alpha`` in the band. Tractions and body loads are weighted the same way
(eq. 49).
Essential conditions: strongly on FE nodes of Dirichlet facets of FE and band cells, by
piecewise-constant facet multipliers on the particles of Dirichlet facets of patch cells (band
included: both discretisations live there). Constraint rows are scaled by ``s = E``.

Stair steps of a slanted or curved interface (issue 23, item 7): a band cell whose nodes all
lie on the interface has ``alpha = 0`` throughout, i.e. the weights ``beta_FE = 1``,
``beta_P = 0`` of ``Omega_FE - Omega_int`` (eq. 47-48). It is FE territory: the constraint
(eq. 52, 57) and the multiplier nodes leave it out (``BridgingBand.tied``). A particle whose
support meets the patch's quadrature only in such cells has no energy, no load and no constraint
(eq. 61-62 vanish for it, eq. 56 is empty): it is held at 0 (:func:`_held_particles`) instead of
leaving the system singular or the VCI dividing by its zero ``alpha``-weighted integral (the
refusal "shape function ... integrates to ~0" of a 32 x 16 model with a slanted patch at
spacing h/2). The linear patch test stays exact.

Variationally consistent integration (``consistent=True``, the default of
:class:`~dolfinx_meshfree.CoupledElasticity`): the particle test gradients are corrected under the
weight ``alpha`` so that the linear patch test passes to round-off on any mesh, with either
constraint (see :func:`_consistent_test_gradients`); the particle stiffness is then not
symmetric. The dynamic operators (:func:`bridging_operators`) use the same stiffness.
"""

from __future__ import annotations

import numbers
import time
from typing import TYPE_CHECKING, Any, ClassVar

import dolfinx
import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.sparse.linalg import spsolve

from .. import _compat
from ..approx.fe_points import locate_points, tabulate_in_cells
from ..geometry.crack import particle_spacing, polyline_samples
from ..geometry.quadrature import QuadraturePoints, cell_quadrature, facet_quadrature
from ..parallel import Layout, raise_on_all_ranks
from ..physics.axisymmetry import (
    approximation_hoop,
    axisymmetric_stiffness,
    hoop_table,
    revolved_if,
)
from ..physics.operators import consistent_gradients, load_vector, stiffness_matrix
from ..physics.user_functions import vector_values
from ..statics.efg import crack_rules
from ..statics.kept_factor import KeptFactorisation
from ..statics.petsc import SolverOptions, create_aij, create_vector
from .assembly import (
    append_patch_conditions,
    body_loads,
    essential_conditions,
    fe_active,
    fe_stiffness,
    fix_fe_rows,
    fixed_dofs,
    patch_facet_rule,
    pin_forces,
    sizes,
    solve_and_gather,
    split_facets,
    strong_values,
)
from .base import (
    CoupledSolution,
    CouplingDefaults,
    CouplingOperators,
    facet_nodes,
    fe_constraint_block,
    fe_dof_layout,
    node_flags,
    particle_constraint_block,
)

if TYPE_CHECKING:  # annotations only: the model imports this module
    from ..statics.coupled import CoupledElasticity

__all__ = [
    "BAND_TIE",
    "CONSTRAINTS",
    "BridgingBand",
    "BridgingSolution",
    "bridging_operators",
    "check_options",
]


#: Where the bridging constraint is imposed: by Gauss quadrature over the band cells (the
#: integral of eq. 52, the default) or at the band particles (eq. 79-81).
CONSTRAINTS = ("points", "integral")

#: Relative tie tolerance of a band of a physical width: a node whose distance to the interface
#: is within ``BAND_TIE * band_width`` of the width is at the width (``alpha = 1``, outside the
#: band). Distances are computed to round-off (about 1e-16 of the width), so exact ties (a width
#: of whole cells) fall on one side on every rank and in every lane.
BAND_TIE = 1e-10


def check_options(
    overlap: int, penalty: float, constraint: str = "integral", band_width: float | None = None
) -> tuple[int, float, str, float | None]:
    """Validate the ``overlap`` (positive integer), ``penalty`` (finite, >= 0),
    ``constraint`` (one of :data:`CONSTRAINTS`) and ``band_width`` (``None`` or finite > 0)
    options."""
    if band_width is not None and (
        isinstance(band_width, bool)
        or not isinstance(band_width, numbers.Real)
        or not (np.isfinite(band_width) and band_width > 0)
    ):
        raise ValueError(
            f"band_width must be None (a band of `overlap` cell layers) or a positive length, "
            f"got {band_width!r}"
        )
    if constraint not in CONSTRAINTS:
        raise ValueError(f"constraint={constraint!r} is not known; use one of {list(CONSTRAINTS)}")
    if isinstance(overlap, bool) or not isinstance(overlap, numbers.Integral) or overlap < 1:
        raise ValueError(f"overlap must be a positive integer (cell layers), got {overlap!r}")
    if isinstance(penalty, bool) or not isinstance(penalty, numbers.Real):
        raise ValueError(f"penalty must be a real number >= 0, got {penalty!r}")
    if not (np.isfinite(penalty) and penalty >= 0.0):
        raise ValueError(f"penalty must be finite and >= 0, got {penalty!r}")
    return (
        int(overlap),
        float(penalty),
        constraint,
        None if band_width is None else float(band_width),
    )


def _segment_distance2(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared distances (points x segments) of points (m, d) to the segments ``[a, b]``."""
    ab = b - a
    ab2 = np.einsum("fi,fi->f", ab, ab)
    ap = x[:, None, :] - a[None]
    t = np.clip(np.einsum("nfi,fi->nf", ap, ab) / ab2, 0.0, 1.0)
    gap = ap - t[..., None] * ab[None]
    return np.einsum("nfi,nfi->nf", gap, gap)


def distance_to_facets(x: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Distance of points (m, gdim) to the nearest of the facets (f, nv, gdim): segments
    (``nv = 2``), triangles (3) or quadrilaterals (4, DOLFINx's vertex order, taken as the two
    triangles 0-1-3 and 0-3-2: exact on planar faces). Local."""
    if facets.shape[1] == 2:
        return np.sqrt(_segment_distance2(x, facets[:, 0], facets[:, 1]).min(axis=1))
    tri = (
        facets
        if facets.shape[1] == 3
        else np.concatenate([facets[:, [0, 1, 3]], facets[:, [0, 3, 2]]])
    )
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    # the foot of the perpendicular in barycentric coordinates: inside, the plane's distance
    g = np.stack([np.einsum("fi,fi->f", e1, e1), np.einsum("fi,fi->f", e1, e2)], axis=1)
    g22 = np.einsum("fi,fi->f", e2, e2)
    det = g[:, 0] * g22 - g[:, 1] ** 2
    ap = x[:, None, :] - a[None]
    r1, r2 = np.einsum("nfi,fi->nf", ap, e1), np.einsum("nfi,fi->nf", ap, e2)
    s = (g22 * r1 - g[:, 1] * r2) / det
    t = (g[:, 0] * r2 - g[:, 1] * r1) / det
    foot = ap - s[..., None] * e1[None] - t[..., None] * e2[None]
    inside = (s >= 0.0) & (t >= 0.0) & (s + t <= 1.0)
    d2 = np.where(inside, np.einsum("nfi,nfi->nf", foot, foot), np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):  # else the nearest edge
        d2 = np.minimum(d2, _segment_distance2(x, tri[:, i], tri[:, j]))
    return np.sqrt(d2.min(axis=1))


class BridgingBand:
    """The overlap band of a :class:`~dolfinx_meshfree.CoupledElasticity` (collective).

    Two constructions of the band and of ``alpha`` (a P1/Q1 function, 0 on the interface):

    * ``band_width=None``: ``overlap`` cell layers, ``alpha = layer / overlap`` (the node
      layer index, see the module docstring);
    * ``band_width=w`` (a length): the patch cells with a node closer than ``w`` to the
      interface, ``alpha = min(d / w, 1)`` at the nodes with ``d`` the distance to the interface
      facets (``d >= (1 - BAND_TIE) w`` counts as ``d = w``: ties are outside): a band of a
      physical width whatever the cells, which on a curved, unstructured interface does not
      narrow or fray under refinement as layers of cells do.

    Raises ``ValueError`` on every rank when the patch has no interface or when the band of
    layers is wider than the patch (fewer than ``overlap`` layers of patch cells beside the
    interface).

    The overlapping subdomain proper, where the constraint of eq. 52 and 57 ties the two fields,
    is the band without the cells where ``alpha`` vanishes identically (``tied``): a patch cell
    whose nodes all lie on the interface (a stair step of a slanted or curved interface, FE
    cells on three sides) has ``beta_FE = 1`` and ``beta_P = 0`` there (eq. 47-48), the
    weights of ``Omega_FE - Omega_int``, so it is FE territory and no part of ``Omega_int``.
    Where no such cell exists, ``tied`` is ``in_band``.

    Attributes:
        layer: Node layer index per local node (``overlap + 1`` beyond the band or off it);
            ``None`` for a band of a width.
        in_band_node: bool per local node: a node of the band (of a band cell).
        alpha: ``alpha`` per local node (``layer / overlap`` or ``min(d / w, 1)`` on band nodes,
            1 elsewhere).
        in_band: bool per local cell (owned and ghost): a band cell.
        cells: Owned band cells (local indices).
        tied: bool per local cell: a band cell where ``alpha`` is not identically 0 (a node
            with ``alpha > 0``): the cells of the constraint.
        tied_cells: Owned ``tied`` cells (local indices).
        tied_node: bool per local node: a node of a ``tied`` cell (the multiplier nodes).
        particles: Indices of the band particles (in closed ``tied`` cells: the points of
            ``constraint="points"``), on every rank.
        local_particles: The band particles this rank handles, with ``local_cells``, the owned
            cell each lies in (each band particle is handled by exactly one rank).
        held: Indices of the particles held at 0 because ``alpha = 0`` on their whole support
            (:func:`_held_particles`), on every rank; set by the assembly of the static system
            (empty until then).
    """

    def __init__(self, problem, overlap: int, band_width: float | None = None):
        V, patch = problem.V, problem.patch
        msh, comm = V.mesh, patch.comm
        self.V, self.mls, self.overlap, self.band_width = V, problem.mls, overlap, band_width
        tdim = msh.topology.dim
        if comm.allreduce(len(patch.interface_facets)) == 0:
            raise ValueError(
                "the bridging coupling needs an interface between FE and patch cells; the patch "
                "has none"
            )
        dofs = _compat.dofmap_array(V)
        self.coordinates = V.tabulate_dof_coordinates()[:, : msh.geometry.dim]
        iface = dolfinx.fem.locate_dofs_topological(V, tdim - 1, patch.interface_facets)
        on_interface = node_flags(problem.V, iface)
        ncl = patch.in_patch.size
        if band_width is None:
            self.layer, self.alpha = self._layers(problem, overlap, on_interface)
            self.in_band_node = self.layer <= overlap
            self.in_band = patch.in_patch & self.in_band_node[dofs[:ncl]].all(axis=1)
        else:
            self.layer = None
            alpha = self._interface_distance(problem, on_interface) / band_width
            # a node at the band's width (a tie: a width of whole cells on a uniform mesh) is
            # outside, whatever the round-off of its distance on this rank
            alpha = np.where(alpha >= 1.0 - BAND_TIE, 1.0, alpha)
            self.in_band = patch.in_patch & (alpha[dofs[:ncl]] < 1.0).any(axis=1)
            n_cells = msh.topology.index_map(tdim).size_local
            self.in_band_node = node_flags(
                problem.V, dofs[:n_cells][self.in_band[:n_cells]].ravel()
            )
            self.alpha = np.where(self.in_band_node, alpha, 1.0)
        n_cells = msh.topology.index_map(tdim).size_local
        self.cells = np.flatnonzero(self.in_band[:n_cells]).astype(np.int32)
        # Omega_int proper: the band cells with a node where alpha > 0 (the P1/Q1 alpha >= 0
        # vanishes identically on a cell exactly when it vanishes at all its nodes)
        self.tied = self.in_band & (self.alpha[dofs[:ncl]] > 0.0).any(axis=1)
        self.tied_cells = np.flatnonzero(self.tied[:n_cells]).astype(np.int32)
        self.tied_node = node_flags(problem.V, dofs[:n_cells][self.tied[:n_cells]].ravel())

        # band particles: those where the indicator of the tied cells (P1 interpolant of
        # tied_node) is 1, each handled by the lowest rank that owns a cell containing it
        x = patch.particles.positions
        cells = locate_points(msh, x)
        claim = np.where(cells >= 0, comm.rank, comm.size).astype(np.int32)
        owner = np.empty_like(claim)
        comm.Allreduce(claim, owner, op=MPI.MIN)
        mine = np.flatnonzero(owner == comm.rank)
        t = tabulate_in_cells(V, x[mine], cells[mine], derivatives=0).values
        indicator = t @ self.tied_node.astype(float)
        keep = indicator >= 1.0 - 1e-10
        self.local_particles = mine[keep]
        self.local_cells = cells[mine][keep]
        self.particles = np.sort(np.concatenate(comm.allgather(self.local_particles)))
        self.held = np.zeros(0, dtype=np.int64)
        self._refuse_bonded_cracks(patch)

    def _refuse_bonded_cracks(self, patch) -> None:
        """Refuse a crack through the band where the FE weight ``1 - alpha`` is not zero
        (collective; the same ``ValueError`` on every rank).

        The FE field of the band is not cut by a crack: its share ``1 - alpha`` of the band's
        energy (eq. 46-48) would bond the crack faces (in Kalthoff-Winkler, with the crack's
        mouth at the interface, K_II fell 18-29 % below pure EFG's). A crack may touch the band's
        particle-side edge, where ``alpha = 1``.
        """
        if not patch.cracks:
            return
        msh = self.V.mesh
        step = 0.25 * particle_spacing(patch)
        for crack in patch.cracks:
            samples = polyline_samples(crack.points, step)
            cells = locate_points(msh, samples)
            weight = np.zeros(samples.shape[0])
            mine = np.flatnonzero(cells >= 0)
            mine = mine[self.in_band[cells[mine]]]
            if mine.size:
                weight[mine] = 1.0 - self.alpha_at(samples[mine], cells[mine])
            patch.comm.Allreduce(MPI.IN_PLACE, weight, op=MPI.MAX)
            bonded = np.flatnonzero(weight > 1e-8)
            if bonded.size:
                k = bonded[0]
                raise ValueError(
                    f"the crack {np.round(crack.points, 12).tolist()} passes through the "
                    f"bridging band at {np.round(samples[k], 12).tolist()} (FE weight 1 - alpha = "
                    f"{weight[k]:.3g}): the band's FE field is not cut by a crack and would bond "
                    "its faces; keep the crack out of the band (overlap cell layers, or "
                    "band_width, beside the FE interface): enlarge the patch around the crack, cut "
                    "the FE mesh (a slot) through the band, or use coupling='lagrange'"
                )

    def _interface_distance(self, problem, on_interface: np.ndarray) -> np.ndarray:
        """Distance of every local node to the interface facets (segments gathered from every
        rank; 0 on the interface nodes). Collective."""

        patch, comm = problem.patch, problem.patch.comm
        corners = self.coordinates[facet_nodes(self.V, patch.interface_facets)]  # (f, nv, gdim)
        facets = np.concatenate(comm.allgather(corners))
        dist = np.empty(self.coordinates.shape[0])
        for chunk in np.array_split(np.arange(dist.size), max(1, dist.size // 2048)):
            dist[chunk] = distance_to_facets(self.coordinates[chunk], facets)
        dist[on_interface] = 0.0
        return dist

    def _layers(self, problem, overlap: int, on_interface: np.ndarray):
        """Node layer index (``overlap + 1`` beyond the band) and ``alpha = layer / overlap``
        (1 beyond the band). Collective."""
        V, patch, comm = self.V, problem.patch, problem.patch.comm
        dofs = _compat.dofmap_array(V)
        n_loc = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
        n_own = V.dofmap.index_map.size_local
        far = overlap + 1
        layer = np.full(n_loc, far, dtype=np.int64)
        layer[on_interface] = 0
        owned_patch = dofs[patch.cells]
        depth = 0
        for k in range(1, overlap + 1):
            touch = (layer[owned_patch] == k - 1).any(axis=1)
            flags = node_flags(problem.V, owned_patch[touch].ravel())
            new = flags & (layer == far)
            layer[new] = k
            if not comm.allreduce(bool(np.any(new[:n_own])), op=MPI.LOR):
                break
            depth = k
        if depth < overlap:
            raise ValueError(
                f"overlap={overlap} cell layers is wider than the patch: only {depth} layer(s) of "
                "patch cells lie beside the interface; choose a smaller overlap or a larger patch, "
                "or a band of a physical width (band_width=...)"
            )
        return layer, np.where(layer <= overlap, layer / overlap, 1.0)

    def alpha_at(
        self, points: np.ndarray, cells: np.ndarray, derivatives: int = 0
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """``alpha`` (m,) at points of local cells, and with ``derivatives`` its gradient."""
        t = tabulate_in_cells(self.V, points, cells, derivatives=derivatives)
        a = t.values @ self.alpha
        if not derivatives:
            return a
        return a, np.stack([g @ self.alpha for g in t.gradients], axis=1)

    def numbering(self, problem: CoupledElasticity) -> tuple[np.ndarray, Layout]:
        """Global multiplier (block) number of each local node of the tied cells (-1
        elsewhere); collective."""
        V, comm = self.V, problem.patch.comm
        n_owned = V.dofmap.index_map.size_local
        mine = np.flatnonzero(self.tied_node[:n_owned])
        layout = Layout.from_local(comm, mine.size)
        num = dolfinx.fem.Function(V)
        num.x.array[:] = 0.0
        bs = V.dofmap.index_map_bs
        num.x.array[bs * mine] = layout.start + np.arange(mine.size) + 1
        num.x.scatter_forward()
        ids = np.rint(num.x.array[0::bs]).astype(np.int64) - 1
        return ids, Layout(bs * layout.size_local, bs * layout.size_global, bs * layout.start)


class BridgingSolution(CoupledSolution):
    """:class:`~dolfinx_meshfree.CoupledSolution` of the bridging coupling: in band cells the
    field is the energy-weighted blend ``(1 - alpha) u_FE + alpha u_P`` (gradient by the product
    rule). ``band`` is the :class:`BridgingBand`."""

    band: BridgingBand | None = None

    def evaluate_at_quadrature(self, q: QuadraturePoints) -> tuple[np.ndarray, np.ndarray]:
        V = self.u.function_space
        gdim = V.mesh.geometry.dim
        local = self.u.x.array.reshape(-1, gdim)
        in_band = self.band.in_band[q.cells]
        inside = self.patch.in_patch[q.cells] & ~in_band
        fe = ~inside & ~in_band
        u = np.empty((len(q), gdim))
        g = np.empty((len(q), gdim, gdim))
        if np.any(fe):
            t = tabulate_in_cells(V, q.points[fe], q.cells[fe])
            u[fe], g[fe] = t.values @ local, t.gradient(local)
        if np.any(inside):
            t = self.mls.tabulate(q.points[inside])
            u[inside], g[inside] = t.values @ self.coefficients, t.gradient(self.coefficients)
        if np.any(in_band):
            pts, cells = q.points[in_band], q.cells[in_band]
            t = tabulate_in_cells(V, pts, cells)
            uf, gf = t.values @ local, t.gradient(local)
            t = self.mls.tabulate(pts)
            up, gp = t.values @ self.coefficients, t.gradient(self.coefficients)
            a, da = self.band.alpha_at(pts, cells, derivatives=1)
            u[in_band] = (1 - a)[:, None] * uf + a[:, None] * up
            g[in_band] = (
                (1 - a)[:, None, None] * gf
                + a[:, None, None] * gp
                + np.einsum("qi,qj->qij", up - uf, da)
            )
        return u, g


def _first_cells(msh, facets: np.ndarray) -> np.ndarray:
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    return np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]


def _fe_weight(problem, band: BridgingBand):
    """``beta_FE`` (eq. 47-48) as a UFL expression: 1 on FE cells, ``1 - alpha`` on band cells
    (alpha a P1 function), 0 on the rest of the patch."""
    V, patch = problem.V, problem.patch
    fe = problem.cell_indicator(~patch.in_patch & ~band.in_band)
    in_band = problem.cell_indicator(band.in_band)
    alpha = dolfinx.fem.Function(V)
    alpha.x.array[:] = 0.0
    alpha.x.array[0 :: V.dofmap.index_map_bs] = band.alpha
    return fe + in_band * (1.0 - alpha[0])


def _fe_stiffness(problem, band: BridgingBand) -> PETSc.Mat:
    """DOLFINx assembly of the FE form weighted by ``beta_FE`` (eq. 47-48, :func:`_fe_weight`)."""
    return fe_stiffness(problem, _fe_weight(problem, band))


def _body_loads(
    problem, band: BridgingBand, tables: dict | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The bridging coupling's shares of ``problem``'s body forces (eq. 49, collective): the FE
    basis weighted by ``beta_FE = 1 - alpha`` in the band and 1 on FE cells, the particles on the
    patch cells weighted by ``beta_P = alpha`` in the band and 1 beyond (a stress part with the
    stiffness's test gradients and weights ``alpha w_q`` in ``tables``). Returns the FE loads
    per owned dof and the particle loads (original interleaved order)."""

    def alpha(q: QuadraturePoints) -> np.ndarray:
        w = np.ones(len(q))
        b = band.in_band[q.cells]
        w[b] = band.alpha_at(q.points[b], q.cells[b])
        return w

    return body_loads(problem, _fe_weight(problem, band), alpha, tables=tables)


def _particle_rule(problem, band: BridgingBand) -> tuple:
    """The particles' rule: Gauss quadrature on the patch cells (cut cells side by side), its
    weights times ``alpha`` in the band (eq. 46), the MLS table there and, for an axisymmetric
    law, the hoop tables of the trial strain
    (:func:`~dolfinx_meshfree.physics.axisymmetry.approximation_hoop`) and of the test
    functions (the plain ``N / r`` under VCI, whose radial identity is the divergence theorem
    for ``N r e_r``; else the trial's); the rule then revolved, ``2 pi r w``, before
    ``alpha``. Returns ``(q, w, table, hoop, test_hoop)``, the hoops ``None`` in plane models
    (collective)."""
    msh, patch, comm = problem.V.mesh, problem.patch, problem.patch.comm
    deg, P = problem.quadrature_degree, problem.patch.particles
    q = crack_rules(msh, P.cells, patch.cracks, deg, None, quadrature=patch.quadrature)[0]
    q = q or cell_quadrature(msh, deg, P.cells)
    q = raise_on_all_ranks(comm, lambda: revolved_if(q, problem.material))
    w = q.weights.copy()
    b = band.in_band[q.cells]
    w[b] *= band.alpha_at(q.points[b], q.cells[b])
    tq = raise_on_all_ranks(comm, lambda: problem.mls.tabulate(q.points))
    hoop = test_hoop = None
    if problem.material.axisymmetric:
        hoop = test_hoop = raise_on_all_ranks(
            comm, lambda: approximation_hoop(problem.mls, msh, q, tq.values)
        )
        if problem.consistent:
            test_hoop = raise_on_all_ranks(comm, lambda: hoop_table(tq.values, q.points))
    return q, w, tq, hoop, test_hoop


def _particle_stiffness(problem, test: list, w: np.ndarray, tq, hoops: tuple) -> sp.csr_matrix:
    """``K_P`` (eq. 78) at the weights ``w`` (``alpha`` in the band), with ``test`` gradients
    (VCI's or the table's); axisymmetric: with the hoop rows, ``hoops = (trial, test)``
    (:func:`_particle_rule`; local particle numbering)."""
    hoop, test_hoop = hoops
    if hoop is not None:
        return axisymmetric_stiffness(
            test, test_hoop, w, problem.material, tq.gradients, trial_hoop=hoop
        )
    return stiffness_matrix(test, w, problem.material, tq.gradients)


def bridging_system(problem: CoupledElasticity, tables: dict | None = None) -> tuple:
    """The bridging-domain block system, assembled, not solved (collective); see
    :func:`~dolfinx_meshfree.couplings.lagrange.interface_system` for ``tables`` and the
    returned ``(blocks, rhs, mats, extra)``. ``extra`` also holds what a finite-strain solve
    needs: the external loads before lifting (``loads``), the cells where the FE law lives
    (``fe_cells``, FE and band cells) and its weight ``beta_FE`` (``fe_weight``, eq. 47-48), the
    particles' weights ``alpha w_q`` (``particle_weights``, eq. 49) and the penalty's
    constant diagonal blocks (``constant_diagonal``)."""
    V, patch, P = problem.V, problem.patch, problem.patch.particles
    comm = patch.comm
    msh = V.mesh
    deg = problem.quadrature_degree
    n = P.num_particles
    s = problem.material.E
    p = problem.penalty
    d = msh.geometry.dim
    pdofs = P.petsc_dofs(d)
    fe_layout, l2g = fe_dof_layout(problem.V)
    pl = P.dof_layout(d)
    t0 = time.perf_counter()

    band = BridgingBand(problem, problem.overlap, problem.band_width)
    tables = {} if tables is None else tables  # the stiffness's rule: the loads' stresses too

    # particle side: Gauss quadrature on the patch cells, weights times alpha in the band
    q, w, tq, hoop, test_hoop = _particle_rule(problem, band)
    held = band.held = _held_particles(problem, q, w, tq)  # alpha = 0 on their support

    # essential conditions: strongly on FE nodes of FE and band facets, multipliers on patch facets
    _, patch_bc, dq, dtabs, ubc, is_bc = essential_conditions(
        problem, lambda f_p: f_p[band.in_band[_first_cells(msh, f_p)]]
    )
    _weight_band_facets(band, dq)
    # active FE nodes: nodes of FE cells and band cells
    active = fe_active(problem, np.concatenate([patch.fe_cells, band.cells]))
    fixed_local = is_bc | ~active
    x_fix = np.where(np.repeat(is_bc, d), ubc.x.array, 0.0)

    # constraints at the band particles (or at the band cells' Gauss points, with weights)
    ids, ml = band.numbering(problem)
    t_fe, t_p, cw = _constraint_tables(problem, band)
    M_fe = (t_fe.T @ sp.diags(cw) @ t_fe).tocoo()
    M_p = (t_fe.T @ sp.diags(cw) @ t_p).tocoo()
    test = None
    if problem.consistent:
        test = _consistent_test_gradients(
            problem, band, q, w, tq, (t_fe, t_p, cw), ids, ml.size_global // d, held, test_hoop
        )
    setup = problem.setup_time + time.perf_counter() - t0
    tables.update(
        quadrature=q, table=tq, test_gradients=test or tq.gradients, weights=w,
        approximation=problem.mls,
    )  # fmt: skip
    if hoop is not None:
        tables["hoop"], tables["test_hoop"] = hoop, test_hoop

    t1 = time.perf_counter()
    Kq = _particle_stiffness(problem, test or tq.gradients, w, tq, (hoop, test_hoop)).tocoo()
    dof_map = pdofs.ravel()
    Kp_loc = sp.csr_matrix((Kq.data, (dof_map[Kq.row], dof_map[Kq.col])), shape=(d * n, d * n))
    hold = _hold_block(problem, held, dof_map, d * n)
    if hold is not None:
        Kp_loc = Kp_loc + hold
    keep = ids[M_fe.row] >= 0
    fe_rows = (ids[M_fe.row[keep]], M_fe.col[keep], M_fe.data[keep])
    keep = ids[M_p.row] >= 0
    p_rows = (ids[M_p.row[keep]], M_p.col[keep], M_p.data[keep])
    G_fe, g_rows, g_vals = fe_constraint_block(
        *fe_rows,
        False,
        s,
        fixed_dofs(problem, is_bc) | ~active[:, None],
        ubc,
        l2g,
        (ml.size_global, fe_layout.size_global),
    )
    G_p = particle_constraint_block(*p_rows, s, pdofs, (ml.size_global, d * n))

    # loads: tractions weighted by beta_FE and beta_P (eq. 49)
    f_fe_rows, f_fe_vals = [], []
    f_p = np.zeros(d * n)
    for facets, fn in problem.tractions:
        f_fe_facets, f_p_facets = split_facets(problem, facets)
        f_fe_facets = np.concatenate(
            [f_fe_facets, f_p_facets[band.in_band[_first_cells(msh, f_p_facets)]]]
        )
        fq = revolved_if(facet_quadrature(msh, f_fe_facets, deg), problem.material)
        t = raise_on_all_ranks(
            comm,
            lambda fn=fn, fq=fq: vector_values(fn, (fq.points, fq.normals), len(fq), "traction", d),
        )
        beta = np.where(band.in_band[fq.cells], 1.0 - band.alpha_at(fq.points, fq.cells), 1.0)
        tab = tabulate_in_cells(V, fq.points, fq.cells, derivatives=0).values
        fl = load_vector(tab, fq.weights * beta, t).reshape(-1, d)
        for comp in range(d):
            f_fe_rows.append(d * l2g[: fl.shape[0]] + comp)
            f_fe_vals.append(fl[:, comp])
        fq = revolved_if(patch_facet_rule(problem, f_p_facets), problem.material)
        t = raise_on_all_ranks(
            comm,
            lambda fn=fn, fq=fq: vector_values(fn, (fq.points, fq.normals), len(fq), "traction", d),
        )
        beta = np.where(band.in_band[fq.cells], band.alpha_at(fq.points, fq.cells), 1.0)
        tab = raise_on_all_ranks(comm, lambda fq=fq: problem.mls.tabulate(fq.points, 0)).values
        f_p += load_vector(tab, fq.weights * beta, t)
    cat = np.concatenate

    # augmented Lagrangian: p G^T G with the pointwise gradients G^FE = N, G^P = -phi (eq. 72-75)
    fe_dof = (d * l2g[:, None] + np.arange(d)).ravel()
    # every dof held strongly, components too: with whole nodes only a roller's penalty row
    # stayed and broke the patch test (3.3e-4 with rollers on band nodes)
    held_dofs, x_held = strong_values(problem, is_bc, ubc)
    fixed_dof = (held_dofs | fixed_local[:, None]).ravel()
    x_held = x_held.ravel()
    K_ff = K_fp = K_pf = A22g = None
    if p > 0.0:
        e2 = sp.identity(d, format="csr")
        root = sp.diags(np.sqrt(cw))
        Nf, Np = sp.kron(root @ t_fe, e2).tocsr(), sp.kron(root @ t_p, e2).tocsr()
        A11 = (p * (Nf.T @ Nf)).tocoo()
        A12 = (-p * (Nf.T @ Np)).tocoo()
        A22 = (p * (Np.T @ Np)).tocoo()
        K_ff = sp.csr_matrix(
            (A11.data, (fe_dof[A11.row], fe_dof[A11.col])), shape=(fe_layout.size_global,) * 2
        )
        A22g = sp.csr_matrix((A22.data, (dof_map[A22.row], dof_map[A22.col])), shape=(d * n, d * n))
        Kp_loc = Kp_loc + A22g
        # FE rows of fixed dofs vanish; their columns move the known values to the particles' rhs
        keep = ~fixed_dof[A12.row]
        K_fp = sp.csr_matrix(
            (A12.data[keep], (fe_dof[A12.row[keep]], dof_map[A12.col[keep]])),
            shape=(fe_layout.size_global, d * n),
        )
        K_pf = K_fp.T.tocsr()
        lift = fixed_dof[A12.row]
        np.add.at(f_p, A12.col[lift], -A12.data[lift] * x_held[A12.row[lift]])
    fe_body = None
    if problem.body_forces:  # weighted by beta_FE and beta_P like the tractions (eq. 49)
        fe_body, p_body = _body_loads(problem, band, tables)
        f_p += p_body
    dirichlet = [(t.values, dw.weights) for t, dw in zip(dtabs, dq, strict=True)]
    _refuse_held_in_equations(problem, held, (t_p, cw), dirichlet, f_p)
    b_fe = create_vector(
        comm, fe_layout, cat([*f_fe_rows, np.zeros(0, np.int64)]), cat([*f_fe_vals, []])
    )
    if fe_body is not None:
        b_fe.array[:] += fe_body

    loads = (b_fe.copy(), f_p.copy())
    K_fe = _fe_stiffness(problem, band)
    mats = [K_fe, loads[0]]
    constant_diagonal = [None, None]
    if K_ff is not None:
        K_pen = create_aij(comm, K_ff, fe_layout, fe_layout)
        K_fe.axpy(1.0, K_pen, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        K_pen_p = create_aij(comm, A22g if hold is None else A22g + hold, pl, pl)
        mats += [K_pen, K_pen_p]
        constant_diagonal = [K_pen, K_pen_p]
    elif hold is not None:  # the held particles' identity rows stay in a Newton tangent
        constant_diagonal[1] = create_aij(comm, hold, pl, pl)
        mats.append(constant_diagonal[1])
    x_bc = fix_fe_rows(problem, K_fe, b_fe, fixed_local, x_fix)
    Kp = create_aij(comm, Kp_loc, pl, pl)
    b_p = create_vector(comm, pl, pdofs.ravel(), f_p)
    Gfe = create_aij(comm, G_fe, ml, fe_layout)
    GfeT = create_aij(comm, G_fe.T.tocsr(), fe_layout, ml)
    Gp = create_aij(comm, G_p, ml, pl)
    GpT = create_aij(comm, G_p.T.tocsr(), pl, ml)
    g = create_vector(comm, ml, cat([*g_rows, np.zeros(0, np.int64)]), cat([*g_vals, []]))
    Kfp = Kpf = None
    if K_fp is not None:
        Kfp = create_aij(comm, K_fp, fe_layout, pl)
        Kpf = create_aij(comm, K_pf, pl, fe_layout)
        mats += [Kfp, Kpf]
    blocks = [[K_fe, Kfp, GfeT], [Kpf, Kp, GpT], [Gfe, Gp, None]]
    rhs = [b_fe, b_p, g]
    mats += [Kp, Gfe, GfeT, Gp, GpT]
    dl, *pins = append_patch_conditions(problem, blocks, rhs, mats, patch_bc, dq, dtabs)
    extra = {
        "pins": tuple(pins),
        "x_bc": x_bc,
        "active": active,
        "is_bc": is_bc,
        "fixed": fixed_local,
        "fixed_values": x_fix,
        "multipliers": ml.size_global + dl.size_global,
        "setup": setup,
        "assemble": time.perf_counter() - t1,
        "loads": loads,
        "fe_cells": ~patch.in_patch | band.in_band,
        "fe_weight": _fe_weight(problem, band),
        "constant_diagonal": constant_diagonal,
        "band": band,
    }
    return blocks, rhs, mats, extra


def solve_bridging(
    problem: CoupledElasticity,
    solver: str | SolverOptions = "mumps",
    kept: KeptFactorisation | None = None,
) -> BridgingSolution:
    """Assemble and solve the bridging-domain coupled system of ``problem`` (collective;
    ``kept``: see :func:`~dolfinx_meshfree.statics.petsc.solve_lu`)."""
    blocks, rhs, mats, extra = bridging_system(problem)
    uh, coeffs, solve, lam = solve_and_gather(
        problem, blocks, rhs, [*mats, extra["x_bc"]], solver, kept
    )
    sol = BridgingSolution(
        u=uh,
        coefficients=coeffs,
        mls=problem.mls,
        patch=problem.patch,
        timings={"setup": extra["setup"], "assemble": extra["assemble"], "solve": solve},
        sizes=sizes(problem, extra["active"], extra["multipliers"]),
        point_forces=pin_forces(extra, lam),
    )
    sol.band = extra["band"]
    return sol


def _band_multiplier_of_alpha(problem, band: BridgingBand, ids: np.ndarray, nb: int, t_fe, cw):
    r"""The multiplier field that balances ``grad(alpha)`` on the FE side: coefficients ``c``
    (``nb`` band nodes x gdim, on every rank) of ``Lambda = sum_k N_k c_k`` with

    .. math::
        \sum_L N_k(x_L) \Lambda(x_L) c_L = \int_{band} N_k \nabla\alpha \, dx

    for every band node ``k`` (``x_L``, ``c_L``: the constraint's points and weights, eq. 52 or
    79-81; the right side by Gauss quadrature, exact for the P1/Q1 ``alpha``). The FE equations
    of the weighted energy (eq. 47-48) of a linear field ``u`` with stress ``sigma`` read
    ``int (1 - alpha) grad N_a . sigma = int N_a sigma grad(alpha)`` (+ boundary terms), so
    ``lambda = -sigma Lambda`` is the multiplier of the exact solution: the particles receive
    ``sum_L phi_J(x_L) sigma Lambda(x_L) c_L``, which is what their consistent integration must
    balance. ``Lambda = grad(alpha)`` when ``grad(alpha)`` lies in the multiplier space (uniform
    straight layers); on unstructured bands it is its projection. The band node mass matrix is
    small (band nodes only): it is gathered and solved on every rank. Collective."""
    V, comm = problem.V, problem.patch.comm
    # grad(alpha) = 0 on the band cells outside the tied ones: the tied cells carry it all
    q = cell_quadrature(V.mesh, problem.quadrature_degree, band.tied_cells)
    q = raise_on_all_ranks(comm, lambda: revolved_if(q, problem.material))  # 2 pi r dx
    t = tabulate_in_cells(V, q.points, q.cells, derivatives=1)
    grad_alpha = np.stack([g @ band.alpha for g in t.gradients], axis=1)
    rhs = t.values.T @ (q.weights[:, None] * grad_alpha)
    M = (t_fe.T @ sp.diags(cw) @ t_fe).tocoo()
    keep = (ids[M.row] >= 0) & (ids[M.col] >= 0)
    # sums over every rank's cells: ghost nodes' rows are added on the owner's numbering
    rows_b = np.flatnonzero(ids >= 0)
    parts = comm.allgather(
        (ids[M.row[keep]], ids[M.col[keep]], M.data[keep], ids[rows_b], rhs[rows_b])
    )
    cat = np.concatenate
    Mg = sp.csr_matrix(
        (cat([p[2] for p in parts]), (cat([p[0] for p in parts]), cat([p[1] for p in parts]))),
        shape=(nb, nb),
    )
    bg = np.zeros((nb, grad_alpha.shape[1]))
    for p in parts:
        np.add.at(bg, p[3], p[4])
    return np.column_stack([spsolve(Mg.tocsc(), bg[:, k]) for k in range(bg.shape[1])])


def _consistent_test_gradients(
    problem,
    band: BridgingBand,
    q,
    w: np.ndarray,
    tq,
    constraint,
    ids: np.ndarray,
    nb: int,
    held: np.ndarray | None = None,
    hoop: sp.csr_matrix | None = None,
) -> list:
    r"""Variationally consistent integration (Chen, Hillman & Rüter 2013) of the particle test
    functions under the energy weight ``alpha`` (eq. 46): corrected gradients with

    .. math::
        \sum_q \alpha \tilde\nabla\phi_J w_q = \sum_b \alpha \phi_J n w_b
        - \sum_L \phi_J(x_L) \Lambda(x_L) c_L,

    the divergence theorem for ``alpha phi_J`` (``alpha = 0`` on the interface, so only the
    exterior facets of the patch count) with its band term ``int phi_J grad(alpha)`` written
    with the multiplier field ``Lambda`` of :func:`_band_multiplier_of_alpha` at the
    constraint's points ``x_L`` and weights ``c_L`` (``constraint = (t_fe, t_p, cw)`` of
    :func:`_constraint_tables`). For a linear field the band term ``-phi_J sigma Lambda`` is then
    balanced exactly by the multipliers (which carry ``-sigma Lambda``), and the boundary term by
    the alpha-weighted facet multipliers: the linear patch test passes to round-off on any mesh,
    with either constraint. (With ``grad(alpha)`` itself in the band term, a piecewise constant
    field outside the continuous multiplier space on unstructured bands, it missed by 1.6e-3.)
    The ``held`` particles (:func:`_held_particles`: ``alpha = 0`` on their whole support, so
    both sides of the equation above vanish for them) are left uncorrected; any other particle
    whose function integrates to ~0 is refused by its coordinates. Collective."""
    patch, comm = problem.patch, problem.patch.comm
    msh, deg = problem.V.mesh, problem.quadrature_degree
    t_fe, t_p, cw = constraint
    coef = _band_multiplier_of_alpha(problem, band, ids, nb, t_fe, cw)
    lam = t_fe @ np.where(ids[:, None] >= 0, coef[np.maximum(ids, 0)], 0.0)
    exterior = (patch.exterior_facets, patch.exterior_cells)
    bq = crack_rules(msh, patch.particles.cells, patch.cracks, deg, exterior, cell_rule=False)[1]
    if bq is None:  # no crack
        bq = facet_quadrature(msh, patch.exterior_facets, deg, patch.exterior_cells)
    bq = raise_on_all_ranks(comm, lambda b=bq: revolved_if(b, problem.material))
    sides = getattr(bq, "sides", None)  # crack faces: one-sided values
    tb = raise_on_all_ranks(comm, lambda: problem.mls.tabulate(bq.points, 0, sides=sides))
    in_b = band.in_band[bq.cells]
    alpha_b = np.ones(len(bq))
    alpha_b[in_b] = band.alpha_at(bq.points[in_b], bq.cells[in_b])
    return raise_on_all_ranks(
        comm,
        lambda: consistent_gradients(
            tq.values,
            tq.gradients,
            w,
            sp.vstack([tb.values, t_p]).tocsr(),
            np.concatenate([bq.weights * alpha_b, cw]),
            np.concatenate([bq.normals, -lam]),
            comm,
            positions=patch.particles.positions,
            inactive=None if held is None else np.isin(np.arange(tq.values.shape[1]), held),
            hoop=hoop,
        ),
    )


def _held_particles(problem, q: QuadraturePoints, w: np.ndarray, tq) -> np.ndarray:
    r"""The particles that carry no energy: their shape function vanishes at every quadrature
    point of the patch where the particle weight ``beta_P`` is positive, though not at all of
    them (indices, increasing, the same on every rank; collective).

    A particle's internal and external forces (eq. 61-62, with ``K_P`` of eq. 78)

    .. math::
        f^{int}_J = \int_{\Omega_P} \beta^P \nabla\phi_J \cdot \sigma, \qquad
        f^{ext}_J = \int_{\Omega_P} \beta^P \phi_J b + \int_{\Gamma_t} \beta^P \phi_J \bar t

    vanish identically when ``beta_P = alpha = 0`` on its whole support: a particle beside a
    band cell whose nodes all lie on the interface (a stair step of a slanted interface), whose
    support reaches the patch's quadrature only there. Such a cell is not in ``Omega_int``
    (:class:`BridgingBand`, ``tied``), so the constraint (eq. 52, 57) does not see the particle
    either: its row and column of eq. 68 are empty, and its coefficient is not part of the
    discrete problem. It is held at 0 (an identity row, :func:`_hold_block`), which leaves
    every other unknown as it was: its shape function is 0 wherever the particle field has a
    weight at a quadrature point, and where it is not (its stair-step cells), the solution is
    ``(1 - alpha) u_FE + alpha u_P = u_FE`` (:class:`BridgingSolution`). VCI cannot
    correct it (its ``alpha``-weighted integral, the denominator of the correction, is 0) and
    need not: its test gradients enter no sum, so :func:`_consistent_test_gradients` skips it.

    A particle whose support holds no quadrature point at all is not held but refused by the
    consistent integration (its support misses the quadrature: a dilation too small).
    ``w``: the quadrature weights times ``alpha`` in the band (eq. 46), ``tq``: the MLS table
    at ``q``. Absolute values: no cancellation can make a particle look empty.
    """
    comm = problem.patch.comm
    a = abs(tq.values.tocsr())
    weighted = comm.allreduce(np.asarray(a.T @ w).ravel(), op=MPI.SUM)
    plain = comm.allreduce(np.asarray(a.T @ q.weights).ravel(), op=MPI.SUM)
    return np.flatnonzero((weighted == 0.0) & (plain > 0.0))


def _hold_block(problem, held: np.ndarray, dof_map: np.ndarray, size: int) -> sp.csr_matrix | None:
    """``s I`` on the dofs of the held particles (:func:`_held_particles`), from the ranks that
    own them (PETSc numbering, ``s = E``: the scale of the constraint rows), or ``None``."""
    if held.size == 0:
        return None
    P = problem.patch.particles
    d = P.gdim
    mine = held[np.isin(held, P.owned)]
    dofs = dof_map[(d * mine[:, None] + np.arange(d)).ravel()]
    return sp.csr_matrix(
        (np.full(dofs.size, float(problem.material.E)), (dofs, dofs)), shape=(size, size)
    )


def _refuse_held_in_equations(
    problem, held: np.ndarray, constraint: tuple, facets: list, loads: np.ndarray
) -> None:
    """Refuse, on every rank, a held particle (:func:`_held_particles`) that an equation still
    sees although no quadrature point of the cells with ``alpha > 0`` does: a point of the band
    constraint (``constraint="points"``: a band particle on the interface), a point of a
    Dirichlet facet with a positive weight, or a traction. Its coefficient would then enter
    that equation with no stiffness of its own (a condition on the multipliers that the exact
    solution does not meet, or a load that no stiffness carries), and no VCI can make it
    consistent (its ``alpha``-weighted integral is 0). ``constraint``: ``(values, weights)`` of
    the constraint points, ``facets``: such pairs for the Dirichlet facets (MLS values at this
    rank's points, weights), ``loads``: this rank's particle loads (interleaved). Collective."""
    if held.size == 0:
        return
    comm, P = problem.patch.comm, problem.patch.particles
    d = P.gdim

    def reach(pairs: list[tuple[Any, np.ndarray]]) -> np.ndarray:
        out = np.zeros(held.size)
        for values, weights in pairs:
            if values.shape[0]:
                out += np.asarray(abs(values.tocsc()[:, held]).T @ np.abs(weights)).ravel()
        return out

    seen = np.stack(
        [reach([constraint]), reach(facets), np.abs(loads.reshape(-1, d)[held]).sum(axis=1)]
    )
    seen = comm.allreduce(seen, op=MPI.SUM)  # the same on every rank
    hit = seen > 0.0
    bad = np.flatnonzero(hit.any(axis=0))
    if bad.size == 0:
        return
    k = bad[0]
    what = ["a point of the band constraint", "a Dirichlet facet with alpha > 0", "a traction"]
    what = " and ".join(w for w, h in zip(what, hit[:, k], strict=True) if h)
    others = f" (and {bad.size - 1} other particle(s) like it)" if bad.size > 1 else ""
    x = np.round(P.positions[held[k]], 12).tolist()
    raise ValueError(
        f"coupling='bridging': the particle at {x}{others} has alpha = 0 at every quadrature "
        "point of its support (it lies beside band cells whose nodes are all on the interface, "
        f"where the particle weight alpha of eq. 46 vanishes), but {what} reaches it: its "
        "coefficient would enter that equation with no stiffness of its own; "
        f"increase the dilation (now {getattr(problem.mls, 'dilation', '?')}) so that its "
        "support reaches the band's interior"
        + (", or use constraint='integral'" if hit[0, k] and problem.constraint == "points" else "")
    )


def _weight_band_facets(band: BridgingBand, quadratures: list[QuadraturePoints]) -> None:
    """Weight the particles' Dirichlet constraints on band facets by ``beta_P = alpha`` (in
    place): ``int_f alpha mu (u_P - ubar)``. The particle energy is ``alpha``-weighted in the
    band (eq. 46), so its boundary reaction there is ``alpha sigma n``, which a piecewise-constant
    multiplier can carry only with the same weight; unweighted, a linear field was not in
    equilibrium at the band's exterior facets (the patch test missed by 2e-4)."""
    for q in quadratures:
        on = band.in_band[q.cells]
        if np.any(on):
            q.weights[on] *= band.alpha_at(q.points[on], q.cells[on])


def _constraint_tables(
    problem, band: BridgingBand
) -> tuple[sp.csr_matrix, sp.csr_matrix, np.ndarray]:
    """FE basis and particle functions where the band is tied, and the weights there: the band
    particles with weight 1 (``constraint="points"``, eq. 79-81), or the Gauss points of the
    band's ``tied`` cells (``alpha`` not identically 0: ``Omega_int``) with their quadrature
    weights (``constraint="integral"``, eq. 52). Collective.

    The point constraints determine the multipliers on the band nodes only if the band particles
    do (``sum_L N_k(x_L) N_a(x_L)`` regular): a band node without a band particle in its support,
    or fewer band particles than band nodes, raises a ValueError naming the remedies.
    """
    V, comm, P = problem.V, problem.patch.comm, problem.patch.particles
    if problem.constraint == "integral":
        q = cell_quadrature(V.mesh, problem.quadrature_degree, band.tied_cells)
        q = raise_on_all_ranks(comm, lambda: revolved_if(q, problem.material))  # 2 pi r dx
        points, cells, weights = q.points, q.cells, q.weights
    else:
        points = P.positions[band.local_particles]
        cells, weights = band.local_cells, np.ones(band.local_particles.size)
    t_fe = tabulate_in_cells(V, points, cells, derivatives=0).values.tocsr()
    t_fe.data[np.abs(t_fe.data) <= 1e-13] = 0.0  # nodes off the point's edge: round-off
    t_fe.eliminate_zeros()
    t_p = raise_on_all_ranks(comm, lambda: problem.mls.tabulate(points, 0)).values.tocsr()
    if problem.constraint == "points":
        seen = node_flags(problem.V, np.unique(t_fe.indices))
        n_owned = V.dofmap.index_map.size_local
        blind = int(np.sum((band.tied_node & ~seen)[:n_owned]))
        blind = comm.allreduce(blind)
        nodes = comm.allreduce(int(np.sum(band.tied_node[:n_owned])))
        if blind or band.particles.size < nodes:
            raise ValueError(
                f"the bridging band has {nodes} FE nodes but {band.particles.size} particles "
                f"({blind} band node(s) have no band particle in their support): the point "
                "constraints cannot determine the band multipliers; use constraint='integral', "
                "a finer particle spacing, or ParticlePatch(..., placement='vertices')"
            )
    return t_fe, t_p, weights


def bridging_operators(problem: CoupledElasticity) -> CouplingOperators:
    """The bridging coupling's operators without essential conditions (collective).

    ``K_FE`` weighted by ``beta_FE`` (eq. 47–48) plus the penalty's FE block, ``K_P`` with the
    quadrature weights times ``alpha`` (eq. 46) plus its particle block, the penalty's
    off-diagonal blocks (eq. 72–75), and the constraints at the band particles (or, with
    ``constraint="integral"``, over the band cells) with multipliers on the band's FE nodes
    (eq. 57, 79–80) with unit scaling. The particle
    quadrature's weights include ``alpha``, so its row sums give the weighted masses of eq. 89;
    ``fe_weight`` is ``beta_FE`` for eq. 88. See
    :class:`~dolfinx_meshfree.couplings.base.CouplingOperators`.
    """

    t0 = time.perf_counter()
    V, patch, P = problem.V, problem.patch, problem.patch.particles
    comm, msh = patch.comm, V.mesh
    n, p = P.num_particles, problem.penalty
    d = msh.geometry.dim
    pdofs = P.petsc_dofs(d)
    dof_map = pdofs.ravel()
    fe_layout, l2g = fe_dof_layout(problem.V)
    pl = P.dof_layout(d)
    band = BridgingBand(problem, problem.overlap, problem.band_width)
    q, w, tq, hoop, test_hoop = _particle_rule(problem, band)  # as bridging_system
    qa = QuadraturePoints(q.points, w, q.cells)
    held = _held_particles(problem, q, w, tq)
    if held.size:  # the same on every rank (reduced sums)
        x = np.round(P.positions[held[0]], 12).tolist()
        raise ValueError(
            f"explicit dynamics with coupling='bridging': the particle at {x}"
            + (f" (and {held.size - 1} other particle(s) like it)" if held.size > 1 else "")
            + " has alpha = 0 on its whole support (it lies beside band cells whose nodes are "
            "all on the interface), so its lumped mass (eq. 89) would be 0; the "
            "statics hold such particles, the central differences cannot yet: increase the "
            f"dilation (now {getattr(problem.mls, 'dilation', '?')}) so that every support "
            "reaches the band's interior, or smooth the patch's staircase"
        )
    active = fe_active(problem, np.concatenate([patch.fe_cells, band.cells]))

    ids, ml = band.numbering(problem)
    t_fe, t_p, cw = _constraint_tables(problem, band)
    test = None
    if problem.consistent:
        test = _consistent_test_gradients(
            problem, band, q, w, tq, (t_fe, t_p, cw), ids, ml.size_global // d, hoop=test_hoop
        )
    Kq = _particle_stiffness(problem, test or tq.gradients, w, tq, (hoop, test_hoop)).tocoo()
    Kp_loc = sp.csr_matrix((Kq.data, (dof_map[Kq.row], dof_map[Kq.col])), shape=(d * n, d * n))
    M_fe = (t_fe.T @ sp.diags(cw) @ t_fe).tocoo()
    M_p = (t_fe.T @ sp.diags(cw) @ t_p).tocoo()
    keep = ids[M_fe.row] >= 0
    zero = dolfinx.fem.Function(V)
    zero.x.array[:] = 0.0
    G_fe, _, _ = fe_constraint_block(
        ids[M_fe.row[keep]],
        M_fe.col[keep],
        M_fe.data[keep],
        False,
        1.0,
        np.zeros(l2g.size, dtype=bool),
        zero,
        l2g,
        (ml.size_global, fe_layout.size_global),
    )
    keep = ids[M_p.row] >= 0
    G_p = particle_constraint_block(
        ids[M_p.row[keep]], M_p.col[keep], M_p.data[keep], 1.0, pdofs, (ml.size_global, d * n)
    )

    K_fe = _fe_stiffness(problem, band)
    K_fp = K_pf = penalty = None
    if p > 0.0:
        fe_dof = (d * l2g[:, None] + np.arange(d)).ravel()
        e2 = sp.identity(d, format="csr")
        root = sp.diags(np.sqrt(cw))
        Nf, Np = sp.kron(root @ t_fe, e2).tocsr(), sp.kron(root @ t_p, e2).tocsr()
        A11 = (p * (Nf.T @ Nf)).tocoo()
        A12 = (-p * (Nf.T @ Np)).tocoo()
        A22 = (p * (Np.T @ Np)).tocoo()
        K_ff = sp.csr_matrix(
            (A11.data, (fe_dof[A11.row], fe_dof[A11.col])), shape=(fe_layout.size_global,) * 2
        )
        K_pen = create_aij(comm, K_ff, fe_layout, fe_layout)
        K_fe.axpy(1.0, K_pen, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        A22g = sp.csr_matrix((A22.data, (dof_map[A22.row], dof_map[A22.col])), shape=(d * n, d * n))
        Kp_loc = Kp_loc + A22g
        penalty = (K_pen, create_aij(comm, A22g, pl, pl))
        fp = sp.csr_matrix(
            (A12.data, (fe_dof[A12.row], dof_map[A12.col])), shape=(fe_layout.size_global, d * n)
        )
        K_fp = create_aij(comm, fp, fe_layout, pl)
        K_pf = create_aij(comm, fp.T.tocsr(), pl, fe_layout)
    return CouplingOperators(
        coupling=problem.coupling,
        K_fe=K_fe,
        K_p=create_aij(comm, Kp_loc, pl, pl),
        fe_weight=_fe_weight(problem, band),
        fe_active=active,
        particle_quadrature=qa,
        particle_table=tq.values.tocsr(),
        fe_layout=fe_layout,
        particle_layout=pl,
        K_fp=K_fp,
        K_pf=K_pf,
        G_fe=create_aij(comm, G_fe, ml, fe_layout),
        G_p=create_aij(comm, G_p, ml, pl),
        multiplier_layout=ml,
        interface=band,
        penalty_blocks=penalty,
        particle_tables={
            "quadrature": q,
            "table": tq,
            "test_gradients": test or tq.gradients,
            "weights": w,
            **({} if hoop is None else {"hoop": hoop, "test_hoop": test_hoop}),
        },
        timings={"operators": time.perf_counter() - t0},
    )


class BridgingCoupling(CouplingDefaults):
    """The bridging domain: an overlap band with energy weights and multipliers on the band's FE
    nodes (Rabczuk et al. 2006, sec. 5.3)."""

    name: ClassVar[str] = "bridging"
    default_dilation: ClassVar[float] = 2.0
    consistent_default: ClassVar[bool] = True
    integrations: ClassVar[tuple[str, ...]] = ("cells",)
    blended: ClassVar[bool] = True
    dimensions: ClassVar[tuple[int, ...]] = (2, 3)
    missing_3d: ClassVar[str] = ""

    def solve(
        self,
        problem: CoupledElasticity,
        solver: str | SolverOptions,
        kept: KeptFactorisation | None = None,
    ) -> CoupledSolution:
        return solve_bridging(problem, solver, kept)

    def system(self, problem: CoupledElasticity, tables: dict | None = None) -> tuple:
        return bridging_system(problem, tables)

    def operators(
        self, problem: CoupledElasticity, integration: str, slaves: str
    ) -> CouplingOperators:
        return bridging_operators(problem)
