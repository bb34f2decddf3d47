"""Service handlers of the node: register access, preset, reset, control, fault injection.

Every handler answers within a bounded time (the client's handshake timeouts) and turns every
failure into ``success: false`` with a message naming the joint, the register and the reason;
no exception escapes into the executor. Each call is also recorded as an event.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

from builtin_interfaces.msg import Time
from rclpy.qos import QoSProfile

from ssi_bridge.exceptions import BusError, ConfigError, RegisterError, SsiBridgeError
from ssi_bridge.module.registers import Reg, validate_para1
from ssi_bridge.ros.units import to_int32
from ssi_bridge_msgs.msg import Event
from ssi_bridge_msgs.srv import (
    InjectFault, ReadRegister, ResetRegisters, SetControl, SetPreset, StartRecording,
    StopRecording, WriteRegister,
)

if TYPE_CHECKING:
    from ssi_bridge.ros.node import SsiBridgeNode

MAX_ADDRESS = 63
#: services keep up to 100 pending requests (rclpy's default of 10 drops a burst of calls)
SERVICE_QOS = QoSProfile(depth=100)
#: REG_SF signatures (000 "Resetting the register bank")
SF_LD20 = 0x6C643230
SF_LD48 = 0x6C643438


class BridgeServices:
    """The handlers, bound to a node's client, station and recorder."""

    def __init__(self, node: SsiBridgeNode) -> None:
        self.node = node
        self.events = node.create_publisher(Event, "~/events", 50)
        node.recorder.offer(self.events.topic_name, self.events.qos_profile)

    def register(self, group: Any) -> None:
        """Create every service of the contract in ``group`` (one at a time: a handshake
        per slot is serialised anyway) with a deep request queue."""
        node, rec = self.node, self.node.recorder
        for srv_type, name, handler in (
                (ReadRegister, "~/read_register", self.read_register),
                (WriteRegister, "~/write_register", self.write_register),
                (SetPreset, "~/set_preset", self.set_preset),
                (ResetRegisters, "~/reset_registers", self.reset_registers),
                (SetControl, "~/set_control", self.set_control),
                (InjectFault, "~/inject_fault", self.inject_fault),
                (StartRecording, "~/start_recording", rec.on_start),
                (StopRecording, "~/stop_recording", rec.on_stop)):
            node.create_service(srv_type, name, handler, callback_group=group,
                                qos_profile=SERVICE_QOS)

    # -- helpers ---------------------------------------------------------------------------
    def _joint(self, requested: str) -> str:
        """The joint a request means; an empty name means the first configured joint."""
        names = list(self.node.joints)
        if not requested:
            return names[0]
        if requested not in self.node.joints:
            raise ConfigError(f"unknown joint {requested!r}; configured joints: {', '.join(names)}")
        return requested

    def log_event(self, kind: str, joint: str, request: str, success: bool, message: str) -> None:
        """Publish (and record) what a user did and how it ended."""
        now = self.node.get_clock().now()
        ev = Event(kind=kind, joint=joint, request=request, success=success, message=message)
        ev.header.stamp = Time(sec=now.nanoseconds // 10**9, nanosec=now.nanoseconds % 10**9)
        self.node.publish_safe(self.events, ev)
        self.node.recorder.record(self.events.topic_name, ev, now.nanoseconds)
        text = f"{kind} {joint} {request}: {message}"
        # rclpy ties a severity to each call site, so one call per severity
        if success:
            self.node.get_logger().info(text)
        else:
            self.node.get_logger().warning(text)

    def _run(self, kind: str, request: Any, response: Any, body: Any, describe: str,
             subject: str = "") -> Any:
        """Run ``body(joint)``; fill success/message; record the event; never raise.

        ``subject`` (e.g. "REG_SSI_POS (0)") leads a failure message so that it names the
        register by its manual name, not only by address.
        """
        what = f"{kind} {subject}".rstrip()
        joint = getattr(request, "joint", "")
        try:
            joint = self._joint(joint)
            message = body(joint)
            response.success, response.message = True, message
        except (SsiBridgeError, ValueError) as err:
            if isinstance(err, (BusError, RegisterError)) and joint in self.node.counters:
                self.node.counters[joint].handshake_failures += 1
            response.success, response.message = False, f"{what} on {joint or '?'}: {err}"
        except Exception as err:  # noqa: BLE001 - a service must answer, whatever happened
            self.node.get_logger().error(f"{kind}: unexpected {type(err).__name__}: {err}")
            response.success = False
            response.message = f"{what} on {joint or '?'}: internal error {type(err).__name__}: {err}"
        self.log_event(kind, joint, describe, response.success, response.message)
        return response

    def _slot(self, joint: str) -> int:
        return self.node.joints[joint].slot

    # -- handlers --------------------------------------------------------------------------
    def read_register(self, request: Any, response: Any) -> Any:
        """~/read_register: REG_RD_ADR handshake; REG_RD_ABORT becomes a refusal."""
        def body(joint: str) -> str:
            _check_address(request.address)
            response.value = self.node.client_of(joint).read_register(self._slot(joint),
                                                                      request.address)
            return f"{_reg_name(request.address)} = 0x{response.value:08X} ({response.value})"
        return self._run("read_register", request, response, body,
                         f"address={request.address}", _reg_name(request.address))

    def write_register(self, request: Any, response: Any) -> Any:
        """~/write_register: REG_WR / REG_WR_AKN / REG_WR_ACCEPT handshake."""
        def body(joint: str) -> str:
            _check_address(request.address)
            if request.address == Reg.REG_PARA1:
                reason = validate_para1(request.value)
                if reason:
                    raise ConfigError(f"REG_PARA1 0x{request.value:08X} refused: {reason}")
            self.node.client_of(joint).write_register(self._slot(joint), request.address,
                                                      request.value)
            return f"{_reg_name(request.address)} <- 0x{request.value:08X} accepted"
        return self._run("write_register", request, response, body,
                         f"address={request.address} value=0x{request.value:08X}",
                         _reg_name(request.address))

    def set_preset(self, request: Any, response: Any) -> Any:
        """~/set_preset: REG_OFFSET = encoder - target, so REG_SSI_POS reads the target.

        000 "Offset function": REG_SSI_POS = SSI encoder - REG_OFFSET.
        """
        def body(joint: str) -> str:
            if not math.isfinite(request.position):
                raise ConfigError(f"position {request.position} is not a finite number")
            scale = self.node.scales[joint]
            target = scale.counts(request.position)
            if not -(1 << 31) <= target < (1 << 31):
                raise ConfigError(f"position {request.position} is {target} counts, outside "
                                  "the Integer32 range of REG_SSI_POS")
            client, slot = self.node.client_of(joint), self._slot(joint)
            old_offset = client.read_register(slot, Reg.REG_OFFSET)
            pos = client.read_register(slot, Reg.REG_SSI_POS)
            encoder = (pos + old_offset) & 0xFFFF_FFFF
            offset = (encoder - target) & 0xFFFF_FFFF
            estimator = self.node.velocity[joint]
            # hold the speed while the zero point moves: samples until the read-back may
            # still carry the old offset, so none of them enters the estimate
            estimator.reset(after=math.inf, hold=True)
            try:
                client.write_register(slot, Reg.REG_OFFSET, offset)
                after = client.read_register(slot, Reg.REG_SSI_POS)
            finally:
                estimator.reset(after=time.monotonic(), hold=True)
            response.offset = to_int32(offset)
            response.position = scale.position(after)
            return (f"REG_OFFSET <- {to_int32(offset)}; position now {response.position:.6f} "
                    f"(requested {request.position:.6f})")
        return self._run("set_preset", request, response, body, f"position={request.position}")

    def reset_registers(self, request: Any, response: Any) -> Any:
        """~/reset_registers: REG_SF = "LD20" (with parameters) or "LD48" (without)."""
        def body(joint: str) -> str:
            value = SF_LD20 if request.include_parameters else SF_LD48
            estimator = self.node.velocity[joint]
            estimator.reset(after=math.inf, hold=True)  # REG_OFFSET may return to 0
            try:
                self.node.client_of(joint).write_register(self._slot(joint), Reg.REG_SF, value)
            finally:
                estimator.reset(after=time.monotonic() + 0.05, hold=True)
            which = "LD20: retentive registers incl. REG_PARA1" if request.include_parameters \
                else "LD48: retentive registers except REG_PARA1"
            return f"{which} restored to defaults"
        return self._run("reset_registers", request, response, body,
                         f"include_parameters={request.include_parameters}")

    def set_control(self, request: Any, response: Any) -> Any:
        """~/set_control: STOP, EN_CMPx and one-cycle CLR_CMPx pulses of the process output."""
        def body(joint: str) -> str:
            self.node.client_of(joint).set_control(
                self._slot(joint), stop=request.stop, enable_cmp1=request.enable_cmp1,
                enable_cmp2=request.enable_cmp2, clear_cmp1=request.clear_cmp1,
                clear_cmp2=request.clear_cmp2)
            return "control bits set"
        return self._run("set_control", request, response, body,
                         f"stop={request.stop} en_cmp1={request.enable_cmp1} "
                         f"en_cmp2={request.enable_cmp2} clr_cmp1={request.clear_cmp1} "
                         f"clr_cmp2={request.clear_cmp2}")

    def inject_fault(self, request: Any, response: Any) -> Any:
        """~/inject_fault: simulation only."""
        def body(joint: str) -> str:
            if self.node.faults is None:
                raise ConfigError("fault injection needs simulation:=true; this node drives "
                                  "real hardware")
            return self.node.faults.inject(request.kind, joint, request.rate, request.duration)
        return self._run("inject_fault", request, response, body,
                         f"kind={request.kind} rate={request.rate} duration={request.duration}")

    def apply_para1(self, joint: str, value: int) -> str | None:
        """Write a new REG_PARA1 for a parameter change; the reason when refused."""
        reason = validate_para1(value)
        if reason:
            return f"{joint}.para1 0x{value:08X} refused (would raise ERR_PARA): {reason}"
        try:
            self.node.client_of(joint).write_register(self._slot(joint), Reg.REG_PARA1, value)
        except SsiBridgeError as err:
            return f"{joint}.para1 0x{value:08X} not written: {err}"
        self.log_event("set_parameters", joint, f"para1=0x{value:08X}", True, "REG_PARA1 written")
        return None


def _check_address(address: int) -> None:
    if not 0 <= address <= MAX_ADDRESS:
        raise ConfigError(f"register address {address} out of range 0..{MAX_ADDRESS}")


def _reg_name(address: int) -> str:
    try:
        return f"{Reg(address).name} ({address})"
    except ValueError:
        return f"register {address}"
