"""The whole loop on a python-can virtual bus: module -> gateway -> CAN -> client.

Real canopen LocalNode/RemoteNode machinery on both sides; nothing is mocked.
"""

from __future__ import annotations

import pytest

from ssi_bridge.exceptions import RegisterReadError, RegisterWriteError
from ssi_bridge.protocol.registers import MAGIC_NO, Reg


def test_magic_number_through_the_handshake(station) -> None:
    _, client, _ = station
    assert client.read_register(1, Reg.REG_MAGIC_NO) == MAGIC_NO == 0xAA55CC33


def test_write_then_read_cmp1(station) -> None:
    gateway, client, _ = station
    client.write_register(1, Reg.REG_CMP1, 0x0001_2345)
    assert client.read_register(1, Reg.REG_CMP1) == 0x0001_2345
    assert gateway.modules[0].read_register(Reg.REG_CMP1) == 0x0001_2345


def test_write_to_ssi_pos_is_refused_as_read_only(station) -> None:
    _, client, _ = station
    with pytest.raises(RegisterWriteError, match="read-only") as info:
        client.write_register(1, Reg.REG_SSI_POS, 5)
    assert info.value.address == 0
    assert "REG_WR_ACCEPT = 0" in str(info.value)


def test_reserved_register_read_aborts(station) -> None:
    _, client, _ = station
    with pytest.raises(RegisterReadError, match="reserved") as info:
        client.read_register(1, 5)
    assert "REG_RD_ABORT = 1" in str(info.value)
    assert client.counters.handshake_failures == 1


def test_sync_delivers_the_module_position(station) -> None:
    gateway, client, readers = station
    readers[0].value = 4321
    t = client.sync()
    assert client.wait_cycle(1.0), "no TPDO after SYNC"
    sample = client.latest(1)
    assert sample is not None
    assert sample.position == gateway.modules[0].read_register(Reg.REG_SSI_POS) == 4321
    assert sample.sync_time == t
    assert sample.process_input == gateway.modules[0].process_input()


def test_counters_and_liveness(station) -> None:
    _, client, _ = station
    client.sync()
    assert client.wait_cycle(1.0)
    assert client.gateway_alive
    assert client.counters.frames > 0
    assert client.counters.configurations == 1
