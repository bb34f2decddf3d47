"""The node's lifecycle: what each standard transition opens, starts, stops and closes.

:class:`NodeLifecycle` is the node's lifecycle part: rclpy calls the transition callbacks on
the node (``on_configure`` ...), which hand them to it; it keeps the state (configured,
active), runs the node's steps (:class:`LifecycleSteps`) and closes the bus side
(``ros/bus_side.py``) and the ROS side's parts (:class:`RosParts`) in order, and reports a
failure.

The bridge is one rclpy ``LifecycleNode`` (ROS 2 managed-node design, lifecycle_msgs), driven
through ``~/change_state`` / ``~/get_state`` like any managed driver: configure opens the bus
side (the simulated station, the master's connection and the gateway's configuration; the
publishers, services and diagnostics timer on the first configure), activate starts the SYNC
cycle, publishing and recording, deactivate stops them with the bus still configured, cleanup
closes the bus (and stops the simulated station), shutdown closes whatever is open. A failing
transition returns FAILURE with ``<transition> failed: <reason>`` in the log and leaves the
node where it was, so it can be tried again.

The read-only parameter ``autostart`` (as nav2's and ros2_control's drivers have it) runs
configure and activate while the node is constructed: ``ssi_bridge_node`` is the node with
autostart on (its default), ``ssi_bridge_managed_node`` the same node with autostart off by
default (it waits for ``~/change_state``). A failed autostart raises the transition's error
out of the constructor, with nothing left open and nothing logged, so the executable prints
the one-line reason and exits 1 (tools/ssi_bridge_node.py).

The publishers are rclpy's plain publishers (``create_publisher``; rclpy makes a managed
``LifecyclePublisher`` only through ``create_lifecycle_publisher``): joint_states and
``~/status`` are published by the cycle, which runs only while active, and ``/diagnostics``
by its timer, which publishes while the bus side is open (inactive and active).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node

from ssi_bridge.ros import logbridge
from ssi_bridge.ros.bus_side import BusSide
from ssi_bridge.ros.node_ports import CycleLoop, Step
from ssi_bridge.ros.param_table import NODE_PARAMETERS
from ssi_bridge.ros.params import NodeSettings
from ssi_bridge.ros.rclpy_compat import RcutilsLogger

if TYPE_CHECKING:
    from ssi_bridge.ros.liveview import LiveView
    from ssi_bridge.ros.node_status import NodeDiagnostics
    from ssi_bridge.ros.recording import SessionRecorder
    from ssi_bridge.ros.services import BridgeServices


def declare_autostart(node: Node, default: bool) -> bool:
    """Declare the read-only ``autostart`` parameter with ``default`` (the executable's: a
    params file or ``-p`` still decides) and return its value; declared before the others
    (ros/params.py then takes it as declared)."""
    _, descriptor = NODE_PARAMETERS["autostart"]
    descriptor.name = "autostart"
    return bool(node.declare_parameter("autostart", default, descriptor).value)


def run_steps(steps: Sequence[Step], error: Callable[[str], object]) -> None:
    """Run every step even if an earlier one fails; a failure is one ``error`` line."""
    for what, step in steps:
        try:
            step()
        except Exception as err:  # noqa: BLE001 - the remaining steps must still run
            error(f"stopping the {what} failed: {err}")


@dataclass(frozen=True)
class RosParts:
    """The parts of the ROS side the transitions stop and close (made by the first configure,
    kept until the end)."""

    recorder: SessionRecorder
    services: BridgeServices
    liveview: LiveView
    diagnostics: NodeDiagnostics


class LifecycleSteps(Protocol):
    """What the transitions ask of the node (ros/node.py)."""

    @property
    def settings(self) -> NodeSettings:
        """The node's settings as they are now."""

    def open_bus_side(self) -> None:
        """Configure: the joints' cores and the bus side. Raises what failed; the lifecycle
        then closes what is open."""

    def create_ros_side(self) -> RosParts:
        """The first configure, after the bus side: publishers, services, timers, a cycle.
        Raises what failed."""

    def renew_cycle(self) -> None:
        """A later configure: a new cycle loop (not started) on the new bus side."""

    def start_cycle(self) -> None:
        """Activate: start SYNC / the cycle, publishing and (record.enabled) recording.
        Raises what failed."""

    def release_cycle(self) -> CycleLoop | None:
        """Deactivate: the node lets go of its cycle loop (a thread runs once: activate
        builds the next one) and returns it to be stopped."""


class NodeLifecycle:
    """The transitions of the node (see the module docstring).

    :param steps: the node's steps the transitions run
    :param bus: the node's bus side (closed by cleanup)
    :param logger: the node's logger (a failed transition, each transition's result)
    """

    def __init__(self, steps: LifecycleSteps, bus: BusSide, logger: RcutilsLogger) -> None:
        self._steps = steps
        self._bus = bus
        self._log = logger
        #: the bus side is open (configure done, cleanup not yet)
        self.configured = False
        #: the cycle runs (activate done, deactivate not yet)
        self.active = False
        #: the ROS side's parts (made by the first configure, kept until the end)
        self._ros: RosParts | None = None
        #: autostart is running configure and activate: a failure is raised, not logged
        self._autostarting = False
        #: the error of the last failed transition
        self._transition_error: BaseException | None = None

    # -- start-up ----------------------------------------------------------------------------
    def begin(self, autostart: bool,
              triggers: Sequence[Callable[[], TransitionCallbackReturn]]) -> None:
        """End of the node's construction: run ``triggers`` (the node's trigger_configure and
        trigger_activate) with ``autostart``, or wait unconfigured.

        :raises BaseException: the failed transition's error (everything closed again)
        """
        if not autostart:
            self._log.info("managed node: unconfigured; configure opens the bus")
            return
        self._autostarting = True
        try:
            for trigger in triggers:
                if trigger() != TransitionCallbackReturn.SUCCESS:
                    error = self._transition_error or RuntimeError("autostart failed")
                    self.shutdown()
                    raise error
        finally:
            self._autostarting = False

    # -- transitions -------------------------------------------------------------------------
    def _failed(self, what: str, err: BaseException) -> TransitionCallbackReturn:
        self._transition_error = err
        if not self._autostarting:
            problem = self._ros.diagnostics.bus_problem() if self._ros is not None else ""
            self._log.error(
                f"{what} failed: {' '.join(str(err).split()) or type(err).__name__}"
                + (f" ({problem})" if problem else ""))
        return TransitionCallbackReturn.FAILURE

    def configure(self) -> TransitionCallbackReturn:
        """Open the bus side (start the simulated station, connect, configure the gateway);
        the first configure also creates publishers, services and timers. FAILURE: the
        reason logged, everything closed again (unconfigured)."""
        try:
            self._steps.open_bus_side()
            if self._ros is None:
                self._ros = self._steps.create_ros_side()
            else:
                self._steps.renew_cycle()
                self._ros.recorder.open_frame_tap()
                self._ros.diagnostics.reset()
        except Exception as err:  # noqa: BLE001 - reported as FAILURE, the node stays unconfigured
            self._close_bus_side()
            return self._failed("configure", err)
        self.configured = True
        if not self._autostarting:
            s = self._steps.settings
            self._log.info(
                f"configured: bus {s.bus_interface}:{s.bus_channel} open, node {s.node_id}"
                + (" (simulated station started)" if self._bus.station is not None else ""))
        return TransitionCallbackReturn.SUCCESS

    def activate(self) -> TransitionCallbackReturn:
        """Start SYNC/the cycle, publishing and (record.enabled) recording. FAILURE: the
        reason logged, the node stays inactive."""
        try:
            self._steps.start_cycle()
        except Exception as err:  # noqa: BLE001 - reported as FAILURE, the node stays inactive
            return self._failed("activate", err)
        self.active = True
        return TransitionCallbackReturn.SUCCESS

    def deactivate(self) -> TransitionCallbackReturn:
        """Stop the cycle and the recording; the bus stays open and configured."""
        self._stop_cycle()
        self._log.info("deactivated: cycle stopped, bus still configured")
        return TransitionCallbackReturn.SUCCESS

    def cleanup(self) -> TransitionCallbackReturn:
        """Close the bus (and stop the simulated station)."""
        self._close_bus_side()
        self._log.info("cleaned up: bus closed")
        return TransitionCallbackReturn.SUCCESS

    def lifecycle_shutdown(self) -> TransitionCallbackReturn:
        """From any state: stop what runs and close what is open; later recordings refused."""
        self._stop_cycle()
        self._close_bus_side()
        if self._ros is not None:
            self._ros.recorder.finalize()  # ~/start_recording is refused from now on
        self._log.info("shut down: bus closed")
        return TransitionCallbackReturn.SUCCESS

    def error(self) -> TransitionCallbackReturn:
        """An error in a transition: close everything, back to unconfigured."""
        self._stop_cycle()
        self._close_bus_side()
        return TransitionCallbackReturn.SUCCESS

    # -- steps -------------------------------------------------------------------------------
    def _stop_cycle(self) -> None:
        """Stop the cycle, a log replay and the recording (if active)."""
        if not self.active:
            return
        self.active = False
        cycle = self._steps.release_cycle()
        steps: list[Step] = [("cycle", cycle.stop)] if cycle is not None else []
        if self._bus.player is not None:
            steps.append(("log replay", self._bus.player.stop))
        if self._ros is not None:
            steps.append(("recording", self._ros.recorder.stop))
        run_steps(steps, self._log.error)

    def _close_bus_side(self) -> None:
        """Close every station's client, the bus, the master, the snapshots' CAN listener;
        stop the simulated station (every step runs, whatever failed before)."""
        self.configured = False
        steps = self._bus.close_steps()
        if self._ros is not None:  # the snapshots' CAN listener holds the bus too
            steps.append(("snapshot CAN listener", self._ros.recorder.close_frame_tap))
        run_steps(steps, self._log.error)

    def shutdown(self) -> None:
        """The process ends: stop services, cycle, recording, live view, the bus side; safe to
        call twice and in any lifecycle state.

        Services stop first (a register handshake in progress needs the cycle); every step
        runs even if an earlier one fails (a recording on a full disk must not leave the bus
        open).
        """
        ros = self._ros
        if ros is not None:
            run_steps([("services", ros.services.stop)], self._log.error)
        self._stop_cycle()
        if ros is not None:
            run_steps([("recording", ros.recorder.finalize), ("live view", ros.liveview.stop)],
                      self._log.error)
        self._close_bus_side()
        logbridge.uninstall()


__all__ = ["LifecycleSteps", "NodeLifecycle", "RosParts", "declare_autostart", "run_steps"]
