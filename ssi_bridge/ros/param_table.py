"""The table of the node's parameters: name -> (default, descriptor with meaning and range).

``ros2 param describe`` shows each one's description, unit and range. Node-wide parameters are
in :data:`NODE_PARAMETERS`, per-joint ones (declared as ``<joint>.<name>``) in
:data:`JOINT_PARAMETERS`; :mod:`ssi_bridge.ros.params` declares them and checks the values
(``autostart`` first, by ``ros/lifecycle.py``, with its executable's default).

No name is both a value and the ``.``-prefix of another: ``ros2 param dump`` and the nested
form of a params file split names on ``.``, so such a pair cannot be written
(:func:`nesting_clashes`). :data:`RENAMED` maps old names to the new ones; the node refuses an
old name with the new one in the message.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from ssi_bridge.protocol.settings import DEFAULT_PARA1


def _describe(description: str, *, read_only: bool = False,
              int_range: tuple[int, int] | None = None,
              float_range: tuple[float, float] | None = None) -> ParameterDescriptor:
    d = ParameterDescriptor(description=description, read_only=read_only)
    if int_range is not None:
        d.integer_range = [IntegerRange(from_value=int_range[0], to_value=int_range[1], step=1)]
    if float_range is not None:
        d.floating_point_range = [FloatingPointRange(
            from_value=float(float_range[0]), to_value=float(float_range[1]), step=0.0)]
    return d


#: name -> (default, descriptor); node-wide parameters
NODE_PARAMETERS: dict[str, tuple[Any, ParameterDescriptor]] = {
    "joints": (["joint1"], _describe(
        "Joint names, one per XN-1SSI channel; per-joint settings are '<joint>.*'",
        read_only=True)),
    "publish_rate": (100.0, _describe(
        "Cycle rate in Hz: one SYNC, one acquisition and one joint_states message per cycle",
        float_range=(1.0, 2000.0))),
    "diagnostics_period": (1.0, _describe(
        "Seconds between /diagnostics messages (also sent at once on a level change)",
        float_range=(0.1, 60.0))),
    "frame_id": ("", _describe("header.frame_id of joint_states and ~/status")),
    "autostart": (True, _describe(
        "true: configure and activate at start-up (ssi_bridge_node's default); false: start "
        "unconfigured and wait for ~/change_state (ssi_bridge_managed_node's default)",
        read_only=True)),
    "simulation.enabled": (True, _describe(
        "true: start the simulated encoders, XN-1SSI modules and gateway (a station of its "
        "own, see simulation.transport) and drive it over CAN; "
        "false: talk to a real XN-GW-CANOPEN station", read_only=True)),
    "simulation.transport": ("udp_multicast", _describe(
        "How the node reaches its simulated station, always over CAN only: udp_multicast "
        "(the station runs as a child process on python-can's udp_multicast bus on loopback, "
        "group and port derived from bus.channel, the node's name and ROS_DOMAIN_ID) or "
        "virtual (the station runs in the node's process on the virtual bus; also the "
        "fallback without multicast on loopback)",
        read_only=True)),
    "simulation.start_timeout": (30.0, _describe(
        "Seconds the node waits for the simulated station's boot-up message at start, and "
        "again for its first SDO answer (a station process on a busy machine may be late)",
        read_only=True, float_range=(0.5, 120.0))),
    "simulation.station_priority": (10, _describe(
        "SCHED_FIFO priority of the simulated station: the child process (udp_multicast) or "
        "the in-process station's receive thread (virtual), which stand in for hardware that "
        "never waits for a CPU (0: normal scheduling; needs CAP_SYS_NICE or an rtprio limit, "
        "else the node says so and schedules it normally)",
        read_only=True, int_range=(0, 99))),
    "bus.interface": ("virtual", _describe(
        "python-can interface (virtual, socketcan, pcan, kvaser, ...)", read_only=True)),
    "bus.channel": ("ssi_bridge", _describe(
        "python-can channel (virtual: any name; socketcan: can0, ...)", read_only=True)),
    "bus.bitrate": (500_000, _describe(
        "CAN bit rate in bit/s (CiA 301 rates; the simulated wire (virtual, udp_multicast) "
        "times every frame at it)",
        read_only=True, int_range=(10_000, 1_000_000))),
    "bus.sdo_timeout": (0.5, _describe(
        "Seconds one SDO transfer step may take (start-up configuration, ~/sdo_read, "
        "~/sdo_write, register writes by SDO) before the gateway counts as not answering; the "
        "request goes out twice, each waiting half. A real gateway answers in milliseconds; "
        "the margin is for a busy master computer",
        read_only=True, float_range=(0.05, 10.0))),
    "bus.listen_only": (False, _describe(
        "Only observe the bus another master drives: no NMT, SDO, SYNC or RPDO; one cycle is "
        "published per observed SYNC; register services refuse. Needs simulation.enabled:=false",
        read_only=True)),
    "replay.can_log": ("", _describe(
        "Run on a recorded CAN log (e.g. <bag>/can_0.log) instead of a bus: it is played onto "
        "a private virtual channel and observed listen-only. Needs simulation.enabled:=false",
        read_only=True)),
    "replay.rate": (1.0, _describe(
        "Speed factor of the log replay (2.0 = twice as fast); stamps keep the logged spacing",
        read_only=True, float_range=(0.01, 100.0))),
    "replay.wait_for_subscribers": (0.0, _describe(
        "Seconds the log replay waits for a joint_states subscriber before it starts "
        "(0: start at once), so a consumer started with the node misses nothing",
        read_only=True, float_range=(0.0, 300.0))),
    "replay.exit_at_end": (False, _describe(
        "Exit 0 when the replayed log ends (default: log it and keep running, diagnostics "
        "go STALE)", read_only=True)),
    "bus.node_id": (1, _describe("CANopen node id of the XN-GW-CANOPEN gateway",
                                 read_only=True, int_range=(1, 127))),
    "stations": ([0], _describe(
        "Node ids of the XN-GW-CANOPEN stations on the bus, driven by this one master (one "
        "SYNC for all); [0]: just bus.node_id. A joint names its station in '<joint>.station'",
        read_only=True)),
    "cpu_affinity": ([-1], _describe(
        "CPUs the whole node process runs on (e.g. [1]); [-1]: no pinning. Keeping the "
        "simulated station, the bus threads and the cycle on one core saves the cross-core "
        "hand-offs of every cycle (docs/node.md, Performance)", read_only=True)),
    "cycle_priority": (5, _describe(
        "SCHED_FIFO priority of the node's cycle thread (SYNC, TPDO wait, publish), as a "
        "ros2_control loop has: on a busy machine the cycle does not wait behind other "
        "processes (0: normal scheduling; needs CAP_SYS_NICE or an rtprio limit, else the node "
        "says so once and schedules it normally). Below simulation.station_priority: the "
        "simulated hardware answers first. The periodic /diagnostics (its CAM reads "
        "included) runs at cycle_priority - 1 for its few milliseconds, then at the "
        "executor's own scheduling again: it holds Python's lock, which the real-time "
        "threads wait for", read_only=True, int_range=(0, 99))),
    "storage_path": ("", _describe(
        "File holding the retentive registers of the simulated modules (000: REG_PARA1, "
        "limits, offset, mask); empty: keep them in memory only", read_only=True)),
    "velocity_window": (5, _describe(
        "Samples in the velocity estimate (newest - oldest over their time difference)",
        int_range=(2, 100))),
    "latch_bound": (0.002, _describe(
        "Seconds a sample's first TPDO may end after its SYNC, beyond the cycle's wire time, "
        "for the sample to be published as latched at the SYNC (the gateway's reaction "
        "allowance); a later, surplus or out-of-step answer is left out of joint_states and "
        "counted as set aside (docs/node.md)", read_only=True, float_range=(0.0001, 0.5))),
    "stale_cycles": (5, _describe(
        "Cycles without a fresh sample before a joint's diagnostics go STALE",
        int_range=(1, 1000))),
    "record.enabled": (False, _describe(
        "Record a session from start-up (also ~/start_recording)", read_only=True)),
    "record.root": ("ssi_bridge_sessions", _describe(
        "Directory under which session bags are created", read_only=True)),
    "record.path": ("", _describe(
        "Bag directory name under record.root for the start-up session; empty: timestamped",
        read_only=True)),
    "record.compression": ("zstd", _describe("MCAP chunk compression: zstd, lz4 or none",
                                             read_only=True)),
    "record.can_log": (False, _describe(
        "Also log the raw CAN traffic of each session beside the bag (can_0.log, candump "
        "format, read by python-can's LogReader), and of each fault snapshot "
        "(record.snapshot.duration)", read_only=True)),
    "record.max_size": (0, _describe(
        "Split a session into its next file <name>_<k>.mcap once the open one holds this many "
        "bytes (rosbag2 --max-bag-size); 0: no split by size, else at least 65536",
        read_only=True, int_range=(0, 1 << 50))),
    "record.max_duration": (0, _describe(
        "Split a session into its next file once a message is more than this many seconds "
        "after the open file's first one (rosbag2 --max-bag-duration); 0: no split by time",
        read_only=True, int_range=(0, 7 * 86400))),
    "record.snapshot.duration": (0.0, _describe(
        "Fault snapshot: seconds of every recorded topic kept in memory (a ring of serialized "
        "messages, its bytes in the bus diagnostics); written as a bag snapshot_<time>_<joint> "
        "under record.root on ERROR or ~/snapshot. 0: off", read_only=True,
        float_range=(0.0, 600.0))),
    "record.snapshot.after": (5.0, _describe(
        "Fault snapshot: seconds recorded into the snapshot after its last trigger (a fault "
        "within them extends the same bag)", read_only=True, float_range=(0.0, 600.0))),
    "record.snapshot.on_error": (True, _describe(
        "Fault snapshot: write one when a joint or the bus reaches ERROR (with "
        "record.snapshot.duration > 0); false: only on ~/snapshot", read_only=True)),
    "record.snapshot.max_bags": (10, _describe(
        "Fault snapshot: snapshot bags kept under record.root; the oldest beyond this is "
        "removed (said in the log)", read_only=True, int_range=(1, 10000))),
    "foxglove.port": (0, _describe(
        "Live view: TCP port of a Foxglove WebSocket server streaming every topic of the node "
        "(ros2msg schemas, CDR); open Foxglove and connect to ws://localhost:<port>. 0: off",
        read_only=True, int_range=(0, 65535))),
    "foxglove.address": ("127.0.0.1", _describe(
        "Address the live view server binds to: 127.0.0.1 accepts clients of this host only; "
        "an interface address or 0.0.0.0 lets other hosts connect", read_only=True)),
    "foxglove.services": (True, _describe(
        "Live view: offer the node's services (Foxglove's Service Call panel; the same "
        "handlers, checks and ~/events as the ROS services); false: not advertised",
        read_only=True)),
    "foxglove.parameters": (True, _describe(
        "Live view: offer the node's parameters (get, set with the checks of 'ros2 param "
        "set', subscribe); false: no Parameters capability. Both false: a view that only "
        "watches", read_only=True)),
}

#: name -> (default, descriptor); per-joint parameters, declared as '<joint>.<name>'
JOINT_PARAMETERS: dict[str, tuple[Any, ParameterDescriptor]] = {
    "station": (0, _describe("Node id of the station holding the joint's module (one of "
                             "'stations'); 0: the first station", read_only=True,
                             int_range=(0, 127))),
    "slot": (0, _describe("XN-1SSI module slot in the station (1-8, the object subindex); "
                          "0: position in 'joints' + 1", read_only=True, int_range=(0, 8))),
    "family": ("GENERIC", _describe(
        "Encoder family preset (GENERIC, AFM60_MULTI, TTK70, ...): the simulated encoder, and "
        "the layout the frame checks and max_speed follow; an unknown name is refused at "
        "start-up", read_only=True)),
    "code": ("", _describe(
        "Simulated encoder transmit code: '' (family default), 'binary' or 'gray'; REG_PARA1's "
        "SSI_CODE_G/D must match it; a code the family's manual does not offer is refused at "
        "start-up (TR_CHECKSUM: binary only, 001 §5.2.4.2)", read_only=True)),
    "cable_length": (10.0, _describe(
        "Simulated SSI cable length in m (line delay; 004 §2.7 bit-rate recommendation)",
        read_only=True, float_range=(0.0, 1200.0))),
    "para1": (DEFAULT_PARA1, _describe(
        "REG_PARA1 (000 Table 18/19): frame length, bit rate, Gray/binary, invalid bits, "
        "ZERO test; a change is written to the module and refused with its ERR_PARA reason",
        int_range=(0, 0xFFFF_FFFF))),
    "ssi_mask": (-1, _describe(
        "REG_SSI_MASK (000 Table 3, object 0x5840) written at start-up: per byte x, bit 7 "
        "copies frame bit SSI_FRAME_BIT_SELx (bits 4-0, 0 = last bit) into SSI_STSx, bit 6 "
        "also raises SSI_DIAG; -1: leave the module's stored value",
        read_only=True, int_range=(-1, 0xFFFF_FFFF))),
    "steps_per_rev": (0, _describe(
        "Counts per revolution of REG_SSI_POS; 0: from the encoder family",
        read_only=True, int_range=(0, 1 << 31))),
    "revolutions": (0, _describe("Distinguishable revolutions; 0: from the encoder family",
                                 read_only=True, int_range=(0, 1 << 31))),
    "measuring_step": (0.0, _describe(
        "Linear encoders: metres per count; 0: from the encoder family", read_only=True,
        float_range=(0.0, 1.0))),
    "direction": (1, _describe("+1 or -1: sign of the joint against the count direction",
                               read_only=True, int_range=(-1, 1))),
    "max_speed": (-1.0, _describe(
        "Plausibility limit in rad/s (rotary) or m/s (linear): a sample whose step from the "
        "previous one is faster is flagged in diagnostics and its velocity is NaN; 0: off; "
        "-1 (default, on for every family): no family's manual states a shaft speed (the "
        "TR 10-6000 1/min of 001 §5.4.2 is the speed monitor's threshold, not a limit), so "
        "12000 1/min = 1257 rad/s, a typical mechanical limit of fast SSI encoders, for "
        "every rotary family (GENERIC and TR included), or 10 m/s for linear ones; "
        "docs/node.md. Changes at run time",
        float_range=(-1.0, 1e6))),
    "motion.kind": ("constant", _describe("Simulated motion: constant, still or sine",
                                          read_only=True)),
    "motion.velocity": (0.25, _describe("constant: speed in rev/s or m/s", read_only=True,
                                        float_range=(-1000.0, 1000.0))),
    "motion.amplitude": (0.5, _describe("sine: amplitude in rev or m", read_only=True,
                                        float_range=(0.0, 1e6))),
    "motion.frequency": (0.5, _describe("sine: frequency in Hz", read_only=True,
                                        float_range=(0.0, 100.0))),
    "motion.start": (0.0, _describe("start position in rev or m", read_only=True,
                                    float_range=(-1e6, 1e6))),
}

#: old name -> new name: parameters renamed so that no name is both a value and a prefix
RENAMED: dict[str, str] = {"simulation": "simulation.enabled"}


def nesting_clashes(names: Iterable[str]) -> list[tuple[str, str]]:
    """Pairs ``(value, longer)`` where parameter ``value`` is also a ``.``-prefix of parameter
    ``longer`` (e.g. ``bus`` and ``bus.channel``): ``ros2 param dump`` nests names on ``.``
    and fails on such a pair, and a nested params file cannot hold both."""
    given = set(names)
    out = []
    for name in sorted(given):
        parts = name.split(".")
        for k in range(1, len(parts)):
            prefix = ".".join(parts[:k])
            if prefix in given:
                out.append((prefix, name))
    return out
