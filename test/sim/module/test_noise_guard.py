"""Bit noise at 1 % per bit: which corrupted samples each configuration lets through unflagged.

Station level (encoder -> SSI line with seeded noise -> XN-1SSI -> the bridge's frame check),
because counting thousands of cycles through the node would take minutes; the in-process
test (test/core/test_inprocess_frame_status.py) shows the same flags through the bridge.

A sample is *corrupted* when the frame the module read (REG_SSI_FRAME) differs from the frame
the encoder sent (a noise-free twin encoder at the same latch time), and *flagged* when the
cycle shows ERR_SSI (ZERO test, 000 Table 19), SSI_DIAG (REG_SSI_MASK, 000 Table 3) or a failed
frame check (parity 001 §5.5.7, TR checksum 001 §5.2.4.2, zero bits 004 §3).

Figures at N = 4000 cycles, seed 7 (docs/module.md "Bit noise"): plain 25-bit frame 879 of
897 corrupted frames pass unflagged; even parity (config/noise_guard.yaml) 95 of 944; the TR
"Check sum" format read in full (43 clocks, a master other than the XN-1SSI) 0 of 7052 in
20000 cycles; the same format cut to the XN-1SSI's 32 clocks 64 of 1108.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import ConstantVelocity
from ssi_bridge.protocol.decode import MasterStatus, check_readout
from ssi_bridge.protocol.frame_check import FrameCheck
from ssi_bridge.sim.line.line import LineConfig, SsiLine
from ssi_bridge.sim.line.multi import MultipleTransmission
from ssi_bridge.protocol.images import ModuleStatus as M
from ssi_bridge.protocol.registers import Para1, Reg
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

CONFIG = Path(__file__).resolve().parents[3] / "config" / "noise_guard.yaml"
N = 4000
RATE = 0.01
PERIOD = 0.001


def _guard_settings() -> dict:
    return yaml.safe_load(CONFIG.read_text())["/**"]["ros__parameters"]["axis"]


def _run(family: str, para1: int, ssi_mask: int) -> dict[str, int]:
    """N module cycles at RATE noise; counts of corrupted / unflagged / odd-flip frames.

    A frame the module cuts (SSI_FRAME_LEN below the encoder's frame) is compared with the
    bits of the sent frame it kept.
    """
    motion = ConstantVelocity(0.25)
    enc = make_encoder(family, motion)
    twin = make_encoder(family, ConstantVelocity(0.25))
    line = SsiLine(enc, LineConfig(cable_length_m=10.0, check_cable_table=False, seed=7))
    line.faults.bit_error_rate = RATE
    module = Xn1Ssi(line)
    module.write_para1(para1)
    module.write_register(Reg.REG_SSI_MASK, ssi_mask)
    n = Para1.decode(para1).ssi_frame_len
    check = FrameCheck(enc.config, n)
    counts = dict(corrupted=0, unflagged=0, unflagged_odd=0, flagged=0)
    for k in range(N):
        module.cycle(k * PERIOD)
        latch = module.last_readout.latch_time
        sent = twin.frame_at(latch).bits >> max(enc.frame_bits - n, 0)
        read = module.read_register(Reg.REG_SSI_FRAME)
        flipped = bin(read ^ sent).count("1")
        flagged = (bool(module.status.sts & (M.ERR_SSI | M.SSI_DIAG))
                   or check.check(read).corrupt)
        counts["flagged"] += flagged
        if flipped:
            counts["corrupted"] += 1
            if not flagged:
                counts["unflagged"] += 1
                counts["unflagged_odd"] += flipped % 2
    return counts


def test_plain_ssi_lets_most_corrupted_frames_through() -> None:
    # the XN-1SSI default frame (25 bits binary, no special bits): only the ZERO test
    c = _run("GENERIC", 0x19010000, 0)
    assert c["corrupted"] > 0.15 * N            # ~1 - 0.99**25 = 22 % of frames
    assert c["unflagged"] > 0.8 * c["corrupted"]


def test_noise_guard_config_flags_every_odd_corruption() -> None:
    # config/noise_guard.yaml: even parity (001 §5.5.7 "supplements the checksum to even
    # parity"): a frame with an odd number of flipped bits never passes; an even number
    # keeps the parity and cannot be seen by one parity bit
    s = _guard_settings()
    c = _run(s["family"], s["para1"], s["ssi_mask"])
    assert c["corrupted"] > 0.15 * N
    assert c["unflagged_odd"] == 0, c
    # what is left: two (or four...) flipped bits, C(26,2) p^2 = ~3 % of frames
    assert c["unflagged"] < 0.05 * N, c
    assert c["unflagged"] < 0.2 * c["corrupted"], c


def test_multiple_transmission_and_parity_let_nothing_through() -> None:
    # 003 multiple transmission with 3 clock bursts ("At least two out of three values need
    # to be similar ... If all three received values are different, the transmission failure
    # is indicated") plus the parity: what a master offering it reaches (the EL500x; the
    # XN-1SSI clocks one burst per cycle)
    s = _guard_settings()
    enc = make_encoder(s["family"], ConstantVelocity(0.25))
    twin = make_encoder(s["family"], ConstantVelocity(0.25))
    line = SsiLine(enc, LineConfig(cable_length_m=10.0, check_cable_table=False, seed=7))
    line.faults.bit_error_rate = RATE
    master = MultipleTransmission(line, bursts=3)
    check = FrameCheck(enc.config, 26)
    unflagged = corrupted = 0
    for k in range(N):
        got = master.read(k * PERIOD, 26, 500_000.0)
        sent = twin.frame_at(got.bursts[0].latch_time).bits
        if got.readout.data != sent:
            corrupted += 1
            if got.status is MasterStatus.OK and not check.check(got.readout.data).corrupt:
                unflagged += 1
    assert corrupted > 0
    assert unflagged == 0


def _full_checksum_master(n_cycles: int) -> tuple[int, int]:
    """A master that clocks all 43 bits of the TR check sum format: (corrupted, unflagged)."""
    enc = make_encoder("TR_CHECKSUM", ConstantVelocity(0.25))
    twin = make_encoder("TR_CHECKSUM", ConstantVelocity(0.25))
    line = SsiLine(enc, LineConfig(cable_length_m=10.0, check_cable_table=False, seed=7))
    line.faults.bit_error_rate = RATE
    check = FrameCheck(enc.config, 43)
    corrupted = unflagged = 0
    for k in range(n_cycles):
        r = line.read(k * PERIOD, 43, 500_000.0)
        if r.data != twin.frame_at(r.latch_time).bits:
            corrupted += 1
            # ZERO test after the last bit (000 Table 19, 001 §4.6) and the checksum
            if check_readout(r) is MasterStatus.OK and not check.check(r.data).corrupt:
                unflagged += 1
    return corrupted, unflagged


def test_check_sum_format_read_in_full_lets_nothing_through() -> None:
    # 001 §5.2.4.2 (German text): "28 Datenbits ... 15 Prüfsummenbits", "arbeitet mit einer
    # Hammingdistanz von 6 und erkennt auf diese Weise bis zu 5 Fehler je Codewort": at 1 %
    # per bit, 5 flips in 43 bits are rarer than 1 in 10^5 frames, and a pattern beyond them
    # passes with odds 2^-15. 43 clocks: a master like TR's own ("Als Empfangsgeräte (SSI-
    # Master) dienen TR-eigene Applikations-Module"), not the XN-1SSI (at most 32)
    corrupted, unflagged = _full_checksum_master(5 * N)
    assert corrupted > 0.3 * 5 * N              # 1 - 0.99**44 = 36 % of frames
    assert unflagged == 0


def test_check_sum_format_cut_to_32_clocks_does_not_reach_zero() -> None:
    # the XN-1SSI clocks at most 32 bits (000 Table 19 SSI_FRAME_LEN 1..32): it reads the
    # 28 data bits and 4 of the 15 checksum bits. The ZERO test must be off (DIS_ERR_SSI,
    # 000 Table 19): clock 33 carries a checksum bit, not the end-of-frame 0. Four checksum
    # bits cannot give distance 6: single flips at clocks 6 and 7 (revolution bits 2^7, 2^6)
    # leave them unchanged, so this is no better than one parity bit for the guard
    para1 = 0x20010420                          # 32 bits, 500 kbit/s, LSB 4, DIS_ERR_SSI
    c = _run("TR_CHECKSUM", para1, 0)
    assert c["corrupted"] > 0.2 * N
    assert 0 < c["unflagged"] < 0.05 * N, c
    enc = make_encoder("TR_CHECKSUM")
    check = FrameCheck(enc.config, 32)
    word = enc.frame_at(0.0).bits >> 11
    blind = [32 - k for k in range(32) if not check.check(word ^ (1 << k)).corrupt]
    assert sorted(blind) == [6, 7]
