"""Subscriber process of the node benchmark (node_measure.py): receive time and header.stamp.

Usage: ``python bench/node_subscriber.py TOPIC OUT_FILE READY_FILE``

Subscribes to ``TOPIC`` (sensor_msgs/JointState) with the QoS the node publishes with
(KEEP_LAST 10, RELIABLE, VOLATILE). For each message it keeps the receive wall time
(``time.time_ns()``, the clock ROS stamps use) and ``header.stamp`` in ns. On the first
message it writes READY_FILE (the receive time, ns) so the benchmark can start its warm-up.
On SIGINT/SIGTERM it writes OUT_FILE: one line per message, "<receive_ns> <stamp_ns>", and
exits 0. The callback does nothing else, so the subscriber is the same light sink for the
node and for the bare publisher it is compared against.
"""

from __future__ import annotations

import os
import sys
import time


def main(argv: list[str]) -> int:
    topic, out_path, ready_path = argv[1], argv[2], argv[3]

    import rclpy
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from ssi_bridge.tools.spin import spin_until_shutdown

    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    recv: list[int] = []
    stamps: list[int] = []
    now_ns = time.time_ns

    def on_msg(msg: JointState) -> None:
        t = now_ns()
        s = msg.header.stamp
        if not recv:
            tmp = ready_path + ".tmp"
            with open(tmp, "w") as f:
                f.write(str(t))
            os.replace(tmp, ready_path)
        recv.append(t)
        stamps.append(s.sec * 1_000_000_000 + s.nanosec)

    rclpy.init(args=None)
    node = rclpy.create_node(f"bench_sub_{os.getpid()}")
    node.create_subscription(JointState, topic, on_msg, qos)

    def write_out() -> None:
        tmp = out_path + ".tmp"
        with open(tmp, "w") as f:
            f.write("".join(f"{r} {s}\n" for r, s in zip(recv, stamps)))
        os.replace(tmp, out_path)

    spin_until_shutdown(node, on_exit=write_out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
