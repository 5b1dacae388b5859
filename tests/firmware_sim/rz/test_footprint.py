"""The thermopile's real footprint as radial weights (firmware_sim.rz.footprint) and its read-out in the world."""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_sim.rz.footprint import SquareSensor, centred_square_area_in_disk, centred_square_weight

SIDE = 0.010
#: Sensors the tests check: centred, offset, rectangular with a sensitivity map, the axis outside.
CASES = [SquareSensor(),
         SquareSensor(offset_x_m=0.4e-3, offset_y_m=-0.3e-3),
         SquareSensor(side_x_m=10.2e-3, side_y_m=9.8e-3, offset_x_m=-0.5e-3, offset_y_m=0.2e-3,
                      gradient_x=0.05, gradient_y=-0.04),
         SquareSensor(side_x_m=4e-3, side_y_m=3e-3, offset_x_m=6e-3, offset_y_m=1e-3, gradient_x=0.3)]


def brute_force_rings(s: SquareSensor, faces: np.ndarray, n: int = 1500) -> np.ndarray:
    """Sensitivity-weighted area per annulus by a midpoint sum over an n x n pixel grid of the footprint."""
    x0, x1, y0, y1 = s.bounds_m
    xs = x0 + (np.arange(n) + 0.5) * (x1 - x0) / n
    ys = y0 + (np.arange(n) + 0.5) * (y1 - y0) / n
    X, Y = np.meshgrid(xs, ys)
    w = s.sensitivity(X, Y) * (x1 - x0) * (y1 - y0) / n ** 2
    return np.histogram(np.hypot(X, Y).ravel(), bins=faces, weights=w.ravel())[0]


def test_centred_square_closed_forms_agree():
    r = np.linspace(0.0, 0.009, 181)
    s = SquareSensor()
    # Area inside the disk: the exact quadrant decomposition against the segment formula.
    np.testing.assert_allclose(s.disk_moments(r), centred_square_area_in_disk(r, SIDE), rtol=0, atol=1e-15)
    # w(r): exact arcs against the brief's closed form, and d(area)/dr against both.
    arcs = np.array([s.circle_weight(x) for x in r])
    np.testing.assert_allclose(arcs, centred_square_weight(r, SIDE), rtol=1e-12, atol=1e-18)
    h = 1e-8
    for x in (1e-3, 4.9e-3, 5.5e-3, 6.5e-3, 7.0e-3):
        d = (s.disk_moments([x + h])[0] - s.disk_moments([x - h])[0]) / (2 * h)
        assert d == pytest.approx(s.circle_weight(x), rel=1e-6)


@pytest.mark.parametrize("s", CASES)
def test_weights_integrate_to_the_sensitivity_weighted_area(s):
    faces = np.concatenate([np.linspace(0, s.outer_radius_m, 37), [s.outer_radius_m * 1.5]])
    w = s.ring_weights(faces)
    # The map has mean 1 over the footprint: the weighted area is the area.
    assert w.sum() == pytest.approx(s.area_m2, rel=1e-12)
    assert w[-1] == pytest.approx(0.0, abs=1e-18)   # nothing beyond the farthest corner
    assert np.all(w >= -1e-18)


@pytest.mark.parametrize("s", CASES)
def test_weights_match_a_brute_force_sum_and_the_arcs(s):
    faces = np.unique(np.concatenate([np.linspace(0, s.outer_radius_m, 23), [s.inner_radius_m, 4.9e-3, 5.1e-3]]))
    w = s.ring_weights(faces)
    bf = brute_force_rings(s, faces)
    # A 1500^2 midpoint sum bins whole pixels by their centres: each ring's area is good to
    # ~6e-5 of the footprint (0.2 % of a ring), far below what a wrong term would move.
    np.testing.assert_allclose(w, bf, rtol=0, atol=1.5e-4 * s.area_m2)
    # The azimuthal integral of the map (exact arcs) integrated over r by Gauss-Legendre per ring,
    # split where w(r) has kinks (the radii of the edges' tangent points and of the corners).
    x0, x1, y0, y1 = s.bounds_m
    kinks = [abs(v) for v in s.bounds_m] + [math.hypot(x, y) for x in (x0, x1) for y in (y0, y1)]
    xg, wg = np.polynomial.legendre.leggauss(40)
    for a, b, wi in zip(faces[:-1], faces[1:], w):
        cuts = [a] + sorted(k for k in kinks if a < k < b) + [b]
        q = 0.0
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            rs = 0.5 * (hi - lo) * xg + 0.5 * (lo + hi)
            q += 0.5 * (hi - lo) * sum(wk * s.circle_weight(r) for wk, r in zip(wg, rs))
        assert q == pytest.approx(wi, abs=1e-7 * s.area_m2)


def test_uniform_field_reads_the_same_through_square_and_disk():
    """A centred square on a uniform field equals the disk (both read the field's value)."""
    s = SquareSensor()
    faces = np.linspace(0, 0.008, 41)
    w = s.ring_weights(faces)
    q = np.full(faces.size - 1, 1234.5)
    assert (w @ q) / w.sum() == pytest.approx(1234.5, rel=1e-14)
    # On a field linear in r^2 (the even field near the axis) square and disk differ by the
    # second moment: the square's mean r^2 is a^2/6, the equal-area disk's a^2/(2 pi).
    # The field is one value per 0.2-mm ring (its annulus mean): good to 0.1 %, where the disk's is 4.5 % off.
    rc2 = 0.5 * (faces[1:] ** 2 + faces[:-1] ** 2)
    assert (w @ rc2) / w.sum() == pytest.approx(SIDE ** 2 / 6, rel=1e-3)
    assert SIDE ** 2 / (2 * math.pi) < 0.96 * SIDE ** 2 / 6


def test_bad_sensors_are_refused():
    with pytest.raises(ValueError):
        SquareSensor(side_x_m=0.0)
    with pytest.raises(ValueError):
        SquareSensor(gradient_x=1.5, gradient_y=0.6)
    with pytest.raises(ValueError):
        SquareSensor(offset_x_m=math.inf)


def test_the_thermocouple_off_the_axis_reads_an_even_profile_exactly():
    from firmware_sim.rz.footprint import off_axis_weights

    faces = np.array([0.0, 1e-3, 1.8e-3, 2.5e-3, 3.3e-3])
    rho = 0.5 * (faces[1:] ** 2 + faces[:-1] ** 2)   # each annulus's mean r^2
    T = 3.0 + 2e5 * rho                               # T = a + b r^2: its annulus means
    for r in (0.3e-3, 0.9e-3, 1.7e-3, 2.9e-3):
        pairs = off_axis_weights(faces, r)
        assert sum(w for _, w in pairs) == pytest.approx(1.0)
        assert sum(w * T[i] for i, w in pairs) == pytest.approx(3.0 + 2e5 * r * r, rel=1e-12)
    with pytest.raises(ValueError):
        off_axis_weights(faces, 0.0)
    with pytest.raises(ValueError):
        off_axis_weights(faces, 5e-3)


def _disk_moments_one_radius_at_a_time(s: SquareSensor, r_m: float) -> float:
    """The weights as first written: NumPy float64 scalars, one radius at a time (the reference the
    vectorised :meth:`SquareSensor.disk_moments` must reproduce bit for bit: the worlds read through it)."""
    x0, x1, y0, y1 = s.bounds_m
    r = float(r_m)
    if r <= 0:
        return 0.0
    c0 = 1.0 - s.gradient_x * s.offset_x_m / s.side_x_m - s.gradient_y * s.offset_y_m / s.side_y_m
    cx, cy = s.gradient_x / s.side_x_m, s.gradient_y / s.side_y_m
    tot = 0.0
    for X, Y, sign in ((x1, y1, 1.0), (x0, y1, -1.0), (x1, y0, -1.0), (x0, y0, 1.0)):
        aX, aY = np.array(abs(X)), np.array(abs(Y))
        xm = np.minimum(aX, r)
        xa = np.minimum(xm, np.sqrt(np.maximum(r * r - aY * aY, 0.0)))
        G = lambda x: 0.5 * (x * np.sqrt(np.maximum(r * r - x * x, 0.0))  # noqa: E731
                             + r * r * np.arcsin(np.clip(x / r, -1.0, 1.0)))
        H = lambda x: np.maximum(r * r - x * x, 0.0) ** 1.5 / 3.0  # noqa: E731
        a = aY * xa + G(xm) - G(xa)
        mx = 0.5 * aY * xa * xa + H(xa) - H(xm)
        my = 0.5 * (aY * aY * xa + r * r * (xm - xa) - (xm ** 3 - xa ** 3) / 3.0)
        sx, sy = math.copysign(1.0, X), math.copysign(1.0, Y)
        tot += sign * (c0 * sx * sy * float(a) + cx * sy * float(mx) + cy * sx * float(my))
    return tot


@pytest.mark.parametrize("s", CASES)
def test_all_radii_at_once_are_the_one_at_a_time_weights_bit_for_bit(s):
    rng = np.random.default_rng(7)
    r = np.concatenate([[-1e-3, 0.0, s.inner_radius_m, s.outer_radius_m, 2 * s.outer_radius_m],
                        np.linspace(0.0, s.outer_radius_m * 1.05, 151), rng.uniform(0, 1.1 * s.outer_radius_m, 150)])
    ref = np.array([_disk_moments_one_radius_at_a_time(s, x) for x in r])
    assert np.array_equal(s.disk_moments(r), ref)
    assert np.array_equal(s.disk_moments(r.reshape(2, -1)), ref.reshape(2, -1))
