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

The package splits by concern -- :mod:`edge.model.container` (files, bounds, npz),
:mod:`edge.model.arrays` (schema checks), :mod:`edge.model.manifest`, :mod:`edge.model.golden`,
:mod:`edge.model.loader` (:func:`load_bundle`), :mod:`edge.model.transport` (the blob) and this
module (writing) -- and this module re-exports every public name, so callers import from here.

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
import json
import os
from collections.abc import Mapping
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from edge.model.arrays import coerce, spec_lookup, validate_arrays
from edge.model.container import (ARRAYS_FILE, BUNDLE_FILES, DEFAULT_LIMITS, GOLDEN_FILE, HASHED_FILES, MANIFEST_FILE,
                                  MAX_SIGNATURE_BYTES, SIGNATURE_FILE, Limits, encode_npz, limits_for_ram,
                                  read_regular_file, temp_sibling, write_dir)
from edge.model.errors import (BundleError, CorruptFileError, DtypeError, GoldenMismatchError, HashMismatchError,
                               ManifestError, MissingArrayError, MissingFileError, NonFiniteError, ObjectArrayError,
                               SchemaVersionError, ShapeError, SizeLimitError, TransportError, UnknownArrayError,
                               UnsafePathError, ValueRangeError)
from edge.model.golden import DEFAULT_GOLDEN_RTOL, GoldenCheck, max_relative_error
from edge.model.loader import Bundle, load_bundle
from edge.model.manifest import parse_manifest
from edge.model.schema import CURRENT_SCHEMA_VERSION, NAME_RE, SCHEMAS
from edge.model.transport import (BLOB_FORMAT_VERSION, BLOB_MAGIC, bundle_from_bytes, bundle_to_bytes, pack_entries,
                                  parse_blob, read_signature)
from edge.storage import durable

__all__ = [
    # files and bounds
    "MANIFEST_FILE", "ARRAYS_FILE", "GOLDEN_FILE", "BUNDLE_FILES", "SIGNATURE_FILE", "MAX_SIGNATURE_BYTES",
    "HASHED_FILES", "Limits", "DEFAULT_LIMITS", "limits_for_ram", "read_regular_file",
    # errors
    "BundleError", "MissingFileError", "UnsafePathError", "CorruptFileError", "HashMismatchError", "ManifestError",
    "SchemaVersionError", "UnknownArrayError", "MissingArrayError", "DtypeError", "ShapeError", "NonFiniteError",
    "ObjectArrayError", "SizeLimitError", "ValueRangeError", "GoldenMismatchError", "TransportError",
    # checks, loading, writing, transport
    "validate_arrays", "DEFAULT_GOLDEN_RTOL", "GoldenCheck", "max_relative_error", "Bundle", "load_bundle",
    "encode_bundle_files", "write_bundle", "BLOB_MAGIC", "BLOB_FORMAT_VERSION", "pack_entries", "read_signature",
    "bundle_to_bytes", "parse_blob", "bundle_from_bytes",
]

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
    a = {k: coerce(k, v, spec_lookup(schema, k, False)) for k, v in arrays.items()}
    g = {k: coerce(k, v, spec_lookup(schema, k, True)) for k, v in golden.items()}
    for k in list(a) + list(g):
        if not NAME_RE.match(k):
            raise UnknownArrayError(f"array name {k!r} is not an identifier of at most 64 characters", k)
    if validate:
        src: dict[str, str] = {}
        dims = validate_arrays(a, schema.arrays, families=schema.families, where=ARRAYS_FILE, dim_sources=src)
        validate_arrays(g, schema.golden, dims=dims, where=GOLDEN_FILE, dim_sources=src)
    files = {ARRAYS_FILE: encode_npz(a), GOLDEN_FILE: encode_npz(g)}
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
        parse_manifest(files[MANIFEST_FILE], DEFAULT_LIMITS)  # same rules the loader applies
    return files


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
    tmp = temp_sibling(path, "tmp")
    try:
        write_dir(tmp, files)
        bundle = load_bundle(tmp, golden_check, golden_rtol=golden_rtol)
        if os.path.lexists(path):
            old = temp_sibling(path, "old")
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
