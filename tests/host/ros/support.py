"""What the ROS tests share: whether the live rclpy tests can run here, and why not."""

from __future__ import annotations

import functools


@functools.cache
def live_ros_unavailable() -> str | None:
    """None if rclpy and the bridge's messages import and a context starts here; else the reason."""
    try:
        import rclpy  # noqa: F401
        from diagnostic_msgs.msg import DiagnosticArray  # noqa: F401
        from sensor_msgs.msg import Temperature  # noqa: F401
        from std_srvs.srv import Trigger  # noqa: F401
    except Exception as e:  # ImportError, or a wheel whose native libraries are missing
        return f"ROS 2 wheels not usable here ({type(e).__name__}: {e}); pip install 'thermotouch[ros]' on x86-64"
    try:
        ctx = rclpy.Context()
        rclpy.init(context=ctx)
        rclpy.shutdown(context=ctx)
    except Exception as e:
        return f"rclpy cannot start a context ({type(e).__name__}: {e})"
    return None


#: The ROS tests, by kind: the serialisation tests always run (rosbags is in the dev extra).
SERIALISATION_TESTS = ("test_ros_bag.py",)
LIVE_TESTS = ("test_ros_live.py",)
