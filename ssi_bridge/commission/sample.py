"""Sample the XN-1SSI modules of the stations found: raw frames, positions, status bits.

Only what the register read handshake needs is written (000 "Internal registers"): each
slot's REG_RD_ADR (process output byte 4, object 0x2100) is set to REG_SSI_FRAME (33) so that
REG_RD_DATA of every process input image carries the raw frame, and set back to the address
it held before when sampling ends. The images are read over SDO (0x2000:slot, 0x6820:slot),
one SYNC per round for all stations, so nothing needs a PDO, an NMT command or a parameter
change; a gateway in PRE-OPERATIONAL runs a module cycle per SYNC too (CiA 301 SYNC).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ssi_bridge.client.handshake import OUT_RD_ADR, Handshake
from ssi_bridge.client.sdo import POSITION, SdoAccess
from ssi_bridge.exceptions import BusError, GatewayUnavailable, SdoAbortError
from ssi_bridge.protocol.dictionary import PROCESS_INPUT, PROCESS_OUTPUT
from ssi_bridge.protocol.images import ADDRESS_MASK, IMAGE_SIZE, ModuleStatus, ProcessInput
from ssi_bridge.protocol.registers import Reg

logger = logging.getLogger(__name__)

#: samples per slot the sampling waits for beyond ``seconds``: fewer tell a code or a
#: direction poorly (a busy host, many slots)
MIN_SAMPLES = 30
#: how many times ``seconds`` the sampling may last while a slot lacks MIN_SAMPLES
MAX_SECONDS_FACTOR = 10
#: one handshake step (s): a few SDO round trips and a module cycle
STEP_TIMEOUT = 0.5


class SdoImagePort:
    """The handshake's :class:`~ssi_bridge.client.handshake.ImagePort` over SDO.

    The output image is written whole to 0x2100:slot (bytes 6/7 as they were read, so the
    comparator and STOP bits are never touched); an input image is read from 0x2000:slot
    after a SYNC, so it was produced after the last write.

    :param sdo: SDO access to the gateway
    :param send_sync: sends one SYNC
    """

    def __init__(self, sdo: SdoAccess, send_sync: Callable[[], None]) -> None:
        self.sdo = sdo
        self.send_sync = send_sync
        #: the output image per slot as this port last wrote or read it
        self.outputs: dict[int, bytearray] = {}
        #: the output image per slot before the port changed anything
        self.original: dict[int, bytes] = {}

    def load(self, slot: int) -> bytes:
        """Read slot's output image (0x2100:slot) and keep it as the one to restore."""
        raw = self.sdo.upload(PROCESS_OUTPUT, slot)[:IMAGE_SIZE].ljust(IMAGE_SIZE, b"\0")
        self.outputs[slot] = bytearray(raw)
        self.original.setdefault(slot, bytes(raw))
        return raw

    def edit_output(self, slot: int, edit: Callable[[bytearray], None]) -> None:
        """Apply ``edit`` to bytes 0-5 of the slot's output image and write it."""
        if slot not in self.outputs:
            self.load(slot)
        scratch = bytearray(self.outputs[slot])
        edit(scratch)
        self.outputs[slot][0:6] = scratch[0:6]
        self.sdo.download(PROCESS_OUTPUT, slot, bytes(self.outputs[slot]))

    def read_input(self, slot: int) -> ProcessInput:
        """The slot's current process input image (0x2000:slot)."""
        raw = self.sdo.upload(PROCESS_INPUT, slot)[:IMAGE_SIZE].ljust(IMAGE_SIZE, b"\0")
        return ProcessInput.decode(raw)

    def next_input(self, slot: int, timeout: float) -> ProcessInput | None:
        """A SYNC, then the input image (None when the gateway did not answer).

        :param slot: the module's slot
        :param timeout: unused: one SDO transfer is bounded by its own timeout
        """
        try:
            self.send_sync()
            return self.read_input(slot)
        except GatewayUnavailable:
            return None

    def alive(self) -> bool:
        """The SDO answers are the sign of life here (no heartbeat is configured)."""
        return True

    def set_read_address(self, slot: int, addr: int) -> None:
        """Put ``addr`` into REG_RD_ADR (output byte 4) and leave it there.

        :param slot: the module's slot
        """
        def put(out: bytearray) -> None:
            out[OUT_RD_ADR] = addr & ADDRESS_MASK
        self.edit_output(slot, put)

    def restore(self, slot: int) -> None:
        """Write REG_RD_ADR back to what it was before (raises BusError).

        :param slot: the module's slot
        """
        if slot in self.original:
            before = self.original[slot][OUT_RD_ADR]
            self.set_read_address(slot, before)


def read_register(port: SdoImagePort, slot: int, addr: int) -> int:
    """Read one register through the 000 read handshake; REG_RD_ADR is set back after.

    :param port: the slot's image port over SDO
    :param slot: the module's slot
    :param addr: the register
    :raises RegisterReadError: the module aborted the read
    :raises HandshakeTimeout: a step got no answer
    """
    port.load(slot)
    return Handshake(port, STEP_TIMEOUT, 3 * STEP_TIMEOUT).read(slot, addr)


@dataclass
class Sample:
    """One module cycle of one slot.

    The module latched the frame after the SYNC was sent and before its image answered, so
    ``(t, t_read)`` bounds the latch time however late the threads ran (a busy host).
    """

    #: monotonic time (s) the round's SYNC had been sent
    t: float
    #: REG_SSI_FRAME (None when the image did not show it)
    frame: int | None
    #: REG_SSI_POS (0x6820)
    position: int | None
    sts: ModuleStatus
    ssi_sts: int
    #: monotonic time (s) the image had been read (``t`` when not measured)
    t_read: float | None = None

    @property
    def latch(self) -> tuple[float, float]:
        """Earliest and latest time (s) the module can have latched this cycle."""
        return self.t, self.t if self.t_read is None else self.t_read


@dataclass
class SlotSamples:
    """The samples of one slot and the reasons some were missed."""

    node_id: int
    slot: int
    samples: list[Sample] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)

    def frames(self) -> list[int]:
        """The frames of the cycles that showed one and had no ERR_SSI."""
        return [s.frame for s in self.samples
                if s.frame is not None and not s.sts & ModuleStatus.ERR_SSI]

    def latches(self) -> list[tuple[float, float]]:
        """The latch bounds (:attr:`Sample.latch`) of the samples :meth:`frames` returns."""
        return [s.latch for s in self.samples
                if s.frame is not None and not s.sts & ModuleStatus.ERR_SSI]

    def share(self, flag: ModuleStatus) -> float:
        """Share of the samples with ``flag`` set in process input byte 7."""
        return (sum(1 for s in self.samples if s.sts & flag) / len(self.samples)
                if self.samples else 0.0)


Target = tuple[SdoImagePort, int, int]  # port, node id, slot


def sample(targets: list[Target], send_sync: Callable[[], None], seconds: float,
           progress: Callable[[str], None] | None = None) -> list[SlotSamples]:
    """Sample every (port, node id, slot) for ``seconds``: one SYNC per round for all.

    Past ``seconds`` sampling goes on, up to :data:`MAX_SECONDS_FACTOR` times as long,
    until every slot has :data:`MIN_SAMPLES` samples: a busy host or a slow gateway takes
    fewer rounds a second, not fewer samples.

    REG_RD_ADR of each slot is set to REG_SSI_FRAME first and set back at the end (also
    when sampling fails). A slot whose gateway stops answering is noted, not fatal.

    :param targets: (port, node id, slot) of every slot to sample
    :param send_sync: sends one SYNC
    :param progress: a progress line for a person
    """
    results = [SlotSamples(node, slot) for _, node, slot in targets]
    live: list[bool] = [True] * len(targets)
    for i, (port, node, slot) in enumerate(targets):
        try:
            port.load(slot)
            port.set_read_address(slot, Reg.REG_SSI_FRAME)
        except BusError as err:
            results[i].errors.append(f"REG_RD_ADR not set: {err}")
            live[i] = False
    start = time.monotonic()
    last_note = 0.0
    try:
        while any(live) and ((now := time.monotonic()) - start < seconds or (
                now - start < MAX_SECONDS_FACTOR * seconds and _short(results, live))):
            t = time.monotonic()  # before the SYNC: no module cycle of this round is earlier
            try:
                send_sync()
            except BusError as err:
                results[0].errors.append(f"SYNC not sent: {err}")
                break
            for i, (port, node, slot) in enumerate(targets):
                if live[i]:
                    live[i] = _one(port, slot, t, results[i])
            if progress is not None and now - last_note >= 0.5:
                last_note = now
                n = sum(len(r.samples) for r in results)
                progress(f"sampling {now - start:4.1f}/{seconds:g} s: {n} images of "
                         f"{len(targets)} slot(s)")
    finally:
        for i, (port, node, slot) in enumerate(targets):
            try:
                port.restore(slot)
            except BusError as err:
                results[i].errors.append(f"REG_RD_ADR not set back: {err}")
    return results


def _short(results: list[SlotSamples], live: list[bool]) -> bool:
    """A live slot has fewer than :data:`MIN_SAMPLES` samples yet."""
    return any(ok and len(r.samples) < MIN_SAMPLES for r, ok in zip(results, live))


def _one(port: SdoImagePort, slot: int, t: float, into: SlotSamples) -> bool:
    """One image and position of ``slot``; False when its gateway stopped answering."""
    try:
        image = port.read_input(slot)
        t_read = time.monotonic()
        position = int.from_bytes(port.sdo.upload(POSITION, slot)[:4].ljust(4, b"\0"),
                                  "little")
    except SdoAbortError as err:
        into.errors.append(str(err))
        return len(into.errors) < 5
    except BusError as err:
        into.errors.append(str(err))
        return False
    frame = (image.reg_rd_data if image.reg_rd_adr == Reg.REG_SSI_FRAME
             and not image.reg_rd_abort else None)
    into.samples.append(Sample(t, frame, position, image.sts, image.ssi_sts,
                               t_read=t_read))
    return True


__all__ = ["MAX_SECONDS_FACTOR", "MIN_SAMPLES", "Sample", "SdoImagePort", "SlotSamples", "read_register", "sample"]
