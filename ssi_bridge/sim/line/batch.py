"""Batch path: many bursts at once with numpy, bit by bit on the same edge schedule.

For replaying or benchmarking long runs: each burst is an independent latch (the pause
before it is assumed longer than tm, so no repeat bursts), the encoder must have no
stateful special bits (toggle, direction monitor, dynamic error, cams) and a frame of at
most 61 bits. The per-sample levels come from :meth:`SsiLine._schedule` (the same edge walk
as :meth:`SsiLine.read`), one column per master sample, so line faults still act per bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ssi_bridge.protocol.checksum import code_word
from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import (ERROR_BITS, Alignment, ErrorOutput, FrameFormat,
                                                SpecialBit)
from ssi_bridge.sim.encoder.encoder import SsiEncoder
from ssi_bridge.protocol.layout import encode_area
from ssi_bridge.sim.encoder.motion import ConstantVelocity, Sine, Still
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.sim.line.line import SsiLine

_CHUNK = 1 << 16
_STATELESS = ERROR_BITS | {SpecialBit.POWER_FAIL, SpecialBit.ZERO}


@dataclass(frozen=True)
class BatchReadout:
    """Per-burst arrays of what the master read (see :class:`LineReadout`)."""

    data: np.ndarray          #: uint64, n_bits data bits per burst, MSB first read
    start_bit: np.ndarray     #: uint8
    trailer_bit: np.ndarray   #: uint8


def _positions(enc: SsiEncoder, ts: np.ndarray) -> np.ndarray:
    m = enc.motion
    if isinstance(m, Still):
        return np.full(ts.shape, m.position(0.0))
    if isinstance(m, ConstantVelocity):
        return m.position(0.0) + m.velocity(0.0) * ts
    if isinstance(m, Sine):
        return m._off + m._a * np.sin(m._w * ts)   # noqa: SLF001 - same closed form
    return np.array([m.position(float(t)) for t in ts])


def _frames(enc: SsiEncoder, ts: np.ndarray) -> np.ndarray:
    """Frame bits of every latch in ``ts`` (uint64)."""
    cfg = enc.config
    if any(b not in _STATELESS for b in cfg.special_bits):
        raise ConfigError("batch path needs an encoder without stateful special bits")
    if cfg.frame_bits > 61:
        raise ConfigError(f"batch path handles frames up to 61 bits, not {cfg.frame_bits}")
    if cfg.formation_period_s > 0:
        p = cfg.formation_period_s
        ts = np.floor((ts - enc.phase_s) / p) * p + enc.phase_s
    pos = _positions(enc, ts)
    raw = np.floor(enc._sign * pos * cfg.steps_per_unit).astype(np.int64) + enc._offset  # noqa: SLF001
    value = cfg.origin + np.mod(raw - cfg.origin, cfg.range_steps)
    fast = (cfg.origin >= 0 and cfg.code in (Code.BINARY, Code.GRAY)
            and not cfg.shift_right)
    if fast:
        v = value.astype(np.uint64)
        if cfg.alignment is Alignment.TANNENBAUM:
            spr = int(cfg.steps_per_rev)
            field = cfg.field_bits - cfg.turn_bits
            st = spr.bit_length() - 1
            word = ((v >> np.uint64(st)) << np.uint64(field)) | \
                   ((v & np.uint64(spr - 1)) << np.uint64(field - st))
        elif cfg.alignment is Alignment.LEFT:
            word = v << np.uint64(cfg.field_bits - cfg.value_bits)
        else:
            word = v
        if cfg.code is Code.GRAY:
            word = word ^ (word >> np.uint64(1))
        area = word << np.uint64(cfg.trailing_zero_bits)
    else:
        area = np.array([encode_area(cfg, int(x)) for x in value], dtype=np.uint64)
    errors = enc.errors
    if errors and cfg.error_output is ErrorOutput.ALL_ONES:
        return np.full(ts.shape, (1 << cfg.frame_bits) - 1, dtype=np.uint64)
    if errors and cfg.error_output is ErrorOutput.ERROR_VALUE:
        area = np.full(ts.shape, cfg.error_value << cfg.trailing_zero_bits, dtype=np.uint64)
    if cfg.frame_format is FrameFormat.CHECKSUM:   # 28-bit field + 15 check sum bits
        return np.array([code_word(int(a)) for a in area], dtype=np.uint64)
    tail = 0
    for b in cfg.special_bits:
        lvl = 1 if (b in errors or (b is SpecialBit.POWER_FAIL and enc.power_failure)) else 0
        tail = (tail << 1) | (lvl ^ (1 if b in cfg.inverted_bits else 0))
    n_spec = len(cfg.special_bits)
    fill = cfg.frame_bits - cfg.position_bits - n_spec
    return ((area << np.uint64(n_spec)) | np.uint64(tail)) << np.uint64(fill)


def read_batch(line: SsiLine, times: np.ndarray, n_bits: int, bit_rate_hz: float,
               rng: np.random.Generator | None = None) -> BatchReadout:
    """Clock one burst of ``n_bits + 1`` clocks at each time in ``times``.

    :param line: the line to read (its encoder, cable and faults)
    :param times: the bursts' start times (s)
    :param n_bits: data bits per burst
    :param bit_rate_hz: the clock rate
    :param rng: the bit-noise source (default: one seeded with the line's ``seed``)
    """
    enc, faults = line.encoder, line.faults
    times = np.asarray(times, dtype=np.float64)
    length = enc.frame_bits
    sched = np.array(line._schedule(n_bits, 1.0 / bit_rate_hz, length), dtype=np.uint64)  # noqa: SLF001
    n_samples = n_bits + 2
    weights = np.arange(n_samples - 1, -1, -1, dtype=np.uint64)
    rng = rng or np.random.default_rng(line.config.seed)
    data = np.empty(times.shape, dtype=np.uint64)
    start = np.empty(times.shape, dtype=np.uint8)
    trailer = np.empty(times.shape, dtype=np.uint8)
    for lo in range(0, times.size, _CHUNK):
        ts = times[lo:lo + _CHUNK]
        if faults.clock_break:
            levels = np.ones((ts.size, n_samples), dtype=np.uint64)
        else:
            word = (np.uint64(1 << (length + 2)) | np.uint64(1 << (length + 1))
                    | (_frames(enc, ts) << np.uint64(1)))
            levels = (word[:, None] >> sched[None, :]) & np.uint64(1)
        if faults.data_break:
            levels[:] = line.config.broken_wire_level
        for idx, lvl in faults.stuck.items():
            if 0 <= idx < n_samples:
                levels[:, idx] = lvl & 1
        if faults.bit_error_rate > 0:
            levels ^= (rng.random(levels.shape) < faults.bit_error_rate).astype(np.uint64)
        samples = np.bitwise_or.reduce(levels << weights[None, :], axis=1)
        data[lo:lo + ts.size] = (samples >> np.uint64(1)) & np.uint64((1 << n_bits) - 1)
        start[lo:lo + ts.size] = (levels[:, 0]).astype(np.uint8)
        trailer[lo:lo + ts.size] = (levels[:, -1]).astype(np.uint8)
    return BatchReadout(data, start, trailer)
