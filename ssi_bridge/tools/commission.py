"""``ros2 run ssi_bridge commission``: find the station on a bus and write its params file.

The logic is ``ssi_bridge/commission/``; this is the command line: options, progress on
stderr, the report on stdout, the params file. Exit codes (also in ``--help``):
0 done (the report names every slot that made no joint and why), 1 the bus could not be
opened or the file not written, 2 bad options, 3 another master is active (refused; see
``--listen-only``), 4 no XN-GW-CANOPEN found.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

EXIT_OK, EXIT_BUS, EXIT_USAGE, EXIT_OTHER_MASTER, EXIT_NOTHING = 0, 1, 2, 3, 4

DESCRIPTION = """\
Find every XN-GW-CANOPEN gateway on a CAN bus, its XN-1SSI modules and their encoders, and
write a params file ssi_bridge_node starts with. Listens first (refuses if another CANopen
master is active), scans node ids over SDO, reads REG_PARA1 of each module through the
register handshake, samples the raw SSI frames for --seconds, infers the moving bits, code
and direction and ranks the encoder families whose frames fit.

Nothing is written to a station but the read handshake's REG_RD_ADR (set back afterwards)
and SYNC (one module cycle per sample); --configure also writes a corrected REG_PARA1.
Move the encoders while sampling: a still encoder shows neither code nor direction.
"""

EPILOG = """\
exit codes:
  0  done: the report names every slot without a joint and why
  1  the bus could not be opened, or the params file not written
  2  bad options
  3  another CANopen master is active (one line; --listen-only watches it instead)
  4  no XN-GW-CANOPEN found

examples:
  commission --interface socketcan --channel can0 --bitrate 500000 -o station.yaml
  commission --interface socketcan --channel can0 --dry-run --json
"""


def _node_ids(text: str) -> tuple[int, ...]:
    ids: set[int] = set()
    for part in text.split(","):
        low, _, high = part.strip().partition("-")
        try:
            a, b = int(low), int(high or low)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: e.g. 1-127 or 3,5,10-20") from None
        if not 1 <= a <= b <= 127:
            raise argparse.ArgumentTypeError(f"{part!r}: node ids are 1-127")
        ids.update(range(a, b + 1))
    return tuple(sorted(ids))


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="commission", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--interface", default="socketcan", help="python-can interface "
                   "(default socketcan; udp_multicast, pcan, virtual, ...)")
    p.add_argument("--channel", default="can0", help="python-can channel (default can0)")
    p.add_argument("--bitrate", type=int, default=500_000, help="bit rate (default 500000)")
    p.add_argument("--node-ids", type=_node_ids, default=tuple(range(1, 128)),
                   metavar="LIST", help="node ids the SDO scan asks (default 1-127)")
    p.add_argument("--seconds", type=float, default=3.0,
                   help="sampling time in s (default 3)")
    p.add_argument("--listen", type=float, default=0.5,
                   help="listening time before sending anything, s (default 0.5)")
    p.add_argument("--listen-only", action="store_true",
                   help="send nothing: watch the bus another master drives")
    p.add_argument("--configure", action="store_true",
                   help="write the corrected REG_PARA1 to the modules that need one")
    p.add_argument("-o", "--output", metavar="FILE", help="write the params file here")
    p.add_argument("--dry-run", action="store_true", help="print the params file instead")
    p.add_argument("--json", action="store_true", help="the report as JSON")
    return p


class _Progress:
    """One progress line on stderr (rewritten in place on a terminal)."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty()
        self.open = False

    def __call__(self, text: str) -> None:
        if self.tty:
            sys.stderr.write("\r\x1b[K" + text)
            self.open = True
        else:
            sys.stderr.write(text + "\n")
        sys.stderr.flush()

    def close(self) -> None:
        if self.open:
            sys.stderr.write("\n")
            self.open = False


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``commission`` executable: find the station, write its params file.

    :param argv: the command line without the program name (default: ``sys.argv[1:]``)
    :returns: the exit code: 0 done; 1 the bus could not be opened or the file not
        written; 2 bad options; 3 another master is active; 4 no XN-GW-CANOPEN found.
        Errors never leave as exceptions (the reason on stderr).
    """
    try:
        args = _parser().parse_args(argv)
    except SystemExit as stop:
        return int(stop.code or 0)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="[%(levelname)s] %(name)s: %(message)s")
    for noisy in ("canopen", "can"):
        logging.getLogger(noisy).setLevel(logging.CRITICAL)
    from ssi_bridge.commission.params_out import BusSpec, render
    from ssi_bridge.commission.report import as_dict, as_text
    from ssi_bridge.commission.run import Options, commission
    from ssi_bridge.exceptions import SsiBridgeError
    from ssi_bridge.protocol.settings import BusConfig
    try:
        options = Options(seconds=args.seconds, listen=args.listen, node_ids=args.node_ids,
                          listen_only=args.listen_only, configure=args.configure)
        config = BusConfig(interface=args.interface, channel=args.channel,
                           bitrate=args.bitrate)
    except (ValueError, SsiBridgeError) as err:
        print(f"commission: {err}", file=sys.stderr)
        return EXIT_USAGE
    progress = _Progress()
    try:
        result = commission(config, options, progress)
    except (SsiBridgeError, OSError) as err:  # the bus could not be opened, or failed
        progress.close()
        print(f"commission: {err}", file=sys.stderr)
        return EXIT_BUS
    progress.close()
    if result.refusal:
        print(f"commission: {result.refusal}; stop it or use --listen-only", file=sys.stderr)
        return EXIT_OTHER_MASTER
    text = None
    if not result.listen_only and result.stations:
        text = render(BusSpec(args.interface, args.channel, args.bitrate), result.slot_results,
                      f" from {args.interface}:{args.channel}")
    if args.json:
        report = as_dict(result)
        if args.dry_run:
            report["params"] = text
        print(json.dumps(report, indent=2))
    else:
        print(as_text(result))
        if args.dry_run and text:
            print("\n" + text, end="")
    if args.output and text:
        try:
            Path(args.output).write_text(text, encoding="utf-8")
        except OSError as err:
            print(f"commission: {args.output} not written: {err}", file=sys.stderr)
            return EXIT_BUS
        print(f"commission: params file written to {args.output}", file=sys.stderr)
    if not result.stations and not result.listen_only:
        return EXIT_NOTHING
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
