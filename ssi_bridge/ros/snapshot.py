"""The node's side of fault snapshots (``record/snapshot.py``): parameters, the ERROR trigger.

``record.snapshot.duration`` > 0 makes the node keep the last N seconds of every recorded
topic in memory (:class:`~ssi_bridge.record.snapshot.SnapshotKeeper`, fed by the session
recorder whether a session runs or not). With ``record.snapshot.on_error`` every status of
/diagnostics that goes to ERROR (a joint, the bus; checked on every DiagnosticArray the node
records, which it publishes at once when a level changes) triggers a snapshot named after
the status's item; ``~/snapshot`` triggers one on demand. With ``record.can_log`` a
:class:`FrameTap` (a bus of its own, as the session's CAN log has) keeps the raw CAN frames in
a second ring of the same duration. :class:`NodeSnapshots` ties these together for the
session recorder (``ros/recording.py``), which feeds it every message it records.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import can
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from rclpy.qos import QoSProfile

from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.base.rx_guard import ERROR_PAUSE, RECEIVE_ERROR, receive_error_kind
from ssi_bridge.base.timebase import frame_wire_time, to_ros_ns
from ssi_bridge.client.bus import open_bus
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.record.can_frames import pack_frame
from ssi_bridge.record.snapshot import SnapshotConfig, SnapshotKeeper
from ssi_bridge.ros.params import NodeSettings
from ssi_bridge.ros.rclpy_compat import RcutilsLogger
from ssi_bridge.ros.recording_meta import bus_config, session_metadata, type_of

logger = logging.getLogger(__name__)

#: the diagnostics level that triggers a snapshot
ERROR = DiagnosticStatus.ERROR


def snapshot_config(node: Node, record_root: str, can_log: bool = False
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

    def new_errors(self, msg: Any) -> list[str]:  # diagnostic_msgs ships no type hints
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


class NodeSnapshots:
    """The fault snapshots of a node: the ring of every message the recorder keeps (and with
    ``record.can_log`` the frames' ring), written on ERROR or on request.

    :param keeper: the rings and the snapshot writer
    :param bus: the node's bus (the frames' ring listens on a bus of its own)
    :param log: the node's logger
    """

    def __init__(self, keeper: SnapshotKeeper, bus: BusConfig, log: RcutilsLogger) -> None:
        self.keeper = keeper
        self._bus = bus
        self._log = log
        self._errors = ErrorWatch()
        self._frame_tap: FrameTap | None = None

    def keep(self, topic: str, msg: Any, data: bytes, now_ns: int, stamp_ns: int) -> None:
        """One recorded message (``data``: its CDR) into the ring; a status of /diagnostics
        newly at ERROR triggers a snapshot (``record.snapshot.on_error``).

        :raises RecordingError: the snapshot cannot be started
        :raises OSError: the snapshot's file cannot be written
        """
        keeper = self.keeper
        keeper.add(topic, data, now_ns, stamp_ns)
        if topic == "/diagnostics" and keeper.config.on_error:
            for item in self._errors.new_errors(msg):
                path, extended = keeper.trigger(item, now_ns)
                self._log.warning(f"{item} reached ERROR: snapshot {path.name} "
                                  + ("extended" if extended else "started"))

    def on_request(self) -> str:
        """``~/snapshot``: write the ring now (or extend the snapshot running); what was done.

        :raises RecordingError: the snapshot cannot be started
        """
        path, extended = self.keeper.trigger("request")
        self._log.info(f"snapshot on request: {path}" + (" (extended)" if extended else ""))
        return f"{'extended' if extended else 'writing'} {path}"

    def open_frame_tap(self) -> None:
        """With ``record.can_log``: listen on the node's bus for the frames' ring (each
        configure; nothing when already listening).

        :raises BusError: the bus cannot be opened (the messages' ring goes on)
        """
        if self.keeper.config.can_log and self._frame_tap is None:
            self._frame_tap = FrameTap(self._bus, self.keeper)

    def close_frame_tap(self) -> None:
        """Stop listening on the bus (cleanup closes the bus side; the ring keeps its frames)."""
        if (tap := self._frame_tap) is not None:
            self._frame_tap = None
            tap.close()

    def counters(self) -> dict[str, int | str]:
        """The snapshots' figures for the bus diagnostics."""
        return self.keeper.counters()

    def close(self) -> None:
        """The node ends: stop listening, finish the snapshot being written."""
        self.close_frame_tap()
        self.keeper.close()


def node_snapshots(node: Node, settings: NodeSettings,
                   qos: Mapping[str, QoSProfile]) -> NodeSnapshots | None:
    """The fault snapshots of ``node`` when ``record.snapshot.duration`` > 0, else None.

    :param qos: each recorded topic's offered QoS (read when a snapshot adds the topic)
    """
    from ssi_bridge.record.bag import BagRecorder

    s = settings
    config = snapshot_config(node, s.record_root, s.record_can_log)
    if config is None:
        return None

    def open_bag(path: Path) -> BagRecorder:
        meta = {**session_metadata(s), "snapshot": path.name}
        return BagRecorder.open(path, compression=s.record_compression, metadata=meta)

    clock = node.get_clock()
    keeper = SnapshotKeeper(config, open_bag, lambda t: (type_of(t), qos.get(t)),
                            clock_ns=lambda: clock.now().nanoseconds, log=node.get_logger())
    return NodeSnapshots(keeper, bus_config(s), node.get_logger())
