"""docs/python-api.md's examples run, as written, against one simulated probe; and the API's types."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from host.api import Measurement, Phase, Probe, RunningAnswer, Samples, typed_event
from host.device import simulated_probe

pytestmark = pytest.mark.hil
DOC = Path(__file__).resolve().parents[2] / "docs" / "python-api.md"


def code_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


_DAEMON: dict = {}


@pytest.fixture(scope="module")
def port(tmp_path_factory):
    with simulated_probe("glass_12V", tmp_path_factory.mktemp("api")) as (p, daemon, sim):
        _DAEMON["daemon"] = daemon
        yield p


def test_the_guide_has_examples():
    assert len(code_blocks(DOC.read_text())) >= 4


@pytest.mark.parametrize("index", range(len(code_blocks(DOC.read_text()))))
def test_each_example_of_the_guide_runs_against_a_simulated_probe(port, index, capsys):
    blocks = code_blocks(DOC.read_text())
    namespace = {"PORT": port}
    # Later blocks use names the earlier ones imported, as a reader running them in order would.
    for block in blocks[:index]:
        exec(compile("\n".join(ln for ln in block.splitlines() if ln.startswith(("from ", "import "))),
                     f"{DOC.name}[{index}]-imports", "exec"), namespace)
    exec(compile(blocks[index], f"{DOC.name}[{index}]", "exec"), namespace)
    assert capsys.readouterr().out.strip()  # each example shows the user something


def test_a_measurement_is_typed_and_frozen(port):
    with Probe.connect(port) as probe:
        m = probe.measure(contact_time_s=1.5)
        assert isinstance(m, Measurement) and m.device_id == probe.info()["device_id"]
        # The device's numbers, typed (glass: e ~ 1.5e3, more on a probe warmed by earlier touches).
        res = m.record["result"]
        assert m.effusivity_W_s05_m2K == res["effusivity_W_s05_m2K"] and 500 < m.effusivity_W_s05_m2K < 4000
        assert m.k_W_mK_u == res["k_W_mK_u"] > 0 and m.object == res["object"] and m.flags == tuple(m.record["flags"])
        assert set(m.determined_by) == {"e", "k", "alpha"} and m.contact_time_s == pytest.approx(1.5)
        with pytest.raises(AttributeError):
            m.status = "ok"  # frozen
        again = probe.result(m.measurement_id)
        assert again == m  # the stored record types to the same measurement
        with pytest.raises(TypeError, match="contact_s"):
            probe.measure(contact_s=1.0)


def test_a_stream_yields_typed_events_then_the_measurement(port):
    with Probe.connect(port) as probe:
        items = list(probe.stream(contact_time_s=1.5))
    assert isinstance(items[-1], Measurement) and items[-1].ok
    kinds = {type(i) for i in items[:-1]}
    assert kinds == {Phase, Samples, RunningAnswer}
    done = [i for i in items if isinstance(i, Phase)][-1]
    assert done.phase == "done" and done.measurement_id == items[-1].measurement_id
    answers = [i for i in items if isinstance(i, RunningAnswer)]
    assert all(math.isfinite(a.effusivity_W_s05_m2K) and 0 <= a.posterior <= 1 for a in answers)


def test_a_null_sample_types_to_nan():
    from edge.protocol.commands import EventKind
    from edge.protocol.messages import Event

    s = typed_event(Event(1, EventKind.SAMPLES, {"kind": "samples", "seq": 2, "t_s": 0.1, "sample_t_s": [0.1],
                                                  "T_C": [None], "q_W_m2": [3.0]}))
    assert isinstance(s, Samples) and math.isnan(s.T_C[0]) and s.q_W_m2 == (3.0,)


def test_leaving_a_stream_while_the_probe_heats_aborts_the_touch(port, monkeypatch):
    import time

    from tests.support.daemons import HookedSensors

    daemon = _DAEMON["daemon"]
    held = []

    def hold(n, heater_on):  # hold the 3rd heating read (wall time) until the heater is cut
        if heater_on:
            held.append(n)
        if len(held) == 3 and heater_on:
            deadline = time.monotonic() + 10.0
            while daemon.heater.is_on and time.monotonic() < deadline:
                time.sleep(0.002)

    real = daemon.sensors
    monkeypatch.setattr(daemon, "sensors", HookedSensors(real, daemon.heater, hold))
    with Probe.connect(port) as probe:
        for item in probe.stream(contact_time_s=2.0):
            if isinstance(item, Phase) and item.phase == "heating":
                break
        daemon.sensors = real
        latest = probe.history(limit=1)[0]
        assert latest.status == "aborted" and latest.reason == "host_abort"
        assert not probe.status()["heater_on"]
        assert probe.measure(contact_time_s=0.5).ok  # the link is clean afterwards
