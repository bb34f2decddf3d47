"""The simulated parts a bus test builds a station from: a python-can virtual channel private
to one test, and an SSI line that answers with the value the test sets."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Iterator

import can
import can.interfaces.virtual as virtual

from ssi_bridge.protocol.readout import LineReadout

_channels = itertools.count()


def private_channel(prefix: str, test_name: str) -> Iterator[str]:
    """Yield a virtual channel name no other test uses (``prefix``-n-``test_name``); after
    the test, fail it if a bus was left open on that channel."""
    name = f"{prefix}-{next(_channels)}-{test_name}"
    yield name
    with virtual.channels_lock:
        leaked = len(virtual.channels.get(name, []))
    assert leaked == 0, f"{leaked} virtual bus(es) left open on {name!r}"


class ScriptedReader:
    """An SsiReader returning the encoder value the test sets, on a healthy line: ``data`` is
    ``value`` cut to the frame length, the line busy for ``n_bits + 1`` clocks."""

    def __init__(self, value: int = 0) -> None:
        self.value = value

    def read(self, t: float, n_bits: int, bit_rate_hz: float) -> LineReadout:
        return LineReadout(latch_time=t, n_bits=n_bits, data=self.value & ((1 << n_bits) - 1),
                           end_time=t + (n_bits + 1) / bit_rate_hz)


def send_syncs(bus: can.BusABC, rate: float, seconds: float, stop: threading.Event) -> int:
    """Send SYNC (0x080) at ``rate`` Hz for ``seconds`` (or until ``stop``) on ``bus``, as
    another SYNC producer would; shut ``bus`` down after. Returns how many were sent."""
    sent = 0
    try:
        start = time.monotonic()
        while not stop.is_set() and time.monotonic() - start < seconds:
            bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
            sent += 1
            time.sleep(max(0.0, start + sent / rate - time.monotonic()))
    finally:
        bus.shutdown()
    return sent
