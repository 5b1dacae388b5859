"""Signing keys on the host: make them, list them, sign a bundle's manifest with one.

A key is two files in the key directory (default ``~/.config/thermotouch/keys``,
or ``$THERMOTOUCH_KEYS``)::

    NAME.secret.json   the secret key (mode 0600): stays on the host
    NAME.public.json   the public key: copy it into the probe's security.trusted_keys_dir

Formats: :mod:`edge.security.keys`.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

from edge.security.keys import KeyFileError, PublicKey, SecretKey, read_key, signature_document
from host.atomic import atomic_path

__all__ = ["KEYS_ENV", "DEFAULT_NAME", "default_keys_dir", "key_paths", "new_key", "list_keys", "load_secret_key",
           "sign_manifest", "KeyEntry"]

#: Environment variable overriding the default key directory.
KEYS_ENV = "THERMOTOUCH_KEYS"
#: Key name when none is given.
DEFAULT_NAME = "thermotouch"

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


def default_keys_dir() -> Path:
    """``$THERMOTOUCH_KEYS``, else ``~/.config/thermotouch/keys``."""
    env = os.environ.get(KEYS_ENV)
    return Path(env) if env else Path.home() / ".config" / "thermotouch" / "keys"


def key_paths(directory: str | os.PathLike, name: str) -> tuple[Path, Path]:
    """``(secret file, public file)`` of key ``name`` in ``directory``.

    Raises
    ------
    ValueError
        ``name`` is not 1-64 letters, digits, '.', '_' or '-' (starting with a letter or digit).
    """
    if not _NAME_RE.match(name or ""):
        raise ValueError(f"key name {name!r} must be 1-64 letters, digits, '.', '_' or '-', "
                         "starting with a letter or digit")
    d = Path(directory)
    return d / f"{name}.secret.json", d / f"{name}.public.json"


def _write_json(path: Path, doc: dict, mode: int | None) -> None:
    with atomic_path(path, mode=mode) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(json.dumps(doc, indent=1, sort_keys=True) + "\n")


def new_key(directory: str | os.PathLike, name: str = DEFAULT_NAME, *, overwrite: bool = False) -> SecretKey:
    """Generate a key pair and write its two files (atomically; the secret one 0600).

    The directory is created (0700) if missing.

    Raises
    ------
    FileExistsError
        A file of that key exists and ``overwrite`` is false (nothing is written).
    ValueError
        A bad ``name``.
    """
    secret_path, public_path = key_paths(directory, name)
    if not overwrite:
        for p in (secret_path, public_path):
            if os.path.lexists(p):
                raise FileExistsError(f"{p} exists (use --overwrite to replace the key; the old one is lost)")
    d = Path(directory)
    if not d.is_dir():
        d.mkdir(mode=0o700, parents=True)
    key = SecretKey.generate(name)
    # Secret first: a crash in between leaves a secret without its public file (re-derivable), never the reverse.
    _write_json(secret_path, key.document(), 0o600)
    _write_json(public_path, key.public_key().document(), None)
    return key


@dataclass(frozen=True)
class KeyEntry:
    """One file of a key directory: its key, or why it does not parse."""

    path: Path
    key: PublicKey | SecretKey | None
    error: str | None = None


def list_keys(directory: str | os.PathLike) -> list[KeyEntry]:
    """Every ``*.json`` in ``directory``, parsed, sorted by file name.

    Raises
    ------
    NotADirectoryError
        ``directory`` does not exist or is not a directory.
    """
    d = Path(directory)
    if not d.is_dir():
        raise NotADirectoryError(f"key directory {d} does not exist (make a key: thermotouch keys new)")
    out = []
    for p in sorted(d.glob("*.json")):
        try:
            out.append(KeyEntry(p, read_key(p)))
        except KeyFileError as e:
            out.append(KeyEntry(p, None, str(e)))
    return out


def load_secret_key(path: str | os.PathLike) -> SecretKey:
    """The secret key in ``path``.

    Raises
    ------
    KeyFileError
        Unreadable, malformed, or a public key file (signing needs the secret one).
    """
    key = read_key(path)
    if not isinstance(key, SecretKey):
        raise KeyFileError(f"{path}: a public key file; signing needs the secret key file (NAME.secret.json)")
    return key


def sign_manifest(bundle_dir: str | os.PathLike, key: SecretKey) -> bytes:
    """``signature.json`` bytes for the bundle in ``bundle_dir``: a signature over its ``manifest.json`` bytes."""
    from edge.model.bundle import DEFAULT_LIMITS, MANIFEST_FILE, read_regular_file  # noqa: PLC0415

    manifest = read_regular_file(Path(bundle_dir) / MANIFEST_FILE, MANIFEST_FILE, DEFAULT_LIMITS.max_manifest_bytes)
    return signature_document(key, manifest)
