"""host.realprobe: the real-probe demonstration's scenes are valid and share one as-built probe.

(The demonstration itself takes ~45 s of faithful-world touches: `thermotouch demo --real-probe`;
its pieces -- calibration fit, install, chain estimate -- are tested in their own modules.)
"""

from __future__ import annotations

import pytest

from firmware_sim.scene.parser import parse_scene
from host.cli.main import main
from host.realprobe import AS_BUILT, HEAT_s, REFERENCE_TOUCHES, TEST_TOUCHES, scene_text


@pytest.mark.parametrize("touch", REFERENCE_TOUCHES + TEST_TOUCHES, ids=lambda t: f"{t.material}-{t.voltage_V:g}V")
def test_every_scene_parses_as_the_same_as_built_probe_on_the_faithful_world(touch):
    sc = parse_scene(scene_text("x", touch, 1))
    assert sc.board.world == "faithful" and sc.board.probe == "paper" and sc.board.ads122c04 is not None
    assert sc.as_built.flux_sensitivity_factor == AS_BUILT["flux_sensitivity_factor"]
    assert sc.as_built.sensing_thickness_factor == AS_BUILT["sensing_thickness_factor"]
    # The touch outlasts contact lead + heating: the probe is never lifted while heating.
    assert sc.touch.length_s > touch.lead_s + HEAT_s and not sc.touch.press_trigger


def test_real_probe_refuses_train_in_one_line(capsys, tmp_path):
    code = main(["demo", "--real-probe", "--train", "--out", str(tmp_path / "d")])
    err = capsys.readouterr().err
    assert code == 2 and "--train" in err and len(err.strip().splitlines()) == 1


def test_the_demo_shows_alpha_only_where_the_touch_determined_it():
    from host.realprobe import _alpha_cell

    measured = {"alpha_m2_s": 5.0e-5, "alpha_m2_s_u": 4e-6, "determined": ["e", "T_obj0", "alpha", "k"]}
    assert _alpha_cell(measured, 5.2e-5) == "; alpha measured 50 ± 4 mm²/s (-4%)"
    assert _alpha_cell({**measured, "determined": ["e", "T_obj0"]}, 5.2e-5) == ""
    assert _alpha_cell({"error": "x"}, 5.2e-5) == ""
