"""ISSUE #35 §10: names from outside reach history --export cells as text, never as spreadsheet formulas."""

import csv

import pytest

from host.cli.main import main
from host.cli.report import csv_cell

EVIL = '=HYPERLINK("http://x","a")'


def test_cells_that_a_spreadsheet_would_run_are_quoted_and_numbers_are_not():
    assert csv_cell(EVIL) == "'" + EVIL
    assert [csv_cell(v) for v in ("@lid", "+1", "-x", "\tx", "\rx")] == ["'@lid", "'+1", "'-x", "'\tx", "'\rx"]
    assert csv_cell("glass") == "glass" and csv_cell(-1.5) == -1.5 and csv_cell(None) is None


@pytest.mark.hil
def test_an_object_named_like_a_formula_is_exported_as_text_with_the_calibration_column(capsys, tmp_path):
    objs = tmp_path / "evil.csv"
    objs.write_text(f'name,class,k_W_mK,rho_kg_m3,c_J_kgK\n"{EVIL.replace(chr(34), 2 * chr(34))}",glass,1.1,2500,800\n'
                    "@lid,polymer,0.19,1180,1430\n")
    sim = ["--sim", "glass_15V", "--workdir", str(tmp_path / "w")]
    assert main(["objects", "add", str(objs), "--name", "evil", *sim]) == 0
    assert main(["measure", *sim]) == 0
    out = tmp_path / "h.csv"
    assert main(["history", *sim, "--export", str(out)]) == 0
    capsys.readouterr()
    (row,) = list(csv.DictReader(out.open(newline="")))
    assert row["object"] == "'" + EVIL and "calibration_sha256" in row
