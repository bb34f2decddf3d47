"""Publish a recorded session again, with its timing and the player's controls; --recover
repairs a bag cut short by a crash.

Examples:

    replay ~/ssi_sessions/run1                       # original timing, all topics
    replay run1 --rate 2 --topics /joint_states --remap /joint_states:=/replayed/joint_states
    replay run1/run1_0.mcap --clock 100 --loop       # bare file, /clock at 100 Hz, forever
    replay run1 --exclude-regex status --playback-duration 10
    replay run1 --foxglove-port 8765 --no-ros        # scrub the session in Foxglove only
    replay --recover run1                            # after kill -9: rebuild summary + metadata

In a terminal: space pauses and resumes, → publishes the next message while paused, ↑/↓ change
the rate by 10 %, and a progress line on stderr shows the time, the rate and the messages
played. The replay's node offers ~/pause, ~/resume, ~/play_next, ~/set_rate and ~/seek.
It waits up to 5 s (--wait-for-subscribers) for a subscriber on every played topic.
Exit status, as ros2 bag play's: 0 done, or stopped by Ctrl-C (SIGINT) or SIGTERM; 2 the
bag or an option is unusable (message says why); 130 a --recover cut short by Ctrl-C.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from decimal import Decimal
from pathlib import Path
from typing import Any

from ssi_bridge.exceptions import RecordingError

#: how long replay waits by default for a subscriber on every played topic (s): Fast DDS
#: announces a participant every 3 s after its first burst, so a discovery that missed the
#: burst on a busy machine still ends within the wait
DEFAULT_WAIT = 5.0
#: exit status of a ``--recover`` cut short by Ctrl-C (the shell's 128 + SIGINT)
INTERRUPTED = 128 + signal.SIGINT


def seconds(text: str) -> Decimal:
    """A time in seconds, kept exact (``sec.nsec`` of a ROS time has 19 digits).

    :param text: seconds as given on the command line (``sec`` or ``sec.nsec``)
    :raises ValueError: not a finite decimal number
    """
    try:
        value = Decimal(text)
    except ArithmeticError:
        raise ValueError(text) from None
    if not value.is_finite():
        raise ValueError(text)
    return value


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface of replay (option names as rosbag2's ``ros2 bag play``)."""
    parser = argparse.ArgumentParser(prog="replay", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("bag", type=Path, help="bag directory or .mcap file")
    parser.add_argument("-r", "--rate", type=float, default=1.0, help="speed factor (default 1)")
    parser.add_argument("-l", "--loop", action="store_true", help="play again and again")
    parser.add_argument("--start-offset", type=float, default=0.0, metavar="S",
                        help="start S seconds into the bag")
    parser.add_argument("-p", "--start-paused", action="store_true",
                        help="start paused (space, ~/resume or Foxglove starts playback)")
    parser.add_argument("--playback-duration", type=float, metavar="S",
                        help="play S seconds of the bag (from the start offset)")
    until = parser.add_mutually_exclusive_group()
    until.add_argument("--playback-until", type=seconds, metavar="T",
                       help="stop after T: a ROS time sec.nsec, or seconds from the bag start")
    until.add_argument("--playback-until-sec", type=float, metavar="SEC",
                       help="stop after this ROS time, seconds since the epoch")
    until.add_argument("--playback-until-nsec", type=int, metavar="NSEC",
                       help="stop after this ROS time, nanoseconds since the epoch")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    parser.add_argument("-e", "--regex", "--topics-regex", dest="regex", default="",
                        metavar="REGEX", help="only topics this regular expression finds")
    parser.add_argument("--exclude-topics", nargs="+", default=[], metavar="TOPIC",
                        help="not these topics")
    parser.add_argument("-x", "--exclude-regex", default="", metavar="REGEX",
                        help="not the topics this regular expression finds")
    parser.add_argument("--remap", nargs="+", default=[], metavar="FROM:=TO",
                        help="publish a recorded topic under another name")
    parser.add_argument("--clock", type=float, nargs="?", const=40.0, default=0.0,
                        metavar="HZ", help="publish /clock (default 40 Hz when given)")
    parser.add_argument("--wait-for-subscribers", type=float, default=DEFAULT_WAIT, metavar="S",
                        help="wait up to S seconds until every topic has a subscriber, then "
                             f"play anyway (default {DEFAULT_WAIT:g}; 0: do not wait)")
    parser.add_argument("--disable-keyboard-controls", action="store_true",
                        help="do not read keys from the terminal")
    parser.add_argument("--foxglove-port", type=int, default=0, metavar="PORT",
                        help="serve the session to Foxglove on this WebSocket port, with "
                             "its time line (playback control); stays up at the end")
    parser.add_argument("--foxglove-address", default="127.0.0.1", metavar="ADDR",
                        help="address of the Foxglove server (default 127.0.0.1: this host)")
    parser.add_argument("--no-ros", action="store_true",
                        help="with --foxglove-port: publish nothing to ROS")
    parser.add_argument("--recover", action="store_true",
                        help="rebuild the summary and metadata.yaml of a crashed recording")
    parser.add_argument("--quiet", action="store_true", help="no progress line")
    return parser


def _remaps(pairs: list[str]) -> dict[str, str]:
    """``FROM:=TO`` pairs to a mapping (ValueError on a malformed one)."""
    out = {}
    for pair in pairs:
        src, sep, dst = pair.partition(":=")
        if not sep or not src or not dst:
            raise ValueError(f"remap {pair!r}: expected FROM:=TO")
        out[src] = dst
    return out


def _until(args: argparse.Namespace) -> float | Decimal | None:
    """The end time of the options, in seconds (see player_state.until_time)."""
    if args.playback_until_nsec is not None:
        return Decimal(args.playback_until_nsec) / 10**9
    if args.playback_until_sec is not None:
        return float(args.playback_until_sec)
    return None if args.playback_until is None else float(args.playback_until)


def _options(args: argparse.Namespace) -> Any:
    """ReplayOptions from the command line (ValueError on a bad value)."""
    from ssi_bridge.record.bag_replay import ReplayOptions

    if args.no_ros and not args.foxglove_port:
        raise ValueError("--no-ros needs --foxglove-port (nothing would see the replay)")
    if not 0 <= args.foxglove_port <= 65535:
        raise ValueError(f"--foxglove-port {args.foxglove_port}: must be 0..65535")
    return ReplayOptions(rate=args.rate, loop=args.loop, start_offset=args.start_offset,
                         topics=args.topics, regex=args.regex,
                         exclude_topics=args.exclude_topics, exclude_regex=args.exclude_regex,
                         remap=_remaps(args.remap), clock_hz=args.clock,
                         wait_for_subscribers=0.0 if args.no_ros else args.wait_for_subscribers,
                         playback_duration=args.playback_duration,
                         playback_until=_until(args), start_paused=args.start_paused,
                         until_is_ros_time=args.playback_until is None,
                         hold_at_end=bool(args.foxglove_port) and not args.loop)


def _stop_on_signals(state: Any) -> None:
    """Ctrl-C (SIGINT) and SIGTERM stop the playback: the replay ends as after its last message
    (subscribers get what was published, the terminal its settings) and exits 0, as
    ``ros2 bag play`` does. rclpy installs no handler of its own (``_play``), so a signal
    never ends a wait with an exception."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: state.stop())


def _spin(executor: Any, stop: threading.Event) -> None:
    """Serve the player services until ``stop`` is set or the context shuts down."""
    from rclpy.executors import ExternalShutdownException

    try:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
    except (ExternalShutdownException, KeyboardInterrupt):
        pass


def _play(args: argparse.Namespace, bag: Any, options: Any, ros_args: list[str]) -> int:
    """Set up the node, services, keys, progress line and Foxglove view; play; tear down."""
    from ssi_bridge.record.bag_replay import Player
    from ssi_bridge.record.replay_keys import Keyboard, ProgressLine

    node = executor = view = spinner = None
    stop_spin = threading.Event()
    if not args.no_ros:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        rclpy.init(args=["replay", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node("ssi_bridge_replay")
    keyboard = None
    progress = None
    keep: list[Any] = []
    try:
        player = Player(node, bag, options)
        if args.foxglove_port:
            from ssi_bridge.record.replay_view import ReplayView
            view = ReplayView(bag, player.topics, player.state, args.foxglove_address,
                              args.foxglove_port)
            player.sinks.append(view.sink)
            print(f"replay: Foxglove WebSocket server on ws://{args.foxglove_address}:"
                  f"{view.port}", file=sys.stderr, flush=True)
        if node is not None:
            from ssi_bridge.record.replay_services import ReplayServices
            keep.append(ReplayServices(node, player.state))  # the services live while kept
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            spinner = threading.Thread(target=_spin, args=(executor, stop_spin),
                                       name="replay-services", daemon=True)
            spinner.start()
        _stop_on_signals(player.state)
        if not args.disable_keyboard_controls:
            keyboard = Keyboard(player.state)
            if keyboard.start():
                logging.getLogger("replay").info(
                    "keys: space pause/resume, \u2192 next message (paused), "
                    "\u2191/\u2193 rate +/-10 %")
        if sys.stderr.isatty() and not args.quiet:
            progress = ProgressLine(player.state, sys.stderr)
        count = player.play(progress)
    finally:
        if keyboard is not None:
            keyboard.stop()
        if progress is not None:
            progress.close()
        if view is not None:
            view.stop()
        stop_spin.set()
        if spinner is not None:
            spinner.join(timeout=5.0)
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
    if player.state.stopped:
        print(f"replay: stopped after {count} messages from {bag.path}", file=sys.stderr)
        return 0
    print(f"replayed {count} messages from {bag.path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``replay`` executable: publish a bag again, or ``--recover`` it.

    :param argv: the command line without the program name (default: ``sys.argv[1:]``);
        ``--ros-args`` and what follows go to rclpy
    :returns: the exit code: 0 played, stopped or recovered; 2 a bag that cannot be read or
        bad options (a RecordingError or ValueError, its reason on stderr); 130 (128 +
        SIGINT) a ``--recover`` interrupted. Errors never leave as exceptions.
    """
    args_in = sys.argv[1:] if argv is None else argv
    ros_args = args_in[args_in.index("--ros-args"):] if "--ros-args" in args_in else []
    args = build_parser().parse_args(args_in[:len(args_in) - len(ros_args)])
    logging.basicConfig(level=logging.INFO, format="replay: %(message)s")
    try:
        if args.recover:
            from ssi_bridge.record.recover import recover_bag
            try:
                summary = recover_bag(args.bag)
            except OSError as err:  # unreadable file or directory: say which, no traceback
                raise RecordingError(f"--recover {args.bag}: {err}") from err
            print(f"recovered {summary.directory}: {summary.message_count} messages, "
                  f"{summary.duration:.3f} s")
            return 0
        from ssi_bridge.record.reader import Bag
        options = _options(args)
        bag = Bag(args.bag)
    except (RecordingError, ValueError) as err:
        print(f"replay: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if args.recover:  # a repair cut short is not done: run it again
            print(f"replay: --recover {args.bag} interrupted", file=sys.stderr)
            return INTERRUPTED
        print(f"replay: stopped before playback of {args.bag}", file=sys.stderr)
        return 0
    try:
        return _play(args, bag, options, ros_args)
    except (RecordingError, ValueError) as err:
        print(f"replay: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C before the player's handlers were in place
        print(f"replay: stopped before playback of {bag.path}", file=sys.stderr)
        return 0
    finally:
        bag.close()
        if not args.no_ros:
            import rclpy
            rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
