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
    def simulation_transport(self) -> str:
        """How the station child is reached: "virtual" or "udp_multicast"."""
    @property
    def simulation_start_timeout(self) -> float:
        """Seconds a station child may take to send its boot-up message."""
    @property
    def simulation_station_priority(self) -> int:
        """The SCHED_FIFO priority of a station child (0: none)."""
    @property
    def bus_interface(self) -> str:
        """The python-can interface of the node's bus."""
    @property
    def bus_channel(self) -> str:
        """The python-can channel of the node's bus."""
    @property
    def bus_bitrate(self) -> int:
        """The bus bit rate in bit/s."""
    @property
    def node_id(self) -> int:
        """The first station's CANopen node id."""
    @property
    def joints(self) -> tuple[JointSettings, ...]:
        """Every configured joint, in the order of the parameters."""
    @property
    def storage_path(self) -> str:
        """Where recordings and station files go."""

    @property
    def station_ids(self) -> tuple[int, ...]:
        """The node ids of the stations, first one first."""

    def station_joints(self, station: int) -> tuple[JointSettings, ...]:
        """The joints of ``station``."""


#: the node's own settings class, whatever it is: a changed copy is of the same class
AnySettings = TypeVar("AnySettings", bound=NodeSettings)


__all__ = ["AnySettings", "NodeSettings"]
