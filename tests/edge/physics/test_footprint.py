"""The edge's square read-out (edge.physics.footprint) against the world's independent one (firmware_sim.rz.footprint)."""

import numpy as np
import pytest

from edge.physics.bessel import bessel_j
from edge.physics.footprint import area_in_disk, rectangle_weights
from edge.physics.geometry import PROBES
from firmware_sim.rz.footprint import SquareSensor


@pytest.mark.parametrize("sensor", [SquareSensor(), SquareSensor(side_x_m=0.0102, side_y_m=0.0098,
                                                                 offset_x_m=4e-4, offset_y_m=-3e-4)])
def test_area_in_disk_matches_the_worlds_quadrant_decomposition(sensor):
    r = np.linspace(1e-5, sensor.outer_radius_m * 1.05, 97)
    assert np.allclose(area_in_disk(r, sensor.bounds_m), sensor.disk_moments(r), rtol=0, atol=1e-14)


@pytest.mark.parametrize("offset_m", [(0.0, 0.0), (5e-4, -5e-4)])
def test_rectangle_weights_match_the_worlds_ring_weights(offset_m):
    s = SquareSensor(offset_x_m=offset_m[0], offset_y_m=offset_m[1])
    faces = np.linspace(0.0, s.outer_radius_m + 1e-4, 20001)
    rings = s.ring_weights(faces) / s.area_m2
    mid = 0.5 * (faces[1:] + faces[:-1])
    zeta = np.array([1.0, 300.0, 2000.0, 8000.0, 25000.0])
    ref = bessel_j(0, zeta[:, None] * mid[None, :]) @ rings
    got = rectangle_weights(zeta, s.side_x_m, s.side_y_m, *offset_m)
    assert np.allclose(got, ref, rtol=0, atol=1e-8)


def test_the_square_differs_from_its_equal_area_disk_where_the_heater_edge_lies():
    g = PROBES["small-heater"]
    assert g.sensor_square_m == (0.010, 0.010)
    zeta = np.array([1000.0, 2000.0])
    b = g.sensor_radius_m
    disk = 2.0 * bessel_j(1, zeta * b) / (zeta * b)
    square = rectangle_weights(zeta, 0.010, 0.010)
    assert np.all(np.abs(square - disk) > 0.01)


@pytest.mark.parametrize("rect", [(0.010, 0.010, 0.0, 0.0), (0.0102, 0.0098, 4e-4, -3e-4), (0.004, 0.003, 6e-3, 1e-3)])
def test_rectangle_weights_have_converged(monkeypatch, rect):
    """The trapezoid rule in the plane-wave angle has converged: 200 more points move no weight by more than
    1e-15 (round-off); and the small-zeta limit is the footprint's mean square radius (J0(x) = 1 - x^2/4 + x^4/64 - ...)."""
    import edge.physics.footprint as fp

    from edge.physics.axisym import hankel_nodes

    zeta = np.concatenate([[0.0, 1.0, 10.0], hankel_nodes(PROBES["small-heater"])[0]])
    got = rectangle_weights(zeta, *rect)
    points = fp.trapezoid_points
    monkeypatch.setattr(fp, "trapezoid_points", lambda x: points(x) + 200)
    assert np.max(np.abs(rectangle_weights(zeta, *rect) - got)) < 1e-15
    sx, sy, ox, oy = rect
    r2 = ox * ox + oy * oy + (sx * sx + sy * sy) / 12.0
    assert got[0] == 1.0
    assert got[1] == pytest.approx(1.0 - r2 / 4.0, abs=1e-10)        # the x^4 term: ~1e-11
    assert got[2] == pytest.approx(1.0 - 100.0 * r2 / 4.0, abs=1e-6)       # the x^4 term: < 3e-7
