"""NumPy cubic spline against scipy.interpolate.CubicSpline (not-a-knot)."""

import numpy as np
import pytest

from edge.estimation.spline import CubicSpline, resample


@pytest.mark.parametrize("n", [2, 3, 4, 5, 17, 200])
def test_matches_scipy_on_irregular_grids(n):
    from scipy.interpolate import CubicSpline as SciSpline  # SciPy only where compared with

    rng = np.random.default_rng(n)
    x = np.sort(rng.uniform(0, 2, n))
    x[0], x[-1] = 0.0, 2.0
    x = np.unique(x)
    y = np.sin(3 * x) + rng.normal(0, 0.1, x.size)
    xi = np.linspace(-0.1, 2.1, 333)
    np.testing.assert_allclose(CubicSpline(x, y)(xi), SciSpline(x, y)(xi), rtol=1e-10, atol=1e-12)


def test_two_series_share_one_solve():
    from scipy.interpolate import CubicSpline as SciSpline

    x = np.linspace(0, 1.95, 40) ** 1.3
    y = np.column_stack([np.sqrt(x), x ** 2])
    xi = np.linspace(0, x[-1], 100)
    np.testing.assert_allclose(resample(x, y, xi), SciSpline(x, y)(xi), rtol=1e-10, atol=1e-12)


def test_cubic_reproduced_exactly():
    x = np.array([0.0, 0.3, 0.7, 1.1, 2.0])
    f = lambda t: 2 * t ** 3 - t + 1
    xi = np.linspace(0, 2, 50)
    np.testing.assert_allclose(CubicSpline(x, f(x))(xi), f(xi), rtol=1e-12)


def test_validation():
    with pytest.raises(ValueError, match="x"):
        CubicSpline([0, 1, 1], [1, 2, 3])
    with pytest.raises(ValueError, match="y"):
        CubicSpline([0, 1, 2], [1, np.nan, 3])
    with pytest.raises(ValueError, match="rows"):
        CubicSpline([0, 1, 2], [1, 2])


def _thomas_slopes_reference(x, y):
    """Knot slopes as edge/spline.py solved them before: a Thomas sweep, one Python step per knot."""
    n = x.size
    dx = np.diff(x)
    slope = np.diff(y, axis=0) / dx[:, None]
    diag, upper, lower = np.empty(n), np.empty(n - 1), np.empty(n - 1)
    rhs = np.empty((n, y.shape[1]))
    diag[1:-1] = 2.0 * (dx[:-1] + dx[1:])
    upper[1:] = dx[:-1]
    lower[:-1] = dx[1:]
    rhs[1:-1] = 3.0 * (dx[1:, None] * slope[:-1] + dx[:-1, None] * slope[1:])
    d0 = x[2] - x[0]
    diag[0], upper[0] = dx[1], d0
    rhs[0] = ((dx[0] + 2 * d0) * dx[1] * slope[0] + dx[0] ** 2 * slope[1]) / d0
    dn = x[-1] - x[-3]
    diag[-1], lower[-1] = dx[-2], dn
    rhs[-1] = (dx[-1] ** 2 * slope[-2] + (2 * dn + dx[-1]) * dx[-2] * slope[-1]) / dn
    c, d = np.zeros(n), np.zeros_like(rhs)
    c[0], d[0] = upper[0] / diag[0], rhs[0] / diag[0]
    for i in range(1, n):
        m = diag[i] - lower[i - 1] * c[i - 1]
        if i < n - 1:
            c[i] = upper[i] / m
        d[i] = (rhs[i] - lower[i - 1] * d[i - 1]) / m
    for i in range(n - 2, -1, -1):
        d[i] -= c[i] * d[i + 1]
    return d


@pytest.mark.parametrize("n", [4, 5, 6, 33, 63, 64, 65, 66, 127, 128, 129, 182, 1001, 6001])
@pytest.mark.parametrize("clock", ["regular", "jittered", "two_rates"])
def test_vectorised_solve_equals_the_thomas_sweep(n, clock):
    rng = np.random.default_rng(n)
    x = np.arange(n) / 90.0
    if clock == "jittered":
        x = x + rng.uniform(-0.3, 0.3, n) / 90.0
    elif clock == "two_rates":
        x = np.concatenate(([0.0], 0.013 + np.arange(n - 1) / 12.5))
    y = np.column_stack([np.sqrt(x - x[0]) + rng.normal(0, 0.01, n), rng.normal(0, 1, n)])
    sp = CubicSpline(x, y)
    ref = _thomas_slopes_reference(x, y)
    assert np.max(np.abs(sp.slopes - ref)) <= 1e-12 * np.max(np.abs(ref))
    xi = np.linspace(x[0], x[-1], 2 * n + 7)
    old = CubicSpline.__new__(CubicSpline)
    old.x, old.y, old.slopes, old._1d = sp.x, sp.y, ref, False
    np.testing.assert_allclose(sp(xi), old(xi), rtol=0, atol=1e-12 * np.max(np.abs(old(xi))))


def test_cached_resampling_operator_gives_the_same_values():
    from edge.estimation import spline

    rng = np.random.default_rng(4)
    x = np.arange(41) / 20.0   # a small base (the daemon's grid): resampled through its operator
    xi = np.arange(201) * 0.01
    xi = xi[xi <= x[-1]]
    with spline._cache_lock:
        spline._operators.clear()
    for _ in range(3):  # first sight builds W; then W from the cache
        y = rng.normal(size=(x.size, 2))
        np.testing.assert_allclose(resample(x, y, xi), CubicSpline(x, y)(xi), rtol=0, atol=1e-12)
        np.testing.assert_allclose(resample(x, y[:, 0], xi), CubicSpline(x, y[:, 0])(xi), rtol=0, atol=1e-12)
    assert 1 <= len(spline._operators) <= spline._OPERATORS_KEPT
    with pytest.raises(ValueError, match="rows"):
        resample(x, np.ones(x.size - 1), xi)
    with pytest.raises(ValueError, match="y"):
        resample(x, np.full(x.size, np.nan), xi)
    W = spline.resampling_operator(x, xi)
    y = rng.normal(size=x.size)
    np.testing.assert_allclose(W @ y, CubicSpline(x, y)(xi), rtol=0, atol=1e-12)


@pytest.mark.parametrize("n", [41, 181])
def test_a_series_resamples_to_the_same_bits_whatever_the_cache_holds(n):
    """The operator and the direct solve round differently: which one runs depends on the sizes only, so
    a record's answer in a fresh process (a cold cache) is the answer of a daemon that met its base before."""
    from edge.estimation import spline

    rng = np.random.default_rng(n)
    x = np.sort(rng.uniform(0.0, 2.0, n))
    xi = np.linspace(x[0], x[-1], 301)
    y = rng.normal(size=n)
    with spline._cache_lock:
        spline._operators.clear()
    first = resample(x, y, xi)
    for _ in range(3):
        assert np.array_equal(resample(x, y, xi), first)
