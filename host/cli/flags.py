"""``thermotouch flags``: every quality flag word, what it means and what to do, from ``edge.status.Flag``.

``thermotouch flags`` lists them all, grouped by who raises them;
``thermotouch flags noisy no_contact`` explains those words (an unknown word
is one line, exit 2); ``--json`` prints ``[{"word", "group", "text"}]``.  The
text is the ``#:`` comment of each member in ``edge/status.py``
(:mod:`host.flag_docs`), so this list cannot drift from the enum.
"""

from __future__ import annotations

import textwrap

from host.cli.errors import CliError
from host.cli.report import dumps


def add_parser(sub, parents):
    p = sub.add_parser("flags", help="what each quality flag word means and what to do about it", parents=parents)
    p.add_argument("words", nargs="*", metavar="WORD", help="flag words to explain (default: all)")
    p.add_argument("--json", action="store_true", help="print [{word, group, text}] as JSON")
    p.set_defaults(func=run)


def flag_lines(docs) -> list[str]:
    """The text listing: a group heading, then each word with its explanation wrapped and indented."""
    lines, group = [], None
    for d in docs:
        if d.group != group:
            group = d.group
            if lines:
                lines.append("")
            lines.append(f"{(group or 'flags').replace('``', chr(39))}:")
        lines.append(f"  {d.word}")
        lines += textwrap.wrap(d.text.replace("``", "'") or "(no description in this installation)", width=96,
                               initial_indent="      ", subsequent_indent="      ")
    return lines


def run(args) -> int:
    from host.flag_docs import flag_docs  # noqa: PLC0415

    docs = flag_docs()
    if args.words:
        by_word = {d.word: d for d in docs}
        unknown = [w for w in args.words if w not in by_word]
        if unknown:
            raise CliError(f"not a flag word: {', '.join(unknown)} (thermotouch flags lists them)")
        docs = tuple(by_word[w] for w in dict.fromkeys(args.words))
    if args.json:
        print(dumps([{"word": d.word, "group": d.group, "text": d.text} for d in docs]))
    else:
        print("\n".join(flag_lines(docs)))
    return 0
