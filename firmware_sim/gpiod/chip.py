"""``gpiod.Chip`` and ``gpiod.ChipInfo``: the device-code handle on a simulated chip."""

from __future__ import annotations

import errno as _errno
import os
from dataclasses import dataclass
from typing import Any

from firmware_sim.gpiod.exception import ChipClosedError
from firmware_sim.gpiod.line import Value, coerce_enum
from firmware_sim.gpiod.line_request import LineRequest
from firmware_sim.gpiod.line_settings import LineSettings, normalise_settings, replace_settings


__all__ = ["Chip", "ChipInfo"]


@dataclass(frozen=True)
class ChipInfo:
    """Snapshot of the chip's properties (mirrors ``gpiod.ChipInfo``)."""

    name: str
    label: str
    num_lines: int



class Chip:
    """A simulated GPIO chip handle (mirrors ``gpiod.Chip``).

    Use the class bound to a kernel, ``GpioSim(...).gpiod.Chip(path)``; the
    unbound module-level class has no kernel to look the path up in.
    """

    _gsim: Any = None  # the GpioSim this class is bound to (kernel.py binds it)

    def __init__(self, path: str):
        gsim = type(self)._gsim
        if gsim is None:
            raise RuntimeError(
                "firmware_sim.gpiod.chip.Chip is not bound to a simulated kernel; "
                "use GpioSim(clock).gpiod.Chip(path)"
            )
        self._sim: Any = gsim._lookup(path)  # its SimChip
        self._path = path

    def __bool__(self) -> bool:
        return self._sim is not None

    def __enter__(self) -> Chip:
        self._check_closed()
        return self

    def __exit__(self, exc_type, exc_value, traceback) -> None:
        self.close()

    def _check_closed(self) -> Any:
        if self._sim is None:
            raise ChipClosedError()
        return self._sim

    def close(self) -> None:
        """Close the chip handle (requests made through it stay valid)."""
        self._sim = None

    @property
    def path(self) -> str:
        """Filesystem path used to open this chip."""
        self._check_closed()
        return self._path

    def get_info(self) -> ChipInfo:
        """Chip name, label and number of lines."""
        sim = self._check_closed()
        return ChipInfo(name=sim.name, label=sim.label, num_lines=sim.num_lines)

    def line_offset_from_id(self, id: str | int) -> int:
        """Map a line name or offset to its offset on this chip."""
        sim = self._check_closed()
        if not isinstance(id, int):
            for ln in sim._lines:
                if ln.name and ln.name == id:
                    return ln.offset
            try:
                offset = int(id)
            except ValueError:
                raise OSError(_errno.ENOENT, f"{os.strerror(_errno.ENOENT)}: no line named {id!r}") from None
        else:
            offset = id
        if not 0 <= offset < sim.num_lines:
            raise ValueError("line offset of out range")
        return offset

    def request_lines(
        self,
        config: dict[Any, LineSettings | None],
        consumer: str | None = None,
        event_buffer_size: int | None = None,
        output_values: dict[int | str, Value] | None = None,
    ) -> LineRequest:
        """Request a set of lines for exclusive use (see ``gpiod.Chip.request_lines``)."""
        sim = self._check_closed()
        mapped_out = None
        if output_values:
            mapped_out = {self.line_offset_from_id(k): v for k, v in output_values.items()}
        cfg: dict[int, LineSettings] = {}
        lines: list[int | str] = []
        name_map: dict[str, int] = {}
        for key, settings in config.items():
            keys = [key] if isinstance(key, (int, str)) else list(key)
            for line_id in keys:
                off = self.line_offset_from_id(line_id)
                if off in cfg:
                    raise ValueError(f"line must be configured exactly once - offset {off} repeats")
                s = normalise_settings(settings)
                if mapped_out is not None:
                    s = replace_settings(s, output_value=coerce_enum(Value, mapped_out.get(off, Value.INACTIVE), "output_values"))
                cfg[off] = s
                lines.append(line_id)
                if isinstance(line_id, str):
                    name_map[line_id] = off
                elif sim._lines[off].name and sim._lines[off].name not in name_map:
                    name_map[sim._lines[off].name] = off
        if not cfg:
            raise ValueError("config must name at least one line")
        req = LineRequest(sim, cfg, lines, name_map, consumer, event_buffer_size)
        sim._claim(req, cfg)
        return req

    def __repr__(self) -> str:
        return "<Chip CLOSED>" if self._sim is None else f'Chip("{self._path}")'
