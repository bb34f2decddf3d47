"""Per joint: the encoder's status bits and frame checks on REG_SSI_FRAME, and the CAM state.

The XN-1SSI only runs the ZERO test (000 Table 19) and copies up to four frame bits into
SSI_STS0..3 (REG_SSI_MASK, 000 Table 3). The bridge knows each joint's encoder layout (its
family and overrides), so every cycle whose process input carries REG_SSI_FRAME (the idle
read register, ``messages.IDLE_READ_REGISTER``) it checks parity (001 §5.5.7), the TR
checksum (001 §5.2.4.2) and the bits that are always 0 (004 §3), and reads the PowerFail (003) and error bits (004 §2.3). A frame
that fails a check is not used for the joint's position. ROS-free.

The CAM state (object 0x6B00, 000 Table 42) is computed per cycle from REG_SSI_POS and the
CAM objects 0x6B10/0x6B20/0x6B01/0x6B02, which the node reads over SDO now and then
(:meth:`FrameWatch.set_cam`).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass

from ssi_bridge.protocol.encoder_config import EncoderConfig
from ssi_bridge.protocol.frame_check import FrameCheck, FrameVerdict
from ssi_bridge.protocol.diagnostics import cam_state
from ssi_bridge.protocol.registers import Para1, Reg

logger = logging.getLogger(__name__)

#: process input byte 4: REG_RD_ADR (bits 0-5) and REG_RD_ABORT (bit 7) (000 "Process input")
_ADR_MASK, _ABORT = 0x3F, 0x80
_ADR_BITS = _ADR_MASK | _ABORT
_FRAME_REGISTER = int(Reg.REG_SSI_FRAME)
#: bytes 0-3 of the image (REG_RD_DATA) as the frame was read: first bit read = MSB
_READ_FRAME = struct.Struct(">I").unpack_from
NO_VERDICT = FrameVerdict(False, False, False, False)


@dataclass(frozen=True)
class CamSettings:
    """The CAM objects of one slot as last read (000 Tables 43-48)."""

    low: int = 0          #: 0x6B10 CAM1 low limit (= REG_CMP2)
    high: int = 0         #: 0x6B20 CAM1 high limit (= REG_CMP1)
    enabled: bool = False  #: 0x6B01
    polarity: int = 0     #: 0x6B02


#: CAM objects (000 Tables 43-48): enable, polarity, low limit, high limit
CAM_ENABLE, CAM_POLARITY, CAM_LOW, CAM_HIGH = 0x6B01, 0x6B02, 0x6B10, 0x6B20


def read_cam(read: Callable[[int], int]) -> CamSettings:
    """The CAM objects of one slot through ``read(index)`` (an SDO upload of sub = slot).

    Two reads while CAM enable is 0 (the state is then 0x00, or 0x01 with polarity 1: "or the
    comparison function is not activated", Table 42 with its inversion note); four otherwise.
    """
    enabled = bool(int(read(CAM_ENABLE)))
    polarity = int(read(CAM_POLARITY)) & 1
    if not enabled:
        return CamSettings(polarity=polarity)
    return CamSettings(int(read(CAM_LOW)) & 0xFFFFFFFF, int(read(CAM_HIGH)) & 0xFFFFFFFF,
                       True, polarity)


class FrameWatch:
    """Frame checks and status-bit edges of one joint.

    :param cfg: the joint's encoder layout (None: no frame checks, status bits only)
    :param para1: the REG_PARA1 in force
    """

    def __init__(self, cfg: EncoderConfig | None, para1: int) -> None:
        self.cfg = cfg
        self.check: FrameCheck | None = None
        self.set_para1(para1)
        self.cam = CamSettings()
        #: verdict of the latest checked frame (NO_VERDICT before one)
        self.verdict = NO_VERDICT
        #: the latest image carried a frame that was checked
        self.checked = False
        self.failures = ParityEvents()
        #: the process input image last evaluated
        self.image = b""

    def set_para1(self, para1: int) -> None:
        """Follow a new REG_PARA1: the frame as read has SSI_FRAME_LEN bits (000 Table 19).

        :param para1: the REG_PARA1 now in force
        """
        if self.cfg is None:
            self.check = None
            return
        frame_len = Para1.decode(para1).ssi_frame_len
        self.check = FrameCheck(self.cfg, frame_len) if 1 <= frame_len <= 32 else None
        #: the bits of REG_RD_DATA the frame as read fills (IMAGE_STRUCT)
        self._frame_mask = (1 << frame_len) - 1

    def set_cam(self, cam: CamSettings) -> None:
        """Follow the CAM settings of the gateway (object 0x6B00's limits, enable and polarity).

        :param cam: the new settings
        """
        self.cam = cam

    def evaluate(self, image: bytes) -> tuple[FrameVerdict, FrameVerdict] | None:
        """Check the frame in ``image``; (previous verdict, new verdict), None when no frame."""
        self.image = image
        check = self.check
        if check is None or image[4] & _ADR_BITS != _FRAME_REGISTER:
            self.checked = False
            return None
        before = self.verdict
        self.verdict = after = check.check(_READ_FRAME(image)[0] & self._frame_mask)
        self.checked = True
        return before, after

    def cam_state(self, reg_ssi_pos: int) -> int:
        """Object 0x6B00 for this REG_SSI_POS (000 Table 42, 0x01 = inside, polarity applied).

        :param reg_ssi_pos: the position as the module reports it
        """
        c = self.cam
        return cam_state(reg_ssi_pos & 0xFFFFFFFF, c.low, c.high, enabled=c.enabled,
                         polarity=c.polarity)


def edges(before: FrameVerdict, after: FrameVerdict) -> list[str]:
    """Sentences for the status bits that changed (for ~/events): power failure, error bits.

    :param before: the frame's verdict of the previous sample
    :param after: the verdict now
    """
    out = []
    if after.power_failure != before.power_failure:
        out.append("POWER_FAILURE: the encoder's PowerFail bit is "
                   + ("set (003)" if after.power_failure else "clear again"))
    if after.encoder_error != before.encoder_error:
        out.append("encoder error bit " + ("set" if after.encoder_error else "clear again"))
    return out


class ParityEvents:
    """At most one ~/events entry per ``period`` seconds for frame check failures, with a count."""

    def __init__(self, period: float = 1.0) -> None:
        self.period = period
        self._last: float | None = None
        self._count = 0

    def failed(self, now: float, verdict: FrameVerdict) -> str | None:
        """Count a failed frame; the sentence to log when one is due, else None.

        :param now: the frame's wire time (s)
        :param verdict: the frame's verdict
        """
        self._count += 1
        if self._last is not None and now - self._last < self.period:
            return None
        what = ("parity bit does not match (001 5.5.7)" if verdict.parity_error else
                "checksum bits do not match (001 5.2.4.2)" if verdict.checksum_error else
                "a bit the layout sends as 0 read as 1 (004 3)")
        text = (f"frame check failed {self._count} time(s) since the last report: {what}; "
                "those cycles' positions were not used")
        self._last, self._count = now, 0
        return text
