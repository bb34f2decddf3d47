"""Canary of rclpy's private API the node uses (ssi_bridge/ros/rclpy_compat.py): an rclpy
whose private names changed fails here, by name, instead of in a running node."""

from __future__ import annotations

import threading

import rclpy
from rclpy.executors import MultiThreadedExecutor
from ssi_bridge_msgs.srv import ReadRegister

from ssi_bridge.ros import rclpy_compat


def test_the_private_names_exist():
    from rclpy.impl.implementation_singleton import rclpy_implementation
    assert issubclass(rclpy_compat.RCLError, Exception)
    assert hasattr(rclpy_implementation, "WaitSet")


def test_a_request_is_waited_for_and_taken_without_an_executor(domain_id):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        node = rclpy.create_node("canary", context=context)
        service = node.create_service(ReadRegister, "canary_trigger", lambda req, res: res)
        guard = node.create_guard_condition(lambda: None)
        assert rclpy_compat.wait_for_requests([service], guard, context, 1_000_000) == []
        assert rclpy_compat.take_request(service) is None
        client = node.create_client(ReadRegister, "canary_trigger")
        assert client.wait_for_service(timeout_sec=10.0)
        client.call_async(ReadRegister.Request())
        ready: list[int] = []
        for _ in range(50):
            ready = rclpy_compat.wait_for_requests([service], guard, context, 200_000_000)
            if ready:
                break
        assert ready == [rclpy_compat.service_pointer(service)]
        taken = rclpy_compat.take_request(service)
        assert taken is not None and isinstance(taken[0], ReadRegister.Request)
        guard.trigger()
        assert rclpy_compat.wait_for_requests([service], guard, context, 1_000_000_000) == []
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_a_running_callback_is_listed(domain_id):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    release, started = threading.Event(), threading.Event()
    try:
        node = rclpy.create_node("canary_tasks", context=context)
        executor = MultiThreadedExecutor(num_threads=2, context=context)
        executor.add_node(node)
        assert rclpy_compat.executor_tasks(executor) == []

        def hold() -> None:
            started.set()
            release.wait(5.0)
        timer = node.create_timer(0.01, hold)
        executor.spin_once(timeout_sec=2.0)
        assert started.wait(5.0)
        timer.cancel()
        tasks = rclpy_compat.executor_tasks(executor)
        assert len(tasks) == 1 and not tasks[0].done()
        release.set()
        executor.shutdown()
        node.destroy_node()
    finally:
        release.set()
        rclpy.try_shutdown(context=context)


def test_the_given_parameters_are_read_declared_or_not(domain_id):
    """``parameter_overrides``: what a params file or ``-p`` gave a node, before and without a
    declaration (``Node._parameter_overrides``), so ros/params.py can name a typo."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        node = rclpy.create_node(
            "canary_overrides", context=context,
            cli_args=["--ros-args", "-p", "publish_rte:=100.0"],
            parameter_overrides=[rclpy.parameter.Parameter("joints", value=["a"])])
        given = rclpy_compat.parameter_overrides(node)
        assert given["publish_rte"].value == 100.0
        assert given["joints"].value == ["a"]
        assert not node.has_parameter("publish_rte")
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_a_nodes_logger_is_the_class_the_log_bridge_names(domain_id):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        node = rclpy.create_node("canary_logger", context=context)
        assert isinstance(node.get_logger(), rclpy_compat.RcutilsLogger)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
