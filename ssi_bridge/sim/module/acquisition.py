"""Per-cycle evaluation steps of the XN-1SSI as pure functions (000 chapter 1).

* :func:`extract` - SSI error check (ZERO test), invalid LSB/MSB bits, Gray -> binary
  ("Transmission procedure", Table 19), via the line stage's master decode.
* :func:`ssi_status` - REG_SSI_MASK -> SSI_STS0..3 and SSI_DIAG (Table 3).
* :func:`compare` - one comparator, the truth table of "Comparison value 1, Comparison value 2".
* :func:`limits` - STS_OFLW / STS_UFLW (Tables 1 and 2).
* :func:`direction` - STS_UP / STS_DN (process input byte 6).

The comparators compare as Integer32 (two's complement): object 0x6820, which *is*
REG_SSI_POS, and the CAM limits 0x6B10/0x6B20 (= REG_CMP2/REG_CMP1) are Integer32.  The
limits compare as Unsigned32: "The limit values are set by default to the maximum and
minimum value" (000 "Lower limit, upper limit") with defaults 0xFFFFFFFF and 0, and Table 1
"Register content of REG_UPPER_LIMIT less than FFFFFFFF hex", Table 2 "greater than 0" -
maximum and minimum only as unsigned numbers; no statement of the manual makes them signed.
"""

from __future__ import annotations

from typing import NamedTuple

from ssi_bridge.protocol.codes import bin_to_gray, gray_to_bin
from ssi_bridge.protocol.decode import XN_MAX_FRAME_BITS, MasterStatus, check_readout, decode_frame
from ssi_bridge.protocol.readout import LineReadout
from ssi_bridge.protocol.diagnostics import to_int32
from ssi_bridge.protocol.para1 import Para1


__all__ = ["Acquired", "bin_to_gray", "compare", "direction", "extract", "gray_to_bin",
           "limits", "ssi_status"]

#: EN_Dx_RMSx (bit 7) of each of the four REG_SSI_MASK bytes (000 Table 3)
_EN_RMS_ANY = 0x80808080


class Acquired(NamedTuple):
    """What one clock burst yields after the module's processing (built once per cycle)."""

    #: REG_SSI_FRAME: the complete frame as read (SSI_FRAME_LEN bits, first bit = MSB)
    frame: int
    #: the encoder value: invalid bits removed, Gray decoded (before REG_OFFSET)
    value: int
    #: REG_GRAY_POS: the same value in Gray code
    gray: int
    #: False when the SSI error check failed (ERR_SSI = 1)
    ok: bool


def extract(readout: LineReadout, para: Para1) -> Acquired:
    """Turn one readout into frame, encoder value and SSI error check (000 Table 19).

    The frame decode is the line stage's master decode (:func:`decode_frame`): LSB-side
    invalid bits shifted out, MSB-side ones masked to 0, then Gray -> binary on the remaining
    field only, so status bits around a Gray-coded position cannot corrupt it.  The error
    check (skipped entirely when DIS_ERR_SSI = 1, "disable SSI error detection", DeviceNet
    attribute 124) is the ZERO test after the last bit (``trailer_bit`` must be 0) plus the
    start level (a data wire break reads LOW where the idle "pause 1" is expected).

    :param readout: what the module clocked in
    :param para: the REG_PARA1 set in force
    """
    n = para.ssi_frame_len
    frame = readout.data & ((1 << n) - 1)
    value = decode_frame(frame, n, invalid_lsb=para.invalid_bits_lsb,
                         invalid_msb=para.invalid_bits_msb, gray=para.ssi_code_gray,
                         max_bits=XN_MAX_FRAME_BITS)
    ok = para.dis_err_ssi or check_readout(readout, zero_test=True) is MasterStatus.OK
    return Acquired(frame, value, bin_to_gray(value), ok)  # positional: built every cycle


def ssi_status(frame: int, mask: int) -> tuple[int, bool]:
    """SSI_STS3..0 (as a 4-bit number) and SSI_DIAG from REG_SSI_MASK (000 Table 3).

    Byte x of REG_SSI_MASK (byte 0 = least significant) serves SSI_STSx: bit 7 EN_Dx_RMSx
    copies frame bit SSI_FRAME_BIT_SELx (bits 4..0; bit 0 = last bit clocked) into SSI_STSx;
    SSI_DIAG = OR over x of (SSI_STSx & EN_Dx_DS), as the manual's formula is written, so a
    status bit reaches SSI_DIAG only when it is also copied (EN_Dx_RMSx = 1).

    :param frame: the frame as clocked in
    :param mask: REG_SSI_MASK
    """
    if not mask & _EN_RMS_ANY:
        return 0, False  # no status bit copied (the default mask 0): nothing to look at
    sts = 0
    diag = False
    for x in range(4):
        byte = (mask >> (8 * x)) & 0xFF
        if byte & 0x80 and (frame >> (byte & 0x1F)) & 1:
            sts |= 1 << x
            diag = diag or bool(byte & 0x40)
    return sts, diag


def compare(pos: int, cmp_value: int, *, enabled: bool, clear: bool,
            flag: bool) -> tuple[bool, bool, bool]:
    """One comparator step; returns (STS_CMPx, FLAG_CMPx, REL_CMPx).

    EN_CMPx = 0: all three 0 and the latched flag forgotten.  STS = (pos == cmp),
    REL = (pos >= cmp) (signed), FLAG latches a match and is cleared by CLR_CMPx = 1 only
    while the values do not match ("Reset of FLAG_CMPx not possible when values match").

    :param pos: REG_SSI_POS
    :param cmp_value: REG_CMPx
    :param enabled: EN_CMPx
    :param clear: CLR_CMPx
    :param flag: FLAG_CMPx before this step
    """
    if not enabled:
        return False, False, False
    p, c = to_int32(pos), to_int32(cmp_value)
    sts = p == c
    flag = flag or sts
    if clear and not sts:
        flag = False
    return sts, flag, p >= c


def limits(pos: int, lower: int, upper: int) -> tuple[bool, bool]:
    """(STS_OFLW, STS_UFLW) per 000 Tables 1 and 2, compared as Unsigned32.

    At the defaults (upper 0xFFFFFFFF, lower 0) no unsigned value can be above / below them,
    which is why the tables give STS_OFLW = STS_UFLW = 0 there.  A REG_SSI_POS that went
    "negative" below REG_OFFSET is a large unsigned number: above an active upper limit.

    :param pos: REG_SSI_POS
    :param lower: REG_LOWER_LIMIT
    :param upper: REG_UPPER_LIMIT
    """
    return pos > upper, pos < lower


def direction(previous: int | None, current: int, width: int) -> tuple[bool, bool]:
    """(STS_UP, STS_DN) from two successive encoder values of ``width`` bits.

    The difference is taken modulo 2**width, so a multiturn wrap (max -> 0) counts as one
    step up, not a jump down.  Both bits are 0 when the value is constant.

    :param previous: the value of the cycle before (None: the first)
    :param current: the value now
    :param width: the value's bits
    """
    if previous is None or width <= 0:
        return False, False
    diff = (current - previous) % (1 << width)
    if diff == 0:
        return False, False
    up = diff < (1 << (width - 1)) or width == 1
    return up, not up
