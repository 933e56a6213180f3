"""Reliability of the stress intensity factors (issue 23, items 1 and 14, and their class).

Item 1: moving an edge crack by 0.05-0.1 of the particle spacing relative to the particle rows
changed K_I with ``crack_enrichment=True`` (reported: -26 % to +11 %; measured here over the
default domains: -7 % to +70 %) while ``path_dependence`` stayed near 0.1 % (as low as 0.03 %).
The cause: the enriched MLS (seven basis functions) had supports of 3 spacings; a point
next to a crack face on the far side of a row that lies 0.05-0.1 spacing from the crack sees
only the rows 1 and 2 spacings away on its side (the third at the edge of its support), its
moment matrix is nearly singular in the ramp region (shape functions up to 44 in magnitude), and
the stiffness of that band is under-integrated (a cut cell held 15x more energy at degree 30
than at degree 7): a spurious mode. Dilation 4 (``approx/tip_enrichment.py``) removes it.
Item 14: the default domains (now 8-16 spacings) give a spread of about 0.1 %.

Oracles: Tada's K_I of the single edge crack (to 0.5 %) at every offset of the crack from the
particle rows, or a :class:`SIFReliabilityWarning`: a test that fails if a wrong K comes out
silently; the old enrichment (dilation 3) gives wrong K's that the indicator must flag (the
check can fail); J = (K_I^2 + K_II^2)/E' on exact Williams fields and on a correct solution;
the default domains' shrinking and refusal by the geometry.

The model: plate [0, 1] x [-1, 1] (H/W = 2), edge crack a = 0.3 (a/W = 0.3), remote tension
1, Q1 cells of 0.025, a particle patch of spacing 0.0125 around the crack coupled by
``lagrange`` in a user's UFL model (``CoupledLinearProblem``), the rigid motions removed by
three scalar conditions at the bottom corners (statically determinate).
"""

from __future__ import annotations

import dataclasses
import functools
import warnings

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.fracture.interaction import (
    DOMAIN_DEPENDENCE_LIMIT,
    ENERGY_MISMATCH_LIMIT,
    SIFReliabilityWarning,
    StressIntensityFactors,
    interaction_integral,
)
from dolfinx_meshfree.fracture.williams import WilliamsField

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

COMM = MPI.COMM_WORLD
MAT = mf.LinearElastic(1000.0, 0.3, plane="strain")
W, HT, A = 1.0, 2.0, 0.3  # plate width, height; crack length
CELL, S = 0.025, 0.0125  # cell size, particle spacing (the particle rows are y = k S)
MARGIN = 0.25  # the patch: x < A + MARGIN, |y - y0| < MARGIN (20 spacings)
K_TADA = float(mf.edge_crack_factor(A / W)) * np.sqrt(np.pi * A)  # sigma = 1


def _forms(msh):
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(MAT.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    facets, tags = [], []
    for k, y in enumerate((HT / 2, -HT / 2)):
        f = dolfinx.mesh.locate_entities_boundary(msh, 1, lambda x, y=y: np.isclose(x[1], y))
        facets.append(f)
        tags.append(np.full(f.size, k + 1, np.int32))
    f, t = np.concatenate(facets), np.concatenate(tags)
    order = np.argsort(f)
    tagged = dolfinx.mesh.meshtags(msh, 1, f[order], t[order])
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tagged)
    L = ufl.dot(dolfinx.fem.Constant(msh, np.array([0.0, 1.0])), v) * ds(1)
    L = L + ufl.dot(dolfinx.fem.Constant(msh, np.array([0.0, -1.0])), v) * ds(2)

    def vertex(p):
        return dolfinx.mesh.locate_entities_boundary(
            msh, 0, lambda x: np.isclose(x[0], p[0]) & np.isclose(x[1], p[1])
        )

    pin = dolfinx.fem.locate_dofs_topological(V, 0, vertex((0.0, -HT / 2)))
    roll = dolfinx.fem.locate_dofs_topological(V.sub(1), 0, vertex((W, -HT / 2)))
    bcs = [
        dolfinx.fem.dirichletbc(np.zeros(2), pin, V),
        dolfinx.fem.dirichletbc(np.float64(0.0), roll, V.sub(1)),
    ]
    return a, L, bcs


def edge_crack(offset: float, enrich: bool):
    """Solve with the crack on ``y = offset * S`` (a fraction of a spacing off the row y = 0).
    Returns ``(solution, crack)``."""
    y0 = offset * S
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.array([0.0, -HT / 2]), np.array([W, HT / 2])],
        [round(W / CELL), round(HT / CELL)], dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    cells = np.flatnonzero((mid[:, 0] < A + MARGIN) & (np.abs(mid[:, 1] - y0) < MARGIN))
    crack = mf.Crack([[0.0, y0], [A, y0]])
    patch = mf.ParticlePatch(msh, cells, S, cracks=[crack], crack_enrichment=enrich)
    a, L, bcs = _forms(msh)
    sol = mf.CoupledLinearProblem(a, L, bcs, patch, material=MAT, coupling="lagrange").solve()
    return sol, crack


def sifs_and_warning(sol, crack, **kw) -> tuple[StressIntensityFactors, bool]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sif = sol.stress_intensity_factors(crack, **kw)
    warned = [w for w in caught if issubclass(w.category, SIFReliabilityWarning)]
    return sif, bool(warned)


@functools.cache
def solved(offset: float, enrich: bool):
    """:func:`edge_crack`, solved once per module run (the tests share the solutions)."""
    return edge_crack(offset, enrich)


# --- item 1: the crack's offset from the particle rows -----------------------------------------

#: |K_I / K_Tada - 1| allowed: Tada's formula is good to 0.5 %; measured worst over the offsets
#: 0.05 .. 0.95 at this spacing (tip on a particle column): enriched 0.83 % (check 1.5 %);
#: linear basis -1.85 % at 0.05 spacing, -1.06 % .. -1.38 % elsewhere (check 3 %: its
#: discretisation error, smooth, which no consistency check can see; it falls with h).
TOLERANCE = {True: 0.015, False: 0.03}


@pytest.mark.parametrize("enrich", [True, False], ids=["enriched", "linear"])
def test_offset_sweep_gives_tada_or_warns(enrich):
    """The crack at 0, 0.05, 0.1, 0.25, 0.5 spacing from the particle row y = 0 (the true K
    unchanged): each K_I (default domains) is within the tolerance of Tada's value, or a
    SIFReliabilityWarning says it is not reliable. Offset 0 (particles on the crack) is refused.
    Measured enriched: -0.83, +0.03, -0.13, +0.44 %, no warning (the old enrichment gave
    -7.2 % and +2.3 % at 0.05 and 0.1); linear: -1.85, -1.28, -1.06, -1.09 %, no warning."""
    with pytest.raises(ValueError, match="particle"):
        edge_crack(0.0, enrich)
    for offset in (0.05, 0.1, 0.25, 0.5):
        sol, crack = solved(offset, enrich)
        sif, warned = sifs_and_warning(sol, crack)
        error = sif.K_I.mean() / K_TADA - 1.0
        assert abs(error) <= TOLERANCE[enrich] or warned, (offset, error, sif)
        if enrich:  # the fix: accurate and not flagged at every offset
            assert abs(error) <= TOLERANCE[True] and not warned, (offset, error, sif)


def test_indicator_flags_the_wrong_k_of_the_old_enrichment(monkeypatch):
    """The enrichment of dilation 3 (before issue 23) at offsets 0.05 and 0.1 spacing: K_I off
    by -7.2 % and +2.3 % (measured; the spread over the default domains only 1.35 % and 0.03 %).
    The indicator must warn (measured: domain dependence 8.4 % and 1.40 %, limit 1 %; J vs K
    21.8 % and 0.39 %, limit 5 %), on every rank."""
    from dolfinx_meshfree.approx.tip_enrichment import enrich_tips
    from dolfinx_meshfree.statics import coupled

    monkeypatch.setattr(coupled, "enrich_tips", functools.partial(enrich_tips, dilation=3.0))
    for offset, figure in ((0.05, "domain dependence"), (0.1, "domain dependence")):
        sol, crack = edge_crack(offset, True)
        with pytest.warns(SIFReliabilityWarning, match=figure):
            sif = sol.stress_intensity_factors(crack)
        assert abs(sif.K_I.mean() / K_TADA - 1.0) > TOLERANCE[True]  # really wrong
        assert not sif.reliable and sif.domain_dependence > DOMAIN_DEPENDENCE_LIMIT


# --- item 14: the default domains --------------------------------------------------------------


def test_default_domains_spread_about_a_tenth_of_a_percent():
    """Default domains r2 = 8 .. 16 spacings: path dependence 0.092 % and 0.049 % (enriched,
    offsets 0.25 and 0.5), 0.026 %, 0.054 % (linear); check 0.2 %. The earlier default
    (r2 = 3, 4, 5 spacings, 8 x 32 points) on the same fields: 1.05 %, 1.06 %, 0.69 %, 0.48 %,
    9 to 26 times more (check 4 times: the size of the domains is what changed)."""
    for enrich in (True, False):
        for offset in (0.25, 0.5):
            sol, crack = solved(offset, enrich)
            sif, _ = sifs_and_warning(sol, crack)
            np.testing.assert_allclose(sif.outer, np.array([8, 10, 12, 14, 16]) * S)
            np.testing.assert_allclose(sif.inner, 0.5 * sif.outer)
            np.testing.assert_allclose(sif.probe.outer, np.array([4, 5]) * S)
            assert sif.path_dependence <= 2e-3, (enrich, offset, sif)
            old, _ = sifs_and_warning(sol, crack, radius=np.array([3.0, 4.0, 5.0]) * S)
            assert old.path_dependence > 4.0 * sif.path_dependence


def test_j_agrees_with_k_on_a_correct_solution():
    """J = (K_I^2 + K_II^2)/E' domain by domain (the same domain integral, no K in J): energy
    mismatch measured 0.196 % (enriched) and 0.155 % (linear) at offset 0.5; check 0.4 %."""
    for enrich in (True, False):
        sol, crack = solved(0.5, enrich)
        sif, warned = sifs_and_warning(sol, crack)
        assert not warned and sif.reliable
        assert sif.energy_mismatch <= 4e-3, (enrich, sif)
        G = (sif.K_I**2 + sif.K_II**2) / sif.E_prime
        assert np.abs(sif.J / G - 1.0).max() <= 4e-3


# --- the figures on exact fields and by hand ----------------------------------------------------


@pytest.mark.serial
def test_figures_vanish_on_the_exact_williams_field():
    """Mixed-mode Williams field with T-stress and higher terms: K exact on every domain and the
    probe, J = (K_I^2 + K_II^2)/E': both figures below 1e-10 (measured ~1e-14), reliable."""
    mat = mf.LinearElastic(1000.0, 0.3, plane="strain")
    tip, angle = np.array([3.0, -2.0]), np.radians(130.0)
    d = np.array([np.cos(angle), np.sin(angle)])
    w = WilliamsField(mat, 2.3, -1.1, tip=tip, direction=d, T=4.0, higher=(0.7 - 0.3j, 0.5j))
    res = interaction_integral(w.displacement_gradient, mat, tip, d, [1.0, 1.5, 2.0, 0.5, 0.6])
    sif = dataclasses.replace(res.select(slice(0, 3)), probe=res.select(slice(3, None)))
    assert sif.path_dependence < 1e-10 and sif.near_tip_deviation < 1e-10
    assert sif.energy_mismatch < 1e-10 and sif.reliable
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert sif.warn() is False


@pytest.mark.serial
def test_figures_and_warning_by_hand():
    """The figures from given K's and J's, the verdict at the limits, the warning's text (value,
    limit, fix), the summary, repr and dict; J_comparable=False leaves J out."""
    Ep = 1000.0
    K = np.array([1.0, 1.002, 0.999])

    def make(KI, J=None, probe=None, comparable=True):
        J = KI**2 / Ep if J is None else J
        z = np.zeros_like(KI)
        return StressIntensityFactors(
            inner=0.5 * np.arange(1.0, 1.0 + KI.size), outer=np.arange(1.0, 1.0 + KI.size),
            K_I=KI, K_II=z, J=J, E_prime=Ep, tip=np.zeros(2), direction=np.array([1.0, 0.0]),
            probe=probe, J_comparable=comparable,
        )  # fmt: skip

    plain = make(K)
    assert plain.path_dependence == pytest.approx(0.003 / K.mean())
    assert np.isnan(plain.near_tip_deviation) and plain.energy_mismatch < 1e-15
    assert plain.domain_dependence == plain.path_dependence and plain.reliable
    off = make(K, probe=make(np.array([1.02, 1.03])))  # mean 1.025: 2.47 % off
    assert off.near_tip_deviation == pytest.approx(1.025 / K.mean() - 1.0)
    assert off.domain_dependence == off.near_tip_deviation and not off.reliable
    with pytest.warns(SIFReliabilityWarning, match=r"domain dependence 2\.47 % > 1 %.*refine"):
        assert off.warn() is True
    j_off = make(K, J=1.06 * K**2 / Ep)  # J 6 % above (K_I^2)/E'
    assert j_off.energy_mismatch == pytest.approx(0.06, rel=0.01) and not j_off.reliable
    assert "J and (K_I^2 + K_II^2)/E' differ by 6" in j_off.warning_message()
    assert make(K, J=1.04 * K**2 / Ep).reliable  # 4 %: within the limit
    blind = make(K, J=1.06 * K**2 / Ep, comparable=False)
    assert np.isnan(blind.energy_mismatch) and blind.reliable
    for text in (repr(off), off.summary()):
        assert "domain dependence 2.47 % (limit 1 %)" in text and "NOT RELIABLE" in text
    assert "(probe)" in off.summary() and "reliable" in repr(plain)
    d = off.as_dict()
    assert d["reliable"] is False and d["probe"]["KI"] == [1.02, 1.03]
    assert DOMAIN_DEPENDENCE_LIMIT == 0.01 and ENERGY_MISMATCH_LIMIT == 0.05


# --- the default domains follow the geometry --------------------------------------------------


def efg_plate(tip_x: float):
    """Pure EFG on the unit square (spacing 0.05), an edge crack from the left edge at
    y = 0.525 (half a spacing off the rows) to ``tip_x``, the faces loaded by sigma_yy = 1 on
    the boundary."""
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.ones(2)], [20, 20], dolfinx.mesh.CellType.quadrilateral
    )
    crack = mf.Crack([[0.0, 0.525], [tip_x, 0.525]])
    prob = mf.EFGElasticity(mf.ParticleSet.from_cells(msh, 0.05), MAT, cracks=[crack])
    G = np.array([[-MAT.nu, 0.0], [0.0, 1.0]]) * (1 - MAT.nu**2) / MAT.E  # sigma_yy = 1
    prob.add_dirichlet(mf.boundary_facets(msh), lambda x: np.asarray(x)[:, :2] @ G.T)
    return prob.solve(), crack


def test_default_domains_shrink_to_fit_and_refuse_below_the_minimum():
    """Tip at (0.5, 0.525): the top edge 0.475 away (9.5 spacings): the defaults 8 .. 16
    spacings shrink by 8.5/16 (one spacing of clearance). Tip at (0.8, 0.525): the right edge
    4 spacings away: refused (minimum 5 + 1), naming the distance and the fix; an explicit
    radius is still taken, without a probe (it does not fit)."""
    sol, crack = efg_plate(0.5)
    sif, _ = sifs_and_warning(sol, crack)
    np.testing.assert_allclose(sif.outer, np.array([8, 10, 12, 14, 16]) * 0.05 * 8.5 / 16)
    np.testing.assert_allclose(sif.probe.outer, [0.2, 0.25])
    sol, crack = efg_plate(0.8)
    with pytest.raises(ValueError, match=r"need the tip 6 particle spacings .* 0\.2 away .*"
                       r"enlarge the particle patch .* radius="):  # fmt: skip
        sol.stress_intensity_factors(crack)
    sif, _ = sifs_and_warning(sol, crack, radius=[0.1, 0.15])
    assert sif.probe is None and np.isnan(sif.near_tip_deviation)


# --- dynamics: the figures, no warning ---------------------------------------------------------


def test_dynamic_sifs_carry_the_figures_without_warning():
    """Explicit dynamics: K(t) passes through zero (here at t = 0, before any load), so no
    warning is issued; the result carries the probe and the figures all the same."""
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.ones(2)], [20, 20], dolfinx.mesh.CellType.quadrilateral
    )
    crack = mf.Crack([[0.2, 0.475], [0.6, 0.475]])  # tip 1: the other tip 8 spacings away
    dyn = mf.ExplicitDynamics.efg(
        mf.ParticleSet.from_cells(msh, 0.05), mf.LinearElastic(1000.0, 0.3, rho=1.0),
        cracks=[crack], safety=0.5,
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error", SIFReliabilityWarning)
        at_rest = dyn.stress_intensity_factors(crack, tip=1)  # K = 0: figures meaningless
        dyn.set_initial(velocity=lambda x: np.stack([0 * x[:, 0], x[:, 1] - 0.5], axis=1))
        dyn.run(20 * dyn.stable_time_step())
        moving = dyn.stress_intensity_factors(crack, tip=1)
    dyn.destroy()
    assert np.all(at_rest.K_I == 0.0) and at_rest.probe is not None
    assert moving.probe is not None and np.isfinite(moving.domain_dependence)
    assert np.isfinite(moving.energy_mismatch) and moving.K_I.mean() > 0
