"""Run-time parameter changes of the node: checked together, applied together, each an event.

:class:`RuntimeParameters` is the node's parameter part (``ros/node.py`` owns it and hands
rclpy's set-parameters callback and its ``set_parameters`` overrides to it).
Changeable at run time: ``publish_rate``, ``diagnostics_period``, ``frame_id``,
``velocity_window``, ``stale_cycles`` and per joint ``para1`` (through the one REG_PARA1 path,
:meth:`~ssi_bridge.core.bridge.Bridge.change_para1`, refused with the module's ERR_PARA reason)
and ``max_speed``; every other parameter is read-only in its descriptor. Every change or
refusal is an ``~/events`` record.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Protocol

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.timer import Timer

from ssi_bridge.core.bridge import Bridge
from ssi_bridge.core.joint import Joint
from ssi_bridge.exceptions import SsiBridgeError
from ssi_bridge.ros.node_ports import CycleLoop
from ssi_bridge.ros.params import NodeSettings

#: parameters that change at run time (every other one is read-only in its descriptor)
LIVE_NODE_PARAMETERS = ("publish_rate", "diagnostics_period", "frame_id", "velocity_window",
                        "stale_cycles")
LIVE_JOINT_PARAMETERS = ("para1", "max_speed")

#: records what a user did and how it ended: (kind, joint, request, success, message)
LogEvent = Callable[[str, str, str, bool, str], None]


class Tunable(Protocol):
    """What a run-time change reaches: the node's settings, its cycle, its diagnostics timer."""

    #: the node's settings; a change replaces them (a frozen dataclass)
    settings: NodeSettings

    @property
    def cycle(self) -> CycleLoop | None:
        """The cycle loop while active (None: the next activate takes the new rate)."""

    @property
    def diag_timer(self) -> Timer:
        """The diagnostics timer (exists once the first configure made the ROS side)."""


def _short(value: object, limit: int = 80) -> str:
    """A parameter value for an event, truncated (a value may be huge)."""
    text = f"0x{value:08X}" if isinstance(value, int) and not isinstance(value, bool) \
        and value > 0xFFFF else repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


class RuntimeParameters:
    """The node's parameter part (see the module docstring).

    :param node: the node whose parameters these are (``get_parameter``, ``set_parameters``)
    :param joints: the joints' cores by name (the node's own mapping)
    :param bridge: the one REG_PARA1 path (``change_para1``) and its lock
    :param target: what a change of a node-wide parameter reaches
    """

    def __init__(self, node: Node, joints: Mapping[str, Joint], bridge: Bridge,
                 target: Tunable) -> None:
        self._node = node
        self._joints = joints
        self._bridge = bridge
        self._target = target
        self._mirror = threading.local()  # .active: a parameter set mirroring the module
        self._log_event: LogEvent | None = None

    def attach_events(self, log_event: LogEvent) -> None:
        """Record every later change and refusal with ``log_event`` (the ``~/events`` of the
        services, which exist from the first configure on; none are recorded before)."""
        self._log_event = log_event

    def mirror_para1(self, joint: str, value: int) -> None:
        """The module holds ``value``: ``<joint>.para1`` follows (no write, no second event)."""
        if self._node.get_parameter(f"{joint}.para1").value == value:
            return
        self._mirror.active = True
        try:
            self._node.set_parameters([Parameter(f"{joint}.para1", value=value)])
        finally:
            self._mirror.active = False

    def on_set(self, params: list[Parameter]) -> SetParametersResult:
        """rclpy's set-parameters callback: runtime changes (LIVE_*_PARAMETERS) checked
        together, then applied together; a refusal names the parameter and the reason."""
        joints = self._joints
        node_values: dict[str, object] = {}
        para1: dict[str, int] = {}
        max_speed: dict[str, float] = {}
        for p in params:
            joint, _, key = p.name.partition(".")
            if p.name in LIVE_NODE_PARAMETERS:
                node_values[p.name] = p.value
            elif joint in joints and key == "para1":
                para1[joint] = int(p.value)
            elif joint in joints and key == "max_speed":
                value = float(p.value)
                if not (value >= 0 or value == -1):
                    return SetParametersResult(
                        successful=False, reason=f"{p.name} {value}: >= 0 (0: off) or -1 "
                        "(the encoder family's limit)")
                max_speed[joint] = value
        if getattr(self._mirror, "active", False):
            return SetParametersResult(successful=True)  # the mirror of the module's value
        for joint, value in para1.items():
            if value == joints[joint].para1:
                continue
            try:
                self._bridge.change_para1(joint, value, "parameter")
            except SsiBridgeError as err:
                return SetParametersResult(successful=False,
                                           reason=f"{joint}.para1 0x{value:08X}: {err}")
        for joint, value in max_speed.items():
            joints[joint].set_max_speed(value)
        if node_values:
            self._apply_node_parameters(node_values)
        return SetParametersResult(successful=True)

    def _apply_node_parameters(self, values: dict[str, object]) -> None:
        """publish_rate, diagnostics_period, frame_id, velocity_window, stale_cycles."""
        target = self._target
        # each value has its field's type: rclpy checked it against the parameter's descriptor
        target.settings = dataclasses.replace(target.settings, **values)  # type: ignore[arg-type]
        s = target.settings
        if "publish_rate" in values and target.cycle is not None:
            target.cycle.period = 1.0 / float(s.publish_rate)
        if "diagnostics_period" in values:
            target.diag_timer.timer_period_ns = int(1e9 * float(s.diagnostics_period))
            target.diag_timer.reset()
        if "velocity_window" in values:
            with self._bridge.para1_lock:
                for joint in self._joints.values():
                    joint.set_velocity_window(int(s.velocity_window))
        if "stale_cycles" in values:
            for joint in self._joints.values():
                joint.stale_cycles = int(s.stale_cycles)

    def set_atomically(self, parameter_list: list[Parameter],
                       set_all: Callable[[list[Parameter]], SetParametersResult]
                       ) -> SetParametersResult:
        """``set_all`` (rclpy's ``set_parameters_atomically``), plus an ~/events record of
        the change or the refusal; raises what ``set_all`` raises (recorded too)."""
        try:
            result = set_all(parameter_list)
        except Exception as err:
            self._parameter_event(parameter_list, False, f"{type(err).__name__}: {err}")
            raise
        self._parameter_event(parameter_list, result.successful, result.reason)
        return result

    def set_each(self, parameter_list: list[Parameter],
                 set_some: Callable[[list[Parameter]], list[SetParametersResult]]
                 ) -> list[SetParametersResult]:
        """``set_some`` (rclpy's ``set_parameters``) one parameter at a time, plus an
        ~/events record of each change or refusal."""
        results: list[SetParametersResult] = []
        for param in parameter_list:
            results.extend(set_some([param]))
            self._parameter_event([param], results[-1].successful, results[-1].reason)
        return results

    def _parameter_event(self, params: Sequence[Parameter], success: bool, reason: str) -> None:
        log_event = self._log_event
        if getattr(self._mirror, "active", False) or log_event is None:
            return  # the mirror of a register write (its own event) or during start-up
        request = ", ".join(f"{p.name}={_short(p.value)}" for p in params)
        log_event("set_parameters", "", request, success,
                  "applied" if success else f"refused: {reason}")


__all__ = ["LIVE_JOINT_PARAMETERS", "LIVE_NODE_PARAMETERS", "LogEvent", "RuntimeParameters",
           "Tunable"]
