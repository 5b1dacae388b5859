"""The running decision through the sensor chain, on touches of the faithful (r, z) world.

The world is not the chain's model: finite volumes with the thermopile inside its sensing layer,
the object off the probe's temperature and a contact resistance (firmware_sim.rigs.contact_record).
The probe is as on its datasheet, so the nominal chain is its correct calibration.
"""

from __future__ import annotations

from functools import lru_cache

import pytest

from edge.calibration.model import ProbeCalibration
from edge.estimation.running import CHAIN_EVERY_s, ChainDecision
from edge.recognition import KnownObject, ObjectSet
from edge.estimation.running import SequentialDecision
from edge.physics.materials import load_materials
from firmware_sim.rigs.contact_record import ContactTouch, record_touch

P = KnownObject.from_properties
KITCHEN = ObjectSet([P("acrylic_sheet", "polymer", 0.19, 1190, 1470), P("window", "glass", 1.0, 2500, 750),
                     P("granite_top", "stone", 2.8, 2800, 1000), P("steel_pan", "alloy", 17, 7900, 500),
                     P("alu_case", "alloy", 160, 2800, 880), P("oak", "wood", 0.18, 700, 1600)])


@lru_cache(maxsize=None)
def _feed(material: str, truth: str, offset_K: float, R_c: float):
    """One 2-s touch fed sample by sample to both decisions, as the sequence does.

    Cached: the window touch serves two tests, which only read the fed decisions (a faithful touch
    costs ~0.5 s of the (r, z) world).
    """
    r = record_touch(ContactTouch(load_materials().get(material).solid, R_c, offset_K, lead_s=1.0, heat_s=2.0),
                     board="precision", seed=0)
    t, T, q = r["t_s"], r["T_C"], r["q_W_m2"]
    base = (t > -0.5) & (t <= 0)
    T0, q0 = T[base].mean(), q[base].mean()
    raw = SequentialDecision(KITCHEN, 0.95, 0.3)
    chain = ChainDecision(KITCHEN, 0.95, 0.3, calibration=ProbeCalibration.nominal("paper"))
    ts, Ts, qs = [], [], []
    chain.attach_record(ts, Ts, qs, 0.0)
    for a, b, c in zip(t, T, q):
        ts.append(a), Ts.append(b), qs.append(c)
        if a > 0:
            raw.update(a, b - T0, c - q0)
            chain.update(a, b - T0, c - q0)
    return raw, chain


@pytest.mark.slow  # a touch on the faithful (r, z) world per case
@pytest.mark.parametrize("material, truth, offset_K, R_c", [
    ("pmma", "acrylic_sheet", 2.0, 3e-5),
    ("soda_lime_plate_glass", "window", -1.5, 1e-5),
    ("oak_cross_grain", "oak", 0.0, 2e-5),
])
def test_the_chain_never_decides_a_wrong_object_where_the_raw_reading_does(material, truth, offset_K, R_c):
    raw, chain = _feed(material, truth, offset_K, R_c)
    # The world is a real test: the raw thick-body decision is fooled by the sensing layer.
    assert raw.decided is not None and raw.decided.object != truth
    # The chain either decides the truth or waits; its running answer ends on the truth.
    assert chain.decided is None or chain.decided.object == truth
    assert chain.answer is not None and chain.answer.object == truth
    assert chain.answer.source == "sensor_chain" and raw.answer.source == "thick_body"
    assert chain.answer.to_dict()["source"] == "sensor_chain"


def test_the_chain_decides_early_where_the_record_allows_and_fits_at_its_pace():
    _, chain = _feed("soda_lime_plate_glass", "window", -1.5, 1e-5)
    assert chain.decided is not None and chain.decided.object == "window"
    assert chain.decided.elapsed_s < 1.5
    # One fit per CHAIN_EVERY_s of heating from min_time_s on, not one per sample.
    assert chain.fits <= (2.0 - 0.3) / CHAIN_EVERY_s + 2


def test_without_its_record_the_chain_has_no_answer():
    chain = ChainDecision(KITCHEN, 0.95, 0.3, calibration=ProbeCalibration.nominal("paper"))
    assert chain.update(0.5, 1.0, 100.0) is None and chain.fits == 0
    with pytest.raises(ValueError):
        ChainDecision(KITCHEN, 0.95, 0.3, calibration=ProbeCalibration.nominal("paper"), every_s=0.0)
