"""Draw a recorded session as a picture (positions, velocities, diagnostics, events).

With --frame it draws instead the bit-level timing diagram of one SSI frame taken from
the recorded ~/status (REG_SSI_FRAME of the chosen joint and sample), or of --value.

Examples:

    plot ~/ssi_sessions/run1 -o run1.png
    plot run1 --frame --joint axis_1 --index 100 --bits 25 --bit-rate 500000 -o frame.png
    plot --frame --value 0x1ABCDE --bits 25 --error-bits 2 -o frame.png   # no bag needed

Exit status 0 on success, 2 when the bag or an option is unusable (message says why), 130
when Ctrl-C cut it short (the shell's 128 + SIGINT: a picture not drawn is not done; one line,
no traceback).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ssi_bridge.exceptions import RecordingError

#: exit status after Ctrl-C (SIGINT), as a shell reports a command it interrupted
INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface of plot."""
    parser = argparse.ArgumentParser(prog="plot", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("bag", type=Path, nargs="?", help="bag directory or .mcap file")
    parser.add_argument("-o", "--output", type=Path, default=Path("session.png"),
                        help="picture file, its type from the suffix (default session.png)")
    parser.add_argument("--dpi", type=int, default=100, help="resolution (default 100)")
    frame = parser.add_argument_group("--frame: SSI timing diagram of one frame")
    frame.add_argument("--frame", action="store_true", help="draw one SSI frame")
    frame.add_argument("--joint", default="", help="channel of ~/status (default: first)")
    frame.add_argument("--index", type=int, default=0,
                       help="n-th status message with a valid REG_SSI_FRAME (default 0)")
    frame.add_argument("--value", type=lambda s: int(s, 0), help="frame value instead of a bag")
    frame.add_argument("--bits", type=int, default=25, help="frame length n (default 25)")
    frame.add_argument("--bit-rate", type=float, default=500e3, help="Hz (default 500 kHz)")
    frame.add_argument("--monoflop", type=float, default=20e-6, help="tm in s (default 20 µs)")
    frame.add_argument("--error-bits", type=int, default=0,
                       help="low bits that are error/special bits (highlighted)")
    return parser


def _recorded_frame(bag: Path, joint: str, index: int) -> tuple[int, str]:
    """REG_SSI_FRAME of the index-th valid status sample of ``joint``."""
    from ssi_bridge_msgs.msg import Status

    from ssi_bridge.record.reader import Bag
    with Bag(bag) as source:
        topics = [t.name for t in source.topics.values()
                  if t.type == "ssi_bridge_msgs/msg/Status"]
        if not topics:
            raise RecordingError(f"{source.path}: no ssi_bridge_msgs/msg/Status topic")
        seen = 0
        for _topic, stamp, msg in source.decoded(topics):
            if not isinstance(msg, Status):
                continue
            for ch in msg.channels:
                if (joint and ch.joint != joint) or not ch.ssi_frame_valid:
                    continue
                if seen == index:
                    t = (stamp - source.start_ns) / 1e9
                    return int(ch.ssi_frame), f"{ch.joint} at t = {t:.3f} s"
                seen += 1
                break
    raise RecordingError(f"{bag}: only {seen} valid SSI frames for joint {joint or '(first)'}")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``plot`` executable: a session, or one SSI frame, as a PNG.

    :param argv: the command line without the program name (default: ``sys.argv[1:]``)
    :returns: the exit code: 0 written; 2 a bag that cannot be read, bad options or an
        unwritable output (a RecordingError, ValueError or OSError, its reason on stderr);
        130 interrupted. Errors never leave as exceptions.
    """
    args = build_parser().parse_args(argv)
    try:
        if args.frame:
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot as plt

            from ssi_bridge.record.frame_diagram import draw_frame
            if args.value is not None:
                value, where = args.value, "given value"
            elif args.bag is not None:
                value, where = _recorded_frame(args.bag, args.joint, args.index)
            else:
                raise RecordingError("--frame needs a BAG or --value")
            fig, ax = plt.subplots(figsize=(max(8.0, 0.35 * args.bits + 3), 3.6), dpi=args.dpi)
            draw_frame(ax, value, args.bits, args.bit_rate, args.monoflop, args.error_bits,
                       title=f"SSI frame 0x{value:X} ({args.bits} bits, "
                             f"{args.bit_rate / 1e3:.0f} kHz) - {where}")
            fig.tight_layout()
            fig.savefig(args.output, dpi=args.dpi)
        else:
            if args.bag is None:
                raise RecordingError("give a BAG to plot")
            from ssi_bridge.record.plot import plot_session
            plot_session(args.bag, args.output, dpi=args.dpi)
    except (RecordingError, ValueError, OSError) as err:
        print(f"plot: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"plot: interrupted; {args.output} not written (or incomplete)", file=sys.stderr)
        return INTERRUPTED
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
