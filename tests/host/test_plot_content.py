"""What a touch's figure shows (ISSUE #36 plots), tested on the figure's content, not its pixels.

Data with the answer's model curve and its band at e -+ u(e) (k = 1), a residual panel, the pre-contact
phase and the fit's window shaded, identification in the title (never a port), a calibrated chain's
answer with the chain's own curve, and quantised data shown against the samples the fit used.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from host.plot_data import identification, touch_identity, touch_plot_data
from host.plots import TouchFigure, mpl_config_dir

# matplotlib: one worker pays for its import (tests/support/schedule.py).
pytestmark = pytest.mark.shares_import("matplotlib")

slow = pytest.mark.slow   # the figures are drawn and written (a few tenths of a second each)


@pytest.fixture(autouse=True, scope="module")
def _needs_matplotlib():
    """Skip without matplotlib; imported when a test here runs, not when every worker collects."""
    pytest.importorskip("matplotlib")


def _content_only(fig: TouchFigure, monkeypatch) -> TouchFigure:
    """``fig`` whose draws set its artists and write an empty file instead of rendering the PNG.

    These tests read the figure's artists (data, labels, limits), never its pixels: rendering is
    tests/host/test_plots.py's and the report tests' (PNG written, same size in and out of process), and
    the calibrated chain's figure below is rendered once.  A render is ~0.1 CPU-s a draw here.
    """
    monkeypatch.setattr(fig.fig, "savefig", lambda *args, **kwargs: None)
    return fig


IDENT = {"measurement_id": 17, "started_utc": "2026-11-27T12:34:56.789+00:00", "power_W": 4.5,
         "contact_time_s": 2.0, "model_sha256": "8e9c1c83d364" + "0" * 52, "calibration_sha256": None}


def _method_touch(step_K: float = 0.0):
    """A touch fitted by a method: raw samples from -0.5 s, the grid from heater-on, the fit's curve."""
    t = np.round(np.arange(-10, 41) * 0.05, 10)
    true = 0.6 * np.sqrt(np.maximum(t, 0.0))
    T = 20.0 + (np.round(true / step_K) * step_K if step_K else true)
    on = t >= 0
    series = {"raw_t_s": t, "raw_T_C": T, "raw_q_W_m2": 5 + 300 * on, "grid_t_s": t[on], "grid_dT_K": T[on] - 20.0,
              "grid_q_W_m2": 300.0 * np.ones(on.sum()), "T0_C": 20.0, "q_offset_W_m2": 5.0}
    result = {"effusivity_W_s05_m2K": 1500.0, "effusivity_W_s05_m2K_u": 75.0, "k_W_mK": 1.1, "k_W_mK_u": 0.1,
              "alpha_m2_s": 5e-7, "alpha_m2_s_u": 1e-7, "method": "default", "material": "glass",
              "material_confidence": 0.9, "flags": [], **IDENT}
    fit = SimpleNamespace(t_model_s=t[on], fit_T_K=true[on], method="default", effusivity_W_s05_m2K=1500.0,
                          effusivity_W_s05_m2K_u=75.0)
    return series, result, fit


@slow
def test_the_figure_shows_data_fit_band_residuals_phases_and_the_touch_identity(tmp_path, monkeypatch):
    series, result, fit = _method_touch()
    with _content_only(TouchFigure(), monkeypatch) as fig:
        fig.draw(tmp_path / "a.png", series, result, fit, "glass sample")
        title = fig._title.get_text()
        assert title.splitlines()[0] == ("measurement 17, 2026-11-27 12:34:56 UTC, 4.5 W, 2 s, model 8e9c1c83d364, "
                                         "calibration none")
        assert "glass sample" in title and "/dev/" not in title
        legend_T = [t.get_text() for t in fig.ax_T.get_legend().get_texts()]
        assert legend_T == ["measured", "fitted data", "model fit (default)", "model at e ± u(e)"]
        assert "k = 1" in fig.ax_T.get_title()
        # The band is the curve at e -+ u: 1/(1 + 5 %) and 1/(1 - 5 %) of it, with the curve inside.
        d = fig.data
        c = d["curve"]
        assert np.allclose(c["lo"], c["dT_K"] / 1.05) and np.allclose(c["hi"], c["dT_K"] / 0.95)
        assert len(fig.ax_T.collections) == 1 and len(fig.ax_r.collections) == 1
        # The residual panel: the fitted data less the curve, on the fit's samples.
        x, y = fig._r_pts.get_data()
        assert len(x) == 41 and np.allclose(y, 0.0, atol=1e-12)
        assert fig.ax_r.get_ylabel() == "residual (K)" and fig.ax_r.get_shared_x_axes().joined(fig.ax_r, fig.ax_T)
        # Every sample is shown, the pre-heater-on phase included, and the phases are shaded in each panel.
        assert fig._T_meas.get_data()[0][0] == -0.5
        assert d["pre_contact"] == (-0.5, 0.0) and d["window"][:2] == (0.0, 2.0)
        shaded = [p for ax in (fig.ax_q, fig.ax_T, fig.ax_r) for p in ax.patches]
        assert len(shaded) == 6
        assert [t.get_text() for t in fig.ax_q.get_legend().get_texts()][-2:] == ["before heater-on",
                                                                                  "default method's window"]
        # The next touch without a fit drops the curve, the band and the residuals, and says why.
        fig.draw(tmp_path / "b.png", series, result, None)
        assert not fig.ax_T.collections and len(fig._r_pts.get_data()[0]) == 0
        assert fig._note.get_text() == "measured series only: no model fit"


@slow
def test_on_quantised_data_the_fit_is_shown_against_the_samples_it_fitted(tmp_path, monkeypatch):
    step = 0.0625   # the reference board's converter step
    series, result, fit = _method_touch(step)
    d = touch_plot_data(series, result, fit)
    r = d["residual"]["r_K"]
    # The curve runs through the steps: every residual within half a step, none systematically off.
    assert np.all(np.abs(r) <= step / 2 + 1e-12) and abs(float(np.mean(r))) < step / 4
    with _content_only(TouchFigure(), monkeypatch) as fig:
        fig.draw(tmp_path / "q.png", series, result, fit)
        lo, hi = fig.ax_r.get_ylim()
        assert hi - lo < 4 * step      # the residual axis scales to the residuals, not to the signal


@slow
def test_a_calibrated_chain_answer_is_drawn_with_the_chains_own_curve(tmp_path, monkeypatch):
    from edge.estimation.chain_estimate import estimate_from_contact
    from edge.physics.materials import load_materials
    from firmware_sim.rigs.contact_record import ContactTouch, record_touch
    from tests.support.calibrations import sample_calibration

    cal = sample_calibration(flux_scale=1.0)
    rec = record_touch(ContactTouch(solid=load_materials().get("tempered_glass").solid, heat_s=2.0, pre_s=0.5,
                                    lead_s=0.3), seed=3)
    chain = estimate_from_contact(rec["t_s"], rec["T_C"], rec["q_W_m2"], cal)
    series = {"raw_t_s": rec["t_s"], "raw_T_C": rec["T_C"], "raw_q_W_m2": rec["q_W_m2"],
              "T0_C": float(rec["T_C"][0]), "q_offset_W_m2": 0.0}
    result = {k: chain.get(k) for k in ("effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u")}
    result.update(method="sensor_chain", probe="paper", flags=[], material="tempered_glass",
                  material_confidence=0.8, k_W_mK=None, k_W_mK_u=None, alpha_m2_s=None, alpha_m2_s_u=None,
                  sensor_chain=chain, **dict(IDENT, calibration_sha256=cal.sha256))
    with TouchFigure() as fig:
        fig.draw(tmp_path / "c.png", series, result, None, calibration=cal)
        d = fig.data
        assert d["note"] is None and d["curve"]["kind"] == "sensor_chain"
        assert fig._T_fit.get_label() == "calibrated sensor chain"
        assert f"calibration {cal.sha256[:12]}" in fig._title.get_text()
        # Its curve follows the record it fitted: residuals at the noise, the band about the curve.
        r = d["residual"]["r_K"]
        assert float(np.sqrt(np.mean(r ** 2))) < 3 * chain["noise_T_K"]
        assert np.all(d["curve"]["lo"] <= d["curve"]["dT_K"] + 1e-12)
        assert np.all(d["curve"]["hi"] >= d["curve"]["dT_K"] - 1e-12)
        # The pre-contact phase runs to the contact the chain found; the window from 0.3 s after it.
        t_c = d["pre_contact"][1]
        assert t_c == pytest.approx(chain["contact_t_s"], abs=0.051)
        assert d["window"][0] == pytest.approx(t_c + 0.3, abs=0.051)
        assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"   # a chain's figure renders
        # Without the device's calibration the plot says what it lacks instead of a wrong curve.
        _content_only(fig, monkeypatch).draw(tmp_path / "d.png", series, result, None)
        assert fig.data["curve"] is None and "needs the device's calibration" in fig._note.get_text()


def test_identity_fields_and_matplotlibs_cache_directory(tmp_path):
    rec = {"measurement_id": 3, "started_utc": "2026-11-27T01:02:03Z", "power_W": 2.0, "contact_time_s": 1.0,
           "model_sha256": None, "result": {"model_sha256": "ab" * 32, "calibration_sha256": "cd" * 32}}
    ident = touch_identity(rec)
    assert identification(ident) == ("measurement 3, 2026-11-27 01:02:03 UTC, 2 W, 1 s, model abababababab, "
                                      "calibration cdcdcdcdcdcd")
    # A home Matplotlib cannot write (here: under a regular file): its font cache goes to one persistent
    # place, not to a new temporary directory per call.
    blocker = tmp_path / "file"
    blocker.write_text("")
    import os
    import tempfile

    env = {"HOME": str(blocker / "home")}
    where = os.path.join(tempfile.gettempdir(), f"thermotouch-matplotlib-{os.getuid()}")
    assert mpl_config_dir(env) == where and os.path.isdir(where) and mpl_config_dir(env) == where
    assert mpl_config_dir({"MPLCONFIGDIR": str(tmp_path)}) is None
    assert mpl_config_dir({"HOME": str(tmp_path)}) is None   # a writable home: Matplotlib's own place
