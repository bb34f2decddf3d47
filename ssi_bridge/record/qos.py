"""Offered QoS profiles as rosbag2 (Jazzy, metadata version 9) writes and reads them.

rosbag2 stores the publishers' QoS twice: as the string ``offered_qos_profiles`` in each MCAP
channel's metadata and as a YAML list under the topic in ``metadata.yaml``. Readers compare
the two (rosbags drops every message of a topic whose two copies differ), so both are
produced from the one text made here. Version 9 spells policies as lower-case names
(``keep_last``, ``reliable``...) and an unset duration as the infinite one
(9223372036 s 854775807 ns = RMW_DURATION_INFINITE).
"""

from __future__ import annotations

from typing import Any

import yaml
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

#: RMW_DURATION_INFINITE split as rosbag2 writes it
INFINITE_SEC, INFINITE_NSEC = 9223372036, 854775807
_INFINITE_NS = INFINITE_SEC * 1_000_000_000 + INFINITE_NSEC

_POLICIES: dict[str, Any] = {
    "history": HistoryPolicy, "reliability": ReliabilityPolicy,
    "durability": DurabilityPolicy, "liveliness": LivelinessPolicy,
}


def _policy_name(policy: Any) -> str:
    """rosbag2's lower-case policy name, e.g. ``HistoryPolicy.KEEP_LAST`` -> ``keep_last``."""
    return str(policy.name).lower()


def _duration(value: Duration) -> dict[str, int]:
    """A duration as ``{sec, nsec}``; 0 (the rmw default) becomes the infinite duration."""
    ns = value.nanoseconds
    if ns <= 0 or ns >= _INFINITE_NS:
        return {"sec": INFINITE_SEC, "nsec": INFINITE_NSEC}
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def qos_dict(qos: QoSProfile) -> dict[str, Any]:
    """One profile as the mapping rosbag2 writes (keys in rosbag2's order).

    :param qos: the profile
    """
    return {
        "history": _policy_name(qos.history),
        "depth": int(qos.depth),
        "reliability": _policy_name(qos.reliability),
        "durability": _policy_name(qos.durability),
        "deadline": _duration(qos.deadline),
        "lifespan": _duration(qos.lifespan),
        "liveliness": _policy_name(qos.liveliness),
        "liveliness_lease_duration": _duration(qos.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(qos.avoid_ros_namespace_conventions),
    }


def qos_text(profiles: list[QoSProfile]) -> str:
    """The ``offered_qos_profiles`` string of the MCAP channel metadata (block YAML).

    :param profiles: the offered profiles (empty: "")
    """
    if not profiles:
        return ""
    return yaml.safe_dump([qos_dict(p) for p in profiles], sort_keys=False,
                          default_flow_style=False).rstrip("\n")


def _policy(kind: str, value: Any) -> Any:
    """A policy from its v9 name or v8 integer; unknown values become SYSTEM_DEFAULT."""
    enum = _POLICIES[kind]
    if isinstance(value, int):
        try:
            return enum(value)
        except ValueError:
            return enum.SYSTEM_DEFAULT
    name = str(value).upper()
    if name in enum.__members__:
        return enum[name]
    return enum.SYSTEM_DEFAULT


def _to_duration(value: dict[str, int] | None) -> Duration:
    """``{sec, nsec}`` back to a Duration; infinite becomes 0 (the rmw default)."""
    if not value:
        return Duration()
    ns = int(value.get("sec", 0)) * 1_000_000_000 + int(value.get("nsec", 0))
    return Duration(nanoseconds=0 if ns >= _INFINITE_NS else ns)


def parse_qos(text: str | list[dict[str, Any]] | None) -> list[QoSProfile]:
    """Profiles from a channel string or a metadata.yaml list (v8 integers or v9 names).

    :param text: the channel metadata's string, a metadata.yaml list, or None
    """
    items = yaml.safe_load(text) if isinstance(text, str) else text
    profiles = []
    for item in items or []:
        history = _policy("history", item.get("history", "keep_last"))
        depth = int(item.get("depth", 0))
        if history in (HistoryPolicy.UNKNOWN, HistoryPolicy.SYSTEM_DEFAULT) or (
                history == HistoryPolicy.KEEP_LAST and depth <= 0):
            # discovery reports "unknown/0" for remote publishers; rosbag2 plays with depth 10
            history, depth = HistoryPolicy.KEEP_LAST, max(depth, 10)
        profiles.append(QoSProfile(
            history=history, depth=depth,
            reliability=_policy("reliability", item.get("reliability", "reliable")),
            durability=_policy("durability", item.get("durability", "volatile")),
            deadline=_to_duration(item.get("deadline")),
            lifespan=_to_duration(item.get("lifespan")),
            liveliness=_policy("liveliness", item.get("liveliness", "automatic")),
            liveliness_lease_duration=_to_duration(item.get("liveliness_lease_duration")),
            avoid_ros_namespace_conventions=bool(
                item.get("avoid_ros_namespace_conventions", False)),
        ))
    return profiles
