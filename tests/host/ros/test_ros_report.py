"""Says how many ROS tests run here, so none is skipped silently (the summary shows it as a warning).

The serialisation tests never skip (rosbags is in the dev extra: a missing rosbags fails here); the
live tests run where the ROS 2 wheels work. ``THERMOTOUCH_REQUIRE_ROS_LIVE=1`` makes a skipped live
test a failure (for a machine that should run them).
"""

from __future__ import annotations

import ast
import os
import warnings
from pathlib import Path

from tests.host.ros.support import LIVE_TESTS, SERIALISATION_TESTS, live_ros_unavailable

HERE = Path(__file__).parent


def _count_tests(name: str) -> int:
    tree = ast.parse((HERE / name).read_text())
    return sum(isinstance(n, ast.FunctionDef) and n.name.startswith("test_") for n in tree.body)


def test_report_how_many_ros_tests_run_here():
    import rosbags  # noqa: F401 - the serialisation tests need it; its absence is a failure, not a skip

    n_ser = sum(_count_tests(f) for f in SERIALISATION_TESTS)
    n_live = sum(_count_tests(f) for f in LIVE_TESTS)
    assert n_ser >= 4 and n_live >= 1
    why = live_ros_unavailable()
    ran = n_ser + (0 if why else n_live)
    line = (f"ROS tests: {ran} of {n_ser + n_live} run here ({n_ser} rosbag2 serialisation, "
            f"{0 if why else n_live} live rclpy" + (f"; {n_live} live skipped: {why})" if why else ")"))
    warnings.warn(line, UserWarning, stacklevel=1)
    print(line)
    if why and os.environ.get("THERMOTOUCH_REQUIRE_ROS_LIVE") == "1":
        raise AssertionError(line)


def test_the_launch_file_and_parameters_name_the_node_s_parameters():
    from host.ros.node import PARAMETERS

    root = HERE.parents[2] / "host" / "ros"
    launch = (root / "launch" / "thermotouch.launch.py").read_text()
    ast.parse(launch)
    assert "host.ros.node" in launch and "thermotouch.params.yaml" in launch
    params = {}
    for line in (root / "config" / "thermotouch.params.yaml").read_text().splitlines():
        body = line.split("#")[0].strip()
        if ":" in body and line.startswith("    "):
            key, value = body.split(":", 1)
            params[key.strip()] = value.strip()
    assert set(params) == set(PARAMETERS)
