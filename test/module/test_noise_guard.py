"""Bit noise at 1 % per bit: which corrupted samples each configuration lets through unflagged.

Station level (encoder -> SSI line with seeded noise -> XN-1SSI -> the bridge's frame check),
because counting thousands of cycles through the node would take minutes; the node test
(test/ros/test_node_frame_status.py) shows the same flags through the installed executable.

A sample is *corrupted* when the frame the module read (REG_SSI_FRAME) differs from the frame
the encoder sent (a noise-free twin encoder at the same latch time), and *flagged* when the
cycle shows ERR_SSI (ZERO test, 000 Table 19), SSI_DIAG (REG_SSI_MASK, 000 Table 3) or a failed
frame check (parity 001 §5.5.7, zero bits 004 §3).
"""

from __future__ import annotations

from pathlib import Path

import yaml

from ssi_bridge.encoder.families import make_encoder
from ssi_bridge.encoder.motion import ConstantVelocity
from ssi_bridge.line.decode import MasterStatus
from ssi_bridge.line.frame_check import FrameCheck
from ssi_bridge.line.line import LineConfig, SsiLine
from ssi_bridge.line.multi import MultipleTransmission
from ssi_bridge.module.images import ModuleStatus as M
from ssi_bridge.module.registers import Para1, Reg
from ssi_bridge.module.xn1ssi import Xn1Ssi

CONFIG = Path(__file__).resolve().parents[2] / "config" / "noise_guard.yaml"
N = 4000
RATE = 0.01
PERIOD = 0.001


def _guard_settings() -> dict:
    return yaml.safe_load(CONFIG.read_text())["/**"]["ros__parameters"]["axis"]


def _run(family: str, para1: int, ssi_mask: int) -> dict[str, int]:
    """N module cycles at RATE noise; counts of corrupted / unflagged / odd-flip frames."""
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
        sent = twin.frame_at(latch).bits
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
