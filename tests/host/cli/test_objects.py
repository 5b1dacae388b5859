"""``thermotouch objects add|list|remove|select`` on a simulated probe, and ``measure --json`` naming the object."""

import json

import pytest

from tests.host.cli.conftest import KITCHEN
from tests.support.cli import one_line_error as one_line, run

pytestmark = pytest.mark.hil


def test_add_list_measure_remove_on_a_kept_simulated_probe(capsys, tmp_path, kitchen):
    sim = ("--sim", "glass_15V", "--workdir", tmp_path / "probe")
    code, out, err = run(capsys, "objects", "add", kitchen, *sim, "--json")
    assert code == 0, err
    assert json.loads(out)["name"] == "kitchen" and json.loads(out)["active"] == "kitchen"
    code, out, err = run(capsys, "objects", "list", *sim, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["active"] == "kitchen" and [s["name"] for s in d["sets"]] == ["kitchen"] and d["sets"][0]["objects"] == 2
    code, out, err = run(capsys, "objects", "list", *sim)
    assert code == 0 and "* kitchen" in out
    # The set survives the simulated probe's restart (each command starts it afresh on the same workdir).
    code, out, err = run(capsys, "measure", *sim, "--json")
    assert code == 0, err
    m = json.loads(out)
    assert m["object_set"] == "kitchen" and m["object"] == "window" and m["class"] == "glass/ceramic/stone"
    assert m["object_posterior"] > 0.9 and m["class_posterior"] > 0.9
    assert [c["name"] for c in m["candidates"]] == ["window", "lid"]
    assert all(set(c) == {"name", "posterior"} for c in m["candidates"])
    code, out, err = run(capsys, "objects", "remove", "kitchen", *sim)
    assert code == 0 and "active set: library" in out, err
    code, out, err = run(capsys, "objects", "remove", "kitchen", *sim)
    assert code == 2 and "no object set 'kitchen'" in one_line(err)
    code, out, err = run(capsys, "measure", *sim, "--json")
    assert code == 0, err
    m = json.loads(out)
    assert m["object_set"] == "library" and m["class"] == "glass/ceramic/stone" and len(m["candidates"]) == 3


def test_measure_json_carries_the_fields_estimate_json_gives(capsys, tmp_path):
    code, out, err = run(capsys, "measure", "--sim", "glass_15V", "--json")
    assert code == 0, err
    m = json.loads(out)
    for key in ("object_set", "object", "object_posterior", "class", "class_posterior", "candidates"):
        assert key in m, key
    assert m["object_set"] == "library" and len(m["candidates"]) == 3


@pytest.mark.parametrize("text,needle", [
    ("name,class,k_W_mK,rho_kg_m3\nwindow,glass,1.1,2450\n", "line 1, column 'c_J_kgK'"),
    ("name,class,e_W_s05_m2K\nwindow,glass,n/a\n", "line 2, column 'e_W_s05_m2K'"),
    ("name,class,k_W_mK,rho_kg_m3,c_J_kgK\nwindow,glass,-1.1,2450,810\n", "line 2, column 'k_W_mK'"),
    ("name,class,e_W_s05_m2K\nwindow,glass,1400\nwindow,glass,1500\n", "line 3, column 'name'"),
])
def test_a_bad_file_is_refused_before_connecting(capsys, tmp_path, text, needle):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    # --port of a port that does not exist: the file is refused before any connection is tried.
    code, out, err = run(capsys, "objects", "add", p, "--port", str(tmp_path / "no-such-port"))
    assert code == 2 and out == ""
    line = one_line(err)
    assert str(p) in line and needle in line


def test_a_name_the_device_cannot_store_is_refused(capsys, tmp_path, kitchen):
    code, out, err = run(capsys, "objects", "add", kitchen, "--name", "library", "--port", tmp_path / "none")
    assert code == 2 and "reserved" in one_line(err)
    code, out, err = run(capsys, "objects", "select", "nothing", "--sim", "glass_15V")
    assert code == 2 and "no object set 'nothing'" in one_line(err)
