"""Loading a bundle: :func:`load_bundle` reads, hashes, validates and golden-checks a directory
into a read-only :class:`Bundle`.

The bundle's identity (:attr:`Bundle.sha256`) is the SHA-256 of ``manifest.json``; as the
manifest carries the hashes of the two array files, it covers the whole bundle.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from edge.model.arrays import validate_arrays
from edge.model.container import (ARRAYS_FILE, DEFAULT_LIMITS, GOLDEN_FILE, HASHED_FILES, MANIFEST_FILE, Limits,
                                  parse_npz, read_regular_file)
from edge.model.errors import BundleError, GoldenMismatchError, MissingFileError, SizeLimitError
from edge.model.golden import DEFAULT_GOLDEN_RTOL, GoldenCheck
from edge.model.manifest import parse_manifest, verify_file
from edge.model.schema import SCHEMAS, Schema

__all__ = [
    "Bundle", "load_bundle",
]

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
    raw_manifest = read_regular_file(root / MANIFEST_FILE, MANIFEST_FILE, limits.max_manifest_bytes)
    manifest = parse_manifest(raw_manifest, limits)
    schema: Schema = SCHEMAS[manifest["schema_version"]]
    parsed: dict[str, dict[str, np.ndarray]] = {}
    for label in HASHED_FILES:
        data = read_regular_file(root / label, label, limits.max_npz_bytes)
        verify_file(data, label, manifest["files"][label])
        # The bytes are the ones the manifest's SHA-256 names: a kept parse of that hash is theirs (_PARSED).
        key = (label, manifest["files"][label]["sha256"], len(data), limits)
        hit = _PARSED.get(key)
        if hit is None:
            hit = _keep(_PARSED, key, parse_npz(data, label, limits))
        parsed[label] = hit
    total = sum(a.nbytes for d in parsed.values() for a in d.values())
    if total > limits.max_total_array_bytes:
        raise SizeLimitError(f"bundle arrays total {total} bytes, above the limit of {limits.max_total_array_bytes}")
    # The manifest's bytes pin both files' hashes (just verified) and the schema version: the checks' outcome.
    key = (raw_manifest, limits)
    dims = _DIMS.get(key)
    if dims is None:
        src: dict[str, str] = {}
        dims = validate_arrays(
            parsed[ARRAYS_FILE], schema.arrays, families=schema.families, where=ARRAYS_FILE, dim_sources=src
        )
        dims = validate_arrays(parsed[GOLDEN_FILE], schema.golden, dims=dims, where=GOLDEN_FILE, dim_sources=src)
        dims = _keep(_DIMS, key, MappingProxyType(dict(dims)))
    sha = hashlib.sha256(raw_manifest).hexdigest()
    bundle = Bundle(root, parsed[ARRAYS_FILE], parsed[GOLDEN_FILE], manifest, sha, dims)
    if golden_check is not None:
        _run_golden_check(bundle, golden_check, golden_rtol)
    return bundle


#: Parsed arrays of a hashed file by (label, its verified SHA-256, size, limits), and a bundle's resolved dims by
#: (manifest bytes, limits).  The daemon loads the same bundle at every start (and every store check and
#: rollback): the npz parse and the schema checks were most of a load.  Both are pure functions of bytes the
#: SHA-256s pin (each load still reads and hashes every file against its manifest first), so a hit is what
#: parsing and checking again would give; the arrays are read-only, so bundles may share them.  Only what
#: passed is kept (a refusal is found again, in the same order); bounded because bundles come from uploads.
#: The golden check runs at every load.  Four entries: the active bundle's two files and one other bundle's
#: (an install's, a rollback's) -- on the device the active bundle's arrays are held anyway, the memo adds at
#: most one more bundle's.
_PARSED: dict[tuple, dict[str, np.ndarray]] = {}
_DIMS: dict[tuple, Mapping[str, int]] = {}
_KEEP_MAX = 4
#: Stores load bundles from several threads (a daemon's boot, an upload's install).
_KEEP_LOCK = threading.Lock()


def _keep(memo: dict, key: tuple, value: Any) -> Any:
    """``memo[key] = value``, dropping the oldest entries beyond :data:`_KEEP_MAX`; returns ``value``."""
    with _KEEP_LOCK:
        memo[key] = value
        while len(memo) > _KEEP_MAX:
            del memo[next(iter(memo))]
    return value


def _run_golden_check(bundle: Bundle, check: GoldenCheck, rtol: float) -> None:
    """Refuse ``bundle`` (:class:`GoldenMismatchError`) unless ``check`` runs and stays within ``rtol``."""
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
