"""Service handlers of the node: register access, preset, reset, control, fault injection.

Every handler answers within a bounded time (the client's handshake timeouts) and turns every
failure into ``success: false`` with a message naming the joint, the register and the reason;
no exception escapes into the executor. Each call is also recorded as an event.

Requests are taken from DDS at once by the node's own thread and served in arrival order by
one worker thread (:class:`~ssi_bridge.ros.request_queue.RequestQueue`). Up to ``MAX_QUEUED``
requests wait; one more is refused at once with "busy: N queued". So a burst of calls is never
lost in a DDS history that overflows while a handshake runs, and the worker's share of the
process's CPU (its GIL time) is bounded so that the cycle keeps its rate through a burst.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from builtin_interfaces.msg import Time

from ssi_bridge.protocol.encoder_config import ERROR_BITS, ErrorOutput, FrameFormat
from ssi_bridge.exceptions import BusError, ConfigError, RegisterError, SsiBridgeError
from ssi_bridge.base.timebase import wire_now
from ssi_bridge.protocol.registers import Para1, Reg
from ssi_bridge.ros.joint_scale import to_int32
from ssi_bridge.ros.request_queue import SERVICE_QOS, RequestQueue
from ssi_bridge_msgs.msg import Event
from ssi_bridge_msgs.srv import (
    InjectFault, ReadRegister, ResetRegisters, SetControl, SetPreset, StartRecording,
    StopRecording, WriteRegister,
)

if TYPE_CHECKING:
    from ssi_bridge.ros.node import SsiBridgeNode

MAX_ADDRESS = 63
#: fault kinds of ssi_bridge_msgs/srv/InjectFault that need a note on hidden effects
ENCODER_ERROR = 3
#: REG_SF signatures (000 "Resetting the register bank")
SF_LD20 = 0x6C643230
SF_LD48 = 0x6C643438


class BridgeServices:
    """The handlers, bound to a node's client, station and recorder."""

    def __init__(self, node: SsiBridgeNode) -> None:
        self.node = node
        self.events = node.create_publisher(Event, "~/events", 50)
        node.recorder.offer(self.events.topic_name, self.events.qos_profile)
        self.queue = RequestQueue(node)
        self.busy_refusals = 0
        self._busy_logged = 0.0

    def register(self, group: Any = None) -> None:
        """Create every service of the contract; their requests go through :attr:`queue`
        (one at a time: a handshake per slot is serialised anyway). ``group`` is unused: no
        executor runs these services."""
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
            service = node.create_service(srv_type, name, handler,
                                          callback_group=self.queue.group,
                                          qos_profile=SERVICE_QOS)
            self.queue.add(service, handler, self._refuser(name[2:]))
        self.queue.start()

    def stop(self) -> None:
        """Stop serving (node shutdown)."""
        self.queue.stop()

    def _refuser(self, kind: str) -> Callable[[Any, Any, int], None]:
        """Fills the prompt answer to a request beyond the queue's limit."""
        def refuse(request: Any, response: Any, waiting: int) -> None:
            response.success = False
            response.message = (f"{kind}: busy: {waiting} queued (at most "
                                f"{self.queue.limit} requests wait); call again later")
            self.busy_refusals += 1
            self._log_busy(kind, getattr(request, "joint", ""), response.message)
        return refuse

    def _log_busy(self, kind: str, joint: str, message: str) -> None:
        """A log line at most once a second with the count (an event per refusal would cost
        the cycle the CPU a burst already takes); the bus diagnostics count them too."""
        if time.monotonic() - self._busy_logged >= 1.0:
            self._busy_logged = time.monotonic()
            self.node.get_logger().warning(
                f"{message} ({self.busy_refusals} busy refusals since start)")

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
        if success and kind == "read_register":
            self.node.get_logger().debug(text)  # a read changes nothing: the event suffices
        elif success:
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
                # the one REG_PARA1 path: module, <joint>.para1, scale and velocity together
                return self.node.change_para1(joint, request.value, "~/write_register")
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
                estimator.reset(after=wire_now(), hold=True)
            response.offset = to_int32(offset)
            response.position = scale.position(after)
            return (f"REG_OFFSET <- {to_int32(offset)}; position now {response.position:.6f} "
                    f"(requested {request.position:.6f})")
        return self._run("set_preset", request, response, body, f"position={request.position}")

    def reset_registers(self, request: Any, response: Any) -> Any:
        """~/reset_registers: REG_SF = "LD20" (with parameters) or "LD48" (without)."""
        def body(joint: str) -> str:
            node, slot = self.node, self._slot(joint)
            if not request.include_parameters:
                estimator = node.velocity[joint]
                estimator.reset(after=math.inf, hold=True)  # REG_OFFSET may return to 0
                try:
                    node.client_of(joint).write_register(slot, Reg.REG_SF, SF_LD48)
                finally:
                    estimator.reset(after=wire_now() + 0.05, hold=True)
                return "LD48: retentive registers except REG_PARA1 restored to defaults"
            # LD20 also restores REG_PARA1 (000 "Resetting the register bank"): the value the
            # module now holds becomes <joint>.para1, the scale and the estimate's resolution
            with node._para1_lock:
                old = node.para1[joint]
                node.para1_changing(joint)
                value = old
                try:
                    node.client_of(joint).write_register(slot, Reg.REG_SF, SF_LD20)
                    value = node.client_of(joint).read_register(slot, Reg.REG_PARA1)
                finally:
                    node.adopt_para1(joint, value, wire_now())
            note = node.para1_note[joint]
            return ("LD20: retentive registers incl. REG_PARA1 restored to defaults; REG_PARA1 "
                    f"0x{old:08X} -> 0x{value:08X}, {joint}.para1, scale and velocity estimate "
                    "follow" + (f"; WARNING: {note} (set {joint}.para1 to read it again)"
                                if note else ""))
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
            message = self.node.faults.inject(request.kind, joint, request.rate,
                                              request.duration)
            if request.kind == ENCODER_ERROR:
                hidden = self._hidden_encoder_error(joint)
                if hidden:
                    message += f"; nothing will show: {hidden}"
            return message
        return self._run("inject_fault", request, response, body,
                         f"kind={request.kind} rate={request.rate} duration={request.duration}")

    def _hidden_encoder_error(self, joint: str) -> str:
        """Why an ENCODER_ERROR on ``joint`` reaches no diagnostics, or "" when it shows.

        The error bits travel in the frame after the position (004 §2.3); the XN-1SSI reports
        them only as SSI_DIAG, and only for a frame bit REG_SSI_MASK selects with EN_Dx_RMSx
        and EN_Dx_DS (000 Table 3; bit 0 = the last bit clocked).
        """
        cfg = self.node.configs.get(joint)
        if cfg is None:
            return ""
        if cfg.error_output is not ErrorOutput.FLAGS or cfg.frame_format is not FrameFormat.PLAIN:
            return ""  # the position itself changes (error value / all ones): it shows
        para = Para1.decode(self.node.para1[joint])
        last = len(cfg.special_bits) - 1
        shift = para.ssi_frame_len - cfg.frame_bits  # extra clocks read 0s after the frame
        bits = {last - i + shift: b for i, b in enumerate(cfg.special_bits)
                if b in ERROR_BITS and 0 <= last - i + shift < para.ssi_frame_len}
        if not bits:
            return ""  # no error bit in this layout: faults.py's own note says so
        mask = self.node.client_of(joint).read_register(self._slot(joint), Reg.REG_SSI_MASK)
        for x in range(4):
            byte = (mask >> (8 * x)) & 0xFF
            if byte & 0xC0 == 0xC0 and (byte & 0x1F) in bits:
                return ""
        listed = ", ".join(f"{b.name} = frame bit {i}" for i, b in sorted(bits.items()))
        first = min(bits)
        dropped = (f"; INVALID_BITS_LSB = {para.invalid_bits_lsb} of REG_PARA1 keeps them out of "
                   "REG_SSI_POS" if para.invalid_bits_lsb > first else "")
        return (f"the {cfg.name} error bit(s) ({listed}, counted from the last clock) are "
                f"mapped by no REG_SSI_MASK byte (now 0x{mask:08X}; SSI_DIAG needs EN_Dx_RMSx + "
                f"EN_Dx_DS + SSI_FRAME_BIT_SELx, 000 Table 3){dropped}; write REG_SSI_MASK "
                f"(51) = 0x{0xC0 | first:02X} to see it as SSI_DIAG (WARN)")


def _check_address(address: int) -> None:
    if not 0 <= address <= MAX_ADDRESS:
        raise ConfigError(f"register address {address} out of range 0..{MAX_ADDRESS}")


def _reg_name(address: int) -> str:
    try:
        return f"{Reg(address).name} ({address})"
    except ValueError:
        return f"register {address}"
