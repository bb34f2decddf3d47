"""Service handlers of the node: register access, preset, reset, control, fault injection.

Every handler answers within a bounded time (the client's handshake timeouts) and turns every
failure into ``success: false`` with a message naming the joint, the register and the reason;
no exception escapes into the executor. Each call is also recorded as an event.

Requests are taken from DDS at once by the node's own thread and served in arrival order by
one worker thread (:class:`~ssi_bridge.ros.request_queue.RequestQueue`). Up to ``MAX_QUEUED``
requests wait; one more is refused at once with "busy: N queued". So a burst of calls is never
lost in a DDS history that overflows while a handshake runs, and the worker's share of the
process's CPU (its GIL time) is bounded so that the cycle keeps its rate through a burst.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from builtin_interfaces.msg import Time
from rclpy.node import Node

from ssi_bridge.core.bridge import Bridge, register_name
from ssi_bridge.core.joint import Joint
from ssi_bridge.exceptions import BusError, RegisterError, SsiBridgeError
from ssi_bridge.ros.recording import SessionRecorder
from ssi_bridge.ros.recording_services import RecorderServices
from ssi_bridge.ros.request_queue import SERVICE_QOS, RequestQueue
from ssi_bridge.ros.sdo_services import SdoServices
from ssi_bridge.core.sdo_access import ObjectAccess
from ssi_bridge_msgs.msg import Event
from std_srvs.srv import Trigger
from ssi_bridge_msgs.srv import (
    InjectFault, ReadRegister, ResetRegisters, SetControl, SetPreset, StartRecording,
    StopRecording, WriteRegister,
)
from ssi_bridge_msgs.srv import SdoRead, SdoWrite

#: publishes a message on a publisher; False when the node is shutting down
Publish = Callable[[Any, Any], bool]


class BridgeServices:
    """The handlers: each turns a request into a call of the :class:`Bridge` facade.

    :param node: the ROS node the services, the ``~/events`` publisher and the log belong to
    :param bridge: the operations (registers, preset, reset, control, faults)
    :param recorder: the session recorder: records every event; its services
        (``ros/recording_services.py``) are registered with the others
    :param publish: the node's publish (shutdown-safe, mirrored to the live view)
    """

    def __init__(self, node: Node, bridge: Bridge, recorder: SessionRecorder,
                 publish: Publish) -> None:
        self.node = node
        self.bridge = bridge
        self.recorder = recorder
        self._publish = publish
        self.events = node.create_publisher(Event, "~/events", 50)
        recorder.offer(self.events.topic_name, self.events.qos_profile)
        self.queue = RequestQueue(node)
        #: ~/sdo_read, ~/sdo_write (ros/sdo_services.py)
        self.sdo = SdoServices(ObjectAccess(bridge), self.log_event, node.get_logger().error)
        self.busy_refusals = 0
        self._busy_logged = 0.0
        #: (type, resolved name, handler) of every service :meth:`register` created: the
        #: live view offers the same list (ros/liveview_services.py)
        self.offered: list[tuple[type[Any], str, Callable[[Any, Any], Any]]] = []

    def register(self, group: Any = None) -> None:
        """Create every service of the contract; their requests go through :attr:`queue`
        (one at a time: a handshake per slot is serialised anyway). ``group`` is unused: no
        executor runs these services."""
        node, rec = self.node, RecorderServices(self.recorder)
        for srv_type, name, handler in (
                (ReadRegister, "~/read_register", self.read_register),
                (WriteRegister, "~/write_register", self.write_register),
                (SetPreset, "~/set_preset", self.set_preset),
                (ResetRegisters, "~/reset_registers", self.reset_registers),
                (SetControl, "~/set_control", self.set_control),
                (InjectFault, "~/inject_fault", self.inject_fault),
                (SdoRead, "~/sdo_read", self.sdo.read),
                (SdoWrite, "~/sdo_write", self.sdo.write),
                (StartRecording, "~/start_recording", rec.on_start),
                (StopRecording, "~/stop_recording", rec.on_stop),
                (Trigger, "~/pause_recording", rec.on_pause),
                (Trigger, "~/resume_recording", rec.on_resume),
                (Trigger, "~/split_recording", rec.on_split),
                (Trigger, "~/snapshot", rec.on_snapshot)):
            service = node.create_service(srv_type, name, handler,
                                          callback_group=self.queue.group,
                                          qos_profile=SERVICE_QOS)
            self.queue.add(service, handler, self._refuser(name[2:]))
            self.offered.append((srv_type, service.service_name, handler))
        self.queue.start()

    def stop(self) -> None:
        """Stop serving (node shutdown)."""
        self.queue.stop()

    def refuser(self, kind: str) -> Callable[[Any, Any, int], None]:
        """The busy answer of service ``kind`` (e.g. "read_register") for a request that
        reaches :attr:`queue` another way (the live view)."""
        return self._refuser(kind)

    def _refuser(self, kind: str) -> Callable[[Any, Any, int], None]:
        """Fills the prompt answer to a request beyond the queue's limit."""
        def refuse(request: Any, response: Any, waiting: int) -> None:
            response.success = False
            response.message = (f"{kind}: busy: {waiting} queued (at most "
                                f"{self.queue.limit} requests wait); call again later")
            self.busy_refusals += 1
            self._log_busy(kind, getattr(request, "joint", ""), response.message)
        return refuse

    def _log_busy(self, kind: str, joint: str, message: str) -> None:
        """A log line at most once a second with the count (an event per refusal would cost
        the cycle the CPU a burst already takes); the bus diagnostics count them too."""
        if time.monotonic() - self._busy_logged >= 1.0:
            self._busy_logged = time.monotonic()
            self.node.get_logger().warning(
                f"{message} ({self.busy_refusals} busy refusals since start)")

    # -- helpers ---------------------------------------------------------------------------
    def log_event(self, kind: str, joint: str, request: str, success: bool, message: str) -> None:
        """Publish (and record) what a user did and how it ended."""
        now = self.node.get_clock().now()
        ev = Event(kind=kind, joint=joint, request=request, success=success, message=message)
        ev.header.stamp = Time(sec=now.nanoseconds // 10**9, nanosec=now.nanoseconds % 10**9)
        self._publish(self.events, ev)
        self.recorder.record(self.events.topic_name, ev, now.nanoseconds)
        text = f"{kind} {joint} {request}: {message}"
        # rclpy ties a severity to each call site, so one call per severity
        if success and kind in ("read_register", "sdo_read"):
            self.node.get_logger().debug(text)  # a read changes nothing: the event suffices
        elif success:
            self.node.get_logger().info(text)
        else:
            self.node.get_logger().warning(text)

    def _run(self, kind: str, request: Any, response: Any, body: Callable[[Joint], str],
             describe: str, subject: str = "") -> Any:
        """Run ``body(joint)``; fill success/message; record the event; never raise.

        ``subject`` (e.g. "REG_SSI_POS (0)") leads a failure message so that it names the
        register by its manual name, not only by address.
        """
        what = f"{kind} {subject}".rstrip()
        name = getattr(request, "joint", "")
        joint: Joint | None = None
        try:
            joint = self.bridge.joint(name)
            name = joint.name
            response.success, response.message = True, body(joint)
        except (SsiBridgeError, ValueError) as err:
            if isinstance(err, (BusError, RegisterError)) and joint is not None:
                joint.counters.handshake_failures += 1
            response.success, response.message = False, f"{what} on {name or '?'}: {err}"
        except Exception as err:  # noqa: BLE001 - a service must answer, whatever happened
            self.node.get_logger().error(f"{kind}: unexpected {type(err).__name__}: {err}")
            response.success = False
            response.message = f"{what} on {name or '?'}: internal error {type(err).__name__}: {err}"
        self.log_event(kind, name, describe, response.success, response.message)
        return response

    # -- handlers --------------------------------------------------------------------------
    def read_register(self, request: Any, response: Any) -> Any:
        """~/read_register: REG_RD_ADR handshake; REG_RD_ABORT becomes a refusal."""
        def body(joint: Joint) -> str:
            response.value = self.bridge.read_register(joint, request.address)
            return f"{register_name(request.address)} = 0x{response.value:08X} ({response.value})"
        return self._run("read_register", request, response, body,
                         f"address={request.address}", register_name(request.address))

    def write_register(self, request: Any, response: Any) -> Any:
        """~/write_register: REG_WR / REG_WR_AKN / REG_WR_ACCEPT handshake."""
        return self._run("write_register", request, response,
                         lambda joint: self.bridge.write_register(joint, request.address,
                                                                  request.value),
                         f"address={request.address} value=0x{request.value:08X}",
                         register_name(request.address))

    def set_preset(self, request: Any, response: Any) -> Any:
        """~/set_preset: REG_OFFSET so that REG_SSI_POS reads the requested position."""
        def body(joint: Joint) -> str:
            response.offset, response.position, text = self.bridge.set_preset(
                joint, request.position)
            return text
        return self._run("set_preset", request, response, body, f"position={request.position}")

    def reset_registers(self, request: Any, response: Any) -> Any:
        """~/reset_registers: REG_SF = "LD20" (with parameters) or "LD48" (without)."""
        return self._run("reset_registers", request, response,
                         lambda joint: self.bridge.reset_registers(joint,
                                                                   request.include_parameters),
                         f"include_parameters={request.include_parameters}")

    def set_control(self, request: Any, response: Any) -> Any:
        """~/set_control: STOP, EN_CMPx and one-cycle CLR_CMPx pulses of the process output."""
        return self._run("set_control", request, response,
                         lambda joint: self.bridge.set_control(
                             joint, stop=request.stop, enable_cmp1=request.enable_cmp1,
                             enable_cmp2=request.enable_cmp2, clear_cmp1=request.clear_cmp1,
                             clear_cmp2=request.clear_cmp2),
                         f"stop={request.stop} en_cmp1={request.enable_cmp1} "
                         f"en_cmp2={request.enable_cmp2} clr_cmp1={request.clear_cmp1} "
                         f"clr_cmp2={request.clear_cmp2}")

    def inject_fault(self, request: Any, response: Any) -> Any:
        """~/inject_fault: simulation only."""
        return self._run("inject_fault", request, response,
                         lambda joint: self.bridge.inject_fault(joint, request.kind, request.rate,
                                                                request.duration),
                         f"kind={request.kind} rate={request.rate} duration={request.duration}")
