"""Liveness measured on the bus: a stalled receive thread, or a starved heartbeat producer
thread of the simulated station, is not a silent gateway; a gateway that really stops sending
(or a producer stuck for good) is still found silent, and never before the timeout."""

from __future__ import annotations

import threading
import time

import can
import pytest

from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import OWED_MAX_S, open_bus
from ssi_bridge.base.timebase import wire_now

from .conftest import wait_until

STALL_COB = 0x123


def test_a_stalled_receive_thread_is_not_a_silent_gateway(station, channel) -> None:
    gateway, client, _ = station
    stall_s = 3 * client.heartbeat_timeout
    client.network.subscribe(STALL_COB, lambda *_: time.sleep(stall_s))
    poke = open_bus(BusConfig(channel=channel, node_id=5))
    try:
        assert client.gateway_alive
        poke.send(can.Message(arbitration_id=STALL_COB, data=b"", is_extended_id=False))
        # while the client's receive thread sleeps, the gateway's heartbeats queue up with
        # their arrival times: the wire never went quiet, so the gateway is never "silent"
        end = time.monotonic() + stall_s + 0.5
        seen_false = 0
        while time.monotonic() < end:
            seen_false += not client.gateway_alive
            time.sleep(0.005)
        assert seen_false == 0, f"gateway reported silent {seen_false} times during a stall"
    finally:
        poke.shutdown()


def test_a_really_silent_gateway_is_found_after_the_timeout(station) -> None:
    gateway, client, _ = station
    assert client.gateway_alive
    muted_at = wire_now()
    gateway.silent = True
    deadline = time.monotonic() + 5.0
    while client.gateway_alive and time.monotonic() < deadline:
        time.sleep(0.005)
    found = wire_now()
    assert not client.gateway_alive, "a silent gateway was never found silent"
    # the decision rests on bus evidence: the last heartbeat is older than the timeout in
    # the wire time the receive thread has seen, and it came before the mute
    last = client._liveness.last_heartbeat
    assert last <= muted_at + 0.01
    assert client.bus.seen_until() - last > client.heartbeat_timeout
    assert found - muted_at >= client.heartbeat_timeout - 0.06  # never before the timeout
    gateway.silent = False
    deadline = time.monotonic() + 5.0
    while not client.gateway_alive and time.monotonic() < deadline:
        time.sleep(0.005)
    assert client.gateway_alive


def _stall_station_sends(gateway, seconds: float) -> None:
    """Hold the station's send path for ``seconds``, as a starved station thread would be held:
    its frames wait behind the loss check's lock (a loss rate that drops nothing)."""
    gateway.bus.loss_rate = 1e-12
    with gateway.bus._rng_lock:
        time.sleep(seconds)


def test_a_starved_heartbeat_producer_is_not_a_silent_gateway(station) -> None:
    """The XN-GW's heartbeat timer is hardware (CiA 301 0x1017); the thread standing in for it
    may be starved. While its next heartbeat is due but not sent, the wire owes it."""
    gateway, client, _ = station
    period = client.heartbeat_ms / 1000.0
    beats: list[float] = []
    client.network.subscribe(0x700 + client.node_id, lambda _cob, _data, ts: beats.append(ts))
    time.sleep(3 * period)
    assert client.gateway_alive
    stall_s = 3 * client.heartbeat_timeout
    seen_false = 0
    stall = threading.Thread(target=_stall_station_sends, args=(gateway, stall_s))
    stall.start()
    end = time.monotonic() + stall_s + 0.3
    while time.monotonic() < end:
        seen_false += not client.gateway_alive
        time.sleep(0.005)
    stall.join()
    released = wire_now()
    assert seen_false == 0, f"gateway reported silent {seen_false} times during a stall"
    # the producer goes on after the stall (waited for by the heartbeats' own stamps: the
    # producer and this client's receive thread may both be starved a while)...
    wait_until(lambda: sum(b >= released for b in list(beats)) >= 4,
               "four heartbeats after the stall", timeout=10.0)
    # ... on its timer's grid, without a burst of the ~12 slots missed: the frame held by the
    # stall goes out at once and the next at the next slot, so any frame and the one after
    # its successor are at least a period apart (a thread late on a loaded machine may put
    # two frames closer than a period, never three; the margin is for frames queued on the
    # wire, each stamped at its end)
    after = [b for b in list(beats) if b >= released - period]
    assert all(c - a > 0.9 * period for a, c in zip(after, after[2:])), after


def test_a_heartbeat_producer_stuck_for_good_is_found_silent(station) -> None:
    """A producer held up beyond OWED_MAX_S owes nothing any more: the gateway goes silent."""
    gateway, client, _ = station
    assert client.gateway_alive
    stall = threading.Thread(target=_stall_station_sends,
                             args=(gateway, OWED_MAX_S + 2 * client.heartbeat_timeout + 0.3))
    stall.start()
    try:
        deadline = time.monotonic() + OWED_MAX_S + 2 * client.heartbeat_timeout + 0.2
        while client.gateway_alive and time.monotonic() < deadline:
            time.sleep(0.005)
        assert not client.gateway_alive, "a producer stuck for good was never found silent"
    finally:
        stall.join()


def _restarts_after(client, seconds: float) -> int:
    """Starts of the station by the master within ``seconds``: NMT start alone or a whole
    re-configuration (both are counted in ``nmt_restarts`` when a heartbeat asked)."""
    deadline = time.monotonic() + seconds
    start = client.counters.nmt_restarts
    while time.monotonic() < deadline and client.counters.nmt_restarts == start:
        time.sleep(0.005)
    return client.counters.nmt_restarts - start


def test_a_heartbeat_queued_before_the_nmt_start_is_no_state_change(station, channel) -> None:
    """A PRE-OPERATIONAL heartbeat (CiA 301 state 127) on the wire within the heartbeat timeout
    after the master's NMT start was queued before the command took effect: not started again.
    One later than that is the station's real state: started again."""
    gateway, client, _ = station
    poke = open_bus(BusConfig(channel=channel, node_id=5))
    stale = can.Message(arbitration_id=0x700 + client.node_id, data=bytes([127]),
                        is_extended_id=False)
    handled: list[float] = []  # monotonic times the client handled a state-127 heartbeat
    client.network.subscribe(0x700 + client.node_id, lambda _cob, data, _ts: handled.append(
        time.monotonic()) if data[:1] == b"\x7f" else None)
    try:
        for _attempt in range(5):
            client.configure()
            started, seen = client._liveness.started_at, len(handled)
            poke.send(stale)
            wait_until(lambda: len(handled) > seen, "the poked heartbeat handled")
            if handled[seen] - started <= client.heartbeat_timeout:
                break  # the case under test: handled within the timeout after the NMT start
            # this thread was held up past the timeout on a busy machine: that heartbeat was
            # the station's state by then, and it is started again; try once more
            _restarts_after(client, 2.0)
        else:
            pytest.fail("five tries never had the heartbeat handled within the timeout")
        assert _restarts_after(client, 2 * client.heartbeat_timeout) == 0
        time.sleep(client.heartbeat_timeout)
        poke.send(stale)
        assert _restarts_after(client, 2.0) == 1
    finally:
        poke.shutdown()
