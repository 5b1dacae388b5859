"""NumPy cubic spline against scipy.interpolate.CubicSpline (not-a-knot)."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline as SciSpline

from edge.estimation.spline import CubicSpline, resample


@pytest.mark.parametrize("n", [2, 3, 4, 5, 17, 200])
def test_matches_scipy_on_irregular_grids(n):
    rng = np.random.default_rng(n)
    x = np.sort(rng.uniform(0, 2, n))
    x[0], x[-1] = 0.0, 2.0
    x = np.unique(x)
    y = np.sin(3 * x) + rng.normal(0, 0.1, x.size)
    xi = np.linspace(-0.1, 2.1, 333)
    np.testing.assert_allclose(CubicSpline(x, y)(xi), SciSpline(x, y)(xi), rtol=1e-10, atol=1e-12)


def test_two_series_share_one_solve():
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
