"""The probe's calibration in the daemon: CALIBRATION_SET/GET, INFO's fields, and every measurement's chain estimate.

:class:`ProbeCalibrations` joins the store (:mod:`edge.storage.calibration_store`,
which knows files) and the sensor-chain estimate
(:mod:`edge.estimation.chain_estimate`, which knows records), as
:mod:`edge.service.objects` joins object sets and recognition.

Every measurement that ends ``ok`` gets, besides the default method's
answer, the sensor chain's: e, the contact resistance and the object's
initial temperature fitted from the moment of contact on the raw record
(baseline samples included), with the installed calibration -- or, without
one, the datasheet chain, and the record is flagged ``uncalibrated``
(ISSUE #10 §4).  It is stored as ``result["sensor_chain"]`` with the
calibration's sha256.  A failure there never loses the measurement: it is
named in ``result["sensor_chain"]["error"]``.
"""

from __future__ import annotations

import logging
import math
from typing import Any, Callable

from edge.calibration.model import MAX_BYTES, ProbeCalibration
from edge.protocol.errors import CommandError, ErrorCode
from edge.storage.calibration_store import CalibrationStore, CalibrationStoreError

__all__ = ["ProbeCalibrations", "UNCALIBRATED", "promote_chain", "PROMOTE_BLOCKERS"]

log = logging.getLogger("thermotouch.edge")

#: The flag of a measurement made without an installed calibration.
UNCALIBRATED = "uncalibrated"
#: Fields of the chain estimate kept in a measurement record: the answer and what judges it.  (The rest
#: -- u's parts, the fit window -- is recomputable from the stored raw series; a HISTORY page is one
#: 4-kB frame, so every record stays small.)
_KEEP = ("contact_lost_t_s", "effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "contact_resistance_m2K_W",
         "contact_resistance_m2K_W_u", "object_temperature0", "object_temperature0_u", "contact_t_s",
         "normalised_residual", "flags", "determined", "alpha_m2_s", "alpha_m2_s_u", "k_W_mK", "k_W_mK_u")


class ProbeCalibrations:
    """The daemon's calibration: store, install/get, and the chain estimate of each measurement.

    Parameters
    ----------
    root : path-like
        Store directory.
    probe : str
        The device's probe head (``board.probe``).
    policy : edge.security.policy.UpdatePolicy
        Who may install a calibration (as for models and object sets).
    """

    def __init__(self, root, probe: str, policy: Any) -> None:
        self.probe = probe
        self._error: str | None = None
        try:
            self.store: CalibrationStore | None = CalibrationStore(
                root, probe, policy, parse=ProbeCalibration.from_json, max_bytes=MAX_BYTES)
        except OSError as e:
            self.store, self._error = None, f"cannot open {root}: {e}"

    def current(self) -> ProbeCalibration | None:
        """The installed calibration (None: none, or one that cannot be used -- see :meth:`error`)."""
        if self.store is None:
            return None
        try:
            return self.store.current()
        except CalibrationStoreError as e:
            self._error = str(e)
            return None

    def error(self) -> str | None:
        """Why the calibration store cannot be used now (None: it can)."""
        if self.store is None:
            return self._error
        try:
            self.store.current()
        except CalibrationStoreError as e:
            return f"{e} (measurements are flagged '{UNCALIBRATED}')"
        return None

    def info(self) -> dict[str, Any]:
        """INFO's fields: the installed calibration's sha256 (None) and whether there is one."""
        cal = self.current()
        return {"calibration_sha256": None if cal is None else cal.sha256, "calibrated": cal is not None}

    def install(self, text: str, signature: str | None) -> dict[str, Any]:
        """CALIBRATION_SET."""
        if self.store is None:
            raise CommandError(ErrorCode.BAD_STATE, f"calibration store unavailable: {self._error}")
        try:
            cal = self.store.install(text.encode("utf-8"), None if signature is None else signature.encode("utf-8"))
        except CalibrationStoreError as e:
            raise CommandError(ErrorCode.MODEL_REJECTED, str(e), "calibration") from None
        except OSError as e:
            raise CommandError(ErrorCode.INTERNAL, f"could not store the calibration: {e}") from None
        log.info("calibration %s installed (probe %s)", cal.sha256[:12], cal.probe)
        return {"sha256": cal.sha256, "probe": cal.probe, "created_utc": cal.created_utc}

    def get(self) -> dict[str, Any]:
        """CALIBRATION_GET."""
        cal = self.current()
        if cal is None:
            return {"calibration": None, "sha256": None, "calibrated": False, "signed_by": None}
        return {"calibration": cal.to_json_compact(), "sha256": cal.sha256, "calibrated": True,
                "signed_by": self.store.signed_by() if self.store is not None else None}

    def apply(self, outcome: Any) -> None:
        """Add the chain estimate and the calibration's identity to a finished measurement (in place)."""
        cal = self.current()
        if self.probe != "paper":
            # The small heater's estimate applied the installed flux scale itself (ModelEstimator) and
            # says so with its calibration_sha256; a result without one was made uncalibrated.
            if outcome.result is None or outcome.result.get("calibration_sha256") is None:
                if UNCALIBRATED not in outcome.flags:
                    outcome.flags.append(UNCALIBRATED)
            return
        if cal is None and UNCALIBRATED not in outcome.flags:
            outcome.flags.append(UNCALIBRATED)
        if outcome.result is None or outcome.raw_t_s is None:
            return
        from edge.estimation.chain_estimate import estimate_from_contact  # noqa: PLC0415

        try:
            d = estimate_from_contact(outcome.raw_t_s, outcome.raw_T_C, outcome.raw_q_W_m2, cal)
            chain = {k: _plain(d.get(k)) for k in _KEEP}
        except Exception as e:  # the chain's estimate must never lose the measurement
            log.warning("sensor-chain estimate failed: %s", e)
            chain = {"error": f"{type(e).__name__}: {e}"}
        chain["calibration_sha256"] = None if cal is None else cal.sha256
        outcome.result["sensor_chain"] = chain
        if "contact_lost" in (chain.get("flags") or ()) and "contact_lost" not in outcome.flags:
            # The probe left the object while heating: every answer of this record is suspect.
            outcome.flags.append("contact_lost")


#: Chain flags that keep the default method's answer first: the chain did not describe the record.
PROMOTE_BLOCKERS = frozenset({"poor_fit", "contact_lost", "no_contact", "no_fit"})
#: Keys of the default method's answer kept under ``result["default_method"]`` once the chain's is first
#: (its candidate list is not: a record must stay within one reply, edge.service.requests.fit_record).
DEFAULT_METHOD_KEYS = ("effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u", "alpha_m2_s",
                       "alpha_m2_s_u", "material", "material_confidence", "method")
#: Keys the chain's answer replaces.
_ANSWER_KEYS = DEFAULT_METHOD_KEYS + ("candidates",)


def promote_chain(result: dict | None, estimator: Callable[[], Any]) -> bool:
    """Make a calibrated chain's e the measurement's answer (in place); True when it did.

    On a real probe the default method inverts the ideal 1-D model -- no
    contact resistance, object at the probe's temperature, flux at the
    object's face -- and is biased by tens of percent (ISSUE #10); the chain
    models all of it. Once a calibration is installed its e is the answer:
    ``effusivity_W_s05_m2K`` and its u are the chain's, k, α and the
    material follow from it through the library prior exactly as for the
    default method (:meth:`edge.estimation.estimate.Estimator.from_effusivity`),
    ``method`` is ``"sensor_chain"``, and the default method's own answer is
    kept in ``result["default_method"]``. Nothing changes when the probe is
    uncalibrated (the datasheet chain is biased too), when the chain failed or
    flagged that it does not describe the record (:data:`PROMOTE_BLOCKERS`),
    or when ``estimator()`` -- called only once the chain qualifies -- is not
    the model the measurement was made with.
    """
    if not result or result.get("method") not in ("default", "paper"):
        return False
    chain = result.get("sensor_chain")
    if not isinstance(chain, dict) or chain.get("calibration_sha256") is None or "error" in chain:
        return False
    if PROMOTE_BLOCKERS & set(chain.get("flags") or ()):
        return False
    e, u = chain.get("effusivity_W_s05_m2K"), chain.get("effusivity_W_s05_m2K_u")
    if not (isinstance(e, (int, float)) and isinstance(u, (int, float)) and math.isfinite(e) and e > 0
            and math.isfinite(u) and u > 0):
        return False
    est = estimator()
    if est is None or getattr(est, "sha256", None) != result.get("model_sha256"):
        return False
    new = est.from_effusivity(float(e), float(u) / float(e), method="sensor_chain").to_dict()
    result["default_method"] = {k: result.get(k) for k in DEFAULT_METHOD_KEYS}
    for k in _ANSWER_KEYS:
        result[k] = new.get(k)
    extra = [str(f) for f in new.get("flags") or () if str(f) not in (result.get("flags") or [])]
    if extra:
        result["flags"] = list(result.get("flags") or []) + extra
    return True


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
