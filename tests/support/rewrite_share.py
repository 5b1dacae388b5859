"""Which test modules an xdist worker imports before it collects, to share pytest's assertion rewriting.

pytest rewrites each test module's asserts and caches the result beside it (``__pycache__``, one
file per module).  Without that cache (CI's clean clone) every xdist worker rewrites every module:
the same work n times over, about 2.5 s of CPU per worker for this suite.  Worker gw0 collects from
the first module on; worker gwi (i >= 1) first imports the i-th of n equal slices of the modules
(in the order collection walks them), so each finds the others' slices already rewritten.  Modules
collection will not import (``skip``: those a ``-m`` expression leaves out, tests/support/static_marks.py)
are in no slice.  ``tests/conftest.py`` (``pytest_collection``) uses it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path


def modules_to_warm(test_root: Path, worker: str, n_workers: int,
                    skip: Callable[[Path], bool] | None = None) -> list[str]:
    """Dotted names of the modules worker ``worker`` (``"gw<i>"``) imports first; none for gw0 or one worker.

    ``test_root`` is the test package's directory (its parent is on ``sys.path``); ``skip(path)`` true:
    a module collection leaves out, in no slice.
    """
    if n_workers < 2 or not worker.startswith("gw") or not worker[2:].isdigit():
        return []
    i = int(worker[2:]) % n_workers
    if i == 0:
        return []
    paths = [p for p in sorted(test_root.rglob("test_*.py")) if skip is None or not skip(p)]
    size = -(-len(paths) // n_workers)
    return [".".join(p.relative_to(test_root.parent).with_suffix("").parts)
            for p in paths[i * size:(i + 1) * size]]
