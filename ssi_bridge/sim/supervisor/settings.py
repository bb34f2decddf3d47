"""What the supervisor reads of the node's settings, as a structural type (no import of ros/).

The node's ``NodeSettings`` (``ros/params.py``) is a frozen dataclass with these fields; the
supervisor only reads them and makes changed copies with ``dataclasses.replace``, so the
simulator needs nothing of the driver to be started by it.
"""

from __future__ import annotations

from dataclasses import Field
from typing import Any, ClassVar, Protocol

from ssi_bridge.protocol.settings import JointSettings


class NodeSettings(Protocol):
    """The node's settings the simulated stations are started from (a dataclass)."""

    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]

    simulation_transport: str
    simulation_start_timeout: float
    simulation_station_priority: int
    bus_interface: str
    bus_channel: str
    bus_bitrate: int
    node_id: int
    joints: tuple[JointSettings, ...]
    storage_path: str

    @property
    def station_ids(self) -> tuple[int, ...]:
        """The node ids of the stations, first one first."""

    def station_joints(self, station: int) -> tuple[JointSettings, ...]:
        """The joints of ``station``."""


__all__ = ["NodeSettings"]
