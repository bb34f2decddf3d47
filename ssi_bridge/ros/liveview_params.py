"""The node's parameters in the live view: Foxglove's Parameters panel gets, sets and watches them.

Names are the node's fully qualified name, a dot and the parameter's name
(``/ssi_bridge.publish_rate``), as foxglove_bridge names a ROS 2 node's parameters; a bare
``publish_rate`` is accepted too. A get with no names lists every declared parameter.

A set goes through the node's own ``set_parameters``: rclpy's checks (read-only, type,
range from the descriptor) and then the node's callbacks (``ros/node_params.py``: the
REG_PARA1 gate, max_speed's rule, the ``~/events`` record), exactly as ``ros2 param set``. The
Foxglove protocol answers a set only with the values the parameters now hold, so a refusal
is also sent to the clients as a warning status: ``<name>: refused: <reason>`` (the reason
``ros2 param set`` prints). A value given as a whole number for a floating-point parameter
(JSON has one number type) is taken as that float.

Every change, whichever way it came (ROS service, live view, the mirror of a REG_PARA1 write),
is published to the clients that subscribed to that parameter.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, TypeGuard

from rclpy.node import Node
from rclpy.parameter import Parameter

if TYPE_CHECKING:  # the SDK is imported only when the live view starts
    import foxglove
    from foxglove.websocket import WebSocketServer

#: separator between the node's name and a parameter's name (foxglove_bridge's)
SEPARATOR = "."


def to_foxglove(name: str, param: Parameter) -> foxglove.Parameter:
    """A ``foxglove.Parameter`` named ``name`` holding rclpy parameter ``param``'s value."""
    import foxglove

    kind, value = param.type_, param.value
    if kind == Parameter.Type.NOT_SET:
        return foxglove.Parameter(name)
    if kind == Parameter.Type.DOUBLE:
        return foxglove.Parameter(name, value=float(value), type=foxglove.ParameterType.Float64)
    if kind == Parameter.Type.DOUBLE_ARRAY:
        return foxglove.Parameter(name, value=[float(v) for v in value],
                                  type=foxglove.ParameterType.Float64Array)
    if kind == Parameter.Type.BYTE_ARRAY:
        return foxglove.Parameter(name, value=bytes(b[0] if isinstance(b, bytes) else b
                                                    for b in value))
    if kind in (Parameter.Type.INTEGER_ARRAY, Parameter.Type.BOOL_ARRAY,
                Parameter.Type.STRING_ARRAY):
        return foxglove.Parameter(name, value=list(value))
    return foxglove.Parameter(name, value=value)


def to_rclpy(name: str, value: object, declared: Parameter.Type) -> Parameter:
    """The rclpy ``Parameter`` ``name`` = ``value``, a whole number taken as the float a
    DOUBLE (array) parameter ``declared`` holds; any other type is left for rclpy to refuse."""
    def whole(v: object) -> TypeGuard[int]:
        return isinstance(v, int) and not isinstance(v, bool)

    if declared == Parameter.Type.DOUBLE and whole(value):
        value = float(value)
    elif declared == Parameter.Type.DOUBLE_ARRAY and isinstance(value, list):
        value = [float(v) if whole(v) else v for v in value]
    return Parameter(name, value=value)


class ParameterBridge:
    """Get, set and subscribe for the live view's listener (see the module docstring).

    :param node: the node whose parameters are offered; its ``set_parameters`` is the one
        path of a change
    """

    def __init__(self, node: Node) -> None:
        self._node = node
        self._prefix = node.get_fully_qualified_name() + SEPARATOR
        self._lock = threading.Lock()
        self._set_lock = threading.Lock()
        #: names (live view spelling) some client subscribed to
        self.subscribed: set[str] = set()
        #: set once the server runs (status and value updates)
        self.server: WebSocketServer | None = None
        node.add_post_set_parameters_callback(self._on_changed)

    def _local(self, name: str) -> str:
        return name[len(self._prefix):] if name.startswith(self._prefix) else name

    def _view(self, name: str) -> str:
        return self._prefix + name

    def get(self, names: list[str]) -> list[foxglove.Parameter]:
        """The named parameters (every declared one if ``names`` is empty); unknown names
        are left out, as the protocol asks."""
        node = self._node
        local = [self._local(n) for n in names] or sorted(node.list_parameters([], 0).names)
        return [to_foxglove(self._view(n), node.get_parameter(n))
                for n in local if node.has_parameter(n)]

    def set(self, params: list[foxglove.Parameter]) -> list[foxglove.Parameter]:
        """Set each through ``node.set_parameters``; the values they hold afterwards.

        A refusal (rclpy's or the node's) is sent to every client as a warning status.
        """
        node = self._node
        refusals: list[str] = []
        names: list[str] = []
        with self._set_lock:  # two clients' sets one after the other, as the ROS service's
            for param in params:
                self._set_one(node, param, refusals, names)
        for text in refusals:
            self._node.get_logger().warning(f"live view: set parameters: {text}")
            self._status(text)
        return self.get(names)

    def _set_one(self, node: Node, param: foxglove.Parameter, refusals: list[str],
                 names: list[str]) -> None:
        """Set one parameter; its refusal text appended to ``refusals``."""
        from rclpy.exceptions import ParameterException

        name = self._local(param.name)
        if not node.has_parameter(name):
            refusals.append(f"{param.name}: refused: not a parameter of "
                            f"{node.get_fully_qualified_name()}")
            return
        names.append(param.name)
        declared = node.get_parameter(name).type_
        try:
            result = node.set_parameters([to_rclpy(name, param.get_value(), declared)])[0]
            ok, reason = result.successful, result.reason
        except (ParameterException, TypeError, ValueError) as err:
            ok, reason = False, f"{type(err).__name__}: {err}"
        if not ok:
            refusals.append(f"{self._view(name)}: refused: {reason}")

    def _status(self, text: str) -> None:
        import foxglove

        if self.server is not None:
            self.server.publish_status(text, foxglove.StatusLevel.Warning)

    def subscribe(self, names: list[str]) -> None:
        """Remember what some client watches (no names: every declared parameter)."""
        if not names:
            names = [self._view(n) for n in self._node.list_parameters([], 0).names]
        with self._lock:
            self.subscribed.update(names)

    def unsubscribe(self, names: list[str]) -> None:
        with self._lock:
            self.subscribed.difference_update(names)

    def _on_changed(self, params: list[Parameter]) -> None:
        """rclpy's post-set callback: send the new values to the clients subscribed to them,
        whichever way the change came."""
        if self.server is None:
            return
        with self._lock:
            watched = [p for p in params if self._view(p.name) in self.subscribed]
        if watched:
            try:
                self.server.publish_parameter_values(
                    [to_foxglove(self._view(p.name), p) for p in watched])
            except Exception as err:  # noqa: BLE001 - never fail a parameter change
                self._node.get_logger().debug(f"live view: parameter update not sent: {err}")

    def stop(self) -> None:
        """No more updates (the server is going)."""
        self.server = None
        try:
            self._node.remove_post_set_parameters_callback(self._on_changed)
        except (ValueError, AttributeError):
            pass


__all__ = ["ParameterBridge", "SEPARATOR", "to_foxglove", "to_rclpy"]
