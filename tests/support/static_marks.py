"""Test modules a ``-m`` expression leaves out entirely, told from their source without importing them.

Collection imports every test module before ``-m`` deselects, so the fast tier (``-m "not slow"``)
imports, and on a fresh clone assertion-rewrites, the 25 modules whose every test is slow by their
module-level ``pytestmark`` (about 0.7 s of CPU to rewrite and 0.1 s per xdist worker to import).
A module whose ``pytestmark`` line names marks under which the expression is false whatever the
module's tests add is not collected at all: its tests would all have been deselected. Only the
plain form is read (one top-level ``pytestmark = pytest.mark.a`` or a one-line list or tuple of
such marks, with or without arguments, and no other mention of ``pytestmark`` in the file);
anything else is collected as before. A test's own marks can only add marks, never remove one, so
a module skipped here has no test the expression selects. ``tests/conftest.py``
(``pytest_ignore_collect``) and ``tests/support/rewrite_share.py`` use it.
"""

from __future__ import annotations

import ast
import itertools
import re
from collections.abc import Callable
from pathlib import Path

_ASSIGN = re.compile(r"^pytestmark[ \t]*=[^\n]*$", re.MULTILINE)
#: More identifiers than this in an expression: too many cases to try, the module is collected.
MAX_FREE_IDENTS = 10


def _mark_name(node: ast.expr) -> str | None:
    """``NAME`` of ``pytest.mark.NAME`` or ``pytest.mark.NAME(...)``, else None."""
    if isinstance(node, ast.Call):
        node = node.func
    if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Attribute)
            and node.value.attr == "mark" and isinstance(node.value.value, ast.Name)
            and node.value.value.id == "pytest"):
        return node.attr
    return None


def module_marks(source: str) -> frozenset[str] | None:
    """The mark names of a module's plain ``pytestmark`` line, or None where the source has none or another form."""
    if source.count("pytestmark") != 1:
        return None
    m = _ASSIGN.search(source)
    if m is None:
        return None
    try:
        stmt = ast.parse(m.group(0)).body[0]
    except SyntaxError:  # a statement continued on the next lines
        return None
    value = stmt.value if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 else None
    elts = value.elts if isinstance(value, (ast.List, ast.Tuple)) else [value]
    names = [_mark_name(e) for e in elts if e is not None]
    if value is None or not names or None in names:
        return None
    return frozenset(names)


class _Unsure(Exception):
    """The expression asks about a mark's arguments: the static reading cannot say."""


def excludes(markexpr: str, marks: frozenset[str]) -> bool:
    """Whether no test carrying ``marks`` (and any others) can match ``markexpr``.

    True only if the expression is false for every truth value of the identifiers not in ``marks``;
    False for an empty, malformed or argument-matching expression.
    """
    if not markexpr or not marks:
        return False
    from _pytest.mark.expression import Expression

    try:
        expr = Expression.compile(markexpr)
        free = sorted(set(expr.idents()) - marks)
    except Exception:  # malformed (pytest reports it), or a pytest without idents()
        return False
    if len(free) > MAX_FREE_IDENTS:
        return False
    for values in itertools.product((False, True), repeat=len(free)):
        truth = dict(zip(free, values))

        def matcher(name: str, /, **kwargs) -> bool:
            if kwargs:
                raise _Unsure
            return name in marks or truth.get(name, False)

        try:
            if expr.evaluate(matcher):
                return False
        except _Unsure:
            return False
    return True


def excluded_module(path: Path, markexpr: str) -> bool:
    """Whether the test module at ``path`` has no test that ``-m markexpr`` could select (read statically)."""
    if not markexpr:
        return False
    try:
        source = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return False
    marks = module_marks(source)
    return marks is not None and excludes(markexpr, marks)


def excluded_by(markexpr: str) -> Callable[[Path], bool]:
    """``excluded_module`` for one expression (its answer per path is what collection and warming share)."""
    return lambda path: excluded_module(path, markexpr)
