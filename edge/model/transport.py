"""The transport blob: a bundle as one byte string for serial upload (:func:`bundle_to_bytes`)::

    b"TTBUNDLE"                  8-byte magic
    u16 format_version (=1)      little-endian
    u16 n_entries (=3, or 4 with signature.json)
    n_entries x { u16 name_len, name (ASCII, one of the bundle's file names),
                  u64 data_len, data }
    sha256 of all preceding bytes (32 bytes)

Every field is bounded when parsed (:func:`parse_blob`); unpacking writes a new directory
atomically (:func:`bundle_from_bytes`), which is then loaded like any other.
"""

from __future__ import annotations

import hashlib
import os
import struct
from pathlib import Path

from edge.model.container import (BUNDLE_FILES, DEFAULT_LIMITS, MANIFEST_FILE, MAX_SIGNATURE_BYTES, SIGNATURE_FILE,
                                  Limits, read_regular_file, temp_sibling, write_dir)
from edge.model.errors import HashMismatchError, SizeLimitError, TransportError, UnsafePathError
from edge.model.loader import load_bundle
from edge.storage import durable

__all__ = [
    "BLOB_MAGIC", "BLOB_FORMAT_VERSION", "pack_entries", "read_signature", "bundle_to_bytes", "parse_blob",
    "bundle_from_bytes",
]

BLOB_MAGIC = b"TTBUNDLE"
BLOB_FORMAT_VERSION = 1


def pack_entries(entries: list[tuple[bytes, bytes]]) -> bytes:
    """Low-level blob packer: no checks on names (tests use it to craft hostile blobs)."""
    out = bytearray(BLOB_MAGIC)
    out += struct.pack("<HH", BLOB_FORMAT_VERSION, len(entries))
    for name, data in entries:
        out += struct.pack("<H", len(name)) + name + struct.pack("<Q", len(data)) + data
    out += hashlib.sha256(out).digest()
    return bytes(out)


def read_signature(path: str | os.PathLike) -> bytes | None:
    """The bytes of the bundle directory's ``signature.json``, or None if it has none."""
    p = Path(path) / SIGNATURE_FILE
    if not os.path.lexists(p):
        return None
    return read_regular_file(p, SIGNATURE_FILE, MAX_SIGNATURE_BYTES)


def bundle_to_bytes(path: str | os.PathLike, limits: Limits = DEFAULT_LIMITS, *,
                    signature: bytes | None = None) -> bytes:
    """Pack a bundle directory into one transport blob (the format: module docstring).

    The bundle is verified (hashes and schema; golden check skipped) first so a broken bundle
    is caught on the host, not after the upload.

    Parameters
    ----------
    signature : bytes, optional
        A ``signature.json`` to carry (e.g. made on the host at flash time); by default the
        directory's own ``signature.json`` if it has one.
    """
    root = Path(path)
    load_bundle(root, golden_check=None, limits=limits)
    entries = []
    for label in BUNDLE_FILES:
        bound = limits.max_manifest_bytes if label == MANIFEST_FILE else limits.max_npz_bytes
        entries.append((label.encode("ascii"), read_regular_file(root / label, label, bound)))
    if signature is None:
        signature = read_signature(root)
    if signature is not None:
        if len(signature) > MAX_SIGNATURE_BYTES:
            raise SizeLimitError(f"{SIGNATURE_FILE} is {len(signature)} bytes, above the limit of "
                                 f"{MAX_SIGNATURE_BYTES}", SIGNATURE_FILE)
        entries.append((SIGNATURE_FILE.encode("ascii"), bytes(signature)))
    return pack_entries(entries)


def parse_blob(data: bytes, limits: Limits = DEFAULT_LIMITS) -> dict[str, bytes]:
    """Parse a transport blob into ``{file name: bytes}`` with every field bounded.

    The three bundle files are required; ``signature.json`` may come as a fourth entry.

    Raises
    ------
    TransportError
        Bad magic/version/count, truncation, trailing bytes, checksum mismatch.
    UnsafePathError
        An entry name with a path separator, ``..`` or anything but the three file names.
    SizeLimitError
        The blob or an entry is above its bound.
    """
    data = bytes(data)
    if len(data) > limits.max_blob_bytes:
        raise SizeLimitError(f"transport blob is {len(data)} bytes, above the limit of {limits.max_blob_bytes}")
    head = len(BLOB_MAGIC) + 4
    if len(data) < head + 32:
        raise TransportError(f"transport blob is truncated ({len(data)} bytes)")
    if data[: len(BLOB_MAGIC)] != BLOB_MAGIC:
        raise TransportError("transport blob has a bad magic number (not a ThermoTouch bundle)")
    body, trailer = data[:-32], data[-32:]
    if hashlib.sha256(body).digest() != trailer:
        raise HashMismatchError("transport blob checksum mismatch (corrupted or truncated in transit)", "blob")
    version, count = struct.unpack_from("<HH", data, len(BLOB_MAGIC))
    if version != BLOB_FORMAT_VERSION:
        raise TransportError(f"transport blob format version {version} is not supported (want {BLOB_FORMAT_VERSION})")
    if count not in (len(BUNDLE_FILES), len(BUNDLE_FILES) + 1):
        raise TransportError(f"transport blob holds {count} entries, expected {len(BUNDLE_FILES)} "
                             f"(or {len(BUNDLE_FILES) + 1} with {SIGNATURE_FILE})")
    pos = head
    files: dict[str, bytes] = {}
    for _ in range(count):
        if pos + 2 > len(body):
            raise TransportError("transport blob is truncated in an entry header")
        (nlen,) = struct.unpack_from("<H", body, pos)
        pos += 2
        if nlen == 0 or nlen > 64 or pos + nlen + 8 > len(body):
            raise TransportError(f"transport blob has a bad entry name length {nlen}")
        raw_name = body[pos : pos + nlen]
        pos += nlen
        try:
            name = raw_name.decode("ascii")
        except UnicodeDecodeError:
            raise UnsafePathError(f"transport blob entry name {raw_name!r} is not ASCII") from None
        if "/" in name or "\\" in name or ".." in name or "\x00" in name or name.startswith("."):
            raise UnsafePathError(f"transport blob entry {name!r} looks like path traversal; refused", name)
        if name not in BUNDLE_FILES and name != SIGNATURE_FILE:
            raise UnsafePathError(f"transport blob entry {name!r} is not one of "
                                  f"{list(BUNDLE_FILES) + [SIGNATURE_FILE]}", name)
        if name in files:
            raise TransportError(f"transport blob holds {name!r} twice", name)
        (dlen,) = struct.unpack_from("<Q", body, pos)
        pos += 8
        bound = (limits.max_manifest_bytes if name == MANIFEST_FILE else
                 MAX_SIGNATURE_BYTES if name == SIGNATURE_FILE else limits.max_npz_bytes)
        if dlen > bound:
            raise SizeLimitError(f"transport blob entry {name!r} is {dlen} bytes, above the limit of {bound}", name)
        if pos + dlen > len(body):
            raise TransportError(f"transport blob is truncated inside {name!r}", name)
        files[name] = body[pos : pos + dlen]
        pos += dlen
    if pos != len(body):
        raise TransportError(f"transport blob has {len(body) - pos} unexpected trailing bytes")
    missing = [n for n in BUNDLE_FILES if n not in files]
    if missing:
        raise TransportError(f"transport blob lacks {missing}", missing[0])
    return files


def bundle_from_bytes(data: bytes, dest: str | os.PathLike, limits: Limits = DEFAULT_LIMITS) -> Path:
    """Unpack a transport blob into a new bundle directory ``dest`` (atomically).

    Only the container is checked here; call :func:`load_bundle` on the result before use.

    Raises
    ------
    FileExistsError
        ``dest`` already exists (including as a symlink).
    BundleError
        Malformed blob (see :func:`parse_blob`).
    """
    dest = Path(dest)
    files = parse_blob(data, limits)
    if os.path.lexists(dest):
        raise FileExistsError(f"dest: {dest} already exists")
    if not dest.parent.is_dir():
        raise FileNotFoundError(f"dest: parent directory {dest.parent} does not exist")
    tmp = temp_sibling(dest, "unpack")
    try:
        write_dir(tmp, files)
        durable.rename_dir(tmp, dest)
        durable.fsync_dir(dest.parent)
    finally:
        durable.remove_tree(tmp)
    return dest
