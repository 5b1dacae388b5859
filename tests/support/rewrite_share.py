"""Which test modules an xdist worker imports before it collects, to share pytest's assertion rewriting.

pytest rewrites each test module's asserts and caches the result beside it (``__pycache__``, one
file per module).  Without that cache (CI's clean clone) every xdist worker rewrites every module:
the same work n times over, about 2.5 s of CPU per worker for this suite.  Worker gw0 collects from
the first module on; worker gwi (i >= 1) first imports the i-th of n equal slices of the modules
(in the order collection walks them), so each finds the others' slices already rewritten.  Modules
collection will not import (``skip``: those a ``-m`` expression leaves out, tests/support/static_marks.py)
are in no slice.  ``tests/conftest.py`` (``pytest_collection``) uses it, and gives the rewriter a
quicker walk for its location fix (:func:`quicker_location_fix`, same rewritten code).
"""

from __future__ import annotations

import ast
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
