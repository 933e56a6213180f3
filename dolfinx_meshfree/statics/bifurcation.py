"""Bifurcations along a followed path: the sign of the bordered system's determinant.

Indirect displacement control (:func:`~dolfinx_meshfree.follow_path`) solves ``R(u, t) = 0``,
``g(u) = tau`` for the displacement ``u`` and the load factor ``t``: Newton's bordered Jacobian
is ``[[K, -q], [c^T, 0]]`` (``K`` the tangent, ``q`` the reference load, ``c`` the control's
functional), whose determinant is ``det K (c . K^-1 q)`` by its Schur complement, and ``c .
K^-1 q`` is the control's growth per unit load along the tangent, ``dg/dt``. Its sign therefore
comes with each factorisation (MUMPS's determinant, ICNTL(33), and the sign of ``g(db)`` that
the step computes anyway):

- it is regular at a peak of the load, where ``det K`` and ``dg/dt`` change sign together: that
  is why the control passes peaks that load control cannot;
- it is singular where ``K`` has a null vector that does not move the control, a bifurcation
  (the classic test along a load path: the tangent's determinant changes sign at a limit point
  and at a bifurcation; bordered by the control, only at a bifurcation), and crossing it
  changes its sign. Past it the equilibrium at a fixed control value is unstable (the tangent
  with the control held gains a negative eigenvalue): a body with any imperfection leaves that
  branch.

The case that showed it, a user's model: an unnotched concrete beam in three-point bending
on a mirror-symmetric mesh of quadrilaterals, crack band damage, controlled by the opening of
its bottom edge. The damage grew in the two middle columns instead of one and the path kept
that symmetric branch, silently, its energy record balanced: at 5 mm cells its peak was 105.3
N/mm against 92.7 for the lagrange coupling on the same mesh (whose particles localise) and
90.8 for FE triangles, the sign flipped for 20 steps; at 10 mm cells 103.6 against the
triangles' 97.1 (``tests/test_bifurcation.py``). Localising paths cross such points too, for a
step or two, before round-off and the mesh's own asymmetry take them onto the localised branch.

The sign sees an odd number of unstable modes only: a branch with two is seen as stable, so a
flipped run can end while the branch stays unstable (the uniform bars below flip on and off).
Over the test suite's 127 paths (before ``tests/test_bifurcation.py``) 19 keep the sign flipped
for :data:`BIFURCATION_STEPS` steps or more (18 under a control, 1 by arc length), each on a
branch past a bifurcation by design: the bars of the closed-form checks, whose
cells all soften at once (the closed form is that uniform branch's curve), and bars with a
notched column or a straight cohesive crack whose band opens evenly while their loaded end is
free to rotate (an uneven opening is the other branch). The concrete beams (Petersson's, the
shear beam; given and found cracks) never flip.

With Crisfield's arc length the load factor is an unknown of its own and passes peaks by itself:
there ``det K`` changes sign at a limit point together with the step's load increment, and at a
bifurcation alone, so the watched sign is ``sign(det K)`` times the load increment's. On the
beam above (10 mm triangles) arc length did not follow CMOD control's localised path: its peak
was 106.3 N/mm against 97.1, the sign flipped at step 13 and stayed flipped past the peak.

:class:`StabilityWatch` keeps the sign per converged step, relative to the path's first (the
Lagrange multipliers' saddle point gives ``det K`` a sign of its own) and warns
(:class:`BifurcationWarning`) when the path stays on the flipped side for
:data:`BIFURCATION_STEPS` steps.
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["BIFURCATION_STEPS", "BifurcationWarning", "StabilityWatch", "bordered_sign"]


class BifurcationWarning(UserWarning):
    """The followed path crossed a bifurcation and stayed on the branch past it
    (:class:`StabilityWatch`): its equilibrium at fixed control is unstable there, so the curve
    past it is not one a body with any imperfection follows."""


#: Consecutive converged steps with the bordered determinant's sign flipped after which
#: :class:`BifurcationWarning` is raised. Measured: the localising beams' crossings last 1 or 2
#: steps (lagrange on triangles and quadrilaterals; FE triangles none), the coupled uniform bars'
#: 2 to 5; the symmetric beam's 7 (10 mm cells) and 20 (5 mm).
BIFURCATION_STEPS = 4


def bordered_sign(det_k: float | None, dg_dt: float) -> float | None:
    """The sign of the bordered Jacobian's determinant, ``sign(det K) sign(dg/dt)`` (with arc
    length, ``dg_dt`` the step's load increment); ``None`` where the solver gave no determinant
    (an iterative solve)."""
    if det_k is None or not np.isfinite(dg_dt) or dg_dt == 0.0:
        return None
    return float(det_k) * (1.0 if dg_dt > 0.0 else -1.0)


class StabilityWatch:
    """The sign of the bordered determinant along a path, relative to its first converged
    step's (or to the first after :meth:`reset`), with the warning of a branch kept past a
    bifurcation. The signs are global (MUMPS's determinant, a global ``dg/dt``): every rank
    decides alike."""

    def __init__(self) -> None:
        self.reference: float | None = None
        self.run = 0  # consecutive steps with the sign flipped
        self.first: tuple[int, float, float] | None = None  # (step, control, load) of the run
        #: The step where the flipped run that warned began (``None``: no warning).
        self.warned_at: int | None = None

    def reset(self) -> None:
        """The model changed (a crack grew, the patch grew: other multipliers): the next step's
        sign is the new reference."""
        self.reference, self.run, self.first = None, 0, None

    def record(self, sign: float | None, step: int, control: float, load: float) -> float | None:
        """Record a converged step's sign (:func:`bordered_sign`); returns it relative to the
        reference (+1 as at the start, -1 flipped, ``None`` unknown), and warns once per path
        when the flipped run reaches :data:`BIFURCATION_STEPS`."""
        if sign is None:
            self.run, self.first = 0, None
            return None
        if self.reference is None:
            self.reference = sign
        relative = sign * self.reference
        if relative > 0.0:
            self.run, self.first = 0, None
            return relative
        self.run += 1
        if self.first is None:
            self.first = (step, control, load)
        if self.run >= BIFURCATION_STEPS and self.warned_at is None:
            k, c, t = self.first
            self.warned_at = k
            warnings.warn(
                f"the path crossed a bifurcation at step {k} (control {c:.6g}, load factor "
                f"{t:.6g}) and has stayed on the branch past it for {self.run} steps: the "
                "determinant of the bordered tangent changed sign without a limit point, so "
                "the equilibrium at fixed control is unstable there and a body with any "
                "imperfection leaves this branch (a mirror-symmetric body whose damage grows "
                "in two mirror bands instead of localising in one). The curve past that step "
                "is not the body's: break the symmetry, e.g. a mesh without the mirror "
                "(triangles) or a small notch where the failure should start "
                "(PathResult.stability)",
                BifurcationWarning,
                stacklevel=3,
            )
        return relative
