"""``thermotouch history --export-series``: a stored measurement's raw record as the CSV estimate reads."""

from __future__ import annotations

import json

from host.cli.main import main
from host.records import read_series


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_export_series_round_trips_into_estimate(capsys, tmp_path):
    w = tmp_path / "w"
    code, _, err = run(capsys, "measure", "--sim", "glass_15V", "--workdir", w)
    assert code == 0, err
    f = tmp_path / "m1.csv"
    code, out, err = run(capsys, "history", "--sim", "glass_15V", "--workdir", w, "--export-series", 1, f)
    assert code == 0 and "written" in out, err
    s = read_series(f)
    # The thermocouple as the device recorded it (°C), not converted (issue #33: columns as recorded).
    assert s["T_column"] == "T_C" and s["t_s"][0] < 0 < s["t_s"][-1]
    assert -10 < float(s["T"].mean()) < 60
    # Refuses to overwrite without --overwrite, and the file stays as it was.
    before = f.read_bytes()
    code, _, err = run(capsys, "history", "--sim", "glass_15V", "--workdir", w, "--export-series", 1, f)
    assert code == 2 and "--overwrite" in err and f.read_bytes() == before
    code, out, err = run(capsys, "estimate", "--csv", f, "--json")
    assert code == 0, err
    assert json.loads(out)["effusivity_W_s05_m2K"] > 0


def test_unknown_measurement_and_bad_id_are_one_line(capsys, tmp_path):
    code, _, err = run(capsys, "history", "--sim", "glass_15V", "--export-series", "x", tmp_path / "a.csv")
    assert code == 2 and "whole number" in err and len(err.strip().splitlines()) == 1
    code, _, err = run(capsys, "history", "--sim", "glass_15V", "--export-series", 5, tmp_path / "a.csv")
    assert code == 1 and "5" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "a.csv").exists()
