"""The operations a user asks of the bridge, ROS-free: registers, preset, reset, control, faults.

The node's services (``ros/services.py``) and any other front end (the live view) call these
and turn the result or the exception into an answer; nothing here knows ROS. Each operation
returns the sentence that says what happened, or raises :class:`~ssi_bridge.exceptions.
SsiBridgeError` (ConfigError for a refused request) with the register and the reason.

REG_PARA1 has one truth: :meth:`Bridge.change_para1` (``<joint>.para1``, a write of address
20) and an LD20 reset move the module, the joint's scale and velocity estimate together, and
``on_para1`` mirrors the value into the node's parameter.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping

from ssi_bridge.base.timebase import wire_now
from ssi_bridge.core.frame_watch import read_cam
from ssi_bridge.core.joint import Joint
from ssi_bridge.core.joint_scale import to_int32
from ssi_bridge.core.ports import FaultPort, StationClient
from ssi_bridge.exceptions import ConfigError, GatewayUnavailable, SsiBridgeError
from ssi_bridge.protocol.encoder_config import ERROR_BITS, ErrorOutput, FrameFormat
from ssi_bridge.protocol.para1 import validate_para1
from ssi_bridge.protocol.registers import Para1, Reg

#: highest register address of the XN-1SSI bank (000 chapter 1: 64 registers)
MAX_ADDRESS = 63
#: the InjectFault kind ENCODER_ERROR (ssi_bridge_msgs/srv/InjectFault)
ENCODER_ERROR = 3
#: REG_SF signatures (000 "Resetting the register bank")
SF_LD20 = 0x6C643230
SF_LD48 = 0x6C643438
#: object 0x5801 Encoder Config = REG_PARA1 of each slot (000 Table 16/17)
ENCODER_CONFIG = 0x5801
#: REG_SSI_MASK object (000 Table 35)
SSI_DIAG_MAPPING = 0x5840


def register_name(address: int) -> str:
    """``REG_SSI_POS (0)``, or ``register 5`` for an address the manual does not name."""
    try:
        return f"{Reg(address).name} ({address})"
    except ValueError:
        return f"register {address}"


def check_address(address: int) -> None:
    """ConfigError unless ``address`` is a register of the bank (0..63)."""
    if not 0 <= address <= MAX_ADDRESS:
        raise ConfigError(f"register address {address} out of range 0..{MAX_ADDRESS}")


class Bridge:
    """The joints of one node and the master's clients they are reached through.

    :param joints: the node's joints by name, in the configured order (kept, not copied)
    :param client_of: the master's client of the station holding a joint's module
    :param on_para1: called with (joint, value) once the module holds a new REG_PARA1
    """

    def __init__(self, joints: Mapping[str, Joint], client_of: Callable[[str], StationClient],
                 on_para1: Callable[[str, int], None] | None = None) -> None:
        #: the node's joints (the node's own mapping: a managed node fills it at each configure)
        self.joints = joints
        self.client_of = client_of
        self._on_para1 = on_para1
        #: fault injection into the simulated station (None on real hardware)
        self.faults: FaultPort | None = None
        self.para1_lock = threading.RLock()

    def joint(self, requested: str) -> Joint:
        """The joint a request means; an empty name means the first configured joint.

        :param requested: a configured joint's name, or empty for the first
        :raises ConfigError: no joint of that name (the message lists the configured ones)
        """
        if not requested:
            return next(iter(self.joints.values()))
        if requested not in self.joints:
            raise ConfigError(f"unknown joint {requested!r}; configured joints: "
                              f"{', '.join(self.joints)}")
        return self.joints[requested]

    # -- REG_PARA1 --------------------------------------------------------------------------
    def adopt_para1(self, joint: Joint, value: int, since: float) -> None:
        """The module holds ``value``: the joint follows, the parameter is mirrored.

        :param joint: the joint whose module holds ``value``
        :param value: the REG_PARA1 read from the module
        :param since: wire time from which samples are latched under ``value``
        """
        with self.para1_lock:
            joint.adopt_para1(value, since)
            if self._on_para1 is not None:
                self._on_para1(joint.name, value)

    def change_para1(self, name: str, value: int, via: str) -> str:
        """Write REG_PARA1 of joint ``name`` and move parameter, scale and estimate with it.

        Checked against the module's rules (000 Table 19, ERR_PARA), written by the handshake;
        samples latched before the write are unknown. Raises ConfigError / SsiBridgeError.

        :param name: the joint's name (empty: the first)
        :param value: the new REG_PARA1
        :param via: who asked (a service, a parameter change), for the sentence
        :returns: the sentence that says what happened
        :raises ConfigError: an unknown joint or a value the module would refuse
        :raises SsiBridgeError: the handshake failed (timeout, refusal, silent gateway)
        """
        reason = validate_para1(value)
        if reason:
            raise ConfigError(f"REG_PARA1 0x{value:08X} refused (would raise ERR_PARA): {reason}")
        joint = self.joint(name)
        with self.para1_lock:
            old = joint.para1
            joint.para1_changing()
            try:
                self.client_of(joint.name).write_register(joint.slot, Reg.REG_PARA1, value)
            except BaseException:
                self.adopt_para1(joint, old, wire_now())
                raise
            self.adopt_para1(joint, value, wire_now())
        return (f"REG_PARA1 0x{old:08X} -> 0x{value:08X} via {via}; {joint.name}.para1, scale and "
                f"velocity estimate follow")

    # -- start-up --------------------------------------------------------------------------
    def configure(self, joint: Joint, idle_output: Callable[[bytearray], None]) -> str:
        """Set the joint's module up as a CANopen master does at start-up; what changed.

        REG_PARA1 through object 0x5801 (000 Table 17) if it differs from ``<joint>.para1``
        (an invalid set is refused with the module's rule, ConfigError), REG_SSI_MASK through
        0x5840 (Table 35) unless ``ssi_mask`` is -1, and the idle process output
        (``idle_output``: the read of the raw frame that the frame checks use).
        """
        client, para1 = self.client_of(joint.name), joint.settings.para1
        current = int(client.read_object(ENCODER_CONFIG, joint.slot))
        change = ""
        if current != para1:
            reason = validate_para1(para1)
            if reason:
                raise ConfigError(f"{joint.name}.para1 0x{para1:08X} is invalid: {reason}")
            client.write_object(ENCODER_CONFIG, joint.slot, para1)
            change = (f"REG_PARA1 0x{current:08X} -> 0x{para1:08X} "
                      f"(object 0x{ENCODER_CONFIG:04X}:{joint.slot})")
        if joint.settings.ssi_mask >= 0:
            client.write_object(SSI_DIAG_MAPPING, joint.slot, joint.settings.ssi_mask)
        client.edit_output(joint.slot, idle_output)
        return change

    def refresh_cams(self) -> list[tuple[str, SsiBridgeError]]:
        """Read the CAM objects 0x6B10/0x6B20/0x6B01/0x6B02 of every joint (000 Tables 43-48)
        into its frame watch; the joints whose objects could not be read, with the error.

        A joint whose gateway is silent (no heartbeat) is not asked: each SDO transfer to it
        would wait out ``bus.sdo_timeout`` and hold up the diagnostics of every station; its
        frame watch keeps the CAM state last read."""
        failed: list[tuple[str, SsiBridgeError]] = []
        for joint in self.joints.values():
            client = self.client_of(joint.name)
            if not client.gateway_alive:
                failed.append((joint.name, GatewayUnavailable("gateway silent: not asked")))
                continue
            try:
                joint.frames.set_cam(read_cam(
                    lambda index: int(client.read_object(index, joint.slot))))
            except SsiBridgeError as err:
                failed.append((joint.name, err))
        return failed

    # -- registers --------------------------------------------------------------------------
    def read_register(self, joint: Joint, address: int) -> int:
        """The register's value through the REG_RD_ADR handshake (000 Table 4).

        :param joint: the joint whose module is read
        :param address: the register (0-63)
        :raises ConfigError: the address is out of range
        :raises SsiBridgeError: the handshake failed (timeout, abort, silent gateway)
        """
        check_address(address)
        return int(self.client_of(joint.name).read_register(joint.slot, address))

    def write_register(self, joint: Joint, address: int, value: int) -> str:
        """REG_WR / REG_WR_AKN / REG_WR_ACCEPT; REG_PARA1 takes :meth:`change_para1`.

        :param joint: the joint whose module is written
        :param address: the register (0-63)
        :param value: the value to write
        :returns: the sentence that says what happened
        :raises ConfigError: the address is out of range or the value breaks a rule of 000
        :raises SsiBridgeError: the handshake failed (timeout, refusal, silent gateway)
        """
        check_address(address)
        if address == Reg.REG_PARA1:
            return self.change_para1(joint.name, value, "~/write_register")
        if address == Reg.REG_OFFSET:
            # the zero point moves, not the shaft: hold the speed as a preset does, so no
            # velocity window spans the change (000 "Offset function")
            estimator = joint.velocity
            estimator.reset(after=math.inf, hold=True)
            try:
                self.client_of(joint.name).write_register(joint.slot, address, value)
            finally:
                estimator.reset(after=wire_now() + 0.05, hold=True)
        else:
            self.client_of(joint.name).write_register(joint.slot, address, value)
        return f"{register_name(address)} <- 0x{value:08X} accepted"

    def set_preset(self, joint: Joint, position: float) -> tuple[int, float, str]:
        """REG_OFFSET = encoder - target, so REG_SSI_POS reads ``position`` (joint units).

        000 "Offset function": REG_SSI_POS = SSI encoder - REG_OFFSET. Returns the offset
        written (Integer32), the position read back and the sentence.

        :param joint: the joint to preset
        :param position: the position REG_SSI_POS shall read, in joint units (rad or m)
        :raises ConfigError: ``position`` is not finite or not reachable in Integer32 counts
        :raises SsiBridgeError: a handshake failed
        """
        if not math.isfinite(position):
            raise ConfigError(f"position {position} is not a finite number")
        scale = joint.scale
        target = scale.counts(position)
        if not -(1 << 31) <= target < (1 << 31):
            raise ConfigError(f"position {position} is {target} counts, outside "
                              "the Integer32 range of REG_SSI_POS")
        client, slot = self.client_of(joint.name), joint.slot
        old_offset = client.read_register(slot, Reg.REG_OFFSET)
        pos = client.read_register(slot, Reg.REG_SSI_POS)
        encoder = (pos + old_offset) & 0xFFFF_FFFF
        offset = (encoder - target) & 0xFFFF_FFFF
        estimator = joint.velocity
        # hold the speed while the zero point moves: samples until the read-back may still
        # carry the old offset, so none of them enters the estimate
        estimator.reset(after=math.inf, hold=True)
        try:
            client.write_register(slot, Reg.REG_OFFSET, offset)
            after = client.read_register(slot, Reg.REG_SSI_POS)
        finally:
            estimator.reset(after=wire_now(), hold=True)
        read_back = scale.position(after)
        return (to_int32(offset), read_back,
                f"REG_OFFSET <- {to_int32(offset)}; position now {read_back:.6f} "
                f"(requested {position:.6f})")

    def reset_registers(self, joint: Joint, include_parameters: bool) -> str:
        """REG_SF = "LD20" (with parameters) or "LD48" (without), 000 "Resetting the bank".

        :param joint: the joint whose module's bank is reset
        :param include_parameters: also REG_PARA1 and the other parameters (LD20)
        :returns: the sentence that says what happened
        :raises SsiBridgeError: the handshake failed
        """
        client, slot = self.client_of(joint.name), joint.slot
        if not include_parameters:
            estimator = joint.velocity
            estimator.reset(after=math.inf, hold=True)  # REG_OFFSET may return to 0
            try:
                client.write_register(slot, Reg.REG_SF, SF_LD48)
            finally:
                estimator.reset(after=wire_now() + 0.05, hold=True)
            return "LD48: retentive registers except REG_PARA1 restored to defaults"
        # LD20 also restores REG_PARA1: the value the module now holds becomes <joint>.para1,
        # the scale and the estimate's resolution
        with self.para1_lock:
            old = value = joint.para1
            joint.para1_changing()
            try:
                client.write_register(slot, Reg.REG_SF, SF_LD20)
                value = client.read_register(slot, Reg.REG_PARA1)
            finally:
                self.adopt_para1(joint, value, wire_now())
        note = joint.para1_note
        return ("LD20: retentive registers incl. REG_PARA1 restored to defaults; REG_PARA1 "
                f"0x{old:08X} -> 0x{value:08X}, {joint.name}.para1, scale and velocity estimate "
                "follow" + (f"; WARNING: {note} (set {joint.name}.para1 to read it again)"
                            if note else ""))

    def set_control(self, joint: Joint, **bits: bool) -> str:
        """STOP, EN_CMPx and one-cycle CLR_CMPx pulses of the process output (000 Table 6).

        :param joint: the joint whose module's control bits are set
        :param bits: as :meth:`BridgeClient.set_control` (``stop``, ``enable_cmp1`` ...)
        :returns: the sentence that says what happened
        """
        self.client_of(joint.name).set_control(joint.slot, **bits)
        return "control bits set"

    # -- faults (simulation only) -----------------------------------------------------------
    def inject_fault(self, joint: Joint, kind: int, rate: float, duration: float) -> str:
        """A fault in the simulated station; ConfigError on real hardware.

        :param joint: the joint whose encoder, line or station is faulted
        :param kind: the fault (``InjectFault`` constants; 0 clears all)
        :param rate: probability per frame or cycle, where the kind has one
        :param duration: seconds, 0 = until cleared
        :returns: the sentence that says what happened
        :raises ConfigError: the node drives a real station (no simulation)
        """
        if self.faults is None:
            raise ConfigError("fault injection needs simulation.enabled:=true; this node drives "
                              "real hardware")
        message = self.faults.inject(kind, joint.name, rate, duration)
        if kind == ENCODER_ERROR:
            hidden = self._hidden_encoder_error(joint)
            if hidden:
                message += f"; nothing will show: {hidden}"
        return message

    def _hidden_encoder_error(self, joint: Joint) -> str:
        """Why an ENCODER_ERROR on ``joint`` reaches no diagnostics, or "" when it shows.

        The error bits travel in the frame after the position (004 §2.3); the XN-1SSI reports
        them only as SSI_DIAG, and only for a frame bit REG_SSI_MASK selects with EN_Dx_RMSx
        and EN_Dx_DS (000 Table 3; bit 0 = the last bit clocked).
        """
        cfg = joint.config
        if cfg is None:
            return ""
        if cfg.error_output is not ErrorOutput.FLAGS or cfg.frame_format is not FrameFormat.PLAIN:
            return ""  # the position itself changes (error value / all ones): it shows
        para = Para1.decode(joint.para1)
        last = len(cfg.special_bits) - 1
        shift = para.ssi_frame_len - cfg.frame_bits  # extra clocks read 0s after the frame
        bits = {last - i + shift: b for i, b in enumerate(cfg.special_bits)
                if b in ERROR_BITS and 0 <= last - i + shift < para.ssi_frame_len}
        if not bits:
            return ""  # no error bit in this layout: the injector's own note says so
        mask = self.client_of(joint.name).read_register(joint.slot, Reg.REG_SSI_MASK)
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


__all__ = ["Bridge", "ENCODER_ERROR", "MAX_ADDRESS", "SF_LD20", "SF_LD48", "check_address",
           "register_name"]
