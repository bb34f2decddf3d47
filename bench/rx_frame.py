"""CPU of one received frame on the master's receive path, apart from the node (micro-benchmark).

``python bench/rx_frame.py [frames] [rounds]``: on a udp_multicast channel of its own (loopback),
a second bus sends ``frames`` TPDOs of an 8-slot station (images and position pairs, changing
payloads) in one burst, then the master's bus stack as the node builds it
(``ReceiveWatch(ReopeningBus(UdpCanBus))``) receives them all from its queue, each one handed
to the master's listener (``FrameListener`` with a ``BusLoad``, the TPDO routes and a
``SlotTable``). Prints the thread CPU per frame (us, median of ``rounds``) of:

* ``recv``: ``bus.recv`` returning a waiting frame (no wait: the frames are queued);
* ``listener``: ``on_message_received`` of that frame;
* ``load``: the bus-load meter's count of the frame, which the receive thread only queues and
  the cycle thread counts once its cycle is over (``BusLoad.count_queued``, timed here with the
  ``BusLoad.add`` of the next SYNC at every 12th frame, an 8-slot cycle; per frame);
* ``send``: ``bus.send`` of a SYNC through the same stack (the cycle thread's send).

Numbers go to docs/node.md, "Performance".
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import can

from ssi_bridge.base.udp_bus import derive_channel, open_udp_bus
from ssi_bridge.client.bus import MasterNetwork, ReceiveWatch
from ssi_bridge.client.link import ReopeningBus
from ssi_bridge.client.load import BusLoad
from ssi_bridge.client.receive import FrameListener, TpdoRoutes
from ssi_bridge.client.samples import ClientCounters, SlotTable

NODE, SLOTS = 1, 8


def _frames(n: int) -> list[can.Message]:
    """``n`` TPDOs of an 8-slot station in cycle order, payloads changing every cycle."""
    routes = TpdoRoutes(NODE, SLOTS, lambda *a: None, lambda *a: None).pdo_numbers
    cobs = sorted(routes, key=lambda c: routes[c])
    out = []
    for i in range(n):
        cob = cobs[i % len(cobs)]
        k = i // len(cobs)
        data = (k * 7919 + cob).to_bytes(4, "little") * 2
        out.append(can.Message(arbitration_id=cob, data=data, is_extended_id=False,
                               timestamp=time.time()))
    return out


def _round(tx: can.BusABC, rx: can.BusABC, listener: FrameListener, table: SlotTable,
           load: BusLoad, frames: list[can.Message]) -> tuple[float, float, float, float]:
    for msg in frames:
        msg.timestamp = time.time()
        tx.send(msg)
    time.sleep(0.05)  # all in the receive queue
    recv_ns = listen_ns = load_ns = 0
    got = 0
    clock = time.thread_time_ns
    sync = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False)
    for i in range(len(frames)):
        if i % 12 == 0:
            table.on_sync()
            c0 = clock()
            load.count_queued()
            load.add(sync)
            load_ns += clock() - c0
        c0 = clock()
        msg = rx.recv(1.0)
        c1 = clock()
        if msg is None:
            break
        listener.on_message_received(msg)
        c2 = clock()
        recv_ns += c1 - c0
        listen_ns += c2 - c1
        got += 1
    c0 = clock()
    for _ in range(200):
        rx.send(sync)
    send_ns = (clock() - c0) / 200
    time.sleep(0.02)
    for bus in (tx, rx):  # the SYNCs (rx drops its own ones unseen)
        while bus.recv(0.0) is not None:
            pass
    load.figures()  # the window emptied of this round's frames
    per = 1e3 * max(got, 1)
    return recv_ns / per, listen_ns / per, send_ns / 1e3, load_ns / per


def main(argv: list[str]) -> int:
    n = int(argv[0]) if argv else 2400
    rounds = int(argv[1]) if len(argv) > 1 else 7
    channel = derive_channel(f"rx_frame_{os.getpid()}")
    tx = open_udp_bus(channel)
    inner = open_udp_bus(channel)
    rx = ReceiveWatch(ReopeningBus(inner, lambda: open_udp_bus(channel), channel))
    network = MasterNetwork(None)
    counters = ClientCounters()
    load = BusLoad(1_000_000)
    listener = FrameListener(network, counters, load)
    table = SlotTable(SLOTS)
    TpdoRoutes(NODE, SLOTS, table.on_image, table.on_positions).attach(network)
    frames = _frames(n)
    results = []
    try:
        for _ in range(rounds):
            results.append(_round(tx, rx, listener, table, load, frames))
    finally:
        tx.shutdown()
        rx.shutdown()
    recv, listen, send, counted = (statistics.median(r[i] for r in results) for i in range(4))
    print(f"{n} frames x {rounds} rounds, thread CPU per frame (us, median): recv {recv:.1f}, "
          f"listener {listen:.1f}, recv+listener {recv + listen:.1f}; load {counted:.1f} (at the"
          f" SYNCs); send of a SYNC {send:.1f} ({counters.frames} frames counted)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
