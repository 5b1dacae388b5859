"""A touch as the probe recorded it: the one input of the estimate seam.

:class:`TouchRecord` is what the device measured and what it knew while it
measured -- raw sample times, thermocouple and flux readings exactly as the
converters gave them, the heater-on instant, the heater's power, the baseline
(pre-contact) part, the probe head, the sample clock and the sensors' known
read-out properties. Nothing in it is derived by an estimator: the device
builds it at the end of a touch, ``history --export-series`` writes it (every
scalar field in the series' header, :data:`HEADER_FIELDS`), ``thermotouch
estimate`` reads it back, and :func:`edge.estimation.seam.estimate_touch`
(the one estimate path) turns it into one typed estimate. Because the record
carries everything the device used, re-estimating an exported touch
reproduces the device's answer.

Times are relative to the heater-on instant (baseline samples negative). When
the heater never went on, ``heater_on_t_s`` is None and times are relative to
the first sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Mapping

import numpy as np

__all__ = ["TouchRecord", "HEADER_FIELDS", "RecordError"]


class RecordError(ValueError):
    """A touch record that cannot be estimated as it stands (one line naming what is wrong)."""


def _array(name: str, v: Any) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim != 1:
        raise RecordError(f"{name} must be one-dimensional, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise RecordError(f"{name} has a value that is not a finite number")
    a = a.copy()
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class TouchRecord:
    """One touch, raw (SI units; temperatures in °C as the thermocouple converter reports them).

    Parameters
    ----------
    probe : str
        The probe head that took it (a name in :data:`edge.physics.geometry.PROBES`).
    t_s : array
        Sample times, s, relative to the heater-on instant (baseline negative).
    T_C : array
        Thermocouple readings, °C, as recorded.
    q_W_m2 : array
        Flux-sensor readings, W/m², as recorded (datasheet sensitivity, no offset removed).
    power_W : float
        Heater power the device drove, W.
    heater_on_s : float
        How long the heater was on, s (0: it never went on).
    sample_rate_Hz : float
        The sample clock.
    baseline_s : float
        The part before heating used as the baseline, s (armed runs: the last ``baseline_s``).
    method : str
        The requested estimation method (``"default"`` or ``"paper"``; probes with one method ignore it).
    T_age_s : float
        The thermocouple reading's age at its time stamp (converter lag), s.
    T_resolution_K : float
        The thermometer's resolution, K.
    saturated : bool
        Whether an ADC clipped during the run.
    T_dt_s, q_dt_s : array or None
        Each sample's thermocouple and flux read time relative to ``t_s``, s (None: not recorded).
    arm_s : float
        Armed runs: the arming time asked for (0: not armed).
    contact_detected_s : float or None
        Armed runs: when contact was detected, s after arming.
    meta : mapping
        Identity that does not change the estimate (measurement id, started_utc, device, software).
    """

    probe: str
    t_s: np.ndarray
    T_C: np.ndarray
    q_W_m2: np.ndarray
    power_W: float
    heater_on_s: float
    sample_rate_Hz: float
    baseline_s: float
    method: str = "default"
    T_age_s: float = 0.0
    T_resolution_K: float = 0.0
    saturated: bool = False
    T_dt_s: np.ndarray | None = None
    q_dt_s: np.ndarray | None = None
    arm_s: float = 0.0
    contact_detected_s: float | None = None
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("t_s", "T_C", "q_W_m2"):
            set_(self, name, _array(name, getattr(self, name)))
        n = self.t_s.size
        for name in ("T_C", "q_W_m2"):
            if getattr(self, name).size != n:
                raise RecordError(f"{name} has {getattr(self, name).size} samples, t_s has {n}")
        if n >= 2 and not np.all(np.diff(self.t_s) > 0):
            raise RecordError("t_s must be strictly increasing")
        for name in ("T_dt_s", "q_dt_s"):
            v = getattr(self, name)
            if v is not None:
                a = _array(name, v)
                if a.size != n:
                    raise RecordError(f"{name} has {a.size} samples, t_s has {n}")
                set_(self, name, a)
        for name in ("power_W", "sample_rate_Hz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise RecordError(f"{name} must be a finite number > 0, got {v!r}")
        for name in ("heater_on_s", "baseline_s", "T_age_s", "T_resolution_K", "arm_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise RecordError(f"{name} must be a finite number >= 0, got {v!r}")
        if not isinstance(self.probe, str) or not self.probe:
            raise RecordError(f"probe must be a probe head's name, got {self.probe!r}")
        set_(self, "meta", dict(self.meta))

    @property
    def heater_on_t_s(self) -> float | None:
        """The heater-on instant on the record's time axis (0.0), or None when it never went on."""
        return 0.0 if self.heater_on_s > 0 else None

    def header(self) -> dict[str, Any]:
        """The scalar fields (and ``meta``) as written in an exported series' header."""
        out = {name: getattr(self, name) for name in HEADER_FIELDS}
        out.update(self.meta)
        return out

    @classmethod
    def from_header(cls, header: Mapping[str, Any], t_s, T_C, q_W_m2, T_dt_s=None, q_dt_s=None) -> "TouchRecord":
        """A record from an export's header (strings or values) and its columns; unknown keys go to ``meta``."""
        kinds = {f.name: f.type for f in fields(cls)}
        kw: dict[str, Any] = {}
        meta: dict[str, Any] = {}
        for key, raw in header.items():
            if key not in HEADER_FIELDS:
                meta[key] = raw
                continue
            kw[key] = _parse(key, kinds[key], raw)
        missing = [k for k in _REQUIRED if k not in kw]
        if missing:
            raise RecordError(f"header lacks {', '.join(missing)}")
        return cls(t_s=t_s, T_C=T_C, q_W_m2=q_W_m2, T_dt_s=T_dt_s, q_dt_s=q_dt_s, meta=meta, **kw)


#: The scalar fields an exported series carries in its header, in this order.
HEADER_FIELDS = ("probe", "power_W", "heater_on_s", "sample_rate_Hz", "baseline_s", "method", "T_age_s",
                 "T_resolution_K", "saturated", "arm_s", "contact_detected_s")
_REQUIRED = ("probe", "power_W", "heater_on_s", "sample_rate_Hz", "baseline_s")


def _parse(key: str, kind: str, raw: Any) -> Any:
    """One header value from its text (or a value already typed)."""
    if not isinstance(raw, str):
        return raw
    text = raw.strip()
    if "bool" in kind:
        if text.lower() in ("true", "1", "yes"):
            return True
        if text.lower() in ("false", "0", "no"):
            return False
        raise RecordError(f"header {key}: expected true or false, got {raw!r}")
    if "float" in kind:
        if text.lower() in ("", "none", "null") and "None" in kind:
            return None
        try:
            return float(text)
        except ValueError:
            raise RecordError(f"header {key}: expected a number, got {raw!r}") from None
    return text
