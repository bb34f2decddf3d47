"""Master-side evaluation of a readout: error detection and the frame decode.

Error detection as the masters describe it (003 status byte, 000 ZERO test, 001 §4.6):

* DATA_ERROR (003 SB.0): the data input is LOW when the master expects the "pause 1"
  start level (wire break on the data pair, or no encoder);
* FRAME_ERROR (003 SB.1): the frame was "not terminated with zero" (ZERO test after the
  last bit, e.g. clock wire break or a frame longer than the clocks);
* POWER_FAILURE (003 SB.2): the encoder's power-fail bit (the last data bit) is set;
* DATA_MISMATCH (003 SB.3): multiple transmission values differ (multi.py).

:func:`decode_frame` is the XN-1SSI decode (000 REG_PARA1): invalid LSB bits removed by
shifting right, invalid MSB bits zeroed by masking, then Gray -> binary. Gray commutes with
a right shift, so shifting before converting gives the same bits as after.
"""

from __future__ import annotations

from enum import IntFlag

from ssi_bridge.protocol.codes import gray_to_bin
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.readout import LineReadout

#: longest frame of the XN-1SSI (000 REG_PARA1 SSI_FRAME_LEN) and of the generic master
XN_MAX_FRAME_BITS = 32
GENERIC_MAX_FRAME_BITS = 64


class MasterStatus(IntFlag):
    """Status bits of an SSI master, numbered as the 003 status byte SB.0..SB.3."""

    OK = 0
    DATA_ERROR = 0x01
    FRAME_ERROR = 0x02
    POWER_FAILURE = 0x04
    DATA_MISMATCH = 0x08


_DATA_ERROR = MasterStatus.DATA_ERROR.value
_FRAME_ERROR = MasterStatus.FRAME_ERROR.value
_POWER_FAILURE = MasterStatus.POWER_FAILURE.value
#: every combination of the four status bits, indexed by value (the same cached members)
_STATUS: tuple[MasterStatus, ...] = tuple(MasterStatus(v) for v in range(16))


def check_readout(readout: LineReadout, *, zero_test: bool = True,
                  power_fail_bit: bool = False, expect_start: bool = True) -> MasterStatus:
    """Status a master derives from one readout.

    ``zero_test`` is the XN-1SSI "encoder data cable test" (000 REG_PARA1, default on);
    ``power_fail_bit`` treats the last data bit as a PowerFail bit (003); ``expect_start``
    is False for repeat bursts of a multiple transmission, where the line is still held low
    by the monoflop when the first clock samples it.
    """
    status = 0                      # plain int: IntFlag "|" builds a member per operation
    if expect_start and readout.start_bit == 0:
        status = _DATA_ERROR
    if zero_test and readout.trailer_bit != 0:
        status |= _FRAME_ERROR
    if power_fail_bit and readout.data & 1:
        status |= _POWER_FAILURE
    return _STATUS[status]


def decode_frame(data: int, frame_bits: int, *, invalid_lsb: int = 0, invalid_msb: int = 0,
                 gray: bool = False, max_bits: int = GENERIC_MAX_FRAME_BITS) -> int:
    """Position value of a frame as an SSI master computes it (000 REG_PARA1).

    :param data: the ``frame_bits`` data bits, first read = MSB
    :param frame_bits: frame length, 1..32 for the XN-1SSI (``max_bits=32``), up to 64
    :param invalid_lsb: bits removed on the LSB side by shifting right
    :param invalid_msb: bits zeroed on the MSB side by masking
    :param gray: the encoder sends Gray code

    :param max_bits: the longest frame allowed (32 for the XN-1SSI)
    :returns: the position value, LSB-aligned
    :raises ConfigError: ``frame_bits`` outside 1..``max_bits``, or negative invalid bits, or
        as many as the frame has
    """
    if not (invalid_lsb or invalid_msb or gray) and 1 <= frame_bits <= max_bits:
        return data & ((1 << frame_bits) - 1)          # the plain frame: mask only
    if not 1 <= frame_bits <= max_bits:
        raise ConfigError(f"frame length {frame_bits} outside 1..{max_bits}")
    if invalid_lsb < 0 or invalid_msb < 0 or invalid_lsb + invalid_msb >= frame_bits:
        raise ConfigError(f"invalid bits LSB {invalid_lsb} + MSB {invalid_msb} must be less "
                          f"than the frame length {frame_bits} (000 REG_PARA1)")
    value = (data & ((1 << frame_bits) - 1)) >> invalid_lsb
    value &= (1 << (frame_bits - invalid_lsb - invalid_msb)) - 1
    return gray_to_bin(value) if gray else value
