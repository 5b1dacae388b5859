"""The axisymmetric model's probe parts, shared between models of the same probe and times."""

import dataclasses

import numpy as np

from edge.physics import axisym
from edge.physics.axisym import AxisymModel
from edge.physics.geometry import SMALL_HEATER


def _answers(m: AxisymModel):
    out = [m.transforms(1.1, 5e-7, derivatives=True), m.transforms(160.0, 6e-5, thickness_m=3e-3, back="insulated",
                                                                    contact_resistance_m2K_W=1e-4)]
    r = m.responses(0.19, 1.1e-7)
    return [a for o in out for a in o] + [r.T_tc_K_per_W, r.q_sensor_W_m2_per_W, m.t_s]


def test_a_model_that_takes_the_parts_of_an_earlier_one_answers_bit_for_bit_as_a_fresh_one():
    t = np.arange(1, 121) / 40.0
    axisym._PARTS.clear()
    fresh = _answers(AxisymModel(SMALL_HEATER, t))
    t_again = t.copy()
    shared = AxisymModel(SMALL_HEATER, t_again)
    assert len(axisym._PARTS) == 1          # the second model was not built again
    assert all(np.array_equal(a, b) for a, b in zip(fresh, _answers(shared)))
    # The caller's times stay the caller's: reusing its array changes no model built from it.
    t_again[:] = 99.0
    assert np.array_equal(shared.t_s, t) and np.array_equal(AxisymModel(SMALL_HEATER, t).t_s, t)


def test_another_probe_or_other_times_or_quadrature_get_their_own_parts():
    t = np.arange(1, 61) / 20.0
    axisym._PARTS.clear()
    base = AxisymModel(SMALL_HEATER, t)
    wider = AxisymModel(dataclasses.replace(SMALL_HEATER, heater_radius_m=SMALL_HEATER.heater_radius_m * 1.1), t)
    later = AxisymModel(SMALL_HEATER, t + 0.5)
    finer = AxisymModel(SMALL_HEATER, t, per_panel=5)
    for m in (wider, later, finer):
        assert not np.array_equal(m.transforms(1.1, 5e-7)[0], base.transforms(1.1, 5e-7)[0])
    assert finer.n_nodes > base.n_nodes
    assert len(axisym._PARTS) == 4
    AxisymModel(SMALL_HEATER, t + 1.0)
    assert len(axisym._PARTS) == axisym._PARTS_MAX == 4      # bounded: the oldest (base's) was dropped
    assert all(k[0] != SMALL_HEATER or k[2] != t.tobytes() or k[3][1] != 4 for k in axisym._PARTS)
