"""``thermotouch demo``: the README's main command runs twice in a row (ISSUE #36), and shows the instrument (ISSUE #34).

The default demo draws an as-built paper probe, calibrates it by the walk-through and touches the
paper's samples on the faithful world; ``--ideal`` (the ideal-world table) is covered by
tests/firmware_sim/test_hil_e2e.py.  One demo run in this module.

Its faithful world marches at ``DEVICE_DT_s`` (tests/support/faithful.py), twice the suite's step, as the round
trip's: what the test asserts is what the demo does with the records the device gets (the files, the
walk-through's calibration and self-check, every answer through it, the table consistent with results.json),
not the world's accuracy in time.  At 40 ms the demo takes the branches it takes at 20 ms (self-check passed,
nothing refused, 3 of 3 touches answered with the same flags, the interval holding the true e on all 3; e
within 0.2 % of the 20-ms run's): the test 6.5 -> 5.5 CPU-s (cpu_times plugin, loaded machine).  Its plots are
drawn in this process (``plots_in_process``): 5.5 -> 5.0 CPU-s, the plot child's 1.5 CPU-s less the matplotlib
import here (none where the worker has imported it already).
"""

import io
import json
import tomllib

import pytest

from host.cli.demo import default_out
from host.cli.main import main
from host.demo import DRAW_SEED, SAMPLE_SCENES
from tests.support.faithful import DEVICE_DT_s, world_step


@pytest.fixture
def device_world_step(faithful_world_test_step):
    """The demo's simulated probe's world marches at ``DEVICE_DT_s`` (see the module docstring)."""
    with world_step(DEVICE_DT_s):
        yield


class _PlotServerHere:
    """Stands in for the plot process's ``Popen``: the jobs :class:`host.plots.PlotProcess` writes to its stdin
    are drawn, at ``communicate``, by the child's own server loop (``host.plots._serve``) in this process."""

    def __init__(self):
        self.stdin, self.returncode = io.StringIO(), None

    def communicate(self, timeout=None):
        from host.plots import _serve

        out = io.StringIO()
        if self.returncode is None:
            self.returncode = _serve(io.StringIO(self.stdin.getvalue()), out)
        return out.getvalue(), ""

    def poll(self):
        return self.returncode

    def kill(self):
        self.returncode = -9


@pytest.fixture
def plots_in_process(monkeypatch):
    """The demo's plots drawn in this process: PlotProcess's job lines, replies and checks and its child's server
    loop, without the child's interpreter and imports (1.5 of the test's 6.5 CPU-s).  The demo's plot process
    itself is tests/firmware_sim/test_hil_e2e.py's (the ideal demo: the same measure_scenes and PlotProcess) and
    tests/host/test_plots.py's."""
    from host.plots import PlotProcess

    def here(self):
        self._paths, self._closed, self._proc = [], False, _PlotServerHere()

    monkeypatch.setattr(PlotProcess, "__init__", here)


def test_default_out_is_the_first_free_numbered_sibling(tmp_path):
    assert default_out(tmp_path) == tmp_path / "thermotouch-demo"
    (tmp_path / "thermotouch-demo").mkdir()
    (tmp_path / "thermotouch-demo-2").write_text("a user's file")
    assert default_out(tmp_path) == tmp_path / "thermotouch-demo-3"


def test_ideal_and_real_probe_are_two_demos(tmp_path, capsys):
    assert main(["demo", "--ideal", "--real-probe", "--out", str(tmp_path / "d")]) == 2
    assert "--ideal and --real-probe" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


@pytest.mark.slow  # the whole demo: a walk-through, three touches and their plots
@pytest.mark.hil
@pytest.mark.usefixtures("device_world_step", "plots_in_process")
def test_a_second_demo_writes_beside_the_first_and_shows_the_calibrated_instrument(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    first = tmp_path / "thermotouch-demo"
    first.mkdir()
    (first / "mine.txt").write_text("kept")
    assert main(["demo"]) == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert (first / "mine.txt").read_text() == "kept" and sorted(p.name for p in first.iterdir()) == ["mine.txt"]
    out = tmp_path / "thermotouch-demo-2"
    assert any((out / "plots").iterdir())
    code = main(["demo", "--out", str(first)])  # an explicit --out that exists still needs --overwrite
    assert code == 2 and "exists (use --overwrite" in capsys.readouterr().err

    # The probe is drawn as built, on the faithful world, and the device is never told the draw.
    res = json.loads((out / "results.json").read_text())
    assert res["mode"] == "as_built" and res["draw_seed"] == DRAW_SEED
    rows = res["rows"]
    assert [r["scene"] for r in rows] == [f"{s}_asbuilt" for s in SAMPLE_SCENES]
    assert sorted(p.name for p in (out / "plots").iterdir()) == sorted(f"{r['scene']}.png" for r in rows)
    for r in rows:
        scene = tomllib.loads((out / "scenes" / f"{r['scene']}.toml").read_text())
        assert scene["as_built"] == {"draw_seed": DRAW_SEED} and scene["board"]["world"] == "faithful"
    # It was calibrated by the walk-through, the calibration checked itself, and every answer went through it.
    sha = res["calibration_sha256"]
    assert res["calibration"]["probe"] == "paper" and res["self_check"]["method"] == "leave-one-reference-out"
    assert {r["name"] for r in res["calibration"]["references"]} == {"pmma", "pyroceram", "aisi_304"}
    assert f"calibration {sha[:12]}" in text and "self-check " in text
    assert res["refused"] is None or "calibration refused" in text   # a refusal is printed, never hidden
    answered = [r for r in rows if r["default"]["e"] is not None]
    assert answered, rows
    for r in answered:
        assert r["calibration_sha256"] == sha and "uncalibrated" not in r["flags"], r
        # Errors against the TRUE value (the simulated object's), not the estimator's world.
        e, u, e_true = r["default"]["e"], r["default"]["e_u"], r["ref"]["e"]
        assert r["default"]["errors"]["e"] == pytest.approx(e / e_true - 1)
        holds = e - 1.96 * u <= e_true <= e + 1.96 * u
        assert f"{e - 1.96 * u:.0f}–{e + 1.96 * u:.0f}" in text
        line = next(ln for ln in text.splitlines() if ln.startswith(r["scene"] + " ") and "│" in ln)
        assert (" yes " if holds else " NO ") in line
    held = sum(r["ref"]["e"] - 1.96 * r["default"]["e_u"] <= r["default"]["e"] <= r["ref"]["e"] + 1.96 * r["default"]["e_u"]
               for r in answered)
    assert f"{len(answered)} of {len(rows)} touches answered; the 95 % interval holds the true e on {held}" in text
    assert "heater invariant held on every touch: yes" in text
