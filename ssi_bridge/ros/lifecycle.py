"""The node's lifecycle: what each standard transition opens, starts, stops and closes.

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

from collections.abc import Callable
from typing import Any

from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn

from ssi_bridge.ros import logbridge
from ssi_bridge.ros.param_table import NODE_PARAMETERS

#: one step of a shutdown: (what, callable); a failing step is logged, the next still runs
Step = tuple[str, Callable[[], object]]


class BridgeLifecycle:
    """The transitions of the node (a part of :class:`~ssi_bridge.ros.node.SsiBridgeNode`).

    The node provides the steps (``_open_bus_side``, ``_create_ros_side``, ``_new_cycle``,
    ``_start``) and the parts they fill (``settings``, ``station``, ``master``, ``client``,
    ``station_clients``, ``cycle``, ``player``, ``recorder``, ``handlers``, ``liveview``).
    """

    settings: Any
    station: Any
    master: Any
    client: Any
    station_clients: dict
    cycle: Any
    player: Any
    recorder: Any
    handlers: Any
    liveview: Any
    #: the bus side is open (configure done, cleanup not yet)
    configured: bool = False
    #: the cycle runs (activate done, deactivate not yet)
    active: bool = False
    #: publishers, services, timers exist (made by the first configure, kept until the end)
    _ros_side: bool = False
    #: autostart is running configure and activate: a failure is raised, not logged
    _autostarting: bool = False
    #: the error of the last failed transition
    _transition_error: BaseException | None = None

    # -- start-up ----------------------------------------------------------------------------
    def _declare_autostart(self, default: bool) -> bool:
        """Declare the read-only ``autostart`` parameter with ``default`` (the executable's:
        a params file or ``-p`` still decides) and return its value; declared before the
        others (ros/params.py then takes it as declared)."""
        _, descriptor = NODE_PARAMETERS["autostart"]
        descriptor.name = "autostart"
        return bool(self.declare_parameter(  # type: ignore[attr-defined]
            "autostart", default, descriptor).value)

    def _begin(self, autostart: bool) -> None:
        """End of construction: configure and activate (autostart), or wait unconfigured.

        Raises the failed transition's error (the bus side closed again) if autostart fails.
        """
        if not autostart:
            self.get_logger().info(  # type: ignore[attr-defined]
                "managed node: unconfigured; configure opens the bus")
            return
        self._autostarting = True
        try:
            for trigger in (self.trigger_configure, self.trigger_activate):  # type: ignore
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
            problem = self.diagnostics.bus_problem() if self._ros_side else ""  # type: ignore
            self.get_logger().error(  # type: ignore[attr-defined]
                f"{what} failed: {' '.join(str(err).split()) or type(err).__name__}"
                + (f" ({problem})" if problem else ""))
        return TransitionCallbackReturn.FAILURE

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Open the bus side (start the simulated station, connect, configure the gateway);
        the first configure also creates publishers, services and timers."""
        s = self.settings
        try:
            self._open_bus_side(s)  # type: ignore[attr-defined]
            if not self._ros_side:
                self._create_ros_side(s)  # type: ignore[attr-defined]
                self._ros_side = True
            else:
                self.cycle = self._new_cycle(s)  # type: ignore[attr-defined]
                self.recorder.open_frame_tap()
        except Exception as err:  # noqa: BLE001 - reported as FAILURE, the node stays unconfigured
            self._close_bus_side()
            return self._failed("configure", err)
        self.configured = True
        if not self._autostarting:
            self.get_logger().info(  # type: ignore[attr-defined]
                f"configured: bus {s.bus_interface}:{s.bus_channel} open, node {s.node_id}"
                + (" (simulated station started)" if self.station is not None else ""))
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start SYNC/the cycle, publishing and (record.enabled) recording."""
        try:
            if self.cycle is None:
                self.cycle = self._new_cycle(self.settings)  # type: ignore[attr-defined]
            self._start(self.settings)  # type: ignore[attr-defined]
        except Exception as err:  # noqa: BLE001 - reported as FAILURE, the node stays inactive
            return self._failed("activate", err)
        self.active = True
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the cycle and the recording; the bus stays open and configured."""
        self._stop_cycle()
        self.get_logger().info(  # type: ignore[attr-defined]
            "deactivated: cycle stopped, bus still configured")
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the bus (and stop the simulated station)."""
        self._close_bus_side()
        self.get_logger().info("cleaned up: bus closed")  # type: ignore[attr-defined]
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state: stop what runs and close what is open."""
        self._stop_cycle()
        self._close_bus_side()
        if self._ros_side:
            self.recorder.finalize()  # ~/start_recording is refused from now on (#24 item 7)
        self.get_logger().info("shut down: bus closed")  # type: ignore[attr-defined]
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
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
        steps: list[Step] = [("cycle", self.cycle.stop)]
        if self.player is not None:
            steps.append(("log replay", self.player.stop))
        steps.append(("recording", self.recorder.stop))
        self._run_steps(steps)
        self.cycle = None  # a thread runs once: activate builds the next one

    def _close_bus_side(self) -> None:
        """Close every station's client, the bus, the master, the snapshots' CAN listener; stop
        the simulated station."""
        self.configured = False
        steps: list[Step] = [(f"station {sid} client", c.close)
                             for sid, c in getattr(self, "station_clients", {}).items()]
        if getattr(self, "client", None) is not None:
            steps.append(("bus", self.client.close))
        if getattr(self, "master", None) is not None:
            steps.append(("master", self.master.close))
        if getattr(self, "station", None) is not None:
            steps.append(("simulated station", self.station.stop))
        if self._ros_side:  # the snapshots' CAN listener holds the bus too
            steps.append(("snapshot CAN listener", self.recorder.close_frame_tap))
        self._run_steps(steps)
        self.station = None
        self.station_clients = {}
        self.master = None

    def _run_steps(self, steps: list[Step]) -> None:
        """Run every step even if an earlier one fails; a failure is one log line."""
        for what, step in steps:
            try:
                step()
            except Exception as err:  # noqa: BLE001 - the remaining steps must still run
                self.get_logger().error(  # type: ignore[attr-defined]
                    f"stopping the {what} failed: {err}")

    def shutdown(self) -> None:
        """The process ends: stop services, cycle, recording, live view, the bus side; safe to
        call twice and in any lifecycle state.

        Services stop first (a register handshake in progress needs the cycle); every step
        runs even if an earlier one fails (a recording on a full disk must not leave the bus
        open).
        """
        if self._ros_side:
            self._run_steps([("services", self.handlers.stop)])
        self._stop_cycle()
        if self._ros_side:
            self._run_steps([("recording", self.recorder.finalize),
                             ("live view", self.liveview.stop)])
        self._close_bus_side()
        logbridge.uninstall()


__all__ = ["BridgeLifecycle"]
