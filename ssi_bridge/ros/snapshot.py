"""The node's side of fault snapshots (``record/snapshot.py``): parameters, the ERROR trigger.

``record.snapshot.duration`` > 0 makes the node keep the last N seconds of every recorded
topic in memory (:class:`~ssi_bridge.record.snapshot.SnapshotKeeper`, fed by the session
recorder whether a session runs or not). With ``record.snapshot.on_error`` every status of
/diagnostics that goes to ERROR (a joint, the bus; checked on every DiagnosticArray the node
records, which it publishes at once when a level changes) triggers a snapshot named after
the status's item; ``~/snapshot`` triggers one on demand.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus

from ssi_bridge.record.snapshot import SnapshotConfig

#: the diagnostics level that triggers a snapshot
ERROR = DiagnosticStatus.ERROR


def snapshot_config(node: Any, record_root: str) -> SnapshotConfig | None:
    """``record.snapshot.*`` of ``node`` (declared from ros/param_table.py); None when the
    duration is 0 (no ring, no snapshots)."""
    def value(name: str) -> Any:
        return node.get_parameter(f"record.snapshot.{name}").value

    duration = float(value("duration"))
    if duration <= 0:
        return None
    return SnapshotConfig(root=Path(record_root).expanduser().absolute(),
                          duration_s=duration, after_s=float(value("after")),
                          on_error=bool(value("on_error")), max_bags=int(value("max_bags")))


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
