"""One BLAS thread for the host tools, the benches and the test suite.

NumPy's OpenBLAS starts one thread per core.  On a shared two-core machine
those threads fight each other and everything else: ``thermotouch train``
took 85 s with two threads and 15.8 s with one.  The work here is many small
matrix products, which gain nothing from threads, so every host entry point
(``host.cli.main``, ``bench/_common.py``, ``tests/conftest.py``) calls
:func:`limit_blas_threads` - this module is the one place the number is set.

``THERMOTOUCH_BLAS_THREADS`` overrides the default of 1.  Edge code never
imports this module (the device has no threadpoolctl).
"""

from __future__ import annotations

import os

#: Environment variables read by the BLAS/OpenMP runtimes when they load
#: (in this process if NumPy is not imported yet, and in child processes).
BLAS_ENV_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

_limiter = None
_applied: int | None = None   # the limit the last call applied through threadpoolctl


def blas_threads() -> int:
    """Threads to allow: ``$THERMOTOUCH_BLAS_THREADS`` or 1."""
    try:
        n = int(os.environ.get("THERMOTOUCH_BLAS_THREADS", "1"))
    except ValueError:
        n = 1
    return max(1, n)


def set_blas_env(n: int | None = None) -> int:
    """Set the BLAS thread variables for runtimes not loaded yet and for child processes."""
    n = blas_threads() if n is None else int(n)
    for name in BLAS_ENV_VARS:
        os.environ[name] = str(n)
    return n


def limit_blas_threads(n: int | None = None) -> int:
    """Limit BLAS/OpenMP to ``n`` threads (default :func:`blas_threads`), now and in children.

    Sets the environment variables and, through threadpoolctl, the thread
    pools already loaded in this process.  Returns the limit.
    """
    global _limiter, _applied
    n = set_blas_env(n)
    if _applied == n:
        # The pools loaded at the last call hold n, and runtimes loaded since read the variables
        # set above: a second scan of the process's libraries (each CLI call in the test suite,
        # a few ms each) would change nothing.
        return n
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is in the host extra
        return n
    _limiter = threadpool_limits(limits=n)
    _applied = n
    return n
