"""SDO access with typed errors, and the PDO set-up a master must do (000 Table 15, CiA 301).

Every SDO goes through :class:`SdoAccess`, which serialises transfers (canopen's SDO client
is not safe for two threads talking to one server) and turns canopen's exceptions into
:class:`~ssi_bridge.exceptions.SdoAbortError` (abort code + CiA 301 meaning + object) or
:class:`~ssi_bridge.exceptions.GatewayUnavailable` (no answer within the timeout).
"""

from __future__ import annotations

import logging
import threading

import can
import canopen
from canopen.sdo import SdoAbortedError, SdoCommunicationError, SdoVariable

from ssi_bridge.exceptions import BusError, GatewayUnavailable, SdoAbortError
from ssi_bridge.protocol.dictionary import (
    PROCESS_INPUT, PROCESS_OUTPUT, rpdo_cob_base, tpdo_cob_base,
)

logger = logging.getLogger(__name__)

#: CiA 301 transmission type "synchronous, every SYNC"
TRANS_SYNC_EVERY = 1
#: CiA 301 transmission type "event driven (manufacturer specific)"
TRANS_EVENT = 255
#: object 0x6820 position value (000 Table 40)
POSITION = 0x6820
#: first encoder default PDO (000 Table 15: PDO9 = channels 0+1)
FIRST_POSITION_PDO = 9
#: COB-ID bit 31 of a PDO communication parameter: the PDO is not valid (CiA 301)
COB_ID_INVALID = 1 << 31
#: the 29 identifier bits of a COB-ID entry
COB_ID_BITS = (1 << 29) - 1


def position_pdos(slots: int) -> list[tuple[int, list[int]]]:
    """Return (PDO number, slots carried) for the encoder default PDOs PDO9-12 in use."""
    return [(FIRST_POSITION_PDO + g, [s for s in (2 * g + 1, 2 * g + 2) if s <= slots])
            for g in range((slots + 1) // 2)]


def abort_meaning(code: int) -> str:
    """The CiA 301 meaning of SDO abort ``code`` as canopen words it (``SdoAbortedError.CODES``),
    or that the code is none of CiA 301's."""
    return SdoAbortedError.CODES.get(
        code, f"abort code 0x{code:08X} is not defined by CiA 301 (manufacturer specific?)")


class SdoAccess:
    """Serialised, typed SDO access to one RemoteNode."""

    def __init__(self, node: canopen.RemoteNode, timeout: float) -> None:
        self.node = node
        self.lock = threading.RLock()
        # canopen counts the first attempt as a retry: 2 = one repeat after a lost frame,
        # each waiting half the budget, so a transfer step is bounded by ``timeout``
        node.sdo.RESPONSE_TIMEOUT = timeout / 2
        node.sdo.MAX_RETRIES = 2
        node.sdo.PAUSE_BEFORE_SEND = 0.0
        self.timeout = timeout
        #: SDO transfers that got no answer
        self.timeouts = 0
        #: SDO transfers the gateway aborted
        self.aborts = 0

    def _fail(self, err: Exception, what: str, index: int, subindex: int) -> Exception:
        where = f"0x{index:04X}:{subindex:02X}"
        if isinstance(err, can.CanError):  # the bus refused the request (interface lost)
            return BusError(f"SDO {what} of {where} on node {self.node.id} not sent: {err}")
        if isinstance(err, SdoAbortedError):
            self.aborts += 1
            meaning = abort_meaning(err.code)
            return SdoAbortError(err.code, meaning,
                                 f"SDO {what} of {where} on node {self.node.id} aborted with "
                                 f"0x{err.code:08X}: {meaning}")
        self.timeouts += 1
        return GatewayUnavailable(
            f"SDO {what} of {where}: node {self.node.id} did not answer within "
            f"{self.timeout:.3f} s ({err}); is the gateway powered, on this bus and not "
            f"STOPPED?")

    def read(self, index: int, subindex: int = 0) -> int | bytes | str:
        """Upload one object (raises SdoAbortError / GatewayUnavailable)."""
        with self.lock:
            try:
                var = self.node.sdo[index]
                var = var[subindex] if not isinstance(var, SdoVariable) else var
                return var.raw
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "upload", index, subindex) from err

    def write(self, index: int, subindex: int, value: int | bytes) -> None:
        """Download one object (raises SdoAbortError / GatewayUnavailable)."""
        with self.lock:
            try:
                var = self.node.sdo[index]
                var = var[subindex] if not isinstance(var, SdoVariable) else var
                var.raw = value
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "download", index, subindex) from err

    def upload(self, index: int, subindex: int) -> bytes:
        """Upload the raw bytes of one object, whether or not the dictionary knows it (so a
        station's own abort, e.g. 0x06020000, reaches the caller); raises SdoAbortError,
        GatewayUnavailable or BusError (the interface refused the request)."""
        with self.lock:
            try:
                return bytes(self.node.sdo.upload(index, subindex))
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "upload", index, subindex) from err

    def download(self, index: int, subindex: int, data: bytes) -> None:
        """Download raw bytes to one object (raises SdoAbortError, GatewayUnavailable or
        BusError)."""
        with self.lock:
            try:
                self.node.sdo.download(index, subindex, data)
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "download", index, subindex) from err

    def configure_pdos(self, slots: int, *, images: bool = True) -> None:
        """Map and enable what the bridge consumes; every PDO is invalid by default.

        TPDO s / RPDO s (s = 1..slots) carry slot s's process input / output image
        (0x2000:s / 0x2100:s); the encoder default PDOs 9.. carry 0x6820 of slot pairs.
        TPDOs are synchronous (type 1), the image RPDOs event driven (type 255, applied on
        reception, so the handshake does not wait an extra cycle).
        """
        node_id = self.node.id
        with self.lock:
            try:
                for pdo, carried in position_pdos(slots):
                    self._setup(self.node.tpdo[pdo], tpdo_cob_base(pdo) + node_id,
                                TRANS_SYNC_EVERY, [(POSITION, s) for s in carried])
                if images:
                    for slot in range(1, slots + 1):
                        self._setup(self.node.tpdo[slot], tpdo_cob_base(slot) + node_id,
                                    TRANS_SYNC_EVERY, [(PROCESS_INPUT, slot)])
                        self._setup(self.node.rpdo[slot], rpdo_cob_base(slot) + node_id,
                                    TRANS_EVENT, [(PROCESS_OUTPUT, slot)])
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "PDO configuration", 0x1400, 0) from err

    def pdos_configured(self, slots: int, *, images: bool = True) -> bool:
        """True when every PDO :meth:`configure_pdos` enables is still valid on its COB-ID.

        One upload of sub-index 1 (COB-ID) of each communication parameter (0x1800 + n - 1
        for TPDO n, 0x1400 + n - 1 for RPDO n). Raises GatewayUnavailable / SdoAbortError.
        """
        node_id = self.node.id
        expected = [(0x1800 + pdo - 1, tpdo_cob_base(pdo) + node_id)
                    for pdo, _carried in position_pdos(slots)]
        if images:
            for slot in range(1, slots + 1):
                expected += [(0x1800 + slot - 1, tpdo_cob_base(slot) + node_id),
                             (0x1400 + slot - 1, rpdo_cob_base(slot) + node_id)]
        for index, cob_id in expected:
            raw = self.upload(index, 1)
            found = int.from_bytes(raw[:4], "little")
            if found & (COB_ID_INVALID | COB_ID_BITS) != cob_id:
                logger.info("0x%04X:01 is 0x%08X, configured was 0x%03X (valid): the PDOs "
                            "are no longer the configured ones", index, found, cob_id)
                return False
        return True

    @staticmethod
    def _setup(pdo: canopen.pdo.PdoMap, cob_id: int, trans_type: int,
               entries: list[tuple[int, int]]) -> None:
        pdo.clear()
        for index, subindex in entries:
            pdo.add_variable(index, subindex)
        pdo.cob_id = cob_id
        pdo.trans_type = trans_type
        pdo.rtr_allowed = False
        pdo.enabled = True
        pdo.save()
        logger.debug("PDO 0x%03X configured: %s", cob_id, entries)
