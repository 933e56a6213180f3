"""Rate-form laws' point work compiled: the HJC and Johnson–Cook updates, HJC's wave speed, the
nominal stress and the smallest principal stretch.

:meth:`~dolfinx_meshfree.physics.hjc.HolmquistJohnsonCook.update` written with numpy (the
reference) evaluates the step as about a hundred whole-array operations, each a pass over
every point with its temporaries; on a Hanchak shot they were most of the run (``hjc.update``
17 s of a 25 s profile, ``loading_pressure`` 62 us a call). Here the same step is one loop
over the points, each taken from ``F`` to its stress and new state before the next:

* the Hughes–Winget kinematics of :mod:`~dolfinx_meshfree.physics.objective` (Hughes & Winget
  1980, eq. 25–32): the mid-step inverse by cofactors, ``d eps``, the half rotation ``Q_h`` as
  the Cayley transform of the half-angle skew matrix, ``s_rot = Q_h s_n Q_h^T`` (:func:`_start`,
  shared by both laws);
* HJC (Holmquist, Johnson & Cook 1993): the equation of state (eq. 3–5; ``pressure``,
  ``permanent_strain``), the strength (eq. 1; ``strength``), the radial return and the damage
  (eq. 2; ``failure_strain``), ``Q_h s_mid Q_h^T``, the trapezoidal stress work, and the
  erosion (the ``hjc`` module docstring): a point eroded before, inverted (``det F <= 0``) or
  not finite is computed at rest and keeps its committed state; one worn through is zeroed;
* Johnson–Cook (Johnson & Cook 1983, eq. 1 without temperature): the radial return's root by
  Newton's steps safeguarded by the bracket (:func:`_jc_return`; the reference bisects 60
  times to the same root), only at yielding points; ``p = -K ln J``.

The operations are the reference's, in its order (but Johnson–Cook's root finder); its orders
of summation differ (LAPACK's ``det``, numpy's stacked products), so the two agree to
round-off, not to the bit
(``tests/test_rate_kernels.py`` compares them over every region of the equation of state,
tension, damage, erosion and the three kinds of models). The backend is the law's
``backend`` (``"numba"`` by default with numba; ``DOLFINX_MESHFREE_LAW_BACKEND`` overrides).

A point the compiled pass cannot take (an inverted or non-finite ``F`` without erosion, a
singular mid-step gradient) is flagged, not raised on: the law then runs the reference, whose
messages name the point.
"""

from __future__ import annotations

import numpy as np

from ..approx import jit as _jit
from ..approx.jit import jit

__all__ = [
    "BACKENDS",
    "DEFAULT_BACKEND",
    "ENV",
    "JC_PARAMETERS",
    "PARAMETERS",
    "cofactor3",
    "det3",
    "hjc_update",
    "hjc_wave_speed",
    "johnson_cook_update",
    "nominal_stress",
    "resolve_backend",
    "smallest_stretches",
]

BACKENDS = ("numba", "numpy")
ENV = "DOLFINX_MESHFREE_LAW_BACKEND"
#: ``"numba"`` when numba is importable, else ``"numpy"`` (the reference);
#: ``DOLFINX_MESHFREE_LAW_BACKEND`` (``numba`` or ``numpy``) overrides it.
DEFAULT_BACKEND = _jit.default_backend(ENV)

#: The order of the parameters in the array the kernel takes (:func:`hjc_update`).
PARAMETERS = (
    "G", "A", "B", "N", "C", "fc", "T", "efmin", "sfmax", "p_crush", "mu_crush", "p_lock",
    "mu_lock", "D1", "D2", "K1", "K2", "K3", "eps0", "mu_plock", "K_elastic", "rho",
)  # fmt: skip


def resolve_backend(backend: str | None) -> str:
    """The backend to use: ``backend`` or :data:`DEFAULT_BACKEND`, checked."""
    return _jit.resolve_backend(DEFAULT_BACKEND if backend is None else backend, ENV, BACKENDS)


@jit
def _loading(c, mu):  # pragma: no cover - compiled
    """The loading curve's pressure at ``mu`` (``loading_pressure``)."""
    if mu <= c[10]:
        return c[20] * mu
    if mu <= c[19]:
        return c[9] + (c[11] - c[9]) * (mu - c[10]) / (c[19] - c[10])
    x = (mu - c[12]) / (1.0 + c[12])
    return c[15] * x + c[16] * x * x + c[17] * (x * x * x)


@jit
def _tangent(c, mu):  # pragma: no cover - compiled
    """``dP/dmu`` on the loading curve (``loading_tangent``)."""
    if mu <= c[10]:
        return c[20]
    if mu <= c[19]:
        return (c[11] - c[9]) / (c[19] - c[10])
    x = (mu - c[12]) / (1.0 + c[12])
    return (c[15] + 2.0 * c[16] * x + 3.0 * c[17] * x * x) / (1.0 + c[12])


@jit
def _unloading(c, mu_max):  # pragma: no cover - compiled
    """The unloading modulus from ``mu_max`` (``unloading_modulus``)."""
    if mu_max <= c[19]:
        frac = min(max((mu_max - c[10]) / (c[19] - c[10]), 0.0), 1.0)
        return (1.0 - frac) * c[20] + frac * c[15]
    return max(c[15], _tangent(c, mu_max))


@jit
def _strength(c, p_star, damage, rate):  # pragma: no cover - compiled
    """The normalised strength ``sigma*`` (``strength``)."""
    intact = c[1] * (1.0 - damage)
    if p_star >= 0.0:
        s = intact + c[2] * max(p_star, 0.0) ** c[3]
    else:
        s = intact + c[1] * p_star * c[5] / c[6]
    s *= 1.0 + c[4] * np.log(max(rate / c[18], 1.0))
    return min(max(s, 0.0), c[8])


@jit
def det3(a: np.ndarray) -> float:  # pragma: no cover - compiled
    """``a_0 . (a_1 x a_2)`` of a 3 x 3 matrix (``objective.inverse_3x3``'s), compiled."""
    return (
        a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
        + a[0, 1] * (a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2])
        + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0])
    )


@jit
def _rotate(Q, s, work, out):  # pragma: no cover - compiled
    """``out = Q s Q^T`` (3 x 3; ``work`` 3 x 3 scratch)."""
    for i in range(3):
        for k in range(3):
            work[i, k] = Q[i, 0] * s[0, k] + Q[i, 1] * s[1, k] + Q[i, 2] * s[2, k]
    for i in range(3):
        for j in range(3):
            out[i, j] = work[i, 0] * Q[j, 0] + work[i, 1] * Q[j, 1] + work[i, 2] * Q[j, 2]


@jit
def _gradient(F, hoop, q, out):  # pragma: no cover - compiled
    """``out``: point ``q``'s gradient of ``F`` (m, d, d) in 3D (``objective.as_3d``: ``F_zz``
    the hoop stretch ``hoop[q]``, or 1 where ``hoop`` is empty); returns whether it is finite."""
    d = F.shape[1]
    for i in range(3):
        for j in range(3):
            out[i, j] = F[q, i, j] if i < d and j < d else (1.0 if i == j else 0.0)
    if d == 2 and hoop.shape[0]:
        out[2, 2] = hoop[q]
    finite = True
    for i in range(3):
        for j in range(3):
            if not np.isfinite(out[i, j]):
                finite = False
    return finite


@jit
def _start(Fo, Fn, s_old, G, scratch, de, Qh, sr, st):  # pragma: no cover - compiled
    """The Hughes–Winget step from ``Fo`` to ``Fn`` (``objective._kinematics``,
    ``RateStep.start``) and the trial deviator of shear modulus ``G``: ``de`` (d eps), ``Qh``,
    ``sr = Q_h s_old Q_h^T`` and ``st = sr + 2 G dev(d eps)``; returns ``(det F_{n+1/2},
    dev(d eps) : dev(d eps), st : st)``, the first ``<= 0`` (or nan) when the mid-step gradient
    is singular (then nothing else is filled). ``scratch`` (4, 3, 3)."""
    Fm, inv, W = scratch[0], scratch[1], scratch[2]
    for i in range(3):
        for j in range(3):
            Fm[i, j] = 0.5 * (Fo[i, j] + Fn[i, j])
    J_mid = det3(Fm)
    if not (J_mid > 0.0):
        return J_mid, 0.0, 0.0
    for i in range(3):  # inv[:, i] = (row i+1) x (row i+2) / det
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for k in range(3):
            k1, k2 = (k + 1) % 3, (k + 2) % 3
            inv[k, i] = (Fm[i1, k1] * Fm[i2, k2] - Fm[i1, k2] * Fm[i2, k1]) / J_mid
    Gr = Fm  # no longer needed
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += (Fn[i, k] - Fo[i, k]) * inv[k, j]
            Gr[i, j] = acc
    for i in range(3):
        for j in range(3):
            de[i, j] = 0.5 * (Gr[i, j] + Gr[j, i])
            W[i, j] = 0.25 * (Gr[i, j] - Gr[j, i])
    w2 = W[2, 1] ** 2 + W[0, 2] ** 2 + W[1, 0] ** 2
    half = 1.0 + np.sqrt(1.0 + w2)
    for i in range(3):
        for j in range(3):
            W[i, j] = W[i, j] / half
    scale = 2.0 / (1.0 + (W[2, 1] * W[2, 1] + W[0, 2] * W[0, 2] + W[1, 0] * W[1, 0]))
    for i in range(3):
        for j in range(3):
            ww = 0.0
            for k in range(3):
                ww += W[i, k] * W[k, j]
            Qh[i, j] = (1.0 if i == j else 0.0) + scale * (W[i, j] + ww)
    _rotate(Qh, s_old, scratch[3], sr)
    trace = (de[0, 0] + de[1, 1] + de[2, 2]) / 3.0
    ee = 0.0
    qq = 0.0
    for i in range(3):
        for j in range(3):
            e = de[i, j] - (trace if i == j else 0.0)
            ee += e * e
            st[i, j] = sr[i, j] + 2.0 * G * e
            qq += st[i, j] * st[i, j]
    return J_mid, ee, qq


@jit
def _arrays():  # pragma: no cover - compiled
    """A kernel's 3 x 3 work arrays, each its own allocation: ``Fn, Fo, de, Qh, so, sr, st, sm,
    sn`` and the (4, 3, 3) scratch of :func:`_start`."""
    Fn, Fo, de, Qh = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    so, sr, st = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    sm, sn = np.empty((3, 3)), np.empty((3, 3))
    return Fn, Fo, de, Qh, so, sr, st, sm, sn, np.empty((4, 3, 3))


@jit
def _work(sr, p_old, sm, p, de):  # pragma: no cover - compiled
    """``(sigma_n + sigma_{n+1}) / 2 : d eps`` in the mid-step frame (``RateStep.work``
    without its ``J_{n+1/2}``)."""
    work = 0.0
    for i in range(3):
        for j in range(3):
            eye = 1.0 if i == j else 0.0
            work += 0.5 * ((sr[i, j] - p_old * eye) + (sm[i, j] - p * eye)) * de[i, j]
    return work


@jit
def _kernel(c, erosion, F, hoop, dt, old, sigma, new, flags):  # pragma: no cover - compiled
    """The step of every point (module docstring). ``old``/``new``: the state's arrays in the
    order of ``HolmquistJohnsonCook.state_fields``: deviator (m, 9) 0, pressure 1, mu_max 2,
    mu_plastic 3, plastic_strain 4, damage 5, work 6 (each (m, 1)), F (m, 9) 7, eroded (m, 1)
    8. ``flags[q]``: 1 where ``F`` is not finite or inverted (no erosion), 2 where the
    mid-step gradient is singular."""
    m = F.shape[0]
    G = c[0]
    Fn, Fo, de, Qh, so, sr, st, sm, sn, scratch = _arrays()
    for q in range(m):
        finite = _gradient(F, hoop, q, Fn)
        gone = erosion > 0.0 and (old[8][q, 0] > 0.0 or not finite or not (det3(Fn) > 0.0))
        if gone:  # computed at rest; the eroded keep the gradient given
            for i in range(3):
                for j in range(3):
                    new[7][q, 3 * i + j] = Fn[i, j]
                    Fn[i, j] = Fo[i, j] = 1.0 if i == j else 0.0
        elif not finite or not (det3(Fn) > 0.0):
            flags[q] = 1
            continue
        else:
            for i in range(9):
                Fo[i // 3, i % 3] = old[7][q, i]
                new[7][q, i] = Fn[i // 3, i % 3]
        J = det3(Fn)
        for i in range(9):
            so[i // 3, i % 3] = old[0][q, i]
        J_mid, ee, qq = _start(Fo, Fn, so, G, scratch, de, Qh, sr, st)
        if not (J_mid > 0.0):
            flags[q] = 2
            continue
        # the equation of state (pressure, permanent_strain)
        damage = old[5][q, 0]
        mu = 1.0 / J - 1.0
        mu_max = max(old[2][q, 0], mu)
        p_max = _loading(c, mu_max)
        K_unload = _unloading(c, mu_max)
        p = p_max if mu >= mu_max else p_max - K_unload * (mu_max - mu)
        p = max(p, -c[6] * (1.0 - damage))
        mu_p = 0.0 if mu_max <= c[10] else max(mu_max - p_max / K_unload, 0.0)
        mu_p = max(mu_p, old[3][q, 0])
        d_mu_p = mu_p - old[3][q, 0]
        # the strength, the radial return, the damage
        rate = np.sqrt(2.0 / 3.0 * ee) / dt
        sigma_y = c[5] * _strength(c, p / c[5], damage, rate)
        qt = np.sqrt(1.5 * qq)
        yielding = qt > sigma_y
        ratio = sigma_y / qt if yielding else 1.0
        for i in range(3):
            for j in range(3):
                sm[i, j] = ratio * st[i, j]
        _rotate(Qh, sm, scratch[0], sn)
        d_eps_p = (qt - sigma_y) / (3.0 * G) if yielding else 0.0
        s_f = max(p / c[5] + c[6] / c[5], 0.0)
        eps_f = max(c[7], c[13] * s_f ** c[14])
        d_damage = (d_eps_p + d_mu_p) / eps_f
        work = _work(sr, old[1][q, 0], sm, p, de)
        for i in range(3):
            for j in range(3):
                sigma[q, i, j] = sn[i, j] - (p if i == j else 0.0)
                new[0][q, 3 * i + j] = sn[i, j]
        new[1][q, 0] = p
        new[2][q, 0] = mu_max
        new[3][q, 0] = mu_p
        new[4][q, 0] = old[4][q, 0] + d_eps_p
        new[5][q, 0] = min(1.0, damage + d_damage)
        new[6][q, 0] = old[6][q, 0] + J_mid * work
        new[8][q, 0] = old[8][q, 0]
        if erosion > 0.0:
            if gone:  # the eroded and the inverted keep their committed state
                for k in (2, 3, 4, 5):  # mu_max, mu_plastic, plastic_strain, damage
                    new[k][q, 0] = old[k][q, 0]
            elif new[5][q, 0] >= 1.0 and new[4][q, 0] >= erosion:
                gone = True
            if gone:
                for i in range(3):
                    for j in range(3):
                        sigma[q, i, j] = 0.0
                for k in range(9):
                    new[0][q, k] = 0.0
                new[1][q, 0] = 0.0
                new[5][q, 0] = 1.0
                new[8][q, 0] = 1.0
                new[6][q, 0] = old[6][q, 0]


def hjc_update(
    constants: np.ndarray,
    erosion: float | None,
    F: np.ndarray,
    hoop: np.ndarray | None,
    dt: float,
    state: dict[str, np.ndarray],
    fields: dict[str, int],
) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """``(sigma (m, 3, 3), new state, flags (m,))``: the compiled step (module docstring) of
    the points with gradients ``F`` ``(m, d, d)`` (``hoop`` ``(m,)`` their hoop stretch in
    axisymmetry, else ``None``) from ``state``, whose ``fields`` are
    ``HolmquistJohnsonCook.state_fields``; ``constants`` the law's :data:`PARAMETERS`,
    ``erosion`` its erosion strain or ``None``. ``flags`` is nonzero where a point could not be
    taken (module docstring); those points' rows are not filled."""
    sigma, new, flags, args = _prepare(F, hoop, state, fields)
    e = -1.0 if erosion is None else float(erosion)
    _kernel(constants, e, args[0], args[1], float(dt), args[2], sigma, new, flags)
    return sigma, dict(zip(fields, new, strict=True)), flags


#: The order of Johnson–Cook's parameters in the array :func:`johnson_cook_update` takes.
JC_PARAMETERS = ("G", "K", "A", "B", "n", "C", "eps0")


@jit
def _flow(c, eps_p, rate_term):  # pragma: no cover - compiled
    """Johnson–Cook's ``(A + B eps_p^n) (1 + C ln max(rate / eps0, 1))`` (``flow_stress``),
    given its rate term ``1 + C ln max(rate / eps0, 1)``."""
    return (c[2] + c[3] * max(eps_p, 0.0) ** c[4]) * rate_term


@jit
def _jc_return(c, G, qt, eps_p, rate_term, iterations):  # pragma: no cover - compiled
    """The root ``d`` of ``g(d) = q_trial - 3 G d - sigma_y(eps_p + d)`` in ``(0, q_trial / 3
    G)`` (``g`` falls from ``g(0) > 0``): Newton's steps kept inside the bracket, which every
    evaluation of ``g`` narrows, and a bisection wherever a step would leave it (the slope is
    infinite at ``eps_p + d = 0`` for ``n < 1``: first yield). Stops when a step or the
    bracket is at round-off of ``d``, or after ``iterations`` evaluations; the reference's
    plain bisection to the same root."""
    lo, hi = 0.0, qt / (3.0 * G)
    d = 0.5 * (lo + hi)
    for _ in range(iterations):
        e = eps_p + d
        g = qt - 3.0 * G * d - _flow(c, e, rate_term)
        if g > 0.0:
            lo = d
        else:
            hi = d
        slope = 3.0 * G + (c[3] * c[4] * e ** (c[4] - 1.0) * rate_term if e > 0.0 else np.inf)
        step = g / slope
        new = d + step
        if not (lo < new < hi):  # outside the bracket (or an infinite slope): bisect
            new = 0.5 * (lo + hi)
        done = abs(new - d) <= 4e-16 * new or hi - lo <= 4e-16 * hi
        d = new
        if done:
            break
    return d


@jit
def _jc_kernel(c, bisections, F, hoop, dt, old, sigma, new, flags):  # pragma: no cover
    """Johnson–Cook's step of every point (``JohnsonCook.update``): the kinematics as HJC's,
    the radial return ``q_trial - 3 G d = sigma_y(eps_p + d)`` by :func:`_jc_return` (at most
    ``bisections`` evaluations), ``p = -K ln J``. ``old``/``new``: deviator (m, 9) 0, pressure
    1, plastic_strain 2, work 3, F (m, 9) 4; ``flags`` as :func:`_kernel`'s."""
    G = c[0]
    Fn, Fo, de, Qh, so, sr, st, sm, sn, scratch = _arrays()
    for q in range(F.shape[0]):
        finite = _gradient(F, hoop, q, Fn)
        J = det3(Fn)
        if not finite or not (J > 0.0):
            flags[q] = 1
            continue
        for i in range(9):
            Fo[i // 3, i % 3] = old[4][q, i]
            so[i // 3, i % 3] = old[0][q, i]
        J_mid, ee, qq = _start(Fo, Fn, so, G, scratch, de, Qh, sr, st)
        if not (J_mid > 0.0):
            flags[q] = 2
            continue
        qt = np.sqrt(1.5 * qq)
        rate = np.sqrt(2.0 / 3.0 * ee) / dt
        rate_term = 1.0 + c[5] * np.log(max(rate / c[6], 1.0))
        eps_p = old[2][q, 0]
        yielding = qt > _flow(c, eps_p, rate_term)
        d_eps_p = 0.0
        if yielding:  # (the reference bisects at elastic points too, for d = 0)
            d_eps_p = _jc_return(c, G, qt, eps_p, rate_term, bisections)
        ratio = 1.0 - 3.0 * G * d_eps_p / qt if yielding else 1.0
        for i in range(3):
            for j in range(3):
                sm[i, j] = ratio * st[i, j]
        p = -c[1] * np.log(J)
        _rotate(Qh, sm, scratch[0], sn)
        for i in range(3):
            for j in range(3):
                sigma[q, i, j] = sn[i, j] - (p if i == j else 0.0)
        for i in range(9):
            new[0][q, i] = sn[i // 3, i % 3]
            new[4][q, i] = Fn[i // 3, i % 3]
        new[1][q, 0] = p
        new[2][q, 0] = eps_p + d_eps_p
        new[3][q, 0] = old[3][q, 0] + J_mid * _work(sr, old[1][q, 0], sm, p, de)


def johnson_cook_update(
    constants: np.ndarray,
    bisections: int,
    F: np.ndarray,
    hoop: np.ndarray | None,
    dt: float,
    state: dict[str, np.ndarray],
    fields: dict[str, int],
) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """:func:`hjc_update` for ``JohnsonCook`` (its :data:`JC_PARAMETERS`, the return's
    ``bisections``)."""
    sigma, new, flags, args = _prepare(F, hoop, state, fields)
    _jc_kernel(constants, bisections, args[0], args[1], float(dt), args[2], sigma, new, flags)
    return sigma, dict(zip(fields, new, strict=True)), flags


def _prepare(
    F: np.ndarray, hoop: np.ndarray | None, state: dict[str, np.ndarray], fields: dict[str, int]
) -> tuple[np.ndarray, tuple[np.ndarray, ...], np.ndarray, tuple]:
    """The outputs (zeros, empty state arrays, flags) and the kernels' inputs ``(F, hoop,
    old state)``."""
    m = len(F)
    new = tuple(np.empty((m, k)) for k in fields.values())
    hoop = np.zeros(0) if hoop is None else np.ascontiguousarray(hoop, dtype=float).reshape(-1)
    old = tuple(np.asarray(state[name], dtype=float) for name in fields)
    args = (np.ascontiguousarray(F, dtype=float), hoop, old)
    return np.zeros((m, 3, 3)), new, np.zeros(m, dtype=np.int8), args


@jit
def _wave_speed(c, eroded, mu_maxes, Fs):  # pragma: no cover - compiled
    """The largest ``sqrt((K + 4 G / 3) / rho)`` over the live points (state fields (m, k))."""
    top = 0.0
    F = np.empty((3, 3))
    for q in range(Fs.shape[0]):
        if eroded[q, 0] != 0.0:
            continue
        mu_max = mu_maxes[q, 0]
        K = max(_tangent(c, mu_max), _unloading(c, mu_max))
        for i in range(9):
            F[i // 3, i % 3] = Fs[q, i]
        c2 = (K + 4.0 * c[0] / 3.0) / (c[21] / det3(F))
        if not (c2 >= 0.0):  # numpy's sqrt gives nan, and its max keeps it
            return np.nan
        top = max(top, c2)
    return np.sqrt(top)


def hjc_wave_speed(constants: np.ndarray, state: dict[str, np.ndarray]) -> float:
    """``HolmquistJohnsonCook.wave_speed`` of ``state``'s points, in one compiled pass."""
    columns = (state[name] for name in ("eroded", "mu_max", "F"))
    return float(_wave_speed(constants, *(np.asarray(a, dtype=float) for a in columns)))


@jit
def cofactor3(a: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """``cof(a) = det(a) a^{-T}`` of a 3 x 3 matrix into ``out``, compiled: its rows
    ``a_1 x a_2``, ``a_2 x a_0``, ``a_0 x a_1`` (``objective.cofactor_3x3``'s)."""
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for k in range(3):
            k1, k2 = (k + 1) % 3, (k + 2) % 3
            out[i, k] = a[i1, k1] * a[i2, k2] - a[i1, k2] * a[i2, k1]


@jit
def _nominal(sigma, F, P):  # pragma: no cover - compiled
    """``P = sigma cof(F)``: ``J sigma F^-T`` (``cof`` the cofactor matrix, rows ``a_1 x a_2``,
    ``a_2 x a_0``, ``a_0 x a_1`` of ``F``'s rows), zero where ``sigma`` is."""
    cof = np.empty((3, 3))
    for q in range(sigma.shape[0]):
        live = False
        for i in range(3):
            for j in range(3):
                if sigma[q, i, j] != 0.0:
                    live = True
        if not live:
            continue
        cofactor3(F[q], cof)
        for i in range(3):
            for j in range(3):
                acc = 0.0
                for k in range(3):
                    acc += sigma[q, i, k] * cof[k, j]
                P[q, i, j] = acc


def nominal_stress(sigma: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``objective.nominal_stress`` in one compiled pass (``sigma``, ``F`` (m, 3, 3))."""
    sigma = np.ascontiguousarray(sigma, dtype=float)
    P = np.zeros_like(sigma)
    _nominal(sigma, np.ascontiguousarray(F, dtype=float), P)
    return P


@jit
def _smallest_stretches(Fs, live, out):  # pragma: no cover - compiled
    """``out[q] = s_min(F_q)`` of the live points: the square root of ``C = F^T F``'s smallest
    eigenvalue, by cyclic Jacobi rotations (Golub & Van Loan, Matrix Computations, 4th ed.,
    sec. 8.5.2) until the off-diagonal part is below round-off."""
    C = np.empty((3, 3))
    for q in range(Fs.shape[0]):
        if not live[q]:
            continue
        for i in range(3):
            for j in range(3):
                C[i, j] = (
                    Fs[q, i] * Fs[q, j] + Fs[q, 3 + i] * Fs[q, 3 + j] + Fs[q, 6 + i] * Fs[q, 6 + j]
                )
        for _ in range(30):
            off = C[0, 1] ** 2 + C[0, 2] ** 2 + C[1, 2] ** 2
            if not (off > 1e-34 * (C[0, 0] ** 2 + C[1, 1] ** 2 + C[2, 2] ** 2)):
                break
            for a, b in ((0, 1), (0, 2), (1, 2)):
                if C[a, b] == 0.0:
                    continue
                k = 3 - a - b
                theta = (C[b, b] - C[a, a]) / (2.0 * C[a, b])
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                cs = 1.0 / np.sqrt(t * t + 1.0)
                sn = t * cs
                C[a, a] -= t * C[a, b]
                C[b, b] += t * C[a, b]
                C[a, b] = C[b, a] = 0.0
                ka, kb = C[k, a], C[k, b]
                C[k, a] = C[a, k] = cs * ka - sn * kb
                C[k, b] = C[b, k] = sn * ka + cs * kb
        out[q] = np.sqrt(max(min(C[0, 0], C[1, 1], C[2, 2]), 0.0))


def smallest_stretches(F: np.ndarray, live: np.ndarray) -> np.ndarray:
    """``s_min(F)`` (m,) of the gradients ``F`` (m, 9) (row-major) where ``live`` (m,) is true,
    1 elsewhere; the same to round-off as the smallest singular value of an SVD."""
    out = np.ones(len(F))
    _smallest_stretches(np.ascontiguousarray(F, dtype=float), np.asarray(live, dtype=bool), out)
    return out
