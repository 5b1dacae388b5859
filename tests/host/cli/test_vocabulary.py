"""One vocabulary across verbs (issue 36, "Consistency"): --time, --power/--voltage, units in names, one ±."""

import json

import numpy as np
import pytest

from edge.physics.probe import HEATER_VOLUME_m3
from host.cli.main import build_parser, main


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def verb_help(verb: str) -> str:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return sub.choices[verb].format_help()


GLASS = ("--k", "1.097", "--rho", "2458.4", "--c", "809")


def test_model_takes_time_and_power_in_watts(capsys):
    code, out, err = run(capsys, "model", *GLASS, "--time", "1", "--json")
    assert code == 0, err
    default = json.loads(out)
    assert default["q_v_W_m3"] == 7.7e7 and default["power_W"] == pytest.approx(7.7e7 * HEATER_VOLUME_m3)
    code, out, err = run(capsys, "model", *GLASS, "--time", "1", "--power", repr(default["power_W"]), "--json")
    d = json.loads(out)
    assert code == 0 and d["q_v_W_m3"] == pytest.approx(7.7e7, rel=1e-12)
    np.testing.assert_allclose(d["T_f_K"], default["T_f_K"], rtol=1e-9)
    code, out, err = run(capsys, "model", *GLASS, "--time", "1", "--power", "2.5", "--json")
    assert json.loads(out)["T_f_K"][-1] == pytest.approx(default["T_f_K"][-1] * 2.5 / default["power_W"], rel=1e-9)
    code, out, err = run(capsys, "model", *GLASS, "--time", "1", "--voltage", "12", "--json")
    assert code == 0 and json.loads(out)["power_W"] > 0


def test_model_old_spellings_still_work_but_are_not_shown(capsys):
    new = run(capsys, "model", *GLASS, "--time", "0.5", "--power", "2", "--json")[1]
    old = run(capsys, "model", *GLASS, "--duration", "0.5", "--qv", repr(2 / HEATER_VOLUME_m3), "--json")[1]
    np.testing.assert_allclose(json.loads(old)["T_f_K"], json.loads(new)["T_f_K"], rtol=1e-12)
    text = verb_help("model")
    assert "--time" in text and "--power" in text and "--voltage" in text
    assert "--duration" not in text and "--qv" not in text
    code, _, err = run(capsys, "model", *GLASS, "--power", "1", "--qv", "1e7")
    assert code == 2 and "not allowed with" in err


def test_design_names_the_radius_unit(capsys):
    code, out, err = run(capsys, "design", "--heater-radius-mm", "5", "--time", "2", "--material", "pmma", "--json")
    assert code == 0, err
    assert json.loads(out)["heater_radius_mm"] == 5
    old = run(capsys, "design", "--heater-radius", "5", "--time", "2", "--material", "pmma", "--json")[1]
    assert json.loads(old) == json.loads(out)
    text = verb_help("design")
    assert "--heater-radius-mm" in text and "--heater-radius " not in text.replace("--heater-radius-mm", "")


@pytest.mark.parametrize("verb", ["measure", "series"])
def test_time_help_states_the_devices_bound(verb):
    text = " ".join(verb_help(verb).split())
    assert "heater.max_on_time_s, 10 s" in text and "<= 60" not in text


def test_contact_time_is_time_in_every_verb():
    for verb in ("measure", "series", "model", "design"):
        text = verb_help(verb)
        assert "--time" in text and "--heat " not in text and "--duration" not in text, verb


def test_estimate_states_the_coverage_once_and_never_plus_minus(capsys, glass_record):
    code, out, err = run(capsys, "estimate", "--csv", glass_record)
    assert code == 0, err
    assert "±" in out and "+-" not in out
    assert out.count("k = 1") == 1


def test_calibrate_takes_time_for_the_contact_time_and_keeps_heat_as_an_alias():
    from host.cli.main import build_parser

    p = build_parser()
    assert p.parse_args(["calibrate", "--sim", "glass_15V", "--time", "3"]).heat == 3.0
    assert p.parse_args(["calibrate", "--sim", "glass_15V", "--heat", "4"]).heat == 4.0
    assert "--heat" not in p._subparsers._group_actions[0].choices["calibrate"].format_help()
