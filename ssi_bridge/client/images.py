"""One station's process output images as its master drives them (000 ch. 2, "Process output").

The port the register handshake runs over (:class:`~ssi_bridge.client.handshake.ImagePort`):
bytes 0-5 of a slot's output image edited and sent, the next input image awaited (with a SYNC
of its own when none comes), and the control bits of bytes 6-7 with their one-cycle clear
pulses (``client/pulses.py``). Sent as RPDOs, or written over SDO with ``transport="sdo"``.

The images live in the station's :class:`~ssi_bridge.client.samples.SlotTable`; what this
needs of the station's client it names as :class:`Station` (no import of ``client/master.py``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Protocol

import can
import canopen

from ssi_bridge.client.pulses import next_pulse_output
from ssi_bridge.client.samples import ClientCounters, SlotTable
from ssi_bridge.client.sdo import SdoAccess
from ssi_bridge.exceptions import GatewayUnavailable
from ssi_bridge.protocol.dictionary import PROCESS_INPUT, PROCESS_OUTPUT, rpdo_cob_base
from ssi_bridge.protocol.images import CmpControl, Control, ProcessInput

logger = logging.getLogger(__name__)


class Station(Protocol):
    """What the images read of their station's client (``BridgeClient``)."""

    node_id: int
    transport: str
    assist_after: float
    table: SlotTable
    counters: ClientCounters
    #: None while the client is not connected: nothing is sent then
    network: canopen.Network | None
    sdo: SdoAccess | None

    @property
    def gateway_alive(self) -> bool:
        """Whether the gateway's heartbeat is current."""

    def sync(self) -> float:
        """Send one SYNC; return its wire time."""


class ProcessImages:
    """The process output images of one station's slots, and the input images they await.

    :param station: the station's client (its slot table, counters, transport, network)
    :param send_lock: the bus master's send lock (one frame at a time on a shared bus)
    """

    def __init__(self, station: Station, send_lock: threading.Lock | threading.RLock) -> None:
        self._station = station
        self._table = station.table
        self._send_lock = send_lock

    def set_control(self, slot: int, *, stop: bool = False, enable_cmp1: bool = False,
                    enable_cmp2: bool = False, clear_cmp1: bool = False,
                    clear_cmp2: bool = False) -> None:
        """Set output bytes 6/7 of ``slot`` and send the image; see
        :meth:`BridgeClient.set_control` for the parameters.

        :raises KeyError: an unknown slot

        (``stop``, ``enable_cmp1``, ``enable_cmp2``, ``clear_cmp1``, ``clear_cmp2``: output bits)
        """
        bits = CmpControl(0)
        for on, flag in ((enable_cmp1, CmpControl.EN_CMP1), (enable_cmp2, CmpControl.EN_CMP2),
                         (clear_cmp1, CmpControl.CLR_CMP1), (clear_cmp2, CmpControl.CLR_CMP2)):
            if on:
                bits |= flag
        table = self._table
        with table.cond:
            st = table.slot(slot)
            st.output[6] = int(bits)
            st.output[7] = int(Control.STOP) if stop else 0
            st.pulse_seq = table.sync_seq if clear_cmp1 or clear_cmp2 else None
            st.pulse_resends, st.release_seq = 0, None
            data = bytes(st.output)
        self.send(slot, data)

    def edit_output(self, slot: int, edit: Callable[[bytearray], None]) -> None:
        """Change bytes 0-5 of ``slot``'s output image and send it.

        :param slot: the module's slot (1-8)
        :param edit: changes the scratch copy of the 8 bytes in place; bytes 6-7 are kept
        :raises KeyError: an unknown slot
        """
        table = self._table
        with table.cond:
            st = table.slot(slot)
            scratch = bytearray(st.output)
            edit(scratch)
            st.output[0:6] = scratch[0:6]
            st.edit_seq = table.sync_seq
            data = bytes(st.output)
        self.send(slot, data)

    def next_input(self, slot: int, timeout: float) -> ProcessInput | None:
        """An input image produced after the last edit; sends SYNC itself when none comes
        within the station's ``assist_after``.

        :param slot: the module's slot (1-8)
        :param timeout: longest wait (s)
        :returns: the image, or None when ``timeout`` passed first
        """
        station = self._station
        end = time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            if station.transport == "sdo":
                return self._poll_input(slot)
            image = self._table.next_input(slot, min(left, station.assist_after))
            if image is not None:
                return image
            if time.monotonic() - self._table.synced_at >= station.assist_after:
                station.sync()
        return None

    def alive(self) -> bool:
        """The gateway's heartbeat is current (the handshake's check)."""
        return self._station.gateway_alive

    def send(self, slot: int, data: bytes) -> None:
        """Send ``slot``'s output image ``data`` (RPDO, or SDO with ``transport="sdo"``).

        Never raises: a frame the bus refuses is counted (``can_errors``) and logged, an SDO
        write the gateway does not answer is logged; nothing is sent while not connected.
        """
        station = self._station
        network = station.network
        if network is None:
            return
        try:
            if station.transport == "sdo":
                assert station.sdo is not None
                station.sdo.write(PROCESS_OUTPUT, slot, int.from_bytes(data, "little"))
                return
            with self._send_lock:
                network.send_message(rpdo_cob_base(slot) + station.node_id, data)
        except can.CanError as err:
            station.counters.can_errors += 1
            logger.warning("slot %d: process output not sent: %s", slot, err)
        except GatewayUnavailable as err:
            logger.warning("slot %d: process output not written: %s", slot, err)

    def on_image(self, slot: int, data: bytearray, timestamp: float) -> None:
        """A TPDO with ``slot``'s input image arrived (network thread): keep it, and send
        the next output of a running clear pulse.

        :param slot: the module's slot (TPDO ``slot`` carries its image)
        :param data: the 8 bytes of the image
        :param timestamp: its wire time (s)
        """
        table = self._table
        st = table.on_image(slot, data, timestamp)
        if st.pulse_seq is None and st.release_seq is None:  # re-checked under the lock
            return
        with table.cond:
            out = next_pulse_output(slot, st, table.sync_seq, data, self._station.counters)
        if out is not None:
            self.send(slot, out)

    def _poll_input(self, slot: int) -> ProcessInput | None:
        station = self._station
        assert station.sdo is not None
        station.sync()
        try:
            data = station.sdo.read_image(PROCESS_INPUT, slot)
        except GatewayUnavailable:
            return None
        self._table.on_image(slot, data)
        return ProcessInput.decode(data)
