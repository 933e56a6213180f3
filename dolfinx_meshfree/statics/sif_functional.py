"""Stress intensity factors as linear functionals of the particle coefficients (issue 26, item 2).

For a fixed tip and domains, the interaction integral's K_I and K_II are linear in the field
(Moran & Shih 1987; :func:`~dolfinx_meshfree.fracture.interaction.interaction_rule`):

.. math::
    K_m = \\sum_q C^m_q : \\nabla u(x_q) + \\sum_q A^m_q \\cdot \\ddot u(x_q)
        = w^m_u \\cdot \\mathbf{u} + w^m_a \\cdot \\mathbf{a},
    \\qquad
    w^m_{u,Ji} = \\sum_q \\sum_l C^m_{q,il} \\, \\partial_l \\phi_J(x_q), \\quad
    w^m_{a,Ji} = \\sum_q A^m_{q,i} \\, \\phi_J(x_q),

with ``phi_J`` the crack-aware MLS functions of the particles (cut, enriched) and ``u``, ``a``
their coefficients. :class:`SIFFunctional` tabulates ``phi_J`` and its gradient at the rule's
points once and keeps the weight vectors (on the particles whose supports reach the domains):
a check is then two dot products per domain. The vectors belong to one tip position, one set
of domains and one version of the MLS (:attr:`~dolfinx_meshfree.MLS.version`, which changes
when a crack grows or the particles move): a caller that keeps them
(:func:`~dolfinx_meshfree.dynamics.sifs.dynamic_sifs` with ``j_integral=False``) keeps the MLS
and its version beside them and rebuilds them when either changed. J is quadratic in the field
and has no such functional.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..fracture.interaction import InteractionRule

if TYPE_CHECKING:  # annotations only
    from ..approx.mls import MLS

__all__ = ["SIFFunctional"]


def _weights(tables: list, coefficients: np.ndarray) -> np.ndarray:
    """``sum_q coefficients[r, q, i, l] T_l[q, J]`` as (columns, i, rows): the weight vectors of
    ``rows`` functionals on the coefficients ``(J, i)``, from tables ``T_l`` (points x columns,
    CSR) and per-point coefficients (rows, points, i, l)."""
    rows, _, gdim, nl = coefficients.shape
    out = np.zeros((tables[0].shape[1], gdim, rows))
    for i in range(gdim):
        for j in range(nl):
            out[:, i, :] += tables[j].T @ coefficients[:, :, i, j].T
    return out


class SIFFunctional:
    """K_I and K_II per domain as weight vectors on the particle coefficients (module
    docstring): built from an MLS and an
    :class:`~dolfinx_meshfree.fracture.interaction.InteractionRule` (local: the MLS is
    tabulated at the rule's points on this rank; with replicated particles every rank builds
    the same vectors).

    Attributes:
        rule: The rule (tip, direction, radii, ``E'``).
        columns: Coefficient indices (p,) with a nonzero weight (the particles whose supports
            reach the domains).
    """

    def __init__(self, mls: MLS, rule: InteractionRule) -> None:
        self.rule = rule
        m, k = rule.gradient_weights.shape[:2]
        grads = mls.tabulate(rule.gradient_points).gradients
        wu = _weights(grads, rule.gradient_weights.reshape(m * k, *rule.gradient_weights.shape[2:]))
        wa = None
        if rule.acceleration_weights is not None:
            values = mls.tabulate(rule.acceleration_points, 0).values
            a = rule.acceleration_weights
            wa = _weights([values], a.reshape(m * k, a.shape[2], a.shape[3], 1))
        used = np.abs(wu).reshape(wu.shape[0], -1).max(axis=1) > 0.0
        if wa is not None:
            used |= np.abs(wa).reshape(wa.shape[0], -1).max(axis=1) > 0.0
        self.columns = np.flatnonzero(used)
        #: (p, gdim, 2 k): the weights of K_I (first k) and K_II (last k) on ``u[columns]``
        self.on_displacement = np.ascontiguousarray(wu[self.columns])
        self.on_acceleration = None if wa is None else np.ascontiguousarray(wa[self.columns])

    @property
    def dynamic(self) -> bool:
        """Whether K holds the inertia term (the rule was built with ``dynamic=True``)."""
        return self.on_acceleration is not None

    def __call__(
        self, u: np.ndarray, acceleration: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(K_I, K_II)`` (k,) each from the particle coefficients ``u`` (n, gdim) and, for a
        dynamic functional, the accelerations' (n, gdim)."""
        if (acceleration is None) == self.dynamic:
            raise ValueError(
                "acceleration must be given exactly when the functional is dynamic "
                f"(dynamic={self.dynamic})"
            )
        c = self.columns
        return self.on_columns(u[c], None if acceleration is None else acceleration[c])

    def on_columns(
        self, u: np.ndarray, acceleration: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`__call__` from the rows of :attr:`columns` only (p, gdim), in their order:
        the same K's to the bit, for a caller that gathers only these particles."""
        if (acceleration is None) == self.dynamic:
            raise ValueError(
                "acceleration must be given exactly when the functional is dynamic "
                f"(dynamic={self.dynamic})"
            )
        K = np.einsum("pi,pir->r", u, self.on_displacement)
        if acceleration is not None:
            K = K + np.einsum("pi,pir->r", acceleration, self.on_acceleration)
        k = K.size // 2
        return K[:k], K[k:]

    def at_points(self, acceleration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(K_I, K_II)`` of the inertia term alone, for an acceleration given at the rule's
        acceleration points (nq, gdim) rather than by coefficients: ``sum_q A^m_q . a_q``
        (a body force's ``-b / rho``, which no particle coefficients carry)."""
        if not self.dynamic:
            raise ValueError("at_points needs a dynamic functional (dynamic=True)")
        a = self.rule.acceleration_weights  # (2, k, nq, gdim): K_I, K_II per domain
        K = np.einsum("mkqi,qi->mk", a, np.asarray(acceleration, dtype=float)).reshape(-1)
        k = K.size // 2
        return K[:k], K[k:]
