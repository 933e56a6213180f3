"""External loads of explicit dynamics: tractions and body forces with time amplitudes.

Each load is a vector per field and an amplitude ``a(t)``: the force at ``t`` is
``a(t) f`` (Belytschko et al. 1995, eq. 4.5). Tractions are assembled with the FE basis on
facets of FE cells, the particles' functions on facets of particle cells and the blended
functions on the ramps' interface cells and bridging's band; body forces with
the functions and weights of the masses (:mod:`~dolfinx_meshfree.physics.body_loads`), else lumped.
Particle forces of master–slave reach the FE nodes and masters through ``T^T`` (Rabczuk et
al. 2006, eq. 28). Fixed dofs carry no load.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from ..approx.fe_points import tabulate_in_cells
from ..geometry.cut_cells import cut_facet_quadrature
from ..geometry.quadrature import DYNAMIC_FACET_DEGREE, QuadraturePoints, facet_quadrature
from ..parallel import raise_on_all_ranks
from ..physics.axisymmetry import revolved
from ..physics.operators import load_vector
from ..physics.user_functions import check_arguments, check_facets
from ..statics.petsc import create_vector
from .discretisation import Discretisation, VectorFunction, vector_values
from .linalg import row_layout
from .prescribed import HeldVelocity, PrescribedMotion

__all__ = ["Amplitude", "BodyLoad", "ExternalLoads"]

Amplitude = Callable[[float], float]
BodyLoad = Callable[[VectorFunction], tuple[np.ndarray | None, np.ndarray | None]]
Traction = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _one(t: float) -> float:
    return 1.0


class ExternalLoads:
    """The loads of a model: ``(vectors per field, amplitude)`` pairs.

    Args:
        disc: The model's spaces.
        free: bool per owned dof of each field: not held at rest (loads are zeroed elsewhere).
        comm: The communicator.
        rho: The density (lumped body loads ``M b / rho``).
        body_load: ``body_load(b) -> (fe, particles)``: the consistent loads of a body force
            ``b(x)`` per owned FE dof and per particle dof (original interleaved order, this
            rank's contributions), either ``None`` for a missing field; ``None``: lumped.
        held: ``(facets, components, velocity)``: FE nodes held at a prescribed velocity
            (:class:`~dolfinx_meshfree.dynamics.prescribed.PrescribedMotion`, :attr:`motion`;
            ``None`` without).
    """

    def __init__(
        self,
        disc: Discretisation,
        free: Sequence[np.ndarray],
        comm: MPI.Comm,
        rho: float,
        body_load: BodyLoad | None = None,
        held: Sequence[HeldVelocity] = (),
    ) -> None:
        self.disc, self.free, self.comm, self.rho = disc, list(free), comm, rho
        self.body_load = body_load
        self.motion = PrescribedMotion(disc, held, comm) if held else None
        self.loads: list[tuple[list[PETSc.Vec], Amplitude]] = []
        #: Body forces among :attr:`loads` (integrated with the cell rule, unlike tractions).
        self.body_forces = 0
        #: ``(b, amplitude)`` of each body force, for the SIFs' term ``-amplitude(t) b / rho``.
        self.body_fields: list[tuple[VectorFunction, Amplitude]] = []

    def at(self, t: float) -> list[tuple[list[PETSc.Vec], float]]:
        """The load vectors with their amplitudes at time ``t``."""
        return [(vecs, a(t)) for vecs, a in self.loads]

    def add_traction(
        self, facets: npt.ArrayLike, traction: Traction, amplitude: Amplitude | None = None
    ) -> None:
        """``amplitude(t) * traction(x, n)`` on owned exterior facets (collective).

        ``traction`` maps points (m, gdim) and outward normals (m, gdim) to tractions (m, gdim),
        assembled with the FE basis on facets of FE cells, with the MLS functions on facets of
        particle cells (Belytschko et al. 1995, eq. 4.5), split at a crack's mouth (each side
        on its own, :func:`~dolfinx_meshfree.geometry.cut_cells.cut_facet_quadrature`), and
        with the blended functions on facets of the ramps' interface cells (eq. 3.15) and of
        bridging's band (``(1 - alpha) N`` and ``alpha phi``, Rabczuk et al. 2006, eq. 49), as
        the masses and the stiffness use them. ``amplitude`` defaults to 1 (a step load).
        """
        check_arguments(traction, 2, "traction")
        d = self.disc
        msh, gdim = d.mesh, d.gdim
        deg = DYNAMIC_FACET_DEGREE
        facets = check_facets(msh, facets, "add_traction: facets")
        msh.topology.create_connectivity(msh.topology.dim - 1, msh.topology.dim)
        f2c = msh.topology.connectivity(msh.topology.dim - 1, msh.topology.dim)
        first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
        blended = d.blended_cells()
        mixed = blended[first] if blended is not None else np.zeros(facets.size, dtype=bool)
        on_p = d.on_particles(first)
        fe_dofs = None
        if d.V is not None:
            imap = d.V.dofmap.index_map
            l2g = np.asarray(
                imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
            )
            fe_dofs = (gdim * l2g[:, None] + np.arange(gdim)).ravel()

        def values(q: QuadraturePoints) -> np.ndarray:
            return raise_on_all_ranks(
                self.comm, lambda: vector_values(traction, q.points, q.normals, name="traction")
            )

        def surface(q: QuadraturePoints) -> QuadraturePoints:  # 2 pi r ds in axisymmetry
            return raise_on_all_ranks(self.comm, lambda: revolved(q)) if d.axisymmetric else q

        def fe_load(
            tab: sp.spmatrix, q: QuadraturePoints, t: np.ndarray
        ) -> tuple[np.ndarray, np.ndarray]:
            fl = load_vector(tab, q.weights, t)
            return fe_dofs[: fl.size], fl

        blend_fe = blend_p = None
        if blended is not None:  # collective: every rank tabulates (maybe no point)
            q = surface(facet_quadrature(msh, facets[mixed], deg))
            t = values(q)
            fe_tab, p_tab = d.blended_tables(q.points, q.cells, self.comm)
            blend_fe = fe_load(fe_tab, q, t)
            blend_p = load_vector(p_tab, q.weights, t)
        parts = []
        for f in d.fields:
            if f.name == "fe":
                q = surface(facet_quadrature(msh, facets[~on_p & ~mixed], deg))
                tab = tabulate_in_cells(d.V, q.points, q.cells, derivatives=0).values
                rows, vals = fe_load(tab, q, values(q))
                if blend_fe is not None:
                    rows, vals = (
                        np.concatenate([rows, blend_fe[0]]),
                        np.concatenate([vals, blend_fe[1]]),
                    )
                parts.append((rows, vals))
            else:
                sel = facets[on_p & ~mixed]
                if d.cracks:  # facets split at the cracks' mouths
                    q = cut_facet_quadrature(msh, sel, d.cracks, deg)
                else:
                    q = facet_quadrature(msh, sel, deg)
                q = surface(q)
                t = values(q)
                tab = raise_on_all_ranks(self.comm, lambda q=q: d.mls.tabulate(q.points, 0))
                vals = load_vector(tab.values, q.weights, t)
                if blend_p is not None:
                    vals = vals + blend_p
                parts.append((d.particles.petsc_dofs(gdim).ravel(), vals))
        self._add(parts, amplitude)

    def add_body_force(self, force: VectorFunction, amplitude: Amplitude | None = None) -> None:
        """``amplitude(t) * int b . v`` of a body force ``b(x)`` per unit volume (points
        (m, gdim) -> (m, gdim)) on the whole body (collective).

        FE, EFG and every coupling integrate it with the functions and weights of their masses
        and stiffness (``body_load``, :mod:`~dolfinx_meshfree.physics.body_loads`: ramp interface
        cells
        blended, eq. 3.15 of Belytschko et al. 1995; bridging band weighted by ``1 - alpha`` and
        ``alpha``, Rabczuk et al. 2006, eq. 49; master-slave through ``T^T``, eq. 28); other
        models take the lumped load ``M b(x_I) / rho`` at their nodes and particles, exact for
        a constant ``b``. ``amplitude`` defaults to 1 (a step load).
        """
        d = self.disc
        self.body_forces += 1
        self.body_fields.append((force, _one if amplitude is None else amplitude))
        if self.body_load is not None:
            fe, f_p = self.body_load(force)
            parts = []
            for f in d.fields:
                if f.name == "fe":
                    lo, hi = f.mass.getOwnershipRange()
                    parts.append((np.arange(lo, hi), fe))
                else:
                    parts.append((d.particles.petsc_dofs(d.gdim).ravel(), f_p))
            self._add(parts, amplitude)
            return
        vecs = []
        for k, f in enumerate(d.fields):
            x = d.owned_points(k)
            b = raise_on_all_ranks(
                self.comm, lambda x=x: vector_values(force, x, name="the body force")
            )
            vec = f.mass.duplicate()
            vec.array[:] = f.mass.array_r * b.ravel() / self.rho
            vecs.append(vec)
        self._add_vectors(vecs, amplitude)

    def body_acceleration(self, t: float, x: np.ndarray) -> np.ndarray | None:
        """``sum amplitude(t) b(x) / rho`` of the body forces at points ``x`` (m, gdim), the
        acceleration they would give a free body; ``None`` without body forces (collective
        when a ``b`` is: a DOLFINx Function evaluated at points)."""
        if not self.body_fields:
            return None
        out = np.zeros((len(x), self.disc.gdim))
        for force, amplitude in self.body_fields:
            b = raise_on_all_ranks(
                self.comm, lambda f=force: vector_values(f, x, name="the body force")
            )
            out += amplitude(t) * b.reshape(len(x), -1) / self.rho
        return out

    def _add(self, parts: list, amplitude: Amplitude | None) -> None:
        """Add a load given per field as ``(global dofs, values)`` (any rank may add any dof; a
        master-slave particle field's values are reduced to the FE nodes and masters by
        ``T^T``, eq. 28). Collective."""
        d = self.disc
        vecs: list[PETSc.Vec] = []
        for f, (rows, vals) in zip(d.fields, parts, strict=True):
            if d.reduction is not None and f.name == "particles":
                # master-slave: particle forces reach the masters through T^T (eq. 28)
                Tpf, S = d.reduction
                full = create_vector(self.comm, row_layout(S), rows, vals)
                b = S.createVecRight()
                S.multTranspose(full, b)
                Tpf.multTransposeAdd(full, vecs[0], vecs[0])
                full.destroy()
                vecs.append(b)
                continue
            b = f.mass.duplicate()
            b.set(0.0)
            b.setValues(rows.astype(PETSc.IntType), vals, addv=PETSc.InsertMode.ADD_VALUES)
            b.assemblyBegin()
            b.assemblyEnd()
            vecs.append(b)
        self._add_vectors(vecs, amplitude)

    def _add_vectors(self, vecs: list[PETSc.Vec], amplitude: Amplitude | None) -> None:
        for k, b in enumerate(vecs):  # no load on fixed dofs
            b.array[:] = b.array_r * self.free[k]
        self.loads.append((vecs, amplitude if amplitude is not None else _one))

    def destroy(self) -> None:
        """Destroy the load vectors (collective)."""
        for vecs, _ in self.loads:
            for b in vecs:
                if b is not None:
                    b.destroy()
        self.loads = []
