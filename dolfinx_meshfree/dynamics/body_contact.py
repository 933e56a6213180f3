"""Contact between bodies in explicit dynamics (2D): a node-to-segment penalty on the normal gap,
frictionless, between two surfaces of one model (issue 27, item 2).

Two bodies are two pieces of one mesh (cells that share no vertex), each discretised as the
model discretises it: FE cells, particle cells, blended cells. A contact pair is two sets of
exterior facets, ``surface_a`` and ``surface_b``. Their vertices ``X_v`` move with the model's
field there, ``y_v = X_v + u_h(X_v)``: FE nodal values on FE cells, the MLS approximation on
particle cells, the blended functions on the ramps' interface cells and bridging's band, so
that ``y = X + A d`` with ``A`` the model's evaluation operator at the vertices
(:meth:`~dolfinx_meshfree.dynamics.evaluation.FieldEvaluator.point_tables`; master–slave
expands its slaves, ``A_P (T_PF d_FE + S d_M)``, Rabczuk et al. 2006, eq. 27).

For a slave vertex ``s`` and a segment ``(a, b)`` of the other surface, at the current positions,

.. math::
    \\xi = \\frac{(y_s - y_a) \\cdot t}{t \\cdot t}, \\quad t = y_b - y_a, \\qquad
    g = (y_s - y_a - \\xi t) \\cdot n, \\quad n = \\frac{(t_2, -t_1)}{|t|},

``n`` the segment's outward normal (the segment is oriented at build time so that it points
away from its cell). The slave is in contact with the segment when ``-depth < g < 0`` and
``xi`` lies in ``[-0.05, 1.05]``; of several such segments the one with the largest ``g`` (the
nearest surface) is taken. The penalty energy and its force (the sign of ``M a + f^int =
f^ext``, added to the internal force) are

.. math::
    E_c = \\tfrac12 \\sum_s k_s \\min(g_s, 0)^2, \\qquad
    f_s = k_s g_s n, \\quad f_a = -(1 - \\xi) k_s g_s n, \\quad f_b = -\\xi k_s g_s n,

in the vertices' displacement space, then ``A^T f`` on the dofs. At a closest point inside the
segment (``0 < xi < 1``), ``∂g/∂y = (n, -(1 - xi) n, -xi n)`` exactly (the variations of ``xi``
and ``n`` multiply ``t . n = 0`` and ``n . dn = 0``), so the force is the gradient of ``E_c``
(beyond a segment's end, within the 5 % margin, ``xi`` is clipped and it is not quite):
central differences conserve ``kinetic + strain + E_c`` up to the non-smoothness of the
contact's start and end (measured in ``tests/test_body_contact.py``). ``k_s = k w_s``, ``k``
the penalty per unit area (Pa/m) and ``w_s`` the slave's tributary length (half its two
segments). With ``two_pass`` (default)
each surface is slave to the other in turn, so that a coarse surface's segments cannot pass
between a fine surface's vertices unnoticed, whatever the two meshes' spacings.

The stable step sees the contact (:meth:`BodyContactSystem.tangent`). A closed pair adds
``k_s b b^T`` with ``b = (1, -(1 - xi), -xi) (x) n``; by Cauchy–Schwarz with weights
proportional to ``(1, 1 - xi, xi)``, ``b b^T <= 2 diag(1, 1 - xi, xi) (x) I``. Summed over the
pairs that can close, the contact stiffness in vertex space is at most ``diag(c)`` in the PSD
order, per pass ``c_s += 2 k_s`` on a slave and ``c_m += 2 k (L_m + 2 l)`` on a master vertex
(``L_m`` the length of its segments, ``l`` the other surface's longest segment: the slave length
that can press on them when the faces meet face to face). So the step is bounded with ``K +
A^T diag(c) A``, safe for every contact state: measured on two bars of 10 cells pressed together,
the largest frequency of ``M^-1 (K + K_c)`` is 32.0, the bound 56.3, the bound without contact
22.8 (``tests/test_body_contact.py``).

The closest points are found by a compiled loop (:func:`closest_points_compiled`, numba) over
every (slave, segment) pair up to :data:`EVERY_PAIR` pairs, beyond that over the
:data:`CANDIDATES` nearest segments of a KD-tree (:func:`candidates`); without numba,
:func:`closest_points` (numpy, the reference) on the KD-tree's candidates.

Left out: friction, 3D (node-to-face), self-contact, particles of two bodies against each
other (their MLS supports would have to stop at the bodies' gap: refused when one particle's
function reaches both surfaces), and contact surfaces that change during a run (an adaptive
patch rebuilds the model: add the contact in the user's ``build``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Collection, Sequence
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
from ..parallel import Layout, raise_on_all_ranks
from ..statics.petsc import create_aij

if TYPE_CHECKING:  # annotations only
    from .evaluation import FieldEvaluator
    from .system import SemiDiscreteSystem

__all__ = [
    "BodyContact",
    "BodyContactSystem",
    "ContactSurfaces",
    "candidates",
    "closest_points",
    "closest_points_compiled",
    "contact_surfaces",
    "evaluation_operators",
    "vertex_coordinates",
    "with_body_contact",
]

#: How far beyond a segment's ends (in fractions of it) a slave still projects onto it.
XI_MARGIN = 0.05
#: Nearest segments (by midpoint) examined per slave vertex.
CANDIDATES = 8
#: Up to this many (slave, segment) pairs the compiled kernel examines every pair (no search:
#: 1.6 us for 21 x 20 pairs, against 100 us for the tree's candidates).
EVERY_PAIR = 100_000
#: The candidate array that makes the compiled kernel take every segment.
EVERY = np.full((1, 1), -1, dtype=np.int64)


@dataclasses.dataclass(frozen=True)
class BodyContact:
    """Options of frictionless contact between two bodies (a penalty on the normal gap).

    Attributes:
        factor: The penalty ``k = factor * E / h`` per unit area (Pa/m) when ``penalty`` is
            ``None``, ``h`` the median length of the surfaces' segments and ``E`` the
            material's Young's modulus: under a contact pressure ``p`` the surfaces
            interpenetrate by ``p / k = (p / E) h / factor`` (two-pass: half that), the elastic
            shortening of one cell at that stress over ``factor``. The default 1 keeps the
            penetration at the cell's own strain and lowers the stable step by the factor
            printed in ``critical_time_step`` (measured on the bars of
            ``demos/bar_impact.py``: 0.39-0.41x the step without contact).
        penalty: ``k`` itself (Pa/m), or ``None``.
        two_pass: Each surface's vertices against the other's segments (default), or only
            ``surface_a``'s vertices against ``surface_b``'s segments.
        depth: The deepest penetration still taken for contact (m); ``None``: the longest
            segment of the two surfaces. A vertex deeper than that behind a segment is taken to
            be elsewhere (the far side of a thin body).
    """

    factor: float = 1.0
    penalty: float | None = None
    two_pass: bool = True
    depth: float | None = None

    def __post_init__(self) -> None:
        for name in ("factor", "penalty", "depth"):
            value = getattr(self, name)
            if name != "factor" and value is None:
                continue
            if isinstance(value, bool) or not (
                isinstance(value, int | float) and np.isfinite(value) and value > 0.0
            ):
                raise ValueError(
                    f"BodyContact({name}={value!r}): {name} must be a positive number"
                    + (" or None" if name != "factor" else "")
                )
        if not isinstance(self.two_pass, bool):
            raise ValueError(f"BodyContact(two_pass={self.two_pass!r}) must be True or False")


@dataclasses.dataclass
class ContactSurfaces:
    """The two surfaces of a contact pair, replicated on every rank.

    Attributes:
        points: Reference positions of the surfaces' vertices (nv, 2), in the order of the
            rows of the evaluation operator (each rank's owned vertices in turn).
        segments: (ns, 2) vertex indices of each segment, ordered so that ``(t_2, -t_1)``
            points out of its body.
        body: 0 (``surface_a``) or 1 (``surface_b``) per segment. vertex_body: the same per
            vertex.
        owned: This rank's rows ``[start, end)`` of the vertices.
    """

    points: np.ndarray
    segments: np.ndarray
    body: np.ndarray
    vertex_body: np.ndarray
    owned: tuple[int, int]

    def lengths(self) -> np.ndarray:
        """Reference length of each segment."""
        p = self.points[self.segments]
        return np.linalg.norm(p[:, 1] - p[:, 0], axis=1)

    def tributary(self) -> np.ndarray:
        """Half the length of the segments at each vertex (the slave's weight ``w_s``)."""
        w = np.zeros(len(self.points))
        half = 0.5 * self.lengths()
        np.add.at(w, self.segments[:, 0], half)
        np.add.at(w, self.segments[:, 1], half)
        return w


def _facets(msh: dolfinx.mesh.Mesh, facets: npt.ArrayLike, name: str) -> np.ndarray:
    """``facets`` validated as owned exterior facets (on every rank)."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    n_own = msh.topology.index_map(tdim - 1).size_local
    exterior = np.asarray(dolfinx.mesh.exterior_facet_indices(msh.topology))

    def check() -> np.ndarray:
        f = np.asarray(facets)
        if f.ndim != 1 or (f.size and not np.issubdtype(f.dtype, np.integer)):
            raise ValueError(
                f"{name} must be a 1D array of facet indices, got {f!r:.80}: pass owned "
                "exterior facets, e.g. mf.boundary_facets(mesh, marker)"
            )
        if f.size and (f.min() < 0 or f.max() >= n_own):
            raise ValueError(
                f"{name} names facets that are not owned here (valid 0..{n_own - 1}): pass "
                "owned exterior facets, e.g. mf.boundary_facets(mesh, marker)"
            )
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
        ValueError: facets that are not owned exterior facets, an empty surface, a 3D mesh,
            or surfaces that share a vertex (on every rank).
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
            segs.append(np.zeros((0, 2), dtype=np.int64))
            continue
        v = np.array([f2v.links(f) for f in facets], dtype=np.int32)
        cells = np.array([f2c.links(f)[0] for f in facets], dtype=np.int32)
        mid_c = dolfinx.mesh.compute_midpoints(msh, tdim, cells)[:, :gdim]
        t = vx[v[:, 1]] - vx[v[:, 0]]
        outward = 0.5 * (vx[v[:, 0]] + vx[v[:, 1]]) - mid_c
        flip = t[:, 1] * outward[:, 0] - t[:, 0] * outward[:, 1] < 0.0
        v[flip] = v[flip][:, ::-1]
        segs.append(l2g[v])
        bodies.append(np.full(len(v), body))
    local_segs = np.concatenate(segs)
    local_body = np.concatenate([*bodies, np.zeros(0, dtype=int)])
    all_segs = np.concatenate(comm.allgather(local_segs)).reshape(-1, 2)
    all_body = np.concatenate(comm.allgather(local_body)).astype(np.int8)
    # the owned surface vertices, each rank's rows in turn, sorted by global index: every
    # owned vertex that any rank's segments name (it may sit only on another rank's facets)
    named = np.unique(all_segs)
    owned_v = np.flatnonzero(np.isin(l2g[: vmap.size_local], named)).astype(np.int32)
    owned_v = owned_v[np.argsort(l2g[owned_v], kind="stable")]
    keys = np.concatenate(comm.allgather(l2g[owned_v]))
    points = np.concatenate(comm.allgather(vx[owned_v])).reshape(-1, gdim)
    counts = comm.allgather(len(owned_v))
    start = int(sum(counts[: comm.rank]))
    order = np.argsort(keys, kind="stable")
    segments = order[np.searchsorted(keys[order], all_segs)]
    vertex_body = np.full(len(keys), -1, dtype=np.int8)
    for body in (0, 1):
        at = np.unique(segments[all_body == body])
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
    surf = ContactSurfaces(points, segments, all_body, vertex_body, (start, start + len(owned_v)))
    return surf, owned_v, cells


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
    if gdim != 2 or tdim != 2:
        raise ValueError(
            f"contact between bodies is available in 2D only (this mesh: gdim={gdim}, "
            f"tdim={tdim}): node-to-face contact in 3D is not built"
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
    vertices: np.ndarray,
    cells: np.ndarray,
    masses: Sequence[PETSc.Vec],
) -> list[PETSc.Mat]:
    """``A_k`` per field: the displacement at the owned surface vertices (rows ``2 i + c`` of
    :class:`ContactSurfaces`' order) from the field's dofs (collective)."""
    d = evaluator.disc
    comm = evaluator.comm
    gdim = 2
    raise_on_all_ranks(comm, lambda: _check_evaluable(evaluator))
    X = vertex_coordinates(d.mesh)[vertices]
    A_fe, A_p = evaluator.point_tables(X, cells)
    nv_global = len(surfaces.points)
    rows = Layout(gdim * len(vertices), gdim * nv_global, gdim * surfaces.owned[0])
    start = surfaces.owned[0]
    names = [f.name for f in d.fields]

    def expand(table: sp.csr_matrix, cols: np.ndarray) -> sp.csr_matrix:
        """(vertices x nodes) with node -> dof per component ``cols`` (nodes, 2) into (global
        rows x global dofs)."""
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
    y: np.ndarray, slaves: np.ndarray, segs: np.ndarray, depth: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """The slaves within the master segments' box (widened by ``depth``) and, per slave, the
    indices of its candidate segments (every segment up to :data:`CANDIDATES` of them, else
    the :data:`CANDIDATES` nearest by midpoint; ``len(segs)`` marks none); ``None`` when no
    slave is near."""
    if not len(slaves) or not len(segs):
        return None
    ya, yb, ys = y[segs[:, 0]], y[segs[:, 1]], y[slaves]
    lo = np.minimum(ya.min(axis=0), yb.min(axis=0)) - depth
    hi = np.maximum(ya.max(axis=0), yb.max(axis=0)) + depth
    near = np.flatnonzero(np.all((ys >= lo) & (ys <= hi), axis=1))
    if not near.size:
        return None
    if len(segs) <= CANDIDATES:  # every segment a candidate
        cand = np.broadcast_to(np.arange(len(segs)), (near.size, len(segs)))
    else:
        reach = depth + float(np.max(np.linalg.norm(yb - ya, axis=1)))
        _, cand = cKDTree(0.5 * (ya + yb)).query(ys[near], k=CANDIDATES, distance_upper_bound=reach)
    return slaves[near], np.ascontiguousarray(cand, dtype=np.int64).reshape(near.size, -1)


def closest_points(
    y: np.ndarray,
    slaves: np.ndarray,
    segs: np.ndarray,
    cand: np.ndarray,
    k: np.ndarray,
    depth: float,
    margin: float,
    f: np.ndarray,
) -> tuple[float, int, float]:
    """One pass of the penalty (module docstring): each slave's closest penetrated candidate
    segment, its force added into ``f`` (nv, 2); returns ``E_c``, the pairs and the deepest
    penetration of the pass. The numpy reference of :func:`closest_points_compiled`."""
    ya, yb = y[segs[:, 0]], y[segs[:, 1]]
    valid = cand < len(segs)
    c = np.where(valid, cand, 0)
    ys = y[slaves][:, None, :]
    a, t = ya[c], yb[c] - ya[c]
    tt = t[..., 0] * t[..., 0] + t[..., 1] * t[..., 1]
    xi = ((ys[..., 0] - a[..., 0]) * t[..., 0] + (ys[..., 1] - a[..., 1]) * t[..., 1]) / tt
    length = np.sqrt(tt)
    nx, ny = t[..., 1] / length, -t[..., 0] / length
    xc = np.clip(xi, 0.0, 1.0)
    dx, dy = ys[..., 0] - a[..., 0] - xc * t[..., 0], ys[..., 1] - a[..., 1] - xc * t[..., 1]
    g = dx * nx + dy * ny
    ok = valid & (g < 0.0) & (g > -depth) & (xi >= -margin) & (xi <= 1.0 + margin)
    score = np.where(ok, g, -np.inf)
    best = np.argmax(score, axis=1)
    hit = np.flatnonzero(np.isfinite(score[np.arange(len(slaves)), best]))
    if not hit.size:
        return 0.0, 0, 0.0
    j = best[hit]
    s, seg = slaves[hit], segs[c[hit, j]]
    gs, xs = g[hit, j], xc[hit, j]
    fs = (k[s] * gs)[:, None] * np.stack([nx[hit, j], ny[hit, j]], axis=1)
    np.add.at(f, s, fs)
    np.add.at(f, seg[:, 0], -(1.0 - xs)[:, None] * fs)
    np.add.at(f, seg[:, 1], -xs[:, None] * fs)
    return 0.5 * float(np.dot(k[s], gs * gs)), len(hit), float(-gs.min())


@jit.jit
def _gap_to(
    y: np.ndarray, s: int, a: int, b: int, margin: float
) -> tuple[float, float, float, float, bool]:
    """``(g, xi clipped, n_x, n_y, projects)`` of slave ``s`` on the segment ``(a, b)``."""
    tx, ty = y[b, 0] - y[a, 0], y[b, 1] - y[a, 1]
    tt = tx * tx + ty * ty
    xi = ((y[s, 0] - y[a, 0]) * tx + (y[s, 1] - y[a, 1]) * ty) / tt
    length = np.sqrt(tt)
    nx, ny = ty / length, -tx / length
    xc = min(max(xi, 0.0), 1.0)
    g = (y[s, 0] - y[a, 0] - xc * tx) * nx + (y[s, 1] - y[a, 1] - xc * ty) * ny
    return g, xc, nx, ny, xi >= -margin and xi <= 1.0 + margin


@jit.jit
def _apply(
    y: np.ndarray, s: int, a: int, b: int, g: float, xc: float, nx: float, ny: float,
    k: np.ndarray, f: np.ndarray,
) -> float:  # fmt: skip
    """Add the pair's forces into ``f``; return its energy."""
    fx, fy = k[s] * g * nx, k[s] * g * ny
    f[s, 0] += fx
    f[s, 1] += fy
    f[a, 0] -= (1.0 - xc) * fx
    f[a, 1] -= (1.0 - xc) * fy
    f[b, 0] -= xc * fx
    f[b, 1] -= xc * fy
    return 0.5 * k[s] * g * g


@jit.jit
def closest_points_compiled(
    y: np.ndarray,
    slaves: np.ndarray,
    segs: np.ndarray,
    cand: np.ndarray,
    k: np.ndarray,
    depth: float,
    margin: float,
    f: np.ndarray,
) -> tuple[float, int, float]:
    """:func:`closest_points` compiled: a loop over the slaves and their candidates (the same
    choice and the same arithmetic; the forces summed in another order). ``cand`` with one
    column ``-1`` takes every segment as a candidate of every slave."""
    energy, pairs, deepest = 0.0, 0, 0.0
    nseg = segs.shape[0]
    every = cand.shape[1] == 1 and cand[0, 0] < 0
    width = nseg if every else cand.shape[1]
    for i in range(slaves.shape[0]):
        s = slaves[i]
        best, bj, bxi, bnx, bny = -np.inf, -1, 0.0, 0.0, 0.0
        for jj in range(width):
            j = jj if every else cand[i, jj]
            if j >= nseg:
                continue
            g, xc, nx, ny, projects = _gap_to(y, s, segs[j, 0], segs[j, 1], margin)
            if projects and g < 0.0 and g > -depth and g > best:
                best, bj, bxi, bnx, bny = g, j, xc, nx, ny
        if bj < 0:
            continue
        energy += _apply(y, s, segs[bj, 0], segs[bj, 1], best, bxi, bnx, bny, k, f)
        pairs += 1
        deepest = max(deepest, -best)
    return energy, pairs, deepest


class BodyContactSystem:
    """A :class:`~dolfinx_meshfree.dynamics.system.SemiDiscreteSystem` with contact between
    two bodies (module docstring): the inner system's internal force plus ``A^T f_c``, its
    strain energy plus ``E_c``, its tangent plus the contact bound ``A^T diag(c) A`` (for the
    stable step). Everything else is the inner system's.

    Args:
        inner: The system without this contact.
        surfaces: The pair's surfaces (replicated).
        operators: ``A_k`` per field (``None`` for a field that does not reach the surfaces).
        penalty: ``k`` (Pa/m). two_pass, depth: As :class:`BodyContact` (``depth`` resolved).
    """

    def __init__(
        self,
        inner: SemiDiscreteSystem,
        surfaces: ContactSurfaces,
        operators: Sequence[PETSc.Mat | None],
        penalty: float,
        two_pass: bool,
        depth: float,
    ) -> None:
        self.inner, self.surfaces, self.A = inner, surfaces, list(operators)
        self.penalty, self.two_pass, self.depth = float(penalty), bool(two_pass), float(depth)
        some = next(A for A in self.A if A is not None)
        self.comm = some.getComm().tompi4py()
        self._y = some.createVecLeft()
        self._f = some.createVecLeft()
        self._k = penalty * surfaces.tributary()
        seg_body = surfaces.body
        self._passes = [(0, 1)] + ([(1, 0)] if two_pass else [])
        self._slaves = [np.flatnonzero(surfaces.vertex_body == s) for s, _ in self._passes]
        self._masters = [surfaces.segments[seg_body == m] for _, m in self._passes]
        self._contact: dict | None = None  # A_k^T diag(c) A_l per pair of fields
        self._sums: list[PETSc.Mat] = []  # the inner blocks plus those, of the last tangent()
        #: The last evaluated state: ``{"pairs", "penetration", "energy"}`` (every rank).
        self.last: dict = {"pairs": 0, "penetration": 0.0, "energy": 0.0}
        #: The closest-point kernel: compiled (numba) when available, else numpy.
        self._kernel = closest_points_compiled if jit.AVAILABLE else closest_points
        #: Seconds spent in the contact's forces (search, forces, ``A^T f``) since the build.
        self.seconds = 0.0

    def __getattr__(self, name: str):  # the inner system's attributes (blocks, shared, ...)
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def fields(self) -> list:
        return self.inner.fields

    def mass(self) -> list[PETSc.Vec]:
        return self.inner.mass()

    def constraints(self) -> list[PETSc.Mat | None] | None:
        return self.inner.constraints()

    def rebuild(self, changed: Collection[str]) -> bool:
        return self.inner.rebuild(changed)

    def positions(self, u: Sequence[PETSc.Vec]) -> np.ndarray:
        """Current positions ``X + A d`` of every surface vertex (nv, 2), on every rank."""
        self._y.set(0.0)
        for A, x in zip(self.A, u, strict=True):
            if A is not None:
                A.multAdd(x, self._y, self._y)
        disp = np.concatenate(self.comm.allgather(self._y.array_r.copy())).reshape(-1, 2)
        return self.surfaces.points + disp

    def forces(self, y: np.ndarray) -> tuple[np.ndarray, float, int, float]:
        """The contact forces on the vertices (nv, 2) at positions ``y``, ``E_c``, the number
        of closed pairs and the deepest penetration (replicated: the same on every rank)."""
        f = np.zeros_like(y)
        energy, pairs, deepest = 0.0, 0, 0.0
        compiled = self._kernel is closest_points_compiled
        for slaves, segs in zip(self._slaves, self._masters, strict=True):
            if compiled and len(slaves) * len(segs) <= EVERY_PAIR:
                near, cand = slaves, EVERY  # every pair, compiled: no search
            else:
                found = candidates(y, slaves, segs, self.depth)
                if found is None:
                    continue
                near, cand = found
            e, p, d = self._kernel(y, near, segs, cand, self._k, self.depth, XI_MARGIN, f)
            energy, pairs, deepest = energy + e, pairs + int(p), max(deepest, d)
        return f, float(energy), pairs, float(deepest)

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

    def internal_force(
        self, u: Sequence[PETSc.Vec], out: Sequence[PETSc.Vec] | None = None
    ) -> list[PETSc.Vec]:
        """The inner force plus ``A^T f_c`` (collective)."""
        y = self.inner.internal_force(u, out)
        tic = time.perf_counter()
        self._evaluate(u)
        for A, yk in zip(self.A, y, strict=True):
            if A is not None:
                A.multTransposeAdd(self._f, yk, yk)
        self.seconds += time.perf_counter() - tic
        return y

    def contact_force(self, u: Sequence[PETSc.Vec]) -> np.ndarray:
        """The resultant force (2,) that ``surface_b`` exerts on ``surface_a``'s body at ``u``
        (every rank)."""
        f, *_ = self.forces(self.positions(u))
        return -f[self.surfaces.vertex_body == 0].sum(axis=0)

    def strain_energy(self, u: Sequence[PETSc.Vec], f_int: Sequence[PETSc.Vec]) -> float:
        """The inner system's energy (from ``f_int`` minus the contact force) plus ``E_c``."""
        energy = self._evaluate(u)
        inner_f = [x.copy() for x in f_int]
        for A, x in zip(self.A, inner_f, strict=True):
            if A is not None:
                self._f.scale(-1.0)
                A.multTransposeAdd(self._f, x, x)
                self._f.scale(-1.0)
        energy += self.inner.strain_energy(u, inner_f)
        for x in inner_f:
            x.destroy()
        return energy

    def bound_stiffness(self) -> np.ndarray:
        """``c`` per vertex (module docstring): ``diag(c)`` (each component) bounds the contact
        stiffness of any contact state in vertex space, in the PSD order."""
        s = self.surfaces
        lengths = s.lengths()
        at_vertex = np.zeros(len(s.points))
        np.add.at(at_vertex, s.segments[:, 0], lengths)
        np.add.at(at_vertex, s.segments[:, 1], lengths)
        c = np.zeros(len(s.points))
        for slave, master in self._passes:
            on_s = s.vertex_body == slave
            c[on_s] += self._k[on_s]
            longest = float(lengths[s.body == slave].max(initial=0.0))
            on_m = s.vertex_body == master
            c[on_m] += self.penalty * (at_vertex[on_m] + 2.0 * longest)
        return 2.0 * c

    def tangent(self, u: Sequence[PETSc.Vec] | None = None) -> dict:
        """The inner tangent plus ``A_k^T diag(c) A_l`` on every pair of fields: an upper
        bound, in the PSD order, of the tangent of any contact state (for the stable step).
        The matrices returned stay valid until the next call."""
        if self._contact is None:
            lo, hi = self.surfaces.owned
            root = self._f.duplicate()
            root.array[:] = np.repeat(np.sqrt(self.bound_stiffness()[lo:hi]), 2)
            scaled = {}
            for k, A in enumerate(self.A):
                if A is not None:
                    scaled[k] = A.copy()
                    scaled[k].diagonalScale(L=root)
            self._contact = {
                (k, m): Ak.transposeMatMult(Am)
                for k, Ak in scaled.items()
                for m, Am in scaled.items()
            }
            for obj in (root, *scaled.values()):
                obj.destroy()
        for obj in self._sums:
            obj.destroy()
        self._sums = []
        blocks = dict(self.inner.tangent(u))
        for km, Kc in self._contact.items():
            if km in blocks:
                K = blocks[km].convert("aij", PETSc.Mat())  # a new matrix
                K.axpy(1.0, Kc, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                self._sums.append(K)
                blocks[km] = K
            else:
                blocks[km] = Kc
        return blocks

    def destroy(self) -> None:
        """Destroy the contact objects and the inner system (collective)."""
        extra = (*(self._contact or {}).values(), *self._sums)
        for obj in (*self.A, self._y, self._f, *extra):
            if obj is not None:
                obj.destroy()
        self.inner.destroy()


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
    surfaces, vertices, cells = contact_surfaces(d.mesh, surface_a, surface_b)
    lengths = surfaces.lengths()
    h = float(np.median(lengths))
    if contact.penalty is None and E is None:  # the same on every rank
        raise ValueError(
            "BodyContact(penalty=None) takes k = factor E / h from a material with Young's "
            "modulus E; this material has none: pass BodyContact(penalty=k) in Pa/m"
        )
    k = float(contact.penalty) if contact.penalty is not None else contact.factor * E / h
    depth = float(contact.depth) if contact.depth is not None else float(lengths.max())
    A = evaluation_operators(evaluator, surfaces, vertices, cells, system.mass())
    _check_particles_apart(evaluator, surfaces, vertices, cells)
    return BodyContactSystem(system, surfaces, A, k, contact.two_pass, depth)


def _check_particles_apart(
    evaluator: FieldEvaluator, surfaces: ContactSurfaces, vertices: np.ndarray, cells: np.ndarray
) -> None:
    """Refuse a particle whose function reaches both surfaces (its support joins the bodies)."""
    d = evaluator.disc
    if d.particles is None:
        return
    X = vertex_coordinates(d.mesh)[vertices]
    _, A_p = evaluator.point_tables(X, cells)
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
                "such particles): its MLS support joins the two bodies, so they cannot separate "
                "or press on each other; keep the particles in one body, or make the gap "
                "between the bodies wider than the particles' support radius"
            ),
        )


def _particle_position(particles, petsc_index: int, comm: MPI.Comm) -> np.ndarray:
    """The position of the particle with this PETSc index (every rank)."""
    at = np.flatnonzero(particles.petsc_index == petsc_index)
    x = particles.positions[at[0]] if at.size else None
    found = [p for p in comm.allgather(x) if p is not None]
    return np.asarray(found[0])
