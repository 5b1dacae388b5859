"""The fuzz run's ZeroDivisionError in the sensor-chain estimate (ISSUE #35, bench/fuzz_bench.py).

Two of 3.66 M fuzzed frames were a MEASURE of a valid ``contact_time_s`` around 0.7 s whose contact was
not recorded in air: the chain's late fit (from 1 s after contact, for the contact's part of u(e)) had no
sample to fit, and the residual's mean square divided by zero inside the estimate. A fit window that
leaves fewer samples than parameters is now refused as a bad argument, by name.
"""

import json

import numpy as np
import pytest

from edge.estimation.sensor_chain import DiskFitter, fit_sensor_chain


def _record(n=14, dt=0.05):
    t = dt * np.arange(n)
    return t, 20.0 + 0.5 * np.sqrt(t), np.full(n, 2000.0)


@pytest.mark.parametrize("start", [1.0, 0.6])
def test_a_fit_window_past_the_record_is_refused_by_name(start):
    t, T, q = _record()                          # 0.65 s after contact
    for fit in (lambda: fit_sensor_chain(t, T, q, fit_start_s=start), lambda: DiskFitter(t, T, q, fit_start_s=start)):
        with pytest.raises(ValueError, match=f"fit_start_s = {start:g} s leaves fewer than 4 samples to fit "
                                             r"\(the record ends 0.65 s after contact\)"):
            fit()
    r = fit_sensor_chain(t, T, q, fit_start_s=0.3)  # the usual window still fits
    assert r.n_fitted == 8 and np.isfinite(r.rms_residual_K)


@pytest.mark.hil
def test_the_fuzzed_measure_gets_its_answer_and_a_named_chain_refusal(tmp_path, caplog):
    from edge.protocol.commands import Command
    from edge.protocol.frame import Frame
    from edge.protocol.messages import decode_request
    from edge.service.daemon import Daemon
    from firmware_sim.rigs.daemon_rig import make_rig
    from tests.support.daemons import FakeEstimator, sim_config

    rig = make_rig()
    d = Daemon(sim_config(tmp_path, measurement={"cooldown_s": 0.0, "baseline_s": 0.2}), rig.board,
               estimator=FakeEstimator())
    try:
        req = decode_request(Frame(int(Command.MEASURE), 1, json.dumps({"contact_time_s": 0.7}).encode()))
        rec = d.handle(req)
    finally:
        d.close()
    chain = rec["result"]["sensor_chain"]
    assert "ZeroDivisionError" not in caplog.text
    assert chain["error"].startswith("ValueError: fit_start_s = 1 s leaves fewer than 4 samples"), chain
    assert rec["status"] == "ok" and rec["result"]["effusivity_W_s05_m2K"] is not None
