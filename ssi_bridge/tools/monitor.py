"""``ros2 run ssi_bridge monitor``: watch a running bridge in the terminal, once a second.

Prints, for the node's namespace, the joints of joint_states (position, velocity and the
level of their ``ssi_bridge: <joint>`` diagnostics) and the bus status with its cycle rate
and, when the bridge reports one, its bus load. Needs no ROS install beyond this package's
set-up: it is a plain rclpy subscriber.

/diagnostics is one topic for every node; the statuses belong to this bridge when they are
named after its joints, and the bus status is the one whose hardware_id names the same CAN
channel and gateway node as those joints' statuses.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any

#: DiagnosticStatus levels (diagnostic_msgs/DiagnosticStatus)
LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
#: seconds after the monitor starts during which a node not (yet) in the graph is "waiting for
#: discovery", not "not found": DDS discovery of a running node takes ~1-3 s
DISCOVERY_S = 5.0

DESCRIPTION = """\
Print what a running ssi_bridge node publishes, once a second: every joint's position and
velocity (rad and rad/s, or m and m/s for linear encoders), the level of its diagnostics,
and the bus status with the achieved cycle rate and the bus load when the bridge reports it.
For its first 5 s it says "waiting for discovery" while the node is not seen yet; after that,
a node that is still not seen is reported as not found. Stop it with Ctrl-C.

examples:
  monitor                                   the node /ssi_bridge
  monitor --namespace station_a             a node started with namespace station_a
  make monitor ARGS="--namespace station_a" the same through make
"""


def level_name(level: Any) -> str:
    """OK / WARN / ERROR / STALE of a DiagnosticStatus level (rclpy gives it as bytes)."""
    value = level[0] if isinstance(level, (bytes, bytearray)) else int(level)
    return LEVELS.get(value, str(value))


def _fmt(value: float) -> str:
    return f"{'nan':>12}" if math.isnan(value) else f"{value:12.4f}"


@dataclass
class MonitorState:
    """What has been heard since the start and since the last report."""

    #: the node's fully qualified name: its statuses are ``<node FQN>: <joint>`` and ``: bus``
    node_fqn: str = "/ssi_bridge"
    joint_states: Any = None
    received: int = 0
    statuses: dict[str, Any] = field(default_factory=dict)

    def on_joint_states(self, msg: Any) -> None:
        """Keep the newest ``joint_states`` message ``msg`` (a subscription callback)."""
        self.joint_states = msg
        self.received += 1

    def on_diagnostics(self, msg: Any) -> None:
        """Keep the newest status of each name in the DiagnosticArray ``msg``."""
        for status in msg.status:
            self.statuses[status.name] = status

    def bus_status(self, joints: list[str]) -> Any:
        """The ``<node FQN>: bus`` status of the gateway the joints' statuses name."""
        prefixes = {s.hardware_id.split(" slot ", 1)[0] for j in joints
                    if (s := self.statuses.get(f"{self.node_fqn}: {j}")) is not None}
        bus = self.statuses.get(f"{self.node_fqn}: bus")
        if bus is None or (prefixes and not any(bus.hardware_id.startswith(p + " ")
                                                for p in prefixes)):
            return None
        return bus

    def report(self, node: str, topic: str, elapsed: float, node_seen: bool = True,
               waited: float = DISCOVERY_S) -> list[str]:
        """The lines of one report about ``node``; resets the message count.

        ``waited``: seconds since the monitor started; before :data:`DISCOVERY_S` a node not
        seen yet is still being discovered.

        :param topic: the joint_states topic watched
        :param elapsed: seconds since the last report
        :param node_seen: the node is in the ROS graph
        """
        rate = self.received / elapsed if elapsed > 0 else 0.0
        self.received = 0
        js = self.joint_states
        if js is None:
            why = ("it is up, no message yet" if node_seen else
                   f"waiting for discovery, {waited:.0f} of {DISCOVERY_S:g} s"
                   if waited < DISCOVERY_S else
                   f"node {node} not found after {waited:.0f} s: is it running, in this "
                   "ROS_DOMAIN_ID?")
            return [f"waiting for {topic} ({why})"]
        joints = list(js.name)
        lines = [f"{time.strftime('%H:%M:%S')} {node}: {topic} {rate:.1f} msg/s",
                 f"  {'joint':<16} {'position':>12} {'velocity':>12}  diagnostics",
                 f"  {'':<16} {'rad (m)':>12} {'rad/s (m/s)':>12}"]
        for i, name in enumerate(joints):
            pos = js.position[i] if i < len(js.position) else math.nan
            vel = js.velocity[i] if i < len(js.velocity) else math.nan
            status = self.statuses.get(f"{self.node_fqn}: {name}")
            diag = (f"{level_name(status.level):<5} {status.message}" if status is not None
                    else "(no diagnostics yet)")
            lines.append(f"  {name:<16} {_fmt(pos)} {_fmt(vel)}  {diag}")
        bus = self.bus_status(joints)
        if bus is None:
            lines.append("  bus: (no diagnostics yet)")
        else:
            values = {kv.key: kv.value for kv in bus.values}
            load = [f"{k} {v}" for k, v in values.items() if "load" in k.lower()]
            lines.append(f"  bus: {level_name(bus.level)} {bus.message}"
                         + (f"; {', '.join(load)}" if load else ""))
        return lines


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface of monitor."""
    parser = argparse.ArgumentParser(prog="monitor", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--namespace", "-n", default="",
                        help="namespace the node runs in (default: none)")
    parser.add_argument("--node", default="ssi_bridge", metavar="NAME",
                        help="name of the node (default ssi_bridge)")
    parser.add_argument("--period", type=float, default=1.0, metavar="S",
                        help="seconds between reports (default 1)")
    parser.add_argument("--count", type=int, default=0, metavar="N",
                        help="exit after N reports (default 0: run until Ctrl-C)")
    return parser


def joint_states_topic(namespace: str) -> str:
    """The node's joint_states, which it publishes relative to its namespace."""
    ns = namespace.strip("/")
    return f"/{ns}/joint_states" if ns else "/joint_states"


def node_seen(node: Any, name: str, namespace: str) -> bool:
    """True if the discovery graph has the node ``namespace``/``name``."""
    ns = "/" + namespace.strip("/")
    return (name, ns) in node.get_node_names_and_namespaces()


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``monitor`` executable: a running bridge's joints and diagnostics
    in the terminal, once per ``--period``.

    :param argv: the command line without the program name (default: ``sys.argv[1:]``);
        ``--ros-args`` and what follows go to rclpy
    :returns: the exit code: 0 on Ctrl-C or after ``--count`` reports; 2 bad options
    """
    args_in = sys.argv[1:] if argv is None else argv
    ros_args = args_in[args_in.index("--ros-args"):] if "--ros-args" in args_in else []
    args = build_parser().parse_args(args_in[:len(args_in) - len(ros_args)])
    if args.period <= 0:
        print("monitor: --period must be > 0", file=sys.stderr)
        return 2
    try:
        return _run(args, ros_args)
    except KeyboardInterrupt:
        return 0  # Ctrl-C before rclpy's own handler was installed


def _run(args: argparse.Namespace, ros_args: list[str]) -> int:
    """Subscribe, report every ``args.period`` s until Ctrl-C or ``args.count`` reports."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    from ssi_bridge.tools.spin import spin_until_shutdown

    rclpy.init(args=["monitor", *ros_args])
    node = rclpy.create_node("ssi_bridge_monitor", start_parameter_services=False)
    topic = joint_states_topic(args.namespace)
    fqn = f"/{args.namespace.strip('/')}/{args.node}".replace("//", "/")
    state = MonitorState(node_fqn=fqn)
    node.create_subscription(JointState, topic, state.on_joint_states, 10)
    node.create_subscription(DiagnosticArray, "/diagnostics", state.on_diagnostics, 10)
    reports = [0]
    last = [time.monotonic()]
    started = last[0]

    def tick() -> None:
        now = time.monotonic()
        seen = state.joint_states is not None or node_seen(node, args.node, args.namespace)
        print("\n".join(state.report(fqn, topic, now - last[0], seen, now - started)),
              flush=True)
        last[0] = now
        reports[0] += 1
        if args.count and reports[0] >= args.count:
            rclpy.try_shutdown()

    node.create_timer(args.period, tick)
    spin_until_shutdown(node)
    return 0


if __name__ == "__main__":
    sys.exit(main())
