"""A grown segment the crack-aware MLS cannot carry is turned a little (dynamic growth by K_Ic,
``dynamics/growth_probe.py``): on a plate where the criterion's segment leaves points with only
collinear particles (the model cannot be built on it: the check can fail), the turned segment
builds; a segment the MLS carries is not turned; the row test on a grid; growth runs that
stopped there now run through, with the turn recorded, and ``fit_segments=False`` keeps the
paper's segments. Serial and 2 ranks (the probe is collective)."""

from __future__ import annotations

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx.mls import MomentMatrixError
from dolfinx_meshfree.dynamics import DynamicCrackGrowth
from dolfinx_meshfree.dynamics.growth_probe import TURNS, _on_a_row, turn_to_fit

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

COMM = MPI.COMM_WORLD
MAT = mf.LinearElastic(E=200e9, nu=0.3, plane="strain", rho=7800.0)
L, HH, H = 0.2, 0.12, 0.004
#: A crack grown on the plate by ``DynamicCrackGrowth`` (pure EFG on quadrilaterals, a random
#: user set-up): its tip ended 0.005 spacing off the particle row y = 0.044, and the criterion's
#: next segment, to (0.0918, 0.04489), passes 0.03 spacing past the row's particle (0.08, 0.044).
TRAPPED = np.array([[0.0, 0.05523], [0.05, 0.0471], [0.06392, 0.04563], [0.07783, 0.04398]])
NEXT = np.array([0.0918, 0.04489])


@pytest.fixture(scope="module")
def plate():
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.array([0.0, 0.0]), np.array([L, HH])], [round(L / H), round(HH / H)],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    return msh, mf.ParticleSet.from_cells(msh, H)


def _kink(points: np.ndarray, to: np.ndarray) -> float:
    """The kink angle (radians) from the last segment of ``points`` to the point ``to``."""
    t = points[-1] - points[-2]
    d = to - points[-1]
    return float(np.arctan2(t[0] * d[1] - t[1] * d[0], t @ d))


def _builds(particles, points: np.ndarray, theta: float) -> bool:
    crack = mf.Crack(points)
    crack.extend(theta, 3.5 * H, tip=-1)
    try:
        mf.ExplicitDynamics.efg(particles, MAT, cracks=[crack]).destroy()
    except MomentMatrixError:
        return False
    return True


@pytest.mark.filterwarnings("ignore::dolfinx_meshfree.geometry.crack.CrackPlacementWarning")
def test_a_segment_the_mls_cannot_carry_is_turned(plate):
    """The criterion's segment (10.5 degrees) cannot be built on; the probe turns it by the
    first turn that can (-5 degrees, measured), and the model builds on the turned one."""
    _, P = plate
    crack = mf.Crack(TRAPPED)
    dyn = mf.ExplicitDynamics.efg(P, MAT, cracks=[crack])
    theta = _kink(TRAPPED, NEXT)
    assert not _builds(P, TRAPPED, theta)  # the check can fail: the plain segment is refused
    turn = turn_to_fit(dyn, crack, -1, theta, 3.5 * H, 7)
    assert turn in TURNS and turn != 0.0
    assert _builds(P, TRAPPED, theta + np.deg2rad(turn))
    assert np.array_equal(crack.points, TRAPPED)  # the probe leaves the crack alone
    # a segment the MLS carries, from a tip off the rows: not turned
    free = np.array([[0.0, 0.0622], [0.05, 0.0706]])
    clear = mf.Crack(free)
    dyn2 = mf.ExplicitDynamics.efg(P, MAT, cracks=[clear])
    assert turn_to_fit(dyn2, clear, -1, 0.2, 3.5 * H, 7) == 0.0
    dyn.destroy()
    dyn2.destroy()


def test_a_tip_on_a_row():
    """On a grid of spacing 1: a tip 0.005 off a row, midway between two particles, reached at
    4 degrees to the row is on it; reached at 60 degrees (across the row), or 0.3 off it, it
    is not; 0.05 from a particle it is (whatever the direction)."""
    g = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0)), axis=-1).reshape(-1, 2)
    along = np.array([np.cos(np.deg2rad(4.0)), np.sin(np.deg2rad(4.0))])
    across = np.array([np.cos(np.deg2rad(60.0)), np.sin(np.deg2rad(60.0))])
    assert _on_a_row(np.array([4.5, 5.005]), along, g, 1.0)
    assert not _on_a_row(np.array([4.5, 5.005]), across, g, 1.0)
    assert not _on_a_row(np.array([4.5, 5.3]), along, g, 1.0)
    assert _on_a_row(np.array([4.03, 5.04]), across, g, 1.0)


#: One draw of the user set-up (``numpy.random.default_rng(2)``): the crack's start height,
#: its angle (radians) and the right edge's traction relative to the top's.
DRAW = (0.05523224268498633, -0.16120708526870137, 0.8699580184159961)


def _growth(plate, y0: float, angle: float, tx: float, **kw) -> DynamicCrackGrowth:
    """Pure EFG on the plate, an edge crack from (0, y0) at ``angle`` (radians) to x = 0.05,
    sudden tractions on the top (100 MPa) and right (``tx`` of it) edges, K_Ic = 2 MPa m^0.5,
    segments of 3.5 spacings at 1000 m/s."""
    msh, P = plate
    tip = np.array([0.05, y0 + 0.05 * np.tan(angle)])

    def build(crack):
        dyn = mf.ExplicitDynamics.efg(P, MAT, cracks=[crack])
        top = mf.boundary_facets(msh, lambda x: np.isclose(x[1], HH))
        right = mf.boundary_facets(msh, lambda x: np.isclose(x[0], L))
        dyn.add_traction(top, lambda x, n: 100e6 * n)
        dyn.add_traction(right, lambda x, n: tx * 100e6 * n)
        return dyn

    return DynamicCrackGrowth(
        build, mf.Crack([[0.0, y0], tip]), K_Ic=2.0e6, speed=1000.0, segment=3.5 * H,
        check_every=5, radius=[2 * H, 3 * H], **kw,
    )  # fmt: skip


@pytest.mark.filterwarnings("ignore::dolfinx_meshfree.geometry.crack.CrackPlacementWarning")
def test_a_growth_that_stopped_runs_through_with_a_turn(plate):
    """A growth that stopped at its third extension (the trapped tip above: a refused model)
    with the paper's segments (``fit_segments=False``) runs to the end with the probe, one
    segment turned by 5 degrees, the others the criterion's; serially and on 2 ranks."""
    plain = _growth(plate, *DRAW, fit_segments=False)
    with pytest.raises(MomentMatrixError):
        plain.run(60e-6)
    g = _growth(plate, *DRAW)
    g.run(60e-6)
    turns = [c.turn for c in g.history if c.extended]
    assert len(turns) >= 3 and sorted(np.abs(turns))[-1] in (5.0, 10.0, 15.0)
    assert sum(t != 0.0 for t in turns) == 1
    with pytest.raises(ValueError, match="fit_segments='yes' must be True or False"):
        _growth(plate, *DRAW, fit_segments="yes")
