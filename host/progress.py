"""Progress bars on stderr (tqdm when installed, silent otherwise)."""

from __future__ import annotations

import sys
from typing import Callable

__all__ = ["ProgressBar"]


class ProgressBar:
    """``bar(i, n)`` updates a bar to ``i`` of ``n``; use as a context manager.

    Parameters
    ----------
    desc : str
        Label in front of the bar.
    unit : str
        Unit of ``i`` and ``n``.
    enabled : bool
        False: no output at all (tests, ``--json``); the bar is also off when
        stderr is not a terminal.
    """

    def __init__(self, desc: str, unit: str = "it", *, enabled: bool = True, unit_scale: bool = False) -> None:
        self._bar = None
        if enabled:
            try:
                from tqdm import tqdm  # noqa: PLC0415 - in the host extra
            except ImportError:  # pragma: no cover
                tqdm = None
            if tqdm is not None:
                self._bar = tqdm(total=0, desc=desc, unit=unit, unit_scale=unit_scale, file=sys.stderr,
                                 leave=True, dynamic_ncols=True, disable=None)

    def __call__(self, i: int, n: int) -> None:
        if self._bar is not None:
            self._bar.total = n
            self._bar.n = i
            self._bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> "ProgressBar":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


ProgressFn = Callable[[int, int], None]
