"""Nothing the user owns is replaced without --overwrite; failures exit as promised (issue 36, "Bad input")."""

import contextlib
import errno
import json

import pytest

from tests.host.cli.conftest import KITCHEN
from tests.support.cli import one_line_error as one_line, run

LONG = "a" * 300


@pytest.mark.hil
def test_objects_add_refuses_a_stored_name_without_overwrite(capsys, tmp_path, kitchen):
    sim = ("--sim", "glass_15V", "--workdir", tmp_path / "probe")
    assert run(capsys, "objects", "add", kitchen, *sim)[0] == 0
    other = tmp_path / "other.csv"
    other.write_text(KITCHEN.replace("window", "pane"))
    code, out, err = run(capsys, "objects", "add", other, "--name", "kitchen", *sim)
    line = one_line(err)
    assert code == 2 and line.startswith("thermotouch objects add: ") and "--overwrite" in line and out == ""
    code, out, err = run(capsys, "objects", "list", *sim, "--json")
    sets = json.loads(out)["sets"]
    assert [s["name"] for s in sets] == ["kitchen"]
    stored = sets[0]["sha256"]
    code, out, err = run(capsys, "objects", "add", other, "--name", "kitchen", "--overwrite", *sim)
    assert code == 0, err
    code, out, err = run(capsys, "objects", "list", *sim, "--json")
    assert json.loads(out)["sets"][0]["sha256"] != stored  # replaced, as asked


def test_objects_calibrate_never_writes_onto_its_input(capsys, kitchen):
    for extra in ((), ("--overwrite",)):
        code, out, err = run(capsys, "objects", "calibrate", kitchen, "--out", kitchen, *extra)
        assert code == 2 and "is the input FILE" in one_line(err)
    assert kitchen.read_text() == KITCHEN


def test_objects_calibrate_keeps_an_existing_calibrated_csv(capsys, tmp_path, kitchen):
    mine = tmp_path / "kitchen_calibrated.csv"
    mine.write_text("the user's own")
    code, out, err = run(capsys, "objects", "calibrate", kitchen)
    assert code == 2 and "kitchen_calibrated.csv exists (use --overwrite" in one_line(err)
    theirs = tmp_path / "elsewhere.csv"
    theirs.write_text("kept too")
    code, out, err = run(capsys, "objects", "calibrate", kitchen, "--out", theirs)
    assert code == 2 and "--out" in one_line(err) and "--overwrite" in one_line(err)
    assert mine.read_text() == "the user's own" and theirs.read_text() == "kept too"


@pytest.mark.parametrize("argv", [
    ("estimate", "--csv", f"{LONG}.csv"),
    ("objects", "calibrate", f"{LONG}.csv"),
    ("measure", "--sim", "glass_15V", "--plot", f"{LONG}.png"),
    ("demo", "--out", LONG),
], ids=["estimate", "objects-calibrate", "measure-plot", "demo"])
def test_a_too_long_file_name_exits_2_with_the_verbs_prefix(capsys, tmp_path, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, *argv)
    line = one_line(err)
    verb = " ".join(argv[:2]) if argv[0] == "objects" else argv[0]
    assert code == 2 and line.startswith(f"thermotouch {verb}: ") and "too long" in line, line
    assert len(line) < 200  # the name is shortened in the message


class _NoPlots:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


@pytest.mark.parametrize("failure", ["disk full", "unreadable scene"])
def test_demo_failure_exits_1_and_leaves_nothing(capsys, tmp_path, monkeypatch, failure):
    import host.demo
    import host.plots
    from host.device import DeviceUnavailable

    @contextlib.contextmanager
    def failing_device(*args, workdir=None, **kw):
        workdir.mkdir(parents=True, exist_ok=True)
        (workdir / "half-written").write_text("x")  # something was written before the disk filled
        if failure == "disk full":
            raise OSError(errno.ENOSPC, "No space left on device", str(workdir / "store"))
        raise DeviceUnavailable("invalid scene: truncated", 2)  # a scene file the full disk cut short
        yield  # pragma: no cover

    monkeypatch.setattr(host.demo, "open_device", failing_device)
    monkeypatch.setattr(host.plots, "PlotProcess", _NoPlots)
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, "demo", "--out", "run")
    line = one_line(err)
    assert code == 1 and line.startswith("thermotouch demo: ") and "nothing written to run" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no partial folder to block the rerun


def test_real_probe_demo_failure_exits_1_and_leaves_nothing(capsys, tmp_path, monkeypatch):
    import host.realprobe

    def full_disk(out, say=print):
        (out / "probe").mkdir()
        raise OSError(errno.ENOSPC, "No space left on device", str(out / "probe" / "history.sqlite"))

    monkeypatch.setattr(host.realprobe, "run_real_probe", full_disk)
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, "demo", "--real-probe", "--out", "real")
    line = one_line(err)
    assert code == 1 and "nothing written to real" in line and "No space left" in line, line
    assert list(tmp_path.iterdir()) == []
