"""Contact between bodies in explicit dynamics, 2D and 3D: a node-to-facet penalty on the normal
gap, frictionless or with Coulomb friction, between two surfaces of one model (issue 27, item
2).

Two bodies are two pieces of one mesh (cells that share no vertex), each discretised as the
model discretises it: FE cells, particle cells, blended cells. A contact pair is two sets of
exterior facets, ``surface_a`` and ``surface_b``: segments in 2D, triangles in 3D (a
quadrilateral face is split in two along the diagonal from its vertex first in coordinate
order, the same on every partition). Their vertices ``X_v`` move with the model's field there,
``y_v = X_v + u_h(X_v)``: FE nodal values on FE cells, the MLS approximation on particle cells,
the blended functions on the ramps' interface cells and bridging's band, so that ``y = X + A d``
with ``A`` the model's evaluation operator at the vertices
(:meth:`~dolfinx_meshfree.dynamics.evaluation.FieldEvaluator.point_tables`; master–slave
expands its slaves, ``A_P (T_PF d_FE + S d_M)``, Rabczuk et al. 2006, eq. 27).

For a slave vertex ``s`` and a facet of the other surface with vertices ``y_i``, at the current
positions, the projection ``y_s = sum_i w_i y_i + g n`` gives the facet's weights ``w``
(``(1 - xi, xi)`` on a segment ``(a, b)``, ``xi = (y_s - y_a) . t / t . t`` with ``t = y_b -
y_a``; barycentric on a triangle) and the normal gap

.. math::
    g = \\Big(y_s - \\sum_i w_i y_i\\Big) \\cdot n, \\qquad
    n = \\frac{(t_2, -t_1)}{|t|} \\ \\text{(2D)}, \\quad
    n = \\frac{(y_b - y_a) \\times (y_c - y_a)}{|\\cdot|} \\ \\text{(3D)},

``n`` the facet's outward normal (the facet is oriented at build time so that it points away
from its cell). The slave is in contact with the facet when ``-depth < g < 0`` and every weight
is ``>= -0.05`` (beyond the facet the weights are clipped to ``>= 0`` and scaled to sum 1); of
several such facets the one with the largest ``g`` (the nearest surface) is taken, and of
facets whose gaps agree within ``TIE * depth`` (a vertex on a vertex or an edge of the other
surface) the first in a canonical order, so that every partition takes the same. The penalty
energy and its force (the sign of ``M a + f^int = f^ext``, added to the internal force) are

.. math::
    E_c = \\tfrac12 \\sum_s k_s \\min(g_s, 0)^2, \\qquad
    f_s = k_s g_s n, \\quad f_i = -w_i k_s g_s n,

in the vertices' displacement space, then ``A^T f`` on the dofs. At a closest point inside the
facet, ``∂g/∂y = (n, -w_1 n, ..., -w_d n)`` exactly (the variations of ``w`` and ``n`` multiply
the facet's tangents' products with ``n``, zero, and ``n . dn = 0``), so the force is the
gradient of ``E_c`` (beyond the facet, within the 5 % margin, the weights are clipped and it is
not quite): central differences conserve ``kinetic + strain + E_c`` up to the non-smoothness of
the contact's start and end (measured in ``tests/test_body_contact.py``). ``k_s = k w_s``,
``k`` the penalty per unit area (Pa/m) and ``w_s`` the slave's tributary measure (half its two
segments' lengths; a third of its triangles' areas; in an axisymmetric model the segments'
revolved shares ``int N_s 2 pi r ds``). With ``two_pass`` (default) each surface
is slave to the other in turn, so that a coarse surface's facets cannot pass between a fine
surface's vertices unnoticed, whatever the two meshes' spacings.

**Coulomb friction** (``BodyContact(friction=mu)``; the penalty regularisation of Coulomb's law
with a return map, as in Wriggers, *Computational Contact Mechanics*, 2006): each closed pair
carries a tangential spring of the normal penalty's stiffness ``k_s``. Its force on the slave
moves by ``-k_s`` times the slave's tangential slip relative to the master's material point it
was at (the previous facet and weights, at the current positions), from its previous value
turned into the current tangent plane; it is limited to ``mu k_s |g|``, the excess being slip,
whose work (the limit times the slip) :attr:`BodyContactSystem.dissipated` accumulates. The force
joins the normal one, equal and opposite on the facet's vertices (weights ``w``). A pair that
opens forgets its spring. The state moves with every evaluation at a new state, so that a
second evaluation at the same displacement changes nothing (the energy records', the dynamic
SIFs'). The energy records' ``internal`` holds the springs' stored energy and the dissipated
work, so the balance still closes: measured 0.3 % on a block sliding down an incline, whose
velocity follows ``g (sin theta - mu cos theta)`` within 1.6 % (2D) and 0.02 % (3D), and 1.6 %
on one that sticks (``tests/test_body_contact.py``).

The stable step sees the contact (:meth:`BodyContactSystem.tangent`). A closed pair adds ``k_s
b b^T`` with ``b = (1, -w_1, ..., -w_d) (x) n``; by Cauchy–Schwarz with weights proportional to
``(1, w_1, ..., w_d)`` (they sum to 2), ``b b^T <= 2 diag(1, w_1, ..., w_d) (x) I``: in every
direction, so the friction's tangential springs of the same stiffness are bounded too. Summed over
the pairs that can close, the contact stiffness in vertex space is at most ``diag(c)`` in the
PSD order, per pass ``c_s += 2 k_s`` on a slave and ``c_m += 2 k P_m`` on a master vertex, ``P_m``
the slave measure that can press on its facets when the faces meet face to face: the facets'
length widened by the other surface's longest segment at each end (2D); the facets' area as a
disc whose radius is widened by the other surface's longest edge (3D). So the step is bounded
with ``K + A^T diag(c) A``, safe for every contact state. Measured on bars pressed together
(``tests/test_body_contact.py``): the largest frequency of ``M^-1 (K + K_c)`` is 32.0 (2D,
10 cells) and 14.1 (3D, 4 hexahedra), the bound 56.3 and 54.2, the bound without contact 22.8
and 13.1.

The closest points are found by a compiled loop (:func:`closest_points_compiled`, numba) over
every (slave, facet) pair up to
:data:`EVERY_PAIR` pairs, beyond that over the :data:`CANDIDATES` nearest facets of a KD-tree
(:func:`candidates`); without numba, :func:`closest_points` (numpy, the reference) on the
KD-tree's candidates.

Particles of two bodies press on each other like FE: the model's MLS (and the hybrid's SPH
sums) stops at the bodies' gap (:mod:`~dolfinx_meshfree.approx.body_cuts`, added whenever
supports could cross it), so each body's surface moves with its own particles. A particle whose
function still reaches both surfaces (an approximation built by hand without that cut) is
refused here.

Left out: self-contact, and contact surfaces that change during a run (an adaptive patch
rebuilds the model: add the contact in the user's ``build``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import dolfinx
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from .. import _compat
from ..approx import jit
from ..geometry.quadrature import facet_normals
from ..parallel import Layout, owned_indices, raise_on_all_ranks
from ..statics.petsc import create_aij
from .system import WrappedSystem, wrapped

if TYPE_CHECKING:  # annotations only
    from ..geometry.particles import ParticleSet
    from .evaluation import FieldEvaluator
    from .system import SemiDiscreteSystem

__all__ = [
    "BodyContact",
    "BodyContactSystem",
    "ContactSurfaces",
    "PointPenaltySystem",
    "candidates",
    "carry_friction",
    "check_friction",
    "closest_points",
    "closest_points_compiled",
    "contact_surfaces",
    "contact_tangent",
    "coulomb_return",
    "evaluation_operators",
    "point_masses",
    "summed_tangent",
    "vertex_coordinates",
    "with_body_contact",
]

#: How far beyond a facet (in its weights) a slave still projects onto it.
XI_MARGIN = 0.05
#: Nearest facets (by centroid) examined per slave vertex.
CANDIDATES = 8
#: Up to this many (slave, facet) pairs the compiled kernel examines every pair (no search:
#: 1.6 us for 21 x 20 pairs, against 100 us for the tree's candidates).
EVERY_PAIR = 100_000
#: Gaps within ``TIE * depth`` of the largest are alike: of their facets the first in order is
#: taken (the same on every partition).
TIE = 1e-9
#: The candidate array that makes the compiled kernels take every facet.
EVERY = np.full((1, 1), -1, dtype=np.int64)


@dataclasses.dataclass(frozen=True)
class BodyContact:
    """Options of contact between two bodies (a penalty on the normal gap; Coulomb friction by
    option).

    Attributes:
        factor: The penalty ``k = factor * E / h`` per unit area (Pa/m) when ``penalty`` is
            ``None``, ``h`` the median of the surfaces' facets' longest edges and ``E`` the
            material's Young's modulus: under a contact pressure ``p`` the surfaces
            interpenetrate by ``p / k = (p / E) h / factor`` (two-pass: half that), the elastic
            shortening of one cell at that stress over ``factor``. The default (``None``: 1)
            keeps the penetration at the cell's own strain and lowers the stable step by the
            factor printed in ``critical_time_step`` (measured on the bars of
            ``demos/bar_impact.py``: 0.39-0.41x the step without contact in 2D, 0.20-0.24x
            in 3D). With ``slaves="body"`` it scales the pairs' mass-weighted penalty
            ``factor omega_0^2 m_s m_f / (m_s + m_f)`` instead
            (:mod:`~dolfinx_meshfree.dynamics.nodes_contact`; default 0.3, the rigid
            projectile's).
        penalty: ``k`` itself (Pa/m), or ``None``.
        two_pass: Each surface's vertices against the other's facets (``None``, the default:
            with ``slaves="surface"``), or (``False``) only ``surface_a``'s vertices against
            ``surface_b``'s facets.
        depth: The deepest penetration still taken for contact (m); ``None``: the longest
            facet edge of the two surfaces. A vertex deeper than that behind a facet is taken to
            be elsewhere (the far side of a thin body).
        friction: Coulomb's coefficient ``mu`` (default 0: frictionless): a tangential spring
            of the normal penalty's stiffness per pair, its force limited to ``mu`` times the
            normal force (module docstring).
        slaves: ``"surface"`` (default): the surfaces' vertices are the slaves. ``"body"``:
            every node of ``surface_a``'s body (FE and blended vertices, particles; the axis
            excepted in axisymmetry) against ``surface_b``'s facets, in one pass, for a
            projectile (``surface_b``) that penetrates or perforates its target
            (:mod:`~dolfinx_meshfree.dynamics.nodes_contact`; LS-DYNA's eroding
            node-to-surface contact).
    """

    factor: float | None = None
    penalty: float | None = None
    two_pass: bool | None = None
    depth: float | None = None
    friction: float = 0.0
    slaves: str = "surface"

    def __post_init__(self) -> None:
        check_friction("BodyContact", self.friction)
        for name in ("factor", "penalty", "depth"):
            value = getattr(self, name)
            if value is None:
                continue
            if isinstance(value, bool) or not (
                isinstance(value, int | float) and np.isfinite(value) and value > 0.0
            ):
                raise ValueError(
                    f"BodyContact({name}={value!r}): {name} must be a positive number or None"
                )
        if self.slaves not in ("surface", "body"):
            raise ValueError(
                f"BodyContact(slaves={self.slaves!r}): slaves must be 'surface' (the surfaces' "
                "vertices) or 'body' (every node of surface_a's body)"
            )
        if self.two_pass is not None and not isinstance(self.two_pass, bool):
            raise ValueError(f"BodyContact(two_pass={self.two_pass!r}) must be True, False or None")
        if self.slaves == "body" and self.two_pass:
            raise ValueError(
                "BodyContact(slaves='body', two_pass=True): with every node of surface_a's body "
                "as a slave the contact has one pass (that body keeps no surface a projectile "
                "could be pressed on once it is perforated); leave two_pass at None"
            )


@dataclasses.dataclass
class ContactSurfaces:
    """The two surfaces of a contact pair, replicated on every rank.

    Attributes:
        points: Reference positions of the surfaces' vertices (nv, gdim), in the order of the
            rows of the evaluation operator (each rank's owned vertices in turn).
        facets: (nf, gdim) vertex indices of each facet: segments in 2D, triangles in 3D (a
            quadrilateral face split in two), ordered so that their normal (:func:`normals`)
            points out of the body.
        body: 0 (``surface_a``) or 1 (``surface_b``) per facet. vertex_body: the same per
            vertex.
        owned: This rank's rows ``[start, end)`` of the vertices.
    """

    points: np.ndarray
    facets: np.ndarray
    body: np.ndarray
    vertex_body: np.ndarray
    owned: tuple[int, int]
    #: The surfaces are curves of an axisymmetric (r, z) section: their measures revolve.
    axisymmetric: bool = False

    def measures(self) -> np.ndarray:
        """Reference length (2D) or area (3D) of each facet."""
        return np.linalg.norm(facet_normals(self.points, self.facets, unit=False), axis=1)

    def sizes(self) -> np.ndarray:
        """The longest edge of each facet (its length in 2D)."""
        p = self.points[self.facets]
        edges = [p[:, (i + 1) % p.shape[1]] - p[:, i] for i in range(p.shape[1])]
        if p.shape[1] == 2:
            edges = edges[:1]
        return np.max([np.linalg.norm(e, axis=1) for e in edges], axis=0)

    def tributary(self) -> np.ndarray:
        """The share of the facets at each vertex (the slave's weight ``w_s``): half the
        segments' lengths in 2D, a third of the triangles' areas in 3D; axisymmetric, the
        revolved share ``int N_s 2 pi r ds = 2 pi L (2 r_s + r_o) / 6`` of each segment
        (positive on the axis, where ``r_s = 0``)."""
        w = np.zeros(len(self.points))
        share = self.measures() / self.facets.shape[1]
        r = self.points[self.facets, 0]  # segments (axisymmetric): vertex i and the other one
        for i in range(self.facets.shape[1]):
            if self.axisymmetric:
                revolved = 2.0 * np.pi * share * (2.0 * r[:, i] + r[:, 1 - i]) / 3.0
                np.add.at(w, self.facets[:, i], revolved)
            else:
                np.add.at(w, self.facets[:, i], share)
        return w


def _facets(msh: dolfinx.mesh.Mesh, facets: npt.ArrayLike, name: str) -> np.ndarray:
    """``facets`` validated as owned exterior facets (on every rank)."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    n_own = msh.topology.index_map(tdim - 1).size_local
    exterior = np.asarray(dolfinx.mesh.exterior_facet_indices(msh.topology))

    def check() -> np.ndarray:
        fix = "pass owned exterior facets, e.g. mf.boundary_facets(mesh, marker)"
        f = owned_indices(facets, name, "facet", n_own, fix)
        inner = np.setdiff1d(f, exterior)
        if inner.size:
            x = msh.geometry.x[_compat.entities_to_geometry(msh, tdim - 1, inner[:1])].mean(1)
            raise ValueError(
                f"{name} holds {inner.size} interior facet(s), e.g. the facet at "
                f"{np.round(x[0, : msh.geometry.dim], 6).tolist()}: a contact surface is made "
                "of exterior facets (mf.boundary_facets)"
            )
        return np.unique(f.astype(np.int32))

    return raise_on_all_ranks(msh.comm, check)


def contact_surfaces(
    msh: dolfinx.mesh.Mesh, surface_a: npt.ArrayLike, surface_b: npt.ArrayLike
) -> tuple[ContactSurfaces, np.ndarray, np.ndarray]:
    """The replicated surfaces of a pair, with this rank's owned vertices (local indices) and
    a local cell of each (collective).

    Raises:
        ValueError: facets that are not owned exterior facets, an empty surface, a mesh of
            another dimension than its space, or surfaces that share a vertex (on every rank).
    """
    comm = msh.comm
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    raise_on_all_ranks(comm, lambda: _check_dimension(gdim, tdim))
    faces = [_facets(msh, s, n) for s, n in ((surface_a, "surface_a"), (surface_b, "surface_b"))]
    msh.topology.create_connectivity(tdim - 1, 0)
    msh.topology.create_connectivity(tdim - 1, tdim)
    msh.topology.create_connectivity(0, tdim)
    f2v, f2c = msh.topology.connectivity(tdim - 1, 0), msh.topology.connectivity(tdim - 1, tdim)
    vmap = msh.topology.index_map(0)
    n_local_v = vmap.size_local + vmap.num_ghosts
    l2g = np.asarray(vmap.local_to_global(np.arange(n_local_v, dtype=np.int32)), dtype=np.int64)
    vx = vertex_coordinates(msh)
    segs, bodies = [], []
    for body, facets in enumerate(faces):
        if not facets.size:
            continue
        v = np.array([f2v.links(f) for f in facets], dtype=np.int32)
        cells = np.array([f2c.links(f)[0] for f in facets], dtype=np.int32)
        mid_c = dolfinx.mesh.compute_midpoints(msh, tdim, cells)[:, :gdim]
        if v.shape[1] == 4:  # a quadrilateral: two triangles
            v = _split_quadrilaterals(vx, v)
            mid_c = np.concatenate([mid_c, mid_c])
        outward = vx[v].mean(axis=1) - mid_c
        flip = np.einsum("ij,ij->i", facet_normals(vx, v, unit=False), outward) < 0.0
        v[flip] = v[flip][:, ::-1]
        segs.append(l2g[v])
        bodies.append(np.full(len(v), body))
    local_segs = np.concatenate([*segs, np.zeros((0, gdim), dtype=np.int64)])
    local_body = np.concatenate([*bodies, np.zeros(0, dtype=int)])
    all_segs = np.concatenate(comm.allgather(local_segs)).reshape(-1, gdim)
    all_body = np.concatenate(comm.allgather(local_body)).astype(np.int8)
    # the owned surface vertices, each rank's rows in turn, sorted by global index: every
    # owned vertex that any rank's facets name (it may sit only on another rank's facets)
    named = np.unique(all_segs)
    owned_v = np.flatnonzero(np.isin(l2g[: vmap.size_local], named)).astype(np.int32)
    owned_v = owned_v[np.argsort(l2g[owned_v], kind="stable")]
    keys = np.concatenate(comm.allgather(l2g[owned_v]))
    points = np.concatenate(comm.allgather(vx[owned_v])).reshape(-1, gdim)
    counts = comm.allgather(len(owned_v))
    start = int(sum(counts[: comm.rank]))
    order = np.argsort(keys, kind="stable")
    facets = order[np.searchsorted(keys[order], all_segs)]
    # a canonical order of the facets (by reference centroid: global indices depend on the
    # partition), which breaks ties between facets alike on every partition
    centroid = points[facets].mean(axis=1)
    canonical = np.lexsort(centroid.T[::-1])
    facets, all_body = facets[canonical], all_body[canonical]
    vertex_body = np.full(len(keys), -1, dtype=np.int8)
    for body in (0, 1):
        at = np.unique(facets[all_body == body])
        shared = at[vertex_body[at] == 0] if body == 1 else at[:0]
        if shared.size:
            x = np.round(points[shared[0]], 6).tolist()
            raise_on_all_ranks(
                comm,
                lambda x=x, n=shared.size: _raise(
                    f"surface_a and surface_b share {n} vertex(es), e.g. the vertex at {x}: "
                    "the bodies in contact must be separate pieces of the mesh (no shared "
                    "vertex); pass the facets of two bodies"
                ),
            )
        vertex_body[at] = body
    for body, name in ((0, "surface_a"), (1, "surface_b")):
        if not np.any(all_body == body):
            raise_on_all_ranks(
                comm,
                lambda name=name: _raise(
                    f"{name} is empty on every rank: a contact pair needs a surface on each "
                    "body (owned exterior facets, e.g. mf.boundary_facets(mesh, marker))"
                ),
            )
    cells = _vertex_cells(msh, owned_v, np.concatenate(faces), f2c)
    surf = ContactSurfaces(points, facets, all_body, vertex_body, (start, start + len(owned_v)))
    return surf, owned_v, cells


def _split_quadrilaterals(x: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Two triangles per quadrilateral face (local vertex indices (n, 4)): the vertices put in
    order around the face by angle in its plane, then split along the diagonal from the vertex
    first in lexicographic order of its coordinates (x, then y, then z), so that every
    partition of the mesh splits a face alike (global indices depend on the partition).
    Returns (2 n, 3): the first triangles of every face, then the second ones."""
    p = x[quads]
    centre = p.mean(axis=1)
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # no three vertices collinear
    e1 = p[:, 0] - centre
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(normal, e1)
    rel = p - centre[:, None, :]
    angle = np.arctan2(np.einsum("nik,nk->ni", rel, e2), np.einsum("nik,nk->ni", rel, e1))
    around = np.take_along_axis(quads, np.argsort(angle, axis=1), axis=1)
    q = x[around]  # (n, 4, 3)
    first = np.array([np.lexsort(c.T[::-1])[0] for c in q], dtype=np.int64)
    around = np.take_along_axis(around, (first[:, None] + np.arange(4)) % 4, axis=1)
    return np.concatenate([around[:, [0, 1, 2]], around[:, [0, 2, 3]]])


def vertex_coordinates(msh: dolfinx.mesh.Mesh) -> np.ndarray:
    """The coordinates (local vertices, gdim) of the mesh's vertices, from the cells' first
    geometry nodes (a cell's vertices come first among its nodes, in the same order)."""
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    msh.topology.create_connectivity(tdim, 0)
    c2v = msh.topology.connectivity(tdim, 0)
    vmap = msh.topology.index_map(0)
    per_cell = np.diff(np.asarray(c2v.offsets))[0] if len(c2v.offsets) > 1 else 0
    verts = np.asarray(c2v.array).reshape(-1, per_cell) if per_cell else np.zeros((0, 1), int)
    nodes = _compat.geometry_dofmap(msh)[: len(verts), :per_cell]
    x = np.zeros((vmap.size_local + vmap.num_ghosts, gdim))
    x[verts.ravel()] = msh.geometry.x[nodes.ravel(), :gdim]
    return x


def _check_dimension(gdim: int, tdim: int) -> None:
    if gdim != tdim or gdim not in (2, 3):
        raise ValueError(
            f"contact between bodies needs a 2D or 3D mesh of its own space's dimension (this "
            f"mesh: gdim={gdim}, tdim={tdim}): a manifold mesh has no contact surfaces"
        )


def _raise(message: str) -> None:
    raise ValueError(message)


def _vertex_cells(
    msh: dolfinx.mesh.Mesh, vertices: np.ndarray, facets: np.ndarray, f2c
) -> np.ndarray:
    """A local cell of each vertex: one of its surface facets' cells on this rank if any, else
    the first local cell that holds it."""
    tdim = msh.topology.dim
    v2c = msh.topology.connectivity(0, tdim)
    msh.topology.create_connectivity(tdim - 1, 0)
    f2v = msh.topology.connectivity(tdim - 1, 0)
    by_vertex: dict[int, int] = {}
    for f in facets:
        c = int(f2c.links(f)[0])
        for v in f2v.links(f):
            by_vertex.setdefault(int(v), c)
    return np.array([by_vertex.get(int(v), int(v2c.links(v)[0])) for v in vertices], dtype=np.int32)


def _field_layout(vec: PETSc.Vec) -> Layout:
    lo, hi = vec.getOwnershipRange()
    return Layout(hi - lo, vec.getSize(), lo)


def evaluation_operators(
    evaluator: FieldEvaluator,
    surfaces: ContactSurfaces,
    tables: tuple[sp.csr_matrix | None, sp.csr_matrix | None],
    masses: Sequence[PETSc.Vec],
) -> list[PETSc.Mat]:
    """``A_k`` per field: the displacement at the owned surface vertices (rows ``gdim i + c``
    of :class:`ContactSurfaces`' order) from the field's dofs, from the vertices' ``tables``
    (:meth:`~dolfinx_meshfree.dynamics.evaluation.FieldEvaluator.point_tables`; collective)."""
    d = evaluator.disc
    comm = evaluator.comm
    gdim = d.gdim
    A_fe, A_p = tables
    nv_global = len(surfaces.points)
    lo, hi = surfaces.owned
    rows = Layout(gdim * (hi - lo), gdim * nv_global, gdim * lo)
    start = surfaces.owned[0]
    names = [f.name for f in d.fields]

    def expand(table: sp.csr_matrix, cols: np.ndarray) -> sp.csr_matrix:
        """(vertices x nodes) with node -> dof per component ``cols`` (nodes, gdim) into
        (global rows x global dofs)."""
        c = table.tocoo()
        r = np.concatenate([gdim * (start + c.row) + k for k in range(gdim)])
        j = np.concatenate([cols[c.col, k] for k in range(gdim)])
        v = np.concatenate([c.data] * gdim)
        return r, j, v

    mats: dict[str, PETSc.Mat] = {}
    if A_fe is not None:
        imap = d.V.dofmap.index_map
        l2g = np.asarray(
            imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)),
            dtype=np.int64,
        )
        cols = gdim * l2g[:, None] + np.arange(gdim)
        k = names.index("fe")
        r, j, v = expand(A_fe, cols)
        local = sp.csr_matrix((v, (r, j)), shape=(rows.size_global, masses[k].getSize()))
        mats["fe"] = create_aij(comm, local, rows, _field_layout(masses[k]))
    if A_p is not None:
        cols = d.particles.petsc_dofs(gdim)
        r, j, v = expand(A_p, cols)
        if d.reduction is None:
            k = names.index("particles")
            local = sp.csr_matrix((v, (r, j)), shape=(rows.size_global, masses[k].getSize()))
            mats["particles"] = create_aij(comm, local, rows, _field_layout(masses[k]))
        else:  # master-slave: u_P = T_PF d_FE + S d_M (eq. 27)
            Tpf, S = d.reduction
            local = sp.csr_matrix((v, (r, j)), shape=(rows.size_global, Tpf.getSize()[0]))
            lo, hi = Tpf.getOwnershipRange()
            Ap = create_aij(comm, local, rows, Layout(hi - lo, Tpf.getSize()[0], lo))
            via_fe, via_m = Ap.matMult(Tpf), Ap.matMult(S)
            Ap.destroy()
            mats["particles"] = via_m
            if "fe" in mats:
                mats["fe"].axpy(1.0, via_fe, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                via_fe.destroy()
            else:
                mats["fe"] = via_fe
    return [mats.get(name) for name in names]


def point_masses(
    A: Sequence[PETSc.Mat | None], masses: Sequence[PETSc.Vec], gdim: int
) -> np.ndarray:
    """Each owned point's share of the lumped masses, ``m_s = sum_j |A_sj| m_j`` (the rows of
    ``A``, one component; collective)."""
    share = next(a for a in A if a is not None).createVecLeft()
    share.set(0.0)
    for Ak, mk in zip(A, masses, strict=True):
        if Ak is None:
            continue
        absolute = Ak.copy()
        ai, aj, av = absolute.getValuesCSR()
        absolute.setValuesCSR(ai, aj, np.abs(av))
        absolute.assemble()
        absolute.multAdd(mk, share, share)
        absolute.destroy()
    m_s = share.array_r.reshape(-1, gdim)[:, 0].copy()
    share.destroy()
    return m_s


def _check_evaluable(evaluator: FieldEvaluator) -> None:
    if evaluator.expand is not None:
        raise ValueError(
            "contact between bodies is not available with master-slave's rotating links (finite "
            "strain, slaves='band'): the slaves' motion is not linear in the dofs; use "
            "slaves='layer' or another coupling"
        )
    if evaluator.disc.mesh is None:
        raise ValueError("contact between bodies needs the model's mesh (the surfaces' facets)")


def candidates(
    y: np.ndarray, slaves: np.ndarray, facets: np.ndarray, depth: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """The slaves within the master facets' box (widened by ``depth``) and, per slave, the
    indices of its candidate facets (every facet up to :data:`CANDIDATES` of them, else the
    :data:`CANDIDATES` nearest by centroid; ``len(facets)`` marks none); ``None`` when no slave
    is near."""
    if not len(slaves) or not len(facets):
        return None
    corners, ys = y[facets], y[slaves]
    lo = corners.min(axis=(0, 1)) - depth
    hi = corners.max(axis=(0, 1)) + depth
    near = np.flatnonzero(np.all((ys >= lo) & (ys <= hi), axis=1))
    if not near.size:
        return None
    if len(facets) <= CANDIDATES:  # every facet a candidate
        cand = np.broadcast_to(np.arange(len(facets)), (near.size, len(facets)))
    else:
        size = np.linalg.norm(corners - corners[:, :1], axis=2).max()
        _, cand = cKDTree(corners.mean(axis=1)).query(
            ys[near], k=CANDIDATES, distance_upper_bound=depth + size
        )
    return slaves[near], np.ascontiguousarray(cand, dtype=np.int64).reshape(near.size, -1)


def closest_points(
    y: np.ndarray,
    slaves: np.ndarray,
    facets: np.ndarray,
    cand: np.ndarray,
    depth: float,
    margin: float,
    hit: np.ndarray,
    gap: np.ndarray,
    weights: np.ndarray,
    normal: np.ndarray,
) -> None:
    """One pass's closest points (module docstring), 2D or 3D: per slave ``i`` the facet it
    presses on into ``hit[i]`` (``-1``: none), its gap ``g < 0``, the facet's weights ``w``
    (``(1 - xi, xi)`` on a segment, barycentric on a triangle; beyond the facet, within
    ``margin``, clipped to ``>= 0`` and scaled to sum 1) and the facet's unit normal. Of
    candidate facets whose gaps lie within ``TIE * depth`` of the largest, the first in the
    facets' order is taken (a vertex on a vertex or an edge of the other surface: its facets'
    gaps differ by round-off, and their normals by the surface's kink), so that every partition
    of the mesh takes the same facet. The numpy reference of :func:`closest_points_compiled`."""
    nf, d = facets.shape
    hit[:] = -1
    valid = cand < nf
    c = np.where(valid, cand, 0)
    corners = y[facets][c]  # (slaves, candidates, d, gdim)
    a = corners[:, :, 0]
    r = y[slaves][:, None, :] - a
    E = corners[:, :, 1:] - a[:, :, None, :]
    G = np.einsum("...ik,...jk->...ij", E, E)
    xi = np.linalg.solve(G, np.einsum("...ik,...k->...i", E, r)[..., None])[..., 0]
    w = np.concatenate([1.0 - xi.sum(axis=-1, keepdims=True), xi], axis=-1)
    projects = np.all(w >= -margin, axis=-1)
    wc = np.clip(w, 0.0, None)
    wc /= wc.sum(axis=-1, keepdims=True)
    if d == 2:
        t = E[:, :, 0]
        n = np.stack([t[..., 1], -t[..., 0]], axis=-1)
    else:
        n = np.cross(E[:, :, 0], E[:, :, 1])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    g = np.einsum("...k,...k->...", r - np.einsum("...i,...ik->...k", wc[..., 1:], E), n)
    ok = valid & projects & (g < 0.0) & (g > -depth)
    top = np.where(ok, g, -np.inf).max(axis=1)
    on = np.flatnonzero(np.isfinite(top))
    if not on.size:
        return
    tied = ok & (g >= top[:, None] - TIE * depth)  # of facets alike, the first in order
    j = np.argmin(np.where(tied, c, nf), axis=1)[on]
    hit[on] = c[on, j]
    gap[on] = g[on, j]
    weights[on, :d] = wc[on, j]
    normal[on, : y.shape[1]] = n[on, j]


@jit.jit
def _gap_to_segment(
    y: np.ndarray, s: int, a: int, b: int, margin: float
) -> tuple[float, float, float, float, float, float, float, bool]:
    """``(g, w_a, w_b, 0, n_x, n_y, 0, projects)`` of slave ``s`` on the segment ``(a, b)``:
    the weights ``(1 - xi, xi)`` of its projection, ``xi`` clipped to ``[0, 1]``."""
    tx, ty = y[b, 0] - y[a, 0], y[b, 1] - y[a, 1]
    tt = tx * tx + ty * ty
    xi = ((y[s, 0] - y[a, 0]) * tx + (y[s, 1] - y[a, 1]) * ty) / tt
    length = np.sqrt(tt)
    nx, ny = ty / length, -tx / length
    xc = min(max(xi, 0.0), 1.0)
    g = (y[s, 0] - y[a, 0] - xc * tx) * nx + (y[s, 1] - y[a, 1] - xc * ty) * ny
    return g, 1.0 - xc, xc, 0.0, nx, ny, 0.0, xi >= -margin and xi <= 1.0 + margin


@jit.jit
def _gap_to_triangle(
    y: np.ndarray, s: int, a: int, b: int, c: int, margin: float
) -> tuple[float, float, float, float, float, float, float, bool]:
    """``(g, w_a, w_b, w_c, n_x, n_y, n_z, projects)`` of slave ``s`` on the triangle ``(a,
    b, c)``: the weights of its projection, clipped to ``>= 0`` and scaled to sum 1."""
    e1 = (y[b, 0] - y[a, 0], y[b, 1] - y[a, 1], y[b, 2] - y[a, 2])
    e2 = (y[c, 0] - y[a, 0], y[c, 1] - y[a, 1], y[c, 2] - y[a, 2])
    r = (y[s, 0] - y[a, 0], y[s, 1] - y[a, 1], y[s, 2] - y[a, 2])
    g11 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]
    g12 = e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2]
    g22 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]
    r1 = e1[0] * r[0] + e1[1] * r[1] + e1[2] * r[2]
    r2 = e2[0] * r[0] + e2[1] * r[1] + e2[2] * r[2]
    det = g11 * g22 - g12 * g12
    x1 = (g22 * r1 - g12 * r2) / det
    x2 = (g11 * r2 - g12 * r1) / det
    w0, w1, w2 = 1.0 - x1 - x2, x1, x2
    projects = w0 >= -margin and w1 >= -margin and w2 >= -margin
    w0, w1, w2 = max(w0, 0.0), max(w1, 0.0), max(w2, 0.0)
    total = w0 + w1 + w2
    w0, w1, w2 = w0 / total, w1 / total, w2 / total
    nx = e1[1] * e2[2] - e1[2] * e2[1]
    ny = e1[2] * e2[0] - e1[0] * e2[2]
    nz = e1[0] * e2[1] - e1[1] * e2[0]
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / length, ny / length, nz / length
    dx = r[0] - w1 * e1[0] - w2 * e2[0]
    dy = r[1] - w1 * e1[1] - w2 * e2[1]
    dz = r[2] - w1 * e1[2] - w2 * e2[2]
    return dx * nx + dy * ny + dz * nz, w0, w1, w2, nx, ny, nz, projects


@jit.jit
def _gap_to_facet(
    y: np.ndarray, s: int, facets: np.ndarray, j: int, margin: float
) -> tuple[float, float, float, float, float, float, float, bool]:
    """The gap, weights, normal and projection test of slave ``s`` on facet ``j`` (a segment
    or a triangle, by the facets' shape)."""
    if facets.shape[1] == 2:
        return _gap_to_segment(y, s, facets[j, 0], facets[j, 1], margin)
    return _gap_to_triangle(y, s, facets[j, 0], facets[j, 1], facets[j, 2], margin)


@jit.jit
def closest_points_compiled(
    y: np.ndarray,
    slaves: np.ndarray,
    facets: np.ndarray,
    cand: np.ndarray,
    depth: float,
    margin: float,
    hit: np.ndarray,
    gap: np.ndarray,
    weights: np.ndarray,
    normal: np.ndarray,
) -> None:
    """:func:`closest_points` compiled, 2D or 3D: a loop over the slaves and their candidates
    (the same choice and the same arithmetic). ``cand`` with one column ``-1`` takes every
    facet as a candidate of every slave."""
    nf, gdim = facets.shape[0], y.shape[1]
    every = cand.shape[1] == 1 and cand[0, 0] < 0
    width = nf if every else cand.shape[1]
    for i in range(slaves.shape[0]):
        s = slaves[i]
        hit[i] = -1
        top = -np.inf
        for jj in range(width):
            j = jj if every else cand[i, jj]
            if j >= nf:
                continue
            g, _, _, _, _, _, _, projects = _gap_to_facet(y, s, facets, j, margin)
            if projects and g < 0.0 and g > -depth and g > top:
                top = g
        if top == -np.inf:
            continue
        bj = nf
        for jj in range(width):  # of the facets alike, the first in order
            j = jj if every else cand[i, jj]
            if j >= bj:
                continue
            g, w0, w1, w2, nx, ny, nz, projects = _gap_to_facet(y, s, facets, j, margin)
            if projects and g < 0.0 and g > -depth and g >= top - TIE * depth:
                bj = j
                hit[i], gap[i] = j, g
                weights[i, 0], weights[i, 1], weights[i, 2] = w0, w1, w2
                normal[i, 0], normal[i, 1] = nx, ny
                if gdim == 3:
                    normal[i, 2] = nz


def check_friction(owner: str, mu: object) -> None:
    """Refuse a Coulomb coefficient ``mu`` that is not a finite number ``>= 0`` (``owner``:
    the class named in the error)."""
    if isinstance(mu, bool) or not (isinstance(mu, int | float) and np.isfinite(mu) and mu >= 0):
        raise ValueError(
            f"{owner}(friction={mu!r}): Coulomb's coefficient must be a number >= 0 (0: "
            "frictionless)"
        )


def coulomb_return(
    previous: np.ndarray, slip: np.ndarray, n: np.ndarray, k: np.ndarray, limit: np.ndarray
) -> tuple[np.ndarray, float]:
    """Coulomb's law regularised by a tangential penalty, with a return map (Wriggers,
    *Computational Contact Mechanics*, 2006): the tangential forces (m, gdim) of springs of
    stiffness ``k`` (m,) whose ``previous`` forces (m, gdim), turned into the tangent planes of
    the unit normals ``n`` (m, gdim), move by ``-k`` times the tangential part of ``slip`` (m,
    gdim), limited to ``limit`` (m,); and the work of the slips past the limit, ``sum limit
    (|trial| - limit) / k`` (the dissipated work of this evaluation)."""
    slip = slip - np.einsum("mk,mk->m", slip, n)[:, None] * n
    previous = previous - np.einsum("mk,mk->m", previous, n)[:, None] * n
    trial = previous - k[:, None] * slip
    size = np.linalg.norm(trial, axis=1)
    slides = size > limit
    force = trial.copy()
    force[slides] *= (limit[slides] / size[slides])[:, None]
    return force, float(np.dot(limit[slides], (size[slides] - limit[slides]) / k[slides]))


def contact_tangent(A: Sequence[PETSc.Mat | None], diagonal: PETSc.Vec) -> dict:
    """``A_k^T diag(c) A_l`` for every pair of fields ``(k, l)`` that reach the points, from the
    points' ``diagonal`` ``c`` (in the rows of ``A``; collective)."""
    root = diagonal.copy()
    root.sqrtabs()
    scaled = {}
    for k, Ak in enumerate(A):
        if Ak is not None:
            scaled[k] = Ak.copy()
            scaled[k].diagonalScale(L=root)
    out = {(k, m): Ak.transposeMatMult(Am) for k, Ak in scaled.items() for m, Am in scaled.items()}
    for obj in (root, *scaled.values()):
        obj.destroy()
    return out


def summed_tangent(inner: dict, contact: dict, keep: list) -> dict:
    """The inner tangent's blocks plus the contact's (new matrices appended to ``keep``, which
    the caller destroys)."""
    blocks = dict(inner)
    for km, Kc in contact.items():
        if km in blocks:
            K = blocks[km].convert("aij", PETSc.Mat())  # a new matrix
            K.axpy(1.0, Kc, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            keep.append(K)
            blocks[km] = K
        else:
            blocks[km] = Kc
    return blocks


class PointPenaltySystem(WrappedSystem):
    """A :class:`~dolfinx_meshfree.dynamics.system.SemiDiscreteSystem` plus penalty forces at
    points that move with the model, ``y = X + A d`` (``A_k`` per field: the model's
    evaluation operator there): the inner internal force plus ``A^T f``, the inner strain
    energy plus the penalty's (:meth:`_evaluate`) and :meth:`_dissipated`, the inner tangent
    plus ``A^T diag(c) A`` with a ``c`` per point that bounds the penalty's stiffness in every
    contact state (:meth:`_bound`; for the stable step). Everything else is the inner system's.
    The base of :class:`BodyContactSystem` and of the rigid projectile's system
    (:mod:`~dolfinx_meshfree.dynamics.rigid_projectile`)."""

    def __init__(
        self, inner: SemiDiscreteSystem, operators: Sequence[PETSc.Mat | None], gdim: int
    ) -> None:
        super().__init__(inner)
        self.A, self.gdim = list(operators), int(gdim)
        some = next(A for A in self.A if A is not None)
        self.comm = some.getComm().tompi4py()
        self._y, self._f = some.createVecLeft(), some.createVecLeft()
        self._contact: dict | None = None  # A_k^T diag(c) A_l per pair of fields
        self._sums: list[PETSc.Mat] = []  # the inner blocks plus those, of the last tangent()
        #: Seconds spent in the penalty's forces since the build.
        self.seconds = 0.0

    def _evaluate(self, u: Sequence[PETSc.Vec]) -> float:
        """The points' share of the internal force at ``u`` into ``self._f`` (this rank's
        rows of ``A``); the stored energy (every rank)."""
        raise NotImplementedError

    def _bound(self) -> np.ndarray:
        """``c`` per owned point (its rows of ``A``, each component)."""
        raise NotImplementedError

    def _dissipated(self) -> float:
        """Work the penalty dissipated since the build (friction), counted as stored."""
        return 0.0

    def internal_force(
        self, u: Sequence[PETSc.Vec], out: Sequence[PETSc.Vec] | None = None
    ) -> list[PETSc.Vec]:
        """The inner force plus ``A^T f`` (collective)."""
        y = self.inner.internal_force(u, out)
        tic = time.perf_counter()
        self._evaluate(u)
        for A, yk in zip(self.A, y, strict=True):
            if A is not None:
                A.multTransposeAdd(self._f, yk, yk)
        self.seconds += time.perf_counter() - tic
        return y

    def strain_energy(self, u: Sequence[PETSc.Vec], f_int: Sequence[PETSc.Vec]) -> float:
        """The inner system's energy (from ``f_int`` minus the penalty's force) plus the
        penalty's stored energy and :meth:`_dissipated`: so the energy records' balance closes,
        ``internal`` then holding what friction dissipated."""
        energy = self._evaluate(u) + self._dissipated()
        inner_f = [x.copy() for x in f_int]
        self._f.scale(-1.0)
        for A, x in zip(self.A, inner_f, strict=True):
            if A is not None:
                A.multTransposeAdd(self._f, x, x)
        self._f.scale(-1.0)
        energy += self.inner.strain_energy(u, inner_f)
        for x in inner_f:
            x.destroy()
        return energy

    def tangent(self, u: Sequence[PETSc.Vec] | None = None) -> dict:
        """The inner tangent plus ``A_k^T diag(c) A_l`` on every pair of fields: an upper
        bound, in the PSD order, of the tangent of any contact state (for the stable step).
        The matrices returned stay valid until the next call."""
        if self._contact is None:
            c = self._f.duplicate()
            c.array[:] = np.repeat(self._bound(), self.gdim)
            self._contact = contact_tangent(self.A, c)
            c.destroy()
        for obj in self._sums:
            obj.destroy()
        self._sums = []
        return summed_tangent(self.inner.tangent(u), self._contact, self._sums)

    def destroy(self) -> None:
        """Destroy the penalty's objects and the inner system (collective)."""
        extra = (*(self._contact or {}).values(), *self._sums)
        for obj in (*self.A, self._y, self._f, *extra):
            if obj is not None:
                obj.destroy()
        self.inner.destroy()


class BodyContactSystem(PointPenaltySystem):
    """A :class:`~dolfinx_meshfree.dynamics.system.SemiDiscreteSystem` with contact between
    two bodies (module docstring): the inner system's internal force plus ``A^T f_c``, its
    strain energy plus the contact's stored energy (and friction's dissipated work), its
    tangent plus the contact bound ``A^T diag(c) A`` (for the stable step). Everything else is
    the inner system's.

    Args:
        inner: The system without this contact.
        surfaces: The pair's surfaces (replicated).
        operators: ``A_k`` per field (``None`` for a field that does not reach the surfaces).
        penalty: ``k`` (Pa/m). two_pass, depth, friction: As :class:`BodyContact` (``depth``
            resolved).
    """

    def __init__(
        self,
        inner: SemiDiscreteSystem,
        surfaces: ContactSurfaces,
        operators: Sequence[PETSc.Mat | None],
        penalty: float,
        two_pass: bool,
        depth: float,
        friction: float = 0.0,
    ) -> None:
        super().__init__(inner, operators, surfaces.points.shape[1])
        self.surfaces = surfaces
        self.penalty, self.two_pass, self.depth = float(penalty), bool(two_pass), float(depth)
        self._k = penalty * surfaces.tributary()
        seg_body = surfaces.body
        self._passes = [(0, 1)] + ([(1, 0)] if two_pass else [])
        self._slaves = [np.flatnonzero(surfaces.vertex_body == s) for s, _ in self._passes]
        self._masters = [surfaces.facets[seg_body == m] for _, m in self._passes]
        #: The last evaluated state: ``{"pairs", "penetration", "energy"}`` (every rank).
        self.last: dict = {"pairs": 0, "penetration": 0.0, "energy": 0.0}
        # the closest-point kernel: compiled (numba) when available, else numpy
        self._kernel = closest_points_compiled if jit.AVAILABLE else closest_points
        #: Coulomb's coefficient (0: frictionless); the work of the slips since the build.
        self.friction, self.dissipated = float(friction), 0.0
        nv, gdim = surfaces.points.shape
        self._active = [np.zeros(nv, dtype=bool) for _ in self._passes]
        self._traction = [np.zeros((nv, gdim)) for _ in self._passes]
        self._relative = [np.zeros((nv, gdim)) for _ in self._passes]
        self._facet = [np.zeros((nv, gdim), dtype=np.int64) for _ in self._passes]
        self._weights = [np.zeros((nv, gdim)) for _ in self._passes]

    def positions(self, u: Sequence[PETSc.Vec]) -> np.ndarray:
        """Current positions ``X + A d`` of every surface vertex (nv, gdim), on every rank."""
        self._y.set(0.0)
        for A, x in zip(self.A, u, strict=True):
            if A is not None:
                A.multAdd(x, self._y, self._y)
        disp = np.concatenate(self.comm.allgather(self._y.array_r.copy()))
        disp = disp.reshape(-1, self.gdim)
        return self.surfaces.points + disp

    def forces(self, y: np.ndarray) -> tuple[np.ndarray, float, int, float]:
        """The contact forces on the vertices (nv, gdim) at positions ``y`` (their share of the
        internal force), the stored energy (penalty, and with friction the tangential springs'),
        the number of closed pairs and the deepest penetration (replicated: the same on every
        rank). With friction the tangential springs' state moves to ``y`` (a second call at the
        same ``y`` gives the same forces and changes nothing)."""
        f = np.zeros_like(y)
        energy, pairs, deepest = 0.0, 0, 0.0
        gdim = y.shape[1]
        compiled = self._kernel is not closest_points
        closed: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for p, (slaves, facets) in enumerate(zip(self._slaves, self._masters, strict=True)):
            if compiled and len(slaves) * len(facets) <= EVERY_PAIR:
                near, cand = slaves, EVERY  # every pair, compiled: no search
            else:
                found = candidates(y, slaves, facets, self.depth)
                near, cand = found if found is not None else (slaves[:0], EVERY)
            d = facets.shape[1]
            hit, gap, w, n = self._closest(y, near, facets, cand)
            on = hit >= 0
            s, fac, g = near[on], facets[hit[on]], gap[on]
            w, n, ks = w[on, :d], n[on, :gdim], self._pair_stiffness(near[on], hit[on], p)
            total = (ks * g)[:, None] * n  # the slave's internal force: -k |g| n
            energy += 0.5 * float(np.dot(ks, g * g))
            if self.friction > 0.0:
                traction, stored = self._friction(p, s, y, fac, w, n, ks, g)
                total -= traction
                energy += stored
            np.add.at(f, s, total)
            for i in range(d):
                np.add.at(f, fac[:, i], -w[:, i, None] * total)
            pairs += len(s)
            deepest = max(deepest, float(-g.min(initial=0.0)))
            closed.append((fac, w, ks))
        #: The closed pairs of the last evaluation: their facets, weights and ``k_s``.
        self.closed = tuple(np.concatenate(c) for c in zip(*closed, strict=True))
        return f, float(energy), pairs, float(deepest)

    def project(
        self, y: np.ndarray, near: np.ndarray, facets: np.ndarray, cand: np.ndarray, margin: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each slave's closest facet ``hit`` (``-1``: none), gap, weights (m, 3) and normal
        (m, 3), the facets' weights allowed down to ``-margin`` (module docstring)."""
        m = len(near)
        hit = np.full(m, -1, dtype=np.int64)
        gap, w, n = np.zeros(m), np.zeros((m, 3)), np.zeros((m, 3))
        if m:
            self._kernel(y, near, facets, cand, self.depth, margin, hit, gap, w, n)
        return hit, gap, w, n

    def _closest(
        self, y: np.ndarray, near: np.ndarray, facets: np.ndarray, cand: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`project` with the margin :data:`XI_MARGIN` (a subclass may choose
        otherwise)."""
        return self.project(y, near, facets, cand, XI_MARGIN)

    def _pair_stiffness(self, slaves: np.ndarray, facets: np.ndarray, p: int) -> np.ndarray:
        """``k_s`` of closed pairs: the slaves' (``facets``: the indices of their facets among
        pass ``p``'s masters; a subclass may weigh the pair)."""
        return self._k[slaves]

    def _friction(
        self,
        p: int,
        s: np.ndarray,
        y: np.ndarray,
        fac: np.ndarray,
        w: np.ndarray,
        n: np.ndarray,
        ks: np.ndarray,
        g: np.ndarray,
    ) -> tuple[np.ndarray, float]:
        """Coulomb friction of pass ``p``'s closed pairs (module docstring): the tangential
        force on each slave (physical, opposing its slip) and the springs' stored energy; the
        state (force, relative position, contact) moves to ``y`` and the slip's work adds to
        :attr:`dissipated`."""
        rel = y[s] - np.einsum("mi,mik->mk", w, y[fac])
        was = self._active[p][s]
        prev_force = np.where(was[:, None], self._traction[p][s], 0.0)
        # the slip: the slave's motion relative to the master's material point it was at (the
        # previous facet and weights, at the current positions)
        at_prev = y[s] - np.einsum("mi,mik->mk", self._weights[p][s], y[self._facet[p][s]])
        step = np.where(was[:, None], at_prev - self._relative[p][s], 0.0)
        force, slipped = coulomb_return(prev_force, step, n, ks, self.friction * ks * np.abs(g))
        self.dissipated += slipped
        self._active[p][:] = False
        self._active[p][s] = True
        self._traction[p][s] = force
        self._relative[p][s] = rel
        self._facet[p][s] = fac
        self._weights[p][s] = w
        return force, 0.5 * float(np.sum(np.einsum("mk,mk->m", force, force) / ks))

    def _evaluate(self, u: Sequence[PETSc.Vec]) -> float:
        """Contact forces of ``u`` into the row vector; ``E_c`` (every rank)."""
        f, energy, pairs, deepest = self.forces(self.positions(u))
        lo, hi = self.surfaces.owned
        self._f.array[:] = f[lo:hi].ravel()
        self.last = {"pairs": pairs, "penetration": deepest, "energy": energy}
        return energy

    def contact_energy(self, u: Sequence[PETSc.Vec]) -> float:
        """``E_c`` at ``u`` (collective, every rank)."""
        return self._evaluate(u)

    def contact_force(self, u: Sequence[PETSc.Vec]) -> np.ndarray:
        """The resultant force (gdim,) that ``surface_b`` exerts on ``surface_a``'s body at ``u``
        (every rank)."""
        f, *_ = self.forces(self.positions(u))
        return -f[self.surfaces.vertex_body == 0].sum(axis=0)

    def _dissipated(self) -> float:
        """Friction's slips' work since the build (:attr:`dissipated`)."""
        return self.dissipated

    def bound_stiffness(self) -> np.ndarray:
        """``c`` per vertex (module docstring): ``diag(c)`` (each component) bounds the contact
        stiffness of any contact state in vertex space, in the PSD order."""
        s = self.surfaces
        measures, sizes = s.measures(), s.sizes()
        star = np.zeros(len(s.points))  # the length (area) of the facets at each vertex
        for i in range(s.facets.shape[1]):
            np.add.at(star, s.facets[:, i], measures)
        c = np.zeros(len(s.points))
        for slave, master in self._passes:
            on_s = s.vertex_body == slave
            c[on_s] += self._k[on_s]
            longest = float(sizes[s.body == slave].max(initial=0.0))
            on_m = s.vertex_body == master
            if self.gdim == 2:  # the star widened by one slave segment at each end
                pressing = star[on_m] + 2.0 * longest
                if s.axisymmetric:  # revolved at the largest radius the widened star reaches
                    pressing *= 2.0 * np.pi * (s.points[on_m, 0] + star[on_m] + longest)
            else:  # the star as a disc, its radius widened by one slave facet
                pressing = np.pi * (np.sqrt(star[on_m] / np.pi) + longest) ** 2
            c[on_m] += self.penalty * pressing
        return 2.0 * c

    def _bound(self) -> np.ndarray:
        """:meth:`bound_stiffness` of the owned vertices."""
        lo, hi = self.surfaces.owned
        return self.bound_stiffness()[lo:hi]


def carry_friction(old: object, new: object) -> int:
    """Carry the work friction dissipated from the model ``old`` (its system) into ``new``, the
    same model rebuilt on a changed patch (a conversion), contact by contact in the order they
    were added (:attr:`BodyContactSystem.dissipated`, which the energy records count). Without
    it the rebuilt model's dissipated work restarted at 0, and the conversion's
    ``strain_change`` booked the past friction's work as its own. The tangential springs start
    afresh (their stored energy is in ``strain_change``), as the rigid projectile's do. Returns
    the number carried."""
    before, after = wrapped(old, BodyContactSystem), wrapped(new, BodyContactSystem)
    for s0, s1 in zip(before, after, strict=False):
        s1.dissipated = s0.dissipated
    return min(len(before), len(after))


def with_body_contact(
    system: SemiDiscreteSystem,
    evaluator: FieldEvaluator,
    E: float | None,
    surface_a: npt.ArrayLike,
    surface_b: npt.ArrayLike,
    contact: BodyContact,
) -> BodyContactSystem:
    """``system`` with contact between the bodies of ``surface_a`` and ``surface_b``
    (collective; the checks raise on every rank before any collective call of their own)."""
    if not isinstance(contact, BodyContact):  # the same on every rank
        raise TypeError(
            f"contact must be a BodyContact, got {type(contact).__name__}: use "
            "contact=dolfinx_meshfree.dynamics.BodyContact()"
        )
    d = evaluator.disc
    raise_on_all_ranks(evaluator.comm, lambda: _check_evaluable(evaluator))
    surfaces, vertices, cells = contact_surfaces(d.mesh, surface_a, surface_b)
    surfaces.axisymmetric = d.axisymmetric  # the penalty per unit revolved area
    sizes = surfaces.sizes()
    h = float(np.median(sizes))
    if contact.penalty is None and E is None:  # the same on every rank
        raise ValueError(
            "BodyContact(penalty=None) takes k = factor E / h from a material with Young's "
            "modulus E; this material has none: pass BodyContact(penalty=k) in Pa/m"
        )
    factor = 1.0 if contact.factor is None else float(contact.factor)
    k = float(contact.penalty) if contact.penalty is not None else factor * E / h
    depth = float(contact.depth) if contact.depth is not None else float(sizes.max())
    tables = evaluator.point_tables(vertex_coordinates(d.mesh)[vertices], cells)
    _check_particles_apart(evaluator, surfaces, tables[1])  # before any PETSc object
    A = evaluation_operators(evaluator, surfaces, tables, system.mass())
    two_pass = contact.two_pass is not False
    return BodyContactSystem(system, surfaces, A, k, two_pass, depth, contact.friction)


def _check_particles_apart(
    evaluator: FieldEvaluator, surfaces: ContactSurfaces, A_p: sp.csr_matrix | None
) -> None:
    """Refuse a particle whose function reaches both surfaces (its support joins the bodies),
    from the owned vertices' particle table ``A_p`` (on every rank)."""
    d = evaluator.disc
    if d.particles is None:
        return
    lo, hi = surfaces.owned
    body = surfaces.vertex_body[lo:hi]
    seen = []
    for b in (0, 1):
        rows = A_p[np.flatnonzero(body == b)] if A_p is not None else sp.csr_matrix((0, 0))
        local = np.unique(rows.tocoo().col[rows.tocoo().data != 0.0])
        keys = d.particles.petsc_index[local] if local.size else np.zeros(0, dtype=np.int64)
        seen.append(np.unique(np.concatenate(evaluator.comm.allgather(keys))))
    both = np.intersect1d(*seen)
    if both.size:
        where = np.round(_particle_position(d.particles, int(both[0]), evaluator.comm), 6)
        raise_on_all_ranks(
            evaluator.comm,
            lambda: _raise(
                f"the particle at {where.tolist()} reaches both contact surfaces ({both.size} "
                "such particles): its support joins the two bodies, so they cannot separate "
                "or press on each other; build the particles' MLS with "
                "mf.separate_bodies(mls, mesh) (the model's own MLS has it), or make the gap "
                "between the bodies wider than the particles' support radius"
            ),
        )


def _particle_position(particles: ParticleSet, petsc_index: int, comm: MPI.Comm) -> np.ndarray:
    """The position of the particle with this PETSc index (every rank)."""
    at = np.flatnonzero(particles.petsc_index == petsc_index)
    x = particles.positions[at[0]] if at.size else None
    found = [p for p in comm.allgather(x) if p is not None]
    return np.asarray(found[0])
