"""The one validation engine: typed fields, checked one value or one table at a time.

The daemon's configuration (TOML and CONFIG_SET), the serial protocol's
request and reply schemas and the simulator's scene files all describe their
values with :class:`Field` and check them here, so a value is judged by the
same rules, and refused with the same words, wherever it enters.

Errors are :class:`SchemaError` with the dotted ``path`` of the offending
value and a ``message`` without subject (``"must be > 0, got -1"``); each
caller wraps it in its own error type with its own context (a file name, a
protocol error code).

Kinds
-----
``int``, ``float`` (finite; ints accepted and converted), ``bool``, ``str``
(no NUL), ``int_or_str``, ``sha256`` (64 hex digits, lower-cased), ``bytes``,
``list``, ``list_str`` (non-empty strings), ``list_num`` (finite numbers or
null), ``dict``, ``config`` (a dict of scalars or flat lists of scalars),
``table`` (a dict, checked by the caller), ``any``. Bounds ``lo``/``hi`` apply
to a number's value and to the length of a str/bytes/list/dict;
``lo_open``/``hi_open`` make them exclusive.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

__all__ = [
    "MISSING",
    "KINDS",
    "SchemaError",
    "Field",
    "check_value",
    "check_table",
    "check_keys",
    "type_name",
]


class _Missing:
    def __repr__(self) -> str:
        return "MISSING"


#: Default of a required field.
MISSING: Any = _Missing()

KINDS = (
    "int",
    "float",
    "bool",
    "str",
    "int_or_str",
    "sha256",
    "bytes",
    "list",
    "list_str",
    "list_num",
    "dict",
    "config",
    "table",
    "any",
)
_SHA256_RE = re.compile(r"^[0-9a-fA-F]{64}$")
#: Longest string item inside a ``list_str`` or ``config`` value.
_ITEM_STR_MAX = 256
#: Longest list inside a ``config`` value.
_CONFIG_LIST_MAX = 1024


class SchemaError(ValueError):
    """A value breaks its field; ``path`` is its dotted name, ``message`` says how."""

    def __init__(self, path: str, message: str) -> None:
        self.path = path
        self.message = message
        super().__init__(f"{path}: {message}" if path else message)


@dataclass(frozen=True)
class Field:
    """Schema of one named value (see the module docstring for kinds and bounds).

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    default : Any
        Value when absent; :data:`MISSING` makes the field required.
    doc : str
        One line for humans (configuration listings, protocol docs).
    lo, hi : float, optional
        Bounds on a number, or on the length of a str/bytes/list/dict.
    lo_open, hi_open : bool
        Make ``lo``/``hi`` exclusive.
    choices : tuple, optional
        The allowed values.
    nullable : bool
        Accept None (JSON null).
    name : str
        The field's name where it is declared in a sequence (protocol commands).
    """

    kind: str
    default: Any = MISSING
    doc: str = ""
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[Any, ...] | None = None
    nullable: bool = False
    name: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:  # a schema bug, caught at import
            raise ValueError(f"unknown field kind {self.kind!r}; known: {', '.join(KINDS)}")

    @property
    def required(self) -> bool:
        """True when the field has no default."""
        return self.default is MISSING

    def check(self, value: Any, path: str = "") -> Any:
        """Validate ``value``; return it normalised. Raises :class:`SchemaError`."""
        return check_value(self, value, path or self.name)


def type_name(v: Any) -> str:
    """A user-facing name of ``v``'s type (``boolean`` rather than ``bool``)."""
    return "boolean" if isinstance(v, bool) else type(v).__name__


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return (_is_int(v) or isinstance(v, float)) and math.isfinite(v)


def _is_scalar(v: Any) -> bool:
    return v is None or isinstance(v, (bool, str)) or _is_number(v)


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def _bounds(f: Field, value: float, what: str, path: str) -> None:
    subject = f"{what} " if what else ""
    if f.lo is not None and ((value <= f.lo) if f.lo_open else (value < f.lo)):
        raise SchemaError(path, f"{subject}must be {'>' if f.lo_open else '>='} {_fmt(f.lo)}, got {value!r}")
    if f.hi is not None and ((value >= f.hi) if f.hi_open else (value > f.hi)):
        raise SchemaError(path, f"{subject}must be {'<' if f.hi_open else '<='} {_fmt(f.hi)}, got {value!r}")


def check_value(f: Field, value: Any, path: str) -> Any:
    """Validate one value against ``f``; return it normalised.

    Raises
    ------
    SchemaError
        ``path`` names the value (or an item inside it).
    """
    if value is None:
        if f.nullable or f.kind == "any":
            return None
        raise SchemaError(path, "must not be null")
    value = _check_kind(f, value, path)
    if f.choices is not None and value not in f.choices:
        raise SchemaError(path, f"must be one of {', '.join(map(str, f.choices))}, got {value!r}")
    return value


def _check_str(f: Field, value: Any, path: str) -> str:
    if not isinstance(value, str):
        raise SchemaError(path, f"must be a string, got {type_name(value)} {value!r}")
    if "\x00" in value:
        raise SchemaError(path, "must not contain NUL")
    _bounds(f, len(value), "length", path)
    return value


def _check_kind(f: Field, value: Any, path: str) -> Any:
    k = f.kind
    if k == "int" or (k == "int_or_str" and not isinstance(value, str)):
        if not _is_int(value):
            what = "an integer or a string" if k == "int_or_str" else "an integer"
            raise SchemaError(path, f"must be {what}, got {type_name(value)} {value!r}")
        _bounds(f, value, "", path)
        return value
    if k == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SchemaError(path, f"must be a number, got {type_name(value)} {value!r}")
        if not math.isfinite(value):
            raise SchemaError(path, f"must be a finite number, got {value!r}")
        _bounds(f, float(value), "", path)
        return float(value)
    if k == "bool":
        if not isinstance(value, bool):
            raise SchemaError(path, f"must be a boolean (true or false), got {type_name(value)} {value!r}")
        return value
    if k in ("str", "int_or_str"):
        return _check_str(f, value, path)
    if k == "sha256":
        if not isinstance(value, str) or not _SHA256_RE.match(value):
            raise SchemaError(path, "must be 64 hex digits")
        return value.lower()
    if k == "bytes":
        if not isinstance(value, (bytes, bytearray, memoryview)):
            raise SchemaError(path, f"must be bytes, got {type_name(value)}")
        value = bytes(value)
        _bounds(f, len(value), "length", path)
        return value
    if k in ("list", "list_str", "list_num"):
        return _check_list(f, value, path)
    if k in ("dict", "config", "table"):
        if not isinstance(value, Mapping):
            what = "a table" if k == "table" else "an object"
            raise SchemaError(path, f"must be {what}, got {type_name(value)}")
        _bounds(f, len(value), "size", path)
        if k == "config":
            return {key: _check_config_item(path, key, item) for key, item in value.items()}
        return dict(value)
    return value  # any


def _check_list(f: Field, value: Any, path: str) -> list:
    if not isinstance(value, (list, tuple)):
        raise SchemaError(path, f"must be a list, got {type_name(value)}")
    _bounds(f, len(value), "length", path)
    if f.kind == "list_num":
        for i, item in enumerate(value):
            if item is not None and not _is_number(item):
                raise SchemaError(f"{path}[{i}]", f"must be a finite number or null, got {item!r}")
        return [None if x is None else float(x) for x in value]
    if f.kind == "list_str":
        for i, item in enumerate(value):
            if not isinstance(item, str) or not 1 <= len(item) <= _ITEM_STR_MAX:
                raise SchemaError(f"{path}[{i}]", "must be a non-empty string")
    return list(value)


def _check_config_item(path: str, key: Any, item: Any) -> Any:
    if not isinstance(key, str) or not 1 <= len(key) <= 64:
        raise SchemaError(path, "keys must be strings of 1..64 characters")
    sub = f"{path}.{key}"
    if isinstance(item, (list, tuple)):
        if len(item) > _CONFIG_LIST_MAX or not all(_is_scalar(x) and x is not None for x in item):
            raise SchemaError(sub, f"must be a list of at most {_CONFIG_LIST_MAX} scalars")
        item = list(item)
    elif not _is_scalar(item):
        raise SchemaError(sub, f"must be a scalar or list of scalars, got {item!r}")
    if isinstance(item, str) and len(item) > _ITEM_STR_MAX:
        raise SchemaError(sub, f"string must be at most {_ITEM_STR_MAX} characters")
    return item


def check_keys(data: Mapping[str, Any], allowed: Iterable[str], path: str = "") -> None:
    """Refuse any key of ``data`` not in ``allowed`` (the message lists the allowed ones)."""
    allowed = tuple(allowed)
    for k in data:
        if k not in allowed:
            raise SchemaError(
                f"{path}.{k}" if path else str(k), f"unknown key (allowed: {', '.join(allowed)})"
            )


def check_table(
    data: Any, fields: Mapping[str, Field], path: str = "", *, fill_defaults: bool = True
) -> dict[str, Any]:
    """Validate a table against named fields: unknown keys refused, required ones demanded.

    Returns the normalised values, with defaults filled in for absent fields
    (``fill_defaults``) except where the default is None.
    """
    if not isinstance(data, Mapping):
        raise SchemaError(path, f"must be a table, got {type_name(data)}")
    check_keys(data, fields, path)
    out: dict[str, Any] = {}
    for name, f in fields.items():
        sub = f"{path}.{name}" if path else name
        if name in data:
            out[name] = check_value(f, data[name], sub)
        elif f.required:
            raise SchemaError(sub, "missing required field")
        elif fill_defaults and f.default is not None:
            out[name] = f.default
    return out
