"""Master-side checks of a raw SSI frame against the encoder's layout (001 §5.5, 003, 004 §3).

What a master can verify in one frame when it knows the encoder's layout:

* even parity (001 §5.5.7): "If the SSI data word contains an odd number of "1", the special
  bit Even Parity = "1" and supplements the checksum to even parity ... It is calculated from
  all previous bits." Inverted parity = odd parity; the error parity is also inverted while
  the encoder is in error, so a mismatch there means "transmission error or encoder error";
* bits that are always 0: non-assigned filler bits (004 §3.1 "non-assigned bits are filled
  with 0"; §3.4 Tannenbaum "the MSB or LSB side is filled with "0""), leading zeros (001
  §5.2.4.1), "Logical 0V" special bits, and clocks beyond the frame (004 §3.6 "the additional
  bits are output with "0"");
* the TR "Check sum" format (001 §5.2.4.2): the 15 checksum bits after the 28 data bits
  ("Hammingdistanz von 6 ... erkennt ... bis zu 5 Fehler je Codewort"), with the polynomial
  the simulation chose (protocol/checksum.py); a frame cut short (the XN-1SSI clocks at most
  32 of its 43 bits, 000 Table 19) is checked on the checksum bits that were read;
* status bits: the PowerFail bit (003 "The last data bit can be a PowerFail bit") and the
  error bits (004 §2.3, 001 §5.5.6).

The XN-1SSI itself only runs the ZERO test; the bridge runs these checks on REG_SSI_FRAME.
"""

from __future__ import annotations

from typing import NamedTuple

from ssi_bridge.protocol.checksum import crc15
from ssi_bridge.protocol.encoder_config import (CHECKSUM_BITS, ERROR_BITS, PARITY_BITS, Alignment,
                                       EncoderConfig, FrameFormat, SpecialBit)


class FrameVerdict(NamedTuple):
    """Result of :meth:`FrameCheck.check` for one frame."""

    #: parity bit disagrees with the bits before it (001 §5.5.7); False without a parity bit
    parity_error: bool
    #: a bit that is always 0 in this layout was read as 1 (004 §3.1, §3.4, §3.6)
    filler_error: bool
    #: the PowerFail bit is active (003)
    power_failure: bool
    #: an error bit of the encoder is active (004 §2.3, 001 §5.5.6)
    encoder_error: bool
    #: the checksum bits read disagree with the data bits (001 §5.2.4.2); False without them
    checksum_error: bool = False

    @property
    def corrupt(self) -> bool:
        """The frame cannot be what the encoder sent: do not use its position."""
        return self.parity_error or self.filler_error or self.checksum_error


#: the verdict of a frame that passed every check and carries no status bit (one shared
#: instance: :meth:`FrameCheck.check` returns it for most frames, once a cycle per joint)
CLEAN = FrameVerdict(False, False, False, False, False)


def _area_mask(cfg: EncoderConfig) -> int:
    """Bits of the position area a value can set (the rest are filler, always 0)."""
    db, w = cfg.field_bits, cfg.value_bits
    if cfg.origin < 0:
        word = (1 << db) - 1                      # sign / complement may use every bit
    elif cfg.alignment is Alignment.TANNENBAUM:
        field = db - cfg.turn_bits
        n = int(cfg.steps_per_rev).bit_length() - 1
        turns = max(w - n, 0)
        word = (((1 << turns) - 1) << field) | (((1 << n) - 1) << (field - n))
    elif cfg.alignment is Alignment.LEFT:
        word = ((1 << w) - 1) << (db - w)
    else:
        word = (1 << w) - 1
    area = word << cfg.trailing_zero_bits
    return area >> 1 if cfg.shift_right else area


class FrameCheck:
    """Checks frames of ``frame_len`` bits (SSI_FRAME_LEN) read from an encoder of ``cfg``.

    Built once per (layout, frame length); :meth:`check` is a few integer operations.  A
    frame shorter than the encoder's cuts its end: only the bits read are checked, and a
    parity bit that was not read cannot be checked.
    """

    def __init__(self, cfg: EncoderConfig, frame_len: int) -> None:
        self.cfg = cfg
        self.frame_len = frame_len
        n = cfg.frame_bits
        #: shift from encoder-frame bit positions to the bits as read (negative: cut)
        self._shift = frame_len - n
        n_spec = len(cfg.special_bits)
        fill = n - cfg.position_bits - n_spec
        zero = ((1 << cfg.position_bits) - 1) & ~_area_mask(cfg)
        zero <<= n_spec + fill
        checksum = cfg.frame_format is FrameFormat.CHECKSUM
        if not checksum:
            zero |= (1 << fill) - 1
        self._pos: dict[SpecialBit, int] = {}
        for i, bit in enumerate(cfg.special_bits):
            at = fill + n_spec - 1 - i
            if bit is SpecialBit.ZERO:
                zero |= 1 << at
            else:
                self._pos[bit] = at
        self._zero = self._to_read(zero) | ((1 << max(self._shift, 0)) - 1)
        self._inverted = 0
        for bit in cfg.inverted_bits:
            if bit in self._pos:
                self._inverted |= 1 << self._pos[bit]
        self._inverted = self._to_read(self._inverted)
        parity = [b for b in cfg.special_bits if b in PARITY_BITS]
        self._parity_at: int | None = None
        if parity and self._pos[parity[0]] + self._shift >= 0:
            self._parity_at = self._pos[parity[0]] + self._shift
        #: checksum bits read (0: none) and how many were cut off the end (001 §5.2.4.2)
        self._cut = max(-self._shift, 0)
        self._crc_read = max(CHECKSUM_BITS - self._cut, 0) if checksum else 0
        self._crc_mask = (1 << self._crc_read) - 1
        self._power = self._bit_mask((SpecialBit.POWER_FAIL,))
        self._errors = self._bit_mask(tuple(ERROR_BITS))

    def _to_read(self, mask: int) -> int:
        """Encoder-frame bit mask -> bit mask of the frame as read."""
        s = self._shift
        return (mask << s if s >= 0 else mask >> -s) & ((1 << self.frame_len) - 1)

    def _bit_mask(self, bits: tuple[SpecialBit, ...]) -> int:
        mask = 0
        for bit in bits:
            if bit in self._pos:
                mask |= 1 << self._pos[bit]
        return self._to_read(mask)

    @property
    def has_parity(self) -> bool:
        """The frame as read carries a parity bit."""
        return self._parity_at is not None

    @property
    def checksum_bits(self) -> int:
        """Checksum bits in the frame as read (15 when all 43 clocks are read, else fewer)."""
        return self._crc_read

    def check(self, frame: int) -> FrameVerdict:
        """Verdict on one frame as read (``frame_len`` bits, first bit read = MSB)."""
        logical = frame ^ self._inverted
        parity_error = False
        at = self._parity_at
        if at is not None:
            # even parity over the parity bit and every bit before it (wire levels); odd
            # parity (inverted) makes the sum odd
            odd = bin(frame >> at).count("1") & 1
            inverted = (self._inverted >> at) & 1
            parity_error = odd != inverted
        checksum_error = False
        if self._crc_read:
            # the data bits and the leading checksum bits read; compare with the checksum
            # of the data bits (cut to the bits read)
            word = frame >> max(self._shift, 0)
            got = word & self._crc_mask
            want = crc15(word >> self._crc_read) >> self._cut
            checksum_error = got != want
        filler = frame & self._zero
        status = logical & (self._power | self._errors)
        if not (parity_error or filler or status or checksum_error):
            return CLEAN
        return FrameVerdict(parity_error, bool(filler), bool(logical & self._power),
                            bool(logical & self._errors), checksum_error)
