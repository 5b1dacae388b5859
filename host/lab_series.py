"""N touches of one sample: running them, the self-describing series file, and reading it back.

A series file (JSON, ``format = "thermotouch-series"``) holds everything a
report or a later reader needs without the device: the user's metadata
(sample, lot, operator, notes), the software version, the device's INFO
(identity, firmware, model, calibration), the settings of the series, every
touch with its measurement id, UTC times, status and whole answer -- also the
touches that gave none, with the reason -- what each answered touch's figure
needs (its series and fitted curve, :mod:`host.lab_plots`), the device's
calibration (for a sensor-chain answer's curve) and a summary recomputed by
:func:`summarize_touches` (:mod:`host.lab_stats`).  A reader recomputes the
summary from the touches (one source of truth); the stored one is what the
series printed.
"""

from __future__ import annotations

import json
import math
import time
from datetime import datetime, timezone
from functools import cache
from pathlib import Path
from typing import Any, Callable, Iterable

from host.lab_metadata import check_metadata
from host.lab_plots import check_plot
from host.lab_stats import QUANTITIES, summarize

__all__ = ["FORMAT", "SCHEMA_VERSION", "MAX_TOUCHES", "SeriesFileError", "measure_once", "touch_entry",
           "run_series", "summarize_touches", "series_document", "load_series", "source_of", "utc_now",
           "software_version", "answered_values"]

FORMAT = "thermotouch-series"
SCHEMA_VERSION = 1
#: Most touches in one series (a day of touches at one every few seconds; bounds the file and the report).
MAX_TOUCHES = 1000
#: Largest series file read, bytes (1000 touches of a few kB each).
MAX_BYTES = 64 * 1024 * 1024
#: Device refusals of one touch that the series records (a touch without an answer) and goes on after;
#: any other (a bad argument, a protocol error) stops the series.
TOUCH_ERRORS = ("BUSY", "SENSOR_FAULT", "INTERNAL")
#: Largest magnitude of a number in a series file read back (in SI units no answer comes near it; it keeps
#: the statistics' squares finite on a hand-edited file).
MAX_MAGNITUDE = 1e12
#: Short names of the quantities in an answer's ``determined_by`` (edge.estimation.result.QUANTITIES).
_SHORT = {"effusivity_W_s05_m2K": "e", "k_W_mK": "k", "alpha_m2_s": "alpha"}


class SeriesFileError(ValueError):
    """A series file that cannot be read; the message names what is wrong."""


@cache
def software_version() -> str:
    """The installed ``thermotouch`` distribution's version (what ``thermotouch --version`` prints).

    Looked up here rather than imported from :mod:`host.cli.main`, which imports the verbs that
    call this (an import cycle). Once per process, as ``--version``'s (the parser is built once):
    each lookup scans the installed distributions and parses a METADATA file (0.3 ms; the suite's
    report runs in one process repeated it hundreds of times).
    """
    from importlib.metadata import PackageNotFoundError, version  # noqa: PLC0415

    try:
        return version("thermotouch")
    except PackageNotFoundError:  # pragma: no cover - a checkout without an install
        return "unknown"


def utc_now() -> str:
    """Now, UTC, ISO 8601 with milliseconds (the device's record format)."""
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def measure_once(session: Any, **kw: Any) -> dict:
    """One MEASURE on ``session``: the device's record, whatever its status (nothing raised for no answer)."""
    return session.client.measure(**{k: v for k, v in kw.items() if v is not None})


def touch_entry(index: int, rec: dict, answer_of: Callable[[dict], dict] | None = None,
                plot_of: Callable[[dict], dict | None] | None = None) -> dict:
    """A series' entry for touch ``index`` (1-based) from the device's MEASURE record.

    ``answer`` is ``answer_of(rec)`` (the CLI passes ``measure --json``'s
    form, :func:`host.cli.report.measure_json`; default: a copy of the
    record's ``result``), None when the record has no result.  ``answered``
    is True when the touch gave an effusivity; otherwise ``no_answer`` says
    why (the device's status and reason, or its flags).
    """
    answer = None
    if rec.get("result"):
        answer = answer_of(rec) if answer_of is not None else dict(rec["result"])
    flags = list(dict.fromkeys(list(rec.get("flags") or []) + list((answer or {}).get("flags") or [])))
    answered = answer is not None and rec.get("status") == "ok" and answer.get("effusivity_W_s05_m2K") is not None
    why = None
    if not answered:
        if rec.get("status") != "ok":
            why = f"{rec.get('status')}: {rec.get('reason') or rec.get('error') or 'no reason given'}"
        else:
            why = "no estimate"
        if flags:
            why += f" (flags: {', '.join(flags)})"
    return {
        "index": index, "measurement_id": rec.get("measurement_id"), "status": rec.get("status"),
        "reason": rec.get("reason"), "started_utc": rec.get("started_utc"), "created_utc": rec.get("created_utc"),
        "power_W": rec.get("power_W"), "contact_time_s": rec.get("contact_time_s"),
        "heater_on_s": rec.get("heater_on_s"), "T0_C": rec.get("T0_C"), "flags": flags,
        "model_sha256": rec.get("model_sha256") or (answer or {}).get("model_sha256"),
        "calibration_sha256": (answer or {}).get("calibration_sha256"),
        "answered": answered, "no_answer": why, "answer": answer,
        "plot": plot_of(rec) if answered and plot_of is not None else None,
    }


def run_series(session: Any, n: int, *, voltage_V: float | None = None, power_W: float | None = None,
               contact_time_s: float | None = None, cooldown_s: float = 0.0,
               answer_of: Callable[[dict], dict] | None = None,
               plot_of: Callable[[dict], dict | None] | None = None,
               before_touch: Callable[[int], None] | None = None,
               on_touch: Callable[[dict], None] | None = None) -> list[dict]:
    """``n`` touches on ``session``; each touch's entry (:func:`touch_entry`) in order.

    A touch the device refuses for a reason of that touch (:data:`TOUCH_ERRORS`: busy, a sensor
    fault, an internal error) is recorded with status ``refused`` and counts as a touch without an
    answer; any other refusal is raised.  Between touches the probe rests ``cooldown_s``: on a
    probe on a port the host waits that long (lift the probe, let it cool, put it back); on a
    simulated probe its simulated clock moves on by that much (its time moves only while it works,
    so a wait on the host would change nothing).  ``answer_of`` makes each touch's answer and
    ``plot_of`` its figure's inputs (:func:`touch_entry`); ``before_touch(i)`` runs after the rest,
    just before touch ``i`` (a prompt to place the probe); ``on_touch`` sees each entry as soon as it is made (printing).
    """
    from host.client import DeviceError  # noqa: PLC0415

    entries = []
    for i in range(1, n + 1):
        if i > 1 and cooldown_s > 0:
            if getattr(session, "simulated", False):
                session.simulator.advance(cooldown_s)
            else:
                time.sleep(cooldown_s)
        if before_touch is not None:
            before_touch(i)
        try:
            rec = measure_once(session, voltage_V=voltage_V, power_W=power_W, contact_time_s=contact_time_s)
        except DeviceError as exc:
            if exc.code.name not in TOUCH_ERRORS:  # the request itself is wrong: every touch would fail
                raise
            rec = {"measurement_id": None, "status": "refused", "reason": exc.code.name.lower(),
                   "error": exc.message, "flags": [], "result": None}
        entry = touch_entry(i, rec, answer_of, plot_of)
        entries.append(entry)
        if on_touch is not None:
            on_touch(entry)
    return entries


def source_of(answer: dict, key: str) -> str:
    """What determined quantity ``key`` of an answer: ``data``, ``prior``, ``calibration``, ``thickness``.

    The answer's ``determined_by`` says it where the device gives it; older
    answers say it through ``from_prior`` / ``determined`` and the
    ``k_alpha_from_prior`` flag; ``not stated`` when none of them does.
    """
    q = _SHORT[key]
    by = answer.get("determined_by") or {}
    if q in by:
        return str(by[q])
    if q in (answer.get("from_prior") or []):
        return "prior"
    if q in (answer.get("determined") or []):
        return "data"
    if q in ("k", "alpha") and "k_alpha_from_prior" in (answer.get("flags") or []):
        return "prior"
    return "not stated"


def summarize_touches(touches: list[dict]) -> dict:
    """The series' summary: counts, the touches without an answer (named), and each quantity's statistics."""
    answered = [t for t in touches if t["answered"]]
    out: dict[str, Any] = {
        "n_requested": len(touches), "n_answered": len(answered), "n_unanswered": len(touches) - len(answered),
        "unanswered": [{"index": t["index"], "measurement_id": t["measurement_id"], "why": t["no_answer"]}
                       for t in touches if not t["answered"]],
        "quantities": {},
    }
    for key, ukey, *_ in QUANTITIES:
        have = [t["answer"] for t in answered if t["answer"].get(key) is not None]
        s = summarize([a[key] for a in have], [a.get(ukey) for a in have])
        sources: dict[str, int] = {}
        for a in have:
            src = source_of(a, key)
            sources[src] = sources.get(src, 0) + 1
        s["determined_by"] = sources
        out["quantities"][key] = s
    flags: dict[str, int] = {}
    for t in touches:
        for f in t["flags"]:
            flags[f] = flags.get(f, 0) + 1
    out["flags"] = flags
    out["model_sha256"] = sorted({t["model_sha256"] for t in touches if t.get("model_sha256")})
    out["calibration_sha256"] = sorted({t["calibration_sha256"] for t in touches if t.get("calibration_sha256")})
    return out


def series_document(touches: list[dict], *, metadata: dict, device: dict, settings: dict, started_utc: str,
                    software_version: str, calibration: str | None = None) -> dict:
    """The series file's content (see the module docstring).

    ``calibration``: the device's installed calibration (its JSON), kept so a report draws a
    sensor-chain answer with the chain's own curve; None when none is installed.
    """
    return {
        "format": FORMAT, "schema_version": SCHEMA_VERSION,
        "software": {"name": "thermotouch", "version": software_version},
        "created_utc": utc_now(), "started_utc": started_utc,
        "metadata": dict(metadata), "device": dict(device), "settings": dict(settings),
        "calibration": calibration, "touches": touches, "summary": summarize_touches(touches),
    }


def _finite_or_none(v: Any, where: str) -> None:
    if v is None:
        return
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SeriesFileError(f"{where}: must be a finite number or null, got {v!r}")
    if abs(v) > MAX_MAGNITUDE:
        raise SeriesFileError(f"{where}: {v!r} is beyond any measurement (|x| <= {MAX_MAGNITUDE:g})")


def _check_touch(i: int, t: Any) -> dict:
    where = f"touches[{i}]"
    if not isinstance(t, dict):
        raise SeriesFileError(f"{where}: must be a table")
    for k in ("index", "answered", "answer", "flags"):
        if k not in t:
            raise SeriesFileError(f"{where}: no {k!r}")
    if isinstance(t["index"], bool) or not isinstance(t["index"], int) or t["index"] < 1:
        raise SeriesFileError(f"{where}.index: must be a whole number >= 1")
    if not isinstance(t["answered"], bool):
        raise SeriesFileError(f"{where}.answered: must be true or false")
    if not isinstance(t["flags"], list) or not all(isinstance(f, str) for f in t["flags"]):
        raise SeriesFileError(f"{where}.flags: must be a list of words")
    for k in ("measurement_id",):
        v = t.get(k)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int)):
            raise SeriesFileError(f"{where}.{k}: must be a whole number or null")
    for k in ("power_W", "contact_time_s", "heater_on_s", "T0_C"):
        _finite_or_none(t.get(k), f"{where}.{k}")
    for k in ("status", "reason", "started_utc", "created_utc", "model_sha256", "calibration_sha256", "no_answer"):
        if t.get(k) is not None and not isinstance(t[k], str):
            raise SeriesFileError(f"{where}.{k}: must be text or null")
    a = t["answer"]
    if a is not None and not isinstance(a, dict):
        raise SeriesFileError(f"{where}.answer: must be a table or null")
    if a is not None:
        for k in ("determined_by",):
            v = a.get(k)
            if v is not None and not (isinstance(v, dict) and all(isinstance(x, str) for x in v.values())):
                raise SeriesFileError(f"{where}.answer.{k}: must be a table of words")
        for k in ("determined", "from_prior", "flags"):
            v = a.get(k)
            if v is not None and not (isinstance(v, list) and all(isinstance(x, str) for x in v)):
                raise SeriesFileError(f"{where}.answer.{k}: must be a list of words")
        for k in ("probe", "method", "object", "material"):
            if a.get(k) is not None and not isinstance(a[k], str):
                raise SeriesFileError(f"{where}.answer.{k}: must be text or null")
    if t["answered"]:
        if a is None or a.get("effusivity_W_s05_m2K") is None:
            raise SeriesFileError(f"{where}: answered but no effusivity")
        for key, ukey, *_ in QUANTITIES:
            _finite_or_none(a.get(key), f"{where}.answer.{key}")
            _finite_or_none(a.get(ukey), f"{where}.answer.{ukey}")
            if a.get(ukey) is not None and a[ukey] < 0:
                raise SeriesFileError(f"{where}.answer.{ukey}: an uncertainty must be >= 0, got {a[ukey]!r}")
    t["plot"] = check_plot(t.get("plot"), f"{where}.plot", SeriesFileError)
    t.setdefault("no_answer", None if t["answered"] else "not stated")
    for k in ("measurement_id", "status", "started_utc", "model_sha256", "calibration_sha256"):
        t.setdefault(k, None)
    return t


def load_series(path: str | Path) -> dict:
    """Read and check a series file; its summary is recomputed from its touches.

    Raises
    ------
    SeriesFileError
        One line naming the file's problem (not JSON, another format, a
        touch without its fields, bad metadata ...).
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise SeriesFileError(f"cannot read: {exc.strerror or exc}") from None
    if len(raw) > MAX_BYTES:
        raise SeriesFileError(f"too large ({len(raw)} bytes; a series file is at most {MAX_BYTES})")
    try:
        d = json.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise SeriesFileError(f"not UTF-8 text (byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise SeriesFileError(f"not JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise SeriesFileError(f"not a series file (format is not {FORMAT!r}; thermotouch series --out writes one)")
    if d.get("schema_version") != SCHEMA_VERSION:
        raise SeriesFileError(f"schema_version {d.get('schema_version')!r} is not {SCHEMA_VERSION}")
    touches = d.get("touches")
    if not isinstance(touches, list) or not touches:
        raise SeriesFileError("touches: must be a non-empty list")
    if len(touches) > MAX_TOUCHES:
        raise SeriesFileError(f"touches: at most {MAX_TOUCHES}, got {len(touches)}")
    try:
        d["metadata"] = check_metadata(d.get("metadata") or {})
    except ValueError as exc:
        raise SeriesFileError(str(exc)) from None
    for k in ("device", "settings", "software"):
        if not isinstance(d.get(k) or {}, dict):
            raise SeriesFileError(f"{k}: must be a table")
        d[k] = d.get(k) or {}
    if d.get("calibration") is not None and not isinstance(d["calibration"], str):
        raise SeriesFileError("calibration: must be the calibration's JSON text or null")
    d.setdefault("calibration", None)
    d["touches"] = [_check_touch(i, t) for i, t in enumerate(touches)]
    d["summary"] = summarize_touches(d["touches"])
    return d


def answered_values(touches: Iterable[dict], key: str) -> list[tuple[int, float, float | None]]:
    """``(index, value, u)`` of quantity ``key`` over the answered touches."""
    ukey = next(u for k, u, *_ in QUANTITIES if k == key)
    return [(t["index"], t["answer"][key], t["answer"].get(ukey)) for t in touches
            if t["answered"] and t["answer"].get(key) is not None]
