"""What the CLI writes reaches a terminal: text from outside (object names, file content, a device's
replies) must not carry control sequences into it.

An object named ``"\\x1b]0;pwned\\x07"`` in a user's set, or a device reply holding ESC, would
otherwise retitle, recolour or rewrite the user's terminal when ``measure`` prints it (ISSUE #35
§10). :class:`NeutralStream` wraps the CLI's stdout for the length of one verb and writes every
control character except tab, newline and carriage return (progress lines use it) as a visible
escape. JSON output is already escaped by ``json.dumps``; this covers the text forms.
"""

from __future__ import annotations

import re
from typing import Any, TextIO

__all__ = ["neutralise", "NeutralStream"]

# C0 controls but \t \n \r, DEL, and the C1 controls (0x80-0x9f: 0x9b is a one-byte CSI).
_CONTROL = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f]")


def neutralise(text: str) -> str:
    """``text`` with every control character but tab, newline and CR written as ``\\xNN``."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


class NeutralStream:
    """A text stream that writes :func:`neutralise`-d text to ``stream`` (everything else passes through)."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        self._stream.write(neutralise(text))
        return len(text)

    def __getattr__(self, name: str) -> Any:  # flush, fileno, isatty, encoding ... of the real stream
        return getattr(self._stream, name)
