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
examples: ``firmware_sim/scenes/README.md``.
"""

from firmware_sim.scene import Fault, Scene, SceneError, parse_scene, read_scene, scene_names
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
