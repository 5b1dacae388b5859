"""Which test modules an xdist worker imports before it collects, to share pytest's assertion rewriting.

pytest rewrites each test module's asserts and caches the result beside it (``__pycache__``, one
file per module).  Without that cache (CI's clean clone) every xdist worker rewrites every module:
the same work n times over, about 2.5 s of CPU per worker for this suite.  Worker gw0 collects from
the first module on; worker gwi (i >= 1) first imports the i-th of n equal slices of the modules
(in the order collection walks them), so each finds the others' slices already rewritten.  Modules
collection will not import (``skip``: those a ``-m`` expression leaves out, tests/support/static_marks.py)
are in no slice.  ``tests/conftest.py`` (``pytest_collection``) uses it, and gives the rewriter a
quicker walk for its location fix (:func:`quicker_location_fix`, same rewritten code).

The project's own modules (edge, host, firmware_sim, ...: collection imports nearly all of them) are
compiled the same way twice over on a fresh checkout: both workers import them at once and each
compiles what it finds without bytecode (0.45 CPU-s for the ~250 files).  Before it imports, each
worker compiles its share of them (:func:`sources_to_compile`, slices of equal size in bytes) to the
bytecode file import would write (:func:`compile_missing`), so each finds the other's share done.
"""

from __future__ import annotations

import ast
import importlib.util
import os
import py_compile
from collections.abc import Callable, Iterable
from pathlib import Path

#: The project's packages under its root whose modules a test collection imports (tests: the helpers,
#: not the test modules or conftest files, which pytest rewrites into bytecode files of its own).
PROJECT_PACKAGES = ("edge", "host", "firmware_sim", "models", "tests")


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


def sources_to_compile(project_root: Path, worker: str, n_workers: int,
                       packages: Iterable[str] = PROJECT_PACKAGES) -> list[Path]:
    """The project source files worker ``worker`` (``"gw<i>"``) compiles first: the i-th of n slices; none without workers.

    Every ``*.py`` under ``packages`` except test modules and conftest files, in sorted order, cut into
    ``n_workers`` consecutive slices of about equal size in bytes (compile time goes with it).
    """
    if n_workers < 2 or not worker.startswith("gw") or not worker[2:].isdigit():
        return []
    i = int(worker[2:]) % n_workers
    paths = sorted(p for pkg in packages for p in (project_root / pkg).rglob("*.py")
                   if not (p.name.startswith("test_") or p.name == "conftest.py") and "__pycache__" not in p.parts)
    sizes = [p.stat().st_size for p in paths]
    total, out, acc = sum(sizes), [], 0
    for path, size in zip(paths, sizes):
        # The slice of a file is where its middle byte falls: slices meet, none overlap.
        if int((acc + size / 2) * n_workers // max(total, 1)) == i:
            out.append(path)
        acc += size
    return out


def compile_missing(paths: Iterable[Path]) -> int:
    """Compile each source that has no bytecode file yet, to the file import would write; returns how many.

    Timestamp-checked, as import writes them (``py_compile`` would otherwise write hash-checked files
    where ``SOURCE_DATE_EPOCH`` is set, which import then checks by hashing the source each time). A
    file that does not compile is left to import, which reports it; a stale bytecode file too.
    """
    done = 0
    for path in paths:
        try:
            cfile = importlib.util.cache_from_source(os.fspath(path))
            if os.path.exists(cfile):
                continue
            py_compile.compile(os.fspath(path), cfile=cfile, doraise=True,
                               invalidation_mode=py_compile.PycInvalidationMode.TIMESTAMP)
            done += 1
        except (py_compile.PyCompileError, OSError, ValueError, NotImplementedError):
            pass
    return done


def _located_candidates(node):
    """The nodes of ``node``'s tree that pytest's location fix would change, depth-first in field order.

    pytest's ``visit_Assert`` walks every node of each statement it generates
    (``traverse_node``, a recursive generator over ``ast.iter_child_nodes``) and calls
    ``ast.copy_location`` on each without a ``lineno``; for a node that has no location
    attributes at all (``Load``, operators, ``comprehension``) that call does nothing. Yielding only
    the nodes that take a location, from an explicit stack, gives the same tree: the rewritten
    modules compile to the same code objects (tests/test_rewrite_share.py).
    """
    ast_node = ast.AST
    stack = [node]
    while stack:
        n = stack.pop()
        if "lineno" in n._attributes and getattr(n, "lineno", None) is None:
            yield n
        kids = []
        for name in n._fields:
            v = getattr(n, name, None)
            if isinstance(v, ast_node):
                kids.append(v)
            elif isinstance(v, list):
                kids.extend(x for x in v if isinstance(x, ast_node))
        kids.reverse()
        stack.extend(kids)


def quicker_location_fix() -> bool:
    """Give pytest's assertion rewriter the walk above (about 20 % less CPU per rewritten module).

    Rewriting the suite's ~200 test modules costs ~2.3 CPU-s on a fresh clone (no bytecode), of
    which ~0.45 s goes to visiting nodes the fix leaves alone. Applied only where pytest's rewriter
    has the function this replaces, used only by that fix (pytest 9); returns whether it was.
    """
    import _pytest.assertion.rewrite as rewrite
    import pytest

    if pytest.version_tuple[0] != 9 or not callable(getattr(rewrite, "traverse_node", None)) or not hasattr(rewrite.AssertionRewriter, "visit_Assert"):
        return False
    rewrite.traverse_node = _located_candidates
    return True
