"""What each quality flag means and what to do about it, read from the ``#:`` comments of ``edge.status.Flag``.

One source of truth: the flag's explanation is the ``#:`` comment block
above its member in ``edge/status.py`` (Sphinx's attribute-doc form), and its
group is the ``# -- from ...`` line above the block.  They are read from the
module's source with :mod:`tokenize` (comments are not in the AST) and
matched to the members by :mod:`ast`, so a flag added to the enum with its
comment shows in ``thermotouch flags``, in reports and in the docs without a
second table to keep in step (``tests/host/cli/test_flags.py`` checks that
every member has one).
"""

from __future__ import annotations

import ast
import functools
import inspect
import io
import tokenize
from dataclasses import dataclass

__all__ = ["FlagDoc", "flag_docs", "parse_flag_docs", "describe_flag"]


@dataclass(frozen=True)
class FlagDoc:
    """One flag word: its member name, its group (who raises it) and its explanation."""

    word: str
    member: str
    group: str
    text: str


def _comments_by_line(source: str) -> dict[int, str]:
    out = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            out[tok.start[0]] = tok.string
    return out


@functools.lru_cache(maxsize=1)
def flag_docs() -> tuple[FlagDoc, ...]:
    """Every :class:`edge.status.Flag` member, in the enum's order, with its group and explanation.

    A member whose source cannot be read (a stripped install) gets an
    empty explanation rather than failing the command that asked.
    """
    import edge.status as status  # noqa: PLC0415

    members = {m.name: m.value for m in status.Flag}
    try:
        source = inspect.getsource(status)
    except (OSError, TypeError):
        return tuple(FlagDoc(v, k, "", "") for k, v in members.items())
    return parse_flag_docs(source, members)


def parse_flag_docs(source: str, members: dict[str, str]) -> tuple[FlagDoc, ...]:
    """The :class:`FlagDoc` of each member (``{name: word}``) of ``class Flag`` in ``source``."""
    comments = _comments_by_line(source)
    lines = source.splitlines()
    cls = next(n for n in ast.parse(source).body if isinstance(n, ast.ClassDef) and n.name == "Flag")
    docs, group = [], ""
    for node in cls.body:
        if not (isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name)):
            continue
        name = node.targets[0].id
        if name not in members:
            continue
        block = []
        ln = node.lineno - 1  # 1-based line above the member
        while ln > 0 and lines[ln - 1].strip().startswith("#:"):
            block.append(comments.get(ln, "#:")[2:].strip())
            ln -= 1
        # the nearest ``# -- from ...`` line above, within the class: the group
        probe = ln
        while probe > cls.lineno:
            text = lines[probe - 1].strip()
            if text.startswith("# --"):
                group = text[4:].strip()
                break
            probe -= 1
        docs.append(FlagDoc(members[name], name, group, " ".join(reversed(block)).strip()))
    return tuple(docs)


def describe_flag(word: str) -> str:
    """The explanation of flag ``word``; a word that is not a Flag says so (an older or newer device's)."""
    for d in flag_docs():
        if d.word == word:
            return d.text or "(no description in this installation)"
    return "not a flag this software knows (a newer device's?)"
