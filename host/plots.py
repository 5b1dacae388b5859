"""Plots of one touch: measured and model-fitted heat flux and temperature (like the paper's Figs. 10, 12, 14).

The model curve is recomputed on the host from the record's resampled series
with the same bundle the device used (:class:`edge.estimation.estimate.Estimator`
returns the fitted temperature ``fit_T_K`` on its model grid ``t_model_s``);
the flux panel shows the measured samples and the resampled flux the model
was driven with.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

__all__ = ["result_title", "plot_touch"]


def _pm(v: float | None, u: float | None, scale: float = 1.0) -> str:
    """``v ± u`` rounded to two significant digits of ``u``."""
    if v is None:
        return "n/a"
    v, u = v * scale, (u or 0.0) * scale
    if not u > 0:
        return f"{v:.4g}"
    decimals = 1 - int(math.floor(math.log10(u)))
    if decimals >= 0:
        return f"{v:.{decimals}f} ± {u:.{decimals}f}"
    q = 10.0 ** (-decimals)
    return f"{round(v / q) * q:.0f} ± {round(u / q) * q:.0f}"


def result_title(result: Mapping[str, Any], label: str = "") -> str:
    """Two title lines: e, k and alpha with uncertainties; method, material and flags."""
    r = result
    if r.get("effusivity_W_s05_m2K") is None:
        line1 = "no estimate: " + (", ".join(r.get("flags") or []) or "no result")
    else:
        line1 = (f"e = {_pm(r['effusivity_W_s05_m2K'], r['effusivity_W_s05_m2K_u'])} W s$^{{0.5}}$/(m$^2$ K),  "
                 f"k = {_pm(r['k_W_mK'], r['k_W_mK_u'])} W/(m K),  "
                 f"α = {_pm(r['alpha_m2_s'], r['alpha_m2_s_u'], 1e6)} mm$^2$/s")
    mat = f"{r['material']} ({r['material_confidence'] * 100:.0f} %)" if r.get("material") else "no material"
    flags = ", ".join(r.get("flags") or []) or "no flags"
    line2 = f"{label + ': ' if label else ''}{r['method']} method, {mat}, {flags}"
    return f"{line2}\n{line1}"


def plot_touch(path: str | Path, series: Mapping[str, Any], result: Mapping[str, Any], fit: Any,
               label: str = "") -> Path:
    """Write a two-panel PNG of one touch.

    Parameters
    ----------
    path : str or Path
        Output file in an existing directory; its suffix picks the format
        (``.png``, ``.pdf``, ``.svg``; none: PNG). Written atomically.
    series : mapping
        The stored record with ``raw_t_s``, ``raw_T_C``, ``raw_q_W_m2``,
        ``grid_t_s``, ``grid_q_W_m2``, ``T0_C`` and ``q_offset_W_m2``.
    result : mapping
        The device's result dict (title).
    fit : edge.estimation.estimate.Estimate
        Host re-estimate on the same record (``t_model_s``, ``fit_T_K``).
    label : str
        Scene or sample name for the title.
    """
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    t = np.asarray(series["raw_t_s"], float)
    heat = t >= 0
    T0 = float(series.get("T0_C") or 0.0)
    q0 = float(series.get("q_offset_W_m2") or 0.0)
    fig, (ax_q, ax_T) = plt.subplots(1, 2, figsize=(11, 4.4), constrained_layout=True)
    ax_q.plot(t[heat], np.asarray(series["raw_q_W_m2"], float)[heat] - q0, "o", ms=4, color="tab:blue",
              label="measured")
    if series.get("grid_t_s") is not None:
        ax_q.plot(series["grid_t_s"], series["grid_q_W_m2"], "-", color="tab:orange", lw=1.5,
                  label="resampled (model input)")
    ax_q.set_xlabel("time since heater on (s)")
    ax_q.set_ylabel("heat flux $q_f$ (W/m$^2$)")
    ax_q.set_title("(a) heat flux into the object")
    ax_q.grid(alpha=0.3)
    ax_q.legend(loc="lower right")
    ax_T.plot(t[heat], np.asarray(series["raw_T_C"], float)[heat] - T0, "o", ms=4, color="tab:blue",
              label="measured")
    if fit is not None and fit.fit_T_K is not None:
        ax_T.plot(fit.t_model_s, fit.fit_T_K, "-", color="tab:red", lw=1.5, label=f"model fit ({fit.method})")
    ax_T.set_xlabel("time since heater on (s)")
    ax_T.set_ylabel("excess temperature $T_f - T_0$ (K)")
    ax_T.set_title("(b) excess temperature")
    ax_T.grid(alpha=0.3)
    ax_T.legend(loc="upper left")  # the rise fills the lower right
    fig.suptitle(result_title(result, label), fontsize=10)
    out = Path(path)
    from host.atomic import atomic_path  # noqa: PLC0415

    try:  # the directory must exist (nothing is created behind the caller's back); written atomically
        fmt = out.suffix.lstrip(".").lower() or "png"
        with atomic_path(out) as tmp:
            fig.savefig(tmp, dpi=110, format=fmt)
    finally:
        plt.close(fig)
    return out
