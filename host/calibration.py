"""The probe's calibration over the link: install, read back, check (host side of CALIBRATION_SET/GET).

Used by ``thermotouch calibrate``; the fit itself is
:func:`edge.calibration.fit.fit_calibration` (the device's own code).  The
walk-through (``calibrate --port/--sim`` without ``--record``) touches each
reference with an armed MEASURE -- the device samples in air, finds the
contact, heats ``settle_s`` after it -- and fits the raw records the device
stored (SERIES), exactly as the offline form fits exported ones.
"""

from __future__ import annotations

import math
from typing import Any

from edge.calibration.model import ProbeCalibration
from edge.protocol.commands import Command

__all__ = ["install_calibration", "read_calibration", "check_record", "touch_reference", "reference_scene",
           "WalkError", "HEAT_s"]

#: Heating time of a reference touch (s): long enough for a metal's rise to stand well out of the
#: thermometer's noise (the chain's fit weighs the whole record).
HEAT_s = 8.0


class WalkError(RuntimeError):
    """A reference touch that cannot enter the fit (no contact, aborted, no raw record)."""


def install_calibration(client: Any, cal: ProbeCalibration, *, key: Any = None) -> dict[str, Any]:
    """CALIBRATION_SET with the compact file text, signed with ``key`` when given."""
    text = cal.to_json_compact()
    args: dict[str, Any] = {"calibration": text}
    if key is not None:
        from edge.security.keys import signature_document  # noqa: PLC0415

        args["signature"] = signature_document(key, text.encode("utf-8")).decode("utf-8")
    return client.request(Command.CALIBRATION_SET, args)


def read_calibration(client: Any) -> tuple[ProbeCalibration | None, dict[str, Any]]:
    """CALIBRATION_GET: the installed calibration (None) and the reply."""
    rep = client.request(Command.CALIBRATION_GET)
    text = rep.get("calibration")
    return (None if text is None else ProbeCalibration.from_json(text)), rep


def check_record(record: dict[str, Any], reference_e: float, reference_u_rel: float) -> dict[str, Any]:
    """Does a touch of a reference agree with its value within the stated uncertainties (95 %)?

    ``record``: a MEASURE reply; its ``result.sensor_chain`` is judged.  Returns ``holds`` (bool or
    None when the chain gave no answer), the relative deviation and the z-score against the combined
    uncertainty of the touch and the reference.
    """
    chain = (record.get("result") or {}).get("sensor_chain") or {}
    e, u = chain.get("effusivity_W_s05_m2K"), chain.get("effusivity_W_s05_m2K_u")
    if e is None or u is None or not (e > 0 and u > 0):
        return {"holds": None, "why": chain.get("error") or "the touch gave no sensor-chain estimate",
                "flags": chain.get("flags")}
    u_comb = math.hypot(u / e, reference_u_rel)
    dev = math.log(e / reference_e)
    z = dev / u_comb
    return {"holds": abs(z) <= 1.96, "e_W_s05_m2K": e, "u_e_W_s05_m2K": u, "reference_e_W_s05_m2K": reference_e,
            "deviation_rel": math.expm1(dev), "z": z, "flags": chain.get("flags"),
            "calibration_sha256": chain.get("calibration_sha256")}


def touch_reference(client: Any, name: str, e_ref: float, *, heat_s: float = HEAT_s, arm_s: float = 30.0,
                    settle_s: float = 1.0):
    """One armed touch of reference ``name`` and its raw record as a fit input.

    Returns ``(ReferenceTouch, record)``.  Raises :class:`WalkError` when the touch cannot be used:
    it did not come within ``arm_s`` (``no_contact``), it was aborted or refused, or the chain found
    no contact in the record (the probe was already on the reference when it was armed).
    """
    import numpy as np  # noqa: PLC0415

    from edge.calibration.fit import ReferenceTouch  # noqa: PLC0415
    from edge.estimation.chain_estimate import uniform_record  # noqa: PLC0415

    rec = client.measure(contact_time_s=heat_s, arm_s=arm_s, settle_s=settle_s)
    if rec.get("status") != "ok":
        why = rec.get("reason") or rec.get("status")
        hint = f": no touch within {arm_s:g} s" if why == "no_contact" else ""
        raise WalkError(f"{name}: the touch ended {why}{hint}; nothing was fitted or installed")
    s = client.series(rec["measurement_id"], "raw")
    if s.get("raw_t_s") is None:
        raise WalkError(f"{name}: measurement {rec['measurement_id']} has no raw record to fit")
    t, T, q = (np.asarray(s[k], float) for k in ("raw_t_s", "raw_T_C", "raw_q_W_m2"))
    keep = np.isfinite(t) & np.isfinite(T) & np.isfinite(q)
    try:  # the converters' own instants onto one uniform grid, as an exported record is read
        t, T, q = uniform_record(t[keep], T[keep], q[keep])
    except ValueError as exc:
        raise WalkError(f"{name}: measurement {rec['measurement_id']}: {exc}") from None
    chain = (rec.get("result") or {}).get("sensor_chain") or {}
    if "contact_not_recorded" in (chain.get("flags") or []):
        raise WalkError(f"{name}: the record starts in contact (the probe was on the reference when armed); "
                        "lift it, then touch again")
    return ReferenceTouch(name, e_ref, t, T, q), rec


def reference_scene(scene: str, name: str, dest_dir: Any, *, heat_s: float = HEAT_s, settle_s: float = 1.0):
    """A simulated touch of reference ``name``: ``scene`` with the reference as its object.

    The object becomes a 50-mm specimen of the library material (insulated back); the touch
    comes 1 s after the simulator starts (the armed device samples the air before it) and lasts
    the settling, the heating and 1.5 s more; its contact resistance and the object's temperature
    stay the scene's. Everything else -- the board, the as-built probe -- is the scene's own.
    """
    import tomllib  # noqa: PLC0415

    from firmware_sim.scene.files import scene_path, scene_variant  # noqa: PLC0415

    data = tomllib.loads(scene_path(scene).read_text())
    touch = dict(data.get("touch", {}))
    for k in ("repeat", "repeat_gap_s", "trigger_hold_s"):
        touch.pop(k, None)
    touch.update(start_s=1.0, length_s=float(settle_s + heat_s + 1.5), contact_lead_s=0.0, press_trigger=False)
    return scene_variant(scene, dest_dir, suffix=f"_ref_{name}",
                         object={"material": name, "thickness_m": 0.05, "back": "insulated"}, touch=touch)

