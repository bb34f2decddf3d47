"""ROS messages built from the cycle core's results: joint_states, ~/status, stamps.

Kept apart from the node so the per-cycle message building reads (and is timed) on its own.
"""

from __future__ import annotations

from array import array

from builtin_interfaces.msg import Time
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import ChannelStatus, Status
from std_msgs.msg import Header

from ssi_bridge.core.cycle import CycleResult

from ssi_bridge.protocol.images import ProcessInput
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.ros.diagnostics import ChannelCounters
from ssi_bridge.core.frame_watch import FrameWatch

#: register whose content the cyclic process image carries in REG_RD_DATA while no handshake
#: runs: the raw SSI frame, so ~/status shows it every cycle as a PLC would read it
IDLE_READ_REGISTER = Reg.REG_SSI_FRAME


def idle_read(out: bytearray) -> None:
    """Process output byte 4 = REG_RD_ADR of the register shown while no handshake runs."""
    out[4] = int(IDLE_READ_REGISTER)


def time_msg(ns: int) -> Time:
    """builtin_interfaces/Time of a ROS time in nanoseconds."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def channel_msg(name: str, slot: int, image: bytes, position: int, inp: ProcessInput,
                 counters: ChannelCounters, watch: FrameWatch | None = None) -> ChannelStatus:
    """Every bit of one channel's process input image ``image`` (decoded: ``inp``) and its
    REG_SSI_POS ``position``, as ~/status carries it."""
    sts, cmp = inp.sts, inp.cmp
    m = ChannelStatus(joint=name, slot=slot)
    m.process_input = list(image)
    m.reg_rd_data, m.reg_rd_adr, m.reg_rd_abort = inp.reg_rd_data, inp.reg_rd_adr, inp.reg_rd_abort
    m.reg_wr_accept, m.reg_wr_akn = inp.reg_wr_accept, inp.reg_wr_akn
    m.ssi_sts0, m.ssi_sts1, m.ssi_sts2, m.ssi_sts3 = (bool(inp.ssi_sts >> i & 1) for i in range(4))
    m.sts_up, m.sts_dn = bool(cmp & cmp.STS_UP), bool(cmp & cmp.STS_DN)
    m.rel_cmp2, m.flag_cmp2, m.sts_cmp2 = (bool(cmp & cmp.REL_CMP2), bool(cmp & cmp.FLAG_CMP2),
                                           bool(cmp & cmp.STS_CMP2))
    m.rel_cmp1, m.flag_cmp1, m.sts_cmp1 = (bool(cmp & cmp.REL_CMP1), bool(cmp & cmp.FLAG_CMP1),
                                           bool(cmp & cmp.STS_CMP1))
    m.sts_stop, m.err_para = bool(sts & sts.STS_STOP), bool(sts & sts.ERR_PARA)
    m.sts_uflw, m.sts_oflw = bool(sts & sts.STS_UFLW), bool(sts & sts.STS_OFLW)
    m.err_ssi, m.ssi_diag = bool(sts & sts.ERR_SSI), bool(sts & sts.SSI_DIAG)
    m.reg_ssi_pos = int(position)
    m.ssi_frame_valid = (not inp.reg_rd_abort) and inp.reg_rd_adr == int(IDLE_READ_REGISTER)
    m.ssi_frame = inp.reg_rd_data if m.ssi_frame_valid else 0
    m.samples, m.stale_cycles, m.error_cycles = (counters.samples, counters.stale_cycles,
                                                 counters.error_cycles)
    m.frame_errors = counters.frame_errors
    if watch is not None:
        if watch.checked:
            v = watch.verdict
            m.frame_checked = True
            m.parity_error, m.filler_error = v.parity_error, v.filler_error
            m.checksum_error = v.checksum_error
            m.power_failure, m.encoder_error = v.power_failure, v.encoder_error
        m.cam_state = watch.cam_state(int(position))
        m.cam_enabled = watch.cam.enabled
    return m



class JointStates:
    """joint_states of each cycle, in one message kept and filled again (a new message and
    its arrays cost several times as much, on the path from the last TPDO to ``publish()``).

    The message :meth:`fill` returns is the same object every call, its content the latest
    cycle's: whoever holds it must be done with it (``publish()`` and the recorder serialize
    it at once) before the next cycle is filled.
    """

    def __init__(self) -> None:
        self.msg = JointState()
        #: the names in the message (the joints published last), never changed in place
        self._names: list[str] = []

    def fill(self, result: CycleResult, stamp_ns: int, frame_id: str) -> JointState:
        """The kept message with ``result``'s cycle: only the joints with a sample latched at
        the stamp (ROS time ``stamp_ns``), in the configured order; no name when none is."""
        msg = self.msg
        joints = result.joints
        outputs = [out for part in joints if (out := part.output) is not None]
        names = [part.joint.name for part in joints if part.output is not None]
        if names == self._names:  # as a rule: the arrays are filled in place
            position, velocity = msg.position, msg.velocity
            i = 0
            for out in outputs:
                position[i] = out.position
                velocity[i] = out.velocity
                i += 1
        else:
            msg.name = self._names = names
            msg.position = array("d", [out.position for out in outputs])
            msg.velocity = array("d", [out.velocity for out in outputs])
        header = msg.header
        stamp = header.stamp
        stamp.sec, stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        if header.frame_id != frame_id:
            header.frame_id = frame_id
        return msg


def joint_state_msg(result: CycleResult, stamp: Time, frame_id: str) -> JointState:
    """joint_states of one cycle (a message of its own): only the joints with a sample
    latched at ``stamp``."""
    return JointStates().fill(result, stamp.sec * 1_000_000_000 + stamp.nanosec, frame_id)


def status_msg(result: CycleResult, header: Header) -> Status:
    """~/status of one cycle: every joint that has an image, published or set aside (and why)."""
    status = Status(header=header)
    for part in result.joints:
        joint = part.joint
        image = part.image or joint.counters.last_image
        if image is None:
            continue
        position = (part.sample.position if part.sample is not None
                    else joint.counters.last_position)
        msg = channel_msg(joint.name, joint.slot, image, position, ProcessInput.decode(image),
                          joint.counters, joint.frames)
        msg.published = part.output is not None
        msg.set_aside_reason = part.reason
        msg.set_aside = joint.counters.set_aside
        status.channels.append(msg)
    return status
