"""Publish a recorded session again, with its timing; --recover repairs a bag cut short by a crash.

Examples:

    replay ~/ssi_sessions/run1                       # original timing, all topics
    replay run1 --rate 2 --topics /joint_states --remap /joint_states:=/replayed/joint_states
    replay run1/run1_0.mcap --clock 100 --loop       # bare file, /clock at 100 Hz, forever
    replay --recover run1                            # after kill -9: rebuild summary + metadata

A progress bar with elapsed/total bag time is drawn on stderr when it is a terminal.
Exit status: 0 done, 1 interrupted, 2 the bag or an option is unusable (message says why).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ssi_bridge.exceptions import RecordingError

BAR_WIDTH = 30


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface of replay."""
    parser = argparse.ArgumentParser(prog="replay", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("bag", type=Path, help="bag directory or .mcap file")
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    parser.add_argument("--loop", action="store_true", help="play again and again")
    parser.add_argument("--start-offset", type=float, default=0.0, metavar="S",
                        help="start S seconds into the bag")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    parser.add_argument("--remap", nargs="+", default=[], metavar="FROM:=TO",
                        help="publish a recorded topic under another name")
    parser.add_argument("--clock", type=float, nargs="?", const=40.0, default=0.0,
                        metavar="HZ", help="publish /clock (default 40 Hz when given)")
    parser.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                        help="wait up to S seconds until every topic has a subscriber")
    parser.add_argument("--recover", action="store_true",
                        help="rebuild the summary and metadata.yaml of a crashed recording")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
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


def _progress(elapsed: float, total: float) -> None:
    """Draw ``[#####.....] 12.3 / 45.6 s`` on the terminal."""
    frac = 0.0 if total <= 0 else min(1.0, elapsed / total)
    filled = int(frac * BAR_WIDTH)
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (BAR_WIDTH - filled)}] "
                     f"{elapsed:7.1f} / {total:.1f} s")
    sys.stderr.flush()


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``replay`` executable."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    args_in = sys.argv[1:] if argv is None else argv
    ros_args = args_in[args_in.index("--ros-args"):] if "--ros-args" in args_in else []
    args = build_parser().parse_args(args_in[:len(args_in) - len(ros_args)])
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
        from ssi_bridge.record.bag_replay import Player, ReplayOptions
        options = ReplayOptions(rate=args.rate, loop=args.loop, start_offset=args.start_offset,
                                topics=args.topics, remap=_remaps(args.remap),
                                clock_hz=args.clock,
                                wait_for_subscribers=args.wait_for_subscribers)
        bag = Bag(args.bag)
    except (RecordingError, ValueError) as err:
        print(f"replay: error: {err}", file=sys.stderr)
        return 2
    show = sys.stderr.isatty() and not args.quiet
    rclpy.init(args=["replay", *ros_args])
    try:
        node = rclpy.create_node("ssi_bridge_replay")
        try:
            player = Player(node, bag, options)
            count = player.play(_progress if show else None)
        finally:
            node.destroy_node()
            bag.close()
    except RecordingError as err:
        print(f"\nreplay: error: {err}" if show else f"replay: error: {err}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        return 1
    finally:
        rclpy.try_shutdown()
    if show:
        sys.stderr.write("\n")
    print(f"replayed {count} messages from {bag.path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
