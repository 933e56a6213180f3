"""Bifurcations along a followed path (``statics.bifurcation``): the sign of the bordered
tangent's determinant, ``sign(det K) sign(dg/dt)``, per converged step of ``mf.follow_path``.

The structural check is a beam whose damage can localise in one band or grow in two mirror
bands: an unnotched beam in three-point bending, crack band damage, controlled by the opening
of its bottom edge across mid-span. On a mirror-symmetric mesh of quadrilaterals the path keeps
the symmetric branch (two bands), stiffer and stronger than the localised one of the same beam
on triangles (one band); only the first may warn.

Serial and 2 ranks (the determinant is MUMPS's, global; ``dg/dt`` is global).
"""

import warnings

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.statics.bifurcation import (
    BIFURCATION_STEPS,
    StabilityWatch,
    bordered_sign,
)

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI


def test_the_watch_warns_only_on_a_kept_flip():
    """``bordered_sign`` multiplies the signs of ``det K`` and ``dg/dt`` (``None`` unknown);
    the watch measures each step's sign from the first's, forgets a flip that lasts fewer than
    ``BIFURCATION_STEPS`` steps, warns once (naming the run's first step) when one lasts that
    long, and starts again from the next step's sign after ``reset`` (a rebuilt model)."""
    assert bordered_sign(-1.0, -2.0) == 1.0 and bordered_sign(1.0, -2.0) == -1.0
    assert bordered_sign(None, 1.0) is None and bordered_sign(1.0, 0.0) is None
    watch = StabilityWatch()
    signs = [-1.0, -1.0, 1.0, 1.0, -1.0] + [-1.0] * (BIFURCATION_STEPS - 2) + [None, -1.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        relative = [watch.record(s, k, 0.1 * k, 1.0) for k, s in enumerate(signs)]
    # measured from the first step's -1: the 1s are flips, each run shorter than the limit
    assert relative[:5] == [1.0, 1.0, -1.0, -1.0, 1.0] and relative[-2] is None
    with pytest.warns(mf.BifurcationWarning, match=r"at step 2 \(control 0\.2, load factor 1\)"):
        watch.record(1.0, 2, 0.2, 1.0)
        for k in range(3, 3 + BIFURCATION_STEPS - 1):
            watch.record(1.0, k, 0.1 * k, 1.0)
    assert watch.warned_at == 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per path
        watch.record(1.0, 20, 2.0, 1.0)
        watch.reset()
        assert [watch.record(1.0, 21 + k, 2.1, 1.0) for k in range(6)] == [1.0] * 6


L, D, H = 400.0, 100.0, 10.0  # span, depth, cell size (mm)


def _beam(cell: str):
    """The unnotched beam, 40 x 10 cells of 10 mm, crack band damage (concrete, plane stress),
    pinned at the bottom left, on a roller at the bottom right, 1 N/mm over the top's middle
    20 mm, followed to a CMOD of 0.1 mm over the bottom's middle 40 mm (FE cells only: the
    package's FE reference, ``mf.FEElasticity``)."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, D]], [40, 10], getattr(dolfinx.mesh.CellType, cell)
    )
    law = mf.RankineDamage(E=30e3, nu=0.2, ft=3.0, Gf=0.1, plane="stress")
    model = mf.FEElasticity(_compat.vector_function_space(msh), law)
    left = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.0) & (x[0] <= H + 1e-9))
    right = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.0) & (x[0] >= L - H - 1e-9))
    top = mf.boundary_facets(msh, lambda x: np.isclose(x[1], D) & (abs(x[0] - L / 2) <= H + 1e-9))
    model.add_dirichlet(left, np.zeros_like)
    model.add_dirichlet(right, np.zeros_like, components=(1,))
    model.add_traction(top, lambda x, n: np.tile([0.0, -1.0 / (2 * H)], (len(x), 1)))
    cmod = mf.DisplacementControl([[L / 2 - 20, 0.0], [L / 2 + 20, 0.0]], [[-1, 0], [1, 0]])
    return mf.follow_path(model, cmod, mf.PathOptions(increment=5e-4, end=0.1))


def _longest_flip(stability) -> int:
    run = longest = 0
    for s in stability:
        run = run + 1 if s is not None and s < 0 else 0
        longest = max(longest, run)
    return longest


def test_a_mirror_symmetric_beam_keeps_its_symmetric_branch_and_warns():
    """On the mirror-symmetric quadrilaterals the damage grows in two mirror bands (the two
    middle columns, x = 195 and 205 mm, 0.477 of the dissipation each) and the path keeps that
    branch: the bordered determinant's sign flips at step 6 (load factor 80, before the peak)
    and stays flipped for 7 steps (then 6 steps as at the start and 7 flipped again: a second
    unstable mode, whose parity the sign does not see), ``BifurcationWarning`` names step 6, and
    the peak, 103.6 N/mm, is 6.7 % above the triangles' 97.1. On triangles (their diagonals
    break the symmetry) the damage localises in one column (190 to 200 mm, 0.96 of it) and the
    sign never flips: no warning. Checked: the warning and a flip of at least
    ``BIFURCATION_STEPS`` steps on quadrilaterals (``PathResult.bifurcation``: step 6), none on
    triangles, and the quadrilaterals' peak above the triangles' by 3 % at least."""
    with pytest.warns(mf.BifurcationWarning, match=r"crossed a bifurcation at step 6 \("):
        quads = _beam("quadrilateral")
    assert _longest_flip(quads.stability) >= BIFURCATION_STEPS and quads.bifurcation == 6
    with warnings.catch_warnings():
        warnings.simplefilter("error", mf.BifurcationWarning)
        triangles = _beam("triangle")
    assert _longest_flip(triangles.stability) < BIFURCATION_STEPS
    assert triangles.bifurcation is None
    assert len(triangles.stability) == len(triangles.control)
    assert max(quads.load_factor) > 1.03 * max(triangles.load_factor)


def test_arc_length_on_the_beam_is_watched_too():
    """With Crisfield's arc length (the sign is ``sign(det K)`` times the step's load increment's,
    which turn together at a limit point) the beam on triangles leaves the localised path that
    CMOD control follows: its peak is 106.3 N/mm against 97.1, the sign flips at step 13 (load
    factor 89, before the peak) and stays flipped past the peak to the end (20 steps), and
    ``BifurcationWarning`` says so. Checked: the warning, and the peak above CMOD control's by
    4 % at least (measured 9.5 %)."""
    given = mf.follow_path

    def arc(model, control, options):
        options = mf.PathOptions(increment=0.01, end=5.0, min_load=0.3, max_increment=0.1)
        return given(model, mf.ArcLength(), options, monitors={"cmod": control})

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(mf, "follow_path", arc)
        with pytest.warns(mf.BifurcationWarning, match=r"crossed a bifurcation at step 13 \("):
            path = _beam("triangle")
    assert path.bifurcation == 13 and _longest_flip(path.stability) >= BIFURCATION_STEPS
    localised = _beam("triangle")  # CMOD control
    assert max(path.load_factor) > 1.04 * max(localised.load_factor)
