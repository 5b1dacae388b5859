"""The ROS 2 node: a probe's answers, running answers, samples and state as topics; a touch as a service.

Run it with ``ros2 launch host/ros/launch/thermotouch.launch.py`` or ``python -m host.ros.node
--ros-args --params-file host/ros/config/thermotouch.params.yaml``. Topics and messages are those
of :mod:`host.ros.bridge` (docs/ros.md); the service ``thermotouch/measure`` (``std_srvs/srv/Trigger``)
runs one streamed touch and answers ``success`` (the touch ended ``ok``) and ``message`` (the
answer as compact JSON: :data:`host.ros.bridge.ANSWER_KEYS`).

Parameters: ``port`` (the probe's serial port), ``contact_time_s`` and ``power_W`` (0: the device's
setting), ``until_decided``, ``frame_id``, ``diagnostics_period_s`` (0: none).

QoS per topic: temperature samples best effort (sensor data), the answer reliable and transient
local (a late subscriber gets the last answer), running answers and diagnostics reliable.
"""

from __future__ import annotations

import json
import math
import threading
from typing import Any

from host.api import Probe
from host.ros.bridge import TOPICS, Bridge, answer_values, rclpy_messages

__all__ = ["ThermoTouchNode", "main"]

#: Node parameters and their defaults.
PARAMETERS: dict[str, Any] = {"port": "", "contact_time_s": 0.0, "power_W": 0.0, "until_decided": False,
                              "frame_id": "thermotouch_tip", "diagnostics_period_s": 1.0}


def _qos() -> dict[str, Any]:
    from rclpy.qos import (DurabilityPolicy, QoSProfile, ReliabilityPolicy,  # noqa: PLC0415
                           qos_profile_sensor_data)

    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    return {"temperature": qos_profile_sensor_data, "answer": latched, "running_answer": reliable,
            "diagnostics": reliable}


def _make_node_class() -> type:
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup  # noqa: PLC0415
    from rclpy.node import Node  # noqa: PLC0415
    from std_srvs.srv import Trigger  # noqa: PLC0415

    class ThermoTouchNode(Node):
        """The bridge node; ``probe`` may be given (tests), else it connects to the ``port`` parameter."""

        def __init__(self, probe: Probe | None = None, **kw: Any) -> None:
            super().__init__("thermotouch", **kw)
            for name, default in PARAMETERS.items():
                self.declare_parameter(name, default)
            port = self.get_parameter("port").value
            if probe is None:
                if not port:
                    raise ValueError("parameter 'port' is empty: give the probe's serial port")
                probe = Probe.connect(port)
            self.probe = probe
            self._busy = threading.Lock()  # one touch at a time; diagnostics wait for none
            qos = _qos()
            self._pubs = {name: self.create_publisher(_msg_class(msgtype), topic, qos[name])
                          for name, (topic, msgtype) in TOPICS.items()}
            self.bridge = Bridge(probe, rclpy_messages(), self._publish,
                                 frame_id=self.get_parameter("frame_id").value)
            # The touch and the diagnostics timer in separate groups: a touch (seconds) blocks neither.
            self.create_service(Trigger, "thermotouch/measure", self._on_measure,
                                callback_group=MutuallyExclusiveCallbackGroup())
            period = float(self.get_parameter("diagnostics_period_s").value)
            if period > 0:
                self.create_timer(period, self._on_timer, callback_group=MutuallyExclusiveCallbackGroup())

        def _publish(self, name: str, msg: Any, stamp_ns: int) -> None:
            self._pubs[name].publish(msg)

        def _measure_kw(self) -> dict[str, Any]:
            kw: dict[str, Any] = {}
            for name in ("contact_time_s", "power_W"):
                v = float(self.get_parameter(name).value)
                if v > 0:
                    kw[name] = v
            if self.get_parameter("until_decided").value:
                kw["until_decided"] = True
            return kw

        def _on_measure(self, request: Any, response: Any) -> Any:
            with self._busy:
                try:
                    m = self.bridge.touch(**self._measure_kw())
                except Exception as e:  # the service answers; the node stays up
                    response.success, response.message = False, f"{type(e).__name__}: {e}"
                    return response
            values = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                      for k, v in answer_values(m).items()}
            response.success, response.message = m.ok, json.dumps(values, separators=(",", ":"))
            return response

        def _on_timer(self) -> None:
            if not self._busy.acquire(blocking=False):
                return  # a touch holds the link; its answer follows
            try:
                self.bridge.diagnostics()
            except Exception as e:
                self.get_logger().warning(f"diagnostics: {e}")
            finally:
                self._busy.release()

        def destroy_node(self) -> None:
            try:
                self.probe.close()
            finally:
                super().destroy_node()

    return ThermoTouchNode


def _msg_class(msgtype: str) -> type:
    import importlib  # noqa: PLC0415

    pkg, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def __getattr__(name: str) -> Any:
    # The class needs rclpy: made on first use, so `import host.ros.node` works without ROS.
    if name == "ThermoTouchNode":
        cls = _make_node_class()
        globals()["ThermoTouchNode"] = cls
        return cls
    raise AttributeError(name)


def main(args: list[str] | None = None) -> None:
    """Spin the node until Ctrl-C (``ros2 run``-style entry point)."""
    import rclpy  # noqa: PLC0415
    from rclpy.executors import MultiThreadedExecutor  # noqa: PLC0415

    rclpy.init(args=args)
    node = __getattr__("ThermoTouchNode")()
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
