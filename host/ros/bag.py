"""A touch's ROS 2 messages to a rosbag2 and back, through ``rosbags`` (pure Python, no ROS install).

::

    with Probe.connect(port) as probe:
        record_touch(probe, "touch.bag", contact_time_s=2.0)
    for topic, stamp_ns, msg in read_bag("touch.bag"):
        ...
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

from host.api import Measurement, Probe
from host.ros.bridge import TOPICS, Bridge, rosbags_messages

__all__ = ["record_touch", "read_bag", "typestore"]


def typestore() -> Any:
    """The message definitions bags are written with (ROS 2 Jazzy's; these messages are alike in all)."""
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415 - an optional dependency

    return get_typestore(Stores.ROS2_JAZZY)


def record_touch(probe: Probe, path: str | Path, *, diagnostics: bool = True, **measure_kw: Any) -> Measurement:
    """Run one streamed touch and write what the bridge publishes for it to a new rosbag2 at ``path``.

    Returns the touch's answer. ``path`` must not exist (rosbags refuses to overwrite a bag).
    """
    from rosbags.rosbag2 import Writer  # noqa: PLC0415

    ts = typestore()
    out: list[tuple[str, Any, int]] = []
    bridge = Bridge(probe, rosbags_messages(ts), lambda name, msg, stamp: out.append((name, msg, stamp)))
    if diagnostics:
        bridge.diagnostics()
    answer = bridge.touch(**measure_kw)
    with Writer(Path(path), version=8) as writer:
        conns: dict[str, Any] = {}
        for name, msg, stamp in out:
            topic, msgtype = TOPICS[name]
            if name not in conns:
                conns[name] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[name], stamp, ts.serialize_cdr(msg, msgtype))
    return answer


def read_bag(path: str | Path) -> Iterator[tuple[str, int, Any]]:
    """``(topic, stamp_ns, message)`` of every message in a rosbag2, in time order."""
    from rosbags.rosbag2 import Reader  # noqa: PLC0415

    ts = typestore()
    with Reader(Path(path)) as reader:
        for conn, stamp, raw in reader.messages():
            yield conn.topic, stamp, ts.deserialize_cdr(raw, conn.msgtype)
