"""Shared parts of the benchmark scripts: loading another demo as a module, the median of
repeated timings and touching memory before the first timed case. The demos are scripts, not a
package; run as ``python demos/bench_X.py`` their folder is on ``sys.path``, so ``from
bench_common import ...`` finds this file (the tests' ``load_demo`` puts the folder there too)."""

from __future__ import annotations

import importlib.util
import pathlib
import sys
import time
from collections.abc import Callable
from types import ModuleType

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent


def load_demo(name: str) -> ModuleType:
    """``demos/<name>.py`` as a module (once per process: later calls return the same one;
    registered before it runs, since dataclasses look their module up in ``sys.modules``)."""
    key = f"bench_demo_{name}"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, HERE / f"{name}.py")
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
