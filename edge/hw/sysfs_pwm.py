"""Driver for one channel of the kernel's sysfs PWM interface.

The kernel exposes ``/sys/class/pwm/pwmchipN/{export,unexport,npwm}`` and,
once channel M is exported, ``pwmchipN/pwmM/{period,duty_cycle,enable,polarity}``
with times in nanoseconds. The kernel refuses (EINVAL) any state whose period
is 0 or whose duty cycle exceeds the period, so this driver

* sets the period before the duty cycle when the period grows, and the duty
  cycle first when it shrinks;
* never enables a channel without a period;
* reads every value back after writing it and raises :class:`PwmError`
  naming the file if the kernel did not take it.

All file access goes through an ``io`` object with ``read(path) -> str`` and
``write(path, text)``; the default uses the real file system. The simulator
passes one that applies the kernel's rules synchronously (see
``firmware_sim.pwm``).
"""

from __future__ import annotations

import errno as _errno
import os
import time
from pathlib import Path
from typing import Any, NamedTuple

__all__ = ["PwmError", "PwmState", "OsSysfsIO", "SysfsPwm", "DEFAULT_PWM_ROOT"]

#: Where the kernel puts the PWM class directory.
DEFAULT_PWM_ROOT = "/sys/class/pwm"

_HINTS = {
    _errno.EINVAL: "the kernel needs period > 0 and duty_cycle <= period",
    _errno.EACCES: "permission denied; run as root or add a udev rule for the pwm class",
    _errno.EPERM: "permission denied; run as root or add a udev rule for the pwm class",
    _errno.ENODEV: "no such PWM channel on this chip",
    _errno.EBUSY: "the channel is in use",
}


class PwmError(RuntimeError):
    """A sysfs PWM operation failed; ``path`` names the file involved."""

    def __init__(self, message: str, path: str | os.PathLike | None = None, errno: int | None = None):
        super().__init__(message)
        self.path = None if path is None else str(path)
        self.errno = errno


class PwmState(NamedTuple):
    """A PWM channel's settings as read from sysfs."""

    period_ns: int
    duty_ns: int
    enabled: bool
    polarity: str

    @property
    def fraction(self) -> float:
        """Active fraction of each period (0 when disabled)."""
        return active_fraction(self.period_ns, self.duty_ns, self.enabled, self.polarity)


def active_fraction(period_ns: int, duty_ns: int, enabled: bool, polarity: str) -> float:
    """Fraction of time a PWM output is active (0 when disabled or without a period)."""
    if not enabled or period_ns <= 0:
        return 0.0
    f = duty_ns / period_ns
    return 1.0 - f if polarity == "inversed" else f


class OsSysfsIO:
    """Real file-system access in sysfs style (one ``write(2)`` per value)."""

    def read(self, path: str | os.PathLike) -> str:
        """Return the file's text."""
        with open(path, "r", encoding="ascii") as f:
            return f.read()

    def write(self, path: str | os.PathLike, text: str) -> None:
        """Write ``text`` in a single write call, as ``echo`` does."""
        fd = os.open(path, os.O_WRONLY)
        try:
            os.write(fd, text.encode("ascii"))
        finally:
            os.close(fd)


class _SystemClock:
    def monotonic(self) -> float:
        return time.monotonic()

    def sleep(self, dt_s: float) -> None:
        time.sleep(dt_s)


def _check_ns(name: str, value: Any, *, positive: bool) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{name} must be an int (ns), got {value!r}")
    if value < (1 if positive else 0) or value > 2**64 - 1:
        raise ValueError(f"{name} must be {'> 0' if positive else '>= 0'} ns, got {value}")
    return value


class SysfsPwm:
    """One PWM channel under a sysfs PWM class root.

    Parameters
    ----------
    root : path
        The PWM class directory (``/sys/class/pwm`` on a Pi; a temporary
        tree in the simulator).
    chip, channel : int
        Selects ``<root>/pwmchip<chip>/pwm<channel>``.
    io : object, optional
        File access with ``read(path) -> str`` and ``write(path, text)``;
        default :class:`OsSysfsIO`.
    clock : object, optional
        ``monotonic()``/``sleep(s)`` used while waiting for an export to
        appear; default the system clock.
    export_timeout_s : float
        How long to wait for ``pwm<channel>`` after exporting (udev may need
        a moment to fix permissions).
    """

    def __init__(
        self,
        root: str | os.PathLike = DEFAULT_PWM_ROOT,
        chip: int = 0,
        channel: int = 0,
        *,
        io: Any = None,
        clock: Any = None,
        export_timeout_s: float = 2.0,
        poll_interval_s: float = 0.01,
    ) -> None:
        for name, v in (("chip", chip), ("channel", channel)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"{name} must be an int >= 0, got {v!r}")
        if not export_timeout_s > 0:
            raise ValueError(f"export_timeout_s must be > 0, got {export_timeout_s!r}")
        if not poll_interval_s > 0:
            raise ValueError(f"poll_interval_s must be > 0, got {poll_interval_s!r}")
        self.root = Path(root)
        self.chip = chip
        self.channel = channel
        self.io = io if io is not None else OsSysfsIO()
        self.clock = clock if clock is not None else _SystemClock()
        self.export_timeout_s = float(export_timeout_s)
        self.poll_interval_s = float(poll_interval_s)

    def __repr__(self) -> str:
        return f"SysfsPwm({str(self.root)!r}, chip={self.chip}, channel={self.channel})"

    # ---- paths

    @property
    def chip_dir(self) -> Path:
        """``<root>/pwmchip<chip>``."""
        return self.root / f"pwmchip{self.chip}"

    @property
    def channel_dir(self) -> Path:
        """``<root>/pwmchip<chip>/pwm<channel>``."""
        return self.chip_dir / f"pwm{self.channel}"

    # ---- raw access with clear errors

    def _read(self, path: Path) -> str:
        try:
            return self.io.read(path)
        except OSError as e:
            raise PwmError(f"reading {path} failed: {e.strerror or e}", path, e.errno) from e

    def _read_int(self, name: str) -> int:
        path = self.channel_dir / name
        text = self._read(path)
        try:
            return int(text.strip())
        except ValueError:
            raise PwmError(f"{path} holds {text!r}, not an integer", path) from None

    def _write(self, path: Path, value: Any) -> None:
        try:
            self.io.write(path, f"{value}\n")
        except OSError as e:
            hint = _HINTS.get(e.errno or 0, "")
            msg = f"writing {value!r} to {path} failed: {e.strerror or e}"
            raise PwmError(msg + (f" ({hint})" if hint else ""), path, e.errno) from e

    def _write_checked(self, name: str, value: Any) -> None:
        """Write ``value`` to attribute ``name`` and verify the read-back."""
        path = self.channel_dir / name
        self._write(path, value)
        got = self._read(path).strip()
        if got != str(value):
            raise PwmError(f"wrote {value!r} to {path} but read back {got!r}", path)

    # ---- export

    def check_present(self) -> None:
        """Raise :class:`PwmError` if the PWM chip directory is missing."""
        if not self.chip_dir.is_dir():
            raise PwmError(
                f"no PWM chip at {self.chip_dir} (on a Raspberry Pi enable it with "
                "'dtoverlay=pwm' in config.txt)",
                self.chip_dir,
                _errno.ENOENT,
            )
        npwm_path = self.chip_dir / "npwm"
        try:
            npwm = int(self._read(npwm_path).strip())
        except (ValueError, PwmError):
            return  # npwm is informative only; export reports a bad channel too
        if self.channel >= npwm:
            raise PwmError(f"channel {self.channel} does not exist: {npwm_path} says {npwm}", npwm_path)

    @property
    def is_exported(self) -> bool:
        """Whether ``pwm<channel>`` exists."""
        return self.channel_dir.is_dir()

    def _ready(self) -> bool:
        p = self.channel_dir / "enable"
        return p.exists() and os.access(p, os.W_OK)

    def open(self) -> None:
        """Export the channel if needed and wait until its files are writable."""
        self.check_present()
        if not self.is_exported:
            try:
                self._write(self.chip_dir / "export", self.channel)
            except PwmError as e:
                if e.errno != _errno.EBUSY:  # EBUSY: exported meanwhile by someone else
                    raise
        deadline = self.clock.monotonic() + self.export_timeout_s
        while not self._ready():
            if self.clock.monotonic() >= deadline:
                raise PwmError(
                    f"{self.channel_dir} did not become writable within {self.export_timeout_s} s "
                    "after export",
                    self.channel_dir / "enable",
                )
            self.clock.sleep(self.poll_interval_s)

    def unexport(self) -> None:
        """Disable the channel, then unexport it."""
        if self.is_exported:
            self.disable()
            self._write(self.chip_dir / "unexport", self.channel)

    def close(self, *, unexport: bool = False) -> None:
        """Disable the output (and unexport the channel if asked)."""
        if unexport:
            self.unexport()
        elif self.is_exported:
            self.disable()

    def __enter__(self) -> SysfsPwm:
        self.open()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ---- reading

    def read_state(self) -> PwmState:
        """Read period, duty cycle, enable and polarity."""
        pol_path = self.channel_dir / "polarity"
        try:
            polarity = self._read(pol_path).strip()
        except PwmError:
            polarity = "normal"  # some controllers do not expose polarity
        return PwmState(
            self._read_int("period"), self._read_int("duty_cycle"), self._read_int("enable") == 1, polarity
        )

    @property
    def period_ns(self) -> int:
        """Current period (ns)."""
        return self._read_int("period")

    @property
    def duty_ns(self) -> int:
        """Current duty cycle, i.e. active time per period (ns)."""
        return self._read_int("duty_cycle")

    @property
    def enabled(self) -> bool:
        """Whether the output is enabled."""
        return self._read_int("enable") == 1

    # ---- writing

    def configure(self, period_ns: int, duty_ns: int) -> None:
        """Set period and duty cycle (ns) in an order the kernel accepts."""
        period_ns = _check_ns("period_ns", period_ns, positive=True)
        duty_ns = _check_ns("duty_ns", duty_ns, positive=False)
        if duty_ns > period_ns:
            raise ValueError(f"duty_ns ({duty_ns}) must be <= period_ns ({period_ns})")
        old_period = self.period_ns
        old_duty = self.duty_ns
        if old_period == 0 or period_ns >= old_period:
            # Growing: the old duty cycle still fits the new period.
            if period_ns != old_period:
                self._write_checked("period", period_ns)
            if duty_ns != old_duty:
                self._write_checked("duty_cycle", duty_ns)
        else:
            # Shrinking: bring the duty cycle under the new period first.
            if duty_ns != old_duty:
                self._write_checked("duty_cycle", duty_ns)
            self._write_checked("period", period_ns)

    def set_duty_ns(self, duty_ns: int) -> None:
        """Set the duty cycle (ns); must not exceed the current period."""
        duty_ns = _check_ns("duty_ns", duty_ns, positive=False)
        period = self.period_ns
        if period == 0:
            raise PwmError(f"cannot set duty cycle: {self.channel_dir / 'period'} is 0; set a period first",
                           self.channel_dir / "period")
        if duty_ns > period:
            raise ValueError(f"duty_ns ({duty_ns}) must be <= the period ({period} ns)")
        self._write_checked("duty_cycle", duty_ns)

    def set_duty_fraction(self, fraction: float) -> int:
        """Set the duty cycle as a fraction 0..1 of the current period; return it in ns."""
        f = float(fraction)
        if not 0.0 <= f <= 1.0:
            raise ValueError(f"fraction must be in [0, 1], got {fraction!r}")
        period = self.period_ns
        duty = min(period, int(round(f * period)))
        self.set_duty_ns(duty)
        return duty

    def enable(self) -> None:
        """Enable the output; the period must be set."""
        if self.period_ns == 0:
            raise PwmError(f"cannot enable {self.channel_dir}: period is 0; set a period first",
                           self.channel_dir / "period")
        self._write_checked("enable", 1)

    def disable(self) -> None:
        """Disable the output (no write if it is already disabled)."""
        if self.enabled:
            self._write_checked("enable", 0)

    def set_polarity(self, polarity: str) -> None:
        """Set ``"normal"`` or ``"inversed"`` polarity (only while disabled)."""
        if polarity not in ("normal", "inversed"):
            raise ValueError(f"polarity must be 'normal' or 'inversed', got {polarity!r}")
        if self.enabled:
            raise PwmError(f"disable {self.channel_dir} before changing its polarity",
                           self.channel_dir / "polarity")
        self._write_checked("polarity", polarity)
