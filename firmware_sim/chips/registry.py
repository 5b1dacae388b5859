"""The chip emulators, registered against the chip registry's entries (:data:`edge.hw.chips.CHIPS`).

One :class:`Emulator` per chip: the emulator class, the ``[sensors]`` key of its noise in a
simulator scene, and how it is built on a board from its wired inputs
(:class:`firmware_sim.wiring.Pins`).  The simulator builds every fitted chip through
:func:`emulate`; the chip contract test checks that every registry chip has one and that each
emulator reads the same register map as its driver.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Callable, Mapping

from edge.hw.chips import CHIPS, Chip
from firmware_sim.chips.ads1115 import ADS1115Emulator
from firmware_sim.chips.ads122c04 import ADS122C04Emulator
from firmware_sim.chips.mcp9600 import MCP9600Emulator
from firmware_sim.wiring import Pins

__all__ = ["Emulator", "EMULATORS", "emulate"]


@dataclass(frozen=True)
class Emulator:
    """How the simulator builds one chip.

    Attributes
    ----------
    chip : Chip
        Its registry entry.
    cls : type
        The emulator class (register-level, on a SimBus).
    build : callable (clock, pins, noise_rms_V, rng) -> emulator
        The noise is the scene's (:attr:`noise_setting`).
    """

    chip: Chip
    cls: type
    build: Callable[[Any, Pins, float, Any], Any]

    @property
    def noise_setting(self) -> str:
        """The scene's ``[sensors]`` key of its input noise (the registry's :attr:`Chip.input_noise`)."""
        return self.chip.setting_key(self.chip.input_noise.key)


def _by_class(cls: type) -> Chip:
    # The emulator's chip is the registry entry whose register map it reads (one statement of the chip).
    module = __import__(cls.__module__, fromlist=["REGISTERS"])
    return next(c for c in CHIPS.values() if c.regmap.REGISTERS is module.REGISTERS)


def _registry(*emulators: Emulator) -> Mapping[str, Emulator]:
    return MappingProxyType({e.chip.name: e for e in emulators})


#: Emulators by chip name.
EMULATORS: Mapping[str, Emulator] = _registry(
    Emulator(_by_class(MCP9600Emulator), MCP9600Emulator,
             lambda clock, pins, noise, rng: MCP9600Emulator(
                 clock, pins["hot_junction"], pins["cold_junction"], rng=rng, emf_noise_rms_V=noise,
                 open_circuit=pins["open_circuit"])),
    Emulator(_by_class(ADS1115Emulator), ADS1115Emulator,
             lambda clock, pins, noise, rng: ADS1115Emulator(clock, pins.mux, noise_rms_V=noise, rng=rng)),
    Emulator(_by_class(ADS122C04Emulator), ADS122C04Emulator,
             lambda clock, pins, noise, rng: ADS122C04Emulator(
                 clock, pins.mux, temperature_C=pins["temperature"], noise_rms_V=noise, rng=rng)),
)


def emulate(name: str, clock: Any, pins: Pins, *, noise_rms_V: float = 0.0, rng: Any = None) -> Any:
    """The emulator of chip ``name`` on ``pins`` (ValueError for a chip without one)."""
    try:
        e = EMULATORS[name]
    except KeyError:
        raise ValueError(f"no emulator for chip {name!r}; emulated: {sorted(EMULATORS)}") from None
    return e.build(clock, pins, noise_rms_V, rng)
