"""Fault injection into the simulated station through its simulation-only SDO objects.

A master injects a fault by writing 0x4000 (rate), 0x4001 (duration in ms) and then
0x4002 (command: kind in bits 0-7, slot in bits 8-15, slot 0 = the bus); 0x4003 reads the
kinds in force as a bit mask. 0x4004 reads the station's motion epoch (``epoch_us``): the wire
time in microseconds at which its encoders' motion time is 0, so a checker outside the
station knows where every shaft was at any wire time without fitting it. Each fault acts where a real one would: a broken wire or noise
on a slot's SSI line, an error or power-failure bit in its encoder, an invalid REG_PARA1 set
at its module's parameter interface (ERR_PARA), lost CAN frames or a silent gateway on the
bus, the error frames of a master's controller gone bus-off (the station then silent, as a
bus-off controller hears nothing) or error passive (``error_frames.py``), a gateway that
queues every received frame and answers every SYNC however late (QUEUE_BACKLOG: some real
devices queue; ``controller.py``). Objects in
``docs/canopen.md`` and ``config/xn_gw_canopen.eds``.

The station keeps the time itself: a fault with a duration is cleared on the station's clock,
also while the gateway is silent, so nothing depends on a master reaching it. A clear
(``CLEAR_ALL``) takes effect at once, before the gateway answers, so it is answered even when
the gateway was silent; a fault that mutes or drops the gateway's own frames
(``GATEWAY_SILENT``, ``CAN_FRAME_LOSS``) takes effect just after the answer has been sent.
"""

from __future__ import annotations

import logging
import math
import struct
import threading
import time
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING, Any, Protocol

from canopen import SdoAbortedError

from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.sim.gateway.error_frames import report_error_frames
from ssi_bridge.protocol.dictionary import (
    SIM_ACTIVE, SIM_COMMAND, SIM_DURATION, SIM_EPOCH, SIM_RATE,
)

if TYPE_CHECKING:
    from ssi_bridge.sim.gateway.gateway import XnGateway

logger = logging.getLogger(__name__)


class FaultKind(IntEnum):
    """Fault kinds, numbered as the constants of ssi_bridge_msgs/srv/InjectFault."""

    CLEAR_ALL = 0
    DATA_WIRE_BREAK = 1
    CLOCK_WIRE_BREAK = 2
    ENCODER_ERROR = 3
    POWER_FAILURE = 4
    BIT_NOISE = 5
    CAN_FRAME_LOSS = 6
    GATEWAY_SILENT = 7
    INVALID_PARA1 = 8
    BUS_OFF = 9
    ERROR_PASSIVE = 10
    QUEUE_BACKLOG = 11


#: faults of the bus or gateway (slot 0 in the command)
BUS_FAULTS = (FaultKind.CAN_FRAME_LOSS, FaultKind.GATEWAY_SILENT, FaultKind.BUS_OFF,
              FaultKind.ERROR_PASSIVE, FaultKind.QUEUE_BACKLOG)
#: faults under which the station sends nothing (only CLEAR_ALL reaches it)
MUTING_FAULTS = (FaultKind.GATEWAY_SILENT, FaultKind.BUS_OFF)
#: faults that need a rate in (0, 1]
RATE_FAULTS = (FaultKind.BIT_NOISE, FaultKind.CAN_FRAME_LOSS)


def epoch_us(epoch: float) -> int:
    """The 0x4004 value of a motion epoch (wire time, s): whole microseconds, rounded."""
    return round(epoch * 1_000_000)


def command_word(kind: int, slot: int) -> int:
    """The 0x4002 value: kind in bits 0-7, slot (0 = bus) in bits 8-15."""
    return (int(kind) & 0xFF) | (int(slot) & 0xFF) << 8


@dataclass(frozen=True)
class StationFault:
    """A fault in force in the station: what, in which slot, how hard, until when (or None)."""

    kind: FaultKind
    slot: int
    rate: float
    until: float | None


class Channels(Protocol):
    """The station's joints (``SimStation``): the encoder, line and module wired to a slot."""

    def channel_in_slot(self, slot: int) -> Any:
        """The ``SimChannel`` of ``slot`` (1-based), None for an empty slot."""


class SimulationControl:
    """Serves 0x4000-0x4004 on a gateway and applies the faults to its station's channels.

    :param sim: the station's channels the faults act on
    :param gateway: the gateway whose objects 0x4000-0x4004 are served
    :param clock: the monotonic clock of fault durations
    """

    def __init__(self, sim: Channels, gateway: XnGateway,
                 clock: object = time.monotonic) -> None:
        self._sim = sim
        self._gateway = gateway
        self._clock = clock
        self._rate = 0.0
        self._duration_ms = 0
        self.active: list[StationFault] = []
        self._wake = threading.Condition()
        self._thread: threading.Thread | None = None
        self._stopping = False
        gateway.node.add_read_callback(self._on_read)
        gateway.node.add_write_callback(self._on_write)

    # -- life cycle ---------------------------------------------------------------------------
    def start(self) -> None:
        """Start the thread that ends faults whose duration ran out."""
        if self._thread is None:
            self._stopping = False
            self._thread = threading.Thread(target=self._run, name="sim-faults", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop that thread (the faults stay as they are)."""
        with self._wake:
            self._stopping = True
            self._wake.notify_all()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None

    # -- SDO ----------------------------------------------------------------------------------
    def _on_read(self, index: int, subindex: int, od: object) -> int | float | None:
        if index == SIM_ACTIVE:
            return self.active_mask()
        if index == SIM_RATE:
            return self._rate
        if index == SIM_DURATION:
            return self._duration_ms
        if index == SIM_EPOCH:
            return epoch_us(self._gateway.clock.epoch)
        return None

    def _on_write(self, index: int, subindex: int, od: object, data: bytes) -> None:
        if index == SIM_RATE:
            (rate,) = struct.unpack("<f", bytes(data[:4]))
            if not (math.isfinite(rate) and 0.0 <= rate <= 1.0):
                raise SdoAbortedError(SdoAbort.INVALID_VALUE)
            self._rate = float(rate)
        elif index == SIM_DURATION:
            self._duration_ms = int.from_bytes(bytes(data[:4]), "little")
        elif index == SIM_COMMAND:
            word = int.from_bytes(bytes(data[:2]), "little")
            self.command(word & 0xFF, word >> 8)

    def command(self, kind: int, slot: int) -> None:
        """Apply the command (raises SdoAbortedError for an impossible one).

        :param kind: the fault (a ``FaultKind``)
        :param slot: the module's slot (0: the bus)
        """
        try:
            fault = FaultKind(kind)
        except ValueError:
            raise SdoAbortedError(SdoAbort.INVALID_VALUE) from None
        if fault is FaultKind.CLEAR_ALL:
            self.clear_all()
            return
        channel = None
        if fault in BUS_FAULTS:
            if slot != 0:
                raise SdoAbortedError(SdoAbort.INVALID_VALUE)
        else:
            channel = self._sim.channel_in_slot(slot)
            if channel is None:
                raise SdoAbortedError(SdoAbort.INVALID_VALUE)
        if fault in RATE_FAULTS and not 0.0 < self._rate <= 1.0:
            raise SdoAbortedError(SdoAbort.INVALID_VALUE)
        duration = self._duration_ms / 1000.0
        until = self._clock() + duration if duration > 0 else None  # type: ignore[operator]
        entry = StationFault(fault, slot, self._rate, until)
        with self._wake:
            self.active.append(entry)
            self._wake.notify_all()
        if fault in BUS_FAULTS:
            # after the answer: the SDO server holds the gateway lock until it has replied
            threading.Thread(target=self._apply_after_reply, args=(entry,), daemon=True).start()
        else:
            self._apply(entry, channel, on=True)
        logger.warning("fault injected: %s in %s%s", fault.name,
                       f"slot {slot}" if slot else "the bus",
                       f" for {duration:g} s" if until is not None else "")

    def _apply_after_reply(self, entry: StationFault) -> None:
        with self._gateway.node.lock:
            with self._wake:
                if entry not in self.active:
                    return  # cleared meanwhile
            self._apply(entry, None, on=True)

    def active_mask(self) -> int:
        """The 0x4003 value: bit k set while a fault of kind k is in force."""
        mask = 0
        for fault in list(self.active):
            mask |= 1 << int(fault.kind)
        return mask

    def clear_all(self) -> None:
        """Remove every fault at once."""
        with self._gateway.node.lock:
            with self._wake:
                done, self.active = self.active, []
            for fault in done:
                self._apply(fault, self._sim.channel_in_slot(fault.slot), on=False)
        if done:
            logger.info("all faults cleared")

    def expire(self) -> list[StationFault]:
        """Clear the faults whose duration has run out; returns them."""
        now = self._clock()  # type: ignore[operator]
        with self._wake:
            done = [f for f in self.active if f.until is not None and now >= f.until]
            for fault in done:
                self.active.remove(fault)
        with self._gateway.node.lock:
            self._clear(done)
        return done

    def _clear(self, done: list[StationFault]) -> None:
        for fault in done:
            # a fault of the same kind still in force in the slot keeps it on
            if not any(f.kind is fault.kind and f.slot == fault.slot for f in self.active):
                self._apply(fault, self._sim.channel_in_slot(fault.slot), on=False)
            logger.info("fault %s in %s cleared after its duration", fault.kind.name,
                        f"slot {fault.slot}" if fault.slot else "the bus")

    def _run(self) -> None:
        while True:
            with self._wake:
                if self._stopping:
                    return
                deadlines = [f.until for f in self.active if f.until is not None]
                now = self._clock()  # type: ignore[operator]
                wait = None if not deadlines else max(0.0, min(deadlines) - now)
                if wait is None or wait > 0:
                    self._wake.wait(wait)
                    continue
            self.expire()

    def _apply(self, fault: StationFault, channel: Any, *, on: bool) -> None:
        kind, gateway = fault.kind, self._gateway
        if kind in MUTING_FAULTS:
            if gateway.bus is not None:
                # off only when no other muting fault is still in force
                gateway.silent = on or any(f.kind in MUTING_FAULTS for f in self.active)
                if kind is FaultKind.BUS_OFF:
                    report_error_frames(gateway.bus, bus_off=True, on=on)
        elif kind is FaultKind.ERROR_PASSIVE:
            if gateway.bus is not None:
                report_error_frames(gateway.bus, bus_off=False, on=on)
        elif kind is FaultKind.CAN_FRAME_LOSS:
            if gateway.bus is not None:
                gateway.bus.loss_rate = fault.rate if on else 0.0
        elif kind is FaultKind.QUEUE_BACKLOG:
            gateway.queue_backlog = on or any(f.kind is kind for f in self.active)
        elif channel is None:
            return
        elif kind is FaultKind.DATA_WIRE_BREAK:
            channel.line.faults.data_break = on
        elif kind is FaultKind.CLOCK_WIRE_BREAK:
            channel.line.faults.clock_break = on
        elif kind is FaultKind.BIT_NOISE:
            channel.line.faults.bit_error_rate = fault.rate if on else 0.0
        elif kind is FaultKind.ENCODER_ERROR:
            channel.encoder.set_error(on)
        elif kind is FaultKind.POWER_FAILURE:
            channel.encoder.power_failure = on
        elif kind is FaultKind.INVALID_PARA1:
            # an invalid set reaches the module's parameter interface (ERR_PARA, EMCY 0x7000 /
            # 0x10), past the master's own check; the clear sends the valid set again
            if on:
                channel.module.inject_parameter_error()
            else:
                channel.module.clear_parameter_error()
