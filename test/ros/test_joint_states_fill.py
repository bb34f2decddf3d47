"""joint_states from one kept message (``ros/messages.JointStates``): filled again each cycle,
it must carry exactly what a message of its own would (ROS ``sensor_msgs/JointState``: the
names, positions and velocities of the joints published, in one order, under the stamp), also
when the set of published joints changes from one cycle to the next."""

from __future__ import annotations

import math

from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from ssi_bridge.core.cycle import CycleResult, JointCycle
from ssi_bridge.core.joint import Joint, JointOutput
from ssi_bridge.protocol.settings import JointSettings
from ssi_bridge.ros.messages import JointStates, joint_state_msg, time_msg

JOINTS = [Joint(JointSettings(name=f"j{s}", slot=s), velocity_window=5, max_speed=-1.0,
                stale_cycles=5) for s in (1, 2, 3)]


def _cycle(k: int, published: tuple[bool, ...]) -> CycleResult:
    """Cycle ``k``: the joints flagged in ``published`` with an output, the others set aside."""
    result = CycleResult(k, k * 0.001)
    for joint, on in zip(JOINTS, published):
        out = JointOutput(0.1 * k + joint.slot, math.nan if k % 3 == 0 else -0.5 * k)
        result.joints.append(JointCycle(joint, out if on else None, None,
                                        "" if on else "no answer", b""))
    return result


def _fields(msg: JointState) -> tuple:
    """Every field of a JointState as it goes on the wire (the arrays bit for bit: NaN too),
    read back from its serialization (its padding bytes are not defined: not compared)."""
    back = deserialize_message(serialize_message(msg), JointState)
    return ((back.header.stamp.sec, back.header.stamp.nanosec), back.header.frame_id,
            list(back.name), bytes(back.position), bytes(back.velocity), bytes(back.effort))


def test_the_kept_message_carries_each_cycle_as_a_message_of_its_own() -> None:
    states = JointStates()
    kept = None
    patterns = [(True, True, True)] * 3 + [(True, False, True), (True, False, True),
                                           (False, False, False), (True, True, True),
                                           (False, True, False), (True, True, True)]
    for k, published in enumerate(patterns, start=1):
        result = _cycle(k, published)
        stamp_ns = 1_700_000_000_123_456_789 + k * 1_000_000
        frame_id = "base" if k < 5 else "world"
        got = states.fill(result, stamp_ns, frame_id)
        want = joint_state_msg(result, time_msg(stamp_ns), frame_id)
        assert kept is None or got is kept, "one message, filled again"
        kept = got
        assert list(got.name) == [j.name for j, on in zip(JOINTS, published) if on]
        assert (got.header.stamp.sec, got.header.stamp.nanosec) == divmod(stamp_ns, 10**9)
        assert _fields(got) == _fields(want), k  # what a new message of the cycle carries
