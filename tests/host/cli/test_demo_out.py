"""The README's main command runs twice in a row (ISSUE #36): a rerun writes beside the first, replacing nothing."""

import pytest

from host.cli.demo import default_out
from host.cli.main import main


def test_default_out_is_the_first_free_numbered_sibling(tmp_path):
    assert default_out(tmp_path) == tmp_path / "thermotouch-demo"
    (tmp_path / "thermotouch-demo").mkdir()
    (tmp_path / "thermotouch-demo-2").write_text("a user's file")
    assert default_out(tmp_path) == tmp_path / "thermotouch-demo-3"


@pytest.mark.slow  # the whole demo, nine scenes and their plots
@pytest.mark.hil
def test_a_second_demo_writes_beside_the_first(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    first = tmp_path / "thermotouch-demo"
    first.mkdir()
    (first / "mine.txt").write_text("kept")
    assert main(["demo"]) == 0, capsys.readouterr().err
    assert (first / "mine.txt").read_text() == "kept" and sorted(p.name for p in first.iterdir()) == ["mine.txt"]
    assert any((tmp_path / "thermotouch-demo-2" / "plots").iterdir())
    code = main(["demo", "--out", str(first)])  # an explicit --out that exists still needs --overwrite
    assert code == 2 and "exists (use --overwrite" in capsys.readouterr().err
