"""A particle patch in an existing DOLFINx model: :class:`CoupledLinearProblem`.

The user keeps the UFL forms ``a`` and ``L``, the ``DirichletBC`` list and the mesh tags of a model
written for ``dolfinx.fem.petsc.LinearProblem``, names cells to replace by particles
(:class:`~dolfinx_meshfree.ParticlePatch`), gives the particle side's constitutive law
(:class:`~dolfinx_meshfree.LinearElastic`) and picks a coupling. How each piece reaches the
coupled system (:class:`~dolfinx_meshfree.CoupledElasticity`):

* ``a``: every cell integral is multiplied by the coupling's FE weight (a DG0 indicator of the FE
  cells, ``1 - alpha`` in a bridging band: Rabczuk et al. 2006, eq. 47-48) and assembled by
  DOLFINx, so the user's measures, tags, coefficients and quadrature metadata are kept on the FE
  side. On the patch cells, ``a`` must equal the material's elasticity form; they are compared
  by assembling both there (relative Frobenius difference below 1e-8), and a disagreement is
  reported with the likely cause (plane stress against plane strain, or a scaled modulus).
* ``L``: cell integrals (body loads, :class:`FormBodyForce`) are weighted like ``a`` on the FE
  side and integrated against the particle shape functions on the patch cells, with every
  coupling's own functions and weights (ramp interface cells: the blended functions; bridging
  band: ``1 - alpha`` and ``alpha``, eq. 49; see :mod:`~dolfinx_meshfree.physics.body_loads`);
  exterior-facet integrals (tractions, pressures with ``FacetNormal``) become tractions
  ``t(x, n)`` evaluated from the UFL integrand with a DOLFINx ``Expression`` at the facet
  Gauss points, so they reach the FE nodes or the particles of whichever side the facet
  belongs to. A cell integral may hold ``grad(v)``: a thermal, initial or residual stress
  ``inner(S, grad(v)) dx``, integrated by each side with the test gradients of its own
  stiffness (:mod:`~dolfinx_meshfree.statics.form_loads`), so that free thermal expansion is
  exact.
* ``bcs``: dofs of FE cells are fixed strongly (``MatZeroRowsColumns``), with the bc's values;
  exterior facets of patch cells whose nodes are all constrained become particle constraints
  with the bc's P1 interpolant as the prescribed value (Lagrange multipliers, as in
  :func:`~dolfinx_meshfree.statics.efg.facet_multipliers`).

An axisymmetric ``material`` (``plane="axisymmetric"``, coupling ``lagrange``) takes forms that
carry their own ``2 pi r`` (:mod:`~dolfinx_meshfree.physics.axisymmetry`): the loads taken from
``L`` are divided by it at their points, since the particle rules are revolved already.

* ``a``'s exterior-facet integrals (elastic supports, springs, Robin conditions
  ``k inner(u, v) ds``) are assembled with its cell integrals on the FE side: they may run over
  exterior facets of FE cells only (not of patch cells, nor of a ramp's interface cells: there
  the displacement is the particles', :mod:`~dolfinx_meshfree.statics.facet_terms`).

Not supported (each raises a ``ValueError`` naming the fix): interior-facet integrals in ``a``
and ``L``, ``ds`` integrals of ``a`` on the patch's facets or with a law with state,
derivatives of the test function in ``L``'s ``ds`` integrals, second derivatives of it, ``grad(v)``
with a law with state or in an axisymmetric model, and constrained nodes strictly inside the
patch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import basix
import dolfinx
import numpy as np
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from ufl.corealg.traversal import unique_pre_traversal

from .. import _compat
from ..approx.fe_points import evaluate_fe_function
from ..couplings.base import facet_nodes, interface_node_flags, node_flags
from ..couplings.point_conditions import PointCondition, check_point_spacing
from ..geometry.crack import particle_spacing
from ..geometry.cut_cells import cut_facet_quadrature
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import (
    boundary_facets,
    facet_quadrature,
    reference_facet_points,
)
from ..parallel import raise_on_all_ranks
from ..physics.materials import LinearElastic, is_axisymmetric
from ..physics.state import check_not_rate_law, is_stateful
from .coupled import COUPLINGS, CoupledElasticity, CoupledSolution, material_stiffness_form
from .facet_terms import FacetTermCheck, integral_entities
from .form_loads import FormBodyForce, load_integrand_error, replace_test_function
from .kept_factor import KeptFactorisation
from .petsc import SolverOptions, solver_options

__all__ = ["CoupledLinearProblem", "point_conditions", "short_stretches"]

#: Relative Frobenius difference above which the form and the material disagree on the patch.
MATERIAL_TOLERANCE = 1e-8


class CoupledLinearProblem:
    """``a(u, v) = L(v)`` with ``bcs`` on a mesh whose ``patch`` cells are particles.

    Mirrors ``dolfinx.fem.petsc.LinearProblem`` (``problem.solve()``), for linear elasticity on a
    vector P1/Q1 space in 2D or 3D (the couplings of 3D: ``lagrange``, ``edge-to-edge``,
    ``bridging``).

    Args:
        a: Bilinear UFL form on the vector P1/Q1 space ``V``: cell integrals, and exterior-facet
            integrals (an elastic support ``k inner(u, v) ds(i)``) on FE cells' facets.
        L: Linear UFL form on ``V`` (cell and exterior-facet integrals).
        bcs: ``DirichletBC`` objects on ``V`` (all components) or on ``V.sub(i)`` (one
            component, e.g. a symmetry plane or a roller; every coupling,
            :data:`COMPONENT_COUPLINGS`): FE dofs held strongly, patch facets whose nodes all
            hold the component get a multiplier on that component only.
        patch: :class:`~dolfinx_meshfree.ParticlePatch` on ``V``'s mesh.
        material: :class:`~dolfinx_meshfree.LinearElastic` of the particle side; must agree with
            ``a`` on the patch cells. Or a law with state (:class:`~dolfinx_meshfree.RankineDamage`,
            :class:`~dolfinx_meshfree.J2Plasticity`): then it is the law of every cell, FE cells
            included, ``a`` must be its elastic form on every cell (checked), and
            :meth:`solve` runs Newton in one load step from where the last solve ended (its
            displacement, state and loads) to the current ``L`` and ``bcs``: a load sweep by
            ``Constant`` objects follows the path, unloading included (:meth:`reset` starts
            again unloaded); past a peak, follow the path:
            ``mf.follow_path(problem.model, control, options)`` (from the unloaded state: on
            a model that has not yielded or softened yet, or after :meth:`reset`).
        coupling: One of :data:`~dolfinx_meshfree.COUPLINGS`.
        petsc_options: PETSc options of the linear solver (a KSP on the assembled block system),
            as ``dolfinx.fem.petsc.LinearProblem`` takes them; default (``None``): MUMPS LU
            tuned for saddle points (see :meth:`solve` for the shorthands). The nest's fields
            are named ``fe``, ``particles``, ``multiplier0``, ... for ``pc_type: fieldsplit``.
        petsc_options_prefix: The KSP's options prefix (default: a unique one). The options
            are removed from PETSc's database after each solve.
        **options: Passed to :class:`~dolfinx_meshfree.CoupledElasticity` (``weight``,
            ``dilation``, ``basis``, ``quadrature_degree``, ``consistent`` (default: VCI for
            every variational coupling, plain Gauss for master-slave), ``overlap``,
            ``penalty``, ``constraint`` (default ``"integral"``), ``band_width``).

    Example::

        problem = mf.CoupledLinearProblem(a, L, bcs, mf.ParticlePatch(mesh, cells, spacing=h),
                                          material=mf.LinearElastic(E=E, nu=nu, plane="strain"),
                                          coupling="lagrange")
        solution = problem.solve()
        u = solution.displacement(points)  # (m, gdim), on every rank
    """

    def __init__(
        self,
        a: ufl.Form,
        L: ufl.Form,
        bcs: Sequence | None,
        patch: ParticlePatch,
        material: LinearElastic,
        coupling: str = "lagrange",
        petsc_options: Mapping[str, Any] | None = None,
        petsc_options_prefix: str | None = None,
        **options,
    ):
        comm = patch.comm if isinstance(patch, ParticlePatch) else MPI.COMM_WORLD
        bcs = [] if bcs is None else list(bcs)
        V = raise_on_all_ranks(
            comm, lambda: _check_arguments(a, L, bcs, patch, material, coupling, options)
        )
        # elastic supports (k u.v ds) on the FE side's facets only (collective, then local)
        raise_on_all_ranks(comm, FacetTermCheck(a, patch, coupling, "a").check)
        self._solver = raise_on_all_ranks(
            comm, lambda: solver_options("mumps", petsc_options, petsc_options_prefix)
        )
        self.a, self.L, self.bcs = a, L, bcs
        self.coupling, self._options = coupling, dict(options)
        self._petsc = (petsc_options, petsc_options_prefix)
        self.problem = CoupledElasticity(V, patch, material, coupling, **options)
        self.problem.form = a
        self.problem._problem = self  # the problem that made it (coupled.on_patch)
        self.V, self.patch, self.material = V, patch, material
        _check_material(self.problem, everywhere=is_stateful(material))
        self._bc_entries: dict[str, list] = {}
        self._facet_loads: list[_FacetLoad] = []
        self._apply_bcs()
        self._apply_loads()
        self._seen = self._values()

    # -- what the user may change between solves ----------------------------------------------

    def _values(self) -> list[np.ndarray]:
        """This rank's values of ``a``'s and ``L``'s coefficients and constants, and of the
        ``bcs``: what DOLFINx's ``LinearProblem`` reads afresh at every solve."""
        bcs = [_compat.dirichlet_values(bc)[1] for bc in self.bcs]
        return [_form_values(self.a), _form_values(self.L), _concatenate(bcs)]

    def _refresh(self) -> None:
        """Take up what the user changed since the last solve (collective): a ``Constant`` or
        ``Function`` of ``L`` (the tractions are tabulated again), of ``bcs`` (the conditions
        rebuilt) or of ``a`` (checked against the material again: the particle side keeps the
        ``material`` it was given)."""
        now = self._values()
        changed = np.array(
            [not np.array_equal(x, y) for x, y in zip(now, self._seen, strict=True)], int
        )
        self.patch.comm.Allreduce(MPI.IN_PLACE, changed, op=MPI.MAX)
        if changed[0]:
            _check_material(self.problem, everywhere=is_stateful(self.material), changed=True)
        if changed[1]:
            for load in self._facet_loads:
                load.refresh()
        if changed[2]:
            for name, entries in self._bc_entries.items():
                kept = [e for e in getattr(self.problem, name) if not _among(e, entries)]
                getattr(self.problem, name)[:] = kept
            self._apply_bcs()
        self._seen = now

    # -- essential conditions -----------------------------------------------------------------

    def _apply_bcs(self) -> None:
        """Strong FE conditions by node; particle constraints on fully constrained patch facets
        (the entries it adds to the model are recorded, to be replaced when the values change)."""
        problem, V, patch = self.problem, self.V, self.patch
        names = ("strong", "dirichlet", "component_dirichlet", "point_dirichlet")
        before = {name: list(getattr(problem, name)) for name in names}
        self._apply_bcs_now(problem, V, patch)
        self._bc_entries = {
            name: [e for e in getattr(problem, name) if not _among(e, before[name])]
            for name in names
        }

    def _apply_bcs_now(
        self, problem: CoupledElasticity, V: dolfinx.fem.FunctionSpace, patch: ParticlePatch
    ) -> None:
        n_local = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
        gdim = V.mesh.geometry.dim
        count = np.zeros((n_local, gdim), dtype=int)
        values = np.zeros((n_local, gdim))
        for bc in self.bcs:
            dofs, vals = _compat.dirichlet_values(bc)
            count.ravel()[dofs] += 1
            values.ravel()[dofs] = vals
        fixed = count.all(axis=1)
        held = count.astype(bool) & ~fixed[:, None]  # dofs held by component (V.sub(i))
        problem.strong.append((fixed, values))
        if patch.comm.allreduce(int(held.any()), op=MPI.MAX):
            problem.strong.append((held, values))
        # exterior facets whose nodes are all constrained, of patch cells (they constrain the
        # particles) and of FE cells with a node on the interface (the nodes are fixed strongly
        # anyway; the ramp's interface cells constrain the particle part of their blended
        # functions there: without it a quadratic field missed by 2.5x the FE error on a patch
        # reaching the boundary)
        msh = V.mesh
        facets = boundary_facets(msh)
        nodes = facet_nodes(V, facets)
        fdim = msh.topology.dim - 1
        gamma = interface_node_flags(V, patch)
        f2c = msh.topology.connectivity(fdim, fdim + 1)
        beside_patch = patch.in_patch[np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]]
        on = fixed[nodes].all(axis=1) & (beside_patch | gamma[nodes].any(axis=1))
        # a held stretch of fewer than gdim facets with a node only particles carry: its
        # multipliers (one per facet) hold its mean, not its rotation; held at its nodes instead
        # (before, a corner held with its neighbour was free to rotate, without a word)
        active = node_flags(problem.V, _compat.dofmap_array(V)[patch.fe_cells].ravel())
        on &= ~short_stretches(V, nodes, on, active)
        bc_facets = facets[on]
        g = dolfinx.fem.Function(V)
        g.x.array[:] = values.ravel()
        g.x.scatter_forward()
        if patch.comm.allreduce(bc_facets.size):
            problem.add_dirichlet(bc_facets, lambda x, g=g: evaluate_fe_function(g, x))
        # patch facets whose nodes all hold component i (and are not fixed whole): a
        # multiplier on that component only (Belytschko et al. 1995, eq. 2.6 by component);
        # FE facets with a node on the interface too (the ramps' interface cells: the particle
        # part of their blended functions held by component there)
        covered = np.zeros((n_local, gdim), dtype=bool)  # dofs a held facet's multiplier holds
        for i in range(gdim):
            on_i = count[nodes, i].all(axis=1) & ~on & (beside_patch | gamma[nodes].any(axis=1))
            on_i &= ~short_stretches(V, nodes, on_i, active)
            covered[:, i] = node_flags(problem.V, nodes[on | on_i].ravel())
            if patch.comm.allreduce(int(on_i.sum())):
                problem.add_dirichlet(
                    facets[on_i], lambda x, g=g: evaluate_fe_function(g, x), components=(i,)
                )
        # held dofs that neither an FE cell nor a held patch facet of their component carries
        # (before, a node on a facet held in x lost its y: a pinned corner beside a roller)
        n_owned = V.dofmap.index_map.size_local
        particle_field = ~active
        if problem.coupling in ("ramp", "ramp-cubic"):
            # R = 1 on the interface: the field at its nodes is the particles' (Belytschko et
            # al. 1995, eq. 3.12), which their FE dof held does not hold (before, a node pinned
            # there held nothing: the field stayed where the load left it, silently)
            particle_field = particle_field | gamma
        lone = (fixed[:, None] | held) & particle_field[:, None] & ~covered
        lone[n_owned:] = False
        # nodes only patch cells carry, held alone (a pinned corner): collocated multipliers
        problem.point_dirichlet += point_conditions(V, patch, lone, values)

    # -- loads ----------------------------------------------------------------------------------

    def _apply_loads(self) -> None:
        """Exterior-facet integrals of ``L`` become tractions; its cell integrals one
        :class:`FormBodyForce`, whose shares every coupling takes with its own functions and
        weights (:mod:`~dolfinx_meshfree.physics.body_loads`)."""
        problem, V = self.problem, self.V
        msh = V.mesh
        v = self.L.arguments()[0]
        deg = problem.quadrature_degree
        # axisymmetric: the user's integrands carry their 2 pi r, which the couplings' rules
        # (revolved) must not count twice
        revolved = problem.material.axisymmetric
        cell_integrals = []
        for itg in self.L.integrals():
            if itg.integral_type() == "cell":
                cell_integrals.append(itg)
            else:
                facets = np.intersect1d(integral_entities(itg, msh), boundary_facets(msh))
                if not msh.comm.allreduce(facets.size):  # as DOLFINx: an integral over none
                    continue
                load = _FacetLoad(itg, v, facets, deg, self.patch.cracks, revolved)
                problem.add_traction(facets.astype(np.int32), load)
                self._facet_loads.append(load)
        if cell_integrals:
            problem.body_forces = [
                FormBodyForce(cell_integrals, v, deg, bool(self.patch.cracks), revolved)
            ]

    # -- solve ----------------------------------------------------------------------------------

    def solve(
        self,
        solver: str | SolverOptions | None = None,
        load_steps: int = 1,
        kept: KeptFactorisation | None = None,
    ) -> CoupledSolution:
        """Assemble and solve the coupled system (collective); see
        :meth:`~dolfinx_meshfree.CoupledElasticity.solve`. As DOLFINx's ``LinearProblem``, it
        reads the current values of the forms' and the conditions' ``Constant`` and
        ``Function`` objects (a load or displacement sweep); a changed ``a`` must still agree
        with the particle side's ``material`` (refused otherwise: build a new problem with the
        new law).

        Args:
            solver: A shorthand, ``"mumps"``, ``"fieldsplit"`` or ``"iterative"``, or a
                :class:`~dolfinx_meshfree.statics.petsc.SolverOptions`, instead of the
                constructor's ``petsc_options``; default: those options, or ``"mumps"``
                without them.
            load_steps: A law with state: Newton's steps from the loads the last solve reached
                to the current ones (a large increment of plastic flow in smaller ones);
                ignored by a linear law.
            kept: A :class:`~dolfinx_meshfree.KeptFactorisation` the caller owns (and
                destroys after the sweep): a solve whose assembled matrix has the values of
                the last one (only ``L`` or the loads' constants changed) is not factorised
                again (:meth:`~dolfinx_meshfree.CoupledElasticity.solve`).
        """
        self._refresh()
        options = self._solver if solver is None else solver
        return self.problem.solve(options, load_steps=load_steps, kept=kept)

    def reset(self) -> None:
        """A law with state: forget the path, so that the next :meth:`solve` starts from the
        unloaded, virgin state (:meth:`~dolfinx_meshfree.CoupledElasticity.reset`)."""
        self.problem.reset()

    def with_patch(self, patch: ParticlePatch) -> CoupledLinearProblem:
        """The same model (forms, conditions, material, coupling, options, solver) on another
        patch of the same mesh (collective): what a patch that grows during a run rebuilds
        (:class:`~dolfinx_meshfree.QuasiStaticCrackGrowth` with ``adapt``). The patch's cracks
        are the ones it was given (``patch.add_crack``)."""
        options, prefix = self._petsc
        new = CoupledLinearProblem(
            self.a, self.L, self.bcs, patch, self.material, self.coupling, options, prefix,
            **self._options,
        )  # fmt: skip
        new.problem.slaves = self.problem.slaves  # set on the model, not a constructor option
        return new

    @property
    def model(self) -> CoupledElasticity:
        """The coupled model: with a law with state, what :func:`~dolfinx_meshfree.follow_path`
        takes (``mf.follow_path(problem.model, control, options)``)."""
        return self.problem


# -- checks -------------------------------------------------------------------------------------


def _check_arguments(a, L, bcs, patch, material, coupling, options):
    """Validate the inputs (local; no collective call). Returns ``V``."""
    if not isinstance(patch, ParticlePatch):
        raise TypeError(f"patch must be a ParticlePatch, got {type(patch).__name__}")
    check_not_rate_law(material, "CoupledLinearProblem")
    if not isinstance(material, LinearElastic) and not is_stateful(material):
        raise TypeError(
            f"material must be a LinearElastic (the particle side's law) or a law with state "
            f"(RankineDamage, J2Plasticity: the law of every cell, a its elastic form), got "
            f"{type(material).__name__}"
        )
    if coupling not in COUPLINGS:
        raise ValueError(f"coupling={coupling!r} is not available; choose one of {list(COUPLINGS)}")
    for name, form, rank in (("a", a, 2), ("L", L, 1)):
        if not isinstance(form, ufl.Form):
            raise TypeError(f"{name} must be a UFL form, got {type(form).__name__}")
        if len(form.arguments()) != rank:
            raise ValueError(
                f"{name} must be a {'bilinear' if rank == 2 else 'linear'} form "
                f"(found {len(form.arguments())} argument(s))"
            )
    spaces = [arg.ufl_function_space() for arg in (*a.arguments(), *L.arguments())]
    V = spaces[0]
    if any(S is not V for S in spaces[1:]):
        raise ValueError("the test and trial functions of a and L must live on one space V")
    msh = V.mesh
    if msh is not patch.mesh:
        raise ValueError("the forms' space and the patch must live on the same mesh object")
    nv = _compat.geometry_dofmap(msh).shape[1]
    gdim = msh.geometry.dim
    if (
        msh.topology.dim not in (2, 3)
        or msh.topology.dim != gdim
        or V.dofmap.index_map_bs != gdim
        or _compat.dofmap_array(V).shape[1] != nv
    ):
        raise ValueError(
            "V must be the vector P1/Q1 space of a 2D or 3D mesh (e.g. "
            f"functionspace(mesh, ('Lagrange', 1, ({gdim},)))), got another space"
        )
    for itg in a.integrals():
        if itg.integral_type() not in ("cell", "exterior_facet"):
            raise ValueError(
                f"a has a {itg.integral_type()} integral; only cell integrals (dx) and "
                "exterior-facet integrals of the FE side (ds: elastic supports) are supported in "
                "the bilinear form of a coupled problem"
            )
        if itg.integral_type() == "exterior_facet" and is_stateful(material):
            raise ValueError(
                f"a has a ds integral (subdomain {itg.subdomain_id()!r}) and material="
                f"{type(material).__name__} is a law with state: Newton assembles every cell "
                "from the law, not from a, so the facet term would be lost; with a law with "
                "state, a may hold cell integrals only"
            )
    v = L.arguments()[0]
    for itg in L.integrals():
        if itg.integral_type() not in ("cell", "exterior_facet"):
            raise ValueError(
                f"L has a {itg.integral_type()} integral; only dx and ds integrals are supported"
            )
        kind = "dx" if itg.integral_type() == "cell" else itg.integral_type()
        where = f"L's {kind} integral (subdomain {itg.subdomain_id()!r})"
        if _differentiates(itg.integrand(), v):  # a stress S : grad(v), in dx only
            if itg.integral_type() != "cell":
                raise ValueError(
                    f"{where} differentiates the test function; on a boundary write the load "
                    "as a traction dot(t, v) ds (a stress inner(S, grad(v)) belongs in a dx "
                    "integral)"
                )
            reason = load_integrand_error(itg.integrand(), v)
            if reason is not None:
                raise ValueError(f"{where}: {reason}")
            if is_stateful(material):
                raise ValueError(
                    f"{where} holds grad(v) (a thermal or initial stress) and material="
                    f"{type(material).__name__} is a law with state: its return map takes the "
                    "stress from the total strain, so the stress S of L would not enter it (a "
                    "free thermal expansion would yield or damage); an initial stress is "
                    "supported with LinearElastic only"
                )
            if is_axisymmetric(material):
                raise ValueError(
                    f"{where} holds grad(v) and material is axisymmetric: an initial or thermal "
                    "stress in (r, z) needs the hoop term S_tt u_r / r, which the couplings' "
                    "load rules do not carry; only body forces dot(b, v) are supported in "
                    "axisymmetric models"
                )
        if itg.subdomain_id() == "otherwise":
            raise ValueError("L uses an 'otherwise' subdomain; name the subdomain ids instead")
    for i, bc in enumerate(bcs):
        if not hasattr(bc, "dof_indices") or not hasattr(bc, "g"):
            raise TypeError(f"bcs[{i}] must be a dolfinx.fem.DirichletBC, got {type(bc).__name__}")
        component = list(bc.function_space.component())
        if len(component) > 1:
            raise ValueError(
                f"bcs[{i}] constrains component {component} of a nested subspace; constrain "
                "V.sub(i) (one displacement component) or V"
            )
    return V


def _form_values(form: ufl.Form) -> np.ndarray:
    """The values of ``form``'s constants and coefficients on this rank, in one array."""
    values = [np.asarray(c.value, dtype=float).ravel() for c in form.constants()]
    values += [np.asarray(f.x.array).ravel() for f in form.coefficients()]
    return _concatenate(values)


def _concatenate(arrays: list[np.ndarray]) -> np.ndarray:
    return np.concatenate([np.asarray(x, dtype=float).ravel() for x in arrays] + [np.zeros(0)])


def short_stretches(
    V: dolfinx.fem.FunctionSpace, nodes: np.ndarray, held: np.ndarray, active: np.ndarray
) -> np.ndarray:
    """Flags of the ``held`` facets (rows of ``nodes``, local node indices) that lie in a
    connected stretch of fewer than ``gdim`` held facets (over every rank) and have a node that
    no FE cell carries (``active`` false): one piecewise-constant multiplier per facet and
    component holds a stretch's mean, and fewer than ``gdim`` of them leave it free to rotate
    (collective, the same answer on every partition)."""
    gdim = V.mesh.geometry.dim
    imap = V.dofmap.index_map
    local = np.asarray(nodes[held], dtype=np.int32).ravel()
    ids = np.asarray(imap.local_to_global(local), dtype=np.int64).reshape(-1, nodes.shape[1])
    ids = np.sort(ids, axis=1)
    every = np.concatenate(V.mesh.comm.allgather(ids))
    if not len(every):
        return np.zeros(len(nodes), dtype=bool)
    every = np.unique(every, axis=0)  # a facet seen by two ranks counts once
    uniq, inv = np.unique(every, return_inverse=True)
    inv = inv.reshape(every.shape)
    k = every.shape[1]
    graph = sp.coo_matrix(
        (np.ones(inv.size * k), (np.repeat(inv, k, axis=1).ravel(), np.tile(inv, (1, k)).ravel())),
        shape=(uniq.size, uniq.size),
    )
    label = connected_components(graph, directed=False)[1]
    size = np.bincount(label[inv[:, 0]])  # facets per stretch
    mine = size[label[np.searchsorted(uniq, ids[:, 0])]] < gdim if len(ids) else np.zeros(0, bool)
    out = np.zeros(len(nodes), dtype=bool)
    out[np.flatnonzero(held)] = mine & (~active[nodes[held]]).any(axis=1)
    return out


def point_conditions(
    V: dolfinx.fem.FunctionSpace,
    patch: ParticlePatch,
    lone: np.ndarray,
    values: np.ndarray,
) -> list[PointCondition]:
    """The :class:`~dolfinx_meshfree.couplings.point_conditions.PointCondition` of the held
    dofs flagged in ``lone`` (num local nodes, gdim), one per set of components held at a node,
    the same sets on every rank (collective; refused, on every rank, for points closer than a
    particle spacing)."""
    gdim = V.mesh.geometry.dim
    at = np.flatnonzero(lone.any(axis=1))
    comps = [tuple(int(i) for i in np.flatnonzero(lone[k])) for k in at]
    kinds = sorted(set().union(*patch.comm.allgather(set(comps))))
    if not kinds:
        return []
    x = V.tabulate_dof_coordinates()[at, :gdim]
    spacing = particle_spacing(patch)
    check_point_spacing(patch.comm, x, spacing)
    dm = _compat.dofmap_array(V)
    cells = np.flatnonzero(patch.in_patch[: len(dm)])
    cell_of = np.full(values.shape[0], -1, dtype=np.int32)
    cell_of[dm[cells].ravel()] = np.repeat(cells, dm.shape[1])
    out = []
    for kind in kinds:
        mine = np.array([c == kind for c in comps], dtype=bool)
        out.append(
            PointCondition(x[mine], values[at[mine]], cell_of[at[mine]], kind, spacing, at[mine])
        )
    return out


def _among(entry: object, entries: list) -> bool:
    """``entry`` is one of ``entries`` (by identity)."""
    return any(entry is e for e in entries)


def _check_material(
    problem: CoupledElasticity, everywhere: bool = False, changed: bool = False
) -> None:
    """Compare the user's form with the material's on the patch cells, or on every cell
    (``everywhere``: a law with state acts on the FE cells too, so the form must be its elastic
    law there as well) (collective). ``changed``: the form's values changed since the problem
    was built (the error says so)."""
    flags = np.ones_like(problem.patch.in_patch) if everywhere else problem.patch.in_patch
    chi = problem.cell_indicator(flags)
    material = problem.material
    where = (
        "on every cell (a law with state acts on the FE cells too)"
        if everywhere
        else ("on the patch cells")
    )

    def stiffness(form: ufl.Form) -> PETSc.Mat:
        return _compat.assemble_matrix(_compat.create_form(form))

    def material_form(m: LinearElastic) -> ufl.Form:
        return material_stiffness_form(m, problem.V, chi)  # axisymmetric: revolved, hoop

    A = stiffness(problem.fe_form(chi))
    B = stiffness(material_form(material))
    nb = B.norm(PETSc.NormType.FROBENIUS)

    def difference(M: PETSc.Mat, scale: float = 1.0) -> float:
        D = A.duplicate(copy=True)
        D.axpy(-scale, M, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        d = D.norm(PETSc.NormType.FROBENIUS)
        D.destroy()
        return d / max(M.norm(PETSc.NormType.FROBENIUS) * scale, 1e-300)

    rel = difference(B)
    if rel > MATERIAL_TOLERANCE:
        other = "strain" if material.plane == "stress" else "stress"
        C = None
        if material.plane in ("stress", "strain"):  # 2D: the other plane law
            C = stiffness(material_form(LinearElastic(E=material.E, nu=material.nu, plane=other)))
        hint = ""
        if C is not None and difference(C) <= MATERIAL_TOLERANCE:
            hint = f"; the form is the plane-{other} law: pass plane={other!r}"
        else:
            ratio = A.norm(PETSc.NormType.FROBENIUS) / nb
            if difference(B, ratio) <= MATERIAL_TOLERANCE:
                hint = (
                    f"; the form's stiffness is {ratio:.6g} times the material's: "
                    f"E={ratio * material.E:.6g}?"
                )
        if C is not None:
            C.destroy()
        A.destroy()
        B.destroy()
        since = (
            " since a Constant or Function of a changed after the problem was built (build a "
            "new problem with the new law)"
            if changed
            else ""
        )
        raise ValueError(
            f"material={material} disagrees with the bilinear form a {where}{since} (relative "
            f"difference {rel:.3g} > {MATERIAL_TOLERANCE:g}){hint}; the particle side uses the "
            "material, so pass the law that a encodes there"
        )
    A.destroy()
    B.destroy()


def _differentiates(expr, v) -> bool:
    """Whether ``expr`` contains a derivative of the argument ``v``."""
    from ufl.algorithms import expand_derivatives

    for node in unique_pre_traversal(expand_derivatives(expr)):
        if isinstance(node, ufl.classes.Derivative) and any(
            sub == v for sub in unique_pre_traversal(node)
        ):
            return True
    return False


# -- helpers ------------------------------------------------------------------------------------


def _split_points(msh, facets, cracks, degree, c2f, cells):
    """The Gauss points of the facets that a crack's mouth splits
    (:func:`~dolfinx_meshfree.geometry.cut_cells.cut_facet_quadrature`) as a rule for
    :class:`_FacetLoad`: their reference coordinates in the facet's cell (straight facets: the
    point's position along the facet mapped onto the reference facet), the cells, and the (cell,
    point) of each; ``None`` when no facet is split (local)."""
    q = cut_facet_quadrature(msh, facets, cracks, degree)
    plain = facet_quadrature(msh, facets, degree)
    if len(q) == len(plain) and np.array_equal(q.points, plain.points):
        return None
    tol = 1e-9 * (np.ptp(msh.geometry.x[:, :2], axis=0).max() + 1.0)
    new = cKDTree(plain.points).query(q.points)[0] > tol
    pts, ents = q.points[new], q.entities[new]
    where = np.searchsorted(facets, ents, sorter=np.argsort(facets))
    idx = np.argsort(facets)[where]
    c = cells[idx]
    cell = getattr(basix.CellType, msh.topology.cell_type.name)
    ref = np.asarray(basix.geometry(cell))
    ends = np.asarray(basix.topology(cell)[1])[np.argmax(c2f[c] == ents[:, None], axis=1)][:, :2]
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[c], :2]  # nodes in reference vertex order
    a, b = xc[np.arange(c.size), ends[:, 0]], xc[np.arange(c.size), ends[:, 1]]
    t = np.einsum("ij,ij->i", pts - a, b - a) / np.einsum("ij,ij->i", b - a, b - a)
    X = ref[ends[:, 0]] + t[:, None] * (ref[ends[:, 1]] - ref[ends[:, 0]])
    return X, c, np.arange(c.size), np.arange(c.size)


class _FacetLoad:
    """Traction ``t(x, n)`` of an exterior-facet integral of ``L``, tabulated at the facet Gauss
    points of :func:`~dolfinx_meshfree.facet_quadrature` and, with ``cracks``, at those of
    :func:`~dolfinx_meshfree.geometry.cut_cells.cut_facet_quadrature` (the facets a crack's
    mouth splits; collective construction).

    ``t(x, n) = A(x) + B(x) n``: the integrand is evaluated with ``FacetNormal`` replaced by a
    Constant set to 0 and each ``e_i`` (and checked to be affine in n at one more value).
    """

    def __init__(
        self, itg, v, facets: np.ndarray, degree: int, cracks: Sequence = (), revolved: bool = False
    ):
        msh = v.ufl_function_space().mesh
        self.revolved = revolved  # the integrand's 2 pi r taken off (see FormBodyForce)
        tdim = msh.topology.dim
        d = msh.geometry.dim
        cname = msh.topology.cell_type.name
        cell = getattr(basix.CellType, cname)
        ref_facets = basix.topology(cell)[tdim - 1]
        X = reference_facet_points(cname, degree)
        npts = X.shape[0] // len(ref_facets)
        nc = dolfinx.fem.Constant(msh, np.zeros(d))
        integrand = itg.integrand()
        has_normal = any(
            isinstance(o, ufl.classes.FacetNormal) for o in unique_pre_traversal(integrand)
        )
        x = ufl.SpatialCoordinate(msh)
        values = ufl.as_vector(
            [replace_test_function(integrand, v, msh, nc)[i] for i in range(d)]
            + [x[i] for i in range(d)]
        )
        # (cell, local facet) of each facet
        msh.topology.create_connectivity(tdim - 1, tdim)
        msh.topology.create_connectivity(tdim, tdim - 1)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        c2f = np.asarray(msh.topology.connectivity(tdim, tdim - 1).array).reshape(
            -1, len(ref_facets)
        )
        facets = np.asarray(facets, dtype=np.int64)
        cells = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
        local = np.argmax(c2f[cells] == facets[:, None], axis=1)
        # the rules: (reference points, cells evaluated, (cell row, point column) per point)
        rules = [(X, cells, np.repeat(np.arange(cells.size), npts),
                  (local[:, None] * npts + np.arange(npts)).ravel())]  # fmt: skip
        if len(cracks) and facets.size:
            split = _split_points(msh, facets, cracks, degree, c2f, cells)
            if split is not None:
                rules.append(split)
        # a rank without split points still takes part in the same expressions' compilation
        num_rules = msh.comm.allreduce(len(rules), op=MPI.MAX)
        if num_rules > len(rules):
            rules.append((np.zeros((1, tdim)), cells[:0], np.zeros(0, int), np.zeros(0, int)))
        evaluators = []
        for Xr, cr, rows, cols in rules:
            expr = _compat.create_expression(values, Xr)
            ucells, pos = np.unique(cr, return_inverse=True)
            evaluators.append((expr, ucells, pos[rows] if rows.size else rows, cols))

        def evaluate(n: np.ndarray) -> np.ndarray:
            nc.value[:] = n
            out = []
            for expr, ucells, rows, cols in evaluators:
                vals = _compat.eval_expression(expr, msh, ucells, 2 * d)
                out.append(vals[rows, cols] if rows.size else np.zeros((0, 2 * d)))
            return np.concatenate(out)

        def tabulate() -> int:
            base = evaluate(np.zeros(d))
            self.points, self.A = base[:, d:], base[:, :d]
            self.B = np.zeros((len(self.A), d, d))
            if not has_normal:
                return 0
            self.B[:] = np.stack([evaluate(e)[:, :d] for e in np.eye(d)], -1)
            self.B -= self.A[:, :, None]
            unit = np.array([0.6, 0.8, 0.0][:d]) if d == 2 else np.array([0.48, 0.64, 0.6])
            probe = evaluate(unit)[:, :d]
            affine = self.A + self.B @ unit
            scale = np.abs(self.A).max(initial=0.0) + np.abs(self.B).max(initial=0.0) + 1e-300
            return int(np.abs(probe - affine).max(initial=0.0) > 1e-10 * scale)

        self._tabulate, self._comm = tabulate, msh.comm
        self.refresh()
        self.tree = cKDTree(self.points) if len(self.points) else None
        self.tol = 1e-9 * (np.ptp(msh.geometry.x[:, :d], axis=0).max() + 1.0)
        self.gdim = d

    def refresh(self) -> None:
        """Tabulate ``A`` and ``B`` at the current values of the integrand's constants and
        coefficients (collective; the points do not move)."""
        bad = raise_on_all_ranks(self._comm, self._tabulate)
        if self._comm.allreduce(bad, op=MPI.MAX):
            raise ValueError(
                "an exterior-facet integral of L is not affine in the FacetNormal n; write the "
                "load as dot(t0 + T n, v) ds with t0, T independent of n"
            )

    def __call__(self, x: np.ndarray, n: np.ndarray) -> np.ndarray:
        if len(x) == 0:
            return np.zeros((0, self.gdim))
        if self.tree is None:
            raise RuntimeError("a traction was requested at points of no facet of its integral")
        d, idx = self.tree.query(x)
        if np.any(d > self.tol):
            raise RuntimeError(
                f"a traction was requested at {int(np.sum(d > self.tol))} point(s) that are not "
                "facet Gauss points of its integral (internal error: quadrature degree mismatch)"
            )
        t = self.A[idx] + np.einsum("mij,mj->mi", self.B[idx], n)
        if self.revolved:  # per unit area; on the axis the revolved weight is 0 anyway
            r = np.asarray(x, dtype=float)[:, :1]
            t = np.where(r > 0.0, t / (2.0 * np.pi * np.where(r > 0.0, r, 1.0)), 0.0)
        return t
