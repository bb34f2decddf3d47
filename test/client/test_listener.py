"""The listen-only master beside a driving one, and a CAN log played back to it.

A real XnGateway with two XN-1SSI modules is driven by a normal BridgeClient; a
ListenOnlyClient on the same virtual channel only watches. Nothing is mocked.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from ssi_bridge.client.listener import LISTEN_ONLY, ListenOnlyClient
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.client.can_log_player import CanLogPlayer
from ssi_bridge.client.sniffer import CanSniffer
from ssi_bridge.exceptions import BusError, ConfigError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

from support.virtual_bus import ScriptedReader


@pytest.fixture
def pair(channel: str) -> Iterator[tuple[BridgeClient, ListenOnlyClient, list[ScriptedReader]]]:
    """Gateway node 5 with two modules, a driving client and a listener on one channel."""
    readers = [ScriptedReader(1000), ScriptedReader(4321)]
    config = BusConfig(channel=channel, node_id=5)
    gateway = XnGateway(config, 5, [Xn1Ssi(r, slot=i + 1) for i, r in enumerate(readers)])
    listener = ListenOnlyClient(config, 5, 2)
    driver = BridgeClient(config, 5, 2, sdo_timeout=0.3, handshake_timeout=0.5, opener=wire_bus)
    gateway.start()
    listener.connect()
    try:
        driver.connect()
        yield driver, listener, readers
    finally:
        driver.close()
        listener.close()
        gateway.stop()


def _drive(driver: BridgeClient, listener: ListenOnlyClient, readers: list[ScriptedReader],
           cycles: int) -> list[float]:
    """Run ``cycles`` driver cycles; check the listener saw each with the driver's data."""
    times = []
    for k in range(cycles):
        readers[0].value = 1000 + 37 * k
        t = driver.sync()
        assert driver.wait_cycle(1.0), f"cycle {k}: the driver got no TPDOs"
        seen = listener.next_cycle(1.0)
        assert seen is not None, f"cycle {k}: the listener reported no cycle"
        assert seen.complete, f"cycle {k}: the listener missed a TPDO"
        assert abs(seen.sync_time - t) < 0.05, (seen.sync_time, t)
        for slot in (1, 2):
            mine, theirs = listener.latest(slot), driver.latest(slot)
            assert mine is not None and theirs is not None
            assert (mine.position, mine.process_input) == (theirs.position,
                                                           theirs.process_input), slot
            assert mine.sync_time == seen.sync_time
        times.append(seen.sync_time)
    return times


def test_listener_samples_equal_the_drivers(pair) -> None:
    driver, listener, readers = pair
    while listener.next_cycle(0.0) is not None:  # cycles of the driver's configuration
        pass
    times = _drive(driver, listener, readers, 20)
    assert times == sorted(times)
    assert listener.latest(1).position == 1000 + 37 * 19
    assert listener.latest(2).position == 4321  # second half of the slot-pair TPDO
    assert listener.gateway_alive, "heartbeats of the gateway were on the bus"
    assert listener.counters.syncs >= 20
    assert listener.counters.frames > 40


def test_listener_refuses_everything_that_sends(pair) -> None:
    driver, listener, _ = pair
    frames = driver.counters.frames
    for call in (lambda: listener.read_register(1, 0), lambda: listener.write_register(1, 34, 1),
                 lambda: listener.set_control(1, stop=True), listener.sync,
                 lambda: listener.read_object(0x1000), lambda: listener.write_object(0x1017, 0, 0),
                 listener.configure):
        with pytest.raises(BusError, match=LISTEN_ONLY):
            call()
    assert driver.counters.frames - frames < 5, "the listener sent frames"


def test_incomplete_cycle_is_reported_when_the_next_sync_comes(channel: str) -> None:
    with can.Bus(interface="virtual", channel=channel) as bus, \
            ListenOnlyClient(BusConfig(channel=channel), 1, 1) as listener:
        bus.send(can.Message(arbitration_id=0x80, data=b"", is_extended_id=False))
        assert listener.next_cycle(0.2) is None, "a cycle is open until the next SYNC"
        bus.send(can.Message(arbitration_id=0x80, data=b"", is_extended_id=False))
        first = listener.next_cycle(1.0)
        assert first is not None and not first.complete and first.seq == 1
        bus.send(can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=False))
        # one slot: TPDO9 carries 0x6820 of slot 1 only (4 bytes, 000 Table 15)
        bus.send(can.Message(arbitration_id=0x1E1, data=(7).to_bytes(4, "little"),
                             is_extended_id=False))
        second = listener.next_cycle(1.0)
        assert second is not None and second.complete and second.seq == 2
        assert listener.latest(1).position == 7
        assert listener.gateway_alive, "TPDOs of the gateway count as traffic"


def test_a_logged_session_played_back_gives_the_same_samples(pair, channel: str,
                                                             tmp_path: Path) -> None:
    driver, listener, readers = pair
    log = tmp_path / "can_0.log"
    sniffer = CanSniffer(BusConfig(channel=channel), log)
    try:
        while listener.next_cycle(0.0) is not None:
            pass
        _drive(driver, listener, readers, 10)
    finally:
        sniffer.stop()
    replay_channel = channel + "-replay"
    player = CanLogPlayer(log, replay_channel, rate=4.0)
    with ListenOnlyClient(BusConfig(channel=replay_channel, node_id=5), 5, 2) as replayed:
        player.start()
        try:
            assert player.finished.wait(10.0), "the replay did not end"
        finally:
            player.stop()
        cycles = []
        while (c := replayed.next_cycle(0.5)) is not None:
            cycles.append(c)
    complete = [c for c in cycles if c.complete]
    assert len(complete) >= 10, cycles
    assert replayed.latest(1).position == listener.latest(1).position == 1000 + 37 * 9
    assert replayed.latest(2).process_input == listener.latest(2).process_input
    # every logged frame was played: 10 cycles of SYNC + 2 image TPDOs + 1 position TPDO,
    # plus whatever heartbeats fell into the window
    logged = sum(1 for _ in can.LogReader(str(log)))
    assert player.frames == logged >= 4 * 10 and not player.error
    # the original spacing of the SYNCs, not the 4x faster playback
    spans = [b.sync_time - a.sync_time for a, b in zip(complete, complete[1:])]
    assert min(spans) > 0


def test_player_refuses_a_missing_log(channel: str, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="does not exist"):
        CanLogPlayer(tmp_path / "nope.log", channel)
