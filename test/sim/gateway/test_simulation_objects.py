"""The simulated station's objects 0x4000-0x4004 (faults, motion epoch), driven over SDO by our
master.

One control path: a fault reaches the station the way every other request does, as SDO
writes on the bus (docs/canopen.md, "Simulation-only objects"). What a fault does is checked
where the manuals say it shows: a broken data wire fails the ZERO test -> ERR_SSI
(000 "Error detection / messages"); a silent gateway sends no heartbeat (CiA 301).
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from ssi_bridge.sim.supervisor.boot import BootWatch
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.exceptions import GatewayUnavailable, SdoAbortError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.protocol.dictionary import (
    SIM_ACTIVE, SIM_COMMAND, SIM_DURATION, SIM_EPOCH, SIM_RATE,
)
from ssi_bridge.protocol.settings import station_settings
from ssi_bridge.sim.gateway.simulation import FaultKind, command_word
from ssi_bridge.sim.gateway.station import Station
from ssi_bridge.protocol.images import ModuleStatus

from support.waiting import wait_for


@pytest.fixture
def rig(channel: str) -> Iterator[tuple[Station, BridgeClient]]:
    """A two-joint station (slots 1 and 2) and our master on a private virtual bus."""
    settings = station_settings({"joints": ["a", "b"], "bus.channel": channel})
    station = Station(settings)
    watch = open_bus(settings.bus)
    station.start()
    try:
        BootWatch(watch, settings.bus.node_id).wait(5.0)
    finally:
        watch.shutdown()
    client = BridgeClient(BusConfig(channel=channel), settings.bus.node_id, 2, opener=wire_bus)
    client.connect()
    yield station, client
    client.close()
    station.stop()


def _inject(client: BridgeClient, kind: FaultKind, slot: int, *, rate: float = 0.0,
            duration_ms: int = 0) -> None:
    client.write_object(SIM_RATE, 0, rate)
    client.write_object(SIM_DURATION, 0, duration_ms)
    client.write_object(SIM_COMMAND, 0, command_word(kind, slot))


def _sts_after_sync(client: BridgeClient, slot: int) -> int:
    t = client.sync()
    wait_for(lambda: (s := client.latest(slot)) is not None and s.sync_time >= t,
             f"no TPDO of slot {slot} after SYNC")
    return client.latest(slot).process_input[7]


def test_data_wire_break_in_one_slot_is_err_ssi_there_only(rig) -> None:
    station, client = rig
    assert not _sts_after_sync(client, 1) & ModuleStatus.ERR_SSI
    _inject(client, FaultKind.DATA_WIRE_BREAK, 2)
    wait_for(lambda: _sts_after_sync(client, 2) & ModuleStatus.ERR_SSI, "no ERR_SSI in slot 2")
    assert not _sts_after_sync(client, 1) & ModuleStatus.ERR_SSI
    assert client.read_object(SIM_ACTIVE) == 1 << FaultKind.DATA_WIRE_BREAK
    client.write_object(SIM_COMMAND, 0, command_word(FaultKind.CLEAR_ALL, 0))
    assert client.read_object(SIM_ACTIVE) == 0
    wait_for(lambda: not _sts_after_sync(client, 2) & ModuleStatus.ERR_SSI,
             "ERR_SSI stays after CLEAR_ALL")


def test_silent_gateway_times_its_duration_itself(rig) -> None:
    station, client = rig
    _inject(client, FaultKind.GATEWAY_SILENT, 0, duration_ms=300)
    wait_for(lambda: station.gateway.silent, "the gateway did not go silent")
    with pytest.raises(GatewayUnavailable):
        client.read_object(0x1000)  # a silent gateway answers nothing
    # nobody talks to it: the station's own clock ends the fault
    wait_for(lambda: not station.gateway.silent, "silence did not end after 0.3 s", 5.0)
    assert client.read_object(SIM_ACTIVE) == 0


def test_clear_all_reaches_a_silent_gateway_and_is_answered(rig) -> None:
    station, client = rig
    _inject(client, FaultKind.GATEWAY_SILENT, 0)
    wait_for(lambda: station.gateway.silent, "the gateway did not go silent")
    client.write_object(SIM_COMMAND, 0, command_word(FaultKind.CLEAR_ALL, 0))  # answered
    assert not station.gateway.silent
    wait_for(lambda: client.gateway_alive, "no heartbeat after the clear", 5.0)


def test_total_frame_loss_is_answered_then_drops_every_frame(rig) -> None:
    station, client = rig
    _inject(client, FaultKind.CAN_FRAME_LOSS, 0, rate=1.0)  # the answer still got out
    wait_for(lambda: station.gateway.bus.loss_rate == 1.0, "frame loss not applied")
    with pytest.raises(GatewayUnavailable):
        client.read_object(0x1000)
    client.write_object(SIM_COMMAND, 0, command_word(FaultKind.CLEAR_ALL, 0))
    assert station.gateway.bus.loss_rate == 0.0


@pytest.mark.parametrize("word, rate", [
    (command_word(99, 0), 0.0),                          # no such kind
    (command_word(FaultKind.DATA_WIRE_BREAK, 5), 0.0),   # no joint in slot 5
    (command_word(FaultKind.GATEWAY_SILENT, 1), 0.0),    # bus faults take slot 0
    (command_word(FaultKind.BIT_NOISE, 1), 0.0),         # noise needs a rate
])
def test_impossible_commands_are_aborted(rig, word: int, rate: float) -> None:
    station, client = rig
    client.write_object(SIM_RATE, 0, rate)
    with pytest.raises(SdoAbortError):
        client.write_object(SIM_COMMAND, 0, word)
    assert client.read_object(SIM_ACTIVE) == 0


def test_a_rate_outside_0_1_is_aborted(rig) -> None:
    _, client = rig
    with pytest.raises(SdoAbortError):
        client.write_object(SIM_RATE, 0, 1.5)


def test_a_duration_ends_only_its_own_fault(rig) -> None:
    station, client = rig
    _inject(client, FaultKind.DATA_WIRE_BREAK, 1, duration_ms=100)
    _inject(client, FaultKind.DATA_WIRE_BREAK, 2)
    deadline = time.monotonic() + 5.0
    while station.control.active and len(station.control.active) > 1 \
            and time.monotonic() < deadline:
        time.sleep(0.01)
    assert [(f.kind, f.slot) for f in station.control.active] == [
        (FaultKind.DATA_WIRE_BREAK, 2)]
    assert not station.sim.channels["a"].line.faults.data_break
    assert station.sim.channels["b"].line.faults.data_break


def test_the_motion_epoch_is_readable_and_places_every_shaft(rig) -> None:
    # 0x4004: the wire time (us) at which the encoders' motion time is 0. A SYNC at wire time
    # t latches each shaft at motion time t - epoch (000 "Process data": acquired on the SYNC)
    station, client = rig
    epoch_us = client.read_object(SIM_EPOCH)
    assert isinstance(epoch_us, int)
    assert epoch_us == round(station.model_clock.epoch * 1e6)
    t = client.sync()
    wait_for(lambda: (s := client.latest(1)) is not None and s.sync_time >= t, "no TPDO")
    channel = station.sim.channels["a"]
    assert channel.line.last_frame.latch_time == pytest.approx(t - epoch_us / 1e6, abs=2e-6)
    with pytest.raises(SdoAbortError):  # read-only (CiA 301 abort 0x06010002)
        client.write_object(SIM_EPOCH, 0, 0)
