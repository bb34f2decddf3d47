"""What a simulated station is made of: joints (encoder, cable, motion, REG_PARA1), storage, bus.

The same values the node declares as ROS parameters (``<joint>.family``, ``bus.channel``, ...),
as frozen dataclasses without rclpy, so the station can run as a process of its own and read
the node's params file (:func:`load_params_file`, :func:`station_settings`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import IO, Any

import yaml

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.families import FAMILIES
from ssi_bridge.protocol.para1 import validate_para1
from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.family_rules import code_refusal

#: REG_PARA1 the node writes unless told otherwise: 25-bit binary frame, ZERO test on (the
#: module's factory values, 000 Table 19) at 250 kbit/s instead of the factory 500 kbit/s:
#: 004 §2.7 recommends < 400 kHz even for the shortest cables (< 50 m), and the default
#: simulated cable is 10 m. A default the manuals call fine, so it starts without a warning.
DEFAULT_PARA1 = 0x19020000
#: bit rates a CANopen device must support or may support (CiA 301 / CiA 102), bit/s
CIA_BITRATES = (10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)
MOTION_KINDS = ("constant", "still", "sine")
CODES = ("", "binary", "gray")
#: the station reads these node-wide parameters (defaults as the node declares them)
STATION_DEFAULTS: dict[str, Any] = {
    "joints": ["joint1"], "storage_path": "", "bus.interface": "virtual",
    "bus.channel": "ssi_bridge", "bus.bitrate": 500_000, "bus.node_id": 1,
}
#: per-joint parameters the station reads ('<joint>.<name>'), with the node's defaults
JOINT_DEFAULTS: dict[str, Any] = {
    "slot": 0, "family": "GENERIC", "code": "", "cable_length": 10.0, "para1": DEFAULT_PARA1,
    "steps_per_rev": 0, "revolutions": 0, "measuring_step": 0.0, "direction": 1,
    "motion.kind": "constant", "motion.velocity": 0.25, "motion.amplitude": 0.5,
    "motion.frequency": 0.5, "motion.start": 0.0,
}


@dataclass(frozen=True)
class BusConfig:
    """Where the gateway and the client meet: python-can interface, channel, bit rate, node."""

    #: python-can interface name ("virtual", "socketcan", "pcan", ...)
    interface: str = "virtual"
    #: python-can channel (virtual: any string; every bus on the same string is one wire)
    channel: str = "ssi_bridge"
    #: bit rate in bit/s, one of :data:`CIA_BITRATES` (the simulated wire times frames at it)
    bitrate: int = 500_000
    #: CANopen node id of the XN-GW-CANOPEN (1-127)
    node_id: int = 1

    def __post_init__(self) -> None:
        if not self.interface:
            raise ConfigError("BusConfig.interface must name a python-can interface")
        if self.channel in ("", None):
            raise ConfigError("BusConfig.channel must not be empty")
        if self.bitrate not in CIA_BITRATES:
            raise ConfigError(
                f"BusConfig.bitrate {self.bitrate} bit/s is not a CiA bit rate {CIA_BITRATES}")
        if not 1 <= self.node_id <= 127:
            raise ConfigError(f"BusConfig.node_id {self.node_id} outside 1-127")


@dataclass(frozen=True)
class MotionSettings:
    """Simulated shaft motion of one joint (revolutions or metres, on the station's clock)."""

    #: "constant", "still" or "sine"
    kind: str = "constant"
    #: constant: speed in rev/s (rotary) or m/s (linear)
    velocity: float = 0.25
    #: sine: amplitude in rev or m
    amplitude: float = 0.5
    #: sine: frequency in Hz
    frequency: float = 0.5
    #: start position in rev or m
    start: float = 0.0


@dataclass(frozen=True)
class JointSettings:
    """One configured joint: which module slot, which encoder, how counts become units."""

    name: str
    slot: int
    family: str = "GENERIC"
    #: simulated encoder's transmit code: "" (family default), "binary" or "gray"
    code: str = ""
    #: simulated SSI cable length (m): sets the line delay and the 004 §2.7 bit-rate check
    cable_length: float = 10.0
    para1: int = DEFAULT_PARA1
    #: REG_SSI_MASK written at start-up (000 Table 3, object 0x5840); -1: leave it as stored
    ssi_mask: int = -1
    #: 0: take it from the simulated encoder family
    steps_per_rev: int = 0
    revolutions: int = 0
    measuring_step: float = 0.0
    direction: int = 1
    motion: MotionSettings = field(default_factory=MotionSettings)
    #: node id of the XN-GW-CANOPEN station holding the module (0: the bus' first station)
    station: int = 0


def joint_from_values(joint: str, jv: Mapping[str, object], *, slot: int,
                      station: int = 0) -> JointSettings:
    """One joint's settings from its values ``{"<key>": value}`` (the keys of JOINT_DEFAULTS).

    The checks every reader of ``<joint>.*`` makes, whether the station reads a params file or
    the node its declared parameters: one place, so both refuse the same values alike, before
    anything is started: an unknown family and a REG_PARA1 the module would refuse with
    ERR_PARA (000 Table 19) included.

    :param joint: the joint's name (how an error names the key: ``<joint>.<key>``)
    :param jv: its values, as read from a params file or the node's parameters (unchecked)
    :param slot: the module's slot on its station (1-based)
    :param station: the station's node id (0: the node's own ``node_id``)
    :returns: the checked settings
    :raises ConfigError: a value of the wrong kind or out of its allowed set, naming the key

    (``TypeError`` inside is turned into that ConfigError.)
    """

    def number(key: str, kind: type[int] | type[float], default: object = None) -> float:
        value = jv.get(key, default)
        try:
            if not isinstance(value, (int, float, str)):
                raise TypeError(type(value).__name__)
            return kind(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{joint}.{key} {str(value)[:40]!r}: not "
                              f"{'an integer' if kind is int else 'a number'}") from None

    def integer(key: str, default: object = None) -> int:
        return int(number(key, int, default))

    family = str(jv["family"])
    if family.upper() not in FAMILIES:
        raise ConfigError(f"{joint}.family {family[:40]!r}: unknown encoder family; known: "
                          f"{', '.join(sorted(FAMILIES))}")
    para1 = integer("para1")
    reason = validate_para1(para1)
    if reason:
        shown = f"0x{para1:08X}" if para1 >= 0 else str(para1)
        raise ConfigError(f"{joint}.para1 {shown} is invalid: {reason}")
    if jv["motion.kind"] not in MOTION_KINDS:
        raise ConfigError(f"{joint}.motion.kind {jv['motion.kind']!r}: one of {MOTION_KINDS}")
    if jv["code"] not in CODES:
        raise ConfigError(f"{joint}.code {jv['code']!r}: one of {CODES}")
    refusal = code_refusal(str(jv["family"]), Code(jv["code"])) if jv["code"] else None
    if refusal:  # the family's manual does not offer it (family_rules.py)
        raise ConfigError(f"{joint}.code: {refusal}")
    if jv["direction"] not in (1, -1):
        raise ConfigError(f"{joint}.direction {jv['direction']}: must be 1 or -1")
    return JointSettings(
        name=joint, slot=slot, station=station, family=str(jv["family"]), code=str(jv["code"]),
        cable_length=number("cable_length", float), para1=para1,
        ssi_mask=integer("ssi_mask", -1), steps_per_rev=integer("steps_per_rev"),
        revolutions=integer("revolutions"), measuring_step=number("measuring_step", float),
        direction=integer("direction"),
        motion=MotionSettings(kind=str(jv["motion.kind"]),
                              velocity=number("motion.velocity", float),
                              amplitude=number("motion.amplitude", float),
                              frequency=number("motion.frequency", float),
                              start=number("motion.start", float)))


def check_joint_names(names: list[str], shown: str = "") -> None:
    """ConfigError unless ``names`` are non-empty, unique, and none is the name of another
    /diagnostics status of the node (``bus``, ``station <id>``: ``<node>: bus`` would then
    name two statuses). ``shown`` is how the list is echoed (default: as it is)."""
    if not names or len(set(names)) != len(names) or not all(names):
        raise ConfigError(f"joints {shown or names} must be non-empty, unique names")
    for name in names:
        if name == "bus" or re.fullmatch(r"station \d+", name):
            raise ConfigError(f"joint name {name!r} is the name of the node's {name} status in "
                              f"/diagnostics ('<node>: {name}'): name the joint otherwise")


def make_joints(names: list[str], values: Mapping[str, Any]) -> tuple[JointSettings, ...]:
    """Joints from ``names`` and per-joint values ``{"<joint>.<key>": value}`` (checked).

    :param names: the joints, in the ``joints`` parameter's order
    :param values: parameter values by dotted name
    :raises ConfigError: more than 8 joints, a slot outside 1-8, two joints on one slot, or a
        value :func:`joint_from_values` refuses
    """
    check_joint_names(names)
    if len(names) > 8:
        raise ConfigError(f"{len(names)} joints: a station holds at most 8 XN-1SSI modules")
    joints = []
    for index, joint in enumerate(names):
        jv = {key: values.get(f"{joint}.{key}", default) for key, default in JOINT_DEFAULTS.items()}
        if not 0 <= int(jv["slot"]) <= 8:
            raise ConfigError(f"{joint}.slot {jv['slot']}: 1-8 (0: position in joints + 1)")
        joints.append(joint_from_values(joint, jv, slot=int(jv["slot"]) or index + 1))
    slots = [j.slot for j in joints]
    if len(set(slots)) != len(slots):
        raise ConfigError(f"joints share a module slot: {dict(zip(names, slots))}")
    return tuple(joints)


@dataclass(frozen=True)
class StationSettings:
    """A whole simulated station: its joints, where retentive registers live, its bus."""

    joints: tuple[JointSettings, ...]
    bus: BusConfig = field(default_factory=BusConfig)
    #: file of the modules' retentive registers ('' = memory only)
    storage_path: str = ""


def _flatten(values: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(_flatten(value, f"{name}."))
        else:
            out[name] = value
    return out


def load_params_file(stream: IO[str], node_name: str = "ssi_bridge") -> dict[str, object]:
    """The ``ros__parameters`` a ROS 2 params file gives a node named ``node_name``.

    Sections apply in file order: ``/**``, ``<node_name>``, ``/<node_name>`` and
    ``/<namespace>/<node_name>`` all match; nested keys become dotted names (``bus.channel``).

    :param stream: the params file's text
    :param node_name: the node's name (the sections that apply to it)
    :raises ConfigError: not YAML, or not a mapping of sections
    """
    try:
        # libyaml's parser where PyYAML has it: the same documents, far faster for the
        # station's parameters the node pipes through here (a long name repeated per key)
        doc = yaml.load(stream, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)) or {}
    except yaml.YAMLError as err:
        raise ConfigError(f"params file is not YAML: {err}") from None
    if not isinstance(doc, Mapping):
        raise ConfigError("params file: expected '<node>: {ros__parameters: {...}}' sections")
    values: dict[str, Any] = {}
    for section, body in doc.items():
        name = str(section)
        match = name in ("/**", node_name, f"/{node_name}") or name.endswith(f"/{node_name}")
        if match and isinstance(body, Mapping) and isinstance(body.get("ros__parameters"),
                                                              Mapping):
            values.update(_flatten(body["ros__parameters"]))
    return values


def station_settings(values: Mapping[str, object]) -> StationSettings:
    """StationSettings from node parameter values (dotted names; absent ones take defaults).

    :param values: parameter values by dotted name (unchecked)
    :raises ConfigError: a value the schema does not allow, naming the parameter
    """
    v = {**STATION_DEFAULTS, **values}
    names = v["joints"]
    if not isinstance(names, list):
        raise ConfigError(f"joints {names!r} must be a list of names")
    joints = make_joints([str(n) for n in names], v)
    try:
        bus = BusConfig(interface=str(v["bus.interface"]), channel=str(v["bus.channel"]),
                        bitrate=int(v["bus.bitrate"]), node_id=int(v["bus.node_id"]))
    except (TypeError, ValueError) as err:
        raise ConfigError(f"bus parameters: {err}") from None
    return StationSettings(joints=joints, bus=bus, storage_path=str(v["storage_path"]))
