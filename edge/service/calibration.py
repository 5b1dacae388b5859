"""The probe's calibration in the daemon: CALIBRATION_SET/GET, INFO's fields, and the installed calibration.

:class:`ProbeCalibrations` joins the store (:mod:`edge.storage.calibration_store`,
which knows files) and the daemon's requests.  What a calibration does to a
measurement is the estimate path's (:func:`edge.estimation.seam.estimate_touch`):
the daemon hands it :meth:`ProbeCalibrations.current`, and every answer says
which calibration it used (``calibration_sha256``) or is flagged ``uncalibrated``.
"""

from __future__ import annotations

import logging
from typing import Any

from edge.calibration.model import MAX_BYTES, ProbeCalibration
from edge.protocol.errors import CommandError, ErrorCode
from edge.status import Flag
from edge.storage.calibration_store import CalibrationStore, CalibrationStoreError

__all__ = ["ProbeCalibrations"]

log = logging.getLogger("thermotouch.edge")


class ProbeCalibrations:
    """The daemon's calibration: store, install/get, and the one installed for the estimate path.

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
            return f"{e} (measurements are flagged '{Flag.UNCALIBRATED}')"
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
