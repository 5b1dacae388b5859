"""What a touch's plot shows, as numbers: curves, band, residuals, phases, identification (no Matplotlib here).

:func:`touch_plot_data` turns a stored touch (its series), the device's answer and the host's re-estimate
into the arrays :class:`host.plots.TouchFigure` draws, so the figure's content can be tested without
pixels and one definition serves ``measure --plot``, the demo and the report.

* **Data**: the raw thermocouple and flux samples of the whole record (pre-contact phase included) as
  excesses over the device's baseline (``T0_C``, ``q_offset_W_m2``), and the conditioned grid the method
  fitted (``grid_t_s``, ``grid_dT_K``, ``grid_q_W_m2``).
* **The answer's model curve**: the method's fitted temperature (``fit_T_K`` on ``t_model_s``); when the
  calibrated sensor chain gave the answer (``method == "sensor_chain"``), the chain's own curve from the
  answer's e, contact resistance and object temperature through the calibration's design
  (:func:`edge.estimation.sensor_chain.chain_design`, linear in 1/e), on the samples it fits.
* **Band**: the curve at e -+ u(e) (k = 1). For the chain this is exact (the model is linear in 1/e); for a
  method's fit the excess scales as 1/e (a semi-infinite body under the same flux), so the band is the
  curve times e / (e -+ u).
* **Residuals**: the fitted data minus the curve, on the samples the fit used (the grid for a method, the
  raw samples from contact + 0.3 s for the chain), with the band's half-width about zero.
* **Phases**: the pre-contact phase (record start to the contact the chain found, else to heater-on) and
  the window the answer's fit used.
* **Identification**: measurement id, UTC start, heater power, model and calibration ids -- never a port.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

__all__ = ["touch_identity", "identification", "touch_plot_data", "chain_curve"]


def touch_identity(record: Mapping[str, Any]) -> dict[str, Any]:
    """The fields that identify a touch in a plot, from the device's MEASURE/RESULT record."""
    r = record.get("result") or {}
    return {"measurement_id": record.get("measurement_id"), "started_utc": record.get("started_utc"),
            "power_W": record.get("power_W"), "contact_time_s": record.get("contact_time_s"),
            "model_sha256": record.get("model_sha256") or r.get("model_sha256"),
            "calibration_sha256": r.get("calibration_sha256")}


def _short(sha: Any) -> str:
    return str(sha)[:12] if sha else "none"


def _utc(text: str) -> str:
    """``YYYY-MM-DD HH:MM:SS UTC`` of an ISO 8601 time (as written when it does not parse)."""
    from datetime import datetime, timezone  # noqa: PLC0415

    try:
        t = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return text
    if t.tzinfo is not None:
        t = t.astimezone(timezone.utc)
    return t.strftime("%Y-%m-%d %H:%M:%S UTC")


def identification(result: Mapping[str, Any]) -> str:
    """One title line: measurement id, UTC time, heater power, model and calibration ids (k = 1 stated)."""
    parts = []
    if result.get("measurement_id") is not None:
        parts.append(f"measurement {result['measurement_id']}")
    if result.get("started_utc"):
        parts.append(_utc(str(result["started_utc"])))
    if result.get("power_W") is not None:
        parts.append(f"{float(result['power_W']):.3g} W")
    if result.get("contact_time_s") is not None:
        parts.append(f"{float(result['contact_time_s']):.3g} s")
    parts.append(f"model {_short(result.get('model_sha256'))}")
    parts.append(f"calibration {_short(result.get('calibration_sha256'))}")
    return ", ".join(parts)


def chain_curve(series: Mapping[str, Any], chain: Mapping[str, Any], calibration: Any,
                probe: str = "paper") -> dict[str, np.ndarray] | None:
    """The calibrated chain's model curve of a record, from the answer's values (None: not computable).

    Returns ``t_s`` (from heater-on), ``T_C`` (the thermocouple the chain predicts), ``T_lo_C``/``T_hi_C``
    (at e + u and e - u), ``data_T_C`` (the samples fitted) -- all on the samples the chain fits.
    """
    from edge.estimation.chain_estimate import FIT_START_s, uniform_record  # noqa: PLC0415
    from edge.estimation.sensor_chain import chain_design  # noqa: PLC0415
    from edge.physics.geometry import PROBES  # noqa: PLC0415

    e, u = chain.get("effusivity_W_s05_m2K"), chain.get("effusivity_W_s05_m2K_u")
    R_c, T_obj0, t_c = (chain.get(k) for k in ("contact_resistance_m2K_W", "object_temperature0", "contact_t_s"))
    if calibration is None or None in (e, R_c, T_obj0, t_c) or not e > 0:
        return None
    try:
        t, T, q = uniform_record(series["raw_t_s"], series["raw_T_C"], series["raw_q_W_m2"])
    except (KeyError, TypeError, ValueError):
        return None
    i0 = int(np.argmin(np.abs(t - float(t_c))))
    tt, TT, qq = t[i0:] - t[i0], T[i0:], q[i0:]
    breaks = (-float(t[i0]),) if t[i0] < 0 else ()
    alpha = chain.get("alpha_m2_s")
    a = PROBES[probe].heater_radius_m if probe in PROBES else float("inf")
    disk = (a, float(alpha)) if alpha and np.isfinite(a) else None
    try:
        X, y = chain_design(tt, TT, qq, calibration.chain, fit_start_s=FIT_START_s, breaks_s=breaks, disk=disk)
    except ValueError:
        return None
    Tp0 = float(TT[0])
    base = X[:, 0] * (float(T_obj0) - Tp0) + X[:, 1] * float(R_c)
    u = float(u or 0.0)

    def at(e_: float) -> np.ndarray:
        return Tp0 + base + X[:, 2] / e_

    t_fit = tt[tt >= FIT_START_s] + t[i0]
    mid = at(e)
    hi = at(e - u) if e > u else 2.0 * mid - at(e + u)
    return {"t_s": t_fit, "T_C": mid, "T_lo_C": at(e + u), "T_hi_C": hi, "data_T_C": Tp0 + y,
            "contact_t_s": float(t[i0])}


def touch_plot_data(series: Mapping[str, Any], result: Mapping[str, Any], fit: Any = None,
                    calibration: Any = None) -> dict[str, Any]:
    """Everything :class:`host.plots.TouchFigure` draws for one touch (module docstring).

    Parameters
    ----------
    series : mapping
        The stored record's series (``raw_*``, ``grid_*``, ``T0_C``, ``q_offset_W_m2``).
    result : mapping
        The device's answer (with :func:`touch_identity`'s fields for the title).
    fit : object, optional
        The host's re-estimate by the answer's method (``t_model_s``, ``fit_T_K``, ``method``,
        ``effusivity_W_s05_m2K`` and ``_u``), None without the device's bundle.
    calibration : edge.calibration.model.ProbeCalibration, optional
        The device's calibration: with it a sensor-chain answer gets its own curve.

    Returns
    -------
    dict
        ``raw`` (t_s, dT_K, q_W_m2), ``grid`` (t_s, dT_K, q_W_m2 or None), ``curve`` (t_s, dT_K, lo, hi,
        label, kind: "method" or "sensor_chain"; None without one), ``residual`` (t_s, r_K, half_band_K;
        None), ``pre_contact`` (t0, t1), ``window`` (t0, t1, label or None), ``note`` (why no curve, or
        None), ``identification``.
    """
    T0 = float(series.get("T0_C") or 0.0)
    q0 = float(series.get("q_offset_W_m2") or 0.0)
    t = np.asarray(series["raw_t_s"], float)
    raw = {"t_s": t, "dT_K": np.asarray(series["raw_T_C"], float) - T0,
           "q_W_m2": np.asarray(series["raw_q_W_m2"], float) - q0}
    grid = None
    if series.get("grid_t_s") is not None:
        grid = {"t_s": np.asarray(series["grid_t_s"], float),
                "dT_K": None if series.get("grid_dT_K") is None else np.asarray(series["grid_dT_K"], float),
                "q_W_m2": None if series.get("grid_q_W_m2") is None else np.asarray(series["grid_q_W_m2"], float)}
    chain = result.get("sensor_chain") or {}
    contact = chain.get("contact_t_s")
    out: dict[str, Any] = {"raw": raw, "grid": grid, "curve": None, "residual": None, "window": None, "note": None,
                           "identification": identification(result)}
    e, u = result.get("effusivity_W_s05_m2K"), result.get("effusivity_W_s05_m2K_u") or 0.0
    if result.get("method") == "sensor_chain":
        c = chain_curve(series, chain, calibration, str(result.get("probe") or "paper"))
        if c is None:
            out["note"] = ("the sensor chain's answer: its curve needs the device's calibration"
                           if calibration is None else "the sensor chain's curve could not be computed")
        else:
            contact = c["contact_t_s"]
            out["curve"] = {"t_s": c["t_s"], "dT_K": c["T_C"] - T0, "lo": c["T_lo_C"] - T0, "hi": c["T_hi_C"] - T0,
                            "label": "calibrated sensor chain", "kind": "sensor_chain"}
            out["residual"] = {"t_s": c["t_s"], "r_K": c["data_T_C"] - c["T_C"],
                               "half_band_K": 0.5 * np.abs(c["T_hi_C"] - c["T_lo_C"])}
            out["window"] = (float(c["t_s"][0]), float(c["t_s"][-1]), "chain fit (contact + 0.3 s on)")
    elif fit is not None and getattr(fit, "fit_T_K", None) is not None:
        tm, Tm = np.asarray(fit.t_model_s, float), np.asarray(fit.fit_T_K, float)
        fe = getattr(fit, "effusivity_W_s05_m2K", None) or e
        fu = getattr(fit, "effusivity_W_s05_m2K_u", None) or u
        rel = float(fu) / float(fe) if fe and fu else 0.0
        # The excess under a given flux scales as 1/e (module docstring): the band at e -+ u.
        lo, hi = Tm / (1.0 + rel), (Tm / (1.0 - rel) if rel < 1 else Tm * (1.0 + rel))
        out["curve"] = {"t_s": tm, "dT_K": Tm, "lo": lo, "hi": hi, "label": f"model fit ({fit.method})",
                        "kind": "method"}
        if grid is not None and grid["dT_K"] is not None:
            g = grid["t_s"]
            inside = (g >= tm[0]) & (g <= tm[-1])
            model_at = np.interp(g[inside], tm, Tm)
            out["residual"] = {"t_s": g[inside], "r_K": grid["dT_K"][inside] - model_at,
                               "half_band_K": model_at * rel}
            out["window"] = (float(g[0]), float(g[-1]), f"{fit.method} method's window")
    else:
        out["note"] = "measured series only: no model fit" if fit is None else "the method has no model curve"
    start = float(t[0]) if t.size else 0.0
    end = float(contact) if contact is not None else 0.0
    out["pre_contact"] = (start, max(start, end))
    out["pre_contact_label"] = "before contact (probe in air)" if contact is not None else "before heater-on"
    return out
