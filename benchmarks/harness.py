"""The shared harness of the benchmarks in this folder (``benchmarks/bench_*.py``).

What it gives them: a demo of ``demos/`` loaded as a module (:func:`load_demo`; the benchmarks
time the demos' models), the median of repeated timings (:func:`median_time`), memory touched
once before the first timed case (:func:`prefault_memory`), the tables of cases and their ratios
to a reference (:func:`print_table`, :func:`ratio`), a description of the machine
(:func:`machine`) and the one way to write results (:func:`write_json`).

The rules every benchmark keeps:

* **ratios within one run**: the machines are shared and noisy, so absolute seconds of two runs
  do not compare; a benchmark times its cases and their reference (FE, the uniform rule, one
  rank, ...) in the same run and reports the ratios (no timing is checked by the tests);
* **JSON with the command and the machine**: every JSON file a benchmark writes goes through
  :func:`write_json`, which records the command as run and :func:`machine` beside the records;
* **JIT warmed first**: numba's compilation (or its cache load) and DOLFINx's form compilation
  run in a warm-up before the first timed case, outside every timing.

The benchmarks are scripts, not a package: run as ``python benchmarks/bench_X.py`` (from the
repository's root) their folder is on ``sys.path``, so ``from harness import ...`` finds this
file; importing it puts ``demos/`` on ``sys.path`` too, for the demos that import their siblings
(``sif_common``). The tests' ``load_benchmark`` puts both folders there.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import importlib.util
import json
import os
import pathlib
import platform
import re
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from types import ModuleType

import dolfinx_meshfree as mf

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
DEMOS = ROOT / "demos"
if str(DEMOS) not in sys.path:
    sys.path.append(str(DEMOS))


def load_demo(name: str) -> ModuleType:
    """``demos/<name>.py`` as a module (once per process: later calls return the same one;
    registered before it runs, since dataclasses look their module up in ``sys.modules``)."""
    key = f"bench_demo_{name}"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, DEMOS / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module
        spec.loader.exec_module(module)
    return sys.modules[key]


def median_time(
    fn: Callable[[], object], repeats: int, clock: Callable[[], float] = time.perf_counter
) -> float:
    """The median over ``repeats`` calls of ``fn`` of the time on ``clock`` (wall by default;
    ``time.process_time`` for CPU seconds)."""
    times = []
    for _ in range(repeats):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return float(np.median(times))


def prefault_memory(gib: float) -> float:
    """Write ``gib`` GiB once and free them; returns the seconds it took.

    On these machines (virtual machines whose guest memory the host backs on first use) the
    first write of fresh memory in a process costs about 2 s per GiB, later ones 0.06 s per GiB
    (measured: 4.1 s, then 0.13 s, for 2 GiB). Without this the first timed case of a
    benchmark pays it alone: bench_balance's first one-rank cantilever set-up took 3.6 s
    against 1.6 s for the same run repeated (h = 0.0625), which inflated the speed-ups over
    it. Call it before the first case with about the largest case's peak per process."""
    t0 = time.perf_counter()
    if gib > 0:
        block = np.empty(int(gib * 2**30) // 8)
        block.fill(1.0)
        del block
    return time.perf_counter() - t0


def ratio(a: float | None, b: float | None) -> float | None:
    """``a / b`` (a case over its reference in the same run: "x FE", a speed-up); None where
    either is missing or ``b`` is 0."""
    return None if a is None or b is None or b == 0 else a / b


def _width(spec: str) -> int | None:
    """The width of a format spec (``"8.3f"``: 8, ``">9"``: 9, ``".2e"``: None)."""
    match = re.match(r"[<>^]?(\d+)", spec)
    return int(match.group(1)) if match else None


def print_table(
    columns: Sequence[tuple[str, str]], rows: Iterable[Sequence], markdown: bool = False
) -> None:
    """Print a table: a line of the column titles, a rule and a line per row.

    ``columns`` are (title, format spec of the column's cells) pairs, e.g. ``("x FE", "6.2f")``;
    the spec's width (if any) is the column's, the titles align right (left with a ``<`` spec).
    A cell that is a ``str`` prints as it is (aligned to the width), ``None`` as a blank
    (markdown: ``-``), anything else by the spec; ratios are best computed by :func:`ratio`.
    ``markdown``: ``| a | b |`` rows under ``|---|---|``, else columns of fixed width joined by
    a space under a dashed rule."""
    specs = [spec for _, spec in columns]
    widths = [_width(spec) or 0 for spec in specs]
    align = ["<" if spec.startswith("<") else ">" for spec in specs]

    def cell(value, spec: str, width: int, side: str) -> str:
        if value is None:
            value = "-" if markdown else ""
        text = value if isinstance(value, str) else format(value, spec)
        return f"{text:{side}{width}}" if width else text

    if markdown:
        print("| " + " | ".join(title for title, _ in columns) + " |")
        print("|---" * len(columns) + "|")
    else:
        head = " ".join(
            f"{title:{a}{w}}" for (title, _), w, a in zip(columns, widths, align, strict=True)
        )
        print(head)
        print("-" * len(head))
    for row in rows:
        cells = [cell(*c) for c in zip(row, specs, widths, align, strict=True)]
        print("| " + " | ".join(cells) + " |" if markdown else " ".join(cells))


def _first_value(path: str, key: str) -> str | None:
    """The value of the first ``key: value`` line of a ``/proc`` file (None if absent)."""
    try:
        with open(path) as f:
            for line in f:
                name, _, value = line.partition(":")
                if name.strip() == key:
                    return value.strip()
    except OSError:
        return None
    return None


def _version(package: str) -> str | None:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return None


def machine() -> dict:
    """What ran the benchmark (not which host: no hostname): the CPU model
    (``/proc/cpuinfo``), the cores, the total memory, the OS, the versions of Python, DOLFINx,
    PETSc and numba (None: not installed), the MPI ranks, the lane (``"a"``: DOLFINx 0.5,
    ``"b"``: the newer DOLFINx), the thread settings and the date and time (UTC)."""
    cpu = _first_value("/proc/cpuinfo", "model name") or platform.processor() or None
    mem_kb = _first_value("/proc/meminfo", "MemTotal")
    affinity = getattr(os, "sched_getaffinity", None)
    major_minor = tuple(mf.DOLFINX_VERSION.split(".")[:2])
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "cores_available": len(affinity(0)) if affinity else os.cpu_count(),
        "memory_gib": None if mem_kb is None else round(int(mem_kb.split()[0]) / 2**20, 2),
        "os": platform.platform(),
        "python": platform.python_version(),
        "dolfinx": mf.DOLFINX_VERSION,
        "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()),
        "numba": _version("numba"),
        "mpi_ranks": MPI.COMM_WORLD.size,
        "lane": "a" if major_minor == ("0", "5") else "b",
        "threads": {
            k: os.environ.get(k)
            for k in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS", "DOLFINX_MESHFREE_THREADS")
        },
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def command() -> str:
    """``sys.argv`` as run, joined by spaces, the script's path relative to the repository's
    root (as given where it lies outside)."""
    argv = list(sys.argv) or [""]
    script = pathlib.Path(argv[0]).resolve()
    shown = script.relative_to(ROOT) if script.is_relative_to(ROOT) else argv[0]
    return " ".join([str(shown), *argv[1:]])


def write_json(path: str | os.PathLike | None, records: list | dict, **meta) -> None:
    """Write ``{"command": command(), "machine": machine(), "records": records, **meta}`` to
    ``path`` on rank 0 (the other ranks write nothing; its folders are made first). Nothing
    at all without a path (``--json`` not given)."""
    if not path or MPI.COMM_WORLD.rank != 0:
        return
    out = {"command": command(), "machine": machine(), "records": records, **meta}
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
