"""A joint's encoder as the node knows it from its parameters, and what REG_PARA1 makes of it.

The node and the simulated station read the same joint parameters (``<joint>.family``,
``.code``, ``.steps_per_rev``, ``.revolutions``, ``.measuring_step``): :func:`joint_config` is
the encoder layout they describe (the family preset with the overrides). From it and the
REG_PARA1 in force, :func:`count_factor` says how many REG_SSI_POS counts one encoder step is
(000 Table 19: frame length, invalid LSB bits) and :func:`para1_mismatch` why a REG_PARA1
does not fit the encoder. The one code path for simulated and real stations.
"""

from __future__ import annotations

from typing import Any

from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import Alignment, EncoderConfig
from ssi_bridge.protocol.families import family_config
from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.protocol.settings import JointSettings


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


def joint_config(joint: JointSettings) -> EncoderConfig:
    """The encoder layout of ``joint``: its family preset with its parameters' overrides.

    Raises ConfigError for an unknown family or overrides the family cannot take.
    """
    return family_config(joint.family, **encoder_overrides(joint))


def count_factor(cfg: EncoderConfig, para1: int) -> float:
    """REG_SSI_POS counts per encoder step for a REG_PARA1 reading an encoder of layout ``cfg``.

    The encoder's position LSB sits ``frame_bits - position_bits`` bits before the end of its
    frame (special and filler bits follow, 004 §2.3; SSI-SHIFT-RIGHT loses one more). The
    module clocks SSI_FRAME_LEN bits — fewer cut the frame's end, more read 0s after it
    (004 §3.6) — then shifts INVALID_BITS_LSB out (000 Table 19). So the step lands at bit
    ``SSI_FRAME_LEN - frame_bits + lsb - INVALID_BITS_LSB`` of REG_SSI_POS. A Tannenbaum
    step field wider than the resolution ends in zeros (004 §3.4; the 16-bit step field of
    the TR check sum format, 001 §5.2.4.2): the whole value sits ``field - n`` bits higher.

    :param cfg: the encoder's layout
    :param para1: the REG_PARA1 in force
    """
    p = Para1.decode(para1)
    lsb = cfg.frame_bits - cfg.position_bits - (1 if cfg.shift_right else 0)
    if cfg.alignment is Alignment.TANNENBAUM and cfg.origin >= 0:
        lsb += cfg.field_bits - cfg.turn_bits - (int(cfg.steps_per_rev).bit_length() - 1)
    return 2.0 ** (p.ssi_frame_len - cfg.frame_bits + lsb - p.invalid_bits_lsb)


def para1_mismatch(cfg: EncoderConfig, para1: int) -> str | None:
    """Why REG_PARA1 does not fit an encoder of layout ``cfg`` (a WARN), or None.

    :param cfg: the encoder's layout
    :param para1: the REG_PARA1 in force
    """
    p = Para1.decode(para1)
    problems = []
    if p.ssi_frame_len != cfg.frame_bits:
        problems.append(f"SSI_FRAME_LEN {p.ssi_frame_len} but the encoder sends {cfg.frame_bits} bits")
    if p.ssi_code_gray != (cfg.code is Code.GRAY):
        problems.append(f"SSI_CODE_G/D {'Gray' if p.ssi_code_gray else 'binary'} but the encoder sends "
                        f"{cfg.code.name.lower()}")
    return "; ".join(problems) or None


__all__ = ["count_factor", "encoder_overrides", "joint_config", "para1_mismatch"]
