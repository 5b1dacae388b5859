"""What a bundle's arrays must hold: every array checked against its schema, and values coerced to it.

:func:`validate_arrays` checks names, dtypes, shapes (resolving the schema's symbolic
dimensions across files), sizes, finiteness and value ranges (:mod:`edge.model.schema`);
:func:`coerce` brings a writer's values to the schema's dtype without losing information.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from edge.model.container import ARRAYS_FILE
from edge.model.errors import (DtypeError, MissingArrayError, NonFiniteError, ObjectArrayError, ShapeError,
                               SizeLimitError, UnknownArrayError, ValueRangeError)
from edge.model.schema import ArraySpec, Schema

__all__ = [
    "validate_arrays", "coerce", "spec_lookup",
]

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


def coerce(name: str, value: Any, spec: ArraySpec | None) -> np.ndarray:
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


def spec_lookup(schema: Schema, name: str, golden: bool) -> ArraySpec | None:
    """The spec of array ``name`` in ``schema`` (a layer family's member by its template), or None."""
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
