"""The master's side of the cycle core: where a client's frames go, and its SYNC count.

The node wires each station's client to its frame log (``core/cycle_log.StationLog``, a
:class:`~ssi_bridge.client.frame_sink.FrameSink`) and asks which number its SYNC had, through
these two calls, so that nothing outside ``client/`` reaches into a client's slot table.
"""

from __future__ import annotations

from typing import Protocol

from ssi_bridge.client.frame_sink import FrameSink
from ssi_bridge.client.samples import SlotTable


class Tabled(Protocol):
    """A master or listen-only client: it keeps its slots in a :class:`SlotTable`."""

    @property
    def table(self) -> SlotTable:
        """The client's slot table."""


def feed_frames(client: Tabled, sink: FrameSink | None) -> None:
    """Hand every SYNC and TPDO ``client`` sees to ``sink`` from now on (None: to nobody)."""
    client.table.sink = sink


def sync_number(client: Tabled, t: float) -> int:
    """The number of the SYNC ``client`` recorded at wire time ``t`` (what its ``sync()``
    returned): not the newest one, which a register handshake's own SYNC, sent from another
    thread meanwhile, may be (its sample is not latched at ``t``)."""
    return client.table.seq_at(t)


__all__ = ["Tabled", "feed_frames", "sync_number"]
