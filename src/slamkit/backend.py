"""numba or NumPy: the one seam where slamkit's compiled kernels are chosen.

numba is optional (``pip install slamkit[fast]``). Whether it can be imported is decided
once, when this module is imported (:data:`AVAILABLE`), and :func:`jit` compiles with
``numba.njit(cache=True)`` when it can (and returns the function as it is otherwise, so
that every module stays importable).

A kernel with a compiled form has a NumPy form beside it: the same numbers (to the bit, or
to a tolerance its tests state where NumPy's BLAS sums in another order), the path without
numba and the oracle the compiled form is tested against. The module that owns the two
declares them once as a pair, ``SEAM.pair(compiled=..., oracle=...)``, and calls the pair;
the pair runs the compiled form under :attr:`Backend.NUMBA` and the oracle under
:attr:`Backend.NUMPY`. This module is the only one that reads which backend is active:
no matcher, no optimiser asks "is numba on?".

The backend is :attr:`Backend.NUMBA` when numba is importable, :attr:`Backend.NUMPY`
otherwise (:attr:`KernelSeam.default`). ``with SEAM.use(Backend.NUMPY):`` runs a block on
the oracles: the tests that compare the two forms and the benchmarks' NumPy column. The
choice is held in a context variable, so it is local to the thread (and the asyncio task)
that made it, and it ends with the block, whatever happens inside.
"""

from __future__ import annotations

import enum
import importlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, TypeVar, cast

import numpy as np

from slamkit.errors import ConfigError

__all__ = ["AVAILABLE", "SEAM", "Backend", "KernelSeam", "jit", "writable"]

F = TypeVar("F", bound=Callable[..., Any])


def _import_numba() -> Any:
    try:  # numba is optional: without it the NumPy oracles run
        return importlib.import_module("numba")
    except ImportError:  # pragma: no cover - depends on the environment
        return None


_NUMBA = _import_numba()
AVAILABLE: bool = _NUMBA is not None
"""numba could be imported (decided once, at import): the default backend is numba."""


def jit(fn: F) -> F:
    """``numba.njit(cache=True)`` when numba is installed, else ``fn`` itself (the seam
    never calls it then, but the module that defines it stays importable)."""
    if _NUMBA is None:  # pragma: no cover - depends on the environment
        return fn
    return cast(F, _NUMBA.njit(cache=True)(fn))


def writable(a: np.ndarray) -> np.ndarray:
    """``a`` itself when C-contiguous and writable, else a copy that is: the kernels are
    compiled once per array type, and a read-only or strided array is another type."""
    if a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(a, order="C")


class Backend(enum.Enum):
    """Which form of a kernel pair runs."""

    NUMBA = "numba"
    """The compiled kernels (numba installed)."""
    NUMPY = "numpy"
    """The NumPy oracles."""


class KernelSeam:
    """The one object that knows the active :class:`Backend` (module docstring)."""

    def __init__(self, default: Backend) -> None:
        self.default = default
        """The backend outside any :meth:`use` block: numba when importable."""
        self._active: ContextVar[Backend] = ContextVar("slamkit_backend", default=default)

    @property
    def backend(self) -> Backend:
        """The backend in force here (the innermost :meth:`use` block's, else the default)."""
        return self._active.get()

    @contextmanager
    def use(self, backend: Backend) -> Iterator[None]:
        """Run the block on ``backend`` (in this thread or task; the previous one after it).
        :attr:`Backend.NUMBA` without numba installed is a :class:`ConfigError`."""
        if backend is Backend.NUMBA and not AVAILABLE:
            raise ConfigError("backend: numba is not installed (pip install slamkit[fast])")
        token = self._active.set(backend)
        try:
            yield
        finally:
            self._active.reset(token)

    def pair(self, *, compiled: F, oracle: F) -> F:
        """One callable for a kernel's two forms (the same signature): ``compiled`` under
        numba, ``oracle`` under NumPy, chosen at each call."""
        active = self._active

        def chosen(*args: Any, **kwargs: Any) -> Any:
            fn = compiled if active.get() is Backend.NUMBA else oracle
            return fn(*args, **kwargs)

        chosen.__name__ = getattr(oracle, "__name__", "kernel")
        chosen.__doc__ = f"{chosen.__name__}: compiled under numba, else the NumPy oracle."
        return cast(F, chosen)


SEAM = KernelSeam(Backend.NUMBA if AVAILABLE else Backend.NUMPY)
"""The seam every kernel pair is declared on."""
