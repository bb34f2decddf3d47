"""Find the XN-GW-CANOPEN gateways on a bus and the XN-1SSI modules in their slots.

Three steps, reading only:

1. :func:`listen`: heartbeats and boot-ups (CiA 301 error control, 0x700 + node id) name the
   devices; SYNC, NMT commands or SDO requests name another master (one per bus, CiA 301);
   anything else that is not a CANopen frame is counted as garbage;
2. :func:`scan`: an SDO upload request of 0x1000 to every node id asked (0x600 + id, all at
   once) finds the silent ones by their answer (0x580 + id), so 127 ids take one window;
3. :func:`identify` reads the identity (0x1000 device type, 0x1008 device name, 0x1018) and
   :func:`find_slots` the slots: object 0x5801 (REG_PARA1, 000 Table 16) exists for a slot
   holding an XN-1SSI; any other slot aborts (0x06090011, no such sub-index).
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field

import can

from ssi_bridge.client.foreign import describe_frame, master_frames
from ssi_bridge.client.sdo import SdoAccess
from ssi_bridge.exceptions import BusError, GatewayUnavailable, SdoAbortError
from ssi_bridge.protocol.dictionary import (DEVICE_NAME, DEVICE_TYPE, MAX_SLOTS, NMT_COB_ID,
                                            NMT_ERROR_CONTROL, NMT_STATES, REVISION,
                                            SYNC_COB_ID)

#: SDO request / response COB-ID bases (CiA 301 pre-defined connection set)
SDO_REQUEST, SDO_RESPONSE = 0x600, 0x580
#: expedited upload request of 0x1000:00 (CiA 301 §7.2.4.3.3: ccs 2 = 0x40, index LE, sub)
UPLOAD_DEVICE_TYPE = bytes((0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0))
#: Encoder Config (REG_PARA1), one sub-index per XN-1SSI slot (000 Table 16)
ENCODER_CONFIG = 0x5801
#: 0x1018 identity sub-indices (CiA 301)
IDENTITY = 0x1018
IDENTITY_FIELDS = ("vendor_id", "product_code", "revision", "serial")


@dataclass
class Heard:
    """What a listening window heard."""

    window: float = 0.0
    #: node id -> NMT state of its last heartbeat ("BOOT-UP" for a boot-up message)
    heartbeats: dict[int, str] = field(default_factory=dict)
    #: words -> count of frames only a master sends
    masters: Counter[str] = field(default_factory=Counter)
    #: frames that are not CANopen of this bus: error, remote, extended, malformed heartbeats
    garbage: Counter[str] = field(default_factory=Counter)
    frames: int = 0

    def master_line(self) -> str:
        """The other master in one line ('' when none was heard)."""
        if not self.masters:
            return ""
        what = ", ".join(f"{n} x {w}" for w, n in self.masters.most_common(3))
        return f"another CANopen master is active: in {self.window:g} s it sent {what}"


def _garbage_kind(msg: can.Message) -> str | None:
    if msg.is_error_frame:
        return "error frame"
    if msg.is_extended_id:
        return f"extended frame 0x{msg.arbitration_id:08X}"
    if msg.is_remote_frame:
        return f"remote frame 0x{msg.arbitration_id:03X}"
    return None


def listen(bus: can.BusABC, window: float) -> Heard:
    """Receive for ``window`` s; sort what came into devices, masters and garbage.

    :param bus: the open bus to receive on
    :param window: how long to listen (s)
    """
    heard = Heard(window=window)
    frames = master_frames(list(range(1, 128)))
    end = time.monotonic() + window
    while (left := end - time.monotonic()) > 0:
        try:
            msg = bus.recv(min(left, 0.05))
        except (can.CanError, OSError, ValueError) as err:
            heard.garbage[f"undecodable frame ({type(err).__name__})"] += 1
            continue
        if msg is None:
            continue
        note(heard, msg, frames)
    return heard


def note(heard: Heard, msg: can.Message, frames: dict[int, str] | None = None) -> None:
    """Sort one received frame into ``heard``.

    :param heard: what was heard so far (updated)
    :param msg: the received frame
    :param frames: the COB-IDs only a master sends, named (default: those of node ids 1-127)
    """
    frames = frames if frames is not None else master_frames(list(range(1, 128)))
    heard.frames += 1
    kind = _garbage_kind(msg)
    if kind:
        heard.garbage[kind] += 1
        return
    cob, data = msg.arbitration_id, bytes(msg.data)
    if cob in frames and (cob in (SYNC_COB_ID, NMT_COB_ID) or len(data) == 8):
        heard.masters[describe_frame(cob, data, frames)] += 1
    elif NMT_ERROR_CONTROL < cob <= NMT_ERROR_CONTROL + 127:
        state = NMT_STATES.get(data[0] & 0x7F) if len(data) == 1 else None
        if state is None:
            heard.garbage[f"malformed heartbeat on 0x{cob:03X} ({data.hex() or 'empty'})"] += 1
        else:
            heard.heartbeats[cob - NMT_ERROR_CONTROL] = state


def scan(bus: can.BusABC, node_ids: list[int], window: float) -> set[int]:
    """Node ids among ``node_ids`` that answer an SDO upload of 0x1000 within ``window`` s.

    Reads only (an upload request changes nothing on a CiA 301 device). Raises BusError
    when the interface refuses to send.

    :param bus: the open bus
    :param node_ids: the node ids to ask
    :param window: how long to wait for answers (s)
    """
    for node_id in node_ids:
        try:
            bus.send(can.Message(arbitration_id=SDO_REQUEST + node_id, is_extended_id=False,
                                 data=UPLOAD_DEVICE_TYPE))
        except can.CanError as err:
            raise BusError(f"SDO scan: request to node {node_id} not sent: {err}") from err
    found: set[int] = set()
    wanted = {SDO_RESPONSE + n: n for n in node_ids}
    end = time.monotonic() + window
    while (left := end - time.monotonic()) > 0:
        try:
            msg = bus.recv(min(left, 0.05))
        except (can.CanError, OSError, ValueError):
            continue
        if msg is not None and not msg.is_error_frame and msg.arbitration_id in wanted:
            found.add(wanted[msg.arbitration_id])
    return found


@dataclass
class Identity:
    """The identity objects of one device (CiA 301 0x1000, 0x1008, 0x1018)."""

    node_id: int
    device_type: int | None = None
    name: str | None = None
    vendor_id: int | None = None
    product_code: int | None = None
    revision: int | None = None
    serial: int | None = None
    #: why it is not an XN-GW-CANOPEN (None: it is one)
    refusal: str | None = None
    #: notes (an old firmware, an object that did not answer)
    notes: list[str] = field(default_factory=list)


def _u32(sdo: SdoAccess, index: int, sub: int = 0) -> int:
    return int.from_bytes(sdo.upload(index, sub)[:4].ljust(4, b"\0"), "little")


def identify(sdo: SdoAccess) -> Identity:
    """Read the identity of ``sdo``'s node and say whether it is an XN-GW-CANOPEN.

    An XN-GW-CANOPEN has device type 0x191 (CiA 401) and device name "XN-GW-CANOPEN"; it
    serves XN-1SSI modules from firmware V3.00 (000 ch. 4, revision 0x00030000).
    Raises GatewayUnavailable when the node does not answer at all.
    """
    ident = Identity(sdo.node_id)
    ident.device_type = _u32(sdo, 0x1000)
    try:
        ident.name = sdo.upload(0x1008, 0).decode("latin-1").rstrip("\0 ")
    except SdoAbortError as err:
        ident.notes.append(f"no device name (0x1008: {err.meaning})")
    for sub, name in enumerate(IDENTITY_FIELDS, start=1):
        try:
            setattr(ident, name, _u32(sdo, IDENTITY, sub))
        except SdoAbortError:
            pass
    if ident.device_type != DEVICE_TYPE or ident.name != DEVICE_NAME:
        ident.refusal = (f"not an {DEVICE_NAME}: device type 0x{ident.device_type:08X}, "
                         f"name {ident.name!r} (an {DEVICE_NAME} has 0x{DEVICE_TYPE:08X}, "
                         f"{DEVICE_NAME!r})")
    elif ident.revision is not None and ident.revision < REVISION:
        ident.notes.append(f"firmware 0x{ident.revision:08X} is older than V3.00, from which "
                           "XN-GW-CANOPEN supports XN-1SSI modules (000 ch. 4)")
    return ident


@dataclass
class SlotProbe:
    """What one slot answered: REG_PARA1 from 0x5801, or why it holds no XN-1SSI."""

    slot: int
    para1: int | None = None
    absent: str | None = None


def find_slots(sdo: SdoAccess) -> list[SlotProbe]:
    """Probe slots 1-8 by 0x5801:slot; raises GatewayUnavailable when the node falls silent.

    :param sdo: SDO access to the gateway
    :raises GatewayUnavailable: the node stopped answering
    """
    probes = []
    for slot in range(1, MAX_SLOTS + 1):
        try:
            probes.append(SlotProbe(slot, para1=_u32(sdo, ENCODER_CONFIG, slot)))
        except SdoAbortError as err:
            probes.append(SlotProbe(slot, absent=f"no XN-1SSI (0x{ENCODER_CONFIG:04X}:"
                                                 f"{slot:02X} aborted 0x{err.code:08X}: "
                                                 f"{err.meaning})"))
        except GatewayUnavailable:
            raise
    return probes


__all__ = ["ENCODER_CONFIG", "Heard", "Identity", "SlotProbe", "find_slots", "identify",
           "listen", "note", "scan"]
