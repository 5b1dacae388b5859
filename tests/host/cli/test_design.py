"""``thermotouch design``: attainable uncertainties from the Fisher information; one-line errors."""

import json

import pytest

import host.cli.design as design_cli
from host.cli.main import main


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_design_json_matches_the_library_function(capsys):
    from edge.estimation.design import attainable
    from edge.physics.materials import load_materials

    code, out, err = run(capsys, "design", "--heater-radius", "5", "--time", "2", "--material", "tempered_glass",
                         "--json")
    assert code == 0, err
    d = json.loads(out)
    from host.objects import board_noise

    sT, sq, dt = board_noise("precision")      # the default board's noise, not a typed pair
    assert (d["noise_T_K"], d["noise_q_W_m2"], d["dt_s"], d["board"]) == (sT, sq, dt, "precision")
    ref = attainable(load_materials().get("tempered_glass").solid, 2.0, heater_radius_m=5e-3, sigma_T_K=sT,
                     sigma_q_W_m2=sq, dt_s=dt)
    assert d["u_rel_alpha"] == pytest.approx(ref.u_rel_alpha, rel=1e-9)
    assert d["u_rel_k"] == pytest.approx(ref.u_rel_k, rel=1e-9)
    assert d["determined"] == ["e", "k", "alpha"] and d["heater_radius_mm"] == 5.0


def test_design_text_says_what_a_large_heater_cannot_determine(capsys):
    code, out, err = run(capsys, "design", "--heater-radius", "32", "--time", "1", "--material", "pmma")
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0].startswith("pmma, heater radius 32 mm")
    assert "determined" in lines[1] and "not determined" not in lines[1]     # e
    assert "not determined" in lines[2] and "> 100 %" in lines[2]              # k


def test_design_table_covers_the_grid(capsys, monkeypatch):
    # A reduced grid keeps the test fast; the command's own grid is the README's table.
    monkeypatch.setattr(design_cli, "TABLE_RADII_MM", (5.0, 32.0))
    monkeypatch.setattr(design_cli, "TABLE_TIMES_S", (1.0, 2.0))
    monkeypatch.setattr(design_cli, "TABLE_MATERIALS", ("pmma", "aluminium"))
    code, out, err = run(capsys, "design", "--table")
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0].startswith("| material | heater radius (mm) | 1 s:") and len(lines) == 2 + 4
    code, out, err = run(capsys, "design", "--table", "--json")
    assert code == 0 and len(json.loads(out)["rows"]) == 8


@pytest.mark.parametrize("argv,needle", [
    (["--heater-radius", "5", "--time", "2"], "give --heater-radius"),
    (["--heater-radius", "5", "--time", "2", "--material", "alu"], "no material named 'alu'"),
    (["--heater-radius", "0", "--time", "2", "--material", "pmma"], "--heater-radius"),
    (["--heater-radius", "5", "--time", "-1", "--material", "pmma"], "--time"),
    (["--heater-radius", "5", "--time", "0.05", "--material", "pmma"], "fewer than 5 samples"),
    (["--table", "--material", "pmma"], "--table computes its own grid"),
    (["--heater-radius", "x", "--time", "2", "--material", "pmma"], "expected a number"),
])
def test_design_bad_arguments_one_line(capsys, argv, needle):
    code, out, err = run(capsys, "design", *argv)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and needle in err


def test_design_hand_counts_contact_resistance_and_object_temperature(capsys):
    from edge.estimation.design import attainable
    from edge.physics.materials import load_materials

    argv = ("design", "--heater-radius-mm", "32", "--time", "1", "--material", "copper", "--json")
    code, out, err = run(capsys, *argv)
    plain = json.loads(out)
    code, out, err = run(capsys, *argv, "--hand", "--contact-resistance", "5e-5", "--lead", "2")
    assert code == 0, err
    d = json.loads(out)
    ref = attainable(load_materials().get("copper").solid, 1.0, heater_radius_m=32e-3, fit_contact=True,
                     contact_resistance_m2K_W=5e-5, fit_object_temperature=True, contact_lead_s=2.0,
                     sigma_T_K=d["noise_T_K"], sigma_q_W_m2=d["noise_q_W_m2"], dt_s=d["dt_s"])
    assert d["u_rel_effusivity"] == pytest.approx(ref.u_rel_effusivity, rel=1e-9)
    assert d["u_rel_effusivity"] > plain["u_rel_effusivity"] and d["hand"] == {"contact_resistance_m2K_W": 5e-5,
                                                                               "lead_s": 2.0}


def test_design_board_sets_the_noise_and_a_given_noise_overrides_it(capsys):
    from host.objects import board_noise

    base = ["design", "--heater-radius-mm", "5", "--time", "2", "--material", "pmma", "--json"]
    answers = {}
    for extra in ([], ["--board", "reference"], ["--board", "reference", "--noise-T", "0.004"]):
        code, out, err = run(capsys, *base, *extra)
        assert code == 0, err
        answers[tuple(extra)] = json.loads(out)
    prec, ref, mixed = answers.values()
    assert ref["board"] == "reference" and mixed["board"] is None      # an override is no longer the board's
    assert (ref["noise_T_K"], ref["noise_q_W_m2"], ref["dt_s"]) == board_noise("reference")
    assert (mixed["noise_T_K"], mixed["noise_q_W_m2"]) == (0.004, board_noise("reference")[1])
    # The reference board's converter is ~15 times noisier and 4 times slower: a wider bound.
    assert ref["u_rel_effusivity"] > 5 * prec["u_rel_effusivity"]
    assert prec["u_rel_effusivity"] < mixed["u_rel_effusivity"] < ref["u_rel_effusivity"]
    code, out, err = run(capsys, *base, "--board", "bench")
    assert code == 2 and "--board" in err and len(err.strip().splitlines()) == 1


def test_design_leaves_the_parsed_arguments_as_given(capsys):
    from host.cli.main import build_parser

    args = build_parser().parse_args(["design", "--heater-radius-mm", "5", "--time", "2", "--material", "pmma",
                                      "--board", "reference", "--json"])
    assert design_cli.run(args) == 0
    capsys.readouterr()
    # The board's noise was used, not written back: a caller re-running with these args still names the board.
    assert (args.noise_T, args.noise_q, args.dt) == (None, None, None)
