"""When a recording moves on to its next file: rosbag2's ``--max-bag-size`` and
``--max-bag-duration`` rule.

Checked before each message is written: the open file is closed when it already holds
``max_size`` bytes or more, or when the message comes more than ``max_duration_s`` after the
file's first message (0 disables either). An empty file is never closed, so every file holds
at least one message.
"""

from __future__ import annotations

from dataclasses import dataclass

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.metadata import FileInfo

#: smallest accepted ``max_size``: a file must hold its header, schemas and a chunk or two
MIN_SPLIT_SIZE = 64 * 1024


@dataclass(frozen=True)
class SplitPolicy:
    """When a session moves on to its next file (rosbag2 ``--max-bag-size/-duration``)."""

    #: bytes; 0 = no split by size
    max_size: int = 0
    #: seconds of log time; 0 = no split by duration
    max_duration_s: float = 0.0

    def __post_init__(self) -> None:
        if self.max_size < 0 or 0 < self.max_size < MIN_SPLIT_SIZE:
            raise RecordingError(f"max_size {self.max_size}: 0 (no split) or at least "
                                 f"{MIN_SPLIT_SIZE} bytes")
        if self.max_duration_s < 0:
            raise RecordingError(f"max_duration {self.max_duration_s}: 0 (no split) or > 0 s")

    def due(self, file: FileInfo, size: int, log_time_ns: int) -> bool:
        """True when the file (``size`` bytes so far) must close before this message.

        :param file: the open file's counts (first message time)
        :param size: its bytes so far
        :param log_time_ns: the next message's log time (ns)
        """
        if file.message_count == 0:
            return False
        if self.max_size and size >= self.max_size:
            return True
        return bool(self.max_duration_s) and (
            log_time_ns - file.start_ns > int(self.max_duration_s * 1e9))
