"""Object dictionary access over SDO per 000 Table 16 and its description tables."""

from __future__ import annotations

import pytest
from canopen.sdo import SdoAbortedError

from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.protocol.dictionary import ENCODER_OBJECTS
from ssi_bridge.protocol.registers import PARA1_DEFAULT, Reg

ARRAY_OBJECTS = [o for o in ENCODER_OBJECTS if o.array]


def test_communication_objects(station) -> None:
    sdo = station.node.sdo
    assert sdo[0x1000].raw == 0x191
    assert sdo[0x1001].raw == 0
    assert sdo[0x1005].raw == 0x80
    assert sdo[0x1008].raw == "XN-GW-CANOPEN"
    assert sdo[0x1014].raw == 0x80 + 7
    assert sdo[0x1018][0].raw == 4
    assert sdo[0x6FFF].raw == 0x000A0196
    assert [sdo[i].raw for i in (0x6D00, 0x6D01, 0x6D02)] == [0, 0, 0]


@pytest.mark.parametrize("obj", ARRAY_OBJECTS, ids=lambda o: f"{o.index:04X}")
def test_every_array_object_has_one_sub_per_slot_and_its_access(station, obj) -> None:
    array = station.node.sdo[obj.index]
    assert array[0].raw == 2
    for slot in (1, 2):
        array[slot].raw  # readable everywhere
    if "w" not in obj.access:
        with pytest.raises(SdoAbortedError) as info:
            array[1].raw = 0
        assert info.value.code == SdoAbort.READ_ONLY
    with pytest.raises(SdoAbortedError) as info:
        station.node.sdo.upload(obj.index, 3)
    assert info.value.code == SdoAbort.NO_SUCH_SUBINDEX


def test_no_function_objects_keep_what_is_written(station) -> None:
    sdo = station.node.sdo
    sdo[0x5800][2].raw = 3
    sdo[0x6B30][1].raw = 99
    sdo[0x6800].raw = 0x1234
    assert (sdo[0x5800][2].raw, sdo[0x6B30][1].raw, sdo[0x6800].raw) == (3, 99, 0x1234)


def test_registers_behind_objects(station) -> None:
    sdo, modules = station.node.sdo, station.gateway.modules
    station.sync()
    assert sdo[0x6820][1].raw == modules[0].ssi_pos == 1000
    assert sdo[0x6820][2].raw == 2000
    # 0x6810 is added to the encoder value (000 object 6810hex); the module subtracts
    # REG_OFFSET (000 ch. 1), so REG_OFFSET holds the preset negated (test_preset_6810.py)
    sdo[0x6810][1].raw = -10
    assert modules[0].read_register(Reg.REG_OFFSET) == 10
    station.sync()
    assert sdo[0x6820][1].raw == 990
    sdo[0x6810][1].raw = 10  # Integer32: REG_OFFSET = -10 = 0xFFFFFFF6
    assert modules[0].read_register(Reg.REG_OFFSET) == 0xFFFFFFF6
    sdo[0x5840][2].raw = 0x00000081
    assert modules[1].read_register(Reg.REG_SSI_MASK) == 0x81
    assert sdo[0x5801][1].raw == PARA1_DEFAULT


def test_encoder_config_invalid_set_gives_abort_and_err_para(station) -> None:
    sdo, module = station.node.sdo, station.gateway.modules[0]
    with pytest.raises(SdoAbortedError) as info:
        sdo[0x5801][1].raw = 0x00000000  # SSI_FRAME_LEN = 0
    assert info.value.code == SdoAbort.INVALID_VALUE
    assert sdo[0x5804][1].raw & 0x10, "ERR_PARA not in Encoder Diag"
    sdo[0x5801][1].raw = 0x0D010000  # 13-bit frame, valid
    assert module.read_register(Reg.REG_PARA1) == 0x0D010000


def test_status_objects_follow_the_process_input(station) -> None:
    sdo, module = station.node.sdo, station.gateway.modules[0]
    station.sync()
    station.readers[0].value = 1100
    station.sync()
    image = module.process_input()
    assert sdo[0x5805][1].raw == image[7] | image[6] << 8
    assert sdo[0x5806][1].raw == image[5] & 0x3F
    assert sdo[0x5802][1].raw == image[6] & 0xC0
    assert sdo[0x5802][1].raw == 0x80  # STS_UP: the value went up
    assert sdo[0x2000][1].raw.to_bytes(8, "little") == image


@pytest.mark.parametrize("flag_object", [0x5803, 0x5805])
def test_flag_reset_by_writing(station, flag_object) -> None:
    sdo = station.node.sdo
    sdo[0x6B20][1].raw = 1000  # CMP1 = current position
    sdo[0x2100][1].raw = int.from_bytes(bytes([0, 0, 0, 0, 0, 0, 0x01, 0]), "little")  # EN_CMP1
    station.sync()
    assert sdo[0x5803][1].raw & 0x08, "FLAG_CMP1 not set on match"
    sdo[flag_object][1].raw = 0
    station.sync()
    assert sdo[0x5803][1].raw & 0x08, "flag reset although still matching"
    station.readers[0].value = 1001
    station.sync()
    sdo[flag_object][1].raw = 0
    station.sync()
    assert not sdo[0x5803][1].raw & 0x08, "flag not reset by the write"


def test_cam_objects(station) -> None:
    sdo, module = station.node.sdo, station.gateway.modules[0]
    sdo[0x6B10][1].raw = 900    # CAM1 low = REG_CMP2
    sdo[0x6B20][1].raw = 1100   # CAM1 high = REG_CMP1
    assert module.read_register(Reg.REG_CMP2) == 900
    assert module.read_register(Reg.REG_CMP1) == 1100
    station.sync()
    assert sdo[0x6B00][1].raw == 0  # not enabled
    sdo[0x6B01][1].raw = 1
    assert sdo[0x6B00][1].raw == 1
    sdo[0x6B02][1].raw = 1
    assert sdo[0x6B00][1].raw == 0  # inverted
    station.readers[0].value = 1200
    station.sync()
    assert sdo[0x6B00][1].raw == 1  # outside, inverted
    with pytest.raises(SdoAbortedError):
        sdo[0x6B01][1].raw = 2


def test_area_objects_are_the_limits(station) -> None:
    sdo, module = station.node.sdo, station.gateway.modules[0]
    sdo[0x6C02][1].raw = 500  # upper limit below the position
    assert module.read_register(Reg.REG_UPPER_LIMIT) == 500
    station.sync()
    assert sdo[0x6C00][1].raw == 0x03  # out of range, overflow
    assert sdo[0x6C01][1].raw == 0
    assert sdo[0x6C02][2].raw == -1  # REG_UPPER_LIMIT default 0xFFFFFFFF as Integer32


def test_error_field_can_only_be_cleared(station) -> None:
    sdo = station.node.sdo
    with pytest.raises(SdoAbortedError) as info:
        sdo[0x1003][0].raw = 1
    assert info.value.code == SdoAbort.INVALID_VALUE
    sdo[0x1003][0].raw = 0


def test_unknown_object_abort(station) -> None:
    with pytest.raises(SdoAbortedError) as info:
        station.node.sdo.upload(0x4321, 0)
    assert info.value.code == SdoAbort.NO_SUCH_OBJECT
