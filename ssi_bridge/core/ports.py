"""What core asks of the master and of the simulated station: structural types (Protocols).

core imports neither the master (``client/``) nor the simulator (``sim/``) (.importlinter,
"order-inside-the-driver"), so the seams are stated here, by what core calls, and the node
(``ros/node.py``) hands in the objects that fit: :class:`StationClient` is met by
``client.master.BridgeClient`` and by ``client.listener.ListenOnlyClient`` (which refuses every
transfer with a BusError), :class:`FaultPort` by the simulated station's
``FaultInjector`` / ``StationFaults`` (``sim/supervisor/faults.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence, Sized
from enum import Enum
from typing import Protocol


class StationClient(Protocol):
    """The master's client of one station (one gateway node id), as core uses it.

    Transfers raise the client's typed errors (:mod:`ssi_bridge.exceptions`): SdoAbortError,
    GatewayUnavailable, HandshakeTimeout / RegisterError, BusError (not connected, or
    listen-only).
    """

    @property
    def node_id(self) -> int:
        """The gateway's CANopen node id."""

    @property
    def gateway_alive(self) -> bool:
        """True while the gateway's heartbeat is current."""

    def read_register(self, slot: int, addr: int) -> int:
        """Register ``addr`` of the module in ``slot`` through the handshake (000 Table 4)."""

    def write_register(self, slot: int, addr: int, value: int) -> None:
        """Write register ``addr`` of the module in ``slot`` through the handshake.

        :param value: the register's new value
        """

    def set_control(self, slot: int, *, stop: bool = False, enable_cmp1: bool = False,
                    enable_cmp2: bool = False, clear_cmp1: bool = False,
                    clear_cmp2: bool = False) -> None:
        """STOP and the CMP bits of the module's process output (000 Table 6).

        Parameters ``slot``, ``stop``, ``enable_cmp1``, ``enable_cmp2``, ``clear_cmp1`` and
        ``clear_cmp2`` as ``client/master.py`` ``BridgeClient.set_control``.
        """

    def edit_output(self, slot: int, edit: Callable[[bytearray], None]) -> None:
        """Change bytes 0-5 of the module's process output image and send it.

        :param slot: the module's slot (1-8)
        :param edit: changes the 8 bytes in place; bytes 6-7 are kept
        """

    def read_object(self, index: int, subindex: int = 0) -> int | float | bytes | str:
        """SDO upload of ``index:subindex``, decoded by the station's dictionary."""

    def write_object(self, index: int, subindex: int, value: int | bytes) -> None:
        """SDO download to ``index:subindex``.

        :param value: the value, encoded by the object's data type (bytes: as they are)
        """


class RawSdo(Protocol):
    """A client's raw SDO access (``client.sdo.SdoAccess``): bytes in, bytes out."""

    def upload(self, index: int, subindex: int) -> bytes:
        """The object's bytes as the station sent them.

        :param index: the object's index
        :param subindex: its subindex
        """

    def download(self, index: int, subindex: int, data: bytes) -> None:
        """Download ``data`` to ``index:subindex`` unchanged."""


class DictionaryEntry(Protocol):
    """A variable of a station's object dictionary (canopen's ``ODVariable``), as core reads
    it: its EDS name and its CiA 301 data type code."""

    @property
    def name(self) -> str:
        """The EDS's parameter name."""

    @property
    def data_type(self) -> int | None:
        """The CiA 301 data type code (0x0007 UNSIGNED32 ...); None where the EDS has none."""


class ExpiredFault(Protocol):
    """A simulated fault whose duration ran out: what and on which joint ("" for the bus)."""

    @property
    def kind(self) -> Enum:
        """The fault's kind (InjectFault's constants, by name)."""

    @property
    def joint(self) -> str:
        """The joint it was on ("" for a fault of the bus or the gateway)."""


class FaultPort(Protocol):
    """Fault injection into the simulated station (None on real hardware)."""

    @property
    def active(self) -> Sized:
        """The faults in force (empty: none)."""

    def inject(self, kind: int, joint: str, rate: float = 0.0, duration: float = 0.0) -> str:
        """Apply fault ``kind`` (InjectFault's constants) to ``joint``.

        :param kind: the fault, one of InjectFault's constants
        :param joint: the joint it applies to; empty: the only (or first) configured joint
            (ignored for bus faults)
        :param rate: the fault's rate where it has one (e.g. the share of frames lost)
        :param duration: seconds until the fault expires by itself; 0 keeps it until CLEAR_ALL
        :returns: the sentence saying what now happens
        :raises ConfigError: for a kind, joint or rate the station refuses
        """

    def expire(self) -> Sequence[ExpiredFault]:
        """Forget the faults whose duration ran out; those faults."""


__all__ = ["DictionaryEntry", "ExpiredFault", "FaultPort", "RawSdo", "StationClient"]
