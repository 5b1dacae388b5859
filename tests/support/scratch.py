"""Where the suite's scratch goes: a RAM file system when the machine has a large enough one.

tests/conftest.py puts ``tmp_path`` and the code under test's ``tempfile`` directories there
(``_scratch_in_memory`` says why); bench/suite_bench.py puts its fresh ``--basetemp`` there too, so
that the runs it times write where the README's test command writes.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

#: The RAM file system looked for, and the free space it must have (a container's 64-MB /dev/shm is too small).
MEMORY_ROOT = Path("/dev/shm")
NEED_BYTES = 2 * 2**30


def memory_scratch_root(root: Path = MEMORY_ROOT, need_bytes: int = NEED_BYTES) -> Path | None:
    """``root`` when it is writable with at least ``need_bytes`` free, else None."""
    try:
        free = shutil.disk_usage(root).free
    except OSError:
        return None
    if free < need_bytes or not os.access(root, os.W_OK):
        return None
    return root
