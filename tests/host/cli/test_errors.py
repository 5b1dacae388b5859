"""The CLI's promise: bad arguments or input print one line naming what is wrong and exit 2, before any work.

One table (argv -> the option the line must name), then the cases that need
more than a table: files in the way, plots, CSV encodings, the device giving
no estimate, the default port, logging, the single error path, progress bars.
"""

from __future__ import annotations

import ast
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from host.cli.main import main

# measure --plot imports matplotlib in this process (the plot, and host.plots.preload while the touch runs):
# the schedule gives this module to the worker that imports it for the reports (tests/support/schedule.py).
pytestmark = [pytest.mark.slow, pytest.mark.shares_import("matplotlib")]

GLASS = ("--k", "1.097", "--rho", "2458.4", "--c", "809")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err and "internal error" not in err
    return lines[0]


@pytest.fixture
def place(tmp_path):
    """``{tmp}`` in argv -> a fresh directory holding ``afile`` (a file) and ``adir`` (a directory)."""
    (tmp_path / "afile").write_text("keep me\n")
    (tmp_path / "adir").mkdir()
    (tmp_path / "adir" / "keep.txt").write_text("keep me too\n")
    (tmp_path / "old.csv").write_text("old\n")
    (tmp_path / "old.png").write_bytes(b"old")
    (tmp_path / "record.csv").write_text("t_s,dT_K,q_W_m2\n0,0,0\n0.1,0.1,1\n0.2,0.2,2\n0.3,0.3,3\n")
    return tmp_path


M = ("measure", "--sim", "glass_15V")

BAD = [
    # measure: heater, timing, timeout -- checked on the host (were "internal error", exit 1)
    (M + ("--voltage", "-5"), "--voltage"),
    (M + ("--voltage", "0"), "--voltage"),
    (M + ("--voltage", "nan"), "--voltage"),
    (M + ("--voltage", "inf"), "--voltage"),
    (M + ("--voltage", "100"), "--voltage"),  # above the protocol's 48 V
    (M + ("--voltage", "x"), "--voltage"),
    (M + ("--power", "-1"), "--power"),
    (M + ("--power", "nan"), "--power"),
    (M + ("--power", "0"), "--power"),
    (M + ("--time", "0"), "--time"),
    (M + ("--time", "-inf"), "--time"),
    (M + ("--time", "100"), "--time"),  # above the protocol's 60 s
    (M + ("--timeout", "0"), "--timeout"),
    (M + ("--timeout", "-1"), "--timeout"),
    (M + ("--timeout", "nan"), "--timeout"),
    # measure --plot: format by suffix, a directory, a missing directory, an existing file
    (M + ("--plot", "{tmp}/out.txt"), "--plot"),
    (M + ("--plot", "{tmp}/adir"), "--plot"),
    (M + ("--plot", "{tmp}/noext"), "--plot"),
    (M + ("--plot", "{tmp}/nonexistent/x.png"), "--plot"),
    (M + ("--plot", "{tmp}/afile/x.png"), "--plot"),
    (M + ("--plot", "{tmp}/old.png"), "--plot"),  # exists: needs --overwrite
    (("measure", "--port", "/dev/x", "--workdir", "{tmp}"), "--workdir"),
    (("measure", "--port", "/dev/x", "--sim", "glass_15V"), "--sim"),
    (M + ("--bundle", "{tmp}"), "--bundle"),  # without --plot
    # estimate
    (("estimate", "--csv", "{tmp}/record.csv", "--thickness", "0"), "--thickness"),  # was silently ignored
    (("estimate", "--csv", "{tmp}/record.csv", "--thickness", "-0.01"), "--thickness"),
    (("estimate", "--csv", "{tmp}/record.csv", "--back", "fixed"), "--back"),  # no --thickness: was ignored
    (("estimate", "--csv", "{tmp}/nope.csv"), "--csv"),
    (("estimate", "--csv", "{tmp}/adir"), "--csv"),
    (("estimate", "--csv", "{tmp}/afile"), "--csv"),  # not a record
    # model
    (("model",) + GLASS + ("--duration", "1e6"), "--duration"),  # was MemoryError
    (("model",) + GLASS + ("--duration", "1000", "--dt", "1e-3"), "--dt"),  # 1e6 samples
    (("model",) + GLASS + ("--dt", "5"), "--dt"),
    (("model",) + GLASS + ("--dt", "0"), "--dt"),
    (("model",) + GLASS + ("--thickness", "0"), "--thickness"),
    (("model",) + GLASS + ("--qv", "nan"), "--qv"),
    (("model", "--k", "inf", "--rho", "1", "--c", "1"), "--k"),
    (("model", "--material", "pmma", "--rho", "1"), "--rho"),
    # train
    (("train", "--out", "/proc/thermotouch-x"), "--out"),  # was: trains fully, then fails
    (("train", "--out", "{tmp}/nonexistent/b"), "--out"),
    (("train", "--out", "{tmp}/adir"), "--out"),  # exists
    (("train", "--out", "{tmp}/afile"), "--out"),  # a file
    (("train", "--out", "{tmp}/b", "--seed", "-1"), "--seed"),  # was a scikit-learn exception
    (("train", "--out", "{tmp}/b", "--seed", str(2**32)), "--seed"),
    (("train", "--out", "{tmp}/b", "--seed", "1.5"), "--seed"),
    # demo
    (("demo", "--out", "{tmp}/afile"), "--out"),  # was FileExistsError
    (("demo", "--out", "{tmp}/adir"), "--out"),  # exists: its files are not replaced without --overwrite
    (("demo", "--out", "{tmp}/nonexistent/d"), "--out"),
    # history
    (("history", "--sim", "glass_15V", "--limit", "-3"), "--limit"),
    (("history", "--sim", "glass_15V", "--limit", "0"), "--limit"),
    (("history", "--sim", "glass_15V", "--export", "{tmp}/old.csv"), "--export"),
    (("history", "--sim", "glass_15V", "--export", "{tmp}/adir"), "--export"),
    # deploy (was the train-and-deploy script)
    (("deploy", "--sim", "glass_15V", "--quick", "--out", "{tmp}/adir"), "--out"),
    (("deploy", "--sim", "glass_15V", "--quick", "--out", "{tmp}/afile"), "--out"),
    (("deploy", "--sim", "glass_15V", "--max-paper-k", "-1"), "--max-paper-k"),
    (("deploy", "--sim", "glass_15V", "--max-paper-k", "x"), "--max-paper-k"),
    (("deploy", "--sim", "glass_15V", "--seed", "-1"), "--seed"),
    (("deploy", "--sim", "glass_15V", "--timeout", "0"), "--timeout"),
    (("deploy", "--sim", "glass_15V", "--bundle", "{tmp}/adir"), "adir"),
    (("deploy", "--sim", "glass_15V", "--reference", "pmma"), "--reference"),
    # global options
    (("--log-file", "{tmp}/nonexistent/log.txt", "model", "--material", "pmma"), "--log-file"),
    (("model", "--material", "pmma", "--log-file", "{tmp}/adir"), "--log-file"),
    (("measure", "--sim", "glass_15V", "--no-such-option"), "--no-such-option"),
]


@pytest.mark.parametrize("argv,needle", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_is_one_line_naming_the_option_and_exit_2(capsys, place, monkeypatch, argv, needle):
    monkeypatch.delenv("THERMOTOUCH_PORT", raising=False)
    before = sorted(p.relative_to(place) for p in place.rglob("*"))
    code, out, err = run(capsys, *[a.replace("{tmp}", str(place)) for a in argv])
    assert code == 2, err
    assert out == ""
    assert needle in one_line(err)
    # Nothing was created, replaced or removed.
    assert sorted(p.relative_to(place) for p in place.rglob("*")) == before
    assert (place / "afile").read_text() == "keep me\n" and (place / "old.png").read_bytes() == b"old"
    assert not Path("/proc/thermotouch-x").exists()


def test_no_port_names_the_options_and_the_environment_variable(capsys, monkeypatch):
    monkeypatch.delenv("THERMOTOUCH_PORT", raising=False)
    code, out, err = run(capsys, "info")
    assert code == 2 and "--port" in one_line(err) and "THERMOTOUCH_PORT" in err


def test_default_port_from_the_environment(capsys, monkeypatch):
    monkeypatch.setenv("THERMOTOUCH_PORT", "/dev/thermotouch-from-env")
    code, out, err = run(capsys, "info")
    assert code == 1
    assert one_line(err) == "thermotouch info: no such serial port: /dev/thermotouch-from-env"
    # --sim wins over the environment.
    code, out, err = run(capsys, "info", "--sim", "glass_15V", "--json")
    assert code == 0 and json.loads(out)["info"]["board"]


def test_the_once_built_parser_keeps_nothing_from_an_earlier_command_line(tmp_path):
    from host.cli.main import build_parser

    rec = tmp_path / "r.csv"
    rec.write_text("t_s,T_K,q_W_m2\n")
    p = build_parser()
    first = p.parse_args(["calibrate", "--record", str(rec), "--reference", "pmma", "--out", str(tmp_path / "c.json")])
    assert first.record == [rec] and first.reference == ["pmma"]
    again = p.parse_args(["calibrate", "--sim", "glass_15V", "--out", str(tmp_path / "c.json")])
    assert build_parser() is p and again.record == [] and again.reference == [] and again.sim == "glass_15V"


def test_version(capsys):
    code, out, err = run(capsys, "--version")
    assert code == 0 and out.startswith("thermotouch ") and err == ""


def test_help_returns_instead_of_exiting(capsys):
    code, out, err = run(capsys, "deploy", "--help")
    assert code == 0 and "--max-paper-k" in out and "--overwrite" in out and "--max-paper_k" not in out


# --- measure: plots and results -------------------------------------------------------------

def test_plot_bad_path_creates_no_directories_and_does_not_touch(capsys, tmp_path):
    target = tmp_path / "nonexistent" / "deeper" / "x.png"
    code, out, err = run(capsys, *M, "--workdir", tmp_path / "dev", "--plot", target)
    assert code == 2 and "--plot" in one_line(err) and "does not exist" in err
    assert not (tmp_path / "nonexistent").exists()
    assert not (tmp_path / "dev").exists()  # refused before the simulated probe started


def test_plot_directory_is_refused_and_nothing_else_is_written(capsys, tmp_path):
    d = tmp_path / "adir"
    d.mkdir()
    code, out, err = run(capsys, *M, "--plot", d)
    assert code == 2 and "is a directory" in one_line(err)
    assert list(tmp_path.iterdir()) == [d] and list(d.iterdir()) == []
    code, out, err = run(capsys, *M, "--plot", tmp_path / "adir2")  # no suffix: would have become adir2.png
    assert code == 2 and ".png" in one_line(err)
    assert list(tmp_path.iterdir()) == [d]


def test_plot_writes_exactly_the_reported_file_atomically_and_overwrite_replaces(capsys, tmp_path):
    png = tmp_path / "touch.png"
    code, out, err = run(capsys, *M, "--plot", png)
    assert code == 0, err
    assert f"plot: {png}" in out and png.read_bytes()[:4] == b"\x89PNG"
    assert [p.name for p in tmp_path.iterdir()] == ["touch.png"]  # no temporary left behind
    png.write_bytes(b"old")
    code, out, err = run(capsys, *M, "--plot", png)
    assert code == 2 and "--overwrite" in one_line(err) and png.read_bytes() == b"old"
    code, out, err = run(capsys, *M, "--plot", png, "--overwrite")
    assert code == 0 and png.read_bytes()[:4] == b"\x89PNG"
    svg = tmp_path / "touch.svg"
    code, out, err = run(capsys, *M, "--plot", svg)
    assert code == 0 and b"<svg" in svg.read_bytes()[:500]


def test_result_is_printed_before_a_plot_error(capsys, tmp_path, monkeypatch):
    import host.plots

    def disk_full(path, *a, **k):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(host.plots, "plot_touch", disk_full)
    for extra in ((), ("--json",)):
        code, out, err = run(capsys, *M, "--plot", tmp_path / "x.png", *extra)
        assert code == 1
        line = one_line(err)
        assert "cannot write the plot" in line and "No space left" in line and "x.png" in line
        if extra:
            assert json.loads(out)["effusivity_W_s05_m2K"] > 0
        else:
            assert "effusivity" in out and "±" in out
    assert not (tmp_path / "x.png").exists()


def test_measure_without_an_estimate_is_not_a_success(capsys):
    code, out, err = run(capsys, "measure", "--sim", "pmma_15V_no_contact")
    assert code == 1
    assert "effusivity   n/a" in out  # the record is still shown
    line = one_line(err)
    assert "gave no estimate" in line and "no_contact" in line
    code, out, err = run(capsys, "measure", "--sim", "pmma_15V_no_contact", "--json")
    assert code == 1 and json.loads(out)["flags"][0] == "no_contact"


def test_device_side_bad_argument_is_exit_2():
    from edge.protocol.commands import Command
    from edge.protocol.errors import ErrorCode
    from host.client import DeviceError
    from host.device import DeviceUnavailable, device_errors

    with pytest.raises(DeviceUnavailable) as info:
        with device_errors("/dev/ttyACM0"):
            raise DeviceError(ErrorCode.BAD_ARGUMENT, "contact_time_s must be <= 10", "contact_time_s",
                              Command.MEASURE)
    assert info.value.code == 2


# --- estimate: CSV encodings ------------------------------------------------------------------

def test_csv_with_a_utf8_byte_order_mark_is_accepted(capsys, glass_record, tmp_path):
    bom = tmp_path / "bom.csv"
    text = glass_record.read_text()
    bom.write_bytes(b"\xef\xbb\xbf" + "\n".join(ln for ln in text.splitlines() if not ln.startswith("#")).encode())
    code, out, err = run(capsys, "estimate", "--csv", bom, "--json")
    assert code == 0, err
    code2, out2, _ = run(capsys, "estimate", "--csv", glass_record, "--json")
    assert json.loads(out)["effusivity_W_s05_m2K"] == json.loads(out2)["effusivity_W_s05_m2K"]


@pytest.mark.parametrize("data", [bytes(range(256)) * 4, b"t_s,dT_K,q_W_m2\n0,0,0\x00\n", b"\xff\xfe" + "t_s".encode("utf-16-le")])
def test_binary_csv_is_one_line_exit_2(capsys, tmp_path, data):
    p = tmp_path / "binary.csv"
    p.write_bytes(data)
    code, out, err = run(capsys, "estimate", "--csv", p)
    assert code == 2 and out == ""
    line = one_line(err)
    assert "--csv" in line and "not a text CSV file" in line


def test_write_record_is_atomic(tmp_path):
    from host.records import write_record

    p = tmp_path / "r.csv"
    write_record(p, [0, 1], [0, 1], [0, 1])
    assert [x.name for x in tmp_path.iterdir()] == ["r.csv"]


# --- model ------------------------------------------------------------------------------------

def test_model_long_record_within_the_limits_runs(capsys):
    code, out, err = run(capsys, "model", *GLASS, "--duration", "100", "--dt", "0.1", "--json")
    assert code == 0, err
    assert len(json.loads(out)["t_s"]) == 1001


# --- history ----------------------------------------------------------------------------------

def test_history_limit_and_export(capsys, tmp_path):
    work = tmp_path / "dev"
    for _ in range(2):
        code, out, err = run(capsys, "measure", "--sim", "glass_12V", "--workdir", work, "--json")
        assert code in (0, 1), err
    code, out, err = run(capsys, "history", "--sim", "glass_12V", "--workdir", work, "--limit", "1", "--json")
    assert code == 0 and len(json.loads(out)) == 1
    csv_path = tmp_path / "h.csv"
    code, out, err = run(capsys, "history", "--sim", "glass_12V", "--workdir", work, "--export", csv_path)
    assert code == 0 and len(csv_path.read_text().splitlines()) == 3
    code, out, err = run(capsys, "history", "--sim", "glass_12V", "--workdir", work, "--export", csv_path)
    assert code == 2 and "--overwrite" in one_line(err)


# --- train / deploy / demo: nothing replaced without --overwrite --------------------------------

def test_deploy_refuses_an_existing_out_and_keeps_its_files(capsys, tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    (d / "mine.txt").write_text("mine")
    code, out, err = run(capsys, "deploy", "--sim", "glass_15V", "--quick", "--out", d)
    assert code == 2 and "exists" in one_line(err) and "--overwrite" in err
    assert [p.name for p in d.iterdir()] == ["mine.txt"]
    f = tmp_path / "f"
    f.write_text("a file")
    code, out, err = run(capsys, "deploy", "--sim", "glass_15V", "--quick", "--out", f, "--overwrite")
    assert code == 2 and "not a directory" in one_line(err) and f.read_text() == "a file"


def test_train_and_deploy_library_refuses_an_existing_out(tmp_path):
    from host.deploy import train_and_deploy

    (tmp_path / "d").mkdir()
    with pytest.raises(FileExistsError):
        train_and_deploy(None, tmp_path / "d", quick=True)  # refused before the session is used


def test_demo_library_refuses_an_existing_out(tmp_path):
    from host.demo import run_demo

    (tmp_path / "f").write_text("x")
    with pytest.raises(NotADirectoryError):
        run_demo(tmp_path / "f", progress=False, log=lambda m: None)
    with pytest.raises(FileExistsError):
        run_demo(tmp_path, progress=False, log=lambda m: None)
    assert [p.name for p in tmp_path.iterdir()] == ["f"]


def _imported_names(path: Path, package: str) -> set[str]:
    """Every module an ``import`` anywhere in the file names (lazy ones in functions too), relative ones resolved."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
    return names


def test_no_import_cycle_through_the_cli():
    # The library (every host module outside host/cli) never imports the CLI, not even lazily in a
    # function: read from the source, so a transitive path is caught at the module that takes it.
    host = Path(__file__).parents[3] / "host"
    offenders = {}
    for path in sorted(host.rglob("*.py")):
        rel = path.relative_to(host.parent).with_suffix("")
        if rel.parts[:2] == ("host", "cli"):
            continue
        package = ".".join(rel.parts[:-1])   # a module's package; an __init__'s is itself
        bad = sorted(n for n in _imported_names(path, package) if n == "host.cli" or n.startswith("host.cli."))
        if bad:
            offenders[str(rel)] = bad
    assert not offenders, offenders
    assert len(list(host.rglob("*.py"))) > 20
    for mod in ("demo", "deploy"):
        src = (host / f"{mod}.py").read_text()
        assert "host.cli" not in src and "CliError" not in src


def test_the_import_reader_sees_lazy_and_relative_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("import os\n"
                 "def f():\n"
                 "    from host.cli.main import main\n"
                 "    from .cli import common\n"
                 "    from ..edge import physics\n")
    names = _imported_names(f, "host.sub")
    assert {"os", "host.cli.main", "host.cli.main.main", "host.sub.cli", "host.sub.cli.common",
            "host.edge", "host.edge.physics"} <= names


# --- the one error path ---------------------------------------------------------------------------

def _replace_verb(monkeypatch, module, fn):
    """``module.run`` replaced by ``fn`` for this test; the parser is built afresh while it is (a
    verb's ``func`` is bound when the once-per-process parser is built, host/cli/main.py)."""
    import host.cli.main

    monkeypatch.setattr(module, "run", fn)
    monkeypatch.setattr(host.cli.main, "build_parser", host.cli.main.build_parser.__wrapped__)


def test_unexpected_error_is_one_line_and_the_traceback_goes_to_the_log_file(capsys, tmp_path, monkeypatch):
    import host.cli.model

    def boom(args):
        raise RuntimeError("something broke")

    _replace_verb(monkeypatch, host.cli.model, boom)
    monkeypatch.delenv("THERMOTOUCH_DEBUG", raising=False)
    log = tmp_path / "tt.log"
    code, out, err = run(capsys, "model", "--material", "pmma", "--log-file", log)
    assert code == 1
    line = one_line(err.replace("internal error", "INTERNAL"))
    assert line.startswith("thermotouch model: INTERNAL") and "RuntimeError: something broke" in line
    text = log.read_text()
    assert "Traceback" in text and "something broke" in text


def test_interrupt_is_one_line_exit_130(capsys, monkeypatch):
    import host.cli.model

    def interrupted(args):
        raise KeyboardInterrupt

    _replace_verb(monkeypatch, host.cli.model, interrupted)
    code, out, err = run(capsys, "model", "--material", "pmma")
    assert code == 130 and one_line(err) == "thermotouch: interrupted"


def test_verbose_logs_on_stderr_and_quiet_runs_do_not(capsys, tmp_path):
    code, out, err = run(capsys, "--verbose", "info", "--sim", "glass_15V")
    assert code == 0 and "thermotouch info" in err and "DEBUG" in err
    code, out, err = run(capsys, "info", "--sim", "glass_15V", "-v")  # after the verb too
    assert code == 0 and "DEBUG" in err
    code, out, err = run(capsys, "info", "--sim", "glass_15V")
    assert code == 0 and err == ""


def test_device_warnings_do_not_add_a_second_line():
    r = subprocess.run([sys.executable, "-m", "host.cli", "measure", "--sim", "glass_15V_faults"],
                       capture_output=True, text=True, timeout=120, env=dict(os.environ, THERMOTOUCH_DEBUG=""))
    assert r.returncode == 1
    assert len(r.stderr.strip().splitlines()) == 1 and "SENSOR_FAULT" in r.stderr


# --- progress bars --------------------------------------------------------------------------------

class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_a_finished_bar_ends_its_line_before_the_next_message():
    from host.progress import ProgressBar, Ticker, echo

    s = _Tty()
    with ProgressBar("training set", "material", file=s) as bar:
        for i in range(1, 6):
            bar(i, 5)
        echo("fitting on all materials ...", file=s)
    text = s.getvalue()
    assert "training set" in text and "\nfitting on all materials ...\n" in text
    s = _Tty()
    with Ticker("fit", file=s, interval_s=0.01):
        pass
    echo("next", file=s)
    assert s.getvalue().endswith("\nnext\n") and "fit" in s.getvalue()


def test_a_message_during_a_bar_is_on_its_own_line():
    from host.progress import ProgressBar, echo

    s = _Tty()
    with ProgressBar("flashing", "B", file=s) as bar:
        bar(1, 10)
        echo("a message", file=s)
        bar(10, 10)
    text = s.getvalue()
    # tqdm clears the bar's line (carriage return) and writes the message there, then redraws the bar below.
    i = text.index("a message\n")
    assert text[i - 1] in "\r\n" and "flashing" in text[i:]


def test_bars_stay_off_the_output_when_stderr_is_not_a_terminal():
    from host.progress import ProgressBar, Ticker

    s = io.StringIO()
    with ProgressBar("x", file=s) as bar, Ticker("y", file=s, interval_s=0.01):
        bar(1, 2)
        bar(2, 2)
    assert s.getvalue() == ""
