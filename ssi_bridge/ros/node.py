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
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, KeyValue
from rclpy._rclpy_pybind11 import RCLError
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rcl_interfaces.msg import SetParametersResult
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Status

from ssi_bridge.client.listener import ListenOnlyClient, ObservedCycle
from ssi_bridge.client.master import BridgeClient, CanMaster
from ssi_bridge.client.samples import ChannelSample
from ssi_bridge.client.can_log_player import CanLogPlayer
from ssi_bridge.protocol.encoder_config import EncoderConfig
from ssi_bridge.exceptions import ConfigError, RecordingError, SsiBridgeError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.protocol.families import family_config
from ssi_bridge.protocol.joint_encoder import count_factor, joint_config, para1_mismatch
from ssi_bridge.base.timebase import ModelClock, to_ros_ns, wire_now
from ssi_bridge.protocol import wire
from ssi_bridge.protocol.images import ModuleStatus, ProcessInput
from ssi_bridge.protocol.registers import Reg, validate_para1
from ssi_bridge.ros import logbridge
from ssi_bridge.ros.cycle import CycleThread, cycle_waits
from ssi_bridge.ros.diagnostics import (
    OK, WARN, ChannelCounters, ChannelHealth, bus_status, channel_status, station_status,
    status_name,
)
from ssi_bridge.ros.liveview import LiveView
from ssi_bridge.ros.joint_scale import JointScale
from ssi_bridge.ros.messages import channel_msg, idle_read, time_msg
from ssi_bridge.ros.observe import SILENT_WARNING_S, ObservedCycleThread
from ssi_bridge.ros.params import JointSettings, NodeSettings, declare_parameters
from ssi_bridge.ros.recording import SessionRecorder
from ssi_bridge.ros.services import BridgeServices
from ssi_bridge.ros.frame_watch import FrameWatch, edges, read_cam
from ssi_bridge.ros.velocity import VelocityEstimator

#: status bits under which the module does not acquire (000 "Error detection / messages")
NOT_MEASURING = int(ModuleStatus.ERR_SSI | ModuleStatus.ERR_PARA | ModuleStatus.STS_STOP)
#: status bits counted as error cycles
ERRORS = int(ModuleStatus.ERR_SSI | ModuleStatus.ERR_PARA)
#: object 0x5801 Encoder Config = REG_PARA1 of each slot (000 Table 16/17)
ENCODER_CONFIG = 0x5801
#: REG_SSI_MASK object (000 Table 35)
SSI_DIAG_MAPPING = 0x5840

#: parameters that change at run time (every other one is read-only in its descriptor)
LIVE_NODE_PARAMETERS = ("publish_rate", "diagnostics_period", "frame_id", "velocity_window",
                        "stale_cycles")
LIVE_JOINT_PARAMETERS = ("para1", "max_speed")


def spec_max_speed(family: str) -> float:
    """The highest speed (rad/s) a family's manual specifies, 0 where it states none.

    Only the TR encoders give one in these manuals: the overspeed limit, at most 6000 1/min
    (001 §5.4.2); SICK's 004 states no speeds for its families.
    """
    if not family.upper().startswith("TR"):
        return 0.0
    cfg = family_config(family)
    return 0.0 if cfg.linear else cfg.overspeed_rpm / 60.0 * 2.0 * math.pi


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

    def __init__(self, stop: Callable[[], None] | None = None, **kwargs: Any) -> None:
        super().__init__("ssi_bridge", **kwargs)
        #: ends the process's spin cleanly (main's stop request; without main: the context)
        self._request_stop = stop or self.context.try_shutdown
        logbridge.install(self.get_logger())
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
            self.settings = Simulation.bus_settings(self.settings)
            self._simulation = Simulation
        s = self.settings
        #: the simulated station's clock: wire time since the node started (gateway/timebase)
        self.model_clock = ModelClock()
        self._last_stamp_ns = 0
        #: header stamps moved forward because the clock stepped back (NTP step)
        self.clock_steps = 0
        #: cycles not published because a joint's TPDOs of that SYNC were missing
        self.incomplete_cycles = 0
        self._waiting_for_clock = False
        self.joints: dict[str, JointSettings] = {j.name: j for j in s.joints}
        self.bus_config = BusConfig(interface=s.bus_interface, channel=s.bus_channel,
                                    bitrate=s.bus_bitrate, node_id=s.node_id)
        self._check_wire(s)
        self._open_bus_side(s)
        self._create_ros_side(s)
        self._start(s)

    def _check_wire(self, s: NodeSettings) -> None:
        """Warn when publish_rate's SYNC cycles do not fit the wire at bus.bitrate (wire.py).

        With several stations the budget is the bus's: one SYNC, every station's TPDOs.
        """
        counts = [max(j.slot for j in s.station_joints(sid)) for sid in s.station_ids]
        self.cycle_wire_s = wire.frame_seconds(wire.stations_cycle_bits(counts), s.bus_bitrate)
        if s.listen_only or wire.stations_fits(counts, s.bus_bitrate, s.publish_rate):
            return
        what = (f"{counts[0]} slot(s)" if len(counts) == 1 else
                f"{len(counts)} stations with {'+'.join(map(str, counts))} slots")
        self.get_logger().warning(
            f"publish_rate {s.publish_rate:g} Hz does not fit the CAN wire: one cycle of "
            f"{what} (SYNC + TPDOs) takes up to {self.cycle_wire_s * 1e3:.3f} ms at "
            f"{s.bus_bitrate} bit/s, plus {wire.SDO_RESERVE_FRAMES} frames reserved for register "
            f"traffic; the highest rate that fits is "
            f"{wire.stations_max_cycle_rate(counts, s.bus_bitrate):g} Hz (docs/canopen.md)")

    def _open_bus_side(self, s: NodeSettings) -> None:
        """The simulated station (if any), the master or listener, and per-joint state.

        The simulated station is a device of its own (a child process, or in-process on the
        virtual bus as the fallback): the node starts it, waits for its boot-up, and from
        then on reaches it only over CAN, fault injection included (SDO 0x4000-0x4002).
        """
        #: fault injection into the simulated station (None on real hardware)
        self.faults: Any = None
        #: each joint's encoder layout from its parameters (family preset + overrides): the
        #: frame checks and the counts -> units scale, simulated station or real
        self.configs = {j.name: self._encoder_config(j) for j in s.joints}
        if self._simulation is not None:
            self.station = self._simulation(s)
            self.station.start()
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
            self.master = CanMaster(self.bus_config, priority=s.cycle_priority,
                                    opener=self.station.open_bus if self.station else None)
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
                self.faults = self.station.fault_injector(self.station_clients, self.configs,
                                                          self.sim_time)
            for joint in s.joints:
                self._configure_para1(joint)
                if joint.ssi_mask >= 0:  # 000 Table 3 via object 0x5840 (Table 35)
                    self.client_of(joint.name).write_object(SSI_DIAG_MAPPING, joint.slot,
                                                            joint.ssi_mask)
                self.client_of(joint.name).edit_output(joint.slot, idle_read)
        #: REG_PARA1 each module holds, as this node last wrote or read it back (one truth
        #: for the parameter, the scale and the velocity estimate: :meth:`change_para1`)
        self.para1 = {j.name: j.para1 for j in s.joints}
        self._para1_lock = threading.RLock()
        #: samples latched at or before this time may carry another REG_PARA1 (inf: a change
        #: is in flight): their position and velocity are published as NaN (unknown)
        self._para1_since = {j.name: -math.inf for j in s.joints}
        #: why the REG_PARA1 in force does not fit the simulated encoder (a WARN), or ""
        self.para1_note = {j.name: self._para1_note(j.name, j.para1) for j in s.joints}
        self._tls = threading.local()  # .mirror: a parameter set that only mirrors the module
        self.scales = {j.name: self._scale(j) for j in s.joints}
        self.max_speed = {j.name: self._max_speed(
            j, float(self.get_parameter(f"{j.name}.max_speed").value)) for j in s.joints}
        self.velocity = {j.name: VelocityEstimator(self.scales[j.name], s.velocity_window,
                                                   self.max_speed[j.name])
                         for j in s.joints}
        self.counters = {j.name: ChannelCounters() for j in s.joints}
        self.health = {j.name: ChannelHealth() for j in s.joints}
        self.frames = {j.name: FrameWatch(self.configs[j.name], j.para1) for j in s.joints}
        if not s.listen_only:
            self.refresh_cams()
        self.positions = {j.name: 0.0 for j in s.joints}
        self._cycle_times: deque[float] = deque()
        self._cycle_started = wire_now()
        self._last_levels: tuple = ()

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
        self.cycle = self._new_cycle(s)
        self.diag_timer = self.create_timer(s.diagnostics_period, self._on_diag_timer,
                                            callback_group=self._diag_group)
        self.handlers = BridgeServices(self)
        self.handlers.register(self._service_group)
        self.liveview = LiveView(self, s)
        for pub in (self.joint_pub, self.status_pub, self.diag_pub, self.handlers.events):
            self.liveview.offer(pub)
        self.add_on_set_parameters_callback(self._on_set_parameters)

    def _new_cycle(self, s: NodeSettings) -> CycleThread | ObservedCycleThread:
        """The cycle loop (not started): SYNC master, or observer of another master's SYNC."""
        if isinstance(self.client, ListenOnlyClient):
            return ObservedCycleThread(
                self.client, 1.0 / s.publish_rate, self._on_observed, self._on_quiet,
                ended=self.player.finished if self.player is not None else None,
                on_end=self._on_replay_end,
                silent_warning=None if self.player is not None else SILENT_WARNING_S,
                priority=s.cycle_priority)
        return CycleThread(1.0 / s.publish_rate, self._on_cycle, priority=s.cycle_priority)

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
        # Python hands the GIL to a waiting thread only every switch interval (5 ms by
        # default): a service burst's CPU-bound handlers would hold the cycle that long
        sys.setswitchinterval(min(sys.getswitchinterval(), 0.25 / s.publish_rate))
        self._cycle_started = wire_now()
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
        station = self.joints[joint].station
        return self.station_clients.get(station, self.client)

    def _encoder_config(self, joint: JointSettings) -> EncoderConfig | None:
        """The joint's encoder layout (family + overrides) from its parameters, if known."""
        try:
            return joint_config(joint)
        except ConfigError as err:
            self.get_logger().warning(f"{joint.name}: no frame checks: {err}")
            return None

    def refresh_cams(self) -> None:
        """Read the CAM objects 0x6B10/0x6B20/0x6B01/0x6B02 of every joint (000 Tables 43-48)."""
        for joint in self.settings.joints:
            try:
                self.frames[joint.name].set_cam(read_cam(
                    lambda index: int(self.client_of(joint.name).read_object(index, joint.slot))))
            except SsiBridgeError as err:
                self.get_logger().debug(f"{joint.name}: CAM objects not read: {err}")

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
        self.get_logger().info(f"{logbridge.clip(joint.name, 80)}: REG_PARA1 0x{current:08X} -> "
                               f"0x{joint.para1:08X} "
                               f"(object 0x{ENCODER_CONFIG:04X}:{joint.slot})")

    # -- time ------------------------------------------------------------------------------
    def sim_time(self) -> float:
        """Seconds since the node started: the clock of the simulated station."""
        return self.model_clock()

    def _stamp_ns(self, wire_t: float) -> int | None:
        """ROS time (ns) of wire time ``wire_t``: strictly after the last stamp; None = wait.

        ROS system time is wire time (``gateway/timebase.to_ros_ns``, no clock is read).
        With ``use_sim_time`` the offset sim - wire is taken from one bracketed pair of
        reads (a pair a thread switch split is read again); before the first ``/clock``
        there is no time to stamp with: nothing is published and the node says so once.
        A stamp at or before the last one (the clock stepped back) becomes last + 1 ns and
        is counted (bus diagnostics ``clock_steps``).
        """
        stamp = to_ros_ns(wire_t)
        clock = self.get_clock()
        if clock.ros_time_is_active:
            for _ in range(5):
                before = wire_now()
                sim_ns = clock.now().nanoseconds
                after = wire_now()
                if after - before < 1e-4:
                    break
            if sim_ns <= 0:
                if not self._waiting_for_clock:
                    self._waiting_for_clock = True
                    self.get_logger().warning(
                        "use_sim_time is true and no /clock has arrived: waiting for /clock, "
                        "nothing is published until it does")
                return None
            if self._waiting_for_clock:
                self._waiting_for_clock = False
                self.get_logger().info("/clock arrived: publishing")
            stamp += sim_ns - to_ros_ns(0.5 * (before + after))
            if stamp <= 0:
                return None
        if stamp <= self._last_stamp_ns:
            self.clock_steps += 1
            stamp = self._last_stamp_ns + 1
        self._last_stamp_ns = stamp
        return stamp

    def _scale(self, joint: JointSettings, para1: int | None = None) -> JointScale:
        """Counts -> units for the joint's REG_PARA1 (its parameter unless given).

        One path for simulated and real stations: the encoder layout the joint's parameters
        describe (family preset, ``steps_per_rev``/``revolutions``/``measuring_step``) and
        the REG_PARA1 in force (frame length, invalid LSB bits: :func:`count_factor`).
        Without a usable layout, ``steps_per_rev``/``revolutions`` or ``measuring_step``
        are taken as the resolution of REG_SSI_POS itself.
        """
        para1 = joint.para1 if para1 is None else para1
        cfg = self.configs.get(joint.name)
        if cfg is not None:
            factor = count_factor(cfg, para1)
            if cfg.linear:
                return JointScale(linear=True, measuring_step_m=cfg.measuring_step_m / factor,
                                  direction=joint.direction)
            return JointScale(
                counts_per_rev=cfg.steps_per_unit * factor,
                revolutions=cfg.revolutions_numerator / cfg.revolutions_divisor,
                direction=joint.direction)
        if joint.measuring_step > 0:
            return JointScale(linear=True, measuring_step_m=joint.measuring_step,
                              direction=joint.direction)
        return JointScale(counts_per_rev=joint.steps_per_rev or 8192,
                          revolutions=joint.revolutions or 4096, direction=joint.direction)

    def _para1_note(self, joint: str, para1: int) -> str:
        """Why ``para1`` does not fit the joint's encoder (or "")."""
        cfg = self.configs.get(joint)
        mismatch = para1_mismatch(cfg, para1) if cfg is not None else None
        return f"REG_PARA1 0x{para1:08X} does not fit the encoder: {mismatch}" if mismatch else ""

    @staticmethod
    def _max_speed(joint: JointSettings, value: float) -> float:
        """``<joint>.max_speed`` in joint units/s; -1: the encoder family's specified limit."""
        return spec_max_speed(joint.family) if value < 0 else value

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
        # the TPDOs need their wire time (cycle.cycle_waits); a late cycle skips SYNC slots,
        # counted in cycles_missed, instead of sending SYNCs nobody can answer. The master
        # wakes once every station's cycle is complete.
        assert self.master is not None
        self.master.wait_cycle(*cycle_waits(1.0 / self.settings.publish_rate, self.cycle_wire_s))
        self._cycle_times.append(t_sync)
        self._publish_cycle(t_sync, self.client.table.sync_seq)

    def _on_observed(self, cycle: ObservedCycle) -> None:
        """Listen-only: publish the cycle of a SYNC another master (or the log) sent."""
        if not self.context.ok():
            return
        self._cycle_times.append(wire_now())  # the achieved rate is the observed one
        try:
            self._publish_cycle(cycle.sync_time, cycle.seq)
        except RCLError:
            if self.context.ok():
                raise

    def _on_quiet(self) -> None:
        """Listen-only: a period without SYNC counts as a stale cycle for every joint."""
        now = wire_now()
        for name, counters in self.counters.items():
            counters.stale_cycles += 1
            counters.consecutive_stale += 1
            self._observe_health(name, now, stale=True, implausible=False)
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
            self._request_stop()

    def _publish_cycle(self, t_sync: float, seq: int) -> None:
        """Publish joint_states and ~/status of the cycle latched at ``t_sync`` (wire time).

        ``seq`` is the SYNC's sequence number: the joints' health counts a SYNC it never saw
        as lost (diagnostics.ChannelHealth).
        """
        stamp_ns = self._stamp_ns(t_sync)
        if stamp_ns is None:
            return
        stamp = time_msg(stamp_ns)
        js = JointState()
        js.header.stamp = stamp
        js.header.frame_id = self.settings.frame_id
        # ~/status costs as much as the rest of the cycle: build it only for a listener
        want_status = (self.recorder.active or self.status_pub.get_subscription_count() > 0
                       or self.liveview.wants(self.status_pub))
        status = Status(header=js.header) if want_status else None
        # a joint without a sample latched at this SYNC holds an older latch than this stamp:
        # while it is not (yet) STALE the cycle is not published and no estimate takes it in
        # (so a velocity window is always the published samples); a STALE joint's last value
        # is published with the others (its diagnostics say STALE), so joint_states goes on
        samples = [(joint, self.client_of(joint.name).latest(joint.slot)) for joint in self.settings.joints]
        limit = self.settings.stale_cycles
        transient = any(
            (sample is None or sample.sync_time < t_sync)
            and self.counters[joint.name].consecutive_stale + 1 < limit
            for joint, sample in samples)
        for joint, sample in samples:
            self._update_joint(joint, t_sync, js, status, sample, publish=not transient,
                               seq=seq)
        if transient:
            # a joint missed this SYNC but is not (yet) STALE: its value is an older latch
            # than this stamp, so the cycle is not published (a STALE joint's last value is)
            self.incomplete_cycles += 1
        elif not js.name:
            return
        elif self.publish_safe(self.joint_pub, js):
            self.recorder.record(self.joint_pub.topic_name, js, stamp_ns)
            if status is not None and self.publish_safe(self.status_pub, status):
                self.recorder.record(self.status_pub.topic_name, status, stamp_ns)
        else:
            return
        levels = self._levels()
        if self._last_levels and levels != self._last_levels:
            self.publish_diagnostics()
        self._last_levels = levels

    def _observe_health(self, name: str, now: float, *, stale: bool, implausible: bool,
                        seq: int | None = None, lost: float | None = None) -> None:
        """One SYNC (wire time ``now``, number ``seq``) for the joint's windowed health."""
        counters = self.counters[name]
        self.health[name].observe(now, stale=stale, implausible=implausible,
                                  sts=counters.last_sts,
                                  consecutive_stale=counters.consecutive_stale,
                                  stale_limit=self.settings.stale_cycles, seq=seq, lost=lost)

    def _observe_cycle(self, joint: JointSettings, seq: int, *, implausible: bool) -> None:
        """The joint's health for one cycle: the SYNC before this one, judged now.

        A cycle is published when its TPDOs are in or its wait is over; an answer that was on
        the wire in time but handled late (the station or the node starved of CPU) misses that
        wait. One cycle later it has been counted for its SYNC (by wire time), so the stale
        ratio measures the bus, not the scheduler.
        """
        settled = self.client_of(joint.name).table.loss(joint.slot, seq - 1)
        if settled is None:
            return  # the first SYNC: judged with the next cycle
        t_prev, lost = settled
        self._observe_health(joint.name, t_prev, stale=lost > 0, implausible=implausible,
                             seq=seq - 1, lost=lost)

    def _update_joint(self, joint: JointSettings, t_sync: float, js: JointState,
                      status: Status | None, sample: ChannelSample | None,
                      seq: int, publish: bool = True) -> bool:
        """Count the joint's sample of this cycle; with ``publish``, add it to ``js``.

        Every cycle, published or not, counts for the joint's health at the SYNC's wire time.
        """
        name = joint.name
        counters = self.counters[name]
        if sample is None:
            counters.stale_cycles += 1
            counters.consecutive_stale += 1
            self._observe_cycle(joint, seq, implausible=False)
            return False
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
        if not publish:
            # the cycle is not published (a joint is not latched at its SYNC); it still counts
            self._observe_cycle(joint, seq, implausible=False)
            return fresh
        estimator = self.velocity[name]
        # the estimator's scale is the one of the REG_PARA1 in force (change_para1 swaps both)
        position = estimator.scale.position(sample.position)
        implausible = False
        watch = self.frames[name]
        # once per image received (an event-driven TPDO may arrive a cycle late, 000 Table 15)
        seen = watch.evaluate(image) if image != watch.image else None
        corrupt = seen is not None and seen[1].corrupt
        if seen is not None:
            for text in edges(*seen):
                self.handlers.log_event("encoder_status", name, "frame check", True, text)
            if corrupt:
                counters.frame_errors += 1
                text = watch.failures.failed(t_sync, seen[1])
                if text:
                    self.handlers.log_event("encoder_status", name, "frame check", False, text)
        counters.frame = watch.verdict if watch.checked else None
        if sample.sync_time <= self._para1_since[name]:
            # latched while REG_PARA1 changed: either setting may have read it
            position = velocity = math.nan
        elif corrupt:
            # parity or filler check failed (001 5.5.7, 004 3): the frame is not what the
            # encoder sent; keep the last good position and speed
            position = self.positions[name]
            velocity = estimator.velocity
        elif sts & NOT_MEASURING:
            # REG_SSI_POS is frozen (wire break, bad REG_PARA1, STOP): the position is the
            # last good one and the speed is unknown; the estimate restarts on recovery
            estimator.reset()
            velocity = math.nan
        elif fresh:
            velocity = estimator.update(sample.sync_time, sample.position)
            implausible = estimator.last_implausible
            if implausible:
                counters.implausible += 1
        elif counters.consecutive_stale >= self.settings.stale_cycles:
            # no fresh sample for stale_cycles cycles (silent gateway, lost frames): the
            # position is frozen, so the speed is unknown and restarts with fresh samples
            estimator.reset()
            velocity = math.nan
        else:
            velocity = estimator.velocity
        self._observe_cycle(joint, seq, implausible=implausible)
        self.positions[name] = position
        js.name.append(name)
        js.position.append(position)
        js.velocity.append(velocity)
        if status is not None:
            inp = ProcessInput.decode(image)
            status.channels.append(channel_msg(name, joint.slot, sample, inp, counters, watch))
        return fresh

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

    # -- diagnostics -----------------------------------------------------------------------
    def achieved_rate(self) -> float:
        """Cycles per second over the last diagnostics period (at least 1 s, at most uptime)."""
        now = wire_now()
        window = min(max(self.settings.diagnostics_period, 1.0), now - self._cycle_started)
        if window <= 0:
            return 0.0
        times = self._cycle_times
        while times and now - times[0] > window:
            times.popleft()
        return len(times) / window

    def _levels(self) -> tuple:
        """The diagnostic levels without building the statuses (checked every cycle)."""
        levels = [max(h.level, WARN if self.para1_note[j] else OK)
                  for j, h in self.health.items()]
        # PowerFail / error bits change a joint's level too (a failed check under noise would
        # flip it every few cycles: that one waits for the periodic message)
        levels += [(f.power_failure, f.encoder_error) if (f := c.frame) else None
                   for c in self.counters.values()]
        levels.extend(int(c.gateway_alive) for c in self.station_clients.values())
        levels.append(int(self.client.gateway_alive) * 2 + int(bool(self._bus_problem())))
        return tuple(levels)

    def _statuses(self) -> list:
        s = self.settings
        fqn = self.get_fully_qualified_name()
        out = []
        for joint in s.joints:
            name = joint.name
            hw = (f"{s.bus_interface}:{s.bus_channel} node {joint.station or s.node_id} "
                  f"slot {joint.slot} XN-1SSI")
            extra = {"para1": f"0x{self.para1[name]:08X}",
                     "max_speed": f"{self.max_speed[name]:g}",
                     "velocity_window": str(s.velocity_window),
                     "stale_limit_cycles": str(s.stale_cycles),
                     "frame_id": s.frame_id}
            st = channel_status(status_name(fqn, name), hw, self.counters[name],
                                self.health[name], self.positions[name], extra)
            if self.para1_note[name] and st.level < WARN:
                st.level, st.message = WARN, self.para1_note[name]
            out.append(st)
        if len(self.station_clients) > 1:
            return out + self._station_statuses()
        counters = dataclasses.asdict(self.client.counters)
        counters.update(self.recorder.counters())
        counters["late_frames"] = self.client.table.late_frames
        counters.update(self._cycle_counters())
        meter = getattr(self.client, "load", None)
        if meter is not None:
            counters.update(meter.figures())
        counters.update(self.liveview.counters())
        out.append(bus_status(
            status_name(fqn, "bus"),
            f"{s.bus_interface}:{s.bus_channel} node {s.node_id} XN-GW-CANOPEN",
            alive=self.client.gateway_alive, connected=self.client.network is not None,
            achieved_rate=self.achieved_rate(), publish_rate=s.publish_rate, counters=counters,
            extra_error=self._bus_problem()))
        return out

    def _cycle_counters(self) -> dict[str, Any]:
        """The bus status's figures of the cycle, its threads and the services (one station
        or several)."""
        counters: dict[str, Any] = {
            "clock_steps": self.clock_steps, "incomplete_cycles": self.incomplete_cycles,
            "cycles_missed": getattr(self.cycle, "missed", 0),
            "cycle_scheduling": getattr(self.cycle, "scheduling", "")}
        if self.master is not None:
            counters["receive_scheduling"] = self.master.receive_scheduling
        counters["diagnostics_period_s"] = f"{self.settings.diagnostics_period:g}"
        counters["service_busy_refusals"] = self.handlers.busy_refusals
        counters["service_rested_s"] = f"{self.handlers.queue.rested:.2f}"
        return counters

    def _station_statuses(self) -> list:
        """Several stations: one bus status (master, SYNC, rate) and one per station."""
        s = self.settings
        fqn = self.get_fully_qualified_name()
        assert self.master is not None
        counters = dataclasses.asdict(self.master.counters)
        counters.update(self.recorder.counters())
        counters["late_frames"] = sum(c.table.late_frames for c in self.station_clients.values())
        counters.update(self._cycle_counters())
        counters.update(self.master.load.figures())
        silent = [sid for sid, c in self.station_clients.items() if not c.gateway_alive]
        out = [bus_status(
            status_name(fqn, "bus"), f"{s.bus_interface}:{s.bus_channel} master of stations "
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
                status_name(fqn, f"station {sid}"),
                f"{s.bus_interface}:{s.bus_channel} node {sid} XN-GW-CANOPEN",
                alive=client.gateway_alive, nmt_state=str(nmt), emcy=emcy,
                counters=station_counters))
        return out

    def _bus_problem(self) -> str:
        """An error beside the bus state: the recorder's, a simulated station that ended."""
        station = self.station.problem() if self.station is not None else None
        return "; ".join(p for p in (self.recorder.error, self.liveview.error, station) if p)

    def _on_diag_timer(self) -> None:
        """Periodic diagnostics; the CAM objects are re-read here (SDO, never in the cycle)."""
        if not self.settings.listen_only and self.context.ok():
            self.refresh_cams()
        self.publish_diagnostics()

    def publish_diagnostics(self) -> None:
        """Publish one DiagnosticArray with a status per joint and one for the bus."""
        if not self.context.ok():
            return
        now = self.get_clock().now()
        if now.nanoseconds <= 0:
            return  # use_sim_time before the first /clock: no time to stamp with
        msg = DiagnosticArray()
        msg.header.stamp = now.to_msg()
        msg.status = self._statuses()
        if not self.publish_safe(self.diag_pub, msg):
            return
        self.recorder.record("/diagnostics", msg, self.get_clock().now().nanoseconds)

    # -- parameters ------------------------------------------------------------------------
    def change_para1(self, joint: str, value: int, via: str) -> str:
        """Write REG_PARA1 of ``joint`` and move parameter, scale and estimate with it.

        The one path for every REG_PARA1 change (``<joint>.para1``, ``~/write_register`` to
        address 20): checked against the module's rules, written by the handshake, then the
        parameter, the counts -> units scale and the velocity estimate (restarted, samples
        latched before the write ignored) follow. Raises ConfigError / SsiBridgeError.
        """
        reason = validate_para1(value)
        if reason:
            raise ConfigError(f"REG_PARA1 0x{value:08X} refused (would raise ERR_PARA): {reason}")
        with self._para1_lock:
            old = self.para1[joint]
            self.para1_changing(joint)
            try:
                self.client_of(joint).write_register(self.joints[joint].slot, Reg.REG_PARA1, value)
            except BaseException:
                self.adopt_para1(joint, old, wire_now())
                raise
            self.adopt_para1(joint, value, wire_now())
        return (f"REG_PARA1 0x{old:08X} -> 0x{value:08X} via {via}; {joint}.para1, scale and "
                f"velocity estimate follow")

    def para1_changing(self, joint: str) -> None:
        """A REG_PARA1 change (write or LD20 reset) starts: samples are unknown until adopted."""
        self._para1_since[joint] = math.inf
        self.velocity[joint].reset(after=math.inf)

    def adopt_para1(self, joint: str, value: int, since: float) -> None:
        """The module now holds ``value`` (written or reset): parameter, scale, estimate follow.

        Samples latched before ``since`` were acquired with the old REG_PARA1 and are skipped.
        """
        with self._para1_lock:
            scale = self._scale(self.joints[joint], value)
            s = self.settings
            estimator = VelocityEstimator(scale, s.velocity_window, self.max_speed[joint])
            estimator.reset(after=since)
            self.scales[joint] = scale
            self.velocity[joint] = estimator
            self.frames[joint].set_para1(value)
            self.para1[joint] = value
            self.para1_note[joint] = self._para1_note(joint, value)
            self._para1_since[joint] = since
            if self.get_parameter(f"{joint}.para1").value != value:
                self._tls.mirror = True
                try:
                    self.set_parameters([Parameter(f"{joint}.para1", value=value)])
                finally:
                    self._tls.mirror = False

    def _on_set_parameters(self, params: list) -> SetParametersResult:
        """Runtime changes (LIVE_*_PARAMETERS): checked together, then applied together."""
        node_values: dict[str, Any] = {}
        para1: dict[str, int] = {}
        max_speed: dict[str, float] = {}
        for p in params:
            joint, _, key = p.name.partition(".")
            if p.name in LIVE_NODE_PARAMETERS:
                node_values[p.name] = p.value
            elif joint in self.joints and key == "para1":
                para1[joint] = int(p.value)
            elif joint in self.joints and key == "max_speed":
                value = float(p.value)
                if not (value >= 0 or value == -1):
                    return SetParametersResult(
                        successful=False, reason=f"{p.name} {value}: >= 0 (0: off) or -1 "
                        "(the encoder family's limit)")
                max_speed[joint] = value
        if getattr(self._tls, "mirror", False):
            return SetParametersResult(successful=True)  # adopt_para1 mirrors the module
        for joint, value in para1.items():
            if value == self.para1[joint]:
                continue
            try:
                self.change_para1(joint, value, "parameter")
            except SsiBridgeError as err:
                return SetParametersResult(successful=False,
                                           reason=f"{joint}.para1 0x{value:08X}: {err}")
        for joint, value in max_speed.items():
            limit = self._max_speed(self.joints[joint], value)
            self.max_speed[joint] = limit
            self.velocity[joint].max_speed = limit
        if node_values:
            self._apply_node_parameters(node_values)
        return SetParametersResult(successful=True)

    def _apply_node_parameters(self, values: dict[str, Any]) -> None:
        """publish_rate, diagnostics_period, frame_id, velocity_window, stale_cycles."""
        names = {"publish_rate": "publish_rate", "diagnostics_period": "diagnostics_period",
                 "frame_id": "frame_id", "velocity_window": "velocity_window",
                 "stale_cycles": "stale_cycles"}
        self.settings = dataclasses.replace(
            self.settings, **{names[k]: v for k, v in values.items()})
        if "publish_rate" in values:
            self.cycle.period = 1.0 / float(values["publish_rate"])
        if "diagnostics_period" in values:
            self.diag_timer.timer_period_ns = int(1e9 * float(values["diagnostics_period"]))
            self.diag_timer.reset()
        if "velocity_window" in values:
            with self._para1_lock:
                for joint in self.joints:
                    self.velocity[joint] = VelocityEstimator(
                        self.scales[joint], int(values["velocity_window"]),
                        self.max_speed[joint])

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """rclpy's, plus an ~/events record of the change or the refusal."""
        try:
            result = super().set_parameters_atomically(parameter_list)
        except Exception as err:
            self._parameter_event(parameter_list, False, f"{type(err).__name__}: {err}")
            raise
        self._parameter_event(parameter_list, result.successful, result.reason)
        return result

    def set_parameters(self, parameter_list: list[Parameter]) -> list[SetParametersResult]:
        """rclpy's, plus an ~/events record of each change or refusal."""
        results = []
        for param in parameter_list:
            results.extend(super().set_parameters([param]))
            self._parameter_event([param], results[-1].successful, results[-1].reason)
        return results

    def _parameter_event(self, params: list[Parameter], success: bool, reason: str) -> None:
        if getattr(self._tls, "mirror", False) or not hasattr(self, "handlers"):
            return  # the mirror of a register write (its own event) or during start-up
        request = ", ".join(f"{p.name}={_short(p.value)}" for p in params)
        self.handlers.log_event("set_parameters", "", request, success,
                                "applied" if success else f"refused: {reason}")

    def shutdown(self) -> None:
        """Stop services, recording, the bus side; safe to call twice.

        Every step runs even if an earlier one fails (a recording on a full disk must not
        leave the bus open); failures are logged on one line each.
        """
        steps: list[tuple[str, Callable[[], object]]] = [
            ("services", self.handlers.stop), ("cycle", self.cycle.stop)]
        if self.player is not None:
            steps.append(("log replay", self.player.stop))
        steps += [("recording", self.recorder.stop), ("live view", self.liveview.stop)]
        steps += [(f"station {sid} client", c.close) for sid, c in self.station_clients.items()]
        steps += [("bus", self.client.close)]
        if self.master is not None:
            steps.append(("master", self.master.close))
        if self.station is not None:
            steps.append(("simulated station", self.station.stop))
        for what, step in steps:
            try:
                step()
            except Exception as err:  # noqa: BLE001 - the remaining steps must still run
                self.get_logger().error(f"stopping the {what} failed: {err}")
        logbridge.uninstall()


def _short(value: Any, limit: int = 80) -> str:
    """A parameter value for an event, truncated (a value may be huge)."""
    text = f"0x{value:08X}" if isinstance(value, int) and not isinstance(value, bool) \
        and value > 0xFFFF else repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


__all__ = ["SsiBridgeNode"]
