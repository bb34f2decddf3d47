"""Live view: an optional Foxglove WebSocket server streaming the node's topics.

A user without a ROS install (the ``make run`` set-up has no ``ros2`` CLI) opens Foxglove and
connects to ``ws://localhost:<foxglove.port>``. Every topic the node publishes becomes one
channel with the ``ros2msg`` schema rosbag2 would store (record/schema.py) and clean CDR
payloads (record/cdr.py), so Foxglove decodes it as it decodes a live ROS 2 robot.

Like the recorder, the sink is fed right after each ``publish``. A message is serialized only
while a client is subscribed to its channel (the SDK's ``has_sinks``), so the default
(``foxglove.port`` 0: no server, not even the SDK imported) and an idle server cost one
dictionary or attribute lookup per message. The server binds to ``foxglove.address``
(default 127.0.0.1): a client on another host finds no listening socket unless the address
says otherwise. The SDK and record/'s schema and CDR code are imported only when the server
starts, as the recorder imports record/ only when a session starts. A server that cannot
start (port in use, bad address) is logged and shown on the bus diagnostics; the bridge keeps
publishing.

Besides the topics the server offers the node's services (``ros/liveview_services.py``: the
same handlers and request queue as the ROS services) and its parameters
(``ros/liveview_params.py``: get, set through the node's own checks, subscribe), so
Foxglove's Service Call and Parameters panels work as with foxglove_bridge;
``foxglove.services`` / ``foxglove.parameters`` false leave either out (a view that only
watches).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

from rclpy.node import Node
from rclpy.publisher import Publisher

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.ros.params import NodeSettings

if TYPE_CHECKING:  # the SDK is imported only when the server starts
    import foxglove
    from foxglove.websocket import ChannelView, Client, ServerListener, WebSocketServer

    from ssi_bridge.ros.liveview_params import ParameterBridge
    from ssi_bridge.ros.services import BridgeServices

#: addresses that keep the server on this host
LOOPBACK = ("127.0.0.1", "::1", "localhost")


def type_name(msg_class: object) -> str:
    """``pkg/msg/Type`` of an rclpy message class (its module is ``pkg.msg._type``)."""
    assert isinstance(msg_class, type), f"{msg_class!r} is no message class"
    return f"{msg_class.__module__.split('.', 1)[0]}/msg/{msg_class.__name__}"


class _Subscriptions:
    """Foxglove ServerListener: counts subscriptions and logs who watches what."""

    def __init__(self, node: Node) -> None:
        self._node = node
        self._lock = threading.Lock()
        self.count = 0

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        with self._lock:
            self.count += 1
        self._node.get_logger().info(f"live view: client {client.id} subscribed to "
                                     f"{channel.topic}")

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        with self._lock:
            self.count = max(0, self.count - 1)
        self._node.get_logger().info(f"live view: client {client.id} left {channel.topic}")

    # the parameter requests (Capability.Parameters only): ros/liveview_params.py
    params: ParameterBridge | None = None

    def on_get_parameters(self, client: Client, param_names: list[str],
                          request_id: str | None = None) -> list[foxglove.Parameter]:
        return self.params.get(param_names) if self.params is not None else []

    def on_set_parameters(self, client: Client, parameters: list[foxglove.Parameter],
                          request_id: str | None = None) -> list[foxglove.Parameter]:
        return self.params.set(parameters) if self.params is not None else []

    def on_parameters_subscribe(self, param_names: list[str]) -> None:
        if self.params is not None:
            self.params.subscribe(param_names)

    def on_parameters_unsubscribe(self, param_names: list[str]) -> None:
        if self.params is not None:
            self.params.unsubscribe(param_names)


class LiveView:
    """The Foxglove WebSocket server of one node and a channel per offered publisher.

    A server that cannot start is no error: :attr:`error` says why (the bus diagnostics show
    it) and every method goes on as if the port were 0.

    :param node: the node whose name the server carries and whose parameters it offers
    :param settings: ``foxglove.*`` (port 0: no server, the SDK not imported)
    :param handlers: the node's services, offered with the same handlers and request queue
        (None, or ``foxglove.services`` false: none)
    """

    def __init__(self, node: Node, settings: NodeSettings,
                 handlers: BridgeServices | None = None) -> None:
        self._node = node
        self._handlers = handlers if settings.foxglove_services else None
        self._with_parameters = settings.foxglove_parameters
        #: resolved names of the services the server offers
        self.services: list[str] = []
        self._channels: dict[Publisher, foxglove.Channel] = {}
        self._server: WebSocketServer | None = None
        self._context: foxglove.Context | None = None
        self._listener = _Subscriptions(node)
        self._serialize: Callable[[Any], bytes] | None = None  # a message: untyped
        #: why the server is not running although asked for; shown on the bus diagnostics
        self.error = ""
        self.port = 0
        if settings.foxglove_port:
            self._start(settings.foxglove_address, settings.foxglove_port)

    @property
    def running(self) -> bool:
        """True while the WebSocket server listens."""
        return self._server is not None

    def _start(self, address: str, port: int) -> None:
        import foxglove

        from foxglove.websocket import Capability

        from ssi_bridge.record.cdr import serialize
        from ssi_bridge.ros.liveview_params import ParameterBridge
        from ssi_bridge.ros.liveview_services import ServiceBridge

        self._serialize = serialize
        where = f"{address}:{port}"
        capabilities, services = [], []
        if self._handlers is not None:
            bridge = ServiceBridge(self._handlers, self._node.get_logger())
            services = bridge.services()
            self.services = bridge.names
            capabilities.append(Capability.Services)
        if self._with_parameters:
            self._listener.params = ParameterBridge(self._node)
            capabilities.append(Capability.Parameters)
        # the listener is a ServerListener by its methods (no SDK import before the start)
        try:
            self._context = foxglove.Context()
            self._server = foxglove.start_server(
                name=self._node.get_fully_qualified_name(), host=address, port=port,
                context=self._context, server_listener=cast("ServerListener", self._listener),
                capabilities=capabilities, supported_encodings=["cdr"], services=services)
        except (RuntimeError, ValueError, OSError) as err:
            reason = str(err).removeprefix("FoxgloveError: ")
            self.error = f"live view off: cannot listen on {where}: {reason}"
            self._node.get_logger().error(f"foxglove.port/foxglove.address: {self.error}")
            self._stop_parameters()
            return
        if self._listener.params is not None:
            self._listener.params.server = self._server
        self.port = int(self._server.port)
        url_host = "localhost" if address in LOOPBACK else address
        can = ["read every topic"] + (["call every service"] if services else []) + (
            ["set parameters"] if self._with_parameters else [])
        scope = ("this host only" if address in LOOPBACK else
                 f"reachable from other hosts: anyone who can reach it can {', '.join(can)}")
        offered = (f"{len(services)} services" if services else "no services") + (
            ", parameters" if self._with_parameters else ", no parameters")
        self._node.get_logger().info(
            f"live view: Foxglove WebSocket server on ws://{url_host}:{self.port} ({scope}); "
            f"topics, {offered}")

    def _stop_parameters(self) -> None:
        params, self._listener.params = self._listener.params, None
        if params is not None:
            params.stop()

    def offer(self, publisher: Publisher) -> None:
        """Advertise ``publisher``'s topic with its ros2msg schema (no-op while off)."""
        if self._context is None:
            return
        import foxglove

        from ssi_bridge.record.schema import build_schema

        name = type_name(publisher.msg_type)
        try:
            schema = build_schema(name)
        except RecordingError as err:
            self._node.get_logger().error(f"live view: {publisher.topic_name} not offered: {err}")
            return
        # keyed by the publisher object: its topic_name is a call into rcl every time
        self._channels[publisher] = foxglove.Channel(
            publisher.topic_name, message_encoding="cdr", context=self._context,
            schema=foxglove.Schema(name=schema.name, encoding="ros2msg",
                                   data=schema.text.encode("utf-8")))

    def wants(self, publisher: Publisher) -> bool:
        """True while a client is subscribed to ``publisher``'s topic."""
        channel = self._channels.get(publisher)
        return channel is not None and channel.has_sinks()

    def publish(self, publisher: Publisher, msg: Any) -> None:
        """Send ``msg`` (just published on ``publisher``) to the subscribed clients, if any."""
        channel = self._channels.get(publisher)
        if channel is None or not channel.has_sinks() or self._serialize is None:
            return
        # no log_time: the SDK stamps the receive time itself (system clock, as ROS time is
        # here), which saves an rclpy clock call per message (docs/node.md "Live view")
        channel.log(self._serialize(msg))

    def counters(self) -> dict[str, int]:
        """Live view figures for the bus diagnostics."""
        return {"liveview_port": self.port, "liveview_subscriptions": self._listener.count}

    def stop(self) -> None:
        """Close the channels and the server; safe to call twice."""
        server, self._server = self._server, None
        channels, self._channels = self._channels, {}
        for channel in channels.values():
            channel.close()
        self._stop_parameters()
        if server is not None:
            server.stop()


__all__ = ["LiveView", "type_name"]
