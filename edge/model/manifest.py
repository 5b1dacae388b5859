"""A bundle's manifest: parsing it by the loader's rules, and checking a file against the hash it lists.

The manifest carries the SHA-256 and size of both array files, so the hash of the manifest's
bytes (the bundle's identity) covers the whole bundle.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from typing import Any

from edge.model.container import HASHED_FILES, MANIFEST_FILE, Limits
from edge.model.errors import HashMismatchError, ManifestError, SchemaVersionError, SizeLimitError
from edge.model.schema import SCHEMAS

__all__ = [
    "parse_manifest", "verify_file",
]

_HEX64 = re.compile(r"^[0-9a-f]{64}$")


def _reject_constant(token: str) -> None:
    raise ValueError(f"non-finite number {token} is not allowed")


def parse_manifest(data: bytes, limits: Limits) -> dict[str, Any]:
    """The manifest's bytes parsed and checked (keys, types, schema version, file hashes); :class:`ManifestError`."""
    if len(data) > limits.max_manifest_bytes:
        raise SizeLimitError(
            f"{MANIFEST_FILE} is {len(data)} bytes, above the limit of {limits.max_manifest_bytes}", MANIFEST_FILE
        )
    try:
        m = json.loads(data.decode("utf-8"), parse_constant=_reject_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise ManifestError(f"{MANIFEST_FILE} is malformed JSON ({e})", MANIFEST_FILE) from None
    if not isinstance(m, dict):
        raise ManifestError(f"{MANIFEST_FILE}: top level must be an object", MANIFEST_FILE)
    sv = m.get("schema_version")
    if not isinstance(sv, int) or isinstance(sv, bool):
        raise ManifestError(f"{MANIFEST_FILE}: 'schema_version' must be an integer, got {sv!r}", "schema_version")
    if sv not in SCHEMAS:
        raise SchemaVersionError(
            f"{MANIFEST_FILE}: unknown schema_version {sv} (this software knows {sorted(SCHEMAS)})", "schema_version"
        )
    for key, typ in (
        ("model_version", str),
        ("description", str),
        ("created_utc", str),
        ("training_set_sha256", str),
        ("metrics", dict),
        ("files", dict),
    ):
        if not isinstance(m.get(key), typ):
            raise ManifestError(
                f"{MANIFEST_FILE}: key {key!r} must be a {typ.__name__}, got {type(m.get(key)).__name__}", key
            )
    if not _HEX64.match(m["training_set_sha256"]):
        raise ManifestError(f"{MANIFEST_FILE}: 'training_set_sha256' must be 64 lowercase hex digits", "training_set_sha256")
    files = m["files"]
    if set(files) != set(HASHED_FILES):
        raise ManifestError(f"{MANIFEST_FILE}: 'files' must list exactly {list(HASHED_FILES)}, got {sorted(files)}", "files")
    for fname, entry in files.items():
        if (
            not isinstance(entry, dict)
            or not isinstance(entry.get("sha256"), str)
            or not _HEX64.match(entry["sha256"])
            or not isinstance(entry.get("size"), int)
            or isinstance(entry.get("size"), bool)
            or entry["size"] < 0
        ):
            raise ManifestError(f"{MANIFEST_FILE}: files[{fname!r}] must be {{'sha256': hex64, 'size': int>=0}}", fname)
    return m


def verify_file(data: bytes, label: str, entry: Mapping[str, Any]) -> None:
    """Check a file's bytes against its manifest entry (size and SHA-256); :class:`HashMismatchError`."""
    if len(data) != entry["size"]:
        raise HashMismatchError(
            f"size mismatch for {label}: manifest says {entry['size']} bytes, file has {len(data)}", label
        )
    digest = hashlib.sha256(data).hexdigest()
    if digest != entry["sha256"]:
        raise HashMismatchError(
            f"sha256 mismatch for {label}: manifest says {entry['sha256']}, file hashes to {digest}", label
        )
