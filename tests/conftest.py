"""Shared fixtures of the dolfinx_meshfree test suite.

``dolfinx_meshfree`` is imported first: in lane B it loads the MPI bundled with the
``dolfinx_solver`` wheel, which must happen before ``dolfinx``, ``petsc4py`` or ``mpi4py`` load
theirs. Every test runs serially and under ``mpirun -n 2 python -m mpi4py -m pytest``; the
autouse fixture below destroys PETSc objects deterministically and re-synchronises the ranks after
each test (as DOLFINx's own ``python/test/conftest.py`` does).
"""

import dolfinx_meshfree  # noqa: I001  (must come first: loads lane B's MPI)

import gc
import importlib.util
import pathlib
import shutil
import sys
import tempfile

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

#: Machine epsilon and its square root: the tolerances of exact properties are built from these.
EPS = float(np.finfo(float).eps)
SQRT_EPS = float(np.sqrt(EPS))


# --- tiers, the 2-rank selection and lane B's reduced run (issues 22, 27) --------------------
#
# Four markers (registered in pyproject.toml) decide where a test runs:
#
# * ``slow``: the slow tier, run only by ``pytest --full`` (``bash .ci/test.sh --full``): tests
#   whose discriminating power a cheaper default-tier test already carries (each says which);
# * ``serial``: not run on more than one rank: the test exercises no parallel code path (pure
#   numpy/numba kernels, closed forms, source checks) and would only run twice as two copies;
# * ``heavy(twin="tests/<module>.py::<test>")``: a long run (10-35 s: a concrete beam followed
#   through its peak, a crack grown segment by segment) whose figures are discretisation
#   properties, the same on any number of ranks and in either lane. It runs in the serial stage
#   of the reference lane (A) only; on more than one rank and in lane B's reduced run its code
#   paths are run by the named cheaper ``twin`` (the same feature on a smaller model), which is
#   checked to exist;
# * ``all_cases``: on more than one rank, every parameter case runs (not a covering subset).
#
# On more than one rank a parametrised test runs a covering subset of its cases: the cases in
# collection order, each kept if it brings a parameter value that no kept case had. Every value
# of every parameter (each coupling, cell type, dimension, placement ...) then runs in parallel at
# least once. The parallel code paths (ghosts, ownership, gathers, partition-dependent sums) are
# chosen by the value of a parameter, not by the product of several: the products are
# discretisation properties, the same on any number of ranks, and the serial stage runs them all.
# The selection is computed from the parameter values (or their positions), so it is the same on
# every rank, which MPI needs.
#
# ``--reduced`` (lane B's run, ``.ci/test.sh --lane b``): no heavy test, and each parametrised
# test runs its first case only. Lane B's job is the version-specific layer (``_compat``, the
# DOLFINx 0.11 and MPICH stack) under every test function on 2 ranks; the cases' products and
# the heavy runs are the same discretisation in both lanes and run in lane A.


def pytest_addoption(parser):
    parser.addoption(
        "--full",
        action="store_true",
        default=False,
        help="run the slow tier too (tests marked slow; the full robustness matrix)",
    )
    parser.addoption(
        "--reduced",
        action="store_true",
        default=False,
        help="lane B's reduced run: no heavy test, each parametrised test's first case only",
    )


def _value_key(value):
    """A key of a parameter value that is the same on every rank: the value itself when it is
    a plain literal, else ``None`` (the caller falls back to the value's position)."""
    plain = (str, int, float, bool, type(None))
    if isinstance(value, plain):
        return repr(value)
    if isinstance(value, tuple | list) and all(isinstance(v, plain) for v in value):
        return repr(tuple(value))
    return None


def covering_subset(items):
    """The items of one parametrised test to run on more than one rank: in order, each item
    that brings a (parameter, value) pair no earlier kept item had."""
    kept, seen = [], set()
    for item in items:
        spec = item.callspec
        pairs = set()
        for name, index in spec.indices.items():
            value = spec.params.get(name, getattr(spec, "funcargs", {}).get(name))
            key = _value_key(value)
            pairs.add((name, key if key is not None else f"#{index}"))
        if pairs - seen:
            kept.append(item)
            seen |= pairs
    return kept


def _check_twins(items, rootpath):
    """Every ``heavy`` test names a ``twin`` that was collected (not deselected by a marker):
    a heavy test left out on 2 ranks or in lane B must leave a cheaper run of its code paths.
    A twin in a module that this run did not collect (a run of some modules) is not looked for;
    a twin missing from its collected module, or in a module that does not exist, is an
    error."""
    ids = {item.nodeid.split("[")[0] for item in items}
    collected = {nodeid.split("::")[0] for nodeid in ids}
    for item in items:
        mark = item.get_closest_marker("heavy")
        if mark is None:
            continue
        twin = mark.kwargs.get("twin")
        module = twin.split("::")[0] if isinstance(twin, str) else ""
        if module and module not in collected and (rootpath / module).is_file():
            continue  # its module is not part of this run
        if not twin or twin not in ids:
            raise pytest.UsageError(
                f"{item.nodeid} is marked heavy with twin={twin!r}, which is not a collected test:"
                ' name one as "tests/<module>.py::<test>" (the cheaper run of the same code paths)'
            )
        twin_item = next(i for i in items if i.nodeid.split("[")[0] == twin)
        if any(twin_item.get_closest_marker(m) for m in ("heavy", "slow", "serial")):
            raise pytest.UsageError(f"{item.nodeid}: its twin {twin} must run in every stage")


def pytest_collection_modifyitems(config, items):
    full = config.getoption("--full")
    reduced = config.getoption("--reduced") and not full
    parallel = MPI.COMM_WORLD.size > 1
    if not config.getoption("keyword") and not config.getoption("markexpr"):
        _check_twins(items, config.rootpath)  # -k and -m may leave a twin out
    selected, deselected = [], []
    groups: dict[tuple, list] = {}
    for item in items:
        if (
            (not full and item.get_closest_marker("slow"))
            or (parallel and item.get_closest_marker("serial"))
            or ((parallel or reduced) and not full and item.get_closest_marker("heavy"))
        ):
            deselected.append(item)
            continue
        if (parallel or reduced) and hasattr(item, "callspec"):
            if reduced or not item.get_closest_marker("all_cases"):
                key = (item.path if hasattr(item, "path") else item.fspath, item.originalname)
                groups.setdefault(key, []).append(item)
        selected.append(item)
    if groups:
        pick = (lambda group: group[:1]) if reduced else covering_subset
        keep = {id(i) for group in groups.values() for i in pick(group)}
        dropped = [i for g in groups.values() for i in g if id(i) not in keep]
        deselected += dropped
        dropped_ids = {id(i) for i in dropped}
        selected = [i for i in selected if id(i) not in dropped_ids]
    if deselected:
        config.hook.pytest_deselected(items=deselected)
        items[:] = selected


def pytest_collection_finish(session):
    """Freeze what collection made (the modules, DOLFINx, numba, UFL: about 1e5 objects) out of
    the cyclic garbage collector: the ``gc.collect()`` after every test then scans only what
    the test made (measured 0.1 s per collection before, under 1 ms after, over some 1,800
    tests per run). The PETSc objects of the tests are made later and are still collected
    deterministically."""
    gc.collect()
    gc.freeze()


@pytest.fixture(autouse=True)
def _collect_and_synchronise():
    """After each test: collect its garbage (PETSc objects destroyed on every rank at the same
    point, not whenever each rank's collector happens to run), then freeze what survives.

    What survives a test's collection is alive beyond it (modules, numba and FFCx caches, module
    fixtures): ``gc.freeze`` moves it to the permanent generation, so that the next test's
    collection scans only the objects made since. Without it a process that has run a few
    hundred tests holds millions of tracked objects, and each collection scanned them all:
    measured in lane A's serial run with warm caches, 30 ms a test at the median, 65 s of the
    two workers' time (90 ms and 187 s in a run with cold caches on a loaded machine); with it,
    under 5 ms. A frozen object that later becomes cyclic garbage is not collected (a small
    leak, no effect on any result).
    """
    yield
    gc.collect()
    gc.freeze()
    MPI.COMM_WORLD.Barrier()


@pytest.fixture
def rank_rng():
    """A random generator seeded by the rank, so that each rank draws different points."""
    return np.random.default_rng(1234 + MPI.COMM_WORLD.rank)


def rectangle(comm, p0, p1, n, cell_type):
    """``dolfinx.mesh.create_rectangle`` with the same call in both lanes."""
    return dolfinx.mesh.create_rectangle(
        comm, [np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)], list(n), cell_type
    )


CELL_TYPES = {
    "triangle": dolfinx.mesh.CellType.triangle,
    "quadrilateral": dolfinx.mesh.CellType.quadrilateral,
}

__all__ = ["CELL_TYPES", "EPS", "SQRT_EPS", "dolfinx_meshfree", "rectangle"]


# --- the Timoshenko cantilever (Belytschko et al. 1995, sec. 5.1.2) ----------------------------

BEAM_L, BEAM_D = 48.0, 12.0


def beam_mesh(comm, h, cell_name="quadrilateral"):
    """[0, L] x [-D/2, D/2] with square (or halved square) cells of size h."""
    return rectangle(
        comm,
        [0.0, -BEAM_D / 2],
        [BEAM_L, BEAM_D / 2],
        [round(BEAM_L / h), round(BEAM_D / h)],
        CELL_TYPES[cell_name],
    )


def beam_ends(msh):
    """Owned exterior facets on x = 0 (clamped, exact displacement) and x = L (loaded)."""
    left = dolfinx_meshfree.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0))
    right = dolfinx_meshfree.boundary_facets(msh, lambda x: np.isclose(x[0], BEAM_L))
    return left, right


def solve_beam_fe(msh, beam):
    """P1/Q1 solution of the cantilever; returns the FESolution."""
    import ufl

    left, right = beam_ends(msh)
    V = dolfinx_meshfree._compat.vector_function_space(msh)
    P, inertia, D = beam.P, beam.inertia, beam.D
    return dolfinx_meshfree.solve_fe_elasticity(
        V,
        beam.material,
        dirichlet=[(left, lambda x: beam.displacement(x[:2].T).T)],
        tractions=[
            (right, lambda x: ufl.as_vector((0.0, P / (2 * inertia) * (D**2 / 4 - x[1] ** 2))))
        ],
    )


def fe_errors(msh, sol, beam):
    V = sol.u.function_space
    local = sol.u.x.array.reshape(-1, V.dofmap.index_map_bs)

    def evaluate(q):
        t = dolfinx_meshfree.tabulate_in_cells(V, q.points, q.cells)
        return t.values @ local, t.gradient(local)

    return dolfinx_meshfree.error_norms(msh, evaluate, beam, beam.material)


def solve_beam_efg(msh, beam, spacing, **options):
    """EFG solution of the cantilever on a regular particle grid of the given spacing."""
    left, right = beam_ends(msh)
    particles = dolfinx_meshfree.ParticleSet.from_cells(msh, spacing)
    problem = dolfinx_meshfree.EFGElasticity(particles, beam.material, **options)
    problem.add_dirichlet(left, beam.displacement)
    problem.add_traction(right, beam.traction)
    return problem.solve()


def efg_errors(msh, sol, beam):
    return dolfinx_meshfree.error_norms(msh, lambda q: sol.evaluate(q.points), beam, beam.material)


def fitted_rate(h, errors):
    """Slope of log(error) against log(h) by least squares (np.polyfit)."""
    return float(np.polyfit(np.log(h), np.log(errors), 1)[0])


def conversion_balance(records, conversions) -> float:
    """The energy balance of a run without external work whose cells became particles
    (``AdaptiveRun``), relative to the initial kinetic energy: ``(K + U - sum of the
    conversions' energy changes - K_0) / K_0`` at the last record (``records``: the stepper's
    energy records, the first at rest in strain)."""
    first, last = records[0], records[-1]
    changed = sum(c.energy_change for c in conversions)
    return (last.kinetic + last.internal - changed - first.kinetic) / first.kinetic


DEMOS = pathlib.Path(__file__).resolve().parents[1] / "demos"


def load_demo(name: str, alias: str | None = None):
    """Import ``demos/<name>.py`` as a module (the demos are scripts, not a package; their
    folder goes on ``sys.path``, as when one runs, for their shared ``sif_common``)."""
    if str(DEMOS) not in sys.path:
        sys.path.append(str(DEMOS))
    spec = importlib.util.spec_from_file_location(alias or f"demo_{name}", DEMOS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    # registered before it runs: dataclasses look their module up in sys.modules
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


BENCHMARKS = pathlib.Path(__file__).resolve().parents[1] / "benchmarks"


def load_benchmark(name: str, alias: str | None = None):
    """Import ``benchmarks/<name>.py`` as a module (as :func:`load_demo`: ``benchmarks/`` goes
    on ``sys.path`` for their shared ``harness``, ``demos/`` for the demos they load)."""
    for folder in (BENCHMARKS, DEMOS):
        if str(folder) not in sys.path:
            sys.path.append(str(folder))
    path = BENCHMARKS / f"{name}.py"
    spec = importlib.util.spec_from_file_location(alias or f"benchmark_{name}", path)
    module = importlib.util.module_from_spec(spec)
    # registered before it runs: dataclasses look their module up in sys.modules
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def shared_dir():
    """A temporary directory whose path is the same on every rank (rank 0 makes it, and removes
    it after the test once every rank is done with it)."""
    comm = MPI.COMM_WORLD
    path = tempfile.mkdtemp() if comm.rank == 0 else None
    path = comm.bcast(path, root=0)
    yield pathlib.Path(path)
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(path, ignore_errors=True)
