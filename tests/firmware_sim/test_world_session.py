"""The thermal world in batches and over long sessions: same numbers, flat cost."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import firmware_sim
from firmware_sim import world as world_mod
from firmware_sim.chips.ads1115 import ADS1115Emulator
from firmware_sim.chips.mcp9600 import MCP9600Emulator
from firmware_sim.clock import VirtualClock
from firmware_sim.scene.model import Fault
from firmware_sim.scene.files import read_scene
from firmware_sim.wiring import connect
from firmware_sim.world import BoardDrive, ManualDrive, ThermalWorld


def _chips(world, clock):
    mcp = MCP9600Emulator(clock, world.thermocouple_C, world.cold_junction_C, open_circuit=world.thermocouple_open)
    ads = ADS1115Emulator(clock, connect(world, "ads1115").mux)
    ads.i2c_write(bytes([0x01, 0x0A, 0xE3]))   # AIN0-AIN1, +-0.256 V, continuous, 860 SPS
    ads.i2c_write(bytes([0x00]))
    return mcp, ads


def _record(world):
    """Wrap the world's query so every value a chip gets is recorded."""
    rec = []
    query = world._query

    def q(t, stream):
        st = query(t, stream)
        rec.append(st)
        return st

    world._query = q
    return rec


def _replica(w, drive, now):
    """A fresh world with the same scene, drive, touches and faults, its clock at ``now``."""
    clock = VirtualClock()
    ref = ThermalWorld(w.scene, clock, drive)
    for a, b in w.touches[1:]:
        ref.add_touch(a, b - a)
    for f in w.faults[len(ref.faults):]:
        ref.add_fault(f)
    clock.advance_to(now)
    ref._sync_drive()
    return ref


def _session(world, clock, drive, mcp, ads, n_touch, *, no_contact=False):
    t0 = world.scene.touch.start_s
    for i in range(n_touch):
        if i:
            world.add_touch(t0, 2.5)
        if no_contact and i == 1:
            world.add_fault(Fault("no_contact", t0 + 1.0, t0 + 1.3, {}))
        clock.advance_to(t0)
        drive.set(t0, 1.0 if i % 2 == 0 else 0.6)
        for k in range(200):
            clock.advance(0.01)
            if k == 120:
                drive.set(clock.now(), 0.3)          # a switching mid-touch, on no grid
            mcp.i2c_write(bytes([0x00]))
            mcp.i2c_read(2)
            ads.i2c_read(2)
        drive.set(clock.now(), 0.0)
        clock.advance_to(t0 + 3.0)
        drive.set(clock.now(), 0.5)                  # heating in air after the touch
        for _ in range(40):
            clock.advance(0.01)
            ads.i2c_read(2)
        drive.set(clock.now(), 0.0)
        t0 = clock.now() + 1.0


@pytest.mark.slow  # sessions of touches, evaluated batched and one value at a time
@pytest.mark.parametrize("name, tau, no_contact", [("glass_15V", 0.0, False), ("pmma_20V", 0.05, True),
                                                   ("alu_25V", 0.0, False)])
def test_batched_evaluation_equals_one_inversion_per_value(name, tau, no_contact):
    sc = read_scene(name)
    sc = dataclasses.replace(sc, sensors=dataclasses.replace(sc.sensors, thermocouple_time_constant_s=tau))
    clock, drive = VirtualClock(), ManualDrive()
    w = ThermalWorld(sc, clock, drive)
    rec = _record(w)
    _session(w, clock, drive, *_chips(w, clock), 3, no_contact=no_contact)
    st = w.stats
    assert st["queries"] == len(rec) > 5000
    assert st["lookahead_hits"] > 0.95 * st["queries"]    # values came from batches ...
    assert st["talbot_calls"] < st["queries"] / 30        # ... one inversion for many values
    # The reference: a fresh world (same scene, drive, touches and faults), one inversion per value.
    ref = _replica(w, drive, clock.now())
    # Every 14th value (470 of 6570, 5 or more in each of the session's 7-9 phases, asserted): one inversion each is
    # what costs here. That is ~6 checked values per 0.1 s of session (a batch's look-ahead) across the chips'
    # streams, where every 7th checked ~13 for twice the CPU: a batch left stale by a drive change, a fault or
    # a touch is wrong for the rest of its 0.1 s, on every stream that read through it.
    phases = {ref._phase_of(s.t_s) for s in rec}
    rec = rec[::14]
    assert {ref._phase_of(s.t_s) for s in rec} == phases
    got = np.array([(s.surface_C, s.thermocouple_C, s.q_f_W_m2) for s in rec])
    exp = np.array([[float(v[0]) for v in (ev.surface_C, ev.thermocouple_C, ev.q_f)]
                    for ev in (ref._eval(ref._phase_of(s.t_s), np.array([s.t_s])) for s in rec)])
    assert [s.contact for s in rec] == [bool(ref._ph_contact[ref._phase_of(s.t_s)]) for s in rec]
    # 1e-9 relative; q_f can be ~1e-20 W/m^2 (Talbot noise around zero) in air: 1e-9 of the record's scale.
    scale = np.max(np.abs(exp), axis=0)
    np.testing.assert_allclose(got, exp, rtol=1e-9, atol=0.0 + 1e-9 * scale.min())
    np.testing.assert_allclose(got[:, 2], exp[:, 2], rtol=1e-9, atol=1e-9 * scale[2])


def test_lookahead_is_dropped_when_the_drive_changes():
    sc = read_scene("glass_15V")
    clock, drive = VirtualClock(), ManualDrive()
    w = ThermalWorld(sc, clock, drive)
    grid = 1.0 + 5e-3 * np.arange(1, 41)
    clock.advance_to(1.0)
    for t in grid[:3]:
        w.thermocouple_C(t)                          # regular: the next 0.1 s are evaluated ahead, heater off
    assert w._streams["thermocouple"].n > 15
    drive.set(1.0155, 1.0)                           # the heater comes on between grid points
    clock.advance_to(1.25)
    got = [w.thermocouple_C(t) for t in grid[3:]]
    fresh = ThermalWorld(sc, clock, drive)
    np.testing.assert_allclose(got, [fresh.state(t).thermocouple_C for t in grid[3:]], rtol=1e-12)
    assert got[-1] > 25.001                          # heating shows (it would not from stale values)
    for t in 1.25 + 5e-3 * np.arange(1, 4):
        w.thermocouple_C(t)
    s = w._streams["thermocouple"]
    assert s.t[s.n - 1] > 1.3
    w.add_fault(Fault("no_contact", 1.3, None, {}))   # touches and faults drop look-ahead from their time on
    assert 0 < s.n and s.t[s.n - 1] < 1.3


@pytest.mark.slow  # a long session of touches
def test_a_long_session_costs_the_same_per_touch_and_retains_bounded_state():
    sc = read_scene("pmma_15V")
    clock, drive = VirtualClock(), ManualDrive()
    w = ThermalWorld(sc, clock, drive)

    def no_full_scan(*a, **k):
        raise AssertionError("the hot path must not rebuild the phase list")

    w.phases = no_full_scan
    # 75 touches (7.5 simulated minutes): the last ten, 60 touches after the early ten, would show any work that
    # grows with the session's length in the exact operation counts compared below (150 cost twice the CPU).
    n, per_touch, first = 75, [], {}
    t0 = sc.touch.start_s
    for i in range(n):
        before = dict(w.stats)
        if i:
            w.add_touch(t0, 2.5)
        clock.advance_to(t0)
        drive.set(t0, 1.0)
        for k in range(1, 41):                        # a flux channel every 10 ms, a thermocouple every 0.32 s
            clock.advance_to(t0 + 0.01 * k)
            w.flux_voltage_V(t0 + 0.01 * k - 0.005)
            if k % 32 == 0:
                w.thermocouple_C(t0 + 0.01 * k - 0.16)
        drive.set(clock.now(), 0.0)
        clock.advance_to(t0 + 2.5)
        w.state(t0 + 2.4)
        if i == 2:
            first = {t: w.state(t) for t in (t0 + 0.1, t0 + 0.3)}
        per_touch.append({k: w.stats[k] - before[k] for k in ("talbot_calls", "talbot_rows", "times", "phase_ends")})
        t0 += 6.0
    del w.phases
    # Work per touch: the same for the last touches as for the first (operation counts, not wall time).
    for key in ("talbot_calls", "talbot_rows", "times", "phase_ends"):
        early = [p[key] for p in per_touch[5:15]]
        late = [p[key] for p in per_touch[-10:]]
        assert max(late) <= max(early), (key, early, late)
    assert w.stats["max_terms"] <= 3               # initial condition + heater on + heater off
    # Bounded retained state: look-ahead per caller, cached states; the phase record is 4 doubles a phase.
    assert all(s.n <= world_mod._LOOKAHEAD_MAX for s in w._streams.values())
    assert len(w._cache) <= world_mod._CACHE_MAX
    assert len(w.phases()) == 2 * n + 1
    assert w._ph_start.itemsize * 4 * len(w._ph_start) < 40 * (2 * n + 1)
    # The past is still there, exactly.
    fresh = _replica(w, drive, clock.now())
    for t, st in first.items():
        assert fresh.state(t) == st


def test_board_drive_mirrors_the_board():
    sim = firmware_sim.load_scene("glass_15V")
    try:
        from edge.hw.drivers.heater import Heater

        board = sim.board()
        sc = sim.scene
        heater = Heater(board, supply_voltage_V=sc.heater.supply_voltage_V, resistance_ohm=sc.heater.resistance_ohm)
        drive = sim.world.drive
        assert isinstance(drive, BoardDrive)
        rev, times = drive.changes_since(None)
        for duty in (1.0, 0.4, 0.0, 0.7):
            sim.advance(0.25)
            heater.on(duty) if duty else heater.off()
            rev2, new = drive.changes_since(rev)
            assert new and rev2 != rev
            assert drive.changes_since(rev2) == (rev2, [])
            rev, times = rev2, times + new
        sim.advance(0.25)
        heater.close()
        p = sim.parts
        public = [t for t, _ in p.chip.line_history(p.heater_enable_offset)]
        public += [h.t_s for h in p.pwm_tree.history(p.pwm_chip, p.pwm_channel)]
        assert sorted(drive.change_times()) == sorted(public)
        for t in np.linspace(0.0, sim.now(), 97).tolist() + sorted(set(public)):
            assert drive.duty_at(t) == float(p.heater_duty_at(t))
    finally:
        sim.close()


def test_manual_drive():
    d = ManualDrive()
    d.set(1.0, 0.5)
    d.set(1.0, 0.7)
    d.set(2.0, 0.0)
    assert (d.duty_at(0.5), d.duty_at(1.0), d.duty_at(1.5), d.duty_at(2.0)) == (0.0, 0.7, 0.7, 0.0)
    assert d.changes_since(None) == (3, [1.0, 1.0, 2.0]) and d.changes_since(3) == (3, [])
    with pytest.raises(ValueError, match="before"):
        d.set(1.5, 0.1)
    with pytest.raises(ValueError, match="duty"):
        d.set(3.0, 1.5)
