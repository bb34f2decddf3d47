"""The inference rules on frames built from the manuals' layouts, without a bus.

Frames come from ``protocol/layout.py`` (the layouts of 004 §3, 001 §5 and 003 that the
simulated encoders send), so each rule of docs/commissioning.md is checked against frames
whose position, code and direction are known.
"""

from __future__ import annotations

import random

import pytest

from ssi_bridge.commission.analyze import analyze
from ssi_bridge.commission.infer import MotionState, read_motion
from ssi_bridge.commission.rank import layout_of, rank_families
from ssi_bridge.commission.sample import Sample, SlotSamples
from ssi_bridge.protocol.checksum import code_word
from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.decode import XN_MAX_FRAME_BITS
from ssi_bridge.protocol.encoder_config import EncoderConfig, FrameFormat, SpecialBit
from ssi_bridge.protocol.families import FAMILIES, family_config
from ssi_bridge.protocol.family_rules import FAMILY_CODES
from ssi_bridge.protocol.images import ModuleStatus
from ssi_bridge.protocol.layout import assemble, encode_area
from ssi_bridge.protocol.para1 import Para1


def frames_of(cfg: EncoderConfig, values: list[int]) -> tuple[list[int], int]:
    """The frames ``cfg`` sends for ``values`` as a module clocking at most 32 bits reads them
    (even parity computed over the frame, 001 §5.5.7; the CRC-15 after the 28 data bits of
    the check sum format, 001 §5.2.4.2), and that frame length."""
    out = []
    for v in values:
        frame = assemble(cfg, encode_area(cfg, v), [0] * len(cfg.special_bits))
        if cfg.frame_format is FrameFormat.CHECKSUM:
            frame = code_word(encode_area(cfg, v))
        if SpecialBit.EVEN_PARITY in cfg.special_bits:
            frame |= bin(frame).count("1") & 1
        if cfg.frame_bits > XN_MAX_FRAME_BITS:
            frame >>= cfg.frame_bits - XN_MAX_FRAME_BITS
        out.append(frame)
    return out, min(cfg.frame_bits, XN_MAX_FRAME_BITS)


CASES = [(family, code) for family in FAMILIES if family != "ATM90"
         for code in FAMILY_CODES[family].codes if code in (Code.BINARY, Code.GRAY)]


@pytest.mark.parametrize("family, code", CASES, ids=[f"{f}-{c.value}" for f, c in CASES])
@pytest.mark.parametrize("step", [37, -53])
def test_code_direction_and_family_of_a_moving_encoder(family, code, step):
    cfg = family_config(family, code=code)
    start = cfg.range_steps // 3
    frames, n = frames_of(cfg, [(start + step * i) % cfg.range_steps for i in range(60)])
    motion = read_motion(frames, n)
    assert motion.state is MotionState.MOVING, motion.evidence
    assert motion.code == code.value and motion.direction == (1 if step > 0 else -1)
    assert motion.lsb == layout_of(cfg, n).lsb
    top = rank_families(frames, n, motion)[0]
    assert family in [f.family for f in top]
    for fit in top:  # ties only between layouts the frame cannot tell apart
        assert layout_of(fit.config, n).lsb == motion.lsb, fit.family


def test_a_still_encoder_is_said_still_and_ranked_by_its_frame_length_alone():
    cfg = family_config("AHM36_MULTI")
    frames, n = frames_of(cfg, [123456] * 20)
    motion = read_motion(frames, n)
    assert motion.state is MotionState.STILL and motion.code is None
    assert motion.direction == 0
    assert "AHM36_MULTI" in [f.family for g in rank_families(frames, n, motion) for f in g]


def test_two_positions_are_too_slow_to_tell_the_code():
    cfg = family_config("GENERIC")
    frames, n = frames_of(cfg, [1000, 1001] * 10)
    motion = read_motion(frames, n)
    assert motion.state is MotionState.TOO_SLOW and motion.code is None


def test_the_parity_bit_is_found_and_not_taken_for_the_position_lsb():
    cfg = family_config("TR_PARITY")
    frames, n = frames_of(cfg, [5000 + 7 * i for i in range(60)])
    motion = read_motion(frames, n)
    assert motion.parity == 1 and motion.lsb == 2   # error bit 1 stays 0 (001 §5.5.6)
    groups = rank_families(frames, n, motion)
    assert [f.family for f in groups[0]] == ["TR_PARITY"]


def test_check_sum_bits_under_the_zero_fill_are_not_position():
    """001 §5.2.4.2: 4096 steps fill 12 of the 16 step bits; the first checksum bits the
    module reads (a 43-bit frame cut at 32) move at random under the 4 zero bits."""
    cfg = family_config("TR_CHECKSUM")
    frames, n = frames_of(cfg, [300_000 + 1501 * i for i in range(60)])
    motion = read_motion(frames, n)
    assert motion.lsb == 8 and motion.code == "binary" and motion.check
    assert [f.family for f in rank_families(frames, n, motion)[0]] == ["TR_CHECKSUM"]


def test_a_lower_resolution_moves_the_lsb_and_is_found():
    """004 §3.1: AHS36 sends its value MSB-justified in 14 bits; 4096 steps end at bit 3."""
    cfg = family_config("AHS36", steps_per_rev=4096.0)
    frames, n = frames_of(cfg, [(100 + 11 * i) % 4096 for i in range(60)])
    motion = read_motion(frames, n)
    fit = next(f for f in rank_families(frames, n, motion)[0] if f.family == "AHS36")
    assert motion.lsb == 3 and fit.config.steps_per_rev == 4096
    assert not fit.default_resolution


def starved_latches(n: int) -> list[tuple[float, float]]:
    """Latch bounds of ``n`` SYNC rounds 30 ms apart where every third round came 0.25-0.55 s
    late (a sampling thread starved on a busy host) and the gateway latched up to 20 ms after
    the SYNC; (SYNC sent, image read) as ``sample.Sample.latch`` gives them."""
    out, t = [], 0.0
    for i in range(n):
        out.append((t, t + 0.002 + 0.018 * (i % 2)))
        t += 0.25 + 0.1 * (i % 4) if i % 3 == 2 else 0.03
    return out


@pytest.mark.parametrize("family, code", CASES, ids=[f"{f}-{c.value}" for f, c in CASES])
def test_a_sampling_with_gaps_is_read_by_when_the_frames_were_latched(family, code):
    """A starved sampler takes the frames at irregular times: a long gap makes a long step,
    not a jump of the code (004 §2.4), once each step is judged against the time it took."""
    cfg = family_config(family, code=code)
    latches = starved_latches(40)
    speed = 1234.5  # counts per second: 37 per regular round, up to 680 across a gap
    late = [hi for _, hi in latches]
    start = cfg.range_steps // 3
    frames, n = frames_of(cfg, [int(start - speed * t) % cfg.range_steps for t in late])
    motion = read_motion(frames, n, latches)
    assert motion.state is MotionState.MOVING, motion.evidence
    assert motion.code == code.value and motion.direction == -1
    top = rank_families(frames, n, motion)[0]
    assert family in [f.family for f in top]
    assert {layout_of(f.config, n).lsb for f in top} == {layout_of(cfg, n).lsb}


def test_frames_no_code_decodes_are_no_joint_but_a_problem():
    """Bits that move at random (a noisy line, or an encoder faster than the sampling) give
    no family ranked on a guess: the slot is reported with "not enough evidence"."""
    rng = random.Random(7)
    para1 = Para1(ssi_frame_len=25)
    found = SlotSamples(5, 1, [Sample(0.03 * i, rng.getrandbits(25), 0, ModuleStatus(0), 0,
                                      t_read=0.03 * i + 0.01) for i in range(40)])
    res = analyze(found, para1.encode(), para1.encode())
    assert res.motion is not None and res.motion.state is MotionState.ERRATIC
    assert not res.joint and not res.groups
    assert res.problem is not None and res.problem.startswith("not enough evidence")
