# # Benchmark: a rate-form law's step, closed forms against LAPACK
#
# The Hughes–Winget step of the rate-form laws (``physics/objective.py``: the mid-step
# inverse, the Cayley rotation ``Q`` and its half ``Q_h``) and the nominal stress ``P = J sigma
# F^-T`` are 3 x 3 algebra at every material point and step. They were written with LAPACK's
# batched ``solve`` and ``svd``, whose per-matrix overhead made them 38 % of a coupled Hanchak
# shot (profiled); they are now closed forms (cofactors, the Cayley transform of a skew
# matrix and of its half angle). This benchmark times both on the same random steps (stretches
# up to 30 %, spins up to 2 rad) at ``--points`` points, in one run: points per CPU second,
# median of ``--repeats``, and the largest difference of the two (relative to the largest
# entry). It also times a whole HJC update (the 48 MPa concrete, axisymmetric) with the closed
# forms, for the share they now take. Prints a table, writes JSON (``--json``); ``--small`` is
# a smoke run for CI (no timing is checked anywhere).

# +
from __future__ import annotations

import argparse
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree.physics import objective
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


def measure(law: mf.HolmquistJohnsonCook, m: int, repeats: int) -> dict:
    """Both forms at ``m`` points: points per CPU second, and the largest difference."""
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
    diff = max(diff, float(np.abs(nominal_stress(sigma, F_new) - P).max() / np.abs(P).max()))
    clock = time.process_time
    t_new = median_time(lambda: objective.RateStep.start(F_old, F_new, zero), repeats, clock)
    t_old = median_time(lambda: lapack_start(F_old, F_new), repeats, clock)
    p_new = median_time(lambda: nominal_stress(sigma, F_new), repeats, clock)
    p_old = median_time(lambda: lapack_nominal(sigma, F_new), repeats, clock)
    # a whole update: an in-plane compression of up to 10 % with a spin of up to 0.5 rad,
    # hoop stretch 1
    rng = np.random.default_rng(1)
    angle, u = rng.uniform(0.0, 0.5, m), rng.uniform(0.0, 1.0, m)
    c, s = np.cos(angle), np.sin(angle)
    F2 = np.stack([np.stack([c, -s], 1), np.stack([s, c], 1)], 1)
    F2 = F2 * np.stack([1.0 - 0.1 * u, 1.0 + 0.02 * u], 1)[:, None, :]
    state = objective.virgin_state(law.state_fields, m)
    hoop = np.ones(m)
    t_law = median_time(lambda: law.update(F2, 1e-7, state, hoop), repeats, clock)
    return {
        "points": m, "start_closed": m / t_new, "start_lapack": m / t_old,
        "nominal_closed": m / p_new, "nominal_lapack": m / p_old, "hjc_update": m / t_law,
        "max_difference": diff,
    }  # fmt: skip


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--points", nargs="+", type=int, default=[1000, 10000, 100000])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--small", action="store_true", help="a smoke run (CI)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    sizes, repeats = ([200], 1) if args.small else (args.points, args.repeats)
    law = mf.HolmquistJohnsonCook.concrete_48mpa(plane="axisymmetric")
    records = [measure(law, m, repeats) for m in sizes]
    print(f"A rate-form law's step, points per CPU second, median of {repeats}")
    columns = [("points", "8d"), ("start closed", "13.3g"), ("start LAPACK", "13.3g"),
               ("x", "5.1f"), ("P closed", "10.3g"), ("P LAPACK", "10.3g"), ("x", "5.1f"),
               ("HJC update", "11.3g"), ("max diff", "9.1e")]  # fmt: skip
    rows = [
        [r["points"], r["start_closed"], r["start_lapack"],
         ratio(r["start_closed"], r["start_lapack"]), r["nominal_closed"], r["nominal_lapack"],
         ratio(r["nominal_closed"], r["nominal_lapack"]), r["hjc_update"], r["max_difference"]]
        for r in records
    ]  # fmt: skip
    print_table(columns, rows)
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
