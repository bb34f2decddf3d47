"""The bridge's per-cycle CAM state (``~/status`` cam_state) equals object 0x6B00 (000 Table 42).

The node reads the CAM objects 0x6B01 / 0x6B10 / 0x6B20 / 0x6B02 over SDO and computes the
state from REG_SSI_POS each cycle (``core/frame_watch.py``, ROS-free); here the same reads go
through the real client and SDO, and the result is compared with the gateway's own 0x6B00.
"""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.registers import Reg
from ssi_bridge.core.frame_watch import FrameWatch, read_cam


def _watch_from_objects(client, slot: int) -> FrameWatch:
    """What the node does on its diagnostics timer (``refresh_cams``)."""
    watch = FrameWatch(None, 0x19010000)
    watch.set_cam(read_cam(lambda index: int(client.read_object(index, slot))))
    return watch


@pytest.mark.parametrize("low, high, polarity, value", [
    (1000, 2000, 0, 1234),      # inside -> 0x01
    (1300, 2000, 0, 1234),      # outside -> 0x00
    (1000, 2000, 1, 1234),      # inside, inverted by 0x6B02 -> 0x00
    (-10, 10, 0, 5),            # Integer32 limits (0x6B10/0x6B20 are Integer32)
])
def test_cam_state_matches_object_6b00(station, low, high, polarity, value) -> None:
    gateway, client, readers = station
    readers[0].value = value
    client.write_register(1, Reg.REG_CMP2, low & 0xFFFFFFFF)    # CAM1 low limit = REG_CMP2
    client.write_register(1, Reg.REG_CMP1, high & 0xFFFFFFFF)   # CAM1 high limit = REG_CMP1
    client.write_object(0x6B01, 1, 1)
    client.write_object(0x6B02, 1, polarity)
    client.sync()
    assert client.wait_cycle(1.0)
    sample = client.latest(1)
    watch = _watch_from_objects(client, 1)
    assert watch.cam_state(sample.position) == int(client.read_object(0x6B00, 1))
    client.write_object(0x6B01, 1, 0)   # comparison off -> 0x00 (0x01 with polarity 1)
    assert _watch_from_objects(client, 1).cam_state(sample.position) == polarity == int(
        client.read_object(0x6B00, 1))
