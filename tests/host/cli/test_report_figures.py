"""The report's per-touch figures (shared TouchFigure) and the PDFs of the report and the certificate (ISSUE #36)."""

from __future__ import annotations

import base64
import json
import re
import zlib
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from io import StringIO

import pytest

from edge.calibration.model import ProbeCalibration, ReferenceFit
from host.cli.main import main
from host.lab_plots import MAX_TOUCH_FIGURES, check_plot, figure_touches
from host.lab_report import report_title
from host.lab_series import SeriesFileError, load_series

# The figures import matplotlib: one worker pays for it (tests/support/schedule.py).
pytestmark = pytest.mark.shares_import("matplotlib")

SAMPLE = "Glass <B33>"
#: Two touches: enough to show one figure per touch, in order, each with its own identification (one touch
#: could not tell that from "the first touch only"), and a spread for the summary; a third added 0.45 CPU-s.
N = 2
#: The tests on the module's simulated series are slow (its N simulated touches, and their report drawing a
#: figure per touch and a PDF: 1.2 s); the figure and PDF tests on hand-made input stay in the fast tier.
ON_SIM_SERIES = pytest.mark.slow


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


#: A stream object's dictionary (not reaching back past the previous object's end) and the start of its data.
_STREAM = re.compile(rb"obj\s*<<((?:(?!endobj).)*?)>>\s*stream\r?\n", re.S)


def _content_streams(raw: bytes):
    """The PDF's streams other than images, inflated where they are Flate-compressed (the default output).

    Images are skipped: their bytes hold no text, and scanning them for text arrays is most of the cost.
    """
    pos = 0
    while (m := _STREAM.search(raw, pos)) is not None:
        end = raw.find(b"endstream", m.end())
        assert end > 0, "a stream without its end"
        pos = end + len(b"endstream")
        if b"/Subtype /Image" in m.group(1):
            continue
        data = raw[m.end():end]
        yield zlib.decompress(data) if b"/FlateDecode" in m.group(1) else data


def pdf_text(raw: bytes) -> str:
    """The text of a Matplotlib PDF (compressed or not): each TJ array's glyph strings joined (kerning dropped).

    Matplotlib's text shaping sets "fi", "fl", "ff" as ligature glyphs in a font of their own (another
    text run): the needles searched here avoid those letter pairs.
    """
    out = []
    # An array is strings "(...)" (which may hold an unescaped "]") and kerning numbers; matched element by
    # element so that a "[" elsewhere fails at once instead of scanning the stream for "] TJ".
    for stream in _content_streams(raw):
        for arr in re.findall(rb"\[((?:\((?:\\.|[^\\)])*\)|[^\](])*)\]\s*TJ", stream):
            out.append(b"".join(re.findall(rb"\(((?:\\.|[^\\)])*)\)", arr)).replace(b"\\(", b"(")
                       .replace(b"\\)", b")").decode("latin-1"))
    return "\n".join(out)


def pdf_pages(raw: bytes) -> int:
    return len(re.findall(rb"/Type /Page\b", raw))


@pytest.fixture(scope="module")
def sim_series(tmp_path_factory):
    """An N-touch series of glass on a simulated probe (each answered touch keeps its series and fit)."""
    d = tmp_path_factory.mktemp("series")
    path = d / "s.json"
    assert main(["series", "--sim", "glass_15V", "--repeat", str(N), "--sample", SAMPLE, "--operator", "A. Smith",
                 "--out", str(path)]) == 0
    return path


@ON_SIM_SERIES
def test_the_series_file_keeps_what_each_touch_figure_needs(sim_series):
    doc = json.loads(sim_series.read_text())
    for t in doc["touches"]:
        assert t["answered"]
        s = t["plot"]["series"]
        assert len(s["raw_t_s"]) == len(s["raw_T_C"]) == len(s["raw_q_W_m2"]) > 10
        assert min(s["raw_t_s"]) < 0 < max(s["raw_t_s"])   # the pre-contact phase is kept
        fit = t["plot"]["fit"]
        assert fit["method"] == t["answer"]["method"] and len(fit["t_model_s"]) == len(fit["fit_T_K"]) > 10
    assert doc["calibration"] is None   # the simulated glass_15V probe has none installed


@pytest.fixture(scope="module")
def sim_report(sim_series):
    """``report`` of the series with ``--pdf``, run once for this module's tests, as a user runs it.

    The blocks and pages the command laid out are kept (a spy on ``layout_pages``) so that the tests
    compare the PDF with what the command meant to draw without drawing every figure again.
    """
    import host.lab_pdf as lab_pdf

    d = sim_series.parent
    html_path, pdf_path = d / "r.html", d / "r.htm.pdf"   # alike but different names are accepted
    laid_out = []
    real = lab_pdf.layout_pages

    def spy(title, blocks, footer=""):
        blocks = list(blocks)
        pages = real(title, blocks, footer)
        laid_out.append((title, blocks, footer, len(pages)))
        return pages

    out, err = StringIO(), StringIO()
    with pytest.MonkeyPatch.context() as mp, redirect_stdout(out), redirect_stderr(err):
        mp.setattr(lab_pdf, "layout_pages", spy)
        code = main(["report", str(sim_series), "--out", str(html_path), "--pdf", str(pdf_path)])
    return {"code": code, "out": out.getvalue(), "err": err.getvalue(), "html": html_path, "pdf": pdf_path,
            "laid_out": laid_out}


@ON_SIM_SERIES
def test_a_report_from_a_simulated_series(sim_series, sim_report):
    """The report of a series a simulated probe measured (moved here from test_report.py: the module's series
    and report serve it, instead of simulating and reporting another series)."""
    assert sim_report["code"] == 0, sim_report["err"]
    html = sim_report["html"].read_text()
    doc = json.loads(sim_series.read_text())
    m = re.search(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert m, "no embedded PNG"
    png = base64.b64decode(m.group(1))
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    assert "Measurement report: Glass &lt;B33&gt;" in html and "simulated probe, scene glass_15V" in html
    for t in doc["touches"]:
        assert t["started_utc"] in html
    e = doc["summary"]["quantities"]["effusivity_W_s05_m2K"]
    assert f"RSD {e['rsd'] * 100:.2f} %" in html and f"{N} of {N} touches answered" in html


@ON_SIM_SERIES
def test_the_report_has_one_identified_figure_per_touch_and_the_pdf_the_same_content(sim_series, sim_report):
    code, out, err = sim_report["code"], sim_report["out"], sim_report["err"]
    assert code == 0, err
    html = sim_report["html"].read_text()
    doc = json.loads(sim_series.read_text())
    imgs = re.findall(r'<img alt="([^"]*)" src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    # The summary plot of the N readings, then one figure per touch, titled with its measurement.
    assert len(imgs) == 1 + N
    for t, (alt, b64) in zip(doc["touches"], imgs[1:]):
        assert base64.b64decode(b64)[:8] == b"\x89PNG\r\n\x1a\n"
        assert alt.startswith(f"measurement {t['measurement_id']}, ") and f"touch {t['index']}:" in alt
        assert "model " + t["model_sha256"][:12] in alt and "calibration none" in alt and "4.5 W" in alt
        assert f"{t['answer']['method']} method" in alt
    assert "Each answered touch: (a) heat flux" in html
    # The PDF (compressed, as written by default): the pages the layout made, with the report's title, sample
    # and each touch's title as text, and the same figures as the HTML.
    raw = sim_report["pdf"].read_bytes()
    assert raw.startswith(b"%PDF") and b"/FlateDecode" in raw and f"PDF ({pdf_pages(raw)} pages)" in out
    loaded = load_series(sim_series)
    [(title, blocks, footer, n_pages)] = sim_report["laid_out"]
    assert title == report_title(loaded) and footer == "series s.json"
    assert pdf_pages(raw) == n_pages >= 3
    text = pdf_text(raw)
    for needle in (f"Measurement report: {SAMPLE}", "A. Smith", "Touches", "Device and probe", "Quality",
                   f"measurement {loaded['touches'][0]['measurement_id']},", f"page 1 of {n_pages}"):
        assert needle in text, needle
    pngs = [b[1] for b in blocks if b[0] == "png"]
    assert len(pngs) == 1 + N and pngs[1:] == [base64.b64decode(b64) for _, b64 in imgs[1:]]


def _calibration(tmp_path):
    refs = (ReferenceFit("pmma <lot&7>", 570.0, 0.03, 3, (0.011, -0.02, 0.004)),
            ReferenceFit("pyroceram", 2100.0, 0.025, 2, (0.013, -0.006)))
    cal = replace(ProbeCalibration.nominal(), calibrated=True, created_utc="2026-11-20T09:00:00+00:00",
                  u_rel_floor=0.021, references=refs)
    p = tmp_path / "cal.json"
    p.write_text(cal.to_json())
    return p, cal


def test_the_certificate_pdf_lists_references_values_residuals_who_when_device(capsys, tmp_path, monkeypatch):
    import host.lab_pdf as lab_pdf

    path, cal = _calibration(tmp_path)
    real = lab_pdf.write_pdf
    monkeypatch.setattr(lab_pdf, "write_pdf", lambda *a, **kw: real(*a, **{**kw, "compress": False}))
    out = tmp_path / "cert.pdf"
    code, stdout, err = run(capsys, "report", "--calibration", path, "--out", tmp_path / "cert.html", "--pdf", out,
                            "--operator", "Q & A <lab>")
    assert code == 0, err
    raw = out.read_bytes()
    n = pdf_pages(raw)
    assert n >= 1 and f"PDF ({n} pages)" in stdout
    text = pdf_text(raw)
    for needle in ("Calibration certi", "probe paper", "Reference materials", "pmma", "<lot&7>", "pyroceram",
                   "570", "2100", "3.00 %", "+1.10, -2.00, +0.40", "issued by", "Q & A <lab>",
                   "2026-11-20T09:00:00+00:00", cal.sha256, "Fitted sensor chain parameters", "2.10 %",
                   "sensing depth"):
        assert needle in text, needle


@ON_SIM_SERIES
def test_pdf_and_out_must_differ_and_an_existing_pdf_needs_overwrite(capsys, tmp_path, sim_series, sim_report):
    # The module's report run wrote r.html and r.htm.pdf: names alike but different are accepted.
    assert sim_report["code"] == 0 and sim_report["pdf"].exists(), sim_report["err"]
    same = tmp_path / "r.pdf"
    code, _, err = run(capsys, "report", sim_series, "--out", tmp_path / "x.html", "--pdf", sim_report["pdf"])
    assert code == 2 and "exists" in err and not (tmp_path / "x.html").exists()
    code, _, err = run(capsys, "report", sim_series, "--out", tmp_path / "y.html", "--pdf", same.with_suffix(".txt"))
    assert code == 2


def test_above_the_limit_the_representative_touch_is_drawn():
    def t(i, e, plot=True):
        return {"index": i, "answered": e is not None, "answer": {"effusivity_W_s05_m2K": e} if e else None,
                "plot": {"series": {}} if plot else None}

    few = [t(1, 100.0), t(2, None), t(3, 120.0, plot=False), t(4, 90.0)]
    chosen, every = figure_touches(few)
    assert every and [x["index"] for x in chosen] == [1, 4]
    many = [t(i, 1000.0 + (i if i % 2 else -i)) for i in range(1, MAX_TOUCH_FIGURES + 3)]
    chosen, every = figure_touches(many)
    values = sorted(x["answer"]["effusivity_W_s05_m2K"] for x in many)
    median = (values[len(values) // 2 - 1] + values[len(values) // 2]) / 2
    assert not every and len(chosen) == 1
    assert abs(chosen[0]["answer"]["effusivity_W_s05_m2K"] - median) == min(abs(v - median) for v in values)


@pytest.mark.parametrize("plot, words", [
    ({"series": {"raw_t_s": [0.0, 1.0], "raw_T_C": [25.0], "raw_q_W_m2": [0.0, 1.0]}}, "differ in length"),
    ({"series": {"raw_t_s": [0.0], "raw_T_C": [float("nan")], "raw_q_W_m2": [0.0]}}, "finite numbers"),
    ({"series": {"raw_t_s": [0.0], "raw_T_C": [25.0]}}, "needs raw_t_s"),
    ({"series": {"raw_t_s": [0.0], "raw_T_C": [25.0], "raw_q_W_m2": [0.0]},
      "fit": {"t_model_s": [0.0, 1.0], "fit_T_K": [1.0], "method": "default"}}, "one length"),
    ("a picture", "must be a table"),
])
def test_a_bad_plot_entry_is_named(plot, words):
    with pytest.raises(SeriesFileError, match=words):
        check_plot(plot, "touches[0].plot", SeriesFileError)


@ON_SIM_SERIES
def test_a_series_file_with_a_bad_plot_is_one_line_exit_2(capsys, tmp_path, sim_series):
    doc = json.loads(sim_series.read_text())
    doc["touches"][1]["plot"]["series"]["raw_T_C"] = doc["touches"][1]["plot"]["series"]["raw_T_C"][:-1]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    code, _, err = run(capsys, "report", bad, "--out", tmp_path / "r.html")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "touches[1].plot.series" in lines[0], err
