"""The station as a generic CiA 406 tool sees it: a plain canopen RemoteNode from the EDS alone.

000 chapter 4 ("Overview of Encoders Device Profile Range", Table 16): the encoder objects are
the DS406 (CiA 406) objects of the gateway's second logical device, each at its CiA 406 index
+ 0x800; 0x6FFF (= 67FFh + 0x800) holds that device's type 0x000A0196 (Table 49: profile 406,
multi-sensor encoder interface). A tool that knows nothing of this project finds the profile
there and reads position (6020h, 000 Table 40), preset (6010h, Table 39), CAM state (6300h,
Table 42) and area state (6400h) at +0x800. The master here is canopen's own, on a plain
python-can ``virtual`` bus; the station is the simulated one with its timed wire.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import canopen
import pytest

from ssi_bridge.base.od import build_dictionary
from ssi_bridge.protocol.dictionary import ENCODER_OBJECTS, ENCODER_PROFILE_OFFSET
from ssi_bridge.protocol.settings import station_settings
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.sim.gateway.station import Station
from ssi_bridge.sim.supervisor.boot import BootWatch

REPO = Path(__file__).resolve().parents[3]
EDS = REPO / "config" / "xn_gw_canopen.eds"
DOC = REPO / "docs" / "canopen.md"
NODE_ID = 5
#: CiA 406 indices of the first logical device (the gateway serves them at + 0x800)
DEVICE_TYPE_406, PRESET_406, POSITION_406 = 0x67FF, 0x6010, 0x6020
CAM_STATE_406, CAM_ENABLE_406, CAM1_LOW_406, CAM1_HIGH_406 = 0x6300, 0x6301, 0x6310, 0x6320
AREA_STATE_406, WORK_LOW_406, WORK_HIGH_406 = 0x6400, 0x6401, 0x6402
#: the simulated shaft stands at 1.25 rev: 10240 counts of the GENERIC 13-bit singleturn
STILL_COUNTS = 10240


@pytest.fixture
def generic(channel: str) -> Iterator[tuple[canopen.RemoteNode, Callable[[], None]]]:
    """A one-joint simulated station at NODE_ID and a RemoteNode built from the EDS file."""
    settings = station_settings({"joints": ["j"], "bus.channel": channel,
                                 "bus.node_id": NODE_ID, "j.motion.kind": "still",
                                 "j.motion.start": 1.25})
    station = Station(settings)
    watch = open_bus(settings.bus)
    station.start()
    try:
        BootWatch(watch, NODE_ID).wait(5.0)
    finally:
        watch.shutdown()
    network = canopen.Network()
    try:
        network.connect(interface="virtual", channel=channel)
        node = canopen.RemoteNode(NODE_ID, str(EDS))  # nothing of ssi_bridge: the file
        node.sdo.RESPONSE_TIMEOUT = 1.0
        network.add_node(node)
        yield node, network.sync.transmit
    finally:
        network.disconnect()
        station.stop()


def _until(read: Callable[[], int], expected: int, sync: Callable[[], None], what: str) -> None:
    """SYNC (the module's cycle) and read until ``read()`` is ``expected`` (5 s at most)."""
    deadline = time.monotonic() + 5.0
    value = None
    while time.monotonic() < deadline:
        sync()
        time.sleep(0.01)
        value = read()
        if value == expected:
            return
    pytest.fail(f"{what}: {value} after 5 s, expected {expected}")


def test_a_generic_cia406_tool_reads_position_preset_cam_and_area(generic) -> None:
    node, sync = generic
    od = node.object_dictionary
    # the second logical device is CiA 406, found where CiA 301 puts its device type
    assert node.sdo[DEVICE_TYPE_406 + ENCODER_PROFILE_OFFSET].raw == 0x000A_0196
    assert od[POSITION_406 + 0x800].name == "Position value for multi-sensor devices"
    assert od[CAM_STATE_406 + 0x800].name == "Cam state register"
    assert od[AREA_STATE_406 + 0x800].name == "Area state register"

    def sdo(index_406: int):
        return node.sdo[index_406 + ENCODER_PROFILE_OFFSET][1]  # channel 1 = slot 1

    position = sdo(POSITION_406)
    _until(lambda: position.raw, STILL_COUNTS, sync, "position of the standing shaft")

    # preset: "added to the value of the SSI encoder" (000, object 6810hex; the gateway keeps
    # REG_OFFSET = -preset); the EDS types it INTEGER32, so a negative preset reads back negative
    sdo(PRESET_406).raw = -1000
    assert sdo(PRESET_406).raw == -1000
    _until(lambda: position.raw, STILL_COUNTS - 1000, sync, "position after the preset")

    # CAM1: in the window [low, high] while enabled (000 Table 42)
    shifted = STILL_COUNTS - 1000
    sdo(CAM1_LOW_406).raw = shifted - 1000
    sdo(CAM1_HIGH_406).raw = shifted + 1000
    sdo(CAM_ENABLE_406).raw = 1
    _until(lambda: sdo(CAM_STATE_406).raw, 1, sync, "CAM state inside the window")
    sdo(CAM1_HIGH_406).raw = shifted - 500
    _until(lambda: sdo(CAM_STATE_406).raw, 0, sync, "CAM state above the window")

    # work area: bit 0 out of range, bit 1 above the high limit, bit 2 below the low one
    sdo(WORK_LOW_406).raw = 0
    sdo(WORK_HIGH_406).raw = 5000
    _until(lambda: sdo(AREA_STATE_406).raw, 0b011, sync, "area state above the high limit")
    sdo(WORK_HIGH_406).raw = 100_000
    _until(lambda: sdo(AREA_STATE_406).raw, 0, sync, "area state inside the work area")


def test_profile_objects_sit_at_their_cia406_index_plus_0x800() -> None:
    profile = [o for o in ENCODER_OBJECTS if o.profile]
    assert profile and all(o.index == o.profile + 0x800 for o in profile)
    assert all(0x6000 <= o.profile <= 0x67FF for o in profile)
    assert not [o for o in ENCODER_OBJECTS if not o.profile and not 0x5800 <= o.index < 0x5900]


def test_the_cia406_table_of_the_docs_lists_every_object_served() -> None:
    text = DOC.read_text(encoding="utf-8")
    section = text.split("## CiA 406 view", 1)[1].split("\n## ", 1)[0]
    listed = set()
    for row in re.findall(r"^\| *0x([0-9A-F]{4})(?:-0x([0-9A-F]{4}))? *\|", section, re.M):
        first = int(row[0], 16)
        listed.update(range(first, int(row[1] or row[0], 16) + 1))
    served = set(build_dictionary(1, 8).indices)
    assert served <= listed, f"objects without a row: {sorted(hex(i) for i in served - listed)}"
    assert not listed - served - set(range(0x1400, 0x1C00)), "rows for objects not served"
    for obj in ENCODER_OBJECTS:
        if obj.profile:
            assert f"{obj.profile:04X}h" in section, f"0x{obj.index:04X}: its CiA 406 index"
