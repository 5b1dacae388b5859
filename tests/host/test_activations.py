"""The exp-based tanh the paper's network trains with, and its swap into scikit-learn."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from host.activations import sklearn_fast_tanh, tanh_derivative_inplace, tanh_inplace

# The fits here are a few iterations long on purpose (what is under test is the swap, not the fit).
# scikit-learn: one worker pays for its import (tests/support/schedule.py).
pytestmark = [pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning"),
              pytest.mark.shares_import("sklearn")]


_STOCK: dict = {}


def _sklearn():
    """scikit-learn's ``MLPRegressor`` and the module holding its activation tables.

    Imported when a test needs them, not at collection (1.2 s in every xdist worker, most of
    which never run a test here); the stock tanh derivative is noted on the first import.
    """
    from sklearn.neural_network import MLPRegressor, _base

    _STOCK.setdefault("tanh_derivative", _base.DERIVATIVES["tanh"])
    return MLPRegressor, _base


def _ours(x):
    y = np.array(x, dtype=float)
    tanh_inplace(y)
    return y


def test_within_a_few_ulp_of_numpy_everywhere_and_exact_far_out():
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.normal(0, 3, 20_000), np.linspace(-40, 40, 8001), [-1e-300, 0.0, 1e-300]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # exp's overflow far out is expected, not reported
        y = _ours(x)
        far = _ours([-np.inf, -1e300, -800.0, -355.0, 355.0, 800.0, 1e300, np.inf])
    assert np.max(np.abs(y - np.tanh(x))) <= 4.5e-16
    assert np.all(np.abs(y) <= 1.0)
    assert far.tolist() == [-1.0] * 4 + [1.0] * 4
    assert np.isnan(_ours([np.nan])[0])


def test_works_in_place_on_a_2d_block():
    x = np.linspace(-3, 3, 12).reshape(3, 4)
    ref = np.tanh(x)
    buf = x.copy()
    assert tanh_inplace(buf) is None
    np.testing.assert_allclose(buf, ref, rtol=0, atol=4.5e-16)


def test_the_swap_is_used_by_fit_and_undone_on_exit_and_on_error():
    MLPRegressor, _base = _sklearn()
    stock, stock_d = _base.ACTIVATIONS["tanh"], _base.DERIVATIVES["tanh"]
    calls = [0]

    def counting(x):
        calls[0] += 1
        tanh_inplace(x)

    x = np.linspace(-1, 1, 40).reshape(-1, 1)
    with sklearn_fast_tanh() as on:
        assert on and _base.ACTIVATIONS["tanh"] is tanh_inplace
        assert _base.DERIVATIVES["tanh"] is tanh_derivative_inplace
        _base.ACTIVATIONS["tanh"] = counting        # to see that fit looks the entry up
        MLPRegressor(hidden_layer_sizes=(5,), activation="tanh", solver="lbfgs", max_iter=5,
                     random_state=0).fit(x, x[:, 0] ** 2)
    assert calls[0] > 0
    assert _base.ACTIVATIONS["tanh"] is stock and _base.DERIVATIVES["tanh"] is stock_d
    with pytest.raises(RuntimeError, match="boom"), sklearn_fast_tanh():
        raise RuntimeError("boom")
    assert _base.ACTIVATIONS["tanh"] is stock and _base.DERIVATIVES["tanh"] is stock_d


def test_predict_after_the_fit_uses_numpys_tanh_like_the_device():
    MLPRegressor, _base = _sklearn()
    x = np.linspace(-2, 2, 50).reshape(-1, 1)
    with sklearn_fast_tanh():
        m = MLPRegressor(hidden_layer_sizes=(7,), activation="tanh", solver="lbfgs", max_iter=50,
                         random_state=0).fit(x, np.sin(x[:, 0]))
    h = np.tanh(x @ m.coefs_[0] + m.intercepts_[0])
    assert np.array_equal(m.predict(x), (h @ m.coefs_[1] + m.intercepts_[1])[:, 0])


def test_nested_or_foreign_entries_are_left_alone(monkeypatch):
    _, _base = _sklearn()
    stock = _base.ACTIVATIONS["tanh"]
    with sklearn_fast_tanh() as outer, sklearn_fast_tanh() as inner:
        assert outer and not inner
    assert _base.ACTIVATIONS["tanh"] is stock

    def someone_elses(x):
        np.tanh(x, out=x)

    monkeypatch.setitem(_base.ACTIVATIONS, "tanh", someone_elses)
    with sklearn_fast_tanh() as on:
        assert not on and _base.ACTIVATIONS["tanh"] is someone_elses
    monkeypatch.delattr(_base, "ACTIVATIONS")
    with sklearn_fast_tanh() as on:
        assert not on


def test_the_derivative_is_scikit_learns_to_the_bit():
    # Its swap and restoring: test_the_swap_is_used_by_fit_and_undone_on_exit_and_on_error.
    _sklearn()
    _stock_derivative = _STOCK["tanh_derivative"]
    rng = np.random.default_rng(3)
    Z = np.tanh(rng.standard_normal((300, 17)) * 3)
    delta = rng.standard_normal(Z.shape)
    ref, mine = delta.copy(), delta.copy()
    _stock_derivative(Z, ref)
    assert tanh_derivative_inplace(Z, mine) is None and np.array_equal(mine, ref)


def test_a_fit_with_the_swapped_derivative_is_the_same_fit_to_the_bit():
    # Only the activation swapped, against both: the derivative changes no bit of the weights.
    MLPRegressor, _base = _sklearn()
    _stock_derivative = _STOCK["tanh_derivative"]
    x = np.linspace(-2, 2, 60).reshape(-1, 1)

    def fit():
        return MLPRegressor(hidden_layer_sizes=(9, 4), activation="tanh", solver="lbfgs", max_iter=40,
                            random_state=0).fit(x, np.sin(2 * x[:, 0]))

    with sklearn_fast_tanh():
        both = fit()
    with sklearn_fast_tanh():
        _base.DERIVATIVES["tanh"] = _stock_derivative     # the with's exit restores it
        one = fit()
    assert _base.DERIVATIVES["tanh"] is _stock_derivative
    assert all(np.array_equal(a, b) for a, b in zip(both.coefs_ + both.intercepts_, one.coefs_ + one.intercepts_))
    assert both.n_iter_ == one.n_iter_ > 5
