"""``thermotouch estimate --objects``: the object among the user's own, and one-line errors for bad files."""

import json

import pytest

from host.cli.main import main

GOOD = ("name,class,k_W_mK,rho_kg_m3,c_J_kgK,spread_rel\n"
        "window,glass,1.0,2500,800,0.05\n"
        "lid,polymer,0.19,1180,1430,\n"
        "desk,wood,0.15,600,1700,0.1\n")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def write(tmp_path, text, name="objects.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_names_the_object_among_the_file(capsys, tmp_path, glass_record):
    objs = write(tmp_path, GOOD)
    code, out, err = run(capsys, "estimate", "--csv", glass_record, "--objects", objs, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["object"] == "window" and d["class"] == "glass/ceramic/stone"
    assert d["object_posterior"] > 0.9 and d["class_posterior"] >= d["object_posterior"]
    assert [c["name"] for c in d["candidates"]][0] == "window" and len(d["candidates"]) == 3
    assert all(set(c) == {"name", "posterior"} for c in d["candidates"])
    # The one result shape states a probability to P_DIGITS significant digits (issue #33's Estimate):
    # the three stated candidates (the file's three objects, closed-set) sum to one within their rounding.
    from edge.estimation.result import P_DIGITS

    stated = [c["posterior"] for c in d["candidates"]]
    assert sum(stated) == pytest.approx(1.0, abs=sum(0.5 * 10.0 ** (1 - P_DIGITS) * p for p in stated))


def test_far_from_every_object_is_unknown(capsys, tmp_path, glass_record):
    objs = write(tmp_path, "name,class,e_W_s05_m2K\nfoam,foam,40\nsteel,metal,14000\n")
    code, out, err = run(capsys, "estimate", "--csv", glass_record, "--objects", objs, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["object"] == "unknown" and d["class"] == "unknown" and d["object_posterior"] > 0.5


def test_without_objects_the_library_names_it(capsys, glass_record):
    code, out, err = run(capsys, "estimate", "--csv", glass_record, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["object_set"] == "library" and d["class"] == "glass/ceramic/stone" and len(d["candidates"]) == 3


def test_text_output_names_the_object(capsys, tmp_path, glass_record):
    code, out, _ = run(capsys, "estimate", "--csv", glass_record, "--objects", write(tmp_path, GOOD))
    assert code == 0 and "object       window" in out


@pytest.mark.parametrize("text,line,column", [
    ("name,class,k_W_mK,rho_kg_m3\nwindow,glass,1.0,2500\n", 1, "c_J_kgK"),             # missing column
    ("name,class,k_W_mK,rho_kg_m3,c_J_kgK\nwindow,glass,abc,2500,800\n", 2, "k_W_mK"),  # not a number
    ("name,class,k_W_mK,rho_kg_m3,c_J_kgK\n# comment\nwindow,glass,-1.0,2500,800\n", 3, "k_W_mK"),  # negative k
    ("name,class,e_W_s05_m2K\nwindow,glass,1400\nwindow,glass,1500\n", 3, "name"),      # duplicate name
])
def test_bad_objects_file_one_line_exit_2(capsys, tmp_path, glass_record, text, line, column):
    objs = write(tmp_path, text)
    code, out, err = run(capsys, "estimate", "--csv", glass_record, "--objects", objs, "--json")
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert str(objs) in lines[0] and f"line {line}" in lines[0] and f"column '{column}'" in lines[0]


def test_not_utf8_and_missing_file(capsys, tmp_path, glass_record):
    p = tmp_path / "latin1.csv"
    p.write_bytes("name,class,e_W_s05_m2K\nfen\xeatre,glass,1400\n".encode("latin-1"))
    code, _, err = run(capsys, "estimate", "--csv", glass_record, "--objects", p)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "UTF-8" in err
    code, _, err = run(capsys, "estimate", "--csv", glass_record, "--objects", tmp_path / "nope.csv")
    assert code == 2 and len(err.strip().splitlines()) == 1
