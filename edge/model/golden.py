"""The golden check: a bundle's golden vectors re-run by the caller before the model is trusted.

The container knows nothing of what the arrays compute, so the check is the caller's
(:data:`GoldenCheck`; the device's is :func:`edge.estimation.estimate.pipeline_golden_check`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

__all__ = [
    "DEFAULT_GOLDEN_RTOL", "GoldenCheck", "max_relative_error",
]

DEFAULT_GOLDEN_RTOL = 1e-9

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
