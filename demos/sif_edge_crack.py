# # Stress intensity factor of a single edge crack in a finite plate (Tada)
#
# Plate [0, W] x [-H/2, H/2], W = 1, H = 2 W (H/W = 2), an edge crack of length a from the left
# edge (the mouth) along y = y0 (y0 = h/2: half a spacing off the particle rows, so that no
# particle lies on it), remote tension sigma = 1 as tractions on the top and bottom edges, all
# other edges free. The rigid motions are removed far from the crack by three scalar conditions,
# statically determinate (pure EFG: u = 0 on the bottom edge's left end facet, u_y = 0 on its
# right end facet, one constant multiplier per facet and component; coupled, a user's
# ``CoupledLinearProblem`` with UFL forms: ``DirichletBC``s at the bottom corners, FE nodes,
# u = 0 at (0, -H/2) and u_y = 0 at (W, -H/2) on ``V.sub(1)``): with self-equilibrated loads
# their reactions vanish and the plate is free, as Tada's formula assumes.
#
# Reference: K_I / (sigma sqrt(pi a)) = F(a/W) = 1.12 - 0.231 (a/W) + 10.55 (a/W)^2
# - 21.72 (a/W)^3 + 30.39 (a/W)^4 (Tada; +-0.5 % for a/W <= 0.6); K_II = 0 by symmetry of the
# loading about the crack line (up to y0 = h/2).
#
# Methods: ``efg`` (particles in the whole plate) or a coupling that carries cracks
# (``lagrange``, ``edge-to-edge``, ``bridging``): particles in the box from the mouth to
# 3 h past the largest domain radius ahead of, above and below the tip, Q1 elements (same size h)
# elsewhere. K by the domain interaction integral (``solution.stress_intensity_factors``) over
# the outer radii 0.4, 0.55, 0.7 x min(a, W - a) (``r1 = r2 / 2``).
#
# Targets (issue 10): |K_I / K_Tada - 1| <= 1 % and path independence <= 0.5 % over the three
# radii; the run exits 1 on a miss (``--quick``: a coarse smoke run, targets reported only).
# Tada's formula itself is +-0.5 %: a converged P2 FE computation differs from it by -0.24,
# +0.37, +0.16 % at a/W = 0.2, 0.4, 0.6.
#
#     python demos/sif_edge_crack.py --method lagrange --a-over-w 0.4 [--h 0.00625] \
#         [--json out.json] [--enrich]
#
# ``--enrich``: the MLS basis enriched near the tip (``crack_enrichment=True``, Fleming et al.
# 1997): at h = 0.05 (1,722 dofs, pure EFG) +0.6 % against Tada where the linear basis gives
# -3.7 %.

from __future__ import annotations

import argparse
import sys
import time

import dolfinx_meshfree as mf

import dolfinx
import numpy as np
from sif_common import COMM, coupled_forms, owned_cells, rigid_motion_bcs, write_json

W, H, SIGMA = 1.0, 2.0, 1.0
#: Outer domain radii as fractions of the tip's distance to the nearest edge, min(a, W - a):
#: fixed in the plate, so that path independence converges with h (radii fixed in spacings
#: kept a spread of 0.72 % at every h: the error of the field within a few spacings of the tip).
RADII = (0.4, 0.55, 0.7)
MATERIAL = mf.LinearElastic(1000.0, 0.3, plane="strain")
TARGET, PATH_TARGET = 0.01, 0.005


def run(method: str, a_over_w: float, h: float, enrich: bool = False) -> dict:
    a = a_over_w * W
    y0 = 0.5 * h
    radii = np.asarray(RADII) * min(a, W - a)
    nx, ny = round(W / h), round(H / h)
    msh = dolfinx.mesh.create_rectangle(
        COMM,
        [np.array([0.0, -H / 2]), np.array([W, H / 2])],
        [nx, ny],
        dolfinx.mesh.CellType.quadrilateral,
    )
    crack = mf.Crack([[0.0, y0], [a, y0]])
    top = mf.boundary_facets(msh, lambda x: np.isclose(x[1], H / 2))
    bottom = mf.boundary_facets(msh, lambda x: np.isclose(x[1], -H / 2))
    tractions = ((top, (0.0, SIGMA)), (bottom, (0.0, -SIGMA)))  # self-equilibrated
    t0 = time.perf_counter()
    if method == "efg":
        P = mf.ParticleSet.from_cells(msh, h)
        prob = mf.EFGElasticity(P, MATERIAL, cracks=[crack], crack_enrichment=enrich)
        on_bottom = lambda x: np.isclose(x[1], -H / 2)  # noqa: E731
        pin = mf.boundary_facets(msh, lambda x: on_bottom(x) & (x[0] < h + 1e-9))
        roll = mf.boundary_facets(msh, lambda x: on_bottom(x) & (x[0] > W - h - 1e-9))
        zero = lambda x: np.zeros((len(x), 2))  # noqa: E731
        for facets, comps in ((pin, (0, 1)), (roll, (1,))):
            if COMM.allreduce(facets.size) == 0:
                raise RuntimeError("no facet for the rigid-motion conditions")
            prob.add_dirichlet(facets, zero, components=comps)
        for facets, t in tractions:
            prob.add_traction(facets, lambda x, n, t=t: np.tile(t, (len(x), 1)))
        sizes = {"particle_dofs": 2 * P.num_particles, "fe_dofs": 0}
    else:
        # a user's model: UFL forms on Q1, DirichletBCs at the bottom corners (FE nodes far
        # from the crack): u = 0 at (0, -H/2), u_y = 0 at (W, -H/2) on V.sub(1)
        m = radii[-1] + 3.0 * h
        cells = owned_cells(msh, lambda c: (c[:, 0] < a + m) & (np.abs(c[:, 1] - y0) < m))
        patch = mf.ParticlePatch(msh, cells, h, cracks=[crack], crack_enrichment=enrich)
        V, form_a, L = coupled_forms(msh, MATERIAL, tractions)
        bcs = rigid_motion_bcs(V, (0.0, -H / 2), (W, -H / 2))
        prob = mf.CoupledLinearProblem(form_a, L, bcs, patch, material=MATERIAL, coupling=method)
        sizes = {
            "particle_dofs": 2 * patch.particles.num_particles,
            "fe_dofs": 2 * V.dofmap.index_map.size_global,
        }
    sol = prob.solve()
    seconds = time.perf_counter() - t0

    t1 = time.perf_counter()
    sif = sol.stress_intensity_factors(crack, tip=0, radius=radii)
    F = float(mf.edge_crack_factor(a_over_w))
    scale = SIGMA * np.sqrt(np.pi * a)
    KI, KII = float(sif.K_I.mean()), float(sif.K_II.mean())
    return {
        "method": method,
        "h": h,
        "a_over_w": a_over_w,
        "crack_enrichment": enrich,
        "KI": KI,
        "KII": KII,
        "KI_normalized": KI / scale,
        "KII_normalized": KII / scale,
        "KI_normalized_reference": F,
        "KII_normalized_reference": 0.0,
        "relative_error_KI": KI / (F * scale) - 1.0,
        "relative_error_KII": KII / (F * scale),
        "error_note": "KII error relative to the Tada K_I",
        "K_per_radius": {"radius": radii.tolist(), "KI": sif.K_I.tolist(),
                         "KII": sif.K_II.tolist()},
        "path_dependence": sif.path_dependence,
        **sizes,
        "times": {"solve": seconds, "sif": time.perf_counter() - t1},
        "ranks": COMM.size,
    }  # fmt: skip


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--method", default="efg")
    parser.add_argument("--a-over-w", type=float, default=0.4, dest="a_over_w")
    parser.add_argument("--h", type=float, default=0.00625, help="particle spacing = cell size")
    parser.add_argument("--json", default=None)
    parser.add_argument("--quick", action="store_true", help="coarse smoke run (h = 0.1)")
    parser.add_argument(
        "--enrich", action="store_true", help="near-tip enrichment (crack_enrichment=True)"
    )
    args = parser.parse_args(argv)
    h = 0.1 if args.quick else args.h
    r = run(args.method, args.a_over_w, h, args.enrich)
    err = abs(r["relative_error_KI"])
    ok = err <= TARGET and r["path_dependence"] <= PATH_TARGET
    if COMM.rank == 0:
        print(
            f"edge crack, a/W = {args.a_over_w:g}, H/W = 2, method {args.method}, h = {h:g}"
            + (", near-tip enrichment" if args.enrich else "")
        )
        print(" radius   KI/s√(πa)   KII/s√(πa)")
        s = np.sqrt(np.pi * args.a_over_w * W) * SIGMA
        for rr, k1, k2 in zip(*r["K_per_radius"].values(), strict=True):
            print(f" {rr:.4f}   {k1 / s:.5f}     {k2 / s:+.5f}")
        print(
            f" mean {r['KI_normalized']:.5f}, Tada {r['KI_normalized_reference']:.5f}, error "
            f"{r['relative_error_KI']:+.2%} (target 1 %), path {r['path_dependence']:.2%} "
            f"(target 0.5 %)"
        )
        print(
            f" particle dofs {r['particle_dofs']}, FE dofs {r['fe_dofs']}, "
            f"solve {r['times']['solve']:.2f} s, K {r['times']['sif']:.2f} s"
        )
        print(f" targets: {'met' if ok else 'MISSED'}")
    write_json(args.json, r)
    return 0 if ok or args.quick else 1


if __name__ == "__main__":
    sys.exit(main())
