"""The ssi_bridge ROS 2 node: one SYNC cycle per period, published as joint_states and status.

Each cycle the node (the CANopen master) sends SYNC; the gateway latches every module's SSI
frame and answers with TPDOs; each joint's core (``core/joint.py``) turns its sample into
joint units and a velocity; the node publishes. ``header.stamp`` is the SYNC time, which is
the SSI latch time of the sample (the module latches on SYNC, well inside one bit time after
it; docs/node.md). Services call the ROS-free facade (``core/bridge.py``) from their own
thread, so the cycle never waits on them. The node is an rclpy ``LifecycleNode`` whose
``autostart`` parameter configures and activates it at start-up (``ssi_bridge_node``) or
leaves that to ``~/change_state`` (``ssi_bridge_managed_node``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.context import Context
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Status

from ssi_bridge.base.timebase import ModelClock, wire_now
from ssi_bridge.client.can_log_player import CanLogPlayer
from ssi_bridge.client.cycle_feed import feed_frames
from ssi_bridge.client.listener import ListenOnlyClient
from ssi_bridge.client.master import BridgeClient, CanMaster
from ssi_bridge.core.bridge import Bridge
from ssi_bridge.core.cycle import Cycle
from ssi_bridge.core.cycle_log import StationLog
from ssi_bridge.core.joint import Joint
from ssi_bridge.exceptions import RecordingError
from ssi_bridge.ros import logbridge
from ssi_bridge.ros.bus_side import BusSide, StationFactory
from ssi_bridge.ros.cycle import CycleThread, cycle_wire_time
from ssi_bridge.ros.cycle_publish import CyclePublisher
from ssi_bridge.ros.lifecycle import NodeLifecycle, RosParts, declare_autostart
from ssi_bridge.ros.liveview import LiveView
from ssi_bridge.ros.node_params import RuntimeParameters
from ssi_bridge.ros.node_start import bridging_line, prepare_process, replay_settings
from ssi_bridge.ros.node_status import CycleRate, NodeDiagnostics
from ssi_bridge.ros.observe import SILENT_WARNING_S, ObservedCycleThread
from ssi_bridge.ros.params import NodeSettings, declare_parameters
from ssi_bridge.ros.qos_overrides import overridable_publisher as publisher
from ssi_bridge.ros.rclpy_compat import RCLError
from ssi_bridge.ros.recording import SessionRecorder
from ssi_bridge.ros.recording_meta import bus_config
from ssi_bridge.ros.services import BridgeServices
from ssi_bridge.ros.span_probe import probe_from_env
from ssi_bridge.ros.stamps import Stamper

class SsiBridgeNode(LifecycleNode):
    """Bridge of the XN-1SSI channels of XN-GW-CANOPEN stations to ROS 2 (a lifecycle node).

    ``autostart`` is the default of the ``autostart`` parameter: on, the constructor
    configures and activates the node and raises the reason if that fails (nothing left
    open); off, it returns unconfigured with nothing open.

    :param stop: ends the process's spin cleanly (default: shuts the context down)
    :param autostart: the default of the ``autostart`` parameter
    :param parameter_overrides: parameters given in code, as rclpy ``Node`` takes them
    :param context: the rclpy context (default: the global one)
    :raises ConfigError: a parameter is invalid; with autostart also what configure or
        activate failed on (SsiBridgeError, OSError)

    It owns its parts: :attr:`bus` (ros/bus_side.py), :attr:`lifecycle` (ros/lifecycle.py;
    rclpy's transition callbacks go to it), :attr:`parameters` (ros/node_params.py), and
    from the first configure :attr:`handlers` (ros/services.py), :attr:`recorder`
    (ros/recording.py), :attr:`liveview` and :attr:`diagnostics` (ros/node_status.py).
    """

    def __init__(self, stop: Callable[[], None] | None = None, autostart: bool = True,
                 parameter_overrides: list[Parameter] | None = None,
                 context: Context | None = None) -> None:
        super().__init__("ssi_bridge", parameter_overrides=parameter_overrides,
                         context=context)
        self._request_stop = stop or self.context.try_shutdown
        logbridge.install(self.get_logger())
        autostart = declare_autostart(self, autostart)
        self.settings: NodeSettings = replay_settings(declare_parameters(self), self)
        #: makes the simulated station(s) (simulation: true; None on real hardware)
        simulation: StationFactory | None = None
        if self.settings.simulation:  # the node's one import of the simulator: a node on
            # real hardware loads nothing of ssi_bridge.sim (docs/architecture.md)
            from ssi_bridge.sim.supervisor import Simulation

            # the node and its simulated station meet on this bus (sim/supervisor/station.py)
            self.settings = Simulation.bus_settings(self.settings,
                                                    self.get_fully_qualified_name())
            simulation = Simulation
        s = self.settings
        #: the simulated station's clock: wire time since the node started (fault durations)
        self.model_clock = ModelClock()
        self.stamper = Stamper(self.get_clock(), self.get_logger())
        #: the benchmark's span per cycle (ros/span_probe.py); None unless it asks
        self._span_probe = probe_from_env()
        #: the joints' cores by name, in the configured order (filled by the bus side)
        self.joints: dict[str, Joint] = {}
        #: each station's frame log by node id (filled by the bus side): which SYNC a TPDO
        #: answers, and whether a sample is vouched for (core/cycle_log.py)
        self.frame_logs: dict[int, StationLog] = {}
        #: the cycle decisions (core/cycle.py): ros/ only turns its results into messages
        self.cycle_core = Cycle(self.joints, self.frame_logs)
        #: SYNC, the cycle's decisions and its messages (ros/cycle_publish.py)
        self.cycle_publisher = CyclePublisher(self)
        self.parameters: RuntimeParameters  # the REG_PARA1 mirror below reaches it
        self.bridge = Bridge(self.joints, self.client_of,
                             lambda joint, value: self.parameters.mirror_para1(joint, value))
        self.parameters = RuntimeParameters(self, self.joints, self.bridge, self)
        self.cycle_wire_s = cycle_wire_time(s, self.get_logger().warning)
        self.cycle: CycleThread | ObservedCycleThread | None = None
        #: the bus side (opened by configure, closed by cleanup; ros/bus_side.py)
        self.bus = BusSide(bus_config(s), simulation, self.bridge, self.model_clock,
                           self.get_logger().info)
        #: the achieved cycle rate; the cycle appends each cycle's monotonic time
        self.cycle_rate = CycleRate()
        self._cycle_times = self.cycle_rate.times
        self.lifecycle = NodeLifecycle(self, self.bus, self.get_logger())
        self.lifecycle.begin(autostart, (self.trigger_configure, self.trigger_activate))

    @property
    def client(self) -> BridgeClient | ListenOnlyClient:
        """The first station's client or the listener (AttributeError before configure)."""
        if (client := self.bus.client) is None:
            raise AttributeError("client: the bus side was never opened")
        return client

    @property
    def master(self) -> CanMaster | None:
        """The CANopen master while configured (None: listen-only, closed)."""
        return self.bus.master

    @property
    def player(self) -> CanLogPlayer | None:
        """The log replay of a listen-only node (``replay.can_log``)."""
        return self.bus.player

    @property
    def latch_bound_s(self) -> float:
        """The longest a sample's frames may end after its SYNC to be published (s): the
        ``latch_bound`` parameter plus one cycle's worst-case wire time."""
        return self.settings.latch_bound + self.cycle_wire_s

    def open_bus_side(self) -> None:
        """Configure: the joints' cores, the bus side (ros/bus_side.py), the frame logs."""
        s = self.settings
        self.joints.clear()
        for j in s.joints:
            core = Joint(j, velocity_window=s.velocity_window, stale_cycles=s.stale_cycles,
                         max_speed=float(self.get_parameter(f"{j.name}.max_speed").value))
            if core.layout_problem:
                self.get_logger().warning(f"{j.name}: no frame checks: {core.layout_problem}")
            self.joints[j.name] = core
        self.bus.open(s, self.joints)
        self._attach_frame_logs()
        if not s.listen_only:
            self.refresh_cams()
        self.cycle_rate.restart()

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

    def create_ros_side(self) -> RosParts:
        """Publishers, the recorder, the cycle loop, services, diagnostics, parameters."""
        s = self.settings
        self.joint_pub = publisher(self, JointState, "joint_states")
        self.status_pub = publisher(self, Status, "~/status")
        self.diag_pub = publisher(self, DiagnosticArray, "/diagnostics")
        self.recorder = SessionRecorder(self, s)
        for pub in (self.joint_pub, self.status_pub, self.diag_pub):
            self.recorder.offer(pub.topic_name, pub.qos_profile)
        self._service_group = MutuallyExclusiveCallbackGroup()
        self._diag_group = MutuallyExclusiveCallbackGroup()
        self.cycle = self._new_cycle(s)
        self.handlers = BridgeServices(self, self.bridge, self.recorder, self.publish_safe)
        self.handlers.register(self._service_group)
        self.liveview = LiveView(self, s, self.handlers)
        for pub in (self.joint_pub, self.status_pub, self.diag_pub, self.handlers.events):
            self.liveview.offer(pub)
        self.diagnostics = NodeDiagnostics(
            self, self, self.bus, self.joints, self.cycle_rate, self.cycle_core, self.stamper,
            recorder=self.recorder, liveview=self.liveview, services=self.handlers,
            publish=lambda msg: self.publish_safe(self.diag_pub, msg),
            refresh_cams=self.refresh_cams, bus_open=lambda: self.lifecycle.configured)
        self.diag_timer = self.create_timer(s.diagnostics_period, self.diagnostics.on_timer,
                                            callback_group=self._diag_group)
        self.parameters.attach_events(self.handlers.log_event)
        self.add_on_set_parameters_callback(self.parameters.on_set)
        return RosParts(self.recorder, self.handlers, self.liveview, self.diagnostics)

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
        prepare_process(s, self.get_logger().info)
        self.cycle_rate.started = time.monotonic()
        assert self.cycle is not None, "start_cycle builds the cycle first"
        self.cycle.start()
        if self.player is not None:
            if s.replay_wait_for_subscribers > 0:
                self.player.start_when(lambda: self.joint_pub.get_subscription_count() > 0,
                                       s.replay_wait_for_subscribers, self.context.ok)
            else:
                self.player.start()
        self.get_logger().info(bridging_line(s, self.joints, self.joint_pub.topic_name,
                                             self.status_pub.topic_name,
                                             self.get_fully_qualified_name()))

    def client_of(self, joint: str) -> BridgeClient | ListenOnlyClient:
        """The client of the station holding ``joint``'s module (KeyError: unknown joint)."""
        return self.bus.station_clients.get(self.joints[joint].settings.station, self.client)

    def refresh_cams(self) -> None:
        """Read the CAM objects of every joint (SDO: never in the cycle)."""
        for name, err in self.bridge.refresh_cams():
            self.get_logger().debug(f"{name}: CAM objects not read: {err}")

    # -- the lifecycle (ros/lifecycle.py: rclpy calls these on the node) --------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Open the bus side; the first configure also creates publishers, services, timers.

        :param state: the state the transition starts from (rclpy's; not needed here)
        :returns: SUCCESS, FAILURE or ERROR, as rclpy's lifecycle takes it
        """
        return self.lifecycle.configure()

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start SYNC/the cycle, publishing and (record.enabled) recording.

        :param state: the state the transition starts from (rclpy's; not needed here)
        :returns: SUCCESS, FAILURE or ERROR, as rclpy's lifecycle takes it
        """
        return self.lifecycle.activate()

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the cycle and the recording; the bus stays open and configured.

        :param state: the state the transition starts from (rclpy's; not needed here)
        :returns: SUCCESS, FAILURE or ERROR, as rclpy's lifecycle takes it
        """
        return self.lifecycle.deactivate()

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the bus (and stop the simulated station).

        :param state: the state the transition starts from (rclpy's; not needed here)
        :returns: SUCCESS, FAILURE or ERROR, as rclpy's lifecycle takes it
        """
        return self.lifecycle.cleanup()

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state: stop what runs and close what is open."""
        return self.lifecycle.lifecycle_shutdown()

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """An error in a transition: close everything, back to unconfigured.

        :param state: the state the transition starts from (rclpy's; not needed here)
        :returns: SUCCESS, FAILURE or ERROR, as rclpy's lifecycle takes it
        """
        return self.lifecycle.error()

    def shutdown(self) -> None:
        """The process ends: close everything (NodeLifecycle.shutdown; safe to call twice)."""
        self.lifecycle.shutdown()

    # -- the steps the lifecycle runs (ros/lifecycle.py LifecycleSteps) ----------------------
    def renew_cycle(self) -> None:
        """A later configure: a new cycle loop on the new bus side."""
        self.cycle = self._new_cycle(self.settings)

    def start_cycle(self) -> None:
        """Activate: a cycle (unless configure just built one), then :meth:`_start`."""
        if self.cycle is None:
            self.cycle = self._new_cycle(self.settings)
        self._start(self.settings)

    def release_cycle(self) -> CycleThread | ObservedCycleThread | None:
        """Deactivate: the cycle to stop (activate builds the next one)."""
        cycle, self.cycle = self.cycle, None
        return cycle

    def set_parameters(self, parameter_list: list[Parameter]) -> list[SetParametersResult]:
        """rclpy's, plus an ~/events record of each change or refusal (node_params.py).

        :param parameter_list: the parameters to set, each on its own
        :returns: one result per parameter, in order
        """
        return self.parameters.set_each(parameter_list, super().set_parameters)

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """rclpy's, plus an ~/events record of the change or the refusal.

        :param parameter_list: the parameters to set, all or none
        :returns: the one result
        """
        return self.parameters.set_atomically(parameter_list, super().set_parameters_atomically)

    def _publish_on_change(self) -> None:
        """The diagnostics at once when a level changed since the last cycle."""
        self.diagnostics.publish_on_change()

    # -- listen-only (the cycle itself: ros/cycle_publish.py) ------------------------------
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

    def publish_safe(self, publisher: Publisher, msg: object) -> bool:
        """Publish; False instead of an error when shutdown invalidated the context meanwhile.

        :param publisher: where to publish
        :param msg: the message (of the publisher's type)
        :returns: True when published (and passed to the live view)
        :raises RCLError: rclpy's, re-raised while the context is still valid
        """
        try:
            publisher.publish(msg)
        except RCLError:
            if self.context.ok():
                raise
            return False
        self.liveview.publish(publisher, msg)
        return True


__all__ = ["SsiBridgeNode"]
