"""Pure element-free Galerkin (EFG) elastostatics on a background mesh.

Discretisation (Belytschko et al. 1995, sec. 4.1): MLS shape functions (eq. 3.9) on the particles,
Gauss quadrature on the background cells (the FE mesh's own cells), tractions on boundary facets
(eq. 4.3), and essential boundary conditions by Lagrange multipliers (Belytschko, Lu & Gu 1994) in
the PETSc nest block system

.. math::
    \\begin{bmatrix} K & s G^T \\\\ s G & 0 \\end{bmatrix}
    \\begin{bmatrix} u \\\\ \\lambda / s \\end{bmatrix} =
    \\begin{bmatrix} f \\\\ s g \\end{bmatrix},

solved with MUMPS. The multipliers are constant on each Dirichlet facet (one per facet and
component): ``G_{(f,i),(J,i)} = int_f phi_J``, ``g_(f,i) = int_f ubar_i``. Piecewise constants hold
``sigma n`` of a linear field exactly on any polygon, which the patch test needs; ``s = E`` scales
the constraint rows to the stiffness so the saddle point is well balanced.

``consistent=True`` adds variationally consistent integration (Chen, Hillman & Rüter 2013, see
:func:`~dolfinx_meshfree.physics.operators.consistent_gradients`), with which the linear patch test
passes
to round-off; plain Gauss quadrature leaves an integration error of about 1e-6.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import dolfinx.fem
import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from scipy.spatial import cKDTree

from .. import _compat
from ..approx.body_cuts import separate_bodies
from ..approx.crack_cuts import attach_cracks
from ..approx.fe_points import point_value_nodes
from ..approx.mls import MLS
from ..approx.tables import ShapeTable
from ..approx.tip_enrichment import enrich_tips
from ..fracture.interaction import StressIntensityFactors
from ..geometry.adaptive_quadrature import AdaptiveQuadrature
from ..geometry.crack import Crack, CrackDomain, particle_spacing, place_crack
from ..geometry.cut_cells import (
    cracked_boundary_quadrature,
    cut_cell_quadrature,
    cut_facet_quadrature,
)
from ..geometry.particles import ParticleSet
from ..geometry.quadrature import (
    QuadraturePoints,
    boundary_facets,
    cell_quadrature,
    facet_quadrature,
    particle_quadrature_degree,
)
from ..geometry.smoothing import (
    STABILISATION,
    SmoothingRule,
    refuse_smoothed,
    resolve_integration,
    smoothed_table,
    smoothing_rule,
    stiffness_rows,
    value_rule,
)
from ..parallel import Layout, raise_on_all_ranks
from ..physics.axisymmetry import (
    approximation_hoop,
    axisymmetric_stiffness,
    check_axis_held,
    check_particle_section,
    hoop_table,
    revolved,
)
from ..physics.body_loads import CallableBodyForce
from ..physics.cohesive import LinearCohesive
from ..physics.constitutive import Material
from ..physics.materials import LinearElastic, is_axisymmetric, linear_twin
from ..physics.operators import (
    consistent_gradients,
    load_vector,
    moment_corrections,
    stiffness_matrix,
)
from ..physics.state import check_not_rate_law, is_stateful
from ..physics.user_functions import check_arguments, check_facets, vector_values
from .cohesive import CohesiveCrack, CohesiveSide, check_cohesive, check_through
from .fe_state import check_bands
from .growth_update import local_update_for
from .history import SolveHistory
from .kept_factor import KeptFactorisation, check_kept
from .newton import NewtonOptions
from .petsc import BlockSystem, SolverOptions, create_aij, create_vector, solver_options
from .sides import (
    BlockProblem,
    ParticleSide,
    check_particle_band,
    particle_band_factor,
    solve_built,
)
from .sifs import solution_sifs

if TYPE_CHECKING:  # annotations only
    import dolfinx.mesh

__all__ = [
    "EFGBlockModel",
    "EFGElasticity",
    "EFGSolution",
    "check_multiplier_facets",
    "crack_rules",
    "facet_multipliers",
    "particle_stiffness",
]

VectorFunction = Callable[[np.ndarray], np.ndarray]
TractionFunction = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _cat(parts: list, dtype) -> np.ndarray:
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype)


@dataclass
class EFGSolution:
    """Particle coefficients of an EFG solve and the means to evaluate them anywhere.

    Attributes:
        coefficients: (n, gdim) nodal parameters ``u_I`` (not the displacement at ``x_I``: MLS is
            not interpolating), replicated on every rank.
        multipliers: owned multiplier values (Lagrange multipliers = boundary tractions).
        timings: seconds spent in ``setup``, ``assemble`` and ``solve``.
    """

    mls: MLS
    coefficients: np.ndarray
    multipliers: np.ndarray
    timings: dict = field(default_factory=dict)
    num_multipliers: int = 0
    #: At finite strain, the Newton record (:class:`~dolfinx_meshfree.NonlinearSolveResult`).
    newton: object | None = None
    #: The small-strain law of the solve (for :meth:`stress_intensity_factors`).
    material: LinearElastic | None = None
    #: The cracks of the model and where they lie (pure EFG, the whole mesh).
    cracks: list = field(default_factory=list)
    domain: CrackDomain | None = None
    #: The particles (pure EFG's model), where a solve has them.
    particles: ParticleSet | None = None
    #: The body force (:meth:`EFGElasticity.set_body_force`): its interaction-integral term.
    body_forces: list = field(default_factory=list)

    def displacement(self, points: np.ndarray) -> np.ndarray:
        """Displacement (m, gdim) at points (m, gdim); local, no communication."""
        return self.mls.tabulate(points, derivatives=0).values @ self.coefficients

    def evaluate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Displacement (m, gdim) and its gradient (m, gdim, gdim), ``g[:, i, j] = du_i/dx_j``."""
        t = self.mls.tabulate(points)
        return t.values @ self.coefficients, t.gradient(self.coefficients)

    def as_function(self, V: dolfinx.fem.FunctionSpace) -> dolfinx.fem.Function:
        """The particle displacement field as a DOLFINx Function on ``V`` (collective), for
        ``XDMFFile``, UFL post-processing and plotting: at every node (dof coordinate) of ``V``
        the MLS field there, ``mls.tabulate(x).values @ coefficients`` (not the coefficients:
        MLS is not interpolating). Each rank evaluates its owned nodes; ghost values are up to
        date.

        Args:
            V: A vector space of ``gdim`` components on the background mesh (or any mesh inside
                the particles' supports) whose dofs are point values (Lagrange, continuous or
                discontinuous, any degree), e.g. ``_compat.vector_function_space(mesh, 1)``.

        Returns:
            A new Function on ``V`` named ``"displacement"``.
        """
        msh = V.mesh
        gdim = self.coefficients.shape[1]

        def evaluate() -> np.ndarray:
            x = point_value_nodes(V, gdim)[: V.dofmap.index_map.size_local]
            if x.shape[0] == 0:
                return np.zeros((0, gdim))
            return self.mls.tabulate(x, 0).values @ self.coefficients

        owned = raise_on_all_ranks(msh.comm, evaluate)
        out = dolfinx.fem.Function(V)
        out.x.array[:] = 0.0
        out.x.array[: owned.size] = owned.ravel()
        out.x.scatter_forward()
        out.name = "displacement"
        return out

    def stress_intensity_factors(
        self,
        crack: Crack,
        tip: int | np.ndarray = 0,
        radius: float | np.ndarray | None = None,
        material: LinearElastic | None = None,
        **options,
    ) -> StressIntensityFactors:
        """K_I, K_II and J at a tip of ``crack`` by the domain interaction integral on the
        crack-aware MLS field (collective; see
        :func:`~dolfinx_meshfree.statics.sifs.solution_sifs`).

        Args:
            crack: one of the model's cracks. tip: an index of ``crack.tips`` or its coordinates.
            radius: outer domain radii (default 8, 10, 12, 14, 16 particle spacings,
                ``r1 = r2 / 2``, shrunk together to fit the patch:
                ``statics.sifs.DOMAIN_RADII``):
                one result per radius, the path independence report.
            material: the law (default: the solve's).
            options: ``inner``, ``weight``, ``points`` of
                :func:`~dolfinx_meshfree.interaction_integral`.
        """
        if self.domain is None:  # the same on every rank
            raise ValueError(
                "the model has no cracks: give EFGElasticity(..., cracks=[crack]) to compute "
                "stress intensity factors"
            )
        return solution_sifs(
            lambda x: self.evaluate(x)[1], material or self.material, self.cracks, self.domain,
            crack, tip, radius, body=(self.body_forces, None), **options,
        )  # fmt: skip


def particle_stiffness(
    particles: ParticleSet,
    mls: MLS,
    material: LinearElastic,
    quadrature_degree: int,
    consistent_boundary: tuple[np.ndarray, np.ndarray | None] | None = None,
    boundary_values: Callable[[QuadraturePoints, sp.csr_matrix], sp.csr_matrix] | None = None,
    quadrature: QuadraturePoints | None = None,
    boundary_normals: Callable[[QuadraturePoints], np.ndarray] | None = None,
    tables: dict | None = None,
    boundary_moments: bool = False,
    boundary_quadrature: QuadraturePoints | None = None,
) -> tuple[sp.csr_matrix, QuadraturePoints, ShapeTable, dict]:
    """EFG stiffness from this rank's integration cells (``particles.cells``), in PETSc numbering.

    Belytschko et al. 1995, eq. (4.3) with Gauss quadrature on the background cells. With
    ``consistent_boundary = (facets, cells)`` — the whole boundary of the integration domain and
    the domain cell beside each facet (``None``: exterior facets) — the test-function gradients
    get the VCI correction; ``boundary_values(bq, values)``, if given, replaces the shape
    function values at the boundary quadrature ``bq`` in the VCI boundary integral (the
    edge-to-edge coupling uses their FE interpolant on the interface); ``boundary_normals(bq)``,
    if given, replaces the normals there (the Lagrange coupling uses their projection on its
    multiplier space on the interface); with ``boundary_moments`` the VCI constant uses the
    traces themselves and the difference ``boundary_values - traces`` is carried by a linear
    correction per shape function that also matches its first moments
    (:func:`~dolfinx_meshfree.physics.operators.moment_corrections`: exact interface terms
    for linear stresses). ``quadrature``, if given,
    replaces the cell Gauss rule (``quadrature_degree`` is then not used for it), e.g. the
    particles and stress points of
    :func:`~dolfinx_meshfree.geometry.stress_points.stress_point_quadrature`
    (Rabczuk, Belytschko & Xiao 2004). ``boundary_quadrature``, if given, replaces the facet
    rule of ``consistent_boundary``'s facets (e.g. a cracked patch's boundary with both crack
    faces, :func:`~dolfinx_meshfree.geometry.cut_cells.cracked_boundary_quadrature`; its
    ``sides`` select the one-sided shape functions on the crack faces). Collective (errors are
    raised on every rank).

    ``tables``, if given, receives ``"quadrature"``, ``"table"`` and ``"test_gradients"`` (the
    VCI-corrected ones when consistent): what a finite-strain solve needs for its internal force.

    Returns:
        ``(K, q, table, timings)``: K as a (gdim n x gdim n) CSR of this rank's contributions
        with PETSc rows and columns, the cell quadrature, the MLS table at its points, and the
        seconds spent tabulating (``setup``) and forming K (``assemble``).
    """
    t0 = time.perf_counter()
    comm = particles.comm
    gdim = particles.gdim
    axi = is_axisymmetric(material)
    if axi:  # the plane paths below would drop the hoop strain: refused by name
        raise_on_all_ranks(
            comm,
            lambda: _check_axisymmetric(
                isinstance(quadrature, SmoothingRule) or local_update_for(mls) is not None,
            ),
        )
    # after a crack grew: update the previous stiffness locally (statics/growth_update.py)
    local = local_update_for(mls)
    if local is not None and (
        boundary_values is not None
        or boundary_moments
        or quadrature is None
        or isinstance(quadrature, SmoothingRule)
        or (consistent_boundary is not None and boundary_quadrature is None)
    ):  # the edge-to-edge interface terms, or rules not from crack_rules: full rebuild
        local = None
    key = (
        id(particles), id(material), quadrature_degree, boundary_normals is not None,
        None if consistent_boundary is None else np.asarray(consistent_boundary[0]).tobytes(),
    )  # fmt: skip
    if local is not None:
        bq = None if consistent_boundary is None else boundary_quadrature
        upd = local.stiffness(particles, material, quadrature, bq, boundary_normals, key, comm)
        if upd is not None:
            Kg, tq, test_fn, timings = upd
            if tables is not None:
                test_grads = test_fn()
                tables.update(quadrature=quadrature, table=tq, test_gradients=test_grads,
                              approximation=mls)  # fmt: skip
            return Kg, quadrature, tq, timings
    if quadrature is None:
        q = cell_quadrature(particles.mesh, quadrature_degree, particles.cells)
    else:
        q = quadrature
    if axi:  # 2 pi r w: every integral below (and the caller's masses and loads) is revolved
        q = raise_on_all_ranks(comm, lambda: revolved(q))
    if isinstance(q, SmoothingRule):  # smoothed strains: symmetric and consistent as they are
        tq = raise_on_all_ranks(comm, lambda: smoothed_table(mls, q))
        consistent_boundary = None
    else:
        tq = raise_on_all_ranks(comm, lambda: mls.tabulate(q.points))
    test_grads = tq.gradients
    hoop = trial_hoop = None  # axisymmetric: see axisymmetry.approximation_hoop
    if axi:  # the trial strain u_r / r with the axis offset taken off in its cells; the test
        # functions' N / r under VCI (its radial identity is the divergence theorem for N r e_r)
        trial_hoop = raise_on_all_ranks(
            comm, lambda: approximation_hoop(mls, particles.mesh, q, tq.values)
        )
        hoop = trial_hoop
        if consistent_boundary is not None:
            hoop = raise_on_all_ranks(comm, lambda: hoop_table(tq.values, q.points))
    if consistent_boundary is not None:
        facets, cells = consistent_boundary
        if boundary_quadrature is None:
            bq = facet_quadrature(particles.mesh, facets, quadrature_degree, cells)
        else:
            bq = boundary_quadrature
        sides = getattr(bq, "sides", None)
        if axi:  # the boundary terms on the revolved surface (a projection of normals too)
            bq = raise_on_all_ranks(comm, lambda b=bq: revolved(b))
        tb = raise_on_all_ranks(comm, lambda: mls.tabulate(bq.points, derivatives=0, sides=sides))
        bvalues = tb.values if boundary_values is None else boundary_values(bq, tb.values)
        normals = bq.normals if boundary_normals is None else boundary_normals(bq)
        moments = boundary_moments and boundary_values is not None
        test_grads = raise_on_all_ranks(
            comm,
            lambda: consistent_gradients(
                tq.values,
                tq.gradients,
                q.weights,
                tb.values if moments else bvalues,
                bq.weights,
                normals,
                comm,
                mls.points,
                hoop=hoop,
            ),
        )
        if moments:
            extra = moment_corrections(
                tq.values, q.points[:, :gdim], q.weights, (bvalues - tb.values).tocsr(),
                bq.points[:, :gdim], bq.weights, normals, comm,
            )  # fmt: skip
            test_grads = [(g + c).tocsr() for g, c in zip(test_grads, extra, strict=True)]
    if tables is not None:
        tables.update(quadrature=q, table=tq, test_gradients=test_grads, approximation=mls)
        if hoop is not None:
            tables["hoop"], tables["test_hoop"] = trial_hoop, hoop
    t1 = time.perf_counter()
    if isinstance(q, SmoothingRule):  # symmetric
        rows, weights = raise_on_all_ranks(comm, lambda: stiffness_rows(mls, q, tq))
        Kg = stiffness_matrix(rows, weights, material, None, particles.petsc_index)
    elif axi:
        Kg = axisymmetric_stiffness(
            test_grads, hoop, q.weights, material, tq.gradients, particles.petsc_index, trial_hoop
        )
    else:
        Kg = stiffness_matrix(test_grads, q.weights, material, tq.gradients, particles.petsc_index)
    timings = {"setup": t1 - t0, "assemble": time.perf_counter() - t1}
    if local is not None:
        cb = consistent_boundary is not None
        local.record(
            key, q, bq if cb else None, tq, tb.values if cb else None,
            normals if cb else None, test_grads, Kg, comm,
        )  # fmt: skip
    return Kg, q, tq, timings


def _check_axisymmetric_model(
    particles: ParticleSet, integration: str, cracks: Sequence, quadrature: object
) -> None:
    """Refuse what :class:`EFGElasticity` does not revolve, and a section outside r >= 0."""
    if cracks or quadrature is not None or integration not in ("vci", "gauss"):
        raise ValueError(
            f"material plane='axisymmetric' with integration={integration!r}, "
            f"{len(cracks)} crack(s), quadrature={quadrature!r}: an axisymmetric model takes "
            "integration='vci' (the default) or 'gauss', without cracks or an adaptive "
            "quadrature"
        )
    check_particle_section(particles)


def _check_axisymmetric(rule: bool) -> None:
    """Refuse what :func:`particle_stiffness` does not revolve (local)."""
    if rule:
        raise ValueError(
            "material plane='axisymmetric' takes the cells' Gauss rule (integration='vci' or "
            "'gauss', no cracks): smoothed strains and a crack's local updates are plane"
        )


def crack_rules(
    msh: dolfinx.mesh.Mesh,
    cells: np.ndarray,
    cracks: list[Crack],
    degree: int,
    boundary: tuple[np.ndarray, np.ndarray | None] | None,
    cell_rule: bool = True,
    quadrature: AdaptiveQuadrature | None = None,
) -> tuple[QuadraturePoints | None, QuadraturePoints | None]:
    """The cell rule and VCI boundary rule of particles cut by ``cracks`` (Belytschko et al.
    1995, sec. 5.2.2: each side of a crack integrated on its own, the faces traction-free).
    ``quadrature``: an :class:`~dolfinx_meshfree.AdaptiveQuadrature` for the cell rule (dense
    near the tips, coarse elsewhere, ``degree`` then not used for the cells; built in full, even
    with a local growth update, since its zone moves with the tips); default the uniform rule:
    :func:`~dolfinx_meshfree.geometry.cut_cells.cut_cell_quadrature` on ``cells`` and, with
    ``boundary = (facets, facet cells)``,
    :func:`~dolfinx_meshfree.geometry.cut_cells.cracked_boundary_quadrature` (its crack-face
    points have ``entities = -1``: they are no mesh facet, e.g. of an interface). ``(None,
    None)`` without cracks: :func:`particle_stiffness`'s defaults; the cell rule is ``None``
    too without ``cell_rule``. Collective.
    """
    if quadrature is not None:  # the zone follows the tips: built in full
        q = None
        if cell_rule:
            q = raise_on_all_ranks(msh.comm, lambda: quadrature.rule(msh, cells, cracks))
        return q, _crack_rules(msh, cells, cracks, degree, boundary, False)[1] if cracks else None
    if not cracks:
        return None, None
    local = next((u for u in map(local_update_for, cracks) if u is not None), None)
    if local is not None:  # after a crack grew: only the cells the new segments cut
        return local.rules(
            msh, cells, cracks, degree, boundary, cell_rule,
            lambda: _crack_rules(msh, cells, cracks, degree, boundary, cell_rule),
        )  # fmt: skip
    return _crack_rules(msh, cells, cracks, degree, boundary, cell_rule)


def _crack_rules(
    msh: dolfinx.mesh.Mesh,
    cells: np.ndarray,
    cracks: list[Crack],
    degree: int,
    boundary: tuple[np.ndarray, np.ndarray | None] | None,
    cell_rule: bool,
) -> tuple[QuadraturePoints | None, QuadraturePoints | None]:
    """:func:`crack_rules` built in full."""
    comm = msh.comm
    q = None
    if cell_rule:
        q = raise_on_all_ranks(comm, lambda: cut_cell_quadrature(msh, cells, cracks, degree))
    if boundary is None:
        return q, None
    facets, fcells = boundary
    bq = cracked_boundary_quadrature(msh, facets, cells, cracks, degree, fcells)
    entities = np.where(bq.sides != 0, -1, bq.entities)
    return q, dataclasses.replace(bq, entities=entities)


def _facet_particles(
    particles: ParticleSet, facets: np.ndarray, tol: float = 1e-8
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The (facet, particle) pairs of the given local facets of a 3D mesh and the particles on
    them (closed: vertices and edges included; positions in ``facets``, indices into the
    particle set), whether a facet has a particle off its vertices (f,), and the facets'
    centroids (f, 3)."""
    msh = particles.mesh
    corners = msh.geometry.x[_compat.entities_to_geometry(msh, 2, facets)]  # (f, 3 or 4, 3)
    if corners.shape[1] == 4:  # a quadrilateral's vertices in DOLFINx order: 0-1-3-2
        tris = [corners[:, [0, 1, 3]], corners[:, [0, 3, 2]]]
    else:
        tris = [corners]
    centroids = corners.mean(axis=1)
    size = np.linalg.norm(corners - centroids[:, None], axis=2).max(axis=1)
    x = particles.positions
    near = cKDTree(x).query_ball_point(centroids, size * (1 + 1e-9))
    k = np.repeat(np.arange(len(facets)), [len(n) for n in near])
    j = np.concatenate([np.asarray(n, dtype=np.int64) for n in near] or [np.zeros(0, np.int64)])
    p, hit = x[j], np.zeros(j.size, dtype=bool)
    for t in tris:
        a, b, c = t[k, 0], t[k, 1], t[k, 2]
        n = np.cross(b - a, c - a)
        area2 = np.einsum("pi,pi->p", n, n)
        in_plane = np.abs(np.einsum("pi,pi->p", p - a, n)) <= tol * size[k] * np.sqrt(area2)
        w_a = np.einsum("pi,pi->p", np.cross(c - b, p - b), n) / area2  # barycentric
        w_b = np.einsum("pi,pi->p", np.cross(a - c, p - c), n) / area2
        hit |= in_plane & (np.minimum(np.minimum(w_a, w_b), 1.0 - w_a - w_b) >= -tol)
    k, j = k[hit], j[hit]
    gap = np.linalg.norm(x[j][:, None] - corners[k], axis=2).min(axis=1)
    off_vertices = np.zeros(len(facets), dtype=bool)
    off_vertices[k[gap > tol * size[k]]] = True
    return k, j, off_vertices, centroids


def _facets_of(quadratures: list[QuadraturePoints]) -> np.ndarray:
    """The local facets of facet quadratures (their entities; -1, a cut piece, left out)."""
    local = [np.unique(d.entities[d.entities >= 0]) for d in quadratures]
    return np.concatenate(local).astype(np.int32) if local else np.zeros(0, np.int32)


def check_multiplier_facets(
    particles: ParticleSet, quadratures: list[QuadraturePoints], what: str
) -> None:
    """Refuse piecewise-constant multipliers on 3D facets that carry too few particles
    (collective; a ``ValueError`` on every rank, naming a facet by its centroid).

    A facet's share of particles counts each particle on it once, divided among the constrained
    facets it lies on (a vertex of six triangles gives each 1/6, a particle on an edge 1/2, one
    inside 1). In 2D a boundary of ``n`` edges has ``n + 1`` vertices, and one multiplier per
    edge is stable with particles at the vertices. In 3D the facets' vertices alone give a share
    of 1 per facet of a structured surface, as do the vertices and the diagonals' midpoints of a
    triangulated one (the default placement at a spacing of the element size): the saddle
    point is then singular (a checkerboard mode on quadrilaterals, as Q1-P0 pressures) or
    nearly so, and the solution can be wrong without an error. Measured on the unit cube with 4
    cells, a quadratic field on the whole boundary (relative L2 errors): pure EFG at the
    hexahedra's vertices 0.52 (n = 3) and 1.15 (perturbed), against 8.7e-3 with particles at
    h / 2; the couplings at spacing h: tetrahedra lagrange 4.4e-2, edge-to-edge 0.086 to 0.52,
    bridging 96 (the shares: 1.0), hexahedra right by luck (the multipliers' block with six
    singular values at 6e-17 relative: median share 1.08, no particle off the vertices),
    against 1.3e-2 to 1.9e-2 at 0.75 h (median shares 4.08 on hexahedra, 2.0 on tetrahedra;
    at 0.5 h 4.08 and 3.5). The rule:
    the median share over the constrained facets must exceed 1, and at least half of them must
    carry a particle off their vertices (a small structured boundary has shares above 1 from
    its edges and corners alone, and still the checkerboard mode). Checked by the static
    solves (pure EFG and the couplings); explicit dynamics' ``fixed_facets`` hold velocities
    (zero or uniform: data the singular multipliers satisfy; the 3D standing wave with
    particles at the vertices measured right) and are not checked.
    """
    comm = particles.comm
    if particles.gdim != 3 or particles.mesh is None:  # the same on every rank
        return
    facets = np.unique(_facets_of(quadratures))
    k, j, off, centroids = raise_on_all_ranks(comm, lambda: _facet_particles(particles, facets))
    count = np.bincount(j, minlength=particles.num_particles).astype(float)
    comm.Allreduce(MPI.IN_PLACE, count, op=MPI.SUM)
    share = np.bincount(k, weights=1.0 / count[j], minlength=facets.size)
    shares = np.concatenate(comm.allgather(share))
    with_off = comm.allreduce(int(off.sum()))
    if shares.size == 0 or (np.median(shares) > 1.0 + 1e-9 and 2 * with_off >= shares.size):
        return
    low = (share <= 1.0 + 1e-9) | ~off
    c = next(g for g in comm.allgather(centroids[low][:1]) if len(g))[0]
    raise ValueError(
        f"{what}: the {shares.size} constrained facets carry a median share of "
        f"{np.median(shares):.3g} particle(s) each, {with_off} of them one off their vertices "
        f"(e.g. the facet centred at ({c[0]:.6g}, {c[1]:.6g}, {c[2]:.6g}): particles at its "
        "vertices and edges only, shared with its neighbours). Piecewise-constant multipliers "
        "on such facets make a singular or nearly singular saddle point in 3D, whose solution "
        "can be wrong without an error (a checkerboard mode on quadrilaterals, too many "
        "multipliers on triangles). Use a particle spacing below the element size there (e.g. "
        "ParticlePatch(mesh, cells, spacing=0.75 * h), ParticleSet.from_cells(mesh, h / 2)), "
        "or give the condition on the FE side or as a traction"
    )


def facet_multipliers(
    particles: ParticleSet,
    conditions: list[tuple[np.ndarray, VectorFunction]],
    quadratures: list[QuadraturePoints],
    tables: list[ShapeTable],
    scale: float,
) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray, Layout]:
    """Constraint block of ``u = ubar`` on facets, one multiplier per facet and component.

    ``G_{(f,i),(J,i)} = s int_f phi_J`` and ``g_(f,i) = s int_f ubar_i`` (Belytschko, Lu & Gu 1994
    with piecewise-constant multipliers), assembled from this rank's owned facets (collective);
    ``i`` runs over the ``gdim`` components (edges in 2D, triangles or quadrilaterals in 3D).

    Args:
        conditions: ``(facets, ubar)`` pairs, or ``(facets, ubar, components)`` triples that
            constrain only the given components (e.g. ``(1,)``: a roller);
            ``quadratures``/``tables``: their facet quadrature and the particle shape functions
            there; ``scale``: ``s``.

    Returns:
        ``(G, rows, values, layout)``: G as (M x gdim n) CSR with PETSc particle columns, the rhs
        entries (global rows and values) and the multipliers' layout.
    """
    comm = particles.comm
    gdim = particles.gdim
    dof_map = particles.petsc_dofs(gdim).ravel()
    comps = [tuple(c[2]) if len(c) > 2 else tuple(range(gdim)) for c in conditions]
    nrows = [np.unique(d.entities).size * len(c) for d, c in zip(quadratures, comps, strict=True)]
    mlayout = Layout.from_local(comm, int(sum(nrows)))
    g_rows, g_cols, g_vals, r_rows, r_vals = [], [], [], [], []
    offset = mlayout.start
    for cond, d, tab, cs in zip(conditions, quadratures, tables, comps, strict=True):
        fn, m = cond[1], len(cs)
        _, facet_id = np.unique(d.entities, return_inverse=True)
        ubar = raise_on_all_ranks(
            comm,
            lambda fn=fn, d=d: vector_values(fn, (d.points,), len(d), "the Dirichlet value", gdim),
        )
        coo = tab.values.tocoo()
        for k, c in enumerate(cs):
            g_rows.append(offset + m * facet_id[coo.row] + k)
            g_cols.append(dof_map[gdim * coo.col + c])
            g_vals.append(scale * d.weights[coo.row] * coo.data)
            r_rows.append(offset + m * facet_id + k)
            r_vals.append(scale * d.weights * ubar[:, c])
        offset += m * (int(facet_id.max()) + 1) if facet_id.size else 0
    G = sp.csr_matrix(
        (_cat(g_vals, float), (_cat(g_rows, np.int64), _cat(g_cols, np.int64))),
        shape=(mlayout.size_global, gdim * particles.num_particles),
    )
    return G, _cat(r_rows, np.int64), _cat(r_vals, float), mlayout


class EFGElasticity:
    """Linear elastostatics discretised by EFG on a particle set, in 2D or 3D.

    One code path for every dimension: the mesh's ``gdim`` (2: triangles, quadrilaterals; 3:
    tetrahedra, hexahedra) sets the number of displacement components, the Voigt strain of
    :func:`~dolfinx_meshfree.approx.tables.strain_operator`, the facet rules and the multipliers
    (one
    per Dirichlet facet and component). The multipliers need fewer Dirichlet facets than
    particles: a tetrahedral box mesh has about two boundary triangles per boundary vertex, so on
    tetrahedra the particles must be finer than the mesh (e.g. spacing h / 2), not its vertices.

    Args:
        particles: Particles with a background mesh (``particles.mesh``); its cells
            (``particles.cells``, default all owned cells) are the integration cells.
        material: :class:`~dolfinx_meshfree.LinearElastic` of the mesh's dimension
            (``plane="stress"|"strain"`` in 2D, ``plane=None`` in 3D), or
            ``plane="axisymmetric"``: the mesh is the (r, z) section (``x[0] = r >= 0``) of a
            solid of revolution (:mod:`~dolfinx_meshfree.physics.axisymmetry`: hoop strain,
            ``2 pi r`` weights in the stiffness, VCI, tractions and body loads; VCI or Gauss, no
            cracks; a mesh touching the axis needs its radial component held there,
            ``add_dirichlet(axis_facets, zero, components=(0,))``; the Dirichlet multipliers are the
            reaction tractions).
        weight, dilation, basis: MLS options (see :class:`~dolfinx_meshfree.MLS`).
        quadrature_degree: Degree of the cell Gauss rule (7: 4 x 4 points on quadrilaterals,
            4 x 4 x 4 on hexahedra). ``None`` (default): the lowest odd degree from 7 with 15
            Gauss points per particle or more
            (:func:`~dolfinx_meshfree.geometry.quadrature.particle_quadrature_degree`): 7 with
            particles at the vertices, 15 (8 x 8) with particles at ``h / 2`` on
            quadrilaterals, where VCI on 4 x 4 points stalls; 7 with cracks.
        consistent: Variationally consistent integration (VCI, Chen, Hillman & Rüter 2013; the
            default: the linear patch test passes to round-off). ``False``: plain Gauss
            quadrature of Belytschko et al. 1995 (patch-test error 1e-4 to 6e-4 at 4 x 4 Gauss).
        integration: ``"vci"`` (the default, as ``consistent=True``), ``"gauss"`` (as
            ``consistent=False``), ``"smoothed"`` (strains smoothed over each cell and
            stabilised by the point strains, :mod:`~dolfinx_meshfree.geometry.smoothing`:
            symmetric and consistent, so that ``solver="mumps"`` factorises by LDL^T) or
            ``"smoothed-subcells"`` (smoothed over sub-cells, not stabilised: the plain
            variant). The smoothed ones: linear elasticity (and, subcells only, the laws
            integrated point by point), not with cracks or an adaptive quadrature yet.
        cracks: 2D :class:`~dolfinx_meshfree.Crack` polylines in the particles' cells (checked by
            :func:`~dolfinx_meshfree.geometry.crack.place_crack`): the MLS weights are cut by
            them (:func:`~dolfinx_meshfree.approx.crack_cuts.attach_cracks`), cut cells are
            integrated side by side, the crack faces are traction-free and part of VCI's boundary
            (:mod:`~dolfinx_meshfree.geometry.cut_cells`).
        crack_method: ``"diffraction"`` (default) or ``"visibility"`` (Organ, Fleming &
            Belytschko 1996).
        crack_enrichment: Enrich the MLS basis near the crack tips (Fleming et al. 1997,
            :mod:`~dolfinx_meshfree.approx.tip_enrichment`); ``False`` (default): linear basis.
        quadrature: An :class:`~dolfinx_meshfree.AdaptiveQuadrature`: the cells near the crack
            tips with its ``near`` degree, the others with ``far`` (Belytschko et al. 1995, sec.
            5.2.2); ``None`` (default): the uniform rule of ``quadrature_degree``.
        particle_band: With a law that softens (:class:`~dolfinx_meshfree.RankineDamage`): the
            crack band width of the particle points, in sizes of their integration cells, as
            :class:`~dolfinx_meshfree.CoupledElasticity`'s. Default (``None``): the MLS
            dilation, about one support radius, the narrowest band a smooth MLS field localises
            in.
    """

    def __init__(
        self,
        particles: ParticleSet,
        material: LinearElastic,
        weight: str = "quartic",
        dilation: float = 2.0,
        basis: str = "linear",
        quadrature_degree: int | None = None,
        consistent: bool | None = None,
        cracks: tuple[Crack, ...] | list[Crack] = (),
        crack_method: str = "diffraction",
        crack_enrichment: bool = False,
        quadrature: AdaptiveQuadrature | None = None,
        integration: str | None = None,
        particle_band: float | None = None,
    ):
        check_particle_band(particle_band)
        integration = raise_on_all_ranks(
            particles.comm, lambda: resolve_integration(consistent, integration)
        )
        refuse_smoothed(integration, cracked=bool(cracks) or quadrature is not None)
        if particles.mesh is None:
            raise ValueError("EFGElasticity needs particles with a background mesh (mesh=...)")
        if quadrature is not None and not isinstance(quadrature, AdaptiveQuadrature):
            raise ValueError(
                f"quadrature={quadrature!r}: give an AdaptiveQuadrature(radius=..., near=..., "
                "far=...) or None (the uniform rule of quadrature_degree)"
            )
        #: The :class:`~dolfinx_meshfree.AdaptiveQuadrature` of the cells, or ``None``.
        self.adaptive_quadrature = quadrature
        check_not_rate_law(material, "EFGElasticity")
        if not isinstance(material, LinearElastic | Material) and not is_stateful(material):
            raise TypeError(
                f"material must be a LinearElastic, a finite-strain Material (NeoHookean, "
                f"SaintVenantKirchhoff) or a law with state (RankineDamage, J2Plasticity), got "
                f"{type(material).__name__}"
            )
        linear_twin(material).check_gdim(
            particles.mesh.geometry.dim, "the particles' mesh", type(material).__name__
        )
        if is_axisymmetric(material):
            raise_on_all_ranks(
                particles.comm,
                lambda: _check_axisymmetric_model(particles, integration, cracks, quadrature),
            )
        quadrature_degree = particle_quadrature_degree(
            particles.mesh, particles.integration_cells(), particles.positions,
            quadrature_degree, bool(cracks),
        )  # fmt: skip
        t0 = time.perf_counter()
        self.particles = particles
        self.mesh = particles.mesh
        self.material = material
        #: With a law that softens: the particle points' crack band in cell sizes (``None``:
        #: the MLS dilation).
        self.particle_band = particle_band
        #: The small-strain law of the stiffness (``material`` itself when linear).
        self.linear_material = linear_twin(material)
        self.mls = raise_on_all_ranks(
            particles.comm, lambda: MLS(particles, weight=weight, dilation=dilation, basis=basis)
        )
        separate_bodies(self.mls, particles.mesh)
        self.quadrature_degree = quadrature_degree
        #: One of :data:`~dolfinx_meshfree.geometry.smoothing.INTEGRATIONS`.
        self.integration = integration
        #: VCI corrects the test gradients (``integration == "vci"``).
        self.consistent = integration == "vci"
        #: The cracks cutting the particles' shape functions.
        self.cracks = list(cracks)
        self._domain: CrackDomain | None = None
        if self.cracks:
            domain = self._domain = CrackDomain.from_particles(particles)
            for crack in self.cracks:
                place_crack(crack, domain)
            raise_on_all_ranks(
                particles.comm,
                lambda: attach_cracks(self.mls, self.cracks, crack_method, domain=domain),
            )
            if crack_enrichment:
                enrich_tips(self.mls, self.cracks, crack_method)
        self._dirichlet: list[tuple[np.ndarray, VectorFunction, tuple[int, ...]]] = []
        #: The cracks whose faces carry a traction-separation law (:meth:`add_cohesive`).
        self.cohesive: list[CohesiveCrack] = []
        self._tractions: list[tuple[np.ndarray, TractionFunction]] = []
        self._body: VectorFunction | None = None
        #: Where the last solve of a law with state (or cohesive faces) ended: the next starts
        #: there (:mod:`~dolfinx_meshfree.statics.history`; :meth:`reset` forgets it).
        self.history = SolveHistory("EFGElasticity")
        self._setup_time = time.perf_counter() - t0

    def reset(self) -> None:
        """Forget the path: the next :meth:`solve` starts from the unloaded, virgin state."""
        self.history.clear()

    @property
    def comm(self) -> MPI.Comm:
        """The particles' communicator."""
        return self.particles.comm

    def add_cohesive(
        self,
        crack: Crack,
        law: LinearCohesive,
        segments: Sequence[int] | None = None,
        points: int = 3,
    ) -> None:
        """Let the faces of one of the model's cracks carry a traction-separation law, on the
        segments ``segments`` of its polyline (``None``: all). See
        :meth:`~dolfinx_meshfree.CoupledElasticity.add_cohesive`."""
        self.cohesive.append(
            raise_on_all_ranks(
                self.comm,
                lambda: check_cohesive(
                    crack, law, self.cracks, segments, points, self.mesh.geometry.dim
                ),
            )
        )

    def add_dirichlet(
        self, facets: np.ndarray, value: VectorFunction, components: tuple[int, ...] | None = None
    ) -> None:
        """Impose ``u = value(x)`` on owned exterior facets by Lagrange multipliers.

        ``value`` maps points (m, gdim) to displacements (m, gdim); ``components``, if given,
        constrains only those components (e.g. ``(1,)``: a roller; one constant multiplier
        per facet and component: its resultant reaction).
        """
        gdim = self.particles.gdim

        def check() -> tuple[int, ...]:
            if components is None:
                return tuple(range(gdim))
            c = tuple(components)
            if not c or len(set(c)) != len(c) or any(k not in range(gdim) for k in c):
                raise ValueError(
                    f"components={components!r} must be distinct indices in 0..{gdim - 1}"
                )
            return c

        check_arguments(value, 1, "the Dirichlet value")
        comps = raise_on_all_ranks(self.comm, check)
        self._dirichlet.append((self._facets(facets, "add_dirichlet: facets"), value, comps))

    def add_traction(self, facets: np.ndarray, traction: TractionFunction) -> None:
        """Apply ``traction(x, n)`` (m, gdim) on owned exterior facets (``n``: outward normals)."""
        check_arguments(traction, 2, "traction")
        self._tractions.append((self._facets(facets, "add_traction: facets"), traction))

    def _facets(self, facets: np.ndarray, name: str) -> np.ndarray:
        """The user's facets of the background mesh, checked (collective)."""
        if self.particles.mesh is None:  # the same on every rank
            return np.asarray(facets, dtype=np.int32)
        return check_facets(self.particles.mesh, facets, name)

    def set_body_force(self, force: VectorFunction) -> None:
        """Body force per unit volume ``b(x)`` (m, gdim)."""
        self._body = force

    def system(self, tables: dict | None = None) -> tuple[BlockSystem, list, dict]:
        """The assembled block system, not solved (collective).

        Args:
            tables: If given, receives the quadrature, MLS table and test gradients of the
                stiffness (see :func:`particle_stiffness`).

        Returns:
            ``(system, objects, extra)``: the :class:`~dolfinx_meshfree.statics.petsc.BlockSystem`
            (fields ``particles`` and, with Dirichlet facets, ``dirichlet``), the PETSc objects
            to destroy with it, and ``extra`` with ``scale`` (the constraint rows' ``s``),
            ``multipliers`` (their layout) and the ``setup``/``assemble`` seconds.
        """
        comm = self.comm
        P = self.particles
        n = P.num_particles
        gdim = P.gdim
        dof_map = P.petsc_dofs(gdim).ravel()  # original interleaved dof -> PETSc dof
        t0 = time.perf_counter()
        deg = self.quadrature_degree
        boundary = (boundary_facets(self.mesh), None) if self.consistent else None
        cells = P.integration_cells()
        q, bq = crack_rules(
            self.mesh, cells, self.cracks, deg, boundary, quadrature=self.adaptive_quadrature
        )
        if self.integration in STABILISATION:
            beta = STABILISATION[self.integration]
            q = raise_on_all_ranks(comm, lambda: smoothing_rule(self.mesh, cells, deg, beta))

        def fq(f: np.ndarray) -> QuadraturePoints:  # facets split at the cracks' mouths
            if self.cracks:
                return cut_facet_quadrature(self.mesh, f, self.cracks, deg)
            return facet_quadrature(self.mesh, f, deg)

        Kg, q, tq, kt = particle_stiffness(
            P, self.mls, self.linear_material, deg, boundary, tables=tables,
            quadrature=q, boundary_quadrature=bq,
        )  # fmt: skip
        if self.linear_material.axisymmetric:  # the particles need the axis held
            groups = [(f, comps) for f, _, comps in self._dirichlet]
            check_axis_held(self.mesh, groups, None, "EFGElasticity")
        dq = [fq(c[0]) for c in self._dirichlet]
        if self.linear_material.axisymmetric:  # multipliers = reaction tractions
            dq = [raise_on_all_ranks(comm, lambda d=d: revolved(d, constraint=True)) for d in dq]
        num_facets = (
            comm.allreduce(
                sum(
                    np.unique(d.entities).size * len(c[2])
                    for d, c in zip(dq, self._dirichlet, strict=True)
                )
            )
            // gdim
        )
        if num_facets > n:
            raise ValueError(
                f"the Dirichlet conditions have {num_facets} facets, each with {gdim} constant "
                f"multipliers, more than the {gdim * n} particle dofs of {n} particles: the "
                "saddle-point system is singular. Use more particles than Dirichlet facets (a "
                "finer spacing, e.g. ParticleSet.from_cells(mesh, h / 2) on tetrahedra, whose "
                "boundary has two triangles per vertex) or fewer Dirichlet facets"
            )
        check_multiplier_facets(P, dq, "Dirichlet conditions on particle facets")
        dtabs = [raise_on_all_ranks(comm, lambda d=d: self.mls.tabulate(d.points, 0)) for d in dq]
        tq_loads = [fq(f) for f, _ in self._tractions]
        if self.linear_material.axisymmetric:  # tractions on the revolved surface
            tq_loads = [raise_on_all_ranks(comm, lambda d=d: revolved(d)) for d in tq_loads]
        ttabs = [
            raise_on_all_ranks(comm, lambda d=d: self.mls.tabulate(d.points, 0)) for d in tq_loads
        ]
        setup = self._setup_time + time.perf_counter() - t0 - kt["assemble"]

        t1 = time.perf_counter()
        udofs = P.dof_layout(gdim)
        K = create_aij(comm, Kg, udofs, udofs)

        f_loc = np.zeros(gdim * n)
        for (_, fn), fq, tab in zip(self._tractions, tq_loads, ttabs, strict=True):
            t = raise_on_all_ranks(
                comm,
                lambda fn=fn, fq=fq: vector_values(
                    fn, (fq.points, fq.normals), len(fq), "traction", gdim
                ),
            )
            f_loc += load_vector(tab.values, fq.weights, t)
        if self._body is not None:
            # a smoothing rule's loads on the cells' Gauss rule
            bq, bvalues = raise_on_all_ranks(comm, lambda: value_rule(self.mls, q, tq))
            b = raise_on_all_ranks(
                comm, lambda: vector_values(self._body, (bq.points,), len(bq), "body force", gdim)
            )
            f_loc += load_vector(bvalues, bq.weights, b)
        f = create_vector(comm, udofs, dof_map, f_loc)

        s = self.material.E
        Gg, g_rows, g_vals, mlayout = facet_multipliers(P, self._dirichlet, dq, dtabs, s)
        G = create_aij(comm, Gg, mlayout, udofs)
        GT = create_aij(comm, Gg.T.tocsr(), udofs, mlayout)
        g = create_vector(comm, mlayout, g_rows, g_vals)
        nodes = [P.owned_positions()]  # solver="iterative": GAMG's block size, rigid modes
        if mlayout.size_global:
            system = BlockSystem(
                [[K, GT], [G, None]], [f, g], names=["particles", "dirichlet"], coordinates=nodes
            )
        else:
            system = BlockSystem([[K]], [f], names=["particles"], coordinates=nodes)
        assemble = time.perf_counter() - t1 + kt["assemble"]

        extra = {"scale": s, "multipliers": mlayout, "setup": setup, "assemble": assemble}
        return system, [K, G, GT, f, g], extra

    def solve(
        self,
        solver: str | SolverOptions = "mumps",
        petsc_options: Mapping[str, Any] | None = None,
        prefix: str | None = None,
        load_steps: int = 1,
        newton: NewtonOptions | None = None,
        kept: KeptFactorisation | None = None,
    ) -> EFGSolution:
        """Assemble the block system and solve it (collective); with a finite-strain material,
        by Newton (:func:`~dolfinx_meshfree.statics.newton.newton`) over ``load_steps`` steps of the
        tractions, body force and prescribed displacements (``newton``: its options); the
        solution's ``newton`` then holds the :class:`~dolfinx_meshfree.NonlinearSolveResult`.

        Args:
            solver: ``"mumps"`` (direct) or ``"fieldsplit"`` (Schur complement on the augmented
                saddle point, see :class:`~dolfinx_meshfree.statics.petsc.BlockSystem`), or a
                :class:`~dolfinx_meshfree.statics.petsc.SolverOptions`.
            petsc_options, prefix: PETSc options of a KSP on the block system instead (fields
                ``particles`` and ``dirichlet``), and its prefix; see
                :meth:`~dolfinx_meshfree.CoupledElasticity.solve`.
            kept: The direct solve's factorisation shared with earlier solves (a load sweep;
                see :meth:`~dolfinx_meshfree.CoupledElasticity.solve`).
        """
        comm = self.comm
        solver = raise_on_all_ranks(comm, lambda: solver_options(solver, petsc_options, prefix))
        raise_on_all_ranks(comm, lambda: check_kept(kept))
        raise_on_all_ranks(self.comm, lambda: check_through(self.cracks, self.cohesive))
        if not isinstance(self.material, LinearElastic) or self.cohesive:
            return self._solve_finite_strain(solver, load_steps, newton)
        P = self.particles
        system, objects, extra = self.system()
        s, mlayout = extra["scale"], extra["multipliers"]
        t2 = time.perf_counter()
        parts = system.solve(solver, kept=kept)
        solve = time.perf_counter() - t2
        for obj in (system, *objects):
            obj.destroy()
        owned = np.concatenate(comm.allgather(parts[0]))  # PETSc order, all ranks
        coeffs = owned.reshape(-1, P.gdim)[P.petsc_index]
        lam = parts[1] * s if len(parts) > 1 else np.zeros(0)
        return EFGSolution(
            mls=self.mls,
            coefficients=coeffs,
            multipliers=lam,
            timings={"setup": extra["setup"], "assemble": extra["assemble"], "solve": solve},
            num_multipliers=mlayout.size_global,
            material=self.linear_material,
            cracks=self.cracks,
            domain=self._domain,
            particles=self.particles,
            body_forces=[] if self._body is None else [CallableBodyForce(self._body)],
        )

    def block_model(self) -> EFGBlockModel:
        """The block problem of Newton (and of path following): ``[[K_T(u), s G^T], [s G, 0]]``
        with ``f_int(u) = sum_q B0^T P w_q`` on the cells' quadrature and the stiffness's test
        gradients, from ``u = 0``. Collective."""
        law = self.material
        refuse_smoothed(self.integration, nonlinear=True)  # the same on every rank
        factor = None  # the particle points' crack band in cell sizes (a law that softens)
        if is_stateful(law) and law.needs_band:  # on every rank, before the assembly
            factor = particle_band_factor(self.mls, self.particle_band)
            cells = np.ones(self.mesh.topology.index_map(self.mesh.topology.dim).size_local, bool)
            raise_on_all_ranks(self.comm, lambda: check_bands(self.mesh, law, cells, factor))
        tables: dict = {}
        system, objects, extra = self.system(tables)
        side = ParticleSide(self.particles, tables, law, factor)
        constant = [list(row) for row in system.blocks]
        constant[0][0] = None
        E, h = self.linear_material.E, particle_spacing(self._domain) if self.cohesive else 0.0
        cohesive = [CohesiveSide(c, side, self.mls, 0, E, h) for c in self.cohesive]
        problem = BlockProblem(system.names, 1, [side], constant, list(system.rhs), shared=cohesive)
        x = [v.duplicate() for v in system.rhs]
        for v in x:
            v.set(0.0)
        return EFGBlockModel(self, problem, x, side, extra, [system, *objects])

    def _solve_finite_strain(
        self, solver: SolverOptions, load_steps: int, options: NewtonOptions | None
    ) -> EFGSolution:
        """Newton on :meth:`block_model` over the load steps (VCI when consistent: a homogeneous
        deformation is reproduced at any load level). Collective."""

        def check() -> None:
            if not (isinstance(load_steps, int) and load_steps >= 1):
                raise ValueError(f"load_steps={load_steps!r} must be an integer >= 1")

        raise_on_all_ranks(self.comm, check)
        history = self.history if is_stateful(self.material) or self.cohesive else None
        return solve_built(
            self.block_model(), load_steps, options or NewtonOptions(), solver, history
        )


@dataclass
class EFGBlockModel:
    """A pure EFG model's block problem (:meth:`EFGElasticity.block_model`): the problem, its
    state ``x`` (particles, multipliers), the particle side."""

    model: EFGElasticity
    problem: BlockProblem
    x: list
    particles: ParticleSide
    extra: dict
    objects: list

    def solution(self) -> EFGSolution:
        """The solution at the current ``x`` (collective); its ``states`` are the laws'."""
        P = self.model.particles
        coeffs = self.particles.coefficients(self.x[0]).reshape(-1, P.gdim)
        s, mlayout = self.extra["scale"], self.extra["multipliers"]
        lam = self.x[1].getArray(readonly=True) * s if len(self.x) > 1 else np.zeros(0)
        solution = EFGSolution(
            mls=self.model.mls,
            coefficients=coeffs,
            multipliers=lam,
            timings={"setup": self.extra["setup"], "assemble": self.extra["assemble"]},
            num_multipliers=mlayout.size_global,
            material=self.model.linear_material,
            cracks=self.model.cracks,
            domain=self.model._domain,
            particles=self.model.particles,
            body_forces=[] if self.model._body is None else [CallableBodyForce(self.model._body)],
        )
        solution.states = self.problem.states
        return solution

    def destroy(self) -> None:
        self.problem.destroy()
        for obj in [*self.objects, *self.x]:
            obj.destroy()
