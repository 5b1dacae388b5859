"""The faithful world's history read-outs: one time on scalars, bit for bit the array path."""

import numpy as np
import pytest

from firmware_sim.rz.history import interpolate

NAMES = ("T_tc", "q_sensor", "T_obj_face")


def _history(rng, n=40):
    t = np.cumsum(rng.uniform(0.001, 0.03, n))
    t[0] = 0.0
    t[17] = t[16]                      # a switch: two records at one time (the right-hand side)
    h = {"t": np.r_[t, np.zeros(8)]}   # capacity beyond the n valid records, as the world grows it
    for name in NAMES + ("y",):
        h[name] = np.r_[rng.normal(25.0, 3.0, n), np.zeros(8)]
    h["T_obj_face"][:10] = np.nan      # no object in the first phase
    return h, n


@pytest.mark.parametrize("tau_s", [0.0, 0.05])
def test_one_time_reads_the_array_paths_bits(tau_s):
    rng = np.random.default_rng(5)
    h, n = _history(rng)
    ts = np.r_[0.0, h["t"][:n], rng.uniform(0.0, h["t"][n - 1] + 0.1, 200)]
    many = interpolate(h, n, ts, NAMES, tau_s)
    for k, x in enumerate(ts):
        one = interpolate(h, n, np.array([x]), NAMES, tau_s)
        for name, v in one.items():
            assert v.shape == (1,)
            assert np.array_equal(v, many[name][k:k + 1], equal_nan=True), (name, x)
