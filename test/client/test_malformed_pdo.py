"""Frames are checked before they are believed: a TPDO whose length differs from its mapping.

The master maps TPDO s to the 8-byte process input image of slot s and TPDO 9 to 0x6820
(Integer32, 4 bytes per slot) (000 Table 15). A frame on those COB-IDs with another length is
no frame of that mapping (CiA 301: a PDO shorter than its mapping is an error): it is counted
and never decoded, so the slot keeps its last good sample. Before, a DLC 5 or 7 frame was
decoded from its first bytes and published as a position of -1 098 066 rad.
"""

from __future__ import annotations

import can

from ssi_bridge.protocol.dictionary import tpdo_cob_base
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus

from .conftest import wait_until

NODE = 5  # the station fixture's gateway


def test_tpdos_of_a_wrong_length_are_counted_and_never_decoded(station, channel, caplog):
    _gateway, client, readers = station
    client.sync()
    assert client.wait_cycle(1.0)
    good = client.latest(1)
    assert good is not None and good.position == readers[0].value
    intruder = wire_bus(BusConfig(channel=channel, node_id=NODE))
    try:
        frames = [(tpdo_cob_base(1) + NODE, bytes([0xFF] * n)) for n in (5, 7)]
        frames.append((tpdo_cob_base(9) + NODE, b"\xff\xff\xff"))  # 3 of 0x6820's 4 bytes
        for can_id, data in frames:
            intruder.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        wait_until(lambda: client.counters.malformed_pdos == 3,
              f"malformed TPDOs counted: {client.counters.malformed_pdos} of 3")
    finally:
        intruder.shutdown()
    after = client.latest(1)
    assert after is not None
    assert after.position == good.position and after.process_input == good.process_input
    lines = [r for r in caplog.records if "its mapping has" in r.getMessage()]
    assert 1 <= len(lines) <= 2, [r.getMessage() for r in lines]  # once per second per kind
    client.sync()
    assert client.wait_cycle(1.0), "the next cycle's good TPDOs are taken again"
    assert client.latest(1).position == readers[0].value
