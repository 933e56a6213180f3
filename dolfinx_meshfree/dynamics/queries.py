"""What a running explicit model can be asked: the displacement and velocity at points, at
quadrature points and as DOLFINx Functions, their L2 errors against an exact field (Rabczuk et
al. 2006, eq. 137), the latest energy record and the dynamic stress intensity factors.

:class:`StateQueries` is the base of :class:`~dolfinx_meshfree.ExplicitDynamics`, which owns
the state it reads: ``u`` (``d_n``), ``stepper`` (the velocities and the energy records),
``evaluator`` (:class:`~dolfinx_meshfree.dynamics.evaluation.FieldEvaluator`), ``V`` and
``time``.
"""

from __future__ import annotations

from collections.abc import Callable

import dolfinx
import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

from ..fracture.interaction import StressIntensityFactors
from ..geometry.crack import Crack
from ..geometry.quadrature import QuadraturePoints
from .energy import EnergyRecord
from .evaluation import FieldEvaluator
from .sifs import dynamic_sifs

__all__ = ["StateQueries"]


class StateQueries:
    """Queries of the current state of an explicit model (the base of
    :class:`~dolfinx_meshfree.ExplicitDynamics`; see the module docstring for what it reads)."""

    evaluator: FieldEvaluator
    u: list[PETSc.Vec]
    V: dolfinx.fem.FunctionSpace | None

    def _current(self) -> list[PETSc.Vec]:
        """The velocity vectors at the current time (``v_n`` at outputs and after a run)."""
        return self.stepper.current_velocity()

    def _local_values(self, vecs: list[PETSc.Vec], particles: bool = True) -> tuple:
        """(FE Function with ghosts or None, particle coefficients (n, gdim) or None)."""
        return self.evaluator.local_values(vecs, particles)

    def velocity_at(self, points: npt.ArrayLike) -> np.ndarray:
        """Velocity (m, gdim) at this rank's points, which may lie anywhere in the mesh
        (collective). Raises :class:`~dolfinx_meshfree.PointsOutsideMeshError` on every rank if
        a point is outside the body."""
        return self.evaluator.at_points(self._current(), points)

    def displacement_at(self, points: npt.ArrayLike) -> np.ndarray:
        """Displacement (m, gdim) at this rank's points, like :meth:`velocity_at` (collective)."""
        return self.evaluator.at_points(self.u, points)

    def fe_functions(self) -> tuple[dolfinx.fem.Function, dolfinx.fem.Function]:
        """The FE displacement and velocity at the current time as new DOLFINx Functions named
        ``"displacement"`` and ``"velocity"`` (ghosts updated; collective). FE nodes outside
        the FE field (touched by patch cells only) hold zero.

        Raises:
            ValueError: the model has no FE field (pure EFG).
        """
        if self.V is None:
            raise ValueError("this model has no FE field (pure EFG): no FE functions")
        u = self.evaluator.fe_function(self.u, "displacement")
        return u, self.evaluator.fe_function(self._current(), "velocity")

    @property
    def energy_record(self) -> EnergyRecord | None:
        """The latest :class:`EnergyRecord` (at an output time: that step's), or ``None``."""
        records = self.stepper.records
        return records[-1] if records else None

    def velocity_at_quadrature(self, degree: int = 5) -> tuple[QuadraturePoints, np.ndarray]:
        """Cell quadrature of degree ``degree`` on the owned cells and the velocity (nq, gdim)
        there: FE on FE cells, MLS on particle cells, blended on ramp interface and bridging
        band cells (tables cached; collective)."""
        return self.evaluator.at_quadrature(self._current(), degree)

    def velocity_error(
        self, exact: Callable[[np.ndarray, float], np.ndarray], degree: int = 5
    ) -> float:
        """Relative L2 velocity error ``|v_h - v| / |v|`` at the current time (Rabczuk et al.
        2006, eq. 137), integrated on the owned cells (collective, same on every rank).

        Args:
            exact: ``exact(points (m, gdim), t) -> (m, gdim)``.
        """
        return self.evaluator.relative_error(self._current(), exact, self.time, degree)

    def displacement_error(
        self, exact: Callable[[np.ndarray, float], np.ndarray], degree: int = 5
    ) -> float:
        """Relative L2 displacement error ``|u_h - u| / |u|`` at the current time, like
        :meth:`velocity_error` (collective, same on every rank).

        Args:
            exact: ``exact(points (m, gdim), t) -> (m, gdim)``.
        """
        return self.evaluator.relative_error(self.u, exact, self.time, degree)

    def stress_intensity_factors(
        self, crack: Crack, tip: int | np.ndarray = 0, radius: float | None = None, **options
    ) -> StressIntensityFactors:
        """K_I, K_II and J at a stationary tip of ``crack`` at the current state (at an output
        or after a run) by the interaction integral with the inertia term, from ``d_n`` and the
        acceleration ``a_n`` (collective): see :func:`~dolfinx_meshfree.dynamics.sifs.dynamic_sifs`.
        """
        return dynamic_sifs(self, crack, tip, radius, **options)
