"""Fixtures of the record/ tests: sample messages, a written bag, readers that assert."""

from __future__ import annotations

from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from ssi_bridge.record.bag import BagRecorder
from ssi_bridge_msgs.msg import ChannelStatus, Event, Status

from ..conftest import log_time_disorder

T0 = 1_700_000_000_000_000_000
JOINTS = ("axis_1", "axis_2")


def joint_state(i: int) -> JointState:
    """Sample i of a two-joint session at 1 kHz: positions ramp, velocities constant."""
    msg = JointState(name=list(JOINTS), position=[0.001 * i, -0.002 * i], velocity=[1.0, -2.0])
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(T0 + i * 1_000_000, 1_000_000_000)
    msg.header.frame_id = "station"
    return msg


def status(i: int) -> Status:
    """Status with two channels whose counters and image bytes change with i."""
    msg = Status(channels=[ChannelStatus(joint=j, slot=k, samples=i, reg_ssi_pos=i - 5 * k,
                                         process_input=[(i + b) % 256 for b in range(8)],
                                         sts_up=bool(i % 2))
                           for k, j in enumerate(JOINTS)])
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(T0 + i * 1_000_000, 1_000_000_000)
    return msg


def diagnostics(i: int) -> DiagnosticArray:
    """One DiagnosticStatus per joint; level cycles OK, WARN, ERROR."""
    return DiagnosticArray(status=[
        DiagnosticStatus(level=bytes([(i // 10) % 3]), name=f"ssi_bridge: {j}",
                         hardware_id="vcan0/1/0", values=[KeyValue(key="rate", value=str(i))])
        for j in JOINTS])


def event(i: int) -> Event:
    """A preset event that succeeded."""
    msg = Event(kind="set_preset", joint=JOINTS[0], request=f"position: {i}", success=True,
                message="ok")
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(T0 + i * 1_000_000, 1_000_000_000)
    return msg


TOPICS = {
    "/joint_states": ("sensor_msgs/msg/JointState", joint_state, 1),
    "/ssi_bridge/status": ("ssi_bridge_msgs/msg/Status", status, 1),
    "/diagnostics": ("diagnostic_msgs/msg/DiagnosticArray", diagnostics, 10),
    "/ssi_bridge/events": ("ssi_bridge_msgs/msg/Event", event, 250),
}


def joint_states_bag(path: Path, n: int, topics: tuple[str, ...] = ("/joint_states",),
                     period_ns: int = 10_000_000) -> Path:
    """A closed bag at ``path`` of ``n`` JointStates ``period_ns`` apart on each of ``topics``
    (reliable, depth 50); message i is :func:`joint_state` (i) at T0 + i periods. Returns its
    directory."""
    rec = BagRecorder.open(path)
    for topic in topics:
        rec.add_topic(topic, "sensor_msgs/msg/JointState",
                      QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    for i in range(n):
        for topic in topics:
            rec.write(topic, joint_state(i), T0 + i * period_ns)
    return rec.close().directory


def write_session(directory: Path, n: int, compression: str = "zstd") -> Path:
    """Record n cycles (1 ms apart) of every topic in TOPICS; return the bag directory."""
    rec = BagRecorder.open(directory, compression=compression,
                           metadata={"encoder_families": "axis_1: TR CE58M"})
    for topic, (type_name, _, _) in TOPICS.items():
        rec.add_topic(topic, type_name)
    for i in range(n):
        for topic, (_, make, every) in TOPICS.items():
            if i % every == 0:
                rec.write(topic, make(i), T0 + i * 1_000_000, T0 + i * 1_000_000 - 1000)
    rec.close()
    return directory


@pytest.fixture(scope="session")
def session_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A closed 2 s bag of the four topics (shared, read-only), in log-time order."""
    bag = write_session(tmp_path_factory.mktemp("bags") / "session", 2000)
    assert not log_time_disorder(bag)
    return bag
