"""What the supervisor reads of the node's settings, as a structural type (no import of ros/).

The node's ``NodeSettings`` (``ros/params.py``) is a frozen dataclass with these fields; the
supervisor only reads them and makes changed copies with ``dataclasses.replace``, so the
simulator needs nothing of the driver to be started by it.
"""

from __future__ import annotations

from dataclasses import Field
from typing import Any, ClassVar, Protocol, TypeVar

from ssi_bridge.protocol.settings import JointSettings


class NodeSettings(Protocol):
    """The node's settings the simulated stations are started from (a dataclass)."""

    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]

    # read-only: the node's settings are a frozen dataclass
    @property
    def simulation_transport(self) -> str: ...
    @property
    def simulation_start_timeout(self) -> float: ...
    @property
    def simulation_station_priority(self) -> int: ...
    @property
    def bus_interface(self) -> str: ...
    @property
    def bus_channel(self) -> str: ...
    @property
    def bus_bitrate(self) -> int: ...
    @property
    def node_id(self) -> int: ...
    @property
    def joints(self) -> tuple[JointSettings, ...]: ...
    @property
    def storage_path(self) -> str: ...

    @property
    def station_ids(self) -> tuple[int, ...]:
        """The node ids of the stations, first one first."""

    def station_joints(self, station: int) -> tuple[JointSettings, ...]:
        """The joints of ``station``."""


#: the node's own settings class, whatever it is: a changed copy is of the same class
AnySettings = TypeVar("AnySettings", bound=NodeSettings)


__all__ = ["AnySettings", "NodeSettings"]
