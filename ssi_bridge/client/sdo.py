"""SDO access with typed errors, and the PDO set-up a master must do (000 Table 15, CiA 301).

Every SDO goes through :class:`SdoAccess`, which serialises transfers (canopen's SDO client
is not safe for two threads talking to one server) and turns canopen's exceptions into
:class:`~ssi_bridge.exceptions.SdoAbortError` (abort code + CiA 301 meaning + object) or
:class:`~ssi_bridge.exceptions.GatewayUnavailable` (no answer within the timeout). Its canopen
client takes only the answer to the current request (``client/sdo_answers.py``): a late answer
to an earlier one is set aside and counted (``stale_sdo_answers``), the transfer goes on
waiting for its own.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import can
import canopen
from canopen import SdoAbortedError, SdoCommunicationError
from canopen.sdo.base import SdoVariable

from ssi_bridge.base.canopen_compat import CheckedRemoteNode
from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.client.samples import ClientCounters
from ssi_bridge.client.sdo_answers import SdoAnswers
from ssi_bridge.exceptions import BusError, GatewayUnavailable, SdoAbortError
from ssi_bridge.protocol.dictionary import (
    PDO_INVALID, PROCESS_INPUT, PROCESS_OUTPUT, RPDO_COM, TPDO_COM, TRANS_EVENT, rpdo_cob_base,
    tpdo_cob_base,
)

logger = logging.getLogger(__name__)

#: CiA 301 transmission type "synchronous, every SYNC"
TRANS_SYNC_EVERY = 1
#: object 0x6820 position value (000 Table 40)
POSITION = 0x6820
#: first encoder default PDO (000 Table 15: PDO9 = channels 0+1)
FIRST_POSITION_PDO = 9
#: the 29 identifier bits of a COB-ID entry
COB_ID_BITS = (1 << 29) - 1


def position_pdos(slots: int) -> list[tuple[int, list[int]]]:
    """Return (PDO number, slots carried) for the encoder default PDOs PDO9-12 in use."""
    return [(FIRST_POSITION_PDO + g, [s for s in (2 * g + 1, 2 * g + 2) if s <= slots])
            for g in range((slots + 1) // 2)]


@dataclass(frozen=True)
class PdoPlan:
    """One PDO the master maps and enables: direction, number, COB-ID, type, mapping."""

    transmit: bool
    number: int
    cob_id: int
    trans_type: int
    entries: tuple[tuple[int, int], ...]

    @property
    def com_index(self) -> int:
        """Its communication parameter object (0x1800 + n - 1 for TPDO n, 0x1400 + n - 1 for
        RPDO n)."""
        return (TPDO_COM if self.transmit else RPDO_COM) + self.number - 1


def pdo_plan(slots: int, node_id: int, *, images: bool = True) -> list[PdoPlan]:
    """What :meth:`SdoAccess.configure_pdos` sets up, in its order.

    TPDO s / RPDO s (s = 1..slots) carry slot s's process input / output image
    (0x2000:s / 0x2100:s); the encoder default PDOs 9.. carry 0x6820 of slot pairs.
    TPDOs are synchronous (type 1), the image RPDOs event driven (type 255, applied on
    reception, so the handshake does not wait an extra cycle).

    :param slots: modules in the station (1-8)
    :param node_id: the gateway's node id (the PDOs' COB-IDs are its defaults)
    :param images: also the image PDOs of each slot, not only the encoder default PDOs
    :returns: one entry per PDO, in the order it is configured
    """
    plan = [PdoPlan(True, pdo, tpdo_cob_base(pdo) + node_id, TRANS_SYNC_EVERY,
                    tuple((POSITION, s) for s in carried))
            for pdo, carried in position_pdos(slots)]
    if images:
        for slot in range(1, slots + 1):
            plan += [PdoPlan(True, slot, tpdo_cob_base(slot) + node_id, TRANS_SYNC_EVERY,
                             ((PROCESS_INPUT, slot),)),
                     PdoPlan(False, slot, rpdo_cob_base(slot) + node_id, TRANS_EVENT,
                             ((PROCESS_OUTPUT, slot),))]
    return plan


def abort_meaning(code: int) -> str:
    """The CiA 301 meaning of SDO abort ``code`` as canopen words it (``SdoAbortedError.CODES``),
    or that the code is none of CiA 301's."""
    return SdoAbortedError.CODES.get(
        code, f"abort code 0x{code:08X} is not defined by CiA 301 (manufacturer specific?)")


class SdoAccess:
    """Serialised, typed SDO access to one station, whose ``RemoteNode`` it makes (``node``).

    :param node_id: the station's node id
    :param dictionary: its object dictionary (``base/od.build_dictionary``)
    :param timeout: bound of one transfer step (s): one repeat after a lost frame, each
        attempt waiting half of it
    :param counters: where set-aside answers are counted (``stale_sdo_answers``); a private
        set when None
    """

    def __init__(self, node_id: int, dictionary: canopen.ObjectDictionary, timeout: float,
                 counters: ClientCounters | None = None) -> None:
        self.lock = threading.RLock()
        #: the station's node id (canopen's ``RemoteNode.id`` is typed ``int | None``)
        self.node_id = node_id
        self.counters = counters if counters is not None else ClientCounters()
        self._stale_log = RateLimitedLog(logger)
        #: the station; its SDO client takes only the answer to its current request
        self.node: canopen.RemoteNode = CheckedRemoteNode(
            node_id, dictionary, timeout=timeout, judge=SdoAnswers, on_stale=self._stale)
        self.timeout = timeout
        #: SDO transfers that got no answer
        self.timeouts = 0
        #: SDO transfers the gateway aborted
        self.aborts = 0

    def _stale(self, frame: bytes, why: str) -> None:
        """A frame on the station's SDO response COB-ID that answers no current request."""
        self.counters.stale_sdo_answers += 1
        self._stale_log.log(logging.INFO, "stale", "SDO answer %s of node %d set aside: %s",
                            frame.hex(" "), self.node.id, why)

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

    def read(self, index: int, subindex: int = 0) -> int | float | bytes | str:
        """Upload one object, decoded by the dictionary (raises SdoAbortError,
        GatewayUnavailable or BusError).

        :param index: the object's index
        :param subindex: its sub-index
        :returns: its value
        """
        with self.lock:
            try:
                var = self.node.sdo[index]
                var = var[subindex] if not isinstance(var, SdoVariable) else var
                return var.raw
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "upload", index, subindex) from err

    def read_image(self, index: int, subindex: int) -> bytes:
        """Upload a process image (0x2000 / 0x2100, UNSIGNED64 in ``base/od.py``) as its 8
        bytes, little endian (raises SdoAbortError / GatewayUnavailable, BusError for a value
        that is no image).

        :param index: the object's index
        :param subindex: its sub-index
        :returns: the image's 8 bytes
        :raises BusError: the value read is no process image (a float or text)
        """
        raw = self.read(index, subindex)
        if isinstance(raw, float | str):
            raise BusError(f"0x{index:04X}:{subindex:02X} read as {raw!r}, not a process image")
        return int(raw).to_bytes(8, "little") if isinstance(raw, int) else bytes(raw)

    def write(self, index: int, subindex: int, value: int | float | bytes) -> None:
        """Download one object, encoded by the dictionary (raises SdoAbortError,
        GatewayUnavailable or BusError).

        :param index: the object's index
        :param subindex: its sub-index
        :param value: the value to write
        """
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
        GatewayUnavailable or BusError (the interface refused the request).

        :param index: the object's index
        :param subindex: its sub-index
        :returns: the object's bytes as the station sent them
        """
        with self.lock:
            try:
                return bytes(self.node.sdo.upload(index, subindex))
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "upload", index, subindex) from err

    def download(self, index: int, subindex: int, data: bytes) -> None:
        """Download raw bytes to one object (raises SdoAbortError, GatewayUnavailable or
        BusError).

        :param index: the object's index
        :param subindex: its sub-index
        :param data: the bytes to write
        """
        with self.lock:
            try:
                self.node.sdo.download(index, subindex, data)
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "download", index, subindex) from err

    def configure_pdos(self, slots: int, *, images: bool = True) -> None:
        """Map and enable what the bridge consumes (:func:`pdo_plan`); every PDO is invalid
        by default. Raises SdoAbortError, GatewayUnavailable or BusError.

        :param slots: modules in the station (1-8)
        :param images: also the image PDOs, as for :func:`pdo_plan`
        """
        with self.lock:
            try:
                for pdo in pdo_plan(slots, self.node_id, images=images):
                    pdo_map = (self.node.tpdo if pdo.transmit else self.node.rpdo)[pdo.number]
                    self._setup(pdo_map, pdo.cob_id, pdo.trans_type, list(pdo.entries))
            except (SdoAbortedError, SdoCommunicationError, can.CanError) as err:
                raise self._fail(err, "PDO configuration", RPDO_COM, 0) from err

    def pdos_configured(self, slots: int, *, images: bool = True) -> bool:
        """True when every PDO :meth:`configure_pdos` enables is still valid on its COB-ID.

        One upload of sub-index 1 (COB-ID) of each communication parameter. Raises
        GatewayUnavailable / SdoAbortError.

        :param slots: modules in the station (1-8)
        :param images: whether the image PDOs were configured too, as for :func:`pdo_plan`
        :returns: False as soon as one PDO is invalid or on another COB-ID
        """
        for pdo in pdo_plan(slots, self.node_id, images=images):
            found = int.from_bytes(self.upload(pdo.com_index, 1)[:4], "little")
            if found & (PDO_INVALID | COB_ID_BITS) != pdo.cob_id:
                logger.info("0x%04X:01 is 0x%08X, configured was 0x%03X (valid): the PDOs "
                            "are no longer the configured ones", pdo.com_index, found,
                            pdo.cob_id)
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
