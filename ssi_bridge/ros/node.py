"""The ssi_bridge ROS 2 node: one SYNC cycle per period, published as joint_states and status.

Each cycle the node (the CANopen master) sends SYNC; the gateway latches every module's SSI
frame and answers with TPDOs; each joint's core (``core/joint.py``) turns its sample into
joint units and a velocity; the node publishes. ``header.stamp`` is the SYNC time, which is
the SSI latch time of the sample (the module latches on SYNC, well inside one bit time after
it; docs/node.md). Services call the ROS-free facade (``core/bridge.py``) from their own
thread, so the cycle never waits on them. Diagnostics, run-time parameters and the lifecycle
transitions are the parts in ``node_status.py``, ``node_params.py`` and ``lifecycle.py``: the
node is an rclpy ``LifecycleNode`` whose ``autostart`` parameter configures and activates it
at start-up (``ssi_bridge_node``) or leaves that to ``~/change_state``
(``ssi_bridge_managed_node``).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.lifecycle import LifecycleNode
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Status

from ssi_bridge.base.realtime import pin_process
from ssi_bridge.base.timebase import ModelClock, wire_now
from ssi_bridge.client.can_log_player import CanLogPlayer
from ssi_bridge.client.cycle_feed import feed_frames
from ssi_bridge.client.listener import ListenOnlyClient
from ssi_bridge.client.master import BridgeClient, CanMaster
from ssi_bridge.client.one_master import ensure_node_alone
from ssi_bridge.core.bridge import Bridge
from ssi_bridge.core.cycle import Cycle
from ssi_bridge.core.cycle_log import StationLog
from ssi_bridge.core.joint import Joint
from ssi_bridge.exceptions import RecordingError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.ros import logbridge
from ssi_bridge.ros.cycle import CycleThread, cycle_wire_time
from ssi_bridge.ros.cycle_publish import CyclePublisher
from ssi_bridge.ros.lifecycle import BridgeLifecycle
from ssi_bridge.ros.liveview import LiveView
from ssi_bridge.ros.messages import idle_read
from ssi_bridge.ros.node_params import RuntimeParameters
from ssi_bridge.ros.node_status import NodeDiagnostics
from ssi_bridge.ros.observe import SILENT_WARNING_S, ObservedCycleThread
from ssi_bridge.ros.params import NodeSettings, declare_parameters
from ssi_bridge.ros.qos_overrides import overridable_publisher as publisher
from ssi_bridge.ros.rclpy_compat import RCLError
from ssi_bridge.ros.recording import SessionRecorder
from ssi_bridge.ros.services import BridgeServices
from ssi_bridge.ros.span_probe import probe_from_env
from ssi_bridge.ros.stamps import Stamper

class SsiBridgeNode(BridgeLifecycle, NodeDiagnostics, RuntimeParameters, LifecycleNode):
    """Bridge of the XN-1SSI channels of XN-GW-CANOPEN stations to ROS 2 (a lifecycle node).

    ``autostart`` is the default of the ``autostart`` parameter: on, the constructor
    configures and activates the node and raises the reason if that fails (nothing left
    open); off, it returns unconfigured with nothing open.
    """

    def __init__(self, stop: Callable[[], None] | None = None, autostart: bool = True,
                 **kwargs: Any) -> None:
        super().__init__("ssi_bridge", **kwargs)
        #: ends the process's spin cleanly (main's stop request; without main: the context)
        self._request_stop = stop or self.context.try_shutdown
        logbridge.install(self.get_logger())
        autostart = self._declare_autostart(autostart)
        self.settings: NodeSettings = declare_parameters(self)
        if self.settings.replay_can_log:
            # the log is played onto a channel of this process only; the sniffer of a
            # re-recording and the diagnostics' hardware_id name that channel
            self.settings = dataclasses.replace(
                self.settings, bus_interface="virtual",
                bus_channel=f"ssi_bridge_replay_{os.getpid()}_{id(self):x}")
        #: the simulated station(s) the node owns while its bus side is open (simulation:
        #: true), else None; the supervisor's class (None on real hardware)
        self.station: Any = None
        self._simulation: Any = None
        if self.settings.simulation:
            # the node's one import of the simulator (docs/architecture.md): a node on
            # real hardware loads nothing of ssi_bridge.sim
            from ssi_bridge.sim.supervisor import Simulation

            # the node and its simulated station meet on this bus (sim/supervisor/station.py)
            self.settings = Simulation.bus_settings(self.settings,
                                                    self.get_fully_qualified_name())
            self._simulation = Simulation
        s = self.settings
        #: the simulated station's clock: wire time since the node started (fault durations)
        self.model_clock = ModelClock()
        self.stamper = Stamper(self.get_clock(), self.get_logger())
        #: the benchmark's span per cycle (ros/span_probe.py); None unless it asks
        self._span_probe = probe_from_env()
        self._mirror = threading.local()  # .active: a parameter set mirroring the module
        #: the joints' cores by name, in the configured order (filled by the bus side)
        self.joints: dict[str, Joint] = {}
        #: each station's frame log by node id (filled by the bus side): which SYNC a TPDO
        #: answers, and whether a sample is vouched for (core/cycle_log.py)
        self.frame_logs: dict[int, StationLog] = {}
        #: the cycle decisions (core/cycle.py): ros/ only turns its results into messages
        self.cycle_core = Cycle(self.joints, self.frame_logs)
        #: SYNC, the cycle's decisions and its messages (ros/cycle_publish.py)
        self.cycle_publisher = CyclePublisher(self)
        self.bridge = Bridge(self.joints, self.client_of, self.mirror_para1)
        self.bus_config = BusConfig(interface=s.bus_interface, channel=s.bus_channel,
                                    bitrate=s.bus_bitrate, node_id=s.node_id)
        self.cycle_wire_s = cycle_wire_time(s, self.get_logger().warning)
        self.cycle: CycleThread | ObservedCycleThread | None = None
        self._begin(autostart)  # lifecycle.py: configure and activate, or wait unconfigured

    @property
    def incomplete_cycles(self) -> int:
        """Cycles in which at least one joint was left out (no sample latched at its SYNC)."""
        return self.cycle_core.incomplete_cycles

    @property
    def latch_bound_s(self) -> float:
        """The longest a sample's frames may end after its SYNC to be published (s): the
        ``latch_bound`` parameter plus one cycle's worst-case wire time."""
        return self.settings.latch_bound + self.cycle_wire_s

    @property
    def clock_steps(self) -> int:
        """Header stamps moved forward because the clock stepped back (NTP step)."""
        return self.stamper.clock_steps

    def _open_bus_side(self, s: NodeSettings) -> None:
        """The joints' cores, the simulated station (if any), the master or listener.

        The simulated station is a device of its own (a child process, or in-process on the
        virtual bus as the fallback): the node starts it, waits for its boot-up, and from
        then on reaches it only over CAN, fault injection included (SDO 0x4000-0x4002).
        """
        self.joints.clear()
        for j in s.joints:
            core = Joint(j, velocity_window=s.velocity_window, stale_cycles=s.stale_cycles,
                         max_speed=float(self.get_parameter(f"{j.name}.max_speed").value))
            if core.layout_problem:
                self.get_logger().warning(f"{j.name}: no frame checks: {core.layout_problem}")
            self.joints[j.name] = core
        self.bridge.faults = None
        self.station = self._simulation(s) if self._simulation is not None else None
        ensure_node_alone(self.bus_config, s, getattr(self.station, "open_bus", None))
        if self.station is not None:
            self.station.start()
        self.player: CanLogPlayer | None = None
        self.client: BridgeClient | ListenOnlyClient
        #: one client per station (node id -> client), all on one master: one SYNC per cycle
        self.station_clients: dict[int, BridgeClient] = {}
        self.master: CanMaster | None = None
        if s.listen_only:
            self.client = ListenOnlyClient(self.bus_config, s.node_id,
                                           max(j.slot for j in s.joints))
            self.client.connect()
            if s.replay_can_log:
                self.player = CanLogPlayer(s.replay_can_log, s.bus_channel, rate=s.replay_rate)
        else:
            self._connect_stations(s)
        self._attach_frame_logs()
        if not s.listen_only:
            self.refresh_cams()
        self._cycle_times: deque[float] = deque()
        self._cycle_started = time.monotonic()
        self._last_levels: tuple = ()
        self._last_bus_counts: dict = {}

    def _attach_frame_logs(self) -> None:
        """A frame log per station, fed by its slot table (every SYNC and TPDO it sees)."""
        self.frame_logs.clear()
        by_client: dict[int, tuple[Any, list[Joint]]] = {}
        for joint in self.joints.values():
            client = self.client_of(joint.name)
            by_client.setdefault(id(client), (client, []))[1].append(joint)
        for client, joints in by_client.values():
            log = StationLog(self.latch_bound_s, slots=tuple(j.slot for j in joints))
            feed_frames(client, log)
            for joint in joints:
                self.frame_logs[joint.settings.station] = log

    def _connect_stations(self, s: NodeSettings) -> None:
        """The master, one client per station, and each joint's start-up configuration."""
        self.master = CanMaster(self.bus_config, priority=s.cycle_priority,
                                opener=self.station.open_bus if self.station else None)
        for sid in s.station_ids:  # a failure: configure closes what is open (lifecycle.py)
            slots = max(j.slot for j in s.station_joints(sid))
            self.station_clients[sid] = BridgeClient(self.master, sid, slots,
                                                     sdo_timeout=s.bus_sdo_timeout)
            # our own station booted just now: on a busy machine its first answer may be late
            self.station_clients[sid].connect(
                patience=s.simulation_start_timeout if self.station is not None else 0.0)
        self.client = self.station_clients[s.station_ids[0]]
        if self.station is not None:
            self.bridge.faults = self.station.fault_injector(
                self.station_clients, {n: j.config for n, j in self.joints.items()},
                self.sim_time)
        for joint in self.joints.values():
            change = self.bridge.configure(joint, idle_read)
            if change:
                self.get_logger().info(f"{logbridge.clip(joint.name, 80)}: {change}")

    def _create_ros_side(self, s: NodeSettings) -> None:
        """Publishers, the recorder, the cycle loop, diagnostics timer, services, parameters."""
        self.joint_pub = publisher(self, JointState, "joint_states")
        self.status_pub = publisher(self, Status, "~/status")
        self.diag_pub = publisher(self, DiagnosticArray, "/diagnostics")
        self.recorder = SessionRecorder(self, s)
        for pub in (self.joint_pub, self.status_pub, self.diag_pub):
            self.recorder.offer(pub.topic_name, pub.qos_profile)
        self._service_group = MutuallyExclusiveCallbackGroup()
        self._diag_group = MutuallyExclusiveCallbackGroup()
        self.cycle = self._new_cycle(s)
        self.diag_timer = self.create_timer(s.diagnostics_period, self._on_diag_timer,
                                            callback_group=self._diag_group)
        self.handlers = BridgeServices(self, self.bridge, self.recorder, self.publish_safe)
        self.handlers.register(self._service_group)
        self.liveview = LiveView(self, s, self.handlers)
        for pub in (self.joint_pub, self.status_pub, self.diag_pub, self.handlers.events):
            self.liveview.offer(pub)
        self.add_on_set_parameters_callback(self._on_set_parameters)

    def _new_cycle(self, s: NodeSettings) -> CycleThread | ObservedCycleThread:
        """The cycle loop (not started): SYNC master, or observer of another master's SYNC."""
        if isinstance(self.client, ListenOnlyClient):
            return ObservedCycleThread(
                self.client, 1.0 / s.publish_rate, self.cycle_publisher.on_observed,
                self._on_quiet,
                ended=self.player.finished if self.player is not None else None,
                on_end=self._on_replay_end,
                silent_warning=None if self.player is not None else SILENT_WARNING_S,
                priority=s.cycle_priority)
        return CycleThread(1.0 / s.publish_rate, self.cycle_publisher.on_cycle,
                           priority=s.cycle_priority, end=self.cycle_publisher.on_end)

    def _start(self, s: NodeSettings) -> None:
        """Start-up recording, CPU pinning, then the cycle (and a log replay) begins."""
        if s.record_enabled:
            try:
                self.recorder.start(s.record_path)
            except (RecordingError, OSError) as err:
                # the bridge still runs; the bus diagnostics show the error until fixed
                self.recorder.error = f"record.enabled: {err}"
                self.get_logger().error(self.recorder.error)
        if s.cpu_affinity:
            pin_process(s.cpu_affinity)
            self.get_logger().info(f"process pinned to CPU(s) {list(s.cpu_affinity)}")
        # Python hands the GIL to a waiting thread only every switch interval (5 ms by
        # default): a service burst's CPU-bound handlers would hold the cycle that long
        sys.setswitchinterval(min(sys.getswitchinterval(), 0.25 / s.publish_rate))
        self._cycle_started = time.monotonic()
        self.cycle.start()
        if self.player is not None:
            if s.replay_wait_for_subscribers > 0:
                self.player.start_when(lambda: self.joint_pub.get_subscription_count() > 0,
                                       s.replay_wait_for_subscribers, self.context.ok)
            else:
                self.player.start()
        mode = ("simulated station" if s.simulation else
                f"replay of {s.replay_can_log}" if s.replay_can_log else
                "listen-only" if s.listen_only else "real station")
        names = logbridge.clip(str(list(self.joints)), 200)  # echoed input: kept short
        self.get_logger().info(
            f"bridging {len(s.joints)} joint(s) {names} on "
            f"{s.bus_interface}:{s.bus_channel} node {s.node_id} "
            f"({mode}); publishing "
            f"{self.joint_pub.topic_name} at {s.publish_rate:g} Hz, {self.status_pub.topic_name}, "
            f"/diagnostics every {s.diagnostics_period:g} s; services under "
            f"{self.get_fully_qualified_name()}/")

    def client_of(self, joint: str) -> BridgeClient | ListenOnlyClient:
        """The client of the station holding ``joint``'s module (KeyError: unknown joint)."""
        return self.station_clients.get(self.joints[joint].settings.station, self.client)

    def refresh_cams(self) -> None:
        """Read the CAM objects of every joint (SDO: never in the cycle)."""
        for name, err in self.bridge.refresh_cams():
            self.get_logger().debug(f"{name}: CAM objects not read: {err}")

    def sim_time(self) -> float:
        """Seconds since the node started: the clock of the simulated station."""
        return self.model_clock()

    def _on_quiet(self) -> None:
        """Listen-only: a period without SYNC counts as a stale cycle for every joint."""
        now = wire_now()
        for joint in self.joints.values():
            joint.quiet(now)
        self._publish_on_change()

    def _on_replay_end(self) -> None:
        """The replayed log is over: say so; exit (0) if ``replay.exit_at_end``."""
        assert self.player is not None
        how = f"stopped: {self.player.error}" if self.player.error else "ended"
        self.get_logger().info(
            f"replay of {self.player.path} {how} after {self.player.frames} frames"
            + ("; exiting (replay.exit_at_end)" if self.settings.replay_exit_at_end else
               "; still running, diagnostics go STALE"))
        if self.settings.replay_exit_at_end:
            self._request_stop()

    def publish_safe(self, publisher: Any, msg: Any) -> bool:
        """Publish; False instead of an error when shutdown invalidated the context meanwhile."""
        try:
            publisher.publish(msg)
        except RCLError:
            if self.context.ok():
                raise
            return False
        self.liveview.publish(publisher, msg)
        return True


__all__ = ["SsiBridgeNode"]
