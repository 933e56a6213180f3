"""The one gate to numba: whether it is importable, and the decorator the compiled kernels use.

numba is a dependency (Debian's ``python3-numba`` in lane A, PyPI's ``numba`` in lane B), but the
package still imports and runs without it: the numpy implementations are then used (they are
the reference the compiled kernels are tested against). ``AVAILABLE`` says which one runs.

The kernels are compiled on first use and cached on disk (``cache=True``: next to the module, or
in numba's user-wide cache directory when the install is read-only; ``NUMBA_CACHE_DIR``
overrides the location; without any writable place they are compiled in every process). IEEE
semantics are kept (no ``fastmath``), and a division by zero gives inf/nan as numpy does
(``error_model="numpy"``) instead of raising: singular moment matrices are detected from the
results.
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["AVAILABLE", "jit", "num_threads"]

#: True when numba can be imported: the compiled kernels are then the default.
AVAILABLE: bool = importlib.util.find_spec("numba") is not None

F = TypeVar("F", bound=Callable[..., Any])

if AVAILABLE:
    import numba as _numba

    def jit(fn: F) -> F:
        """Compile ``fn`` in nopython mode (cached on disk, numpy error model, no fastmath).

        Where no cache directory is writable (a read-only install, an unwritable home and no
        ``NUMBA_CACHE_DIR``) numba refuses ``cache=True`` with a RuntimeError when the function
        is decorated; the function is then compiled in every process instead.
        """
        try:
            return _numba.njit(cache=True, error_model="numpy", nogil=True)(fn)
        except RuntimeError:  # "cannot cache function ...: no locator available"
            return _numba.njit(cache=False, error_model="numpy", nogil=True)(fn)

else:

    def jit(fn: F) -> F:
        """Without numba the function stays plain Python (never called by the default paths)."""
        return fn


def num_threads() -> int:
    """The threads a compiled path may use (its kernels release the GIL): the environment
    variable ``DOLFINX_MESHFREE_THREADS``, 1 by default, so that MPI ranks sharing a node's
    cores are not oversubscribed; ignored without numba."""
    value = os.environ.get("DOLFINX_MESHFREE_THREADS", "1")
    if not (value.isdigit() and int(value) >= 1):
        raise ValueError(
            f"DOLFINX_MESHFREE_THREADS={value!r} is not a positive integer; set it to the "
            "number of threads per process (e.g. 2) or unset it (1 thread)"
        )
    return int(value) if AVAILABLE else 1
