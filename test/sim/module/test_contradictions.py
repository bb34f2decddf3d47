"""The places where manual 000 contradicts itself, each resolved as docs/module.md says."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.diagnostics import Diag, cam_state, to_int32
from ssi_bridge.protocol.images import CmpControl, CmpStatus, ModuleStatus
from ssi_bridge.protocol.registers import BIT_RATES_HZ, DEVICENET_BIT_RATES_HZ, Para1, Reg


def test_bit_rate_codes_3_and_4_follow_profibus_and_canopen(reader, module) -> None:
    # 000 Table 19 / PROFIBUS-DP "Parameters": 3 = 125000, 4 = 100000 Bit/s.
    # 000 ch. 3 DeviceNet attribute 126 BITRATE: 3 = 100 kbps, 4 = 125 kbps (its own enum).
    assert (BIT_RATES_HZ[3], BIT_RATES_HZ[4]) == (125_000, 100_000)
    assert (DEVICENET_BIT_RATES_HZ[3], DEVICENET_BIT_RATES_HZ[4]) == (100_000, 125_000)
    module.write_para1(Para1(ssi_bit_rate=3).encode())
    module.cycle(0.0)
    assert reader.calls[-1][2] == 125_000, "REG_PARA1 code 3 clocks at 125 kHz"


def test_offset_is_subtracted_not_added(reader, module) -> None:
    # 000 ch. 1 "Offset function": REG_SSI_POS = SSI encoder - REG_OFFSET.
    # 000 ch. 4 object 0x6810 (= REG_OFFSET) says "added"; the module follows chapter 1 and
    # the gateway negates 0x6810 into REG_OFFSET (test/sim/gateway/test_preset_6810.py).
    module.write_register(Reg.REG_OFFSET, 300)
    reader.push(1000)
    module.cycle(0.0)
    assert module.ssi_pos == 700


def test_devicenet_diagnostics_bit_2_is_overflow_of_the_upper_limit(reader, module) -> None:
    # 000 ch. 3 attribute 123 bit 2 "error POS > LOWER LIMIT" vs attribute 112 bit 2 and the
    # PROFIBUS/CANopen diagnostics "POS > UPPER LIMIT": bit 2 = overflow (upper limit).
    module.write_register(Reg.REG_LOWER_LIMIT, 10)
    reader.push(500)
    module.cycle(0.0)
    assert Diag.STS_OFLW not in module.diag, "POS > LOWER LIMIT does not set bit 2"
    module.write_register(Reg.REG_UPPER_LIMIT, 400)
    module.cycle(0.001)
    assert int(module.diag) & 0x04, "POS > UPPER LIMIT sets bit 2"


@pytest.mark.parametrize("pos, enabled, polarity, state", [
    (150, True, 0, 0x01), (100, True, 0, 0x01), (200, True, 0, 0x01),   # inside, inclusive
    (99, True, 0, 0x00), (201, True, 0, 0x00),                          # outside
    (150, False, 0, 0x00),                                              # comparison off
    (150, True, 1, 0x00), (99, True, 1, 0x01), (150, False, 1, 0x01),   # polarity inverts
])
def test_cam_state_second_row_means_inside(pos, enabled, polarity, state) -> None:
    # 000 Table 42 prints "outside" for 0x00 and 0x01; 0x01 must be "inside" (Table 46 inverts
    # the two).  CAM1 Low Limit 0x6B10 = REG_CMP2, CAM1 High Limit 0x6B20 = REG_CMP1.
    assert cam_state(pos, 100, 200, enabled=enabled, polarity=polarity) == state


def test_cam_state_is_signed() -> None:
    # 0x6B10 / 0x6B20 are Integer32: -5 lies inside [-10, 10]
    assert cam_state(0xFFFFFFFB, 0xFFFFFFF6, 10, enabled=True) == 0x01


@pytest.mark.parametrize("raw, signed", [
    (0, 0), (0x7FFFFFFF, 2**31 - 1), (0x80000000, -(2**31)), (0xFFFFFFFF, -1)])
def test_values_compare_as_integer32(raw: int, signed: int) -> None:
    # 000 Table 40: object 0x6820 (REG_SSI_POS) is Integer32
    assert to_int32(raw) == signed


def test_signed_comparison_in_the_module(reader, module, master) -> None:
    # REG_SSI_POS = 5 - 10 = -5 (0xFFFFFFFB) is *below* REG_CMP1 = 0 (unsigned would say above)
    module.write_register(Reg.REG_OFFSET, 10)
    reader.push(5)
    image = master.control(CmpControl.EN_CMP1)
    assert not image.cmp & CmpStatus.REL_CMP1, "REL_CMP1 = 0: -5 < 0"
    # the limits are Unsigned32 (docs/module.md): 0xFFFFFFFB is above 0x7FFFFFFF
    module.write_register(Reg.REG_UPPER_LIMIT, 0x7FFFFFFF)
    assert master.control(CmpControl.EN_CMP1).sts & ModuleStatus.STS_OFLW
