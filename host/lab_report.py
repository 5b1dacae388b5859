"""The measurement report of a series: one HTML page from a series file (``thermotouch report SERIES.json``).

What a lab hands on (Hot Disk's and C-Therm's reports are the bar): who
measured what (sample, lot, operator, notes), with which device, probe
head, model and calibration, every touch with its answer, the mean ± RSD of
each quantity with the check of the spread against the stated u, a plot, what
determined each quantity (the touch's data, the library prior, the
calibration), and each quality flag that occurred, explained (the words of
``thermotouch flags``).  Everything is recomputed from the touches
(:func:`host.lab_series.summarize_touches`).
"""

from __future__ import annotations

from host.lab_html import esc, figure_png, fmt, kv_table, page, pm, png_img, pyplot, table
from host.lab_series import answered_values, source_of
from host.lab_stats import QUANTITIES, TAIL, VERDICTS

__all__ = ["series_report_html", "series_plot_png", "touch_figures", "results_rows", "sample_pairs", "device_pairs",
           "headline_text", "report_title", "calibration_of", "report_blocks"]

#: What each source of a quantity means, for the report's readers.
SOURCES = {
    "data": "this touch's own measurement",
    "prior": "the material library's prior given the measured e (not measured by the touch)",
    "calibration": "the calibrated sensor chain (the probe's calibration on reference materials)",
    "thickness": "the touch, with the object's stated thickness",
    "not stated": "the answer does not say (an older device)",
}


def series_plot_png(doc: dict) -> bytes:
    """Each touch's e (and k) with its u (k = 1), the mean and the ±sd band; touches without an answer marked."""
    plt = pyplot()
    touches = doc["touches"]
    keys = [q for q in QUANTITIES[:2] if answered_values(touches, q[0])]
    fig, axes = plt.subplots(max(1, len(keys)), 1, figsize=(7.5, 2.6 * max(1, len(keys))), sharex=True,
                             squeeze=False)
    missing = [t["index"] for t in touches if not t["answered"]]
    for ax, (key, _, label, unit, scale) in zip(axes[:, 0], keys or [QUANTITIES[0]]):
        pts = answered_values(touches, key)
        if pts:
            idx = [p[0] for p in pts]
            val = [p[1] * scale for p in pts]
            err = [(p[2] or 0.0) * scale for p in pts]
            ax.errorbar(idx, val, yerr=err, fmt="o", color="C0", capsize=3, label="touch ± u (k = 1)")
            s = doc["summary"]["quantities"][key]
            ax.axhline(s["mean"] * scale, color="C1", label="mean")
            if s["sd"] is not None:
                ax.axhspan((s["mean"] - s["sd"]) * scale, (s["mean"] + s["sd"]) * scale, color="C1", alpha=0.15,
                           label="mean ± sd")
        for i in missing:
            ax.axvline(i, color="0.6", linestyle=":", linewidth=1)
        ax.set_ylabel(f"{label}\n({unit})", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="best")
    if missing:
        axes[0, 0].set_title(f"dotted: touch{'es' if len(missing) > 1 else ''} without an answer "
                             f"({', '.join(map(str, missing))})", fontsize=9)
    axes[-1, 0].set_xlabel("touch")
    axes[-1, 0].set_xticks([t["index"] for t in touches] if len(touches) <= 30 else axes[-1, 0].get_xticks())
    return figure_png(fig)


RESULT_HEADER = ["quantity", "unit", "mean ± sd", "RSD", "n", "mean stated u (k = 1)", "χ²/dof", "sd / rms(u)",
                 "spread against u"]


def results_rows(summary: dict) -> list[list[str]]:
    """The result table's rows (HTML and PDF): per quantity mean ± sd, RSD, n, mean u and the spread check."""
    rows = []
    for key, _, label, unit, scale in QUANTITIES:
        s = summary["quantities"][key]
        if not s["n"]:
            rows.append([label, unit, "–", "–", "0", "–", "–", "–", "no values"])
            continue
        band = "–" if s["ratio_band"] is None else f"{s['ratio_band'][0]:.2f}–{s['ratio_band'][1]:.2f}"
        chi = "–" if s["chi2"] is None else f"{s['chi2_dof']:.2f} (dof {s['dof']}, p = {s['p_value']:.3f})"
        ratio = "–" if s["sd_over_u_rms"] is None else f"{s['sd_over_u_rms']:.2f} (accepted {band})"
        rows.append([label, unit, pm(s["mean"], s["sd"], scale),
                     "–" if s["rsd"] is None else f"{s['rsd'] * 100:.2f} %", str(s["n"]), fmt(s["u_mean"], 3, scale),
                     chi, ratio, VERDICTS[s["verdict"]]])
    return rows


def _results_table(summary: dict) -> str:
    return table(RESULT_HEADER, results_rows(summary), numeric=(2, 3, 4, 5))


def _sources_table(summary: dict) -> str:
    rows = []
    for key, _, label, *_ in QUANTITIES:
        by = summary["quantities"][key]["determined_by"]
        for src, n in sorted(by.items()):
            rows.append([label, src, str(n), SOURCES.get(src, "")])
    if not rows:
        return "<p>No answered touch.</p>"
    return table(["quantity", "determined by", "touches", "meaning"], rows, numeric=(2,))


TOUCH_HEADER = ["touch", "measurement", "started (UTC)", "e (W s^0.5/(m² K))", "k (W/(m K))", "α (mm²/s)",
                "object / material", "determined by", "flags"]


def _touch_rows(doc: dict) -> list[list[str]]:
    rows = []
    for t in doc["touches"]:
        a = t["answer"] or {}
        if not t["answered"]:
            rows.append([str(t["index"]), esc(t["measurement_id"]), esc(t.get("started_utc")),
                         f"<span class=\"warn\">no answer: {esc(t['no_answer'])}</span>", "", "", "", "",
                         esc(", ".join(t["flags"]) or "none")])
            continue
        src = ", ".join(f"{q}: {source_of(a, k)}" for k, q in
                        (("effusivity_W_s05_m2K", "e"), ("k_W_mK", "k"), ("alpha_m2_s", "α")) if a.get(k) is not None)
        rows.append([str(t["index"]), esc(t["measurement_id"]), esc(t.get("started_utc")),
                     esc(pm(a.get("effusivity_W_s05_m2K"), a.get("effusivity_W_s05_m2K_u"))),
                     esc(pm(a.get("k_W_mK"), a.get("k_W_mK_u"))),
                     esc(pm(a.get("alpha_m2_s"), a.get("alpha_m2_s_u"), 1e6)),
                     esc(a.get("object") if a.get("object") not in (None, "unknown") else a.get("material")),
                     esc(src), esc(", ".join(t["flags"]) or "none")])
    return rows


def _flags_table(summary: dict) -> str:
    from host.flag_docs import describe_flag  # noqa: PLC0415

    if not summary["flags"]:
        return "<p>No quality flag on any touch.</p>"
    rows = [[w, str(n), describe_flag(w).replace("``", "")] for w, n in sorted(summary["flags"].items())]
    return table(["flag", "touches", "meaning and what to do"], rows, numeric=(1,))


def _distinct(touches: list[dict], key: str) -> str:
    vals = sorted({str((t.get("answer") or {}).get(key)) for t in touches if (t.get("answer") or {}).get(key)})
    return ", ".join(vals) or "–"


def headline_text(doc: dict) -> str:
    """The report's headline, plain text (the HTML sets the exponents)."""
    summary = doc["summary"]
    e = summary["quantities"]["effusivity_W_s05_m2K"]
    if not e["n"]:
        return f"No answer in {summary['n_requested']} touches."
    rsd = "" if e["rsd"] is None else f", RSD {e['rsd'] * 100:.2f} %"
    return (f"e = {pm(e['mean'], e['sd'])} W s^0.5/(m² K) (mean ± sd{rsd}, "
            f"n = {e['n']} of {summary['n_requested']} touches)")


def report_title(doc: dict) -> str:
    """``Measurement report: SAMPLE``."""
    return f"Measurement report: {doc['metadata'].get('sample') or 'unnamed sample'}"


def sample_pairs(doc: dict, source_name: str) -> list[tuple[str, object]]:
    """The Sample table: who measured what, when, from which file."""
    md = doc["metadata"]
    return [("sample", md.get("sample")), ("lot", md.get("lot")), ("operator", md.get("operator")),
            ("notes", md.get("notes")), ("series started (UTC)", doc.get("started_utc")),
            ("series written (UTC)", doc.get("created_utc")), ("series file", source_name)]


def device_pairs(doc: dict) -> list[tuple[str, object]]:
    """The Device and probe table: identity, firmware, model, calibration, power, contact time."""
    dev, st, summary = doc["device"], doc["settings"], doc["summary"]
    powers = sorted({t["power_W"] for t in doc["touches"] if t.get("power_W") is not None})
    times = sorted({t["contact_time_s"] for t in doc["touches"] if t.get("contact_time_s") is not None})
    where = (f"simulated probe, scene {dev.get('scene')}" if dev.get("source") == "sim"
             else f"port {dev.get('port')}" if dev.get("port") else None)
    return [("device", dev.get("device_id")), ("connection", where), ("board", dev.get("board")),
            ("firmware", dev.get("firmware_version")), ("protocol", dev.get("protocol_version")),
            ("probe head", _distinct(doc["touches"], "probe")),
            ("method", _distinct(doc["touches"], "method")),
            ("model", f"{dev.get('model_version')} (sha256 {dev.get('model_sha256')})"),
            ("models in the answers", ", ".join(summary["model_sha256"]) or None),
            ("calibration", (f"sha256 {dev.get('calibration_sha256')}" if dev.get("calibrated")
                             else "none installed: answers are flagged 'uncalibrated'")
             if "calibrated" in dev else None),
            ("calibrations in the answers", ", ".join(summary["calibration_sha256"]) or None),
            ("object set", dev.get("object_set")),
            ("heater power (W)", ", ".join(f"{p:.3g}" for p in powers) or None),
            ("contact time (s)", ", ".join(f"{x:.3g}" for x in times) or None),
            ("rest between touches (s)", st.get("cooldown_s")),
            ("software (series)", f"{doc['software'].get('name')} {doc['software'].get('version')}")]


#: The note under the result table (HTML and PDF).
SPREAD_NOTE = (f"± and u are standard uncertainties (coverage factor k = 1). RSD = sd / mean. The spread is checked "
               f"by χ² of the touches about their u-weighted mean with n − 1 degrees of freedom, two-sided at "
               f"{(1 - 2 * TAIL) * 100:.0f} %: below the band, u holds parts every touch shares (calibration, "
               f"model, prior) that repeating cannot show; above it, the touches differ by more than their u.")


def touch_figures(doc: dict) -> tuple[list[tuple[dict, bytes, str]], str]:
    """The touches' figures (shared :class:`host.plots.TouchFigure`, PNG) and the sentence introducing them."""
    from host.lab_plots import MAX_TOUCH_FIGURES, figure_touches, touch_figure_pngs  # noqa: PLC0415

    chosen, every = figure_touches(doc["touches"])
    n_ans = doc["summary"]["n_answered"]
    if not chosen:
        return [], ("No touch figure: the series file keeps no touch's series (written by an older "
                    "thermotouch series, or no touch answered).")
    cal = calibration_of(doc)
    pngs = touch_figure_pngs(chosen, label=doc["metadata"].get("sample") or "", calibration=cal)
    if every:
        missing = n_ans - len(chosen)
        text = (f"Each answered touch: (a) heat flux, (b) excess temperature with the model fit and its band at "
                f"e ± u(e), (c) residuals; grey: before contact, green: the fit's window."
                + (f" {missing} answered touch(es) kept no series and are not drawn." if missing else ""))
    else:
        text = (f"{n_ans} answered touches (more than {MAX_TOUCH_FIGURES}): the representative touch "
                f"{chosen[0]['index']} (e nearest the median) is drawn; the summary plot shows every reading.")
    return pngs, text


def calibration_of(doc: dict):
    """The device's calibration the series file kept (None: none, or not readable -- the chain curve is omitted)."""
    if not doc.get("calibration"):
        return None
    from edge.calibration.model import CalibrationError, ProbeCalibration  # noqa: PLC0415

    try:
        return ProbeCalibration.from_json(doc["calibration"])
    except CalibrationError:
        return None


def series_report_html(doc: dict, *, source_name: str, generated_utc: str, software_version: str,
                       figures: tuple[list[tuple[dict, bytes, str]], str] | None = None,
                       summary_png: bytes | None = None) -> str:
    """The report page of a loaded series file (:func:`host.lab_series.load_series`).

    ``figures``: :func:`touch_figures` of ``doc`` when the caller drew them already (the PDF uses the same);
    ``summary_png``: :func:`series_plot_png` of ``doc``, likewise.
    """
    summary = doc["summary"]
    title = report_title(doc)
    headline = esc(headline_text(doc)).replace("s^0.5", "s<sup>0.5</sup>").replace("m² K", "m<sup>2</sup> K")
    pngs, fig_text = figures if figures is not None else touch_figures(doc)
    body = [
        f"<h1>{esc(title)}</h1>",
        f"<p class=\"headline\">{headline}</p>",
        "<h2>Sample</h2>",
        kv_table(sample_pairs(doc, source_name)),
        "<h2>Device and probe</h2>",
        kv_table(device_pairs(doc)),
        "<h2>Result</h2>",
        _results_table(summary),
        f"<p class=\"note\">{esc(SPREAD_NOTE)}</p>",
        png_img(series_plot_png(doc) if summary_png is None else summary_png, "each touch's value with its u, the mean and the ±sd band"),
        "<h2>Touch figures</h2>",
        f"<p>{esc(fig_text)}</p>",
        *(png_img(png, title) for _, png, title in pngs),
        "<h2>What determined each quantity</h2>",
        _sources_table(summary),
        "<h2>Touches</h2>",
        f"<p>{summary['n_answered']} of {summary['n_requested']} touches answered"
        + ("." if not summary["n_unanswered"] else
           f"; {summary['n_unanswered']} without an answer: "
           + esc("; ".join(f"touch {u['index']} (measurement {u['measurement_id']}): {u['why']}"
                           for u in summary["unanswered"])) + ".") + "</p>",
        table(TOUCH_HEADER, _touch_rows(doc), numeric=(0, 1, 3, 4, 5), raw=tuple(range(9))),
        "<h2>Quality flags</h2>",
        _flags_table(summary),
        f"<p class=\"note\">Report generated {esc(generated_utc)} by thermotouch {esc(software_version)} from "
        f"{esc(source_name)}; the flags' texts are those of <code>thermotouch flags</code>.</p>",
    ]
    return page(title, body)


def report_blocks(doc: dict, *, source_name: str, generated_utc: str, software_version: str,
                  figures: tuple[list[tuple[dict, bytes, str]], str], summary_png: bytes | None = None) -> list[tuple]:
    """The report as :mod:`host.lab_pdf` blocks: the HTML page's content in its order (tables as text).

    ``summary_png``: :func:`series_plot_png` of ``doc`` when the caller drew it already (the HTML page's).
    """
    from host.flag_docs import describe_flag  # noqa: PLC0415
    from host.lab_pdf import from_html  # noqa: PLC0415

    summary = doc["summary"]
    pngs, fig_text = figures
    by = [[label, src, str(n), SOURCES.get(src, "")] for key, _, label, *_ in QUANTITIES
          for src, n in sorted(summary["quantities"][key]["determined_by"].items())]
    flags = [[w, str(n), describe_flag(w).replace("``", "")] for w, n in sorted(summary["flags"].items())]
    unanswered = "; ".join(f"touch {u['index']} (measurement {u['measurement_id']}): {u['why']}"
                           for u in summary["unanswered"])
    return [
        ("h1", report_title(doc)), ("p", headline_text(doc)),
        ("h2", "Sample"), ("kv", sample_pairs(doc, source_name)),
        ("h2", "Device and probe"), ("kv", device_pairs(doc)),
        ("h2", "Result"), ("table", RESULT_HEADER, results_rows(summary)), ("note", SPREAD_NOTE),
        ("png", series_plot_png(doc) if summary_png is None else summary_png),
        ("h2", "Touch figures"), ("p", fig_text),
        *(b for _, png, title in pngs for b in (("png", png), ("note", title))),
        ("h2", "What determined each quantity"),
        ("table", ["quantity", "determined by", "touches", "meaning"], by) if by else ("p", "No answered touch."),
        ("h2", "Touches"),
        ("p", f"{summary['n_answered']} of {summary['n_requested']} touches answered"
         + (f"; {summary['n_unanswered']} without an answer: {unanswered}." if unanswered else ".")),
        ("table", TOUCH_HEADER, [[from_html(c) for c in r] for r in _touch_rows(doc)]),
        ("h2", "Quality flags"),
        ("table", ["flag", "touches", "meaning and what to do"], flags) if flags
        else ("p", "No quality flag on any touch."),
        ("note", f"Report generated {generated_utc} by thermotouch {software_version} from {source_name}; the "
                 f"flags' texts are those of thermotouch flags."),
    ]
