"""One touch from the host: MEASURE over the serial link, then the record's series and model fits.

The device estimates on its own (its configured method); the host adds,
when it can reach the stored series (a simulated probe), the fitted curves
for plots and the other method's result on the very same record, computed
with the same bundle the device used.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from host.device import DeviceSession, DeviceUnavailable

__all__ = ["Touch", "touch", "reestimate"]


@dataclass
class Touch:
    """A measured touch.

    Attributes
    ----------
    record : dict
        The device's MEASURE reply (stored record summary, ``result`` inside).
    series : dict or None
        Raw and resampled series (only when reachable).
    fits : dict
        ``{method: edge.estimate.Estimate}`` recomputed on the host from
        ``series`` (empty without series).
    """

    record: dict
    series: dict | None
    fits: dict

    @property
    def result(self) -> dict | None:
        return self.record.get("result")


def reestimate(session: DeviceSession, series: dict, methods=("default", "paper")) -> dict:
    """Estimates of ``series`` by ``methods`` with the bundle active on the (simulated) device."""
    from edge.drivers.heater import volumetric_heat_w_m3  # noqa: PLC0415
    from edge.estimate import Estimator  # noqa: PLC0415

    if session.daemon is None or series.get("grid_t_s") is None:
        return {}
    bundle = session.daemon.store.current()
    est = Estimator.from_bundle(bundle)
    q_v = volumetric_heat_w_m3(series["power_W"]) if series.get("power_W") else None
    out = {}
    for m in methods:
        if m == "paper" and not est.has_paper:
            continue
        out[m] = est.estimate(series["grid_t_s"], series["grid_dT_K"], series["grid_q_W_m2"], method=m,
                              q_v_W_m3=q_v)
    return out


def touch(session: DeviceSession, *, power_W: float | None = None, voltage_V: float | None = None,
          contact_time_s: float | None = None, method: str | None = None, with_series: bool = True) -> Touch:
    """Run one measurement (optionally with ``method`` set on the device for it) and collect what is reachable.

    The device's estimation method is a runtime setting; when ``method``
    differs from it, it is set for this touch and restored afterwards.

    Raises
    ------
    DeviceUnavailable
        If the measurement did not produce a result (the device's reason is named).
    """
    c = session.client
    previous = None
    if method is not None:
        previous = c.config_get("estimation.method").get("estimation.method")
        if previous == method:
            previous = None
        else:
            c.config_set(**{"estimation.method": method})
    try:
        rec = c.measure(power_W=power_W, voltage_V=voltage_V, contact_time_s=contact_time_s)
    finally:
        if previous is not None:
            c.config_set(**{"estimation.method": previous})
    if rec.get("status") != "ok" or not rec.get("result"):
        why = rec.get("reason") or rec.get("error") or "no result"
        raise DeviceUnavailable(f"measurement {rec.get('measurement_id')} {rec.get('status')}: {why}"
                                + (f" (flags: {', '.join(rec['flags'])})" if rec.get("flags") else ""))
    series = session.series(rec["measurement_id"]) if with_series else None
    fits = reestimate(session, series) if series else {}
    return Touch(rec, series, fits)
