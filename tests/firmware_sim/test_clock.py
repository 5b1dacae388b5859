"""The simulator's clock modes: VirtualClock, WallClock, BusClock (firmware_sim.clock)."""

import errno
import threading
import time

import pytest

import firmware_sim
from firmware_sim.bus import SimBus
from firmware_sim.clock import (CLOCK_MODES, BusClock, SimClock, VirtualClock, WallClock,
                                check_clock_mode, i2c_transaction_time_s, make_clock)


class FakeWall:
    """A hand-moved wall clock for deterministic WallClock tests."""

    def __init__(self, t=100.0):
        self.t = t
        self.slept = []

    def __call__(self):
        return self.t

    def sleep(self, dt):
        self.slept.append(dt)
        self.t += dt


def _clocks():
    wall = FakeWall()
    return {
        "virtual": VirtualClock(),
        "wall": WallClock(wall=wall, sleeper=wall.sleep),
        "bus": BusClock(),
    }


class Ram:
    def __init__(self):
        self.ptr = 0

    def i2c_write(self, data):
        if data:
            self.ptr = data[0]

    def i2c_read(self, n):
        return bytes(n)


# ---- the shared contract -------------------------------------------------------------

@pytest.mark.parametrize("mode", CLOCK_MODES)
def test_satisfies_the_protocol(mode):
    clock = _clocks()[mode]
    assert isinstance(clock, SimClock)
    assert isinstance(make_clock(mode), SimClock)
    assert type(make_clock(mode)).__name__ == {"virtual": "VirtualClock", "wall": "WallClock",
                                               "bus": "BusClock"}[mode]


@pytest.mark.parametrize("mode", CLOCK_MODES)
def test_contract_monotonic_and_listeners_in_order(mode):
    clock = _clocks()[mode]
    calls = []
    clock.on_advance(lambda a, b: calls.append((a, b)))
    seen = [clock.now()]
    assert seen[0] == 0.0
    assert clock.advance(0.25) == pytest.approx(0.25)
    seen.append(clock.now())
    clock.sleep(0.5)
    seen.append(clock.now())
    assert clock.advance_to(0.1) == pytest.approx(0.75)      # the past: no-op
    assert clock.advance_to(2.0) == pytest.approx(2.0)
    seen.append(clock.monotonic())
    clock.sleep(-1.0)                                          # negative sleep: no time, no error
    seen.append(clock.now())
    assert seen == sorted(seen)
    assert seen[-1] == pytest.approx(2.0)
    assert clock.monotonic_ns() == round(clock.now() * 1e9)
    with pytest.raises(ValueError):
        clock.advance(-0.1)
    assert calls, "listeners were never called"
    # Contiguous, strictly increasing steps from the start to now.
    assert calls[0][0] == 0.0
    for (a0, b0), (a1, b1) in zip(calls, calls[1:]):
        assert b0 == a1
    assert all(b >= a for a, b in calls)
    if mode != "virtual":                  # VirtualClock also reports zero-length steps
        assert all(b > a for a, b in calls)
    assert calls[-1][1] == pytest.approx(clock.now())


@pytest.mark.parametrize("mode", CLOCK_MODES)
def test_start_time_validated(mode):
    cls = type(_clocks()[mode])
    with pytest.raises(ValueError, match="start_s"):
        cls(-1.0)
    wall = FakeWall()
    clock = WallClock(3.0, wall=wall, sleeper=wall.sleep) if mode == "wall" else cls(3.0)
    assert clock.now() == 3.0


# ---- mode names --------------------------------------------------------------------------

@pytest.mark.parametrize("bad", ["Wall", "real", "", None, 1])
def test_bad_mode_one_clear_error(bad):
    with pytest.raises(ValueError) as ei:
        check_clock_mode(bad)
    msg = str(ei.value)
    assert repr(bad) in msg
    for m in CLOCK_MODES:
        assert repr(m) in msg
    with pytest.raises(ValueError, match="'virtual', 'wall', 'bus'"):
        make_clock(bad)


def test_load_scene_validates_clock_before_reading():
    with pytest.raises(ValueError, match=r"clock must be one of 'virtual', 'wall', 'bus'; got 'sundial'"):
        firmware_sim.load_scene("no-such-scene", clock="sundial")
    scene = firmware_sim.read_scene("glass_15V")
    with pytest.raises(ValueError, match="got 'sundial'"):
        firmware_sim.Simulator(scene, clock="sundial")


@pytest.mark.parametrize("mode, cls", [("virtual", VirtualClock), ("wall", WallClock), ("bus", BusClock)])
def test_simulator_clock_modes(mode, cls):
    with firmware_sim.load_scene("glass_15V", clock=mode) as sim:
        assert type(sim.clock) is cls
        assert sim.clock_mode == mode
        assert sim.board().clock is sim.clock
        assert sim.bus.clock is sim.clock
    with firmware_sim.load_scene("glass_15V") as sim:
        assert type(sim.clock) is VirtualClock


def test_simulator_bus_mode_takes_the_bit_rate():
    with firmware_sim.load_scene("glass_15V", clock="bus", bit_rate_Hz=400e3) as sim:
        assert sim.clock.bit_rate_Hz == 400e3
        assert sim.bus.bit_rate_Hz is None          # counted once, by the clock
        t0 = sim.now()
        sim.bus.read_i2c_block_data(0x60, 0x20, 2)   # MCP9600 device id
        assert sim.now() - t0 == pytest.approx(i2c_transaction_time_s(5, 2, 400e3))


# ---- WallClock ---------------------------------------------------------------------------

def test_wall_clock_follows_a_fake_wall():
    wall = FakeWall(50.0)
    clock = WallClock(2.0, rate=0.5, wall=wall, sleeper=wall.sleep)
    calls = []
    clock.on_advance(lambda a, b: calls.append((a, b)))
    assert clock.now() == 2.0
    assert calls == []                      # no time passed
    wall.t += 4.0
    assert clock.now() == pytest.approx(4.0)            # 2 + 0.5 * 4
    assert calls == [(2.0, pytest.approx(4.0))]
    clock.sleep(1.0)                                    # one simulated second = two wall seconds
    assert wall.slept == [pytest.approx(2.0)]
    assert clock.now() == pytest.approx(5.0)
    assert clock.advance(10.0) == pytest.approx(15.0)   # a jump ...
    wall.t += 2.0
    assert clock.now() == pytest.approx(16.0)           # ... then it follows the wall again
    assert [b for _, b in calls] == sorted(b for _, b in calls)


def test_wall_clock_tracks_real_wall_time():
    w_before = time.monotonic()
    clock = WallClock()
    w_after = time.monotonic()
    for _ in range(5):
        time.sleep(0.01)
        a = time.monotonic()
        t = clock.now()
        b = time.monotonic()
        # Bracketed by the wall readings around both calls: exact, no timing tolerance.
        assert a - w_after - 1e-9 <= t <= b - w_before + 1e-9


def test_wall_clock_sleep_really_sleeps():
    clock = WallClock()
    t0, w0 = clock.now(), time.monotonic()
    clock.sleep(0.03)
    assert time.monotonic() - w0 >= 0.03
    assert clock.now() - t0 >= 0.03 - 1e-9


def test_wall_clock_listener_reentry_sees_its_time():
    wall = FakeWall()
    clock = WallClock(wall=wall, sleeper=wall.sleep)
    inside = []

    def listener(a, b):
        wall.t += 1.0                   # the wall moves while the listener runs ...
        inside.append((b, clock.now(), clock.advance(0.0)))

    clock.on_advance(listener)
    wall.t += 1.0
    assert clock.now() == pytest.approx(1.0)
    # ... yet inside it now() is the time being dispatched, and no nested dispatch happens.
    assert inside == [(pytest.approx(1.0),) * 3]


def test_wall_clock_threads_see_monotonic_time_and_ordered_listeners():
    clock = WallClock()
    calls = []
    lock = threading.Lock()

    def listener(a, b):
        with lock:
            calls.append((a, b))

    clock.on_advance(listener)
    per_thread = {}
    stop = time.monotonic() + 0.2

    def worker(i):
        seen = []
        # A minimum count as well as a deadline: on a loaded machine a thread may first run after
        # the deadline, and a thread that saw nothing (or a thread 0 that never advanced) proves nothing.
        while time.monotonic() < stop or len(seen) < 200:
            seen.append(clock.now())
            if i == 0:
                clock.advance(1e-4)
        per_thread[i] = seen

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(10)
    final = clock.now()
    for seen in per_thread.values():
        assert seen and seen == sorted(seen)
    assert calls[0][0] == 0.0
    assert all(b > a for a, b in calls)
    assert all(b0 == a1 for (_, b0), (a1, _) in zip(calls, calls[1:]))
    assert calls[-1][1] == final


def test_wall_clock_no_deadlock_with_a_listener_that_takes_a_lock():
    """A thread holding lock L calls now() while another thread's listener waits for L."""
    wall = FakeWall()
    clock = WallClock(wall=wall, sleeper=wall.sleep)
    L = threading.Lock()
    in_listener = threading.Event()
    got = []
    calls = []

    def listener(a, b):
        calls.append((a, b))
        if not in_listener.is_set():
            in_listener.set()
            got.append(L.acquire(timeout=10))
            L.release()

    clock.on_advance(listener)
    L.acquire()
    wall.t += 1.0
    th = threading.Thread(target=clock.now)
    th.start()
    assert in_listener.wait(10)
    wall.t += 1.0
    assert clock.now() == pytest.approx(2.0)      # returns at once, though L is held and a dispatch runs
    L.release()
    th.join(10)
    assert not th.is_alive() and got == [True]
    # The dispatching thread covered the time handed out meanwhile, in order.
    assert calls == [(0.0, pytest.approx(1.0)), (pytest.approx(1.0), pytest.approx(2.0))]


def test_wall_clock_rate_validated():
    with pytest.raises(ValueError, match="rate"):
        WallClock(rate=0.0)


# ---- BusClock ----------------------------------------------------------------------------

def test_bus_clock_advances_per_transaction():
    clock = BusClock(bit_rate_Hz=100e3)
    bus = SimBus(clock=clock)
    bus.attach(0x50, Ram())
    bus.read_byte_data(0x50, 0x00)                  # addr+W, reg, addr+R, data; 2 segments
    assert clock.now() == pytest.approx((9 * 4 + 2 * 2) / 100e3)
    assert clock.now() == pytest.approx(0.4e-3)
    t = clock.now()
    bus.write_i2c_block_data(0x50, 0x10, [1, 2, 3])  # addr+W, reg, 3 data; 1 segment
    assert clock.now() - t == pytest.approx((9 * 5 + 2) / 100e3)
    t = clock.now()
    with pytest.raises(OSError) as ei:
        bus.read_byte(0x51)                         # nobody there: the address byte, then NACK
    assert ei.value.errno == errno.EREMOTEIO
    assert clock.now() - t == pytest.approx(11 / 100e3)
    assert clock.transactions == 3
    t = clock.now()
    clock.sleep(0.01)
    assert clock.now() - t == pytest.approx(0.01)


def test_bus_clock_quantum_is_documented_formula():
    clock = BusClock(bit_rate_Hz=400e3, per_transaction_s=1e-4)
    assert clock.transaction_time_s(4, 2) == pytest.approx(40 / 400e3 + 1e-4)
    assert i2c_transaction_time_s(4, 2, 100e3) == pytest.approx(0.4e-3)
    with pytest.raises(ValueError):
        BusClock(bit_rate_Hz=0)
    with pytest.raises(ValueError):
        BusClock(per_transaction_s=-1)


def test_bus_clock_and_bit_rate_not_both():
    with pytest.raises(ValueError, match="bus clock"):
        SimBus(clock=BusClock(), bit_rate_Hz=100e3)


def test_bit_rate_on_wall_clock_sleeps_the_wire_time():
    wall = FakeWall()
    clock = WallClock(wall=wall, sleeper=wall.sleep)
    bus = SimBus(clock=clock, bit_rate_Hz=100e3)
    bus.attach(0x50, Ram())
    bus.read_byte_data(0x50, 0x00)
    assert wall.slept == [pytest.approx(0.4e-3)]
    assert clock.now() == pytest.approx(0.4e-3)
