"""A float64 tanh built on ``exp``, swapped into scikit-learn while the paper's network trains.

The network (:mod:`host.train`) has 120 tanh units; scikit-learn's lbfgs fit
evaluates them on every sample ~800 times, about 5e8 tanh evaluations for the
shipped recipe.  NumPy's float64 ``tanh`` has a vector loop only on CPUs with
AVX-512; on AVX2-only x86 it costs about twice ``np.exp`` per element
(``python bench/tanh_bench.py``; ``bench/results/*.json`` name the CPU).
:func:`tanh_inplace` computes ``2 / (1 + exp(-2x)) - 1``: one ``exp`` and four
cheap passes, within 4e-16 of ``np.tanh`` (absolute; its relative error near 0
is larger, which a hidden unit feeding a weighted sum does not see), exactly ±1
far out, NaN for NaN.

Only the fit uses it (:func:`sklearn_fast_tanh` around ``MLPRegressor.fit``):
``predict`` - and so the golden outputs a bundle carries - uses NumPy's
``tanh``, the same as the device (:mod:`edge.estimation.mlp`).  The swap
replaces an entry of scikit-learn's private activation table
(``sklearn.neural_network._base.ACTIVATIONS``), which its fit looks up at
every evaluation; where that table is missing or holds something else, the
fit runs unchanged with NumPy's ``tanh``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np

__all__ = ["tanh_inplace", "sklearn_fast_tanh"]

#: The name of scikit-learn's own in-place tanh in its activation table.
_STOCK_NAME = "inplace_tanh"


def tanh_inplace(x: np.ndarray) -> None:
    """``x[...] = tanh(x)`` for a float64 array, through one ``exp``.

    ``exp(-2x)`` overflows to inf for x < -354, which gives exactly -1; the
    overflow is expected and not reported.
    """
    np.multiply(x, -2.0, out=x)
    with np.errstate(over="ignore"):
        np.exp(x, out=x)
    x += 1.0
    np.divide(2.0, x, out=x)
    x -= 1.0


@contextlib.contextmanager
def sklearn_fast_tanh() -> Iterator[bool]:
    """Inside the ``with``, scikit-learn's MLPs evaluate tanh units with :func:`tanh_inplace`.

    Yields whether the swap took effect: False where scikit-learn's table is not
    where it was (other versions) or its tanh entry is not scikit-learn's own
    (already swapped by an enclosing ``with``). The table is restored on every
    exit, an exception's too.
    """
    try:
        from sklearn.neural_network import _base  # noqa: PLC0415 - host only, and only to train

        table = _base.ACTIVATIONS
        stock = table["tanh"]
    except (ImportError, AttributeError, KeyError, TypeError):
        yield False
        return
    if getattr(stock, "__name__", None) != _STOCK_NAME:
        yield False
        return
    table["tanh"] = tanh_inplace
    try:
        yield True
    finally:
        table["tanh"] = stock
