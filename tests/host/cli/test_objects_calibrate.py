"""``thermotouch objects calibrate``: the fit written into the set's CSV, offline."""

import json

import pytest

from edge.recognition import ObjectSet
from host.cli.main import main

pytestmark = pytest.mark.slow


@pytest.fixture
def device_world_step(faithful_world_test_step):
    """The small-heater touches' faithful world at ``DEVICE_DT_s`` (tests/support/faithful.py), twice the suite's step.

    What is checked is the command's path (the small-heater estimator fits the world's touches, the set is
    written), not the world's accuracy in time: half the steps, the file 1.71 -> 1.43 CPU-s (7 touches fitted at
    both steps)."""
    from tests.support.faithful import DEVICE_DT_s, world_step  # noqa: PLC0415

    with world_step(DEVICE_DT_s):
        yield


KITCHEN = "name,class,k_W_mK,rho_kg_m3,c_J_kgK,e_W_s05_m2K\nwindow,glass,1.1,2450,810,\nlid,polymer,0.19,1180,1430,\n" \
          "pan,alloy,,,,8200\n"


def test_calibrate_writes_the_fit_as_directives(capsys, tmp_path):
    src = tmp_path / "kitchen.csv"
    src.write_text(KITCHEN)
    code = main(["objects", "calibrate", str(src), "--touches", "2", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    rep = json.loads(out)
    written = tmp_path / "kitchen_calibrated.csv"
    assert rep["file"] == str(written) and rep["board"] == "ads122c04" and rep["touches"] == 3 * 2 * 4
    s = ObjectSet.from_csv_text(written.read_text())
    assert s.names == ("window", "lid", "pan")
    assert s.temperature == rep["temperature"] and s.z_crit == rep["z_crit"] >= 1.96
    # The specimen spread is the objects' own: T stays 1 and only the stated u is rescaled (ISSUE #37).
    assert s.temperature == 1.0 and s.u_var_scale == rep["u_var_scale"] > 0
    assert "#@ u_var_scale" in written.read_text() or rep["u_var_scale"] == 1.0
    assert all(r["temperature"] == 1.0 and r["u_var_scale"] > 0 for r in rep["by_contact_s"].values())
    assert src.read_text() == KITCHEN  # the input is left alone


def test_calibrate_refuses_a_bad_file_in_one_line(capsys, tmp_path):
    src = tmp_path / "bad.csv"
    src.write_text("name,class\nx,wood\n")
    code = main(["objects", "calibrate", str(src), "--out", str(tmp_path / "o.csv")])
    _, err = capsys.readouterr()
    assert code == 2 and "Traceback" not in err and not (tmp_path / "o.csv").exists()


def test_calibrate_for_the_small_heater_probe_fits_on_touches_that_measure_alpha(capsys, tmp_path, device_world_step):
    # Two objects, one specimen each, on the faithful world: every touch at 0.5 / 1 / 1.5 / 2 s is fitted
    # by the small-heater estimator (the 'pan' given by e alone gets alpha from the library prior).
    src = tmp_path / "kitchen.csv"
    src.write_text("name,class,k_W_mK,rho_kg_m3,c_J_kgK,e_W_s05_m2K\nwindow,glass,1.1,2450,810,\n"
                   "pan,alloy,,,,8200\n")
    out_csv = tmp_path / "small.csv"
    code = main(["objects", "calibrate", str(src), "--probe", "small-heater", "--touches", "1", "--out",
                 str(out_csv), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    rep = json.loads(out)
    assert rep["probe"] == "small-heater" and 0 < rep["touches"] <= 2 * 4
    s = ObjectSet.from_csv_text(out_csv.read_text())
    assert s.names == ("window", "pan") and s.temperature == rep["temperature"]
