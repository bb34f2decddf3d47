"""``ros2 run ssi_bridge ssi_bridge_node``: start the bridge, stop it cleanly on SIGINT/SIGTERM.

rclpy's own signal handlers (SIGINT and SIGTERM) shut the context down; the executor then
returns, the node closes its recording and bus, and the process exits 0. A start-up failure
(bad parameter, bus that cannot be opened, gateway that does not answer) exits 1 with the
reason on one line instead of a traceback.
"""

from __future__ import annotations

import sys

import rclpy
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor

from ssi_bridge.exceptions import SsiBridgeError


def main(args: list[str] | None = None) -> int:
    """Run the node until interrupted; exit 0 on a clean stop, 1 with the reason otherwise."""
    from ssi_bridge.ros.node import SsiBridgeNode

    rclpy.init(args=args)
    node = None
    try:
        try:
            node = SsiBridgeNode()
        except (SsiBridgeError, ParameterException, NameValidationException, ValueError,
                OSError) as err:
            print(f"ssi_bridge_node: cannot start: {err}", file=sys.stderr)
            return 1
        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        try:
            executor.spin()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            executor.shutdown(timeout_sec=1.0)
    finally:
        if node is not None:
            node.shutdown()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
