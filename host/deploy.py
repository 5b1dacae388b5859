"""``thermotouch deploy``: train a bundle, prove it is no worse than the probe's, flash it, check a touch.

Steps, each printed as it runs::

    1. device     INFO: the model the probe runs now, its thermocouple converter
    2. train      training set (progress bar) and fit (host.train.train_bundle),
                  with its held-back-material metrics
    3. evaluate   both bundles on the same fixed, seeded evaluation set (host.gate:
                  90 simulated touches of 7 materials not in the training library
                  and the paper's 3 samples, 3 voltages x 3 noise seeds) through a
                  model of the probe's instrument
    4. judge      per touch, paired: for each quantity the bundle decides (paper-method
                  e, the network's k against the library prior, the named material's
                  e) a seeded paired-bootstrap 95 % interval of the change in mean
                  |error|; REFUSE (exit 3, nothing flashed) when an interval lies
                  wholly above the quantity's practical margin, or when an absolute
                  threshold is exceeded (held-back k; paper-method k and alpha and
                  default-method e and k on the paper samples - prior-limited or
                  bundle-independent, so thresholded, never compared)
    5. flash      verified upload over serial (progress bar); the device must report
                  the new sha256
    6. self-check one touch: on the simulator the scene's object, on a real probe the
                  reference sample named by --reference; e must lie within the
                  evaluated bar and k within two stated uncertainties

The device's current bundle is compared when it is the shipped default
(loaded locally from ``thermotouch_models``) or when ``--baseline DIR``
holds it; otherwise only the thresholds apply, and the report says so.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from host.device import DeviceSession, DeviceUnavailable, open_device

__all__ = ["Thresholds", "DeployRefused", "score_bundle", "judge", "self_check", "train_and_deploy"]

@dataclass(frozen=True)
class Thresholds:
    """Largest errors a bundle may have to be deployed (relative, as fractions).

    ``heldout_k_median`` is the training's held-back-material metric; the
    others are means of absolute errors (answered touches) over the paper's
    three samples in the gate's evaluation set (:mod:`host.gate`) through the
    probe's instrument model.  These numbers are limited by the library prior
    (k, alpha) or do not depend on the bundle (the default method's e), so they
    are held to these limits only, never compared with the device's bundle.
    """

    heldout_k_median: float = 0.35
    paper_k: float = 0.35
    paper_alpha: float = 0.60
    default_e: float = 0.10
    default_k: float = 0.30


class DeployRefused(DeviceUnavailable):
    """The new bundle is not deployed; the message says why (exit status 3)."""

    def __init__(self, message: str) -> None:
        super().__init__(message, 3)


def score_bundle(bundle: Any, instrument: str) -> dict:
    """The gate's evaluation of a bundle (:func:`host.gate.evaluate`) on the fixed evaluation set."""
    from host.gate import evaluate  # noqa: PLC0415

    return evaluate(bundle, instrument)


#: Held to a threshold only: prior-limited (k, alpha against the truth) or the same for every bundle (e).
_THRESHOLDED = ("paper_k", "paper_alpha", "default_e", "default_k")


def judge(metrics: dict, new: dict, comparisons: Sequence[Any] = (),
          thresholds: Thresholds = Thresholds()) -> list[str]:
    """Reasons to refuse the new bundle (empty: deploy).

    Parameters
    ----------
    metrics : dict
        Training metrics (``heldout_k_median_rel_err``).
    new : dict
        Means of the new bundle's absolute errors on the paper samples (``paper_k``,
        ``paper_alpha``, ``default_e``, ``default_k``: ``evaluate(...)["means"]``).
    comparisons : sequence of host.gate.Comparison
        The paired comparison with the device's bundle (empty: unknown); a quantity whose
        verdict is ``"worse"`` (95 % interval wholly above its practical margin) refuses.
    """
    why = []
    held = metrics.get("heldout_k_median_rel_err")
    if held is None or not held <= thresholds.heldout_k_median:
        why.append(f"held-back k median error {held if held is None else f'{held * 100:.1f} %'} exceeds "
                   f"the threshold {thresholds.heldout_k_median * 100:.0f} %")
    for key in _THRESHOLDED:
        limit = getattr(thresholds, key)
        if not new[key] <= limit:
            why.append(f"{key.replace('_', ' ')} error {new[key] * 100:.1f} % exceeds the threshold "
                       f"{limit * 100:.0f} %")
    for c in comparisons:
        if c.verdict == "worse":
            why.append(f"{c.quantity.replace('_', ' ')} is worse than the device's model: {c.old:.4f} -> "
                       f"{c.new:.4f}, difference {c.diff:+.4f} (95 % CI {c.lo:+.4f} .. {c.hi:+.4f}) above the "
                       f"margin {c.margin:.3f}")
    return why


def _reference_for(session: DeviceSession, reference: str | None) -> tuple[str, Any] | None:
    from host.evaluate import SAMPLES  # noqa: PLC0415

    if session.simulated:
        obj = session.simulator.scene.object
        return session.simulator.scene.name, obj.solid
    if reference is None:
        return None
    return reference, SAMPLES[reference][0]


def self_check(session: DeviceSession, score: dict, *, reference: str | None = None,
               log: Callable[[str], None] = print) -> dict | None:
    """One touch on a known object; returns the check (``ok`` and numbers) or None if skipped.

    The effusivity bar is three times the evaluated mean error of the
    closest paper case of the same kind of material (at least 10 %); k must
    lie within two of the device's stated standard uncertainties.
    """
    from host.touch import touch  # noqa: PLC0415

    ref = _reference_for(session, reference)
    if ref is None:
        log("self-check: skipped (hold the probe on a reference sample and pass --reference SAMPLE)")
        return None
    name, solid = ref
    t = touch(session, method="default", with_series=False)
    r = t.result
    e_ref = solid.effusivity_W_s05_m2K
    rows = [x for x in score["rows"] if x["method"] == "default" and x["e_err"] is not None]
    # The evaluated case whose material is closest in effusivity carries the bar.
    from host.evaluate import SAMPLES  # noqa: PLC0415
    closest = min(rows, key=lambda x: abs(math.log(SAMPLES[x["sample"]][0].effusivity_W_s05_m2K / e_ref)))
    same = [x["e_err"] for x in rows if x["sample"] == closest["sample"]]
    bar_e = max(3.0 * float(np.mean(same)), 0.10)
    e = r["effusivity_W_s05_m2K"]
    e_err = (e - e_ref) / e_ref if e else math.inf
    k, k_u = r["k_W_mK"], r["k_W_mK_u"] or 0.0
    k_ok = k is not None and abs(k - solid.k_W_mK) <= 2.0 * k_u
    ok = abs(e_err) <= bar_e and k_ok
    out = {"ok": ok, "reference": name, "e": e, "e_ref": e_ref, "e_err": e_err, "e_bar": bar_e,
           "k": k, "k_u": k_u, "k_ref": solid.k_W_mK, "measurement_id": t.record["measurement_id"],
           "model_sha256": r.get("model_sha256"), "flags": t.record.get("flags", [])}
    log(f"self-check on {name}: e = {e:.4g} ({e_err * 100:+.1f} %, bar ±{bar_e * 100:.0f} %), "
        f"k = {k:.3g} ± {k_u:.2g} (reference {solid.k_W_mK:.4g}) -> {'PASS' if ok else 'FAIL'}")
    return out


def _device_baseline(info: dict, baseline: str | Path | None, log: Callable[[str], None]) -> Any:
    """The bundle the device runs, when the host has it (shipped default or --baseline)."""
    from host.flash import load_verified  # noqa: PLC0415

    candidates = [baseline] if baseline is not None else []
    try:
        from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415

        candidates.append(DEFAULT_BUNDLE)
    except ImportError:  # pragma: no cover - the package ships it
        pass
    for c in candidates:
        b = load_verified(c)
        if b.sha256 == info.get("model_sha256"):
            return b
    log(f"device model {str(info.get('model_sha256'))[:12]} is not available on this host: "
        "comparing with the thresholds only")
    return None


def train_and_deploy(session: DeviceSession, out: str | Path, *, quick: bool = False, seed: int = 0,
                     lib: Any = None, bundle: str | Path | None = None, baseline: str | Path | None = None,
                     thresholds: Thresholds = Thresholds(), reference: str | None = None,
                     progress: bool = True, overwrite: bool = False,
                     log: Callable[[str], None] = print, key: Any = None) -> dict:
    """The whole flow on an open session (see the module docstring).

    Parameters
    ----------
    session : DeviceSession
    out : path
        Bundle directory to write; if it exists it is replaced only with ``overwrite``.
    quick, seed, lib :
        Passed to :func:`host.train.train_bundle` (``lib``: a material subset).
    bundle : path, optional
        Skip training and deploy this existing bundle (its manifest metrics are used).
    baseline : path, optional
        The device's current bundle, if it is not the shipped default.
    key : edge.security.keys.SecretKey, optional
        Sign the bundle's manifest with it when flashing (see :func:`host.flash.flash_bundle`).

    Returns
    -------
    dict
        ``{"model_sha256", "metrics", "score", "device_score", "flash", "self_check"}``.

    Raises
    ------
    DeployRefused
        The new bundle does worse (nothing is flashed).
    DeviceUnavailable
        Device problems, a refused upload, or a failed self-check.
    """
    from host.flash import flash_bundle, load_verified  # noqa: PLC0415
    from host.progress import ProgressBar, Ticker  # noqa: PLC0415

    if bundle is None and os.path.lexists(out) and not overwrite:
        raise FileExistsError(f"{out} exists (use --overwrite to replace it)")
    c = session.client
    info = c.info()
    instrument = c.config_get("sensors.thermocouple").get("sensors.thermocouple", "mcp9600")
    log(f"device: {info['board']} board, model {info.get('model_version')} "
        f"({str(info.get('model_sha256'))[:12]}), thermocouple via {instrument}")
    if bundle is None:
        from host.train import train_bundle  # noqa: PLC0415

        with warnings.catch_warnings(), ProgressBar("training set", "material", enabled=progress) as bar:
            warnings.simplefilter("ignore")  # sklearn convergence chatter; the metrics tell the truth
            new_bundle, metrics = train_bundle(out, quick=quick, seed=seed, lib=lib, progress=bar,
                                               overwrite=overwrite, log=lambda s: log(f"train: {s}"),
                                               step=lambda desc: Ticker(desc, enabled=progress))
        path = Path(out)
    else:
        path = Path(bundle)
        new_bundle = load_verified(path)
        metrics = dict(new_bundle.manifest.get("metrics", {}))
    log(f"held-back materials: k median error {metrics.get('heldout_k_median_rel_err', math.nan) * 100:.1f} %, "
        f"90th percentile {metrics.get('heldout_k_p90_rel_err', math.nan) * 100:.1f} %")
    from host.gate import compare, describe_set, format_report  # noqa: PLC0415

    with Ticker("evaluating the new bundle", enabled=progress):
        score = score_bundle(new_bundle, instrument)
    old_bundle = _device_baseline(info, baseline, log)
    old = None
    if old_bundle is not None:
        if old_bundle.sha256 == new_bundle.sha256:
            old = score
        else:
            with Ticker("evaluating the device's bundle", enabled=progress):
                old = score_bundle(old_bundle, instrument)
    log(f"evaluation set: {describe_set(instrument)}")
    comparisons = [] if old is None else compare(score, old)
    if comparisons:
        log(format_report(comparisons))
    log("paper cases (mean |error|, held to thresholds):  new " + _fmt_score(score["means"])
        + ("" if old is None else "\n" + " " * 44 + "device " + _fmt_score(old["means"])))
    why = judge(metrics, score["means"], comparisons, thresholds)
    if why:
        raise DeployRefused("not deploying " + str(path) + ": " + "; ".join(why))
    if old_bundle is not None and old_bundle.sha256 == new_bundle.sha256:
        log("device already runs this model; flashing anyway to verify the link")
    fl = flash_bundle(session, path, progress=progress, key=key)
    log(f"flashed {fl['bytes']} B; device reports sha256 {fl['model_sha256']}")
    with Ticker("self-check touch", enabled=progress):
        check = self_check(session, score, reference=reference, log=log)
    result = {"model_sha256": fl["model_sha256"], "metrics": metrics, "score": dict(score["means"]),
              "device_score": None if old is None else dict(old["means"]),
              "gate": [dict(c.__dict__, verdict=c.verdict) for c in comparisons],
              "flash": fl, "self_check": check, "bundle": str(path)}
    if check is not None and not check["ok"]:
        raise DeviceUnavailable(f"self-check failed on {check['reference']}: e error {check['e_err'] * 100:+.1f} % "
                                f"(bar ±{check['e_bar'] * 100:.0f} %), k {check['k']:.3g} ± {check['k_u']:.2g} vs "
                                f"{check['k_ref']:.4g}; the new model stays installed (flash the previous bundle "
                                "to roll back)")
    return result


def _fmt_score(s: dict) -> str:
    return (f"paper k {s['paper_k'] * 100:.1f} %, paper α {s['paper_alpha'] * 100:.1f} %, "
            f"default e {s['default_e'] * 100:.1f} %, default k {s['default_k'] * 100:.1f} %")
