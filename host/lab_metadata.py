"""What a lab user says about a measurement: the sample, its lot, the operator and free notes.

The four fields travel with ``measure``'s answer, into a series file and
onto its report; they are the host's (the device record is not changed).
Each is checked where it is parsed: printable text (no control characters,
so a name cannot break a line of output or a CSV row), not blank, and at
most :data:`MAX_CHARS` characters -- a one-line ``argument --sample: ...``
error (exit 2) otherwise.  Characters with a meaning in HTML (``<``, ``&``)
are allowed: every writer escapes them.
"""

from __future__ import annotations

import argparse
from typing import Any, Callable, Mapping

__all__ = ["FIELDS", "MAX_CHARS", "check_text", "add_metadata_args", "metadata_of", "check_metadata"]

#: The metadata fields, in the order they are shown, with their option's help.
FIELDS = {
    "sample": "name of the sample (specimen) measured",
    "lot": "its lot or batch",
    "operator": "who measured",
    "notes": "free notes (contact agent, conditions, ...)",
}

#: Longest value of each field, characters: names fit a report's table cell, notes a paragraph.
MAX_CHARS = {"sample": 80, "lot": 80, "operator": 80, "notes": 500}


def check_text(field: str, text: Any) -> str:
    """``text`` as a value of metadata ``field``, stripped of surrounding spaces.

    Raises
    ------
    ValueError
        If it is not a string, blank, longer than ``MAX_CHARS[field]`` or
        holds a non-printable character (the message says which and where).
    """
    if not isinstance(text, str):
        raise ValueError(f"must be text, got {type(text).__name__}")
    value = text.strip()
    if not value:
        raise ValueError("must not be empty")
    limit = MAX_CHARS[field]
    if len(value) > limit:
        raise ValueError(f"at most {limit} characters, got {len(value)}")
    for i, ch in enumerate(value):
        if not ch.isprintable():  # newline, tab, escape sequences, other control or unassigned characters
            raise ValueError(f"non-printable character {ch!r} at position {i + 1}")
    return value


def _converter(field: str) -> Callable[[str], str]:
    def conv(text: str) -> str:
        try:
            return check_text(field, text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    conv.__name__ = "text"
    return conv


def add_metadata_args(p: argparse.ArgumentParser, fields=tuple(FIELDS), helps: Mapping[str, str] | None = None) -> None:
    """``--sample``, ``--lot``, ``--operator``, ``--notes`` (checked by :func:`check_text` when parsed).

    ``helps`` replaces a field's help where the verb means something narrower (a certificate's issuer).
    """
    for field in fields:
        what = (helps or {}).get(field, FIELDS[field])
        p.add_argument(f"--{field}", type=_converter(field), default=None, metavar="TEXT",
                       help=f"{what} (printable, at most {MAX_CHARS[field]} characters)")


def metadata_of(args: argparse.Namespace) -> dict[str, str | None]:
    """The four fields from parsed arguments (None where not given)."""
    return {field: getattr(args, field, None) for field in FIELDS}


def check_metadata(d: Any) -> dict[str, str | None]:
    """A metadata table read from a file: the four fields, each None or valid text.

    Raises
    ------
    ValueError
        Naming the field at fault (``metadata.sample: must not be empty``).
    """
    if not isinstance(d, Mapping):
        raise ValueError("metadata: must be a table")
    out: dict[str, str | None] = {}
    for field in FIELDS:
        v = d.get(field)
        if v is None:
            out[field] = None
            continue
        try:
            out[field] = check_text(field, v)
        except ValueError as exc:
            raise ValueError(f"metadata.{field}: {exc}") from None
    return out
