"""``GpioSim``: the simulated kernel -- GPIO chips by path on one clock, and the bound ``gpiod`` module.

A real process sees one kernel, so ``Chip`` and ``request_lines`` must know
which simulated chips exist: :attr:`GpioSim.gpiod` is a module-like object
whose ``Chip`` is bound to this kernel; inject it into edge code in place of
the real ``gpiod``.
"""

from __future__ import annotations

import errno as _errno
import os
import threading
import types
from typing import Any

from firmware_sim.gpiod import line
from firmware_sim.gpiod.chip import Chip, ChipInfo
from firmware_sim.gpiod.edge_event import EdgeEvent
from firmware_sim.gpiod.exception import ChipClosedError, RequestReleasedError
from firmware_sim.gpiod.line import Value
from firmware_sim.gpiod.line_request import LineRequest
from firmware_sim.gpiod.line_settings import LineSettings
from firmware_sim.gpiod.sim_chip import SimChip
from firmware_sim.gpiod.sim_line import SimLine
from firmware_sim.gpiod.state import LineStateDir

__all__ = ["GpioSim"]


class GpioSim:
    """A simulated GPIO subsystem: chips by path, sharing one virtual clock.

    Parameters
    ----------
    clock : VirtualClock
        Simulated time; edge events are time-stamped with it and scheduled
        input changes are applied as it advances.
    state_dir : path-like, optional
        Mirror every line's state to files there, with the holder's pid
        (:mod:`firmware_sim.gpiod.state`), so another process can read a line
        after the simulated device process died.
    """

    def __init__(self, clock: Any, *, state_dir: str | os.PathLike | None = None) -> None:
        self.clock = clock
        self.lock = threading.RLock()
        self._chips: dict[str, SimChip] = {}
        #: Where line states are mirrored for other processes (None: not mirrored).
        self.state_dir = None if state_dir is None else LineStateDir(state_dir)
        clock.on_advance(self._on_advance)
        self.gpiod = self._make_module()

    def add_chip(
        self,
        path: str = "/dev/gpiochip0",
        num_lines: int = 54,
        label: str = "sim-gpio",
        line_names: dict[int, str] | None = None,
    ) -> SimChip:
        """Create a chip at ``path`` (54 lines like the Pi's main GPIO bank)."""
        with self.lock:
            if path in self._chips:
                raise ValueError(f"a simulated GPIO chip already exists at {path!r}")
            chip = SimChip(self, path, num_lines, label, line_names)
            self._chips[path] = chip
            return chip

    def chip(self, path: str) -> SimChip:
        """The simulator-side view of the chip at ``path``."""
        return self._lookup(path)

    def _lookup(self, path: str) -> SimChip:
        try:
            return self._chips[str(path)]
        except KeyError:
            raise FileNotFoundError(
                _errno.ENOENT, f"{os.strerror(_errno.ENOENT)}: no simulated GPIO chip at", str(path)
            ) from None

    def _on_advance(self, t_old: float, t_new: float) -> None:
        for chip in list(self._chips.values()):
            chip._process_until(t_new)

    def _mirror(self, chip: SimChip, ln: SimLine, t: float | None = None) -> None:
        """Write one line's state to ``state_dir`` (if set), with the holder's pid."""
        if self.state_dir is None:
            return
        self.state_dir.write(chip.name, ln.offset, {
            "t_s": self.clock.now() if t is None else t, "level": ln.level,
            "direction": ln.settings.direction.name, "bias": ln.settings.bias.name,
            "active_low": ln.settings.active_low,
            "consumer": None if ln.request is None else ln.request._consumer,
            "pid": None if ln.request is None else os.getpid()})

    def _make_module(self) -> types.SimpleNamespace:
        bound_chip = type("Chip", (Chip,), {"_gsim": self, "__module__": __name__})
        gsim = self

        def request_lines(
            path: str,
            config: dict[Any, LineSettings | None],
            consumer: str | None = None,
            event_buffer_size: int | None = None,
            output_values: dict[int | str, Value] | None = None,
        ) -> LineRequest:
            """Open the chip at ``path``, request lines, close the chip, return the request."""
            with bound_chip(path) as chip:
                return chip.request_lines(
                    config=config,
                    consumer=consumer,
                    event_buffer_size=event_buffer_size,
                    output_values=output_values,
                )

        def is_gpiochip_device(path: str) -> bool:
            """True if ``path`` names a simulated chip."""
            return str(path) in gsim._chips

        return types.SimpleNamespace(
            __name__="firmware_sim.gpiod(bound)",
            __version__="2.5.0-sim",
            Chip=bound_chip,
            ChipInfo=ChipInfo,
            LineSettings=LineSettings,
            LineRequest=LineRequest,
            EdgeEvent=EdgeEvent,
            ChipClosedError=ChipClosedError,
            RequestReleasedError=RequestReleasedError,
            line=line,
            request_lines=request_lines,
            is_gpiochip_device=is_gpiochip_device,
            sim=self,
        )
