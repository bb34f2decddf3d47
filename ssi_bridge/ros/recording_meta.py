"""What a bag of the node says about itself: each topic's message type and the session's
metadata (package version, bus, stations, joints); and the node's bus, which the recording's
listeners open beside the master.

Shared by the session recorder (``ros/recording.py``) and the fault snapshots
(``ros/snapshot.py``): a snapshot is a bag like a session's.
"""

from __future__ import annotations

from ssi_bridge import __version__
from ssi_bridge.exceptions import RecordingError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.ros.params import NodeSettings

#: type of every topic the node records, by the suffix of its resolved name
TOPIC_TYPES = {
    "joint_states": "sensor_msgs/msg/JointState",
    "status": "ssi_bridge_msgs/msg/Status",
    "events": "ssi_bridge_msgs/msg/Event",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


def type_of(topic: str) -> str:
    """The message type (``pkg/msg/Type``) of a resolved topic the node records.

    :raises RecordingError: the topic is none of :data:`TOPIC_TYPES`
    """
    for suffix, type_name in TOPIC_TYPES.items():
        if topic == suffix or topic.endswith("/" + suffix.lstrip("/")):
            return type_name
    raise RecordingError(f"no message type known for topic {topic}")


def session_metadata(s: NodeSettings) -> dict[str, str]:
    """The bag's metadata: package version, bus, stations, mode, rate, CAN log, each joint."""
    meta = {"package_version": __version__, "bus": f"{s.bus_interface}:{s.bus_channel}",
            "bus_bitrate": str(s.bus_bitrate), "node_id": str(s.node_id),
            "stations": ",".join(str(i) for i in s.station_ids),
            "simulation": str(s.simulation), "publish_rate": f"{s.publish_rate:g}",
            "can_log": "can_0.log" if s.record_can_log else ""}
    for j in s.joints:
        meta[f"joint.{j.name}"] = (f"station={j.station or s.node_id} slot={j.slot} "
                                   f"family={j.family} "
                                   f"para1=0x{j.para1:08X}")
    return meta


def bus_config(s: NodeSettings) -> BusConfig:
    """The node's bus (its master's; a recording's listeners open one of their own)."""
    return BusConfig(interface=s.bus_interface, channel=s.bus_channel,
                     bitrate=s.bus_bitrate, node_id=s.node_id)


__all__ = ["TOPIC_TYPES", "bus_config", "session_metadata", "type_of"]
