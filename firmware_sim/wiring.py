"""The simulated board's wiring: one table from chip pins (and the heater's lines) to world signals.

Every row of :data:`WIRING` says that one input of one fitted chip sees one signal of the
thermal world (:class:`firmware_sim.world_protocol.World`); the rows come from the chip
registry's :attr:`edge.hw.chips.Chip.wiring` -- the same statement of the board the drivers'
roles are checked against -- so the simulator, both worlds and the drivers cannot disagree
on which pin carries what.  :data:`HEATER` is the one output row: the heater's enable line
times its PWM channel is the duty the world heats with (:class:`firmware_sim.drive.BoardDrive`).

The worlds carry no per-chip methods: :func:`connect` hands a chip emulator its inputs
(:class:`Pins`) -- a callable per wired pin, and for a multiplexed ADC :meth:`Pins.mux`, which
answers a reversed pair with the negated voltage and an unwired one with 0 V (tied to ground).

| chip | pin | signal |
|---|---|---|
| MCP9600 | hot junction / cold junction / open circuit | thermocouple (°C) / board at ambient / open fault |
| ADS1115 | AIN0-AIN1 (AIN2, AIN3 to GND) | flux sensor voltage |
| ADS122C04 | AIN0-AIN1, AIN2-AIN3, internal sensor | thermocouple EMF, flux sensor voltage, board at ambient |
| board | GPIO17 enable x PWM0 channel 0 | heater duty |
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from edge.hw.chips import CHIPS, COLD_JUNCTION_C, THERMOCOUPLE_OPEN
from firmware_sim.drive import BoardDrive
from firmware_sim.world_protocol import World

__all__ = ["Wire", "WIRING", "HEATER", "Pins", "connect", "heater_drive", "pin_value"]

#: Signals that depend only on time (no per-caller sampling grid).
_PLAIN = (COLD_JUNCTION_C, THERMOCOUPLE_OPEN)


@dataclass(frozen=True)
class Wire:
    """One row of the wiring table: ``pin`` of ``part`` sees the world's ``signal``.

    ``stream`` names the caller to the world (``"<chip>:<pin>"``): a lazily
    evaluating world recognises each chip input's sampling grid by it.
    """

    part: str
    pin: str
    signal: str

    @property
    def stream(self) -> str:
        return f"{self.part}:{self.pin}"


#: Every chip input of the board and the world signal it sees (from the chip registry).
WIRING: tuple[Wire, ...] = tuple(Wire(spec.name, pin, signal)
                                 for spec in CHIPS.values() for pin, signal in spec.wiring.items())
#: The heater: the board's enable line times its PWM duty drives the world's heater.
HEATER = Wire("board", "heater_enable*pwm", "heater_duty")


def _reader(world: World, wire: Wire) -> Callable[[float], Any]:
    fn = getattr(world, wire.signal)
    if wire.signal in _PLAIN:
        return fn
    stream = wire.stream
    return lambda t_s: fn(t_s, stream=stream)


class Pins:
    """A chip's inputs on the board: ``pins["hot_junction"](t_s)``, ``pins.mux("AIN0_AIN1", t_s)``."""

    def __init__(self, part: str, readers: dict[str, Callable[[float], Any]]) -> None:
        self.part = part
        self._readers = readers

    def __getitem__(self, pin: str) -> Callable[[float], Any]:
        try:
            return self._readers[pin]
        except KeyError:
            raise KeyError(f"{self.part} has no wired input {pin!r}; wired: {sorted(self._readers)}") from None

    def __contains__(self, pin: str) -> bool:
        return pin in self._readers

    def mux(self, label: str, t_s: float) -> float:
        """Differential input for a multiplexer setting ``"AINp_AINn"``: the wired pair, the negated
        reversed pair, or 0 V (an input tied to ground)."""
        fn = self._readers.get(label)
        if fn is not None:
            return fn(t_s)
        p, sep, n = label.partition("_")
        fn = self._readers.get(f"{n}_{p}") if sep else None
        if fn is not None:
            return -fn(t_s)
        return 0.0


def connect(world: World, part: str) -> Pins:
    """The inputs of chip ``part`` wired to ``world`` (the rows of :data:`WIRING` for it)."""
    rows = [w for w in WIRING if w.part == part]
    if not rows:
        raise ValueError(f"no wiring for {part!r}; wired chips: {sorted({w.part for w in WIRING})}")
    return Pins(part, {w.pin: _reader(world, w) for w in rows})


def pin_value(world: World, part: str, pin: str, t_s: float) -> Any:
    """What ``pin`` of chip ``part`` sees at ``t_s`` (a multiplexer label or a named input)."""
    pins = connect(world, part)
    return pins[pin](t_s) if pin in pins else pins.mux(pin, t_s)


def heater_drive(parts: Any) -> BoardDrive:
    """The world's heater drive from a sim board's parts: the :data:`HEATER` row."""
    return BoardDrive(parts)
