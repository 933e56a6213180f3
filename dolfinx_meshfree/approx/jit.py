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

__all__ = [
    "AVAILABLE",
    "carray",
    "default_backend",
    "jit",
    "num_threads",
    "resolve_backend",
    "stack_pointer",
]

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

    from numba import carray, types
    from numba.core import cgutils
    from numba.extending import intrinsic

    @intrinsic
    def stack_pointer(typingctx: Any, size: Any) -> Any:
        """A pointer to ``size`` (an integer literal) float64 on the stack of the compiled
        function that calls it: with :func:`carray`, a small work array that costs no
        allocation and no reference counting, and whose entries LLVM keeps in registers when
        they are indexed by constants (loops over a basis of compile-time size, unrolled)."""
        if not isinstance(size, types.IntegerLiteral):
            return None
        n = size.literal_value

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            return cgutils.alloca_once(builder, context.get_value_type(types.float64), size=n)

        return types.CPointer(types.float64)(size), codegen

else:

    def jit(fn: F) -> F:
        """Without numba the function stays plain Python (never called by the default paths)."""
        return fn

    carray = stack_pointer = None  # used only inside compiled functions


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


def default_backend(env_var: str, fallback: str = "numpy") -> str:
    """The default backend of a module with a compiled and a reference implementation: the
    environment variable ``env_var`` if set (e.g. to run a test suite on the reference path),
    else ``"numba"`` when numba is importable, else ``fallback``."""
    return os.environ.get(env_var) or ("numba" if AVAILABLE else fallback)


def resolve_backend(
    name: str,
    env_var: str,
    backends: tuple[str, ...] = ("numba", "numpy"),
    argument: str = "backend",
) -> str:
    """``name`` checked against ``backends`` (the compiled one first, the reference last);
    ``argument``: the name of the argument it came from, for the messages.

    Raises:
        ValueError: An unknown backend (naming ``argument`` and ``env_var``, where it may come
            from), or ``"numba"`` without numba.
    """
    if name not in backends:
        raise ValueError(
            f"{argument}={name!r} (argument or {env_var}) is not known; use one of {backends}"
        )
    if name == "numba" and not AVAILABLE:
        raise ValueError(
            f"{argument}='numba' needs numba, which is not importable: install numba "
            f"(python3-numba or pip install numba) or use {argument}={backends[-1]!r}"
        )
    return name
