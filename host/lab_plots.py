"""Per-touch figures of a series: what a series file keeps of each touch for its plot, and the report's PNGs.

A report must draw each touch without the device (years later, on another
host), so ``thermotouch series`` keeps with every answered touch what the
shared touch figure (:class:`host.plots.TouchFigure`, content by
:func:`host.plot_data.touch_plot_data`) needs: the stored record's series
(raw samples with the pre-contact phase, the grid the method fitted, the
baseline) and the host's re-estimate curve by the answer's method (through
the device's own bundle, :func:`host.touch.reestimate`), or why there is
none.  A sensor-chain answer is drawn with the chain's curve from the
device's calibration, which the series file keeps once (``calibration``).
The report draws each touch with that same figure, as PNG bytes.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path
from statistics import median
from types import SimpleNamespace
from typing import Any, Iterable

from host.plots import _SERIES_KEYS

__all__ = ["PLOT_SERIES_KEYS", "MAX_TOUCH_FIGURES", "MAX_SAMPLES", "touch_plot_inputs", "check_plot",
           "figure_touches", "touch_figure_pngs"]

#: The series entries a touch's figure reads (those the plot process reads: one list for both).
PLOT_SERIES_KEYS = _SERIES_KEYS

#: Most touches drawn one figure each in a report; above it the report draws the representative touch
#: (the answered touch whose e is nearest the median) beside the summary plot of all readings.
MAX_TOUCH_FIGURES = 12
#: Longest array kept per touch (a 10 s touch at 1 kHz); a longer one in a file is refused.
MAX_SAMPLES = 20000
_ARRAYS = ("raw_t_s", "raw_T_C", "raw_q_W_m2", "grid_t_s", "grid_dT_K", "grid_q_W_m2")
_FIT_ARRAYS = ("t_model_s", "fit_T_K")


def _list(x: Any) -> list[float] | None:
    if x is None:
        return None
    return [float(v) for v in (x.tolist() if hasattr(x, "tolist") else x)]


def touch_plot_inputs(session: Any, record: dict, *, bundle_dir: str | Path | None = None) -> dict | None:
    """What a touch's figure needs, read from ``session`` after MEASURE ``record`` (None: no stored record).

    Returns ``{"series": {...}, "fit": {t_model_s, fit_T_K, method, effusivity_W_s05_m2K(_u)} or None,
    "fit_note": why no fit or None}`` -- plain JSON values.
    """
    from host.touch import host_bundle, reestimate  # noqa: PLC0415

    mid = record.get("measurement_id")
    if mid is None or record.get("status") != "ok" or not record.get("result"):
        return None
    series = session.series(mid)
    out_series = {k: (_list(series.get(k)) if k in _ARRAYS else series.get(k)) for k in PLOT_SERIES_KEYS}
    sha = record.get("model_sha256") or record["result"].get("model_sha256")
    bundle, note = host_bundle(sha, bundle_dir=bundle_dir, session=session)
    fits = reestimate(bundle, series, record=record)
    f = fits.get(record["result"].get("method"))
    fit = None
    if f is not None and getattr(f, "fit_T_K", None) is not None:
        fit = {"t_model_s": _list(f.t_model_s), "fit_T_K": _list(f.fit_T_K), "method": f.method,
               "effusivity_W_s05_m2K": getattr(f, "effusivity_W_s05_m2K", None),
               "effusivity_W_s05_m2K_u": getattr(f, "effusivity_W_s05_m2K_u", None)}
        note = None
    elif record["result"].get("method") == "sensor_chain":
        note = "the calibrated sensor chain's curve, from the device's calibration"
    elif bundle is not None:
        note = "the method has no model curve" if fits else "no raw series stored"
    return {"series": out_series, "fit": fit, "fit_note": note}


def _numbers(v: Any, where: str, err: type[Exception]) -> None:
    if v is None:
        return
    if not isinstance(v, list) or len(v) > MAX_SAMPLES:
        raise err(f"{where}: must be a list of at most {MAX_SAMPLES} numbers")
    for x in v:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise err(f"{where}: must hold finite numbers, got {x!r}")


def check_plot(p: Any, where: str, err: type[Exception] = ValueError) -> dict | None:
    """A series file's per-touch ``plot`` entry, checked (None stays None); raises ``err`` naming the field."""
    if p is None:
        return None
    if not isinstance(p, dict) or not isinstance(p.get("series"), dict):
        raise err(f"{where}: must be a table with a 'series' table")
    s = p["series"]
    for k in _ARRAYS:
        _numbers(s.get(k), f"{where}.series.{k}", err)
    if any(s.get(k) is None for k in ("raw_t_s", "raw_T_C", "raw_q_W_m2")):
        raise err(f"{where}.series: needs raw_t_s, raw_T_C and raw_q_W_m2")
    if len({len(s[k]) for k in ("raw_t_s", "raw_T_C", "raw_q_W_m2")}) != 1:
        raise err(f"{where}.series: raw_t_s, raw_T_C and raw_q_W_m2 differ in length")
    for k in ("T0_C", "q_offset_W_m2"):
        if s.get(k) is not None and (isinstance(s[k], bool) or not isinstance(s[k], (int, float))
                                     or not math.isfinite(s[k])):
            raise err(f"{where}.series.{k}: must be a finite number or null")
    f = p.get("fit")
    if f is not None:
        if not isinstance(f, dict):
            raise err(f"{where}.fit: must be a table or null")
        for k in _FIT_ARRAYS:
            _numbers(f.get(k), f"{where}.fit.{k}", err)
        if f.get("t_model_s") is None or f.get("fit_T_K") is None or len(f["t_model_s"]) != len(f["fit_T_K"]):
            raise err(f"{where}.fit: t_model_s and fit_T_K must be given with one length")
        if not isinstance(f.get("method"), str):
            raise err(f"{where}.fit.method: must be text")
    if p.get("fit_note") is not None and not isinstance(p["fit_note"], str):
        raise err(f"{where}.fit_note: must be text or null")
    return p


def figure_touches(touches: list[dict], limit: int = MAX_TOUCH_FIGURES) -> tuple[list[dict], bool]:
    """The touches the report draws, and whether that is every answered touch with a plot.

    Every answered touch that kept its plot when there are at most ``limit``; else the representative
    touch: the one whose e is nearest the median e (the first of equals).
    """
    drawable = [t for t in touches if t["answered"] and t.get("plot")]
    if len(drawable) <= limit:
        return drawable, True
    m = median(t["answer"]["effusivity_W_s05_m2K"] for t in drawable)
    return [min(drawable, key=lambda t: abs(t["answer"]["effusivity_W_s05_m2K"] - m))], False


def _title_result(t: dict) -> dict:
    """The answer with the identification fields the figure's title shows (the measurement, not a port)."""
    a = dict(t["answer"])
    for k in ("measurement_id", "started_utc", "power_W", "contact_time_s", "model_sha256", "calibration_sha256"):
        if t.get(k) is not None:
            a[k] = t[k]
    a.setdefault("method", "unknown")
    for k in ("effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u", "alpha_m2_s", "alpha_m2_s_u"):
        a.setdefault(k, None)
    return a


def touch_figure_pngs(touches: Iterable[dict], *, label: str = "", calibration: Any = None,
                      fmt: str = "png") -> list[tuple[dict, bytes, str]]:
    """Each touch drawn with the shared :class:`host.plots.TouchFigure`: ``(touch, image bytes, title)``.

    ``title`` is the figure's title as drawn (identification line, label and method, the answer): the
    HTML's alt text and the PDF's caption, so the documents say in text what each figure shows.
    """
    from host.plots import TouchFigure  # noqa: PLC0415

    touches = list(touches)
    out: list[tuple[dict, bytes, str]] = []
    if not touches:
        return out
    with tempfile.TemporaryDirectory(prefix="thermotouch-report-") as tmp, TouchFigure() as fig:
        for t in touches:
            p = t["plot"]
            fit = None if p.get("fit") is None else SimpleNamespace(**p["fit"])
            lab = f"{label}, touch {t['index']}" if label else f"touch {t['index']}"
            if fit is None and t["answer"].get("method") != "sensor_chain":
                lab += f" (measured series only: {p.get('fit_note') or 'no model fit'})"
            path = Path(tmp) / f"touch{t['index']}.{fmt}"
            fig.draw(path, p["series"], _title_result(t), fit, lab, calibration=calibration)
            title = fig.fig._suptitle.get_text() if fig.fig._suptitle is not None else lab
            out.append((t, path.read_bytes(), title.replace("$^{0.5}$", "^0.5").replace("$^2$", "²")))
    return out
