"""``metadata.yaml`` of a rosbag2 bag directory (format version 9, as Jazzy writes it).

Shared by the recorder (written on close) and by recovery (rebuilt from the MCAP file after a
crash), so both produce the same layout: ``rosbag2_bagfile_information`` with version,
storage_identifier ``mcap``, duration, starting_time, message_count,
topics_with_message_count (type, serialization_format ``cdr``, offered_qos_profiles with the
very text of the channel metadata, type_description_hash), relative_file_paths, files,
custom_data and ros_distro. A split session lists every file in ``relative_file_paths`` and
``files`` (path, starting_time, duration, message_count), as rosbag2's SequentialWriter does.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

#: rosbag2 metadata format version written by Jazzy
METADATA_VERSION = 9
METADATA_FILE = "metadata.yaml"
ROS_DISTRO = os.environ.get("ROS_DISTRO", "jazzy")


@dataclass
class TopicInfo:
    """What metadata.yaml says about one topic."""

    #: topic name as recorded (absolute)
    name: str
    #: ``pkg/msg/Type``
    type: str
    #: the channel's ``offered_qos_profiles`` string ("" when none)
    qos_text: str = ""
    #: ``RIHS01_...`` or ""
    type_hash: str = ""
    #: messages recorded on this topic
    message_count: int = 0


@dataclass
class FileInfo:
    """One MCAP file of a bag (a ``files:`` entry): a session split by size or duration has
    ``<name>_0.mcap``, ``<name>_1.mcap``, ... in the order they were written."""

    #: file name relative to the bag directory
    path: str
    #: earliest and latest log time in this file (ns since epoch); 0 when empty
    start_ns: int = 0
    end_ns: int = 0
    message_count: int = 0

    @property
    def duration_ns(self) -> int:
        """Log-time span of this file (ns)."""
        return max(0, self.end_ns - self.start_ns)

    def add(self, log_time_ns: int, count: int = 1) -> None:
        """Account ``count`` messages logged at ``log_time_ns``."""
        if self.message_count == 0 or log_time_ns < self.start_ns:
            self.start_ns = log_time_ns
        self.end_ns = max(self.end_ns, log_time_ns)
        self.message_count += count


@dataclass
class BagInfo:
    """Everything metadata.yaml holds for an MCAP bag of one or more files."""

    #: the bag's files in writing order
    files: list[FileInfo] = field(default_factory=list)
    topics: list[TopicInfo] = field(default_factory=list)
    #: earliest and latest log time (ns since epoch); 0 when empty
    start_ns: int = 0
    end_ns: int = 0
    #: free key/value pairs (rosbag2 ``custom_data``): the session configuration
    custom_data: dict[str, str] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        """Messages in the bag."""
        return sum(t.message_count for t in self.topics)

    @property
    def duration_ns(self) -> int:
        """Log-time span of the bag (ns)."""
        return max(0, self.end_ns - self.start_ns)



@dataclass(frozen=True)
class BagSummary:
    """Result of :meth:`BagRecorder.close`."""

    directory: Path
    message_count: int
    #: log-time span of the recorded messages (s)
    duration: float
    topics: dict[str, int] = field(default_factory=dict)
    #: the bag's MCAP files (relative names) in writing order
    files: tuple[str, ...] = ()

def file_name(bag_name: str, index: int) -> str:
    """rosbag2's name of the ``index``-th file of bag directory ``bag_name``: ``<name>_<i>.mcap``."""
    return f"{bag_name}_{index}.mcap"


def file_index(bag_name: str, name: str) -> int | None:
    """The index ``i`` of a file named ``<bag_name>_<i>.mcap``, else None.

    :param bag_name: the bag directory's name
    :param name: a file name
    """
    prefix, suffix = f"{bag_name}_", ".mcap"
    if not (name.startswith(prefix) and name.endswith(suffix)):
        return None
    digits = name[len(prefix):-len(suffix)]
    return int(digits) if digits.isdigit() else None


def _topic_entry(topic: TopicInfo) -> dict[str, Any]:
    """One ``topics_with_message_count`` item."""
    qos = yaml.safe_load(topic.qos_text) if topic.qos_text else []
    return {
        "topic_metadata": {
            "name": topic.name,
            "type": topic.type,
            "serialization_format": "cdr",
            "offered_qos_profiles": qos,
            "type_description_hash": topic.type_hash,
        },
        "message_count": topic.message_count,
    }


def metadata_dict(info: BagInfo) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping, keys in rosbag2's order.

    :param info: the bag as known now
    """
    duration = {"nanoseconds": info.duration_ns}
    start = {"nanoseconds_since_epoch": info.start_ns}
    return {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": duration,
        "starting_time": start,
        "message_count": info.message_count,
        "topics_with_message_count": [_topic_entry(t) for t in info.topics],
        # rosbag2's own (file/message) compression; MCAP chunk compression is internal
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f.path for f in info.files],
        "files": [{"path": f.path, "starting_time": {"nanoseconds_since_epoch": f.start_ns},
                   "duration": {"nanoseconds": f.duration_ns},
                   "message_count": f.message_count} for f in info.files],
        "custom_data": dict(info.custom_data) or None,
        "ros_distro": ROS_DISTRO,
    }


def metadata_text(info: BagInfo) -> str:
    """The YAML text of metadata.yaml.

    PyYAML writes the QoS list in the same block style as :func:`qos.qos_text`, so each
    topic's ``offered_qos_profiles`` lines are the channel string's lines, indented.

    :param info: the bag as known now
    """
    return yaml.safe_dump({"rosbag2_bagfile_information": metadata_dict(info)},
                          sort_keys=False, default_flow_style=False)


def write_metadata(directory: Path, info: BagInfo) -> Path:
    """Write ``directory/metadata.yaml`` atomically (temp file + rename) and return its path.

    :param directory: the bag directory
    :param info: the bag as known now
    """
    target = directory / METADATA_FILE
    tmp = directory / f".{METADATA_FILE}.tmp"
    tmp.write_text(metadata_text(info), encoding="utf-8")
    os.replace(tmp, target)
    return target


def read_metadata(directory: Path) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of a bag directory (ValueError if bad)."""
    data = yaml.safe_load((directory / METADATA_FILE).read_text(encoding="utf-8"))
    if not isinstance(data, dict) or "rosbag2_bagfile_information" not in data:
        raise ValueError("no 'rosbag2_bagfile_information' mapping")
    info: dict[str, Any] = data["rosbag2_bagfile_information"]
    return info
