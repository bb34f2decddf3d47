"""The node's simulated station: started, watched and stopped by the node, reached over CAN only.

``simulation.transport: udp_multicast`` (default) runs the station as a child process (the
``station`` program, :mod:`ssi_bridge.sim.program`) on python-can's udp_multicast
bus on loopback, on a group and port derived from ``bus.channel``, the node's name and
``ROS_DOMAIN_ID`` (:func:`with_station_bus`); ``virtual`` is the
fallback for machines without multicast on loopback: the same station in the node's process
on the in-process virtual bus. Either way the node talks to it only through the bus. The
start waits for the station's boot-up message (bounded by ``simulation.start_timeout``).

The child dies with the node: ``PR_SET_PDEATHSIG`` (SIGTERM when the thread that forked it
ends; the node forks from its main thread, which lives as long as the node) and the child's
own check of its parent process. ROS-free.
"""

from __future__ import annotations

import ctypes
import dataclasses
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from typing import Any

import yaml

from ssi_bridge.sim.supervisor.boot import BootWatch
from ssi_bridge.exceptions import BusError, GatewayUnavailable
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.base.udp_bus import derive_channel
from ssi_bridge.protocol.settings import BusConfig, JOINT_DEFAULTS, JointSettings, StationSettings
from ssi_bridge.sim.gateway.station import Station
from ssi_bridge.sim.supervisor.settings import AnySettings, NodeSettings

logger = logging.getLogger(__name__)

#: prctl(2) option: signal this process when its parent (thread) dies
PR_SET_PDEATHSIG = 1
_LIBC = ctypes.CDLL(None, use_errno=True)


#: the node's default fully qualified name: its derived bus is the one of ``bus.channel`` alone
DEFAULT_NODE = "/ssi_bridge"
#: rcl's domain without ROS_DOMAIN_ID (or with it empty)
DEFAULT_DOMAIN = 0


def ros_domain_id() -> int:
    """The DDS domain this process's nodes join by default: ``ROS_DOMAIN_ID`` as rcl reads it
    (unset or empty: 0). A value rcl refuses has ended ``rclpy.init`` before this is asked;
    here it counts as the default."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip()
    try:
        return int(text) if text else DEFAULT_DOMAIN
    except ValueError:
        return DEFAULT_DOMAIN


def with_station_bus(s: AnySettings, node: str = DEFAULT_NODE,
                     domain: int | None = None) -> AnySettings:
    """``s`` with the bus the node ``node`` (fully qualified name) shares with its station.

    udp_multicast: the user's udp_multicast channel, else a group and port of their own on
    loopback, derived from ``bus.channel``, for any other node name than the default from the
    name too, and for any other DDS domain than 0 from ``domain`` too (default: this process's
    ``ROS_DOMAIN_ID``): bridges in different namespaces or domains never meet on one bus by
    accident (a CAN bus has one master). virtual: the bus as configured (it is the process's
    own). The node's client, CAN log sniffer and diagnostics all use the result.
    """
    if s.simulation_transport == "udp_multicast" and s.bus_interface != "udp_multicast":
        key = s.bus_channel if node == DEFAULT_NODE else f"{node}:{s.bus_channel}"
        domain = ros_domain_id() if domain is None else domain
        if domain != DEFAULT_DOMAIN:
            key = f"domain {domain}:{key}"
        return dataclasses.replace(s, bus_interface="udp_multicast",
                                   bus_channel=derive_channel(key))
    return s


def station_bus(s: NodeSettings) -> BusConfig:
    """The bus config of ``s`` (after :func:`with_station_bus`)."""
    return BusConfig(interface=s.bus_interface, channel=s.bus_channel, bitrate=s.bus_bitrate,
                     node_id=s.node_id)


def station_params(s: NodeSettings, bus: BusConfig) -> dict[str, Any]:
    """The node's station parameters as a ROS 2 params file document for the ``station``.

    :param s: the node's settings
    :param bus: the station's end of the bus
    """
    values: dict[str, Any] = {
        "joints": [j.name for j in s.joints], "storage_path": s.storage_path,
        "bus.interface": bus.interface, "bus.channel": str(bus.channel),
        "bus.bitrate": bus.bitrate, "bus.node_id": bus.node_id}
    for joint in s.joints:
        values.update({f"{joint.name}.{key}": value
                       for key, value in _joint_values(joint).items()})
    return {"/**": {"ros__parameters": values}}


def _joint_values(joint: JointSettings) -> dict[str, Any]:
    m = joint.motion
    values = {"slot": joint.slot, "family": joint.family, "code": joint.code,
              "cable_length": joint.cable_length, "para1": joint.para1,
              "steps_per_rev": joint.steps_per_rev, "revolutions": joint.revolutions,
              "measuring_step": joint.measuring_step, "direction": joint.direction,
              "motion.kind": m.kind, "motion.velocity": m.velocity,
              "motion.amplitude": m.amplitude, "motion.frequency": m.frequency,
              "motion.start": m.start}
    assert values.keys() == JOINT_DEFAULTS.keys()
    return values


def _die_with_parent() -> None:
    """preexec_fn of the child: SIGTERM when the forking thread (the node's main) ends."""
    _LIBC.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


#: seconds a stop waits for the ended child's last log lines
FORWARD_DRAIN_S = 2.0


class ChildStation:
    """The ``station`` program as a child process of the node, on the given bus.

    :param s: the node's settings (the station's joints, node id, storage, priority)
    :param bus: the bus the station opens
    """

    def __init__(self, s: NodeSettings, bus: BusConfig) -> None:
        self.settings = s
        self.bus = bus
        self.proc: subprocess.Popen[bytes] | None = None
        self._stderr: deque[str] = deque(maxlen=20)
        self._forwarder: threading.Thread | None = None
        self._stopping = False
        #: exit code once the child has ended, else None
        self.exit_code: int | None = None
        #: seconds from spawn to the station's boot-up message
        self.start_time = 0.0

    @property
    def pid(self) -> int | None:
        """Process id of the station (None before start)."""
        return self.proc.pid if self.proc is not None else None

    def start(self, timeout: float) -> None:
        """Spawn the station and wait for its boot-up.

        :param timeout: longest wait for the boot-up message (s)
        :raises BusError: the node's end of the bus cannot be opened
        :raises GatewayUnavailable: no boot-up within ``timeout``, with the station's last
            log line
        """
        cmd = [sys.executable, "-m", "ssi_bridge.sim.program", "--params-file", "-",
               "--parent-pid", str(os.getpid()),
               "--priority", str(self.settings.simulation_station_priority)]
        try:
            watch = open_bus(self.bus)  # listening before the station can send its boot-up
        except BusError as err:
            raise BusError(f"{err} (where loopback has no multicast, run the simulated station "
                           "in the node's process: simulation.transport:=virtual)") from err
        try:
            t0 = time.monotonic()
            # a process group of its own (a terminal's Ctrl-C reaches the node, which stops
            # it) but the node's session: Linux schedules a session as one group (autogroup),
            # so the station shares the node's CPU share as it does in-process; in a session
            # of its own it waited up to 200 ms for the CPU beside two CPU burners
            self.proc = subprocess.Popen(
                cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                preexec_fn=_die_with_parent, process_group=0, close_fds=True)
            assert self.proc.stdin is not None
            # libyaml's emitter where PyYAML has it: each per-joint key repeats the joint's
            # name, and the pure-Python emitter takes seconds for a long one
            self.proc.stdin.write(yaml.dump(station_params(self.settings, self.bus),
                                            Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper))
                                  .encode())
            self.proc.stdin.close()
            self._forwarder = threading.Thread(target=self._forward_log, name="station-log",
                                               daemon=True)
            self._forwarder.start()
            threading.Thread(target=self._reap, name="station-reaper", daemon=True).start()
            BootWatch(watch, self.bus.node_id).wait(timeout, self.problem)
            self.start_time = time.monotonic() - t0
        except GatewayUnavailable as err:
            self.stop()
            detail = f": {self._stderr[-1]}" if self._stderr else ""
            raise GatewayUnavailable(f"simulated station did not start ({err}){detail}") \
                from None
        finally:
            watch.shutdown()
        logger.info("simulated station up as process %d on %s:%s after %.2f s", self.proc.pid,
                    self.bus.interface, self.bus.channel, self.start_time)

    def _forward_log(self) -> None:
        """The child's log lines into the node's log (and the last ones for errors)."""
        assert self.proc is not None and self.proc.stderr is not None
        for raw in self.proc.stderr:
            line = raw.decode(errors="replace").rstrip()
            if not line:
                continue
            self._stderr.append(line)
            level = logging.INFO
            for name in ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"):
                if line.startswith(f"[{name}] "):
                    level, line = getattr(logging, name), line[len(name) + 3:]
                    break
            else:
                if line.startswith("Traceback") or "Error" in line:
                    level = logging.ERROR
            logger.log(level, "station: %s", line)

    def _reap(self) -> None:
        """Wait for the child's end (stdout closes with it) and keep its exit code."""
        assert self.proc is not None and self.proc.stdout is not None
        for _ in self.proc.stdout:
            pass
        self.exit_code = self.proc.wait()
        if not self._stopping:
            logger.error("%s", self.problem())

    def problem(self) -> str | None:
        """Why the station is not running (its process ended), or None while it runs."""
        if self.exit_code is None or self._stopping:
            return None
        last = f"; last output: {self._stderr[-1]}" if self._stderr else ""
        return f"simulated station process exited with code {self.exit_code}{last}"

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after 3 s; waits for the child and for its last log lines
        (e.g. "gateway node 1 stopped") to reach the node's log (idempotent)."""
        self._stopping = True
        proc = self.proc
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(3.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(2.0)
        if self._forwarder is not None and self._forwarder is not threading.current_thread():
            self._forwarder.join(FORWARD_DRAIN_S)  # stderr ends with the child


class InProcessStation:
    """The fallback: the same station in the node's process, reached over the bus only."""

    def __init__(self, s: NodeSettings, bus: BusConfig) -> None:
        self.bus = bus
        self.station = Station(StationSettings(joints=s.joints, bus=bus,
                                               storage_path=s.storage_path))
        # its receive thread answers the SYNCs: above the node's cycle threads, as the child
        # process would be (docs/node.md "Scheduling")
        self.station.gateway.rx_priority = s.simulation_station_priority
        self.pid: int | None = None
        self.start_time = 0.0

    def start(self, timeout: float) -> None:
        """Start the station and wait for its boot-up on the bus.

        :param timeout: longest wait for the boot-up (s)
        """
        watch = open_bus(self.bus)
        try:
            t0 = time.monotonic()
            self.station.start()
            BootWatch(watch, self.bus.node_id).wait(timeout)
            self.start_time = time.monotonic() - t0
        finally:
            watch.shutdown()

    def problem(self) -> str | None:
        """Never gone while the node runs."""
        return None

    def stop(self) -> None:
        """Stop the station (idempotent)."""
        self.station.stop()


class StationGroup:
    """The simulated stations of a bus with several XN-GW-CANOPEN gateways, one per node id.

    Each station is its own device as on a real bus: one child process per station on
    udp_multicast (a crash or stall of one does not take the others along), one in-process
    :class:`Station` per node id on virtual. The node reaches each over CAN only.
    """

    def __init__(self, stations: dict[int, ChildStation | InProcessStation]) -> None:
        self.stations = stations

    @property
    def pid(self) -> int | None:
        """Process id of the first station's child (None in-process)."""
        return next(iter(self.stations.values())).pid

    @property
    def pids(self) -> list[int]:
        """Process ids of every station child."""
        return [st.pid for st in self.stations.values() if st.pid is not None]

    def problem(self) -> str | None:
        """Why a station is not running (per node id), or None while all run."""
        found = [f"station {sid}: {p}" for sid, st in self.stations.items()
                 if (p := st.problem())]
        return "; ".join(found) or None

    def stop(self) -> None:
        """Stop every station (idempotent)."""
        for st in self.stations.values():
            st.stop()


def start_stations(s: NodeSettings) -> ChildStation | InProcessStation | StationGroup:
    """Start one simulated station per entry of ``stations`` (a group when there are several).

    A station gets only its own joints and its node id; a ``storage_path`` is suffixed with
    ``.node<id>`` so the stations keep their registers apart.

    :param s: the node's settings
    """
    ids = s.station_ids
    if len(ids) == 1:
        return start_station(s)
    started: dict[int, ChildStation | InProcessStation] = {}
    try:
        for sid in ids:
            joints = s.station_joints(sid)
            path = f"{s.storage_path}.node{sid}" if s.storage_path else ""
            started[sid] = start_station(dataclasses.replace(
                s, joints=joints, node_id=sid, stations=(sid,), storage_path=path))
    except BaseException:
        StationGroup(started).stop()
        raise
    return StationGroup(started)


def start_station(s: NodeSettings) -> ChildStation | InProcessStation:
    """Start the node's simulated station per ``simulation.transport`` and wait for it."""
    bus = station_bus(s)
    station: ChildStation | InProcessStation = (
        ChildStation(s, bus) if s.simulation_transport == "udp_multicast"
        else InProcessStation(s, bus))
    station.start(s.simulation_start_timeout)
    return station
