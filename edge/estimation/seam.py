"""The one estimate path: a touch record and what the device knows -> one :class:`~edge.estimation.result.Estimate`.

:func:`estimate_touch` does everything the device does after the last
sample, and nothing else calls an estimator on a touch: the daemon after
each MEASURE, ``thermotouch estimate`` on an exported record, ``thermotouch
calibrate`` re-measuring its references, the demo and the benches.  So an
exported touch re-estimated with the same model, calibration and object set
gives the device's answer.

Steps, in order:

1. **conditioning** (:func:`condition`): the baseline (T0, flux offset), the
   quality flags (``no_contact``, ``saturated``, ``noisy``,
   ``unstable_baseline`` against the ``[measurement]`` thresholds), then the
   heating phase resampled on the uniform grid the estimators expect;
2. **the probe head's method**: the class its estimator kind names
   (:data:`edge.estimation.methods.KINDS`), with the installed calibration
   when it is this probe head's;
3. **the calibrated sensor chain**, for kinds that carry it: fitted on the raw
   record from the contact on; once the probe is calibrated and the chain
   raises none of :data:`BLOCKERS`, its e is the answer and k, α follow from
   the one prior (the bundle's library, :meth:`Library.k_alpha_given_e`);
4. ``uncalibrated`` when no calibration of this probe head was applied;
5. **recognition** among the active object set (``object = "unknown"`` when it cannot say);
6. the running decision's verdict: ``decided`` when it stopped the heating,
   ``decision_disagrees`` when the answer names another object.

The sequence keeps the heater's safety (on/off checks, ``no_heat_while_on``,
the watchdog) and builds the :class:`~edge.estimation.record.TouchRecord`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Mapping

import numpy as np

from edge.estimation.conditioning import baseline_mask, contact_effusivity, quality_flags, resample_uniform
from edge.estimation.estimate import FLUX_CALIBRATION_U_REL
from edge.estimation.methods import method_class
from edge.estimation.record import TouchRecord
from edge.estimation.result import BLOCKERS, QUANTITIES, Estimate, unknown_recognition
from edge.physics.geometry import get_probe
from edge.recognition import recognition_fields
from edge.status import Flag

#: Flags under which a touch gets no answer (ISSUE #34 item 3): nothing was touched, or nothing measured.
NO_ANSWER = frozenset({Flag.NO_CONTACT, Flag.NO_SIGNAL})

__all__ = ["SeamContext", "TouchEstimator", "Conditioned", "TooFewSamples", "BLOCKERS", "condition", "estimate_touch",
           "chain_answer", "method_estimate", "MethodFn", "CHAIN_KEEP"]

log = logging.getLogger(__name__)

#: ``method(t_s, dT_K, q_W_m2, power_W, method) -> dict``: a probe head's estimator on the uniform grid
#: (:mod:`edge.estimation.methods`); a test or a bench may put its own in :attr:`SeamContext.method`.
MethodFn = Callable[..., Mapping[str, Any]]

#: Fields of the chain's estimate kept in the answer's ``sensor_chain``: the answer and what judges it (the
#: rest -- the fit window, ... -- is recomputable from the raw record; a HISTORY page is one frame; the
#: chain's parts of u(e) become the answer's ``u_e_parts`` when its e is the answer).
CHAIN_KEEP = ("contact_lost_t_s", "effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "contact_resistance_m2K_W",
              "contact_resistance_m2K_W_u", "object_temperature0", "object_temperature0_u", "contact_t_s",
              "contact_detected", "normalised_residual", "flags", "determined", "alpha_m2_s", "alpha_m2_s_u", "k_W_mK", "k_W_mK_u",
              "u_e_fit_noise", "u_e_fit_noise_nuisance_known")
#: Keys of the method's own answer kept under ``default_method`` once the chain's is the answer.
DEFAULT_METHOD_KEYS = ("effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u", "alpha_m2_s",
                       "alpha_m2_s_u", "material", "material_confidence", "method")


class TouchEstimator:
    """The sequence's estimator hook on one context: ``(record, decision) -> Estimate``."""

    def __init__(self, context: "SeamContext") -> None:
        self.context = context

    def __call__(self, record: TouchRecord, decision: Mapping[str, Any] | None = None) -> Estimate:
        return estimate_touch(record, self.context, decision=decision)


class TooFewSamples(ValueError):
    """The heating phase has too few samples to resample (the record's reason ``too_few_samples``)."""


@dataclass(frozen=True, eq=False)
class SeamContext:
    """What the device knows besides the record: the model, the calibration, the objects.

    Parameters
    ----------
    estimator : edge.estimation.estimate.Estimator or None
        The model bundle's estimator (the daemon caches it per bundle): its library is the one prior
        and names the material, its ``sha256`` the model.  None only with :attr:`method` given.
    calibration : edge.calibration.model.ProbeCalibration or None
        The installed calibration; one made for another probe head is not applied (``uncalibrated``).
    object_set : edge.recognition.ObjectSet or None
        The objects the answer is named among (None: no naming, ``object = "unknown"``).
    object_set_name : str or None
        Its name as reported (``object_set``; default the set's label).
    thresholds : namespace or None
        The ``[measurement]`` quality thresholds (``noise_T_K``, ``noise_q_W_m2``,
        ``unstable_baseline_K``, ``no_contact_e_W_s05_m2K``); None: no quality flags.
    thickness_m, back : float or None, str
        A known finite object (``"insulated"`` or ``"fixed"`` back) for the methods that use it.
    method : MethodFn or None
        Replaces the probe head's registered estimator (tests, benches); called with
        ``(t_s, dT_K, q_W_m2, power_W, method)``.
    T_resolution_K : float or None
        The thermometer's resolution the estimator carries into u(e); None: the record's (what the
        device's converter had).
    methods : dict
        Built estimators per (probe, model): shared by the contexts of one device so the small
        heater's model is built once per grid (:meth:`with_` keeps it).
    """

    estimator: Any = None
    calibration: Any = None
    object_set: Any = None
    object_set_name: str | None = None
    thresholds: Any = None
    thickness_m: float | None = None
    back: str = "infinite"
    method: MethodFn | None = None
    T_resolution_K: float | None = None
    methods: dict = field(default_factory=dict, repr=False)

    def with_(self, **changes: Any) -> "SeamContext":
        """A copy with ``changes`` (the method cache is shared)."""
        return replace(self, **changes)

    @classmethod
    def from_bundle_dir(cls, path: Any, *, calibration: Any = None, object_set: Any = None,
                        object_set_name: str | None = None, thresholds: Any = None, **kw: Any) -> "SeamContext":
        """A context on the bundle at ``path`` (verified as the device loads it)."""
        from edge.estimation.estimate import Estimator, pipeline_golden_check  # noqa: PLC0415
        from edge.model.bundle import load_bundle  # noqa: PLC0415

        est = Estimator.from_bundle(load_bundle(path, golden_check=pipeline_golden_check))
        return cls(estimator=est, calibration=calibration, object_set=object_set, object_set_name=object_set_name,
                   thresholds=thresholds, **kw)

    def calibration_for(self, probe: str) -> Any:
        """The calibration to apply to a touch of ``probe`` (None: none installed, or another probe's)."""
        cal = self.calibration
        return cal if cal is not None and getattr(cal, "probe", None) == probe else None

    def method_for(self, probe: str, T_resolution_K: float = 0.0) -> Any:
        """The probe head's estimator (its kind's class from the registry), built once per model and grid."""
        if self.estimator is None:
            raise ValueError("no model: the context needs the bundle's estimator (or a method)")
        geo = get_probe(probe)
        if any(m.estimator is not self.estimator for m in self.methods.values()):
            self.methods.clear()  # one model at a time: a new bundle drops the old one's estimators
        key = (geo.name, float(T_resolution_K))
        m = self.methods.get(key)
        if m is None:
            m = self.methods[key] = method_class(geo)(self.estimator, geo, T_resolution_K=T_resolution_K)
        return m


@dataclass(frozen=True, eq=False)
class Conditioned:
    """A record's baseline and quality flags (:func:`condition`)."""

    T0_C: float | None
    q_offset_W_m2: float | None
    flags: tuple[Flag, ...]
    base: np.ndarray
    contact_e: float | None


def condition(record: TouchRecord, thresholds: Any) -> Conditioned:
    """Baseline T0 and flux offset, and the quality flags (no_contact, saturated, noisy, unstable_baseline)."""
    t, T, q = record.t_s, record.T_C, record.q_W_m2
    heated = record.heater_on_t_s is not None
    base = baseline_mask(t, heated, record.arm_s, record.baseline_s)
    T0 = float(np.mean(T[base])) if base.any() else None
    q0 = float(np.mean(q[base])) if base.any() else None
    heat_q = q[~base] - (q0 or 0.0)
    contact_e = None
    if T0 is not None and heat_q.size:
        contact_e = contact_effusivity(t[~base], T[~base] - T0, heat_q, record.T_age_s,
                                       min_rise_K=2 * record.T_resolution_K)
    flags: list[Flag] = []
    if thresholds is not None:
        flags = quality_flags(t[base], T[base], q[base], heat_q, contact_e, record.saturated, thresholds)
    elif record.saturated:
        flags = [Flag.SATURATED]
    return Conditioned(T0, q0, tuple(flags), base, contact_e)


def _grid(record: TouchRecord, c: Conditioned) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if c.T0_C is None or record.heater_on_t_s is None:
        raise TooFewSamples("no baseline or no heating: nothing to resample")
    try:
        return resample_uniform(record.t_s, record.T_C, record.q_W_m2, c.T0_C, c.q_offset_W_m2,
                                record.sample_rate_Hz, record.heater_on_s, record.T_age_s,
                                T_dt_s=record.T_dt_s, q_dt_s=record.q_dt_s)
    except ValueError as e:
        raise TooFewSamples(str(e)) from None


def _num(x: Any) -> float | None:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _flags(words: Any) -> list[Flag]:
    """The Flag members of a method's flag list (a word outside the enum is a bug: it raises)."""
    return [Flag(str(w)) for w in words or ()]


def _sources(d: Mapping[str, Any], thickness: bool) -> dict[str, str]:
    det, prior = set(d.get("determined") or ()), set(d.get("from_prior") or ())
    if not det and not prior and d.get("effusivity_W_s05_m2K") is not None:
        det = {"e"}   # a method that does not say: its e is the record's
    thick = set(d.get("thickness_determined") or ()) if thickness else set()
    out = {}
    for q in QUANTITIES:
        if q in thick:
            out[q] = "thickness"
        elif q in det:
            out[q] = "data"
        elif q in prior:
            out[q] = "prior"
    return out


def _u_parts(d: Mapping[str, Any], fit: Mapping[str, Any] | None) -> dict[str, float]:
    """The relative parts of u(e) a method's answer carries: its fit's and the flux sensor's calibration."""
    e, u = _num(d.get("effusivity_W_s05_m2K")), _num(d.get("effusivity_W_s05_m2K_u"))
    if e is None or u is None or not e > 0:
        return {}
    if fit is not None:     # the small heater's fit: the flux scale's part through its sensitivity
        u_fit = _num(fit.get("u_rel_effusivity"))
        sens = _num((fit.get("flux_scale_sensitivity") or {}).get("effusivity"))
        u_flux = _num(fit.get("flux_u_rel"))
        parts = {"fit": u_fit}
        if sens is not None and u_flux is not None:
            parts["flux_calibration"] = abs(sens) * u_flux
        return {k: v for k, v in parts.items() if v is not None}
    if d.get("method") in ("default", "paper"):
        # The 1-D methods add the flux sensor's datasheet calibration to the fit's part in quadrature.
        u_rel = u / e
        return {"fit": math.sqrt(max(u_rel ** 2 - FLUX_CALIBRATION_U_REL ** 2, 0.0)),
                "flux_calibration": FLUX_CALIBRATION_U_REL}
    return {}


def method_estimate(d: Mapping[str, Any], probe: str, model_sha: str | None, thickness: bool) -> Estimate:
    """A probe head's estimator's dict as a typed :class:`Estimate` (before the chain, the flags and the naming).

    ``thickness``: the touch had a stated thickness (quantities the method resolved through it are
    ``"thickness"``-determined).  A flag that is not a :class:`Flag` word raises ValueError.
    """
    fit = d.get("fit") if isinstance(d.get("fit"), Mapping) else None
    corr = {"k_alpha": d.get("corr_k_alpha")}
    if fit is not None:
        corr["e_alpha"] = fit.get("corr_e_alpha")
    details = {"fit": d["fit"]} if fit is not None else {}
    cands = d.get("candidates") or ()
    lib = [(c[0], c[1]) for c in cands if isinstance(c, (list, tuple)) and len(c) == 2]
    u_parts = _u_parts(d, fit)
    return Estimate(
        probe=probe, method=str(d.get("method") or "none"),
        effusivity_W_s05_m2K=_num(d.get("effusivity_W_s05_m2K")),
        effusivity_W_s05_m2K_u=_num(d.get("effusivity_W_s05_m2K_u")),
        k_W_mK=_num(d.get("k_W_mK")), k_W_mK_u=_num(d.get("k_W_mK_u")),
        alpha_m2_s=_num(d.get("alpha_m2_s")), alpha_m2_s_u=_num(d.get("alpha_m2_s_u")),
        determined_by=_sources(d, thickness), corr_ln={k: v for k, v in corr.items() if _num(v) is not None},
        prior_reason=d.get("prior_reason"),
        normalised_residual=_num(fit.get("chi2_reduced")) ** 0.5 if fit and _num(fit.get("chi2_reduced")) else None,
        u_e_parts=u_parts, calibration_sha256=d.get("calibration_sha256"),
        model_sha256=d.get("model_sha256") or model_sha, flags=tuple(_flags(d.get("flags"))),
        material=d.get("material"), material_confidence=float(d.get("material_confidence") or 0.0),
        material_candidates=tuple(lib), details=details)


def _plain(v: Any) -> Any:
    """JSON-safe and short: floats to 5 significant digits (NaN/inf become None), lists and dicts of them."""
    if isinstance(v, float):
        return float(f"{v:.5g}") if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if hasattr(v, "item"):
        return _plain(v.item())
    return v


def _chain(record: TouchRecord, calibration: Any, estimator: Any) -> tuple[dict[str, Any], dict[str, float]]:
    """The sensor chain's estimate of the raw record as kept in the answer (its error if it fails), and its u parts."""
    from edge.estimation.chain_estimate import estimate_from_contact  # noqa: PLC0415 - only kinds with a chain

    library = getattr(estimator, "library", None)
    try:
        d = estimate_from_contact(record.t_s, record.T_C, record.q_W_m2, calibration, library=library,
                                  T_resolution_K=record.T_resolution_K or 0.0)
        chain = {k: _plain(d[k]) for k in CHAIN_KEEP if d.get(k) is not None}   # absent: not given
        parts = dict(d.get("u_e_parts") or {})
        chain["flags"] = [str(f) for f in d.get("flags") or ()]
    except Exception as e:  # the chain's estimate must never lose the measurement
        log.warning("sensor-chain estimate failed: %s", e)
        chain, parts = {"error": f"{type(e).__name__}: {e}"}, {}
    chain["calibration_sha256"] = None if calibration is None else calibration.sha256
    return chain, parts


def chain_answer(est: Estimate, chain: Mapping[str, Any], estimator: Any,
                 u_e_parts: Mapping[str, float] | None = None) -> Estimate | None:
    """The answer with the calibrated chain's e, k and α from the prior given it; None when it does not qualify.

    On a real probe the 1-D methods invert the ideal model -- no contact
    resistance, object at the probe's temperature, flux at the object's face --
    and are biased by tens of percent (ISSUE #10); the chain models all of it.
    Its e is the answer when a calibration was applied, the chain gave a finite
    e and u, and it raised none of :data:`BLOCKERS`; the method's own answer is
    kept in ``default_method``; ``u_e_parts`` are the chain's parts of u(e) (fit, calibration, floor,
    contact, lateral).
    """
    if est.method not in ("default", "paper") or chain.get("calibration_sha256") is None or "error" in chain:
        return None
    if BLOCKERS & set(chain.get("flags") or ()):
        return None
    e, u = _num(chain.get("effusivity_W_s05_m2K")), _num(chain.get("effusivity_W_s05_m2K_u"))
    if e is None or u is None or not (e > 0 and u > 0) or estimator is None:
        return None
    u_ln_e = u / e
    k, u_lk, alpha, u_la, outside = estimator.library.k_alpha_given_e(e, u_ln_e)
    cands = estimator.library.identify(e, u_ln_e)
    flags = est.flags + ((Flag.OUTSIDE_TRAINING_RANGE,) if outside else ())
    old = est.to_dict()
    return replace(est, method="sensor_chain", effusivity_W_s05_m2K=e, effusivity_W_s05_m2K_u=u,
                   k_W_mK=k, k_W_mK_u=k * u_lk, alpha_m2_s=alpha, alpha_m2_s_u=alpha * u_la,
                   determined_by={"e": "calibration", "k": "prior", "alpha": "prior"}, prior_reason=None,
                   corr_ln={}, normalised_residual=chain.get("normalised_residual"),
                   u_e_parts=dict(u_e_parts or {}),
                   material=cands[0][0], material_confidence=cands[0][1], material_candidates=tuple(cands),
                   flags=flags, details={**est.details, "default_method": {k_: old[k_] for k_ in DEFAULT_METHOD_KEYS}})


def _recognise(est: Estimate, context: SeamContext, contact_time_s: float | None = None) -> Estimate:
    objs = context.object_set
    name = context.object_set_name
    if objs is None or not len(objs):
        return replace(est, **_recognition_kw(unknown_recognition(name)))
    try:
        r = recognition_fields(objs, est.to_dict(), set_name=name, contact_time_s=contact_time_s)
    except Exception as e:  # naming the object must never lose the measurement
        log.exception("naming the object failed")
        return replace(est, details={**est.details, "object_error": f"{type(e).__name__}: {e}"},
                       **_recognition_kw(unknown_recognition(name or getattr(objs, "label", None))))
    return replace(est, **_recognition_kw(r))


def _recognition_kw(r: Mapping[str, Any]) -> dict[str, Any]:
    return {"object_set": r.get("object_set"), "object": r.get("object") or "unknown",
            "object_posterior": r.get("object_posterior"), "cls": r.get("class"),
            "class_posterior": r.get("class_posterior"), "unknown_posterior": r.get("unknown_posterior"),
            "candidates": tuple(r.get("candidates") or ())}


def estimate_touch(record: TouchRecord, context: SeamContext, *,
                   decision: Mapping[str, Any] | None = None) -> Estimate:
    """The answer to one touch: everything the device does after the last sample.

    Parameters
    ----------
    record : TouchRecord
        The raw touch and what the device knew while it measured.
    context : SeamContext
        The model, the calibration, the object set, the quality thresholds.
    decision : mapping, optional
        The running decision's last answer (``RunningAnswer.to_dict()`` with ``stopped_early``), if any.

    Returns
    -------
    Estimate
        Typed and immutable; ``to_dict()`` is the stored and sent JSON.

    Raises
    ------
    TooFewSamples
        The heating phase cannot be resampled (too short, or the heater never went on).
    Exception
        Whatever the probe head's estimator raises (the caller records ``estimation_failed``).
    """
    cond = condition(record, context.thresholds)
    seq_flags = list(cond.flags)
    if decision is not None and decision.get("stopped_early"):
        seq_flags.append(Flag.DECIDED)
    g_t, g_dT, g_q = _grid(record, cond)
    cal = context.calibration_for(record.probe)
    T_res = record.T_resolution_K if context.T_resolution_K is None else context.T_resolution_K
    thickness = context.thickness_m is not None and context.back != "infinite"
    kind = method_class(record.probe)
    if context.method is not None:
        d = context.method(g_t, g_dT, g_q, record.power_W, record.method)
    else:
        m = context.method_for(record.probe, T_res)
        d = m(g_t, g_dT, g_q, record.power_W, record.method, calibration=cal, thickness_m=context.thickness_m,
              back=context.back, **({"record": record, "baseline": (cond.T0_C, cond.q_offset_W_m2)}
                                    if getattr(m, "takes_record", False) else {}))
    model_sha = getattr(context.estimator, "sha256", None)
    est = method_estimate(d, record.probe, model_sha, thickness)
    est = replace(est, flags=tuple(seq_flags) + est.flags + (() if cal is not None else (Flag.UNCALIBRATED,)))
    withhold = False
    if kind.sensor_chain and record.heater_on_t_s is not None:
        chain, chain_parts = _chain(record, cal, context.estimator)
        extra = (Flag.CONTACT_LOST,) if Flag.CONTACT_LOST in (chain.get("flags") or ()) else ()
        est = replace(est, calibration_sha256=chain["calibration_sha256"], flags=est.flags + extra,
                      details={**est.details, "sensor_chain": chain})
        promoted = chain_answer(est, chain, context.estimator, chain_parts)
        if promoted is not None:
            # The calibrated chain found the contact in the record and fitted it, object temperature and
            # R_c included: the 1-D judgements of "no contact" / "no signal" (which assume an object at
            # the probe's temperature; a hand touch of a metal 2 K colder fooled them) are superseded.
            gone = tuple(f for f in promoted.flags if f in NO_ANSWER)
            chain_d = {**promoted.details.get("sensor_chain", {}), "superseded_flags": [str(f) for f in gone]}
            # Named in the chain's details so that whoever merges the conditioning's flags with this answer's
            # (the device's record) drops them too: an answered touch must not read "no_contact".
            est = replace(promoted, flags=tuple(f for f in promoted.flags if f not in NO_ANSWER),
                          details={**promoted.details, "sensor_chain": chain_d})
        elif cal is not None:
            # The installed calibration did not make this answer: say so (ISSUE #34, "answers that look
            # calibrated but are not"); sensor_chain.flags say why.
            est = est.with_flags(Flag.CALIBRATION_REFUSED)
            chain_flags = set(chain.get("flags") or ())
            if (Flag.POOR_FIT in chain_flags and chain.get("contact_detected")
                    and Flag.CONTACT_NOT_RECORDED not in chain_flags):
                # The contact was made during the record, before heating: the 1-D methods' premise (a
                # probe resting on the object long before heater-on) fails, and the chain, which models
                # the contact, does not fit either. No answer: on drawn as-built probes the 1-D fallback
                # read hand touches of foam 8-36 times too high with a u of 7-19 % (ISSUE #34).
                est, withhold = est.with_flags(Flag.POOR_FIT), True
    if withhold or NO_ANSWER & set(est.flags):
        # Nothing was touched or nothing measured: no answer, whatever a method fitted (ISSUE #34 item 3).
        est = replace(est, effusivity_W_s05_m2K=None, k_W_mK=None, alpha_m2_s=None, determined_by={},
                      material=None, material_confidence=0.0, material_candidates=(), u_e_parts={})
    est = _recognise(est, context, record.heater_on_s)   # the set's calibration at this contact time
    if decision is not None:
        est = replace(est, details={**est.details, "decision": dict(decision)})
        if decision.get("stopped_early") and decision.get("object") not in (None, est.object):
            # Heating stopped on a running answer the full estimate names differently: the result is the
            # answer, the decision is kept and flagged.
            est = est.with_flags(Flag.DECISION_DISAGREES)
    extra = d.get("series") if isinstance(d.get("series"), Mapping) else {}
    return replace(est, series={"grid_t_s": g_t, "grid_dT_K": g_dT, "grid_q_W_m2": g_q, **extra})
