"""Keep the network training's large arrays on the heap (glibc), instead of a fresh mapping per array.

scikit-learn's lbfgs training of the paper's network allocates and frees its
activations and gradients (samples x 100 hidden units: tens of MB each) on
every one of its ~800 loss evaluations.  glibc serves any block above its
mmap threshold -- at most 32 MiB however it adapts -- with a new mapping and
returns it on free, so every evaluation faulted in, zeroed and unmapped the
same memory again: 2.6 s of the full recipe's 9 s was kernel time
(``/usr/bin/time`` on the gate's retrain test).  Inside :func:`large_blocks_on_heap`
blocks up to ``threshold_bytes`` come from the heap and freed ones are kept
for the next evaluation.

Only around training (``host.train``): a long-lived process keeps memory it
freed this way, and elsewhere glibc's own adaptation serves well.  A no-op
where the C library has no ``mallopt`` (not glibc).  Edge code never imports
this module.
"""

from __future__ import annotations

import contextlib
import ctypes
from collections.abc import Iterator

# mallopt(3) parameters (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: What the thresholds return to after training: glibc's own ceilings for its adaptive thresholds
#: (32 MiB for mmap on 64-bit, twice that for trimming).  Setting a threshold once switches glibc's
#: adaptation off for the process, so they are set to where it would have settled for large arrays.
AFTER_MMAP_BYTES = 32 * 1024 * 1024
AFTER_TRIM_BYTES = 2 * AFTER_MMAP_BYTES
#: Default ceiling inside the block: above the largest training array of the shipped recipe.
DEFAULT_THRESHOLD_BYTES = 1024 * 1024 * 1024


def _mallopt():
    # The process's own symbols (libc is loaded already): no ctypes.util.find_library, which runs
    # ldconfig in a subprocess on Linux.
    try:
        fn = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return None
    fn.argtypes = (ctypes.c_int, ctypes.c_int)
    fn.restype = ctypes.c_int
    return fn


_MALLOPT = _mallopt()


def available() -> bool:
    """Whether this C library has ``mallopt`` (glibc)."""
    return _MALLOPT is not None


@contextlib.contextmanager
def large_blocks_on_heap(threshold_bytes: int = DEFAULT_THRESHOLD_BYTES) -> Iterator[bool]:
    """Blocks up to ``threshold_bytes`` from the heap, and freed memory kept, inside the ``with``.

    Yields whether it took effect (False without ``mallopt``).
    """
    threshold_bytes = int(threshold_bytes)
    if not 0 < threshold_bytes < 2**31:
        raise ValueError(f"threshold_bytes must be in (0, 2**31), got {threshold_bytes}")
    fn = _MALLOPT
    on = fn is not None and bool(fn(_M_MMAP_THRESHOLD, threshold_bytes)) and bool(
        fn(_M_TRIM_THRESHOLD, 2**31 - 1))
    try:
        yield on
    finally:
        if fn is not None:
            fn(_M_TRIM_THRESHOLD, AFTER_TRIM_BYTES)
            fn(_M_MMAP_THRESHOLD, AFTER_MMAP_BYTES)
