"""ThermoTouch hardware-in-the-loop simulator.

Emulated I2C chips on an smbus2-compatible bus, gpiod and sysfs-PWM fakes, a
virtual clock and an exact thermal world, driven by TOML scenes. The public
face::

    import firmware_sim
    sim = firmware_sim.load_scene("glass_15V")   # or a path to a .toml scene
    sim.bus, sim.advance(0.5), sim.scene, sim.board(), sim.truth(), sim.inject(...)

Importing this package registers the board kind ``"sim"`` with
:func:`edge.hw.board.register_board_factory`, so
``edge.hw.board.make_board("sim", scene="glass_15V")`` works. Scene schema and
examples: ``firmware_sim/scene/shipped/README.md``.

Layout (each name is imported from its module; this face re-exports only the
names above)::

    clock.py       VirtualClock, WallClock, BusClock
    bus.py         SimBus: smbus2-compatible I2C adapter with fault injection
    chips/         register-level chip emulators, one module per chip; chips/registry.py EMULATORS,
                   registered against the chip registry's entries (edge.hw.chips.CHIPS)
    gpiod/         python-gpiod 2.x fake: device-side API modules + simulated lines, chips, kernel
    pwm.py         SimPwmTree: sysfs PWM tree fake
    board.py       make_sim_board: an edge Board on the GPIO/PWM fakes
    scene/         scene model, schema (edge.schema Fields), parser, files; shipped/ scenes
    world_protocol.py  World: the protocol every thermal world implements (signals, truth, touches, faults)
    wiring.py      WIRING: the one table from chip pins (and the heater's lines) to world signals
    drive.py       HeaterDrive: the heater duty a world reads (BoardDrive, ScheduleDrive, ManualDrive)
    world.py       ThermalWorld: exact 1-D thermal model behind the chips ([board] world = "ideal")
    rz/            axisymmetric finite-volume probe model; rz/probe_world.py FaithfulWorld ("faithful"),
                   rz/configs.py its as-built probe and grid configurations, rz/heater.py its heater film
    simulator.py   Simulator, load_scene: one object per scene
    ptylink.py     NullModem: virtual serial cable
    run.py         ``thermotouch sim``: the daemon on a scene behind a NullModem
    rigs/          test rigs (daemon_rig)
"""

from firmware_sim.scene.files import read_scene, scene_names
from firmware_sim.scene.model import Fault, Scene, SceneError
from firmware_sim.scene.parser import parse_scene
from firmware_sim.simulator import Simulator, load_scene, make_scene_board, register_scene_board
from firmware_sim.world import ThermalWorld, Truth

__all__ = [
    "Fault",
    "Scene",
    "SceneError",
    "Simulator",
    "ThermalWorld",
    "Truth",
    "load_scene",
    "make_scene_board",
    "parse_scene",
    "read_scene",
    "register_scene_board",
    "scene_names",
]

register_scene_board("sim")
