"""The node benchmark's two baselines, each a program of its own (this file, run by the
benchmark with :func:`bare_cmd` or :func:`floor_cmd`), publishing the node's JointState.

* the **bare** publisher (``--bare``): an rclpy timer publishing an equally sized JointState
  (same joint names, position and velocity arrays) at the case rate, stamped the instant
  before ``publish()``: what publishing costs any rclpy node.
* the **floor** publisher (``--floor``): another process (``--floor-sender``) sends a datagram
  stamped with its send time at the case rate; a thread of an rclpy node, woken by it at the
  node's receive-thread priority (:data:`FLOOR_PRIORITY`), publishes the same JointState
  stamped with that send time at once. That is the least any rclpy node adds that publishes
  data it receives from a device (its receive thread's wake-up, nothing else): the bridge's
  latency beyond the wire cannot be below it. Given a span file it writes its span per
  message as the node's span probe does (``ssi_bridge/ros/span_probe.py``).

Both use the bridge's QoS (KEEP_LAST 10, RELIABLE, VOLATILE) and run until SIGINT.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from node_cases import case_rate
from node_procs import die_with_parent

BARE_TOPIC = "/bench_bare/joint_states"
FLOOR_TOPIC = "/bench_floor/joint_states"
#: the floor's receive thread runs at the node's default cycle_priority, which the node's CAN
#: receive thread takes too
FLOOR_PRIORITY = 5
#: Linux's SO_TIMESTAMPNS (Python's socket module may not name it)
SO_TIMESTAMPNS = 35
PROGRAM = Path(__file__).resolve()


def bare_cmd(n_joints: int) -> list[str]:
    """The bare publisher's command line for the ``n_joints`` case, on :data:`BARE_TOPIC`."""
    return [sys.executable, str(PROGRAM), "--bare", str(n_joints),
            str(case_rate(n_joints)), BARE_TOPIC]


def floor_cmd(n_joints: int, spans: Path | None = None) -> list[str]:
    """The floor publisher's command line for the ``n_joints`` case, on :data:`FLOOR_TOPIC`;
    ``spans``: the file it writes its spans to."""
    return [sys.executable, str(PROGRAM), "--floor", str(n_joints),
            str(case_rate(n_joints)), FLOOR_TOPIC] + ([str(spans)] if spans else [])


def _joint_state_publisher(kind: str, topic: str) -> tuple[Any, Any]:
    """rclpy started, a node ``bench_<kind>_<pid>`` and its JointState publisher on ``topic``
    with the bridge's QoS."""
    import rclpy
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    rclpy.init(args=None)
    node = rclpy.create_node(f"bench_{kind}_{os.getpid()}")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    return node, node.create_publisher(JointState, topic, qos)


def _joint_state(names: list[str], count: int, sec: int, nanosec: int) -> Any:
    """The benchmark's JointState: ``names``, a position that moves with ``count``, a speed."""
    from sensor_msgs.msg import JointState

    js = JointState()
    js.header.stamp.sec, js.header.stamp.nanosec = sec, nanosec
    js.name = names
    js.position = [count * 1e-3] * len(names)
    js.velocity = [1.0] * len(names)
    return js


def bare_publisher(n_joints: int, rate: float, topic: str) -> int:
    """A bare rclpy timer publishing an N-joint JointState at ``rate``; runs until SIGINT."""
    from ssi_bridge.tools.spin import spin_until_shutdown

    node, pub = _joint_state_publisher("bare", topic)
    names = [f"j{i + 1}" for i in range(n_joints)]
    clock = node.get_clock()
    count = [0]

    def tick() -> None:
        count[0] += 1
        sec, nanosec = clock.now().seconds_nanoseconds()
        pub.publish(_joint_state(names, count[0], sec, nanosec))

    node.create_timer(1.0 / rate, tick)
    spin_until_shutdown(node)
    return 0


def floor_sender(port: int, rate: float) -> int:
    """Send a datagram holding ``time.time_ns()`` to 127.0.0.1:``port`` ``rate`` times a
    second (started with :func:`die_with_parent`: it ends with the floor publisher)."""
    import socket
    import struct

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    period, due = 1.0 / rate, time.monotonic()
    while True:
        due += period
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        sock.sendto(struct.pack("<q", time.time_ns()), ("127.0.0.1", port))


def _kernel_receive(sock: Any) -> tuple[bytes, int]:
    """One datagram of ``sock`` (SO_TIMESTAMPNS on) and its kernel receive time (ns, 0: none),
    as the node's udp_multicast bus receives each frame."""
    import socket
    import struct

    data, ancillary, _, _ = sock.recvmsg(64, socket.CMSG_SPACE(16))
    for level, kind, raw in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(raw) >= 16:
            sec, nsec = struct.unpack("@ll", raw[:16])
            return data, sec * 1_000_000_000 + nsec
    return data, 0


def floor_publisher(n_joints: int, rate: float, topic: str, span_log: str = "") -> int:
    """The least any rclpy node that publishes what it receives adds to the bare publisher.

    Another process sends a datagram stamped with its send time ``rate`` times a second (as a
    station's last TPDO reaches the node); a thread of this node, blocked on the socket at
    ``FLOOR_PRIORITY`` as the node's CAN receive thread is, wakes and publishes an N-joint
    JointState stamped with that send time at once: no simulation, no CAN decoding, no
    hand-off to another thread, nothing computed. Runs until SIGINT.

    ``span_log``: a file that gets the floor's span per message as the node's span probe
    writes it (``ssi_bridge/ros/span_probe.py``): the datagram's kernel receive time
    (``SO_TIMESTAMPNS``, read with ``recvmsg`` as the node's bus reads its frames) and the
    instant ``publish()`` returned.
    """
    import socket
    import struct
    import threading

    from ssi_bridge.base.realtime import run_this_thread_at
    from ssi_bridge.ros.span_probe import SpanProbe
    from ssi_bridge.tools.spin import spin_until_shutdown

    node, pub = _joint_state_publisher("floor", topic)
    names = [f"j{i + 1}" for i in range(n_joints)]
    probe = SpanProbe(span_log) if span_log else None
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.bind(("127.0.0.1", 0))
    # die_with_parent: in this process the benchmark's PID is the floor publisher's own PID
    sender = subprocess.Popen([sys.executable, str(PROGRAM), "--floor-sender",
                               str(sock.getsockname()[1]), str(rate)],
                              preexec_fn=die_with_parent)

    def receive() -> None:
        run_this_thread_at("floor_rx", FLOOR_PRIORITY)
        count = 0
        while True:
            data, received_ns = _kernel_receive(sock)
            sent_ns = struct.unpack("<q", data)[0]
            count += 1
            pub.publish(_joint_state(names, count, *divmod(sent_ns, 1_000_000_000)))
            if probe is not None:
                probe.published(received_ns / 1e9, n_joints)

    threading.Thread(target=receive, name="floor_rx", daemon=True).start()
    try:
        spin_until_shutdown(node)
    finally:
        sender.kill()
        sender.wait(5)
    return 0


def main(argv: list[str]) -> int:
    """``--bare N RATE TOPIC``, ``--floor N RATE TOPIC [SPAN_FILE]`` or ``--floor-sender PORT
    RATE``; anything else is a usage error (exit status 2)."""
    if len(argv) == 4 and argv[0] == "--bare":
        return bare_publisher(int(argv[1]), float(argv[2]), argv[3])
    if len(argv) in (4, 5) and argv[0] == "--floor":
        return floor_publisher(int(argv[1]), float(argv[2]), argv[3], *argv[4:])
    if len(argv) == 3 and argv[0] == "--floor-sender":
        return floor_sender(int(argv[1]), float(argv[2]))
    print(f"usage: {PROGRAM.name} --bare N RATE TOPIC | --floor N RATE TOPIC [SPAN_FILE] | "
          "--floor-sender PORT RATE", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
