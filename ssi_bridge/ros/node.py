"""The ssi_bridge ROS 2 node: one SYNC cycle per period, published as joint_states and status.

Each cycle the node (the CANopen master) sends SYNC; the gateway latches every module's SSI
frame and answers with TPDOs; the node turns REG_SSI_POS into joint units, estimates velocity,
and publishes. ``header.stamp`` is the SYNC time, which is the SSI latch time of the sample
(the module latches on SYNC, well inside one bit time after it; docs/node.md). Services do the
register handshake over the bus in their own callback group, so the cycle never waits on them.
"""

from __future__ import annotations

import dataclasses
import math
import os
import threading
import time
from collections import deque
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, KeyValue
from rclpy._rclpy_pybind11 import RCLError
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rcl_interfaces.msg import SetParametersResult
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Status

from ssi_bridge.client.listener import ListenOnlyClient, ObservedCycle
from ssi_bridge.client.master import BridgeClient, CanMaster
from ssi_bridge.client.player import CanLogPlayer
from ssi_bridge.exceptions import ConfigError, RecordingError
from ssi_bridge.gateway.bus import BusConfig
from ssi_bridge.gateway.station import count_factor, joint_encoder
from ssi_bridge.module.images import ModuleStatus, ProcessInput
from ssi_bridge.module.registers import validate_para1
from ssi_bridge.ros import logbridge
from ssi_bridge.ros.cycle import CycleThread
from ssi_bridge.ros.diagnostics import (
    ChannelCounters, bus_status, channel_level, channel_status, station_status,
)
from ssi_bridge.ros.faults import FaultInjector, StationFaults
from ssi_bridge.ros.messages import channel_msg, idle_read, time_msg
from ssi_bridge.ros.observe import ObservedCycleThread
from ssi_bridge.ros.params import JointSettings, NodeSettings, declare_parameters
from ssi_bridge.ros.recording import SessionRecorder
from ssi_bridge.ros.services import BridgeServices
from ssi_bridge.ros.station import (
    ChildStation, InProcessStation, StationGroup, start_stations, with_station_bus,
)
from ssi_bridge.ros.units import JointScale, VelocityEstimator

#: status bits under which the module does not acquire (000 "Error detection / messages")
NOT_MEASURING = int(ModuleStatus.ERR_SSI | ModuleStatus.ERR_PARA | ModuleStatus.STS_STOP)
#: status bits counted as error cycles
ERRORS = int(ModuleStatus.ERR_SSI | ModuleStatus.ERR_PARA)
#: object 0x5801 Encoder Config = REG_PARA1 of each slot (000 Table 16/17)
ENCODER_CONFIG = 0x5801


def pin_process(cpus: tuple[int, ...]) -> None:
    """Pin every thread of this process (DDS, bus notifiers, cycle) to ``cpus``.

    ``sched_setaffinity(0)`` moves only the calling thread on Linux; threads started later
    inherit from their creator, so the existing ones are moved one by one.
    """
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setaffinity(int(tid), cpus)
        except (ProcessLookupError, PermissionError):
            pass  # a thread that just ended


class SsiBridgeNode(Node):
    """Bridge of one XN-GW-CANOPEN station's XN-1SSI channels to ROS 2."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("ssi_bridge", **kwargs)
        logbridge.install(self.get_logger())
        self.settings: NodeSettings = declare_parameters(self)
        if self.settings.replay_can_log:
            # the log is played onto a channel of this process only; the sniffer of a
            # re-recording and the diagnostics' hardware_id name that channel
            self.settings = dataclasses.replace(
                self.settings, bus_interface="virtual",
                bus_channel=f"ssi_bridge_replay_{os.getpid()}_{id(self):x}")
        if self.settings.simulation:
            # the node and its simulated station meet on this bus (ros/station.py)
            self.settings = with_station_bus(self.settings)
        s = self.settings
        self._t0 = time.monotonic()
        self.joints: dict[str, JointSettings] = {j.name: j for j in s.joints}
        self.bus_config = BusConfig(interface=s.bus_interface, channel=s.bus_channel,
                                    bitrate=s.bus_bitrate, node_id=s.node_id)
        self._open_bus_side(s)
        self._create_ros_side(s)
        self._start(s)

    def _open_bus_side(self, s: NodeSettings) -> None:
        """The simulated station (if any), the master or listener, and per-joint state.

        The simulated station is a device of its own (a child process, or in-process on the
        virtual bus as the fallback): the node starts it, waits for its boot-up, and from
        then on reaches it only over CAN, fault injection included (SDO 0x4000-0x4002).
        """
        self.station: ChildStation | InProcessStation | StationGroup | None = None
        self.faults: FaultInjector | StationFaults | None = None
        #: the simulated encoders' models (frame layout and resolution), built from the params
        self.encoders = {j.name: joint_encoder(j) for j in s.joints} if s.simulation else {}
        if s.simulation:
            self.station = start_stations(s)
        n_slots = max(j.slot for j in s.joints)
        self.player: CanLogPlayer | None = None
        self.client: BridgeClient | ListenOnlyClient
        #: one client per station (node id -> client), all on one master: one SYNC per cycle
        self.station_clients: dict[int, BridgeClient] = {}
        self.master: CanMaster | None = None
        if s.listen_only:
            self.client = ListenOnlyClient(self.bus_config, s.node_id, n_slots)
            self.client.connect()
            if s.replay_can_log:
                self.player = CanLogPlayer(s.replay_can_log, s.bus_channel, rate=s.replay_rate)
        else:
            self.master = CanMaster(self.bus_config)
            try:
                for sid in s.station_ids:
                    slots = max(j.slot for j in s.station_joints(sid))
                    self.station_clients[sid] = BridgeClient(self.master, sid, slots)
                    self.station_clients[sid].connect()
            except Exception:
                for client in self.station_clients.values():
                    client.close()
                self.master.close()
                if self.station is not None:
                    self.station.stop()
                raise
            self.client = self.station_clients[s.station_ids[0]]
            if self.station is not None:
                injectors = {sid: FaultInjector(
                    client, {j.name: j for j in s.station_joints(sid)}, self.encoders,
                    self.sim_time) for sid, client in self.station_clients.items()}
                self.faults = (injectors[s.node_id] if len(injectors) == 1
                               else StationFaults(injectors, self.joints))
            for joint in s.joints:
                self._configure_para1(joint)
                self.client_of(joint.name).edit_output(joint.slot, idle_read)
        self.scales = {j.name: self._scale(j) for j in s.joints}
        self.velocity = {j.name: VelocityEstimator(self.scales[j.name], s.velocity_window)
                         for j in s.joints}
        self.counters = {j.name: ChannelCounters() for j in s.joints}
        self.positions = {j.name: 0.0 for j in s.joints}
        self._cycle_times: deque[float] = deque()
        self._cycle_started = time.monotonic()
        self._last_levels: tuple[int, ...] = ()

    def _create_ros_side(self, s: NodeSettings) -> None:
        """Publishers, the recorder, the cycle loop, diagnostics timer, services, parameters."""
        self.joint_pub = self.create_publisher(JointState, "joint_states", 10)
        self.status_pub = self.create_publisher(Status, "~/status", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.recorder = SessionRecorder(self, s)
        for pub in (self.joint_pub, self.status_pub, self.diag_pub):
            self.recorder.offer(pub.topic_name, pub.qos_profile)

        self._service_group = MutuallyExclusiveCallbackGroup()
        self._diag_group = MutuallyExclusiveCallbackGroup()
        self.cycle: CycleThread | ObservedCycleThread
        if isinstance(self.client, ListenOnlyClient):
            self.cycle = ObservedCycleThread(
                self.client, 1.0 / s.publish_rate, self._on_observed, self._on_quiet,
                ended=self.player.finished if self.player is not None else None,
                on_end=self._on_replay_end)
        else:
            self.cycle = CycleThread(1.0 / s.publish_rate, self._on_cycle)
        self.diag_timer = self.create_timer(s.diagnostics_period, self.publish_diagnostics,
                                            callback_group=self._diag_group)
        self.handlers = BridgeServices(self)
        self.handlers.register(self._service_group)
        self.add_on_set_parameters_callback(self._on_set_parameters)

    def _start_player_when_heard(self, timeout: float) -> None:
        """Start the log replay once joint_states has a subscriber (or ``timeout`` passed)."""
        deadline = time.monotonic() + timeout
        while (self.joint_pub.get_subscription_count() == 0 and time.monotonic() < deadline
               and self.context.ok()):
            time.sleep(0.02)
        if self.context.ok() and self.player is not None:
            self.player.start()

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
        self._cycle_started = time.monotonic()
        self.cycle.start()
        if self.player is not None:
            if s.replay_wait_for_subscribers > 0:
                threading.Thread(target=self._start_player_when_heard,
                                 args=(s.replay_wait_for_subscribers,), daemon=True).start()
            else:
                self.player.start()
        mode = ("simulated station" if s.simulation else
                f"replay of {s.replay_can_log}" if s.replay_can_log else
                "listen-only" if s.listen_only else "real station")
        self.get_logger().info(
            f"bridging {len(s.joints)} joint(s) {list(self.joints)} on "
            f"{s.bus_interface}:{s.bus_channel} node {s.node_id} "
            f"({mode}); publishing "
            f"{self.joint_pub.topic_name} at {s.publish_rate:g} Hz, {self.status_pub.topic_name}, "
            f"/diagnostics every {s.diagnostics_period:g} s; services under "
            f"{self.get_fully_qualified_name()}/")

    def client_of(self, joint: str) -> BridgeClient | ListenOnlyClient:
        """The client of the station holding ``joint``'s module (KeyError: unknown joint)."""
        station = self.joints[joint].station
        return self.station_clients.get(station, self.client)

    def _configure_para1(self, joint: JointSettings) -> None:
        """Write the joint's REG_PARA1 through object 0x5801 (000 Table 17) if it differs.

        This is what a CANopen master does at start-up; an invalid set is refused by the
        gateway with an SDO abort, which stops the node with the module's reason.
        """
        client = self.client_of(joint.name)
        current = int(client.read_object(ENCODER_CONFIG, joint.slot))
        if current == joint.para1:
            return
        reason = validate_para1(joint.para1)
        if reason:
            raise ConfigError(f"{joint.name}.para1 0x{joint.para1:08X} is invalid: {reason}")
        client.write_object(ENCODER_CONFIG, joint.slot, joint.para1)
        self.get_logger().info(f"{joint.name}: REG_PARA1 0x{current:08X} -> 0x{joint.para1:08X} "
                               f"(object 0x{ENCODER_CONFIG:04X}:{joint.slot})")

    # -- time ------------------------------------------------------------------------------
    def sim_time(self) -> float:
        """Seconds since the node started: the clock of the simulated station."""
        return time.monotonic() - self._t0

    def _stamp_ns(self, monotonic_t: float) -> int:
        """ROS time (ns) of a past ``time.monotonic()`` instant."""
        now_ns = self.get_clock().now().nanoseconds
        return now_ns - int((time.monotonic() - monotonic_t) * 1e9)

    def _scale(self, joint: JointSettings, para1: int | None = None) -> JointScale:
        """Counts -> units for the joint's current REG_PARA1.

        Simulated: from the encoder's resolution and frame layout (:func:`count_factor`).
        Real hardware: ``steps_per_rev``/``revolutions`` or ``measuring_step`` are the
        resolution of REG_SSI_POS itself, as the user configured the module.
        """
        para1 = joint.para1 if para1 is None else para1
        if joint.name in self.encoders:
            enc = self.encoders[joint.name]
            factor = count_factor(enc, para1)
            if enc.linear:
                return JointScale(linear=True, measuring_step_m=enc.measuring_step_m / factor,
                                  direction=joint.direction)
            return JointScale(counts_per_rev=enc.steps_per_rev * factor,
                              revolutions=enc.revolutions, direction=joint.direction)
        if joint.measuring_step > 0:
            return JointScale(linear=True, measuring_step_m=joint.measuring_step,
                              direction=joint.direction)
        return JointScale(counts_per_rev=joint.steps_per_rev or 8192,
                          revolutions=joint.revolutions or 4096, direction=joint.direction)

    # -- the cycle -------------------------------------------------------------------------
    def _on_cycle(self) -> None:
        """One cycle; a shutdown racing it (the context goes first) ends it quietly."""
        if not self.context.ok():
            return
        try:
            self._cycle()
        except RCLError:
            if self.context.ok():
                raise

    def _cycle(self) -> None:
        """SYNC, collect the TPDOs of this cycle, publish joint_states and ~/status."""
        if self.faults is not None and self.faults.active:
            for done in self.faults.expire():
                self.handlers.log_event("inject_fault", done.joint, f"expired {done.kind.name}",
                                        True, "fault duration over, cleared")
        t_sync = self.client.sync()  # the master's one SYNC: every station's cycle
        assert self.master is not None
        self.master.wait_cycle(min(0.5 / self.settings.publish_rate, 0.05))
        self._cycle_times.append(t_sync)
        self._publish_cycle(t_sync)

    def _on_observed(self, cycle: ObservedCycle) -> None:
        """Listen-only: publish the cycle of a SYNC another master (or the log) sent."""
        if not self.context.ok():
            return
        self._cycle_times.append(time.monotonic())  # the achieved rate is the observed one
        try:
            self._publish_cycle(cycle.sync_time)
        except RCLError:
            if self.context.ok():
                raise

    def _on_quiet(self) -> None:
        """Listen-only: a period without SYNC counts as a stale cycle for every joint."""
        for counters in self.counters.values():
            counters.stale_cycles += 1
            counters.consecutive_stale += 1
        levels = self._levels()
        if self._last_levels and levels != self._last_levels:
            self.publish_diagnostics()
        self._last_levels = levels

    def _on_replay_end(self) -> None:
        """The replayed log is over: say so; exit (0) if ``replay.exit_at_end``."""
        assert self.player is not None
        how = f"stopped: {self.player.error}" if self.player.error else "ended"
        self.get_logger().info(
            f"replay of {self.player.path} {how} after {self.player.frames} frames"
            + ("; exiting (replay.exit_at_end)" if self.settings.replay_exit_at_end else
               "; still running, diagnostics go STALE"))
        if self.settings.replay_exit_at_end:
            self.context.try_shutdown()

    def _publish_cycle(self, t_sync: float) -> None:
        """Publish joint_states and ~/status of the cycle latched at ``t_sync`` (monotonic)."""
        stamp_ns = self._stamp_ns(t_sync)
        stamp = time_msg(stamp_ns)
        js = JointState()
        js.header.stamp = stamp
        js.header.frame_id = self.settings.frame_id
        # ~/status costs as much as the rest of the cycle: build it only for a listener
        want_status = self.recorder.active or self.status_pub.get_subscription_count() > 0
        status = Status(header=js.header) if want_status else None
        for joint in self.settings.joints:
            self._update_joint(joint, t_sync, js, status)
        if not js.name:
            return
        if not self.publish_safe(self.joint_pub, js):
            return
        self.recorder.record(self.joint_pub.topic_name, js, stamp_ns)
        if status is not None and self.publish_safe(self.status_pub, status):
            self.recorder.record(self.status_pub.topic_name, status, stamp_ns)
        levels = self._levels()
        if self._last_levels and levels != self._last_levels:
            self.publish_diagnostics()
        self._last_levels = levels

    def _update_joint(self, joint: JointSettings, t_sync: float, js: JointState,
                      status: Status | None) -> None:
        name = joint.name
        counters = self.counters[name]
        sample = self.client_of(name).latest(joint.slot)
        if sample is None:
            counters.stale_cycles += 1
            counters.consecutive_stale += 1
            return
        fresh = sample.sync_time >= t_sync
        if fresh:
            counters.samples += 1
            counters.consecutive_stale = 0
        else:
            counters.stale_cycles += 1
            counters.consecutive_stale += 1
        image = sample.process_input
        counters.last_image = image
        counters.last_position = sample.position
        sts = image[7]
        if sts & ERRORS:
            counters.error_cycles += 1
        scale = self.scales[name]
        position = scale.position(sample.position)
        estimator = self.velocity[name]
        if sts & NOT_MEASURING:
            # REG_SSI_POS is frozen (wire break, bad REG_PARA1, STOP): the position is the
            # last good one and the speed is unknown; the estimate restarts on recovery
            estimator.reset()
            velocity = math.nan
        elif fresh:
            velocity = estimator.update(sample.sync_time, sample.position)
        else:
            velocity = estimator.velocity
        self.positions[name] = position
        js.name.append(name)
        js.position.append(position)
        js.velocity.append(velocity)
        if status is not None:
            inp = ProcessInput.decode(image)
            status.channels.append(channel_msg(name, joint.slot, sample, inp, counters))

    def publish_safe(self, publisher: Any, msg: Any) -> bool:
        """Publish; False instead of an error when shutdown invalidated the context meanwhile."""
        try:
            publisher.publish(msg)
        except RCLError:
            if self.context.ok():
                raise
            return False
        return True

    # -- diagnostics -----------------------------------------------------------------------
    def achieved_rate(self) -> float:
        """Cycles per second over the last diagnostics period (at least 1 s, at most uptime)."""
        now = time.monotonic()
        window = min(max(self.settings.diagnostics_period, 1.0), now - self._cycle_started)
        if window <= 0:
            return 0.0
        times = self._cycle_times
        while times and now - times[0] > window:
            times.popleft()
        return len(times) / window

    def _levels(self) -> tuple[int, ...]:
        """The diagnostic levels without building the statuses (checked every cycle)."""
        limit = self.settings.stale_cycles
        levels = [channel_level(c.last_sts, c.consecutive_stale, limit)[0]
                  for c in self.counters.values()]
        levels.extend(int(c.gateway_alive) for c in self.station_clients.values())
        levels.append(int(self.client.gateway_alive) * 2 + int(bool(self._bus_problem())))
        return tuple(levels)

    def _statuses(self) -> list:
        s = self.settings
        out = []
        for joint in s.joints:
            hw = (f"{s.bus_interface}:{s.bus_channel} node {joint.station or s.node_id} "
                  f"slot {joint.slot} XN-1SSI")
            out.append(channel_status(joint.name, hw, self.counters[joint.name],
                                      s.stale_cycles, self.positions[joint.name]))
        if len(self.station_clients) > 1:
            return out + self._station_statuses()
        counters = dataclasses.asdict(self.client.counters)
        counters.update(self.recorder.counters())
        out.append(bus_status(
            "ssi_bridge: bus", f"{s.bus_interface}:{s.bus_channel} node {s.node_id} XN-GW-CANOPEN",
            alive=self.client.gateway_alive, connected=self.client.network is not None,
            achieved_rate=self.achieved_rate(), publish_rate=s.publish_rate, counters=counters,
            extra_error=self._bus_problem()))
        return out

    def _station_statuses(self) -> list:
        """Several stations: one bus status (master, SYNC, rate) and one per station."""
        s = self.settings
        assert self.master is not None
        counters = dataclasses.asdict(self.master.counters)
        counters.update(self.recorder.counters())
        silent = [sid for sid, c in self.station_clients.items() if not c.gateway_alive]
        out = [bus_status(
            "ssi_bridge: bus", f"{s.bus_interface}:{s.bus_channel} master of stations "
            f"{list(self.station_clients)}", alive=True, connected=self.master.network is not None,
            achieved_rate=self.achieved_rate(), publish_rate=s.publish_rate, counters=counters,
            extra_error=self._bus_problem())]
        if silent:
            out[0].values.append(KeyValue(key="silent_stations", value=str(silent)))
        for sid, client in self.station_clients.items():
            node = client.node
            nmt = node.nmt.state if node is not None else "UNKNOWN"
            emcy = ([f"0x{e.code:04X} reg 0x{e.register:02X} {e.get_desc()}".strip()
                     for e in node.emcy.log] if node is not None else [])
            station_counters = {k: v for k, v in dataclasses.asdict(client.counters).items()
                                if k not in ("frames", "syncs")}
            out.append(station_status(
                f"ssi_bridge: station {sid}",
                f"{s.bus_interface}:{s.bus_channel} node {sid} XN-GW-CANOPEN",
                alive=client.gateway_alive, nmt_state=str(nmt), emcy=emcy,
                counters=station_counters))
        return out

    def _bus_problem(self) -> str:
        """An error beside the bus state: the recorder's, a simulated station that ended."""
        station = self.station.problem() if self.station is not None else None
        return "; ".join(p for p in (self.recorder.error, station) if p)

    def publish_diagnostics(self) -> None:
        """Publish one DiagnosticArray with a status per joint and one for the bus."""
        if not self.context.ok():
            return
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = self._statuses()
        if not self.publish_safe(self.diag_pub, msg):
            return
        self.recorder.record("/diagnostics", msg, self.get_clock().now().nanoseconds)

    # -- parameters ------------------------------------------------------------------------
    def _on_set_parameters(self, params: list) -> SetParametersResult:
        """Runtime changes: REG_PARA1 via the module (refused with its reason), rates."""
        for p in params:
            if p.name.endswith(".para1"):
                joint = p.name[: -len(".para1")]
                if joint in self.joints:
                    reason = self.handlers.apply_para1(joint, int(p.value))
                    if reason:
                        return SetParametersResult(successful=False, reason=reason)
                    self.scales[joint] = self._scale(self.joints[joint], int(p.value))
                    self.velocity[joint] = VelocityEstimator(self.scales[joint],
                                                             self.settings.velocity_window)
            elif p.name == "publish_rate":
                self.cycle.period = 1.0 / float(p.value)
            elif p.name == "diagnostics_period":
                self.diag_timer.timer_period_ns = int(1e9 * float(p.value))
        return SetParametersResult(successful=True)

    def shutdown(self) -> None:
        """Stop recording, stop the bus side; safe to call twice."""
        logbridge.uninstall()
        self.cycle.stop()
        if self.player is not None:
            self.player.stop()
        self.recorder.stop()
        for client in self.station_clients.values():
            client.close()
        self.client.close()
        if self.master is not None:
            self.master.close()
        if self.station is not None:
            self.station.stop()


__all__ = ["SsiBridgeNode"]
