"""The SSI line: clock burst, encoder shift register, monoflop, cable delay and faults.

One :meth:`SsiLine.read` is one clock burst of ``n_bits + 1`` clocks (001 §4.6), modelled
edge by edge (004 §2.2, Figure 2; 001 §4.6, Figure 4):

* falling edge k at ``t + k·T``: the first one latches the encoder value into its shift
  register and sets the monoflop; every falling edge retriggers it for ``tm``;
* rising edge k at ``t + k·T + T/2``: the master samples the data line, then the encoder
  shifts out its next bit; that bit reaches the master after the delay ``tv`` (encoder +
  cable round trip), so with ``tv < T`` the master reads, at edge k, the bit shifted at
  edge k - 1: edge 0 reads the idle "pause 1", edges 1..n the frame MSB first;
* the trailer sample one period after the last edge is the ZERO test: while the monoflop
  holds the line low it reads 0; clocks beyond the encoder's frame shift out 0 (004 §3.6);
* when the monoflop has run out the encoder releases the line to the idle level (high),
  and a burst starting while it still runs gets the latched word again (multiple
  transmission, 003; 26-bit + repeat, 001 §5.2.4.3) while the line is still low.

Faults act on the levels (``line.faults``): data wire break (the master reads LOW, 003
SB.0), clock wire break (the encoder sees no edges: no latch, no shifting, line idle high,
so the frame is not terminated with zero, 003 SB.1), stuck samples and random bit errors.
"""

from __future__ import annotations

import logging
import math
import random
from collections.abc import Callable
from operator import itemgetter
from dataclasses import dataclass, field
from typing import NamedTuple

from ssi_bridge.protocol.encoder_config import FrameFormat, SsiMode
from ssi_bridge.sim.encoder.encoder import EncoderFrame, SsiEncoder
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.decode import MasterStatus, check_readout, decode_frame
from ssi_bridge.protocol.readout import LineReadout
from ssi_bridge.sim.line.timing import data_delay, pause_warnings, static_warnings

__all__ = ["LineConfig", "LineFaults", "SsiLine", "decode_frame", "check_readout",
           "MasterStatus"]

logger = logging.getLogger(__name__)

#: builds the :class:`LineReadout` NamedTuple from its fields in declaration order, without
#: the generated ``__new__`` (a Python-level call per burst); same type, same fields
_tuple_new = tuple.__new__


@dataclass(frozen=True)
class LineConfig:
    """Physical line and encoder interface timing."""

    #: cable length (m): sets the delay tv and the 004 §2.7 bit-rate check
    cable_length_m: float = 10.0
    #: encoder monoflop time tm (s): 15..25 µs SICK (004 §2.2), 9..41 µs TR (001 §5.2.3)
    monoflop_s: float = 20e-6
    #: level the master reads on an open data input (003 SB.0: LOW)
    broken_wire_level: int = 0
    #: data delay tv (s); None = 100 ns + 2 × 5 ns/m × cable length
    delay_s: float | None = None
    #: warn when the bit rate is not below the 004 §2.7 recommendation
    check_cable_table: bool = True
    #: seed of the random bit-error generator (reproducible noise)
    seed: int | None = 0

    def __post_init__(self) -> None:
        if self.cable_length_m < 0:
            raise ConfigError(f"cable_length_m {self.cable_length_m} must be >= 0")
        if not 1e-6 <= self.monoflop_s <= 1e-3:
            raise ConfigError(f"monoflop_s {self.monoflop_s} outside 1 us..1 ms")
        if self.broken_wire_level not in (0, 1):
            raise ConfigError("broken_wire_level must be 0 or 1")
        if self.delay_s is not None and self.delay_s <= 0:
            raise ConfigError(f"delay_s {self.delay_s} must be > 0")

    @property
    def tv(self) -> float:
        """The data line's delay (s): ``delay_s`` when given, else the cable's (``data_delay``)."""
        return self.delay_s if self.delay_s is not None else data_delay(self.cable_length_m)


@dataclass
class LineFaults:
    """Faults injected on the line; ``stuck`` maps a sample index to a level.

    Sample 0 is the pause-1 sample, 1..n the data bits (1 = MSB), n + 1 the ZERO-test
    sample.
    """

    data_break: bool = False
    clock_break: bool = False
    stuck: dict[int, int] = field(default_factory=dict)
    #: probability that any sampled level is inverted (noise)
    bit_error_rate: float = 0.0

    def clear(self) -> None:
        """Remove every fault of the line."""
        self.data_break = self.clock_break = False
        self.stuck.clear()
        self.bit_error_rate = 0.0

    @property
    def active(self) -> bool:
        """Whether any fault is in force."""
        return self.data_break or self.clock_break or bool(self.stuck) or self.bit_error_rate > 0


class _Burst(NamedTuple):
    """Constants of one burst shape ``(n_bits, bit rate)``, computed on its first read.

    ``const``, ``initial``, ``full`` and ``runs`` turn the cached edge schedule
    (:meth:`SsiLine._schedule`) into integer operations on the frame bits: the bits of
    ``const`` are samples that see the idle-high level, those of ``initial`` the level before
    the first shift (high, low inside a repeat); ``runs`` copy consecutive frame bits
    ``(source shift, width mask, destination shift)`` and ``full`` is the destination shift
    when one run copies the whole frame (the usual case: lag 1, tm longer than the burst).
    """

    #: half a clock period (s)
    half: float
    #: first to last falling edge, ``(clocks - 1) * period`` (s)
    span: float
    #: clocks per burst, ``n_bits + 1``
    clocks: int
    #: mask of the ``n_bits`` data bits
    data_mask: int
    #: warnings that depend only on the configuration and the burst shape
    static: tuple[str, ...]
    #: frame length the placement below was computed for
    length: int
    const: int
    initial: int
    full: int | None
    runs: tuple[tuple[int, int, int], ...]


class SsiLine:
    """An encoder at the end of a cable, read by bursts of clocks (an ``SsiReader``).

    :param encoder: the encoder at the far end
    :param config: cable, delay and monoflop (default: :class:`LineConfig`'s)
    """

    def __init__(self, encoder: SsiEncoder, config: LineConfig | None = None) -> None:
        self.encoder = encoder
        self.config = config or LineConfig()
        self.faults = LineFaults()
        self._rng = random.Random(self.config.seed)
        self._tm = encoder.config.monoflop_s or self.config.monoflop_s
        self._repeat_once = encoder.config.frame_format is FrameFormat.REPEAT_26
        self._mono_until = -math.inf
        self._latched: EncoderFrame | None = None
        self._repeats = 0
        self._last_end: float | None = None
        self._last_pause: float | None = None
        self._bursts: dict[tuple[int, float], _Burst] = {}
        self._two_tm = 2.0 * self._tm
        self._schedules: dict[tuple[int, float, int], tuple[int, ...]] = {}
        self._pickers: dict[tuple[int, float, int], Callable[[str], tuple[str, ...]]] = {}
        ecfg = encoder.config
        self._pause_rules = (ecfg.ssi_mode is SsiMode.SYNC or ecfg.async_max_pause_s is not None
                             or ecfg.async_pause_tolerance is not None)
        #: the frame the encoder latched for the last burst (None after a clock break)
        self.last_frame: EncoderFrame | None = None
        #: bursts read and values latched (repeat bursts latch nothing)
        self.bursts = 0
        self.latches = 0

    @property
    def monoflop_s(self) -> float:
        """tm in effect: the encoder's own (ATM60 sync) or the line's."""
        return self._tm

    def read(self, t: float, n_bits: int, bit_rate_hz: float, *,
             expect_repeat: bool = False) -> LineReadout:
        """Clock ``n_bits + 1`` clocks from ``t`` (first falling edge) at ``bit_rate_hz``.

        ``expect_repeat`` marks a deliberate repeat burst inside tm (multiple transmission):
        its short pause is then not reported and not used for the async pause check.

        This is the scalar hot path: everything that depends only on the burst shape (the
        timing figures, the static warnings, where each schedule level goes in the sample
        word) comes from :meth:`_burst`, cached on the first read of that shape.
        """
        burst = self._bursts.get((n_bits, bit_rate_hz))
        if burst is None:
            burst = self._burst(n_bits, bit_rate_hz)
        half, span, clocks, data_mask, warnings, length, const, initial, full, runs = burst
        faults = self.faults
        last_end = self._last_end
        if last_end is not None and not expect_repeat:
            pause = t - last_end
            if self._pause_rules or pause < self._two_tm:
                extra = pause_warnings(self.encoder.config, pause, self._last_pause, self._tm)
                if extra:
                    warnings += tuple(extra)
            self._last_pause = pause
        self.bursts += 1
        clock_ok = not faults.clock_break
        line_low = t < self._mono_until           # monoflop of the previous burst running
        if clock_ok:
            latched = self._latched
            if line_low and latched is not None and not (self._repeat_once and self._repeats):
                self._repeats += 1                 # same word again, no new latch
            else:
                latched = self.encoder.frame_at(t)
                self._latched = latched
                self._repeats = 0
                self.latches += 1
            self.last_frame = latched
            bits = latched.bits
            if latched.length == length and not bits >> length:   # 0 <= bits < 2**length
                # place the levels the schedule names with integer operations
                if full is not None:
                    samples = const | (bits << full)
                else:
                    samples = const
                    for src, mask, dst in runs:
                        samples |= ((bits >> src) & mask) << dst
                if not line_low:
                    samples |= initial
            else:                                  # a word wider than its frame: by string
                samples = self._pick_samples(latched, n_bits, 1.0 / bit_rate_hz,
                                             0 if line_low else 1)
        else:
            self.last_frame = None
            samples = (1 << (clocks + 1)) - 1      # encoder never clocked: idle high
        if faults.data_break or not clock_ok or faults.stuck or faults.bit_error_rate > 0:
            samples = self._apply_faults(samples, clocks + 1)
        last_fall = t + span
        end_time = last_fall + half
        if clock_ok:
            self._mono_until = last_fall + self._tm
            self.encoder.end_burst(end_time)
        self._last_end = end_time
        return _tuple_new(LineReadout, (t, n_bits, (samples >> 1) & data_mask,
                                        samples >> clocks, samples & 1, end_time, warnings))

    def _burst(self, n_bits: int, bit_rate_hz: float) -> _Burst:
        """Validate a burst shape and cache its constants (logs its static warnings once)."""
        if n_bits < 1 or bit_rate_hz <= 0:
            raise ConfigError(f"burst of {n_bits} bits at {bit_rate_hz} Hz is not possible")
        cfg, tm = self.config, self._tm
        period = 1.0 / bit_rate_hz
        clocks = n_bits + 1
        static = static_warnings(self.encoder.config, cfg.cable_length_m, tm, cfg.tv,
                                 n_bits, bit_rate_hz, cfg.check_cable_table)
        for w in static:
            logger.warning("SSI line: %s", w)
        length = self.encoder.frame_bits
        sched = self._schedule(n_bits, period, length)
        n_samples = clocks + 1
        const = initial = 0
        runs: list[tuple[int, int, int]] = []
        k = 0
        while k < n_samples:
            src, pos = sched[k], n_samples - 1 - k
            if src == length + 2:
                initial |= 1 << pos
            elif src == length + 1:
                const |= 1 << pos
            elif src > 0:                          # frame bit src - 1: extend the run
                m = 1
                while k + m < n_samples and sched[k + m] == src - m >= 1:
                    m += 1
                runs.append((src - m, (1 << m) - 1, pos - m + 1))
                k += m
                continue
            k += 1
        full = runs[0][2] if len(runs) == 1 and runs[0][:2] == (0, (1 << length) - 1) else None
        burst = _Burst(0.5 * period, (clocks - 1) * period, clocks, (1 << n_bits) - 1,
                       static, length, const, initial, full, tuple(runs))
        self._bursts[(n_bits, bit_rate_hz)] = burst
        return burst

    def _pick_samples(self, frame: EncoderFrame, n_bits: int, period: float,
                      initial: int) -> int:
        """Sample word by picking characters of the extended word's binary string.

        The general form of the integer placement in :meth:`read`, kept for a frame whose
        bits do not fit its length (e.g. an error value wider than the position area).
        """
        length = frame.length
        word = (initial << (length + 2)) | (1 << (length + 1)) | (frame.bits << 1)
        pick = self._picker(n_bits, period, length)
        return int("".join(pick(format(word, self._fmt(length)))), 2)

    @staticmethod
    def _fmt(length: int) -> str:
        return f"0{length + 3}b"

    def _picker(self, n_bits: int, period: float, length: int) -> Callable[[str], tuple[str, ...]]:
        """Per-sample selector over the extended word's binary string (from the schedule)."""
        key = (n_bits, period, length)
        pick = self._pickers.get(key)
        if pick is None:
            idx = [length + 2 - shift for shift in self._schedule(n_bits, period, length)]
            pick = itemgetter(*idx)
            self._pickers[key] = pick
        return pick

    def _schedule(self, n_bits: int, period: float, length: int) -> tuple[int, ...]:
        """Which level the master samples at each clock, from the edge timing (cached).

        Walks the edges of one burst: at rising edge k the master samples the line, then
        the encoder shifts its next bit, which arrives ``lag`` edges later (``tv``); the
        monoflop (retriggered at each falling edge) releases the line to idle high after
        ``tm``. The result names, per sample, a bit of the extended word built in
        :meth:`read`: ``length + 2`` = level before the first shift (idle high, or low
        inside a repeat), ``length + 1`` = idle high, ``length - j`` = frame bit j (MSB
        first), 0 = a clock beyond the frame (the encoder shifts out 0, 004 §3.6).
        """
        key = (n_bits, period, length)
        sched = self._schedules.get(key)
        if sched is not None:
            return sched
        tm, clocks, half = self._tm, n_bits + 1, 0.5 * period
        lag = max(1, math.ceil(self.config.tv / period - 1e-9))
        out: list[int] = []
        shifted: list[int] = []                  # source of the level after shift j
        for k in range(clocks + 1):
            sample_t = k * period + half         # relative to the first falling edge
            last_fall = min(k, clocks - 1) * period
            j = k - lag
            if j < 0:
                out.append(length + 2)
            elif sample_t >= last_fall + tm:
                out.append(length + 1)           # monoflop ran out: line idle high
            else:
                out.append(shifted[j])
            if k < clocks:                       # rising edge k: encoder shifts bit k
                shifted.append(length - k if k < length else 0)
        sched = tuple(out)
        self._schedules[key] = sched
        return sched

    def _apply_faults(self, samples: int, n_samples: int) -> int:
        """Per-sample faults: broken data wire, stuck samples, random bit errors."""
        faults = self.faults
        if faults.data_break:
            lvl = self.config.broken_wire_level
            samples = ((1 << n_samples) - 1) if lvl else 0
        for index, lvl in faults.stuck.items():
            if 0 <= index < n_samples:
                pos = n_samples - 1 - index
                samples = (samples & ~(1 << pos)) | ((lvl & 1) << pos)
        rate = faults.bit_error_rate
        if rate > 0.0:
            rnd = self._rng.random
            for pos in range(n_samples):
                if rnd() < rate:
                    samples ^= 1 << pos
        return samples

    def read_status(self, t: float, n_bits: int, bit_rate_hz: float
                    ) -> tuple[LineReadout, MasterStatus]:
        """Read and evaluate with the default master checks (ZERO test on).

        :param t: the burst's start (s)
        :param n_bits: data bits
        :param bit_rate_hz: the clock rate
        """
        r = self.read(t, n_bits, bit_rate_hz)
        return r, check_readout(r)
