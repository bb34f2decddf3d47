"""Every use of rclpy's private API in one place (Jazzy, rclpy 7.1), checked by a canary test.

The node needs six things rclpy does not offer publicly:

* :data:`RCLError`: the exception rcl raises when a publish or a take races the context's
  shutdown (``rclpy._rclpy_pybind11``); the node ends a cycle quietly on it during shutdown.
* :func:`wait_for_requests` and :func:`take_request`: the request queue takes service
  requests from DDS itself, at once and in arrival order, instead of through an executor
  (``rclpy_implementation.WaitSet``, ``service.handle.service_take_request``), so a burst of
  calls waits in the KEEP_ALL history and none is lost while a handshake runs.
* :func:`executor_tasks`: the callbacks an executor still runs (``executor._futures``), so
  the node can let them finish before it closes the bus under them.
* :func:`parameter_overrides`: the parameters given to a node (params file, ``-p``, the
  ``parameter_overrides`` argument), declared or not (``Node._parameter_overrides``), so a
  typo or an old name is reported instead of silently ignored.
* :class:`RcutilsLogger`: the class of ``Node.get_logger()``, which rclpy defines in its
  implementation package (``rclpy.impl``), for the log bridge's annotations.

``test/ros/test_rclpy_compat.py`` fails on an rclpy whose private names changed.
"""

from __future__ import annotations

from contextlib import ExitStack
from typing import Any

from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import Executor
from rclpy.task import Task
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy


def wait_for_requests(services: list[Any], guard: Any, context: Any, timeout_ns: int) -> list[int]:
    """Block until one of ``services`` has a request, ``guard`` (a GuardCondition) is
    triggered or ``timeout_ns`` passed; the pointers of the services with a request."""
    with ExitStack() as stack:
        handles = [s.handle for s in services]
        for handle in handles:
            stack.enter_context(handle)
        stack.enter_context(guard.handle)
        stack.enter_context(context.handle)
        wait_set = _rclpy.WaitSet(0, 1, 0, 0, len(handles), 0, context.handle)
        wait_set.clear_entities()
        for handle in handles:
            wait_set.add_service(handle)
        wait_set.add_guard_condition(guard.handle)
        wait_set.wait(timeout_ns)
        return wait_set.get_ready_entities("service")


def take_request(service: Any) -> tuple[Any, Any] | None:
    """One waiting request of ``service`` and its header (for the response), or None."""
    with service.handle:
        taken = service.handle.service_take_request(service.srv_type.Request)
    if taken is None or taken[1] is None:
        return None
    return taken


def service_pointer(service: Any) -> int:
    """The pointer :func:`wait_for_requests` reports a ready ``service`` by."""
    return service.handle.pointer


def parameter_overrides(node: Any) -> dict[str, Any]:
    """The parameters given to ``node`` by name (rclpy ``Parameter``), declared or not
    (AttributeError on an rclpy that keeps them elsewhere)."""
    given: dict[str, Any] = node._parameter_overrides
    return given


def executor_tasks(executor: Executor) -> list[Task]:
    """The tasks (callbacks) ``executor`` has started and not yet dropped (AttributeError on
    an rclpy that keeps them elsewhere)."""
    tasks: list[Task] = list(executor._futures)  # type: ignore[attr-defined]  # private
    return tasks


__all__ = ["RCLError", "RcutilsLogger", "executor_tasks", "parameter_overrides",
           "service_pointer", "take_request", "wait_for_requests"]
