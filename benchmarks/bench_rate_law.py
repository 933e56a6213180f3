# # Benchmark: a rate-form law's step: closed forms against LAPACK, compiled against numpy
#
# The Hughes–Winget step of the rate-form laws (``physics/objective.py``: the mid-step
# inverse, the Cayley rotation ``Q`` and its half ``Q_h``) and the nominal stress ``P = J sigma
# F^-T`` are 3 x 3 algebra at every material point and step. They were written with LAPACK's
# batched ``solve`` and ``svd``, whose per-matrix overhead made them 38 % of a coupled Hanchak
# shot (profiled); they are now closed forms (cofactors, the Cayley transform of a skew
# matrix and of its half angle). This benchmark times both on the same random steps (stretches
# up to 30 %, spins up to 2 rad) at ``--points`` points, in one run: points per CPU second,
# median of ``--repeats``, and the largest difference of the two (relative to the largest
# entry).
#
# The closed forms in numpy still left the laws' whole-array updates most of a Hanchak shot
# (``hjc.update`` 17 s of a 25 s profile); the laws and the nominal stress now default to one
# compiled pass over the points (``physics/rate_kernels.py``, ``backend="numba"``). The
# benchmark times the whole update of the HJC concrete (48 MPa, axisymmetric, an in-plane
# compression with a spin) and of Johnson–Cook's 4340 steel (the same steps, plastic), the
# nominal stress and the smallest principal stretch (against an SVD) both ways, with the
# largest difference of the compiled results from numpy's. Prints a table, writes JSON
# (``--json``); ``--small`` is a smoke run for CI (no timing is checked anywhere).

# +
from __future__ import annotations

import argparse
import dataclasses
import functools
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree.approx import jit
from dolfinx_meshfree.physics import objective, rate_kernels
from dolfinx_meshfree.physics.objective import nominal_stress

import numpy as np
from harness import median_time, print_table, ratio, write_json

# -


def lapack_start(F_old: np.ndarray, F_new: np.ndarray) -> tuple[np.ndarray, ...]:
    """The step's kinematics as written before (``d eps``, ``Q``, ``Q_h``, ``det F_{n+1/2}``):
    LAPACK's batched solves, the polar factor of ``I + Q`` by an SVD, ``np.linalg.det``."""
    F_mid = 0.5 * (F_old + F_new)
    det = np.linalg.det(F_mid)
    G = np.linalg.solve(F_mid.transpose(0, 2, 1), (F_new - F_old).transpose(0, 2, 1))
    G = G.transpose(0, 2, 1)
    d_eps = 0.5 * (G + G.transpose(0, 2, 1))
    half_w = 0.25 * (G - G.transpose(0, 2, 1))
    eye = np.broadcast_to(np.eye(3), G.shape)
    Q = np.linalg.solve(eye - half_w, eye + half_w)
    U, _, Vt = np.linalg.svd(np.eye(3) + Q)
    return d_eps, Q, U @ Vt, det


def lapack_nominal(sigma: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``J sigma F^-T`` as written before: ``np.linalg.det`` and a batched solve."""
    J = np.linalg.det(F)
    return J[:, None, None] * np.linalg.solve(F, sigma.transpose(0, 2, 1)).transpose(0, 2, 1)


def steps(m: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``m`` random steps ``F_n -> F_{n+1}`` (m, 3, 3) and symmetric stresses (m, 3, 3)."""
    rng = np.random.default_rng(seed)
    F_old = np.eye(3) + 0.3 * rng.uniform(-1, 1, (m, 3, 3))
    axis = rng.normal(size=(m, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    angle = rng.uniform(0.0, 2.0, m)
    K = np.zeros((m, 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K -= K.transpose(0, 2, 1)
    R = np.eye(3) + np.sin(angle)[:, None, None] * K + (1 - np.cos(angle))[:, None, None] * K @ K
    F_new = R @ (F_old + 0.05 * rng.uniform(-1, 1, (m, 3, 3)))
    sigma = rng.normal(size=(m, 3, 3))
    return F_old, F_new, sigma + sigma.transpose(0, 2, 1)


def measure(hjc: mf.HolmquistJohnsonCook, steel: mf.JohnsonCook, m: int, repeats: int) -> dict:
    """Both forms at ``m`` points: points per CPU second, and the largest differences."""
    F_old, F_new, sigma = steps(m)
    zero = np.zeros((m, 3, 3))
    new = objective.RateStep.start(F_old, F_new, zero)
    d_eps, Q, Qh, det = lapack_start(F_old, F_new)
    diff = max(
        float(np.abs(a - b).max() / np.abs(b).max())
        for a, b in ((new.d_eps, d_eps), (new.Qh, Qh), (new.J_mid, det))
    )
    diff = max(diff, float(np.abs(objective.hughes_winget(F_old, F_new)[1] - Q).max()))
    P = lapack_nominal(sigma, F_new)
    P_numpy = nominal_stress(sigma, F_new, backend="numpy")
    diff = max(diff, float(np.abs(P_numpy - P).max() / np.abs(P).max()))
    clock = time.process_time
    t_new = median_time(lambda: objective.RateStep.start(F_old, F_new, zero), repeats, clock)
    t_old = median_time(lambda: lapack_start(F_old, F_new), repeats, clock)
    p_new = median_time(lambda: nominal_stress(sigma, F_new, backend="numpy"), repeats, clock)
    p_old = median_time(lambda: lapack_nominal(sigma, F_new), repeats, clock)
    record = {
        "points": m, "start_closed": m / t_new, "start_lapack": m / t_old,
        "nominal_closed": m / p_new, "nominal_lapack": m / p_old, "max_difference": diff,
    }  # fmt: skip
    if not jit.AVAILABLE:
        return record
    # compiled against numpy: whole updates from a state reached by two steps, an in-plane
    # compression of up to 10 % with a spin of up to 0.5 rad, hoop stretch 1
    rng = np.random.default_rng(1)
    angle, u = rng.uniform(0.0, 0.5, m), rng.uniform(0.0, 1.0, m)
    hoop, worst = np.ones(m), 0.0
    for name, base in (("hjc", hjc), ("jc", steel)):
        laws = {b: dataclasses.replace(base, backend=b) for b in ("numba", "numpy")}
        state = base.initial_state(m)
        for k in (1, 2):
            state = base.update(in_plane(angle, u, k / 3), 1e-7, state, hoop)[1]
        F2 = in_plane(angle, u, 1.0)
        got = {b: law.update(F2, 1e-7, state, hoop) for b, law in laws.items()}
        worst = max(worst, relative(got["numba"][0], got["numpy"][0]))
        for field in state:
            worst = max(worst, relative(got["numba"][1][field], got["numpy"][1][field]))
        for b, law in laws.items():
            step = functools.partial(law.update, F2, 1e-7, state, hoop)
            t = median_time(step, repeats, clock)
            record[f"{name}_{b}"] = m / t
    P_numba = nominal_stress(sigma, F_new, backend="numba")
    worst = max(worst, relative(P_numba, P_numpy))
    t = median_time(lambda: nominal_stress(sigma, F_new, backend="numba"), repeats, clock)
    record["nominal_numba"] = m / t
    F9, live = F_new.reshape(m, 9), np.ones(m, dtype=bool)
    s_svd = np.linalg.svd(F_new, compute_uv=False)[:, -1]
    worst = max(worst, relative(rate_kernels.smallest_stretches(F9, live), s_svd))
    t = median_time(lambda: rate_kernels.smallest_stretches(F9, live), repeats, clock)
    record["stretch_numba"] = m / t
    t = median_time(lambda: np.linalg.svd(F_new, compute_uv=False), repeats, clock)
    record["stretch_svd"] = m / t
    record["compiled_difference"] = worst
    return record


def in_plane(angle: np.ndarray, u: np.ndarray, t: float) -> np.ndarray:
    """``(m, 2, 2)`` gradients at ``t`` in [0, 1] of a compression by ``10 u %`` with a spin
    by ``angle``."""
    c, s = np.cos(t * angle), np.sin(t * angle)
    F2 = np.stack([np.stack([c, -s], 1), np.stack([s, c], 1)], 1)
    return F2 * np.stack([1.0 - 0.1 * t * u, 1.0 + 0.02 * t * u], 1)[:, None, :]


def relative(a: np.ndarray, b: np.ndarray) -> float:
    """``max |a - b| / max |b|`` (0 where both are 0)."""
    scale = float(np.abs(b).max(initial=0.0))
    return float(np.abs(a - b).max(initial=0.0)) / scale if scale > 0 else 0.0


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--points", nargs="+", type=int, default=[1000, 10000, 100000])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--small", action="store_true", help="a smoke run (CI)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    sizes, repeats = ([200], 1) if args.small else (args.points, args.repeats)
    hjc = mf.HolmquistJohnsonCook.concrete_48mpa(plane="axisymmetric")
    steel = mf.JohnsonCook.steel_4340(plane="axisymmetric")
    records = [measure(hjc, steel, m, repeats) for m in sizes]
    print(f"A rate-form law's step, points per CPU second, median of {repeats}")
    columns = [("points", "8d"), ("start closed", "13.3g"), ("start LAPACK", "13.3g"),
               ("x", "5.1f"), ("P closed", "10.3g"), ("P LAPACK", "10.3g"), ("x", "5.1f"),
               ("max diff", "9.1e")]  # fmt: skip
    rows = [
        [r["points"], r["start_closed"], r["start_lapack"],
         ratio(r["start_closed"], r["start_lapack"]), r["nominal_closed"], r["nominal_lapack"],
         ratio(r["nominal_closed"], r["nominal_lapack"]), r["max_difference"]]
        for r in records
    ]  # fmt: skip
    print_table(columns, rows)
    if jit.AVAILABLE:
        print("Compiled (numba) against numpy, points per CPU second; x: the speed-up")
        columns = [("points", "8d"), ("HJC numba", "10.3g"), ("HJC numpy", "10.3g"),
                   ("x", "5.1f"), ("JC numba", "10.3g"), ("JC numpy", "10.3g"), ("x", "5.1f"),
                   ("P numba", "10.3g"), ("x", "5.1f"), ("s_min numba", "11.3g"),
                   ("s_min SVD", "10.3g"), ("x", "5.1f"), ("max diff", "9.1e")]  # fmt: skip
        rows = [
            [r["points"], r["hjc_numba"], r["hjc_numpy"], ratio(r["hjc_numba"], r["hjc_numpy"]),
             r["jc_numba"], r["jc_numpy"], ratio(r["jc_numba"], r["jc_numpy"]),
             r["nominal_numba"], ratio(r["nominal_numba"], r["nominal_closed"]),
             r["stretch_numba"], r["stretch_svd"], ratio(r["stretch_numba"], r["stretch_svd"]),
             r["compiled_difference"]]
            for r in records
        ]  # fmt: skip
        print_table(columns, rows)
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
