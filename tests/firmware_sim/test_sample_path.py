"""What one sample of a simulated touch costs: bus transactions, conversions, world evaluations, PWM file reads.

A sample's bus traffic is the drivers' behaviour on a real board (every transaction is bus time on the
Pi), so its count is pinned here: a driver change that adds a read shows up. In the simulator each
conversion evaluates the thermal world once, at its own sampling instant -- not once per register
read or DRDY poll -- and a clock step with no raw write in the simulated sysfs PWM tree reads none of
its files (:class:`firmware_sim.pwm.SimPwmTree`).
"""

from __future__ import annotations

import collections

import pytest

import firmware_sim.pwm as pwm_mod
import firmware_sim.wiring as wiring
from edge.measure.sensors import make_sensors
from firmware_sim.run import config_for_scene
from firmware_sim.scene.files import read_scene
from firmware_sim.simulator import Simulator

N_SAMPLES = 40
PERIOD_S = 0.1      # within both boards' rates

#: board -> (scene, configuration, bus transactions a sample, conversions a sample by chip)
BOARDS = {
    # thermocouple: TS=1, START, DRDY, RDATA, TS=0; its EMF: input, START, DRDY, RDATA; flux: the same
    "ads122c04": ("alu_20V_ads122c04", None, 13, {"ads122c04": 3}),
    # MCP9600 (split reads: pointer, then data): STATUS, clear TH_UPDATE, TH = 5;
    # ADS1115: CONFIG with OS, CONFIG poll (pointer + data), CONVERSION = 3
    "mcp9600+ads1115": ("alu_20V", {"sensors": {"thermocouple": "mcp9600", "flux_adc": "ads1115"}}, 8,
                        {"ads1115": 1}),
}


@pytest.fixture
def counted_world(monkeypatch):
    """Counts of every chip input's evaluations of the world, by signal."""
    calls: collections.Counter = collections.Counter()
    real = wiring._reader

    def reader(world, wire):
        fn = real(world, wire)

        def counted(t_s):
            calls[wire.signal] += 1
            return fn(t_s)
        return counted
    monkeypatch.setattr(wiring, "_reader", reader)
    return calls


@pytest.mark.parametrize("board_name", sorted(BOARDS))
def test_a_sample_costs_its_transactions_and_one_world_evaluation_per_conversion(board_name, counted_world,
                                                                                  tmp_path, monkeypatch):
    scene_name, overrides, per_sample, conversions = BOARDS[board_name]
    scene = read_scene(scene_name)
    with Simulator(scene) as sim:
        board = sim.board()
        sensors = make_sensors(board, config_for_scene(scene, str(tmp_path), overrides).sensors)
        clock = board.clock
        sensors.read()                      # warm: first conversions, the PWM tree read once
        clock.sleep(PERIOD_S)
        reads = collections.Counter()
        real_read = pwm_mod._read

        def read(p):
            reads["pwm"] += 1
            return real_read(p)
        monkeypatch.setattr(pwm_mod, "_read", read)
        ok0, conv0 = sim.bus.stats["ok"], {c: sim.chips[c].conversions for c in conversions}
        counted_world.clear()
        for _ in range(N_SAMPLES):
            sensors.read()
            clock.sleep(PERIOD_S)
        assert sim.bus.stats["ok"] - ok0 == per_sample * N_SAMPLES
        assert sum(sim.bus.stats[k] for k in ("nack", "stuck", "flaky")) == 0
        for chip, n in conversions.items():
            assert sim.chips[chip].conversions - conv0[chip] == n * N_SAMPLES
        if board_name == "ads122c04":
            # Its three conversions: the die temperature, the thermocouple EMF, the flux voltage.
            assert counted_world == {"cold_junction_C": N_SAMPLES, "thermocouple_emf_V": N_SAMPLES,
                                     "flux_voltage_V": N_SAMPLES}
        else:
            # The ADS1115's single shot reads the flux once; the MCP9600 converts on its own clock.
            assert counted_world["flux_voltage_V"] == N_SAMPLES
        if pwm_mod._dir_watch() is not None:
            assert reads["pwm"] == 0        # nothing wrote to the PWM tree: no file was read
