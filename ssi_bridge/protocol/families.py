"""Named encoder presets with the frame layouts of 004 §3 (SICK) and 001 §5 (TR).

``family_config("AFM60_MULTI", steps_per_rev=32768)`` is the layout of the encoder a user has
on the machine; overrides are :class:`EncoderConfig` fields (the simulated encoder of a family:
:func:`ssi_bridge.sim.encoder.encoder.make_encoder`). Where a family sends its
position bits "directly added" (the error bits follow the last position bit, 004 §3.2
"13 bits -> 16 bits output"), ``data_bits`` follows the resolution unless overridden.
Selecting ``ssi_mode=SsiMode.SYNC`` fills in the family's synchronous timing.

Assumptions the manual leaves open (docs/encoder_line.md): ARS60 values are MSB-justified
like the other non-programmable SICK encoders; the measuring steps of TTK70 (1 µm) and KH53
(0.1 mm) are not in 004 and are only defaults.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace
from collections.abc import Callable
from typing import Any

from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import (Alignment, EncoderConfig, ErrorOutput, FrameFormat,
                                       SpecialBit, SsiMode, SyncReference, round_half_up)
from ssi_bridge.exceptions import ConfigError

SICK3 = (SpecialBit.ERRDIG, SpecialBit.ERRSI, SpecialBit.ERRSYNC)   # 004 §3.2
#: AHS/AHM36 asynchronous / synchronous timing (004 §3.1)
AHM36_TIMING: dict[str, Any] = dict(formation_period_s=125e-6, async_pause_tolerance=0.2,
                                    async_max_pause_s=0.6)
AHM36_SYNC: dict[str, Any] = dict(sync_reference=SyncReference.BURST_END, sync_delay_s=20e-6,
                                  min_pause_s=150e-6)
#: ATM60 synchronous timing, both layouts (004 §3.4)
ATM60_SYNC: dict[str, Any] = dict(sync_reference=SyncReference.LATCH, monoflop_s=150e-6,
                                  min_pause_s=150e-6)


def _is_binary(steps: float) -> bool:
    s = int(steps)
    return s == steps and s > 0 and not s & (s - 1)


def _st_bits(steps: float, code: Code = Code.BINARY) -> int:
    """Bits a singleturn value of ``steps`` steps needs (BCD: four per decimal digit)."""
    top = max(int(steps) - 1, 1)
    return 4 * len(str(top)) if code is Code.BCD else top.bit_length()


def _directly_added(cfg: Any, given: dict[str, Any], turn_bits: int = 0) -> dict[str, Any]:
    """data_bits = position bits of the resolution (004 §3.2 example, §3.3 note)."""
    if "data_bits" in given:
        return {}
    return {"data_bits": turn_bits + _st_bits(cfg.steps_per_rev, cfg.code)}


def _multiturn_layout(cfg: Any, given: dict[str, Any]) -> dict[str, Any]:
    """Tannenbaum for binary resolutions; else MSB-justified / right-aligned (004 §3.1, §3.4)."""
    if "alignment" in given or _is_binary(cfg.steps_per_rev):
        return {}
    return {"alignment": Alignment.LEFT}


def _atm60_layout(cfg: Any, given: dict[str, Any]) -> dict[str, Any]:
    """ATM60 non-binary / round axis: right aligned on the 24th bit, 200 µs (004 §3.4)."""
    out: dict[str, Any] = {}
    if "alignment" not in given and not _is_binary(cfg.steps_per_rev):
        out.update(alignment=Alignment.RIGHT, data_bits=24, trailing_zero_bits=1)
        out["formation_period_s"] = 200e-6
        if cfg.ssi_mode is SsiMode.SYNC:
            out.update(monoflop_s=200e-6, min_pause_s=200e-6)
    return out


def _exact_data_bits(cfg: Any, given: dict[str, Any]) -> dict[str, Any]:
    """Check sum format: the Number of data bits the total number of steps needs, "typed in
    exactly" (001 §5.2.1; §5.2.4.2: 4096 x 1024 steps = 22 data bits)."""
    if "data_bits" in given:
        return {}
    total = cfg.total_steps or round_half_up(cfg.steps_per_rev * cfg.revolutions_numerator
                                             / cfg.revolutions_divisor)
    return {"data_bits": max(cfg.origin + total - 1, 1).bit_length()}


def _ars60_layout(cfg: Any, given: dict[str, Any]) -> dict[str, Any]:
    """ARS60: 13 bits up to 8192 steps, else 15 bits + 2 error bits (004 §3.5)."""
    if cfg.steps_per_rev > 8192 and "data_bits" not in given:
        out: dict[str, Any] = {"data_bits": 15}
        if "special_bits" not in given:
            out["special_bits"] = (SpecialBit.ERR_POSITION, SpecialBit.ERR_SENDER)
        return out
    return {}


Fix = Callable[[Any, dict[str, Any]], dict[str, Any]]


@dataclasses.dataclass(frozen=True)
class Family:
    """A preset: base fields, extra fields for synchronous mode, and resolution fix-ups."""

    base: dict[str, Any]
    sync: dict[str, Any] = dataclasses.field(default_factory=dict)
    fixes: tuple[Fix, ...] = ()
    doc: str = ""


_ROTARY_ST = dict(revolutions_numerator=1, revolutions_divisor=1)

FAMILIES: dict[str, Family] = {
    "GENERIC": Family(
        dict(steps_per_rev=8192, revolutions_numerator=4096, data_bits=25),
        doc="25-bit multiturn, 12 + 13 bits, binary, no special bits (XN-1SSI default frame)"),
    "AHS36": Family(
        dict(steps_per_rev=16384, data_bits=14, alignment=Alignment.LEFT,
             special_bits=(SpecialBit.ERROR,), **_ROTARY_ST, **AHM36_TIMING),
        AHM36_SYNC, doc="004 §3.1: 14 position bits MSB-justified + error bit (clock 15)"),
    "AHM36_MULTI": Family(
        dict(steps_per_rev=16384, revolutions_numerator=4096, data_bits=26, turn_bits=12,
             alignment=Alignment.TANNENBAUM, special_bits=(SpecialBit.ERROR,), **AHM36_TIMING),
        AHM36_SYNC, (_multiturn_layout,),
        doc="004 §3.1: 12 multiturn + 14 singleturn bits + error bit (clock 27)"),
    "AFS60": Family(
        dict(steps_per_rev=262144, data_bits=18, special_bits=SICK3, **_ROTARY_ST),
        fixes=(lambda c, g: _directly_added(c, g),),
        doc="004 §3.2: 18 position bits + ERRDIG, ERRSI, ERRSYNC"),
    "AFM60_MULTI": Family(
        dict(steps_per_rev=262144, revolutions_numerator=4096, data_bits=30, turn_bits=12,
             alignment=Alignment.TANNENBAUM, special_bits=SICK3),
        fixes=(lambda c, g: _directly_added(c, g, 12), _multiturn_layout),
        doc="004 §3.2: 12 + 18 (30 bits) or 12 + 15 (27 bits) + 3 error bits"),
    "AFS60S_PRO": Family(
        dict(steps_per_rev=262144, data_bits=18, special_bits=SICK3,
             error_output=ErrorOutput.ALL_ONES, **_ROTARY_ST),
        fixes=(lambda c, g: _directly_added(c, g),),
        doc="004 §3.3: as AFS60; on an internal error every bit is 1"),
    "AFM60S_PRO": Family(
        dict(steps_per_rev=262144, revolutions_numerator=4096, data_bits=30, turn_bits=12,
             alignment=Alignment.TANNENBAUM, special_bits=SICK3,
             error_output=ErrorOutput.ALL_ONES),
        fixes=(lambda c, g: _directly_added(c, g, 12), _multiturn_layout),
        doc="004 §3.3: 12 + 18 bits + 3 error bits (33 clocks); error -> all ones"),
    "ATM60": Family(
        dict(steps_per_rev=8192, revolutions_numerator=4096, data_bits=25, turn_bits=12,
             alignment=Alignment.TANNENBAUM, formation_period_s=150e-6),
        ATM60_SYNC, (_atm60_layout,), doc="004 §3.4: 25 bits Tannenbaum, 12 + 13, optional error bit"),
    "ATM60_13_12": Family(
        dict(steps_per_rev=4096, revolutions_numerator=8192, data_bits=25, turn_bits=13,
             alignment=Alignment.TANNENBAUM, formation_period_s=150e-6),
        ATM60_SYNC, (_atm60_layout,), doc="004 §3.4 Figure 17: 13 multiturn + 12 singleturn bits"),
    "ARS60": Family(
        dict(steps_per_rev=8192, data_bits=13, alignment=Alignment.LEFT, **_ROTARY_ST),
        fixes=(_ars60_layout,),
        doc="004 §3.5: 13 bits up to 8192 steps; 15 bits + 2 error bits above"),
    "TTK70": Family(
        dict(linear=True, measuring_step_m=1e-6, data_bits=24,
             special_bits=(SpecialBit.ERR_DISTANCE, SpecialBit.ERR_TEMPERATURE), max_clocks=31),
        doc="004 §3.6: 24 position bits + 2 error bits, 26..31 clocks, extra clocks read 0"),
    "KH53": Family(
        dict(linear=True, measuring_step_m=1e-4, data_bits=24,
             error_output=ErrorOutput.ERROR_VALUE, error_value=0xFFFFE),
        doc="004 §3.7: 24 position bits, no error bits, error value FFFFE hex"),
    "TR_PROGRAMMABLE": Family(
        dict(steps_per_rev=4096, revolutions_numerator=4096, data_bits=24),
        doc="001 §5: programmable scaling, code, data bits, formats, special bits"),
    "SSI25_POWERFAIL": Family(
        dict(steps_per_rev=4096, revolutions_numerator=4096, data_bits=24,
             special_bits=(SpecialBit.POWER_FAIL,)),
        doc="003: a 25-bit frame whose last data bit is a PowerFail bit (24 position bits)"),
    "TR_PARITY": Family(
        dict(steps_per_rev=4096, revolutions_numerator=4096, data_bits=24,
             special_bits=(SpecialBit.ENCODER_ERROR, SpecialBit.EVEN_PARITY)),
        doc="001 §5.5.6/§5.5.7: 24 data bits + encoder error + even parity (26 bits)"),
    "TR_CHECKSUM": Family(
        dict(steps_per_rev=4096, revolutions_numerator=4096, data_bits=24, turn_bits=12,
             alignment=Alignment.TANNENBAUM, frame_format=FrameFormat.CHECKSUM),
        fixes=(_exact_data_bits,),
        doc="001 §5.2.4.2: 12 revolution + 16 step bits + 15-bit checksum (43 clocks); "
            "data_bits = the bits of the total number of steps (001 §5.2.1); CRC-15 "
            "polynomial is a simulation choice (protocol/checksum.py)"),
}
FAMILIES["ATM90"] = FAMILIES["ATM60"]


#: the fastest shaft (1/min) assumed where a rotary family's manual states no speed: none of
#: them does. 004 and 003 give none; 001 neither: it leaves technical data to the series'
#: "Product data sheets" ("The following documentation therefore also applies"; not among
#: the manuals here), and its 10-6000 1/min (§5.4.2) is only the range of the speed
#: monitor's adjustable threshold, which a faster shaft exceeds and reports with the
#: overspeed bit (§5.5.2): no limit of the shaft. 12000 1/min is about the mechanical limit
#: of the fastest industrial SSI encoders (common ones are built for 6000-12000 1/min), so
#: no real motion is flagged while a misread frame's jump is. A limit from the SSI frame
#: itself would mean nothing: the counts of one frame at the highest REG_PARA1 bit rate can
#: represent a change of the whole range per frame (docs/node.md)
DEFAULT_MAX_RPM = 12000.0
#: the fastest travel (m/s) assumed for a linear family: 004 §3.6/§3.7 state none (§3.7 only
#: names KH53's "max. traversing speed"); about the fastest linear axes and tape/linear
#: measuring systems run, so a faster decoded step is a bit error, not motion
DEFAULT_MAX_LINEAR_SPEED = 10.0


@dataclasses.dataclass(frozen=True)
class SpeedSpec:
    """The physical speed limit of a family: joint units/s, and where it comes from."""

    #: rad/s (rotary) or m/s (linear)
    limit: float
    linear: bool
    #: the manual's figure, or the documented default
    source: str


def family_max_speed(family: str, linear: bool | None = None) -> SpeedSpec:
    """The speed a joint of ``family`` cannot exceed (``<joint>.max_speed: -1``).

    No family's manual states a shaft speed (the TR overspeed of 001 §5.4.2 is a monitor's
    threshold, see :data:`DEFAULT_MAX_RPM`), so every rotary family (GENERIC and TR
    included) takes :data:`DEFAULT_MAX_RPM`, linear ones :data:`DEFAULT_MAX_LINEAR_SPEED`.
    ``linear`` overrides the family's own kind (a joint whose layout is unknown is linear
    when it has a measuring step); an unknown family is taken as GENERIC.
    """
    key = family.upper()
    base = FAMILIES.get(key)
    cfg = family_config(key) if base is not None else None
    is_linear = linear if linear is not None else bool(cfg is not None and cfg.linear)
    if is_linear:
        return SpeedSpec(DEFAULT_MAX_LINEAR_SPEED, True,
                         f"{DEFAULT_MAX_LINEAR_SPEED:g} m/s: no speed in the family's manual, "
                         "the default for linear encoders (docs/node.md)")
    if key.startswith("TR_"):
        return SpeedSpec(DEFAULT_MAX_RPM / 60.0 * 2.0 * math.pi, False,
                         f"{DEFAULT_MAX_RPM:g} 1/min: 001 states no shaft speed (10-6000 1/min, "
                         "001 §5.4.2, is the speed monitor's threshold, whose excess sets the "
                         "overspeed bit, §5.5.2), the default for rotary encoders "
                         "(docs/node.md)")
    return SpeedSpec(DEFAULT_MAX_RPM / 60.0 * 2.0 * math.pi, False,
                     f"{DEFAULT_MAX_RPM:g} 1/min: no speed in the family's manual, the "
                     "default for rotary encoders (docs/node.md)")


def family_config(family: str, **overrides: object) -> EncoderConfig:
    """The :class:`EncoderConfig` of a preset with ``overrides`` applied and fixed up.

    :param family: the preset's name (case-insensitive)
    :param overrides: :class:`EncoderConfig` fields to change
    :raises ConfigError: an unknown family, or overrides that make no valid configuration
    """
    key = family.upper()
    if key not in FAMILIES:
        raise ConfigError(f"unknown encoder family {family!r}; known: {', '.join(sorted(FAMILIES))}")
    fam = FAMILIES[key]
    fields: dict[str, Any] = {"name": key, **fam.base}
    if overrides.get("ssi_mode") is SsiMode.SYNC:
        fields.update(fam.sync)
    fields.update(overrides)
    # the fix-ups need the resolution and mode, so build once permissively, then fix
    probe = SimpleNamespace(steps_per_rev=fields.get("steps_per_rev", 8192.0),
                            ssi_mode=fields.get("ssi_mode", SsiMode.ASYNC),
                            code=fields.get("code", Code.BINARY),
                            revolutions_numerator=fields.get("revolutions_numerator", 4096),
                            revolutions_divisor=fields.get("revolutions_divisor", 1),
                            total_steps=fields.get("total_steps", 0),
                            origin=fields.get("origin", 0))
    for fix in fam.fixes:
        for k, v in fix(probe, overrides).items():
            if k not in overrides:
                fields[k] = v
    return EncoderConfig(**fields)


__all__ = ["DEFAULT_MAX_LINEAR_SPEED", "DEFAULT_MAX_RPM", "FAMILIES", "Family", "SpeedSpec",
           "family_config", "family_max_speed", "Code"]
