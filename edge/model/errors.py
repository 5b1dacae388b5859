"""What a refused bundle raises: :class:`BundleError` and one subclass per kind of problem.

Every subclass carries ``subject``, the file or array at fault, so a message (and a test) can name it.
"""

from __future__ import annotations


__all__ = [
    "BundleError", "MissingFileError", "UnsafePathError", "CorruptFileError", "HashMismatchError", "ManifestError",
    "SchemaVersionError", "UnknownArrayError", "MissingArrayError", "DtypeError", "ShapeError", "NonFiniteError",
    "ObjectArrayError", "SizeLimitError", "ValueRangeError", "GoldenMismatchError", "TransportError",
]

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
