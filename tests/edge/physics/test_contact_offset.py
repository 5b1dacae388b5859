"""The contact response of an object at another temperature (edge.physics.contact_offset) against exact solutions."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from edge.physics.contact_offset import ContactKernel
from edge.physics.geometry import PROBES
from edge.physics.solids import Solid

G = PROBES["small-heater"]
PROBE = Solid(0.2, 1200.0, 1500.0)


def half_space_probe():
    """The stack made one material, thick: the probe is a half-space (the sensor a thin slice at the face)."""
    L = G.sensing_thickness_m
    return dataclasses.replace(G, sensing=PROBE, heater_material=PROBE, substrate=PROBE, substrate_thickness_m=10.0,
                               sensor_depth_m=(0.999 * L, L))


@pytest.mark.parametrize("e_obj", [60.0, 600.0, 6000.0])
def test_two_half_spaces_meet_at_the_exact_contact_temperature_and_flux(e_obj):
    tau = np.linspace(0.05, 5.0, 40)
    K = ContactKernel(half_space_probe(), tau, tau, tau)
    T, q = K.responses(e_obj)
    e_p = PROBE.effusivity_W_s05_m2K
    # Exact: the face jumps to e_o / (e_o + e_p) and stays; the flux into the probe is e_p theta_i / sqrt(pi t).
    np.testing.assert_allclose(T, e_obj / (e_obj + e_p), rtol=1e-5)
    np.testing.assert_allclose(q, -e_p * e_obj / (e_obj + e_p) / np.sqrt(math.pi * tau), rtol=2e-3)
    # The heater film at depth L inside the probe: theta_i erfc(L / (2 sqrt(alpha t))).
    L = G.sensing_thickness_m
    exact = e_obj / (e_obj + e_p) * np.array([math.erfc(L / (2 * math.sqrt(PROBE.alpha_m2_s * t))) for t in tau])
    np.testing.assert_allclose(K.heater_response(e_obj), exact, rtol=1e-4, atol=1e-7)


def test_a_contact_resistance_delays_the_face_and_a_warmer_object_pushes_heat_up():
    tau = np.geomspace(0.02, 8.0, 60)
    K = ContactKernel(G, tau, tau)
    T0, q0 = K.responses(1000.0)
    T1, q1 = K.responses(1000.0, 1e-4)
    assert np.all(T1 < T0) and np.all(np.diff(T0) > -1e-8)
    assert np.all(q0 < 0)                      # heat flows up into the probe: the sensor reads it negative
    # Behind the thin stack the insulating foam: the face heads on for the object's temperature.
    assert T0[0] + 0.15 < T0[-1] < 1.0


def test_times_before_contact_give_nothing():
    tau = np.array([-0.5, -0.1, 0.3, 1.0])
    T, q = ContactKernel(G, tau, tau).responses(800.0)
    assert T[0] == T[1] == 0.0 and q[0] == q[1] == 0.0 and T[2] > 0
