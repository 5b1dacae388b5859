"""The World protocol both thermal worlds implement, and the one wiring table from chip pins to their signals."""

from __future__ import annotations

import pytest

from edge.hw.chips import CHIPS, SIGNALS
from firmware_sim.chips.registry import EMULATORS
from firmware_sim.clock import VirtualClock
from firmware_sim.drive import ScheduleDrive
from firmware_sim.rz.probe_world import FaithfulWorld
from firmware_sim.scene.files import read_scene
from firmware_sim.scene.model import Fault
from firmware_sim.simulator import load_scene, make_world
from firmware_sim.wiring import WIRING, connect, pin_value
from firmware_sim.world import ThermalWorld
from firmware_sim.world_protocol import World


@pytest.fixture(scope="module", params=["glass_15V", "glass_15V_faithful"])
def world(request):
    sc = read_scene(request.param)
    return make_world(sc, VirtualClock(), ScheduleDrive([sc.touch.heater_on_s, sc.touch.heater_on_s + 1.0],
                                                        [1.0, 0.0]))


def test_both_worlds_implement_the_world_protocol(world):
    assert isinstance(world, World) and isinstance(world, (ThermalWorld, FaithfulWorld))
    for name in ("ads1115_input_V", "ads122c04_input_V"):
        assert not hasattr(world, name)               # no per-chip methods: the wiring table connects pins


def test_the_wiring_table_is_the_registrys_and_names_world_signals():
    assert WIRING == tuple(w for spec in CHIPS.values() for w in WIRING if w.part == spec.name)
    assert {(w.part, w.pin, w.signal) for w in WIRING} == {
        (spec.name, pin, sig) for spec in CHIPS.values() for pin, sig in spec.wiring.items()}
    assert {w.signal for w in WIRING} == set(SIGNALS)
    assert len({w.stream for w in WIRING}) == len(WIRING)  # each chip input is its own caller of the world
    for sig in SIGNALS:
        assert callable(getattr(World, sig))


def test_pins_see_their_signals_reversed_pairs_negated_and_grounded_inputs_zero(world):
    t = world.scene.touch.heater_on_s + 0.5
    emf, flux = world.thermocouple_emf_V(t), world.flux_voltage_V(t)
    assert emf != 0 and flux != 0
    assert pin_value(world, "ads122c04", "AIN0_AIN1", t) == emf
    assert pin_value(world, "ads122c04", "AIN1_AIN0", t) == -emf
    assert pin_value(world, "ads122c04", "AIN3_AIN2", t) == -flux
    assert pin_value(world, "ads1115", "AIN0_AIN1", t) == flux
    assert pin_value(world, "ads1115", "AIN2_AIN3", t) == 0.0 and pin_value(world, "ads1115", "AIN0_GND", t) == 0.0
    assert pin_value(world, "mcp9600", "hot_junction", t) == world.thermocouple_C(t)
    assert pin_value(world, "ads122c04", "temperature", t) == world.cold_junction_C(t)
    with pytest.raises(KeyError, match="no wired input"):
        connect(world, "mcp9600")["AIN0_AIN1"]
    with pytest.raises(ValueError, match="no wiring"):
        connect(world, "max31855")


def test_an_open_thermocouple_reaches_every_pin_wired_to_it(world):
    t = world.scene.touch.heater_on_s + 0.2
    world.add_fault(Fault("open_thermocouple", t, t + 0.1, {}), now_s=0.0)
    assert pin_value(world, "mcp9600", "open_circuit", t + 0.05) is True
    assert pin_value(world, "ads122c04", "AIN0_AIN1", t + 0.05) == 1.65     # the rail
    assert pin_value(world, "mcp9600", "open_circuit", t + 0.15) is False


def test_the_simulator_builds_each_fitted_chip_with_its_registered_emulator():
    with load_scene("alu_20V_ads122c04") as sim:
        fitted = {name for name in CHIPS if sim.scene.board.address_of(name) is not None}
        assert set(sim.chips) == fitted
        for name, chip in sim.chips.items():
            assert type(chip) is EMULATORS[name].cls
            assert sim.bus.devices[sim.scene.board.address_of(name)] is chip
