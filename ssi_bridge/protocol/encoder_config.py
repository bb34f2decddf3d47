"""Encoder configuration: scaling, code, frame layout, special bits and SSI timing.

One frozen dataclass describes any encoder the project simulates; the named presets in
``families.py`` fill it from 004 §3 (SICK families) and 001 §5 (TR programmable encoder).

Frame layout (MSB first on the wire)::

    | position area: field_bits (+ trailing_zero_bits) | special bits, in order | zero fill |

* ``Alignment.RIGHT``: value right-justified in ``data_bits`` (leading zeros, 001 §5.2.4.1).
* ``Alignment.LEFT``: value MSB-justified, non-assigned LSBs 0 (004 §3.1 AHS/AHM36).
* ``Alignment.TANNENBAUM``: ``turn_bits`` of revolutions right-justified, the rest of
  the field holds the step within the revolution MSB-justified (004 §3.4, Figures 17/18).
* ``shift_right`` drops the LSB of the position area and sends a 0 first (004 §3.4
  SSI-SHIFT-RIGHT); RIGHT with one ``trailing_zero_bits`` is "right aligned on the 24th bit".

The field on the wire (``field_bits``) is ``data_bits`` wide, except in the TR check sum
format: its field is always 28 bits while its Number of data bits is exactly what the total
number of steps needs (001 §5.2.1, §5.2.4.2).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from functools import cached_property

from ssi_bridge.protocol.codes import Code, bcd_encode
from ssi_bridge.protocol.family_rules import (TR_DATA_BITS, TR_DATA_BITS_WORDS, TR_FAMILIES,
                                              TR_PLAIN_FRAME_BITS, TR_PLAIN_FRAME_WORDS,
                                              code_refusal)
from ssi_bridge.exceptions import ConfigError


class Alignment(Enum):
    """Placement of the position value in the position area (004 §2.5, §3.1, §3.4)."""

    RIGHT = "right"
    LEFT = "left"
    TANNENBAUM = "tannenbaum"


class FrameFormat(Enum):
    """TR transmission format (001 §5.2.4)."""

    PLAIN = "no_special_format"
    REPEAT_26 = "26bit_repeat"
    #: 001 §5.2.4.2: a 28-bit field (12 revolutions + 16 steps) + 15 checksum bits, 43 clocks
    CHECKSUM = "check_sum"


class Negative(Enum):
    """Representation of negative values (001 §5.2.5)."""

    COMPLEMENT = "complement"
    SIGN_VALUE = "sign_value"


class SsiMode(Enum):
    """When the encoder forms the position it sends (004 §2.8)."""

    ASYNC = "asynchronous"
    SYNC = "synchronous"


class SyncReference(Enum):
    """Synchronous mode: what starts the position formation for the next burst.

    ``LATCH``: the first falling edge of the burst (004 §3.4 ATM60); ``BURST_END``: the end
    of the last clock plus ``sync_delay_s`` (004 §3.1 AHS/AHM36: 20 µs).
    """

    LATCH = "latch"
    BURST_END = "burst_end"


class ErrorOutput(Enum):
    """What the position area carries while an encoder error is active."""

    FLAGS = "flags"            #: position as usual, only the error bits are set (004 §2.3)
    ALL_ONES = "all_ones"      #: every bit 1, error bits set (004 §3.3 AFS/AFM60S Pro)
    ERROR_VALUE = "error_value"  #: a fixed error value, e.g. 0xFFFFE (004 §3.7 KH53)


class Direction(Enum):
    """Count direction, looking onto the flange (001 §5.1.1)."""

    INCREASING = "increasing"  #: position increases clockwise
    DECREASING = "decreasing"


class SpecialBit(Enum):
    """Error and special bits sent after the position bits (004 §3, 001 §5.5, 003 SB.2)."""

    ERROR = "error"                    #: AHS/AHM36, ATM60 general error bit
    ERRDIG = "errdig"                  #: AFS/AFM60 speed-related error
    ERRSI = "errsi"                    #: AFS/AFM60 light source error
    ERRSYNC = "errsync"                #: AFS/AFM60 contamination
    ERR_POSITION = "err_position"      #: ARS60 error bit 1
    ERR_SENDER = "err_sender"          #: ARS60 error bit 2
    ERR_DISTANCE = "err_distance"      #: TTK70 error bit 1 (head-tape distance)
    ERR_TEMPERATURE = "err_temperature"  #: TTK70 error bit 2
    POWER_FAIL = "power_fail"          #: 003: last data bit as PowerFail bit
    CAM1 = "cam1"
    CAM2 = "cam2"
    CAM3 = "cam3"
    CAM4 = "cam4"
    OVERSPEED = "overspeed"
    GOING_UP = "going_up"
    GOING_DOWN = "going_down"
    UP = "up"
    MOVING = "moving"
    ENCODER_ERROR = "encoder_error"
    DYNAMIC_ERROR = "dynamic_error"
    EVEN_PARITY = "even_parity"
    EVEN_ERROR_PARITY = "even_error_parity"
    TOGGLE = "toggle"
    ZERO = "zero"                      #: an always-0 filler bit ("Logical 0V")


#: special bits that report an encoder error (set by :meth:`SsiEncoder.set_error`)
ERROR_BITS = frozenset({
    SpecialBit.ERROR, SpecialBit.ERRDIG, SpecialBit.ERRSI, SpecialBit.ERRSYNC,
    SpecialBit.ERR_POSITION, SpecialBit.ERR_SENDER, SpecialBit.ERR_DISTANCE,
    SpecialBit.ERR_TEMPERATURE, SpecialBit.ENCODER_ERROR,
})
PARITY_BITS = frozenset({SpecialBit.EVEN_PARITY, SpecialBit.EVEN_ERROR_PARITY})
#: checksum bits after the 28-bit field of the TR "Check sum" format (001 §5.2.4.2)
CHECKSUM_BITS = 15
#: the "Check sum" format's field on the wire: 12 bits number of revolutions + 16 bits steps
#: per revolution, whatever the Number of data bits (001 §5.2.4.2)
CHECKSUM_TURN_BITS, CHECKSUM_FIELD_BITS = 12, 28
CAM_BITS = (SpecialBit.CAM1, SpecialBit.CAM2, SpecialBit.CAM3, SpecialBit.CAM4)


def round_half_up(x: float) -> int:
    """Round to the nearest integer, halves up: 001 §5.1.2.2 "rounded up or down".

    :param x: the value
    """
    return int(x + 0.5) if x >= 0 else -int(-x + 0.5)


@dataclass(frozen=True)
class EncoderConfig:
    """Everything that fixes the bits an encoder sends; validated on construction.

    A config named after a family (``families.py``) follows that family's manual
    (``family_rules.py``): only the transmit codes it offers, and for the TR encoders (and
    any TR frame format) 6..63 data bits (001 §5.2.1) and plain frames of 8..36 bits
    (001 §5.2.4.1). Raises ConfigError with the manual's words and section otherwise.
    """

    #: preset name (families.py) or "GENERIC"; any other name is a hand-made layout
    name: str = "GENERIC"
    #: linear measuring system (metres) instead of rotary (revolutions)
    linear: bool = False
    #: linear only: length of one step (m)
    measuring_step_m: float = 0.0
    #: rotary: measuring steps per revolution (may be decimal, 001 §5.1.2)
    steps_per_rev: float = 8192.0
    #: number of revolutions before the count restarts at 0, as a fraction (001 §5.1.2.2)
    revolutions_numerator: int = 4096
    revolutions_divisor: int = 1
    #: total number of steps; 0 = steps_per_rev * numerator / divisor, rounded (001 §5.1.2.2)
    total_steps: int = 0
    #: transmit code of the position value
    code: Code = Code.BINARY
    #: TR "Number of data bits" (001 §5.2.1): the width of the position field on the wire;
    #: in the check sum format exactly the bits the total number of steps needs, inside the
    #: format's fixed 28-bit field (:attr:`field_bits`, 001 §5.2.4.2)
    data_bits: int = 25
    alignment: Alignment = Alignment.RIGHT
    #: Tannenbaum only: width of the revolutions field (12 or 13, 004 §3.4)
    turn_bits: int = 12
    #: zero bits between the position field and the special bits
    trailing_zero_bits: int = 0
    #: 004 §3.4 SSI-SHIFT-RIGHT: position area shifted right by one, LSB lost
    shift_right: bool = False
    #: special / error bits after the position, first listed = first sent
    special_bits: tuple[SpecialBit, ...] = ()
    #: special bits sent active-low (001 §5.5; inverted parity = odd parity, §5.5.7)
    inverted_bits: frozenset[SpecialBit] = frozenset()
    frame_format: FrameFormat = FrameFormat.PLAIN
    direction: Direction = Direction.INCREASING
    #: value the preset function sets (001 §5.1.3)
    preset_value: int = 0
    #: start of counting: values run origin .. origin + total_steps - 1 (001 §5.1.5)
    origin: int = 0
    negative: Negative = Negative.COMPLEMENT
    error_output: ErrorOutput = ErrorOutput.FLAGS
    error_value: int = 0
    ssi_mode: SsiMode = SsiMode.ASYNC
    #: asynchronous mode: position formed every this many seconds; 0 = at the latch edge
    formation_period_s: float = 0.0
    sync_reference: SyncReference = SyncReference.LATCH
    sync_delay_s: float = 0.0
    #: minimum pause between bursts the encoder requires (sync mode, 004 §3.1/§3.4)
    min_pause_s: float = 0.0
    #: asynchronous mode: allowed pause jitter (0.2 = ±20 %) and maximum pause (004 §3.1)
    async_pause_tolerance: float | None = None
    async_max_pause_s: float | None = None
    #: most clocks per burst the encoder allows (TTK70: 31, 004 §3.6)
    max_clocks: int | None = None
    #: encoder monoflop time tm overriding the line's (ATM60 sync: 150/200 µs, 004 §3.4)
    monoflop_s: float | None = None
    #: cam switch (on, off) points in output steps, up to four (001 §5.4.1)
    cams: tuple[tuple[int, int], ...] = ()
    #: the speed monitor's threshold (1/min, 10..6000, 001 §5.4.2): above it the overspeed
    #: special bit is set (§5.5.2); no limit of the shaft
    overspeed_rpm: float = 6000.0
    #: going up/down cleared after this long without a step (001 §5.5.3: 50 ms)
    standstill_s: float = 0.05
    #: movement hysteresis in output steps (001 §5.5.3: one step)
    hysteresis_steps: int = 1
    #: accept a transmit code the family's manual does not name, for the families whose
    #: section names no code at all (004 §3.2, §3.3, §3.5-§3.7; family_rules.py); never
    #: against a list a manual gives
    code_outside_manual: bool = False
    extra: dict[str, str] = field(default_factory=dict, compare=False, hash=False)

    def __post_init__(self) -> None:
        def bad(msg: str) -> None:
            raise ConfigError(f"encoder {self.name}: {msg}")

        if self.linear and not self.measuring_step_m > 0:
            bad(f"linear encoder needs measuring_step_m > 0, got {self.measuring_step_m}")
        if not self.linear and not self.steps_per_rev > 0:
            bad(f"steps_per_rev {self.steps_per_rev} must be > 0")
        if not 1 <= self.revolutions_numerator <= 256000:
            bad(f"revolutions_numerator {self.revolutions_numerator} outside 1..256000 (001 §5.1.2.2)")
        if not 1 <= self.revolutions_divisor <= 16384:
            bad(f"revolutions_divisor {self.revolutions_divisor} outside 1..16384 (001 §5.1.2.2)")
        if not self.linear and self.revolutions_numerator < 0.5 * self.revolutions_divisor:
            bad("revolutions numerator/divisor must be >= 0.5 (001 §5.1.2.2)")
        if not 1 <= self.data_bits <= 64:
            bad(f"data_bits {self.data_bits} outside 1..64")
        if self.tr_rules and not TR_DATA_BITS[0] <= self.data_bits <= TR_DATA_BITS[1]:
            bad(f"data_bits {self.data_bits} outside {TR_DATA_BITS[0]}..{TR_DATA_BITS[1]}: "
                f"{TR_DATA_BITS_WORDS}")
        refusal = code_refusal(self.name, self.code, code_outside_manual=self.code_outside_manual)
        if refusal:
            bad(refusal)
        if self.range_steps < 2:
            bad(f"total number of steps {self.range_steps} must be >= 2 (001 §5.1.2.1)")
        if self.value_bits > self.data_bits:
            bad(f"values need {self.value_bits} bits but data_bits is {self.data_bits}")
        if self.alignment is Alignment.TANNENBAUM:
            spr = self.steps_per_rev
            if spr != int(spr) or int(spr) & (int(spr) - 1) or self.linear:
                bad("Tannenbaum format needs a binary (2**n) rotary resolution (004 §3.4)")
            if self.code not in (Code.BINARY, Code.GRAY):
                bad("Tannenbaum format sends binary or Gray only (004 §3.4)")
            if int(spr).bit_length() - 1 > self.field_bits - self.turn_bits:
                bad(f"{int(spr)} steps do not fit {self.field_bits - self.turn_bits} singleturn "
                    "bits")
            if self.range_steps > int(spr) << self.turn_bits:
                bad(f"{self.range_steps} steps need more than {self.turn_bits} revolution bits")
        if self.origin < 0 and self.alignment is not Alignment.RIGHT:
            bad("negative values (origin < 0) need right-justified output (001 §5.2.5)")
        if self.origin != 0 and self.code is Code.GRAY_EXCESS:
            bad("Gray-excess code needs origin 0 (004 §2.4)")
        named = [b for b in self.special_bits if b is not SpecialBit.ZERO]
        if len(set(named)) != len(named):
            bad("a special bit may appear only once (ZERO fillers excepted)")
        parity = [i for i, b in enumerate(self.special_bits) if b in PARITY_BITS]
        if len(parity) > 1 or (parity and parity[0] != len(self.special_bits) - 1):
            bad("only one parity bit, and it must be the last special bit (001 §5.5.7)")
        if len(self.cams) > 4:
            bad("at most four cams (001 §5.4.1)")
        if not 10 <= self.overspeed_rpm <= 6000:
            bad(f"overspeed_rpm {self.overspeed_rpm} outside 10..6000 (001 §5.4.2)")
        if self.frame_format is FrameFormat.REPEAT_26:
            if self.position_bits + len(self.special_bits) > 26:
                bad("26-bit + repeat: data bits + special bits must be <= 26 (001 §5.2.4.3)")
            if parity and self.position_bits + len(self.special_bits) != 26:
                bad("26-bit + repeat with parity: data + special bits must fill all 26 clocks")
            if len(self.special_bits) > 8:
                bad("at most 8 special bits (001 §5.5)")
        if self.frame_format is FrameFormat.CHECKSUM:
            self._check_checksum_format(bad)
        if self.frame_bits > 64:
            bad(f"frame of {self.frame_bits} bits exceeds 64")
        low, high = TR_PLAIN_FRAME_BITS
        if self.tr_rules and self.frame_format is FrameFormat.PLAIN \
                and not low <= self.frame_bits <= high:
            bad(f"a frame of {self.frame_bits} bits ({self.position_bits} data + "
                f"{len(self.special_bits)} special bits) outside {low}..{high}: "
                f"{TR_PLAIN_FRAME_WORDS}")
        if self.formation_period_s < 0 or self.min_pause_s < 0 or self.sync_delay_s < 0:
            bad("timing values must be >= 0")

    def _check_checksum_format(self, bad: Callable[[str], None]) -> None:
        """001 §5.2.4.2 / §5.2.1 rules of the "Check sum" format."""
        if self.linear or self.alignment is not Alignment.TANNENBAUM \
                or self.turn_bits != CHECKSUM_TURN_BITS:
            bad("check sum format: 12 bits revolutions + 16 bits steps per revolution "
                "(turn_bits 12, Tannenbaum placement; 001 §5.2.4.2)")
        if int(self.steps_per_rev) > 65536 or self.revolutions_numerator > 4096:
            bad("check sum format: at most 65536 steps x 4096 revolutions (001 §5.2.4.2)")
        if self.data_bits > CHECKSUM_FIELD_BITS:
            bad(f"check sum format: data_bits {self.data_bits}, but max. number of data bits "
                f"<= {CHECKSUM_FIELD_BITS} (001 §5.2.1)")
        if self.data_bits != self.value_bits:
            bad(f"check sum format: data_bits {self.data_bits}, but the total number of steps "
                f"{self.range_steps} needs exactly {self.value_bits}: 'the Number of data bits "
                "required for the programmed Total number of steps must be typed in exactly' "
                f"(001 §5.2.1, §5.2.4.2; the field on the wire is {CHECKSUM_FIELD_BITS} bits "
                "whatever the number)")
        if self.code is not Code.BINARY:
            bad("check sum format: the transmit code must be binary (001 §5.2.4.2)")
        if self.special_bits:
            bad("check sum format: no SSI special bits (001 §5.2.4.2 'ohne SSI-Sonderbits')")
        if self.trailing_zero_bits or self.shift_right or self.origin < 0:
            bad("check sum format: no trailing zeros, shift or negative values (001 §5.2.4.2)")

    # -- derived figures -------------------------------------------------------------
    @property
    def tr_rules(self) -> bool:
        """The TR limits of 001 §5.2 apply: a TR family, or a TR-only frame format."""
        return self.name.upper() in TR_FAMILIES or self.frame_format is not FrameFormat.PLAIN

    @cached_property
    def range_steps(self) -> int:
        """Total number of steps before the count restarts (001 §5.1.2.1)."""
        if self.total_steps:
            return self.total_steps
        if self.linear:
            return 1 << (self.data_bits - (1 if self.origin < 0 else 0))
        return round_half_up(self.steps_per_rev * self.revolutions_numerator
                             / self.revolutions_divisor)

    @cached_property
    def steps_per_unit(self) -> float:
        """Output steps per revolution (rounding spread over all revolutions) or per metre."""
        if self.linear:
            return 1.0 / self.measuring_step_m
        return self.range_steps * self.revolutions_divisor / self.revolutions_numerator

    @cached_property
    def value_bits(self) -> int:
        """Bits the value range needs in the chosen code, sign included (001 §5.2.5)."""
        top = max(self.origin + self.range_steps - 1, 1)
        low = -self.origin
        if self.origin >= 0:
            return 4 * len(str(top)) if self.code is Code.BCD else top.bit_length()
        if self.code is Code.BCD:
            if self.negative is Negative.COMPLEMENT:     # -10**d/2 .. 10**d/2 - 1
                return 4 * len(str(2 * max(low, top + 1) - 1))
            return bcd_encode(max(low, top)).bit_length() + 1
        if self.negative is Negative.COMPLEMENT:         # -2**(n-1) .. 2**(n-1) - 1
            return max(low - 1, top).bit_length() + 1
        return max(low, top).bit_length() + 1

    @property
    def field_bits(self) -> int:
        """Width of the position field on the wire: ``data_bits``, except in the check sum
        format, whose field is always 12 revolution + 16 step bits while its Number of data
        bits counts only the bits the total number of steps needs (001 §5.2.1, §5.2.4.2:
        4096 x 1024 steps = 22 data bits in the 28-bit field)."""
        if self.frame_format is FrameFormat.CHECKSUM:
            return CHECKSUM_FIELD_BITS
        return self.data_bits

    @property
    def position_bits(self) -> int:
        """Width of the position area: the field on the wire plus trailing zero bits."""
        return self.field_bits + self.trailing_zero_bits

    @property
    def frame_bits(self) -> int:
        """Number of bits the encoder sends per frame (clocks minus the pause-1 clock)."""
        if self.frame_format is FrameFormat.REPEAT_26:
            return 26
        if self.frame_format is FrameFormat.CHECKSUM:
            return self.position_bits + CHECKSUM_BITS
        return self.position_bits + len(self.special_bits)
