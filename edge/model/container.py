"""A bundle's container: its file names, the size bounds, and reading and writing its files and npz arrays.

The layout on disk is :mod:`edge.model.bundle`'s (its module docstring).

Loading never unpickles: every file is read with a size bound (:func:`read_regular_file`), and
:func:`parse_npz` parses each npy header before allocating. What the arrays must hold is
:mod:`edge.model.arrays`' business, the manifest :mod:`edge.model.manifest`'s.
"""

from __future__ import annotations

import io
import math
import os
import secrets
import stat
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from edge.model.errors import (CorruptFileError, DtypeError, MissingFileError, ObjectArrayError, SizeLimitError,
                               UnsafePathError)
from edge.model.schema import NAME_RE
from edge.storage import durable

__all__ = [
    "MANIFEST_FILE", "ARRAYS_FILE", "GOLDEN_FILE", "BUNDLE_FILES", "SIGNATURE_FILE", "MAX_SIGNATURE_BYTES",
    "HASHED_FILES", "Limits", "DEFAULT_LIMITS", "limits_for_ram", "read_regular_file", "parse_npz", "encode_npz",
    "temp_sibling", "write_dir",
]

MANIFEST_FILE = "manifest.json"
ARRAYS_FILE = "arrays.npz"
GOLDEN_FILE = "golden.npz"
BUNDLE_FILES = (MANIFEST_FILE, ARRAYS_FILE, GOLDEN_FILE)
#: The optional detached signature (same name as edge.security.keys.SIGNATURE_FILE).
SIGNATURE_FILE = "signature.json"
#: Longest signature.json accepted (bytes); the real one is about 180.
MAX_SIGNATURE_BYTES = 4096
HASHED_FILES = (ARRAYS_FILE, GOLDEN_FILE)


@dataclass(frozen=True)
class Limits:
    """Size bounds applied while loading (all in bytes unless named otherwise)."""

    max_manifest_bytes: int = 64 * 1024
    max_npz_bytes: int = 64 * 1024 * 1024
    max_members: int = 256
    max_array_elements: int = 4_000_000
    max_array_bytes: int = 32 * 1024 * 1024
    max_total_array_bytes: int = 64 * 1024 * 1024

    @property
    def max_blob_bytes(self) -> int:
        return self.max_manifest_bytes + 2 * self.max_npz_bytes + 4096


DEFAULT_LIMITS = Limits()

#: Longest npy header read before a member's data (NumPy itself writes at most a few hundred bytes).
_NPY_HEADER_MAX = 16 * 1024


def limits_for_ram(ram_bytes: int) -> Limits:
    """Bundle bounds for a device with ``ram_bytes`` of RAM (never looser than :data:`DEFAULT_LIMITS`).

    Loading holds the npz file, each member's decompressed bytes and the
    array built from them, while the active model stays loaded: about four
    times the arrays' size. Arrays are held to 1/32 of RAM in total and
    1/64 each, so an install peaks well below 1/4 of RAM beside the
    daemon and the OS.

    Parameters
    ----------
    ram_bytes : int
        The device's RAM (``[limits] ram_bytes``).

    Returns
    -------
    Limits
    """
    ram_bytes = int(ram_bytes)
    if ram_bytes <= 0:
        raise ValueError(f"ram_bytes must be > 0, got {ram_bytes!r}")
    d = DEFAULT_LIMITS
    total = min(d.max_total_array_bytes, ram_bytes // 32)
    per_array = min(d.max_array_bytes, ram_bytes // 64)
    return Limits(
        max_manifest_bytes=d.max_manifest_bytes,
        max_npz_bytes=min(d.max_npz_bytes, total + 1024 * 1024),  # arrays + zip and npy overhead
        max_members=d.max_members,
        max_array_elements=min(d.max_array_elements, max(1, per_array // 8)),
        max_array_bytes=per_array,
        max_total_array_bytes=total,
    )


def read_regular_file(path: Path, label: str, max_bytes: int) -> bytes:
    """Read a regular (non-symlink) file of at most ``max_bytes``."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise MissingFileError(f"missing file {label} in bundle {path.parent}", label) from None
    if stat.S_ISLNK(st.st_mode):
        raise UnsafePathError(f"{label} is a symlink; bundles must hold regular files", label)
    if not stat.S_ISREG(st.st_mode):
        raise UnsafePathError(f"{label} is not a regular file", label)
    if st.st_size > max_bytes:
        raise SizeLimitError(f"{label} is {st.st_size} bytes, above the limit of {max_bytes}", label)
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    with os.fdopen(fd, "rb") as f:
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise SizeLimitError(f"{label} grew above the limit of {max_bytes} bytes while reading", label)
    return data


# Parsed npy headers by their exact bytes. A header is parsed with ``ast.literal_eval`` (numpy's
# reader), the slowest part of a load; the same bundle is loaded at every daemon start, store check
# and install, and its headers repeat. The parse is a pure function of the bytes, so a hit is
# exactly what parsing would give; bounded because headers come from files we do not trust.
_HEADER_CACHE: dict[bytes, tuple[tuple[int, ...], np.dtype, bool, int]] = {}
_HEADER_CACHE_MAX = 1024


def _npy_header(raw: bytes, label: str, name: str) -> tuple[tuple[int, ...], np.dtype, bool, int]:
    """Parse an npy header without reading data: (shape, dtype, fortran order, header length)."""
    hit = _HEADER_CACHE.get(raw)
    if hit is not None:
        return hit
    bio = io.BytesIO(raw)
    try:
        version = np.lib.format.read_magic(bio)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(bio)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(bio)
        else:
            raise ValueError(f"unsupported npy format version {version}")
    except (ValueError, TypeError, SyntaxError, EOFError) as e:
        raise CorruptFileError(f"{label}: array {name!r} has an unreadable npy header ({e})", name) from None
    out = (tuple(int(d) for d in shape), dtype, bool(fortran), bio.tell())
    if len(_HEADER_CACHE) >= _HEADER_CACHE_MAX:
        _HEADER_CACHE.clear()
    _HEADER_CACHE[raw] = out
    return out


def _read_npy_header(zf: zipfile.ZipFile, info: zipfile.ZipInfo, label: str,
                     name: str) -> tuple[tuple[int, ...], np.dtype, bool, int]:
    """Shape, dtype, order and header length of one member, decompressing only its header."""
    try:
        with zf.open(info) as f:
            head = f.read(12)  # magic (6), version (2), header length (2 or 4)
            if len(head) < 10 or head[:6] != b"\x93NUMPY":
                raise CorruptFileError(f"{label}: array {name!r} is not an npy file", name)
            hlen = int.from_bytes(head[8:10], "little") + 10 if head[6] == 1 else \
                int.from_bytes(head[8:12], "little") + 12
            if hlen > _NPY_HEADER_MAX:
                raise CorruptFileError(f"{label}: array {name!r} has an npy header of {hlen} bytes", name)
            head += f.read(hlen - len(head))
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, NotImplementedError, zlib.error) as e:
        raise CorruptFileError(f"{label}: array {name!r} is unreadable ({e})", name) from None
    return _npy_header(head, label, name)


def parse_npz(data: bytes, label: str, limits: Limits) -> dict[str, np.ndarray]:
    """Parse npz bytes defensively into read-only arrays.

    Nothing is decompressed before it is known to fit: first the declared
    (central-directory) sizes of all members, then every member's npy header
    (shape and dtype, the only bytes inflated) are checked against
    ``limits``; only then are the members read, each bounded by its
    declared size. A zip bomb or a bundle whose arrays would not fit the
    device's memory is refused having cost a few kilobytes.
    """
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        infos = zf.infolist()
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
        raise CorruptFileError(f"{label} is truncated or not a readable npz ({e})", label) from None
    if len(infos) > limits.max_members:
        raise SizeLimitError(f"{label} holds {len(infos)} members, above the limit of {limits.max_members}", label)
    budget = limits.max_array_bytes + _NPY_HEADER_MAX  # data + npy header
    names: dict[str, zipfile.ZipInfo] = {}
    declared = 0
    # 1. Declared sizes: the central directory only.
    for info in infos:
        member = info.filename
        name = member[:-4] if member.endswith(".npy") else member
        if not member.endswith(".npy") or not NAME_RE.match(name):
            raise CorruptFileError(f"{label}: unexpected member {member!r} (want <identifier>.npy)", label)
        if name in names:
            raise CorruptFileError(f"{label}: array {name!r} appears twice", name)
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
            raise CorruptFileError(f"{label}: array {name!r} uses zip method {info.compress_type} "
                                   "(only stored or deflated)", name)
        if info.file_size > budget:
            raise SizeLimitError(
                f"{label}: array {name!r} is {info.file_size} bytes, above the limit of "
                f"{limits.max_array_bytes}",
                name,
            )
        declared += info.file_size
        if declared > limits.max_total_array_bytes + len(infos) * _NPY_HEADER_MAX:
            raise SizeLimitError(
                f"{label}: members declare more than {limits.max_total_array_bytes} bytes (at {name!r})", name
            )
        names[name] = info
    # 2. npy headers: shapes and dtypes, the data still compressed.
    total = 0
    headers: dict[str, tuple[tuple[int, ...], np.dtype, bool, int]] = {}
    for name, info in names.items():
        shape, dtype, _fortran, hlen = headers[name] = _read_npy_header(zf, info, label, name)
        if dtype.hasobject:
            raise ObjectArrayError(f"{label}: array {name!r} has dtype object (refused: needs pickle)", name)
        if dtype.fields is not None or dtype.subdtype is not None:
            raise DtypeError(f"{label}: array {name!r} has a structured dtype {dtype}", name)
        n_el = math.prod(shape)
        n_bytes = n_el * dtype.itemsize
        if n_el > limits.max_array_elements or n_bytes > limits.max_array_bytes:
            raise SizeLimitError(
                f"{label}: array {name!r} has {n_el} elements / {n_bytes} bytes, above the limit of "
                f"{limits.max_array_elements} elements / {limits.max_array_bytes} bytes",
                name,
            )
        if info.file_size - hlen != n_bytes:
            raise CorruptFileError(
                f"{label}: array {name!r} holds {info.file_size - hlen} data bytes, header says {n_bytes}", name
            )
        total += n_bytes
        if total > limits.max_total_array_bytes:
            raise SizeLimitError(
                f"{label}: arrays total more than {limits.max_total_array_bytes} bytes (at {name!r})", name
            )
    # 3. The data, each member bounded by the size just checked.
    out: dict[str, np.ndarray] = {}
    for name, info in names.items():
        try:
            with zf.open(info) as f:
                raw = f.read(info.file_size + 1)
        except (zipfile.BadZipFile, OSError, ValueError, EOFError, NotImplementedError, zlib.error) as e:
            raise CorruptFileError(f"{label}: array {name!r} is unreadable ({e})", name) from None
        if len(raw) != info.file_size:
            raise CorruptFileError(f"{label}: array {name!r} holds {len(raw)} bytes, its entry says "
                                   f"{info.file_size}", name)
        # The header was parsed and checked above (the data length against it too): the array is
        # its bytes after the header, not a second parse by np.load.
        shape, dtype, fortran, hlen = headers[name]
        try:
            flat = np.frombuffer(raw, dtype=dtype, count=math.prod(shape), offset=hlen)
        except ValueError as e:
            raise CorruptFileError(f"{label}: array {name!r} is unreadable ({e})", name) from None
        arr = np.array(flat.reshape(shape, order="F" if fortran else "C"), order="C", copy=True)
        arr.flags.writeable = False
        out[name] = arr
    return out


def encode_npz(arrays: Mapping[str, np.ndarray]) -> bytes:
    """Deterministic uncompressed npz (fixed timestamps, sorted names) readable by np.load."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for name in sorted(arrays):
            arr = np.array(arrays[name], order="C")
            npy = io.BytesIO()
            np.lib.format.write_array(npy, arr, allow_pickle=False)
            info = zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_STORED
            info.external_attr = 0o644 << 16
            zf.writestr(info, npy.getvalue())
    return buf.getvalue()


def temp_sibling(path: Path, tag: str) -> Path:
    """A fresh hidden name beside ``path`` for staging (pid and a random token: never an existing one)."""
    return path.parent / f".{path.name}.{tag}-{os.getpid()}-{secrets.token_hex(4)}"


def write_dir(dirpath: Path, files: Mapping[str, bytes]) -> None:
    """Create ``dirpath`` and write the bundle's files into it durably (the signature if given)."""
    durable.make_dir(dirpath)
    for label in BUNDLE_FILES + ((SIGNATURE_FILE,) if SIGNATURE_FILE in files else ()):
        durable.write_new_file(dirpath / label, files[label])
    durable.fsync_dir(dirpath)
