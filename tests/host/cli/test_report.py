"""``thermotouch report``: the measurement report of a series and the calibration certificate (HTML)."""

from __future__ import annotations

import base64
import json
import re
from dataclasses import replace

import pytest

from edge.calibration.model import ProbeCalibration, ReferenceFit
from host.flag_docs import describe_flag
from host.lab_series import series_document, touch_entry
from host.lab_stats import VERDICTS
from tests.support.cli import run, one_line_error

# The report's plots import matplotlib: one worker pays for it (tests/support/schedule.py).
pytestmark = pytest.mark.shares_import("matplotlib")

SAMPLE = "Glass <B33> & 'co'"
E = [1500.0, 1540.0, None, 1470.0]


def _record(i: int, e: float | None) -> dict:
    result = {"effusivity_W_s05_m2K": e, "effusivity_W_s05_m2K_u": None if e is None else 0.05 * e,
              "k_W_mK": None if e is None else 1.1, "k_W_mK_u": None if e is None else 0.3,
              "alpha_m2_s": None if e is None else 6e-7, "alpha_m2_s_u": None if e is None else 2e-7,
              "material": "borofloat_33", "material_confidence": 0.2, "method": "sensor_chain", "probe": "paper",
              "model_sha256": "a" * 64, "calibration_sha256": "c" * 64,
              "determined_by": {} if e is None else {"e": "calibration", "k": "prior", "alpha": "prior"},
              "flags": ["no_contact"] if e is None else ["k_alpha_from_prior"] + (["noisy"] if i == 1 else [])}
    return {"measurement_id": 40 + i, "status": "ok", "started_utc": f"2026-11-27T10:00:0{i}.000+00:00",
            "created_utc": f"2026-11-27T10:00:0{i}.500+00:00", "power_W": 4.5, "contact_time_s": 2.0,
            "model_sha256": "a" * 64, "flags": [], "result": result}


@pytest.fixture
def series_file(tmp_path):
    touches = [touch_entry(i + 1, _record(i, e)) for i, e in enumerate(E)]
    doc = series_document(touches, metadata={"sample": SAMPLE, "lot": "L&1", "operator": "Dr <X>", "notes": None},
                          device={"source": "port", "port": "/dev/ttyACM0", "device_id": "tt-0123456789abcdef",
                                  "board": "pi", "firmware_version": "0.1.0", "model_version": "m1",
                                  "model_sha256": "a" * 64, "calibrated": True, "calibration_sha256": "c" * 64},
                          settings={"repeat": len(E), "cooldown_s": 10.0}, started_utc="2026-11-27T10:00:00+00:00",
                          software_version="9.9")
    p = tmp_path / "series.json"
    p.write_text(json.dumps(doc))
    return p, doc


def _png_of(html: str) -> bytes:
    m = re.search(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert m, "no embedded PNG"
    png = base64.b64decode(m.group(1))
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    return png


def _self_contained(html: str) -> None:
    assert "<script" not in html and "<link" not in html and "http://" not in html and "https://" not in html
    assert not re.search(r'src="(?!data:)', html)


def test_the_report_has_the_numbers_the_escaped_names_and_the_plot(capsys, tmp_path, series_file):
    path, doc = series_file
    out = tmp_path / "r.html"
    code, stdout, err = run(capsys, "report", str(path), "--out", str(out))
    assert code == 0, err
    assert "measurement report of 4 touches (3 answered)" in stdout
    html = out.read_text()
    _self_contained(html)
    _png_of(html)
    # the user's names are shown as typed, never as markup
    assert "Glass &lt;B33&gt; &amp; &#x27;co&#x27;" in html and "<B33>" not in html
    assert "L&amp;1" in html and "Dr &lt;X&gt;" in html
    s = doc["summary"]["quantities"]["effusivity_W_s05_m2K"]
    assert s["n"] == 3 and s["mean"] == pytest.approx(sum(e for e in E if e) / 3)
    assert "1503 ± 35" in html  # mean ± sd, rounded to two digits of sd
    assert f"RSD {s['rsd'] * 100:.2f} %" in html and f"{s['chi2_dof']:.2f} (dof 2, p = {s['p_value']:.3f})" in html
    assert VERDICTS[s["verdict"]] in html
    for mid in (40, 41, 43):
        assert f"<td class=\"num\">{mid}</td>" in html
    assert "tt-0123456789abcdef" in html and "c" * 64 in html and "/dev/ttyACM0" in html
    # what determined each quantity, and the touch without an answer named
    assert re.search(r"<td>effusivity e</td><td>calibration</td><td class=\"num\">3</td>", html)
    assert re.search(r"<td>conductivity k</td><td>prior</td><td class=\"num\">3</td>", html)
    assert "touch 3 (measurement 42): no estimate (flags: no_contact)" in html
    # each flag that occurred, with the words of thermotouch flags
    import html as html_mod
    for word, n in (("k_alpha_from_prior", 3), ("noisy", 1), ("no_contact", 1)):
        assert f"<td>{word}</td><td class=\"num\">{n}</td>" in html
        assert html_mod.escape(describe_flag(word).replace("``", "")) in html


def _calibration(tmp_path, **kw):
    kw.setdefault("references", (ReferenceFit("pmma <lot&7>", 570.0, 0.03, 3, (0.011, -0.02, 0.004)),
                                 ReferenceFit("pyroceram", 2100.0, 0.025, 2, (0.013, -0.006))))
    cal = replace(ProbeCalibration.nominal(), calibrated=True, created_utc="2026-11-20T09:00:00+00:00",
                  u_rel_floor=0.021, **kw)
    p = tmp_path / "cal.json"
    p.write_text(cal.to_json())
    return p, cal


def test_the_certificate_has_references_residuals_parameters_and_the_issuer(capsys, tmp_path):
    path, cal = _calibration(tmp_path)
    out = tmp_path / "cert.html"
    code, stdout, err = run(capsys, "report", "--calibration", str(path), "--out", str(out),
                            "--operator", "Q & A <lab>", "--notes", "annual")
    assert code == 0, err
    assert f"calibration certificate of probe paper ({cal.sha256[:12]})" in stdout
    html = out.read_text()
    _self_contained(html)
    _png_of(html)
    assert cal.sha256 in html and "2026-11-20T09:00:00+00:00" in html and "Q &amp; A &lt;lab&gt;" in html
    assert "pmma &lt;lot&amp;7&gt;" in html and "<lot&7>" not in html
    assert "<td class=\"num\">570</td><td class=\"num\">3.00 %</td><td class=\"num\">3</td>" in html
    assert "+1.10, -2.00, +0.40" in html and "+1.30, -0.60" in html  # each re-measured touch, %
    assert "2.10 %" in html  # the residual floor
    # pmma: 2 u = 2 hypot(3 %, 2.1 %) = 7.3 %, every touch within; a reference read 11 % off would be named
    assert "all within ±7.3 %" in html
    assert "0.400 ± 0.020" in html  # sensing depth, mm, with its u (the nominal 5 %)
    assert "1.000 ± 0.050" in html  # flux sensor sensitivity, × nominal
    for name in ("ln_flux_scale", "ln_sensing_thickness_m", "tc_tau_s", "ln_sensing_k_W_mK"):
        assert name in html


def test_a_reference_re_measured_outside_its_u_is_pointed_out(capsys, tmp_path):
    path, cal = _calibration(tmp_path, references=(ReferenceFit("aisi_304", 7493.0, 0.02, 2, (0.114, 0.01)),))
    out = tmp_path / "cert.html"
    code, _, err = run(capsys, "report", "--calibration", str(path), "--out", str(out))
    assert code == 0, err
    assert "1 of 2 outside ±5.8 %" in out.read_text()  # 2 hypot(2 %, 2.1 %)
    path, _ = _calibration(tmp_path, references=(ReferenceFit("absurd", 7493.0, 0.02, 1, (1e300,)),))
    code, _, err = run(capsys, "report", "--calibration", str(path), "--out", str(out), "--overwrite")
    assert code == 0 and err == ""  # shown as it is, no warning on stderr


@pytest.mark.parametrize("content, words", [
    ("not json", "not a usable calibration: not JSON"),
    ('{"format": "thermotouch-calibration"}', "not a usable calibration"),
])
def test_a_bad_calibration_file_is_one_line_and_exit_2(capsys, tmp_path, content, words):
    bad = tmp_path / "bad.json"
    bad.write_text(content)
    code, _, err = run(capsys, "report", "--calibration", str(bad), "--out", str(tmp_path / "c.html"))
    line = one_line_error(err)
    assert code == 2 and line.startswith("thermotouch report: ") and words in line, line
    assert not (tmp_path / "c.html").exists()


def test_a_changed_or_uncalibrated_calibration_is_refused(capsys, tmp_path):
    path, _ = _calibration(tmp_path)
    d = json.loads(path.read_text())
    d["u_rel_floor"] = 0.001  # edited after it was made: its sha256 no longer matches
    path.write_text(json.dumps(d))
    code, _, err = run(capsys, "report", "--calibration", str(path), "--out", str(tmp_path / "c.html"))
    assert code == 2 and "sha256" in one_line_error(err)
    path.write_text(ProbeCalibration.nominal().to_json())
    code, _, err = run(capsys, "report", "--calibration", str(path), "--out", str(tmp_path / "c.html"))
    assert code == 2 and "nothing to certify" in one_line_error(err)


@pytest.mark.parametrize("content, words", [
    ("{", "not JSON"), ('{"format": "other"}', "not a series file"),
    ('{"format": "thermotouch-series", "schema_version": 1, "touches": []}', "touches: must be a non-empty list"),
    ('{"format": "thermotouch-series", "schema_version": 1, "touches": [{"index": 1}]}', "touches[0]: no 'answered'"),
    ('{"format": "thermotouch-series", "schema_version": 1, "metadata": {"sample": "a\\u0007"}, '
     '"touches": [{"index": 1, "answered": false, "answer": null, "flags": []}]}', "metadata.sample: non-printable"),
])
def test_a_bad_series_file_is_one_line_and_exit_2(capsys, tmp_path, content, words):
    bad = tmp_path / "bad.json"
    bad.write_text(content)
    code, _, err = run(capsys, "report", str(bad), "--out", str(tmp_path / "r.html"))
    line = one_line_error(err)
    assert code == 2 and line.startswith(f"thermotouch report: {bad}: ") and words in line, line


def test_an_existing_out_is_kept_without_overwrite_and_replaced_with_it(capsys, tmp_path, series_file):
    path, _ = series_file
    out = tmp_path / "r.html"
    out.write_text("mine")
    code, _, err = run(capsys, "report", str(path), "--out", str(out))
    assert code == 2 and "--overwrite" in one_line_error(err) and out.read_text() == "mine"
    code, _, err = run(capsys, "report", str(path), "--out", str(out), "--overwrite")
    assert code == 0 and out.read_text().startswith("<!DOCTYPE html>")


@pytest.mark.parametrize("extra, words", [
    ([], "give a series file"),
    (["--calibration", "SERIES"], "not both"),
    (["--operator", "me"], "--operator and --notes are for a certificate"),
])
def test_wrong_combinations_are_one_line_and_exit_2(capsys, tmp_path, series_file, extra, words):
    path, _ = series_file
    argv = ["report"] + ([] if extra == [] else [str(path)]) + [str(path) if a == "SERIES" else a for a in extra]
    code, _, err = run(capsys, *argv, "--out", str(tmp_path / "r.html"))
    assert code == 2 and words in one_line_error(err)


def test_out_must_be_html(capsys, tmp_path, series_file):
    path, _ = series_file
    code, _, err = run(capsys, "report", str(path), "--out", str(tmp_path / "r.pdf"))
    assert code == 2 and ".html" in one_line_error(err)


WEIRD = ("x", [], {"e": 1}, -1, True, None, float("nan"))
NUMBERS = (-1.0, 0.0, None, float("nan"), 1e300)


def _mutations(doc, where, values):
    for value in values:
        bad = json.loads(json.dumps(doc))
        node = bad
        for k in where[:-1]:
            node = node[k]
        node[where[-1]] = value
        yield value, bad


def _report_or_refuse(capsys, path, out, bad, what):
    path.write_text(json.dumps(bad))
    code, _, err = run(capsys, "report", str(path), "--out", str(out), "--overwrite")
    assert code in (0, 2), (what, err)
    if code == 2:
        assert "internal error" not in one_line_error(err), (what, err)
    return code


@pytest.mark.slow  # a report run per field and kind of wrong value: seconds
def test_a_hand_edited_series_file_is_reported_or_refused_in_one_line_never_a_crash(capsys, tmp_path, series_file,
                                                                                    monkeypatch):
    import host.lab_report

    # every field, every kind of wrong value; the plot is drawn by the next test (it costs 0.1 s a page)
    monkeypatch.setattr(host.lab_report, "series_plot_png", lambda doc: b"\x89PNG\r\n\x1a\n")
    path, doc = series_file
    paths = [("touches", 0, k) for k in doc["touches"][0] if k != "answer"]
    paths += [("touches", 0, "answer", k) for k in doc["touches"][0]["answer"]]
    paths += [(k,) for k in ("metadata", "device", "settings", "software", "started_utc")]
    paths += [("device", k) for k in doc["device"]] + [("settings", "cooldown_s"), ("software", "version")]
    seen = set()
    for where in paths:
        for value, bad in _mutations(doc, where, WEIRD):
            seen.add(_report_or_refuse(capsys, path, tmp_path / "r.html", bad, (where, value)))
    assert seen == {0, 2}


# The summary plot draws e and k with their u as error bars through the same code: e's value stays in the fast
# tier, the other three fields (0.3-0.5 s each: a plotted report per odd number) run with the slow tests.
@pytest.mark.parametrize("key", ["effusivity_W_s05_m2K"] + [
    pytest.param(k, marks=pytest.mark.slow) for k in ("effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u")])
def test_odd_numbers_in_an_answer_are_plotted_or_refused(capsys, tmp_path, series_file, key):
    path, doc = series_file
    for value, bad in _mutations(doc, ("touches", 0, "answer", key), NUMBERS):
        _report_or_refuse(capsys, path, tmp_path / "r.html", bad, (key, value))
