"""The node benchmark's I/O floor: a program of its own (this file, run by the benchmark with
:func:`io_floor_cmd`) that does the real driver's bus I/O and nothing else.

The driver as deployed (``simulation.enabled:=false`` on ``udp_multicast``, the station a
separate process) sends one SYNC datagram a cycle and receives the cycle's TPDOs, one datagram
each, spaced at their CAN wire time. Any driver on this bus pays for that I/O: a multicast
``sendto`` whose loop-back delivery to the station's socket the kernel charges to the sender,
and a wake-up of the receive thread per TPDO. The bare publisher does no I/O and the floor
publisher receives one datagram a cycle, so neither shows it.

* ``--io-floor N RATE TOPIC [SPAN_FILE]``: an rclpy node whose paced thread
  (``io_floor_sync``, SCHED_FIFO at :data:`FLOOR_PRIORITY`, the node's default
  ``cycle_priority``, where permitted) sends a SYNC-sized datagram to its multicast group
  ``RATE`` times a second; its receive thread (``io_floor_rx``, same priority, as the node's
  CAN receive thread) receives every datagram with ``recvmsg`` and ``SO_TIMESTAMPNS``, and
  on the cycle's last TPDO fills and publishes an N-joint JointState stamped with the SYNC's
  send time, and writes its span (kernel receive time of that TPDO -> ``publish()``
  returned) to the span file as the node's span probe does (``ssi_bridge/ros/span_probe.py``).
* ``--io-station CHANNEL N``: the station, started by the I/O floor (it dies with it): waits
  for each SYNC and sends the cycle's frames (``wire.cycle_payloads(N)[1:]``: N process
  images and the position PDOs, 2 frames for 1 joint, 12 for 8), each one
  python-can udp_multicast datagram of its payload size, each sent when its worst-case
  stuffed frame at :data:`~node_cases.BITRATE` would have ended on the wire (frame after
  frame from the SYNC's arrival or the previous frame's end, whichever is later, sleeping
  until then, as the simulated station's wire paces them), its thread SCHED_FIFO at
  :data:`STATION_PRIORITY` where permitted, as the ``station`` program's.

Both ends open the bus as the driver and the station do (``base/udp_bus.UdpCanBus``: the group
joined on 127.0.0.1, multicast loop-back on, a sender's own datagrams dropped by a kernel
socket filter), so the kernel does the same work; neither decodes a frame.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from node_baselines import FLOOR_PRIORITY, _joint_state, _joint_state_publisher
from node_cases import BITRATE, case_rate
from node_procs import die_with_parent

IO_FLOOR_TOPIC = "/bench_io_floor/joint_states"
#: the station's priority (SCHED_FIFO where permitted): the ``station`` program's default
STATION_PRIORITY = 10
#: CANopen's SYNC COB-ID, and the COB-ID of the first TPDO the station sends
SYNC_ID, FIRST_TPDO_ID = 0x080, 0x181
PROGRAM = Path(__file__).resolve()


def io_floor_cmd(n_joints: int, spans: Path | None = None) -> list[str]:
    """The I/O floor's command line for the ``n_joints`` case, on :data:`IO_FLOOR_TOPIC`;
    ``spans``: the file it writes its spans to."""
    return [sys.executable, str(PROGRAM), "--io-floor", str(n_joints),
            str(case_rate(n_joints)), IO_FLOOR_TOPIC] + ([str(spans)] if spans else [])


def cycle_frames(n_joints: int) -> list[tuple[bytes, float]]:
    """The station's datagrams of one cycle of ``n_joints`` slots, each with its wire time
    (s): python-can udp_multicast datagrams of the cycle's payload sizes
    (``wire.cycle_payloads``), every one different (the last one marks the cycle's end)."""
    import can

    from ssi_bridge.base.udp_bus import pack_frame
    from ssi_bridge.protocol import wire

    return [(pack_frame(can.Message(arbitration_id=FIRST_TPDO_ID + i, is_extended_id=False,
                                    data=bytes([i]) * size, timestamp=0.0)),
             wire.worst_frame_bits(size) / BITRATE)
            for i, size in enumerate(wire.cycle_payloads(n_joints)[1:])]


def _receiver(sockets: Any) -> Any:
    """A function that returns the next datagram of another sender on the bus's receive
    socket and its kernel receive time (ns): ``recvmsg`` with ``SO_TIMESTAMPNS`` as the
    bus receives; the bus's own datagrams dropped where its kernel filter did not."""
    import socket
    import struct

    from ssi_bridge.base.can_compat import SO_TIMESTAMPNS

    sock, own = sockets.receive_socket, sockets.own_address
    size, ancillary = sockets.max_buffer, sockets.received_ancillary_buffer_size
    check_own = not sockets.kernel_drops_own
    timespec = struct.Struct("@ll").unpack

    def receive() -> tuple[bytes, int]:
        while True:
            data, anc, _, sender = sock.recvmsg(size, ancillary)
            if check_own and sender[:2] == own:
                continue
            for level, kind, raw in anc:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                    sec, nsec = timespec(raw[:16])
                    return data, sec * 1_000_000_000 + nsec
            return data, 0
    return receive


def _open_bus(channel: str) -> Any:
    """The bus the driver and the station open on ``channel`` (its sockets are used raw)."""
    from ssi_bridge.base.udp_bus import UdpCanBus
    return UdpCanBus(channel)


def io_station(channel: str, n_joints: int) -> int:
    """Answer every SYNC on ``channel`` with the cycle's frames (:func:`cycle_frames`), each
    sent when its frame would have ended on the wire; runs until killed (it dies with its
    parent, the I/O floor)."""
    from ssi_bridge.base.realtime import run_this_thread_at

    run_this_thread_at("io_station", STATION_PRIORITY)
    bus = _open_bus(channel)
    receive, frames = _receiver(bus.sockets), cycle_frames(n_joints)
    send, group = bus.sockets.send_socket.sendto, (bus.endpoint.group, bus.endpoint.port)
    due = 0.0  # when the wire is free: the end of the last frame sent
    try:
        while True:
            receive()  # a SYNC: only the I/O floor sends to the group
            due = max(due, time.monotonic())
            for data, wire_s in frames:
                due += wire_s
                wait = due - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                send(data, group)
    except KeyboardInterrupt:  # a SIGINT to the process group: stop quietly
        return 0


def io_floor(n_joints: int, rate: float, topic: str, span_log: str = "") -> int:
    """The driver's bus I/O and publishing, nothing else (module docstring); runs until
    SIGINT. ``span_log``: the span file (records as ``ros/span_probe.py`` writes them)."""
    import can

    from ssi_bridge.base.realtime import run_this_thread_at
    from ssi_bridge.base.udp_bus import derive_channel, pack_frame
    from ssi_bridge.ros.span_probe import SpanProbe
    from ssi_bridge.tools.spin import spin_until_shutdown

    node, pub = _joint_state_publisher("io_floor", topic)
    names = [f"j{i + 1}" for i in range(n_joints)]
    probe = SpanProbe(span_log) if span_log else None
    bus = _open_bus(derive_channel(f"bench_io_floor_{os.getpid()}"))
    station = subprocess.Popen([sys.executable, str(PROGRAM), "--io-station",
                                bus.endpoint.channel, str(n_joints)],
                               preexec_fn=die_with_parent)
    sync = pack_frame(can.Message(arbitration_id=SYNC_ID, is_extended_id=False, data=b"",
                                  timestamp=0.0))
    last = cycle_frames(n_joints)[-1][0]
    sync_ns = [0]

    def pace() -> None:
        run_this_thread_at("io_floor_sync", FLOOR_PRIORITY)
        send, group = bus.sockets.send_socket.sendto, (bus.endpoint.group, bus.endpoint.port)
        period, due = 1.0 / rate, time.monotonic()
        while True:
            due += period
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            sync_ns[0] = time.time_ns()
            send(sync, group)

    def receive() -> None:
        run_this_thread_at("io_floor_rx", FLOOR_PRIORITY)
        next_datagram, count = _receiver(bus.sockets), 0
        while True:
            data, received_ns = next_datagram()
            if data != last:
                continue
            count += 1
            pub.publish(_joint_state(names, count, *divmod(sync_ns[0], 1_000_000_000)))
            if probe is not None:
                probe.published(received_ns / 1e9, n_joints)

    threading.Thread(target=receive, name="io_floor_rx", daemon=True).start()
    threading.Thread(target=pace, name="io_floor_sync", daemon=True).start()
    try:
        spin_until_shutdown(node)
    finally:
        station.kill()
        station.wait(5)
    return 0


def main(argv: list[str]) -> int:
    """``--io-floor N RATE TOPIC [SPAN_FILE]`` or ``--io-station CHANNEL N``; anything else
    is a usage error (exit status 2)."""
    if len(argv) in (4, 5) and argv[0] == "--io-floor":
        return io_floor(int(argv[1]), float(argv[2]), argv[3], *argv[4:])
    if len(argv) == 3 and argv[0] == "--io-station":
        return io_station(argv[1], int(argv[2]))
    print(f"usage: {PROGRAM.name} --io-floor N RATE TOPIC [SPAN_FILE] | "
          "--io-station CHANNEL N", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
