"""The simulated SSI encoder: motion -> quantised, scaled value -> coded frame bits.

``SsiEncoder.frame_at(t)`` is what the encoder loads into its shift register at the first
falling clock edge ``t`` (004 §2.2 time 1, 001 §4.6 item 1). Which position that frame
carries depends on the SSI mode (004 §2.8):

* asynchronous: the position is formed every ``formation_period_s`` (125 µs AHS/AHM36,
  150 µs ATM60, 004 §3.1/§3.4) independent of the clock, so the frame carries the value
  formed at the last formation instant before ``t`` and two reads may return the same value;
  ``formation_period_s = 0`` idealises this to "formed at the latch edge";
* synchronous: the position is recorded at the first falling edge (``SyncReference.LATCH``,
  ATM60) or ``sync_delay_s`` after the end of the burst (``BURST_END``, AHS/AHM36), and
  "the position recorded at the last clock pulse chain is sent" (004 §3.4): each frame
  carries the position recorded for the previous burst (the very first one: the position at
  its own latch).

Scaling (001 §5.1.2): value = origin + ((⌊±pos · steps_per_unit⌋ + preset offset − origin)
mod total steps); the sign follows the count direction, inverted by the F/B input (§4.5).
"""

from __future__ import annotations

import logging
import math
from typing import Any, NamedTuple

from ssi_bridge.protocol.checksum import code_word
from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import (ERROR_BITS, PARITY_BITS, Alignment, Direction,
                                       EncoderConfig, ErrorOutput, FrameFormat, SpecialBit,
                                       SsiMode, SyncReference)
from ssi_bridge.protocol.layout import encode_area
from ssi_bridge.protocol.families import family_config
from ssi_bridge.sim.encoder.motion import MotionProfile, Still
from ssi_bridge.sim.encoder.special import SpecialState
from ssi_bridge.exceptions import ConfigError

__all__ = ["EncoderConfig", "EncoderFrame", "SsiEncoder", "make_encoder"]

logger = logging.getLogger(__name__)


class EncoderFrame(NamedTuple):
    """The frame an encoder latched, with the ground truth it was made from.

    A :class:`typing.NamedTuple` (immutable, built once per latch in the scalar hot path,
    where a frozen dataclass pays an ``object.__setattr__`` per field, docs/encoder_line.md
    "Performance"); use
    ``frame._replace(...)`` for a modified copy.
    """

    #: frame bits, first transmitted bit = most significant bit of ``bits``
    bits: int
    #: number of frame bits
    length: int
    #: output value encoded in the position bits (steps, may be negative, 001 §5.2.5)
    count: int  # type: ignore[assignment]  # the field shadows tuple.count on purpose
    #: ground truth position at the formation time (rev or m)
    position: float
    #: ground truth velocity at the formation time (rev/s or m/s)
    velocity: float = 0.0
    #: latch time (first falling clock edge) (s)
    latch_time: float = 0.0
    #: time the position was formed (s), earlier than the latch in async/sync modes
    sample_time: float = 0.0
    #: logically active special / error bits (before active-low inversion)
    flags: frozenset[SpecialBit] = frozenset()
    #: an encoder error was active
    error: bool = False
    #: the power-failure condition was active
    power_failure: bool = False


#: the flags of a frame without special bits (one shared empty set, not one per frame)
_NO_FLAGS: frozenset[SpecialBit] = frozenset()
#: builds a NamedTuple from its fields in declaration order without the generated
#: ``__new__`` (a Python-level call per frame); the result is the same object type
_tuple_new = tuple.__new__


def _plain_area_shift(cfg: EncoderConfig) -> int | None:
    """Shift that turns a value into its position area, when :func:`encode_area` is one.

    True for non-negative binary values right- or MSB-justified without SSI-SHIFT-RIGHT
    (001 §5.2.4.1, 004 §3.1): ``encode_area(cfg, v) == v << shift``. None otherwise
    (Gray, BCD, Gray-excess, Tannenbaum, negative values, shift right), which keep the
    general :func:`encode_area`.
    """
    if (cfg.origin < 0 or cfg.code is not Code.BINARY or cfg.shift_right
            or cfg.alignment is Alignment.TANNENBAUM):
        return None
    shift = cfg.field_bits - cfg.value_bits if cfg.alignment is Alignment.LEFT else 0
    return shift + cfg.trailing_zero_bits


class SsiEncoder:
    """An absolute encoder with an SSI output, driven by a motion profile.

    :param config: its layout, scaling and timing
    :param motion: the shaft's motion (the ground truth)
    """

    def __init__(self, config: EncoderConfig, motion: MotionProfile) -> None:
        self.config = config
        self.motion = motion
        self._offset = 0
        self._fb_input = False
        self._sign = 1 if config.direction is Direction.INCREASING else -1
        self._errors: frozenset[SpecialBit] = frozenset()
        self.power_failure = False
        #: asynchronous mode: time of one formation instant (s); formation every period
        self.phase_s = 0.0
        self._sync_next: float | None = None
        self._special = SpecialState(config) if config.special_bits else None
        self._mask = (1 << config.frame_bits) - 1
        self._layout_bits = frozenset(config.special_bits)
        self._frame_bits = config.frame_bits
        self._fill = config.frame_bits - config.position_bits
        # per-config constants of the hot path (frame_at runs once per latch); the config
        # is frozen, so they are computed once here instead of on every frame
        self._sync = config.ssi_mode is SsiMode.SYNC
        self._sync_burst_end = self._sync and config.sync_reference is SyncReference.BURST_END
        self._period = config.formation_period_s
        self._origin = config.origin
        self._range = config.range_steps
        self._steps_per_unit = config.steps_per_unit
        self._flags_on_error = config.error_output is ErrorOutput.FLAGS
        self._area_shift = _plain_area_shift(config)
        #: TR "Check sum" format: the 28 data bits are followed by their checksum (001 §5.2.4.2)
        self._checksum = config.frame_format is FrameFormat.CHECKSUM
        #: frame = value << this, for a plain binary area and no special bits; else None
        self._plain_shift = (self._area_shift + self._fill
                             if self._area_shift is not None and self._special is None else None)

    # -- description --------------------------------------------------------------------
    @property
    def frame_bits(self) -> int:
        """Bits per frame (the master clocks ``frame_bits + 1``, 001 §4.6)."""
        return self.config.frame_bits

    @property
    def steps_per_rev(self) -> float:
        """Output steps per revolution (per metre for a linear encoder)."""
        return self.config.steps_per_unit

    @property
    def revolutions(self) -> float:
        """Revolutions before the count restarts (numerator / divisor, 001 §5.1.2.2)."""
        return self.config.revolutions_numerator / self.config.revolutions_divisor

    @property
    def linear(self) -> bool:
        """Whether the encoder measures a length (m) rather than an angle (rev)."""
        return self.config.linear

    @property
    def measuring_step_m(self) -> float:
        """The length of one step of a linear encoder (m)."""
        return self.config.measuring_step_m

    # -- inputs and faults --------------------------------------------------------------
    @property
    def fb_input(self) -> bool:
        """F/B input (001 §4.5): when active, the set count direction is inverted."""
        return self._fb_input

    @fb_input.setter
    def fb_input(self, active: bool) -> None:
        self._fb_input = bool(active)
        base = 1 if self.config.direction is Direction.INCREASING else -1
        self._sign = -base if self._fb_input else base

    @property
    def errors(self) -> frozenset[SpecialBit]:
        """Encoder error bits currently active."""
        return self._errors

    def set_error(self, active: bool = True, bits: set[SpecialBit] | None = None) -> None:
        """Raise or clear encoder errors; ``bits=None`` means every error bit of the layout.

        A layout without error bits still records the error (it shows as ERROR_VALUE or
        ALL_ONES where the family does that, 004 §3.3/§3.7).

        :param active: raise (True) or clear (False)
        :param bits: which error bits
        """
        if bits is None:
            bits = {b for b in self.config.special_bits if b in ERROR_BITS} or {SpecialBit.ERROR}
        self._errors = (self._errors | frozenset(bits)) if active else (self._errors - frozenset(bits))
        logger.debug("encoder %s errors now %s", self.config.name, sorted(b.value for b in self._errors))

    def apply_preset(self, t: float, value: int | None = None) -> int:
        """Preset adjustment (001 §5.1.3/§5.1.4): the value at ``t`` becomes ``value``.

        Only the zero point moves (an integer offset), so the speed does not jump.
        Returns the new offset in steps.

        :raises ConfigError: ``value`` outside the encoder's range
        """
        cfg = self.config
        value = cfg.preset_value if value is None else value
        if not cfg.origin <= value < cfg.origin + cfg.range_steps:
            raise ConfigError(f"encoder {cfg.name}: preset {value} outside "
                              f"{cfg.origin}..{cfg.origin + cfg.range_steps - 1} (001 §5.1.3)")
        raw = math.floor(self._sign * self.motion.position(t) * cfg.steps_per_unit)
        self._offset = value - raw
        return self._offset

    # -- the data path ------------------------------------------------------------------
    def value_at(self, position: float) -> int:
        """Output value for a ground-truth position (rev or m), 001 §5.1.2."""
        origin = self._origin
        raw = math.floor(self._sign * position * self._steps_per_unit) + self._offset
        return origin + (raw - origin) % self._range

    def sample_time(self, t: float) -> float:
        """Formation time of the value a latch at ``t`` loads (004 §2.8, §3.1, §3.4)."""
        cfg = self.config
        if cfg.ssi_mode is SsiMode.SYNC:
            ts = t if self._sync_next is None else self._sync_next
            if cfg.sync_reference is SyncReference.LATCH:
                self._sync_next = t + cfg.sync_delay_s
            return ts
        period = cfg.formation_period_s
        if period > 0.0:
            return math.floor((t - self.phase_s) / period) * period + self.phase_s
        return t

    def end_burst(self, t_end: float) -> None:
        """The master's last clock ended at ``t_end`` (sync mode, 004 §3.1: +20 µs)."""
        if self._sync_burst_end:
            self._sync_next = t_end + self.config.sync_delay_s

    def frame_at(self, t: float) -> EncoderFrame:
        """Latch at ``t``: form (or reuse) the position and assemble the frame bits.

        The hot path of the scalar line (once per latch): :meth:`sample_time` and
        :meth:`value_at` are inlined for the asynchronous modes, and a plain binary layout
        places the value with one shift instead of :func:`encode_area` (same bits).
        """
        if self._sync:
            ts = self.sample_time(t)
        elif self._period > 0.0:
            period = self._period
            ts = math.floor((t - self.phase_s) / period) * period + self.phase_s
        else:
            ts = t
        motion = self.motion
        pos = motion.position(ts)
        origin = self._origin
        value = origin + (math.floor(self._sign * pos * self._steps_per_unit) + self._offset
                          - origin) % self._range
        errors = self._errors
        shift = self._plain_shift
        if shift is not None and not errors:
            # plain binary frame without special bits (GENERIC): the value shifted is the frame
            return _tuple_new(EncoderFrame, (value << shift, self._frame_bits, value, pos,
                                             motion.velocity(ts), t, ts, _NO_FLAGS, False,
                                             self.power_failure))
        cfg = self.config
        if errors and not self._flags_on_error:
            if cfg.error_output is ErrorOutput.ALL_ONES:
                area = (1 << cfg.position_bits) - 1
            else:
                area = cfg.error_value << cfg.trailing_zero_bits
        elif self._area_shift is not None:
            area = value << self._area_shift
        else:
            area = encode_area(cfg, value)
        special = self._special
        if special is None:
            bits = code_word(area) if self._checksum else area << self._fill
            return EncoderFrame(bits, self._frame_bits,
                                value, pos, motion.velocity(ts), t, ts, _NO_FLAGS,
                                bool(errors), self.power_failure)
        vel = motion.velocity(ts)
        speed_rps = vel if not cfg.linear else 0.0
        active = special.active(ts, value, speed_rps, errors, self.power_failure)
        frame = area
        inverted = cfg.inverted_bits
        for bit in cfg.special_bits:
            if bit in PARITY_BITS:
                level = bin(frame).count("1") & 1
                if bit is SpecialBit.EVEN_ERROR_PARITY and errors:
                    level ^= 1
                if level:
                    active.add(bit)
            else:
                level = 1 if bit in active else 0
            if bit in inverted:
                level ^= 1
            frame = (frame << 1) | level
        frame <<= cfg.frame_bits - cfg.position_bits - len(cfg.special_bits)
        if errors and cfg.error_output is ErrorOutput.ALL_ONES:
            frame = self._mask
        flags = frozenset(b for b in active if b in self._layout_bits)
        return EncoderFrame(frame, cfg.frame_bits, value, pos, vel, t, ts, flags,
                            bool(errors), self.power_failure)


def make_encoder(family: str, motion: MotionProfile | None = None, **overrides: Any) -> SsiEncoder:
    """An :class:`SsiEncoder` of a named family driven by ``motion`` (default: at rest).

    :param family: the preset's name
    :param overrides: :class:`EncoderConfig` fields to change (``family_config``)
    :raises ConfigError: an unknown family or overrides that make no valid configuration
    """
    return SsiEncoder(family_config(family, **overrides), motion or Still())
