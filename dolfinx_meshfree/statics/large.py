"""Large pure-EFG static solves: chunked tabulation and assembly, Nitsche boundary conditions and
an iterative (Krylov + GAMG) solve.

The default EFG solve (:meth:`~dolfinx_meshfree.EFGElasticity.solve`) tabulates every
quadrature point at once, keeps the tables, imposes ``u = ubar`` by Lagrange multipliers and
factorises the saddle point with MUMPS: its memory grows with the tables (about 3.6 KB per
evaluation point) and the factors. :func:`solve_large` solves the same model

* with the stiffness (Belytschko et al. 1995, eq. (4.3)) tabulated and assembled in chunks of
  ``chunk_points`` quadrature points (:func:`chunked_stiffness`): one chunk's table at a time,
  each chunk summed by the compiled kernel (:mod:`~dolfinx_meshfree.physics.assembly_kernel`) into
  the stiffness; with variationally consistent integration (VCI, Chen, Hillman & Rüter 2013) in
  two passes over the chunks (the per-node sums of the correction, then the corrected
  gradients);
* with the essential conditions by Nitsche's method instead of multipliers,

  .. math::
      a(u, v) - \\int_{\\Gamma_D} (v \\cdot \\sigma(u) n + u \\cdot \\sigma(v) n)
      + \\frac{\\beta E}{h} \\int_{\\Gamma_D} u \\cdot v
      = l(v) - \\int_{\\Gamma_D} \\bar u \\cdot \\sigma(v) n
      + \\frac{\\beta E}{h} \\int_{\\Gamma_D} \\bar u \\cdot v,

  (``h`` the facet size; consistent, so the linear patch test still passes), which keeps the
  system a single positive definite matrix (symmetric without VCI; VCI's Petrov-Galerkin
  test gradients make it slightly unsymmetric);
* with ``integration="smoothed"`` (:mod:`~dolfinx_meshfree.geometry.smoothing`), chunks of
  cells whose smoothing domains and Gauss points stay inside the chunk: consistent and
  symmetric, so that CG solves it;
* solved by CG (symmetric) or GMRES (with VCI) preconditioned by smoothed-aggregation AMG
  (PETSc GAMG) with the rigid-body modes as near-nullspace, or by MUMPS on the same matrix
  (``direct=True``, the reference);
* with each rank's shape functions tabulated by the MLS of its *halo* (:class:`HaloMLS`): the
  particles whose supports reach the rank's evaluation points (its integration cells and the
  cells beside its boundary facets, :func:`halo_particles`), with their global support radii,
  the tables returned in the particle set's numbering. The matrix is the one the whole MLS
  gives (the same pairs and sums, to the last bit); the neighbour structures (cell lists,
  k-d tree) of a rank then cover about ``1 / ranks`` of the particles. The particle set's
  positions, ownership and PETSc numbering stay replicated (the rest of the package reads
  them), and so does the problem's MLS, which the solution evaluates anywhere.
"""

from __future__ import annotations

import ctypes
import itertools
import resource
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from .. import _compat
from ..approx.jit import AVAILABLE as _COMPILED
from ..approx.jit import jit
from ..approx.tables import ShapeTable
from ..geometry.quadrature import (
    QuadraturePoints,
    boundary_facets,
    cell_quadrature,
    facet_quadrature,
)
from ..geometry.smoothing import STABILISATION, smoothed_table, smoothing_rule, stiffness_rows
from ..parallel import raise_on_all_ranks
from ..physics.materials import LinearElastic
from ..physics.operators import (
    corrected_gradients,
    load_vector,
    stiffness_matrix,
    vci_constants,
    voigt_tangent,
)
from ..physics.user_functions import vector_values
from .efg import EFGElasticity, EFGSolution
from .petsc import create_aij, create_vector, rigid_body_modes, scoped_options, solve_lu

if TYPE_CHECKING:  # annotations only
    from ..approx.mls import MLS
    from ..geometry.particles import ParticleSet

__all__ = [
    "HaloMLS",
    "IterativeOptions",
    "chunked_l2_error",
    "chunked_stiffness",
    "csr_sum",
    "halo_particles",
    "joined",
    "nitsche_terms",
    "peak_rss_mb",
    "release_freed_memory",
    "row_blocks",
    "solve_large",
]

_prefix_counter = itertools.count()


@dataclass(frozen=True)
class IterativeOptions:
    """Options of :func:`solve_large`.

    Attributes:
        ksp_type: Krylov method; ``None``: ``"cg"`` when the matrix is symmetric (plain Gauss
            quadrature), ``"gmres"`` with VCI.
        rtol, atol, max_it: Stopping test of the Krylov method, on the unpreconditioned
            residual norm ``|b - A x| <= max(rtol |b|, atol)``. The default 1e-12 leaves the
            cantilever's L2 error as MUMPS's to 4 digits at 100k particles (1e-10: 6e-4
            relative there, and 2.5 % between 1 and 2 ranks at 300k).
        nitsche: ``beta`` of the Nitsche penalty ``beta E / h`` (``h`` the facet length).
        chunk_points: Quadrature points tabulated at a time.
        direct: Solve the same matrix by MUMPS instead (the reference of the iterative solve).
        halo: Tabulate by the MLS of each rank's halo (:class:`HaloMLS`; the same matrix);
            ``False``: by the problem's MLS of all particles (the reference).
        petsc_options: Further PETSc options of the KSP (without prefix, e.g.
            ``{"pc_gamg_threshold": 0.02}``), written under :attr:`prefix` and removed after.
        prefix: The KSP's options prefix (default: a unique ``dolfinx_meshfree_large_<n>_``).
    """

    ksp_type: str | None = None
    rtol: float = 1e-12
    atol: float = 0.0
    max_it: int = 5000
    nitsche: float = 100.0
    chunk_points: int = 1 << 17
    direct: bool = False
    halo: bool = True
    petsc_options: Mapping[str, Any] | None = field(default=None)
    prefix: str | None = None

    def check(self) -> None:
        """ValueError naming the option, its value and the fix (local)."""
        if self.ksp_type not in (None, "cg", "gmres", "fgmres", "bcgs"):
            raise ValueError(
                f"ksp_type={self.ksp_type!r}: use None, 'cg', 'gmres', 'fgmres', 'bcgs'"
            )
        if not (0 < self.rtol < 1) or self.atol < 0:
            raise ValueError(f"rtol={self.rtol!r} must lie in (0, 1), atol={self.atol!r} >= 0")
        if not (isinstance(self.max_it, int) and self.max_it >= 1):
            raise ValueError(f"max_it={self.max_it!r} must be an integer >= 1")
        if not self.nitsche > 0:
            raise ValueError(f"nitsche={self.nitsche!r} must be > 0 (e.g. 100)")
        if not (isinstance(self.chunk_points, int) and self.chunk_points >= 1):
            raise ValueError(f"chunk_points={self.chunk_points!r} must be an integer >= 1")


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, in MB (``getrusage``; local)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _chunks(m: int, size: int, comm: MPI.Comm | None = None):
    """Slices of ``range(m)`` of ``size``; with ``comm``, as many on every rank (the last ones
    empty where a rank has fewer points), for loops with collective calls."""
    count = -(-m // size)
    if comm is not None:
        count = comm.allreduce(count, op=MPI.MAX)
    for c in range(count):
        yield slice(min(c * size, m), min((c + 1) * size, m))


#: Cells per chunk of :func:`halo_particles`' cell balls (bounds its temporaries).
_HALO_CHUNK = 1 << 16


def halo_particles(
    positions: np.ndarray, radii: np.ndarray, msh: Any, cells: np.ndarray
) -> np.ndarray:
    """The particles whose support ``|x - x_I| < d_I`` may reach a point of the given local
    cells (increasing indices; local, no communication).

    A superset, exact up to the cells' bounding balls: particle ``I`` is kept when its distance
    to the nearest cell centre (vertex mean) is below ``d_I + R``, ``R`` the largest distance
    from a centre to a vertex of its cell (every point of a cell, a convex hull of its
    vertices, lies within ``R`` of its centre). The MLS of these particles with the same radii
    gives the whole set's shape functions at every point of the cells (:meth:`MLS.subset`).
    """
    gdim = positions.shape[1]
    cells = np.unique(np.asarray(cells, dtype=np.int64))
    if cells.size == 0:
        return np.zeros(0, np.int64)
    dofmap = _compat.geometry_dofmap(msh)
    centres = np.empty((cells.size, gdim))
    reach = 0.0
    for a in range(0, cells.size, _HALO_CHUNK):
        nodes = msh.geometry.x[dofmap[cells[a : a + _HALO_CHUNK]], :gdim]  # (nc, nv, gdim)
        c = nodes.mean(axis=1)
        centres[a : a + len(c)] = c
        reach = max(reach, float(np.sqrt(np.max(np.sum((nodes - c[:, None]) ** 2, axis=2)))))
    reach *= 1.0 + 1e-12  # the centres' rounding
    rmax = float(radii.max())
    lo, hi = centres.min(axis=0) - reach - rmax, centres.max(axis=0) + reach + rmax
    near = np.flatnonzero(np.all((positions >= lo) & (positions <= hi), axis=1))
    tree = cKDTree(centres)
    keep = np.zeros(near.size, dtype=bool)
    for a in range(0, near.size, _HALO_CHUNK):
        part = near[a : a + _HALO_CHUNK]
        bound = radii[part] + reach
        d, _ = tree.query(positions[part], k=1, distance_upper_bound=rmax + reach)
        keep[a : a + part.size] = d < bound
    return near[keep]


class HaloMLS:
    """Tabulation by the MLS of a subset of the particles (a rank's halo), the tables in the
    whole set's numbering: ``n`` columns, the subset's at ``indices`` (monotone, so each row's
    columns stay sorted). Equal to ``mls.tabulate(x)`` wherever the subset holds every support
    reaching ``x`` (:func:`halo_particles`).

    Args:
        mls: The MLS of all particles (without pair cuts or table transforms).
        indices: Increasing particle indices of the subset (may be empty on a rank without
            evaluation points; it may then tabulate no point).
    """

    def __init__(self, mls: MLS, indices: np.ndarray) -> None:
        self.num_particles = mls.num_particles
        self.gdim = mls.gdim
        self.version = mls.version
        idx = np.asarray(indices, dtype=np.int64)
        self.indices = idx.astype(np.int32 if self.num_particles < 2**31 else np.int64)
        self._mls = mls.subset(idx) if idx.size else None

    def tabulate(self, x: np.ndarray, derivatives: int = 1) -> ShapeTable:
        """:meth:`MLS.tabulate` in the whole set's numbering (local)."""
        n = self.num_particles
        if self._mls is None:
            if len(x):
                raise ValueError(
                    f"{len(x)} point(s), first {np.asarray(x)[0]}: the halo holds no particle; "
                    "build the HaloMLS from cells that contain the points"
                )
            empty = sp.csr_matrix((0, n))
            return ShapeTable(
                np.zeros((0, self.gdim)), empty, [empty] * (self.gdim * derivatives), self.version
            )
        t = self._mls.tabulate(x, derivatives)

        def widen(a: sp.csr_matrix) -> sp.csr_matrix:
            return sp.csr_matrix((a.data, self.indices[a.indices], a.indptr), (a.shape[0], n))

        grads = [widen(g) for g in t.gradients]
        return ShapeTable(t.points, widen(t.values), grads, self.version)


def _halo(problem: EFGElasticity, consistent: bool) -> HaloMLS:
    """The :class:`HaloMLS` of this rank's evaluation points: the integration cells and the
    cells beside its Dirichlet, traction and (with VCI) boundary facets (local)."""
    P, msh = problem.particles, problem.mesh
    cells = [
        P.cells
        if P.cells is not None
        else np.arange(msh.topology.index_map(msh.topology.dim).size_local)
    ]
    facets = [f for f, *_ in problem._dirichlet] + [f for f, _ in problem._tractions]
    if consistent:
        facets.append(boundary_facets(msh))
    for f in facets:
        cells.append(facet_quadrature(msh, f, 1).cells)
    idx = halo_particles(P.positions, problem.mls.radii, msh, np.concatenate(cells))
    return HaloMLS(problem.mls, idx)


@jit
def _merge_rows(ap, ai, ax, bp, bi, bx, outp, oi, ox, fill):  # pragma: no cover - compiled
    """Row by row, the sorted merge of two canonical CSR matrices, equal columns summed, zero
    sums dropped: with ``fill`` False the counts into ``outp[1:]``, else the entries."""
    for r in range(outp.size - 1):
        i, ie, j, je = ap[r], ap[r + 1], bp[r], bp[r + 1]
        k = outp[r] if fill else 0
        while i < ie or j < je:
            if j == je or (i < ie and ai[i] < bi[j]):
                c, v = ai[i], ax[i]
                i += 1
            elif i == ie or bi[j] < ai[i]:
                c, v = bi[j], bx[j]
                j += 1
            else:
                c, v = ai[i], ax[i] + bx[j]
                i += 1
                j += 1
            if v != 0.0:
                if fill:
                    oi[k] = c
                    ox[k] = v
                k += 1
        if not fill:
            outp[r + 1] = k


def csr_sum(a: sp.csr_matrix, b: sp.csr_matrix) -> sp.csr_matrix:
    """``a + b`` as scipy computes it (the same sums, zero sums dropped: equal to the last bit),
    into arrays of exactly the result's size: the peak is the two operands and the result,
    where scipy's sum also allocates ``nnz(a) + nnz(b)`` entries and then copies the result to
    trim it (local). Without numba, scipy's sum."""
    if a.shape != b.shape:
        raise ValueError(f"csr_sum of shapes {a.shape} and {b.shape}: give equal shapes")
    if not _COMPILED:
        return (a + b).tocsr()
    a, b = a.tocsr(), b.tocsr()
    for m in (a, b):
        if not m.has_canonical_format:
            m.sum_duplicates()  # in place: sorted indices, no duplicates
    itype = np.int64 if max(a.nnz + b.nnz, *a.shape) >= np.iinfo(np.int32).max else np.int32
    outp = np.zeros(a.shape[0] + 1, itype)
    dummy_i, dummy_x = np.zeros(0, itype), np.zeros(0)
    args = (a.indptr, a.indices, a.data, b.indptr, b.indices, b.data)
    _merge_rows(*args, outp, dummy_i, dummy_x, False)
    np.cumsum(outp, out=outp)
    oi, ox = np.empty(outp[-1], itype), np.empty(outp[-1])
    _merge_rows(*args, outp, oi, ox, True)
    out = sp.csr_matrix((ox, oi, outp), shape=a.shape)
    out.has_sorted_indices = True
    return out


def _libc_trim() -> Any:
    """glibc's ``malloc_trim``, or ``None`` where there is none (not glibc)."""
    try:
        return ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None


_MALLOC_TRIM = _libc_trim()


def release_freed_memory() -> None:
    """Return the C heap's free pages to the system (glibc's ``malloc_trim(0)``; a no-op
    elsewhere; local). numpy arrays below glibc's mmap threshold (which rises up to 32 MB after
    large frees) live on the heap, and freed ones stay resident until trimmed: without it the
    blocks :func:`joined` frees stay resident beside the matrix that replaces them (+0.9 x
    the stiffness at 300k particles)."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


#: Rows per block of the partial stiffness sums (:func:`row_blocks`).
ROW_BLOCK = 1 << 16


def row_blocks(a: sp.csr_matrix, size: int = ROW_BLOCK) -> list[sp.csr_matrix]:
    """The CSR ``a`` cut into blocks of ``size`` rows (copies; local)."""
    a = a.tocsr()
    return [a[r : r + size] for r in range(0, max(a.shape[0], 1), size)]


def _blocks_sum(a: list[sp.csr_matrix], b: list[sp.csr_matrix]) -> list[sp.csr_matrix]:
    """Block by block :func:`csr_sum` of two :func:`row_blocks` lists, emptying them as it goes
    (each input block freed once summed)."""
    out = []
    for k in range(len(a)):
        out.append(csr_sum(a[k], b[k]))
        a[k] = b[k] = None
    return out


def joined(blocks: list[sp.csr_matrix]) -> sp.csr_matrix:
    """One CSR of the :func:`row_blocks` ``blocks`` (emptying the list: each block freed once
    copied into arrays of the result's size; local)."""
    rows = sum(m.shape[0] for m in blocks)
    nnz = sum(m.nnz for m in blocks)
    shape = (rows, blocks[0].shape[1])
    itype = np.int64 if max(nnz, *shape) >= np.iinfo(np.int32).max else np.int32
    indptr = np.zeros(rows + 1, itype)
    indices, data = np.empty(nnz, itype), np.empty(nnz)
    r = p = 0
    for k in range(len(blocks)):
        m = blocks[k]
        indptr[r + 1 : r + m.shape[0] + 1] = m.indptr[1:] + p
        indices[p : p + m.nnz] = m.indices
        data[p : p + m.nnz] = m.data
        r, p = r + m.shape[0], p + m.nnz
        blocks[k] = m = None
        release_freed_memory()
    out = sp.csr_matrix((data, indices, indptr), shape=shape)
    out.has_sorted_indices = True
    return out


def chunked_stiffness(
    particles: ParticleSet,
    mls: MLS | HaloMLS,
    material: LinearElastic,
    quadrature_degree: int,
    consistent: bool,
    chunk_points: int,
    quadrature: QuadraturePoints | None = None,
) -> tuple[sp.csr_matrix, QuadraturePoints, dict]:
    """The EFG stiffness of this rank's integration cells (Belytschko et al. 1995, eq. (4.3)),
    tabulated and assembled ``chunk_points`` quadrature points at a time (collective).

    Equal to :func:`~dolfinx_meshfree.statics.efg.particle_stiffness` with
    ``consistent_boundary = (boundary_facets(mesh), None)`` when ``consistent`` (VCI over the
    whole mesh boundary), else with none, to round-off. Chunks are slices of the point list, so
    a chunk may end inside a cell. With VCI the chunks are tabulated twice: the sums
    ``sum_q N_I w_q`` and ``sum_q grad N_I w_q`` of the correction
    (:func:`~dolfinx_meshfree.physics.operators.consistent_gradients`) first, then the
    corrected gradients. The partial sums (merged like a binary counter: the chunks' stiffnesses
    in pairs, the pairs' sums in pairs, ...) are held in blocks of rows (:func:`row_blocks`),
    summed block by block and joined at the end, each input block freed once summed or copied:
    the peak is about one stiffness and one chunk's table, not two or three stiffnesses.

    Returns:
        ``(K, q, timings)``: K (gdim n x gdim n) CSR of this rank's contributions in PETSc
        numbering, the cell rule, and the seconds of ``tabulate`` and ``assemble``.
    """
    K, q, timings = _stiffness_blocks(
        particles, mls, material, quadrature_degree, consistent, chunk_points, quadrature
    )
    t0 = time.perf_counter()
    K = joined(K)
    timings["assemble"] += time.perf_counter() - t0
    return K, q, timings


def _stiffness_blocks(
    particles: ParticleSet,
    mls: MLS | HaloMLS,
    material: LinearElastic,
    quadrature_degree: int,
    consistent: bool,
    chunk_points: int,
    quadrature: QuadraturePoints | None = None,
    smoothing: float | None = None,
) -> tuple[list[sp.csr_matrix], QuadraturePoints, dict]:
    """:func:`chunked_stiffness` as :func:`row_blocks` (collective); ``smoothing``: the
    stabilisation of a smoothed integration (:func:`_smoothed_chunk`), ``None``: Gauss points
    (VCI when ``consistent``)."""
    comm = particles.comm
    gdim, n = particles.gdim, particles.num_particles
    cells = particles.integration_cells()
    if quadrature is None:
        quadrature = cell_quadrature(particles.mesh, quadrature_degree, cells)
    q = quadrature
    tab = asm = 0.0
    xi = None
    if consistent:
        t0 = time.perf_counter()
        bq = facet_quadrature(particles.mesh, boundary_facets(particles.mesh), quadrature_degree)
        tb = raise_on_all_ranks(comm, lambda: mls.tabulate(bq.points, derivatives=0))
        vol = np.zeros(n)
        rhs = np.asarray(tb.values.T @ (bq.weights[:, None] * bq.normals[:, :gdim]))
        for s in _chunks(len(q), chunk_points, comm):
            t = raise_on_all_ranks(comm, lambda s=s: mls.tabulate(q.points[s]))
            vol += t.values.T @ q.weights[s]
            for k in range(gdim):
                rhs[:, k] -= t.gradients[k].T @ q.weights[s]
        xi = vci_constants(vol, rhs, comm, particles.positions)
        tab += time.perf_counter() - t0
    stack: list[tuple[sp.csr_matrix, int]] = []  # partial sums, merged like a binary counter
    per_cell = max(len(q) // max(len(cells), 1), 1)
    chunks = (
        _chunks(len(q), chunk_points, comm)
        if smoothing is None
        else _chunks(len(cells), max(chunk_points // per_cell, 1), comm)
    )
    for s in chunks:
        t0 = time.perf_counter()
        if smoothing is None:
            t = raise_on_all_ranks(comm, lambda s=s: mls.tabulate(q.points[s]))
            test, trial, weights = t.gradients, t.gradients, q.weights[s]
            if xi is not None:  # grad^ N_I = grad N_I + xi_I N_I on the table's own pattern
                test = corrected_gradients(t.values, t.gradients, xi)
        else:  # the cells' smoothing domains, stabilised by their Gauss points
            t = None
            test, weights = raise_on_all_ranks(
                comm,
                lambda s=s: _smoothed_chunk(particles, mls, cells[s], quadrature_degree, smoothing),
            )
            trial = test
        t1 = time.perf_counter()
        Kc = stiffness_matrix(test, weights, material, trial, particles.petsc_index)
        del t, test, trial
        stack.append((row_blocks(Kc), 0))
        del Kc
        while len(stack) > 1 and stack[-1][1] == stack[-2][1]:
            (a, level), (b, _) = stack.pop(), stack.pop()
            stack.append((_blocks_sum(a, b), level + 1))
            del a, b
        tab += t1 - t0
        asm += time.perf_counter() - t1
    t1 = time.perf_counter()
    K = row_blocks(sp.csr_matrix((gdim * n, gdim * n)))
    while stack:
        K = _blocks_sum(K, stack.pop()[0])
    asm += time.perf_counter() - t1
    return K, q, {"tabulate": tab, "assemble": asm}


def _smoothed_chunk(
    particles: ParticleSet,
    mls: MLS | HaloMLS,
    cells: np.ndarray,
    degree: int,
    stabilisation: float,
) -> tuple[list[sp.csr_matrix], np.ndarray]:
    """The stiffness rows and weights of the smoothed integration of ``cells`` (local; see
    :func:`~dolfinx_meshfree.geometry.smoothing.stiffness_rows`): a chunk of cells whose
    smoothing domains and Gauss points stay inside it."""
    rule = smoothing_rule(particles.mesh, cells, degree, stabilisation)
    return stiffness_rows(mls, rule, smoothed_table(mls, rule))


def nitsche_terms(
    particles: ParticleSet,
    mls: MLS | HaloMLS,
    material: LinearElastic,
    conditions: list[tuple[np.ndarray, Any, tuple[int, ...]]],
    quadrature_degree: int,
    beta: float,
) -> tuple[sp.csr_matrix, np.ndarray]:
    """Nitsche's terms of ``u_i = ubar_i`` on facets (module docstring), this rank's facets.

    Args:
        conditions: ``(facets, ubar, components)`` as
            :meth:`~dolfinx_meshfree.EFGElasticity.add_dirichlet` stores them.

    Returns:
        ``(N, f)``: (gdim n x gdim n) CSR in PETSc dof numbering and (gdim n,) load in the
        particles' interleaved numbering (``gdim I + i``), to add to the stiffness and the load.
    """
    gdim, n = particles.gdim, particles.num_particles
    A = voigt_tangent(material.voigt(), gdim)  # A[d i + a, d k + b]
    dofs = (gdim * particles.petsc_index[:, None] + np.arange(gdim)).T  # (gdim, n), PETSc
    rows, cols, vals = [], [], []
    f = np.zeros(gdim * n)
    comm = particles.comm
    for facets, ubar, comps in conditions:
        bq = facet_quadrature(particles.mesh, facets, quadrature_degree)
        tb = raise_on_all_ranks(comm, lambda bq=bq: mls.tabulate(bq.points))  # (collective)
        ub = vector_values(ubar, (bq.points,), len(bq), "the Dirichlet value", gdim)
        length = np.bincount(bq.entities, weights=bq.weights)[bq.entities]
        w = bq.weights
        alpha = beta * material.E / length
        nrm = bq.normals[:, :gdim]
        V = tb.values.tocsr()
        # T[i][k]: traction component i of the shape functions of component k, (nb x n)
        T = [
            [
                sum(
                    sp.diags(nrm @ A[gdim * i : gdim * i + gdim, gdim * k + b]) @ tb.gradients[b]
                    for b in range(gdim)
                ).tocsr()
                for k in range(gdim)
            ]
            for i in range(gdim)
        ]
        blocks = {}
        Wv = sp.diags(w) @ V
        for i in comps:
            for k in range(gdim):
                blocks[(i, k)] = blocks.get((i, k), 0) - Wv.T @ T[i][k]
                blocks[(k, i)] = blocks.get((k, i), 0) - T[i][k].T @ Wv
            blocks[(i, i)] = blocks[(i, i)] + (sp.diags(w * alpha) @ V).T @ V
            f_i = np.zeros((n, gdim))
            f_i[:, i] += V.T @ (w * alpha * ub[:, i])
            for k in range(gdim):
                f_i[:, k] -= T[i][k].T @ (w * ub[:, i])
            f += f_i.ravel()
        for (i, k), M in blocks.items():
            M = sp.coo_matrix(M)
            rows.append(dofs[i][M.row])
            cols.append(dofs[k][M.col])
            vals.append(M.data)
    cat = lambda parts, t: np.concatenate(parts).astype(t) if parts else np.zeros(0, t)  # noqa: E731
    N = sp.csr_matrix(
        (cat(vals, float), (cat(rows, np.int64), cat(cols, np.int64))), shape=(gdim * n, gdim * n)
    )
    return N, f


def _rigid_modes(particles: ParticleSet, A: PETSc.Mat) -> tuple[PETSc.NullSpace, list]:
    """The rigid-body modes on the owned dofs (2D: two translations and a rotation; 3D: three
    and three), orthonormalised: GAMG's near-nullspace."""
    gdim = particles.gdim
    inv = np.empty_like(particles.petsc_index)
    inv[particles.petsc_index] = np.arange(particles.num_particles)
    start, end = A.getOwnershipRange()
    x = particles.positions[inv[start // gdim : end // gdim], :gdim]
    template = A.createVecLeft()
    try:
        return rigid_body_modes(x, template)
    finally:
        template.destroy()


def _krylov(A: PETSc.Mat, b: PETSc.Vec, particles, options: IterativeOptions, symmetric: bool):
    """The KSP solve of :func:`solve_large`; returns ``(x, iterations)``."""
    prefix = options.prefix or f"dolfinx_meshfree_large_{next(_prefix_counter)}_"
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setType(options.ksp_type or ("cg" if symmetric else "gmres"))
    if ksp.getType() in ("gmres", "fgmres"):
        ksp.setGMRESRestart(200)
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=options.rtol, atol=options.atol, max_it=options.max_it)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.GAMG)
    nullspace, vecs = _rigid_modes(particles, A)
    A.setNearNullSpace(nullspace)
    with scoped_options(prefix, options.petsc_options):
        ksp.setFromOptions()
        x = A.createVecRight()
        ksp.solve(b, x)
        reason, its = ksp.getConvergedReason(), ksp.getIterationNumber()
    for obj in (pc, ksp, nullspace, *vecs):
        obj.destroy()
    if reason < 0:
        raise RuntimeError(
            f"the {options.ksp_type or ('cg' if symmetric else 'gmres')} + GAMG solve did not "
            f"converge (KSP reason {reason}, {its} iterations); raise max_it or use direct=True"
        )
    return x, its


def solve_large(problem: EFGElasticity, options: IterativeOptions | None = None) -> EFGSolution:
    """Solve a linear pure-EFG problem with chunked assembly, Nitsche's conditions and an
    iterative (or, ``direct=True``, MUMPS) solve (module docstring; collective).

    The problem's Dirichlet conditions, tractions and body force are used as given; cracks and
    finite-strain materials are not supported (use :meth:`EFGElasticity.solve`).

    Returns:
        The :class:`~dolfinx_meshfree.statics.efg.EFGSolution` (no multipliers); its
        ``timings`` hold the seconds of ``halo`` (finding this rank's halo and building its MLS),
        ``tabulate``, ``assemble``, ``matrix`` (the PETSc copy) and ``solve``, this rank's
        ``halo_particles`` (all of them with ``halo=False``), the ``iterations`` (0 for the
        direct solve), the matrix's ``nonzeros`` and this rank's ``peak_rss_mb`` after each
        phase (:func:`peak_rss_mb`) and ``cpu`` seconds of each phase (``process_time``: on a
        shared machine, the work without the waiting for a core).
    """
    options = options or IterativeOptions()
    comm = problem.comm

    def check() -> None:
        options.check()
        if problem.cracks or not isinstance(problem.material, LinearElastic):
            raise ValueError(
                "solve_large supports linear materials without cracks; use EFGElasticity.solve"
            )

    raise_on_all_ranks(comm, check)
    c0 = time.process_time()
    P = problem.particles
    gdim = P.gdim
    deg = problem.quadrature_degree
    mat = problem.linear_material
    t0 = time.perf_counter()
    mls = problem.mls
    if options.halo:
        mls = raise_on_all_ranks(comm, lambda: _halo(problem, problem.consistent))
    halo_time = time.perf_counter() - t0
    beta = STABILISATION.get(problem.integration)
    K, q, timings = _stiffness_blocks(
        P, mls, mat, deg, problem.consistent, options.chunk_points, smoothing=beta
    )
    timings["halo"] = halo_time
    timings["halo_particles"] = len(mls.indices) if options.halo else P.num_particles
    peak = {"assemble": peak_rss_mb()}
    cpu = {"assemble": time.process_time() - c0}
    c0 = time.process_time()
    t0 = time.perf_counter()
    conds = problem._dirichlet
    N, f_loc = nitsche_terms(P, mls, mat, conds, deg, options.nitsche)
    K = joined(_blocks_sum(K, row_blocks(N)))
    del N
    for facets, fn in problem._tractions:
        fq = facet_quadrature(problem.mesh, facets, deg)
        t = vector_values(fn, (fq.points, fq.normals), len(fq), "traction", gdim)
        f_loc += load_vector(mls.tabulate(fq.points, 0).values, fq.weights, t)
    if problem._body is not None:
        for s in _chunks(len(q), options.chunk_points):
            b = vector_values(problem._body, (q.points[s],), s.stop - s.start, "body force", gdim)
            vals = mls.tabulate(q.points[s], 0).values
            f_loc += load_vector(vals, q.weights[s], b)
    del q, mls
    udofs = P.dof_layout(gdim)
    A = create_aij(comm, K, udofs, udofs, block_size=gdim)
    del K
    release_freed_memory()
    b = create_vector(comm, udofs, P.petsc_dofs(gdim).ravel(), f_loc)
    timings["matrix"] = time.perf_counter() - t0
    timings["nonzeros"] = int(A.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"])
    peak["matrix"] = peak_rss_mb()
    cpu["matrix"] = time.process_time() - c0
    c0 = time.process_time()
    t0 = time.perf_counter()
    if options.direct:
        x, its = solve_lu(A, b), 0
    else:
        x, its = _krylov(A, b, P, options, symmetric=not problem.consistent)
    timings["solve"] = time.perf_counter() - t0
    timings["iterations"] = its
    peak["solve"] = peak_rss_mb()
    cpu["solve"] = time.process_time() - c0
    timings["peak_rss_mb"] = peak
    timings["cpu"] = cpu
    owned = np.concatenate(comm.allgather(x.getArray(readonly=True).copy()))
    for obj in (A, b, x):
        obj.destroy()
    return EFGSolution(
        mls=problem.mls,
        coefficients=owned.reshape(-1, gdim)[P.petsc_index],
        multipliers=np.zeros(0),
        timings=timings,
        material=mat,
    )


def chunked_l2_error(
    solution: EFGSolution,
    exact: Any,
    msh: Any,
    degree: int = 4,
    chunk_points: int = 1 << 17,
    cells: np.ndarray | None = None,
) -> tuple[float, float]:
    """``(|u_h - u|_L2, |u|_L2)`` over this rank's cells (default all owned), summed over the
    ranks (collective), with ``exact(x)`` (m, gdim) and a Gauss rule of ``degree``, the
    solution evaluated ``chunk_points`` points at a time."""
    if cells is None:
        cells = np.arange(msh.topology.index_map(msh.topology.dim).size_local)
    q = cell_quadrature(msh, degree, cells)
    gdim = solution.coefficients.shape[1]
    err = ref = 0.0
    for s in _chunks(len(q), chunk_points):
        u = exact(q.points[s, :gdim])
        e = solution.displacement(q.points[s]) - u
        err += float(q.weights[s] @ np.sum(e * e, axis=1))
        ref += float(q.weights[s] @ np.sum(u * u, axis=1))
    err, ref = msh.comm.allreduce(np.array([err, ref]), op=MPI.SUM)
    return float(np.sqrt(err)), float(np.sqrt(ref))
