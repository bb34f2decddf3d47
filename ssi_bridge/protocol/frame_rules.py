"""The lengths CiA 301 fixes for the frames of its services, for both ends of the wire.

A frame on a service's COB-ID with another length is no frame of that service: the receiver
counts it as malformed and drops it before any handler decodes it (canopen's handlers unpack
it blindly: an empty heartbeat raises in ``NmtMaster.on_heartbeat``, a short SDO request in
``SdoServer.on_request``). The rules of one end name only the COB-IDs it consumes, with its
stations' node ids, so a PDO another node maps onto the same identifier range is not judged:

* the master: heartbeat / boot-up 0x700 + id (1 byte: the NMT state), EMCY 0x080 + id (8 bytes:
  error code, error register, 5 manufacturer bytes) and the SDO responses 0x580 + id (8 bytes);
* a station: NMT module control 0x000 (2 bytes: command specifier, node id) and the SDO
  requests 0x600 + id (8 bytes).

Every SDO frame of CiA 301's expedited, segmented and abort protocols is 8 bytes long; the
unused bytes are sent, not left out.
"""

from __future__ import annotations

from dataclasses import dataclass

from ssi_bridge.protocol.dictionary import NMT_COB_ID, NMT_ERROR_CONTROL

#: CiA 301 COB-ID bases of EMCY and of the SDO server's responses and requests (+ node id)
EMCY_COB_BASE, SDO_RESPONSE_BASE, SDO_REQUEST_BASE = 0x080, 0x580, 0x600
#: bytes of the fixed-length services (CiA 301)
HEARTBEAT_BYTES, EMCY_BYTES, SDO_BYTES, NMT_COMMAND_BYTES = 1, 8, 8, 2


@dataclass(frozen=True)
class FrameRule:
    """What a COB-ID carries and the one length its frames have."""

    #: the service, as a log line names it ("heartbeat of node 1")
    service: str
    length: int

    def problem(self, length: int) -> str | None:
        """Why a frame of ``length`` bytes is no frame of this service, or None."""
        if length == self.length:
            return None
        return f"no {self.service} (CiA 301: {self.length} byte(s))"


def master_rules(node_id: int) -> dict[int, FrameRule]:
    """The COB-IDs a master consumes of station ``node_id``, with their frames' length."""
    return {
        NMT_ERROR_CONTROL + node_id: FrameRule(f"heartbeat of node {node_id}", HEARTBEAT_BYTES),
        EMCY_COB_BASE + node_id: FrameRule(f"EMCY of node {node_id}", EMCY_BYTES),
        SDO_RESPONSE_BASE + node_id: FrameRule(f"SDO response of node {node_id}", SDO_BYTES),
    }


def station_rules(node_id: int) -> dict[int, FrameRule]:
    """The COB-IDs station ``node_id`` consumes with a fixed length (not SYNC, not RPDOs)."""
    return {
        NMT_COB_ID: FrameRule("NMT command", NMT_COMMAND_BYTES),
        SDO_REQUEST_BASE + node_id: FrameRule(f"SDO request to node {node_id}", SDO_BYTES),
    }


__all__ = ["EMCY_BYTES", "EMCY_COB_BASE", "FrameRule", "HEARTBEAT_BYTES", "NMT_COMMAND_BYTES",
           "SDO_BYTES", "SDO_REQUEST_BASE", "SDO_RESPONSE_BASE", "master_rules",
           "station_rules"]
