# # Robustness matrix: every coupling wherever a user puts the patch
#
# The papers test their couplings on their own set-ups: an axis-aligned patch, particles at the
# element size, no body load. A user puts the patch where the physics needs it, chooses the
# cells by a criterion of their own, and loads the model by gravity. This demo runs every
# coupling over the matrix
#
#     coupling x mesh {quadrilateral, triangle (crossed), gmsh (unstructured triangles)}
#              x patch {axis-aligned, slanted, curved}
#              x spacing {0.5 h, 0.75 h, h, 1.5 h, vertices}
#              x load {none, body, traction}
#
# on the square [0, 2]^2, plane stress, against an exact polynomial solution of degree 2, at two
# mesh sizes, and compares each coupled error with the plain FE error of the same model on the
# same mesh. The model is written as a DOLFINx user writes it (UFL forms, `DirichletBC`s, a
# tagged `ds`) and given to `mf.CoupledLinearProblem`; the hybrid SPH–FE coupling, which has no
# form interface, is given the same data through `mf.HybridElasticity`.
#
#     python demos/robustness.py [--coupling lagrange ...] [--mesh quadrilateral ...]
#         [--patch axis ...] [--spacing 0.5 1 vertices ...] [--load body ...] [--json F]
#
# Targets (issue 8): the variational couplings (lagrange, edge-to-edge, ramp, ramp-cubic,
# bridging) within 1.2x the plain FE L2 error on the finer mesh and an L2 rate of at least 1.8;
# master–slave and hybrid (first order by construction) an L2 rate of at least 1.0. A case that
# cannot work must stop with a clear error (a `ValueError` that says what to change); the table
# says which.

# +
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time
from dataclasses import dataclass

import dolfinx_meshfree as mf  # first: it loads the right MPI for the dolfinx_solver lane
from dolfinx_meshfree import _compat

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

MESHES = pathlib.Path(__file__).resolve().parent.parent / "meshes"
COUPLINGS = (*mf.COUPLINGS, "hybrid")
MESH_KINDS = ("quadrilateral", "triangle", "gmsh")
PATCHES = ("axis", "slanted", "curved")
SPACINGS = ("0.5", "0.75", "1", "1.5", "vertices")
LOADS = ("none", "body", "traction")
#: First-order couplings: only the rate is held to a target.
FIRST_ORDER = ("master-slave", "hybrid")
RATIO_MAX, RATE_MIN, RATE_MIN_FIRST_ORDER = 1.2, 1.8, 1.0
MATERIAL = mf.LinearElastic(1000.0, 0.3, plane="stress")
TRACTION_TAG = 5
# -


# ## Exact solutions
#
# Two quadratic fields on the square: a harmonic, divergence-free one (`div sigma = 0` with no
# body force: loads `none` and `traction`) and one that a constant body force equilibrates
# (`body`). Both carry a rigid and a linear part so that no component vanishes.


# +
@dataclass(frozen=True)
class QuadraticField:
    """u_i = c_i + G_ij x_j + 1/2 H_ijk x_j x_k (numpy and UFL)."""

    c: np.ndarray
    G: np.ndarray
    H: np.ndarray

    def displacement(self, x: np.ndarray) -> np.ndarray:
        return self.c + x @ self.G.T + 0.5 * np.einsum("ijk,qj,qk->qi", self.H, x, x)

    def displacement_gradient(self, x: np.ndarray) -> np.ndarray:
        return self.G[None] + np.einsum("ijk,qk->qij", self.H, x)

    def body_force(self, material: mf.LinearElastic) -> np.ndarray:
        """``-div sigma(u)``, constant: ``-(mu lap u + (lambda + mu) grad div u)``."""
        lap = np.einsum("ijj->i", self.H)
        grad_div = np.einsum("kki->i", self.H)
        return -(material.mu * lap + (material.lmbda + material.mu) * grad_div)

    def ufl(self, x) -> ufl.core.expr.Expr:
        return ufl.as_vector(
            [
                self.c[i]
                + sum(self.G[i, j] * x[j] for j in range(2))
                + 0.5 * sum(self.H[i, j, k] * x[j] * x[k] for j in range(2) for k in range(2))
                for i in range(2)
            ]
        )


def _hessians(coefficients: dict[tuple[int, int, int], float]) -> np.ndarray:
    H = np.zeros((2, 2, 2))
    for (i, j, k), value in coefficients.items():
        H[i, j, k] = H[i, k, j] = value
    return H


C0 = np.array([1e-3, -2e-3])
G0 = 1e-3 * np.array([[1.0, 0.5], [-0.3, 2.0]])
#: u = (x^2 - y^2, -2 x y) (scaled): harmonic and divergence free, so div sigma = 0.
HARMONIC = QuadraticField(
    C0, G0, 1e-3 * _hessians({(0, 0, 0): 2.0, (0, 1, 1): -2.0, (1, 0, 1): -2.0})
)
#: u = (x^2 + x y, y^2 - x y) (scaled): div sigma is a non-zero constant.
LOADED = QuadraticField(
    C0, G0, 1e-3 * _hessians({(0, 0, 0): 2.0, (0, 0, 1): 1.0, (1, 1, 1): 2.0, (1, 0, 1): -1.0})
)
# -


# ## Meshes and patches
#
# Level 0 and 1 of each mesh family: `create_rectangle` with 12 and 24 cells per side
# (quadrilaterals, or triangles with crossed diagonals), and the committed gmsh mesh of the
# square refined once and twice (unstructured, no two cells alike). The patch is chosen by a
# criterion on the cell centroids, as a user would: `axis` x > 1, `slanted` above the line
# y = 0.7 + 0.4 x, `curved` the disc of radius 0.6 about the centre.


# +
def build_mesh(comm, kind: str, level: int):
    """The mesh and its nominal cell size."""
    if kind == "gmsh":
        encoding = dolfinx.io.XDMFFile.Encoding.ASCII
        path = MESHES / "patch_irregular_triangle_6.xdmf"
        with dolfinx.io.XDMFFile(comm, str(path), "r", encoding=encoding) as f:
            msh = f.read_mesh(name="mesh")
        for _ in range(level + 1):
            msh = _compat.refine(msh)
        return msh, 2.0 / 6 / 2 ** (level + 1)
    n = 12 * 2**level
    if kind == "quadrilateral":
        msh = dolfinx.mesh.create_rectangle(
            comm, [np.zeros(2), np.full(2, 2.0)], [n, n], dolfinx.mesh.CellType.quadrilateral
        )
    else:
        msh = dolfinx.mesh.create_rectangle(
            comm,
            [np.zeros(2), np.full(2, 2.0)],
            [n, n],
            dolfinx.mesh.CellType.triangle,
            diagonal=dolfinx.mesh.DiagonalType.crossed,
        )
    return msh, 2.0 / n


def patch_cells(msh, shape: str) -> np.ndarray:
    n = msh.topology.index_map(2).size_local
    mid = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)
    if shape == "axis":
        keep = mid[:, 0] > 1.0
    elif shape == "slanted":
        keep = mid[:, 1] > 0.7 + 0.4 * mid[:, 0]
    else:
        keep = np.hypot(mid[:, 0] - 1.0, mid[:, 1] - 1.0) < 0.6
    return np.flatnonzero(keep).astype(np.int32)


# -


# ## The user's model
#
# Plain DOLFINx: the elasticity form, the load (`f . v dx` with `f = -div sigma(u)`, the zero
# load `Constant((0, 0)) . v dx` otherwise), the exact traction `sigma(u) n` on the right and
# top edges for `traction`, and the exact displacement as a `DirichletBC` on the rest of the
# boundary.


# +
@dataclass
class Model:
    V: object
    a: ufl.Form
    L: ufl.Form
    bcs: list
    exact: QuadraticField
    body: object  # UFL body force, or None
    traction_facets: np.ndarray
    dirichlet_facets: np.ndarray


def user_model(msh, load: str) -> Model:
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    exact = LOADED if load == "body" else HARMONIC
    V = _compat.vector_function_space(msh)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    x = ufl.SpatialCoordinate(msh)
    sigma_exact = MATERIAL.ufl_stress(exact.ufl(x))
    a = ufl.inner(MATERIAL.ufl_stress(u), ufl.sym(ufl.grad(v))) * ufl.dx
    everything = mf.boundary_facets(msh)
    if load == "traction":
        loaded = mf.boundary_facets(msh, lambda p: np.isclose(p[0], 2.0) | np.isclose(p[1], 2.0))
    else:
        loaded = np.zeros(0, dtype=np.int32)
    fixed = np.setdiff1d(everything, loaded).astype(np.int32)
    if load == "body":
        body = -ufl.div(sigma_exact)
        L = ufl.dot(body, v) * ufl.dx
    else:
        body = None
        L = ufl.dot(dolfinx.fem.Constant(msh, np.zeros(2)), v) * ufl.dx
    if load == "traction":
        tags = dolfinx.mesh.meshtags(
            msh, tdim - 1, loaded, np.full(loaded.size, TRACTION_TAG, dtype=np.int32)
        )
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        L = L + ufl.dot(sigma_exact * ufl.FacetNormal(msh), v) * ds(TRACTION_TAG)
    g = dolfinx.fem.Function(V)
    g.interpolate(lambda p: exact.displacement(p[:2].T).T)
    bcs = [dolfinx.fem.dirichletbc(g, dolfinx.fem.locate_dofs_topological(V, tdim - 1, fixed))]
    return Model(V, a, L, bcs, exact, body, loaded, fixed)


def solve_plain_fe(model: Model) -> dict:
    """The model as written: DOLFINx assembly and LU; its L2 and energy errors."""
    local = mf.solve_forms(model.a, model.L, model.bcs).u.x.array.reshape(-1, 2)

    def evaluate(q):
        t = mf.tabulate_in_cells(model.V, q.points, q.cells)
        return t.values @ local, t.gradient(local)

    return mf.error_norms(model.V.mesh, evaluate, model.exact, MATERIAL)


# -


# ## The same model with a particle patch


# +
def make_patch(msh, shape: str, spacing: str, h: float):
    cells = patch_cells(msh, shape)
    if spacing == "vertices":
        return mf.ParticlePatch(msh, cells, placement="vertices")
    return mf.ParticlePatch(msh, cells, float(spacing) * h)


def solve_coupled(model: Model, patch, coupling: str) -> dict:
    if coupling == "hybrid":
        return _solve_hybrid(model, patch)
    problem = mf.CoupledLinearProblem(
        model.a, model.L, model.bcs, patch, material=MATERIAL, coupling=coupling
    )
    solution = problem.solve()
    return mf.error_norms(model.V.mesh, solution.evaluate_at_quadrature, model.exact, MATERIAL)


def _solve_hybrid(model: Model, patch) -> dict:
    problem = mf.HybridElasticity(model.V, patch, MATERIAL)
    exact = model.exact
    if model.body is not None:
        b = exact.body_force(MATERIAL)
        problem.set_body_force(lambda x: np.tile(b, (x.shape[0], 1)))
    problem.add_dirichlet(model.dirichlet_facets, exact.displacement)
    if model.V.mesh.comm.allreduce(model.traction_facets.size) > 0:  # collective: every rank

        def traction(x, n):
            return np.einsum("qij,qj->qi", MATERIAL.stress(exact.displacement_gradient(x)), n)

        problem.add_traction(model.traction_facets, traction)
    solution = problem.solve()
    return mf.error_norms(model.V.mesh, solution.evaluate_at_quadrature, exact, MATERIAL)


# -


# ## Running the matrix


# +
@dataclass
class Case:
    coupling: str
    mesh: str
    patch: str
    spacing: str
    load: str

    @property
    def key(self) -> str:
        return f"{self.coupling}/{self.mesh}/{self.patch}/{self.spacing}/{self.load}"


def run_case(comm, case: Case, levels: tuple[int, ...] = (0, 1), fe_cache=None) -> dict:
    """Errors of one case at every level, the FE errors beside, the rate and the verdict.

    A ``ValueError`` (the package's refusals, named argument and fix) ends the case as
    ``refused`` with its message; any other exception propagates."""
    fe_cache = {} if fe_cache is None else fe_cache
    out = {
        "case": case.key,
        "coupling": case.coupling,
        "mesh": case.mesh,
        "patch": case.patch,
        "spacing": case.spacing,
        "load": case.load,
        "h": [],
        "l2": [],
        "fe_l2": [],
        "energy": [],
        "fe_energy": [],
        "seconds": 0.0,
    }
    t0 = time.perf_counter()
    for level in levels:
        msh, h = build_mesh(comm, case.mesh, level)
        model = user_model(msh, case.load)
        fe_key = (case.mesh, case.load, level)
        if fe_key not in fe_cache:
            fe_cache[fe_key] = solve_plain_fe(model)
        try:
            patch = make_patch(msh, case.patch, case.spacing, h)
            errors = solve_coupled(model, patch, case.coupling)
        except ValueError as e:
            out.update(status="refused", message=str(e).splitlines()[0][:300])
            out["seconds"] = time.perf_counter() - t0
            return out
        out["h"].append(h)
        out["l2"].append(errors["l2"])
        out["energy"].append(errors["energy"])
        out["fe_l2"].append(fe_cache[fe_key]["l2"])
        out["fe_energy"].append(fe_cache[fe_key]["energy"])
    out["seconds"] = time.perf_counter() - t0
    out["ratio"] = out["l2"][-1] / out["fe_l2"][-1]
    if len(levels) > 1:
        out["rate"] = float(
            np.log(out["l2"][-2] / out["l2"][-1]) / np.log(out["h"][-2] / out["h"][-1])
        )
    out["status"] = "ok" if not verdict(out) else "missed"
    out["misses"] = verdict(out)
    return out


def verdict(r: dict) -> list[str]:
    """The targets a finished case misses (empty: all met)."""
    misses = []
    if r["coupling"] in FIRST_ORDER:
        if "rate" in r and not r["rate"] >= RATE_MIN_FIRST_ORDER:
            misses.append(f"L2 rate {r['rate']:.2f} < {RATE_MIN_FIRST_ORDER}")
        return misses
    if not r["ratio"] <= RATIO_MAX:
        misses.append(f"L2 error {r['ratio']:.2f}x FE > {RATIO_MAX}")
    if "rate" in r and not r["rate"] >= RATE_MIN:
        misses.append(f"L2 rate {r['rate']:.2f} < {RATE_MIN}")
    return misses


def cases(args) -> list[Case]:
    return [
        Case(c, m, p, s, ld)
        for c in args.coupling
        for m in args.mesh
        for p in args.patch
        for s in args.spacing
        for ld in args.load
    ]


def cell(r: dict) -> str:
    """A table cell: ratio/rate, R for a refusal; * marks a missed target."""
    if r["status"] == "refused":
        return "refused"
    text = f"{r['ratio']:.2f}/{r.get('rate', float('nan')):.2f}"
    return text + ("*" if r["misses"] else "")


def report(records: list[dict], comm) -> None:
    if comm.rank != 0:
        return
    print(
        f"Robustness matrix, {comm.size} rank(s), DOLFINx {mf.DOLFINX_VERSION}: each cell is "
        "L2 error / plain FE L2 error on the finer mesh, and the L2 rate; * = target missed"
    )
    head = f"{'coupling':<13}{'mesh':<14}{'patch':<9}{'spacing':<9}" + "".join(
        f"{ld:>13}" for ld in LOADS
    )
    print(head)
    print("-" * len(head))
    rows: dict[tuple, dict] = {}
    for r in records:
        rows.setdefault((r["coupling"], r["mesh"], r["patch"], r["spacing"]), {})[r["load"]] = r
    for (c, m, p, s), by_load in rows.items():
        cells = "".join(f"{cell(by_load[ld]) if ld in by_load else '':>13}" for ld in LOADS)
        print(f"{c:<13}{m:<14}{p:<9}{s:<9}{cells}")
    refused = [r for r in records if r["status"] == "refused"]
    missed = [r for r in records if r["status"] == "missed"]
    print(
        f"{len(records)} cases: {len(records) - len(refused) - len(missed)} met the targets, "
        f"{len(missed)} missed, {len(refused)} refused"
    )
    for r in refused:
        print(f"  refused {r['case']}: {r['message']}")
    for r in missed:
        print(f"  missed  {r['case']}: {'; '.join(r['misses'])}")


def parse(argv):
    p = argparse.ArgumentParser(description="robustness matrix of the couplings")
    p.add_argument("--coupling", nargs="+", default=list(COUPLINGS), choices=COUPLINGS)
    p.add_argument("--mesh", nargs="+", default=list(MESH_KINDS), choices=MESH_KINDS)
    p.add_argument("--patch", nargs="+", default=list(PATCHES), choices=PATCHES)
    p.add_argument("--spacing", nargs="+", default=list(SPACINGS), choices=SPACINGS)
    p.add_argument("--load", nargs="+", default=list(LOADS), choices=LOADS)
    p.add_argument("--json", default=None, help="write the records as JSON")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> list[dict]:
    args = parse(argv)
    comm = MPI.COMM_WORLD
    fe_cache: dict = {}
    records = []
    for c in cases(args):
        records.append(run_case(comm, c, fe_cache=fe_cache))
        if comm.rank == 0:  # progress, on stderr
            print(f"{c.key}: {cell(records[-1])} ({records[-1]['seconds']:.1f} s)",
                  file=sys.stderr, flush=True)  # fmt: skip
    report(records, comm)
    if args.json and comm.rank == 0:
        pathlib.Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        pathlib.Path(args.json).write_text(
            json.dumps(
                {"ranks": comm.size, "dolfinx": mf.DOLFINX_VERSION, "records": records}, indent=1
            )
        )
    if any(r["status"] == "missed" for r in records):
        sys.exit(1)
    return records


if __name__ == "__main__":
    main()
# -
