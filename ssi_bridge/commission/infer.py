"""Read an SSI frame sequence: which bits move, which stay, the code and the direction.

Pure: it sees only the raw frames the module clocked (REG_SSI_FRAME, 000 "Register access
and meaning": "Complete frame read from SSI encoder", bit 0 = the last bit clocked) in the
order they were latched. Rules (docs/commissioning.md):

* a bit that changes between two frames *moves*; the position's LSB is the bottom of a run
  of moving bits, the lowest one that decodes continuously (004 §2.3: error and special
  bits follow the position's LSB); moving bits under it are check bits. A binary count
  moves every bit under its highest moving one, so binary is ruled out for an LSB with a
  constant bit above it (the TR check sum under the zero fill of the step field,
  001 §5.2.4.2); Gray moves its high bits once per 2**k steps and may leave gaps;
* a moving bit that always equals the even parity of all other bits is a parity bit
  (001 §5.5.7), not position;
* the code is the one whose decoding of the bits from the LSB up is *continuous*: steps of
  one sign and similar size between frames. Gray read as binary jumps by 2^k at random
  (004 §2.4: Gray changes one bit per step), binary read as Gray steps back and forth.
  Runs are tried from the lowest up, at most :data:`MAX_CHECK_BITS` bits above it;
* direction: the sign of the net travel when at least :data:`MIN_CONSISTENT` of the steps
  have that sign; fewer than :data:`MIN_DISTINCT` distinct positions is too slow to tell.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from statistics import median

from ssi_bridge.protocol.codes import gray_to_bin

#: moving bits below the LSB the code check may skip (check sum bits the module reads)
MAX_CHECK_BITS = 16
#: share of continuous steps a code must reach to be taken
MIN_CONSISTENT = 0.9
#: distinct decoded positions needed before the code or the direction is told
MIN_DISTINCT = 4
#: distinct frames needed before a bit is taken for parity (a chance fit is 2**-n)
MIN_PARITY_FRAMES = 16
#: a step larger than this many times the median step is a jump, not motion
JUMP_FACTOR = 4.0


class MotionState(Enum):
    """What the frames say about the shaft."""

    STILL = "still"          #: no position bit moved
    TOO_SLOW = "too slow"    #: moved, but too little to tell the code or the direction
    MOVING = "moving"
    ERRATIC = "erratic"      #: bits move, yet no code decodes them continuously


@dataclass(frozen=True)
class BitStats:
    """Which of ``frame_len`` frame bits moved, were ever 1, were always 1."""

    frame_len: int
    samples: int
    moving: int
    ones: int
    always_one: int

    @staticmethod
    def of(frames: list[int], frame_len: int) -> BitStats:
        """Statistics of ``frames`` (each masked to ``frame_len`` bits)."""
        mask = (1 << frame_len) - 1
        moving = ones = 0
        always = mask
        prev: int | None = None
        for raw in frames:
            f = raw & mask
            ones |= f
            always &= f
            if prev is not None:
                moving |= prev ^ f
            prev = f
        return BitStats(frame_len, len(frames), moving, ones, always if frames else 0)


def bit_list(mask: int) -> list[int]:
    """Bit positions set in ``mask``, highest first (frame order)."""
    return [b for b in range(mask.bit_length() - 1, -1, -1) if mask >> b & 1]


def parity_bits(frames: list[int], stats: BitStats) -> int:
    """The lowest moving bit when it is the even parity of every other bit in every frame.

    A parity bit is the last special bit (001 §5.5.7), so only the lowest moving bit can be
    one: in a frame of even parity *every* bit is the parity of the others.

    :param frames: the sampled frames
    :param stats: which bits moved
    :returns: that bit as a mask (``1 << b``), or 0
    """
    if not stats.moving or len(set(frames)) < MIN_PARITY_FRAMES:
        return 0
    b = (stats.moving & -stats.moving).bit_length() - 1
    if all(((f >> b) & 1) == (bin(f & ~(1 << b)).count("1") & 1) for f in frames):
        return 1 << b
    return 0


def run_bottoms(moving: int) -> list[int]:
    """The lowest bit of each run of adjacent moving bits, lowest run first."""
    return [b for b in range(moving.bit_length())
            if moving >> b & 1 and (b == 0 or not moving >> (b - 1) & 1)]


def contiguous(mask: int) -> bool:
    """``mask`` is one run of set bits starting at bit 0 (2**k - 1)."""
    return mask > 0 and not mask & (mask + 1)


def _signed(d: int, width: int) -> int:
    half = 1 << (width - 1)
    return ((d + half) % (1 << width)) - half


@dataclass(frozen=True)
class Continuity:
    """How continuous a decoding is: the share of steps that are neither jumps nor reversals."""

    score: float
    steps: list[int]

    @property
    def distinct(self) -> int:
        """Number of nonzero steps."""
        return sum(1 for d in self.steps if d)


Latch = tuple[float, float]
"""Earliest and latest time (s) a frame can have been latched (the SYNC sent, its image read)."""


def continuity(values: list[int], width: int, latches: list[Latch] | None = None) -> Continuity:
    """Score a position sequence: 1.0 = every step the same sign and similar speed.

    Without ``latches`` the frames are taken as evenly spaced. With them a step is a jump
    only when it is larger than :data:`JUMP_FACTOR` times the typical speed (the median of
    step / time between the SYNCs) could travel in the longest time the two latches can be
    apart: a host that sampled late or lost cycles makes longer, not discontinuous steps.

    :param values: the positions in latch order
    :param width: their bits (a wrap-around is a small step)
    :param latches: each frame's latch bounds (:data:`Latch`), as many as ``values``
    :raises ValueError: ``latches`` and ``values`` differ in length
    """
    if latches is not None and len(latches) != len(values):
        raise ValueError(f"{len(latches)} latch times for {len(values)} positions")
    steps = [_signed(b - a, width) for a, b in zip(values, values[1:])]
    if latches is None:
        least = most = [1.0] * len(steps)
    else:
        least = [max(b[0] - a[0], 1e-6) for a, b in zip(latches, latches[1:])]
        most = [max(b[1] - a[0], lo) for a, b, lo in zip(latches, latches[1:], least)]
    moved = [(d, lo, hi) for d, lo, hi in zip(steps, least, most) if d]
    if len(moved) < 2:
        return Continuity(0.0, steps)
    speed = median(abs(d) / lo for d, lo, _ in moved)
    jumps = sum(1 for d, _, hi in moved if abs(d) > JUMP_FACTOR * speed * hi + 2)
    reversals = sum(1 for (a, _, _), (b, _, _) in zip(moved, moved[1:]) if (a > 0) != (b > 0))
    bad = jumps + reversals
    return Continuity(max(0.0, 1.0 - bad / len(moved)), steps)


def decode_window(frames: list[int], lsb: int, width: int, gray: bool) -> list[int]:
    """The value of frame bits ``lsb`` .. ``lsb + width - 1`` of each frame, Gray-decoded if
    ``gray`` (the whole field above the LSB, so Gray's XOR chain is complete).

    :param frames: the sampled frames
    :param lsb: the window's lowest bit
    :param width: its bits
    :param gray: the window is Gray-coded
    """
    mask = (1 << width) - 1
    out = []
    for f in frames:
        word = (f >> lsb) & mask
        out.append(gray_to_bin(word) if gray else word)
    return out


@dataclass(frozen=True)
class Motion:
    """The result of reading the frames: state, position LSB, code, direction, evidence."""

    state: MotionState
    #: frame bit of the position's LSB (lowest moving non-check bit), None when still
    lsb: int | None = None
    #: "binary" / "gray", None when the frames cannot tell
    code: str | None = None
    #: +1 counting up, -1 down, 0 unknown / back and forth
    direction: int = 0
    #: moving bits that are parity (001 §5.5.7)
    parity: int = 0
    #: moving bits below the LSB skipped as check bits
    check: int = 0
    #: the decoded positions (field above ``lsb``) and their width
    values: list[int] = field(default_factory=list)
    width: int = 0
    #: counts travelled (sum of |steps|) in units of the LSB
    travel: int = 0
    evidence: tuple[str, ...] = ()


def _direction(steps: list[int]) -> tuple[int, str]:
    moved = [d for d in steps if d]
    net = sum(moved)
    if not moved or not net:
        return 0, "no net travel"
    sign = 1 if net > 0 else -1
    share = sum(1 for d in moved if (d > 0) == (sign > 0)) / len(moved)
    if share < MIN_CONSISTENT:
        return 0, f"back and forth ({share:.0%} of the steps {'up' if sign > 0 else 'down'})"
    return sign, f"counts {'increasing' if sign > 0 else 'decreasing'} in {share:.0%} of the steps"


def read_motion(frames: list[int], frame_len: int,
                latches: list[Latch] | None = None) -> Motion:
    """What ``frames`` (in latch order) say about the position bits, code and direction.

    Only the lowest run of moving bits may be "too slow": a higher run is tried as the LSB
    only after the lower one failed to decode, and then it must decode outright.

    :param frames: the sampled frames, in latch order
    :param frame_len: their length in bits
    :param latches: when each frame was latched (:func:`continuity`); None: evenly spaced
    :raises ValueError: ``latches`` and ``frames`` differ in length
    """
    stats = BitStats.of(frames, frame_len)
    parity = parity_bits(frames, stats) if stats.moving else 0
    moving = stats.moving & ~parity
    if not moving:
        return Motion(MotionState.STILL, parity=parity,
                      evidence=(f"no frame bit moved in {stats.samples} frames",))
    bottoms = run_bottoms(moving)
    lowest = bottoms[0]
    tried: list[str] = []
    for lsb in [b for b in bottoms if b < lowest + MAX_CHECK_BITS]:
        width = frame_len - lsb
        fits = {}
        for name, gray in (("binary", False), ("gray", True)):
            values = decode_window(frames, lsb, width, gray)
            fits[name] = (continuity(values, width, latches), values)
        if not contiguous(moving >> lsb):  # a binary count moves every bit under its top
            fits["binary"] = (Continuity(0.0, fits["binary"][0].steps), fits["binary"][1])
        best = max(fits, key=lambda n: fits[n][0].score)
        other = "gray" if best == "binary" else "binary"
        cont, values = fits[best]
        distinct = len(set(values))
        travel = sum(abs(d) for d in cont.steps)
        check = moving & ((1 << lsb) - 1)
        if distinct < MIN_DISTINCT and lsb != lowest:
            tried.append(f"LSB {lsb}: only {distinct} distinct positions")
            continue
        if distinct < MIN_DISTINCT:
            return Motion(MotionState.TOO_SLOW, lsb, None, 0, parity, check, values, width,
                          travel, (f"only {distinct} distinct positions: too slow to tell the "
                                   "code or the direction",))
        if cont.score >= MIN_CONSISTENT and fits[other][0].score < MIN_CONSISTENT:
            direction, words = _direction(cont.steps)
            ev = [f"bits {lsb}..{frame_len - 1} decode continuously as {best} "
                  f"({cont.score:.0%} of the steps), as {other} only "
                  f"{fits[other][0].score:.0%}", words]
            if check:
                ev.append(f"moving bits {bit_list(check)} under a constant bit: check bits")
            return Motion(MotionState.MOVING, lsb, best, direction, parity, check, values,
                          width, travel, tuple(ev))
        tried.append(f"LSB {lsb}: binary {fits['binary'][0].score:.0%}, "
                     f"gray {fits['gray'][0].score:.0%}")
        if cont.score >= MIN_CONSISTENT and lsb == lowest:  # both continuous: steps too small
            return Motion(MotionState.TOO_SLOW, lsb, None, 0, parity, check, values, width,
                          travel, ("both binary and Gray decode continuously: the steps are "
                                   "too small to tell the code",))
    return Motion(MotionState.ERRATIC, lowest, None, 0, parity, 0,
                  evidence=("no code decodes the moving bits continuously: "
                            + "; ".join(tried[:4]),))


__all__ = ["BitStats", "Continuity", "Motion", "MotionState", "bit_list", "continuity",
           "Latch", "decode_window", "parity_bits", "read_motion"]
