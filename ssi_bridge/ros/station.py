"""The simulated XI/ON station: per joint an encoder on its SSI line into an XN-1SSI module.

ROS-free wiring of the stages left of the gateway, built from the node's settings. The
gateway gets :attr:`SimStation.modules` (one per slot, slots without a joint hold a module
with nothing connected) and runs them on SYNC; the node reaches the simulated hardware only
through the bus, except for fault injection, which acts here like a hand on the cable.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any
from pathlib import Path

from ssi_bridge.encoder.encoder import SsiEncoder
from ssi_bridge.encoder.families import family_config, make_encoder
from ssi_bridge.encoder.motion import ConstantVelocity, MotionProfile, Sine, Still
from ssi_bridge.encoder.codes import Code
from ssi_bridge.line.line import LineConfig, SsiLine
from ssi_bridge.module.registers import Para1
from ssi_bridge.module.store import MemoryStore, RetentiveStore
from ssi_bridge.module.xn1ssi import Xn1Ssi
from ssi_bridge.ros.params import JointSettings, MotionSettings, NodeSettings

logger = logging.getLogger(__name__)


def make_motion(m: MotionSettings) -> MotionProfile:
    """The motion profile a joint's simulated shaft follows (rev or m over seconds)."""
    if m.kind == "still":
        return Still(m.start)
    if m.kind == "sine":
        return Sine(m.amplitude, m.frequency, offset=m.start)
    return ConstantVelocity(m.velocity, start=m.start)


def encoder_overrides(joint: JointSettings) -> dict[str, Any]:
    """EncoderConfig fields a joint's parameters set on top of its family preset."""
    out: dict[str, Any] = {}
    if joint.code:
        out["code"] = Code.GRAY if joint.code == "gray" else Code.BINARY
    if joint.steps_per_rev:
        out["steps_per_rev"] = float(joint.steps_per_rev)
    if joint.revolutions:
        out["revolutions_numerator"] = int(joint.revolutions)
    if joint.measuring_step:
        out["measuring_step_m"] = float(joint.measuring_step)
    return out


def count_factor(encoder: SsiEncoder, para1: int) -> float:
    """REG_SSI_POS counts per encoder step for a REG_PARA1 reading this encoder.

    The encoder's position LSB sits ``frame_bits - position_bits`` bits before the end of its
    frame (special and filler bits follow, 004 §2.3; SSI-SHIFT-RIGHT loses one more). The
    module clocks SSI_FRAME_LEN bits — fewer cut the frame's end, more read 0s after it
    (004 §3.6) — then shifts INVALID_BITS_LSB out (000 Table 19). So the step lands at bit
    ``SSI_FRAME_LEN - frame_bits + lsb - INVALID_BITS_LSB`` of REG_SSI_POS.
    """
    cfg = encoder.config
    p = Para1.decode(para1)
    lsb = cfg.frame_bits - cfg.position_bits - (1 if cfg.shift_right else 0)
    return 2.0 ** (p.ssi_frame_len - cfg.frame_bits + lsb - p.invalid_bits_lsb)


def spec_max_speed(family: str) -> float:
    """The highest speed (rad/s) a family's manual specifies, 0 where it states none.

    Only the TR encoders give one in these manuals: the overspeed limit, at most 6000 1/min
    (001 §5.4.2); SICK's 004 states no speeds for its families.
    """
    if not family.upper().startswith("TR"):
        return 0.0
    cfg = family_config(family)
    return 0.0 if cfg.linear else cfg.overspeed_rpm / 60.0 * 2.0 * math.pi


def para1_mismatch(encoder: SsiEncoder, para1: int) -> str | None:
    """Why REG_PARA1 does not fit the simulated encoder (a start-up warning), or None."""
    cfg = encoder.config
    p = Para1.decode(para1)
    problems = []
    if p.ssi_frame_len != cfg.frame_bits:
        problems.append(f"SSI_FRAME_LEN {p.ssi_frame_len} but the encoder sends {cfg.frame_bits} bits")
    if p.ssi_code_gray != (cfg.code is Code.GRAY):
        problems.append(f"SSI_CODE_G/D {'Gray' if p.ssi_code_gray else 'binary'} but the encoder sends "
                        f"{cfg.code.name.lower()}")
    return "; ".join(problems) or None


@dataclass
class SimChannel:
    """One simulated joint: the encoder, its SSI line and the module it is wired to."""

    joint: JointSettings
    encoder: SsiEncoder
    line: SsiLine
    module: Xn1Ssi


class SimStation:
    """All simulated modules of one gateway station; ``modules[slot - 1]`` sits in slot 1-8."""

    def __init__(self, settings: NodeSettings) -> None:
        n_slots = max(j.slot for j in settings.joints)
        self.channels: dict[str, SimChannel] = {}
        self.modules: list[Xn1Ssi] = []
        by_slot = {j.slot: j for j in settings.joints}
        for slot in range(1, n_slots + 1):
            store = self._store(settings.storage_path, slot)
            joint = by_slot.get(slot)
            if joint is None:
                self.modules.append(Xn1Ssi(None, store=store, slot=slot))
                continue
            encoder = make_encoder(joint.family, make_motion(joint.motion),
                                   **encoder_overrides(joint))
            line = SsiLine(encoder, LineConfig(cable_length_m=joint.cable_length))
            module = Xn1Ssi(line, store=store, slot=slot)
            self.modules.append(module)
            self.channels[joint.name] = SimChannel(joint, encoder, line, module)
            logger.info("slot %d: %s encoder (%d-bit %s frame) for joint %s", slot,
                        joint.family, encoder.frame_bits, encoder.config.code.name.lower(),
                        joint.name)
            mismatch = para1_mismatch(encoder, joint.para1)
            if mismatch:
                logger.warning("joint %s: REG_PARA1 0x%08X does not match the simulated %s "
                               "encoder: %s", joint.name, joint.para1, joint.family, mismatch)

    @staticmethod
    def _store(storage_path: str, slot: int) -> RetentiveStore | MemoryStore:
        """One retentive bank file per slot next to ``storage_path`` (or memory only)."""
        if not storage_path:
            return MemoryStore()
        path = Path(storage_path).expanduser()
        path.parent.mkdir(parents=True, exist_ok=True)
        return RetentiveStore(path.with_name(f"{path.stem}.slot{slot}{path.suffix or '.bank'}"))
