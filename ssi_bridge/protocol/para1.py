"""REG_PARA1, the parameter register of the XN-1SSI (000 Tables 18 and 19, chapter 2 "Parameters").

The 32-bit value is read as four bytes with byte 3 the most significant one, so the default
``0x19010000`` is byte 3 = 0x19 (SSI_FRAME_LEN = 25) and byte 2 = 0x01 (SSI_BIT_RATE = 500 kBit/s)::

    byte 3  bit 7 SSI_CODE_G/D (1 = Gray)        bits 5..0 SSI_FRAME_LEN (1..32)
    byte 2                                        bits 3..0 SSI_BIT_RATE (0..7, 8..15 reserved)
    byte 1  bits 6..4 INVALID_BITS_MSB (0..7)     bits 3..0 INVALID_BITS_LSB (0..15)
    byte 0  bit 5 DIS_ERR_SSI (1 = no ZERO test of the data line)

Bit-rate codes follow the PROFIBUS-DP parameter table (chapter 2) and Table 19 (CANopen):
3 = 125 kBit/s, 4 = 100 kBit/s.  The DeviceNet BITRATE attribute 126 lists 3 = 100 k and
4 = 125 k; that is the DeviceNet attribute's own enumeration, not REG_PARA1 (docs/module.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

#: REG_PARA1 default (000 "Register access and meaning"): 25-bit binary frame at 500 kBit/s
PARA1_DEFAULT = 0x19010000

#: SSI_BIT_RATE code -> bit rate in Hz (000 Table 19 and PROFIBUS-DP "Parameters")
BIT_RATES_HZ: Mapping[int, int] = {
    0: 1_000_000,
    1: 500_000,
    2: 250_000,
    3: 125_000,
    4: 100_000,
    5: 83_000,
    6: 71_000,
    7: 62_500,
}

#: DeviceNet attribute 126 BITRATE code -> Hz (000 chapter 3): codes 3 and 4 swapped against
#: REG_PARA1.  Only for translating a DeviceNet configuration; never used to decode REG_PARA1.
DEVICENET_BIT_RATES_HZ: Mapping[int, int] = {**BIT_RATES_HZ, 3: 100_000, 4: 125_000}

# field positions (Table 18)
_CODE_GRAY_BIT = 31
_FRAME_LEN_SHIFT, _FRAME_LEN_MASK = 24, 0x3F
_BIT_RATE_SHIFT, _BIT_RATE_MASK = 16, 0x0F
_MSB_SHIFT, _MSB_MASK = 12, 0x07
_LSB_SHIFT, _LSB_MASK = 8, 0x0F
_DIS_ERR_SSI_BIT = 5
#: every bit Table 18 marks X (reserved)
RESERVED_MASK = 0xFFFFFFFF & ~(
    (1 << _CODE_GRAY_BIT)
    | (_FRAME_LEN_MASK << _FRAME_LEN_SHIFT)
    | (_BIT_RATE_MASK << _BIT_RATE_SHIFT)
    | (_MSB_MASK << _MSB_SHIFT)
    | (_LSB_MASK << _LSB_SHIFT)
    | (1 << _DIS_ERR_SSI_BIT)
)


@dataclass(frozen=True)
class Para1:
    """The decoded fields of REG_PARA1 (000 Table 19); field names are the manual's."""

    #: SSI_FRAME_LEN: bits in the SSI frame, 1..32 (default 25)
    ssi_frame_len: int = 25
    #: SSI_BIT_RATE code 0..7 (default 1 = 500 kBit/s), see BIT_RATES_HZ
    ssi_bit_rate: int = 1
    #: INVALID_BITS_MSB 0..7: MSB-side bits zeroed by masking
    invalid_bits_msb: int = 0
    #: INVALID_BITS_LSB 0..15: LSB-side bits removed by shifting right
    invalid_bits_lsb: int = 0
    #: SSI_CODE_G/D: True = the encoder sends Gray code, False = binary
    ssi_code_gray: bool = False
    #: DIS_ERR_SSI: True = no ZERO test of the data line after the last bit
    dis_err_ssi: bool = False
    #: reserved (X) bits found set when decoding; an encoded set never has them
    reserved_bits: int = 0

    @classmethod
    def decode(cls, value: int) -> Para1:
        """Split a 32-bit REG_PARA1 value into its fields without validating them."""
        value &= 0xFFFFFFFF
        return cls(
            ssi_frame_len=(value >> _FRAME_LEN_SHIFT) & _FRAME_LEN_MASK,
            ssi_bit_rate=(value >> _BIT_RATE_SHIFT) & _BIT_RATE_MASK,
            invalid_bits_msb=(value >> _MSB_SHIFT) & _MSB_MASK,
            invalid_bits_lsb=(value >> _LSB_SHIFT) & _LSB_MASK,
            ssi_code_gray=bool(value >> _CODE_GRAY_BIT & 1),
            dis_err_ssi=bool(value >> _DIS_ERR_SSI_BIT & 1),
            reserved_bits=value & RESERVED_MASK,
        )

    def encode(self) -> int:
        """Pack the fields into the 32-bit REG_PARA1 value (reserved bits kept as decoded).

        :raises ValueError: a field does not fit its bits
        """
        fields = (
            (self.ssi_frame_len, _FRAME_LEN_MASK, "ssi_frame_len"),
            (self.ssi_bit_rate, _BIT_RATE_MASK, "ssi_bit_rate"),
            (self.invalid_bits_msb, _MSB_MASK, "invalid_bits_msb"),
            (self.invalid_bits_lsb, _LSB_MASK, "invalid_bits_lsb"),
        )
        for value, mask, name in fields:
            if not 0 <= value <= mask:
                raise ValueError(f"{name} = {value} does not fit its field (0..{mask})")
        return (
            (int(self.ssi_code_gray) << _CODE_GRAY_BIT)
            | (self.ssi_frame_len << _FRAME_LEN_SHIFT)
            | (self.ssi_bit_rate << _BIT_RATE_SHIFT)
            | (self.invalid_bits_msb << _MSB_SHIFT)
            | (self.invalid_bits_lsb << _LSB_SHIFT)
            | (int(self.dis_err_ssi) << _DIS_ERR_SSI_BIT)
            | (self.reserved_bits & RESERVED_MASK)
        )

    def problem(self) -> str | None:
        """Why the module would refuse this set with ERR_PARA = 1 (000 Table 19), or None."""
        if self.reserved_bits:
            return f"reserved bits 0x{self.reserved_bits:08X} must be 0 (000 Table 18)"
        if not 1 <= self.ssi_frame_len <= 32:
            return f"SSI_FRAME_LEN = {self.ssi_frame_len} must be 1..32"
        if self.ssi_bit_rate not in BIT_RATES_HZ:
            return f"SSI_BIT_RATE = {self.ssi_bit_rate} is reserved (valid 0..7)"
        invalid = self.invalid_bits_msb + self.invalid_bits_lsb
        if invalid >= self.ssi_frame_len:
            return (
                f"INVALID_BITS_MSB + INVALID_BITS_LSB = {invalid} "
                f"must be < SSI_FRAME_LEN = {self.ssi_frame_len}"
            )
        return None

    @property
    def bit_rate_hz(self) -> int:
        """Clock rate of SSI_BIT_RATE in Hz (000 Table 19); 0 for a reserved code."""
        return BIT_RATES_HZ.get(self.ssi_bit_rate, 0)

    @property
    def value_bits(self) -> int:
        """Meaningful word width: SSI_FRAME_LEN - INVALID_BITS_MSB - INVALID_BITS_LSB."""
        return max(self.ssi_frame_len - self.invalid_bits_msb - self.invalid_bits_lsb, 0)


def validate_para1(value: int) -> str | None:
    """Return why ``value`` is not an acceptable REG_PARA1 set, or None if it is valid."""
    if not 0 <= value <= 0xFFFFFFFF:
        return f"value {value} out of range 0..0xFFFFFFFF"
    return Para1.decode(value).problem()
