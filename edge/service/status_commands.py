"""The daemon's state and its PING, INFO and STATUS replies.
"""

from __future__ import annotations

import logging
import time
from enum import StrEnum

import edge
from edge.measure.sequence import Phase
from edge.protocol.frame import PROTOCOL_VERSION
from edge.storage.history import HistoryError

__all__ = [
    "FIRMWARE_VERSION", "State", "StatusCommands",
]

log = logging.getLogger("thermotouch.edge")

FIRMWARE_VERSION = edge.__version__


class State(StrEnum):
    """The daemon's state (``state`` in STATUS)."""

    STARTING = "starting"
    IDLE = "idle"
    MEASURING = "measuring"
    #: The heater could not be switched off: measurements stay disabled until restart.
    FAULT = "fault"
    STOPPED = "stopped"


class StatusCommands:
    """PING, INFO and STATUS: what the daemon is, what it is doing, whether it can measure.

    Mixed into :class:`edge.service.daemon.Daemon`, whose constructor sets the attributes used
    here; the methods are the daemon's own (``self`` is the daemon).
    """

    def _cmd_ping(self, args: dict) -> dict:
        return {"echo": args.get("echo")}

    def _cmd_info(self, args: dict) -> dict:
        st = self.store.status()
        return {"protocol_version": PROTOCOL_VERSION, "firmware_version": FIRMWARE_VERSION,
                "model_version": st.get("model_version"), "model_sha256": st.get("sha256"),
                "model_source": st.get("source"), "board": self.board.name, "device_id": self.device_id,
                "faults": self.fault_list(),
                "object_set": self._named_object_set()[0], **self.calibration.info()}

    def _cmd_status(self, args: dict) -> dict:
        try:
            total: int | None = self.history.count()
        except HistoryError:
            total = None  # named in faults
        out = {"state": self.state, "heater_on": self.heater.is_on,
               "heater_fault": self.heater.disabled is not None or self.heater.fault is not None,
               "heater_on_time_s": round(self.heater.on_time_s, 6), "measurements": self.measurements,
               "last_measurement_id": self.last_id, "history_total": total,
               "sensor_error": self.sensor_error, "faults": self.fault_list(),
               "unsaved_records": len(self.unsaved), "can_measure": not self._measure_blockers(),
               "replies_dropped": getattr(self.endpoint, "replies_dropped", 0),
               # Streaming MEASUREs' events queued for the link, and those a slow or gone host lost.
               "events_sent": getattr(self.endpoint, "events_sent", 0),
               "events_dropped": getattr(self.endpoint, "events_dropped", 0),
               "uptime_s": round(time.monotonic() - self.t_start, 3)}
        upload = self.upload.progress()
        if upload is not None:
            out["upload"] = upload
        t0 = self._measure_t0
        if self.state == State.MEASURING and t0 is not None:
            out["phase"] = self.phase
            out["measurement_elapsed_s"] = round(self.board.clock.monotonic() - t0, 3)  # board clock
            seq = self.sequence
            running = (Phase.HEATING, Phase.RESAMPLING, Phase.ESTIMATING)
            ans = getattr(seq, "answer", None) if self.phase in running else None
            if ans is not None:
                out["answer"] = ans.to_dict()
            out["ready"] = False
        else:
            self._poll_readiness()
            m = self.config.measurement
            out["ready"] = bool(out["can_measure"] and self.state == State.IDLE
                                and self.readiness.settled(m.baseline_s, m.unstable_baseline_K))
        return out
