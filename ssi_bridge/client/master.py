"""BridgeClient: the CANopen master the ROS node uses to talk to the XN-GW-CANOPEN.

``connect()`` brings the gateway up as a real master must (CiA 301): probe it over SDO, go
PRE-OPERATIONAL, map and enable the PDOs it consumes (all invalid by default, 000 Table 15),
set the heartbeat producer time, start the node (OPERATIONAL). ``sync()`` produces the SYNC
(the module cycle), TPDO callbacks keep the newest sample per slot, and the register
handshake of 000 runs over the process-image PDOs (or SDO, ``transport="sdo"``).

A supervisor thread (``client/liveness.py``) consumes the heartbeat: a silent gateway is
reported (``gateway_alive`` False), a boot-up message or a non-OPERATIONAL heartbeat triggers
an automatic re-configuration, and while no heartbeat comes the gateway is probed over SDO so
a restarted station whose heartbeat is off again is found as well.

The slots' process output images, the port the handshake runs over, with the control bits
and their clear pulses, are ``client/images.py``'s :class:`ProcessImages` (``images``).

Threads: ``sync``/``latest``/``wait_cycle`` (timer thread), ``read_register``/
``write_register``/``set_control`` (service thread) and the network thread share
:class:`~ssi_bridge.client.samples.SlotTable`; one handshake per slot at a time (slot lock).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import can
import canopen

from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.client.bus_master import CanMaster
from ssi_bridge.client.emcy_log import EmcySummary
from ssi_bridge.client.handshake import WRITE_STEPS, Handshake
from ssi_bridge.client.images import ProcessImages
from ssi_bridge.client.liveness import HEARTBEAT_OBJECT, Liveness
from ssi_bridge.client.load import BusLoad
from ssi_bridge.client.receive import TpdoRoutes
from ssi_bridge.client.samples import ChannelSample, ClientCounters, SlotTable
from ssi_bridge.client.sdo import SdoAccess
from ssi_bridge.exceptions import (BusError, GatewayUnavailable, HandshakeTimeout,
                                   RegisterError, SsiBridgeError)
from ssi_bridge.client.bus import BusOpener, ReceiveWatch
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.protocol.dictionary import (
    MAX_SLOTS, NMT_COB_ID, NMT_ENTER_PRE_OPERATIONAL, NMT_START, SYNC_COB_ID)
from ssi_bridge.base.od import build_dictionary
from ssi_bridge.protocol.images import ProcessInput

logger = logging.getLogger(__name__)
__all__ = ["SYNC_COB_ID", "BridgeClient", "CanMaster"]


class BridgeClient:
    """Master side of the bridge for one station with ``slots`` XN-1SSI modules.

    :param bus: a :class:`BusConfig` (the client opens its own bus), an open bus it takes
        over, or a :class:`CanMaster` shared with the clients of other stations on the bus
        (the master owns bus and SYNC; :meth:`sync` then sends the one SYNC of all stations)
    :param node_id: the gateway's node id
    :param slots: number of modules (1-8)
    :param sdo_timeout: bound of one SDO transfer (s)
    :param handshake_timeout: bound of one handshake step (s); a whole write is bounded by
        three steps
    :param heartbeat_ms: heartbeat producer time configured on the gateway (ms); the gateway
        counts as silent after 4 periods without one
    :param transport: "pdo" (process images over PDOs) or "sdo" (SDO polling of 0x2000/0x2100)
    :param assist_after: a handshake sends its own SYNC when none was sent for this long (s)
    :param opener: opens the bus of a :class:`BusConfig` (default: a plain python-can bus;
        a simulated wire's opener puts the master's frames on that wire's time line)

    :raises ValueError: ``slots`` outside 1-8 or an unknown ``transport``
    """

    def __init__(self, bus: BusConfig | can.BusABC | CanMaster, node_id: int, slots: int, *,
                 sdo_timeout: float = 0.5, handshake_timeout: float = 1.0,
                 heartbeat_ms: int = 50, transport: str = "pdo",
                 assist_after: float = 0.005, opener: BusOpener | None = None) -> None:
        if not 1 <= slots <= MAX_SLOTS:
            raise ValueError(f"slots {slots} outside 1-{MAX_SLOTS}")
        if transport not in ("pdo", "sdo"):
            raise ValueError(f"transport {transport!r}: use 'pdo' or 'sdo'")
        self.node_id = node_id
        self.slots = slots
        self.sdo_timeout = sdo_timeout
        self.handshake_timeout = handshake_timeout
        self.heartbeat_ms = heartbeat_ms
        self.heartbeat_timeout = max(4 * heartbeat_ms / 1000.0, 0.1)
        self.transport = transport
        self.assist_after = assist_after
        self.counters = ClientCounters()
        self._emcy_log = EmcySummary(logger, f"gateway node {node_id} ")
        self._rx_log = RateLimitedLog(logger)
        #: the bus' master; a private one (counting into this client) unless one was given
        self._owns_master = not isinstance(bus, CanMaster)
        self.master = (CanMaster(bus, self.counters, opener=opener) if not isinstance(bus, CanMaster)
                       else bus)
        self.table = SlotTable(slots, self.master.gate)
        self.table.counters = self.counters
        #: bus load from frame timestamps (for the bus diagnostics): the master's, one bus
        self.load: BusLoad = self.master.load
        self.bus: ReceiveWatch | None = None
        self.network: canopen.Network | None = None
        self.node: canopen.RemoteNode | None = None
        self.sdo: SdoAccess | None = None
        #: the slots' process images: the handshake's port, control bits, clear pulses
        self.images = ProcessImages(self, self.master.send_lock)
        self._handshake = Handshake(self.images, handshake_timeout,
                                    WRITE_STEPS * handshake_timeout)
        self._slot_locks = {s: threading.Lock() for s in range(1, slots + 1)}
        self._liveness = Liveness(self)
        self._routes = TpdoRoutes(node_id, slots, self.images.on_image, self.table.on_positions,
                                  self._on_malformed)

    # -- life cycle -------------------------------------------------------------------------
    def connect(self, patience: float = 0.0) -> None:
        """Open the bus and configure the gateway (raises GatewayUnavailable / SdoAbortError).

        ``patience``: for this long (s) a gateway that does not answer is asked again (a
        station process that has just booted on a busy machine); 0: the first timeout raises.
        """
        if self.network is not None:
            return
        self.master.connect()
        self.master.attach(self)
        self.bus = self.master.bus
        self.network = self.master.network
        assert self.network is not None
        self.sdo = SdoAccess(self.node_id, build_dictionary(self.node_id, self.slots),
                             self.sdo_timeout, self.counters)
        self.node = self.sdo.node
        self.network.add_node(self.node)
        # the master sends its own NMT commands (send_nmt) and consumes the heartbeat itself:
        # canopen's tracking of NMT commands on 0x000 would look states up that a foreign
        # heartbeat may have left outside CiA 301 (KeyError)
        self.network.unsubscribe(NMT_COB_ID, self.node.nmt.on_command)
        self.network.subscribe(0x700 + self.node_id, self._liveness.on_heartbeat_frame)
        self.node.emcy.add_callback(self._on_emcy)
        self._routes.attach(self.network)
        give_up = time.monotonic() + patience
        while True:
            try:
                self.configure()
                break
            except SsiBridgeError as err:
                if isinstance(err, GatewayUnavailable) and time.monotonic() < give_up:
                    self._rx_log.log(logging.INFO, "first_contact", "gateway node %d did not "
                                     "answer yet (%s); asking again", self.node_id, err)
                    continue
                self.close()
                raise
        self._liveness.start()

    def close(self) -> None:
        """Stop the supervisor and shut the bus down (the gateway keeps running)."""
        self._liveness.stop(timeout=2 * self.sdo_timeout + 1.0)
        if self.network is not None:
            self.network = None
            self.master.detach(self)
            if self._owns_master:
                self.master.close()
        self.bus = None

    def __enter__(self) -> BridgeClient:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def configure(self) -> None:
        """(Re)configure the gateway: PRE-OP, PDOs, heartbeat, OPERATIONAL, resend outputs."""
        assert self.sdo is not None and self.node is not None
        sdo, node = self.sdo, self.node

        def setup() -> None:
            # first, so a STOPPED station (another node's NMT stop) serves SDO again
            self.send_nmt(NMT_ENTER_PRE_OPERATIONAL)
            sdo.read(0x1000)  # probe: a clear error when nobody answers
            sdo.configure_pdos(self.slots, images=self.transport == "pdo")
            self._routes.release_maps(node)
            sdo.write(HEARTBEAT_OBJECT, 0, self.heartbeat_ms)

        self._start(setup)
        self.counters.configurations += 1
        logger.info("gateway node %d configured (%d slot(s), %s transport)", self.node_id,
                    self.slots, self.transport)

    def start_again(self) -> bool:
        """NMT start alone, for a station another node put in STOPPED or PRE-OPERATIONAL.

        Such a command leaves the object dictionary as it was (CiA 301 §7.2.8.2.1), so the
        PDOs are running again with the next SYNC. Afterwards (data already flows) each PDO's
        COB-ID is read back: False when one is no longer the one configured (a reset whose
        boot-up was not seen, another tool's SDO writes); :meth:`configure` is then due.
        Raises SsiBridgeError (BusError, GatewayUnavailable) like :meth:`configure`.
        """
        assert self.sdo is not None
        self._start(lambda: None)
        return self.sdo.pdos_configured(self.slots, images=self.transport == "pdo")

    def _start(self, setup: Callable[[], None]) -> None:
        """``setup()`` then NMT start, as the master's own NMT commands; resend the outputs."""
        assert self.sdo is not None
        with self.sdo.lock:
            self._liveness.configuring = True
            try:
                setup()
                self.send_nmt(NMT_START)
            finally:
                self._liveness.configuring = False
            self._liveness.started()  # counts as heard: the liveness clock (monotonic)
        for slot in range(1, self.slots + 1):
            self.images.send(slot, bytes(self.table.slot(slot).output))

    def request_configuration(self) -> None:
        """Have the supervisor thread configure the station again (the bus came back)."""
        self._liveness.reconfigure()

    def send_nmt(self, command: int) -> None:
        """Send NMT module control ``command`` (CiA 301 §7.2.8.3.1) to this station.

        Sent by the master itself, not through canopen's ``NmtMaster``, whose state lookup
        raises KeyError once a heartbeat carried a state outside CiA 301. Raises BusError when
        the bus refuses the frame.
        """
        try:
            self.master.send(NMT_COB_ID, bytes((command, self.node_id)))
        except can.CanError as err:
            self.counters.can_errors += 1
            raise BusError(f"gateway node {self.node_id}: NMT command 0x{command:02X} not "
                           f"sent: {err}") from err

    # -- cyclic data ------------------------------------------------------------------------
    def sync(self) -> float:
        """Send one SYNC (one module cycle); return its wire time (``base/timebase``).

        On a simulated wire that is the instant the SYNC's last bit was on the wire, where
        the modules latch (the frame's own timestamp); on a real interface the instant it was
        handed to the driver. One clock, no conversion.

        :raises BusError: the client is not connected, or the frame could not be sent
        """
        if self.network is None:
            raise BusError("client not connected")
        return self.master.sync()

    def latest(self, slot: int) -> ChannelSample | None:
        """The newest sample of ``slot`` (None before the first complete one)."""
        return self.table.latest(slot)

    def wait_cycle(self, timeout: float) -> bool:
        """True once every slot's image and position arrived since the last :meth:`sync`.

        On a master shared by several stations the wake-up comes when every station's cycle
        is complete (one per cycle); use ``master.wait_cycle`` to wait for all of them.

        :param timeout: longest wait (s)
        :returns: False when ``timeout`` passed first
        """
        return self.table.wait_cycle(timeout)

    @property
    def gateway_alive(self) -> bool:
        """True while the gateway's heartbeat is current."""
        return self.network is not None and self._liveness.alive()

    @property
    def emergencies(self) -> canopen.emcy.EmcyConsumer:
        """canopen's EMCY consumer of the gateway (``log``, ``active``, ``wait``)."""
        assert self.node is not None
        return self.node.emcy

    # -- registers and control --------------------------------------------------------------
    def read_register(self, slot: int, addr: int) -> int:
        """Read register ``addr`` of ``slot`` through the 000 handshake."""
        return self._locked(slot, lambda: self._handshake.read(slot, addr))

    def write_register(self, slot: int, addr: int, value: int) -> None:
        """Write ``value`` to register ``addr`` of ``slot`` through the 000 handshake."""
        self._locked(slot, lambda: self._handshake.write(slot, addr, value))

    def set_control(self, slot: int, *, stop: bool = False, enable_cmp1: bool = False,
                    enable_cmp2: bool = False, clear_cmp1: bool = False,
                    clear_cmp2: bool = False) -> None:
        """Set output bytes 6/7; CLR_CMPx are sent for one module cycle, then dropped.

        :param slot: the module's slot (1-8)
        :param stop: STOP (output byte 7): the module stops clocking its encoder
        :param enable_cmp1: EN_CMP1 (byte 6): comparator 1 on
        :param enable_cmp2: EN_CMP2: comparator 2 on
        :param clear_cmp1: CLR_CMP1: clear comparator 1's flag (a one-cycle pulse)
        :param clear_cmp2: CLR_CMP2: clear comparator 2's flag (a one-cycle pulse)
        :raises KeyError: an unknown slot
        """
        self.images.set_control(slot, stop=stop, enable_cmp1=enable_cmp1,
                                enable_cmp2=enable_cmp2, clear_cmp1=clear_cmp1,
                                clear_cmp2=clear_cmp2)

    def read_object(self, index: int, subindex: int = 0) -> int | float | bytes | str:
        """SDO upload with typed errors (SdoAbortError with the CiA 301 meaning).

        :param index: the object's index
        :param subindex: its subindex
        :returns: the value, decoded by the object's data type in the dictionary
        :raises BusError: the client is not connected
        :raises SdoAbortError: the gateway aborted the transfer (code and CiA 301 meaning)
        :raises GatewayUnavailable: no answer within the SDO timeout
        """
        if self.sdo is None:
            raise BusError("client not connected")
        return self.sdo.read(index, subindex)

    def write_object(self, index: int, subindex: int, value: int | float | bytes) -> None:
        """SDO download with typed errors.

        :param index: the object's index
        :param subindex: its subindex
        :param value: the value, encoded by the object's data type (bytes: as they are)
        :raises BusError: the client is not connected
        :raises SdoAbortError: the gateway aborted the transfer (code and CiA 301 meaning)
        :raises GatewayUnavailable: no answer within the SDO timeout
        """
        if self.sdo is None:
            raise BusError("client not connected")
        self.sdo.write(index, subindex, value)

    def _locked[T](self, slot: int, job: Callable[[], T]) -> T:
        self.table.slot(slot)  # KeyError for an unknown slot
        lock = self._slot_locks[slot]
        if not lock.acquire(timeout=self._handshake.total_timeout):
            self.counters.handshake_failures += 1
            raise HandshakeTimeout(f"slot {slot}: another register handshake is still running")
        try:
            return job()
        except (HandshakeTimeout, GatewayUnavailable):
            self.counters.timeouts += 1
            self.counters.handshake_failures += 1
            raise
        except RegisterError:
            self.counters.handshake_failures += 1
            raise
        finally:
            lock.release()

    # -- the handshake's ImagePort (client/images.py) ---------------------------------------
    def edit_output(self, slot: int, edit: Callable[[bytearray], None]) -> None:
        """Change bytes 0-5 of ``slot``'s output image with ``edit`` and send it
        (:meth:`ProcessImages.edit_output`: parameters and errors)."""
        self.images.edit_output(slot, edit)

    def next_input(self, slot: int, timeout: float) -> ProcessInput | None:
        """An input image of ``slot`` produced after the last edit, or None after ``timeout``
        s (:meth:`ProcessImages.next_input`)."""
        return self.images.next_input(slot, timeout)

    def alive(self) -> bool:
        """ImagePort: the heartbeat is current."""
        return self.gateway_alive

    # -- network thread callbacks ------------------------------------------------------------
    # TPDOs arrive raw on their COB-IDs (client/receive.py), not through canopen's PdoMaps
    def _on_malformed(self, can_id: int, length: int, expected: int) -> None:
        self.counters.malformed_pdos += 1
        self._rx_log.warning("malformed_pdo", "gateway node %d: TPDO 0x%03X with %d byte(s), "
                             "its mapping has %d: not decoded (%d so far)", self.node_id,
                             can_id, length, expected, self.counters.malformed_pdos)

    def _on_emcy(self, error: canopen.emcy.EmcyError) -> None:
        self.counters.emergencies += 1
        self._emcy_log.on_emcy(error.code, bytes(error.data))
