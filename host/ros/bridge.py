"""The ROS 2 bridge without ROS: a touch's answers and events as standard ROS 2 messages.

The mapping (docs/ros.md has it as a table):

* each raw sample of a streamed touch -> ``sensor_msgs/msg/Temperature`` on ``thermotouch/temperature``
  (°C as the message defines it; ``variance`` 0 = unknown; stamp = the touch's start on the host
  clock plus the sample's board-clock offset);
* each answer -> ``diagnostic_msgs/msg/DiagnosticArray`` on ``thermotouch/answer``: one
  ``DiagnosticStatus`` (name ``thermotouch/answer``, level OK / WARN when flagged / ERROR when not
  ``ok``, ``hardware_id`` the device id) whose ``KeyValue`` pairs are :data:`ANSWER_KEYS`
  -- each value with its ``*_variance`` (u², k = 1), what determined it, the object, flags and ids;
* the running answer while the probe heats -> the same on ``thermotouch/running_answer``
  (:data:`RUNNING_KEYS`);
* device state (STATUS) -> ``diagnostic_msgs/msg/DiagnosticArray`` on ``/diagnostics``.

Messages are built through a :class:`MessageSet`, so the same code makes ``rosbags`` messages (CI,
no ROS install: :func:`rosbags_messages`) and ``rclpy`` messages (:func:`rclpy_messages`, the live
node in :mod:`host.ros.node`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from host.api import Measurement, Phase, Probe, RunningAnswer, Samples

__all__ = ["TOPICS", "ANSWER_KEYS", "RUNNING_KEYS", "MessageSet", "rosbags_messages", "rclpy_messages",
           "Bridge", "key_values"]

#: name -> (topic, message type) of everything the bridge publishes.
TOPICS: dict[str, tuple[str, str]] = {
    "temperature": ("thermotouch/temperature", "sensor_msgs/msg/Temperature"),
    "answer": ("thermotouch/answer", "diagnostic_msgs/msg/DiagnosticArray"),
    "running_answer": ("thermotouch/running_answer", "diagnostic_msgs/msg/DiagnosticArray"),
    "diagnostics": ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
}
#: KeyValue keys of an answer, in order (values: decimal text; "nan" where the device gave none).
ANSWER_KEYS = ("measurement_id", "status", "reason", "effusivity_W_s05_m2K", "effusivity_W_s05_m2K_variance",
               "k_W_mK", "k_W_mK_variance", "alpha_m2_s", "alpha_m2_s_variance", "determined_by_e",
               "determined_by_k", "determined_by_alpha", "object", "object_posterior", "flags", "device_id",
               "model_sha256", "calibration_sha256", "started_utc")
#: KeyValue keys of a running answer.
RUNNING_KEYS = ("object", "posterior", "effusivity_W_s05_m2K", "effusivity_W_s05_m2K_variance", "u_ln_e",
                "elapsed_s", "decided", "source")
#: DiagnosticStatus levels (the message's constants).
OK, WARN, ERROR = 0, 1, 2


@dataclass(frozen=True)
class MessageSet:
    """The message classes one ROS binding provides, and how it spells a DiagnosticStatus level."""

    Time: type
    Header: type
    Temperature: type
    DiagnosticArray: type
    DiagnosticStatus: type
    KeyValue: type
    level: Callable[[int], Any]


def rosbags_messages(typestore: Any = None) -> MessageSet:
    """Messages of ``rosbags`` (pure Python; ``typestore`` default: ROS 2 Jazzy's)."""
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415 - an optional dependency

    ts = typestore if typestore is not None else get_typestore(Stores.ROS2_JAZZY)
    t = ts.types
    return MessageSet(t["builtin_interfaces/msg/Time"], t["std_msgs/msg/Header"], t["sensor_msgs/msg/Temperature"],
                      t["diagnostic_msgs/msg/DiagnosticArray"], t["diagnostic_msgs/msg/DiagnosticStatus"],
                      t["diagnostic_msgs/msg/KeyValue"], int)


def rclpy_messages() -> MessageSet:
    """Messages of the ROS 2 Python wheels (``thermotouch[ros]``)."""
    from builtin_interfaces.msg import Time  # noqa: PLC0415 - an optional dependency
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: PLC0415
    from sensor_msgs.msg import Temperature  # noqa: PLC0415
    from std_msgs.msg import Header  # noqa: PLC0415

    return MessageSet(Time, Header, Temperature, DiagnosticArray, DiagnosticStatus, KeyValue,
                      lambda n: bytes([n]))


def _text(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else "nan"
    if isinstance(v, (list, tuple)):
        return ",".join(map(str, v))
    return str(v)


def _var(u: float) -> float:
    return u * u if math.isfinite(u) else math.nan


def answer_values(m: Measurement) -> dict[str, Any]:
    """An answer's :data:`ANSWER_KEYS` (values before they become text)."""
    d = m.determined_by
    return {"measurement_id": m.measurement_id, "status": m.status, "reason": m.reason,
            "effusivity_W_s05_m2K": m.effusivity_W_s05_m2K,
            "effusivity_W_s05_m2K_variance": _var(m.effusivity_W_s05_m2K_u),
            "k_W_mK": m.k_W_mK, "k_W_mK_variance": _var(m.k_W_mK_u),
            "alpha_m2_s": m.alpha_m2_s, "alpha_m2_s_variance": _var(m.alpha_m2_s_u),
            "determined_by_e": d.get("e"), "determined_by_k": d.get("k"), "determined_by_alpha": d.get("alpha"),
            "object": m.object, "object_posterior": m.object_posterior, "flags": m.flags, "device_id": m.device_id,
            "model_sha256": m.model_sha256, "calibration_sha256": m.calibration_sha256,
            "started_utc": m.started_utc}


def running_values(a: RunningAnswer) -> dict[str, Any]:
    """A running answer's :data:`RUNNING_KEYS` (the effusivity's variance from its relative u)."""
    e = a.effusivity_W_s05_m2K
    return {"object": a.object, "posterior": a.posterior, "effusivity_W_s05_m2K": e,
            "effusivity_W_s05_m2K_variance": (e * a.u_ln_e) ** 2, "u_ln_e": a.u_ln_e, "elapsed_s": a.elapsed_s,
            "decided": a.decided, "source": a.source}


def key_values(msg: Any) -> dict[str, str]:
    """The KeyValue pairs of a DiagnosticArray's first status (how a subscriber reads an answer)."""
    return {kv.key: kv.value for kv in msg.status[0].values}


class Bridge:
    """Publishes a probe's touches and state as ROS 2 messages through ``publish(name, msg, stamp_ns)``.

    Parameters
    ----------
    probe : Probe
    msgs : MessageSet
    publish : callable
        ``publish(name, msg, stamp_ns)`` with ``name`` a key of :data:`TOPICS`.
    frame_id : str
        The headers' frame (the probe's tip).
    clock_ns : callable
        Host clock for stamps, ns (default wall time, as ROS's system time).
    """

    def __init__(self, probe: Probe, msgs: MessageSet, publish: Callable[[str, Any, int], None], *,
                 frame_id: str = "thermotouch_tip", clock_ns: Callable[[], int] = time.time_ns) -> None:
        self.probe = probe
        self.msgs = msgs
        self.publish = publish
        self.frame_id = frame_id
        self.clock_ns = clock_ns

    def _header(self, stamp_ns: int) -> Any:
        M = self.msgs
        return M.Header(stamp=M.Time(sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9)),
                        frame_id=self.frame_id)

    def _array(self, stamp_ns: int, name: str, level: int, message: str, hardware_id: str,
               values: Mapping[str, Any]) -> Any:
        M = self.msgs
        status = M.DiagnosticStatus(level=M.level(level), name=name, message=message, hardware_id=hardware_id,
                                    values=[M.KeyValue(key=k, value=_text(v)) for k, v in values.items()])
        return M.DiagnosticArray(header=self._header(stamp_ns), status=[status])

    def answer_msg(self, m: Measurement, stamp_ns: int) -> Any:
        """The DiagnosticArray of an answer (:data:`ANSWER_KEYS`)."""
        level = ERROR if not m.ok else (WARN if m.flags else OK)
        summary = (f"{m.object}: e = {m.effusivity_W_s05_m2K:.4g} W s^0.5/m^2/K" if m.ok
                   else f"{m.status} ({m.reason})")
        return self._array(stamp_ns, "thermotouch/answer", level, summary, m.device_id or "", answer_values(m))

    def running_msg(self, a: RunningAnswer, stamp_ns: int) -> Any:
        """The DiagnosticArray of a running answer (:data:`RUNNING_KEYS`)."""
        return self._array(stamp_ns, "thermotouch/running_answer", OK, f"{a.object} ({a.posterior:.2f})",
                           self.probe.device_id or "", running_values(a))

    def temperature_msg(self, T_C: float, stamp_ns: int) -> Any:
        """One raw sample as sensor_msgs/Temperature (°C; variance 0 = unknown)."""
        return self.msgs.Temperature(header=self._header(stamp_ns), temperature=float(T_C), variance=0.0)

    def touch(self, **measure_kw: Any) -> Measurement:
        """Run one streamed touch, publishing its samples, running answers and answer; return the answer."""
        t0_ns = self.clock_ns()
        final: Measurement | None = None
        for item in self.probe.stream(**measure_kw):
            if isinstance(item, Samples):
                for t_s, T_C in zip(item.t_s, item.T_C):
                    if math.isfinite(T_C):
                        stamp = t0_ns + int(round(t_s * 1e9))
                        self.publish("temperature", self.temperature_msg(T_C, stamp), stamp)
            elif isinstance(item, RunningAnswer):
                stamp = t0_ns + int(round(item.t_s * 1e9))
                self.publish("running_answer", self.running_msg(item, stamp), stamp)
            elif isinstance(item, Measurement):
                final = item
            elif isinstance(item, Phase):
                pass  # the phases show in the diagnostics (STATUS phase) and the answer's status
        if final is None:  # pragma: no cover - stream() ends with the Measurement or raises
            raise RuntimeError("the touch's stream ended without its answer")
        stamp = self.clock_ns()
        self.publish("answer", self.answer_msg(final, stamp), stamp)
        return final

    def diagnostics(self) -> Any:
        """Publish (and return) the device's state as /diagnostics."""
        st = self.probe.status()
        faults = st.get("faults") or []
        level = ERROR if st.get("state") == "fault" or st.get("heater_fault") else (WARN if faults else OK)
        keys = ("state", "ready", "can_measure", "heater_on", "heater_fault", "measurements", "last_measurement_id",
                "events_sent", "events_dropped", "replies_dropped", "uptime_s")
        values = {k: st.get(k) for k in keys}
        values["faults"] = "; ".join(map(str, faults))
        stamp = self.clock_ns()
        msg = self._array(stamp, "thermotouch: device", level, str(st.get("state")), self.probe.device_id or "",
                          values)
        self.publish("diagnostics", msg, stamp)
        return msg
