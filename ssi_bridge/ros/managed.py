"""The bridge as a managed (lifecycle) node: ``ros2 run ssi_bridge ssi_bridge_managed_node``.

Robot stacks bring drivers up through the standard lifecycle (``~/change_state``): the node
starts unconfigured with nothing open; configure opens the bus side (the simulated station,
the master's connection and the gateway's configuration), activate starts the SYNC cycle,
publishing and recording, deactivate stops them with the bus still configured, cleanup closes
the bus (and stops the simulated station), shutdown closes whatever is open. It reuses
:class:`SsiBridgeNode`'s split (``_open_bus_side`` / ``_create_ros_side`` / ``_start`` /
``shutdown``); a failing transition returns FAILURE with the reason in the log.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from ssi_bridge.ros import logbridge
from ssi_bridge.ros.node import SsiBridgeNode
from ssi_bridge.ros.params import NodeSettings


class ManagedBridgeNode(SsiBridgeNode, LifecycleNode):
    """:class:`SsiBridgeNode` whose bus side and cycle follow the lifecycle transitions."""

    def __init__(self, stop: Callable[[], None] | None = None, **kwargs: Any) -> None:
        #: the bus side is open (configure done, cleanup not yet)
        self.configured = False
        #: the cycle runs (activate done, deactivate not yet)
        self.active = False
        self._deferred = True  # SsiBridgeNode.__init__ only declares: the transitions open
        super().__init__(stop=stop, **kwargs)
        self._deferred = False
        self.get_logger().info("managed node: unconfigured; configure opens the bus")

    # SsiBridgeNode.__init__ calls these three: deferred to the transitions
    def _open_bus_side(self, s: NodeSettings) -> None:
        if not self._deferred:
            super()._open_bus_side(s)

    def _create_ros_side(self, s: NodeSettings) -> None:
        if not self._deferred:
            super()._create_ros_side(s)

    def _start(self, s: NodeSettings) -> None:
        if not self._deferred:
            super()._start(s)

    def _on_diag_timer(self) -> None:
        if self.configured:  # the CAM objects are read over the bus: only while it is open
            super()._on_diag_timer()

    # -- transitions -----------------------------------------------------------------------
    def _failed(self, what: str, err: BaseException) -> TransitionCallbackReturn:
        problem = self._bus_problem() if hasattr(self, "recorder") else ""
        self.get_logger().error(f"{what} failed: {' '.join(str(err).split()) or type(err).__name__}"
                                + (f" ({problem})" if problem else ""))
        return TransitionCallbackReturn.FAILURE

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Open the bus side (start the simulated station, connect, configure the gateway)."""
        s = self.settings
        try:
            SsiBridgeNode._open_bus_side(self, s)
        except Exception as err:  # noqa: BLE001 - reported as FAILURE, the node stays unconfigured
            self._close_bus_side()
            return self._failed("configure", err)
        if not hasattr(self, "handlers"):  # publishers, services, timers: once per process
            SsiBridgeNode._create_ros_side(self, s)
        else:
            self.cycle = self._new_cycle(s)
        self.configured = True
        self.get_logger().info(
            f"configured: bus {s.bus_interface}:{s.bus_channel} open, node {s.node_id}"
            + (" (simulated station started)" if self.station is not None else ""))
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start SYNC/the cycle, publishing and (record.enabled) recording."""
        try:
            if self.cycle is None:
                self.cycle = self._new_cycle(self.settings)
            SsiBridgeNode._start(self, self.settings)
        except Exception as err:  # noqa: BLE001
            return self._failed("activate", err)
        self.active = True
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the cycle and the recording; the bus stays open and configured."""
        self._stop_cycle()
        self.get_logger().info("deactivated: cycle stopped, bus still configured")
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the bus (and stop the simulated station)."""
        self._close_bus_side()
        self.get_logger().info("cleaned up: bus closed")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state: stop what runs and close what is open."""
        self._stop_cycle()
        self._close_bus_side()
        if hasattr(self, "recorder"):
            self.recorder.finalize()  # ~/start_recording is refused from now on (#24 item 7)
        self.get_logger().info("shut down: bus closed")
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """An error in a transition: close everything, back to unconfigured."""
        self._stop_cycle()
        self._close_bus_side()
        return TransitionCallbackReturn.SUCCESS

    # -- steps -----------------------------------------------------------------------------
    def _stop_cycle(self) -> None:
        if not self.active:
            return
        self.active = False
        steps: list[tuple[str, Callable[[], object]]] = [("cycle", self.cycle.stop)]
        if self.player is not None:
            steps.append(("log replay", self.player.stop))
        steps.append(("recording", self.recorder.stop))
        self._run_steps(steps)
        self.cycle = None  # a thread runs once: activate builds the next one

    def _close_bus_side(self) -> None:
        self.configured = False
        steps: list[tuple[str, Callable[[], object]]] = [
            (f"station {sid} client", c.close)
            for sid, c in getattr(self, "station_clients", {}).items()]
        if getattr(self, "client", None) is not None:
            steps.append(("bus", self.client.close))
        if getattr(self, "master", None) is not None:
            steps.append(("master", self.master.close))
        if getattr(self, "station", None) is not None:
            steps.append(("simulated station", self.station.stop))
        self._run_steps(steps)
        self.station = None
        self.station_clients = {}
        self.master = None

    def _run_steps(self, steps: list[tuple[str, Callable[[], object]]]) -> None:
        for what, step in steps:
            try:
                step()
            except Exception as err:  # noqa: BLE001 - the remaining steps must still run
                self.get_logger().error(f"stopping the {what} failed: {err}")

    def shutdown(self) -> None:
        """The process ends (signal): close whatever the lifecycle left open."""
        self._stop_cycle()
        if hasattr(self, "handlers"):
            self._run_steps([("services", self.handlers.stop),
                             ("recording", self.recorder.finalize),
                             ("live view", self.liveview.stop)])
        self._close_bus_side()
        logbridge.uninstall()


__all__ = ["ManagedBridgeNode"]
