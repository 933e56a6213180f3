# # Benchmark: MLS tabulation speed beside DOLFINx assembly on the same mesh
#
# How fast are the meshfree building blocks next to what DOLFINx does for the FE side? On the
# cantilever mesh (L = 48, D = 12, element size h, Q1) this benchmark times, each as the median
# of ``--repeats`` runs on one rank:
#
# * DOLFINx assembly of the Q1 elasticity stiffness matrix (JIT excluded: compiled before timing);
# * EFG/MLS tabulation (values and gradients, linear basis, quartic weight, d_max = 2) at the
#   4 x 4 Gauss points of every cell, particles on the mesh vertices: points per second;
# * assembly of the EFG stiffness from that table (scipy sparse products);
# * FE basis tabulation at the same points (`tabulate_in_cells`): points per second.
#
# It prints a table and writes JSON (``--json``). Numbers are machine-dependent; compare the
# ratios within one run.

# +
from __future__ import annotations

import argparse

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.physics.operators import stiffness_matrix

import dolfinx
import numpy as np
import ufl
from harness import median_time, print_table, ratio, write_json
from mpi4py import MPI

# -


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--h", nargs="+", type=float, default=[1.0, 0.5, 0.25])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    comm = MPI.COMM_SELF  # a single-rank benchmark by design
    material = mf.LinearElastic(3e7, 0.3)
    records = []
    for h in args.h:
        msh = dolfinx.mesh.create_rectangle(
            comm,
            [np.array([0.0, -6.0]), np.array([48.0, 6.0])],
            [round(48 / h), round(12 / h)],
            dolfinx.mesh.CellType.quadrilateral,
        )
        V = _compat.vector_function_space(msh)
        u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        a = _compat.create_form(ufl.inner(material.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx)
        t_fe_assemble = median_time(lambda a=a: _compat.assemble_matrix(a).destroy(), args.repeats)
        q = mf.cell_quadrature(msh, 7)
        particles = mf.ParticleSet.from_cells(msh, h)
        mls = mf.MLS(particles)
        t_mls = median_time(lambda q=q, mls=mls: mls.tabulate(q.points), args.repeats)
        table = mls.tabulate(q.points)
        t_efg_k = median_time(
            lambda t=table, q=q: stiffness_matrix(t.gradients, q.weights, material), args.repeats
        )
        t_fe_tab = median_time(
            lambda V=V, q=q: mf.tabulate_in_cells(V, q.points, q.cells), args.repeats
        )
        npts = len(q)
        records.append(
            {
                "h": h,
                "cells": msh.topology.index_map(2).size_local,
                "fe_dofs": 2 * V.dofmap.index_map.size_global,
                "particles": particles.num_particles,
                "quadrature_points": npts,
                "time_dolfinx_assemble_K": t_fe_assemble,
                "time_mls_tabulate": t_mls,
                "mls_points_per_second": npts / t_mls,
                "time_efg_assemble_K": t_efg_k,
                "time_fe_tabulate": t_fe_tab,
                "fe_points_per_second": npts / t_fe_tab,
                "dolfinx_version": mf.DOLFINX_VERSION,
                "repeats": args.repeats,
            }
        )
    if MPI.COMM_WORLD.rank == 0:
        print(
            f"MLS tabulation vs DOLFINx assembly, 1 rank, DOLFINx {mf.DOLFINX_VERSION}, "
            f"median of {args.repeats}"
        )
        columns = [
            ("h", "5.3g"), ("cells", "6d"), ("quad pts", "8d"), ("DOLFINx K s", "11.4f"),
            ("MLS tab s", "9.4f"), ("MLS pts/s", "10.3g"), ("EFG K s", "8.4f"),
            ("FE tab s", "8.4f"), ("FE pts/s", "10.3g"), ("MLS/DOLFINx", "11.1f"),
        ]  # fmt: skip
        keys = ("h", "cells", "quadrature_points", "time_dolfinx_assemble_K", "time_mls_tabulate",
                "mls_points_per_second", "time_efg_assemble_K", "time_fe_tabulate",
                "fe_points_per_second")  # fmt: skip
        rows = [
            [*(r[k] for k in keys), ratio(r["time_mls_tabulate"], r["time_dolfinx_assemble_K"])]
            for r in records
        ]
        print_table(columns, rows)
    write_json(args.json, records)
    return records


if __name__ == "__main__":
    main()
