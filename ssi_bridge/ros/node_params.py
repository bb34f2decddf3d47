"""Run-time parameter changes of the node: checked together, applied together, each an event.

:class:`RuntimeParameters` is a part of :class:`~ssi_bridge.ros.node.SsiBridgeNode` (a mixin).
Changeable at run time: ``publish_rate``, ``diagnostics_period``, ``frame_id``,
``velocity_window``, ``stale_cycles`` and per joint ``para1`` (through the one REG_PARA1 path,
:meth:`~ssi_bridge.core.bridge.Bridge.change_para1`, refused with the module's ERR_PARA reason)
and ``max_speed``; every other parameter is read-only in its descriptor. Every change or
refusal is an ``~/events`` record.
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter

from ssi_bridge.exceptions import SsiBridgeError

#: parameters that change at run time (every other one is read-only in its descriptor)
LIVE_NODE_PARAMETERS = ("publish_rate", "diagnostics_period", "frame_id", "velocity_window",
                        "stale_cycles")
LIVE_JOINT_PARAMETERS = ("para1", "max_speed")


def _short(value: Any, limit: int = 80) -> str:
    """A parameter value for an event, truncated (a value may be huge)."""
    text = f"0x{value:08X}" if isinstance(value, int) and not isinstance(value, bool) \
        and value > 0xFFFF else repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


class RuntimeParameters:
    """The parameter part of the node (see the module docstring)."""

    # provided by the node
    settings: Any
    joints: dict
    bridge: Any
    cycle: Any
    diag_timer: Any
    _mirror: threading.local

    def mirror_para1(self, joint: str, value: int) -> None:
        """The module holds ``value``: ``<joint>.para1`` follows (no write, no second event)."""
        if self.get_parameter(f"{joint}.para1").value == value:  # type: ignore[attr-defined]
            return
        self._mirror.active = True
        try:
            self.set_parameters([Parameter(f"{joint}.para1", value=value)])
        finally:
            self._mirror.active = False

    def _on_set_parameters(self, params: list) -> SetParametersResult:
        """Runtime changes (LIVE_*_PARAMETERS): checked together, then applied together."""
        node_values: dict[str, Any] = {}
        para1: dict[str, int] = {}
        max_speed: dict[str, float] = {}
        for p in params:
            joint, _, key = p.name.partition(".")
            if p.name in LIVE_NODE_PARAMETERS:
                node_values[p.name] = p.value
            elif joint in self.joints and key == "para1":
                para1[joint] = int(p.value)
            elif joint in self.joints and key == "max_speed":
                value = float(p.value)
                if not (value >= 0 or value == -1):
                    return SetParametersResult(
                        successful=False, reason=f"{p.name} {value}: >= 0 (0: off) or -1 "
                        "(the encoder family's limit)")
                max_speed[joint] = value
        if getattr(self._mirror, "active", False):
            return SetParametersResult(successful=True)  # the mirror of the module's value
        for joint, value in para1.items():
            if value == self.joints[joint].para1:
                continue
            try:
                self.bridge.change_para1(joint, value, "parameter")
            except SsiBridgeError as err:
                return SetParametersResult(successful=False,
                                           reason=f"{joint}.para1 0x{value:08X}: {err}")
        for joint, value in max_speed.items():
            self.joints[joint].set_max_speed(value)
        if node_values:
            self._apply_node_parameters(node_values)
        return SetParametersResult(successful=True)

    def _apply_node_parameters(self, values: dict[str, Any]) -> None:
        """publish_rate, diagnostics_period, frame_id, velocity_window, stale_cycles."""
        self.settings = dataclasses.replace(self.settings, **values)
        if "publish_rate" in values:
            self.cycle.period = 1.0 / float(values["publish_rate"])
        if "diagnostics_period" in values:
            self.diag_timer.timer_period_ns = int(1e9 * float(values["diagnostics_period"]))
            self.diag_timer.reset()
        if "velocity_window" in values:
            with self.bridge.para1_lock:
                for joint in self.joints.values():
                    joint.set_velocity_window(int(values["velocity_window"]))
        if "stale_cycles" in values:
            for joint in self.joints.values():
                joint.stale_cycles = int(values["stale_cycles"])

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """rclpy's, plus an ~/events record of the change or the refusal."""
        try:
            result = super().set_parameters_atomically(parameter_list)  # type: ignore[misc]
        except Exception as err:
            self._parameter_event(parameter_list, False, f"{type(err).__name__}: {err}")
            raise
        self._parameter_event(parameter_list, result.successful, result.reason)
        return result

    def set_parameters(self, parameter_list: list[Parameter]) -> list[SetParametersResult]:
        """rclpy's, plus an ~/events record of each change or refusal."""
        results = []
        for param in parameter_list:
            results.extend(super().set_parameters([param]))  # type: ignore[misc]
            self._parameter_event([param], results[-1].successful, results[-1].reason)
        return results

    def _parameter_event(self, params: list[Parameter], success: bool, reason: str) -> None:
        if getattr(self._mirror, "active", False) or not hasattr(self, "handlers"):
            return  # the mirror of a register write (its own event) or during start-up
        request = ", ".join(f"{p.name}={_short(p.value)}" for p in params)
        self.handlers.log_event("set_parameters", "", request, success,  # type: ignore
                                "applied" if success else f"refused: {reason}")


__all__ = ["LIVE_JOINT_PARAMETERS", "LIVE_NODE_PARAMETERS", "RuntimeParameters"]
