"""Key files and detached signatures of updates: small JSON documents, parsed strictly.

Key file (one per key; the host writes them, ``thermotouch keys new``)::

    {"kind": "thermotouch-ed25519-public", "key_id": "<16 hex>", "public_hex": "<64 hex>"}
    {"kind": "thermotouch-ed25519-secret", "key_id": "<16 hex>", "public_hex": "<64 hex>",
     "secret_hex": "<64 hex>"}

``key_id`` is the first 16 hex digits of the SHA-256 of the 32-byte public
key: a name for messages and for choosing the key, never trusted by itself
(the public key it names is what verifies).

Signature of an update (``signature.json`` beside the bundle's manifest)::

    {"key_id": "<16 hex>", "signature_hex": "<128 hex>"}

The signed message is the exact bytes of ``manifest.json``: the manifest lists
the SHA-256 and size of every other file, so one signature covers the bundle.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from edge.security import ed25519

__all__ = [
    "PUBLIC_KIND",
    "SECRET_KIND",
    "SIGNATURE_FILE",
    "KeyFileError",
    "PublicKey",
    "SecretKey",
    "key_id",
    "parse_key",
    "read_key",
    "load_trusted_keys",
    "signature_document",
    "parse_signature",
    "DOWNGRADE_KIND",
    "downgrade_message",
    "downgrade_document",
    "parse_downgrade",
]

PUBLIC_KIND = "thermotouch-ed25519-public"
SECRET_KIND = "thermotouch-ed25519-secret"
#: Name of the detached signature inside a bundle directory and a transport blob.
SIGNATURE_FILE = "signature.json"
#: ``kind`` of a downgrade authorisation (see :func:`downgrade_document`).
DOWNGRADE_KIND = "thermotouch-downgrade"
#: Longest key or signature file read (bytes): a few hundred suffice.
MAX_KEY_FILE_BYTES = 4096

_HEX16 = re.compile(r"^[0-9a-f]{16}$")
_HEX64 = re.compile(r"^[0-9a-f]{64}$")
_HEX128 = re.compile(r"^[0-9a-f]{128}$")


class KeyFileError(ValueError):
    """A key or signature document is malformed; the message names the file or field."""


def key_id(public: bytes) -> str:
    """First 16 hex digits of SHA-256 of the 32-byte public key."""
    return hashlib.sha256(bytes(public)).hexdigest()[:16]


@dataclass(frozen=True)
class PublicKey:
    """A public key and its id (``name``: where it came from, for messages)."""

    public: bytes
    key_id: str
    name: str = ""

    def document(self) -> dict[str, Any]:
        return {"kind": PUBLIC_KIND, "key_id": self.key_id, "public_hex": self.public.hex()}


@dataclass(frozen=True)
class SecretKey:
    """A secret key with its public key and id."""

    secret: bytes
    public: bytes
    key_id: str
    name: str = ""

    @classmethod
    def generate(cls, name: str = "") -> SecretKey:
        sk = ed25519.generate_secret()
        pk = ed25519.public_key(sk)
        return cls(sk, pk, key_id(pk), name)

    def public_key(self) -> PublicKey:
        return PublicKey(self.public, self.key_id, self.name)

    def document(self) -> dict[str, Any]:
        return {"kind": SECRET_KIND, "key_id": self.key_id, "public_hex": self.public.hex(),
                "secret_hex": self.secret.hex()}

    def sign(self, message: bytes) -> bytes:
        return ed25519.sign(self.secret, message)

    def __repr__(self) -> str:  # never print the secret into a log
        return f"SecretKey(key_id={self.key_id!r}, name={self.name!r})"


def _hex_field(doc: dict, name: str, rx: re.Pattern, where: str) -> str:
    v = doc.get(name)
    if not isinstance(v, str) or not rx.match(v):
        n = {_HEX16: 16, _HEX64: 64, _HEX128: 128}[rx]
        raise KeyFileError(f"{where}: {name!r} must be {n} lowercase hex digits")
    return v


def _load_json(data: bytes | str, where: str) -> dict:
    if isinstance(data, bytes) and len(data) > MAX_KEY_FILE_BYTES:
        raise KeyFileError(f"{where}: {len(data)} bytes, more than a key or signature file holds")
    try:
        doc = json.loads(data)
    except (ValueError, UnicodeDecodeError, RecursionError) as e:
        raise KeyFileError(f"{where}: not JSON ({e})") from None
    if not isinstance(doc, dict):
        raise KeyFileError(f"{where}: must be a JSON object")
    return doc


def parse_key(data: bytes | str, where: str = "key file") -> PublicKey | SecretKey:
    """A key file's content as a :class:`PublicKey` or :class:`SecretKey`.

    The ``key_id`` must match the public key, and a secret key's public key
    must be the one it derives: a file edited by hand is refused, not half used.

    Raises
    ------
    KeyFileError
        Naming ``where`` and the field at fault.
    """
    doc = _load_json(data, where)
    kind = doc.get("kind")
    if kind not in (PUBLIC_KIND, SECRET_KIND):
        raise KeyFileError(f"{where}: 'kind' must be {PUBLIC_KIND!r} or {SECRET_KIND!r}, got {kind!r}")
    kid = _hex_field(doc, "key_id", _HEX16, where)
    pub = bytes.fromhex(_hex_field(doc, "public_hex", _HEX64, where))
    if key_id(pub) != kid:
        raise KeyFileError(f"{where}: key_id {kid} does not match its public key ({key_id(pub)})")
    name = Path(where).name if where != "key file" else ""
    if kind == PUBLIC_KIND:
        if "secret_hex" in doc:
            raise KeyFileError(f"{where}: a public key file must not hold 'secret_hex'")
        return PublicKey(pub, kid, name)
    sec = bytes.fromhex(_hex_field(doc, "secret_hex", _HEX64, where))
    if ed25519.public_key(sec) != pub:
        raise KeyFileError(f"{where}: 'secret_hex' does not derive 'public_hex'")
    return SecretKey(sec, pub, kid, name)


def read_key(path: str | os.PathLike) -> PublicKey | SecretKey:
    """Read and parse one key file (bounded read; see :func:`parse_key`)."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            data = f.read(MAX_KEY_FILE_BYTES + 1)
    except OSError as e:
        raise KeyFileError(f"{p}: cannot read ({e.strerror or e})") from None
    return parse_key(data, str(p))


def load_trusted_keys(directory: str | os.PathLike) -> tuple[dict[str, PublicKey], list[str]]:
    """The public keys in ``directory`` (``*.json``), by key id, and why other files were skipped.

    A secret key file found there is used for its public half only (and
    reported: secrets do not belong on the device). A missing directory
    trusts nothing.
    """
    d = Path(directory)
    keys: dict[str, PublicKey] = {}
    skipped: list[str] = []
    if not d.is_dir():
        return keys, [f"{d}: no such directory"]
    for p in sorted(d.glob("*.json")):
        if not p.is_file():
            continue
        try:
            k = read_key(p)
        except KeyFileError as e:
            skipped.append(str(e))
            continue
        if isinstance(k, SecretKey):
            skipped.append(f"{p}: a secret key file; only its public key is trusted (keep secrets off the device)")
            k = k.public_key()
        keys[k.key_id] = k
    return keys, skipped


def signature_document(key: SecretKey, message: bytes) -> bytes:
    """``signature.json`` for ``message`` signed with ``key`` (UTF-8 JSON, newline-terminated)."""
    doc = {"key_id": key.key_id, "signature_hex": key.sign(message).hex()}
    return (json.dumps(doc, sort_keys=True) + "\n").encode("utf-8")


def parse_signature(data: bytes, where: str = SIGNATURE_FILE) -> tuple[str, bytes]:
    """``(key_id, 64-byte signature)`` from a ``signature.json``.

    Raises
    ------
    KeyFileError
        Malformed document.
    """
    doc = _load_json(data, where)
    kid = _hex_field(doc, "key_id", _HEX16, where)
    sig = bytes.fromhex(_hex_field(doc, "signature_hex", _HEX128, where))
    return kid, sig


def downgrade_message(to_sha256: str, from_sha256: str) -> bytes:
    """The bytes a downgrade authorisation signs: the kind and the two model identities it joins.

    Binding both identities addresses the authorisation to one device state: it installs
    ``to_sha256`` only over ``from_sha256``, so once anything else runs (the next update, or the
    rollback itself) a replay of it authorises nothing.
    """
    return f"{DOWNGRADE_KIND}\nto {to_sha256}\nfrom {from_sha256}\n".encode("ascii")


def downgrade_document(key: SecretKey, to_sha256: str, from_sha256: str) -> bytes:
    """A signed authorisation to install model ``to_sha256`` over the active ``from_sha256`` (JSON bytes)."""
    for name, v in (("to_sha256", to_sha256), ("from_sha256", from_sha256)):
        if not isinstance(v, str) or not _HEX64.match(v):
            raise KeyFileError(f"downgrade: {name!r} must be 64 lowercase hex digits")
    doc = {"kind": DOWNGRADE_KIND, "to_sha256": to_sha256, "from_sha256": from_sha256, "key_id": key.key_id,
           "signature_hex": key.sign(downgrade_message(to_sha256, from_sha256)).hex()}
    return (json.dumps(doc, sort_keys=True) + "\n").encode("utf-8")


def parse_downgrade(data: bytes | str, where: str = "downgrade") -> tuple[str, str, str, bytes]:
    """``(key_id, to_sha256, from_sha256, signature)`` of a downgrade authorisation.

    Raises
    ------
    KeyFileError
        Malformed document (the signature itself is checked by the update policy).
    """
    doc = _load_json(data, where)
    if doc.get("kind") != DOWNGRADE_KIND:
        raise KeyFileError(f"{where}: 'kind' must be {DOWNGRADE_KIND!r}, got {doc.get('kind')!r}")
    kid = _hex_field(doc, "key_id", _HEX16, where)
    to = _hex_field(doc, "to_sha256", _HEX64, where)
    frm = _hex_field(doc, "from_sha256", _HEX64, where)
    sig = bytes.fromhex(_hex_field(doc, "signature_hex", _HEX128, where))
    return kid, to, frm, sig
