"""Choose and create the directory of a new recording session under the recording root.

The ``~/start_recording`` service takes an optional path from a remote caller, so it is
confined to the root: an absolute path or ``..`` that leaves the root, a name that already
exists, and a root the node cannot write are each refused with their own message, which
the node passes unchanged into the service response.
"""

from __future__ import annotations

import os
from datetime import datetime
from pathlib import Path

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.metadata import file_name

#: bytes of a file name on Linux file systems (ext4, xfs, tmpfs: NAME_MAX)
NAME_MAX = 255
#: rosbag2's default bag name pattern (``rosbag2_YYYY_MM_DD-HH_MM_SS``), with our prefix
NAME_FORMAT = "ssi_bridge_%Y_%m_%d-%H_%M_%S"


def timestamped_name(now: datetime | None = None) -> str:
    """A bag directory name from the local time, like rosbag2's default.

    :param now: the time (default: now)
    """
    return (now or datetime.now()).strftime(NAME_FORMAT)


def resolve_bag_path(root: Path, requested: str, *, now: datetime | None = None) -> Path:
    """Return the absolute bag directory for ``requested`` (empty: timestamped) under ``root``.

    Raises :class:`RecordingError` when the path leaves the root, the bag exists, or the
    root is missing / not writable. The directory itself is not created here.

    :param root: the recording root
    :param requested: a path relative to the root, or empty
    :param now: the time a timestamped name is made from (default: now)
    """
    root = Path(root).expanduser().resolve()
    requested = requested.strip()
    if not requested:
        requested = timestamped_name(now)
        candidate, n = root / requested, 1
        while candidate.exists():
            candidate, n = root / f"{requested}_{n}", n + 1
    else:
        candidate = (root / Path(requested).expanduser()).resolve()
        if candidate == root or not candidate.is_relative_to(root):
            raise RecordingError(f"bag path {requested!r} is outside the recording root {root};"
                                 " give a name relative to the root")
    if candidate.exists():
        raise RecordingError(f"bag {candidate} already exists; choose another name")
    parent = candidate.parent
    if not root.is_dir():
        raise RecordingError(f"recording root {root} does not exist or is not a directory")
    existing = parent
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise RecordingError(f"recording directory {existing} is not writable by this process"
                             f" (uid {os.getuid()})")
    return candidate


def create_bag_directory(directory: Path) -> None:
    """Create a new bag directory whose files (``<name>_<k>.mcap``) the file system can name.

    :param directory: the bag directory (absolute); its parents are created as needed
    :raises RecordingError: it exists, its name leaves no room for its files' names, or the
        OS refuses to create it
    """
    if directory.exists():
        raise RecordingError(f"bag directory {directory} already exists; choose a new name")
    name = len(directory.name.encode())
    longest = len(file_name(directory.name, 99999).encode())  # the files are named after it
    if longest > NAME_MAX:
        raise RecordingError(
            f"bag name of {name} bytes is too long: its files ('{directory.name[:20]}..._0.mcap') "
            f"must fit the file system's {NAME_MAX}-byte names; at most "
            f"{NAME_MAX - longest + name} bytes")
    try:
        directory.mkdir(parents=True)
    except OSError as err:
        raise RecordingError(f"cannot create bag {directory}: {err.strerror or err}") from err
