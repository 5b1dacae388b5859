"""``thermotouch estimate`` / ``evaluate`` / ``train``: outputs and one-line errors."""

import json

import numpy as np
import pytest

from edge.physics.forward import simulate
from edge.physics.solids import Solid
from host.cli.main import main

GLASS = Solid(1.097, 2458.4, 809.0)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("method", ["default", "paper"])
def test_estimate_json_with_shipped_bundle(capsys, glass_record, method):
    code, out, err = run(capsys, "estimate", "--csv", glass_record, "--method", method, "--json")
    assert code == 0, err
    d = json.loads(out)
    for key in ("effusivity_W_s05_m2K", "k_W_mK", "alpha_m2_s"):
        assert d[key] > 0 and d[key + "_u"] > 0
    assert d["method"] == method and len(d["model_sha256"]) == 64 and isinstance(d["flags"], list)
    assert abs(d["effusivity_W_s05_m2K"] / GLASS.effusivity_W_s05_m2K - 1) < 0.02
    assert d["material"]


def test_estimate_text_and_absolute_temperature_column(capsys, tmp_path):
    r = simulate(GLASS, 7.7e7, 2.0, back="infinite", scheme="exact", dt_s=0.01)
    p = tmp_path / "abs.csv"
    t = np.concatenate(([-0.2, -0.1], r.t_s))
    T = np.concatenate(([298.15, 298.15], 298.15 + r.T_f_K))
    q = np.concatenate(([0.0, 0.0], r.q_f_W_m2))
    p.write_text("t_s,T_K,q_W_m2\n" + "\n".join(f"{a},{b},{c}" for a, b, c in zip(t, T, q)) + "\n")
    code, out, _ = run(capsys, "estimate", "--csv", p)
    assert code == 0 and "effusivity" in out and "material" in out


@pytest.mark.parametrize(
    "content,needle",
    [
        ("t_s,dT_K,q_W_m2\n0,0,0\n0.1,x,1\n0.2,0.2,2\n0.3,0.3,3\n", "line 3, column 'dT_K'"),
        ("t_s,dT_K\n0,0\n", "header"),
        ("t_s,dT_K,q_W_m2\n0,0,0\n0.1,0.1\n", "line 3"),
        ("", "empty"),
    ],
)
def test_malformed_csv_one_line(capsys, tmp_path, content, needle):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    code, out, err = run(capsys, "estimate", "--csv", p)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and needle in err


def test_corrupt_bundle_refused_one_line(capsys, glass_record, tmp_path):
    import shutil

    from thermotouch_models import DEFAULT_BUNDLE

    b = tmp_path / "bundle"
    shutil.copytree(DEFAULT_BUNDLE, b)
    data = bytearray((b / "arrays.npz").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (b / "arrays.npz").write_bytes(bytes(data))
    code, _, err = run(capsys, "estimate", "--bundle", b, "--csv", glass_record)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "refused" in err and "arrays.npz" in err


@pytest.mark.slow  # the paper's cases and the identification evaluated in full
def test_evaluate_json(capsys):
    code, out, err = run(capsys, "evaluate", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert len(d["paper_cases"]) == 18
    assert d["identification"]["top1_resolvable"] >= 0.97


@pytest.mark.slow  # a retrain
def test_train_quick_writes_a_loadable_bundle_and_refuses_overwrite(capsys, tmp_path, monkeypatch):
    from edge.model.bundle import load_bundle
    from edge.estimation.estimate import pipeline_golden_check

    import contextlib

    import host.progress

    steps = []

    @contextlib.contextmanager
    def ticker(desc, **kw):  # the fits (no known length) run under an elapsed-time indicator
        steps.append(desc)
        yield

    monkeypatch.setattr(host.progress, "Ticker", ticker)
    monkeypatch.setenv("THERMOTOUCH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "b"
    code, _, err = run(capsys, "train", "--out", out, "--quick")
    assert code == 0, err
    assert "explained variance" in err
    assert steps == ["fit (held-in materials)", "fit (all materials)"]
    b = load_bundle(out, golden_check=pipeline_golden_check)
    assert b.manifest["metrics"]["quick"] is True
    assert any((tmp_path / "cache").glob("dataset-*.npz")), "the training set is cached"
    code, _, err = run(capsys, "train", "--out", out, "--quick")
    assert code == 2 and "exists" in err and "--overwrite" in err and len(err.strip().splitlines()) == 1


def test_measure_profile_sets_the_contact_time(capsys):
    code, out, err = run(capsys, "measure", "--sim", "glass_15V", "--profile", "quick", "--json")
    # 0.5 s on glass may be too short for an estimate (flag no_signal): the record is still printed, and
    # a touch without an estimate is not a success (exit 1, one line).
    assert code == 0 or (code == 1 and "gave no estimate" in err and len(err.strip().splitlines()) == 1), err
    assert json.loads(out)["contact_time_s"] == pytest.approx(0.5)
    code, out, err = run(capsys, "measure", "--sim", "glass_15V", "--profile", "quick", "--time", "1")
    assert code == 2 and "--profile" in err and len(err.strip().splitlines()) == 1


@pytest.fixture
def small_heater_record(tmp_path):
    """A 3-s small-heater record on glass (thermocouple, flux sensor; 20-ms samples, noise), tagged with its probe."""
    from edge.physics.axisym import AxisymModel
    from edge.physics.geometry import PROBES
    from host.records import write_record

    t = np.arange(151) * 0.02
    T, q = AxisymModel(PROBES["small-heater"], t).signals(GLASS.k_W_mK, GLASS.alpha_m2_s)
    rng = np.random.default_rng(11)
    p = tmp_path / "small.csv"
    write_record(p, t, T + 0.01 * rng.standard_normal(t.size), q + 0.5 * rng.standard_normal(t.size),
                 probe="small-heater")
    return p


def test_estimate_small_heater_json_says_what_was_determined(capsys, small_heater_record):
    code, out, err = run(capsys, "estimate", "--probe", "small-heater", "--csv", small_heater_record, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["probe"] == "small-heater" and d["method"] == "axisym"
    assert d["determined"] == ["e", "k", "alpha"] and d["from_prior"] == []
    assert abs(d["k_W_mK"] / GLASS.k_W_mK - 1) < 4 * d["k_W_mK_u"] / d["k_W_mK"]
    assert abs(d["alpha_m2_s"] / GLASS.alpha_m2_s - 1) < 4 * d["alpha_m2_s_u"] / d["alpha_m2_s"]
    assert -1 < d["corr_k_alpha"] < 1
    code, out, err = run(capsys, "estimate", "--probe", "small-heater", "--csv", small_heater_record)
    assert code == 0 and "determined e, k, alpha" in out


@pytest.mark.parametrize("argv,needle", [
    (["--probe", "tiny"], "unknown probe 'tiny'"),
    ([], "taken with probe 'small-heater', not --probe paper"),
    (["--probe", "small-heater", "--method", "paper"], "--method is for the paper probe"),
])
def test_estimate_probe_errors_one_line(capsys, small_heater_record, argv, needle):
    code, out, err = run(capsys, "estimate", "--csv", small_heater_record, *argv)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and needle in err


def test_estimate_thickness_the_record_cannot_show_is_flagged(capsys, tmp_path):
    # Issue #11: 20-mm PMMA, 2 s; before: k 1.73 +- 0.08 W/m/K (true 0.185).
    from host.records import write_record

    pmma = Solid(0.185, 1178.35, 1429.0)
    r = simulate(pmma, 7.7e7, 2.0, thickness_m=0.02, back="insulated", scheme="exact", dt_s=0.01)
    p = tmp_path / "pmma20.csv"
    write_record(p, r.t_s, r.T_f_K, r.q_f_W_m2)
    code, out, err = run(capsys, "estimate", "--csv", p, "--thickness", "0.02", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert {"thickness_unresolved", "k_alpha_from_prior"} <= set(d["flags"]) and d["prior_reason"]
    assert abs(d["k_W_mK"] / 0.185 - 1) < 2 * d["k_W_mK_u"] / d["k_W_mK"]


@pytest.mark.shares_import("sklearn")  # host.train: one worker pays for the import (tests/support/schedule.py)
def test_train_reprior_copies_the_network_and_refits_only_the_priors_spread(tmp_path, capsys):
    from edge.estimation.estimate import pipeline_golden_check
    from edge.model.bundle import load_bundle
    from thermotouch_models import DEFAULT_BUNDLE

    src = load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check)
    out = tmp_path / "rp"
    assert main(["train", "--reprior", str(DEFAULT_BUNDLE), "--out", str(out)]) == 0
    b = load_bundle(out, golden_check=pipeline_golden_check)
    assert b.model_version.endswith("+prior-loo") and b.model_version.count("+prior-loo") == 1
    for name, arr in src.arrays.items():
        if name != "prior_coef":
            np.testing.assert_array_equal(b.arrays[name], arr, err_msg=name)
    # The shipped bundle already carries the fitted spread: a second fit finds the same value.
    np.testing.assert_allclose(b.arrays["prior_coef"], src.arrays["prior_coef"], rtol=1e-12)
    assert b.manifest["metrics"]["prior_rho_c_intrinsic_ln"] == pytest.approx(src.arrays["prior_coef"][1])
    # An existing --out is refused (nothing replaced), and --quick does not apply.
    capsys.readouterr()
    assert main(["train", "--reprior", str(DEFAULT_BUNDLE), "--out", str(out)]) == 2
    assert main(["train", "--reprior", str(DEFAULT_BUNDLE), "--quick", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "exists" in err and "--quick" in err and not (tmp_path / "x").exists()


_EXPORT_HEAD = ("# measurement_id: 3\n# probe: paper\n# power_W: 4.5\n# heater_on_s: 2.0\n# sample_rate_Hz: 10.0\n"
                "# baseline_s: 0.5\n# method: default\n")


def _export(tmp_path, head=_EXPORT_HEAD, cols="t_s,T_C,q_W_m2"):
    t = np.arange(-5, 21) * 0.1
    T = 25.0 + np.where(t > 0, 0.8 * np.sqrt(np.clip(t, 0, None)), 0.0)
    q = np.where(t > 0, 3000.0, 0.0)
    p = tmp_path / "export.csv"
    rows = zip(t.tolist(), T.tolist(), q.tolist())
    p.write_text(head + cols + "\n" + "\n".join(f"{a!r},{b!r},{c!r}" for a, b, c in rows) + "\n")
    return p


@pytest.mark.parametrize("head,needle", [
    (_EXPORT_HEAD.replace("4.5", "lots"), "header power_W: expected a number, got 'lots'"),
    (_EXPORT_HEAD.replace("# sample_rate_Hz: 10.0\n", ""), "header lacks sample_rate_Hz"),
    (_EXPORT_HEAD.replace("4.5", "-1"), "power_W must be a finite number > 0"),
    (_EXPORT_HEAD + "# saturated: maybe\n", "header saturated: expected true or false"),
    (_EXPORT_HEAD + "# measurement.noise_T_K: loud\n", "measurement.noise_T_K: expected a number"),
    (_EXPORT_HEAD.replace("paper", "tiny"), "tiny"),
    (_EXPORT_HEAD.replace("# probe: paper\n", ""), "header lacks probe"),
])
def test_bad_export_header_is_one_line(capsys, tmp_path, head, needle):
    code, out, err = run(capsys, "estimate", "--csv", _export(tmp_path, head), "--json")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and needle in err, err


def test_export_names_its_probe_and_a_failed_touch_has_no_estimate(capsys, tmp_path):
    p = _export(tmp_path, _EXPORT_HEAD.replace("paper", "small-heater"))
    code, out, err = run(capsys, "estimate", "--csv", p, "--json")   # no --probe: the export's own
    d = json.loads(out)  # (this made-up touch is too weak for the small heater's fit: no estimate, exit 1)
    assert d["probe"] == "small-heater" and code == (0 if d["effusivity_W_s05_m2K"] is not None else 1), err
    code, out, err = run(capsys, "estimate", "--csv", p, "--probe", "paper")
    assert code == 2 and "taken with probe 'small-heater', not --probe paper" in err
    failed = _export(tmp_path, _EXPORT_HEAD + "# status: failed\n# reason: open_thermocouple\n")
    code, out, err = run(capsys, "estimate", "--csv", failed)
    assert code == 1 and out == "" and "measurement 3 ended failed (open_thermocouple)" in err
    assert len(err.strip().splitlines()) == 1


def test_an_estimate_in_another_context_than_the_devices_says_so(capsys, tmp_path):
    p = _export(tmp_path, _EXPORT_HEAD + "# calibration_sha256: " + "d" * 64 + "\n# model_sha256: " + "e" * 64 + "\n")
    code, out, err = run(capsys, "estimate", "--csv", p, "--json")
    notes = [ln for ln in err.splitlines() if ln.startswith("note: ")]
    assert code == 0 and json.loads(out)["effusivity_W_s05_m2K"] > 0
    assert len(notes) == 2 and "model eeeeeeeeeeee" in notes[0] and "calibration dddddddddddd" in notes[1]
    plain = _export(tmp_path)   # the device was uncalibrated, and so is this estimate: nothing to say
    code, out, err = run(capsys, "estimate", "--csv", plain, "--json")
    assert code == 0 and err == ""
