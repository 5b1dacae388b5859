"""The device's identity: a serial generated at its first start, kept for its life.

A lab needs to know which instrument made a number, and a calibration is only
valid on the probe it was made on (ISSUE #35 §2, #36): the daemon reads
``device_id`` at start, creating it once (random, 64 bits, written durably),
shows it in INFO and carries it in every measurement. It is a name, not a
secret: it identifies, it does not authenticate.
"""

from __future__ import annotations

import re
import secrets
from pathlib import Path

from edge.storage import durable

__all__ = ["DEVICE_ID_RE", "IdentityError", "load_or_create_device_id"]

#: ``tt-`` and 16 lowercase hex digits.
DEVICE_ID_RE = re.compile(r"^tt-[0-9a-f]{16}$")


class IdentityError(RuntimeError):
    """The identity file exists but does not hold an identity (the message names it)."""


def load_or_create_device_id(path: str | Path) -> str:
    """The identity stored at ``path``; a new one is generated and written durably if there is none.

    Raises
    ------
    IdentityError
        The file exists and does not hold an identity (never overwritten: a person should look).
    OSError
        It cannot be read or written.
    """
    p = Path(path)
    try:
        text = p.read_bytes()[:64].decode("ascii", "replace").strip()
    except FileNotFoundError:
        new = f"tt-{secrets.token_hex(8)}"
        p.parent.mkdir(parents=True, exist_ok=True)
        durable.atomic_write_file(p, (new + "\n").encode("ascii"))  # whole or absent after a power cut
        return new
    if not DEVICE_ID_RE.match(text):
        raise IdentityError(f"{p} does not hold a device identity (tt- and 16 hex digits)")
    return text
