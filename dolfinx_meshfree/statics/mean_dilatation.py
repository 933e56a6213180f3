"""Mean dilatation (B-bar) for a law with state on Q1 cells: no volumetric locking.

Plastic flow is isochoric. Q1 cells integrated by their full rule (2 x 2, 2 x 2 x 2 Gauss) ask
the strain's trace to follow it at every point, and lock: a perfectly plastic thick ring in plane
strain kept gaining load past its limit pressure (pure FE +0.24 % at ``u_r(a) = 6e-3``,
lagrange +4.3 % at 0.3, stop 61). Hughes' B-bar (Hughes 1980, "Generalization of selective
integration procedures to anisotropic and nonlinear media", IJNME 15, eq. 31-35) replaces the
trace of the strain at each point by its cell mean, and keeps the deviatoric part:

.. math::
    \\bar\\varepsilon_q = \\varepsilon_q + \\tfrac{1}{d}\\,(\\bar\\theta - \\theta_q)\\, m,
    \\qquad \\theta_q = m \\cdot \\varepsilon_q, \\qquad
    \\bar\\theta = \\frac{\\sum_q W_q\\, \\theta_q}{\\sum_q W_q}

with ``m`` the Voigt identity and ``d`` the space dimension. In plane strain ``d = 2`` (the
in-plane trace, ``e_zz = 0`` kept), as de Souza Neto et al. (1996) take the exponent of their
F-bar in plane strain; in 3D ``d = 3``. Plane stress has no volumetric constraint (``e_zz`` is
free) and triangles and tetrahedra have a constant strain per cell: neither needs it.

The law runs at ``eps_bar``. With an extra weight ``w`` of the integrand (the bridging band's
``1 - alpha``) the mean is taken with the weights ``Omega_q = W_q w_q`` (``W`` the points'
geometric weights): then ``int w eps_bar(v) = int w eps(v)`` for every ``v``, so a uniform
stress does the same work as without the mean, and a bridging band keeps its patch test. With
``B_bar = P B + m g / d`` (``P = I - m m^T / d``, ``g`` the cell's mean divergence row), the
residual ``sum_q Omega_q B_bar^T sigma_q`` is the plain ``sum_q W_q B_q^T sigma_hat_q`` of a
modified stress

.. math::
    \\hat\\sigma_q = w_q\\, (\\sigma_q + (\\bar p - p_q)\\, m), \\qquad
    p_q = m \\cdot \\sigma_q / d, \\qquad
    \\bar p = \\frac{\\sum_q \\Omega_q\\, p_q}{\\sum_q \\Omega_q},

so the FE form keeps reading a quadrature function. The consistent tangent
``sum_q Omega_q B_bar^T C_q B_bar`` is the pointwise ``B^T (w P^T C P) B`` (again a quadrature
function) plus three rank-one terms per cell,

.. math::
    h_1 \\otimes g + g \\otimes h_2 + \\bar c\\, g \\otimes g, \\qquad
    h_1 = \\sum_q \\Omega_q B_q^T P^T C_q m / d, \\quad
    h_2 = \\sum_q \\Omega_q B_q^T P^T C_q^T m / d, \\quad
    \\bar c = \\sum_q \\Omega_q\\, m^T C_q m / d^2,

which a UFL form cannot write (products of two cell integrals): they are added to the assembled
matrix cell by cell (:meth:`MeanDilatation.add_to`).
"""

from __future__ import annotations

import warnings

import dolfinx
import numpy as np
from petsc4py import PETSc

from .. import _compat
from ..physics.state import tensor_from_voigt

__all__ = [
    "DILATATIONS",
    "MEAN_DILATATION_CELLS",
    "MeanDilatation",
    "VolumetricLockingWarning",
    "resolve_dilatation",
    "warn_locking",
]

#: The ``dilatation`` options: ``None`` (automatic: ``"mean"`` where it applies), ``"mean"``
#: (B-bar), ``"pointwise"`` (the plain strain at every point).
DILATATIONS = (None, "mean", "pointwise")

#: The cells whose strain varies inside a cell, where mean dilatation changes the answer.
MEAN_DILATATION_CELLS = ("quadrilateral", "hexahedron")


class VolumetricLockingWarning(UserWarning):
    """A law whose plastic flow keeps the volume (``J2Plasticity``) on P1 triangles or
    tetrahedra in plane strain or 3D: their constant strain cannot follow it and they lock, so
    the load keeps rising past the limit load (Prandtl's punch on 40 x 20 cells, each square cut
    in two: 1.40 times the limit pressure at a settlement of 0.2 of the footing's half width, and
    rising; quadrilaterals with the mean dilatation 1.018, flat). Use quadrilaterals or
    hexahedra, or plane stress where the body is thin."""


def warn_locking(law: object, cell_name: str) -> None:
    """Warn (:class:`VolumetricLockingWarning`) where ``law``'s isochoric flow runs on simplices
    in plane strain or 3D (local)."""
    if (
        getattr(law, "isochoric_flow", False)
        and getattr(law, "plane", None) != "stress"
        and cell_name in ("triangle", "tetrahedron")
    ):
        warnings.warn(
            f"{type(law).__name__} (plane={getattr(law, 'plane', None)!r}) on {cell_name} "
            "cells: their constant strain cannot follow isochoric plastic flow, so they lock and "
            "the load rises past the limit load. Use quadrilaterals or hexahedra (the FE cells "
            "then take the cell's mean dilatation), or plane stress where the body is thin",
            VolumetricLockingWarning,
            stacklevel=3,
        )


def resolve_dilatation(dilatation: str | None, law: object, cell_name: str, what: str) -> bool:
    """Whether ``what`` uses mean dilatation: ``dilatation`` checked against ``law`` (a law with
    state, or ``None`` for a law without) and the cell; a ValueError names an option that does
    not apply (local, the same on every rank)."""
    if dilatation not in DILATATIONS:
        raise ValueError(
            f"{what}: dilatation={dilatation!r} is not known; use None (automatic), 'mean' "
            "(B-bar on quadrilaterals and hexahedra) or 'pointwise'"
        )
    plane = getattr(law, "plane", None)
    applies = law is not None and cell_name in MEAN_DILATATION_CELLS and plane != "stress"
    if dilatation == "mean" and not applies:
        if law is None:
            why = (
                "the FE cells run the user's UFL form (a law without state); write the "
                "volumetric part of that form as you wish"
            )
        elif plane == "stress":
            why = "plane stress has no volumetric constraint (e_zz is free) and does not lock"
        else:
            why = (
                f"{cell_name} cells have a constant strain per cell, so the mean is the strain "
                "itself and their locking stays; use quadrilaterals or hexahedra"
            )
        raise ValueError(f"{what}: dilatation='mean' does not apply: {why}. Leave it None")
    return applies if dilatation is None else dilatation == "mean"


class MeanDilatation:
    """The cell-wise operators of B-bar on ``cells`` (local, owned) of a vector P1/Q1 space.

    Args:
        V: The FE space.
        cells: The cells (their points contiguous, ``X.shape[0]`` per cell).
        X, w: The law's reference quadrature rule.
        weights: The points' geometric weights ``W`` (``w`` times ``|det J|``), cell by cell, as
            the state's rule has them: the mapping here is checked against them.
        factor: The extra weight of the integrand at the points (ones without one).
    """

    def __init__(
        self,
        V: dolfinx.fem.FunctionSpace,
        cells: np.ndarray,
        X: np.ndarray,
        w: np.ndarray,
        weights: np.ndarray,
        factor: np.ndarray,
    ) -> None:
        msh = V.mesh
        d = msh.geometry.dim
        nc = len(cells)
        self.d, self.nv = d, d * (d + 1) // 2
        self.m = np.zeros(self.nv)
        self.m[:d] = 1.0
        element = _compat.basix_lagrange_p1(msh.topology.cell_type.name)
        dN = element.tabulate(1, X)[1 : 1 + d, :, :, 0]  # (d, nq, nn) reference derivatives
        #: The dofs of a cell (nodes times components).
        self.n = dN.shape[2] * d
        x = msh.geometry.x[:, :d][_compat.geometry_dofmap(msh)[cells]]  # (nc, nn, d)
        J = np.einsum("cag,tqa->cqgt", x, dN)  # dx_g / dX_t
        #: Gradients of the cells' basis functions at their points, (nc, nq, nn, d).
        self.grad = np.einsum("tqa,cqtg->cqag", dN, np.linalg.inv(J))
        W = np.abs(np.linalg.det(J)) * np.asarray(w)[None, :]
        if not np.allclose(W.ravel(), weights, rtol=1e-10, atol=0.0):
            raise RuntimeError("mean dilatation: the cells' mapping differs from the state's rule")
        #: The extra weight at the points (nc, nq).
        self.factor = np.asarray(factor, dtype=float).reshape(nc, X.shape[0])
        #: The points' weights in the integrals, ``Omega = W w`` (nc, nq).
        self.work = W * self.factor
        #: The weights of the means: ``Omega``, or ``W`` in a cell where ``w`` vanishes (it does
        #: no work; its state stays the mean-dilatation state of its strain).
        self.mean_weights = np.where((self.work.sum(axis=1) > 0.0)[:, None], self.work, W)
        self.mean_total = self.mean_weights.sum(axis=1)
        #: The mean divergence row of each cell, (nc, nn * d): ``theta_bar = g . u_K``.
        g = np.einsum("cq,cqag->cag", self.mean_weights, self.grad) / self.mean_total[:, None, None]
        self.g = g.reshape(nc, self.n)
        imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
        nodes = _compat.dofmap_array(V)[cells]
        gnodes = np.asarray(imap.local_to_global(nodes.ravel().astype(np.int32)))
        #: The cells' global dofs (nc, nn * d), node by node.
        dofs = bs * gnodes.reshape(nodes.shape)[:, :, None] + np.arange(bs)
        self.dofs = np.ascontiguousarray(dofs.reshape(nc, self.n), dtype=PETSc.IntType)
        #: ``(P^T C m / d, P^T C^T m / d, m^T C m / d^2)`` at the points at the last
        #: :meth:`stress_tangent`: what the tangent's rank-one cell terms are made of, summed
        #: only by :meth:`add_to` (a residual alone, as in a line search, needs none of them).
        self._terms: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def strain(self, strain: np.ndarray) -> np.ndarray:
        """``eps_bar`` of the points' Voigt strains (nc * nq, nv): the trace replaced by the
        cell's mean."""
        nc, nq = self.mean_weights.shape
        e = strain.reshape(nc, nq, self.nv)
        theta = e @ self.m
        mean = np.einsum("cq,cq->c", self.mean_weights, theta) / self.mean_total
        return (e + ((mean[:, None] - theta) / self.d)[..., None] * self.m).reshape(-1, self.nv)

    def stress_tangent(
        self, stress: np.ndarray, tangent: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The pointwise stress and tangent the forms read (``sigma_hat`` and ``w P^T C P``, with
        the weight ``w`` in), from the law's ``stress`` (n, nv) and ``tangent`` (n, nv, nv) at
        ``eps_bar``; keeps what the cells' rank-one terms need for :meth:`add_to`."""
        nc, nq = self.mean_weights.shape
        d, m = self.d, self.m
        s = stress.reshape(nc, nq, self.nv)
        C = tangent.reshape(nc, nq, self.nv, self.nv)
        ww = self.factor
        p = s @ m / d
        p_bar = np.einsum("cq,cq->c", self.mean_weights, p) / self.mean_total
        s_hat = ww[..., None] * (s + (p_bar[:, None] - p)[..., None] * m)
        a = C @ m / d  # C m / d
        a_t = m @ C / d  # C^T m / d
        c = a @ m / d  # m^T C m / d^2
        P_a = a - c[..., None] * m
        P_at = a_t - c[..., None] * m
        PCP = (
            C
            - a[..., :, None] * m[None, None, None, :]
            - m[None, None, :, None] * a_t[..., None, :]
            + c[..., None, None] * np.outer(m, m)
        )
        self._terms = (P_a, P_at, c)
        return s_hat.reshape(-1, self.nv), (ww[..., None, None] * PCP).reshape(-1, self.nv, self.nv)

    def _bt(self, v: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """``sum_q weights_q B_q^T v_q`` of stress-like Voigt vectors ``v`` (nc, nq, nv), per
        cell (nc, nn * d)."""
        d = self.d
        S = tensor_from_voigt(v.reshape(-1, self.nv), d).reshape(*v.shape[:2], d, d)
        out = np.einsum("cq,cqag,cqig->cai", weights, self.grad, S)
        return out.reshape(out.shape[0], self.n)

    def add_to(self, A: PETSc.Mat) -> None:
        """Add the cells' rank-one terms of the last :meth:`stress_tangent` to the assembled ``A``
        (global numbering, the rows of other ranks through PETSc's stash) and assemble it
        (collective)."""
        if self._terms is None:
            raise RuntimeError("mean dilatation: add_to before stress_tangent")
        if self.dofs.shape[0]:
            P_a, P_at, c = self._terms
            h1 = self._bt(P_a, self.work)
            h2 = self._bt(P_at, self.work)
            cb = np.einsum("cq,cq->c", self.work, c)
            g = self.g
            values = (
                h1[:, :, None] * g[:, None, :]
                + g[:, :, None] * h2[:, None, :]
                + cb[:, None, None] * g[:, :, None] * g[:, None, :]
            )
            A.setValuesRCV(self.dofs, self.dofs, values, addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()
