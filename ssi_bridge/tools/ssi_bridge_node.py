"""``ros2 run ssi_bridge ssi_bridge_node``: start the bridge, stop it cleanly on SIGINT/SIGTERM.

rclpy's own signal handlers (SIGINT and SIGTERM) shut the context down; the executor then
returns, the node closes its recording and bus, and the process exits 0 — also when the
signal arrives while the node is still starting. A start-up failure (bad parameter, bus that
cannot be opened, gateway that does not answer) exits 1 with the reason on one line instead
of a traceback.
"""

from __future__ import annotations

import signal
import sys


def _stopped_while_importing(signum: int, _frame: object) -> None:
    sys.exit(0)  # nothing is open yet: a stop request during start-up is a clean exit


# importing rclpy takes a few hundred ms; until rclpy.init() installs its handlers, SIGTERM
# would kill the process with 143 instead of the clean exit a launch system expects
signal.signal(signal.SIGTERM, _stopped_while_importing)

import rclpy  # noqa: E402
from rclpy.exceptions import NameValidationException, ParameterException  # noqa: E402
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor  # noqa: E402

from ssi_bridge.exceptions import SsiBridgeError  # noqa: E402

#: errors that mean "this configuration cannot run", reported in one line
START_ERRORS = (SsiBridgeError, ParameterException, NameValidationException, ValueError, OSError)


def main(args: list[str] | None = None) -> int:
    """Run the node until interrupted; exit 0 on a clean stop, 1 with the reason otherwise."""
    from ssi_bridge.ros.node import SsiBridgeNode

    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # rclpy.init() installs its own handler
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = SsiBridgeNode()
        except START_ERRORS as err:
            if not rclpy.ok():
                return 0  # stopped by a signal while starting
            print(f"ssi_bridge_node: cannot start: {err}", file=sys.stderr)
            return 1
        except Exception:
            if not rclpy.ok():
                return 0
            raise
        executor: MultiThreadedExecutor | None = None
        try:
            if not rclpy.ok():
                return 0  # a stop signal arrived while the node was being built
            executor = MultiThreadedExecutor(num_threads=4)
            executor.add_node(node)
            executor.spin()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except Exception:
            if rclpy.ok():
                raise  # a real fault, not a shutdown racing the start of the executor
        finally:
            if executor is not None:
                executor.shutdown(timeout_sec=1.0)
    finally:
        if node is not None:
            node.shutdown()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
