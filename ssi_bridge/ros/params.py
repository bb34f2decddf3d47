"""Every parameter of the node, declared in one place with descriptions and ranges.

``ros2 param describe`` shows each one's meaning, unit and range. Per-joint parameters live
under ``<joint>.`` (e.g. ``joint1.para1``) and are declared after ``joints`` is known.
Values are gathered into frozen settings dataclasses that the rest of the node reads.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.joint_encoder import joint_config
from ssi_bridge.ros.param_table import (
    JOINT_PARAMETERS, NODE_PARAMETERS, RENAMED, nesting_clashes,
)
from ssi_bridge.ros.qos_overrides import stray_overrides
from ssi_bridge.ros.rclpy_compat import parameter_overrides

# the station's part of the settings lives with the station (gateway/), rclpy-free
from ssi_bridge.protocol.settings import (  # noqa: F401 - DEFAULT_PARA1, JointSettings re-exported
    DEFAULT_PARA1, JointSettings, check_joint_names, joint_from_values,
)

#: smallest record.max_size (bytes); the same floor as record/bag.py's MIN_SPLIT_SIZE
MIN_SPLIT_SIZE = 64 * 1024


@dataclass(frozen=True)
class NodeSettings:
    """Node-wide settings."""

    joints: tuple[JointSettings, ...]
    publish_rate: float = 100.0
    diagnostics_period: float = 1.0
    frame_id: str = ""
    #: simulation.enabled: the node starts and drives a simulated station of its own
    simulation: bool = True
    #: how the node reaches its simulated station: "udp_multicast" (child process) or "virtual"
    simulation_transport: str = "udp_multicast"
    #: seconds the node waits for the simulated station's boot-up at start
    simulation_start_timeout: float = 30.0
    #: SCHED_FIFO priority of the station child process (0: normal scheduling)
    simulation_station_priority: int = 10
    bus_interface: str = "virtual"
    bus_channel: str = "ssi_bridge"
    bus_bitrate: int = 500_000
    #: bound of one SDO transfer step (s), bus.sdo_timeout
    bus_sdo_timeout: float = 0.5
    node_id: int = 1
    #: node ids of the XN-GW-CANOPEN stations this master drives (() : just ``node_id``)
    stations: tuple[int, ...] = ()
    storage_path: str = ""
    velocity_window: int = 5
    stale_cycles: int = 5
    #: latch_bound: the gateway's reaction allowance (s) for a sample to count as latched at
    #: its SYNC (core/cycle_log.py); the node adds one cycle's wire time
    latch_bound: float = 0.002
    record_enabled: bool = False
    record_root: str = "ssi_bridge_sessions"
    record_path: str = ""
    record_compression: str = "zstd"
    record_can_log: bool = False
    #: split a session into a new file at this size (bytes) / duration (s); 0 = never
    record_max_size: int = 0
    record_max_duration: int = 0
    cpu_affinity: tuple[int, ...] = ()
    #: SCHED_FIFO priority of the cycle thread (0: normal scheduling)
    cycle_priority: int = 5
    #: observe another master's traffic (or a replayed log) instead of driving the bus
    bus_listen_only: bool = False
    #: a CAN log (python-can format) to replay on a private virtual channel; implies listen-only
    replay_can_log: str = ""
    replay_rate: float = 1.0
    replay_exit_at_end: bool = False
    replay_wait_for_subscribers: float = 0.0
    #: live view (ros/liveview.py): Foxglove WebSocket port, 0 = off; address it binds to
    foxglove_port: int = 0
    foxglove_address: str = "127.0.0.1"
    #: the live view also offers the services / the parameters (ros/liveview_*.py)
    foxglove_services: bool = True
    foxglove_parameters: bool = True

    @property
    def station_ids(self) -> tuple[int, ...]:
        """The stations' node ids, first one first (``(node_id,)`` unless ``stations``)."""
        return self.stations or (self.node_id,)

    def station_joints(self, node_id: int) -> tuple[JointSettings, ...]:
        """The joints whose modules sit in station ``node_id``."""
        return tuple(j for j in self.joints if j.station == node_id)

    @property
    def listen_only(self) -> bool:
        """True when the node only observes the bus (``bus.listen_only`` or a replay)."""
        return self.bus_listen_only or bool(self.replay_can_log)


TRANSPORTS = ("udp_multicast", "virtual")


def _declare(node: Node, name: str, default: Any, descriptor: ParameterDescriptor) -> Any:
    if name == "autostart" and node.has_parameter(name):  # declared first (ros/lifecycle.py)
        return node.get_parameter(name).value
    descriptor.name = name
    if isinstance(default, list):
        descriptor.type = (ParameterType.PARAMETER_INTEGER_ARRAY if default and
                           isinstance(default[0], int) else ParameterType.PARAMETER_STRING_ARRAY)
    return node.declare_parameter(name, default, descriptor).value


def _cpus(values: list[int]) -> tuple[int, ...]:
    """The CPUs of ``cpu_affinity`` ([-1]: none), checked against the machine's."""
    cpus = tuple(int(c) for c in values if int(c) != -1)
    available = sorted(os.sched_getaffinity(0))
    bad = [c for c in cpus if c not in available]
    if bad:
        raise ConfigError(f"cpu_affinity {list(cpus)}: CPU(s) {bad} not available; this "
                          f"process may use {available}")
    return cpus


def _stations(values: list[int], node_id: int) -> tuple[int, ...]:
    """The ``stations`` list checked: CANopen node ids 1-127, unique; [0] -> (node_id,)."""
    ids = tuple(int(v) for v in values if int(v) != 0) or (int(node_id),)
    bad = [i for i in ids if not 1 <= i <= 127]
    if bad or len(set(ids)) != len(ids):
        raise ConfigError(f"stations {list(ids)}: unique CANopen node ids 1-127")
    return ids


#: parameters rclpy itself declares or reads, never reported as unknown
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")
RCLPY_PREFIXES = ("qos_overrides.",)
#: longest echo of a configured value in a message
ECHO = 80


def _echo(value: Any) -> str:
    """A configured value as text for a message, cut to :data:`ECHO` characters."""
    text = repr(value)
    return text if len(text) <= ECHO else f"{text[:ECHO]}... ({len(text)} characters)"


def unknown_overrides(node: Node) -> list[str]:
    """One line per parameter given (params file, ``-p``) that no declared parameter takes,
    with the closest declared name: a typo such as ``publish_rte`` is otherwise silently
    ignored."""
    import difflib

    declared = set(node.list_parameters([], 0).names)
    given = parameter_overrides(node)
    out = stray_overrides(node, list(given))  # qos_overrides.* (ros/qos_overrides.py)
    for name in sorted(given):
        if name in declared or name in RCLPY_PARAMETERS or name.startswith(RCLPY_PREFIXES):
            continue
        close = difflib.get_close_matches(name, sorted(declared), n=1, cutoff=0.6)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        joint, _, key = name.partition(".")
        if key in JOINT_PARAMETERS and f"{joint}.slot" not in declared:
            hint = (f"; '{_echo(joint)[1:-1]}' is not in joints "
                    f"{_echo(list(node.get_parameter('joints').value))}")
        out.append(f"parameter '{_echo(name)[1:-1]}' is not a parameter of this node and is "
                   f"ignored{hint}")
    return out


def renamed_overrides(node: Node) -> None:
    """ConfigError for a parameter given (params file, ``-p``) under its old name
    (:data:`~ssi_bridge.ros.param_table.RENAMED`), naming the new one."""
    given = parameter_overrides(node)
    for old, new in RENAMED.items():
        if old in given:
            raise ConfigError(f"parameter '{old}' is now '{new}' (a name that is also the prefix "
                              f"of others breaks 'ros2 param dump'): set {new} instead")


def _joint_name_clashes(node: Node, names: list[str]) -> None:
    """ConfigError when a joint's parameters would make a name both a value and a prefix
    (a joint named ``publish_rate``: ``publish_rate`` and ``publish_rate.slot``)."""
    declared = set(node.list_parameters([], 0).names)
    per_joint = {f"{joint}.{key}" for joint in names for key in JOINT_PARAMETERS}
    for value, longer in nesting_clashes(declared | per_joint):
        if value in per_joint or longer in per_joint:
            raise ConfigError(f"joints {_echo(names)}: parameter '{_echo(value)[1:-1]}' would "
                              f"also be the prefix of '{_echo(longer)[1:-1]}' (params files and "
                              "'ros2 param dump' nest names on '.'): name the joint otherwise")


def declare_parameters(node: Node) -> NodeSettings:
    """Declare every parameter on ``node`` and return the validated settings.

    Raises ConfigError, before anything is opened, for an old parameter name, a joint name
    that clashes with a parameter name, or a value out of place."""
    renamed_overrides(node)
    values = {name: _declare(node, name, d, desc) for name, (d, desc) in NODE_PARAMETERS.items()}
    if not values["joints"]:
        # an empty YAML list has no element type, so ROS hands it over as "not set"
        raise ConfigError("joints is empty: list at least one joint name, one per XN-1SSI "
                          "channel (e.g. joints: [joint1])")
    names = [str(j) for j in values["joints"]]
    check_joint_names(names, _echo(names))
    _joint_name_clashes(node, names)
    stations = _stations(values["stations"], values["bus.node_id"])
    joints = []
    per_station: dict[int, int] = {}
    for joint in names:
        jv = {key: _declare(node, f"{joint}.{key}", d, desc)
              for key, (d, desc) in JOINT_PARAMETERS.items()}
        station = jv["station"] or stations[0]
        if station not in stations:
            raise ConfigError(f"{joint}.station {station}: not one of stations {list(stations)}")
        index = per_station[station] = per_station.get(station, 0) + 1
        if index > 8:
            raise ConfigError(f"station {station}: more than 8 joints; a station holds at most "
                              "8 XN-1SSI modules")
        joints.append(joint_from_values(joint, jv, slot=jv["slot"] or index, station=station))
    slots = [(j.station, j.slot) for j in joints]
    if len(set(slots)) != len(slots):
        raise ConfigError("joints share a module slot: "
                          f"{ {j.name: f'station {j.station} slot {j.slot}' for j in joints} }")
    empty = [sid for sid in stations if not any(j.station == sid for j in joints)]
    if empty:
        raise ConfigError(f"stations {empty} hold no joint: name them in '<joint>.station'")
    if len(stations) > 1 and (values["bus.listen_only"] or values["replay.can_log"]):
        raise ConfigError("bus.listen_only / replay.can_log observe one station: use a single "
                          "entry in stations")
    if values["foxglove.port"] and not str(values["foxglove.address"]).strip():
        raise ConfigError("foxglove.address is empty: give the address the live view binds to "
                          "(127.0.0.1: this host only)")
    if values["record.compression"] not in ("zstd", "lz4", "none"):
        raise ConfigError(f"record.compression {values['record.compression']!r}: zstd, lz4 or none")
    if 0 < values["record.max_size"] < MIN_SPLIT_SIZE:
        raise ConfigError(f"record.max_size {values['record.max_size']}: 0 (no split) or at "
                          f"least {MIN_SPLIT_SIZE} bytes")
    if values["simulation.transport"] not in TRANSPORTS:
        raise ConfigError(f"simulation.transport {values['simulation.transport']!r}: one of "
                          f"{TRANSPORTS}")
    for flag in ("bus.listen_only", "replay.can_log"):
        if values[flag] and values["simulation.enabled"]:
            raise ConfigError(f"{flag} needs simulation.enabled:=false: the simulated station "
                              "needs this node to drive its bus")
    settings = NodeSettings(
        joints=tuple(joints), publish_rate=values["publish_rate"],
        diagnostics_period=values["diagnostics_period"], frame_id=values["frame_id"],
        simulation=values["simulation.enabled"],
        simulation_transport=values["simulation.transport"],
        simulation_start_timeout=values["simulation.start_timeout"],
        simulation_station_priority=values["simulation.station_priority"],
        bus_interface=values["bus.interface"],
        bus_channel=values["bus.channel"], bus_bitrate=values["bus.bitrate"],
        bus_sdo_timeout=values["bus.sdo_timeout"],
        node_id=stations[0], stations=stations, storage_path=values["storage_path"],
        velocity_window=values["velocity_window"], stale_cycles=values["stale_cycles"],
        latch_bound=values["latch_bound"], record_enabled=values["record.enabled"],
        record_root=values["record.root"],
        record_path=values["record.path"], record_compression=values["record.compression"],
        record_can_log=values["record.can_log"], record_max_size=values["record.max_size"],
        record_max_duration=values["record.max_duration"], bus_listen_only=values["bus.listen_only"],
        cpu_affinity=_cpus(values["cpu_affinity"]), cycle_priority=values["cycle_priority"],
        replay_can_log=values["replay.can_log"], replay_rate=values["replay.rate"],
        replay_exit_at_end=values["replay.exit_at_end"],
        replay_wait_for_subscribers=values["replay.wait_for_subscribers"],
        foxglove_port=values["foxglove.port"], foxglove_address=values["foxglove.address"].strip(),
        foxglove_services=values["foxglove.services"],
        foxglove_parameters=values["foxglove.parameters"])
    check_simulated_layouts(settings)
    for line in unknown_overrides(node):  # warnings only once the settings can run
        node.get_logger().warning(line)
    return settings


def check_simulated_layouts(settings: NodeSettings) -> None:
    """With a simulated station, every joint's encoder layout must be one it can simulate.

    The station builds each joint's encoder from the family preset and the overrides
    (:func:`~ssi_bridge.protocol.joint_encoder.joint_config`) and refuses to start otherwise;
    checked here, the refusal comes before the station is started or the bus opened. A real
    station only loses the frame checks of such a joint (a warning at start-up).

    Raises ConfigError naming the joint and the rule.
    """
    if not settings.simulation:
        return
    for joint in settings.joints:
        try:
            joint_config(joint)
        except ConfigError as err:
            raise ConfigError(f"{joint.name}: the simulated station cannot build its encoder: "
                              f"{err}") from None
