"""Build MCAP schemas the way rosbag2 does: ``ros2msg`` text with dependency definitions.

rosbag2 (rosbag2_cpp ``LocalMessageDefinitionSource``) stores a type's ``.msg`` file text,
followed, for every type it depends on (transitively), by a line of 80 ``=``, a line
``MSG: pkg/Type`` and that type's ``.msg`` text. Readers (Foxglove, mcap_ros2, rosbags) parse
exactly this. The ``.msg`` files are the installed ones, found via the ament index
(``share/<pkg>/msg/<Type>.msg``), so the schema matches what the publisher was built from.
The RIHS01 type hash comes from the ``<Type>.json`` type description rosidl installs beside.
"""

from __future__ import annotations

import functools
import json
import logging
from dataclasses import dataclass
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

from ssi_bridge.exceptions import RecordingError

logger = logging.getLogger(__name__)

#: separator line between definitions in a ``ros2msg`` schema
SEPARATOR = "=" * 80

#: field types that are not messages (``.msg`` spelling)
BUILTIN_TYPES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
})


@dataclass(frozen=True)
class MessageSchema:
    """The schema record content of one type, plus what the channel metadata needs."""

    #: ``pkg/msg/Type``
    name: str
    #: ``ros2msg`` text with dependencies
    text: str
    #: ``RIHS01_...`` or ``""`` when the type description is not installed
    type_hash: str


def split_type(type_name: str) -> tuple[str, str]:
    """Split ``pkg/msg/Type`` or ``pkg/Type`` into ``(pkg, Type)``.

    :param type_name: ``pkg/msg/Type`` or ``pkg/Type``
    :raises RecordingError: another form
    """
    parts = type_name.split("/")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != "msg") or not all(parts):
        raise RecordingError(f"message type {type_name!r}: expected 'pkg/msg/Type'")
    return parts[0], parts[-1]


def _interface_file(pkg: str, name: str, suffix: str) -> Path:
    """Path of ``share/<pkg>/msg/<name><suffix>`` from the ament index."""
    try:
        share = Path(get_package_share_directory(pkg))
    except (PackageNotFoundError, LookupError, ValueError) as err:
        raise RecordingError(f"message package {pkg!r} is not installed (ament index)") from err
    return share / "msg" / f"{name}{suffix}"


def msg_text(pkg: str, name: str) -> str:
    """The installed ``.msg`` text of ``pkg/Type``.

    :param pkg: the package
    :param name: the type's name
    :raises RecordingError: the package is not installed or has no such ``.msg``
    """
    path = _interface_file(pkg, name, ".msg")
    try:
        return path.read_text(encoding="utf-8")
    except OSError as err:
        raise RecordingError(f"message definition {pkg}/{name} not found at {path}") from err


def dependencies(pkg: str, text: str) -> list[tuple[str, str]]:
    """Message types ``(pkg, Type)`` used by the fields of a ``.msg`` text, in order."""
    found: list[tuple[str, str]] = []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        ftype = line.split()[0].split("[", 1)[0].split("<=", 1)[0]
        if ftype in BUILTIN_TYPES:
            continue
        if "/" in ftype:
            dep = split_type(ftype)
        elif ftype == "Header":
            dep = ("std_msgs", "Header")
        else:
            dep = (pkg, ftype)
        if dep not in found:
            found.append(dep)
    return found


def type_hash(pkg: str, name: str) -> str:
    """RIHS01 hash of ``pkg/msg/Type`` from its installed type description, or ``""``.

    :param pkg: the package
    :param name: the type's name
    """
    path = _interface_file(pkg, name, ".json")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        logger.debug("no type description at %s", path)
        return ""
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == f"{pkg}/msg/{name}":
            return str(entry.get("hash_string", ""))
    return ""


def with_dependencies(pkg: str, text: str, seen: set[tuple[str, str]] | None = None) -> str:
    """``text`` (an interface definition of package ``pkg``) followed by every message type it
    uses, transitively, each once after a separator line, as rosbag2 lays out a ``ros2msg``
    schema; ``seen`` holds types already in it (the root type)."""
    parts, seen = [text], set(seen or ())
    pending = dependencies(pkg, text)
    while pending:
        dep = pending.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        body = msg_text(*dep)
        parts.append(f"{SEPARATOR}\nMSG: {dep[0]}/{dep[1]}\n{body}")
        pending.extend(d for d in dependencies(dep[0], body) if d not in seen)
    return "\n".join(part if part.endswith("\n") else part + "\n" for part in parts)


@functools.lru_cache(maxsize=None)
def build_schema(type_name: str) -> MessageSchema:
    """Build the ``ros2msg`` schema of ``type_name`` with every transitive dependency."""
    pkg, name = split_type(type_name)
    body = with_dependencies(pkg, msg_text(pkg, name), seen={(pkg, name)})
    return MessageSchema(f"{pkg}/msg/{name}", body, type_hash(pkg, name))
