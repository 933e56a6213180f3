"""Laws with state in coupled models: the state store, its binding to the force code, the FE
cells' quadrature-point law, commit at converged steps, and path following past the peak.

The structural checks compare with closed forms: a bar in uniaxial tension (plane stress,
nu = 0) made of FE cells and a particle patch in the middle carries a uniform strain, which every
consistent coupling reproduces exactly, so its load-elongation curve is the law's bilinear
softening curve (Bazant & Oh 1983), ``sigma = E eps`` up to ``f_t``, then linear to 0 at
``eps_f = 2 G_f / (f_t h)``, with the residual stiffness ``(1 - max_damage) E`` once the damage
is capped; and the energy it dissipates is ``G_f / h`` per unit volume, less the capped tail
(written out here, not taken from the law). Path following (indirect displacement control)
must carry it through the peak to full softening. Every check runs serially and on 2 ranks.
"""

import warnings

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.physics.state import BoundLaw, PointState, tangent_from_voigt, voigt_strain

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

E, FT, GF = 1000.0, 1.0, 0.02
L, W = 2.0, 1.0


def _bar(n: int, coupling: str, cell: str = "quadrilateral", law=None, notch=None, **options):
    """The bar, its patch ``0.5 <= x <= 1.5``; ``notch``: a section 10 % narrower there (a
    Gaussian half a cell wide)."""
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [2 * n, n], getattr(dolfinx.mesh.CellType, cell)
    )
    if notch is not None:
        x = msh.geometry.x
        x[:, 1] *= 1.0 - 0.1 * np.exp(-(((x[:, 0] - notch) / (0.5 / n)) ** 2))
    V = _compat.vector_function_space(msh)
    mid = dolfinx.mesh.locate_entities(msh, 2, lambda p: (p[0] > 0.5 - 1e-9) & (p[0] < 1.5 + 1e-9))
    patch = mf.ParticlePatch(msh, mid, placement="vertices")
    law = law or mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")
    model = mf.CoupledElasticity(V, patch, law, coupling=coupling, **options)
    left = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0))
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    model.add_dirichlet(left, lambda p: np.zeros_like(p))
    model.add_traction(right, lambda p, nrm: np.tile([1.0, 0.0], (len(p), 1)))
    return model


def _closed_form(eps: np.ndarray, h: float, max_damage: float) -> np.ndarray:
    """Uniaxial stress of linear softening with the damage capped at ``max_damage``."""
    eps0, epsf = FT / E, 2.0 * GF / (FT * h)
    kappa = np.maximum(eps, eps0)
    D = 1.0 - (eps0 / kappa) * (epsf - kappa) / (epsf - eps0)
    D = np.clip(np.where(eps <= eps0, 0.0, D), 0.0, max_damage)
    return (1.0 - D) * E * eps


def _peak(path) -> float:
    """The curve's peak: the vertex of the parabola through the path's largest load factor and
    its two neighbours (an estimate of the continuous curve's, independent of where the steps
    fall). The largest step alone is off by up to 1e-3 on the bars here, where the steps near
    the peak lie 2e-3 to 3e-3 of control apart; comparisons between two paths whose steps
    fell differently measured that, not the models."""
    load = np.asarray(path.load_factor)
    k = int(np.argmax(load))
    assert 0 < k < len(load) - 1, "the path's peak is at its first or last step"
    c = np.polyfit(np.asarray(path.control[k - 1 : k + 2]), load[k - 1 : k + 2], 2)
    return float(c[2] - c[1] ** 2 / (4.0 * c[0]))


def _capped_dissipation(h: float, max_damage: float) -> float:
    """Energy per volume dissipated up to the cap: the work up to the strain where ``D`` reaches
    ``max_damage`` minus the energy stored there (written out from the bilinear curve)."""
    eps0, epsf = FT / E, 2.0 * GF / (FT * h)
    # D(k) = max_damage  <=>  (eps0 / k)(epsf - k) / (epsf - eps0) = 1 - max_damage
    r = (1.0 - max_damage) * (epsf - eps0) / eps0
    kc = epsf / (1.0 + r)
    work = 0.5 * FT * eps0 + FT * ((kc - eps0) - 0.5 * (kc - eps0) ** 2 / (epsf - eps0))
    return work - 0.5 * (1.0 - max_damage) * E * kc**2


@pytest.mark.parametrize(
    "coupling, cell, n",
    [
        ("lagrange", "quadrilateral", 4),
        ("edge-to-edge", "quadrilateral", 4),
        ("bridging", "triangle", 4),
        ("lagrange", "triangle", 3),
        ("ramp", "quadrilateral", 4),
        ("ramp-cubic", "triangle", 3),
    ],
)
def test_softening_bar_follows_the_closed_form_through_the_peak(coupling, cell, n):
    """Path following carries the coupled bar through the peak to full softening: the load
    factor on the closed-form curve at every step (1e-9 f_t), and the energy dissipated by the
    laws (FE and particle points) equal to the closed form and to the external work minus the
    stored energy."""
    # the particle points' band equal to the FE cells' (their size): one law everywhere, so
    # that the uniform strain is the solution through the softening
    model = _bar(n, coupling, cell, particle_band=1.0)
    h = 1.0 / n  # the cells' size (squares, or halves of them)
    law = model.law
    eps_f = 2.0 * GF / (FT * h)
    end = 1.25 * eps_f * L  # past full softening
    control = mf.DisplacementControl([[L, 0.5]], [[1.0, 0.0]])
    options = mf.PathOptions(increment=5e-4, end=end, max_increment=end / 20)
    res = mf.follow_path(model, control, options)
    eps = np.array(res.control) / L
    t = np.array(res.load_factor)
    assert np.abs(t - _closed_form(eps, h, law.max_damage)).max() < 1e-9 * FT
    assert eps.min() < FT / E < eps.max()  # the path went through the peak
    assert t[-1] < 0.05 * FT  # softened to the residual stiffness
    expected = _capped_dissipation(h, law.max_damage) * L * W
    assert res.dissipated_energy[-1] == pytest.approx(expected, rel=1e-9)
    # energy balance, independent of the laws' dissipation: trapezoidal external work (exact on
    # the piecewise-linear curve but for the step that crosses the peak) minus stored energy
    balance = res.external_work[-1] - res.stored_energy[-1]
    assert balance == pytest.approx(res.dissipated_energy[-1], rel=2e-3)
    # Newton's iterations stay few with the consistent tangent
    assert max(res.iterations) <= 6


@pytest.mark.all_cases
@pytest.mark.parametrize(
    "coupling, cell",
    [
        ("ramp", "quadrilateral"),
        ("ramp-cubic", "triangle"),
        ("lagrange", "quadrilateral"),
        ("edge-to-edge", "triangle"),
        ("bridging", "quadrilateral"),
        ("master-slave", "quadrilateral"),
    ],
)
def test_particle_band_is_the_dilation_by_default(coupling, cell):
    """With no ``particle_band``, every particle point's crack band is the MLS dilation times its
    cell's side (the documented default), and every FE or blended cell's its side: on the
    uniform bar the side is ``1 / n``, the dilation the coupling's default (2.0; the ramps' 2.5).
    The ramps' particle tables did not carry their MLS, and the band fell back to one cell, not
    2.5: their notched beam then dissipated 1.48 G_f per unit area and peaked 27 % above pure
    EFG's, silently (demos/concrete_beam.py --crack band --method ramp)."""
    n = 4
    model = _bar(n, coupling, cell)
    model.tractions = []
    right = mf.boundary_facets(model.V.mesh, lambda p: np.isclose(p[0], L))
    model.add_traction(right, lambda p, nrm: np.tile([0.5 * FT, 0.0], (len(p), 1)))
    states = model.solve(load_steps=1).states
    dilation = mf.DEFAULT_DILATION[coupling]
    assert dilation == (2.5 if coupling.startswith("ramp") else 2.0)
    in_patch = model.patch.in_patch
    inside = [st for st in states if in_patch[st.cells].all()]
    assert len(inside) == 1 and len(inside) < len(states)  # the particles' store, and the FE's
    for st in states:
        expected = (dilation if st is inside[0] else 1.0) / n
        assert np.allclose(st.band, expected, rtol=1e-12), (coupling, len(st))


def test_pure_efg_particle_band_is_its_dilation():
    """Pure EFG's particle points: the band is its dilation (given 2.5 here, the default 2.0)
    times the side of their integration cell, ``1 / n`` on the uniform bar, or
    ``particle_band`` times it when given (as a coupling's; pure EFG had no such option, so a
    coupled model and its pure EFG reference could not share a band other than the dilation).
    A band that is not a positive number is refused by name, by both models."""
    n = 4
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [2 * n, n], dolfinx.mesh.CellType.quadrilateral
    )
    particles = mf.ParticleSet.from_vertices(msh)
    law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")
    left = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0))
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    for band, expected in ((None, 2.5), (1.5, 1.5)):
        model = mf.EFGElasticity(particles, law, dilation=2.5, particle_band=band)
        model.add_dirichlet(left, lambda p: np.zeros_like(p))
        model.add_traction(right, lambda p, nrm: np.tile([0.5 * FT, 0.0], (len(p), 1)))
        (state,) = model.solve(load_steps=1).states
        assert np.allclose(state.band, expected / n, rtol=1e-12)
    for bad in (0.0, -1.0, np.inf, "2", True):
        match = rf"particle_band={bad!r} must be a positive number"
        with pytest.raises(ValueError, match=match):
            mf.EFGElasticity(particles, law, particle_band=bad)
        with pytest.raises(ValueError, match=match):
            _bar(2, "lagrange", particle_band=bad)


def test_load_steps_commit_the_state_and_unloading_is_elastic():
    """``CoupledElasticity.solve(load_steps=)`` commits the state at every converged step: a
    bar loaded below the peak (load control cannot pass it) has no damage; the states are kept
    on the solution."""
    model = _bar(3, "lagrange", particle_band=1.0)
    model.tractions = []
    right = mf.boundary_facets(model.V.mesh, lambda p: np.isclose(p[0], L))
    model.add_traction(right, lambda p, nrm: np.tile([0.9 * FT, 0.0], (len(p), 1)))
    sol = model.solve(load_steps=3)
    states = sol.states
    assert len(states) == 2  # the FE cells' and the particles'
    for st in states:
        kappa = st.committed["kappa"][:, 0]
        # the committed history: the strain of 0.9 f_t, below eps0 (kappa stays eps0)
        assert np.allclose(kappa, FT / E, rtol=1e-12)
        assert np.all(st.committed["damage"] == 0.0)
    u = sol.displacement(np.array([[L, 0.5]]))
    assert u[0, 0] == pytest.approx(0.9 * FT / E * L, rel=1e-10)


def test_bound_law_tangent_is_the_derivative_of_its_stress():
    """``BoundLaw`` (a law with state as a Material): ``A = dP/dF`` by central differences in
    every entry of ``F`` (1e-6), in the loading branch of damage and the plastic branch of J2,
    and ``P`` symmetric."""
    rng = np.random.default_rng(3)
    laws = [
        (mf.RankineDamage(E=E, nu=0.2, ft=FT, Gf=GF, plane="stress"), 2, 3e-3),
        (mf.RankineDamage(E=E, nu=0.2, ft=FT, Gf=GF, plane=None), 3, 3e-3),
        (mf.J2Plasticity(E=E, nu=0.3, sigma_y=FT, H=50.0, plane="strain"), 2, 4e-3),
    ]
    for law, d, scale in laws:
        m = 5
        H = scale * (np.eye(d)[None] + 0.3 * rng.standard_normal((m, d, d)))
        band = np.full(m, 0.05) if law.needs_band else None
        bound = BoundLaw(PointState(law, rng.random((m, d)), band))
        F = np.eye(d) + H
        P, A = bound.first_piola(F), bound.tangent(F)
        assert np.allclose(P, np.swapaxes(P, 1, 2))
        step = 1e-7 * scale
        fd = np.zeros_like(A)
        for k in range(d):
            for ll in range(d):
                dF = np.zeros((d, d))
                dF[k, ll] = step
                fd[:, :, :, k, ll] = (bound.first_piola(F + dF) - bound.first_piola(F - dF)) / (
                    2 * step
                )
        assert np.abs(fd - A).max() <= 1e-6 * np.abs(A).max(), type(law).__name__
        # the Voigt round trip of the binding
        eps = voigt_strain(H)
        Cv = law.update(eps, law.initial_state(m), band)[1]
        assert np.allclose(tangent_from_voigt(Cv, d), A)


def test_point_state_commits_and_restores():
    """The committed state changes only at ``commit``; ``restore`` drops the trial state; an
    evaluation never touches the committed arrays."""
    law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")
    st = PointState(law, np.zeros((2, 2)), np.full(2, 0.1))
    strain = np.array([[5e-3, 0.0, 0.0], [1e-4, 0.0, 0.0]])
    st.evaluate(strain)
    assert st.trial["damage"][0, 0] > 0.0
    assert np.all(st.committed["damage"] == 0.0)
    st.restore()
    assert np.all(st.trial["damage"] == 0.0)
    st.evaluate(strain)
    st.commit()
    committed = st.committed["damage"].copy()
    st.evaluate(0.5 * strain)  # unloading: the damage stays
    assert np.array_equal(st.trial["damage"], committed)
    assert np.array_equal(st.committed["damage"], committed)


def test_state_is_refused_where_it_is_not_carried():
    """A law with state is refused, with what to use instead, by explicit dynamics and by the
    user-UFL nonlinear problem (never run as if elastic); a band that would snap back locally
    is refused, naming the cell."""
    law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [8, 4], dolfinx.mesh.CellType.quadrilateral
    )
    V = _compat.vector_function_space(msh)
    mid = dolfinx.mesh.locate_entities(msh, 2, lambda p: p[0] < 1.0 + 1e-9)
    patch = mf.ParticlePatch(msh, mid, placement="vertices")
    with pytest.raises(TypeError, match=r"explicit dynamics does not carry state.*mf\.JohnsonCook"):
        mf.ExplicitDynamics.fe(V, law)
    with pytest.raises(TypeError, match="explicit dynamics does not carry state"):
        mf.ExplicitDynamics.coupled(mf.CoupledElasticity(V, patch, law, coupling="lagrange"))
    u = dolfinx.fem.Function(V)
    v = ufl.TestFunction(V)
    F = ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx
    with pytest.raises(TypeError, match="CoupledNonlinearProblem"):
        mf.CoupledNonlinearProblem(F, u, [], patch, law)
    cracked = mf.ParticlePatch(
        msh, mid, placement="vertices", cracks=[mf.Crack([[0.0, 0.55], [0.26, 0.55]])]
    )
    grow = mf.CoupledElasticity(V, cracked, law, coupling="lagrange")
    with pytest.raises(TypeError, match="QuasiStaticCrackGrowth"):
        mf.QuasiStaticCrackGrowth(grow, cracked.cracks[0], increment=0.1, steps=2, K_Ic=1.0)
    # a band that would snap back locally: cells of 0.25 above 2 E Gf / ft^2 = 0.2
    weak = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=1e-4, plane="stress")
    with pytest.raises(ValueError, match="snap"):
        mf.CoupledElasticity(V, patch, weak, coupling="lagrange").solve(load_steps=1)


def test_path_following_bad_input():
    """A control quantity that does not move, and bad options, are refused by name."""
    with pytest.raises(ValueError, match="increment=-1"):
        mf.PathOptions(increment=-1, end=1.0)
    with pytest.raises(ValueError, match=r"end=0\.001"):
        mf.PathOptions(increment=0.01, end=0.001)
    model = _bar(2, "lagrange")
    fixed = mf.DisplacementControl([[0.0, 0.5]], [[1.0, 0.0]])  # on the held end
    with pytest.raises(ValueError, match="does not move"):
        mf.follow_path(model, fixed, mf.PathOptions(increment=1e-4, end=1e-3))
    with pytest.raises(ValueError, match="directions"):
        mf.follow_path(
            model,
            mf.DisplacementControl([[1.0, 0.5]], [[0.0, 0.0]]),
            mf.PathOptions(increment=1e-4, end=1e-3),
        )


def test_a_path_cut_short_by_max_steps_says_so():
    """The elastic part of the bar's path from increments of 1e-4 to 1e-3: with max_steps=3 it
    stops at control 3.5e-4 (the increments grow by 1.5 on this easy stretch, from the second
    step on: 1e-4, 1e-4, 1.5e-4) and warns, naming max_steps and where it stopped; followed to
    the end it does not warn. Before, a path cut short by max_steps returned without a word."""
    model = _bar(2, "lagrange")
    control = mf.DisplacementControl([[L, 0.5]], [[1.0, 0.0]])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        short = mf.follow_path(model, control, mf.PathOptions(1e-4, 1e-3, max_steps=3))
        full = mf.follow_path(_bar(2, "lagrange"), control, mf.PathOptions(1e-4, 1e-3))
    warned = [w for w in caught if issubclass(w.category, mf.PathShortWarning)]
    assert len(short.control) == 3 and short.control[-1] == pytest.approx(3.5e-4, rel=1e-9)
    assert full.control[-1] == pytest.approx(1e-3, rel=1e-12)
    assert len(warned) == 1
    message = str(warned[0].message)
    assert "max_steps=3" in message and "at control 0.00035 of end=0.001" in message


def test_elastic_steps_store_the_work_under_gauss_integration():
    """The energy record in the elastic steps of a bar thinned in its patch (a non-uniform
    strain): with plain Gauss integration (a Galerkin system) the trapezoidal work of the load
    equals the laws' stored energy at the FE, particle and blended points to 1e-9 (measured
    3e-14). Under VCI, the default, the internal force has corrected test gradients and the
    two differ by a constant share: 1e-7 (lagrange) to 3e-4 (edge-to-edge) here, 1.12 % in the
    notched beam at h = 25 mm (docs/guide/softening.md, "Where the state lives")."""
    for coupling in ("ramp", "edge-to-edge"):
        model = _bar(4, coupling, "triangle", notch=1.125, integration="gauss")
        control = mf.DisplacementControl([[L, 0.5]], [[1.0, 0.0]])
        res = mf.follow_path(model, control, mf.PathOptions(increment=2e-4, end=1.5e-3))
        work, stored = np.array(res.external_work), np.array(res.stored_energy)
        assert len(work) >= 3 and max(res.dissipated_energy) == 0.0  # elastic
        assert np.all(np.abs(work - stored) <= 1e-9 * work), coupling


def test_localised_softening_is_objective_in_the_particle_spacing():
    """A bar that fails in its particle patch (a local damage law, band: the MLS dilation times
    the cell size, the default): the peak load and the energy dissipated up to the same opening
    across the band differ between spacings h and h / 2 by less than 0.3 % and 3 % (measured
    at 4 and 8 cells across: 0.10 % and 2.3 %, 0.09 % and 2.3 % before the first step's
    convergence test was fixed; the issue's target is 3 % for both)."""
    out = []
    for n in (4, 8):
        xc = 1.0 + 0.5 / n  # mid-cell
        model = _bar(n, "lagrange", notch=xc)
        control = mf.DisplacementControl([[xc - 0.3, 0.5], [xc + 0.3, 0.5]], [[-1, 0], [1, 0]])
        options = mf.PathOptions(increment=2e-4, end=0.05, min_load=0.15, max_increment=4e-3)
        res = mf.follow_path(model, control, options)
        out.append(res)
        assert res.band_cut is None  # the band keeps off the interface
        # the particle points dissipate it all (the FE cells stay elastic)
        fe, particles = res.solution.states
        assert np.all(fe.committed["damage"] == 0.0)
        assert particles.committed["damage"].max() > 0.99
        balance = res.external_work[-1] - res.stored_energy[-1]
        assert balance == pytest.approx(res.dissipated_energy[-1], rel=2e-2)
    common = min(r.control[-1] for r in out)  # the same opening
    d1, d2 = (np.interp(common, r.control, r.dissipated_energy) for r in out)
    p1, p2 = (r.peak[0] for r in out)
    print(f"peaks {p1:.5f} {p2:.5f}, dissipated at {common:.4f}: {d1:.6f} {d2:.6f}")
    assert abs(p2 - p1) <= 0.003 * p1
    assert abs(d2 - d1) <= 0.03 * d1


def test_a_band_cut_by_the_interface_is_named():
    """A bar thinned in the patch cell on the interface (x = 1.375, the interface at 1.5; n = 4,
    band 2 cells): the band cannot localise over its width there and dissipates 0.65 of
    ``G_f`` times the thinned section (measured; the same bar thinned at 1.125, two cells from
    the interface: 0.97); with the ramp (band 2.5 cells) it spills into the blended cells,
    whose band is one cell: 1.29. ``follow_path`` warns at the first step a fully softened
    particle point lies within a quarter cell of the interface with the cell across not
    softened (steps 8 and 10), the same step and point on 2 ranks, and records it in
    ``PathResult.band_cut``; the lagrange bar
    thinned at 1.125 (``test_localised_softening_is_objective_in_the_particle_spacing``) does
    not warn."""
    n, xc = 4, 1.375
    control = mf.DisplacementControl([[xc - 0.3, 0.5], [xc + 0.3, 0.5]], [[-1, 0], [1, 0]])
    options = mf.PathOptions(increment=2e-4, end=0.2, min_load=0.1, max_increment=4e-3)
    for coupling, first in (("lagrange", 8), ("ramp", 10)):
        model = _bar(n, coupling, notch=xc)
        with pytest.warns(mf.BandCutWarning, match="reached the FE interface at"):
            res = mf.follow_path(model, control, options)
        step, point, damage, across = res.band_cut
        assert step == first and 1.5 - 0.25 / n <= point[0] < 1.5
        assert damage >= 0.9 and across < 0.9
        assert res.load_factor[-1] < 0.1 * res.peak[0]  # softened through
        ratio = res.dissipated_energy[-1] / (GF * 0.9 * W)
        if coupling == "lagrange":
            assert ratio < 0.8  # cut short (0.65)
        else:
            assert ratio > 1.2  # the band spills into blended cells of band one cell (1.29)


def test_arc_length_follows_the_closed_form_and_a_snap_back():
    """Crisfield's arc length: (1) on the uniform bar it follows the closed-form softening curve
    (1e-9 f_t) against the end displacement, recorded as a monitor; (2) a bar failing in one
    band with a brittle law (G_f = 5e-4: its band of width h dissipates less than the rest of
    the bar releases, 2 E G_f / f_t^2 = 1 < L = 2) snaps back: the end displacement, which
    cannot control it, decreases along the path, and the arc length carries on past it to
    full softening with the energy balance (2 %)."""
    model = _bar(4, "lagrange", particle_band=1.0)
    end_u = mf.DisplacementControl([[L, 0.5]], [[1.0, 0.0]])
    h = 0.25
    eps_f = 2.0 * GF / (FT * h)
    opts = mf.PathOptions(increment=2e-4, end=2.0, min_load=0.05, max_increment=4e-3)
    res = mf.follow_path(model, mf.ArcLength(), opts, monitors={"u": end_u})
    eps = np.array(res.monitors["u"]) / L
    t = np.array(res.load_factor)
    assert eps.max() > 0.5 * eps_f and t.min() < 0.1 * FT  # through the softening
    assert np.abs(t - _closed_form(eps, h, model.law.max_damage)).max() < 1e-9 * FT

    brittle = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=5e-4, plane="stress")
    xc = 1.0 + 0.5 / 4
    model = _bar(4, "lagrange", law=brittle, notch=xc)
    res = mf.follow_path(
        model,
        mf.ArcLength(),
        mf.PathOptions(increment=1e-4, end=0.5, min_load=0.1, max_increment=1e-3),
        monitors={"u": end_u},
    )
    u = np.array(res.monitors["u"])
    k = int(np.argmax(res.load_factor))
    assert np.any(np.diff(u[k:]) < -1e-3 * u[k])  # the end moves back after the peak
    assert res.load_factor[-1] < 0.1 * res.load_factor[k]
    balance = res.external_work[-1] - res.stored_energy[-1]
    assert balance == pytest.approx(res.dissipated_energy[-1], rel=2e-2)
    # the end displacement cannot follow it: the step past the peak is refused, by name
    model = _bar(4, "lagrange", law=brittle, notch=xc)
    with pytest.raises(mf.PathError, match=r"at step \d+: from control"):
        mf.follow_path(model, end_u, mf.PathOptions(increment=1e-4, end=0.01, max_increment=1e-3))


def test_an_arc_length_without_a_root_is_refused_by_name():
    """An arc length whose constraint circle misses Newton's line at every increment tried (the
    brittle bar of the test above from an arc length of 0.02 and one cut: measured at step 1)
    stops with a ``PathError`` that names the step, the arc length and load factor it started
    from, the reason and the fix."""
    brittle = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=5e-4, plane="stress")
    model = _bar(4, "lagrange", law=brittle, notch=1.0 + 0.5 / 4)
    options = mf.PathOptions(increment=0.02, end=1.0, max_increment=0.02, max_cuts=1)
    match = r"at step 1: from arc length 0 .*found no real root; choose a smaller increment"
    with pytest.raises(mf.PathError, match=match):
        mf.follow_path(model, mf.ArcLength(), options)


def _plane_strain_point(law, traction: float, steps: int) -> tuple[np.ndarray, dict]:
    """The plane-strain material point ``eps = (e_xx, e_yy, 0)`` with ``sigma = (t_k, 0, *)``
    at ``t_k = k / steps`` of ``traction``, by Newton on the law's update, committed per step."""
    state = law.initial_state(1)
    e = np.zeros(2)
    for k in range(1, steps + 1):
        target = np.array([traction * k / steps, 0.0])
        for _ in range(30):
            s, C, trial = law.update(np.array([[e[0], e[1], 0.0]]), state)
            r = s[0, :2] - target
            if np.abs(r).max() <= 1e-13 * traction:
                break
            e -= np.linalg.solve(C[0, :2, :2], r)
        state = trial
    return e, state


@pytest.mark.parametrize(
    "coupling, plane",
    [
        ("lagrange", "strain"),
        ("edge-to-edge", "strain"),
        ("bridging", "strain"),
        ("lagrange", "stress"),
        ("ramp", "stress"),
        ("bridging", "stress"),
    ],
)
def test_plastic_bar_reproduces_the_material_point(coupling, plane):
    """J2 plasticity with hardening in a coupled bar (rollers on x = 0 and y = 0, a traction on
    x = L past yield, in load steps): the strain is uniform, so the end displacements equal
    those of one material point under the same stress path to 1e-9; the plastic strain
    committed at every FE and particle point is that point's. A wrong commit (none, or of a
    rejected trial) or a wrong tangent mapping would show. Plane strain: the material point
    solved apart here (sigma_xx = t, sigma_yy = 0 by Newton on the law's update at every load
    step, committing as the solver does). Plane stress: uniaxial stress in closed form,
    ``alpha = (t - sigma_y) / H``, ``e_xx = t / E + alpha``, ``e_yy = -nu t / E - alpha / 2``."""
    law = mf.J2Plasticity(E=E, nu=0.3, sigma_y=FT, H=100.0, plane=plane)
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [8, 4], dolfinx.mesh.CellType.quadrilateral
    )
    V = _compat.vector_function_space(msh)
    mid = dolfinx.mesh.locate_entities(msh, 2, lambda p: (p[0] > 0.5 - 1e-9) & (p[0] < 1.5 + 1e-9))
    patch = mf.ParticlePatch(msh, mid, placement="vertices")
    model = mf.CoupledElasticity(V, patch, law, coupling=coupling)
    left = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0))
    bottom = mf.boundary_facets(msh, lambda p: np.isclose(p[1], 0.0))
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    model.add_dirichlet(left, lambda x: np.zeros_like(x), components=(0,))
    model.add_dirichlet(bottom, lambda x: np.zeros_like(x), components=(1,))
    traction = 1.6 * FT  # past the uniaxial yield stress (plane strain: ~1.0-1.1 sigma_y)
    model.add_traction(right, lambda x, n: np.tile([traction, 0.0], (len(x), 1)))
    steps = 4
    sol = model.solve(load_steps=steps)
    if plane == "stress":  # uniaxial stress in closed form
        alpha = (traction - FT) / law.H
        e = np.array([traction / E + alpha, -law.nu * traction / E - alpha / 2])
        state = {"alpha": np.array([[alpha]])}
    else:
        e, state = _plane_strain_point(law, traction, steps)
    assert state["alpha"][0, 0] > 0.0  # it yielded
    pts = np.array([[L, 0.0], [L, W], [1.0, W]])
    u = sol.displacement(pts)
    expected = np.array([[e[0] * L, 0.0], [e[0] * L, e[1] * W], [e[0] * 1.0, e[1] * W]])
    assert np.abs(u - expected).max() <= 1e-9 * abs(e[0]) * L
    for st in sol.states:
        assert np.allclose(st.committed["alpha"], state["alpha"][0, 0], rtol=1e-9)


def test_softening_bar_in_3d():
    """The uniform bar in 3D (hexahedra, lagrange, plane=None): the closed-form softening curve
    through the peak to 1e-9 f_t (measured 4e-14; tetrahedra 5e-14, not run here for time)."""
    n = 2
    msh = dolfinx.mesh.create_box(
        MPI.COMM_WORLD, [np.zeros(3), np.array([L, W, W])], [2 * n, n, n],
        dolfinx.mesh.CellType.hexahedron,
    )  # fmt: skip
    V = _compat.vector_function_space(msh)
    mid = dolfinx.mesh.locate_entities(msh, 3, lambda p: (p[0] > 0.5 - 1e-9) & (p[0] < 1.5 + 1e-9))
    patch = mf.ParticlePatch(msh, mid, placement="vertices")
    # the law's default plane="stress" on a 3D mesh: refused, naming the user's class
    planar = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF)
    with pytest.raises(ValueError, match=r"gdim=3; use RankineDamage\(\.\.\., plane=None"):
        mf.CoupledElasticity(V, patch, planar, coupling="lagrange")
    law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane=None)
    model = mf.CoupledElasticity(V, patch, law, coupling="lagrange", particle_band=1.0)
    left = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0))
    right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
    model.add_dirichlet(left, lambda x: np.zeros_like(x))
    model.add_traction(right, lambda x, nrm: np.tile([1.0, 0.0, 0.0], (len(x), 1)))
    h = W / n
    eps_f = 2 * GF / (FT * h)
    control = mf.DisplacementControl([[L, 0.5, 0.5]], [[1.0, 0.0, 0.0]])
    options = mf.PathOptions(increment=5e-4, end=1.25 * eps_f * L, max_increment=eps_f * L / 16)
    res = mf.follow_path(model, control, options)
    eps = np.array(res.control) / L
    t = np.array(res.load_factor)
    assert t[-1] < 0.05 * FT
    assert np.abs(t - _closed_form(eps, h, law.max_damage)).max() < 1e-9 * FT


def test_a_users_ufl_model_with_a_law_with_state():
    """The bar written as a DOLFINx user writes it (``a`` the elastic form, ``L`` the traction,
    a ``DirichletBC``) with ``CoupledLinearProblem(..., material=RankineDamage)``, followed past
    the peak by ``mf.follow_path(problem.model, ...)``: the closed-form curve to 1e-9 f_t. An
    ``a`` that is not the law's elastic form on the FE cells is refused (the law acts there)."""
    n = 4
    msh = dolfinx.mesh.create_rectangle(
        MPI.COMM_WORLD, [[0, 0], [L, W]], [2 * n, n], dolfinx.mesh.CellType.quadrilateral
    )
    V = _compat.vector_function_space(msh)
    law = mf.RankineDamage(E=E, nu=0.0, ft=FT, Gf=GF, plane="stress")

    def forms(E_fe: float):
        u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        x = ufl.SpatialCoordinate(msh)
        E_x = ufl.conditional(ufl.And(ufl.gt(x[0], 0.5), ufl.lt(x[0], 1.5)), E, E_fe)
        elastic = law.elastic()
        sigma = E_x / E * elastic.ufl_stress(u)
        a = ufl.inner(sigma, ufl.sym(ufl.grad(v))) * ufl.dx
        right = mf.boundary_facets(msh, lambda p: np.isclose(p[0], L))
        tags = dolfinx.mesh.meshtags(msh, 1, right, np.full(right.size, 1, dtype=np.int32))
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        L_form = ufl.inner(dolfinx.fem.Constant(msh, np.array([1.0, 0.0])), v) * ds(1)
        return a, L_form

    left = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 0.0))
    bc = dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, left), V)
    mid = dolfinx.mesh.locate_entities(msh, 2, lambda p: (p[0] > 0.5 - 1e-9) & (p[0] < 1.5 + 1e-9))
    patch = mf.ParticlePatch(msh, mid, placement="vertices")
    a, L_form = forms(E)
    problem = mf.CoupledLinearProblem(a, L_form, [bc], patch, law, particle_band=1.0)
    h = 1.0 / n
    eps_f = 2.0 * GF / (FT * h)
    control = mf.DisplacementControl([[L, 0.5]], [[1.0, 0.0]])
    options = mf.PathOptions(increment=5e-4, end=1.25 * eps_f * L, max_increment=eps_f * L / 20)
    res = mf.follow_path(problem.model, control, options)
    eps = np.array(res.control) / L
    t = np.array(res.load_factor)
    assert t[-1] < 0.05 * FT
    assert np.abs(t - _closed_form(eps, h, law.max_damage)).max() < 1e-9 * FT
    # a stiffer FE region in a: the law (which acts on the FE cells) does not encode it
    a2, _ = forms(2.0 * E)
    with pytest.raises(ValueError, match="on every cell"):
        mf.CoupledLinearProblem(a2, L_form, [bc], patch, law)
