"""Subscriber of the two-hosts test, run inside its own network namespace (not a test file).

Collects joint_states for a while, writes and reads back a register through the node's
services, and prints one JSON line: the stamps seen and the register values.
"""

from __future__ import annotations

import json
import sys
import threading
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import ReadRegister, WriteRegister


def _call(node, executor, srv_type, name, request, timeout: float):
    client = node.create_client(srv_type, name)
    if not client.wait_for_service(timeout_sec=timeout):
        return None
    future = client.call_async(request)
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    done.wait(timeout)
    return future.result() if future.done() else None


def main() -> int:
    duration, address, value = float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    rclpy.init()
    node = rclpy.create_node("netns_probe")
    stamps: list[int] = []
    node.create_subscription(JointState, "/joint_states",
                             lambda m: stamps.append(m.header.stamp.sec * 10**9
                                                     + m.header.stamp.nanosec), 100)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    def spin() -> None:
        try:
            executor.spin()
        except Exception:  # noqa: BLE001 - ends with the shutdown below
            pass
    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    deadline = time.monotonic() + 60.0
    while not stamps and time.monotonic() < deadline:  # DDS discovery across the veth
        time.sleep(0.05)
    first = len(stamps)
    time.sleep(duration)
    window = stamps[first:]
    w = _call(node, executor, WriteRegister, "/ssi_bridge/write_register",
              WriteRegister.Request(address=address, value=value), 20.0)
    r = _call(node, executor, ReadRegister, "/ssi_bridge/read_register",
              ReadRegister.Request(address=address), 20.0)
    print(json.dumps({
        "stamps": window,
        "write": None if w is None else [w.success, w.message],
        "read": None if r is None else [r.success, r.value, r.message]}), flush=True)
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()
    rclpy.try_shutdown()
    spinner.join(5.0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
