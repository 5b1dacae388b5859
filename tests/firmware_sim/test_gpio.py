"""The simulated gpiod 2.x module: API parity, kernel rules, edge events in virtual time."""

import errno
import inspect
from datetime import timedelta

import pytest

from firmware_sim.clock import VirtualClock
from firmware_sim.gpiod.edge_event import EdgeEvent
from firmware_sim.gpiod.kernel import GpioSim

CHIP = "/dev/gpiochip0"


@pytest.fixture
def sim():
    clock = VirtualClock()
    g = GpioSim(clock)
    chip = g.add_chip(CHIP, num_lines=8, line_names={3: "HEATER_EN"})
    return clock, g, chip, g.gpiod


def out_settings(gpiod, **kw):
    return gpiod.LineSettings(direction=gpiod.line.Direction.OUTPUT, **kw)


def in_settings(gpiod, **kw):
    return gpiod.LineSettings(direction=gpiod.line.Direction.INPUT, **kw)


# ---- API parity with the real python gpiod 2.x


def test_names_and_signatures_match_real_gpiod(sim):
    real = pytest.importorskip("gpiod")
    _, _, _, fake = sim
    for name in ("Chip", "LineSettings", "LineRequest", "EdgeEvent", "request_lines",
                 "ChipClosedError", "RequestReleasedError", "is_gpiochip_device"):
        assert hasattr(fake, name), name
    for enum_name in ("Value", "Direction", "Bias", "Drive", "Edge", "Clock"):
        real_enum = getattr(real.line, enum_name)
        fake_enum = getattr(fake.line, enum_name)
        assert {m.name: m.value for m in real_enum} == {m.name: m.value for m in fake_enum}
    assert {m.name: m.value for m in real.EdgeEvent.Type} == {m.name: m.value for m in fake.EdgeEvent.Type}
    real_fields = [f for f in real.LineSettings.__dataclass_fields__]
    assert real_fields == [f for f in fake.LineSettings.__dataclass_fields__]
    pairs = [(real.request_lines, fake.request_lines), (real.Chip.request_lines, fake.Chip.request_lines)]
    for meth in ("get_value", "get_values", "set_value", "set_values", "wait_edge_events",
                 "read_edge_events", "release"):
        pairs.append((getattr(real.LineRequest, meth), getattr(fake.LineRequest, meth)))
    for r, f in pairs:
        assert list(inspect.signature(r).parameters) == list(inspect.signature(f).parameters), r.__name__


def test_real_gpiod_settings_objects_are_accepted(sim):
    real = pytest.importorskip("gpiod")
    _, _, chip, fake = sim
    s = real.LineSettings(direction=real.line.Direction.OUTPUT, output_value=real.line.Value.ACTIVE)
    with fake.request_lines(CHIP, config={2: s}, consumer="t") as req:
        assert req.get_value(2) is fake.line.Value.ACTIVE
        assert chip.level(2) == 1


# ---- outputs and line history


def test_output_value_is_recorded_with_virtual_time(sim):
    clock, _, chip, gpiod = sim
    V = gpiod.line.Value
    req = gpiod.request_lines(CHIP, config={3: out_settings(gpiod)}, consumer="heater")
    clock.advance(1.5)
    req.set_value(3, V.ACTIVE)
    clock.advance(2.0)
    req.set_value("HEATER_EN", V.INACTIVE)  # by name, too
    assert chip.line_history(3) == [(0.0, 0), (1.5, 1), (3.5, 0)]
    assert chip.level_at(3, 1.4) == 0 and chip.level_at(3, 1.5) == 1 and chip.level_at(3, 3.6) == 0
    assert req.get_values() == [V.INACTIVE]


def test_active_low_output_inverts_physical_level(sim):
    _, _, chip, gpiod = sim
    V = gpiod.line.Value
    with gpiod.request_lines(CHIP, config={1: out_settings(gpiod, active_low=True)}) as req:
        assert chip.level(1) == 1  # logical INACTIVE
        req.set_value(1, V.ACTIVE)
        assert chip.level(1) == 0
        assert req.get_value(1) is V.ACTIVE


def test_output_values_argument_overrides_settings(sim):
    _, _, chip, gpiod = sim
    V = gpiod.line.Value
    req = gpiod.Chip(CHIP).request_lines({(4, 5): out_settings(gpiod)}, output_values={5: V.ACTIVE})
    assert (chip.level(4), chip.level(5)) == (0, 1)
    assert req.offsets == [4, 5]


def test_released_line_keeps_driving_its_last_level(sim):
    _, _, chip, gpiod = sim
    req = gpiod.request_lines(CHIP, config={3: out_settings(gpiod)})
    req.set_value(3, gpiod.line.Value.ACTIVE)
    req.release()
    assert chip.level(3) == 1
    assert not chip.is_requested(3)


# ---- kernel rules


def test_double_request_is_ebusy_until_released(sim):
    _, _, chip, gpiod = sim
    req = gpiod.request_lines(CHIP, config={3: out_settings(gpiod)}, consumer="first")
    with pytest.raises(OSError) as ei:
        gpiod.Chip(CHIP).request_lines(config={3: None}, consumer="second")
    assert ei.value.errno == errno.EBUSY
    assert "first" in str(ei.value)
    assert chip.consumer(3) == "first"
    req.release()
    gpiod.request_lines(CHIP, config={3: None}, consumer="second").release()


def test_failed_request_claims_nothing(sim):
    _, _, chip, gpiod = sim
    gpiod.request_lines(CHIP, config={3: None})
    with pytest.raises(OSError):
        gpiod.request_lines(CHIP, config={(2, 3): None})
    assert not chip.is_requested(2)


def test_setting_an_input_line_is_eperm(sim):
    _, _, _, gpiod = sim
    req = gpiod.request_lines(CHIP, config={2: in_settings(gpiod)})
    with pytest.raises(OSError) as ei:
        req.set_value(2, gpiod.line.Value.ACTIVE)
    assert ei.value.errno == errno.EPERM


def test_edge_detection_on_output_is_einval(sim):
    _, _, _, gpiod = sim
    with pytest.raises(OSError) as ei:
        gpiod.request_lines(CHIP, config={2: out_settings(gpiod, edge_detection=gpiod.line.Edge.BOTH)})
    assert ei.value.errno == errno.EINVAL


def test_released_request_raises(sim):
    _, _, _, gpiod = sim
    with gpiod.request_lines(CHIP, config={3: out_settings(gpiod)}) as req:
        assert req
    assert not req
    for call in (lambda: req.get_value(3), lambda: req.set_value(3, gpiod.line.Value.ACTIVE),
                 lambda: req.wait_edge_events(0), lambda: req.read_edge_events(), lambda: req.offsets):
        with pytest.raises(gpiod.RequestReleasedError):
            call()
    req.release()  # idempotent


def test_closed_chip_raises_but_its_requests_live_on(sim):
    _, _, _, gpiod = sim
    chip = gpiod.Chip(CHIP)
    req = chip.request_lines({3: out_settings(gpiod)})
    chip.close()
    with pytest.raises(gpiod.ChipClosedError):
        chip.get_info()
    req.set_value(3, gpiod.line.Value.ACTIVE)


def test_bad_offsets_and_paths(sim):
    _, _, _, gpiod = sim
    with pytest.raises(ValueError, match="out range"):
        gpiod.request_lines(CHIP, config={8: None})
    with pytest.raises(ValueError, match="exactly once"):
        gpiod.request_lines(CHIP, config={(1, 1): None})
    with pytest.raises(FileNotFoundError):
        gpiod.Chip("/dev/gpiochip9")
    req = gpiod.request_lines(CHIP, config={1: None})
    with pytest.raises(ValueError, match="not part of this request"):
        req.get_value(2)
    assert gpiod.is_gpiochip_device(CHIP) and not gpiod.is_gpiochip_device("/dev/null")


# ---- inputs and edge events


def test_wait_advances_virtual_clock_to_the_event(sim):
    clock, _, chip, gpiod = sim
    req = gpiod.request_lines(CHIP, config={2: in_settings(gpiod, edge_detection=gpiod.line.Edge.BOTH)})
    chip.schedule_input(2, 1, at_s=0.75)
    chip.schedule_input(2, 0, at_s=1.25)
    assert req.wait_edge_events(timeout=timedelta(seconds=5))
    assert clock.now() == 0.75
    (ev,) = req.read_edge_events()
    assert isinstance(ev, EdgeEvent)
    assert (ev.event_type, ev.timestamp_ns, ev.line_offset, ev.global_seqno, ev.line_seqno) == (
        EdgeEvent.Type.RISING_EDGE, 750_000_000, 2, 1, 1)
    assert req.wait_edge_events(5.0)
    (ev2,) = req.read_edge_events()
    assert ev2.event_type is EdgeEvent.Type.FALLING_EDGE and ev2.global_seqno == 2
    assert req.get_value(2) is gpiod.line.Value.INACTIVE


def test_wait_times_out_in_virtual_time(sim):
    clock, _, _, gpiod = sim
    req = gpiod.request_lines(CHIP, config={2: in_settings(gpiod, edge_detection=gpiod.line.Edge.BOTH)})
    assert req.wait_edge_events(2.5) is False
    assert clock.now() == 2.5
    with pytest.raises(RuntimeError, match="block forever"):
        req.wait_edge_events(None)
    with pytest.raises(ValueError):
        req.wait_edge_events(-1)


def test_events_keep_their_own_times_across_a_long_sleep(sim):
    clock, _, chip, gpiod = sim
    req = gpiod.request_lines(CHIP, config={2: in_settings(gpiod, edge_detection=gpiod.line.Edge.BOTH)})
    chip.schedule_input(2, 1, at_s=0.1)
    chip.schedule_input(2, 0, at_s=0.3)
    clock.sleep(10.0)
    evs = req.read_edge_events()
    assert [e.timestamp_ns for e in evs] == [100_000_000, 300_000_000]
    assert chip.line_history(2)[-2:] == [(0.1, 1), (0.3, 0)]


def test_edge_filter_and_active_low_edges(sim):
    clock, _, chip, gpiod = sim
    settings = in_settings(gpiod, edge_detection=gpiod.line.Edge.RISING, active_low=True,
                           bias=gpiod.line.Bias.PULL_UP)
    req = gpiod.request_lines(CHIP, config={6: settings})
    assert chip.level(6) == 1 and req.get_value(6) is gpiod.line.Value.INACTIVE
    chip.press(6, at_s=1.0, hold_s=0.5)  # to ground, then floats back to the pull-up
    clock.advance(2.0)
    evs = req.read_edge_events()
    # Going low is logically rising; the release (falling) is filtered out.
    assert [(e.event_type, e.timestamp_ns) for e in evs] == [(EdgeEvent.Type.RISING_EDGE, 1_000_000_000)]


def test_debounce_collapses_chatter_and_drops_glitches(sim):
    clock, _, chip, gpiod = sim
    s = in_settings(gpiod, edge_detection=gpiod.line.Edge.BOTH, debounce_period=timedelta(milliseconds=10),
                    bias=gpiod.line.Bias.PULL_UP, active_low=True)
    req = gpiod.request_lines(CHIP, config={6: s})
    chip.press(6, at_s=1.0, hold_s=0.5, bounces=3, bounce_interval_s=1e-3)
    chip.schedule_input(6, 0, at_s=2.0)  # a 4 ms glitch, shorter than the debounce period
    chip.schedule_input(6, None, at_s=2.004)
    assert req.wait_edge_events(None)
    assert clock.now() == pytest.approx(1.016)  # last bounce at 1.006 + 10 ms
    evs = req.read_edge_events()
    clock.advance(3.0)
    evs += req.read_edge_events() if req.wait_edge_events(0) else []
    assert [e.event_type for e in evs] == [EdgeEvent.Type.RISING_EDGE, EdgeEvent.Type.FALLING_EDGE]
    assert [e.timestamp_ns for e in evs] == [1_016_000_000, 1_516_000_000]
    assert [e.line_seqno for e in evs] == [1, 2]


def test_event_buffer_overflow_drops_oldest(sim):
    clock, _, chip, gpiod = sim
    req = gpiod.request_lines(CHIP, config={2: in_settings(gpiod, edge_detection=gpiod.line.Edge.BOTH)},
                              event_buffer_size=2)
    for k in range(5):
        chip.schedule_input(2, (k + 1) % 2, at_s=0.1 * (k + 1))
    clock.advance(1.0)
    evs = req.read_edge_events(max_events=10)
    assert [e.global_seqno for e in evs] == [4, 5]
    assert req.overflows == 3


def test_unbound_chip_class_explains_itself():
    from firmware_sim.gpiod.chip import Chip

    with pytest.raises(RuntimeError, match="GpioSim"):
        Chip(CHIP)


def test_schedule_input_validation(sim):
    _, _, chip, _ = sim
    with pytest.raises(ValueError, match="level"):
        chip.schedule_input(2, 2, at_s=1.0)
    with pytest.raises(ValueError, match="offset"):
        chip.schedule_input(99, 1, at_s=1.0)
    with pytest.raises(ValueError, match="hold_s"):
        chip.press(2, at_s=1.0, hold_s=0.001, bounces=5)


# ---- released lines and the state mirrored for other processes


@pytest.mark.parametrize("bias, level", [("PULL_DOWN", 0), ("PULL_UP", 1)])
def test_released_biased_output_returns_to_its_bias_level(sim, bias, level):
    clock, _, chip, gpiod = sim
    V = gpiod.line.Value
    req = gpiod.request_lines(CHIP, config={3: out_settings(gpiod, bias=gpiod.line.Bias[bias])})
    req.set_value(3, V.INACTIVE if level else V.ACTIVE)
    clock.advance(1.0)
    req.release()
    assert chip.level(3) == level and not chip.is_requested(3)
    assert chip.line_history(3)[-1] == (1.0, level)


def test_line_state_outlives_its_process_and_a_dead_holder_is_released(tmp_path):
    import os
    import subprocess
    import sys

    from firmware_sim.gpiod.state import read_line

    g = GpioSim(VirtualClock(), state_dir=tmp_path)
    g.add_chip(CHIP, num_lines=8)
    gpiod = g.gpiod
    req = gpiod.request_lines(CHIP, config={2: out_settings(gpiod, bias=gpiod.line.Bias.PULL_DOWN),
                                            5: out_settings(gpiod)}, consumer="me")
    req.set_values({2: gpiod.line.Value.ACTIVE, 5: gpiod.line.Value.ACTIVE})
    st = read_line(tmp_path, CHIP, 2)
    assert st["level"] == 1 and st["requested"] and st["pid"] == os.getpid() and st["consumer"] == "me"
    assert read_line(tmp_path, CHIP, 7) is None
    # Pretend a process that has died holds the lines: the kernel released them.
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    for off in (2, 5):
        p = tmp_path / "gpiochip0" / f"{off}.json"
        p.write_text(p.read_text().replace(f'"pid": {os.getpid()}', f'"pid": {int(dead.stdout)}'))
    st2, st5 = read_line(tmp_path, CHIP, 2), read_line(tmp_path, CHIP, 5)
    assert st2["released_by_death"] and st2["level"] == 0 and not st2["requested"]  # pulled down
    assert st5["released_by_death"] and st5["level"] == 1  # no bias: keeps its last level
    req.release()
    assert read_line(tmp_path, CHIP, 2)["level"] == 0 and not read_line(tmp_path, CHIP, 2)["requested"]
