"""Launch the ThermoTouch bridge node with its parameters file.

    ros2 launch host/ros/launch/thermotouch.launch.py port:=/dev/ttyACM0

The node is ``python -m host.ros.node`` (the package installs with pip, not colcon); its
parameters are config/thermotouch.params.yaml, ``port`` overridable on the command line.
"""

from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.substitutions import LaunchConfiguration

PARAMS = Path(__file__).resolve().parent.parent / "config" / "thermotouch.params.yaml"


def generate_launch_description() -> LaunchDescription:
    port = LaunchConfiguration("port")
    return LaunchDescription([
        DeclareLaunchArgument("port", default_value="/dev/ttyACM0", description="the probe's serial port"),
        ExecuteProcess(
            cmd=["python3", "-m", "host.ros.node", "--ros-args", "--params-file", str(PARAMS),
                 "-p", ["port:=", port]],
            output="screen", name="thermotouch"),
    ])
