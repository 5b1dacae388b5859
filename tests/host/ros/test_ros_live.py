"""The bridge node live, where the ROS 2 wheels work: a service call runs a simulated touch, a subscriber
gets the answer, the running answers and the temperatures through rclpy."""

from __future__ import annotations

import json
import threading
import time

import pytest

from host.api import Probe
from host.device import simulated_probe
from host.ros.bridge import ANSWER_KEYS, key_values
from tests.host.ros.support import live_ros_unavailable

# slow: a live rclpy node around a simulated probe's touch (1.3 s); test_ros_bag.py's mapping tests stay fast.
pytestmark = [pytest.mark.hil, pytest.mark.slow]
WAIT_s = 20.0


@pytest.fixture(autouse=True)
def _live_ros():
    """Skip where rclpy cannot run here: asked when a test here runs, not when every worker collects
    (the question imports rclpy and starts a context)."""
    why = live_ros_unavailable()
    if why is not None:
        pytest.skip(why)


def _wait(cond, timeout_s=WAIT_s):
    deadline = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.01)
    return cond()


def test_a_service_call_runs_a_touch_and_its_answer_reaches_a_subscriber(tmp_path):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import Temperature
    from std_srvs.srv import Trigger

    from host.ros.node import ThermoTouchNode

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    got: dict[str, list] = {"answer": [], "running": [], "temperature": []}
    with simulated_probe("glass_12V", tmp_path) as (port, daemon, sim):
        node = ThermoTouchNode(Probe.connect(port), context=ctx)
        robot = rclpy.create_node("robot", context=ctx)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        robot.create_subscription(DiagnosticArray, "thermotouch/answer", got["answer"].append, latched)
        robot.create_subscription(DiagnosticArray, "thermotouch/running_answer", got["running"].append, 10)
        robot.create_subscription(Temperature, "thermotouch/temperature", got["temperature"].append,
                                  qos_profile_sensor_data)
        client = robot.create_client(Trigger, "thermotouch/measure")
        executor = MultiThreadedExecutor(context=ctx)
        executor.add_node(node)
        executor.add_node(robot)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        try:
            assert client.wait_for_service(timeout_sec=WAIT_s)
            future = client.call_async(Trigger.Request())
            assert _wait(future.done)
            response = future.result()
            assert _wait(lambda: got["answer"])
        finally:
            executor.shutdown()
            # The spinner leaves its loop before the context goes: on a loaded machine it was still
            # between two waits when try_shutdown ran, and its next wait set raised in the thread.
            spinner.join(WAIT_s)
            node.destroy_node()
            robot.destroy_node()
            rclpy.try_shutdown(context=ctx)
    assert response.success, response.message
    reply = json.loads(response.message)
    kv = key_values(got["answer"][-1])
    assert tuple(kv) == ANSWER_KEYS and int(kv["measurement_id"]) == reply["measurement_id"]
    assert float(kv["effusivity_W_s05_m2K"]) == reply["effusivity_W_s05_m2K"] > 0
    assert got["running"] and got["temperature"]
    assert all(20.0 < m.temperature < 80.0 for m in got["temperature"])
