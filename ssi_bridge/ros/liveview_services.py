"""The node's services in the live view: Foxglove's Service Call panel reaches the same handlers.

Every service the node registers (:attr:`BridgeServices.offered <ssi_bridge.ros.services.
BridgeServices.offered>`, so a service added there appears here too) is advertised on the
Foxglove WebSocket server under its resolved ROS name (``/ssi_bridge/read_register``) and its
``pkg/srv/Type``, with the request and response schemas as foxglove_bridge gives them: the two
halves of the installed ``.srv`` file as ``ros2msg`` text (``pkg/srv/Type_Request`` /
``_Response``, each followed by its dependencies as rosbag2 lays them out), message encoding
``cdr``.

A call is decoded with rclpy's ``deserialize_message``, queued in the node's one
:class:`~ssi_bridge.ros.request_queue.RequestQueue` behind the ROS calls (so live-view and ROS
calls stay serialised, and the busy limit counts both), served by the same handler (the same
validation, refusal messages and ``~/events`` record) and answered with
``serialize_message`` of the filled response. A payload that does not decode, or a node that
stops before answering, is a Foxglove "service call failure" with the reason.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ssi_bridge.exceptions import RecordingError

#: seconds a live-view call waits for its answer (handlers answer within their handshake
#: timeouts; this only bounds a call the queue never serves, e.g. at shutdown)
CALL_TIMEOUT_S = 60.0


@dataclass(frozen=True)
class ServiceDefinition:
    """The ``ros2msg`` schemas of one service type (``pkg/srv/Type``)."""

    name: str
    request: str
    response: str


def srv_type_name(srv_type: type[Any]) -> str:
    """``pkg/srv/Type`` of an rclpy service class (its module is ``pkg.srv._type``)."""
    return f"{srv_type.__module__.split('.', 1)[0]}/srv/{srv_type.__name__}"


def _with_dependencies(pkg: str, text: str) -> str:
    """``text`` followed by every message type it uses, as rosbag2 lays out a schema."""
    from ssi_bridge.record.schema import with_dependencies

    return with_dependencies(pkg, text)


@functools.lru_cache(maxsize=None)
def build_service_definition(type_name: str) -> ServiceDefinition:
    """The request and response schemas of ``pkg/srv/Type`` from its installed ``.srv`` file.

    :raises RecordingError: the package or its ``.srv`` file is not installed, or the file
        has no ``---`` line between request and response
    """
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    pkg, kind, name = (type_name.split("/") + ["", ""])[:3]
    if kind != "srv" or not pkg or not name:
        raise RecordingError(f"service type {type_name!r}: expected 'pkg/srv/Type'")
    try:
        path = Path(get_package_share_directory(pkg)) / "srv" / f"{name}.srv"
        text = path.read_text(encoding="utf-8")
    except (PackageNotFoundError, LookupError, ValueError, OSError) as err:
        raise RecordingError(f"service definition {type_name} not installed: {err}") from err
    lines = text.splitlines(keepends=True)
    cut = next((i for i, line in enumerate(lines) if line.strip() == "---"), None)
    if cut is None:
        raise RecordingError(f"service definition {path}: no '---' line")
    return ServiceDefinition(type_name, _with_dependencies(pkg, "".join(lines[:cut])),
                             _with_dependencies(pkg, "".join(lines[cut + 1:])))


class ServiceBridge:
    """The live view's services: one Foxglove ``Service`` per service of the node.

    :param handlers: the node's :class:`~ssi_bridge.ros.services.BridgeServices` (its
        ``offered`` list, ``queue`` and busy ``refuser``)
    :param log: the node's logger (a service that cannot be offered is logged, not fatal)
    """

    def __init__(self, handlers: Any, log: Any) -> None:
        self._handlers = handlers
        self._log = log
        #: resolved names of the services advertised
        self.names: list[str] = []

    def services(self) -> list[Any]:
        """The ``foxglove.Service`` objects to hand to ``start_server``."""
        import foxglove

        out = []
        for srv_type, name, handler in self._handlers.offered:
            try:
                definition = build_service_definition(srv_type_name(srv_type))
            except RecordingError as err:
                self._log.error(f"live view: service {name} not offered: {err}")
                continue
            schema = foxglove.ServiceSchema(
                definition.name,
                request=foxglove.MessageSchema(encoding="cdr", schema=foxglove.Schema(
                    name=f"{definition.name}_Request", encoding="ros2msg",
                    data=definition.request.encode("utf-8"))),
                response=foxglove.MessageSchema(encoding="cdr", schema=foxglove.Schema(
                    name=f"{definition.name}_Response", encoding="ros2msg",
                    data=definition.response.encode("utf-8"))))
            out.append(foxglove.Service(name, schema=schema,
                                        handler=self._caller(srv_type, name, handler)))
            self.names.append(name)
        return out

    def _caller(self, srv_type: type[Any], name: str,
                handler: Callable[[Any, Any], Any]) -> Callable[[Any], bytes]:
        """The Foxglove handler of one service: decode, queue, serve, encode.

        Runs on the SDK's thread for this call; it blocks until the queue's worker served
        the request. Raises ``ValueError`` (a service call failure with that text) for a
        payload that does not decode, an encoding other than cdr, or no answer.
        """
        from rclpy.serialization import deserialize_message, serialize_message

        kind = name.rsplit("/", 1)[-1]
        refuse = self._handlers.refuser(kind)

        def call(request: Any) -> bytes:
            if request.encoding != "cdr":
                raise ValueError(f"{kind}: encoding {request.encoding!r}: only cdr is served")
            try:
                ros_request = deserialize_message(bytes(request.payload), srv_type.Request)
            except Exception as err:  # noqa: BLE001 - rclpy raises several kinds
                raise ValueError(f"{kind}: request does not decode as "
                                 f"{srv_type_name(srv_type)}_Request: {err}") from None
            response = srv_type.Response()
            if not self._handlers.queue.call(handler, ros_request, response, refuse,
                                             CALL_TIMEOUT_S):
                raise ValueError(f"{kind}: not answered (the node is stopping or the call "
                                 f"waited more than {CALL_TIMEOUT_S:g} s)")
            return bytes(serialize_message(response))
        return call


__all__ = ["CALL_TIMEOUT_S", "ServiceBridge", "ServiceDefinition", "build_service_definition",
           "srv_type_name"]
