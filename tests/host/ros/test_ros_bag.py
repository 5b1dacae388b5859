"""The ROS 2 bridge's messages, serialised without ROS: a simulated touch to a rosbag2 and back (rosbags)."""

from __future__ import annotations

import math
from collections import Counter

import pytest

from host.api import Probe
from host.device import simulated_probe
from host.ros.bag import read_bag, record_touch
from host.ros.bridge import ANSWER_KEYS, RUNNING_KEYS, TOPICS, key_values

pytestmark = pytest.mark.hil


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    """One streamed touch on a simulated probe, recorded; (answer, messages read back, raw series)."""
    tmp = tmp_path_factory.mktemp("rosbag")
    with simulated_probe("glass_12V", tmp / "dev") as (port, daemon, sim):
        with Probe.connect(port) as probe:
            answer = record_touch(probe, tmp / "touch", contact_time_s=1.5)
            series = probe.series(answer.measurement_id)
    return answer, list(read_bag(tmp / "touch")), series


def test_the_bag_holds_every_topic_of_the_mapping(bag):
    answer, msgs, series = bag
    counts = Counter(topic for topic, _, _ in msgs)
    assert set(counts) == {topic for topic, _ in TOPICS.values()}
    assert counts["thermotouch/answer"] == 1 and counts["/diagnostics"] == 1
    assert counts["thermotouch/running_answer"] >= 1
    stamps = [s for _, s, _ in msgs]
    assert stamps == sorted(stamps)


def test_the_answer_reads_back_with_its_variances_and_traceability(bag):
    answer, msgs, series = bag
    (msg,) = [m for t, _, m in msgs if t == "thermotouch/answer"]
    kv = key_values(msg)
    assert tuple(kv) == ANSWER_KEYS
    assert int(kv["measurement_id"]) == answer.measurement_id and kv["status"] == "ok"
    assert float(kv["effusivity_W_s05_m2K"]) == answer.effusivity_W_s05_m2K
    assert float(kv["effusivity_W_s05_m2K_variance"]) == pytest.approx(answer.effusivity_W_s05_m2K_u ** 2)
    assert float(kv["k_W_mK_variance"]) == pytest.approx(answer.k_W_mK_u ** 2)
    assert kv["determined_by_e"] == answer.determined_by["e"] and kv["object"] == answer.object
    assert kv["device_id"] == answer.device_id and kv["device_id"].startswith("tt-")
    status = msg.status[0]
    assert status.name == "thermotouch/answer" and status.hardware_id == answer.device_id
    assert status.level == (1 if answer.flags else 0)  # WARN: flagged (here: uncalibrated)
    assert msg.header.frame_id == "thermotouch_tip"


def test_running_answers_and_temperatures_are_the_touch_s(bag):
    answer, msgs, series = bag
    running = [key_values(m) for t, _, m in msgs if t == "thermotouch/running_answer"]
    assert all(tuple(kv) == RUNNING_KEYS for kv in running)
    last = running[-1]
    assert 0.0 <= float(last["posterior"]) <= 1.0 and float(last["effusivity_W_s05_m2K_variance"]) > 0
    assert float(last["effusivity_W_s05_m2K"]) == pytest.approx(answer.effusivity_W_s05_m2K, rel=0.5)
    temps = [m for t, _, m in msgs if t == "thermotouch/temperature"]
    T = [m.temperature for m in temps]
    raw = series["raw_T_C"]
    assert len(T) == int(sum(math.isfinite(x) for x in raw))
    assert T == pytest.approx([x for x in raw if math.isfinite(x)], abs=1e-3)
    # Stamps advance by the sample period (10 Hz here), to within the board clock's rounding.
    dt_ns = temps[-1].header.stamp.sec * 10**9 + temps[-1].header.stamp.nanosec \
        - (temps[0].header.stamp.sec * 10**9 + temps[0].header.stamp.nanosec)
    assert dt_ns == pytest.approx((series["raw_t_s"][-1] - series["raw_t_s"][0]) * 1e9, abs=1e6)


def test_device_state_is_a_diagnostics_array(bag):
    answer, msgs, series = bag
    (msg,) = [m for t, _, m in msgs if t == "/diagnostics"]
    kv = key_values(msg)
    assert kv["state"] == "idle" and kv["heater_on"] == "false" and kv["faults"] == ""
    assert msg.status[0].name == "thermotouch: device"
