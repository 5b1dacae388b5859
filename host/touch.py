"""One touch from the host: MEASURE over the serial link, then the record's series and model fits.

The device estimates on its own (its configured method). The host then
reads the stored series over the link (SERIES pages, for a probe on a port
and a simulated one alike) and, when it holds the bundle the device used --
identified by its sha256 -- recomputes the estimate on the very same record:
the fitted curves for plots, and the other method's result. Without that
bundle the touch carries the measured series only, and :attr:`Touch.fit_note`
says why.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from host.device import DeviceSession, DeviceUnavailable

__all__ = ["Touch", "touch", "reestimate", "touch_record", "host_bundle", "bundle_identity"]

#: Bundles loaded by :func:`host_bundle`, by (directory, sha256): a verified load takes a moment.
_LOADED: dict[tuple[str, str], Any] = {}


@dataclass
class Touch:
    """A measured touch.

    Attributes
    ----------
    record : dict
        The device's MEASURE reply (stored record summary, ``result`` inside).
    series : dict or None
        The stored record with its raw and resampled series (None unless asked for).
    fits : dict
        ``{method: edge.estimation.result.Estimate}`` recomputed on the host from the raw
        ``series`` through the device's own estimate path (empty without series or without
        the device's bundle).
    fit_note : str or None
        Why ``fits`` is empty although series were read (e.g. the device's
        model is not on this host); None when there are fits or no series.
    """

    record: dict
    series: dict | None
    fits: dict
    fit_note: str | None = None

    @property
    def result(self) -> dict | None:
        return self.record.get("result")


def _manifest_sha256(directory: Path) -> str | None:
    from edge.model.bundle import MANIFEST_FILE  # noqa: PLC0415

    try:
        return hashlib.sha256((directory / MANIFEST_FILE).read_bytes()).hexdigest()
    except OSError:
        return None


def bundle_identity(bundle_dir: str | Path) -> str:
    """sha256 of a bundle directory's ``manifest.json`` (its identity); DeviceUnavailable (status 2) if unreadable.

    Cheap: lets the CLI refuse a wrong ``--bundle`` before it touches the device.
    """
    d = Path(bundle_dir)
    sha = _manifest_sha256(d)
    if sha is None:
        raise DeviceUnavailable(f"--bundle {d}: not a bundle directory (no readable manifest.json)", 2)
    return sha


def _load(directory: Path, sha256: str) -> Any:
    from edge.model.bundle import load_bundle  # noqa: PLC0415
    from edge.estimation.estimate import pipeline_golden_check  # noqa: PLC0415

    key = (str(directory.resolve()), sha256)
    if key not in _LOADED:
        _LOADED[key] = load_bundle(directory, golden_check=pipeline_golden_check)
    return _LOADED[key]


def host_bundle(model_sha256: str | None, *, bundle_dir: str | Path | None = None,
                session: DeviceSession | None = None) -> tuple[Any, str]:
    """The bundle with identity ``model_sha256`` as far as this host has it.

    Looks, in order, at ``bundle_dir`` (e.g. ``--bundle DIR``), the bundle
    active on an in-process simulated probe, and the shipped default bundle
    (:data:`thermotouch_models.DEFAULT_BUNDLE`); a bundle counts only when its
    sha256 (of ``manifest.json``) is the device's.

    Returns
    -------
    (bundle or None, note)
        ``note`` says where the bundle came from, or why there is none.

    Raises
    ------
    DeviceUnavailable
        If ``bundle_dir`` is the device's model but fails verification (exit status 2).
    """
    from edge.model.bundle import BundleError  # noqa: PLC0415

    if not model_sha256:
        return None, "the device reported no model"
    sha = model_sha256.lower()
    if bundle_dir is not None:
        d = Path(bundle_dir)
        got = bundle_identity(d)
        if got != sha:
            return None, f"bundle {d} is model {got[:12]}, the device used {sha[:12]}"
        try:
            return _load(d, sha), f"bundle {d}"
        except BundleError as exc:
            raise DeviceUnavailable(f"--bundle {d} refused: {exc}", 2) from None
    daemon = getattr(session, "daemon", None)
    if daemon is not None:
        try:
            b = daemon.store.current()
        except Exception:  # noqa: BLE001 - a simulated probe without a usable model
            b = None
        if b is not None and b.sha256 == sha:
            return b, "the simulated probe's bundle"
    try:
        from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415
    except ImportError:
        DEFAULT_BUNDLE = None  # noqa: N806
    if DEFAULT_BUNDLE is not None and _manifest_sha256(Path(DEFAULT_BUNDLE)) == sha:
        try:
            return _load(Path(DEFAULT_BUNDLE), sha), "the shipped default bundle"
        except BundleError:
            return None, "the shipped default bundle fails verification on this host"
    return None, f"the device's model {sha[:12]} is not on this host (give --bundle DIR)"


def touch_record(record: dict, series: dict, *, arm_s: float | None = None) -> Any:
    """The :class:`~edge.estimation.record.TouchRecord` of a stored measurement, None without raw samples.

    The series' own header (``touch_header``, when the device sends it) is the record as the device
    made it; otherwise it is rebuilt from the MEASURE reply: the probe the answer names, the power,
    heating time and sample clock; the baseline's length from the record's configuration snapshot
    (default: the configuration's default) and ``arm_s`` as the touch was asked for.
    """
    from edge.estimation.record import RecordError, TouchRecord  # noqa: PLC0415
    from edge.service.config import Config  # noqa: PLC0415

    cols = [series.get(k) for k in ("raw_t_s", "raw_T_C", "raw_q_W_m2")]
    if any(c is None or len(c) < 4 for c in cols):
        return None
    try:
        header = series.get("touch_header")
        if header:
            return TouchRecord.from_header(header, *cols, T_dt_s=series.get("raw_T_dt_s"),
                                           q_dt_s=series.get("raw_q_dt_s"))
        m = (record.get("config") or {}).get("measurement") or {}
        return TouchRecord(
            probe=(record.get("result") or {}).get("probe") or "paper", t_s=cols[0], T_C=cols[1], q_W_m2=cols[2],
            power_W=float(record["power_W"]), heater_on_s=float(record.get("heater_on_s") or 0.0),
            sample_rate_Hz=float(record["sample_rate_Hz"]),
            baseline_s=float(m.get("baseline_s", Config().measurement.baseline_s)),
            method=(record.get("result") or {}).get("method") or "default", arm_s=float(arm_s or 0.0))
    except (RecordError, KeyError, TypeError, ValueError):
        return None


def reestimate(bundle: Any, series: dict, methods=("default", "paper"), *, record: dict | None = None,
               arm_s: float | None = None) -> dict:
    """Estimates of a stored touch by ``methods`` with ``bundle``, through the one estimate path.

    The host holds neither the device's calibration nor its object set: these are the methods'
    own answers (the plots' fitted curves, the other method's numbers), not the device's answer.
    """
    from dataclasses import replace  # noqa: PLC0415

    from edge.estimation.estimate import Estimator  # noqa: PLC0415
    from edge.estimation.seam import SeamContext, estimate_touch  # noqa: PLC0415

    if bundle is None:
        return {}
    est = Estimator.from_bundle(bundle)
    if not series.get("touch_header") and series.get("grid_t_s") is not None:
        # A record without the device's header: the host knows neither the converters' lag nor their
        # resolution, so it re-runs the probe head's estimator on the grid the device conditioned
        # (the seam's method step, the same class: edge.estimation.methods).
        return _methods_on_grid(est, series, record or {}, methods)
    rec = touch_record(record or series, series, arm_s=arm_s)
    if rec is None:
        return {}
    ctx = SeamContext(estimator=est)
    out = {}
    for m in methods:
        if m == "paper" and not ctx.estimator.has_paper:
            continue
        try:
            out[m] = estimate_touch(replace(rec, method=m), ctx)
        except ValueError:   # too few samples to resample, or a record the method refuses
            continue
    return out


def _methods_on_grid(est: Any, series: dict, record: dict, methods) -> dict:
    """The probe head's estimator on the device's stored grid, per method, as typed estimates."""
    from edge.estimation.methods import method_class  # noqa: PLC0415
    from edge.estimation.seam import method_estimate  # noqa: PLC0415
    from edge.physics.geometry import get_probe  # noqa: PLC0415

    probe = (record.get("result") or {}).get("probe") or "paper"
    fn = method_class(probe)(est, get_probe(probe))
    out = {}
    for m in methods:
        if m == "paper" and not est.has_paper:
            continue
        try:
            d = fn(series["grid_t_s"], series["grid_dT_K"], series["grid_q_W_m2"], record.get("power_W"), m)
        except ValueError:
            continue
        from dataclasses import replace  # noqa: PLC0415

        extra = d.get("series") or {}
        out[m] = replace(method_estimate(d, probe, est.sha256, False), series=dict(extra))
    return out


def touch(session: DeviceSession, *, power_W: float | None = None, voltage_V: float | None = None,
          contact_time_s: float | None = None, method: str | None = None, with_series: bool = True,
          bundle_dir: str | Path | None = None, sample_rate_Hz: float | None = None,
          until_decided: bool = False, arm_s: float | None = None, settle_s: float | None = None,
          on_event: Any = None) -> Touch:
    """Run one measurement (optionally with ``method`` set on the device for it) and collect what is reachable.

    The device's estimation method is a runtime setting; when ``method``
    differs from it, it is set for this touch and restored afterwards. With
    ``with_series`` the stored series are read over the link and, if the
    host has the device's bundle (see :func:`host_bundle`; ``bundle_dir``
    is looked at first), re-estimated.

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
        rec = c.measure(power_W=power_W, voltage_V=voltage_V, contact_time_s=contact_time_s,
                        sample_rate_Hz=sample_rate_Hz, until_decided=until_decided, arm_s=arm_s, settle_s=settle_s,
                        on_event=on_event)
    finally:
        if previous is not None:
            c.config_set(**{"estimation.method": previous})
    if rec.get("status") != "ok" or not rec.get("result"):
        why = rec.get("reason") or rec.get("error") or "no result"
        raise DeviceUnavailable(f"measurement {rec.get('measurement_id')} {rec.get('status')}: {why}"
                                + (f" (flags: {', '.join(rec['flags'])})" if rec.get("flags") else ""))
    if not with_series:
        return Touch(rec, None, {})
    series = session.series(rec["measurement_id"])
    sha = rec.get("model_sha256") or (rec.get("result") or {}).get("model_sha256")
    bundle, note = host_bundle(sha, bundle_dir=bundle_dir, session=session)
    fits = reestimate(bundle, series, record=rec, arm_s=arm_s)
    if bundle is not None and not fits:
        note = "no raw series stored"
    return Touch(rec, series, fits, None if fits else note)
