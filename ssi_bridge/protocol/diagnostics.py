"""Diagnostics byte of the XN-1SSI, the CANopen emergency values derived from it, CAM state.

000 chapter 2 "Diagnostics" (PROFIBUS-DP): bit 0 SSI group diagnostics, bit 1 wire-break,
bit 2 encoder value overflow, bit 3 underflow, bit 4 parameter error.  The same byte is
REG_DIAG1 and CANopen object 5804 (Table 27).  000 chapter 4 "Additional emergencies":
EMCY 0x7000 with byte 5 = 0x01 SSI diag, 0x02 SSI error, 0x04 overflow, 0x08 underflow,
0x10 parameter error, i.e. byte 5 carries the value of the diagnostics bit concerned.

Contradiction resolved here: the DeviceNet DIAGNOSTICS attribute 123 (chapter 3) names bit 2
"error POS > LOWER LIMIT", attribute 112 and every other table name it POS > UPPER LIMIT.
Bit 2 is the overflow bit (REG_SSI_POS > REG_UPPER_LIMIT); the attribute 123 text is a typo.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import IntFlag

logger = logging.getLogger(__name__)

#: CANopen emergency error code for module diagnostics (000 "Additional emergencies")
EMCY_ADDITIONAL_MODULES = 0x7000
#: byte 4 of that emergency: channel number, always 1 for the XN-1SSI
EMCY_CHANNEL = 1


class Diag(IntFlag):
    """The diagnostics byte (000 chapter 2 "Diagnostics", Table 27); bits 5..7 reserved."""

    SSI_DIAG = 0x01
    ERR_SSI = 0x02
    STS_OFLW = 0x04
    STS_UFLW = 0x08
    ERR_PARA = 0x10


#: PROFIBUS channel-diagnostics text of each bit (000 chapter 2 "Diagnostics")
DIAG_TEXT: dict[Diag, str] = {
    Diag.SSI_DIAG: "SSI group diagnostics",
    Diag.ERR_SSI: "Wire-break",
    Diag.STS_OFLW: "Encoder value overflow",
    Diag.STS_UFLW: "Encoder value underflow",
    Diag.ERR_PARA: "Parameter error",
}


@dataclass(frozen=True)
class DiagEdge:
    """One diagnostics bit that changed: what the gateway turns into an EMCY message."""

    #: the bit
    bit: Diag
    #: True = the condition appeared, False = it went away
    rising: bool
    #: module slot number (EMCY byte 3)
    slot: int

    @property
    def emcy_value(self) -> int:
        """EMCY byte 5 (0x01 .. 0x10, 000 "Additional emergencies")."""
        return int(self.bit)

    @property
    def text(self) -> str:
        """The manual's name of the diagnostic."""
        return DIAG_TEXT[self.bit]


def diag_edges(previous: Diag, current: Diag, slot: int = 0) -> list[DiagEdge]:
    """Rising and falling edges between two diagnostics bytes, lowest bit first.

    :param previous: the byte before
    :param current: the byte now
    :param slot: the module's slot (named in the edges)
    """
    out: list[DiagEdge] = []
    for bit in Diag:
        was, now = bit in previous, bit in current
        if was != now:
            out.append(DiagEdge(bit, now, slot))
    return out


class DiagTracker:
    """Remember the last diagnostics byte of one slot and report its edges.

    The gateway calls :meth:`update` after every module cycle and sends an EMCY (0x7000,
    byte 5 = :attr:`DiagEdge.emcy_value`) for each rising edge, and the error-reset EMCY once
    the byte returns to 0.

    :param slot: the module's slot (named in the edges)
    :param initial: the byte before the first update
    """

    def __init__(self, slot: int = 0, initial: Diag = Diag(0)) -> None:
        self.slot = slot
        self.current = initial

    def update(self, diag: Diag) -> list[DiagEdge]:
        """Store ``diag`` and return the edges since the previous call."""
        edges = diag_edges(self.current, diag, self.slot)
        for edge in edges:
            logger.debug("slot %d: %s %s", self.slot, edge.text, "on" if edge.rising else "off")
        self.current = diag
        return edges


def to_int32(value: int) -> int:
    """Read a 32-bit register value as Integer32 (two's complement), as object 0x6820 types it."""
    value &= 0xFFFFFFFF
    return value - (1 << 32) if value & 0x80000000 else value


def cam_state(pos: int, cam_low: int, cam_high: int, *, enabled: bool, polarity: int = 0) -> int:
    """CAM state register value (object 0x6B00, 000 Table 42) for one slot.

    Table 42 prints "outside" for both rows; resolved as 0x00 = outside the range or comparison
    disabled, 0x01 = inside CAM1 Low Limit (REG_CMP2) <= pos <= CAM1 High Limit (REG_CMP1),
    both ends inclusive, compared as Integer32; polarity 0x01 inverts (Table 46).

    :param pos: REG_SSI_POS
    :param cam_low: CAM1 low limit (REG_CMP2, object 0x6B10)
    :param cam_high: CAM1 high limit (REG_CMP1, object 0x6B20)
    :param enabled: the CAM is enabled (object 0x6B01)
    :param polarity: object 0x6B02 (0x01 inverts)
    :returns: 0x00 or 0x01
    """
    inside = enabled and to_int32(cam_low) <= to_int32(pos) <= to_int32(cam_high)
    return int(inside) ^ (polarity & 1)
