"""The probe's calibration over the link: install, read back, check (host side of CALIBRATION_SET/GET).

Used by ``thermotouch calibrate --install/--show/--check``; the fit itself is
:func:`edge.calibration.fit.fit_calibration` (the device's own code).
"""

from __future__ import annotations

import math
from typing import Any

from edge.calibration.model import ProbeCalibration
from edge.protocol.commands import Command

__all__ = ["install_calibration", "read_calibration", "check_record"]


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
