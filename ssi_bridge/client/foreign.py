"""Frames on the master's own identifiers that the master did not send.

CiA 301 has one SYNC producer (COB-ID 0x080) and one NMT master (COB-ID 0x000) per network.
The master never receives its own frames (python-can buses do not echo them by default, the
CAN-over-UDP bus filters them), so every SYNC or NMT command it receives is another node's:

* a SYNC from another producer is counted (``foreign_syncs``), logged at most once per
  second, and handed to the master's slot tables, which then take no TPDO that followed it
  on the wire for the master's own cycle (``foreign_sync_answers``): the station latched
  those at the other producer's SYNC, and stamping them with the master's SYNC time would
  break the velocity estimate;
* an NMT command is counted (``foreign_nmt_commands``) and logged at most once per second,
  naming the command and the node it addressed; the liveness supervisor starts a station it
  stopped again (``client/liveness.py``).
* an SDO request to one of the master's stations (COB-ID 0x600 + node id, CiA 301
  pre-defined connection set; no PDO of any node can use it) is another master's or a
  tool's: counted (``foreign_station_frames``) and logged at most once per second, naming
  the COB-ID. RPDOs are not watched: XI/ON's PDO5-12 identifiers of one node id are the
  PDO1-4 identifiers of another (000 Table 15), so a station's TPDO could look like one.

Before the master sends anything, :func:`ensure_alone` (``client/one_master.py``) listens
for the same frames: a bus that another master already drives is a start-up error naming
what it sent.

:meth:`ForeignTraffic.recent` says what was seen within a window, for a WARN of the bus
diagnostics.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.protocol.dictionary import (
    NMT_COB_ID, NMT_ENTER_PRE_OPERATIONAL, NMT_RESET_COMMUNICATION, NMT_RESET_NODE, NMT_START,
    NMT_STOP, SYNC_COB_ID,
)

logger = logging.getLogger(__name__)

#: ClientCounters fields this module counts
FOREIGN_SYNCS = "foreign_syncs"
FOREIGN_NMT = "foreign_nmt_commands"
FOREIGN_STATION = "foreign_station_frames"
#: CiA 301 pre-defined connection set: SDO requests (client to server) on 0x600 + node id
SDO_REQUEST_BASE = 0x600
#: CiA 301 §7.2.8.3.1 command specifiers, for the log and the diagnostics
NMT_COMMAND_NAMES = {NMT_START: "start", NMT_STOP: "stop",
                     NMT_ENTER_PRE_OPERATIONAL: "enter PRE-OPERATIONAL",
                     NMT_RESET_NODE: "reset node", NMT_RESET_COMMUNICATION: "reset communication"}


def describe_nmt(data: bytes) -> str:
    """An NMT frame's payload in words: "NMT stop (0x02) to node 1", "... to all nodes".

    :param data: the NMT frame's 2 data bytes (command, node id)
    """
    if len(data) < 2:
        return f"NMT frame [{data.hex(' ')}] (not 2 bytes)"
    command, node = data[0], data[1]
    name = NMT_COMMAND_NAMES.get(command, "unknown command")
    target = "all nodes" if node == 0 else f"node {node}"
    return f"NMT {name} (0x{command:02X}) to {target}"


def station_frames(node_id: int) -> dict[int, str]:
    """COB-IDs only the master of station ``node_id`` sends to it, and what each is."""
    return {SDO_REQUEST_BASE + node_id: f"SDO request to node {node_id}"}


def master_frames(station_ids: tuple[int, ...] | list[int] = ()) -> dict[int, str]:
    """COB-IDs only the master of these stations sends (SYNC, NMT, SDO requests).

    :param station_ids: the node ids of the master's stations (SDO requests to them)
    :returns: COB-ID -> name of the service ("SYNC", "NMT", "SDO request to node 1")
    """
    frames = {SYNC_COB_ID: "SYNC", NMT_COB_ID: "NMT command"}
    for node_id in station_ids:
        frames.update(station_frames(node_id))
    return frames


def describe_frame(can_id: int, data: bytes, frames: dict[int, str]) -> str:
    """A frame of :func:`master_frames` in words with its COB-ID ("SYNC on 0x080", "NMT stop
    (0x02) to node 1 on 0x000", "SDO request to node 1 on 0x601").

    :param can_id: the frame's COB-ID
    :param data: its data bytes
    :param frames: the master's COB-IDs and their names (:func:`master_frames`)
    """
    if can_id == NMT_COB_ID:
        return f"{describe_nmt(data)} on 0x000"
    return f"{frames.get(can_id, 'frame')} on 0x{can_id:03X}"


class ForeignTraffic:
    """SYNC, NMT and SDO request frames of other nodes the master's receive path handed over.

    :param count: counts one event of a ClientCounters field in every counter set
    :param on_sync: called with the wire time of another producer's SYNC (the slot tables)
    :param clock: the clock of :meth:`recent`'s window (monotonic: an interval, not a stamp)
    """

    def __init__(self, count: Callable[[str], None],
                 on_sync: Callable[[float], None] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._count = count
        self.on_sync = on_sync
        self._clock = clock
        self._log = RateLimitedLog(logger)
        self._lock = threading.Lock()
        #: what was seen last of each kind: (``clock`` time it was handled, words)
        self.last: dict[str, tuple[float, str]] = {}
        #: the COB-IDs only this master sends (its stations' added by :meth:`watch`)
        self.frames = master_frames()
        self.ids = frozenset(self.frames)

    def watch(self, node_id: int) -> None:
        """Watch the SDO requests to station ``node_id`` too (it is attached)."""
        self.frames = {**self.frames, **station_frames(node_id)}
        self.ids = frozenset(self.frames)

    def observe(self, can_id: int, data: bytes | bytearray, wire_t: float) -> None:
        """A received frame on one of :attr:`ids` (receive thread); others are ignored.

        :param can_id: the frame's identifier
        :param data: its data bytes
        :param wire_t: its wire time (s)
        """
        if can_id == SYNC_COB_ID:
            self._count(FOREIGN_SYNCS)
            if self.on_sync is not None:
                self.on_sync(wire_t)
            words = "SYNC on 0x080 from another producer (CiA 301: one per network)"
            kind = FOREIGN_SYNCS
        elif can_id == NMT_COB_ID:
            self._count(FOREIGN_NMT)
            words = f"{describe_nmt(bytes(data))} not sent by this master"
            kind = FOREIGN_NMT
        elif can_id in self.ids:
            self._count(FOREIGN_STATION)
            words = (f"{describe_frame(can_id, bytes(data), self.frames)} not sent by this "
                     "master (another master or a tool)")
            kind = FOREIGN_STATION
        else:
            return
        with self._lock:
            self.last[kind] = (self._clock(), words)
        self._log.warning(kind, "%s", words)

    def recent(self, window: float, now: float | None = None) -> str:
        """What was seen within the last ``window`` s ("" if nothing), for a bus WARN;
        ``now`` on the ``clock`` (default: now)."""
        now = self._clock() if now is None else now
        with self._lock:
            seen = [words for t, words in self.last.values() if now - t <= window]
        return "; ".join(sorted(seen))


__all__ = ["FOREIGN_NMT", "FOREIGN_STATION", "FOREIGN_SYNCS", "ForeignTraffic",
           "NMT_COMMAND_NAMES", "describe_frame", "describe_nmt", "master_frames",
           "station_frames"]
