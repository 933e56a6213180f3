"""Master–slave FE–EFG coupling (Rabczuk, Xiao & Sauer 2006, sec. 5.1.2, eq. 17–28).

The particles next to the interface are slaves of the FE boundary: each is rigidly linked to the
closest-point projection ``C`` of its position ``P`` on the interface Gamma_I (eq. 17), and moves
with the FE edge through ``C`` (eq. 19–27, in 2D):

.. math::
    u_P = u_C + \\theta \\, e_z \\times (x_P - x_C), \\qquad
    u_C = (1 - \\xi) u_a + \\xi u_b, \\qquad
    \\theta = \\frac{t \\times (u_b - u_a)}{|t|^2},

where ``a, b`` are the end nodes of the edge, ``t = x_b - x_a`` and ``xi`` the edge coordinate
of ``C``. ``theta`` is the (small) rotation of the edge: eq. 29–31 take the angular velocity
from the rate of the surface normal, which for a straight edge is this rotation. Both ``u_C``
and ``theta`` are linear in the edge's nodal displacements, so ``u_P = T_I u_master`` (eq. 27)
and the forces on a slave go to its masters with ``T_I^T`` (eq. 28, work conjugacy). When
several edges are equally close (``C`` at a vertex, where the normal is undefined, or at equal
distance from two edges) the row of ``T`` is the mean of their rows: each reproduces rigid
motions, so the mean does too, and the choice does not depend on the partition.

The slaves (``slaves="layer"``, the default) are the particles on Gamma_I when every interface FE
node carries one (the default placement puts particles on the patch border's nodes and edges,
``placement="vertices"`` on the nodes): Johnson's coincident particles of sec. 5.1.1, with links
of length zero. Otherwise (a grid that does not meet Gamma_I, ``placement="grid"``) ``"layer"``
refuses the patch, by the first interface node without a particle: a linear field then missed by
up to 29 % on a disc patch, not converging (:class:`MasterSlaveLinks`). ``slaves="first-layer"``
takes the paper's variant there, the particles of the first layer: the particles "adjacent to
the FEM model" (sec. 5.1.2, Figure 1), i.e. those nearest to some stretch of Gamma_I, whose
Voronoi cells cut the interface, so that no other particle lies between a slave and the FE
side. Along each interface edge the nearest particle is the lower envelope of the distance,
computed exactly (:func:`_first_layer`); the links are between 0 and about one spacing
long, varying along the interface: first order in the mean link length
(rates 0.9-1.9 measured with coefficient ties).

What a link fixes (``tie``, :func:`_reduction`): the layer's default ``"values"`` ties the
slave's MLS *value*, ``u^h(x_P) = sum_J phi_J(x_P) u_J = u_P^{link}`` (Belytschko et al. 1995,
eq. 3.3), solved for the slaves' parameters as ``u_S = Phi_SS^{-1} (u_S^{link} - Phi_SM u_M)``;
``"coefficients"``, the default of ``"band"`` and ``"coincident"`` (the paper's), sets the
slave's nodal parameter ``u_P`` itself. MLS is not interpolating, so the two differ, and with
the coefficient tie the field at a slave is left free to follow its masters: the particle
field does not meet the FE trace even at the slaves. Measured on the robustness matrix
(``demos/robustness.py --coupling master-slave``, 135 cases, quadratic field): with coefficient
ties and the first layer, 11 cases below rate 1.0 (curved patches in triangle and gmsh meshes,
rates 0.28-1.0, 5.9-31x FE), errors 0.84-37x plain FE (median 10); with value ties and the
particles on Gamma_I, every case at rate 1.09-2.87 with errors 0.84-9.5x FE (median 3.3), up to
7.3x lower (median 2.9x; six body-load cases on axis-aligned patches 1-19 % higher). Value ties on
the first layer's off-interface slaves impose the rigid link on the field itself (error
``|strain| x |PC|``), hence the particles on Gamma_I whenever they exist. On the aligned
cantilever (Table II set-up, spacing h) the coefficient tie happened to be lower (0.65-0.78x
pure Q1 against 0.92x, both at rate 2.0).

``slaves="band"`` keeps the layer one spacing wide: the particles within ``SLAVE_LAYER = 1.01 s``
of Gamma_I (``s``: the median nearest-neighbour distance), i.e. two rows when a row lies on
Gamma_I. It reproduces the paper's cantilever figures (rates 1.36/1.21/1.15 here against
1.23/1.23/1.13, Table II), but it is not robust: the rigid link drops the strain across the
layer, an error of about ``|strain| x |PC|``, and which particles lie within 1.01 s changes
along a staircase or curved interface and from one refinement to the next (a grid of 0.1 x
0.091 has s = 0.091 and one slave row at h = 1/8, but two at h = 1/16), so the error constant
jumps: on slanted, curved and gmsh patches with a quadratic field and a body load its L2 rate
was 0.4-1.0 with errors 13-35x plain FE (the first layer: 1.4-2.0, 1-8x).

Body loads on slaves: the slaves' share of ``f`` (particle load vector, tractions and cell
loads of :class:`~dolfinx_meshfree.CoupledLinearProblem` alike) reaches the masters through
``T^T`` (eq. 28) with the rest of the right-hand side, below.

With ``u = T u_m + g`` (rows: every dof, FE then particles; columns: the master dofs, the free
FE dofs and the free particles; ``g``: the known strong FE values carried to the slaves), the
reduced system is ``T^T K T u_m = T^T (f - K g)`` with ``K = blockdiag(K_FE, K_P)``. ``T`` has
the blocks ``[[I, 0], [T_PF, S]]`` (``S`` selects the free particles), so the reduced matrix is
assembled block by block with PETSc's products,

.. math::
    A_{FF} = K_{FE} + T_{PF}^T K_P T_{PF}\\;(\\mathrm{PtAP}), \\quad
    A_{FM} = T_{PF}^T K_P S, \\quad A_{MM} = S^T K_P S\\;(\\mathrm{PtAP}),

rather than as one ``PtAP`` on an AIJ conversion of the whole ``K``: ``K`` is block diagonal, so
three products give the same matrix; the system stays a MatNest with the fields FE, free
particles and (patch-side) Dirichlet multipliers, which
:class:`~dolfinx_meshfree.statics.petsc.BlockSystem`
solves with MUMPS or its fieldsplit; and ``T`` keeps the natural FE and particle numberings
instead of the rank-interleaved row order of a converted nest. Strong FE conditions are applied
to ``K_FE`` as in :mod:`~dolfinx_meshfree.statics.coupled` (``MatZeroRowsColumns``) and their
columns
are removed from ``T_PF`` (their values go to ``g``); patch-side Dirichlet facets are multiplier
rows ``D`` of :func:`~dolfinx_meshfree.statics.efg.facet_multipliers` mapped through ``T``: ``D T``,
right-hand side ``d - D g``.

Johnson's coincident variant (``slaves="coincident"``, Rabczuk et al. 2006, sec. 5.1.1, eq.
15–16; Johnson 1994): the slaves are the particles *on* Gamma_I, and every interface FE node must
carry one. A particle on a node follows it, ``u_P = u_K`` (the row of ``T`` is the identity on
that node: a link of length zero), and the reduced explicit system gives the node and its particle
the common acceleration of eq. 16, ``a = (F_K + F_P) / (m_K + m_P)``: the row sums of ``T^T M T``
add the particle's lumped mass to the node's and ``T^T`` adds the particle's force to the node's
(eq. 15 takes both forces from the separately computed accelerations, ``F = m a``; the sum is the
same). Particles on Gamma_I between two nodes (a particle grid finer than the FE mesh) follow the
edge, ``u_P = (1 - xi) u_a + xi u_b`` (eq. 17–18 with ``P = C``), the extension of Johnson's
one-to-one pairing to ratios above 1:1. ``u_P`` is the particle's nodal parameter, as above.

Master–slave reproduces rigid motions exactly but not linear fields: a slave off Gamma_I moves
with the rotation of its edge, not with the strain of the field, so the linear patch test fails
by about ``|strain| x |PC|`` at the slaves; and a slave on Gamma_I matches the FE trace at its
point only (value tie) or not at all (coefficient tie: it ties its nodal parameter, not the
non-interpolating MLS field), so the two sides do not match between the slaves. The coupled
error is first order in general (the paper's rates 1.23/1.23/1.13 for the cantilever), second
order on aligned grids with the layer on Gamma_I. Consistent integration (``consistent=True``,
VCI over the patch boundary, Gamma_I included) cannot remove that mismatch and is not the
choice here: measured on the cantilever (spacing h, slaves on Gamma_I, coefficient ties), L2
errors 1.9e-2, 3.0e-3, 2.0e-4, 8.1e-4, 1.3e-3, 1.4e-3 for h = 3 ... 0.375 (no convergence),
against 2.2e-2 ... 5.3e-4 (rate 2.0) with Gauss integration; with value ties the linear patch
test error (spacing 1/3, 1/6, 1/12, FE cells 1/3) was 1.1e-2, 1.8e-3, 6.9e-3 with VCI against
1.1e-2, 1.9e-3, 2.4e-3 with Gauss (coefficient ties: 2.1e-2, 3.7e-3, 2.6e-3) on 4 x 4 points;
on the default rule that follows the particles
(:func:`~dolfinx_meshfree.geometry.quadrature.particle_quadrature_degree`: degrees 7, 15, 31)
it is 1.1e-2, 1.5e-3, 4.6e-4 with VCI and 1.1e-2, 1.5e-3, 4.5e-4 with Gauss (coefficient ties:
2.1e-2, 3.6e-3, 5.9e-4): smaller, not round-off.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, ClassVar

import dolfinx
import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from .. import _compat
from ..geometry.quadrature import DYNAMIC_FACET_DEGREE, facet_quadrature
from ..geometry.smoothing import value_rule
from ..geometry.stress_points import check_integration
from ..parallel import Layout, raise_on_all_ranks
from ..physics.axisymmetry import revolved_if
from ..statics.efg import facet_multipliers, particle_stiffness
from ..statics.kept_factor import KeptFactorisation
from ..statics.petsc import BlockSystem, SolverOptions, create_aij, create_vector
from .assembly import (
    component_conditions,
    essential_conditions,
    fe_active,
    fe_stiffness,
    fix_fe_rows,
    fixed_dofs,
    patch_rules,
    traction_loads,
)
from .base import CoupledSolution, CouplingDefaults, CouplingOperators, fe_dof_layout

if TYPE_CHECKING:  # annotations only: the model imports this module
    from ..statics.coupled import CoupledElasticity

__all__ = [
    "MASTER_SELECTION",
    "SLAVES",
    "SLAVE_LAYER",
    "TIES",
    "MasterSlaveLinks",
    "master_slave_operators",
    "outside_slave_layer",
    "slave_solve",
    "solve_master_slave",
    "strong_dofs",
]

#: ``slaves="band"``: particles within ``SLAVE_LAYER`` times the particle spacing of Gamma_I.
SLAVE_LAYER = 1.01

#: Which particles are slaves: the first layer (the particles nearest to Gamma_I, eq. 17–28;
#: ``"layer"`` refuses a layer off Gamma_I, ``"first-layer"`` takes it: the paper's variant),
#: the band within ``SLAVE_LAYER`` spacings (the paper's figures) or those on the interface FE
#: nodes and edges (Johnson's coincident particles, eq. 15–16).
SLAVES = ("layer", "first-layer", "band", "coincident")

#: What a slave's link fixes: its MLS value ``u^h(x_P)`` (default) or its nodal parameter
#: ``u_P`` (the paper's, eq. 27). See :func:`_reduction`.
TIES = ("values", "coefficients")

#: ``slaves="coincident"``: a particle is on Gamma_I (or on a node) within this times the spacing.
COINCIDENT_TOL = 1e-8


class MasterSlaveLinks:
    """The rigid links of the slave particles to the interface edges (collective to construct).

    Every rank gathers the interface edges (end points, global FE nodes, strong-condition values)
    and computes the links of all particles, so the result is the same on every rank.

    Args:
        problem: The :class:`~dolfinx_meshfree.CoupledElasticity`.
        is_bc, ubc: Strong-condition flags per local FE node and component (n, 2) (whole nodes
            and rollers: :func:`strong_dofs`) and their values (n, 2).
        slaves: ``"layer"``: the particles on Gamma_I when every interface FE node carries
            one, else refused (below); ``"first-layer"``: those, else the first particle layer,
            the particles nearest to some stretch of Gamma_I (eq. 17–28; links up to about a
            spacing long); ``"band"``: the particles within ``SLAVE_LAYER`` spacings of
            Gamma_I; ``"coincident"``: the particles on Gamma_I, one on every interface FE node
            (Johnson's coupling, eq. 15–16). See the module docstring.

    Raises:
        ValueError: on every rank for an unknown ``slaves``, and with ``"coincident"`` or
            ``"layer"`` when an interface FE node has no particle on it. With the first layer
            off Gamma_I the coupling is not reliably convergent: a linear field on a disc patch
            of triangles with a grid of spacing 1.5 h missed by 13.6, 16.8 and 17.7 % at n = 8,
            16, 32 (0.2, 28.9 and 9.6 % on quadrilaterals), where the default placement, which
            puts particles on Gamma_I, missed by 2.7, 1.2 and 0.5 %.

    Attributes:
        spacing: The particle spacing ``s`` (median nearest-neighbour distance).
        slaves: Indices of the slave particles (sorted).
        distance: Distance of each particle to the interface.
        width: The largest link length of a slave (``"layer"``) or the distance criterion.
        edges: (m, 2, 2) end points of the interface edges, ``nodes`` (m, 2) their global FE
            nodes, ``fixed`` (m, 2, 2) whether a node's component carries a strong condition
            and ``values`` (m, 2, 2) the strong values.
        rows: Per slave, ``(global FE nodes (k,), weights (k, 2, 2))``: ``u_P = sum_k
            weights[k] @ u[nodes[k]]``.
    """

    def __init__(self, problem, is_bc: np.ndarray, ubc: np.ndarray, slaves: str = "layer"):
        if slaves not in SLAVES:
            raise ValueError(f"slaves={slaves!r} is not known; use one of {list(SLAVES)}")
        off_interface = slaves == "first-layer"  # the paper's layer, wherever it lies
        slaves = "layer" if off_interface else slaves
        V, patch = problem.V, problem.patch
        msh = V.mesh
        comm = patch.comm
        P = patch.particles
        x = P.positions
        fdim = msh.topology.dim - 1
        imap = V.dofmap.index_map
        l2g = np.asarray(
            imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
        )
        facets = patch.interface_facets
        coords = V.tabulate_dof_coordinates()[:, :2]
        ends = np.zeros((facets.size, 2, 2))
        nodes = np.zeros((facets.size, 2), dtype=np.int64)
        fixed = np.zeros((facets.size, 2, 2), dtype=bool)
        values = np.zeros((facets.size, 2, 2))
        if facets.size:
            ends = msh.geometry.x[_compat.entities_to_geometry(msh, fdim, facets), :2]
            dofs = _compat.dofmap_array(V)[patch.interface_fe_cells]
            for k in range(2):
                # the FE cell's node at each end point of the facet
                d = np.linalg.norm(coords[dofs] - ends[:, k][:, None, :], axis=2)
                local = dofs[np.arange(facets.size), np.argmin(d, axis=1)]
                nodes[:, k] = l2g[local]
                fixed[:, k] = is_bc[local]
                values[:, k] = ubc[local]
        gathered = comm.allgather((ends, nodes, fixed, values))
        self.edges = np.concatenate([g[0] for g in gathered]).reshape(-1, 2, 2)
        self.nodes = np.concatenate([g[1] for g in gathered]).reshape(-1, 2)
        self.fixed = np.concatenate([g[2] for g in gathered]).reshape(-1, 2, 2)
        self.values = np.concatenate([g[3] for g in gathered]).reshape(-1, 2, 2)
        if self.edges.shape[0] == 0:
            raise ValueError("master-slave coupling: the patch has no interface with the FE cells")

        if x.shape[0] > 1:
            dist, _ = cKDTree(x).query(x, k=2)
            self.spacing = float(np.median(dist[:, 1]))
        else:
            self.spacing = float(np.linalg.norm(self.edges[:, 1] - self.edges[:, 0], axis=1).max())
        a = self.edges[:, 0]
        t = self.edges[:, 1] - self.edges[:, 0]
        length2 = np.einsum("ij,ij->i", t, t)
        # distances of every particle to every edge (n x m), in chunks of particles
        n, m = x.shape[0], a.shape[0]
        xi = np.empty((n, m))
        dist = np.empty((n, m))
        step = max(1, 2_000_000 // max(m, 1))
        for lo in range(0, n, step):
            r = x[lo : lo + step, None, :] - a[None, :, :]
            s = np.clip(np.einsum("pmj,mj->pm", r, t) / length2, 0.0, 1.0)
            xi[lo : lo + step] = s
            dist[lo : lo + step] = np.linalg.norm(r - s[..., None] * t[None], axis=2)
        self.distance = dist.min(axis=1)
        self.kind = slaves
        #: Distance to Gamma_I within which a particle is a slave.
        self.width = SLAVE_LAYER * self.spacing
        if slaves == "coincident":
            self.width = COINCIDENT_TOL * self.spacing
            ends = np.unique(self.edges.reshape(-1, 2), axis=0)
            gap, _ = cKDTree(x).query(ends)
            if np.any(gap > self.width):
                k = int(np.argmax(gap))
                raise ValueError(
                    f"slaves='coincident' (Johnson's coupling, eq. 15-16) needs a particle on "
                    f"every interface FE node; {int(np.sum(gap > self.width))} node(s) have none, "
                    f"first {ends[k]} (nearest particle {gap[k]:.3e} away): use a particle "
                    "spacing that divides the FE cells' edges on the interface"
                )
        if slaves == "layer":
            self._tree = cKDTree(x)
            on = np.flatnonzero(self.distance <= COINCIDENT_TOL * self.spacing)
            nodes = np.unique(self.edges.reshape(-1, 2), axis=0)
            gap, _ = self._tree.query(nodes)
            if np.all(gap <= COINCIDENT_TOL * self.spacing):
                # every interface FE node carries a particle: the particles on Gamma_I
                self.slaves = on
            elif not off_interface:
                k = int(np.argmax(gap))
                raise ValueError(
                    f"master-slave coupling: {int(np.sum(gap > COINCIDENT_TOL * self.spacing))} "
                    f"FE node(s) on the interface carry no particle, first {nodes[k]} (nearest "
                    f"particle {gap[k]:.3e} away, spacing {self.spacing:.3e}), so the slaves "
                    "would be a particle layer off the interface, rigidly linked to it; that "
                    "is not reliably convergent (a linear field missed by up to 29 % on a disc "
                    "patch). Use the default placement ('conforming', particles on the patch "
                    "border) or 'vertices', another coupling, or slaves='first-layer' for the "
                    "paper's layer wherever it lies"
                )
            else:
                self.slaves = _first_layer(self._tree, x, a, t)
            self.width = float(self.distance[self.slaves].max())
        else:
            self.slaves = np.flatnonzero(self.distance <= self.width)
        self._is_slave = np.zeros(x.shape[0], dtype=bool)
        self._is_slave[self.slaves] = True
        if self.slaves.size == x.shape[0]:
            raise ValueError(
                "master-slave coupling: every particle is a slave (the patch is one particle "
                "layer thick); use a larger patch or a finer particle spacing"
            )
        tol = 1e-9 * np.sqrt(length2.max())
        self.rows = []
        #: Per slave, its links ``(edge, xi, C -> P)`` to the equally close edges.
        self.links = []
        for p in self.slaves:
            tied = np.flatnonzero(dist[p] <= self.distance[p] + tol)
            cols, weights = [], []
            self.links.append(
                [(int(e), float(xi[p, e]), x[p] - (a[e] + xi[p, e] * t[e])) for e in tied]
            )
            for e in tied:
                s = xi[p, e]
                rr = x[p] - (a[e] + s * t[e])  # the link C -> P
                # theta = (t x (u_b - u_a)) / |t|^2: d theta / d(u_a, u_b)
                dth = np.array([[t[e, 1], -t[e, 0]], [-t[e, 1], t[e, 0]]]) / length2[e]
                for k, nk in enumerate((1.0 - s, s)):
                    w = nk * np.eye(2)
                    # u_P += theta (-r_y, r_x)
                    w = w + np.outer([-rr[1], rr[0]], dth[k])
                    cols.append(self.nodes[e, k])
                    weights.append(w / tied.size)
            self.rows.append((np.asarray(cols, dtype=np.int64), np.asarray(weights)))

    def in_layer(self, points: np.ndarray) -> np.ndarray:
        """Whether each point lies within the slave layer: ``slaves="layer"``, its nearest
        particle is a slave (it lies in a slave's Voronoi cell); otherwise, within the slaves'
        distance :attr:`width` of Gamma_I."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if self.kind == "layer":
            _, nearest = self._tree.query(points)
            return self._is_slave[nearest]
        a = self.edges[:, 0]
        t = self.edges[:, 1] - a
        r = points[:, None, :] - a[None]
        s = np.clip(np.einsum("pmj,mj->pm", r, t) / np.einsum("ij,ij->i", t, t), 0.0, 1.0)
        dist = np.linalg.norm(r - s[..., None] * t[None], axis=2).min(axis=1, initial=np.inf)
        return dist <= self.width

    def is_fixed(self) -> dict[int, float]:
        """Strong values of the interface FE dofs that carry one, by global FE dof (``2 node +
        component``): whole nodes and single components (a roller) alike."""
        e, k, c = np.nonzero(self.fixed)
        dofs = 2 * self.nodes[e, k] + c
        return dict(zip(dofs.tolist(), self.values[e, k, c].tolist(), strict=True))


def _first_layer(tree: cKDTree, x: np.ndarray, a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The particles nearest to some stretch of the interface (sorted indices).

    For every edge ``a + tau t`` (tau in [0, 1]) the squared distance to particle ``p`` is
    ``|a - p|^2 + 2 tau t.(a - p) + tau^2 |t|^2``; the last term is common to all particles, so
    the nearest particle along the edge is the lower envelope of lines in ``tau``: the particles
    that attain it on an interval of positive length are the edge's first layer (their Voronoi
    cells cut the edge).
    """
    out = set()
    for e in range(a.shape[0]):
        ends = np.array([a[e], a[e] + t[e]])
        d_end, _ = tree.query(ends)
        reach = np.linalg.norm(t[e]) + d_end.max() + 1e-12
        cand = np.asarray(tree.query_ball_point(a[e] + 0.5 * t[e], reach), dtype=np.int64)
        ra = a[e] - x[cand]
        c0 = np.einsum("ij,ij->i", ra, ra)
        c1 = 2.0 * ra @ t[e]
        # breakpoints: pairwise intersections of the lines inside (0, 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = (c0[None, :] - c0[:, None]) / (c1[:, None] - c1[None, :])
        tau = np.unique(np.concatenate([[0.0, 1.0], tau[np.isfinite(tau) & (tau > 0) & (tau < 1)]]))
        mid = 0.5 * (tau[1:] + tau[:-1])[np.diff(tau) > 1e-9]
        f = c0[None, :] + mid[:, None] * c1[None, :]
        scale = np.einsum("ij,ij->", t[e : e + 1], t[e : e + 1])
        best = f.min(axis=1, keepdims=True)
        out.update(cand[np.any(f <= best + 1e-9 * scale, axis=0)].tolist())
    return np.asarray(sorted(out), dtype=np.int64)


def solve_master_slave(
    problem: CoupledElasticity,
    solver: str | SolverOptions = "mumps",
    slaves: str | None = None,
    tie: str | None = None,
    kept: KeptFactorisation | None = None,
) -> CoupledSolution:
    """Assemble and solve the master–slave coupled system of ``problem`` (collective; ``kept``:
    see :func:`~dolfinx_meshfree.statics.petsc.solve_lu`).

    ``slaves``: which particles are slaves, see :class:`MasterSlaveLinks` (``None``: the
    model's ``slaves``, ``"layer"`` unless set).
    ``tie``: ``"values"`` (the slaves' MLS values follow their links) or ``"coefficients"``
    (their nodal parameters, the paper's eq. 27); ``None``: values for ``"layer"``, the
    paper's coefficients for ``"band"`` and ``"coincident"``. See :func:`_reduction`.
    """

    V, patch, P = problem.V, problem.patch, problem.patch.particles
    comm = patch.comm
    deg = problem.quadrature_degree
    s = problem.material.E
    pdofs = P.petsc_dofs(2)
    fe_layout, _ = fe_dof_layout(problem.V)
    pl = P.dof_layout()
    t0 = time.perf_counter()

    boundary = patch.boundary() if problem.consistent else None
    q, bq = patch_rules(problem)  # cut cells and crack faces with cracks
    tables: dict = {}  # the stiffness's rule: the loads' stresses are integrated on it
    Kp_loc, _, _, kt = particle_stiffness(
        P, problem.mls, problem.material, deg, boundary, quadrature=q, boundary_quadrature=bq,
        tables=tables,
    )  # fmt: skip

    # essential conditions: FE side strongly (whole nodes or components), patch side by
    # multipliers
    _, patch_bc, dq, dtabs, ubc, is_bc = essential_conditions(problem)
    active = fe_active(problem)
    held, held_values = strong_dofs(problem, is_bc, ubc)

    slaves = problem.slaves if slaves is None else slaves
    links = raise_on_all_ranks(comm, lambda: MasterSlaveLinks(problem, held, held_values, slaves))
    patch_bc, dq, dtabs = outside_slave_layer(problem, links, patch_bc, dq, dtabs)
    T_pf, S_loc, _, g_rows, g_vals, ml = _reduction(
        problem, links, fe_layout, tie, links.is_fixed()
    )
    setup = problem.setup_time + time.perf_counter() - t0 - kt["assemble"]

    t1 = time.perf_counter()
    b_fe, f_p = traction_loads(problem, tables)
    # K_FE with strong conditions and inactive dofs (zero rows and columns, lifted into b_fe)
    K_fe = fe_stiffness(problem)
    n_owned = V.dofmap.index_map.size_local
    x_bc = fix_fe_rows(
        problem,
        K_fe,
        b_fe,
        is_bc | ~active,
        np.where(is_bc[:, None], ubc.x.array.reshape(-1, 2), 0.0),
    )

    Kp = create_aij(comm, Kp_loc, pl, pl)
    Tpf = create_aij(comm, T_pf, pl, fe_layout)
    S = create_aij(comm, S_loc, pl, ml)
    g_p = create_vector(comm, pl, np.asarray(g_rows, dtype=np.int64), np.asarray(g_vals))
    # reduced blocks: T^T K T
    A_pp = Kp.PtAP(Tpf)
    A_ff = K_fe
    A_ff.axpy(1.0, A_pp, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    KpS = Kp.matMult(S)
    A_fm = Tpf.transposeMatMult(KpS)
    A_mf = KpS.transposeMatMult(Tpf)
    A_mm = Kp.PtAP(S)
    # right-hand side: T^T (f - K g); g's FE part is already lifted into b_fe
    r = create_vector(comm, pl, pdofs.ravel(), f_p)
    Kg = Kp.createVecLeft()
    Kp.mult(g_p, Kg)
    r.axpy(-1.0, Kg)
    Tpf.multTransposeAdd(r, b_fe, b_fe)
    b_m = S.createVecRight()
    S.multTranspose(r, b_m)
    blocks = [[A_ff, A_fm], [A_mf, A_mm]]
    rhs = [b_fe, b_m]
    mats = [A_ff, A_pp, KpS, A_fm, A_mf, A_mm]
    Gd, d_rows, d_vals, dl = facet_multipliers(P, patch_bc, dq, dtabs, s)
    if dl.size_global:
        D = create_aij(comm, Gd, dl, pl)
        d = create_vector(comm, dl, d_rows, d_vals)
        Dg = D.createVecLeft()
        D.mult(g_p, Dg)
        d.axpy(-1.0, Dg)
        D_f, D_m = D.matMult(Tpf), D.matMult(S)
        D_fT, D_mT = D_f.transpose(PETSc.Mat()), D_m.transpose(PETSc.Mat())
        blocks = [[A_ff, A_fm, D_fT], [A_mf, A_mm, D_mT], [D_f, D_m, None]]
        rhs.append(d)
        mats += [D, Dg, D_f, D_m, D_fT, D_mT]
    names = ["fe", "particles"] + [f"multiplier{i}" for i in range(len(blocks) - 2)]
    system = BlockSystem(blocks, rhs, num_primal=2, names=names)
    assemble = time.perf_counter() - t1 + kt["assemble"]

    t2 = time.perf_counter()
    parts = system.solve(solver, kept=kept)
    solve = time.perf_counter() - t2
    system.destroy()

    # expand u = T u_m + g
    x_f = Tpf.createVecRight()
    x_f.setArray(parts[0])
    x_m = S.createVecRight()
    x_m.setArray(parts[1])
    u_p = g_p.copy()
    Tpf.multAdd(x_f, u_p, u_p)
    S.multAdd(x_m, u_p, u_p)
    owned = np.concatenate(comm.allgather(u_p.getArray(readonly=True).copy()))
    for obj in [*mats, *rhs, x_bc, Kp, Tpf, S, g_p, r, Kg, x_f, x_m, u_p]:
        obj.destroy()
    uh = dolfinx.fem.Function(V)
    uh.x.array[: 2 * n_owned] = parts[0]
    uh.x.scatter_forward()
    coeffs = owned.reshape(-1, 2)[P.petsc_index]
    sol = CoupledSolution(
        u=uh,
        coefficients=coeffs,
        mls=problem.mls,
        patch=patch,
        timings={"setup": setup, "assemble": assemble, "solve": solve},
        sizes={
            "fe_dofs": 2 * comm.allreduce(int(np.sum(active[:n_owned]))),
            "particle_dofs": ml.size_global,
            "multiplier_dofs": dl.size_global,
            "slave_dofs": 2 * links.slaves.size,
        },
    )
    sol.links = links
    return sol


def strong_dofs(
    problem: CoupledElasticity, is_bc: np.ndarray, ubc: dolfinx.fem.Function
) -> tuple[np.ndarray, np.ndarray]:
    """The FE dofs held strongly, (n, 2) flags per local node and component (whole nodes
    ``is_bc`` and single components, :func:`~dolfinx_meshfree.couplings.assembly.fixed_dofs`),
    and their values (n, 2) (local): what :class:`MasterSlaveLinks` carries to the slaves
    through ``g`` instead of linking them to a held dof."""
    values = component_conditions(problem)[1]
    u = ubc.x.array.reshape(-1, 2)
    return fixed_dofs(problem, is_bc), np.where(is_bc[:, None], u, values)


def outside_slave_layer(
    problem: CoupledElasticity, links: MasterSlaveLinks, patch_bc: list, dq: list, dtabs: list
) -> tuple[list, list, list]:
    """Drop the patch-side Dirichlet facets that lie in the slave layer (both end points within
    it): the slaves there follow the FE boundary, whose nodes carry the condition strongly, and a
    multiplier on such a facet over-determines them (the linear patch test then failed by 1.9e2
    instead of the layer's O(strain x spacing)). Returns the filtered conditions, quadratures
    and tables (collective)."""
    msh = problem.V.mesh
    fdim = msh.topology.dim - 1
    comm = problem.patch.comm
    out_bc, out_q, out_t = [], [], []
    for (facets, fn, *components), q, tab in zip(patch_bc, dq, dtabs, strict=True):
        if facets.size:
            ends = msh.geometry.x[_compat.entities_to_geometry(msh, fdim, facets), :2]
            inside = links.in_layer(ends.reshape(-1, 2)).reshape(-1, 2).all(axis=1)
        else:
            inside = np.zeros(0, dtype=bool)
        if not comm.allreduce(bool(inside.any()), op=MPI.LOR):
            out_bc.append((facets, fn, *components))
            out_q.append(q)
            out_t.append(tab)
            continue
        kept = facets[~inside]
        fq = facet_quadrature(msh, kept, problem.quadrature_degree)
        fq = raise_on_all_ranks(comm, lambda fq=fq: revolved_if(fq, problem.material, True))
        out_bc.append((kept, fn, *components))
        out_q.append(fq)
        out_t.append(raise_on_all_ranks(comm, lambda fq=fq: problem.mls.tabulate(fq.points, 0)))
    return out_bc, out_q, out_t


def master_slave_operators(
    problem: CoupledElasticity,
    integration: str = "cells",
    slaves: str = "layer",
    tie: str | None = None,
) -> CouplingOperators:
    """The master–slave coupling's operators without essential conditions (collective).

    ``K_FE`` on the FE cells and ``K_P`` on the patch, unreduced, with the reduction
    ``(T_PF, S)``: ``u_P = T_PF u_FE + S u_M`` where the slaves follow their edges (eq. 27) and
    ``S`` is the identity on the free (master) particles, numbered by :attr:`master_layout` in
    PETSc particle order (with value ties its slave rows are ``-Phi_SS^{-1} Phi_SM``; the
    selection of its master rows is composed on it as :data:`MASTER_SELECTION`). The reduced
    stiffness is ``T^T K T`` and the forces on the slaves go to their masters with ``T^T``
    (eq. 28). See :class:`~dolfinx_meshfree.statics.coupled.CouplingOperators`.

    Args:
        integration: ``"cells"`` or ``"stress-points"``: the rule of ``K_P`` (see
            :meth:`CoupledElasticity.operators <dolfinx_meshfree.CoupledElasticity.operators>`).
        slaves: ``"layer"`` or ``"coincident"`` (Johnson, eq. 15–16): see
            :class:`MasterSlaveLinks`.
        tie: What a link fixes, as in :func:`solve_master_slave`.
    """

    check_integration(integration)
    t0 = time.perf_counter()
    patch, P = problem.patch, problem.patch.particles
    comm = patch.comm
    fe_layout, l2g = fe_dof_layout(problem.V)
    pl = P.dof_layout()
    boundary = patch.boundary() if problem.consistent else None
    tables: dict = {}  # the particle rule, table and test gradients (finite strain)
    q, bq = patch_rules(problem, integration, DYNAMIC_FACET_DEGREE)
    Kp_loc, q, tq, _ = particle_stiffness(
        P,
        problem.mls,
        problem.material,
        problem.quadrature_degree,
        boundary,
        quadrature=q,
        tables=tables,
        boundary_quadrature=bq,
    )
    # masses and body loads: a smoothing rule's cell Gauss rule
    mq, mvalues = raise_on_all_ranks(comm, lambda: value_rule(problem.mls, q, tq))
    no_bc = np.zeros((l2g.size, 2), dtype=bool)
    links = raise_on_all_ranks(
        comm, lambda: MasterSlaveLinks(problem, no_bc, np.zeros((l2g.size, 2)), slaves)
    )
    T_pf, S_loc, sel, _, _, ml = _reduction(problem, links, fe_layout, tie, {})
    return CouplingOperators(
        coupling=problem.coupling,
        K_fe=fe_stiffness(problem),
        K_p=create_aij(comm, Kp_loc, pl, pl),
        fe_weight=problem.cell_indicator(~patch.in_patch),
        fe_active=fe_active(problem),
        particle_quadrature=mq,
        particle_table=mvalues.tocsr(),
        fe_layout=fe_layout,
        particle_layout=pl,
        reduction=(
            create_aij(comm, T_pf, pl, fe_layout),
            _with_selection(S_loc, sel, comm, pl, ml),
        ),
        master_layout=ml,
        interface=links,
        particle_tables=tables,
        timings={"operators": time.perf_counter() - t0},
    )


def _reduction(problem, links: MasterSlaveLinks, fe_layout: Layout, tie: str | None, known: dict):
    """The reduction ``u_P = T_PF u_FE + S u_M + g`` of the owned particle dofs (eq. 27).

    Every slave ``P`` has a target ``w_P = W_P u_FE + g_P``: the motion of its link (eq. 17-27),
    ``W_P`` from :attr:`MasterSlaveLinks.rows`, ``g_P`` the part carried by strong FE values
    (``known``: value by global FE dof, :meth:`MasterSlaveLinks.is_fixed`).
    ``tie="coefficients"`` (the paper's) sets the slave's nodal parameter to it, ``u_P = w_P``.
    ``tie="values"`` sets the slave's MLS *value* to it,
    ``u^h(x_P) = sum_J phi_J(x_P) u_J = w_P`` (eq. 3.3 of Belytschko et al. 1995): with
    ``Phi_SS``, ``Phi_SM`` the slaves' shape functions at the slaves and at the masters,
    ``u_S = Phi_SS^{-1} (w_S - Phi_SM u_M)``. MLS is not interpolating, so the two differ: a
    tied nodal parameter leaves the field at the slave free to follow the masters, and the
    interface loses consistency (see the module docstring for the measured effect).
    ``Phi_SS`` is inverted densely (the slaves are one layer along Gamma_I; condition numbers
    3.7-7.6 measured with the package's supports) and entries below ``1e-14`` of a row's
    largest, which decay geometrically along the layer, are dropped: about 60 entries per row
    remain whatever the interface's length (bushing ring, 44 / 59 / 61 at h = 0.2 / 0.1 /
    0.05), so ``T`` has O(slaves) entries, each slave coupled to its neighbours within about
    30 spacings along Gamma_I. The positions are replicated, so
    every rank computes the same inverse and keeps its owned slaves' rows.

    Returns ``(T_PF, S, S_sel, g_rows, g_vals, master_layout)``: local SciPy matrices (rows:
    the particle dofs, PETSc numbering; columns: global FE dofs and master dofs; ``S_sel``: the
    masters' rows of ``S``, a selection), the owned nonzero entries of ``g`` and the master dof
    layout.
    """
    tie = _resolve_tie(links, tie)
    P = problem.patch.particles
    comm = problem.patch.comm
    n = P.num_particles
    pdofs = P.petsc_dofs(2)
    sl = links.slaves
    is_slave = np.zeros(n, dtype=bool)
    is_slave[sl] = True
    # masters in PETSc order, numbered owner by owner: the columns of S
    order = np.argsort(P.petsc_index, kind="stable")
    masters = order[~is_slave[order]]
    mcol = np.full(n, -1, dtype=np.int64)
    mcol[masters] = np.arange(masters.size)
    mine = np.flatnonzero(~is_slave & (P.owner == comm.rank))
    mlay = Layout.from_local(comm, mine.size)
    ml = Layout(2 * mlay.size_local, 2 * mlay.size_global, 2 * mlay.start)
    # W (2 n_S x FE dofs) and g (2 n_S) of every slave: the link targets
    wr, wc, wv = [], [], []
    g = np.zeros(2 * sl.size)
    for k, (nodes, weights) in enumerate(links.rows):
        for node, w in zip(nodes, weights, strict=True):
            for j in range(2):
                u = known.get(int(2 * node + j))
                for i in range(2):
                    if w[i, j] == 0.0:
                        continue
                    if u is not None:
                        g[2 * k + i] += w[i, j] * u
                    else:
                        wr.append(2 * k + i)
                        wc.append(2 * node + j)
                        wv.append(w[i, j])
    W = sp.csr_matrix((wv, (wr, wc)), shape=(2 * sl.size, fe_layout.size_global))
    own = np.flatnonzero(P.owner[sl] == comm.rank)  # owned slaves, positions in sl
    X, Phi = slave_solve(problem, links, tie, own)
    M = sp.csr_matrix((own.size, masters.size)) if Phi is None else -(X @ Phi[:, masters])
    I2 = sp.identity(2, format="csr")
    X2 = sp.kron(X, I2, format="csr")
    rows = pdofs[sl[own]].ravel()
    T_s = (X2 @ W).tocoo()
    T_pf = sp.csr_matrix((T_s.data, (rows[T_s.row], T_s.col)), shape=(2 * n, fe_layout.size_global))
    # S: identity on the owned masters, -Phi_SS^{-1} Phi_SM on the owned slaves
    M2 = sp.kron(M, I2, format="coo")
    srow = np.concatenate([pdofs[mine].ravel(), rows[M2.row]])
    scol = np.concatenate([(2 * mcol[mine][:, None] + np.arange(2)).ravel(), M2.col])
    sval = np.concatenate([np.ones(2 * mine.size), M2.data])
    S_loc = sp.csr_matrix((sval, (srow, scol)), shape=(2 * n, ml.size_global))
    k = 2 * mine.size
    sel = sp.csr_matrix((sval[:k], (srow[:k], scol[:k])), shape=S_loc.shape)
    gs = X2 @ g
    nz = np.flatnonzero(gs)
    return T_pf, S_loc, sel, rows[nz], gs[nz], ml


def _resolve_tie(links: MasterSlaveLinks, tie: str | None) -> str:
    """``tie``, or the default of ``links.kind`` for ``None``; a ``ValueError`` if unknown."""
    if tie is None:
        tie = "values" if links.kind == "layer" else "coefficients"
    if tie not in TIES:
        raise ValueError(f"tie={tie!r} is not known; use one of {list(TIES)} or None")
    return tie


def slave_solve(
    problem: CoupledElasticity, links: MasterSlaveLinks, tie: str | None, own: np.ndarray
) -> tuple[sp.csr_matrix, sp.csr_matrix | None]:
    """``(X, Phi)``: the rows ``own`` (positions in ``links.slaves``) of the map from the slaves'
    link targets to their nodal parameters, ``u_S = X (w_S - Phi_SM u_M)`` (see
    :func:`_reduction`): ``Phi_SS^{-1}`` with the slaves' MLS values ``Phi`` (value tie) or the
    identity and ``None`` (coefficient tie). ``tie=None``: the default of ``links.kind``."""
    tie = _resolve_tie(links, tie)
    sl = links.slaves
    if tie == "coefficients":
        return sp.identity(sl.size, format="csr")[own], None
    P = problem.patch.particles
    Phi = sp.csr_matrix(problem.mls.tabulate(P.positions[sl], 0).values)
    inv = np.linalg.inv(Phi[:, sl].toarray())[own]
    inv[np.abs(inv) < 1e-14 * np.abs(inv).max(axis=1, initial=0.0)[:, None]] = 0.0
    return sp.csr_matrix(inv), Phi


#: Name under which the reduction's ``S`` carries the selection of the master rows (a PETSc
#: object composed on it, see :func:`_with_selection`).
MASTER_SELECTION = "master_selection"


def _with_selection(S_loc: sp.csr_matrix, sel_loc: sp.csr_matrix, comm, pl: Layout, ml: Layout):
    """``S`` as a PETSc matrix carrying (``compose``, name :data:`MASTER_SELECTION`) the
    selection of its master rows ``S_sel``: ``S_sel^T c`` keeps the masters' entries of a
    particle vector ``c`` (initial conditions). With ``tie="values"`` the slaves' rows of ``S``
    are not zero, so ``S^T`` is not that restriction (collective)."""
    S = create_aij(comm, S_loc, pl, ml)
    sel = create_aij(comm, sel_loc, pl, ml)
    S.compose(MASTER_SELECTION, sel)
    sel.destroy()
    return S


class MasterSlaveCoupling(CouplingDefaults):
    """Particles linked to the FE boundary (Rabczuk et al. 2006, sec. 5.1.2).

    First order by construction; plain Gauss quadrature by default (its slaves, not
    multipliers, carry the interface traction that consistent integration's identity assumes).
    """

    name: ClassVar[str] = "master-slave"
    default_dilation: ClassVar[float] = 2.0
    consistent_default: ClassVar[bool] = False
    integrations: ClassVar[tuple[str, ...]] = ("cells", "stress-points")
    blended: ClassVar[bool] = False
    dimensions: ClassVar[tuple[int, ...]] = (2,)
    missing_3d: ClassVar[str] = (
        "its rigid links (Rabczuk et al. 2006, eq. 17-28) carry a 2D in-plane rotation per "
        "master node and its slave layer is found from 2D interface edges"
    )

    def solve(
        self,
        problem: CoupledElasticity,
        solver: str | SolverOptions,
        kept: KeptFactorisation | None = None,
    ) -> CoupledSolution:
        return solve_master_slave(problem, solver, kept=kept)

    def operators(
        self, problem: CoupledElasticity, integration: str, slaves: str
    ) -> CouplingOperators:
        return master_slave_operators(problem, integration, slaves)
