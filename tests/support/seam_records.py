"""The touch records the seam's contract tests run every estimate path over (tests/edge/estimation).

Built once per session by the ``records`` fixture of tests/edge/estimation/conftest.py: the contract
test and the refusal tests of the seam read the same records, which before were simulated again in
each module that imported the fixture. The faithful-world touch is :func:`tests.support.records.recorded_touch`
(shared with tests/edge/estimation/test_no_answer.py's, the very same call).
"""

from __future__ import annotations

import numpy as np

from edge.estimation.record import TouchRecord
from edge.physics.axisym import AxisymModel
from edge.physics.geometry import PROBES


def paper_record(effusivity: float, contact: bool = True) -> TouchRecord:
    """A touch of the paper probe through the device's sequence on the simulated rig (its TouchRecord)."""
    from tests.support.daemons import make_sequence  # noqa: PLC0415

    from edge.service.config import Config  # noqa: PLC0415

    # Pinned at 10 Hz: paper/glass is the record without its contact in air (the chain finds the contact at
    # heater-on); the reference rig's 12.5 Hz records it in air first.
    cfg = Config({"measurement": {"sample_rate_Hz": 10.0}})
    _, _, seq, params = make_sequence(effusivity=effusivity, contact=contact, cfg=cfg)
    try:
        out = seq.run(params)
    finally:
        seq.close()
    assert out.touch is not None
    return out.touch


def small_record(solid, seed: int) -> TouchRecord:
    """A small-heater touch: 0.5 s of baseline, 3 s of heating at 50 Hz from the axisymmetric model."""
    g = PROBES["small-heater"]
    rng = np.random.default_rng(seed)
    rate = 50.0
    t_heat = np.arange(1, 151) / rate
    T, q = AxisymModel(g, t_heat).signals(solid.k_W_mK, solid.alpha_m2_s)
    t = np.concatenate((np.arange(-25, 0) / rate, t_heat))
    T = np.concatenate((np.zeros(25), T)) + 22.0 + 0.01 * rng.standard_normal(t.size)
    q = np.concatenate((np.zeros(25), q)) + 0.5 * rng.standard_normal(t.size)
    return TouchRecord(probe="small-heater", t_s=t, T_C=T, q_W_m2=q, power_W=g.nominal_power_W, heater_on_s=3.0,
                       sample_rate_Hz=rate, baseline_s=0.5)


def faithful_record(solid) -> TouchRecord:
    """A paper-probe touch on the faithful world, armed: 2 s in air and on the object before heating."""
    from firmware_sim.rigs.contact_record import ContactTouch  # noqa: PLC0415
    from tests.support.records import recorded_touch  # noqa: PLC0415

    touch = ContactTouch(solid, 1e-5, 0.0, lead_s=1.0, heat_s=3.0)
    r = recorded_touch(touch, seed=3)
    return TouchRecord(probe="paper", t_s=r["t_s"], T_C=r["T_C"], q_W_m2=r["q_W_m2"], power_W=5.0,
                       heater_on_s=touch.heat_s, sample_rate_Hz=1.0 / float(r["t_s"][1] - r["t_s"][0]),
                       baseline_s=0.5, arm_s=touch.pre_s + touch.lead_s)


def seam_records() -> dict[str, TouchRecord]:
    """Every record the contract runs over, by name (probe head / what was touched)."""
    from edge.physics.materials import load_materials  # noqa: PLC0415

    lib = load_materials()
    return {
        "paper/faithful_pmma": faithful_record(lib.get("pmma").solid),
        "paper/glass": paper_record(1400.0),
        "paper/pmma": paper_record(570.0),
        "paper/air": paper_record(1400.0, contact=False),
        "small/glass": small_record(lib.get("tempered_glass").solid, 1),
        "small/pmma": small_record(lib.get("pmma").solid, 2),
    }
