"""Touch plots: the re-used figure and the plot process write what the caller asked, or say why not."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from host.plots import PlotError, PlotProcess, TouchFigure, plot_touch

# The in-process figures import matplotlib: one worker pays for it (tests/support/schedule.py).
pytestmark = [pytest.mark.slow, pytest.mark.shares_import("matplotlib")]


@pytest.fixture(autouse=True, scope="module")
def _needs_matplotlib():
    """Skip without matplotlib; imported when a test here runs, not when every worker collects."""
    pytest.importorskip("matplotlib")


PNG = b"\x89PNG"


def _touch(scale: float = 1.0):
    t = np.arange(-0.5, 2.01, 0.1)
    series = {"raw_t_s": t, "raw_T_C": 20 + scale * np.sqrt(np.maximum(t, 0)), "raw_q_W_m2": 5 + 300 * scale * (t > 0),
              "grid_t_s": t[t >= 0], "grid_q_W_m2": 300 * scale * np.ones((t >= 0).sum()), "T0_C": 20.0,
              "q_offset_W_m2": 5.0}
    result = {"effusivity_W_s05_m2K": 1500.0 * scale, "effusivity_W_s05_m2K_u": 20.0, "k_W_mK": 1.1,
              "k_W_mK_u": 0.1, "alpha_m2_s": 5e-7, "alpha_m2_s_u": 1e-7, "method": "default",
              "material": "glass", "material_confidence": 0.9, "flags": []}
    fit = SimpleNamespace(t_model_s=t[t >= 0], fit_T_K=scale * np.sqrt(t[t >= 0]), method="default")
    return series, result, fit


def _size(png: bytes) -> tuple[int, int]:
    return int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")


def test_plot_process_writes_each_touch_like_the_in_process_figure(tmp_path):
    with PlotProcess() as pp:
        for i in range(3):
            series, result, fit = _touch(1 + i)
            assert pp.submit(tmp_path / f"t{i}.png", series, result, fit, f"touch {i}") == tmp_path / f"t{i}.png"
        assert pp.close() == [tmp_path / f"t{i}.png" for i in range(3)]
    series, result, fit = _touch(1)
    plot_touch(tmp_path / "local.png", series, result, fit, "touch 0")
    local = (tmp_path / "local.png").read_bytes()
    for i in range(3):
        png = (tmp_path / f"t{i}.png").read_bytes()
        assert png[:4] == PNG and _size(png) == _size(local)
    # the drawn data differ from touch to touch: the re-used figure does not repeat the first touch
    assert (tmp_path / "t0.png").read_bytes() != (tmp_path / "t1.png").read_bytes()


def test_a_reused_figure_drops_curves_a_touch_does_not_have(tmp_path):
    series, result, fit = _touch()
    with TouchFigure() as fig:
        fig.draw(tmp_path / "a.png", series, result, fit)
        bare = dict(series, grid_t_s=None)
        fig.draw(tmp_path / "b.png", bare, result, None)
        assert [t.get_text() for t in fig.ax_T.get_legend().get_texts()] == ["measured"]
        assert [t.get_text() for t in fig.ax_q.get_legend().get_texts()] == ["measured", "before heater-on"]
    assert (tmp_path / "b.png").read_bytes()[:4] == PNG


def test_a_plot_that_cannot_be_written_is_named_and_nothing_else_is_lost(tmp_path):
    series, result, fit = _touch()
    pp = PlotProcess()
    pp.submit(tmp_path / "ok.png", series, result, fit)
    pp.submit(tmp_path / "missing-dir" / "x.png", series, result, fit)
    with pytest.raises(PlotError, match="missing-dir/x.png"):
        pp.close()
    assert (tmp_path / "ok.png").read_bytes()[:4] == PNG
    assert not (tmp_path / "missing-dir").exists()  # nothing created behind the caller's back


def test_a_plot_process_that_dies_is_reported(tmp_path):
    series, result, fit = _touch()
    pp = PlotProcess()
    pp._proc.kill()
    pp._proc.wait()
    with pytest.raises(PlotError, match="plot process ended"):
        pp.submit(tmp_path / "x.png", series, result, fit)
        pp.close()


def test_a_failing_caller_does_not_wait_for_its_plots(tmp_path):
    series, result, fit = _touch()
    with pytest.raises(RuntimeError, match="touch failed"):
        with PlotProcess() as pp:
            pp.submit(tmp_path / "x.png", series, result, fit)
            raise RuntimeError("touch failed")
    assert pp._proc.poll() is not None  # the child is gone, not left drawing
