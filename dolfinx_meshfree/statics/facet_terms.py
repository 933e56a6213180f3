"""Facet integrals of the unknown in a user's coupled form: where the FE side can carry them.

A model written for DOLFINx may hold boundary terms that depend on the unknown: an elastic
support (a Winkler foundation, a spring, a Robin condition) ``k inner(u, v) ds(i)`` in a
bilinear form ``a``, or a follower pressure ``p J inner(inv(F).T N, v) ds(i)`` in a residual
``F(u; v)``. :class:`~dolfinx_meshfree.CoupledLinearProblem` and
:class:`~dolfinx_meshfree.CoupledNonlinearProblem` assemble such a term on the FE side, with
DOLFINx, over the FE cells' exterior facets: there the FE field is the model's displacement.
On a facet of a patch cell the displacement is the particles' (MLS) field, and on a facet of a
ramp's interface cell a blend of both, which a UFL form on the FE space cannot see; such a facet
is refused (:meth:`FacetTermCheck.check`), never integrated with the wrong field or dropped.
Interior-facet integrals of the unknown (``dS``) are refused too.

The FE weight of every coupling (:attr:`~dolfinx_meshfree.couplings.base.CouplingOperators.
fe_weight`: a DG0 indicator of the FE cells, ``1 - alpha`` only in a bridging band, whose cells
are patch cells) is 1 on the facets kept, so weighting the facet integrals with it, as the cell
integrals are, leaves them as the user wrote them.
"""

from __future__ import annotations

import dolfinx
import numpy as np
import ufl

from .. import _compat
from ..couplings.base import interface_node_flags
from ..geometry.patch import ParticlePatch
from ..geometry.quadrature import boundary_facets

__all__ = ["FacetTermCheck", "facet_integrals", "integral_entities"]

#: Couplings whose FE cells with a node on the interface carry blended (FE and particle)
#: functions (Belytschko et al. 1995, eq. 3.1; Rabczuk et al. 2006, eq. 33).
BLENDED = ("ramp", "ramp-cubic")


def facet_integrals(form: ufl.Form) -> list:
    """The integrals of ``form`` that are not cell integrals."""
    return [itg for itg in form.integrals() if itg.integral_type() != "cell"]


def integral_entities(itg: ufl.classes.Integral, msh: dolfinx.mesh.Mesh) -> np.ndarray:
    """Local entities (cells or facets, owned and ghost) an integral runs over."""
    tdim = msh.topology.dim
    dim = tdim if itg.integral_type() == "cell" else tdim - 1
    imap = msh.topology.index_map(dim)
    sid = itg.subdomain_id()
    if sid == "everywhere":
        return np.arange(imap.size_local + imap.num_ghosts, dtype=np.int64)
    ids = np.atleast_1d(np.asarray(sid, dtype=np.int64))
    tags = itg.subdomain_data()
    if tags is None:
        raise ValueError(f"an integral uses subdomain {sid!r} without subdomain_data")
    tags = getattr(tags, "_cpp_object", tags)
    mask = np.isin(np.asarray(tags.values), ids)
    return np.asarray(tags.indices, dtype=np.int64)[mask]


class FacetTermCheck:
    """Where the facet integrals of the unknown in ``form`` fall (collective to build, local to
    :meth:`check`): on the FE side's exterior facets, or on facets it cannot carry.

    Args:
        form: The user's bilinear form ``a``, or the ``u``-dependent part of a residual.
        patch: The particle patch on the form's mesh.
        coupling: The coupling's name (the ramps' interface cells are refused too).
        name: How the form is named in an error (``"a"``, ``"F"``).
    """

    def __init__(self, form: ufl.Form, patch: ParticlePatch, coupling: str, name: str) -> None:
        self.name, self.coupling = name, coupling
        self.integrals = facet_integrals(form)
        msh = patch.mesh
        tdim = msh.topology.dim
        self.interior = [i for i in self.integrals if i.integral_type() != "exterior_facet"]
        if not self.integrals:
            self.refused: list[tuple[object, np.ndarray]] = []
            return
        refused_cells = np.asarray(patch.in_patch, dtype=bool).copy()
        if coupling in BLENDED:  # collective: the ramp's interface cells (RampInterface's rule)
            V = form.arguments()[0].ufl_function_space()
            on_gamma = interface_node_flags(V, patch)
            refused_cells |= on_gamma[_compat.dofmap_array(V)[: refused_cells.size]].any(axis=1)
        msh.topology.create_connectivity(tdim - 1, tdim)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        exterior = boundary_facets(msh)
        self.refused = []
        for itg in self.integrals:
            if itg.integral_type() != "exterior_facet":
                continue
            facets = np.intersect1d(integral_entities(itg, msh), exterior)
            first = np.asarray(f2c.array)[np.asarray(f2c.offsets)[facets]]
            bad = facets[refused_cells[first]].astype(np.int32)
            if bad.size:
                x = dolfinx.mesh.compute_midpoints(msh, tdim - 1, bad)[:, : msh.geometry.dim]
                self.refused.append((itg, x))

    def check(self) -> None:
        """Raise a ``ValueError`` naming the integral, the facets by their midpoints and the
        fix, if a facet integral of the unknown cannot be carried (local)."""
        name = self.name
        if self.interior:
            raise ValueError(
                f"{name} has an interior-facet integral (dS) of the unknown; a coupled problem "
                "takes cell integrals and exterior-facet integrals (ds) of the FE side only"
            )
        if not self.refused:
            return
        itg, x = self.refused[0]
        where = "a patch cell" + (
            " or a ramp's interface cell (blended functions)" if self.coupling in BLENDED else ""
        )
        raise ValueError(
            f"{name}'s ds integral of the unknown (subdomain {itg.subdomain_id()!r}: an elastic "
            f"support, a spring or a follower load) runs over {len(x)} exterior facet(s) of "
            f"{where}, e.g. the facets at {x[:3].round(6).tolist()}: there the displacement is "
            "the particles', which a form on the FE space does not see. Such terms are "
            "integrated on the FE cells' facets only: keep the patch (and a ramp's interface "
            "cells) off these facets, or tag only FE facets for this integral"
        )
