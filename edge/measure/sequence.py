"""The measurement sequence and the heater's safety net.

One touch runs::

    idle -> baseline -> heating -> (heater off) -> resampling -> estimating -> done

* **baseline** (``baseline_s``, heater off): T0 is the mean thermocouple
  reading and the flux offset the mean flux reading; their spread and drift
  give the ``noisy`` and ``unstable_baseline`` flags.
* **heating**: the heater runs at the requested power for the contact time
  while the sensors are sampled at ``sample_rate_Hz`` on the board clock
  (the simulator's virtual clock makes a 2-s touch take milliseconds).
* **heater off**, then the raw series are resampled onto a uniform grid
  with a cubic spline (edge.estimation.spline) and handed to the estimator, whose crash can
  no longer leave the heater on.

Safety (the heater can burn)
----------------------------
* Every exit from the heating phase -- normal end, exception, sensor fault,
  ``KeyboardInterrupt``/``SystemExit``, the abort event set by SIGTERM/SIGINT
  or a daemon stop -- passes a ``finally`` that switches the heater off.
* The heating time is clamped to ``max_on_time_s`` whatever is requested
  (hard cap on the request), and the sampling loop stops heating before a
  sample whose read could end past the limit (watchdog check in the loop,
  using the slowest read seen so far as the margin).
* :class:`HeaterWatchdog` is independent of the loop: a thread (and, on a
  clock that can notify time steps such as the simulator's, a clock hook)
  cuts the heater ``guard_s`` before ``max_on_time_s`` and at once when the
  abort event is set, even while the loop is stuck in a driver call.
* A thermocouple reading above ``over_temperature_C`` or an open
  thermocouple (SensorFault ``open_thermocouple``) cuts the heater at once.
* A cool-down between touches (``cooldown_s``) is enforced on the board clock.

Nothing here imports the simulator; sensors are reached through the board.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from edge.physics.probe import HEATER_AREA_m2, volumetric_heat_W_m3
from edge.hw.drivers.heater import Heater, HeaterOffError
from edge.hw.faults import SensorFault
from edge.storage.history import utc_now
from edge.estimation.spline import resample

__all__ = [
    "Reading",
    "ProbeSensors",
    "make_sensors",
    "HeaterWatchdog",
    "resample_uniform",
    "quality_flags",
    "Limits",
    "MeasurementParams",
    "Outcome",
    "MeasurementSequence",
    "EstimatorFn",
    "QUALITY_FLAGS",
]

log = logging.getLogger(__name__)

#: Flags a record can carry (the estimator may add more).
QUALITY_FLAGS = ("no_contact", "saturated", "noisy", "unstable_baseline", "outside_training_range")

#: ``estimator(t_s, dT_K, q_W_m2, q_v_W_m3, method) -> JSON-able dict`` (see edge.estimation.estimate).
EstimatorFn = Callable[[np.ndarray, np.ndarray, np.ndarray, float, str], Mapping[str, Any]]


# --------------------------------------------------------------------------
# Sensors


@dataclass(frozen=True)
class Reading:
    """One sample: thermocouple (°C), heat flux (W/m^2), and whether an ADC clipped."""

    T_C: float
    q_W_m2: float
    saturated: bool = False


class ProbeSensors:
    """Reads the thermocouple and the flux sensor through the chip drivers.

    Parameters
    ----------
    read_T : callable () -> (float °C, bool saturated)
    read_q_V : callable () -> (float V, bool saturated)
    flux_sensitivity_V_per_W_m2 : float
    """

    def __init__(self, read_T: Callable[[], tuple[float, bool]], read_q_V: Callable[[], tuple[float, bool]],
                 flux_sensitivity_V_per_W_m2: float, *, description: str = "", T_age_s: float = 0.0) -> None:
        if not flux_sensitivity_V_per_W_m2 > 0:
            raise ValueError(f"flux_sensitivity_V_per_W_m2 must be > 0, got {flux_sensitivity_V_per_W_m2!r}")
        if not T_age_s >= 0:
            raise ValueError(f"T_age_s must be >= 0, got {T_age_s!r}")
        #: Mean age (s) of a temperature reading when it is read: a converter that
        #: converts continuously holds a value taken one conversion time ago on average.
        self.T_age_s = float(T_age_s)
        self._read_T = read_T
        self._read_q_V = read_q_V
        self.sensitivity = float(flux_sensitivity_V_per_W_m2)
        self.description = description

    def read(self) -> Reading:
        """One reading of both sensors (SensorFault on failure)."""
        T, sat_T = self._read_T()
        v, sat_q = self._read_q_V()
        return Reading(float(T), float(v) / self.sensitivity, bool(sat_T or sat_q))


def make_sensors(board: Any, sensors_cfg: Any) -> ProbeSensors:
    """Build :class:`ProbeSensors` for the chips named in the ``[sensors]`` config section.

    Probes and configures each chip (SensorFault if one does not answer).
    """
    from edge.hw.drivers.ads1115 import ADS1115  # noqa: PLC0415 - only what is fitted
    from edge.hw.drivers.ads122c04 import ADS122C04  # noqa: PLC0415
    from edge.hw.drivers.mcp9600 import MCP9600  # noqa: PLC0415

    s = sensors_cfg
    bus, sleep = board.i2c, board.clock.sleep
    if bus is None:
        raise SensorFault("i2c", "not_found", "the board has no I2C bus")
    kw = dict(attempts=s.i2c_attempts, sleep=sleep)
    ads122 = None

    def get_ads122() -> Any:
        nonlocal ads122
        if ads122 is None:
            ads122 = ADS122C04(bus, s.ads122c04_address, on_saturation="flag", **kw)
            ads122.reset()
            ads122.configure(gain=s.ads122c04_gain, data_rate_sps=s.ads122c04_data_rate_sps)
        return ads122

    if s.thermocouple == "mcp9600":
        mcp = MCP9600(bus, s.mcp9600_address, **kw)
        mcp.probe()
        mcp.configure(adc_resolution_bits=s.mcp9600_adc_bits)

        def read_T() -> tuple[float, bool]:
            return mcp.read_hot_junction_C(), False
        T_age_s = mcp.conversion_time_s
    else:
        T_age_s = 0.0  # single-shot conversions, read when done
        adc = get_ads122()

        def read_T() -> tuple[float, bool]:
            t = adc.read_thermocouple_C("AIN0_AIN1", s.ads122c04_gain)
            return t, adc.saturated

    if s.flux_adc == "ads1115":
        ads = ADS1115(bus, s.ads1115_address, on_saturation="flag", **kw)
        ads.configure(mux="AIN0_AIN1", fsr_V=s.ads1115_fsr_V, data_rate_sps=s.ads1115_data_rate_sps)

        def read_q() -> tuple[float, bool]:
            v = ads.read_single_shot_V()
            return v, ads.saturated
    else:
        adc2 = get_ads122()

        def read_q() -> tuple[float, bool]:
            v = adc2.read_flux_voltage_V("AIN2_AIN3", s.ads122c04_gain)
            return v, adc2.saturated

    return ProbeSensors(read_T, read_q, s.flux_sensitivity_V_per_W_m2, T_age_s=T_age_s,
                        description=f"thermocouple={s.thermocouple} flux={s.flux_adc}")


# --------------------------------------------------------------------------
# Watchdog


class HeaterWatchdog:
    """Cuts the heater independently of the sampling loop.

    While armed it switches the heater off when its current on-time reaches
    ``limit_s - guard_s`` or when ``abort_event`` is set. It checks from its
    own thread every ``poll_s`` of wall time and, if ``clock`` has
    ``on_advance`` (the simulator's virtual clock), on every clock step.

    Parameters
    ----------
    heater : Heater
    clock : Clock
    limit_s : float
        The on-time limit (s).
    abort_event : threading.Event, optional
    guard_s : float
        Margin below the limit (s) that covers the check resolution.
    poll_s : float
        Wall-clock polling period (s).
    """

    def __init__(self, heater: Heater, clock: Any, limit_s: float, *, abort_event: threading.Event | None = None,
                 guard_s: float = 0.02, poll_s: float = 0.005) -> None:
        if not limit_s > guard_s >= 0:
            raise ValueError(f"need limit_s > guard_s >= 0, got limit_s={limit_s!r} guard_s={guard_s!r}")
        self.heater = heater
        self.clock = clock
        self.limit_s = float(limit_s)
        self.guard_s = float(guard_s)
        self.poll_s = float(poll_s)
        self.abort_event = abort_event
        self._armed = False
        self._stop = threading.Event()
        self._lock = threading.Lock()
        #: Why the watchdog last cut the heater ('max_on_time', 'abort') or None.
        self.tripped: str | None = None
        on_advance = getattr(clock, "on_advance", None)
        if callable(on_advance):
            on_advance(lambda _old, _new: self.check())
        self._thread = threading.Thread(target=self._run, name="heater-watchdog", daemon=True)
        self._thread.start()

    def arm(self) -> None:
        """Start watching (call right before switching the heater on)."""
        with self._lock:
            self.tripped = None
            self._armed = True

    def disarm(self) -> None:
        """Stop watching (after the heater is off)."""
        with self._lock:
            self._armed = False

    def check(self) -> str | None:
        """One check; cuts the heater and returns the reason if a limit is hit."""
        with self._lock:
            if not self._armed:
                return None
        reason = None
        if self.abort_event is not None and self.abort_event.is_set():
            reason = "abort"
        elif self.heater.current_on_time_s >= self.limit_s - self.guard_s:
            reason = "max_on_time"
        if reason is None:
            return None
        try:
            self.heater.off()
        except HeaterOffError:
            log.critical("watchdog (%s): switching the heater off failed", reason)
        with self._lock:
            if self._armed and self.tripped is None:
                self.tripped = reason
                log.warning("watchdog cut the heater: %s", reason)
        return reason

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
            try:
                self.check()
            except Exception:  # never let the watchdog thread die
                log.exception("heater watchdog check failed")

    def close(self) -> None:
        """Stop the thread (the clock hook stays registered but is disarmed)."""
        self.disarm()
        self._stop.set()
        self._thread.join(timeout=2.0)


# --------------------------------------------------------------------------
# Resampling


def resample_uniform(t_s: np.ndarray, T_C: np.ndarray, q_W_m2: np.ndarray, T0_C: float, q_offset_W_m2: float,
                     rate_Hz: float, t_end_s: float, T_age_s: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heating-phase series on the grid ``k / rate_Hz``, k = 1 .. floor(t_end * rate).

    ``t_s`` is time since heater-on; samples with ``t_s < 0`` (baseline) are
    ignored. The temperature rise is anchored at ``(0, 0)`` (temperature is
    continuous at switch-on; flux is not, so it is not anchored).  Temperature
    readings are placed ``T_age_s`` before they were read (the converter's
    sampling lag), which would otherwise bias e upwards by several percent.

    Returns ``(t_s, dT_K, q_W_m2)`` with the flux offset removed.
    """
    t_s = np.asarray(t_s, float)
    heat = t_s >= 0
    th, Th, qh = t_s[heat], np.asarray(T_C, float)[heat], np.asarray(q_W_m2, float)[heat]
    if th.size < 2:
        raise ValueError(f"need at least 2 heating samples to resample, got {th.size}")
    tT, dT = th - T_age_s, Th - T0_C
    keep = tT > 0  # a reading taken before heater-on belongs to the baseline
    tT, dT = tT[keep], dT[keep]
    if tT.size < 1:
        raise ValueError("no temperature reading taken after heater-on")
    tT, dT = np.concatenate(([0.0], tT)), np.concatenate(([0.0], dT))
    n = int(math.floor(t_end_s * rate_Hz + 1e-9))
    grid = np.arange(1, n + 1) / rate_Hz
    grid = grid[grid <= min(th[-1], tT[-1]) + 1e-9]  # interpolate, never extrapolate
    if grid.size < 2:
        raise ValueError("heating phase too short for the sample rate")
    dT_grid = resample(tT, dT, grid)
    q_grid = resample(th, qh - q_offset_W_m2, np.maximum(grid, th[0]))
    return grid, dT_grid, q_grid


# --------------------------------------------------------------------------
# Quality flags


def quality_flags(base_t: np.ndarray, base_T: np.ndarray, base_q: np.ndarray, heat_q: np.ndarray,
                  power_W: float, saturated: bool, thresholds: Any) -> list[str]:
    """Flags from the baseline and heating series (see the ``[measurement]`` thresholds)."""
    flags = []
    if heat_q.size and power_W > 0:
        q_in = float(np.mean(heat_q))
        if q_in < thresholds.no_contact_flux_fraction * power_W / HEATER_AREA_m2:
            flags.append("no_contact")
    if saturated:
        flags.append("saturated")
    if base_T.size >= 3:
        # Noise is the scatter about the baseline's trend; the trend itself is drift.
        x = base_t - base_t[0]
        span = float(x[-1])
        slope, resid_T = 0.0, base_T - np.mean(base_T)
        if span > 0:
            coef = np.polyfit(x, base_T, 1)
            slope, resid_T = float(coef[0]), base_T - np.polyval(coef, x)
        if float(np.std(resid_T)) > thresholds.noise_T_K or float(np.std(base_q)) > thresholds.noise_q_W_m2:
            flags.append("noisy")
        if abs(slope) * span > thresholds.unstable_baseline_K:
            flags.append("unstable_baseline")
    return flags


# --------------------------------------------------------------------------
# The sequence


@dataclass(frozen=True)
class Limits:
    """Safety limits: ``max_on_time_s`` (s) and ``over_temperature_C`` (°C)."""

    max_on_time_s: float
    over_temperature_C: float


@dataclass(frozen=True)
class MeasurementParams:
    """One measurement's settings (from the config, optionally overridden by MEASURE)."""

    power_W: float
    contact_time_s: float
    baseline_s: float
    sample_rate_Hz: float
    cooldown_s: float
    method: str = "default"

    def __post_init__(self) -> None:
        for name in ("power_W", "contact_time_s", "baseline_s", "sample_rate_Hz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        if not (math.isfinite(self.cooldown_s) and self.cooldown_s >= 0):
            raise ValueError(f"cooldown_s must be >= 0, got {self.cooldown_s!r}")


@dataclass
class Outcome:
    """What one run produced; :meth:`record` turns it into a history row.

    ``status`` is ``"ok"``, ``"aborted"`` (a safety cut or a stop: reason
    says which) or ``"failed"`` (sensor fault, estimator crash, bug).
    """

    status: str = "failed"
    reason: str | None = None
    error: str | None = None
    flags: list[str] = field(default_factory=list)
    result: dict[str, Any] | None = None
    started_utc: str = ""
    power_W: float = 0.0
    contact_time_s: float = 0.0
    heater_on_s: float = 0.0
    T0_C: float | None = None
    q_offset_W_m2: float | None = None
    sample_rate_Hz: float = 0.0
    model_sha256: str | None = None
    raw_t_s: np.ndarray | None = None
    raw_T_C: np.ndarray | None = None
    raw_q_W_m2: np.ndarray | None = None
    grid_t_s: np.ndarray | None = None
    grid_dT_K: np.ndarray | None = None
    grid_q_W_m2: np.ndarray | None = None
    compute_s: float | None = None
    exception: BaseException | None = None

    def record(self, config_snapshot: Mapping[str, Any]) -> dict[str, Any]:
        """Keyword set for :meth:`edge.storage.history.History.add`."""
        keys = ("status", "reason", "error", "flags", "result", "started_utc", "power_W", "contact_time_s",
                "heater_on_s", "T0_C", "q_offset_W_m2", "sample_rate_Hz", "model_sha256", "raw_t_s",
                "raw_T_C", "raw_q_W_m2", "grid_t_s", "grid_dT_K", "grid_q_W_m2")
        rec = {k: getattr(self, k) for k in keys}
        rec["config"] = dict(config_snapshot)
        return rec


class _Stop(Exception):
    """Internal: leave the heating loop for a safety reason."""

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason = reason
        super().__init__(detail or reason)


class MeasurementSequence:
    """Runs measurements on one heater + sensors pair.

    Parameters
    ----------
    heater : Heater
    sensors : object with ``read() -> Reading``
    clock : Clock
        The board clock (virtual in the simulator).
    limits : Limits
    estimator : EstimatorFn
        Called after the heater is off; any exception it raises becomes a
        ``failed`` outcome with the raw data kept.
    thresholds : namespace
        The ``[measurement]`` flag thresholds.
    watchdog : HeaterWatchdog, optional
        Built here (and closed by :meth:`close`) if not given.
    abort_event : threading.Event, optional
        Set to stop a running measurement (heater off within a sample period,
        or at once through the watchdog).
    model_sha256 : callable () -> str or None, optional
        Identity of the model the estimator uses, stored with the record.
    on_state : callable (str) -> None, optional
        Told each state change (for STATUS).
    """

    def __init__(self, heater: Heater, sensors: Any, clock: Any, limits: Limits, estimator: EstimatorFn,
                 thresholds: Any, *, watchdog: HeaterWatchdog | None = None,
                 abort_event: threading.Event | None = None,
                 model_sha256: Callable[[], str | None] | None = None,
                 on_state: Callable[[str], None] | None = None) -> None:
        self.heater = heater
        self.sensors = sensors
        self.clock = clock
        self.limits = limits
        self.estimator = estimator
        self.thresholds = thresholds
        self.abort_event = abort_event if abort_event is not None else threading.Event()
        self._own_watchdog = watchdog is None
        self.watchdog = watchdog if watchdog is not None else HeaterWatchdog(
            heater, clock, limits.max_on_time_s, abort_event=self.abort_event)
        self.model_sha256 = model_sha256 or (lambda: None)
        self.on_state = on_state or (lambda s: None)
        self.state = "idle"
        self._last_off: float | None = None
        self._max_read_s = 0.0

    def _set_state(self, s: str) -> None:
        self.state = s
        try:
            self.on_state(s)
        except Exception:
            log.exception("on_state callback failed")

    def close(self) -> None:
        """Heater off and the watchdog stopped (if this object built it)."""
        try:
            self.heater.off()
        finally:
            if self._own_watchdog:
                self.watchdog.close()

    # -- sampling ----------------------------------------------------------------------
    def _sample(self, ts: list, Ts: list, qs: list, sat: list) -> Reading:
        t0 = self.clock.monotonic()
        r = self.sensors.read()
        t1 = self.clock.monotonic()
        self._max_read_s = max(self._max_read_s, t1 - t0)
        ts.append(0.5 * (t0 + t1))  # board-clock time, made relative later
        Ts.append(r.T_C)
        qs.append(r.q_W_m2)
        sat.append(r.saturated)
        return r

    def _check_temperature(self, r: Reading) -> None:
        if not math.isfinite(r.T_C):
            raise _Stop("sensor_fault", f"thermocouple reading is {r.T_C}")
        if r.T_C > self.limits.over_temperature_C:
            raise _Stop("over_temperature",
                        f"thermocouple {r.T_C:.2f} °C above the {self.limits.over_temperature_C} °C limit")

    def _wait(self, until: float) -> None:
        """Sleep on the board clock until ``until``, in steps, watching the abort event."""
        while True:
            if self.abort_event.is_set():
                raise _Stop("stopped", "measurement stopped (daemon shutting down)")
            dt = until - self.clock.monotonic()
            if dt <= 0:
                return
            self.clock.sleep(min(dt, 0.05))

    # -- the run ---------------------------------------------------------------------
    def run(self, params: MeasurementParams) -> Outcome:
        """Run one measurement; never returns with the heater on.

        Returns an :class:`Outcome` for everything except BaseExceptions
        (KeyboardInterrupt, SystemExit), which propagate after the heater is
        off. A :class:`~edge.hw.drivers.heater.HeaterOffError` is reported as a
        failed outcome with reason ``heater_fault``.
        """
        out = Outcome(started_utc=utc_now(), power_W=params.power_W,
                      contact_time_s=params.contact_time_s, sample_rate_Hz=params.sample_rate_Hz)
        period = 1.0 / params.sample_rate_Hz
        # Hard cap on the request, below the watchdog's trip point.
        heat_s = min(params.contact_time_s, self.limits.max_on_time_s - 2 * self.watchdog.guard_s)
        if heat_s < params.contact_time_s:
            log.warning("contact_time_s=%g s clamped to %g s by max_on_time_s", params.contact_time_s, heat_s)
        ts: list[float] = []
        Ts: list[float] = []
        qs: list[float] = []
        sat: list[bool] = []
        on_before = self.heater.on_time_s
        t_on = t_off = None
        try:
            try:
                if self.abort_event.is_set():
                    raise _Stop("stopped", "measurement stopped before it started")
                if self._last_off is not None and params.cooldown_s > 0:
                    self._set_state("cooldown")
                    self._wait(self._last_off + params.cooldown_s)
                # ---- baseline
                self._set_state("baseline")
                t_base = self.clock.monotonic()
                n_base = max(3, int(round(params.baseline_s * params.sample_rate_Hz)))
                for k in range(n_base):
                    self._wait(t_base + k * period)
                    self._check_temperature(self._sample(ts, Ts, qs, sat))
                self._wait(t_base + n_base * period)
                # ---- heating
                self._set_state("heating")
                self.watchdog.arm()
                t_on = self.clock.monotonic()
                self.heater.on_power(params.power_W)
                guard = self.watchdog.guard_s
                for k in range(int(math.floor(heat_s * params.sample_rate_Hz + 1e-9)) + 1):
                    self._wait(t_on + k * period)
                    if not self.heater.is_on:
                        why = {"abort": "stopped"}.get(self.watchdog.tripped, self.watchdog.tripped)
                        raise _Stop(why or "heater_cut", f"heater was cut by the watchdog ({why})")
                    on_s = self.clock.monotonic() - t_on
                    # Watchdog in the loop: no read may end past the limit.
                    if on_s + self._max_read_s >= self.limits.max_on_time_s - guard:
                        if on_s >= heat_s - period:
                            break  # within a sample of the end anyway
                        raise _Stop("max_on_time", "sensor reads too slow to stay within "
                                    f"max_on_time_s={self.limits.max_on_time_s} s")
                    r = self._sample(ts, Ts, qs, sat)
                    if self.clock.monotonic() - t_on > self.limits.max_on_time_s:
                        raise _Stop("max_on_time", "a sensor read ended past max_on_time_s")
                    self._check_temperature(r)
                self._wait(t_on + heat_s)
                self.heater.off()
                t_off = self.clock.monotonic()
                self.watchdog.disarm()
            except _Stop as e:
                out.status = "failed" if e.reason == "sensor_fault" else "aborted"
                out.reason, out.error = e.reason, str(e)
                log.warning("measurement %s: %s", out.status, e)
            except SensorFault as e:
                out.status = "failed"
                out.reason = "open_thermocouple" if e.reason == "open_thermocouple" else "sensor_fault"
                out.error, out.exception = str(e), e
                log.error("measurement failed: %s", e)
            except HeaterOffError:
                raise
            except Exception as e:  # a bug or an unexpected driver error: heater off, keep the data
                out.status, out.reason = "failed", "internal"
                out.error, out.exception = f"{type(e).__name__}: {e}", e
                log.exception("measurement failed")
            finally:
                # Every path, including BaseException, passes here with the heater switched off.
                try:
                    self.heater.off()
                finally:
                    self.watchdog.disarm()
                    if t_on is not None:
                        self._last_off = self.clock.monotonic()
                        if t_off is None:
                            t_off = self._last_off
        except HeaterOffError as e:
            out.status, out.reason = "failed", "heater_fault"
            out.error, out.exception = str(e), e
            log.critical("heater fault: %s", e)
        out.heater_on_s = self.heater.on_time_s - on_before
        t_arr, T_arr, q_arr = np.array(ts, float), np.array(Ts, float), np.array(qs, float)
        # Times relative to heater-on (baseline negative); without heating, to the first sample.
        if t_on is not None:
            t_arr -= t_on
        elif t_arr.size:
            t_arr -= t_arr[-1] + 1.0
        out.raw_t_s, out.raw_T_C, out.raw_q_W_m2 = t_arr, T_arr, q_arr
        if out.status != "failed" or out.reason != "heater_fault":
            self._finish(out, params, t_arr, T_arr, q_arr, any(sat), t_on, t_off)
        self._set_state("idle")
        return out

    def _finish(self, out: Outcome, params: MeasurementParams, t: np.ndarray, T: np.ndarray, q: np.ndarray,
                saturated: bool, t_on: float | None, t_off: float | None) -> None:
        """Baseline statistics, flags, resampling and estimation (heater already off)."""
        c0 = time.perf_counter()
        base = t < 0 if t_on is not None else np.ones(t.shape, bool)
        if base.any():
            out.T0_C = float(np.mean(T[base]))
            out.q_offset_W_m2 = float(np.mean(q[base]))
        heat_q = q[~base] - (out.q_offset_W_m2 or 0.0)
        out.flags = quality_flags(t[base], T[base], q[base], heat_q, params.power_W, saturated, self.thresholds)
        if out.status != "ok" and out.reason is not None:
            # Don't estimate from a cut-short or faulty run; the raw data is kept.
            return
        out.status = "ok"
        self._set_state("resampling")
        try:
            g_t, g_dT, g_q = resample_uniform(t, T, q, out.T0_C, out.q_offset_W_m2, params.sample_rate_Hz,
                                              t_off - t_on, getattr(self.sensors, "T_age_s", 0.0))
        except ValueError as e:
            out.status, out.reason, out.error = "failed", "too_few_samples", str(e)
            return
        out.grid_t_s, out.grid_dT_K, out.grid_q_W_m2 = g_t, g_dT, g_q
        self._set_state("estimating")
        try:
            out.model_sha256 = self.model_sha256()
        except Exception:
            out.model_sha256 = None
        try:
            res = dict(self.estimator(g_t, g_dT, g_q, volumetric_heat_W_m3(params.power_W), params.method))
        except Exception as e:
            out.status, out.reason = "failed", "estimation_failed"
            out.error, out.exception = f"{type(e).__name__}: {e}", e
            log.exception("estimation failed (heater was already off)")
            return
        finally:
            out.compute_s = time.perf_counter() - c0
        out.result = res
        out.model_sha256 = res.get("model_sha256", out.model_sha256)
        for f in res.get("flags", []) or []:
            if isinstance(f, str) and f not in out.flags:
                out.flags.append(f)
