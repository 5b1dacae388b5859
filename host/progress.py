"""Progress bars on stderr (tqdm when installed, silent otherwise).

* :class:`ProgressBar` -- a step with a known length (``bar(i, n)``); it ends
  its line as soon as ``i`` reaches ``n``, so the next message starts on a
  line of its own.
* :class:`Ticker` -- a step without a known length (a network fit, an
  evaluation, a touch): elapsed seconds, updated from a background thread.
* :func:`echo` -- a message on stderr that never shares a line with a bar
  (written above a running bar).

Bars are drawn only when their stream is a terminal (``disable=None``), so
pipes, logs and tests see the messages alone.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any, Callable, TextIO

__all__ = ["ProgressBar", "Ticker", "echo", "ProgressFn"]

_ACTIVE: list[Any] = []  # running tqdm bars, innermost last


def _tqdm(**kw: Any) -> Any:
    try:
        from tqdm import tqdm  # noqa: PLC0415 - in the host extra
    except ImportError:  # pragma: no cover
        return None
    bar = tqdm(dynamic_ncols=True, leave=True, **kw)
    if bar.disable:
        bar.close()
        return None
    _ACTIVE.append(bar)
    return bar


def _close(bar: Any) -> None:
    if bar in _ACTIVE:
        _ACTIVE.remove(bar)
    bar.close()  # leave=True: the final state stays, and the line ends


def echo(message: str, file: TextIO | None = None) -> None:
    """Print ``message`` on stderr (or ``file``) on its own line, above any running bar."""
    stream = file if file is not None else sys.stderr
    if _ACTIVE:
        from tqdm import tqdm  # noqa: PLC0415

        tqdm.write(message, file=stream)
    else:
        print(message, file=stream, flush=True)


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
        its stream is not a terminal.
    file : stream, optional
        Default stderr.
    """

    def __init__(self, desc: str, unit: str = "it", *, enabled: bool = True, unit_scale: bool = False,
                 file: TextIO | None = None) -> None:
        self._kw = dict(desc=desc, unit=unit, unit_scale=unit_scale, file=file if file is not None else sys.stderr,
                        disable=None)
        self._enabled = enabled
        self._bar = None
        self._done = False

    def __call__(self, i: int, n: int) -> None:
        if not self._enabled or self._done:
            return
        if self._bar is None:
            self._bar = _tqdm(total=n, **self._kw)
            if self._bar is None:
                self._enabled = False
                return
        self._bar.total = n
        self._bar.n = i
        self._bar.refresh()
        if n and i >= n:  # complete: end the line now, not when the block ends
            self.close()
            self._done = True

    def close(self) -> None:
        if self._bar is not None:
            _close(self._bar)
            self._bar = None

    def __enter__(self) -> "ProgressBar":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Ticker:
    """Elapsed time of a step whose length is unknown (``with Ticker("fitting"): ...``).

    Parameters
    ----------
    desc : str
        What runs.
    enabled : bool
        False: no output.
    interval_s : float
        Refresh period of the background thread.
    """

    def __init__(self, desc: str, *, enabled: bool = True, interval_s: float = 0.5,
                 file: TextIO | None = None) -> None:
        self.desc = desc
        self._enabled = enabled
        self._interval = interval_s
        self._file = file if file is not None else sys.stderr
        self._bar = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> "Ticker":
        if self._enabled:
            self._bar = _tqdm(total=None, desc=self.desc, unit="s", file=self._file, disable=None,
                              bar_format="{desc}: {elapsed}")
        if self._bar is not None:
            t0 = time.monotonic()

            def tick() -> None:
                while not self._stop.wait(self._interval):
                    self._bar.n = int(time.monotonic() - t0)
                    self._bar.refresh()

            self._thread = threading.Thread(target=tick, name="thermotouch-ticker", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self._bar is not None:
            _close(self._bar)
            self._bar = None


ProgressFn = Callable[[int, int], None]
