"""The node's side of fault snapshots (``record/snapshot.py``): parameters, the ERROR trigger.

``record.snapshot.duration`` > 0 makes the node keep the last N seconds of every recorded
topic in memory (:class:`~ssi_bridge.record.snapshot.SnapshotKeeper`, fed by the session
recorder whether a session runs or not). With ``record.snapshot.on_error`` every status of
/diagnostics that goes to ERROR (a joint, the bus; checked on every DiagnosticArray the node
records, which it publishes at once when a level changes) triggers a snapshot named after
the status's item; ``~/snapshot`` triggers one on demand. With ``record.can_log`` a
:class:`FrameTap` (a bus of its own, as the session's CAN log has) keeps the raw CAN frames in
a second ring of the same duration.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import can
from diagnostic_msgs.msg import DiagnosticStatus

from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.base.rx_guard import ERROR_PAUSE, RECEIVE_ERROR, receive_error_kind
from ssi_bridge.base.timebase import frame_wire_time, to_ros_ns
from ssi_bridge.client.bus import open_bus
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.record.can_frames import pack_frame
from ssi_bridge.record.snapshot import SnapshotConfig, SnapshotKeeper

logger = logging.getLogger(__name__)

#: the diagnostics level that triggers a snapshot
ERROR = DiagnosticStatus.ERROR


def snapshot_config(node: Any, record_root: str, can_log: bool = False
                    ) -> SnapshotConfig | None:
    """``record.snapshot.*`` of ``node`` (declared from ros/param_table.py); None when the
    duration is 0 (no ring, no snapshots). ``can_log``: keep the CAN frames too."""
    def value(name: str) -> Any:
        return node.get_parameter(f"record.snapshot.{name}").value

    duration = float(value("duration"))
    if duration <= 0:
        return None
    return SnapshotConfig(root=Path(record_root).expanduser().absolute(),
                          duration_s=duration, after_s=float(value("after")),
                          on_error=bool(value("on_error")), max_bags=int(value("max_bags")),
                          can_log=can_log)


def item_of(status_name: str) -> str:
    """The item of a status name ``<node FQN>: <item>`` (a joint, ``bus``, ``station 3``)."""
    return status_name.rpartition(": ")[2] or status_name


class ErrorWatch:
    """Which statuses of a DiagnosticArray went to ERROR since the previous one."""

    def __init__(self) -> None:
        self._in_error: set[str] = set()

    def new_errors(self, msg: Any) -> list[str]:
        """The items (joint names, ``bus``) whose status is ERROR now and was not before."""
        now = [st.name for st in msg.status if st.level == ERROR]
        new = [item_of(name) for name in now if name not in self._in_error]
        self._in_error = set(now)
        return new


class FrameTap(can.Listener):
    """Every frame of the bus into the keeper's frame ring, from a bus of its own (both
    directions, as ``client/sniffer.py`` logs a session). A receive error is counted and
    logged at most once a second; the tap goes on.

    :raises BusError: the bus cannot be opened
    """

    def __init__(self, config: BusConfig, keeper: SnapshotKeeper) -> None:
        self._keeper = keeper
        self.errors = 0
        self._log = RateLimitedLog(logger)
        self._bus = open_bus(config)
        self._notifier = can.Notifier(self._bus, [self], timeout=0.1)

    def on_message_received(self, msg: can.Message) -> None:
        t = frame_wire_time(msg)
        self._keeper.add_frame(to_ros_ns(t), pack_frame(msg, t))

    def on_error(self, exc: Exception) -> None:
        kind = receive_error_kind(exc)
        self.errors += 1
        self._log.warning(kind, "snapshot CAN ring: receive error (%s), goes on: %s", kind, exc)
        if kind == RECEIVE_ERROR:
            time.sleep(ERROR_PAUSE)

    def close(self) -> None:
        """Stop receiving and close the bus."""
        self._notifier.stop()
        self._bus.shutdown()
