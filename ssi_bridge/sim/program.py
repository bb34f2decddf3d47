"""``ros2 run ssi_bridge station``: the simulated XN-GW-CANOPEN station as a device of its own.

Reads the node's params file (joints, families, motion, para1, storage, bus), opens the bus
and runs until SIGINT/SIGTERM (exit 0). A node with ``simulation.enabled:=false`` on the same
bus then drives it exactly as a real station. The node with ``simulation.enabled:=true`` starts
this same program as its child process (``--parent-pid``: the station ends with its parent).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
from typing import Any

import yaml

from ssi_bridge.exceptions import SsiBridgeError
from ssi_bridge.protocol.settings import load_params_file, station_settings
from ssi_bridge.base.realtime import fifo_this_thread
from ssi_bridge.base.stop_signals import StopRequests

logger = logging.getLogger(__name__)

#: printed on stdout once the station has sent its boot-up message
READY = "station ready"

DESCRIPTION = """\
Run the simulated XN-GW-CANOPEN station (SSI encoders -> SSI lines -> XN-1SSI modules ->
gateway) on a CAN bus, as a device of its own. A ssi_bridge node started with
simulation.enabled:=false on the same bus drives it like real hardware, on this host or another.

The station reads the node's parameters from a ROS 2 params file: joints, <joint>.family,
<joint>.slot, <joint>.code, <joint>.cable_length, <joint>.para1, <joint>.motion.*, the
resolution overrides, storage_path, bus.interface, bus.channel, bus.bitrate, bus.node_id.
Options given here override the file.

Buses (python-can interfaces):
  udp_multicast  channel GROUP[:PORT][@INTERFACE_ADDRESS], e.g. 239.74.163.2:43113@127.0.0.1
                 (other processes or hosts; INTERFACE_ADDRESS is the local address the
                 group is joined and sent on, 127.0.0.1 for this host only)
  virtual        in-process only: useful in tests, not between processes
  socketcan      channel can0, vcan0, ...: a real or virtual SocketCAN interface

Fault injection reaches the station over the bus: simulation-only SDO objects
0x4000-0x4003, and 0x4004 holds the motion epoch (see docs/canopen.md).

Stop with Ctrl-C or SIGTERM (exit 0). Exit 2: bad parameters; exit 1: the bus cannot be
opened.
"""

EPILOG = """\
examples:
  station --params-file config/ssi_bridge.yaml --interface udp_multicast \\
      --channel 239.74.163.2:43113@127.0.0.1
  ssi_bridge_node --ros-args --params-file config/ssi_bridge.yaml -p simulation.enabled:=false \\
      -p bus.interface:=udp_multicast -p bus.channel:=239.74.163.2:43113@127.0.0.1
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="station", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params-file", metavar="FILE",
                   help="ROS 2 params file of the node ('-': read it from stdin)")
    p.add_argument("--node-name", default="ssi_bridge", metavar="NAME",
                   help="node name whose section of the params file applies (default "
                        "ssi_bridge; '/**' sections always apply)")
    p.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                   help="set one parameter, e.g. -p joints:=[a,b] -p a.family:=TTK70 "
                        "(value in YAML; repeatable)")
    p.add_argument("--interface", help="python-can interface (overrides bus.interface)")
    p.add_argument("--channel", help="python-can channel (overrides bus.channel)")
    p.add_argument("--bitrate", type=int, help="bit rate in bit/s (overrides bus.bitrate)")
    p.add_argument("--node-id", type=int, help="CANopen node id 1-127 (overrides bus.node_id)")
    p.add_argument("--priority", type=int, default=10, metavar="N",
                   help="run every thread SCHED_FIFO N (1-99; hardware never waits for a CPU, "
                        "and a driver sets aside answers later than its latch bound), set "
                        "before the station starts any thread; default 10, as the node's own "
                        "station child (simulation.station_priority); 0: normal scheduling. "
                        "Without the right to it: normal, said once")
    p.add_argument("--parent-pid", type=int, default=0, metavar="PID",
                   help="exit when this process is gone (used by the node for its child)")
    p.add_argument("--log-level", default="INFO",
                   choices=("DEBUG", "INFO", "WARNING", "ERROR"), help="default INFO")
    return p


def _values(args: argparse.Namespace) -> dict[str, Any]:
    values: dict[str, Any] = {}
    if args.params_file:
        if args.params_file == "-":
            values.update(load_params_file(sys.stdin, args.node_name))
        else:
            with open(args.params_file, encoding="utf-8") as fh:
                values.update(load_params_file(fh, args.node_name))
    for item in args.param:
        name, sep, text = item.partition(":=")
        if not sep or not name:
            raise SsiBridgeError(f"-p {item!r}: use NAME:=VALUE")
        values[name] = yaml.safe_load(text) if text else ""
    for option, name in (("interface", "bus.interface"), ("channel", "bus.channel"),
                         ("bitrate", "bus.bitrate"), ("node_id", "bus.node_id")):
        if getattr(args, option) is not None:
            values[name] = getattr(args, option)
    return values


def _watch_parent(parent: int, stop: StopRequests) -> None:
    """Stop when the parent is gone (PR_SET_PDEATHSIG is the fast path; this is the sure one)."""
    while not stop.event.wait(0.2):
        if os.getppid() != parent:
            logger.warning("parent process %d is gone: stopping", parent)
            stop.request()


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``station`` executable: the simulated station on its bus until
    SIGINT/SIGTERM.

    :param argv: the command line without the program name (default: ``sys.argv[1:]``):
        ``--params-file``, ``-p NAME:=VALUE`` overrides, the bus (see ``--help``)
    :returns: the exit code: 0 stopped by a signal; 2 bad parameters; 1 the bus could not be
        opened or failed (the reason on stderr)
    """
    # a handler that set an Event itself deadlocked the station for good when a second signal
    # (the node's stop, PR_SET_PDEATHSIG, a terminal's Ctrl-C) landed inside the first one
    stop = StopRequests()
    stop.install(watch=False)  # its thread starts after the priority is set (it inherits it)
    try:
        return _run(stop, argv)
    finally:
        stop.ignore_further()  # no signal of a storm may end the exit with its default action


def _run(stop: StopRequests, argv: list[str] | None) -> int:
    """The station program after its stop signals are routed (see :func:`main`)."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=args.log_level, stream=sys.stderr,
                        format="[%(levelname)s] %(name)s: %(message)s")
    if args.log_level != "DEBUG":  # every SDO transfer and NMT step is an INFO there
        for noisy in ("canopen", "can"):
            logging.getLogger(noisy).setLevel(logging.WARNING)
    from ssi_bridge.sim.gateway.station import Station  # after argparse: --help stays fast
    try:
        settings = station_settings(_values(args))
        station = Station(settings)
    except (SsiBridgeError, OSError, ValueError) as err:
        print(f"station: bad parameters: {err}", file=sys.stderr)
        return 2
    if args.parent_pid and os.getppid() != args.parent_pid:
        return 0  # the parent died before we got here
    if args.priority and not fifo_this_thread(args.priority):
        logger.info("simulated station runs with normal scheduling: SCHED_FIFO %d not permitted "
                    "(needs CAP_SYS_NICE or an rtprio limit; simulation.station_priority 0 skips "
                    "this)", args.priority)
    stop.watch()  # the first thread: every thread from here on inherits the policy
    try:
        station.start()
    except (SsiBridgeError, OSError) as err:
        print(f"station: cannot start: {err}", file=sys.stderr)
        return 1
    bus = settings.bus
    print(f"{READY}: node {bus.node_id} with {len(station.sim.modules)} module(s) on "
          f"{bus.interface}:{bus.channel}", flush=True)
    if args.parent_pid:
        threading.Thread(target=_watch_parent, args=(args.parent_pid, stop), daemon=True).start()
    try:
        stop.event.wait()
    finally:
        station.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
