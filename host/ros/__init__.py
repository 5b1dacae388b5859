"""ROS 2 for ThermoTouch (``pip install 'thermotouch[ros]'``): the bridge node and its message mapping.

:mod:`host.ros.bridge` maps answers, running answers, samples and device state to standard ROS 2
messages (no ROS needed: the same code serialises through ``rosbags``); :mod:`host.ros.bag`
records a touch to a rosbag2; :mod:`host.ros.node` is the rclpy node (``launch/thermotouch.launch.py``,
``config/thermotouch.params.yaml``). docs/ros.md describes topics, service and parameters.
"""
