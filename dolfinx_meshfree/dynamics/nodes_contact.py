"""Contact of every node of one body against another body's surface, for penetration and
perforation by a deformable projectile (issue 27, items 2 and 3): ``BodyContact(slaves="body")``.

The node-to-facet contact of :mod:`~dolfinx_meshfree.dynamics.body_contact` takes the vertices
of two *surfaces* as slaves. A projectile that perforates its target leaves no target surface in
front of it: it passes through material whose nodes were inside the body when the model was
built. LS-DYNA's eroding node-to-surface contact (``*CONTACT_ERODING_NODES_TO_SURFACE``) answers
this with every node of the target as a slave, and so does the rigid projectile of
:mod:`~dolfinx_meshfree.dynamics.rigid_projectile`, whose body is analytic. Here the master is a
deformable body's surface (``surface_b``: a steel projectile in FE, Johnson–Cook by
:class:`~dolfinx_meshfree.MaterialZones`), and the slaves are **every node of the other body**
(``surface_a``'s body, :func:`~dolfinx_meshfree.geometry.bodies.mesh_bodies`): the model's own
nodes on its cells, as the rigid projectile strikes them (FE and blended vertices, particles;
:func:`~dolfinx_meshfree.dynamics.rigid_projectile.contact_nodes`), at ``y = X + A d``.

Each slave is checked against ``surface_b``'s facets as a surface vertex is (the nearest facet
within ``depth`` behind it; the penalty ``E_c = 1/2 sum k g^2``; the force ``k g n`` on the
slave and ``-w_i k g n`` on the facet's vertices; Coulomb friction by option:
:class:`~dolfinx_meshfree.dynamics.body_contact.BodyContactSystem`), in one pass: the slaves'
body has no surface left to be pressed on.

**The penalty is weighed by mass**, not by area. A pair's stiffness is

.. math::
    k = \\text{factor}\\ \\omega_0^2\\ \\frac{m_s m_f}{m_s + m_f},

``factor`` 0.3 by default (:data:`FACTOR`, the rigid projectile's), ``omega_0`` the bound of
the model's largest frequency without this contact, ``m_s`` the slave's mass (a vertex's share
of the lumped masses ``sum_j |A_sj| m_j``, exact at an FE node; a particle's ``rho V_I``,
revolved in axisymmetry) and ``m_f`` the smallest mass of the facet's vertices: the pair's two
sides then oscillate at ``sqrt(factor) omega_0`` at most, and a light vertex of the projectile
(its tip, near the axis) pressed by a heavy node of the target does not take the step down. The
stiffness is taken when the slave enters contact and kept while it stays, whatever facet it
slides to, so that ``E_c`` stays continuous (``g`` is: the nearest facet is taken). Measured on
the bars (``tests/test_nodes_contact.py``): the same stiffness recomputed at every change of
facet put 2.1 % of energy into the model; an area weight with one cross-section per node
(``E / h`` times the spacing) pressed a body's corner twice as hard as its mass, the face tilted
and slid, and the bars gained 48 % energy.

**Entering and staying.** A slave enters contact only where it projects inside a facet (to
round-off, :data:`ENTRY`) and less than ``ENTRY_DEPTH`` of ``depth`` behind it: a slave found
deeper did not arrive by being pushed. Once in contact it stays while it projects within
:data:`~dolfinx_meshfree.dynamics.body_contact.XI_MARGIN` of a facet. Neither counts where the
slave lies in front of a facet neighbouring its own (sharing a vertex) that it projects inside:
that slave is outside the body at a convex corner, behind the plane of the facet around the
corner only. Measured on a square punch driven into a plate (``v0 / c = 0.05``, triangles):
without this test, the plate's nodes under the punch's corners were pushed sideways by its side
faces and the balance drifted by 8 % (FE) and 240 % (lagrange) to t = 3; with it, 0.13 % and
0.08 % (the surface contact: 0.05 %; ``tests/test_nodes_contact.py``). A wider margin for
slaves in contact (half a facet) let them slide past the projectile's shank end and cost the
Hanchak shot 1.1 % of its balance.

**The stable step** (the Cauchy–Schwarz bound of :mod:`~dolfinx_meshfree.dynamics.body_contact`,
``b b^T <= 2 diag(1, w_1, ..., w_d)``): ``c_s = 2 factor omega_0^2 m_s`` on a slave (``k <=
factor omega_0^2 m_s``) and ``c_m = 2 N_m factor omega_0^2 m_m`` on a master vertex (``k <=
factor omega_0^2 m_m``), ``N_m`` the slaves that can press its facets at once: the facets'
length (area) at the vertex over the slaves' median spacing, plus one, times :data:`DENSITY`
(room for a target compacted ahead of the nose). Each evaluation counts the master vertices'
actual ``2 sum k w_i`` over the closed pairs against ``c_m`` (:attr:`NodesContactSystem.bound_use`,
the largest ratio); above 1 the run stops with the vertex named, rather than stepping past its
stable step unseen.

**The axis is not a slave** in an axisymmetric model, for the rigid projectile's reason: a node on
it cannot move radially, so the nose would push it ahead through the whole target.

**depth** (default): the longest edge of the master facets, as the surface contact takes it. A
slave deeper than that behind its facet is let go (taken to be elsewhere).

**Through conversions** (:func:`carry_contacts`, called by
:func:`~dolfinx_meshfree.dynamics.patch_conversion.convert`): a rebuilt model's slave at the
reference position of one in contact keeps the stiffness it entered with. Measured without it:
the hybrid's first conversion beside a deformable projectile raised one pair's penalty energy
from 2,315 J to 8,484 J (the new model's ``omega_0`` and vertex mass are not the old ones), the
conversions put 2.2 % of the impact's energy into the model, and a cell inverted.

Left out: self-contact; the projectile's vertices as slaves of the target's surface (which
perforation removes); a penalty in Pa/m (``BodyContact(penalty=...)`` is refused here).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import dolfinx
import numpy as np
import numpy.typing as npt
from petsc4py import PETSc
from scipy.spatial import cKDTree

from ..geometry.bodies import Bodies, mesh_bodies
from ..parallel import raise_on_all_ranks
from .body_contact import (
    XI_MARGIN,
    BodyContact,
    BodyContactSystem,
    ContactSurfaces,
    _check_evaluable,
    _check_particles_apart,
    contact_surfaces,
    evaluation_operators,
    point_masses,
)
from .rigid_projectile import contact_nodes
from .system import wrapped

if TYPE_CHECKING:  # annotations only
    from .discretisation import Discretisation
    from .evaluation import FieldEvaluator
    from .system import SemiDiscreteSystem

__all__ = [
    "DENSITY",
    "ENTRY",
    "ENTRY_DEPTH",
    "FACTOR",
    "NodesContactSystem",
    "carry_contacts",
    "contacts",
    "with_nodes_contact",
]

#: The default ``factor`` of the mass-weighted penalty (the rigid projectile's): the pairs
#: oscillate at ``sqrt(0.3) omega_0`` at most. Measured on the Hanchak slab with a deformable
#: projectile (24 cells, FE, 430 m/s): the balance closes to 0.25 % against 1.47 % at
#: ``factor=1``, the exit velocity within 0.2 %.
FACTOR = 0.3
#: How far beyond a facet (in its weights) a slave may be to enter contact with it: round-off
#: (a slave at a master vertex), and how deep behind it, as a share of ``depth``: a slave
#: deeper than that did not arrive by being pushed (module docstring).
ENTRY, ENTRY_DEPTH = 1e-9, 0.25
#: How much denser than at their reference spacing the slaves pressing on one master vertex's
#: facets may be before the stable step's bound no longer holds (and the run stops, named).
DENSITY = 2.0


class NodesContactSystem(BodyContactSystem):
    """Contact of every node of one body (rows of vertex body 0) against the facets of another
    (body 1), one pass, with a mass-weighted penalty per pair (module docstring).

    Args:
        inner: The system without this contact.
        surfaces: The master facets and the rows: master vertices (body 1) and slaves (body 0).
        operators: ``A_k`` per field at the rows.
        depth, friction: As :class:`BodyContact` (``depth`` resolved).
        masses: The rows' masses ``m`` (module docstring).
        stiffness: ``factor omega_0^2``.
        spacing: The slaves' median spacing (m).
    """

    def __init__(
        self,
        inner: SemiDiscreteSystem,
        surfaces: ContactSurfaces,
        operators: Sequence[PETSc.Mat | None],
        depth: float,
        friction: float,
        masses: np.ndarray,
        stiffness: float,
        spacing: float,
    ) -> None:
        super().__init__(inner, surfaces, operators, 0.0, False, depth, friction)
        self.masses = np.asarray(masses, dtype=float)
        self.stiffness, self.spacing = float(stiffness), float(spacing)
        self._k = self.stiffness * np.where(surfaces.vertex_body == 0, self.masses, 0.0)
        #: The smallest vertex mass of each master facet.
        self.facet_mass = self.masses[surfaces.facets].min(axis=1)
        # the slaves in contact at the last evaluation and the stiffness each entered with
        self._held = np.zeros(len(self.masses), dtype=bool)
        self._kept = np.zeros(len(self.masses))
        self._ceiling = self.bound_stiffness()
        #: The largest ratio of a master vertex's contact stiffness to its bound, last
        #: evaluation (module docstring).
        self.bound_use = 0.0
        self._neighbours: np.ndarray | None = None
        # the positions of the last evaluation and the contact state before it
        self._last_y: np.ndarray | None = None
        self._before = (self._held.copy(), self._kept.copy())

    def _closest(
        self, y: np.ndarray, near: np.ndarray, facets: np.ndarray, cand: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A slave enters contact only where it projects inside a facet (weights down to
        ``-ENTRY``) less than ``ENTRY_DEPTH * depth`` behind it; one in contact at the last
        evaluation stays while it projects within ``XI_MARGIN`` of a facet; neither where it
        lies in front of a neighbouring facet it projects inside (:meth:`_outside`; module
        docstring)."""
        m = len(near)
        hit = np.full(m, -1, dtype=np.int64)
        gap, w, n = np.zeros(m), np.zeros((m, 3)), np.zeros((m, 3))
        held = self._held[near]
        for rows, margin in ((held, XI_MARGIN), (~held, ENTRY)):  # each slave projected once
            if rows.any():
                sub = cand[rows] if len(cand) == m else cand  # per slave, or every facet
                hit[rows], gap[rows], w[rows], n[rows] = self.project(
                    y, near[rows], facets, sub, margin
                )
        hit[~held & (gap <= -ENTRY_DEPTH * self.depth)] = -1
        hit[self._outside(y, near, facets, hit)] = -1
        return hit, gap, w, n

    def _outside(
        self, y: np.ndarray, near: np.ndarray, facets: np.ndarray, hit: np.ndarray
    ) -> np.ndarray:
        """Which slaves with a facet (``hit >= 0``) lie in front of a neighbouring facet (one
        sharing a vertex with it) that they project inside: outside the body at a convex
        corner, where only the facet around the corner has them behind its plane."""
        out = np.zeros(len(near), dtype=bool)
        on = np.flatnonzero(hit >= 0)
        if not on.size:
            return out
        if self._neighbours is None:
            self._neighbours = _facet_neighbours(facets)
        nb = self._neighbours[hit[on]]  # (k, width), -1 padded
        for j in range(nb.shape[1]):
            has = nb[:, j] >= 0
            if not has.any():
                continue
            rows = on[has]
            g, inside = _gaps(y, near[rows], facets[nb[has, j]])
            out[rows[inside & (g >= 0.0)]] = True
        return out

    def _pair_stiffness(self, slaves: np.ndarray, facets: np.ndarray, p: int) -> np.ndarray:
        """``factor omega_0^2 m_s m_f / (m_s + m_f)`` of each closed pair, taken when the slave
        enters contact and kept while it stays (module docstring). The state moves to this
        evaluation's pairs (a second evaluation of the same pairs changes nothing)."""
        m_s, m_f = self.masses[slaves], self.facet_mass[facets]
        k = np.where(
            self._held[slaves], self._kept[slaves], self.stiffness * m_s * m_f / (m_s + m_f)
        )
        self._held[:] = False
        self._held[slaves] = True
        self._kept[slaves] = k
        return k

    def capacity(self) -> np.ndarray:
        """``N_m`` per row (0 on the slaves): how many slaves can press a master vertex's
        facets at once (module docstring)."""
        s = self.surfaces
        measures = s.measures()  # the section's lengths in axisymmetry, not revolved
        star = np.zeros(len(s.points))
        for i in range(s.facets.shape[1]):
            np.add.at(star, s.facets[:, i], measures)
        across = star / self.spacing if self.gdim == 2 else np.sqrt(star) / self.spacing
        count = DENSITY * (across + 1.0) ** (self.gdim - 1)
        return np.where(s.vertex_body == 1, count, 0.0)

    def bound_stiffness(self) -> np.ndarray:
        """``c`` per row (module docstring): ``2 factor omega_0^2 m_s`` on a slave (or twice
        the stiffness it holds, if larger: one carried over a conversion), ``2 N_m factor
        omega_0^2 m_m`` on a master vertex."""
        c = 2.0 * self.stiffness * self.masses
        c = np.where(self._held, np.maximum(c, 2.0 * self._kept), c)
        return np.where(self.surfaces.vertex_body == 1, c * self.capacity(), c)

    def forces(self, y: np.ndarray) -> tuple[np.ndarray, float, int, float]:
        """As :meth:`BodyContactSystem.forces`, and the master vertices' stiffness of the
        closed pairs checked against the stable step's bound (every rank: the data are
        replicated, so every rank raises alike). A second evaluation at the same positions
        starts from the same contact state as the first (the energy records')."""
        if self._last_y is not None and np.array_equal(y, self._last_y):
            self._held, self._kept = self._before[0].copy(), self._before[1].copy()
        else:
            self._before = (self._held.copy(), self._kept.copy())
            self._last_y = y.copy()
        out = super().forces(y)
        fac, w, ks = self.closed
        actual = np.zeros(len(y))
        for i in range(fac.shape[1]):
            np.add.at(actual, fac[:, i], 2.0 * ks * w[:, i])
        on_m = self.surfaces.vertex_body == 1
        ratio = actual[on_m] / self._ceiling[on_m]
        self.bound_use = float(ratio.max(initial=0.0))
        if self.bound_use > 1.0:
            at = np.flatnonzero(on_m)[int(np.argmax(ratio))]
            raise ValueError(
                f"the slaves pressing on the master vertex at "
                f"{np.round(self.surfaces.points[at], 6).tolist()} (reference position) carry a "
                f"contact stiffness {self.bound_use:.3g}x the bound the stable step was taken "
                f"with: more than {DENSITY:g}x the slaves that fit its facets at their spacing "
                "press on them; refine the master surface or lower BodyContact(factor=...)"
            )
        return out


def contacts(system: object) -> list[NodesContactSystem]:
    """The nodes' contacts in a model's chain of wrapped systems (``system``, its ``inner``,
    ...), outermost first."""
    return wrapped(system, NodesContactSystem)


def carry_contacts(old: object, new: object) -> int:
    """Carry the closed pairs' stiffness from the model ``old`` (its system) into ``new``, the
    same model rebuilt on a changed patch (a conversion, :mod:`~dolfinx_meshfree.dynamics.
    patch_conversion`), contact by contact in the order they were added: a slave of the new
    model at the reference position of a slave in contact in the old one keeps the stiffness
    it entered with, so the penalty's energy ``k g^2 / 2`` does not jump (measured without it:
    the hybrid's first conversion beside a deformable projectile raised one pair's energy from
    2,315 J to 8,484 J, the new model's ``omega_0`` and the vertex's mass being another's);
    the new particles enter afresh. Before the new model's first force. Returns the number
    carried (every rank: the rows are replicated)."""
    before, after = contacts(old), contacts(new)
    for s0, s1 in zip(before, after, strict=False):
        slaves0 = np.flatnonzero((s0.surfaces.vertex_body == 0) & s0._held)
        slaves1 = np.flatnonzero(s1.surfaces.vertex_body == 0)
        if not slaves0.size or not slaves1.size:
            continue
        p0, p1 = s0.surfaces.points, s1.surfaces.points
        extent = float(np.ptp(p1, axis=0).max(initial=0.0))
        dist, at = cKDTree(p0[slaves0]).query(p1[slaves1])
        same = dist <= 1e-9 * max(extent, 1e-300)
        s1._held[slaves1[same]] = True
        s1._kept[slaves1[same]] = s0._kept[slaves0[at[same]]]
        s1._last_y = None
        s1._ceiling = s1.bound_stiffness()
        s1._contact = None  # the stable step's bound with the carried stiffness
    return min(len(before), len(after))


def _facet_neighbours(facets: np.ndarray) -> np.ndarray:
    """The facets (nf, d) sharing a vertex with each facet, itself excepted, ``-1`` padded."""
    by_vertex: dict[int, list[int]] = {}
    for f, vertices in enumerate(facets):
        for v in vertices:
            by_vertex.setdefault(int(v), []).append(f)
    lists = [
        sorted({g for v in vertices for g in by_vertex[int(v)]} - {f})
        for f, vertices in enumerate(facets)
    ]
    width = max((len(x) for x in lists), default=0)
    out = np.full((len(facets), max(width, 1)), -1, dtype=np.int64)
    for f, x in enumerate(lists):
        out[f, : len(x)] = x
    return out


def _gaps(y: np.ndarray, slaves: np.ndarray, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The signed gap of each slave to the plane of its facet (facets (k, d), one per slave)
    and whether it projects inside the facet (weights ``>= -ENTRY``)."""
    corners = y[facets]
    a = corners[:, 0]
    E = corners[:, 1:] - a[:, None, :]
    r = y[slaves] - a
    G = np.einsum("kid,kjd->kij", E, E)
    xi = np.linalg.solve(G, np.einsum("kid,kd->ki", E, r)[..., None])[..., 0]
    w = np.concatenate([1.0 - xi.sum(axis=1, keepdims=True), xi], axis=1)
    if facets.shape[1] == 2:
        n = np.stack([E[:, 0, 1], -E[:, 0, 0]], axis=1)
    else:
        n = np.cross(E[:, 0], E[:, 1])
    n /= np.linalg.norm(n, axis=1)[:, None]
    return np.einsum("kd,kd->k", r, n), np.all(w >= -ENTRY, axis=1)


def _spacings(points: np.ndarray) -> np.ndarray:
    """The distance of each point (m, gdim) to its nearest fellow (m,)."""
    if len(points) < 2:
        return np.zeros(len(points))
    dist, _ = cKDTree(points).query(points, k=2)
    return dist[:, 1]


def _bodies_of(msh: dolfinx.mesh.Mesh, facets: npt.ArrayLike, bodies: Bodies) -> np.ndarray:
    """The bodies whose cells hold ``facets`` (owned exterior facets), gathered (every rank)."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    f = np.asarray(facets, dtype=np.int64).reshape(-1)
    local = np.unique([bodies.cell_body[f2c.links(int(i))[0]] for i in f]).astype(np.int64)
    return np.unique(np.concatenate(msh.comm.allgather(local)))


def _densities(material: object, msh: dolfinx.mesh.Mesh) -> np.ndarray:
    """The density of every local cell (zones: their laws'; collective), or the one density
    (1,)."""
    if hasattr(material, "cell_zones"):
        return np.asarray(material.densities())[material.cell_zones(msh)]
    rho = getattr(material, "rho", None)
    if rho is None:  # the same on every rank
        raise_on_all_ranks(msh.comm, _no_density)
    return np.array([float(rho)])


def _particle_volumes(disc: Discretisation, index: np.ndarray) -> np.ndarray:
    """The particles' volumes (local indices): revolved in an axisymmetric model (the set's
    own revolved volumes where it has them, else ``2 pi r V``)."""
    P = disc.particles
    volumes = np.asarray(P.volumes, dtype=float)
    if not disc.axisymmetric:
        return volumes[index]
    if P.revolved_volumes is not None:
        return np.asarray(P.revolved_volumes, dtype=float)[index]
    return 2.0 * np.pi * P.positions[index, 0] * volumes[index]


def with_nodes_contact(
    system: SemiDiscreteSystem,
    evaluator: FieldEvaluator,
    material: object,
    omega_0: float,
    surface_a: npt.ArrayLike,
    surface_b: npt.ArrayLike,
    contact: BodyContact,
) -> NodesContactSystem:
    """``system`` with every node of ``surface_a``'s body in contact with ``surface_b``'s
    facets (module docstring); ``material`` the model's (its density, or its zones', for the
    particles' masses), ``omega_0`` the bound of the model's largest frequency without this
    contact. Collective; the checks raise on every rank before any collective call of their
    own."""
    d = evaluator.disc
    comm = evaluator.comm
    raise_on_all_ranks(comm, lambda: _check_evaluable(evaluator))
    if contact.penalty is not None:  # the same on every rank
        raise_on_all_ranks(comm, lambda: _no_penalty(contact.penalty))
    msh = d.mesh
    surf, _, cells_v = contact_surfaces(msh, surface_a, surface_b)
    gdim = surf.points.shape[1]
    bodies = mesh_bodies(msh)
    body_a = _bodies_of(msh, surface_a, bodies)
    if np.intersect1d(body_a, _bodies_of(msh, surface_b, bodies)).size:  # every rank alike
        raise_on_all_ranks(comm, _same_body)
    density = _densities(material, msh) if d.particles is not None else np.ones(1)
    # the rows: this rank's owned master vertices, then its slaves
    lo, hi = surf.owned
    is_b = surf.vertex_body[lo:hi] == 1
    points, cells, particle = contact_nodes(evaluator, None)
    slave = np.isin(bodies.cell_body[cells], body_a)
    if d.axisymmetric:  # the axis is not a slave (module docstring)
        extent = float(np.ptp(surf.points, axis=0).max(initial=0.0))
        slave &= points[:, 0] > 1e-12 * max(extent, 1e-300)
    points, cells, particle = points[slave], cells[slave], particle[slave]
    if comm.allreduce(len(points)) == 0:
        raise_on_all_ranks(comm, _no_slaves)
    n_b = int(is_b.sum())
    rows = np.concatenate([surf.points[lo:hi][is_b], points])
    row_cells = np.concatenate([cells_v[is_b], cells]).astype(np.int32)
    row_body = np.concatenate([np.ones(n_b, np.int8), np.zeros(len(points), np.int8)])
    counts = comm.allgather(len(rows))
    start = int(sum(counts[: comm.rank]))
    all_rows = np.concatenate(comm.allgather(rows)).reshape(-1, gdim)
    vertex_body = np.concatenate(comm.allgather(row_body)).astype(np.int8)
    # the master facets in the new rows
    old = np.concatenate(comm.allgather(np.arange(lo, hi)[is_b]))
    new = np.concatenate(comm.allgather(start + np.arange(n_b)))
    remap = np.full(len(surf.points), -1, dtype=np.int64)
    remap[old] = new
    facets = remap[surf.facets[surf.body == 1]]
    rows_surf = ContactSurfaces(
        all_rows, facets, np.ones(len(facets), dtype=np.int8), vertex_body,
        (start, start + len(rows)), d.axisymmetric,
    )  # fmt: skip
    on_s = vertex_body == 0
    spacing = float(np.median(_spacings(all_rows[on_s])))
    depth = float(contact.depth) if contact.depth is not None else float(rows_surf.sizes().max())
    tables = evaluator.point_tables(rows, row_cells)
    _check_particles_apart(evaluator, rows_surf, tables[1])  # before any PETSc object
    A = evaluation_operators(evaluator, rows_surf, tables, system.mass())
    m = point_masses(A, system.mass(), gdim)
    at = np.concatenate([np.full(n_b, -1), particle])
    if np.any(at >= 0):  # a particle's own mass, rho V_I (module docstring)
        rho = density[cells[particle >= 0]] if density.size > 1 else density[0]
        m[at >= 0] = rho * _particle_volumes(d, at[at >= 0])
    masses = np.concatenate(comm.allgather(m))
    factor = FACTOR if contact.factor is None else float(contact.factor)
    stiffness = factor * omega_0**2
    return NodesContactSystem(
        system, rows_surf, A, depth, contact.friction, masses, stiffness, spacing
    )


def _no_penalty(penalty: float) -> None:
    raise ValueError(
        f"BodyContact(slaves='body', penalty={penalty!r}): the contact of a body's nodes weighs "
        "each pair's penalty by the two sides' masses (factor omega_0^2 m_s m_f / (m_s + m_f)); "
        "leave penalty at None and scale it by factor"
    )


def _same_body() -> None:
    raise ValueError(
        "BodyContact(slaves='body'): surface_a and surface_b lie on the same body (a connected "
        "piece of the mesh): every node of surface_a's body would press on its own surface; "
        "pass the facets of two bodies that share no vertex"
    )


def _no_slaves() -> None:
    raise ValueError(
        "BodyContact(slaves='body'): surface_a's body has no node off the axis to press on "
        "surface_b; pass the facets of the body whose nodes are struck as surface_a"
    )


def _no_density() -> None:
    raise ValueError(
        "BodyContact(slaves='body') weighs a particle by its mass rho V_I; this material has no "
        "density rho: give the material one"
    )
