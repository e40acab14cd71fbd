"""The thread policy of slamkit's dense linear algebra: one BLAS thread unless told otherwise.

slamkit's estimators and its graph optimiser factor and multiply small dense matrices
(a 3×3 pose covariance, a landmark's 2×2 innovation, an EKF-SLAM state of a few hundred
rows) thousands of times a run. Split over two BLAS threads such a product costs more in
hand-over than it saves, and on a machine whose other cores are busy a waiting BLAS thread
can make it many times slower (the measurements are in ``docs/performance.md``). The large
sparse solves of :mod:`slamkit.optim` measured no faster with a second thread either
(CHOLMOD through cvxopt runs its own single-threaded BLAS; SuperLU and the linearisation
were slower with two). So the library runs its work with one BLAS thread:
:func:`slamkit.pipeline.run` (and so ``slamkit run``) and :func:`slamkit.optim.optimize`
(and so ``slamkit optimize``) enter :func:`blas_threads`.

What wins over that default, in order:

* an explicit count, ``blas_threads(n)`` (``run(..., blas_threads=n)``), even inside
  another policy;
* an enclosing ``with blas_threads(...)``: a call inside it keeps what it set (so
  :func:`slamkit.optim.optimize` inside a run costs nothing, and a caller may wrap a call
  in ``with blas_threads(2):``);
* a thread count the user put in the environment (any of :data:`BLAS_ENV_VARS`, e.g.
  ``OPENBLAS_NUM_THREADS=2 slamkit run ...``): BLAS read it when it was loaded, and the
  policy leaves it alone.

The limit is process-wide, as BLAS's own setting is (threadpoolctl sets it in every BLAS
library loaded, NumPy's and SciPy's alike), and is restored when the block ends. This module
is the only place in slamkit that reads those environment variables.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from functools import lru_cache

# SciPy ships a BLAS of its own beside NumPy's, loaded with scipy.linalg. A limit reaches
# only the libraries loaded when it is set, so load it before any limit is.
import scipy.linalg  # noqa: F401
from threadpoolctl import ThreadpoolController, threadpool_info

from slamkit.errors import InputError

__all__ = ["BLAS_ENV_VARS", "DEFAULT_BLAS_THREADS", "blas_thread_counts", "blas_threads"]

DEFAULT_BLAS_THREADS = 1
"""BLAS threads of slamkit's runs unless the caller or the environment says otherwise."""

BLAS_ENV_VARS = (
    "OPENBLAS_NUM_THREADS",
    "GOTO_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
)
"""The variables from which OpenBLAS, MKL and BLIS take their thread count when loaded; one
of them set (not empty) means the user chose, and the default policy steps aside."""

_DECIDED: ContextVar[bool] = ContextVar("slamkit_blas_threads_decided", default=False)
"""Inside a :func:`blas_threads` block (of this thread of control)."""


@lru_cache(maxsize=1)
def _controller(modules_loaded: int) -> ThreadpoolController:
    """threadpoolctl's handle on the BLAS libraries loaded now. Finding them reads the
    process's list of shared libraries (milliseconds, as long as a small graph solve), so the
    handle is kept while the number of imported modules, the key, stays the same: a new BLAS
    comes with a new extension module, which rebuilds it."""
    del modules_loaded  # the cache key only
    return ThreadpoolController()


def _environment_chooses() -> bool:
    return any(os.environ.get(name, "").strip() for name in BLAS_ENV_VARS)


@contextmanager
def blas_threads(threads: int | None = None) -> Iterator[None]:
    """Run the block with ``threads`` BLAS threads; ``None``: the library's policy (the
    module docstring): keep an enclosing block's choice, else the environment's, else
    :data:`DEFAULT_BLAS_THREADS`. The previous counts are restored at the end."""
    if threads is not None and (
        isinstance(threads, bool) or not isinstance(threads, int) or threads < 1
    ):
        raise InputError(f"blas_threads: expected an integer >= 1 or None, got {threads!r}")
    if threads is None and (_DECIDED.get() or _environment_chooses()):
        limit = None  # decided already: by an enclosing block or by the user's environment
    else:
        limit = DEFAULT_BLAS_THREADS if threads is None else threads
    token = _DECIDED.set(True)
    try:
        if limit is None:
            yield
        else:
            with _controller(len(sys.modules)).limit(limits=limit, user_api="blas"):
                yield
    finally:
        _DECIDED.reset(token)


def blas_thread_counts() -> dict[str, int]:
    """The thread count of every BLAS library loaded now that can run threads, by file name
    (what a benchmark records beside its times). A BLAS built without threads (cvxopt's) is
    left out: it has one, whatever the policy."""
    return {
        os.path.basename(str(lib["filepath"])): int(lib["num_threads"])
        for lib in threadpool_info()
        if lib.get("user_api") == "blas" and lib.get("threading_layer") != "disabled"
    }
