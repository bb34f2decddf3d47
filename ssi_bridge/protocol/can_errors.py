"""SocketCAN error frames in words: the error classes and data bytes of linux/can/error.h.

A CAN controller does not put error frames on the wire as messages; SocketCAN reports what its
controller saw as an *error frame* to the application: ``can_id`` has CAN_ERR_FLAG set and the
error classes below as a bit mask (python-can: ``Message.is_error_frame`` and the mask in
``arbitration_id``), and the 8 data bytes (CAN_ERR_DLC) say more for some classes:

==========  ===================  =====================================================
class bit   name                 data
==========  ===================  =====================================================
0x001       CAN_ERR_TX_TIMEOUT   TX timeout (by the netdevice driver)
0x002       CAN_ERR_LOSTARB      data[0]: bit of the lost arbitration (0: unspecified)
0x004       CAN_ERR_CRTL         data[1]: controller status (warning, passive, overflow,
                                 back to error active)
0x008       CAN_ERR_PROT         data[2]: protocol violation type, data[3]: location
0x010       CAN_ERR_TRX          data[4]: transceiver status (CANH/CANL wire, short)
0x020       CAN_ERR_ACK          no ACK on transmission (no other node on the bus)
0x040       CAN_ERR_BUSOFF       the controller went bus-off
0x080       CAN_ERR_BUSERROR     bus error (may flood)
0x100       CAN_ERR_RESTARTED    the controller restarted (after bus-off)
0x200       CAN_ERR_CNT          data[6]: TX error counter, data[7]: RX error counter
==========  ===================  =====================================================

Error states by counter (ISO 11898-1, as error.h states them): 0-95 error active, 96-127
error warning, 128-255 error passive, 256 and more bus-off. Pure: no I/O, no clock, no can.
"""

from __future__ import annotations

from dataclasses import dataclass

#: error classes (the bit mask in the error frame's identifier), linux/can/error.h
CAN_ERR_TX_TIMEOUT = 0x001
CAN_ERR_LOSTARB = 0x002
CAN_ERR_CRTL = 0x004
CAN_ERR_PROT = 0x008
CAN_ERR_TRX = 0x010
CAN_ERR_ACK = 0x020
CAN_ERR_BUSOFF = 0x040
CAN_ERR_BUSERROR = 0x080
CAN_ERR_RESTARTED = 0x100
CAN_ERR_CNT = 0x200
#: data length of an error frame
CAN_ERR_DLC = 8

#: data[1], controller status
CAN_ERR_CRTL_RX_OVERFLOW = 0x01
CAN_ERR_CRTL_TX_OVERFLOW = 0x02
CAN_ERR_CRTL_RX_WARNING = 0x04
CAN_ERR_CRTL_TX_WARNING = 0x08
CAN_ERR_CRTL_RX_PASSIVE = 0x10
CAN_ERR_CRTL_TX_PASSIVE = 0x20
CAN_ERR_CRTL_ACTIVE = 0x40

#: class bit -> the short name used in counters, logs and diagnostics keys
CLASS_NAMES: dict[int, str] = {
    CAN_ERR_TX_TIMEOUT: "tx_timeout", CAN_ERR_LOSTARB: "lost_arbitration",
    CAN_ERR_CRTL: "controller", CAN_ERR_PROT: "protocol", CAN_ERR_TRX: "transceiver",
    CAN_ERR_ACK: "no_ack", CAN_ERR_BUSOFF: "bus_off", CAN_ERR_BUSERROR: "bus_error",
    CAN_ERR_RESTARTED: "restarted", CAN_ERR_CNT: "error_counters"}

#: data[2], protocol violation type (bits)
PROT_TYPES: dict[int, str] = {
    0x01: "single bit error", 0x02: "frame format error", 0x04: "bit stuffing error",
    0x08: "unable to send dominant bit", 0x10: "unable to send recessive bit",
    0x20: "bus overload", 0x40: "active error announcement", 0x80: "error on transmission"}
#: data[3], protocol violation location (values)
PROT_LOCATIONS: dict[int, str] = {
    0x03: "start of frame", 0x02: "ID bits 28-21", 0x06: "ID bits 20-18",
    0x04: "substitute RTR", 0x05: "identifier extension", 0x07: "ID bits 17-13",
    0x0F: "ID bits 12-5", 0x0E: "ID bits 4-0", 0x0C: "RTR", 0x0D: "reserved bit 1",
    0x09: "reserved bit 0", 0x0B: "data length code", 0x0A: "data section",
    0x08: "CRC sequence", 0x18: "CRC delimiter", 0x19: "ACK slot", 0x1B: "ACK delimiter",
    0x1A: "end of frame", 0x12: "intermission"}
#: data[4], transceiver status (values)
TRX_STATES: dict[int, str] = {
    0x04: "CANH no wire", 0x05: "CANH short to BAT", 0x06: "CANH short to VCC",
    0x07: "CANH short to GND", 0x40: "CANL no wire", 0x50: "CANL short to BAT",
    0x60: "CANL short to VCC", 0x70: "CANL short to GND", 0x80: "CANL short to CANH"}
_CRTL_BITS: dict[int, str] = {
    CAN_ERR_CRTL_RX_OVERFLOW: "RX buffer overflow", CAN_ERR_CRTL_TX_OVERFLOW: "TX buffer overflow",
    CAN_ERR_CRTL_RX_WARNING: "RX error warning", CAN_ERR_CRTL_TX_WARNING: "TX error warning",
    CAN_ERR_CRTL_RX_PASSIVE: "RX error passive", CAN_ERR_CRTL_TX_PASSIVE: "TX error passive",
    CAN_ERR_CRTL_ACTIVE: "back to error active"}

#: controller states, from best to worst
ERROR_ACTIVE, ERROR_WARNING, ERROR_PASSIVE, BUS_OFF = ("error active", "error warning",
                                                       "error passive", "bus-off")


@dataclass(frozen=True)
class ErrorFrame:
    """One decoded SocketCAN error frame.

    ``classes``: the names of the class bits set (:data:`CLASS_NAMES` order); ``state``: the
    controller state the frame reports (None: it reports none); ``details``: the data bytes in
    words; ``tx_errors`` / ``rx_errors``: the error counters (None unless CAN_ERR_CNT).
    """

    mask: int
    classes: tuple[str, ...]
    state: str | None
    details: tuple[str, ...]
    tx_errors: int | None = None
    rx_errors: int | None = None

    def text(self) -> str:
        """The frame in one line: "bus_off; controller: TX error passive"."""
        return "; ".join(self.details) if self.details else ", ".join(self.classes) or "none"


def _bits(value: int, names: dict[int, str]) -> list[str]:
    return [name for bit, name in names.items() if value & bit]


def _counter_state(tx: int, rx: int) -> str:
    worst = max(tx, rx)
    return ERROR_PASSIVE if worst >= 128 else ERROR_WARNING if worst >= 96 else ERROR_ACTIVE


def decode_error_frame(mask: int, data: bytes | bytearray) -> ErrorFrame:
    """Decode the class ``mask`` (the error frame's identifier) and its ``data`` bytes.

    Short data is read as zeros (unspecified). The state: bus-off for CAN_ERR_BUSOFF, error
    active for CAN_ERR_RESTARTED or a controller "back to error active", else passive /
    warning from the controller status bits, else from the error counters (CAN_ERR_CNT).
    """
    raw = bytes(data[:CAN_ERR_DLC]).ljust(CAN_ERR_DLC, b"\0")
    classes = tuple(name for bit, name in CLASS_NAMES.items() if mask & bit)
    details: list[str] = []
    state: str | None = None
    tx = rx = None
    if mask & CAN_ERR_TX_TIMEOUT:
        details.append("TX timeout")
    if mask & CAN_ERR_LOSTARB:
        details.append("lost arbitration" + (f" at bit {raw[0]}" if raw[0] else ""))
    if mask & CAN_ERR_CRTL:
        crtl = _bits(raw[1], _CRTL_BITS)
        details.append("controller: " + (", ".join(crtl) if crtl else "unspecified"))
        if raw[1] & CAN_ERR_CRTL_ACTIVE:
            state = ERROR_ACTIVE
        elif raw[1] & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE):
            state = ERROR_PASSIVE
        elif raw[1] & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING):
            state = ERROR_WARNING
    if mask & CAN_ERR_PROT:
        kind = ", ".join(_bits(raw[2], PROT_TYPES)) or "unspecified"
        where = PROT_LOCATIONS.get(raw[3], "unspecified location")
        details.append(f"protocol violation: {kind} at {where}")
    if mask & CAN_ERR_TRX:
        details.append("transceiver: " + TRX_STATES.get(raw[4], "unspecified"))
    if mask & CAN_ERR_ACK:
        details.append("no ACK on transmission (no other node on the bus?)")
    if mask & CAN_ERR_BUSERROR:
        details.append("bus error")
    if mask & CAN_ERR_CNT:
        tx, rx = raw[6], raw[7]
        details.append(f"error counters TX {tx} RX {rx}")
        if state is None:
            state = _counter_state(tx, rx)
    if mask & CAN_ERR_RESTARTED:
        details.append("controller restarted")
        state = ERROR_ACTIVE
    if mask & CAN_ERR_BUSOFF:
        details.append("bus-off")
        state = BUS_OFF
    return ErrorFrame(mask, classes, state, tuple(details), tx, rx)


__all__ = ["BUS_OFF", "CAN_ERR_ACK", "CAN_ERR_BUSERROR", "CAN_ERR_BUSOFF", "CAN_ERR_CNT",
           "CAN_ERR_CRTL", "CAN_ERR_CRTL_ACTIVE", "CAN_ERR_CRTL_RX_OVERFLOW",
           "CAN_ERR_CRTL_RX_PASSIVE", "CAN_ERR_CRTL_RX_WARNING", "CAN_ERR_CRTL_TX_OVERFLOW",
           "CAN_ERR_CRTL_TX_PASSIVE", "CAN_ERR_CRTL_TX_WARNING", "CAN_ERR_DLC", "CAN_ERR_LOSTARB",
           "CAN_ERR_PROT", "CAN_ERR_RESTARTED", "CAN_ERR_TRX", "CAN_ERR_TX_TIMEOUT",
           "CLASS_NAMES", "ERROR_ACTIVE", "ERROR_PASSIVE", "ERROR_WARNING", "ErrorFrame",
           "PROT_LOCATIONS", "PROT_TYPES", "TRX_STATES", "decode_error_frame"]
