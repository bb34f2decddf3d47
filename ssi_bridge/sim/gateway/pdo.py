"""The station's PDO engine: CiA 301 PDO communication/mapping objects made to work.

canopen's ``LocalNode`` stores PDO parameters but does not act on them, so this module reads
the live 0x1400-0x140B / 0x1600-0x160B (RPDO) and 0x1800-0x180B / 0x1A00-0x1A0B (TPDO)
objects, checks writes to them as CiA 301 requires (mapping only while the PDO is invalid,
mapped objects must exist and be mappable, at most 64 bits) and moves data:

* TPDOs: transmission type 1-240 = every n-th SYNC, 254/255 = event driven: sent after a
  SYNC cycle when the mapped data changed (000 Table 15, "normally 255"). CiA 301 sub 3
  inhibit time (x 100 µs): an event-driven TPDO is not sent again before it has passed since
  the last transmission; a change meanwhile goes out when it ends. Sub 5 event timer (ms,
  0 = off): an event-driven TPDO is also sent when that long passed without a transmission
  (its timer restarts with every transmission). The inhibit time may only be written while
  the TPDO is invalid (CiA 301); both act through a timer thread that runs only while some
  TPDO needs it;
* RPDOs: 0-240 = applied at the next SYNC, 254/255 = applied on reception.
PDOs move only in NMT OPERATIONAL (the gateway checks the state before calling in).

A TPDO's payload is read through one reader per PDO, chosen when the PDO parameters are
(re)loaded, i.e. once per mapping change: the gateway's ``fast_packer`` for a whole mapping it
can encode in one step, else one reader per mapped object (the ``fast_reader`` the gateway
supplies for the objects it can encode directly, else ``LocalNode.get_data``: the read
callbacks, stored data, default), joined. The TPDOs due after one SYNC go to ``send`` as one
batch, so the bus path is entered once per cycle, not once per frame.
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import canopen
from canopen import SdoAbortedError

from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.protocol.dictionary import (
    N_PDOS, PDO_INVALID, RPDO_COM, RPDO_MAP, TPDO_COM, TPDO_MAP,
)

logger = logging.getLogger(__name__)

U32 = struct.Struct("<I")
#: COB-ID bits that are not the 11-bit identifier (valid, RTR, frame)
_COB_FLAGS = 0xE000_0000
#: a reader of one mapped object's encoded bytes
Reader = Callable[[], bytes]
#: ``fast_reader(index, subindex)``: a direct reader for that object, or None
FastReader = Callable[[int, int], Reader | None]
#: ``fast_packer([(index, subindex), ...])``: one reader of the whole payload, or None
FastPacker = Callable[[list[tuple[int, int]]], Reader | None]
#: sends the (COB-ID, payload) frames of one SYNC cycle, in order
SendMany = Callable[[list[tuple[int, bytes]]], None]
#: largest synchronous transmission type (1-240 = every n-th SYNC, 0 = acyclic synchronous)
SYNC_TYPE_MAX = 240
#: synchronous transmission types
SYNC_TYPES = range(0, SYNC_TYPE_MAX + 1)


@dataclass
class _Pdo:
    """The current state of one PDO as the station acts on it."""

    number: int
    cob_id: int
    valid: bool
    trans_type: int
    entries: list[tuple[int, int, int]]  # (index, subindex, bits)
    last: bytes | None = None
    pending: bytes | None = None
    #: CiA 301 sub 3 inhibit time (s) and sub 5 event timer (s, 0 = off); TPDOs only
    inhibit_s: float = 0.0
    event_s: float = 0.0
    #: clock time of the last transmission (None: never sent)
    sent_at: float | None = None
    #: a change held back by the inhibit time, sent when it ends
    held: bytes | None = None
    #: one reader per entry (TPDOs), fixed until the parameters are reloaded
    readers: list[Reader] = field(default_factory=list)
    #: reader of the whole payload (TPDOs): a packer, the only entry's reader or
    #: :meth:`joined`; chosen by the engine's reload (until then: no bytes)
    read: Reader = bytes

    def joined(self) -> bytes:
        """The mapped objects' bytes, one reader per entry, concatenated in mapping order."""
        return b"".join([read() for read in self.readers])

    def payload(self) -> bytes:
        """The payload through the reader chosen at the last reload."""
        return self.read()


class PdoEngine:
    """Read PDO parameters from ``node`` and transmit / apply PDO data.

    :param node: the station's canopen ``LocalNode`` (its PDO objects)
    :param send: puts a batch of frames on the bus
    :param fast_reader: a direct reader per mapped object (``EncoderObjects.pdo_reader``)
    :param fast_packer: one reader of a whole payload (``EncoderObjects.pdo_packer``)
    :param lock: the station lock the dictionary is read under
    :param clock: the monotonic clock of the event timers and inhibit times
    """

    def __init__(self, node: canopen.LocalNode, send: SendMany,
                 fast_reader: FastReader | None = None,
                 fast_packer: FastPacker | None = None, *,
                 lock: threading.RLock | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._node = node
        self._send = send
        self._fast_reader = fast_reader
        self._fast_packer = fast_packer
        #: held while the timer thread reads and sends (the gateway's lock: no module cycle
        #: runs meanwhile)
        self._lock = lock if lock is not None else threading.RLock()
        self._clock = clock
        self._timed: list[_Pdo] = []  # event-driven TPDOs with an inhibit time or event timer
        self._timer: threading.Thread | None = None
        self._wake = threading.Event()
        self._stopping = False
        self.tpdos: list[_Pdo] = []
        self.rpdos: list[_Pdo] = []
        self._active: list[_Pdo] = []  # the valid, mapped TPDOs
        self._subscribed: dict[int, Callable[[int, bytearray, float], None]] = {}
        self._sync_count = 0

    # -- configuration -----------------------------------------------------------------------
    def _u(self, index: int, subindex: int) -> int:
        obj = self._node.object_dictionary.get_variable(index, subindex)
        if obj is None:
            raise KeyError(f"0x{index:04X}:{subindex:02X} is not in the station's dictionary")
        return int(obj.decode_raw(self._node.get_data(index, subindex)))

    def _load(self, com: int, mapping: int, number: int) -> _Pdo:
        cob = self._u(com, 1)
        entries = []
        for sub in range(1, self._u(mapping, 0) + 1):
            value = self._u(mapping, sub)
            entries.append((value >> 16, (value >> 8) & 0xFF, value & 0xFF))
        pdo = _Pdo(number, cob & 0x7FF, not cob & PDO_INVALID, self._u(com, 2), entries)
        if com >= TPDO_COM:
            pdo.inhibit_s = self._u(com, 3) / 10_000   # CiA 301: multiples of 100 µs
            pdo.event_s = self._u(com, 5) / 1_000      # CiA 301: ms
        return pdo

    def _reader(self, index: int, subindex: int) -> Reader:
        fast = self._fast_reader(index, subindex) if self._fast_reader else None
        return fast if fast is not None else partial(self._node.get_data, index, subindex)

    def reload(self) -> None:
        """Re-read all PDO objects, choose the TPDO readers, (re)subscribe the valid RPDOs."""
        self.tpdos = [self._load(TPDO_COM + n, TPDO_MAP + n, n + 1) for n in range(N_PDOS)]
        for pdo in self.tpdos:
            pdo.readers = [self._reader(i, s) for i, s, _ in pdo.entries]
            packed = (self._fast_packer([(i, s) for i, s, _ in pdo.entries])
                      if self._fast_packer and pdo.entries else None)
            if packed is not None:
                pdo.read = packed
            else:
                pdo.read = pdo.readers[0] if len(pdo.readers) == 1 else pdo.joined
        self._active = [pdo for pdo in self.tpdos if pdo.valid and pdo.entries]
        self._timed = [pdo for pdo in self._active
                       if pdo.trans_type >= 254 and (pdo.inhibit_s > 0 or pdo.event_s > 0)]
        if self._timed:
            self._start_timer()
        self._wake.set()
        self.rpdos = [self._load(RPDO_COM + n, RPDO_MAP + n, n + 1) for n in range(N_PDOS)]
        network = self._node.network
        for cob, callback in self._subscribed.items():
            network.unsubscribe(cob, callback)
        self._subscribed = {}
        for pdo in self.rpdos:
            if pdo.valid and pdo.entries:
                callback = self._make_receiver(pdo)
                network.subscribe(pdo.cob_id, callback)
                self._subscribed[pdo.cob_id] = callback

    def detach(self) -> None:
        """Unsubscribe every RPDO and end the timer thread (gateway stop)."""
        for cob, callback in self._subscribed.items():
            self._node.network.unsubscribe(cob, callback)
        self._subscribed = {}
        timer, self._timer = self._timer, None
        if timer is not None:
            self._stopping = True
            self._wake.set()
            if timer is not threading.current_thread():
                timer.join(2.0)
            self._stopping = False

    # -- inhibit time and event timer (CiA 301 sub 3 / sub 5) --------------------------------
    def _start_timer(self) -> None:
        if self._timer is None or not self._timer.is_alive():
            self._timer = threading.Thread(target=self._run_timer, name="tpdo_timer",
                                           daemon=True)
            self._timer.start()

    def _run_timer(self) -> None:
        while not self._stopping:
            delay = 0.05
            self._wake.clear()  # before the tick: a wake-up during it is not lost
            # a timed acquire: stop() holds the lock while it waits for this thread to end
            if not self._lock.acquire(timeout=0.05):
                continue
            try:
                if self._stopping:
                    break
                delay = self.tick()
            except Exception:  # noqa: BLE001 - the timer must outlive one bad read
                logger.exception("TPDO timer failed")
            finally:
                self._lock.release()
            self._wake.wait(max(delay, 0.0005))

    def tick(self) -> float:
        """Send what the inhibit time held back or an event timer calls for; next wait (s)."""
        if not self._timed or self._node.nmt.state != "OPERATIONAL":
            return 0.05
        now = self._clock()
        frames: list[tuple[int, bytes]] = []
        due = 0.05
        for pdo in self._timed:
            since = now - pdo.sent_at if pdo.sent_at is not None else None
            if pdo.held is not None:
                if since is None or since >= pdo.inhibit_s:
                    frames.append(self._sent(pdo, pdo.held, now))
                    since = 0.0
                else:
                    due = min(due, pdo.inhibit_s - since)
            if pdo.event_s > 0:
                if since is None or since >= pdo.event_s:
                    frames.append(self._sent(pdo, pdo.read(), now))
                    since = 0.0
                due = min(due, pdo.event_s - since)
        if frames:
            self._send(frames)
        return due

    @staticmethod
    def _sent(pdo: _Pdo, data: bytes, now: float) -> tuple[int, bytes]:
        pdo.last, pdo.held, pdo.sent_at = data, None, now
        return pdo.cob_id, data

    def check_write(self, index: int, subindex: int, data: bytes) -> None:
        """Refuse a PDO parameter write CiA 301 forbids (raises ``SdoAbortedError``).

        :param index: the object's index
        :param subindex: its subindex
        :param data: the bytes to be written
        """
        is_tx = index >= TPDO_COM
        base = index & 0xFE00
        is_map = base in (RPDO_MAP, TPDO_MAP)
        n = index - base
        if n >= N_PDOS:
            return
        com = (TPDO_COM if is_tx else RPDO_COM) + n
        valid = not self._u(com, 1) & PDO_INVALID
        if not is_map:
            if subindex == 1:
                new = U32.unpack(data)[0]
                if valid and not new & PDO_INVALID and (new ^ self._u(com, 1)) & 0x7FF:
                    raise SdoAbortedError(SdoAbort.INVALID_VALUE)
                if new & 0x2000_0000 or new & 0x1FFF_F800:
                    raise SdoAbortedError(SdoAbort.INVALID_VALUE)  # 29-bit ids not supported
            elif subindex == 2 and 240 < data[0] < 252:
                raise SdoAbortedError(SdoAbort.INVALID_VALUE)
            elif subindex == 3 and valid and is_tx:
                # CiA 301: the inhibit time shall not be changed while the PDO exists
                raise SdoAbortedError(SdoAbort.CANNOT_STORE_STATE)
            return
        if valid:
            raise SdoAbortedError(SdoAbort.CANNOT_STORE_STATE)
        if subindex == 0:
            self._check_mapping(index, data[0], is_tx)
        elif self._u(index, 0) != 0:
            raise SdoAbortedError(SdoAbort.CANNOT_STORE_STATE)
        else:
            self._check_entry(U32.unpack(data)[0], is_tx)

    def _check_entry(self, value: int, is_tx: bool) -> int:
        index, subindex, bits = value >> 16, (value >> 8) & 0xFF, value & 0xFF
        od = self._node.object_dictionary
        if index not in od:
            raise SdoAbortedError(SdoAbort.NO_SUCH_OBJECT)
        obj = od[index]
        if not isinstance(obj, canopen.objectdictionary.ODVariable):
            if subindex not in obj:
                raise SdoAbortedError(SdoAbort.NO_SUCH_SUBINDEX)
            obj = obj[subindex]
        allowed = obj.readable if is_tx else obj.writable
        if not obj.pdo_mappable or not allowed or bits != len(obj):
            raise SdoAbortedError(SdoAbort.NOT_MAPPABLE)
        return bits

    def _check_mapping(self, index: int, count: int, is_tx: bool) -> None:
        if count > 8:
            raise SdoAbortedError(SdoAbort.VALUE_TOO_HIGH)
        total = sum(self._check_entry(self._u(index, sub), is_tx) for sub in range(1, count + 1))
        if total > 64:
            raise SdoAbortedError(SdoAbort.PDO_TOO_LONG)

    # -- data ---------------------------------------------------------------------------------
    def on_sync(self) -> None:
        """Send the TPDOs due after this SYNC's module cycle, as one batch in PDO order."""
        count = self._sync_count = self._sync_count % SYNC_TYPE_MAX + 1
        frames: list[tuple[int, bytes]] = []
        try:
            for pdo in self._active:
                trans = pdo.trans_type
                if trans <= SYNC_TYPE_MAX:
                    if trans == 0 or count % trans == 0:
                        frames.append((pdo.cob_id, pdo.read()))
                elif trans >= 254:
                    data = pdo.read()
                    if data != pdo.last:
                        if pdo.inhibit_s > 0 or pdo.event_s > 0:
                            now = self._clock()
                            if (pdo.inhibit_s > 0 and pdo.sent_at is not None
                                    and now - pdo.sent_at < pdo.inhibit_s):
                                pdo.held = data  # goes out when the inhibit time ends
                                self._wake.set()
                                continue
                            frames.append(self._sent(pdo, data, now))
                        else:
                            pdo.last = data
                            frames.append((pdo.cob_id, data))
                    elif pdo.held is not None:
                        pdo.held = None  # changed back within the inhibit time: no change
        finally:  # a reader that raises still lets the TPDOs before it go, as frame by frame
            if frames:
                self._send(frames)

    def apply_pending(self) -> None:
        """Write the data of synchronous RPDOs received since the last SYNC."""
        for pdo in self.rpdos:
            if pdo.pending is not None:
                data, pdo.pending = pdo.pending, None
                self._apply(pdo, data)

    def _apply(self, pdo: _Pdo, data: bytes) -> None:
        offset = 0
        for index, subindex, bits in pdo.entries:
            size = bits // 8
            chunk = bytes(data[offset:offset + size])
            offset += size
            if len(chunk) != size:
                logger.warning("RPDO%d: %d bytes too short for its mapping", pdo.number, len(data))
                return
            try:
                self._node.set_data(index, subindex, chunk)
            except SdoAbortedError as err:
                logger.warning("RPDO%d: 0x%04X:%02X refused (0x%08X)", pdo.number, index,
                               subindex, err.code)

    def _make_receiver(self, pdo: _Pdo) -> Callable[[int, bytearray, float], None]:
        def receive(can_id: int, data: bytearray, timestamp: float) -> None:
            if self._node.nmt.state != "OPERATIONAL":
                return
            if pdo.trans_type in SYNC_TYPES:
                pdo.pending = bytes(data)
            else:
                self._apply(pdo, bytes(data))
        return receive
