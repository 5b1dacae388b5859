"""The board abstraction: what the probe's device code talks to.

A :class:`Board` bundles the probe's hardware handles:

* ``i2c`` -- an smbus2-compatible bus (``read_i2c_block_data`` etc.);
* ``heater_enable`` and ``trigger`` -- :class:`GpioLine` descriptions of the
  heater-enable output and the trigger-button input (gpiod module, chip
  path, offset, polarity, bias); drivers request them with the settings they
  need;
* ``pwm`` -- the heater's :class:`edge.hw.sysfs_pwm.SysfsPwm` channel;
* ``clock`` -- ``monotonic()`` seconds and ``sleep(s)``.

Boards are built by named factories (like gpiozero's pin factories):
``make_board("rpi", i2c_bus=1, ...)`` builds the real one; the simulator
registers ``"sim"`` with :func:`register_board_factory`, so edge never
imports firmware_sim. Nothing here touches hardware at import time; the real
factory checks its devices when called and names any that is missing.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from datetime import timedelta
from typing import Any, Callable, Iterable, Protocol

from edge.hw.sysfs_pwm import DEFAULT_PWM_ROOT, PwmError, SysfsPwm

__all__ = [
    "BoardError",
    "Clock",
    "SystemClock",
    "GpioLine",
    "Board",
    "register_board_factory",
    "unregister_board_factory",
    "board_kinds",
    "make_board",
    "make_rpi_board",
]

_BIASES = ("as-is", "pull-up", "pull-down", "disabled")
_EDGES = ("none", "rising", "falling", "both")


class BoardError(RuntimeError):
    """A board cannot be built, e.g. because a device is missing."""


class Clock(Protocol):
    """What the device code needs from a clock."""

    def monotonic(self) -> float:  # pragma: no cover - protocol
        """Monotonic time in seconds."""

    def sleep(self, dt_s: float) -> None:  # pragma: no cover - protocol
        """Wait ``dt_s`` seconds."""


class SystemClock:
    """The real clock: ``time.monotonic`` and ``time.sleep``.

    Its time base is CLOCK_MONOTONIC, the clock gpiod edge events are
    stamped with by default.
    """

    def monotonic(self) -> float:
        """Seconds on CLOCK_MONOTONIC."""
        return time.monotonic()

    def sleep(self, dt_s: float) -> None:
        """Sleep ``dt_s`` seconds (negative values sleep 0)."""
        time.sleep(max(0.0, float(dt_s)))


@dataclass(frozen=True)
class GpioLine:
    """Where one GPIO line lives and how it is wired.

    Parameters
    ----------
    gpiod : module-like
        The real ``gpiod`` (2.x) module or a simulated one with the same API
        (``firmware_sim.gpiod.kernel.GpioSim(...).gpiod``).
    chip_path : str
        GPIO character device, e.g. ``"/dev/gpiochip0"``.
    offset : int
        Line offset on that chip (the BCM number on a Pi's main bank).
    active_low : bool
        True if the line's *active* state is a low level.
    bias : str
        ``"as-is"``, ``"pull-up"``, ``"pull-down"`` or ``"disabled"``.
    """

    gpiod: Any
    chip_path: str
    offset: int
    active_low: bool = False
    bias: str = "as-is"

    def __post_init__(self) -> None:
        if isinstance(self.offset, bool) or not isinstance(self.offset, int) or self.offset < 0:
            raise ValueError(f"offset must be an int >= 0, got {self.offset!r}")
        if self.bias not in _BIASES:
            raise ValueError(f"bias must be one of {_BIASES}, got {self.bias!r}")
        if not isinstance(self.chip_path, str) or not self.chip_path:
            raise ValueError(f"chip_path must be a non-empty str, got {self.chip_path!r}")

    def _bias(self, bias: str | None = None) -> Any:
        bias = self.bias if bias is None else bias
        if bias not in _BIASES:
            raise ValueError(f"bias must be one of {_BIASES}, got {bias!r}")
        return self.gpiod.line.Bias[bias.upper().replace("-", "_")]

    @property
    def inactive_bias(self) -> str:
        """The bias that pulls the line to its *inactive* level: pull-down, or pull-up if active low."""
        return "pull-up" if self.active_low else "pull-down"

    def request_output(self, consumer: str, value: bool = False, *, bias: str | None = None) -> Any:
        """Request the line as an output driven to logical ``value``; return the request.

        ``bias`` overrides the line's configured bias for this request.
        """
        g = self.gpiod
        settings = g.LineSettings(
            direction=g.line.Direction.OUTPUT,
            output_value=g.line.Value.ACTIVE if value else g.line.Value.INACTIVE,
            active_low=self.active_low,
            bias=self._bias(bias),
        )
        return g.request_lines(self.chip_path, config={self.offset: settings}, consumer=consumer)

    def request_fail_safe_output(self, consumer: str) -> Any:
        """Request the line as an output driven inactive, biased towards inactive.

        For a line whose active level is dangerous (the heater enable): the
        kernel releases a process's line requests when it dies, however it
        dies (SIGKILL, OOM kill, a crash in C, a watchdog kill of a frozen
        process), and a released line is no longer driven. With the bias
        pulling towards the inactive level, the line then falls inactive
        where the controller returns freed lines to inputs (BCM283x/RP1 do,
        unless the kernel is told to keep freed outputs; the board's external
        pull resistor on the switch's gate covers the rest).
        """
        return self.request_output(consumer, value=False, bias=self.inactive_bias)

    def request_input(self, consumer: str, *, edge: str = "none", debounce_s: float = 0.0) -> Any:
        """Request the line as an input with edge detection and debouncing; return the request.

        ``edge`` is ``"none"``, ``"rising"``, ``"falling"`` or ``"both"``
        (logical edges: rising means becoming active); ``debounce_s`` is the
        kernel debounce period in seconds.
        """
        if edge not in _EDGES:
            raise ValueError(f"edge must be one of {_EDGES}, got {edge!r}")
        if not debounce_s >= 0.0:
            raise ValueError(f"debounce_s must be >= 0, got {debounce_s!r}")
        g = self.gpiod
        settings = g.LineSettings(
            direction=g.line.Direction.INPUT,
            edge_detection=g.line.Edge[edge.upper()],
            active_low=self.active_low,
            bias=self._bias(),
            debounce_period=timedelta(seconds=float(debounce_s)),
        )
        return g.request_lines(self.chip_path, config={self.offset: settings}, consumer=consumer)


class Board:
    """The probe's hardware handles (see the module docstring).

    Parameters
    ----------
    name : str
        Factory kind that built it, e.g. ``"rpi"`` or ``"sim"``.
    i2c : smbus2.SMBus-like
        The sensor bus.
    heater_enable, trigger : GpioLine
        Heater-enable output and trigger-button input.
    pwm : SysfsPwm
        Heater power PWM channel.
    clock : Clock
        Time source for every driver on this board.
    on_close : iterable of callables
        Extra clean-up run by :meth:`close` (after closing ``i2c``).
    extras : dict, optional
        Backend-specific objects, e.g. the simulator's parts under ``"sim"``.
    """

    def __init__(
        self,
        *,
        name: str,
        i2c: Any,
        heater_enable: GpioLine,
        trigger: GpioLine,
        pwm: SysfsPwm,
        clock: Clock,
        on_close: Iterable[Callable[[], None]] = (),
        extras: dict[str, Any] | None = None,
    ) -> None:
        for field, v in (("heater_enable", heater_enable), ("trigger", trigger)):
            if not isinstance(v, GpioLine):
                raise TypeError(f"{field} must be a GpioLine, got {type(v).__name__}")
        if not (callable(getattr(clock, "monotonic", None)) and callable(getattr(clock, "sleep", None))):
            raise TypeError("clock must have monotonic() and sleep(s)")
        self.name = name
        self.i2c = i2c
        self.heater_enable = heater_enable
        self.trigger = trigger
        self.pwm = pwm
        self.clock = clock
        self._on_close = list(on_close)
        self.extras: dict[str, Any] = dict(extras or {})
        self._closed = False
        self._lock = threading.Lock()

    def __repr__(self) -> str:
        return (
            f"<Board {self.name!r} heater_enable={self.heater_enable.chip_path}:{self.heater_enable.offset} "
            f"trigger={self.trigger.chip_path}:{self.trigger.offset} pwm={self.pwm!r}>"
        )

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    def close(self) -> None:
        """Close the I2C bus and run the clean-up hooks (idempotent).

        Drivers (heater, button) release their own lines; close them first.
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
        errors: list[BaseException] = []
        close_i2c = getattr(self.i2c, "close", None)
        for fn in ([close_i2c] if callable(close_i2c) else []) + self._on_close:
            try:
                fn()
            except Exception as e:  # run every hook, then report
                errors.append(e)
        if errors:
            raise BoardError(f"closing board {self.name!r} failed: {errors!r}") from errors[0]

    def __enter__(self) -> Board:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


# --------------------------------------------------------------------------
# Factory registry

BoardFactory = Callable[..., Board]
_factories: dict[str, BoardFactory] = {}
_factories_lock = threading.Lock()


def register_board_factory(name: str, factory: BoardFactory, *, replace: bool = False) -> None:
    """Make ``make_board(name, **options)`` call ``factory(**options)``.

    Raises ValueError if ``name`` is taken and ``replace`` is False.
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty str, got {name!r}")
    if not callable(factory):
        raise TypeError(f"factory for {name!r} must be callable, got {factory!r}")
    with _factories_lock:
        if name in _factories and not replace and _factories[name] is not factory:
            raise ValueError(f"a board factory named {name!r} is already registered (pass replace=True)")
        _factories[name] = factory


def unregister_board_factory(name: str) -> None:
    """Remove the factory ``name`` (no error if absent)."""
    with _factories_lock:
        _factories.pop(name, None)


def board_kinds() -> list[str]:
    """Names of the registered board factories, sorted."""
    with _factories_lock:
        return sorted(_factories)


def make_board(kind: str, **options: Any) -> Board:
    """Build a board with the factory registered as ``kind``.

    Raises
    ------
    ValueError
        If no factory named ``kind`` is registered.
    BoardError
        If the factory cannot reach its hardware.
    """
    with _factories_lock:
        factory = _factories.get(kind)
        known = sorted(_factories)
    if factory is None:
        hint = " (the simulator registers 'sim' when its board support is imported)" if kind == "sim" else ""
        raise ValueError(f"unknown board kind {kind!r}; registered: {known}{hint}")
    board = factory(**options)
    if not isinstance(board, Board):
        raise TypeError(f"board factory {kind!r} returned {type(board).__name__}, not Board")
    return board


# --------------------------------------------------------------------------
# The real Raspberry Pi board


def _i2c_path(i2c_bus: int | str) -> str:
    if isinstance(i2c_bus, bool):
        raise ValueError(f"i2c_bus must be a bus number or a device path, got {i2c_bus!r}")
    if isinstance(i2c_bus, int):
        if i2c_bus < 0:
            raise ValueError(f"i2c_bus must be >= 0, got {i2c_bus}")
        return f"/dev/i2c-{i2c_bus}"
    if isinstance(i2c_bus, str) and i2c_bus:
        return i2c_bus
    raise ValueError(f"i2c_bus must be a bus number or a device path, got {i2c_bus!r}")


def make_rpi_board(
    *,
    i2c_bus: int | str = 1,
    gpio_chip: str = "/dev/gpiochip0",
    heater_enable_offset: int = 17,
    heater_active_low: bool = False,
    trigger_offset: int = 27,
    trigger_active_low: bool = True,
    trigger_bias: str = "pull-up",
    pwm_root: str = DEFAULT_PWM_ROOT,
    pwm_chip: int = 0,
    pwm_channel: int = 0,
    clock: Clock | None = None,
) -> Board:
    """Build the real board: smbus2 I2C, gpiod lines, sysfs PWM.

    Defaults match the reference wiring: sensors on I2C-1 (GPIO2/3), heater
    enable on GPIO17, trigger button on GPIO27 to ground (pull-up, active
    low), heater PWM on PWM0 channel 0 (GPIO18 with ``dtoverlay=pwm``).
    On a Pi 5 with an older kernel the main bank may be ``/dev/gpiochip4``.

    Raises
    ------
    BoardError
        Naming every missing device, or a device that is not what it should be.
    """
    i2c_path = _i2c_path(i2c_bus)
    clock = clock if clock is not None else SystemClock()
    pwm = SysfsPwm(pwm_root, pwm_chip, pwm_channel, clock=clock)
    missing = []
    if not os.path.exists(i2c_path):
        missing.append(f"{i2c_path} (enable I2C: dtparam=i2c_arm=on in config.txt)")
    if not os.path.exists(gpio_chip):
        missing.append(f"{gpio_chip} (GPIO character device; is this a Raspberry Pi?)")
    if not pwm.chip_dir.is_dir():
        missing.append(f"{pwm.chip_dir} (enable PWM: dtoverlay=pwm in config.txt)")
    if missing:
        raise BoardError("rpi board: missing device(s): " + "; ".join(missing))

    try:
        import gpiod  # noqa: PLC0415 - imported only when real hardware is wanted
    except ImportError as e:
        raise BoardError("rpi board needs the 'gpiod' (>= 2.0) Python package") from e
    if not gpiod.is_gpiochip_device(gpio_chip):
        raise BoardError(f"rpi board: {gpio_chip} is not a GPIO character device")
    try:
        with gpiod.Chip(gpio_chip) as chip:
            n_lines = chip.get_info().num_lines
    except OSError as e:
        raise BoardError(f"rpi board: cannot open {gpio_chip}: {e.strerror or e}") from e
    for field, off in (("heater_enable_offset", heater_enable_offset), ("trigger_offset", trigger_offset)):
        if not 0 <= off < n_lines:
            raise BoardError(f"rpi board: {field}={off} is outside {gpio_chip}'s lines 0..{n_lines - 1}")
    if heater_enable_offset == trigger_offset:
        raise ValueError("heater_enable_offset and trigger_offset must differ")
    try:
        pwm.check_present()
    except PwmError as e:
        raise BoardError(f"rpi board: {e}") from e

    try:
        import smbus2  # noqa: PLC0415
    except ImportError as e:
        raise BoardError("rpi board needs the 'smbus2' Python package") from e
    try:
        i2c = smbus2.SMBus(i2c_path)
    except OSError as e:
        raise BoardError(f"rpi board: cannot open I2C adapter {i2c_path}: {e.strerror or e}") from e

    return Board(
        name="rpi",
        i2c=i2c,
        heater_enable=GpioLine(gpiod, gpio_chip, heater_enable_offset, active_low=heater_active_low),
        trigger=GpioLine(gpiod, gpio_chip, trigger_offset, active_low=trigger_active_low, bias=trigger_bias),
        pwm=pwm,
        clock=clock,
    )


register_board_factory("rpi", make_rpi_board)


def force_rpi_heater_off(
    *,
    gpio_chip: str = "/dev/gpiochip0",
    heater_enable_offset: int = 17,
    heater_active_low: bool = False,
    pwm_root: str = DEFAULT_PWM_ROOT,
    pwm_chip: int = 0,
    pwm_channel: int = 0,
    gpiod_module: Any = None,
    pwm_io: Any = None,
) -> list[str]:
    """Drive the real heater off without building the board; return what failed.

    Used before anything else at start-up and by the service's
    ``ExecStopPost``: it needs neither I2C nor a complete board, so a missing
    sensor bus or a crashed daemon cannot leave the heater on.  Both channels
    are tried whatever happens to the other: the enable line is driven
    inactive and released biased towards inactive (see
    :meth:`GpioLine.request_fail_safe_output`) and the PWM channel, if it
    is exported, gets duty 0 and is disabled.  ``gpiod_module`` and
    ``pwm_io`` replace the real gpiod module and sysfs file access (tests).
    """
    failures: list[str] = []
    try:
        g = gpiod_module
        if g is None:
            import gpiod as g  # noqa: PLC0415 - real hardware only
        line = GpioLine(g, gpio_chip, heater_enable_offset, active_low=heater_active_low)
        line.request_fail_safe_output("thermotouch-heater-off").release()
    except Exception as e:  # noqa: BLE001 - report and go on to the PWM
        failures.append(f"enable line {gpio_chip}:{heater_enable_offset}: {e}")
    try:
        pwm = SysfsPwm(pwm_root, pwm_chip, pwm_channel, io=pwm_io)
        if pwm.is_exported:
            if pwm.period_ns:
                pwm.set_duty_ns(0)
            pwm.disable()
    except Exception as e:  # noqa: BLE001
        failures.append(f"PWM {pwm_root}/pwmchip{pwm_chip}/pwm{pwm_channel}: {e}")
    return failures
