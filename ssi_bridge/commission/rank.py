"""Which encoder families of the manuals send the frames a module clocked, best fit first.

Every family preset (``protocol/families.py``: 004 §3, 001 §5, 003) is laid out at its default
resolution and at the binary resolutions around it (the resolutions a joint's
``steps_per_rev`` can express); a layout fits when (rules, with their
sections, in docs/commissioning.md):

1. its frame is SSI_FRAME_LEN bits long (000 Table 19), or shorter where the manual lets the
   module clock more (TTK70: extra clocks read 0, 004 §3.6), or longer than the 32 bits the
   module can read (the TR check sum frame, 001 §5.2.4.2, is read in its first 32 bits);
2. no bit is ever 1 where the layout sends a filler 0, and no bit moves outside its position
   field and its check bits (004 §2.3, 001 §5.5);
3. its position LSB is the lowest moving bit, when the encoder moved (a moving binary value
   toggles its LSB every step, a Gray one every second step, 004 §2.4);
4. a parity bit it has is even parity of the frame in every sample (001 §5.5.7);
5. the family's manual offers the code the frames show (``protocol/family_rules.py``);
6. every decoded position lies in its range.

Families whose best layouts score alike are tied: the frame cannot tell them apart.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from ssi_bridge.commission.infer import BitStats, Motion, MotionState, bit_list
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.decode import XN_MAX_FRAME_BITS
from ssi_bridge.protocol.encoder_config import (CHECKSUM_BITS, PARITY_BITS, Alignment,
                                                EncoderConfig, FrameFormat, SpecialBit)
from ssi_bridge.protocol.families import FAMILIES, family_config
from ssi_bridge.protocol.layout import encode_area

#: aliases of another preset (the same Family object): ranked once, under the first name
ALIASES = {"ATM90": "ATM60"}
#: special bits that may change between frames without an error (001 §5.5)
MOVABLE_SPECIALS = PARITY_BITS | {SpecialBit.TOGGLE, SpecialBit.GOING_UP, SpecialBit.GOING_DOWN,
                                  SpecialBit.UP, SpecialBit.MOVING, SpecialBit.CAM1,
                                  SpecialBit.CAM2, SpecialBit.CAM3, SpecialBit.CAM4}
#: binary resolutions (bits per revolution) tried around a family's default
RESOLUTION_BITS = range(8, 21)


@dataclass(frozen=True)
class Layout:
    """Where a layout puts its bits in the module's frame (bit 0 = last clocked)."""

    #: bits the position value may occupy
    value: int
    #: bits that may be 1 at all (value, special and check bits)
    allowed: int
    #: bits that may change between frames
    movable: int
    #: position of each named special bit
    specials: dict[SpecialBit, int]
    #: frame bit of the value's LSB (-1: cut off)
    lsb: int
    #: module clocks minus encoder bits
    shift: int


def layout_of(cfg: EncoderConfig, frame_len: int) -> Layout:
    """The masks of ``cfg``'s frame as a module clocking ``frame_len`` bits sees them."""
    binary = cfg if cfg.code is Code.BINARY else replace(cfg, code=Code.BINARY)
    area = 0
    top = binary.range_steps - 1 + binary.origin
    for k in range(max(top, 1).bit_length()):
        area |= encode_area(binary, 1 << k) if (1 << k) <= top else 0
    tail = cfg.frame_bits - cfg.position_bits
    value = area << tail
    specials: dict[SpecialBit, int] = {}
    allowed, movable = value, value
    if cfg.frame_format is FrameFormat.CHECKSUM:
        check = ((1 << CHECKSUM_BITS) - 1)
        allowed |= check
        movable |= check
    for i, bit in enumerate(cfg.special_bits):
        pos = tail - 1 - i
        if bit is SpecialBit.ZERO:
            continue
        specials[bit] = pos
        allowed |= 1 << pos
        if bit in MOVABLE_SPECIALS:
            movable |= 1 << pos
    shift = frame_len - cfg.frame_bits

    def moved(mask: int) -> int:
        return (mask << shift if shift >= 0 else mask >> -shift) & ((1 << frame_len) - 1)

    v = moved(value)
    lsb = (v & -v).bit_length() - 1 if v else -1
    return Layout(v, moved(allowed), moved(movable),
                  {b: p + shift for b, p in specials.items() if 0 <= p + shift < frame_len},
                  lsb, shift)


@dataclass(frozen=True)
class Fit:
    """One family's best layout for the frames: score, overrides, the reasons."""

    family: str
    score: int
    #: EncoderConfig overrides of family_config (and the joint parameters they are)
    overrides: dict[str, Any]
    config: EncoderConfig
    evidence: tuple[str, ...]
    #: the manual's section (Family.doc)
    source: str
    #: the resolution is the family's default, not seen in the frame
    default_resolution: bool


def _candidates(family: str, code: str | None) -> list[tuple[dict[str, Any],
                                                                             EncoderConfig]]:
    base = family_config(family)
    code_over: dict[str, Any] = {}
    if code is not None and base.code.value != code:
        code_over = {"code": Code(code)}
    options: list[dict[str, Any]] = [{}]
    if not base.linear:
        options += [{"steps_per_rev": float(1 << k)} for k in RESOLUTION_BITS
                    if (1 << k) != base.steps_per_rev]
    out = []
    for opt in options:
        try:
            out.append(({**opt, **code_over}, family_config(family, **opt, **code_over)))
        except (ConfigError, ValueError):
            continue
    return out


def _score(cfg: EncoderConfig, frame_len: int, stats: BitStats,
           motion: Motion) -> tuple[int, list[str]] | None:
    """Score of a layout, with the evidence; None when the frames rule it out."""
    f = cfg.frame_bits
    if f > frame_len and (f <= XN_MAX_FRAME_BITS or frame_len != XN_MAX_FRAME_BITS):
        return None
    if f < frame_len and not (cfg.max_clocks and frame_len <= cfg.max_clocks):
        return None
    lay = layout_of(cfg, frame_len)
    if stats.ones & ~lay.allowed:
        return None
    if (stats.moving & ~motion.parity & ~motion.check) & ~lay.value:
        return None
    if (motion.parity | motion.check) & ~lay.movable:
        return None
    score, ev = 0, []
    if f == frame_len:
        score += 2
        ev.append(f"{f} bits = SSI_FRAME_LEN")
    elif f < frame_len:
        score += 1
        ev.append(f"{f} bits, {frame_len - f} more clocks read 0 (max {cfg.max_clocks} clocks)")
    else:
        score += 1
        ev.append(f"{f}-bit frame, its first {frame_len} bits read")
    moved = motion.state in (MotionState.MOVING, MotionState.TOO_SLOW)
    if moved and motion.lsb is not None:
        if motion.lsb != lay.lsb:
            return None
        score += 3
        ev.append(f"position LSB at frame bit {lay.lsb} moves")
    for bit, pos in lay.specials.items():
        if bit in PARITY_BITS:
            if not motion.parity >> pos & 1 and stats.moving:
                return None
            if motion.parity >> pos & 1:
                score += 3
                ev.append(f"bit {pos} is even parity in every frame")
    if (motion.values and motion.lsb == lay.lsb and cfg.alignment is Alignment.RIGHT
            and cfg.origin == 0 and max(motion.values) >= cfg.range_steps):
        return None  # a position beyond the layout's range
    consts = [p for b, p in lay.specials.items() if b not in MOVABLE_SPECIALS]
    if consts:
        on = [p for p in consts if stats.always_one >> p & 1]
        ev.append(f"special bits at {sorted(consts, reverse=True)} "
                  + (f"set: {on}" if on else "0"))
    return score, ev


def rank_families(frames: list[int], frame_len: int, motion: Motion,
                  stats: BitStats | None = None) -> list[list[Fit]]:
    """The families fitting ``frames``: groups of equal score, best group first.

    :param frames: the sampled frames
    :param frame_len: their length in bits
    :param motion: what the frames say about the position bits, code and direction
    :param stats: which bits moved (computed from ``frames`` when None)
    """
    stats = stats or BitStats.of(frames, frame_len)
    fits: list[Fit] = []
    for family, fam in FAMILIES.items():
        if family in ALIASES:
            continue
        best: tuple[tuple[int, int, int], Fit] | None = None
        for overrides, cfg in _candidates(family, motion.code):
            scored = _score(cfg, frame_len, stats, motion)
            if scored is None:
                continue
            score, ev = scored
            default = "steps_per_rev" not in overrides
            key = (score, int(default), -len(overrides))
            if best is None or key > best[0]:
                fit = Fit(family, score, overrides, cfg, tuple(ev), fam.doc, default)
                best = (key, fit)
        if best is not None:
            fits.append(best[1])
    groups: dict[int, list[Fit]] = {}
    for fit in fits:
        groups.setdefault(fit.score, []).append(fit)
    return [groups[s] for s in sorted(groups, reverse=True)]


def describe_bits(stats: BitStats, motion: Motion) -> str:
    """One line on the frame's bits: moving, constant 1, constant 0.

    :param stats: which bits moved
    :param motion: the inferred position bits
    """
    moving = stats.moving & ~motion.parity & ~motion.check
    parts = [f"{stats.frame_len} clocks"]
    if moving:
        hi = moving.bit_length() - 1
        lo = (moving & -moving).bit_length() - 1
        parts.append(f"bits {lo}..{hi} move" if hi != lo else f"bit {lo} moves")
    else:
        parts.append("no position bit moves")
    if motion.parity:
        parts.append(f"parity bit(s) {bit_list(motion.parity)}")
    if motion.check:
        parts.append(f"check bits {bit_list(motion.check)}")
    if stats.always_one:
        parts.append(f"always 1: {bit_list(stats.always_one)}")
    low_zero = ((1 << (motion.lsb or 0)) - 1) & ~stats.ones & ~motion.check & ~motion.parity
    if motion.lsb and low_zero:
        parts.append(f"{bin(low_zero).count('1')} constant 0 bit(s) below the LSB")
    return ", ".join(parts)


__all__ = ["ALIASES", "Fit", "Layout", "describe_bits", "layout_of", "rank_families"]
