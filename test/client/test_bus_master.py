"""One CanMaster, two XN-GW-CANOPEN stations (node 1 with two modules, node 3 with one).

CiA 301: one SYNC producer per bus; every other COB-ID carries the station's node id. The
master's one SYNC makes both stations answer with their own TPDOs; a register handshake (000
chapter 1) on station 3 slot 1 leaves station 1 slot 1 alone.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import can
import pytest

from ssi_bridge.sim.supervisor.boot import BootWatch
from ssi_bridge.client.master import BridgeClient, CanMaster
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.protocol.settings import station_settings
from ssi_bridge.sim.gateway.station import Station
from ssi_bridge.protocol.registers import Reg

from support.waiting import wait_for


@pytest.fixture
def rig(channel: str, request: pytest.FixtureRequest
        ) -> Iterator[tuple[CanMaster, dict[int, BridgeClient], can.BusABC]]:
    """Stations 1 (joints a, b) and 3 (joint c) on one virtual bus, one master, a sniffer."""
    stations = [Station(station_settings({"joints": names, "bus.channel": channel,
                                          "bus.node_id": sid}))
                for sid, names in ((1, ["a", "b"]), (3, ["c"]))]
    watch = open_bus(BusConfig(channel=channel))
    for st in stations:
        st.start()
    try:
        for sid in (1, 3):
            BootWatch(watch, sid).wait(5.0)
    finally:
        watch.shutdown()
    master = CanMaster(BusConfig(channel=channel), opener=wire_bus)
    clients = {1: BridgeClient(master, 1, 2), 3: BridgeClient(master, 3, 1)}
    sniffer = open_bus(BusConfig(channel=channel))
    for client in clients.values():
        client.connect()
    request.node.stations = stations
    yield master, clients, sniffer
    for client in clients.values():
        client.close()
    master.close()
    sniffer.shutdown()
    for st in stations:
        st.stop()


def _drain(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (msg := bus.recv(0.0)) is not None:
        out.append(msg)
    return out


def test_one_sync_serves_every_station(rig) -> None:
    master, clients, sniffer = rig
    _drain(sniffer)
    for _ in range(5):
        t = clients[3].sync()  # any client's sync() is the master's one SYNC
        for sid, client in clients.items():
            wait_for(lambda c=client: c.wait_cycle(0.05) or all(
                (s := c.latest(slot)) is not None and s.sync_time >= t
                for slot in range(1, c.slots + 1)), f"station {sid}: no TPDOs after SYNC")
    frames = _drain(sniffer)
    ids = [m.arbitration_id for m in frames]
    assert ids.count(0x080) == 5
    # TPDO1 of each station at 0x180 + its node id, TPDO2 only where slot 2 exists
    assert ids.count(0x181) >= 5 and ids.count(0x183) >= 5 and ids.count(0x281) >= 5
    assert 0x283 not in ids
    assert master.counters.syncs == 5
    assert clients[1].counters.syncs == clients[3].counters.syncs == 5


def test_register_write_reaches_only_its_station(rig) -> None:
    _, clients, _ = rig
    before_1 = clients[1].read_register(1, Reg.REG_CMP1)
    before_3 = clients[3].read_register(1, Reg.REG_CMP1)
    clients[3].write_register(1, Reg.REG_CMP1, before_3 + 777)
    assert clients[3].read_register(1, Reg.REG_CMP1) == before_3 + 777
    assert clients[1].read_register(1, Reg.REG_CMP1) == before_1


def test_a_node_id_is_attached_once(rig) -> None:
    master, _, _ = rig
    with pytest.raises(ValueError, match="node id 3 already attached"):
        BridgeClient(master, 3, 1).connect()


def test_a_silent_station_does_not_hold_up_the_others_cycles(rig, request) -> None:
    """A station that answers a SYNC with nothing gets a starved process's turn (the second
    wait of ``wait_cycle``); once its gateway counts as silent (no heartbeat, CiA 301
    consumer) it does not: the cycle of the station that answers is complete at once."""
    master, clients, _ = rig
    request.node.stations[1].stop()  # station 3 falls silent
    wait_for(lambda: not clients[3].gateway_alive, "station 3 never counted as silent", 5.0)
    assert clients[1].gateway_alive
    for _ in range(3):
        clients[1].sync()
        start = time.monotonic()
        master.wait_cycle(0.05, 2.0)
        waited = time.monotonic() - start
        assert waited < 1.0, f"waited {waited:.2f} s for a silent station"
        assert clients[1].table.cycle_complete()


def test_no_starved_turn_once_another_producer_synced(rig, request) -> None:
    """CiA 301 allows one SYNC producer. Once another producer's SYNC followed the master's,
    every frame after it answers that SYNC and is not taken for this cycle, so a station that
    has answered nothing yet can no longer complete it: the wait ends at its first timeout
    instead of giving the station a starved process's turn (which would slow every SYNC of a
    flood of foreign SYNCs to that turn)."""
    master, clients, sniffer = rig
    clients[3].heartbeat_timeout = 30.0  # station 3 stays alive for this test: not the reason
    request.node.stations[1].stop()  # station 3 answers nothing from now on
    assert not master.foreign_sync_within(60.0), "no other producer yet"
    clients[1].sync()
    sniffer.send(can.Message(arbitration_id=0x080, is_extended_id=False, data=b""))
    start = time.monotonic()
    assert not master.wait_cycle(0.2, 3.0)
    waited = time.monotonic() - start
    assert master.foreign_sync_within(60.0), "the diagnostics' change test sees it"
    assert not master.foreign_sync_within(0.0)
    assert clients[3].gateway_alive
    assert waited < 1.5, f"waited {waited:.2f} s: a starved station's turn after a foreign SYNC"
    # without the foreign SYNC the silent (but alive) station gets its turn, as before
    clients[1].sync()
    start = time.monotonic()
    assert not master.wait_cycle(0.2, 1.0)
    assert time.monotonic() - start >= 0.9
