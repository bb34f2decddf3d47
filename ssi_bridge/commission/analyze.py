"""Judge one XN-1SSI slot from what was read and sampled: a working encoder, or why not.

The module's own status comes first (000 "Process input", byte 7): ERR_PARA (REG_PARA1
rejected: the module acquires nothing), ERR_SSI (the SSI error check failed: wire break,
no encoder, 000 Table 19 DIS_ERR_SSI). Then the frames (``infer.py``) and the families that
fit them (``rank.py``). A joint is made only for a slot whose encoder answers with frames
that carry information and that a family of the manuals fits: a joint always comes with
its candidate families and their evidence; everything else is a finding with its reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from ssi_bridge.commission.infer import (MIN_PARITY_FRAMES, BitStats, Motion, MotionState,
                                         read_motion)
from ssi_bridge.commission.rank import Fit, describe_bits, rank_families
from ssi_bridge.commission.sample import SlotSamples
from ssi_bridge.protocol.images import ModuleStatus
from ssi_bridge.protocol.para1 import Para1

#: share of cycles with ERR_SSI above which no encoder counts as answering
NO_ENCODER_SHARE = 0.9
#: frames (cycles without ERR_SSI) below which nothing is inferred: a parity bit is only
#: told with this many distinct frames, so fewer could rule out a family wrongly
MIN_FRAMES = MIN_PARITY_FRAMES


@dataclass
class SlotResult:
    """Everything found about one slot, and the joint made of it (if any)."""

    node_id: int
    slot: int
    #: REG_PARA1 read through the handshake (None: not read), and from object 0x5801
    para1: int | None = None
    para1_object: int | None = None
    samples: int = 0
    frames: int = 0
    err_para: float = 0.0
    err_ssi: float = 0.0
    ssi_diag: float = 0.0
    motion: Motion | None = None
    bits: str = ""
    groups: list[list[Fit]] = field(default_factory=list)
    #: why no joint is made (None: a joint is made)
    problem: str | None = None
    warnings: list[str] = field(default_factory=list)
    #: REG_PARA1 the joint should run with (the read one, or a corrected one)
    para1_joint: int | None = None
    #: the module's diagnostics byte after sampling (0x5804 = REG_DIAG1, 000 Table 27), in
    #: the manual's words; None when it could not be read
    diag_now: list[str] | None = None

    @property
    def joint(self) -> bool:
        """A joint is made of this slot."""
        return self.problem is None and self.para1_joint is not None

    @property
    def best(self) -> Fit | None:
        """The first candidate (None when no family fits)."""
        return self.groups[0][0] if self.groups and self.groups[0] else None

    @property
    def decoded(self) -> Para1 | None:
        """REG_PARA1 in force, decoded (000 Table 19)."""
        value = self.para1 if self.para1 is not None else self.para1_object
        return Para1.decode(value) if value is not None else None


def analyze(found: SlotSamples, para1: int | None, para1_object: int | None) -> SlotResult:
    """The :class:`SlotResult` of one sampled slot.

    :param found: the slot's samples
    :param para1: REG_PARA1 read through the handshake (None: not read)
    :param para1_object: REG_PARA1 read over SDO (object 0x5802; None: not read)
    """
    res = SlotResult(found.node_id, found.slot, para1, para1_object,
                     samples=len(found.samples))
    res.err_para = found.share(ModuleStatus.ERR_PARA)
    res.err_ssi = found.share(ModuleStatus.ERR_SSI)
    res.ssi_diag = found.share(ModuleStatus.SSI_DIAG)
    if para1 is not None and para1_object is not None and para1 != para1_object:
        res.warnings.append(f"REG_PARA1 0x{para1:08X} through the handshake, object 0x5801 "
                            f"reads 0x{para1_object:08X}")
    p = res.decoded
    frames = found.frames()
    res.frames = len(frames)
    if p is None:
        res.problem = "REG_PARA1 could not be read: " + "; ".join(found.errors[:2])
        return res
    if not found.samples:
        res.problem = "no process image could be read: " + "; ".join(found.errors[:2])
        return res
    if res.err_para > 0.5:
        res.problem = (f"ERR_PARA: the module rejects REG_PARA1 0x{p.encode():08X} "
                       f"({p.problem() or 'rejected'}) and acquires nothing (000 Table 19)")
        return res
    if res.err_ssi >= NO_ENCODER_SHARE or not frames:
        res.problem = (f"no encoder answering: ERR_SSI in {res.err_ssi:.0%} of "
                       f"{res.samples} cycles (wire break or no encoder on the SSI line; "
                       "000 Table 19 SSI error check)")
        return res
    if res.err_ssi > 0:
        res.warnings.append(f"ERR_SSI in {res.err_ssi:.0%} of the cycles: an intermittent "
                            "SSI line (wire, cable length against the bit rate, 004 §2.7)")
    if res.ssi_diag > 0:
        res.warnings.append(f"SSI_DIAG in {res.ssi_diag:.0%} of the cycles: the encoder "
                            "reports an error in a status bit REG_SSI_MASK selects")
    n = p.ssi_frame_len
    stats = BitStats.of(frames, n)
    if not stats.ones:
        res.problem = (f"every frame is 0 ({len(frames)} frames of {n} bits): no encoder "
                       "answering (an open data wire reads 0) or one standing at 0 with no "
                       "bit set; move it and run again")
        return res
    if stats.always_one == (1 << n) - 1:
        res.problem = (f"every frame is all ones: data line stuck at 1 or an encoder "
                       "error (004 §3.3 'all bits 1')")
        return res
    if len(frames) < MIN_FRAMES:
        res.problem = (f"not enough evidence: {len(frames)} frames, {MIN_FRAMES} needed to "
                       "tell the bits (a busy host, a slow gateway or an intermittent line; "
                       "run again with a longer --seconds)")
        return res
    motion = read_motion(frames, n, found.latches())
    res.motion = motion
    res.bits = describe_bits(stats, motion)
    if motion.state is MotionState.ERRATIC:
        res.problem = (f"not enough evidence: {'; '.join(motion.evidence)} in {len(frames)} "
                       "frames (a noisy line, an encoder moving faster than the sampling can "
                       "follow, or a host too busy to sample; run again, the encoder slower)")
        return res
    res.groups = rank_families(frames, n, motion, stats)
    if not res.groups:
        res.problem = (f"no encoder family of the manuals sends this frame ({res.bits}): "
                       "check SSI_FRAME_LEN and the encoder; a GENERIC joint must be written "
                       "by hand")
        return res
    res.para1_joint = p.encode()
    if motion.state is MotionState.STILL:
        res.warnings.append("the encoder stood still: the frame length alone tells the "
                            "families; code, direction and resolution are not seen")
    elif motion.state is not MotionState.MOVING:
        res.warnings.append(f"{motion.state.value}: {'; '.join(motion.evidence)}")
    if motion.code is not None and (motion.code == "gray") != p.ssi_code_gray:
        fixed = replace(p, ssi_code_gray=motion.code == "gray")
        res.para1_joint = fixed.encode()
        res.warnings.append(f"the frames are {motion.code} but SSI_CODE_G/D says "
                            f"{'Gray' if p.ssi_code_gray else 'binary'}: REG_SSI_POS is wrong; "
                            f"the params file sets 0x{res.para1_joint:08X}")
    return res


__all__ = ["MIN_FRAMES", "NO_ENCODER_SHARE", "SlotResult", "analyze"]
