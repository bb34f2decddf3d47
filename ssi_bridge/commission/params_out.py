"""Write the params file the node starts with: bus, stations, one joint per working encoder.

Every inferred value carries a comment with its evidence and certainty, so a person can see
what was read (REG_PARA1, certain), what the frames showed (family, code, resolution) and what
is only a default (a resolution the frame cannot show). The file is the node's own format (a
ROS 2 params file, ``/**: ros__parameters``), read by ``--params-file``.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone

from ssi_bridge.commission.analyze import SlotResult
from ssi_bridge.commission.infer import MotionState
from ssi_bridge.protocol.para1 import BIT_RATES_HZ, Para1

#: the node parameter that selects a simulated station, and the value a real station needs.
#: One place, so a rename of the parameter is a one-line change here.
SIMULATION_KEY = "simulation.enabled"
SIMULATION_OFF = "false"


@dataclass(frozen=True)
class BusSpec:
    """The bus the tool ran on, written as the node's ``bus.*`` parameters."""

    interface: str
    channel: str
    bitrate: int


def joint_name(res: SlotResult) -> str:
    """The joint's name: station and slot (never 'bus' or 'station N', the node's statuses).

    :param res: the slot's result
    """
    return f"node{res.node_id}_slot{res.slot}"


def describe_para1(p: Para1) -> str:
    """REG_PARA1's fields in words (000 Table 19).

    :param p: the decoded REG_PARA1
    """
    words = [f"{p.ssi_frame_len}-bit frame", "Gray" if p.ssi_code_gray else "binary",
             f"{BIT_RATES_HZ.get(p.ssi_bit_rate, 0) / 1000:g} kbit/s"]
    if p.invalid_bits_lsb:
        words.append(f"{p.invalid_bits_lsb} invalid LSB")
    if p.invalid_bits_msb:
        words.append(f"{p.invalid_bits_msb} invalid MSB")
    if p.dis_err_ssi:
        words.append("no ZERO test")
    return ", ".join(words)


def _family_lines(res: SlotResult) -> list[str]:
    best = res.best
    if best is None:
        return ["      family: GENERIC   # no family of the manuals fits the frame: check it"]
    tied = [f.family for f in res.groups[0]]
    if len(tied) == 1:
        certainty = "the only family whose frame fits"
    else:
        certainty = (f"tied with {', '.join(t for t in tied if t != best.family)}: the frame "
                     "cannot tell them apart, choose")
    lines = [f"      # {'; '.join(best.evidence)}", f"      # {best.source}",
             f"      family: {best.family}   # {certainty}"]
    code = best.overrides.get("code")
    motion = res.motion
    if motion is not None and motion.code is not None:
        lines.append(f"      code: {motion.code}   # seen in the frames (continuous as "
                     f"{motion.code})")
    elif code is not None:
        lines.append(f"      code: {code.value}   # from REG_PARA1 SSI_CODE_G/D (not seen)")
    cfg = best.config
    if cfg.linear:
        lines.append(f"      measuring_step: {cfg.measuring_step_m:g}   # m, the family's "
                     "default: not in the frame, check it")
    else:
        where = ("the family's default: not in the frame" if best.default_resolution
                 else "where the position LSB sits in the frame")
        lines.append(f"      steps_per_rev: {int(cfg.steps_per_rev)}   # {where}")
        lines.append(f"      revolutions: {cfg.revolutions_numerator}   # the family's "
                     "multiturn range" if cfg.revolutions_numerator > 1 else
                     "      revolutions: 1   # singleturn")
    return lines


def _direction_line(res: SlotResult) -> str:
    motion = res.motion
    if motion is None or motion.state is not MotionState.MOVING or not motion.direction:
        return ("      direction: 1   # not seen (the encoder did not move clearly): set -1 if "
                "the joint runs against the count")
    way = "increased" if motion.direction > 0 else "decreased"
    return (f"      direction: 1   # the count {way} while sampling; -1 if the joint moved "
            "the other way")


def render(bus: BusSpec, results: list[SlotResult], source: str = "") -> str:
    """The params file text for the joints of ``results`` (slots without a joint left out).

    :param bus: the bus the params file names (interface, channel, bit rate)
    :param results: the judged slots; each with a joint becomes one
    :param source: where the values came from, written as the file's comment
    :returns: the YAML text of a ROS 2 params file
    """
    joints = [r for r in results if r.joint]
    stations = sorted({r.node_id for r in results})
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    out = [f"# ssi_bridge params file written by `commission` {stamp}{source}",
           "#   ros2 run ssi_bridge ssi_bridge_node --ros-args --params-file <this file>",
           "/**:", "  ros__parameters:",
           f"    {SIMULATION_KEY}: {SIMULATION_OFF}   # a real station on the bus below",
           f"    bus.interface: {bus.interface}", f"    bus.channel: {_quote(bus.channel)}",
           f"    bus.bitrate: {bus.bitrate}",
           f"    bus.node_id: {stations[0] if stations else 1}",
           f"    stations: [{', '.join(str(s) for s in stations)}]" if stations
           else "    # no XN-GW-CANOPEN found",
           f"    joints: [{', '.join(joint_name(r) for r in joints)}]"]
    for res in joints:
        assert res.para1_joint is not None
        p = Para1.decode(res.para1_joint)
        read = (f"read through the register handshake" if res.para1_joint == res.para1
                else f"corrected from the 0x{(res.para1 or 0):08X} read")
        out += ["", f"    {joint_name(res)}:",
                f"      station: {res.node_id}", f"      slot: {res.slot}",
                f"      para1: 0x{res.para1_joint:08X}   # {read}: {describe_para1(p)} "
                "(000 Table 19)",
                *_family_lines(res), _direction_line(res)]
        for warning in res.warnings:
            out.append(f"      # note: {warning}")
    return "\n".join(out) + "\n"


def _quote(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


__all__ = ["BusSpec", "SIMULATION_KEY", "SIMULATION_OFF", "describe_para1", "joint_name",
           "render"]
