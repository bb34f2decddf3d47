"""The node's service requests: taken from DDS at once, served in order by one paced worker.

Why not rclpy's executor, and how the taker and the worker share the work:
:class:`RequestQueue`. Both threads yield to the cycle: their CPU time (GIL time the cycle
thread cannot have) is held to ``cpu_share`` of the wall time each.
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from rclpy.callback_groups import CallbackGroup
from rclpy.context import Context
from rclpy.node import Node
from rclpy.service import Service
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from ssi_bridge.ros.rclpy_compat import (
    service_pointer, take_request, wait_for_requests,
)

logger = logging.getLogger(__name__)

#: KEEP_ALL: DDS keeps every request until the executor takes it (a KEEP_LAST history of
#: depth N silently replaced the oldest of more than N waiting requests)
SERVICE_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL,
                         reliability=ReliabilityPolicy.RELIABLE)
#: requests waiting for the worker; one more is refused at once with "busy: N queued"
MAX_QUEUED = 100
#: the worker's and the taker's CPU time each at most this share of the wall time: after a
#: request (a pass of the taker) that took c s of its CPU it rests c * (1 / share - 1) s.
#: Every Python step of the node holds the GIL, so the process's CPU is one budget; together
#: the two threads take at most 5 % of it (why this share: docs/node.md "Services")
SERVICE_CPU_SHARE = 0.025
#: requests the taker takes of one service per pass before it rests, so that one pass never
#: holds the GIL for a whole burst (docs/node.md "Services")
TAKE_PER_PASS = 16


#: a service handler: fills and returns the response to a request (ROS's generated request
#: and response classes carry no type hints)
Handler = Callable[[Any, Any], Any]
#: fills the busy answer to a request: (request, response, requests waiting)
Refuse = Callable[[Any, Any, int], None]


class Replier(Protocol):
    """Where a served request's response goes: its service, or a waiting caller."""

    def send_response(self, response: Any, header: Any) -> None:
        """Send ``response`` to the client of the request ``header`` names."""


class _Job:
    """One request: run by the worker, then its reply sent with the request's header."""

    __slots__ = ("run", "service", "response", "header")

    def __init__(self, run: Callable[[], object], service: Replier, response: Any,
                 header: Any) -> None:
        self.run = run
        self.service = service
        self.response = response
        self.header = header


class _Reply:
    """Stands in for a service in a :class:`_Job` of :meth:`RequestQueue.call`: "sending"
    the response tells the waiting caller it is filled."""

    __slots__ = ("done",)

    def __init__(self, done: threading.Event) -> None:
        self.done = done

    def send_response(self, response: Any, header: Any) -> None:
        self.done.set()


class _Detached(CallbackGroup):
    """A callback group no executor runs: :class:`RequestQueue` takes these requests itself."""

    def can_execute(self, entity: object) -> bool:
        return False

    def beginning_execution(self, entity: object) -> bool:
        return False

    def ending_execution(self, entity: object) -> None:
        pass


class RequestQueue:
    """Takes the requests of its services from DDS at once, serves them in arrival order.

    rclpy's executor takes one request per wait-set rebuild (a fraction of a millisecond of
    Python each, which a 1 kHz cycle feels: docs/node.md "Services") and hands a callback no
    reply header, so a reply cannot wait in a queue. Here a taker thread waits on the services alone and takes every waiting request
    per wake-up (the calls rclpy's executor makes, through ``ros/rclpy_compat.py``, and
    ``send_response``); a worker thread runs them one at a time and replies; beyond ``limit``
    waiting requests the taker refuses at once.
    """

    def __init__(self, node: Node, limit: int = MAX_QUEUED, name: str = "ssi_services",
                 cpu_share: float = SERVICE_CPU_SHARE) -> None:
        if not 0.0 < cpu_share <= 1.0:
            raise ValueError(f"cpu_share {cpu_share} outside (0, 1]")
        self.node = node
        self.limit = limit
        self.cpu_share = cpu_share
        #: seconds the worker and the taker rested to keep their CPU share (diagnostics)
        self.rested = 0.0
        self.group = _Detached()
        self._services: list[tuple[Service, Handler, Refuse]] = []
        self._jobs: deque[_Job] = deque()
        self._lock = threading.Condition()
        self._stopped = False
        self._wake = node.create_guard_condition(lambda: None, callback_group=self.group)
        self._worker = threading.Thread(target=self._work, name=name, daemon=True)
        self._taker = threading.Thread(target=self._take, name=f"{name}_take", daemon=True)

    def __len__(self) -> int:
        return len(self._jobs)

    def add(self, service: Service, handler: Handler, refuse: Refuse) -> None:
        """Serve ``service`` (created in :attr:`group`); ``refuse`` fills a busy answer."""
        self._services.append((service, handler, refuse))

    def call(self, handler: Handler, request: Any, response: Any, refuse: Refuse,
             timeout: float) -> bool:
        """Serve a request that came another way (the live view) in the same order.

        It waits behind the requests taken from DDS and counts toward :attr:`limit` like
        them; beyond it ``refuse`` fills the busy answer at once. Blocks the calling thread
        until ``response`` is filled; False if it was not (the queue stopped, or ``timeout``
        s passed).
        """
        done = threading.Event()
        with self._lock:
            if self._stopped:
                return False
            waiting = len(self._jobs)
            queued = waiting < self.limit
            if queued:
                self._jobs.append(_Job(lambda: handler(request, response), _Reply(done),
                                       response, None))
                self._lock.notify()
        if not queued:
            refuse(request, response, waiting)
            return True
        deadline = time.monotonic() + timeout
        while not done.wait(0.2):
            if self._stopped or time.monotonic() > deadline:
                return False
        return True

    def start(self) -> None:
        """Start taking requests (after every service was added)."""
        self._worker.start()
        self._taker.start()

    def stop(self) -> None:
        """End both threads; waiting requests are not answered (the node is going)."""
        with self._lock:
            self._stopped = True
            self._jobs.clear()
            self._lock.notify_all()  # the worker, and the taker if it rests
        self._wake.trigger()
        for thread in (self._taker, self._worker):
            if thread.is_alive() and thread is not threading.current_thread():
                thread.join(2.0)

    def _take(self) -> None:
        context = self.node.context
        cpu = time.thread_time
        while not self._stopped and context.ok():
            try:
                ready = self._wait(context)
                used = cpu()
                for service, handler, refuse in self._services:
                    if service_pointer(service) in ready:
                        self._take_all(service, handler, refuse)
                # a burst's requests wait in the KEEP_ALL history meanwhile (none is lost)
                self._rest(cpu() - used)
            except Exception as err:  # noqa: BLE001 - shutdown invalidates the handles
                if self._stopped or not context.ok():
                    return
                logger.error("service requests not taken: %s: %s", type(err).__name__, err)
                time.sleep(0.1)

    def _wait(self, context: Context) -> list[int]:
        """Block until a request (or :meth:`stop`) arrives; the ready services' pointers."""
        # 0.2 s: also re-checks stop and the context
        return wait_for_requests([s for s, _h, _r in self._services], self._wake, context,
                                 200_000_000)

    def _take_all(self, service: Service, handler: Handler, refuse: Refuse) -> None:
        """Take up to TAKE_PER_PASS waiting requests (the rest stay in DDS for the next pass)."""
        for _ in range(TAKE_PER_PASS):
            taken = take_request(service)
            if taken is None:
                return
            request, header = taken
            srv_type: Any = service.srv_type  # a generated class; rclpy types it a bare TypeVar
            response = srv_type.Response()
            with self._lock:
                waiting = len(self._jobs)
                if waiting < self.limit and not self._stopped:
                    self._jobs.append(_Job(functools.partial(handler, request, response),
                                           service, response, header))
                    self._lock.notify()
                    continue
            refuse(request, response, waiting)
            self._send(service, response, header)

    @staticmethod
    def _send(service: Replier, response: Any, header: Any) -> None:
        try:
            service.send_response(response, header)
        except Exception as err:  # noqa: BLE001 - a client gone or shutdown
            logger.debug("reply not sent: %s", err)

    def _work(self) -> None:
        cpu = time.thread_time  # this thread's CPU time: what it took from the GIL
        while True:
            with self._lock:
                while not self._jobs and not self._stopped:
                    self._lock.wait()
                if self._stopped:
                    return
                job = self._jobs[0]
            used = cpu()
            try:
                job.run()
            except Exception:  # noqa: BLE001 - handlers answer themselves; keep serving
                logger.exception("service handler failed")
            with self._lock:
                if self._jobs and self._jobs[0] is job:
                    self._jobs.popleft()
            self._send(job.service, job.response, job.header)
            self._rest(cpu() - used)

    def _rest(self, used: float) -> None:
        """Yield to the cycle: rest so that ``used`` s of CPU stay ``cpu_share`` of the time.

        A lone request is served at once (the rest comes after its answer); only requests
        back to back are spread out, the waiting ones stay queued (or are refused as busy).
        The taker rests the same way after each pass, so a burst of refusals is spread too.
        """
        pause = used * (1.0 / self.cpu_share - 1.0)
        if pause <= 0.0:
            return
        self.rested += pause
        with self._lock:
            self._lock.wait_for(lambda: self._stopped, pause)


__all__ = ["MAX_QUEUED", "SERVICE_QOS", "SERVICE_CPU_SHARE", "RequestQueue"]
