"""Laws with internal state at quadrature points: the state store and its binding to the
force code.

A law with state (:class:`StatefulLaw`: damage, plasticity, :mod:`~dolfinx_meshfree.physics.
inelastic`) maps the total small strain at the end of a load step and the state *committed* at its
start to the stress, the consistent (algorithmic) tangent and a *trial* state (backward Euler: the
result depends only on the two, so Newton may evaluate it as often as it likes). The state lives in
a :class:`PointState`, one per set of quadrature points (the particle rule, the FE cells' rule):

* :meth:`PointState.commit`: the trial state becomes the committed one; called once a load step
  has converged, after a last evaluation at the converged displacements;
* :meth:`PointState.restore`: the trial state is dropped; called when a step is cut (its
  iterations never touch the committed state, so nothing else is needed);
* a quadrature that changes (a cell newly cut by a growing cohesive crack) gets its committed
  state from the old points of the same cell (:mod:`~dolfinx_meshfree.statics.state_carry`);
  the solvers that change the quadrature in other ways (a cell that joins the patch, a crack
  growing in dynamics) refuse a law with state (see :func:`check_stateless`).

:class:`BoundLaw` turns a law and its :class:`PointState` into a
:class:`~dolfinx_meshfree.physics.constitutive.Material` (``first_piola`` and ``tangent`` of a
displacement gradient stack), so that :class:`~dolfinx_meshfree.InternalForces` and the Newton
sides use it unchanged: small strain, ``P = sigma(sym(F - I))`` and
``A_iJkL = d sigma_iJ / d H_kL``.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..approx.tables import voigt_pairs
from .materials import LinearElastic

__all__ = [
    "BoundLaw",
    "PointState",
    "StatefulLaw",
    "check_not_rate_law",
    "check_stateless",
    "is_rate_law",
    "is_stateful",
    "tangent_from_voigt",
    "tensor_from_voigt",
    "voigt_strain",
]


@runtime_checkable
class StatefulLaw(Protocol):
    """A small-strain law with state at its points (Voigt order of
    :func:`~dolfinx_meshfree.approx.tables.voigt_pairs`, engineering shear strains)."""

    plane: str | None
    rho: float
    E: float
    nu: float
    needs_band: bool

    @property
    def gdim(self) -> int: ...

    @property
    def state_fields(self) -> dict[str, int]:
        """Name and components per point of each state array."""
        ...

    def initial_state(self, m: int) -> dict[str, np.ndarray]: ...

    def update(
        self, strain: np.ndarray, state: dict[str, np.ndarray], band: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """``(stress (m, nv), tangent (m, nv, nv), trial state)`` from the total strain at the
        end of a step and the committed state at its start (never modified)."""
        ...

    def elastic(self) -> LinearElastic: ...

    def stored_energy(self, strain: np.ndarray, state: dict[str, np.ndarray]) -> np.ndarray: ...

    def dissipated_energy(self, state: dict[str, np.ndarray]) -> np.ndarray: ...

    def check_band(self, band: np.ndarray, points: np.ndarray | None = None) -> None: ...


def is_stateful(law: object) -> bool:
    """Whether ``law`` carries state at its points (a :class:`StatefulLaw`)."""
    return isinstance(law, StatefulLaw) and hasattr(law, "initial_state")


def check_stateless(law: object, where: str) -> None:
    """Refuse a law with state in code that does not carry it (never silently elastic); in
    explicit dynamics, name the rate-form laws that carry plasticity and damage there."""
    if is_stateful(law) or isinstance(law, BoundLaw):
        dynamics = (
            "; in explicit dynamics, plasticity and damage are the rate-form laws at finite "
            "strain: mf.JohnsonCook (J2 flow, yield stress A + B eps_p^n: A=sigma_y, B=H, n=1, "
            "C=0 is linear hardening; plane strain, 3D or axisymmetric) and "
            "mf.HolmquistJohnsonCook (damaging concrete)"
            if where == "explicit dynamics"
            else ""
        )
        raise TypeError(
            f"{type(getattr(law, 'law', law)).__name__} is a law with internal state (damage, "
            f"plasticity), and {where} does not carry state at its quadrature points; solve it "
            "with CoupledElasticity(...) or EFGElasticity(...): .solve(load_steps=...), or "
            f"follow_path(...) past a peak{dynamics}"
        )


def is_rate_law(law: object) -> bool:
    """Whether ``law`` is a rate-form material point (state with ``F``; ``update(F, dt,
    state)``)."""
    fields = getattr(law, "state_fields", None)
    return isinstance(fields, dict) and "F" in fields and hasattr(law, "update")


def check_not_rate_law(law: object, where: str) -> None:
    """Refuse a rate-form material point (:class:`~dolfinx_meshfree.HolmquistJohnsonCook`,
    :class:`~dolfinx_meshfree.JohnsonCook`: state with the deformation gradient ``F``) in code
    that does not carry its state, naming how to use it."""
    if is_rate_law(law):
        raise TypeError(
            f"{type(law).__name__} is a rate-form material point for impact (finite strain, "
            f"state with F at each point), and {where} does not carry its state: run it in "
            "explicit dynamics, ExplicitDynamics.fe(V, law) or .efg(particles, law), or drive "
            "it at your points with state = law.initial_state(m); sigma, state = "
            "law.update(F, dt, state)"
        )


def _voigt_maps(d: int) -> tuple[np.ndarray, np.ndarray]:
    """``M`` (nv, d*d): engineering Voigt strain from a row-major gradient ``H``; ``S`` (d*d,
    nv): a row-major symmetric tensor from Voigt stress components."""
    pairs = voigt_pairs(d)
    M = np.zeros((len(pairs), d * d))
    S = np.zeros((d * d, len(pairs)))
    for a, (i, j) in enumerate(pairs):
        M[a, d * i + j] += 1.0
        if i != j:
            M[a, d * j + i] += 1.0
            S[d * j + i, a] = 1.0
        S[d * i + j, a] = 1.0
    return M, S


def voigt_strain(H: np.ndarray) -> np.ndarray:
    """Engineering Voigt strain (m, nv) of displacement gradients ``H`` (m, d, d)."""
    d = H.shape[-1]
    M, _ = _voigt_maps(d)
    return H.reshape(-1, d * d) @ M.T


def tensor_from_voigt(s: np.ndarray, d: int) -> np.ndarray:
    """Symmetric tensors (m, d, d) from Voigt stress components (m, nv)."""
    _, S = _voigt_maps(d)
    return (s @ S.T).reshape(-1, d, d)


def tangent_from_voigt(C: np.ndarray, d: int) -> np.ndarray:
    """``A_iJkL = d sigma_iJ / d H_kL`` (m, d, d, d, d) from the Voigt tangent ``d sigma /
    d eps`` (m, nv, nv) with engineering shear strains (chain rule through ``eps = M H``)."""
    M, S = _voigt_maps(d)
    return np.einsum("ia,mab,bj->mij", S, C, M).reshape(-1, d, d, d, d)


class PointState:
    """The state of a law at ``m`` points: committed (start of the step) and trial (the last
    evaluation).

    Args:
        law: The :class:`StatefulLaw`.
        points: (m, gdim) coordinates of the points (to name a bad one).
        band: (m,) crack-band widths ``h`` (laws with ``needs_band``; checked by the law's
            ``check_band``), or ``None``.
        cells: (m,) the local cell of each point, or ``None``: what a state carried to a
            changed quadrature is taken from (:mod:`~dolfinx_meshfree.statics.state_carry`).
    """

    def __init__(
        self,
        law: StatefulLaw,
        points: np.ndarray,
        band: np.ndarray | None = None,
        cells: np.ndarray | None = None,
    ):
        self.law = law
        self.points = np.asarray(points, dtype=float)
        m = self.points.shape[0]
        self.cells = None if cells is None else np.asarray(cells, dtype=np.int64).reshape(-1)
        if self.cells is not None and self.cells.shape != (m,):
            raise ValueError(f"cells should have shape ({m},), got {self.cells.shape}")
        if law.needs_band:
            if band is None:
                raise ValueError(
                    f"{type(law).__name__} needs the crack-band width h of each of its {m} points "
                    "(band=...): the solvers pass the cell size"
                )
            band = np.asarray(band, dtype=float).reshape(-1)
            if band.shape != (m,):
                raise ValueError(f"band should have shape ({m},), got {band.shape}")
            law.check_band(band, self.points)
        self.band = band
        self.committed = law.initial_state(m)
        self.trial = {k: v.copy() for k, v in self.committed.items()}
        #: Changes at every commit and restore (evaluations kept by a :class:`BoundLaw` are
        #: keyed on it).
        self.version = 0
        #: Evaluate the law's tangent of unloading (its ``unloading_tangent``, where it has one)
        #: instead of the consistent one: the predictor of a load step that unloads.
        self.predictor = False

    def __len__(self) -> int:
        return self.points.shape[0]

    def evaluate(self, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stress and tangent at ``strain`` (m, nv) from the committed state; the trial state
        becomes the one of this evaluation. With :attr:`predictor`, the law's tangent of
        unloading where it has one."""
        stress, tangent, self.trial = self.law.update(strain, self.committed, self.band)
        unloading = getattr(self.law, "unloading_tangent", None)
        if self.predictor and unloading is not None:
            tangent = unloading(strain, self.committed, self.band)
        return stress, tangent

    def commit(self) -> None:
        """The trial state becomes the committed one (a converged step)."""
        self.committed = {k: v.copy() for k, v in self.trial.items()}
        self.version += 1

    def restore(self) -> None:
        """Drop the trial state (a cut step): back to the committed one."""
        self.trial = {k: v.copy() for k, v in self.committed.items()}
        self.version += 1

    def dissipated(self, weights: np.ndarray, trial: bool = False) -> float:
        """``sum_q D_q w_q``: the energy dissipated at these points (this rank's)."""
        state = self.trial if trial else self.committed
        return float(self.law.dissipated_energy(state) @ np.asarray(weights, dtype=float))


class BoundLaw:
    """A :class:`StatefulLaw` bound to the :class:`PointState` of one set of points, as a
    :class:`~dolfinx_meshfree.physics.constitutive.Material` (small strain: ``P = sigma(eps)``,
    ``eps = sym(F - I)``).

    ``first_piola`` and ``tangent`` evaluate the law from the committed state and leave the trial
    state of that evaluation in :attr:`state` (the last evaluation is kept, so a residual and a
    tangent at the same ``F`` and committed state run the law once).
    """

    def __init__(self, state: PointState):
        law = state.law
        self.law, self.state = law, state
        self.rho, self.plane, self.E, self.nu = law.rho, law.plane, law.E, law.nu
        self.density_given = getattr(law, "density_given", True)
        self._last: tuple[Any, np.ndarray, np.ndarray] | None = None

    @property
    def gdim(self) -> int:
        return self.law.gdim

    def _evaluate(self, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        F = np.asarray(F, dtype=float)
        d = self.gdim
        if F.ndim != 3 or F.shape != (len(self.state), d, d):
            raise ValueError(
                f"F should have shape ({len(self.state)}, {d}, {d}): the points this law's state "
                f"is kept at; got {F.shape}"
            )
        key = (self.state.version, self.state.predictor, F.tobytes())
        if self._last is None or self._last[0] != key:
            stress, tangent = self.state.evaluate(voigt_strain(F - np.eye(d)))
            self._last = (key, stress, tangent)
        return self._last[1], self._last[2]

    def first_piola(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        return tensor_from_voigt(self._evaluate(F)[0], self.gdim)

    def tangent(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        return tangent_from_voigt(self._evaluate(F)[1], self.gdim)

    def strain_energy_density(self, F: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """The recoverable energy at ``F`` with the trial state of the last evaluation."""
        d = self.gdim
        return self.law.stored_energy(voigt_strain(np.asarray(F) - np.eye(d)), self.state.trial)

    def ufl_first_piola(self, F: Any) -> Any:
        raise TypeError(
            f"{type(self.law).__name__} has internal state: it has no UFL expression; the FE "
            "cells evaluate it at their quadrature points (statics.fe_state.FEStateLaw)"
        )

    def wave_speed(self, F: np.ndarray | None = None) -> float:
        """The elastic dilatational speed (damage and plasticity only soften)."""
        return self.law.elastic().wave_speed()
