"""Model bundles: a directory of plain numeric arrays, a manifest and golden vectors.

On disk a bundle is a directory holding three files and optionally a fourth::

    manifest.json   schema_version, model_version, description, created_utc,
                    training_set_sha256, metrics, files: {arrays.npz|golden.npz: {sha256, size}}
    arrays.npz      every weight and preprocessing constant (see edge.model.schema)
    golden.npz      golden input/output vectors the device re-runs before trusting the model
    signature.json  optional: a detached Ed25519 signature over the manifest's bytes
                    ({key_id, signature_hex}; edge.security.keys). Not part of the identity:
                    the same bundle signed by another key is the same model.

The bundle's identity (:attr:`Bundle.sha256`) is the SHA-256 of ``manifest.json``; as the
manifest carries the hashes of the two array files, it covers the whole bundle.

Loading never unpickles (``np.load(..., allow_pickle=False)``), reads every file with a size
bound, parses each npy header before allocating, and refuses anything unexpected with a
:class:`BundleError` subclass whose message names the file or array at fault.

For serial upload a bundle travels as one "transport blob" (:func:`bundle_to_bytes`)::

    b"TTBUNDLE"                  8-byte magic
    u16 format_version (=1)      little-endian
    u16 n_entries (=3, or 4 with signature.json)
    n_entries x { u16 name_len, name (ASCII, one of the bundle's file names),
                  u64 data_len, data }
    sha256 of all preceding bytes (32 bytes)
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import re
import secrets
import stat
import struct
import zipfile
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from edge.storage import durable
from edge.model.schema import CURRENT_SCHEMA_VERSION, NAME_RE, SCHEMAS, ArraySpec, Schema

MANIFEST_FILE = "manifest.json"
ARRAYS_FILE = "arrays.npz"
GOLDEN_FILE = "golden.npz"
BUNDLE_FILES = (MANIFEST_FILE, ARRAYS_FILE, GOLDEN_FILE)
#: The optional detached signature (same name as edge.security.keys.SIGNATURE_FILE).
SIGNATURE_FILE = "signature.json"
#: Longest signature.json accepted (bytes); the real one is about 180.
MAX_SIGNATURE_BYTES = 4096
HASHED_FILES = (ARRAYS_FILE, GOLDEN_FILE)

BLOB_MAGIC = b"TTBUNDLE"
BLOB_FORMAT_VERSION = 1
DEFAULT_GOLDEN_RTOL = 1e-9
_HEX64 = re.compile(r"^[0-9a-f]{64}$")


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


# --------------------------------------------------------------------------------------------
# Errors


class BundleError(ValueError):
    """A bundle (or transport blob) was refused. ``subject`` names the file or array at fault."""

    def __init__(self, message: str, subject: str | None = None) -> None:
        super().__init__(message)
        self.subject = subject


class MissingFileError(BundleError):
    """One of the bundle's three files is absent."""


class UnsafePathError(BundleError):
    """A symlink, non-regular file, or path-traversal name was found."""


class CorruptFileError(BundleError):
    """A file could not be parsed (truncated or unreadable npz, bad npy header)."""


class HashMismatchError(BundleError):
    """A file's sha256 or size differs from the manifest (or the blob's trailer)."""


class ManifestError(BundleError):
    """manifest.json is malformed JSON or lacks/mistypes a required key."""


class SchemaVersionError(BundleError):
    """The manifest names a schema_version this code does not know."""


class UnknownArrayError(BundleError):
    """An array not declared in the schema."""


class MissingArrayError(BundleError):
    """A required array is absent (or an all-or-none group is incomplete)."""


class DtypeError(BundleError):
    """An array has the wrong dtype."""


class ShapeError(BundleError):
    """An array has the wrong number of dimensions or sizes."""


class NonFiniteError(BundleError):
    """A float array holds NaN or inf."""


class ObjectArrayError(BundleError):
    """An array has dtype object (would need pickle)."""


class SizeLimitError(BundleError):
    """A file, array or total exceeds its size bound."""


class ValueRangeError(BundleError):
    """An array's values are outside the declared bounds or allowed codes."""


class GoldenMismatchError(BundleError):
    """The golden vectors did not reproduce within tolerance."""


class TransportError(BundleError):
    """A transport blob is malformed."""


# --------------------------------------------------------------------------------------------
# Bundle object

GoldenCheck = Callable[["Bundle", Mapping[str, np.ndarray]], float]
"""``check(bundle, golden) -> max relative error`` over the golden vectors."""


def max_relative_error(got: np.ndarray, expected: np.ndarray, floor_fraction: float = 1e-3) -> float:
    """Largest ``|got - expected| / max(|expected|, floor)`` over all elements.

    The floor is ``floor_fraction * max|expected|`` so an expected value that happens to sit
    near zero does not turn last-bit rounding differences (another BLAS, another CPU) into a
    huge relative error. Shape mismatch or non-finite output gives ``inf``.
    """
    got = np.asarray(got, dtype=np.float64)
    expected = np.asarray(expected, dtype=np.float64)
    if got.shape != expected.shape or not np.all(np.isfinite(got)):
        return math.inf
    if expected.size == 0:
        return 0.0
    scale = float(np.max(np.abs(expected)))
    floor = max(floor_fraction * scale, np.finfo(np.float64).tiny)
    return float(np.max(np.abs(got - expected) / np.maximum(np.abs(expected), floor)))


class Bundle:
    """A verified, read-only model bundle.

    Attributes
    ----------
    path : Path or None
        Directory it was loaded from.
    arrays : Mapping[str, ndarray]
        Read-only arrays from ``arrays.npz``.
    golden : Mapping[str, ndarray]
        Read-only golden vectors from ``golden.npz``.
    sha256 : str
        SHA-256 (hex) of ``manifest.json`` -- the bundle's identity.
    dims : Mapping[str, int]
        Resolved symbolic dimensions (``n_features``, ``n_components``, ...).
    """

    def __init__(
        self,
        path: Path | None,
        arrays: Mapping[str, np.ndarray],
        golden: Mapping[str, np.ndarray],
        manifest: Mapping[str, Any],
        sha256: str,
        dims: Mapping[str, int],
    ) -> None:
        self.path = path
        self.arrays: Mapping[str, np.ndarray] = MappingProxyType(dict(arrays))
        self.golden: Mapping[str, np.ndarray] = MappingProxyType(dict(golden))
        self._manifest_json = json.dumps(manifest)
        self.sha256 = sha256
        self.dims: Mapping[str, int] = MappingProxyType(dict(dims))

    @property
    def manifest(self) -> dict[str, Any]:
        """A fresh copy of the parsed manifest."""
        return json.loads(self._manifest_json)

    @property
    def schema_version(self) -> int:
        return int(self.manifest["schema_version"])

    @property
    def model_version(self) -> str:
        return str(self.manifest["model_version"])

    def __repr__(self) -> str:
        return f"Bundle(model_version={self.model_version!r}, sha256={self.sha256[:12]}..., path={self.path})"


# --------------------------------------------------------------------------------------------
# Reading


def _read_regular_file(path: Path, label: str, max_bytes: int) -> bytes:
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


def _parse_npz(data: bytes, label: str, limits: Limits) -> dict[str, np.ndarray]:
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


_DTYPES = {"f": np.dtype("<f8"), "i": np.dtype("<i8")}


def _fmt_shape(shape: tuple) -> str:
    return "(" + ", ".join(str(d) for d in shape) + ("," if len(shape) == 1 else "") + ")"


def _check_one(
    name: str, arr: np.ndarray, spec: ArraySpec, dims: dict[str, int], dim_src: dict[str, str], where: str
) -> None:
    if arr.dtype.hasobject:
        raise ObjectArrayError(f"{where}: array {name!r} has dtype object (refused)", name)
    if spec.kind == "U":
        if arr.dtype.kind != "U" or arr.dtype.byteorder == ">":
            raise DtypeError(f"{where}: array {name!r} expected unicode '<U{spec.max_str_len}', got {arr.dtype}", name)
        if arr.dtype.itemsize // 4 > spec.max_str_len:
            raise DtypeError(
                f"{where}: array {name!r} expected strings of at most {spec.max_str_len} characters, "
                f"got {arr.dtype}",
                name,
            )
    elif arr.dtype != _DTYPES[spec.kind]:
        raise DtypeError(f"{where}: array {name!r} expected dtype {_DTYPES[spec.kind]}, got {arr.dtype}", name)

    def expected_txt() -> str:
        return _fmt_shape(tuple(f"{d}={dims[d]}" if isinstance(d, str) and d in dims else d for d in spec.shape))

    if arr.ndim != spec.ndim:
        raise ShapeError(
            f"{where}: array {name!r} expected {spec.ndim}-D shape {expected_txt()}, got {_fmt_shape(arr.shape)}",
            name,
        )
    for axis, (d, got) in enumerate(zip(spec.shape, arr.shape)):
        if isinstance(d, str) and d not in dims:
            dims[d], dim_src[d] = int(got), f"{where}:{name}"
        elif got != (d if isinstance(d, int) else dims[d]):
            src = f" ({d} set by {dim_src.get(d, '?')})" if isinstance(d, str) else ""
            raise ShapeError(
                f"{where}: array {name!r} expected shape {expected_txt()}{src}, got {_fmt_shape(arr.shape)} "
                f"(axis {axis})",
                name,
            )
    if arr.size > spec.max_elements:
        raise SizeLimitError(
            f"{where}: array {name!r} has {arr.size} elements, above its limit of {spec.max_elements}", name
        )
    if spec.kind == "f" and not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise NonFiniteError(f"{where}: array {name!r} contains {bad} NaN/inf value(s)", name)
    if spec.kind in "fi" and arr.size:
        if spec.allowed is not None and not np.all(np.isin(arr, spec.allowed)):
            raise ValueRangeError(
                f"{where}: array {name!r} has value(s) {np.setdiff1d(arr, spec.allowed)[:5].tolist()} "
                f"outside the allowed codes {list(spec.allowed)}",
                name,
            )
        if spec.min_value is not None and np.min(arr) < spec.min_value:
            raise ValueRangeError(f"{where}: array {name!r} has value {np.min(arr).item()!r} below {spec.min_value}", name)
        if spec.max_value is not None and np.max(arr) > spec.max_value:
            raise ValueRangeError(f"{where}: array {name!r} has value {np.max(arr).item()!r} above {spec.max_value}", name)


def validate_arrays(
    arrays: Mapping[str, np.ndarray],
    specs: Mapping[str, ArraySpec],
    dims: dict[str, int] | None = None,
    families: tuple = (),
    where: str = ARRAYS_FILE,
    dim_sources: dict[str, str] | None = None,
) -> dict[str, int]:
    """Check arrays against declared specs; return the resolved symbolic dimensions.

    Parameters
    ----------
    arrays : mapping
        Name -> array.
    specs : mapping
        Name -> :class:`ArraySpec` (non-family entries).
    dims : dict, optional
        Already-resolved dimensions (shared with another file of the same bundle); updated.
    dim_sources : dict, optional
        Which ``file:array`` fixed each dimension (for messages); updated alongside ``dims``.
    families : tuple of LayerFamily
        Per-layer families, expanded using their count array.
    where : str
        File label used in error messages.

    Raises
    ------
    BundleError
        The specific subclass for the first problem found.
    """
    dims = {} if dims is None else dims
    dim_src: dict[str, str] = {} if dim_sources is None else dim_sources
    specs = dict(specs)
    # Count arrays of families are ordinary specs; check them first so expansion is safe.
    for fam in families:
        if fam.count in arrays and fam.count in specs:
            _check_one(fam.count, np.asarray(arrays[fam.count]), specs[fam.count], dims, dim_src, where)
    for fam in families:
        if fam.count not in arrays:
            raise MissingArrayError(f"{where}: missing required array {fam.count!r}", fam.count)
        n = int(arrays[fam.count])
        if not 1 <= n <= fam.max_count:
            raise ValueRangeError(f"{where}: array {fam.count!r} = {n} outside 1..{fam.max_count}", fam.count)
        pattern = fam.template_regex()
        expanded = fam.expand(n)
        for name in arrays:
            if pattern.match(name) and name not in expanded:
                raise UnknownArrayError(
                    f"{where}: array {name!r} is beyond the {n} layer(s) given by {fam.count!r}", name
                )
        specs.update(expanded)
    for name in arrays:
        if name not in specs:
            raise UnknownArrayError(f"{where}: unknown array {name!r} (not declared in the schema)", name)
    for name, spec in specs.items():
        if spec.required and name not in arrays:
            raise MissingArrayError(f"{where}: missing required array {name!r}", name)
    groups: dict[str, list[str]] = {}
    for name, spec in specs.items():
        if spec.group:
            groups.setdefault(spec.group, []).append(name)
    for group, members in groups.items():
        present = [m for m in members if m in arrays]
        if present and len(present) != len(members):
            missing = [m for m in members if m not in arrays]
            raise MissingArrayError(
                f"{where}: group {group!r} is all-or-none; have {present} but missing {missing}", missing[0]
            )
    for name, spec in specs.items():
        if name in arrays:
            _check_one(name, np.asarray(arrays[name]), spec, dims, dim_src, where)
    return dims


def _reject_constant(token: str) -> None:
    raise ValueError(f"non-finite number {token} is not allowed")


def _parse_manifest(data: bytes, limits: Limits) -> dict[str, Any]:
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


def _verify_file(data: bytes, label: str, entry: Mapping[str, Any]) -> None:
    if len(data) != entry["size"]:
        raise HashMismatchError(
            f"size mismatch for {label}: manifest says {entry['size']} bytes, file has {len(data)}", label
        )
    digest = hashlib.sha256(data).hexdigest()
    if digest != entry["sha256"]:
        raise HashMismatchError(
            f"sha256 mismatch for {label}: manifest says {entry['sha256']}, file hashes to {digest}", label
        )


def load_bundle(
    path: str | os.PathLike,
    golden_check: GoldenCheck | None,
    *,
    golden_rtol: float = DEFAULT_GOLDEN_RTOL,
    limits: Limits = DEFAULT_LIMITS,
) -> Bundle:
    """Load and verify a bundle directory.

    Parameters
    ----------
    path : path-like
        Bundle directory.
    golden_check : callable or None
        ``check(bundle, golden) -> max relative error``; the bundle is refused if the result is
        above ``golden_rtol`` (or not finite, or the check raises). The container knows
        nothing of what the arrays compute, so the caller supplies the check (the device:
        :func:`edge.estimation.estimate.pipeline_golden_check`). ``None`` skips the golden check (inspection only; never for a
        model that will be used).
    golden_rtol : float
        Tolerance on the golden check's result.
    limits : Limits
        Size bounds.

    Returns
    -------
    Bundle

    Raises
    ------
    BundleError
        A subclass naming the problem (missing file, symlink, size, sha256, manifest, schema
        version, unknown/missing array, dtype, shape, NaN/inf, object array, golden mismatch).
    """
    root = Path(path)
    if not root.is_dir():
        raise MissingFileError(f"bundle directory {root} does not exist or is not a directory", str(root))
    raw_manifest = _read_regular_file(root / MANIFEST_FILE, MANIFEST_FILE, limits.max_manifest_bytes)
    manifest = _parse_manifest(raw_manifest, limits)
    schema: Schema = SCHEMAS[manifest["schema_version"]]
    parsed: dict[str, dict[str, np.ndarray]] = {}
    for label in HASHED_FILES:
        data = _read_regular_file(root / label, label, limits.max_npz_bytes)
        _verify_file(data, label, manifest["files"][label])
        parsed[label] = _parse_npz(data, label, limits)
    total = sum(a.nbytes for d in parsed.values() for a in d.values())
    if total > limits.max_total_array_bytes:
        raise SizeLimitError(f"bundle arrays total {total} bytes, above the limit of {limits.max_total_array_bytes}")
    src: dict[str, str] = {}
    dims = validate_arrays(
        parsed[ARRAYS_FILE], schema.arrays, families=schema.families, where=ARRAYS_FILE, dim_sources=src
    )
    dims = validate_arrays(parsed[GOLDEN_FILE], schema.golden, dims=dims, where=GOLDEN_FILE, dim_sources=src)
    bundle = Bundle(
        root,
        parsed[ARRAYS_FILE],
        parsed[GOLDEN_FILE],
        manifest,
        hashlib.sha256(raw_manifest).hexdigest(),
        dims,
    )
    if golden_check is not None:
        _run_golden_check(bundle, golden_check, golden_rtol)
    return bundle


def _run_golden_check(bundle: Bundle, check: GoldenCheck, rtol: float) -> None:
    try:
        err = float(check(bundle, bundle.golden))
    except BundleError:
        raise
    except Exception as e:  # a check that cannot run means the bundle cannot be trusted
        raise GoldenMismatchError(f"golden check {getattr(check, '__name__', check)!r} failed: {e!r}") from e
    if not err <= rtol:  # also catches NaN
        raise GoldenMismatchError(
            f"golden vectors do not reproduce: max relative error {err:.3g} > tolerance {rtol:.3g} "
            f"(check {getattr(check, '__name__', check)!r})"
        )


# --------------------------------------------------------------------------------------------
# Writing


def _coerce(name: str, value: Any, spec: ArraySpec | None) -> np.ndarray:
    """Bring caller-supplied values to the schema dtype without silently losing information."""
    arr = np.asarray(value)
    if spec is None or arr.dtype.hasobject:
        return arr  # validation reports it
    if spec.kind == "f" and arr.dtype.kind in "iuf" and arr.dtype != np.float64:
        if arr.dtype.kind == "f" and arr.dtype.itemsize < 8:
            raise DtypeError(f"array {name!r}: refusing to widen {arr.dtype} (train in float64)", name)
        return arr.astype("<f8")
    if spec.kind == "i" and arr.dtype.kind in "iu" and arr.dtype != np.int64:
        if arr.size and (arr.max() > np.iinfo(np.int64).max):
            raise ValueRangeError(f"array {name!r}: value does not fit int64", name)
        return arr.astype("<i8")
    if spec.kind == "f" and arr.dtype.byteorder == ">":
        return arr.astype("<f8")
    return arr


def _spec_lookup(schema: Schema, name: str, golden: bool) -> ArraySpec | None:
    table = schema.golden if golden else schema.arrays
    if name in table:
        return table[name]
    if not golden:
        for fam in schema.families:
            for template, spec in fam.members.items():
                rx = re.escape(template).replace(r"\{i\}", r"\d+").replace(r"\{j\}", r"\d+")
                if re.fullmatch(rx, name):
                    return spec
    return None


def _encode_npz(arrays: Mapping[str, np.ndarray]) -> bytes:
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


_RESERVED_MANIFEST_KEYS = ("schema_version", "files")


def encode_bundle_files(
    arrays: Mapping[str, Any],
    golden: Mapping[str, Any],
    manifest_extra: Mapping[str, Any],
    *,
    schema_version: int = CURRENT_SCHEMA_VERSION,
    validate: bool = True,
) -> dict[str, bytes]:
    """The three files of a bundle as bytes (no disk I/O).

    ``manifest_extra`` must provide ``training_set_sha256``, ``metrics``, ``description`` and
    ``model_version``; ``created_utc`` defaults to now. Extra JSON-serialisable keys are kept.
    """
    if schema_version not in SCHEMAS:
        raise SchemaVersionError(f"schema_version: unknown version {schema_version}", "schema_version")
    schema = SCHEMAS[schema_version]
    a = {k: _coerce(k, v, _spec_lookup(schema, k, False)) for k, v in arrays.items()}
    g = {k: _coerce(k, v, _spec_lookup(schema, k, True)) for k, v in golden.items()}
    for k in list(a) + list(g):
        if not NAME_RE.match(k):
            raise UnknownArrayError(f"array name {k!r} is not an identifier of at most 64 characters", k)
    if validate:
        src: dict[str, str] = {}
        dims = validate_arrays(a, schema.arrays, families=schema.families, where=ARRAYS_FILE, dim_sources=src)
        validate_arrays(g, schema.golden, dims=dims, where=GOLDEN_FILE, dim_sources=src)
    files = {ARRAYS_FILE: _encode_npz(a), GOLDEN_FILE: _encode_npz(g)}
    bad = [k for k in _RESERVED_MANIFEST_KEYS if k in manifest_extra]
    if bad:
        raise ValueError(f"manifest_extra: keys {bad} are set by write_bundle")
    manifest: dict[str, Any] = {
        "schema_version": schema_version,
        "created_utc": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "description": "",
    }
    manifest.update(manifest_extra)
    manifest["files"] = {
        label: {"sha256": hashlib.sha256(files[label]).hexdigest(), "size": len(files[label])} for label in HASHED_FILES
    }
    try:
        text = json.dumps(manifest, indent=2, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise ValueError(f"manifest_extra: not JSON-serialisable without NaN/inf ({e})") from None
    files[MANIFEST_FILE] = (text + "\n").encode("utf-8")
    if validate:
        _parse_manifest(files[MANIFEST_FILE], DEFAULT_LIMITS)  # same rules the loader applies
    return files


def _temp_sibling(path: Path, tag: str) -> Path:
    return path.parent / f".{path.name}.{tag}-{os.getpid()}-{secrets.token_hex(4)}"


def _write_dir(dirpath: Path, files: Mapping[str, bytes]) -> None:
    durable.make_dir(dirpath)
    for label in BUNDLE_FILES + ((SIGNATURE_FILE,) if SIGNATURE_FILE in files else ()):
        durable.write_new_file(dirpath / label, files[label])
    durable.fsync_dir(dirpath)


def write_bundle(
    path: str | os.PathLike,
    arrays: Mapping[str, Any],
    golden: Mapping[str, Any],
    manifest_extra: Mapping[str, Any],
    *,
    overwrite: bool = False,
    schema_version: int = CURRENT_SCHEMA_VERSION,
    golden_check: GoldenCheck | None,
    golden_rtol: float = DEFAULT_GOLDEN_RTOL,
) -> Bundle:
    """Write a bundle directory atomically and return it loaded and verified.

    The files go into a temporary sibling directory, which is loaded back (hashes, schema,
    golden check) before being renamed into place, so a bundle that would be refused on the
    device is never written.

    Parameters
    ----------
    path : path-like
        Target directory.
    arrays, golden : mapping of name -> array_like
        Contents of ``arrays.npz`` / ``golden.npz``; ints/floats are coerced to the schema dtype
        (float32 is refused rather than widened).
    manifest_extra : mapping
        ``training_set_sha256`` (hex), ``metrics`` (dict), ``description``, ``model_version``,
        optionally ``created_utc`` and further JSON keys.
    overwrite : bool
        Replace an existing bundle at ``path``.

    Raises
    ------
    FileExistsError
        ``path`` exists and ``overwrite`` is false.
    BundleError
        The content would be refused by :func:`load_bundle`.
    """
    path = Path(path)
    if os.path.lexists(path) and not overwrite:
        raise FileExistsError(f"path: {path} exists (pass overwrite=True to replace it)")
    files = encode_bundle_files(arrays, golden, manifest_extra, schema_version=schema_version)
    tmp = _temp_sibling(path, "tmp")
    try:
        _write_dir(tmp, files)
        bundle = load_bundle(tmp, golden_check, golden_rtol=golden_rtol)
        if os.path.lexists(path):
            old = _temp_sibling(path, "old")
            durable.rename_dir(path, old)
            durable.rename_dir(tmp, path)
            durable.fsync_dir(path.parent)
            durable.remove_tree(old)
        else:
            durable.rename_dir(tmp, path)
            durable.fsync_dir(path.parent)
    finally:
        durable.remove_tree(tmp)
    bundle.path = path
    return bundle


# --------------------------------------------------------------------------------------------
# Transport blob


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
    return _read_regular_file(p, SIGNATURE_FILE, MAX_SIGNATURE_BYTES)


def bundle_to_bytes(path: str | os.PathLike, limits: Limits = DEFAULT_LIMITS, *,
                    signature: bytes | None = None) -> bytes:
    """Pack a bundle directory into one transport blob (see module docstring for the format).

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
        entries.append((label.encode("ascii"), _read_regular_file(root / label, label, bound)))
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
    tmp = _temp_sibling(dest, "unpack")
    try:
        _write_dir(tmp, files)
        durable.rename_dir(tmp, dest)
        durable.fsync_dir(dest.parent)
    finally:
        durable.remove_tree(tmp)
    return dest
