"""End to end on the simulated probe, over the virtual serial link: train, judge, flash, touch the nine scenes.

The module trains one small quick bundle (12 library materials, a few
seconds) and runs the user's flows on it:

* ``thermotouch deploy`` (host.deploy.train_and_deploy) against a probe running the shipped model REFUSES it
  (it does worse on the paper cases) and flashes nothing;
* the small bundle flashed by hand, then a deploy of the shipped
  bundle against it (``baseline``) deploys: verified flash, the device
  reports the new sha256, a self-check touch on glass_15V passes;
* the nine paper scenes touched with the quick-trained bundle on the device
  (effusivity does not depend on the network) and with the shipped one (k and alpha bars):
  ``thermotouch demo --ideal`` on one scene per sample, the six others by the demo's measure_scenes.

Accuracy through the MCP9600 (16-bit, 10 Hz sampling, the daemon's
defaults; readings placed one conversion time earlier, the converter's lag),
default method, device result vs paper Table 2, measured on this code:

======== ======= ======= ======= ========
scene    e err   k err   α err   note
======== ======= ======= ======= ========
glass12  -1.9 %  +3.1 %  +10.5 %
glass15  +1.0 %  +7.2 %  +12.8 %
glass18  +7.2 %  +17.8 % +20.7 %
pmma8    +8.1 %  +11.6 % +6.6 %
pmma15   +1.7 %  +0.4 %  -2.5 %
pmma20   +3.2 %  +1.9 %  -2.5 %
alu15    --      --      --      insufficient_signal (0.15 K rise, ~1 LSB)
alu20    --      --      --      insufficient_signal (u(e) > 1/3 e with the rounding term)
alu25    +3.9 %  -10.4 % -25.6 %
======== ======= ======= ======= ========

The thermocouple's 0.197 K steps on a 0.15-2 K rise are what limit e, so the
bars are not per-touch numbers but what the instrument can promise: e within
10 % on glass and PMMA and 25 % on aluminium, and within 3 stated standard
uncertainties (quantisation is not white noise, so 2 would be too tight).
"""

from __future__ import annotations

import json
import math

import pytest

from host.demo import PAPER_SCENES, SAMPLE_SCENES, measure_scenes, run_demo
from host.deploy import DeployRefused, train_and_deploy
from host.device import open_device
from host.flash import flash_bundle, load_verified

# shares_import: the module fixture trains through host.train, which imports scikit-learn (~1 CPU-s with
# scipy.stats): the schedule runs it on the worker that imports it for the other trainers
# (tests/support/schedule.py), so the other worker need not.
pytestmark = [pytest.mark.hil, pytest.mark.slow, pytest.mark.shares_import("sklearn")]

SMALL_LIBRARY = ("tempered_glass", "pmma", "aluminium_alloy", "polystyrene_extruded_foam", "cork_board", "plywood",
                 "ptfe", "polycarbonate", "fused_silica", "granite", "aisi_304", "copper")

#: |e error| bars by sample on the reference board (see the module docstring); alu_15V must refuse instead.
E_BAR = {"tempered glass": 0.10, "PMMA": 0.10, "Al alloy": 0.25}


def assert_e_within_bars(r):
    d = r["default"]
    err = d["errors"]["e"]
    assert abs(err) <= E_BAR[r["sample"]], (r["scene"], err)
    assert abs(d["e"] - r["ref"]["e"]) <= 3 * d["e_u"], (r["scene"], d["e"], d["e_u"])
#: |k error| and |alpha error| bars of the shipped model's default method on the reference board:
#: k = e^2/(rho c) and alpha = e^2/(rho c)^2 double the e error (25 % on aluminium) on top of the prior's.
K_BAR = {"tempered glass": 0.32, "PMMA": 0.24, "Al alloy": 0.50}
ALPHA_BAR = {"tempered glass": 0.36, "PMMA": 0.20, "Al alloy": 0.65}


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A quick bundle on 12 materials, via train_and_deploy against a probe running the shipped model."""
    from edge.physics.materials import MaterialLibrary, load_materials

    lib = load_materials()
    small = MaterialLibrary([lib.get(n) for n in SMALL_LIBRARY])
    root = tmp_path_factory.mktemp("e2e")
    logs: list[str] = []
    with open_device(sim="glass_15V", workdir=root / "dev0") as s:
        sha_before = s.client.info()["model_sha256"]
        with pytest.raises(DeployRefused) as ei:
            train_and_deploy(s, root / "small", quick=True, lib=small, progress=False, log=logs.append)
        sha_after = s.client.info()["model_sha256"]
    return {"root": root, "bundle": root / "small", "refusal": ei.value, "logs": logs,
            "sha_before": sha_before, "sha_after": sha_after}


def test_train_and_deploy_refuses_a_model_worse_than_the_devices(trained):
    msg = str(trained["refusal"])
    assert trained["refusal"].code == 3
    assert "worse than the device's model" in msg or "exceeds the threshold" in msg
    assert trained["sha_after"] == trained["sha_before"], "a refused model must not be flashed"
    # It was trained, evaluated on held-back materials and compared on the paper cases first.
    assert any("held-back materials" in m for m in trained["logs"])
    assert any("paper cases" in m and "device" in m for m in trained["logs"])
    assert load_verified(trained["bundle"]).sha256 != trained["sha_before"]


def test_quick_model_flashed_measures_the_nine_scenes_with_the_heater_safe(trained):
    """The trained bundle over the link, then every paper scene: e bars and the heater invariant."""
    work = trained["root"] / "dev1"
    with open_device(sim="glass_12V", workdir=work) as s:
        fl = flash_bundle(s, trained["bundle"], progress=False)
    sha = load_verified(trained["bundle"]).sha256
    assert fl["model_sha256"] == sha
    rows = measure_scenes(work, PAPER_SCENES, expect_sha256=sha, log=lambda m: None)
    assert [r["scene"] for r in rows] == list(PAPER_SCENES)
    for r in rows:
        assert r["model_sha256"] == sha
        h = r["heater"]
        assert h["ok"] and h["off_now"] and h["longest_on_s"] <= h["limit_s"]
        assert h["longest_on_s"] == pytest.approx(2.0, abs=0.01)  # one 2-s pulse, no more
        if r["scene"] == "alu_15V" or (r["sample"] == "Al alloy" and r["default"]["e"] is None):
            # A rise of one or two thermometer steps: refusing is the honest answer.
            assert "insufficient_signal" in r["flags"] and r["default"]["e"] is None
            continue
        assert_e_within_bars(r)


def test_deploying_a_better_model_flashes_confirms_and_self_checks(trained):
    from thermotouch_models import DEFAULT_BUNDLE

    work = trained["root"] / "dev2"
    shipped = load_verified(DEFAULT_BUNDLE).sha256
    with open_device(sim="glass_15V", workdir=work) as s:
        flash_bundle(s, trained["bundle"], progress=False)  # the device now runs the worse model
    logs: list[str] = []
    with open_device(sim="glass_15V", workdir=work) as s:
        r = train_and_deploy(s, work / "unused", bundle=DEFAULT_BUNDLE, baseline=trained["bundle"],
                             progress=False, log=logs.append)
        assert s.client.info()["model_sha256"] == shipped
        inv = s.simulator.heater_invariant(s.daemon.config.heater.max_on_time_s)
    assert r["model_sha256"] == shipped
    assert r["device_score"] is not None and r["score"]["paper_k"] < r["device_score"]["paper_k"]
    chk = r["self_check"]
    assert chk["ok"] and chk["reference"] == "glass_15V" and abs(chk["e_err"]) <= chk["e_bar"]
    assert chk["model_sha256"] == shipped
    assert inv["ok"] and inv["n_intervals"] == 1


def test_ideal_demo_prints_table2_comparison_and_writes_plots(tmp_path):
    # ``thermotouch demo --ideal``: today's table on the estimator's own 1-D world, both boards. The demo runs
    # one scene per paper sample (SAMPLE_SCENES: every sample's Table 2 line, both tables, a plot per touch);
    # the six other paper scenes are touched by the same code (measure_scenes) on a fresh probe with the same
    # shipped model, without plots, so that all nine answers are held to the bars below. Running the demo on
    # all nine drew nine plots in its plot process and touched nine more scenes on the precision board
    # (3.9 CPU-s, over half of it the plot process) for a table whose rows this test does not read.
    out = tmp_path / "demo"
    lines: list[str] = []
    assert run_demo(out, scenes=SAMPLE_SCENES, progress=False, ideal=True, log=lines.append) == 0
    text = "\n".join(lines)
    assert "Reference board (MCP9600" in text and "Precision board (ADS122C04" in text
    assert "calibration" not in text   # no walk-through in the ideal world
    for sample in ("tempered glass", "PMMA", "Al alloy"):
        assert sample in text
    assert "heater invariant held on every touch: yes" in text
    res = json.loads((out / "results.json").read_text())
    rows = res["rows"]
    assert [r["scene"] for r in rows] == list(SAMPLE_SCENES) and len(res["rows_precision"]) == len(SAMPLE_SCENES)
    for scene in SAMPLE_SCENES:
        png = out / "plots" / f"{scene}.png"
        assert png.read_bytes()[:4] == b"\x89PNG"
    rest = [sc for sc in PAPER_SCENES if sc not in SAMPLE_SCENES]
    rows += measure_scenes(tmp_path / "rest", rest, expect_sha256=res["model_sha256"], log=lambda m: None)
    assert sorted(r["scene"] for r in rows) == sorted(PAPER_SCENES)
    for r in rows:
        assert r["heater"]["ok"], r["scene"]
        d = r["default"]
        if d["e"] is None:
            assert r["sample"] == "Al alloy" and "insufficient_signal" in r["flags"], r["scene"]
            continue
        assert_e_within_bars(r)
        assert abs(d["errors"]["k"]) <= K_BAR[r["sample"]], (r["scene"], d["errors"])
        assert abs(d["errors"]["alpha"]) <= ALPHA_BAR[r["sample"]], (r["scene"], d["errors"])
        # The stated uncertainty covers the k error within 2 sigma (it carries the prior's spread).
        assert abs(d["k"] - r["ref"]["k"]) <= 2 * d["k_u"], r["scene"]
        assert r["paper"] is not None and math.isfinite(r["paper"]["k"])
    # Table 2 references, as the paper gives them.
    assert "1.097" in text and "0.185" in text and "120.4" in text


def test_deploy_command_refuses_in_one_line(trained, capsys):
    from host.cli.main import main

    code = main(["deploy", "--sim", "glass_15V", "--bundle", str(trained["bundle"])])
    out, err = capsys.readouterr()
    assert code == 3
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("thermotouch deploy: not deploying") and "Traceback" not in err
    assert "paper cases" in out  # it evaluated before refusing


def test_judge_compares_with_the_device_and_the_thresholds():
    # The statistics and verdicts are tested in tests/host/test_gate.py; here the thresholds.
    from host.deploy import Thresholds, judge

    good = {"paper_k": 0.10, "paper_alpha": 0.20, "default_e": 0.03, "default_k": 0.10}
    metrics = {"heldout_k_median_rel_err": 0.15}
    assert judge(metrics, good) == []
    assert "paper alpha" in judge(metrics, dict(good, paper_alpha=0.70))[0]
    assert "held-back" in judge({"heldout_k_median_rel_err": 0.5}, good)[0]
    assert judge(metrics, good, (), Thresholds(default_e=0.01))[0].startswith("default e error 3.0 %")
