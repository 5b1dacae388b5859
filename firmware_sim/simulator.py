"""The simulator's public face: one object per scene.

``load_scene("glass_15V")`` (a shipped scene name or a path) returns a
:class:`Simulator` that holds a virtual clock, the GPIO and PWM fakes, the
thermal world and an smbus2-compatible :class:`~firmware_sim.bus.SimBus` with
the scene's chips attached and wired to the world::

    sim = firmware_sim.load_scene("glass_15V")
    board = sim.board()                 # an edge.hw.board.Board for the daemon
    sim.advance(0.5)                    # move virtual time
    sim.bus.read_i2c_block_data(0x60, 0x00, 2)
    sim.truth([1.0, 1.5])               # exact surface temperature and flux

Importing :mod:`firmware_sim` registers the board kind ``"sim"``, so
``edge.hw.board.make_board("sim", scene="glass_15V")`` builds a board on a new
simulator (reachable as ``board.extras["simulator"]``).
"""

from __future__ import annotations

import os
import weakref
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from edge.hw.board import Board, register_board_factory

from firmware_sim.board import SimBoardParts, make_sim_board
from firmware_sim.bus import SimBus
from firmware_sim.chips.registry import EMULATORS, emulate
from firmware_sim.clock import SimClock, check_clock_mode, make_clock
from firmware_sim.gpiod.kernel import GpioSim
from firmware_sim.pwm import SimPwmTree
from firmware_sim.scene.files import read_scene
from firmware_sim.scene.model import Fault, Scene
from firmware_sim.scene.parser import MaterialLookup, validate_fault
from firmware_sim.rz.probe_world import FaithfulWorld
from firmware_sim.wiring import connect, heater_drive
from firmware_sim.world import ThermalWorld
from firmware_sim.world_protocol import Truth, World

__all__ = ["Simulator", "load_scene", "make_scene_board", "make_world", "register_scene_board", "SCENE_ENV"]

_BUS_FAULTS = ("i2c_nack", "bus_stuck")
#: Faults one chip emulator plays (firmware_sim.chips.freeze).
_CHIP_FAULTS = ("converter_frozen",)


def make_world(scene: Scene, clock, drive) -> World:
    """The thermal world ``[board] world`` names: the exact 1-D ``ThermalWorld`` ("ideal") or the
    axisymmetric ``FaithfulWorld`` ("faithful", with the scene's probe geometry and ``[as_built]``)."""
    if scene.board.world == "faithful":
        return FaithfulWorld.for_scene(scene, clock, drive)
    return ThermalWorld(scene, clock, drive)


class Simulator:
    """Virtual hardware for one scene (see the module docstring).

    Parameters
    ----------
    scene : Scene
        A parsed scene (:func:`firmware_sim.scene.files.read_scene`).
    bit_rate_Hz : float, optional
        If given, I2C transfers take their wire time on the clock. With
        ``clock="bus"`` it is the bus clock's bit rate (default 100 kHz).
    clock : {"virtual", "wall", "bus"}
        Time base (:mod:`firmware_sim.clock`). ``"virtual"`` (default): time
        moves only when the device code sleeps through the board clock or a
        test advances it -- fast and reproducible. ``"wall"``: simulated time
        follows wall time (:class:`~firmware_sim.clock.WallClock`), for
        unmodified third-party drivers that poll with ``time.sleep`` and time
        out on ``time.time``; :meth:`advance` then jumps ahead. ``"bus"``: each
        I2C transaction advances time by its wire time
        (:class:`~firmware_sim.clock.BusClock`), plus sleeps.

    Attributes
    ----------
    scene : Scene
    clock : SimClock
        VirtualClock, WallClock or BusClock per ``clock``.
    clock_mode : str
    gpio : GpioSim
        Simulated gpiod (``sim.gpio.gpiod`` is the module-like object).
    pwm : SimPwmTree
        Simulated sysfs PWM tree.
    bus : SimBus
        smbus2-compatible bus with the fitted chips.
    world : World
        Per ``[board] world`` (:func:`make_world`): a ThermalWorld or a FaithfulWorld, wired to the
        chips by :mod:`firmware_sim.wiring`.
    chips : dict
        Chip emulators by registry name (:data:`edge.hw.chips.CHIPS`), fitted ones only.
    parts : SimBoardParts
        GPIO chip, PWM channel and line offsets of the board.
    """

    def __init__(self, scene: Scene, *, bit_rate_Hz: float | None = None, clock: str = "virtual") -> None:
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
        self.scene = scene
        self.clock: SimClock = make_clock(clock, bit_rate_Hz=bit_rate_Hz)
        self.clock_mode = clock
        if clock == "bus":
            bit_rate_Hz = None          # the bus clock counts wire time itself
        self.gpio = GpioSim(self.clock)
        self.pwm = SimPwmTree(self.clock)
        seeds = np.random.SeedSequence(scene.seed).spawn(1 + len(EMULATORS))
        self.bus = SimBus(1, clock=self.clock, rng=np.random.default_rng(seeds[0]), bit_rate_Hz=bit_rate_Hz)
        self._board = make_sim_board(clock=self.clock, i2c=self.bus, gpio=self.gpio, pwm_tree=self.pwm)
        self._board.extras["simulator"] = self
        self.parts: SimBoardParts = self._board.extras["sim"]
        self.world = make_world(scene, self.clock, heater_drive(self.parts))
        self.chips: dict[str, Any] = {}
        self._injected: list[Fault] = []
        # The PWM tree lives in a temporary directory: remove it even if close() is never called.
        weakref.finalize(self, self.pwm.close)
        # Each fitted chip: its emulator (registered against the chip registry) on its wired inputs,
        # with the scene's noise and its own random stream (one per registry chip, after the bus's).
        for (name, emu), seed in zip(EMULATORS.items(), seeds[1:]):
            address = scene.board.address_of(name)
            if address is None:
                continue
            chip = emulate(name, self.clock, connect(self.world, name),
                           noise_rms_V=getattr(scene.sensors, emu.noise_setting), rng=np.random.default_rng(seed))
            self.chips[name] = chip
            self.bus.attach(address, chip)
        for f in scene.faults:
            if f.kind in _BUS_FAULTS:
                self._apply_bus_fault(f)
            elif f.kind in _CHIP_FAULTS:
                self.chips[f.params["chip"]].freeze(f.at_s, f.until_s)
        if scene.touch.press_trigger:
            hold = min(scene.touch.trigger_hold_s, scene.touch.length_s)
            self.parts.chip.press(self.parts.trigger_offset, scene.touch.start_s, hold)

    # ---- time

    def now(self) -> float:
        """Current simulated time (s)."""
        return self.clock.now()

    def advance(self, seconds: float) -> float:
        """Move simulated time forward by ``seconds`` (a jump on a wall clock); return the new time."""
        return self.clock.advance(seconds)

    def advance_to(self, t_s: float) -> float:
        """Move virtual time forward to ``t_s`` (no-op if already past it)."""
        return self.clock.advance_to(t_s)

    # ---- the board

    def board(self) -> Board:
        """The edge Board on this simulator (same object until it is closed, then a new one)."""
        if self._board.closed:
            if self.bus.closed:
                self.bus.open(1)
            self._board = make_sim_board(clock=self.clock, i2c=self.bus, gpio=self.gpio, pwm_tree=self.pwm)
            self._board.extras["simulator"] = self
        return self._board

    # ---- faults

    def inject(self, kind: str, *, at_s: float | None = None, until_s: float | None = None,
               **params: Any) -> Fault:
        """Inject a fault from code (same kinds and params as a scene's ``[[faults]]``).

        ``at_s`` defaults to now and may not lie in the past; ``until_s``
        None means for ever. Returns the validated :class:`Fault`.
        """
        now = self.clock.now()      # read once: on a wall clock every read is later
        at = now if at_s is None else float(at_s)
        if at < now - 1e-12:
            raise ValueError(f"at_s={at} s is in the past (now {now} s)")
        fault = validate_fault(kind, at, until_s, params)
        if "chip" in fault.params \
                and self.scene.board.address_of(fault.params["chip"]) is None:
            raise ValueError(f"params.chip: {fault.params['chip']} is not fitted on this board")
        if fault.kind in _BUS_FAULTS:
            self._apply_bus_fault(fault)
        elif fault.kind in _CHIP_FAULTS:
            self.chips[fault.params["chip"]].freeze(fault.at_s, fault.until_s)
        else:
            self.world.add_fault(fault, now_s=now)
        self._injected.append(fault)
        return fault

    @property
    def faults(self) -> tuple[Fault, ...]:
        """Scene faults followed by injected ones."""
        return tuple(self.scene.faults) + tuple(self._injected)

    def _apply_bus_fault(self, f: Fault) -> None:
        if f.kind == "bus_stuck":
            self.bus.stuck(f.at_s, f.until_s)
            return
        addr = f.params.get("address")
        if addr is None:
            addr = self.scene.board.address_of(f.params["chip"])
        self.bus.nack(addr, f.at_s, f.until_s)

    # ---- touches

    def add_touch(self, start_s: float, length_s: float, *, press_trigger: bool = True,
                  trigger_hold_s: float = 0.1) -> None:
        """Touch the object again (e.g. a second measurement); optionally press the trigger at ``start_s``."""
        self.world.add_touch(start_s, length_s)
        if press_trigger:
            self.parts.chip.press(self.parts.trigger_offset, start_s, min(trigger_hold_s, length_s))

    def repeat_touches(self) -> None:
        """Touch after touch: the probe goes back on the object ``[touch] repeat_gap_s`` after each touch,
        until the next heating ends (see :mod:`firmware_sim.world`). On by default in a sim session."""
        if self.scene.touch.repeat is not False:
            self.world.repeat_touches()

    # ---- heater invariants for HIL tests

    def heater_intervals(self, t_end_s: float | None = None) -> list[tuple[float, float]]:
        """Intervals ``(start_s, end_s)`` with electrical power in the film, up to ``t_end_s`` (default now).

        Faults count (a stuck-on heater is on; a dead one is off).
        """
        t_end = self.clock.now() if t_end_s is None else float(t_end_s)
        sched = self.world.power_schedule(t_end)
        out: list[tuple[float, float]] = []
        edges = list(sched.t_start_s) + [t_end]
        for a, b, q in zip(edges[:-1], edges[1:], sched.q_v_W_m3):
            if q > 0 and b > a:
                if out and out[-1][1] == a:
                    out[-1] = (out[-1][0], b)
                else:
                    out.append((float(a), float(b)))
        return out

    def heater_on_time_s(self, t_end_s: float | None = None) -> float:
        """Total time (s) the heater dissipated power, from 0 to ``t_end_s`` (default now)."""
        return float(sum(b - a for a, b in self.heater_intervals(t_end_s)))

    def heater_is_on(self) -> bool:
        """Whether the film dissipates power now."""
        return self.world.heater_power_W(self.clock.now()) > 0.0

    def heater_invariant(self, max_on_time_s: float) -> dict:
        """Check the heater safety invariant on the simulated hardware.

        Returns ``{"ok", "longest_on_s", "total_on_s", "off_now", "n_intervals"}``;
        ``ok`` means no on-interval was longer than ``max_on_time_s`` and the
        film dissipates nothing now.
        """
        iv = self.heater_intervals()
        longest = max((b - a for a, b in iv), default=0.0)
        off_now = not self.heater_is_on()
        return {"ok": longest <= max_on_time_s + 1e-9 and off_now, "longest_on_s": longest,
                "total_on_s": float(sum(b - a for a, b in iv)), "off_now": off_now, "n_intervals": len(iv)}

    def heater_energy_J(self, t_end_s: float | None = None) -> float:
        """Electrical energy dissipated in the film (J) from 0 to ``t_end_s`` (default now)."""
        t_end = self.clock.now() if t_end_s is None else float(t_end_s)
        sched = self.world.power_schedule(t_end)
        # The world's stack: the faithful world's film has the probe's real area (small-heater probe).
        stack = self.world.stack
        return sched.energy_density(t_end) * stack.heater_area_m2 * stack.heater_thickness_m

    # ---- truth

    def truth(self, t_s: Sequence[float] | None = None, *, dt_s: float = 0.01) -> Truth:
        """Exact surface temperature, thermocouple reading and flux at ``t_s``.

        Default times: 0, dt_s, ... up to now.
        """
        if t_s is None:
            n = int(np.floor(self.clock.now() / dt_s + 1e-9))
            t_s = np.arange(n + 1) * dt_s
        return self.world.truth(t_s)

    # ---- lifecycle

    def close(self) -> None:
        """Close the board and remove the temporary PWM tree."""
        try:
            if not self._board.closed:
                self._board.close()
        finally:
            self.pwm.close()

    def __enter__(self) -> Simulator:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Simulator scene={self.scene.name!r} t={self.clock.now():.6f}s chips={sorted(self.chips)}>"


def load_scene(path_or_name: str | Path, *, material_lookup: MaterialLookup | None = None,
               bit_rate_Hz: float | None = None, clock: str = "virtual") -> Simulator:
    """A :class:`Simulator` for a scene file or shipped scene name (e.g. ``"glass_15V"``).

    ``clock`` is ``"virtual"`` (default), ``"wall"`` or ``"bus"`` (see
    :class:`Simulator`); ``clock="wall"`` lets an unmodified third-party
    driver that polls with ``time.sleep`` see conversions take their
    datasheet time.

    Raises
    ------
    ValueError
        If ``clock`` is not one of ``"virtual"``, ``"wall"``, ``"bus"``.
    SceneError
        If the file is invalid (the message names the key).
    FileNotFoundError
        If there is no such file or shipped scene.
    """
    check_clock_mode(clock)
    return Simulator(read_scene(path_or_name, material_lookup=material_lookup), bit_rate_Hz=bit_rate_Hz,
                     clock=clock)


SCENE_ENV = "THERMOTOUCH_SIM_SCENE"


def make_scene_board(scene: str | Path | Scene | None = None, **options: Any) -> Board:
    """Board factory for ``make_board("sim", scene=...)``.

    With ``scene`` (a name, path or Scene) the board sits on a new
    :class:`Simulator` (``board.extras["simulator"]``). Without it, the scene
    named by the environment variable ``THERMOTOUCH_SIM_SCENE`` is used if set
    and no ``options`` are given (so a daemon configured with ``kind = "sim"``
    runs on a scene); otherwise this is
    :func:`firmware_sim.board.make_sim_board` with ``options``.
    """
    if scene is None and not options and os.environ.get(SCENE_ENV):
        scene = os.environ[SCENE_ENV]
    if scene is None:
        return make_sim_board(**options)
    if options:
        raise ValueError(f"options {sorted(options)} cannot be combined with scene=")
    sim = Simulator(scene) if isinstance(scene, Scene) else load_scene(scene)
    return sim.board()


def register_scene_board(name: str = "sim") -> None:
    """Register :func:`make_scene_board` as board kind ``name``."""
    register_board_factory(name, make_scene_board, replace=True)
