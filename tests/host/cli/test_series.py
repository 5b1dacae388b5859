"""``thermotouch series`` and the metadata of ``measure``: N touches of one sample, their statistics, refusals.

One simulated series (4 touches of glass_15V, the second made to miss the
object with an injected ``no_contact`` window) is run once for the module;
its printed lines, its file and its statistics are checked against a
recomputation with the standard library alone (the chi-square tail in closed form).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import statistics
from datetime import datetime
from types import SimpleNamespace

import pytest

import host.lab_series as lab_series
from host.cli.main import main, version
from host.lab_metadata import MAX_CHARS
from host.lab_stats import TAIL, summarize
from tests.support.cli import run, one_line_error

SAMPLE = "Borofloat <B33> & co"
N = 4


@pytest.fixture(scope="module")
def series_run(tmp_path_factory):
    """``series --sim glass_15V --repeat 4`` with metadata; touch 2 lifted off the object (no answer)."""
    out = tmp_path_factory.mktemp("series") / "glass.json"
    real = lab_series.measure_once
    calls = []

    def measure_once(session, **kw):
        calls.append(kw)
        if len(calls) == 2:  # the probe in air for this touch only (a touch lasts ~7.5 s of simulated time)
            now = session.simulator.clock.now()
            session.simulator.inject("no_contact", at_s=now, until_s=now + 7.0)
        return real(session, **kw)

    buf = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(buf):
        mp.setattr(lab_series, "measure_once", measure_once)
        code = main(["series", "--sim", "glass_15V", "--repeat", str(N), "--sample", SAMPLE, "--lot", "L-17",
                     "--operator", "A. Smith", "--notes", "dry contact, 23 °C", "--time", "2", "--out", str(out)])
    return SimpleNamespace(code=code, path=out, doc=json.loads(out.read_text()), calls=calls, out=buf.getvalue())


@pytest.fixture
def printed(series_run):
    """What the series printed on stdout."""
    return series_run.out


def test_a_series_runs_every_touch_and_writes_a_self_describing_file(series_run):
    doc = series_run.doc
    assert series_run.code == 0 and f"series: {series_run.path}" in series_run.out
    assert len(series_run.calls) == N and all(kw["contact_time_s"] == 2.0 for kw in series_run.calls)
    assert doc["format"] == "thermotouch-series" and doc["schema_version"] == 1
    assert doc["software"] == {"name": "thermotouch", "version": version()}
    assert doc["metadata"] == {"sample": SAMPLE, "lot": "L-17", "operator": "A. Smith", "notes": "dry contact, 23 °C"}
    dev = doc["device"]
    assert dev["source"] == "sim" and dev["scene"] == "glass_15V" and dev["device_id"].startswith("tt-")
    assert len(dev["model_sha256"]) == 64 and "calibrated" in dev
    assert doc["settings"]["repeat"] == N and doc["settings"]["contact_time_s"] == 2.0
    assert [t["index"] for t in doc["touches"]] == [1, 2, 3, 4]
    ids = [t["measurement_id"] for t in doc["touches"]]
    assert len(set(ids)) == N and all(isinstance(i, int) for i in ids)
    for t in doc["touches"]:
        datetime.fromisoformat(t["started_utc"])  # a UTC time the device stamped
        assert t["model_sha256"] == dev["model_sha256"] and t["power_W"] > 0
    assert datetime.fromisoformat(doc["started_utc"]) <= datetime.fromisoformat(doc["created_utc"])


def test_a_touch_without_an_answer_is_counted_and_named(series_run, printed):
    doc = series_run.doc
    t2 = doc["touches"][1]
    assert t2["answered"] is False and t2["no_answer"] and t2["answer"]["effusivity_W_s05_m2K"] is None
    assert all(t["answered"] for i, t in enumerate(doc["touches"]) if i != 1)
    s = doc["summary"]
    assert (s["n_requested"], s["n_answered"], s["n_unanswered"]) == (N, N - 1, 1)
    assert s["unanswered"] == [{"index": 2, "measurement_id": t2["measurement_id"], "why": t2["no_answer"]}]
    assert s["quantities"]["effusivity_W_s05_m2K"]["n"] == N - 1  # not averaged in, not silently dropped
    assert f"3 of {N} touches answered" in printed
    assert f"without an answer: 1 of {N}: touch 2 (measurement {t2['measurement_id']})" in printed
    assert f"touch 2/{N} (measurement {t2['measurement_id']}): no answer" in printed


def _chi2_sf(c2: float, dof: int) -> float:
    """P(chi2_dof >= c2) for an integer ``dof``, in closed form (an independent check of host.lab_stats, which
    takes SciPy's): even dof, e^(-x/2) sum_{j<dof/2} (x/2)^j / j!; odd, erfc(sqrt(x/2)) plus
    sqrt(2x/pi) e^(-x/2) sum_{j<(dof-1)/2} x^j / (1 3 5 ... (2j+1))."""
    h = c2 / 2
    if dof % 2 == 0:
        term, total = 1.0, 0.0
        for j in range(dof // 2):
            total += term
            term *= h / (j + 1)
        return math.exp(-h) * total
    term, total = 1.0, 0.0
    for j in range((dof - 1) // 2):
        total += term
        term *= c2 / (2 * j + 3)
    return math.erfc(math.sqrt(h)) + math.sqrt(2 * c2 / math.pi) * math.exp(-h) * total


def test_the_closed_form_chi2_tail_has_its_known_values():
    # The 95th percentiles of chi2 with 1, 2, 3 and 10 degrees of freedom (standard tables), and the exact forms.
    for dof, q95 in ((1, 3.841458820694124), (2, 5.991464547107979), (3, 7.814727903251179), (10, 18.307038053275146)):
        assert _chi2_sf(q95, dof) == pytest.approx(0.05, rel=1e-12)
    assert _chi2_sf(3.0, 2) == math.exp(-1.5) and _chi2_sf(0.0, 5) == 1.0


def test_the_statistics_agree_with_a_recomputation(series_run):
    doc = series_run.doc
    answers = [t["answer"] for t in doc["touches"] if t["answered"]]
    for key in ("effusivity_W_s05_m2K", "k_W_mK", "alpha_m2_s"):
        x = [a[key] for a in answers]
        u = [a[key + "_u"] for a in answers]
        s = doc["summary"]["quantities"][key]
        mean, sd = statistics.fmean(x), statistics.stdev(x)
        assert s["mean"] == pytest.approx(mean, rel=1e-12) and s["sd"] == pytest.approx(sd, rel=1e-12)
        assert s["rsd"] == pytest.approx(sd / mean, rel=1e-12)
        assert s["u_mean"] == pytest.approx(statistics.fmean(u), rel=1e-12)
        xw = sum(xi / ui**2 for xi, ui in zip(x, u)) / sum(1 / ui**2 for ui in u)
        c2 = sum(((xi - xw) / ui) ** 2 for xi, ui in zip(x, u))
        assert s["chi2"] == pytest.approx(c2, rel=1e-9) and s["dof"] == len(x) - 1
        p_upper = _chi2_sf(c2, len(x) - 1)
        assert s["p_value"] == pytest.approx(p_upper, rel=1e-9) and s["p_lower"] == pytest.approx(1 - p_upper, abs=1e-12)
        rms = math.sqrt(statistics.fmean(ui**2 for ui in u))
        assert s["sd_over_u_rms"] == pytest.approx(sd / rms, rel=1e-12)
        lo, hi = p_upper < TAIL, 1 - p_upper < TAIL
        assert s["verdict"] == ("spread_exceeds_u" if lo else "spread_below_u" if hi else "agrees")
    e = doc["summary"]["quantities"]["effusivity_W_s05_m2K"]
    assert 1000 < e["mean"] < 2200  # glass: the right decade, not a unit slip


def test_the_summary_is_printed_with_mean_rsd_u_and_the_verdict(series_run, printed):
    e = series_run.doc["summary"]["quantities"]["effusivity_W_s05_m2K"]
    assert (f"effusivity e: mean {e['mean']:.4g} W s^0.5/(m^2 K), sd {e['sd']:.4g}, "
            f"RSD {e['rsd'] * 100:.2f} %") in printed
    assert f"mean stated u (k = 1) {e['u_mean']:.4g}" in printed
    assert f"chi2/dof {e['chi2_dof']:.2f} (dof {e['dof']}, p {e['p_value']:.3f})" in printed


def test_an_existing_out_is_not_replaced(series_run, capsys):
    before = series_run.path.read_bytes()
    code, out, err = run(capsys, "series", "--sim", "glass_15V", "--repeat", "2", "--out", str(series_run.path))
    assert code == 2 and "--out" in one_line_error(err) and "--overwrite" in err
    assert series_run.path.read_bytes() == before


@pytest.mark.parametrize("args, words", [
    (["--repeat", "1"], "--repeat"), (["--repeat", "0"], "--repeat"), (["--repeat", "ten"], "whole number"),
    (["--repeat", "1001"], "between 2 and 1000"), (["--repeat", "3", "--sample", "a\nb"], "non-printable"),
    (["--repeat", "3", "--sample", "x" * (MAX_CHARS["sample"] + 1)], "at most 80 characters"),
    (["--repeat", "3", "--operator", "   "], "must not be empty"),
    (["--repeat", "3", "--notes", "bell\x07"], "non-printable"),
    (["--repeat", "3", "--cooldown", "-1"], "--cooldown"),
])
def test_bad_input_is_one_line_and_exit_2_before_any_touch(capsys, tmp_path, args, words):
    out = tmp_path / "s.json"
    code, _, err = run(capsys, "series", "--sim", "no_such_scene_is_started", *args, "--out", str(out))
    line = one_line_error(err)
    assert code == 2 and line.startswith("thermotouch series: ") and words in line, line
    assert not out.exists()


def test_out_is_required_and_must_be_json(capsys, tmp_path):
    code, _, err = run(capsys, "series", "--sim", "glass_15V", "--repeat", "3")
    assert code == 2 and "--out" in one_line_error(err)
    code, _, err = run(capsys, "series", "--sim", "glass_15V", "--repeat", "3", "--out", str(tmp_path / "s.csv"))
    assert code == 2 and ".json" in one_line_error(err)


def test_measure_carries_the_metadata_into_its_json_and_text(capsys):
    code, out, err = run(capsys, "measure", "--sim", "glass_15V", "--json", "--sample", SAMPLE, "--operator", "Bo")
    assert code == 0, err
    d = json.loads(out)
    assert d["metadata"] == {"sample": SAMPLE, "lot": None, "operator": "Bo", "notes": None}


def test_measure_refuses_bad_metadata_in_one_line(capsys):
    code, _, err = run(capsys, "measure", "--sim", "glass_15V", "--lot", "tab\there")
    line = one_line_error(err)
    assert code == 2 and line.startswith("thermotouch measure: argument --lot:") and "non-printable" in line


def test_a_series_without_any_answer_exits_1_and_still_writes_its_file(capsys, tmp_path):
    out = tmp_path / "air.json"
    code, _, err = run(capsys, "series", "--sim", "pmma_15V_no_contact", "--repeat", "2", "--out", str(out))
    assert code == 1 and "none of the 2 touches gave an answer" in one_line_error(err)
    s = json.loads(out.read_text())["summary"]
    assert (s["n_answered"], s["n_unanswered"]) == (0, 2) and [u["index"] for u in s["unanswered"]] == [1, 2]
    assert s["quantities"]["effusivity_W_s05_m2K"]["mean"] is None


def test_cooldown_moves_a_simulated_clock_and_waits_on_a_port(monkeypatch):
    advanced, slept = [], []
    sim = SimpleNamespace(simulated=True, simulator=SimpleNamespace(advance=advanced.append))
    port = SimpleNamespace(simulated=False)
    rec = {"status": "ok", "measurement_id": 1, "flags": [],
           "result": {"effusivity_W_s05_m2K": 600.0, "effusivity_W_s05_m2K_u": 30.0, "flags": []}}
    monkeypatch.setattr(lab_series, "measure_once", lambda session, **kw: dict(rec))
    monkeypatch.setattr(lab_series.time, "sleep", slept.append)
    assert len(lab_series.run_series(sim, 3, cooldown_s=20.0)) == 3 and advanced == [20.0, 20.0] and not slept
    asked = []
    assert len(lab_series.run_series(port, 2, cooldown_s=5.0, before_touch=asked.append)) == 2 and slept == [5.0]
    assert asked == [1, 2]  # the prompt comes after the rest, before each touch


def test_summarize_verdicts_on_known_spreads():
    x = [100.0, 101.0, 99.0, 100.5, 99.5]
    assert summarize(x, [0.9] * 5)["verdict"] == "agrees"
    assert summarize(x, [0.01] * 5)["verdict"] == "spread_exceeds_u"
    assert summarize(x, [50.0] * 5)["verdict"] == "spread_below_u"
    two = summarize(x[:2], [1.0, 1.0])
    assert two["verdict"] == "too_few" and two["sd"] == pytest.approx(statistics.stdev(x[:2]))
    no_u = summarize(x, [1.0, None, 1.0, 1.0, 1.0])
    assert no_u["chi2"] is None and no_u["verdict"] == "too_few" and no_u["mean"] == pytest.approx(100.0)
    assert summarize([], [])["n"] == 0


def test_a_touch_the_device_refuses_is_recorded_and_a_bad_request_stops_the_series(monkeypatch):
    from edge.protocol.errors import ErrorCode
    from host.client import DeviceError

    calls = []

    def measure_once(session, **kw):
        calls.append(kw)
        if len(calls) == 2:
            raise DeviceError(ErrorCode.BUSY, "measurement in progress")
        return {"status": "ok", "measurement_id": len(calls), "flags": [],
                "result": {"effusivity_W_s05_m2K": 600.0, "effusivity_W_s05_m2K_u": 30.0, "flags": []}}

    monkeypatch.setattr(lab_series, "measure_once", measure_once)
    entries = lab_series.run_series(SimpleNamespace(simulated=False), 3)
    assert [e["answered"] for e in entries] == [True, False, True]
    assert entries[1]["status"] == "refused" and entries[1]["no_answer"] == "refused: busy"
    assert lab_series.summarize_touches(entries)["n_unanswered"] == 1

    def bad(session, **kw):
        raise DeviceError(ErrorCode.BAD_ARGUMENT, "power_W out of range")

    monkeypatch.setattr(lab_series, "measure_once", bad)
    with pytest.raises(DeviceError):
        lab_series.run_series(SimpleNamespace(simulated=False), 3)


def test_an_interrupted_series_keeps_the_touches_it_made(capsys, tmp_path, monkeypatch):
    out = tmp_path / "cut.json"
    real, calls = lab_series.measure_once, []

    def measure_once(session, **kw):
        calls.append(kw)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(session, **kw)

    monkeypatch.setattr(lab_series, "measure_once", measure_once)
    code, stdout, err = run(capsys, "series", "--sim", "glass_15V", "--repeat", "5", "--out", str(out))
    assert code == 130 and "interrupted" in one_line_error(err)
    assert f"stopped after 2 of 5 touches; what was measured: {out}" in stdout
    doc = json.loads(out.read_text())
    assert len(doc["touches"]) == 2 and doc["settings"]["stopped_after"] == 2
    assert doc["summary"]["n_answered"] == 2


class _Terminal(io.StringIO):
    """stdin as a person at a terminal: lines typed in advance."""

    def isatty(self) -> bool:
        return True


def test_on_a_port_each_touch_waits_for_enter_and_end_of_input_stops_keeping_the_touches(capsys, tmp_path,
                                                                                         monkeypatch):
    from host.device import simulated_probe

    out = tmp_path / "port.json"
    with simulated_probe("glass_15V") as (port, _daemon, _sim):
        monkeypatch.setattr("sys.stdin", _Terminal("\n"))  # Enter once: touch 1 runs, touch 2 finds no input
        code, stdout, err = run(capsys, "series", "--port", port, "--repeat", "2", "--out", str(out))
    assert code == 1 and one_line_error(err) == "thermotouch series: stopped before touch 2: no Enter (end of input)"
    assert "touch 1/2: put the probe on the sample and press Enter" in stdout
    doc = json.loads(out.read_text())
    assert doc["device"]["source"] == "port" and doc["device"]["port"] == port
    assert [t["answered"] for t in doc["touches"]] == [True] and doc["settings"]["stopped_after"] == 1
