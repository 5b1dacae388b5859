"""Argument policy and reply sizing for the daemon's requests -- pure functions, no daemon state.

The protocol layer (:mod:`edge.protocol.messages`) has already checked each
argument's type and range; what is decided here needs the device's
configuration or the frame size:

* MEASURE: :func:`measure_params` turns the optional ``power_W`` /
  ``voltage_V`` / ``contact_time_s`` into :class:`MeasurementParams` within
  the heater's limits.
* RESULT, HISTORY, SERIES, CONFIG_GET/SET: a reply must fit one frame, so
  :func:`fit_record` trims a record, :func:`history_page` and
  :func:`series_page` return as much of a page as fits (the host continues
  from where the reply ends), :func:`config_reply` falls back to the
  runtime keys.
"""

from __future__ import annotations

import json
import math
from typing import Any, Mapping

import numpy as np

from edge.hw import chips
from edge.hw.chips import max_sample_rate_Hz  # the MEASURE rate cap, re-exported for callers
from edge.physics.probe import heater_power_W
from edge.measure.sequence import MeasurementParams
from edge.measure.signal import min_contact_time_s
from edge.protocol.errors import CommandError, ErrorCode
from edge.service.config import RUNTIME_KEYS, Config
from edge.storage.history import series_header

__all__ = ["REPLY_MARGIN", "SERIES_COLUMNS", "max_sample_rate_Hz", "measure_params", "fit_record", "history_page", "series_page",
           "config_reply"]

#: Bytes kept free in a reply for the frame's JSON envelope.
REPLY_MARGIN = 256
#: SERIES reply names and History columns, per ``which``.
SERIES_COLUMNS = {"raw": (("t_s", "raw_t_s"), ("T_C", "raw_T_C"), ("q_W_m2", "raw_q_W_m2"),
                           ("T_dt_s", "raw_T_dt_s"), ("q_dt_s", "raw_q_dt_s")),
                  "grid": (("t_s", "grid_t_s"), ("dT_K", "grid_dT_K"), ("q_W_m2", "grid_q_W_m2"))}


def measure_params(config: Config, max_power_W: float, *, power_W: float | None = None,
                   voltage_V: float | None = None, contact_time_s: float | None = None,
                   sample_rate_Hz: float | None = None, until_decided: bool = False,
                   arm_s: float | None = None, settle_s: float | None = None) -> MeasurementParams:
    """One measurement's settings: the configuration, overridden by MEASURE's arguments.

    Parameters
    ----------
    config : Config
        The daemon's current configuration.
    max_power_W : float
        The heater's maximum power (full duty at the supply voltage).
    power_W, voltage_V : float, optional
        Heater power, or the voltage to apply at full duty (it wins over
        ``power_W``); default ``heater.power_W``.
    contact_time_s : float, optional
        Heating time; default ``measurement.contact_time_s``.
    sample_rate_Hz : float, optional
        Sampling rate; default ``measurement.sample_rate_Hz``. A rate above
        :func:`max_sample_rate_Hz` of the fitted converters is capped there
        (the record's ``sample_rate_Hz`` is the rate used).
    until_decided : bool
        Stop heating once the running answer is decided.
    arm_s, settle_s : float, optional
        Armed measurement (see :class:`edge.measure.sequence.MeasurementParams`); default
        ``measurement.arm_s`` / ``measurement.settle_s``.

    Returns
    -------
    MeasurementParams

    Raises
    ------
    CommandError
        BAD_ARGUMENT for a voltage above the supply, a power above the
        heater's maximum, or a contact time not below ``heater.max_on_time_s`` or
        below :func:`edge.measure.signal.min_contact_time_s`.
    """
    h, m = config.heater, config.measurement
    if voltage_V is not None:
        if voltage_V > h.supply_voltage_V:
            raise CommandError(ErrorCode.BAD_ARGUMENT, f"voltage_V={voltage_V} exceeds the supply "
                               f"{h.supply_voltage_V} V", "voltage_V")
        power_W = heater_power_W(1.0, voltage_V, h.resistance_ohm)
    power = h.power_W if power_W is None else power_W
    if power > max_power_W * (1 + 1e-12):  # rounding: a full-duty power computed elsewhere is not "above"
        raise CommandError(ErrorCode.BAD_ARGUMENT, f"power_W={power} exceeds the heater's maximum "
                           f"{max_power_W:.4g} W", "power_W")
    contact = m.contact_time_s if contact_time_s is None else contact_time_s
    if contact >= h.max_on_time_s:
        raise CommandError(ErrorCode.BAD_ARGUMENT, f"contact_time_s={contact} must be below "
                           f"heater.max_on_time_s={h.max_on_time_s}", "contact_time_s")
    if contact > h.max_duty * h.duty_window_s:
        raise CommandError(ErrorCode.BAD_ARGUMENT, f"contact_time_s={contact} exceeds the duty limit "
                           f"heater.max_duty x duty_window_s = {h.max_duty * h.duty_window_s:g} s", "contact_time_s")
    # The configured rate and a request alike: faster reads would only repeat a conversion.
    rate = chips.sample_rate_Hz(config.sensors, m.sample_rate_Hz if sample_rate_Hz is None else sample_rate_Hz)
    shortest = min_contact_time_s(rate)
    if contact < shortest:
        # Refused before heating: too short to estimate, and too short to judge the heater by.
        raise CommandError(ErrorCode.BAD_ARGUMENT, f"contact_time_s={contact} is too short: a touch at "
                           f"{rate:g} Hz needs at least {shortest:g} s of heating", "contact_time_s")
    return MeasurementParams(power_W=power, contact_time_s=contact, baseline_s=m.baseline_s,
                             sample_rate_Hz=rate, cooldown_s=m.cooldown_s,
                             method=config.estimation.method, until_decided=bool(until_decided),
                             arm_s=m.arm_s if arm_s is None else float(arm_s),
                             settle_s=m.settle_s if settle_s is None else float(settle_s))


def fit_record(record: dict, max_payload: int) -> dict:
    """Drop bulky optional fields until a record fits in one reply (``record`` is changed in place).

    The error text is cut to 200 characters first, then the result keeps
    only its scalar fields.
    """
    for key in ("error", "result"):
        if len(json.dumps(record, default=str)) + REPLY_MARGIN <= max_payload:
            break
        if key == "result" and isinstance(record.get("result"), dict):
            record["result"] = {k: v for k, v in record["result"].items()
                                if not isinstance(v, (list, dict))}
        elif record.get(key):
            record[key] = str(record[key])[:200]
    return record


#: The answer's keys a HISTORY page carries for each record: what a list shows and an export writes. The
#: rest (candidates, the running decision, the sensor chain's fit, u parts) is RESULT's: a whole answer is
#: ~2 kB, which made a 4-kB page one record long (ISSUE #35 §8).
HISTORY_RESULT_KEYS = ("effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u", "alpha_m2_s",
                       "alpha_m2_s_u", "determined_by", "material", "material_confidence", "method", "probe",
                       "object_set", "object", "object_posterior", "class", "class_posterior", "unknown_posterior",
                       "model_sha256", "calibration_sha256", "flags")


def history_item(record: dict) -> dict:
    """A record as a HISTORY page lists it: its result reduced to :data:`HISTORY_RESULT_KEYS`."""
    result = record.get("result")
    if not isinstance(result, dict):
        return record
    return dict(record, result={k: result[k] for k in HISTORY_RESULT_KEYS if k in result})


def history_page(offset: int, total: int, items: list[dict], max_payload: int) -> dict[str, Any]:
    """The HISTORY reply: as many of ``items`` (each fitted) as fit in one reply.

    The host continues at ``offset + len(items)``. Each item is fitted and encoded once and the
    page grows while the encoded sizes fit: linear in the items asked for (ISSUE #35 §8: popping
    one item and re-encoding the whole page each time made a 20-item request cost 20 encodings of
    up to 20 items, and a 1100-record export took minutes).
    """
    budget = max_payload - REPLY_MARGIN - len(json.dumps({"offset": offset, "total": total, "items": []}))
    page: list[dict] = []
    for r in items:
        r = fit_record(history_item(r), max_payload)
        size = len(json.dumps(r)) + (2 if page else 0)  # ", " before every item but the first
        if size > budget:
            break
        budget -= size
        page.append(r)
    return {"offset": offset, "total": total, "items": page}


def series_page(record: Mapping[str, Any], measurement_id: int, which: str, offset: int, limit: int | None,
                max_payload: int) -> dict[str, Any]:
    """The SERIES reply: samples ``offset`` .. ``offset + limit`` of one stored series, cut to fit one reply.

    Parameters
    ----------
    record : mapping
        The stored record with its series (``History.get(..., series=True)``).
    measurement_id : int
    which : {"raw", "grid"}
    offset : int
        First sample.
    limit : int, optional
        Most samples wanted (default: to the end).
    max_payload : int
        Frame payload bound, bytes.

    Raises
    ------
    CommandError
        BAD_ARGUMENT for an offset past the end; INTERNAL if not even one
        sample fits.
    """
    # The read-time columns travel only when stored (records before them, and boards that do not time
    # their reads, have none); the touch's header rides on the raw series' first page.
    cols = [(name, record.get(col)) for i, (name, col) in enumerate(SERIES_COLUMNS[which])
            if i < 3 or record.get(col) is not None]
    total = 0 if cols[0][1] is None else int(len(cols[0][1]))
    if offset > total:
        raise CommandError(ErrorCode.BAD_ARGUMENT, f"offset {offset} is past the end of the {which} series "
                           f"({total} samples)", "offset")
    end = total if limit is None else min(total, offset + limit)
    body: dict[str, Any] = {"measurement_id": measurement_id, "which": which, "offset": offset, "total": total}
    if which == "raw" and offset == 0 and total:
        header = series_header(record)
        if header is not None:
            body["header"] = header
    body.update((name, []) for name, _ in cols)
    # JSON has no NaN: a non-finite sample travels as null.
    values = [[x if math.isfinite(x) else None for x in np.asarray(a[offset:end], float).tolist()]
              if end > offset else [] for _, a in cols]
    n = _samples_that_fit(body, values, end - offset, max_payload)
    if n == 0 and end > offset and body.pop("header", None) is not None:
        # A frame too small for the header and a sample: the samples first (the host then rebuilds the
        # header from the measurement's record).
        n = _samples_that_fit(body, values, end - offset, max_payload)
    if n == 0 and end > offset:
        raise CommandError(ErrorCode.INTERNAL, f"max_payload {max_payload} B is too small for one sample")
    for (name, _), v in zip(cols, values):
        body[name] = v[:n]
    return body


def _samples_that_fit(body: dict[str, Any], values: list[list], n_max: int, max_payload: int) -> int:
    """How many of the ``values``' samples fit in one reply beside ``body``."""
    budget = max_payload - len(json.dumps(body, separators=(",", ":")))
    n = used = 0
    for i in range(n_max):
        cost = sum(len(json.dumps(v[i])) + 1 for v in values)  # the value and its comma
        if used + cost > budget:
            break
        used += cost
        n += 1
    return n


def config_reply(values: dict[str, Any], max_payload: int) -> dict[str, Any]:
    """The CONFIG_GET/CONFIG_SET reply: every value, or only the runtime keys if the whole set is too big.

    Long paths could push the whole set past one frame; the runtime keys always fit.
    """
    if len(json.dumps(values)) + REPLY_MARGIN > max_payload:
        return {"config": {k: v for k, v in values.items() if k in RUNTIME_KEYS}, "truncated": True}
    return {"config": values}
