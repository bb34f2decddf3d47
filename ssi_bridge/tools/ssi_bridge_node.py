"""``ros2 run ssi_bridge ssi_bridge_node``: start the bridge, stop it cleanly on SIGINT/SIGTERM.

Any number of SIGINT/SIGTERM at any moment ends in exit 0 with the recording closed (summary
and metadata.yaml) and the bus closed. ``ros2 launch`` forwards the terminal's Ctrl-C, so the
node sees SIGINT twice, often milliseconds apart; the second one must not interrupt the
shutdown the first one started:

* until the handlers below are in place nothing is open, and a stop signal is a plain exit 0;
* from then on a signal only wakes a watcher thread (``signal.set_wakeup_fd``); the Python
  handler itself does nothing, so no KeyboardInterrupt ever lands inside a shutdown step;
* the watcher stops the executor; the main thread then closes the recording and the bus while
  the ROS context is still valid (its log lines reach /rosout, no "Failed to publish log
  message to rosout"), and only then shuts the context down. Later signals are no-ops.

A start-up failure (bad parameter or params file, bus that cannot be opened, gateway that does
not answer) exits 1 with the reason on one line instead of a traceback.
"""

from __future__ import annotations

import signal
import sys
import time

from ssi_bridge.record.heap import fix_mmap_threshold, limit_malloc_arenas
from ssi_bridge.base.stop_signals import STOP_SIGNALS, StopRequests

#: longest reason printed for a start-up error (an echoed 1 MB value stays readable)
MAX_REASON = 400
#: seconds a stop waits for callbacks still running (a register handshake takes < 1 s)
CALLBACK_DRAIN_S = 5.0


def _stopped_while_importing(signum: int, _frame: object) -> None:
    raise SystemExit(0)  # nothing is open yet: a stop request during start-up is a clean exit


# before rclpy starts its threads: at most 2 glibc malloc arenas, and a fixed mmap threshold
# so that large short-lived blocks never stay in the heap (record/heap.py)
limit_malloc_arenas()
fix_mmap_threshold()

# importing rclpy takes a few hundred ms; until the node's own handlers are in place a stop
# signal would otherwise end in a KeyboardInterrupt traceback (SIGINT) or exit 143 (SIGTERM)
for _sig in STOP_SIGNALS:
    signal.signal(_sig, _stopped_while_importing)

import rclpy  # noqa: E402
from rclpy.exceptions import NameValidationException, ParameterException  # noqa: E402
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402

from ssi_bridge.exceptions import SsiBridgeError  # noqa: E402
from ssi_bridge.ros.rclpy_compat import executor_tasks  # noqa: E402

#: errors that mean "this configuration cannot run", reported in one line
START_ERRORS = (SsiBridgeError, ParameterException, NameValidationException, ValueError, OSError)


def one_line(err: object, limit: int = MAX_REASON) -> str:
    """``err`` as one line of at most ``limit`` characters (rcl errors span several lines)."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= limit else text[: limit - 14] + f"... ({len(text)} chars)"


def params_file_problem(argv: list[str]) -> str | None:
    """Why a ``--params-file`` on the command line cannot be used, in one line, or None.

    rcl would report it too, but over several lines (its own log line, then the error with
    source positions); checked first, a missing or malformed file is one clear line.

    :param argv: the node's command line
    """
    import yaml

    for flag, path in zip(argv, argv[1:]):
        if flag != "--params-file":
            continue
        try:
            with open(path, encoding="utf-8") as f:
                data = yaml.safe_load(f)
        except OSError as err:
            return f"params file {one_line(path, 200)}: {err.strerror or err}"
        except yaml.YAMLError as err:
            return f"params file {one_line(path, 200)} is not valid YAML: {one_line(err, 300)}"
        if not isinstance(data, dict):
            return (f"params file {one_line(path, 200)}: expected a mapping "
                    "'<node name or /**>: {ros__parameters: {...}}'")
    return None


def _init(args: list[str] | None) -> str | None:
    """rclpy.init() without rclpy's signal handlers (ours are in place); the reason on one
    line if the command line or a params file is bad."""
    from rclpy.signals import SignalHandlerOptions

    problem = params_file_problem(sys.argv if args is None else args)
    if problem is not None:
        return problem
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:  # noqa: BLE001 - rcl reports a bad params file as RCLError
        return one_line(err)
    return None


def _spin(node: Node, stops: StopRequests) -> None:
    """Run the node's callbacks until a stop is requested or the context goes away."""
    executor = MultiThreadedExecutor(num_threads=4)
    try:
        executor.add_node(node)
        stops.on_stop(executor.wake)
        while not stops.requested and rclpy.ok():
            executor.spin_once(timeout_sec=0.5)
    except ExternalShutdownException:
        pass
    except Exception:
        if rclpy.ok() and not stops.requested:
            raise  # a real fault, not a shutdown racing a callback
    finally:
        _wait_for_callbacks(executor, node)  # no new ones start: spin_once is not called again
        executor.shutdown(timeout_sec=1.0)


def _wait_for_callbacks(executor: MultiThreadedExecutor, node: Node,
                        timeout: float = CALLBACK_DRAIN_S) -> None:
    """Let callbacks still running (a service call in its register handshake) finish before
    the node closes the bus under them; their errors are logged, not left to Task.__del__.

    Jazzy's ``Executor.shutdown`` does not wait for them (its wait is skipped once the
    executor is marked shut down) and destroys the guard condition a finishing callback
    wakes, so the executor's task list is read here, before it is shut down.
    """
    deadline = time.monotonic() + timeout
    for task in executor_tasks(executor):
        while not task.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        if task.done() and task.exception() is not None:
            node.get_logger().warning(f"a callback failed while stopping: "
                                      f"{one_line(task.exception())}")


def main(args: list[str] | None = None, managed: bool = False) -> int:
    """Run the node until interrupted; exit 0 on a clean stop, 1 with the reason otherwise.

    The node is a lifecycle node; its ``autostart`` parameter defaults to on (configure and
    activate at start-up; a failure is a start-up error) or, ``managed``
    (ssi_bridge_managed_node), off: it opens nothing until configured over ``~/change_state``.

    :param args: the command line without the program name (default: ``sys.argv[1:]``),
        ``--ros-args`` included
    :param managed: ``autostart`` defaults to off
    :returns: the exit code: 0 stopped by SIGINT/SIGTERM or a lifecycle shutdown; 1 the node
        could not start (bad parameters, a bus or station that cannot be reached), the
        reason on stderr
    """
    from ssi_bridge.ros.node import SsiBridgeNode

    from ssi_bridge.tools.memprobe import start_from_env

    start_from_env()
    stops = StopRequests()
    stops.install()
    reason = _init(args)
    if reason is not None:
        if stops.requested:
            return 0
        print(f"ssi_bridge_node: cannot start: {reason}", file=sys.stderr)
        return 1
    node = None
    try:
        try:
            node = SsiBridgeNode(stop=stops.request, autostart=not managed)
        except START_ERRORS as err:
            if stops.requested or not rclpy.ok():
                return 0  # stopped by a signal while starting
            print(f"ssi_bridge_node: cannot start: {one_line(err)}", file=sys.stderr)
            return 1
        except Exception:
            if stops.requested or not rclpy.ok():
                return 0
            raise
        if not stops.requested:
            _spin(node, stops)
    finally:
        if node is not None:
            if stops.signum:
                name = signal.Signals(stops.signum).name
                node.get_logger().info(f"{name} received: closing the recording and the bus")
            node.shutdown()
            node.destroy_node()
        rclpy.try_shutdown()
        stops.ignore_further()  # no signal of a storm may end the exit with its default action
    return 0


if __name__ == "__main__":
    sys.exit(main())
