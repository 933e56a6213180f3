"""Shared parts of the benchmark scripts: loading another demo as a module and the median of
repeated timings. The demos are scripts, not a package; run as ``python demos/bench_X.py``
their folder is on ``sys.path``, so ``from bench_common import ...`` finds this file (the tests'
``load_demo`` puts the folder there too)."""

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
