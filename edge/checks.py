"""Argument checks shared by the compute modules.

Every public compute function validates its inputs with these so that a bad
argument fails early with a ``ValueError`` that names it, instead of turning
into NaN somewhere downstream.
"""

from __future__ import annotations

import math

import numpy as np


def finite_positive(name: str, value) -> float:
    """Return ``value`` as float if it is finite and > 0, else raise ValueError naming ``name``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x) or x <= 0.0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return x


def finite_nonnegative(name: str, value) -> float:
    """Return ``value`` as float if it is finite and >= 0, else raise ValueError naming ``name``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x) or x < 0.0:
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return x


def finite_array(name: str, values, ndim: int = 1, min_len: int = 1) -> np.ndarray:
    """Return ``values`` as a float64 array of ``ndim`` dims, finite, with at least ``min_len`` entries."""
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric") from None
    if a.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {a.shape}")
    if a.size < min_len:
        raise ValueError(f"{name} needs at least {min_len} values, got {a.size}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf")
    return a


def strictly_increasing(name: str, a: np.ndarray) -> np.ndarray:
    """Raise ValueError naming ``name`` unless ``a`` is strictly increasing."""
    if a.size > 1 and not np.all(np.diff(a) > 0):
        raise ValueError(f"{name} must be strictly increasing")
    return a


def one_of(name: str, value, choices) -> str:
    """Raise ValueError naming ``name`` unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ValueError(f"{name} must be one of {sorted(choices)}, got {value!r}")
    return value


def positive_number(name: str, value) -> float:
    """Like :func:`finite_positive`, but a non-number is a ``TypeError`` (driver arguments)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number, got {value!r}") from None
    if not (x > 0 and math.isfinite(x)):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return x


def unit_fraction(name: str, value) -> float:
    """Return ``value`` as float if it is in [0, 1]; a non-number is a ``TypeError``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number, got {value!r}") from None
    if not 0.0 <= x <= 1.0:
        raise ValueError(f"{name} must be in [0, 1], got {value!r}")
    return x
