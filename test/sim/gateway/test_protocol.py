"""NMT, PDOs, EMCY and the EDS of the station, checked with canopen's master-side classes."""

from __future__ import annotations

import struct
from pathlib import Path

import canopen
import pytest
from canopen.sdo import SdoAbortedError

from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.base.od import build_dictionary
from ssi_bridge.protocol.dictionary import tpdo_cob_base
from ssi_bridge.protocol.registers import Reg

NODE_ID = 7  # conftest's station node id

EDS = Path(__file__).resolve().parents[3] / "config" / "xn_gw_canopen.eds"


def _attributes(var: canopen.objectdictionary.ODVariable) -> tuple:
    return (var.name, var.data_type, var.access_type, var.pdo_mappable, var.default)


def test_eds_matches_the_live_dictionary(station8) -> None:
    eds = canopen.import_od(str(EDS), NODE_ID)
    live = station8.gateway.node.object_dictionary
    assert sorted(eds.indices) == sorted(live.indices)
    for index in live.indices:
        mine, theirs = live[index], eds[index]
        assert type(mine) is type(theirs), f"0x{index:04X} object code"
        assert mine.name == theirs.name
        if isinstance(mine, canopen.objectdictionary.ODVariable):
            assert _attributes(mine) == _attributes(theirs), f"0x{index:04X}"
            continue
        assert sorted(mine.subindices) == sorted(theirs.subindices), f"0x{index:04X} subs"
        for sub in mine.subindices:
            assert _attributes(mine[sub]) == _attributes(theirs[sub]), f"0x{index:04X}:{sub}"


def test_default_pdos_per_table_15(station) -> None:
    sdo = station.node.sdo
    for pdo, base in zip(range(9, 13), (0x1E0, 0x2E0, 0x3E0, 0x4E0)):
        assert sdo[0x1800 + pdo - 1][1].raw == 0x8000_0000 | base + NODE_ID
        assert sdo[0x1800 + pdo - 1][2].raw == 255
        assert sdo[0x1400 + pdo - 1][1].raw == 0x8000_0000 | base + 0x80 + NODE_ID


def _unused(): pass


def _enable_positions(node: canopen.RemoteNode, slots: int) -> list[canopen.pdo.PdoMap]:
    maps = []
    for g in range((slots + 1) // 2):
        pdo = node.tpdo[9 + g]
        pdo.clear()
        for s in (2 * g + 1, 2 * g + 2):
            if s <= slots:
                pdo.add_variable(0x6820, s)
        pdo.cob_id, pdo.trans_type, pdo.enabled = tpdo_cob_base(9 + g) + NODE_ID, 1, True
        pdo.save()
        maps.append(pdo)
    return maps


def test_tpdo_positions_for_every_slot_only_when_operational(station8) -> None:
    st = station8
    maps = _enable_positions(st.node, 8)
    st.sync()  # PRE-OPERATIONAL: the module cycles, no PDO
    assert all(not m.is_received for m in maps)
    st.node.nmt.state = "OPERATIONAL"
    st.wait_for(lambda: st.gateway.nmt_state == "OPERATIONAL", "gateway not OPERATIONAL")
    for m in maps:
        m.is_received = False
    st.sync()
    st.wait_for(lambda: all(m.is_received for m in maps), "not all position TPDOs arrived")
    for g, m in enumerate(maps):
        pair = struct.unpack("<ii", bytes(m.data))
        assert pair == (st.gateway.modules[2 * g].ssi_pos, st.gateway.modules[2 * g + 1].ssi_pos)
        assert pair == (1000 * (2 * g + 1), 1000 * (2 * g + 2))


def test_mapping_rules(station) -> None:
    sdo = station.node.sdo
    with pytest.raises(SdoAbortedError) as info:  # Encoder Config is not PDO-mappable
        sdo[0x1A08][1].raw = 0x5801_0120
    assert info.value.code == SdoAbort.NOT_MAPPABLE
    sdo[0x1808][1].raw = 0x1E0 + NODE_ID  # valid now
    with pytest.raises(SdoAbortedError) as info:
        sdo[0x1A08][0].raw = 0
    assert info.value.code == SdoAbort.CANNOT_STORE_STATE


def test_rpdo_writes_the_process_output(station) -> None:
    st = station
    rpdo = st.node.rpdo[1]
    rpdo.clear()
    rpdo.add_variable(0x2100, 1)
    rpdo.cob_id, rpdo.trans_type, rpdo.enabled = 0x200 + NODE_ID, 255, True
    rpdo.save()
    st.node.nmt.state = "OPERATIONAL"
    st.wait_for(lambda: st.gateway.nmt_state == "OPERATIONAL", "gateway not OPERATIONAL")
    image = bytes([0, 0, 0, 0, 1, 0, 0, 0])  # REG_RD_ADR = 1
    st.network.send_message(0x200 + NODE_ID, image)
    st.wait_for(lambda: st.gateway.objects.outputs[0] == image, "RPDO not applied")
    st.sync()
    assert st.gateway.modules[0].process_input()[:5] == bytes.fromhex("aa55cc3301")


def test_stopped_node_ignores_sdo_and_sync(station) -> None:
    st = station
    st.node.nmt.state = "STOPPED"
    st.wait_for(lambda: st.gateway.nmt_state == "STOPPED", "gateway not STOPPED")
    before = st.gateway.cycles
    st.network.sync.transmit()
    with pytest.raises(canopen.SdoCommunicationError):
        st.node.sdo.upload(0x1000, 0)
    assert st.gateway.cycles == before


def test_emcy_on_rising_diag_and_reset_when_clear(station) -> None:
    st = station
    st.node.sdo[0x6C02][2].raw = 100  # upper limit below slot 2's position -> STS_OFLW
    st.sync()
    st.wait_for(lambda: st.node.emcy.log, "no EMCY 0x7000")
    emcy = st.node.emcy.log[0]
    assert emcy.code == 0x7000
    assert emcy.data[:3] == bytes([2, 1, 0x04])  # module 2, channel 1, overflow
    assert emcy.register & 0x01
    assert st.node.sdo[0x1001].raw == emcy.register
    assert st.node.sdo[0x1003][0].raw == 1
    assert st.node.sdo[0x1003][1].raw == (2 << 8 | 0x04) << 16 | 0x7000
    st.node.sdo[0x6C02][2].raw = -1
    st.sync()
    st.wait_for(lambda: st.node.emcy.log[-1].code == 0, "no error-reset EMCY")
    assert st.node.emcy.active == []
    assert st.node.sdo[0x1001].raw == 0


def test_heartbeat_and_nmt_reset(station) -> None:
    st = station
    st.node.sdo[0x1017].raw = 20
    assert st.node.nmt.wait_for_heartbeat(1.0) == "PRE-OPERATIONAL"
    st.node.sdo[0x1808][1].raw = 0x1E0 + NODE_ID
    st.node.nmt.send_command(0x82)  # reset communication
    st.node.nmt.wait_for_bootup(1.0)
    assert st.node.sdo[0x1808][1].raw == 0x8000_0000 | 0x1E0 + NODE_ID
    assert st.node.sdo[0x1017].raw == 0


def test_silent_gateway_sends_nothing(station) -> None:
    st = station
    st.gateway.silent = True
    with pytest.raises(canopen.SdoCommunicationError):
        st.node.sdo.upload(0x1000, 0)
    st.gateway.silent = False
    assert st.node.sdo[0x1000].raw == 0x191


def test_dictionary_slot_count_is_checked() -> None:
    with pytest.raises(ValueError, match="1-8"):
        build_dictionary(1, 9)


def test_injected_invalid_para1_raises_err_para_and_its_emcy(station) -> None:
    # 000 "Additional emergencies": 7000 hex, byte 3 module no., byte 4 channel 1, byte 5
    # 0x10 "Parameter error"; the invalid set reaches the module past every master check
    st = station
    module = st.gateway.modules[0]
    reason = module.inject_parameter_error()
    assert "SSI_BIT_RATE = 8 is reserved" in reason
    assert module.read_register(Reg.REG_PARA1) == 0x19010000, "REG_PARA1 keeps the valid set"
    st.sync()
    st.wait_for(lambda: any(e.code == 0x7000 for e in st.node.emcy.log), "no EMCY 0x7000")
    emcy = next(e for e in st.node.emcy.log if e.code == 0x7000)
    assert emcy.data[:3] == bytes([1, 1, 0x10])  # module 1, channel 1, parameter error
    assert st.node.sdo[0x5804][1].raw & 0x10, "diagnostics bit 4 (object 0x5804)"
    module.clear_parameter_error()
    st.sync()
    st.wait_for(lambda: st.node.emcy.log[-1].code == 0, "no error-reset EMCY")


def test_identity_revision_from_the_manual_rest_marked_as_simulation(station) -> None:
    # 000 ch. 4: "The support of XN-1SSI modules has been implemented from firmware version
    # V3.00 of XN-GW-CANOPEN" -> revision 3.0 (CiA 301: major in the upper 16 bits). The manual
    # gives no Vendor-ID, product code or serial number: named simulation values, also in the EDS
    sdo = station.node.sdo
    assert sdo[0x1018][3].raw == 0x0003_0000
    eds = canopen.import_od(str(EDS), NODE_ID)
    for sub in (1, 2, 4):
        assert eds[0x1018][sub].name.endswith("(simulation value)")
        assert sdo[0x1018][sub].raw == eds[0x1018][sub].default
    assert eds[0x1018][3].name == "Revision number"
    assert "simulation values" in EDS.read_text()
