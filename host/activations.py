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

The same ``with`` swaps the backward pass's tanh derivative
(``DERIVATIVES["tanh"]``, ``delta *= 1 - Z**2``) for
:func:`tanh_derivative_inplace`, the same arithmetic to the bit through one
scratch array instead of two fresh temporaries per layer and evaluation.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np

__all__ = ["tanh_inplace", "tanh_derivative_inplace", "sklearn_fast_tanh"]


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


def tanh_derivative_inplace(Z: np.ndarray, delta: np.ndarray) -> None:
    """``delta *= 1 - Z**2`` (scikit-learn's tanh derivative), bit for bit, with one temporary."""
    tmp = np.multiply(Z, Z)            # what Z**2 computes (NumPy's power fast path is a square)
    np.subtract(1.0, tmp, out=tmp)
    delta *= tmp


#: (table in ``sklearn.neural_network._base``, scikit-learn's own entry's name, the replacement).
_SWAPS = (("ACTIVATIONS", "inplace_tanh", tanh_inplace),
          ("DERIVATIVES", "inplace_tanh_derivative", tanh_derivative_inplace))


@contextlib.contextmanager
def sklearn_fast_tanh() -> Iterator[bool]:
    """Inside the ``with``, scikit-learn's MLPs evaluate tanh units with :func:`tanh_inplace`
    and their derivative with :func:`tanh_derivative_inplace`.

    Yields whether the tanh swap took effect: False where scikit-learn's table is
    not where it was (other versions) or its tanh entry is not scikit-learn's own
    (already swapped by an enclosing ``with``).  Each table is swapped only if it
    holds scikit-learn's own entry, and restored on every exit, an exception's too.
    """
    try:
        from sklearn.neural_network import _base  # noqa: PLC0415 - host only, and only to train
    except ImportError:
        yield False
        return
    swapped, tanh_on = [], False
    try:
        for name, stock_name, mine in _SWAPS:
            try:
                table = getattr(_base, name)
                stock = table["tanh"]
            except (AttributeError, KeyError, TypeError):
                continue
            if getattr(stock, "__name__", None) == stock_name:
                table["tanh"] = mine
                swapped.append((table, stock))
                tanh_on = tanh_on or mine is tanh_inplace
        yield tanh_on
    finally:
        for table, stock in reversed(swapped):
            table["tanh"] = stock
