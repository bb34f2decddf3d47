"""Spin one node until Ctrl-C or an external shutdown, then tear it down quietly.

The command-line tools (monitor) and the benchmarks' helper processes all end the same way:
no traceback on SIGINT, the executor and node destroyed, the context shut down once.
"""

from __future__ import annotations

from typing import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node


def spin_until_shutdown(node: Node, on_exit: Callable[[], None] | None = None) -> None:
    """Spin ``node`` on its own executor; ``on_exit`` runs before the node is destroyed."""
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # Ctrl-C shuts the context down under a take in progress (rclpy raises from the
        # binding); an error of a context that is still up is a real one
        if node.context.ok():
            raise
    finally:
        if on_exit is not None:
            on_exit()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()
