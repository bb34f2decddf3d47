"""The live view: the node's Foxglove WebSocket server, seen by a WebSocket client.

The client here speaks the Foxglove WebSocket protocol itself (JSON ``serverInfo`` /
``advertise`` / ``subscribe``, binary message data: opcode 0x01, subscription id u32 LE, log
time u64 LE, payload) and decodes payloads only with the schema the server advertised, parsed
by mcap_ros2's dynamic ``ros2msg`` decoder: what Foxglove does with a live ROS 2 robot.
foxglove-sdk 0.30 selects the subprotocol ``foxglove.sdk.v1`` (the successor of
``foxglove.websocket.v1`` with the same messages); the client offers both.
"""

from __future__ import annotations

import asyncio
import json
import math
import socket
import struct
import time
from dataclasses import dataclass, field
from typing import Any

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import ReadRegister

from support.liveview import free_port

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
#: binary server message "Message Data": opcode, subscription id, log time (ns)
MESSAGE_DATA = struct.Struct("<BIQ")
OP_MESSAGE_DATA = 0x01


def non_loopback_address() -> str | None:
    """This host's primary non-loopback IPv4 address (the source of its default route)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("192.0.2.123", 9))  # UDP connect sends nothing; it only picks a route
        except OSError:
            return None
        addr = s.getsockname()[0]
    return None if addr.startswith("127.") or addr == "0.0.0.0" else addr


@dataclass
class Received:
    """One decoded message: channel topic, log time (ns), receive time, decoded object."""

    topic: str
    log_time: int
    at: float
    msg: Any


@dataclass
class FoxgloveClient:
    """A minimal Foxglove WebSocket client decoding with the advertised ros2msg schemas."""

    url: str
    channels: dict[str, dict] = field(default_factory=dict)
    server_info: dict = field(default_factory=dict)
    subprotocol: str = ""

    async def run(self, topics: list[str], until: Any, timeout: float,
                  on_subscribed: Any = None) -> list[Received]:
        """Subscribe to ``topics``; collect decoded messages until ``until(received)``."""
        import websockets
        from mcap.records import Schema
        from mcap_ros2.decoder import DecoderFactory

        received: list[Received] = []
        decoders: dict[int, tuple[str, Any]] = {}
        async with websockets.connect(self.url, subprotocols=SUBPROTOCOLS,
                                      open_timeout=timeout, max_size=None) as ws:
            self.subprotocol = ws.subprotocol or ""
            deadline = time.monotonic() + timeout
            while not all(t in self.channels for t in topics):
                frame = await asyncio.wait_for(ws.recv(), deadline - time.monotonic())
                msg = json.loads(frame)
                if msg["op"] == "serverInfo":
                    self.server_info = msg
                elif msg["op"] == "advertise":
                    self.channels.update({c["topic"]: c for c in msg["channels"]})
            subs = []
            for sub_id, topic in enumerate(topics, start=1):
                ch = self.channels[topic]
                assert ch["encoding"] == "cdr" and ch["schemaEncoding"] == "ros2msg", ch
                schema = Schema(id=ch["id"], name=ch["schemaName"], encoding="ros2msg",
                                data=ch["schema"].encode())
                decoders[sub_id] = (topic, DecoderFactory().decoder_for("cdr", schema))
                subs.append({"id": sub_id, "channelId": ch["id"]})
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            if on_subscribed is not None:
                await asyncio.to_thread(on_subscribed)
            while not until(received):
                frame = await asyncio.wait_for(ws.recv(), deadline - time.monotonic())
                if isinstance(frame, str) or frame[0] != OP_MESSAGE_DATA:
                    continue
                _, sub_id, log_time = MESSAGE_DATA.unpack_from(frame)
                topic, decode = decoders[sub_id]
                received.append(Received(topic, log_time, time.monotonic(),
                                         decode(frame[MESSAGE_DATA.size:])))
        return received


def stream(port: int, topics: list[str], until: Any, timeout: float = 20.0,
           host: str = "127.0.0.1", on_subscribed: Any = None
           ) -> tuple[FoxgloveClient, list[Received]]:
    client = FoxgloveClient(f"ws://{host}:{port}")
    return client, asyncio.run(client.run(topics, until, timeout, on_subscribed))


def stamp_ns(header: Any) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def test_every_topic_is_streamed_and_joint_states_decode_with_the_advertised_schema(running,
                                                                                    probe):
    """One node with the live view on: every topic streamed with its schema and the
    subscriptions counted in the bus diagnostics, then joint_states of two joints decoded at
    the published rate, the same messages as over DDS. (Two tests before, each on a node of
    its own: the default one and ``lift``/``tilt`` at 100 Hz; one node of the latter now,
    so the ~/status channels are ``lift``/``tilt`` instead of ``joint1``; every check kept.)"""
    port = free_port()
    node = running({"publish_rate": 100.0, "foxglove.port": port, "joints": ["lift", "tilt"]})
    over_dds = probe.subscribe(JointState, node.topic("joint_states"), qos=500)
    topics = ["/joint_states", node.topic("~/status"), "/diagnostics", node.topic("~/events")]

    def trigger_event() -> None:
        reply = probe.call(ReadRegister, node.topic("~/read_register"),
                           ReadRegister.Request(address=34))
        assert reply.success, reply.message

    def one_of_each(rx: list[Received]) -> bool:
        return {r.topic for r in rx} == set(topics) and any(
            kv.key == "liveview_subscriptions" and int(kv.value) == 4
            for r in rx if r.topic == "/diagnostics" for s in r.msg.status for kv in s.values)

    client, rx = stream(port, topics, one_of_each, on_subscribed=trigger_event)

    assert {t: client.channels[t]["schemaName"] for t in topics} == {
        "/joint_states": "sensor_msgs/msg/JointState",
        node.topic("~/status"): "ssi_bridge_msgs/msg/Status",
        "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
        node.topic("~/events"): "ssi_bridge_msgs/msg/Event"}
    status = next(r.msg for r in rx if r.topic == node.topic("~/status"))
    assert [c.joint for c in status.channels] == ["lift", "tilt"]
    event = next(r.msg for r in rx if r.topic == node.topic("~/events"))
    assert event.kind == "read_register" and event.success
    bus = next(s for r in rx if r.topic == "/diagnostics" for s in r.msg.status
               if s.name == "/ssi_bridge: bus")
    assert dict((kv.key, kv.value) for kv in bus.values)["liveview_port"] == str(port)

    def one_second_after_first(rx: list[Received]) -> bool:
        return bool(rx) and rx[-1].at - rx[0].at >= 1.0

    client, rx = stream(port, ["/joint_states"], one_second_after_first)

    assert client.subprotocol in SUBPROTOCOLS
    ch = client.channels["/joint_states"]
    assert ch["schemaName"] == "sensor_msgs/msg/JointState"
    # rosbag2's layout: the type's .msg text, then each dependency after a line of '='
    assert "MSG: std_msgs/Header" in ch["schema"] and "MSG: builtin_interfaces/Time" in ch["schema"]
    first_second = [r for r in rx if r.at - rx[0].at <= 1.0]
    assert len(first_second) >= 50, f"{len(first_second)} joint_states in 1 s at 100 Hz"
    stamps = [stamp_ns(r.msg.header) for r in rx]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    for r in rx:
        assert list(r.msg.name) == ["lift", "tilt"]
        assert all(math.isfinite(p) for p in r.msg.position)
    # the same messages as over DDS: equal content for equal stamps (the SSI latch time)
    probe.wait_for(lambda: any(stamp_ns(m.header) >= stamps[-1] for _, m in over_dds), 10.0,
                   "the DDS copy of the last streamed message", node)
    by_stamp = {stamp_ns(m.header): m for _, m in over_dds}
    common = [r for r in rx if stamp_ns(r.msg.header) in by_stamp]
    assert len(common) >= len(rx) - 5, "DDS and the live view carry the same cycles"
    for r in common:
        dds = by_stamp[stamp_ns(r.msg.header)]
        assert list(r.msg.position) == list(dds.position)
        assert [v if math.isfinite(v) else None for v in r.msg.velocity] == \
               [v if math.isfinite(v) else None for v in dds.velocity]


def test_default_address_refuses_clients_of_other_hosts(start_node, probe):
    """Bound to 127.0.0.1, the server has no socket on the host's network address.

    A client on another host reaches this host only through one of its non-loopback
    addresses, so connecting to that address from here is what such a client's connection
    meets: the kernel finds no listener and answers with a reset (ECONNREFUSED). The same
    connection succeeds once ``foxglove.address`` is 0.0.0.0, so the refusal is the bind
    address at work, not a firewall or a route that would also stop an allowed client.
    """
    addr = non_loopback_address()
    if addr is None:
        pytest.skip("this host has no non-loopback IPv4 address to connect through")
    local_port, open_port = free_port(), free_port()
    local = start_node({"foxglove.port": local_port})
    seen = probe.subscribe(JointState, local.topic("joint_states"))
    probe.wait_for(lambda: len(seen) > 0, 30.0, "joint_states of the local-only node", local)

    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((addr, local_port), timeout=5.0).close()
    client, rx = stream(local_port, ["/joint_states"], lambda rx: len(rx) >= 1)
    assert rx, "a client on this host (127.0.0.1) is served"
    local.stop()

    opened = start_node({"foxglove.port": open_port, "foxglove.address": "0.0.0.0"})
    seen.clear()
    probe.wait_for(lambda: len(seen) > 0, 30.0, "joint_states of the open node", opened)
    client, rx = stream(open_port, ["/joint_states"], lambda rx: len(rx) >= 1, host=addr)
    assert list(rx[0].msg.name) == ["joint1"]
    assert "reachable from other hosts" in opened.log()


def test_a_port_in_use_is_reported_and_the_bridge_keeps_publishing(running, probe):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        node = running({"foxglove.port": port})
        diags = probe.subscribe(DiagnosticArray, "/diagnostics")
        probe.wait_for(lambda: any(s.name == "/ssi_bridge: bus" and s.level == DiagnosticStatus.ERROR
                                   for _, d in diags for s in d.status), 10.0,
                       "the bus diagnostics ERROR naming the live view", node)
    bus = next(s for _, d in diags for s in d.status if s.name == "/ssi_bridge: bus")
    assert "live view off" in bus.message and str(port) in bus.message
    assert "Address already in use" in node.log()
    seen = probe.subscribe(JointState, node.topic("joint_states"))
    probe.wait_for(lambda: len(seen) > 20, 10.0, "joint_states still flowing", node)
